"""A digest of a folder's Python sources: what a compiled kernel of that folder was built from.

Plain hashlib, no numba, so the add-on can name its cache folder by it without importing core
(kd_addon/corelib.py loads this file on its own).
"""
import hashlib
from pathlib import Path


def sources_digest(folder) -> str:
    """16 hex digits that change whenever any `*.py` file in `folder` is added, removed, renamed
    or edited."""
    h = hashlib.blake2b(digest_size=8)
    for path in sorted(Path(folder).glob("*.py")):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()
