"""Geometry-nodes instances read in bulk: transforms and reference indices as arrays, meshes once each.

Walking ``depsgraph.object_instances`` costs microseconds an entry in Python, most of a frame of a
scene with a million scattered instances. Blender 4.3+ gives an evaluated object's ``GeometrySet``
(``Object.evaluated_geometry()``), whose ``instances_pointcloud()`` holds the attributes
``instance_transform`` (4x4 float32, column-major) and ``.reference_index``, and whose
``instance_references()`` lists what is instanced: these are read with ``foreach_get``, nested
GeometrySets level by level (docs/choices.md#bulk-instance-extraction).

The result is what the per-entry walk (scene_walk.py) gives, row for row: the same world matrices, to
the bit (Blender composes them in float32 with mul_m4_m4m4's pairwise sums, which `_compose` repeats),
the same order (an instance's mesh, then its own instances, depth first), the same records and
visibility (the walk's EntryReader decides, once per carrier and object). Whatever the bulk reading
cannot express as the walk does (collection references, particles, vertex or face instancing, curves
and other non-mesh geometry, instances a render-hidden path may block, Show Instancer off in the
viewport) makes `read_in_bulk` return None, and the caller walks instead: nothing is half-read.
"""

from __future__ import annotations

import bpy
import numpy as np

from .dupli_paths import instances_things
from .node_instances import has_node_modifier
from .instance_table import InstanceTable, Kind, as_table, concatenated
from .render_visibility import instanced_by_its_parent
from .scene_records import object_label
from .scene_walk import EntryReader, SelfEntry

AVAILABLE = hasattr(bpy.types.Object, "evaluated_geometry")  # Blender 4.3 and later
ENABLED = True  # tests switch it off to run the walk on the same scenes (both paths must agree)

# Object types whose own entry the walk reads or skips without instancing anything.
_PLAIN_TYPES = frozenset(("MESH", "EMPTY", "LIGHT", "CAMERA", "LIGHT_PROBE", "LIGHTPROBE", "SPEAKER", "ARMATURE",
                          "LATTICE"))


class NotInBulk(Exception):
    """The scene holds something only the per-entry walk reads as a render would."""


def usable(depsgraph: bpy.types.Depsgraph) -> bool:
    """Whether the bulk path may read this scene: bpy offers it, it is on, and every object of the file
    is of a kind whose own entry and instances it reads as the walk does."""
    if not (AVAILABLE and ENABLED) or depsgraph.scene.background_set is not None:
        return False
    return all(_plain(ob) for ob in bpy.data.objects)


def _plain(ob: bpy.types.Object) -> bool:
    return (ob.type in _PLAIN_TYPES and ob.instance_type == "NONE" and not len(ob.particle_systems)
            and ob.show_instancer_for_viewport and not instanced_by_its_parent(ob))


def read_in_bulk(depsgraph: bpy.types.Depsgraph, reader: EntryReader) -> InstanceTable | None:
    """Every placement of the depsgraph in the walk's order, or None when the walk must read it."""
    segments: list = []
    own: list = []
    alive: list = []  # every GeometrySet read, until the end: a freed one's mesh address may come back as
    # another's, and the mesh reader keys meshes by address
    try:
        for ob in depsgraph.objects:
            own.append(reader.read(SelfEntry(ob)))
            if ob.type == "MESH" and has_node_modifier(ob.original):  # is_instancer is off for them here
                segments.append([r for r in own if r is not None])
                own = []
                segments.append(_carrier_rows(ob, reader, alive))
    except NotInBulk:
        return None
    segments.append([r for r in own if r is not None])
    return concatenated([as_table(reader.without_hidden_carriers(s)) if isinstance(s, list) else s
                         for s in segments])


def _carrier_rows(carrier, reader: EntryReader, alive: list) -> InstanceTable:
    """The placements a geometry-nodes carrier's instances give, as the walk would record them."""
    if reader.paths.walks(carrier.original):
        raise NotInBulk  # a render-hidden path may block some: dupli_paths.py decides entry by entry
    geometry = carrier.evaluated_geometry()
    alive.append(geometry)
    world = np.array(carrier.matrix_world, np.float32).T  # Blender's column-major layout
    rows = _Rows(reader, carrier, alive)
    level = _Level(np.broadcast_to(world, (1, 4, 4)), [geometry], np.zeros(1, np.int64), [])
    while level is not None:
        level = rows.expand(level)
    return rows.table()


class _Level:
    """Pending instancing: parents (N, 4, 4) column-major float32, the GeometrySet each row instances
    from (an index into `sets`), and each row's path (one index array a level, for the walk's order)."""

    def __init__(self, parents, sets, set_of, path):
        self.parents, self.sets, self.set_of, self.path = parents, sets, set_of, path


class _Rows:
    """Rows gathered over the levels of one carrier: (geometry key, matrix, kind, path) per placement."""

    def __init__(self, reader: EntryReader, carrier, alive: list):
        self.reader, self.carrier, self.alive = reader, carrier, alive
        self.keys, self.matrices, self.kinds, self.paths = [], [], [], []
        self.kind_list: dict[Kind, int] = {}

    def expand(self, level: _Level) -> _Level | None:
        """Rows of the instances the level's GeometrySets hold; the next level, or None at the end."""
        nested = _Nested()
        for index, geometry in enumerate(level.sets):
            _check_components(geometry)
            cloud = geometry.instances_pointcloud()
            rows = np.flatnonzero(level.set_of == index)
            if cloud is None or len(cloud.points) == 0 or len(rows) == 0:
                continue
            transforms, reference_of = _instance_arrays(cloud)
            count = len(transforms)
            composed = _compose(np.repeat(level.parents[rows], count, axis=0), np.tile(transforms, (len(rows), 1, 1)))
            refs = np.tile(reference_of, len(rows))
            path = [p[rows].repeat(count) for p in level.path] + [np.tile(np.arange(count), len(rows))]
            references = geometry.instance_references()
            self.alive.append(references)
            order = np.argsort(refs, kind="stable")
            bounds = np.searchsorted(refs[order], np.arange(len(references) + 1))
            for ref_index, reference in enumerate(references):
                chosen = np.sort(order[bounds[ref_index]:bounds[ref_index + 1]])
                if len(chosen):
                    self._place(reference, composed[chosen], [p[chosen] for p in path], nested)
        return nested.level()

    def _place(self, reference, matrices, path, nested: "_Nested") -> None:
        """Record the rows of one reference; a GeometrySet holding instances goes to the next level."""
        if reference is None:
            return
        if isinstance(reference, bpy.types.Object):
            self._object_rows(reference, matrices, path)
        elif isinstance(reference, bpy.types.GeometrySet):
            _check_components(reference)
            if reference.mesh is not None:
                self._mesh_rows(reference.mesh, matrices, path)
            cloud = reference.instances_pointcloud()
            if cloud is not None and len(cloud.points):
                nested.add(reference, matrices, path)
        else:
            raise NotInBulk  # a collection: its members follow the collection rules of a render

    def _mesh_rows(self, mesh, matrices, path) -> None:
        """Rows of a GeometrySet's mesh: entries of the carrier itself (named and seen as it)."""
        verdict = self.reader.verdict(self.carrier, self.carrier)
        if verdict is None:
            return
        key = self.reader.geometries.get_mesh(self.carrier, mesh, verdict[0])
        if key is not None:
            self.reader.meshed.add(verdict[0])
            self._add(key, matrices, verdict, path)

    def _object_rows(self, target, matrices, path) -> None:
        """Rows of an instanced object (Object Info "As Instance", separated children; `target` is the
        evaluated object): entries of it, instanced by the carrier."""
        if target.type not in ("MESH", "EMPTY", "LIGHT", "CAMERA") or instances_things(target.original):
            raise NotInBulk  # curves, text, nested instancers: the walk reads their entries
        verdict = self.reader.verdict(target, self.carrier)  # an instanced empty makes its carrier an instancer
        if verdict is None or target.type != "MESH":
            return
        key = self.reader.geometries.get(target, verdict[0])
        if key is not None:
            self._add(key, matrices, verdict, path)

    def _add(self, key, matrices, verdict, path) -> None:
        finite = np.isfinite(matrices).all(axis=(1, 2))
        if not finite.all():
            name, instancer = verdict[0], verdict[1]
            self.reader.non_finite_placements.setdefault(
                (name, instancer), f"{object_label(name, instancer)} has a non-finite transform (NaN or infinite "
                "location, rotation or scale); left out")
            matrices, path = matrices[finite], [p[finite] for p in path]
        kind = self.kind_list.setdefault(Kind(verdict[0], verdict[1], True, *verdict[2:]), len(self.kind_list))
        self.keys.append(np.full(len(matrices), key, np.int64))
        self.matrices.append(matrices)
        self.kinds.append(np.full(len(matrices), kind, np.int32))
        self.paths.append(path)

    def table(self) -> InstanceTable:
        """The rows in the walk's order: by path, an instance's mesh before its own instances (-1 pads)."""
        if not self.keys:
            return InstanceTable(np.zeros(0, np.int64), np.zeros((0, 4, 4)), np.zeros(0, np.int32), [])
        keys, kinds, matrices = np.concatenate(self.keys), np.concatenate(self.kinds), np.concatenate(self.matrices)
        if len(self.keys) > 1:
            depth = max(len(p) for p in self.paths)
            columns = [np.concatenate([p[d] if d < len(p) else np.full(len(k), -1) for p, k in zip(self.paths, self.keys)])
                       for d in range(depth)]
            order = np.lexsort(columns[::-1])
            keys, kinds, matrices = keys[order], kinds[order], matrices[order]
        return InstanceTable(keys, matrices.transpose(0, 2, 1).astype(np.float64), kinds, list(self.kind_list))


class _Nested:
    """The GeometrySets of one level that hold instances themselves, with the rows instancing them."""

    def __init__(self):
        self.parents, self.sets, self.set_of, self.paths = [], [], [], []

    def add(self, geometry, matrices, path) -> None:
        self.set_of.append(np.full(len(matrices), len(self.sets)))
        self.sets.append(geometry)
        self.parents.append(matrices)
        self.paths.append(path)

    def level(self) -> _Level | None:
        if not self.sets:
            return None
        return _Level(np.concatenate(self.parents), self.sets, np.concatenate(self.set_of),
                      [np.concatenate(column) for column in zip(*self.paths)])


def _check_components(geometry) -> None:
    """Point clouds, curves, volumes and grease pencil among the instances: the walk names them."""
    if any(getattr(geometry, part, None) is not None for part in ("pointcloud", "curves", "volume", "grease_pencil")):
        raise NotInBulk


def _instance_arrays(cloud) -> tuple[np.ndarray, np.ndarray]:
    """(transforms (K, 4, 4) float32 as Blender stores them (column-major), reference indices (K,))."""
    count = len(cloud.points)
    transforms = np.empty(count * 16, np.float32)
    cloud.attributes["instance_transform"].data.foreach_get("value", transforms)
    references = np.zeros(count, np.int32)
    index = cloud.attributes.get(".reference_index")
    if index is not None:
        index.data.foreach_get("value", references)
    return transforms.reshape(count, 4, 4), references


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b of column-major float32 4x4 matrices (N, 4, 4) as Blender's mul_m4_m4m4 computes them:
    column i of the product is sum_k a[k] * b[i][k], summed in pairs ((0 + 1) + (2 + 3)), each step
    rounded to float32, so the result is the walk's matrix to the bit."""
    with np.errstate(over="ignore", invalid="ignore"):  # an infinite scale: the row is dropped, and named
        terms = [a[:, k, None, :] * b[:, :, k, None] for k in range(4)]
        return (terms[0] + terms[1]) + (terms[2] + terms[3])
