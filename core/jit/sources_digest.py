"""A digest of a folder's Python sources: what a compiled kernel of that folder was built from.

Plain hashlib, no numba, so the add-on can name its cache folder by it without importing core
(kd_addon/corelib.py loads this file on its own).
"""
import hashlib
from pathlib import Path


def sources_digest(folder) -> str:
    """16 hex digits that change whenever any `*.py` file in `folder` or its subfolders is added,
    removed, renamed, moved or edited (each file is hashed with its path relative to `folder`)."""
    h = hashlib.blake2b(digest_size=8)
    folder = Path(folder)
    for relative in sorted(path.relative_to(folder).as_posix() for path in folder.rglob("*.py")):
        h.update(relative.encode() + b"\0")
        h.update((folder / relative).read_bytes())
    return h.hexdigest()
