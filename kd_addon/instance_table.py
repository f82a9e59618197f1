"""Placements as arrays: what the bulk instance reader gives, readable as a sequence of Instance records.

A scene of a million scattered instances cannot afford a Python object per placement, so the bulk path
(bulk_instances.py) returns one row per placement: its geometry key and world matrix, and an index
into a short list of kinds (object name, instancer, ray visibility, holdout), which are shared by all
instances one carrier makes. Indexing or iterating gives the same Instance records the per-entry walk
makes, so code that reads records works unchanged; the hot consumers (tree_cache.mesh_inputs, the
world triangles) use the arrays. Nothing here imports bpy.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from .scene_records import Instance


class Kind(NamedTuple):
    """What every placement of one row group shares (the Instance fields besides key and matrix)."""

    name: str
    instancer: str | None
    is_instance: bool
    camera: bool
    shadow: bool
    holdout: bool


class InstanceTable(Sequence):
    """Rows of placements: geometry_keys (I,) int64, matrices (I, 4, 4) float64, kind_of (I,) int32
    indices into `kinds`."""

    def __init__(self, geometry_keys: np.ndarray, matrices: np.ndarray, kind_of: np.ndarray, kinds: list[Kind],
                 token: bytes | None = None):
        self.geometry_keys = np.ascontiguousarray(geometry_keys, np.int64)
        self.matrices = np.ascontiguousarray(matrices, np.float64).reshape(-1, 4, 4)
        self.kind_of = np.ascontiguousarray(kind_of, np.int32)
        self.kinds = list(kinds)
        # Stands for the matrices, kinds and kind_of in tree_cache.image_key: equal tokens, equal rows (a
        # carrier's rows kept from last frame keep theirs, new rows get a new one), whatever the keys.
        self.token = token if token is not None else _content_token(self.matrices, self.kind_of, self.kinds)

    def __len__(self) -> int:
        return len(self.geometry_keys)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        index = range(len(self))[index]  # negative indices, IndexError
        kind = self.kinds[self.kind_of[index]]
        return Instance(int(self.geometry_keys[index]), self.matrices[index].copy(), kind.name, kind.instancer,
                        kind.is_instance, kind.camera, kind.shadow, kind.holdout)

    def records(self) -> list[Instance]:
        """Every row as an Instance record (a Python object each: for tests and small scenes)."""
        return list(self)

    def distinct_kinds(self) -> list[Instance]:
        """One record per kind in use: what name- and flag-based consumers need, without a row each."""
        first = np.unique(self.kind_of, return_index=True)[1]
        return [self[int(i)] for i in np.sort(first)]

    def visibility(self, camera_bit: int, shadow_bit: int, holdout_bit: int) -> np.ndarray:
        """(I,) uint8: the bits of each row's kind (core's CAMERA_RAYS, SHADOW_RAYS, HOLDOUT)."""
        per_kind = np.array([camera_bit * k.camera | shadow_bit * k.shadow | holdout_bit * k.holdout
                             for k in self.kinds], np.uint8)
        return per_kind[self.kind_of] if len(per_kind) else np.zeros(0, np.uint8)


def as_table(instances) -> InstanceTable:
    """`instances` (an InstanceTable, or a list of Instance records) as an InstanceTable."""
    if isinstance(instances, InstanceTable):
        return instances
    kinds: dict[Kind, int] = {}
    kind_of = [kinds.setdefault(Kind(r.name, r.instancer, r.is_instance, r.camera, r.shadow, r.holdout), len(kinds))
               for r in instances]
    matrices = np.stack([r.matrix_world for r in instances]) if instances else np.zeros((0, 4, 4))
    return InstanceTable(np.array([r.geometry_key for r in instances], np.int64), matrices,
                         np.array(kind_of, np.int32), list(kinds))


def concatenated(tables: list[InstanceTable]) -> InstanceTable:
    """The rows of `tables` one after the other, their kinds merged. The matrices and kinds of the last
    call are taken again when the parts' tokens say they are unchanged (a static frame copies no matrix)."""
    tables = [t for t in tables if len(t)] or tables[:1]
    if not tables:
        return InstanceTable(np.zeros(0, np.int64), np.zeros((0, 4, 4)), np.zeros(0, np.int32), [])
    if len(tables) == 1:
        return tables[0]
    token = hashlib.blake2b(b"".join(t.token for t in tables), digest_size=16).digest()
    keys = np.concatenate([t.geometry_keys for t in tables])
    if _last_joined and _last_joined[0] == token:
        _, matrices, kind_of, kinds = _last_joined
        return InstanceTable(keys, matrices, kind_of, kinds, token)
    merged: dict[Kind, int] = {}
    kind_of = []
    for table in tables:
        remap = np.array([merged.setdefault(k, len(merged)) for k in table.kinds] or [0], np.int32)
        kind_of.append(remap[table.kind_of])
    joined = InstanceTable(keys, np.concatenate([t.matrices for t in tables]), np.concatenate(kind_of), list(merged),
                           token)
    _last_joined[:] = [token, joined.matrices, joined.kind_of, joined.kinds]
    return joined


_last_joined: list = []  # [token, matrices, kind_of, kinds] of the last concatenation


def _content_token(matrices: np.ndarray, kind_of: np.ndarray, kinds: list[Kind]) -> bytes:
    h = hashlib.blake2b(digest_size=16)
    h.update(matrices.tobytes())
    h.update(kind_of.tobytes())
    h.update(repr(kinds).encode())
    return h.digest()
