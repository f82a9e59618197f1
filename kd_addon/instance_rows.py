"""The rows of one geometry-nodes carrier composed from its GeometrySets' arrays, and kept across frames.

bulk_instances.py reads each GeometrySet holding instances once (`Gathered`: transforms, reference
indices, and what each reference places); `compose_rows` turns that into rows, level by level, in the
walk's order. The result (`CarrierRows`) remembers what it was made of, so the next frame, whose
arrays and references are equal (compared as arrays, never per instance in Python), takes its rows as
they are: a static frame of a million instances costs the reading of the arrays and one comparison
(docs/choices.md#bulk-instance-extraction). Nothing here imports bpy.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

from .instance_table import InstanceTable, Kind


class Reference(NamedTuple):
    """What one instance reference places: rows of mesh `slot` (-1: none) with kind `kind`, and the
    instances of GeometrySet `nested` (an index into Gathered.sets, -1: none)."""

    slot: int
    kind: int
    nested: int


class InstanceSet(NamedTuple):
    """One GeometrySet's instances: transforms (K, 4, 4) float32 column-major, reference indices (K,)."""

    transforms: np.ndarray
    reference_of: np.ndarray
    references: tuple


class Gathered:
    """A carrier's GeometrySets (sets[0] its own), its mesh slots (geometry key and fingerprint each)
    and the kinds its rows take."""

    def __init__(self):
        self.sets: list[InstanceSet] = []
        self.keys: list[int] = []
        self.fingerprints: list[int] = []
        self.kinds: list[Kind] = []

    def place(self, reader, key, verdict) -> tuple[int, int]:
        """(slot, kind) of rows of geometry `key` with the walk's `verdict`; (-1, -1) when none."""
        if key is None or verdict is None:
            return -1, -1
        from .scene_records import geometry_fingerprint
        if key not in self.keys:
            self.keys.append(key)
            self.fingerprints.append(geometry_fingerprint(reader.geometries.geometries[key]))
        kind = Kind(verdict[0], verdict[1], True, *verdict[2:])
        if kind not in self.kinds:
            self.kinds.append(kind)
        return self.keys.index(key), self.kinds.index(kind)


class CarrierRows:
    """One carrier's rows: matrices (I, 4, 4) float64, mesh slot and kind per row, and what they were
    made of (world matrix, the GeometrySets' arrays, slot fingerprints, kinds); `non_finite`: the
    rows left out for a non-finite matrix, counted by (object name, instancer name)."""

    def __init__(self, world, gathered: Gathered, slots, matrices, kind_of, non_finite, meshed):
        self.world, self.sets = world.copy(), gathered.sets
        self.fingerprints, self.kinds = list(gathered.fingerprints), list(gathered.kinds)
        self.slots, self.matrices, self.kind_of = slots, matrices, kind_of
        self.non_finite, self.meshed = non_finite, meshed
        self.token = os.urandom(16)  # new rows, a new token: instance_table.InstanceTable.token

    def matches(self, world, gathered: Gathered) -> bool:
        """Whether `gathered` is what these rows were made of: the rows are then this frame's too."""
        if not (np.array_equal(world, self.world) and self.fingerprints == gathered.fingerprints
                and self.kinds == gathered.kinds and len(self.sets) == len(gathered.sets)):
            return False
        return all(a.references == b.references and np.array_equal(a.reference_of, b.reference_of)
                   and np.array_equal(a.transforms, b.transforms) for a, b in zip(self.sets, gathered.sets))

    def table(self, keys: list[int]) -> InstanceTable:
        """The rows with this frame's geometry keys (`keys`: by slot)."""
        key_of_slot = np.array(keys or [0], np.int64)
        return InstanceTable(key_of_slot[self.slots], self.matrices, self.kind_of, self.kinds, token=self.token)


def compose_rows(world: np.ndarray, gathered: Gathered) -> CarrierRows:
    """Rows of every mesh the carrier's instances place, nested GeometrySets level by level, in the
    walk's order (an instance's mesh, then its own instances, depth first); rows whose matrix is not
    finite are left out and counted per object, as the walk counts them."""
    parts = _Parts()
    parents, set_of, path = world[None], np.zeros(1, np.int64), []
    while len(parents):
        parents, set_of, path = _level(gathered, parents, set_of, path, parts)
    slots, matrices, kind_of, paths = parts.joined()
    finite = np.isfinite(matrices).all(axis=(1, 2))
    non_finite = {}
    for kind in np.unique(kind_of[~finite]):
        name, instancer = gathered.kinds[kind].name, gathered.kinds[kind].instancer
        key = (name, instancer)  # kinds of other ray flags may share it
        non_finite[key] = non_finite.get(key, 0) + int(np.count_nonzero(kind_of[~finite] == kind))
    if not finite.all():
        slots, matrices, kind_of, paths = slots[finite], matrices[finite], kind_of[finite], [p[finite] for p in paths]
    if len(parts.slots) > 1:
        order = np.lexsort(paths[::-1])
        slots, matrices, kind_of = slots[order], matrices[order], kind_of[order]
    meshed = {gathered.kinds[k].name for k in np.unique(kind_of)
              if gathered.kinds[k].name == gathered.kinds[k].instancer}
    return CarrierRows(world, gathered, slots, _row_major(matrices), kind_of, non_finite, meshed)


def _level(gathered: Gathered, parents, set_of, path, parts):
    """Rows of the instances one level's GeometrySets hold; (parents, set_of, path) of the next level."""
    nested = _Parts()
    for index in np.unique(set_of):
        instances = gathered.sets[index]
        rows = np.flatnonzero(set_of == index)
        count = len(instances.transforms)
        if count == 0:
            continue
        if len(rows) == 1:  # the carrier's own set (and any set instanced once): no copy of the parent
            composed = compose(parents[rows], instances.transforms)
        else:
            composed = compose(np.repeat(parents[rows], count, axis=0), np.tile(instances.transforms, (len(rows), 1, 1)))
        refs = np.tile(instances.reference_of, len(rows))
        level_path = [p[rows].repeat(count) for p in path] + [np.tile(np.arange(count), len(rows))]
        single = len(instances.references) == 1
        order = None if single else np.argsort(refs, kind="stable")
        bounds = None if single else np.searchsorted(refs[order], np.arange(len(instances.references) + 1))
        for ref_index, reference in enumerate(instances.references):
            chosen = slice(None) if single else np.sort(order[bounds[ref_index]:bounds[ref_index + 1]])
            if reference.slot >= 0:
                parts.add(reference.slot, reference.kind, composed[chosen], [p[chosen] for p in level_path])
            if reference.nested >= 0:
                nested.add(reference.nested, -1, composed[chosen], [p[chosen] for p in level_path])
    if not nested.slots:
        return np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int64), []
    set_of_next, matrices, _, paths = nested.joined()
    return matrices, set_of_next, paths


class _Parts:
    """Row blocks: (slot, kind) per block, their matrices and paths; joined into arrays at the end."""

    def __init__(self):
        self.slots, self.kinds, self.matrices, self.paths = [], [], [], []

    def add(self, slot, kind, matrices, path) -> None:
        if len(matrices):
            self.slots.append(np.full(len(matrices), slot, np.int64))
            self.kinds.append(np.full(len(matrices), kind, np.int32))
            self.matrices.append(matrices)
            self.paths.append(path)

    def joined(self):
        if not self.slots:
            return np.zeros(0, np.int64), np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int32), []
        depth = max(len(p) for p in self.paths)
        paths = [np.concatenate([p[d] if d < len(p) else np.full(len(s), -1) for p, s in zip(self.paths, self.slots)])
                 for d in range(depth)]
        join = (lambda arrays: arrays[0]) if len(self.slots) == 1 else np.concatenate
        return join(self.slots), join(self.matrices), join(self.kinds), paths


def compose(a: np.ndarray, b: np.ndarray, chunk: int = 1 << 14) -> np.ndarray:
    """a @ b of column-major float32 4x4 matrices (N or 1, 4, 4) as Blender's mul_m4_m4m4 computes them:
    column i of the product is sum_k a[k] * b[i][k], summed in pairs ((0 + 1) + (2 + 3)), each step
    rounded to float32, so the result is the walk's matrix to the bit. In chunks of `chunk` rows, whose
    temporaries stay in cache: only the result is allocated whole."""
    count = max(len(a), len(b))
    out = np.empty((count, 4, 4), np.float32)
    pair, term = np.empty((2, min(count, chunk), 4, 4), np.float32)
    with np.errstate(over="ignore", invalid="ignore"):  # an infinite scale: the row is dropped, and named
        for start in range(0, count, chunk):
            end = min(count, start + chunk)
            left = a if len(a) == 1 else a[start:end]
            right = b if len(b) == 1 else b[start:end]
            o, p, t = out[start:end], pair[:end - start], term[:end - start]
            np.multiply(left[:, 0, None, :], right[:, :, 0, None], out=o)
            o += np.multiply(left[:, 1, None, :], right[:, :, 1, None], out=t)
            np.multiply(left[:, 2, None, :], right[:, :, 2, None], out=p)
            p += np.multiply(left[:, 3, None, :], right[:, :, 3, None], out=t)
            o += p
    return out


def _row_major(matrices: np.ndarray) -> np.ndarray:
    """(I, 4, 4) float64 C-contiguous, rows as numpy (and the walk's Instance records) hold them."""
    out = np.empty(matrices.shape, np.float64)
    out[...] = matrices.transpose(0, 2, 1)
    return out
