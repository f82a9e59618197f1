#!/usr/bin/env bash
# Set up the environment and render the built-in animated demo scene headlessly to out/demo
# (images, a per-frame table and report.json). Extra arguments go to the renderer's command line.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m kd_addon render --frames 1-24 --out out/demo --mode ao+shadow "$@"
