#!/usr/bin/env bash
# Set up the environment and run the whole test suite (what CI runs). Extra arguments go to pytest:
# `-m "not slow"` leaves out the long tests (pyproject.toml registers the marker) for a quick check.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m pytest "$@"
