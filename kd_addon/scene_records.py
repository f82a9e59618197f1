"""What extraction hands on: per-mesh geometry, its placements, and the scene that holds both.

Plain numpy records without bpy, so the later stages (trees, tracing, the tree cache) and their tests
never need Blender. Each distinct evaluated mesh is one :class:`MeshGeometry` in object space; each
placement of it is one :class:`Instance` with a float64 world matrix, so later stages build one
kd-tree per mesh and a top-level tree over the instances. Geometry keys are ``Mesh.as_pointer()``
values: unique and stable within one extraction only.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class MeshGeometry:
    """One evaluated mesh in object space, shared by all its instances."""

    key: int
    name: str
    vertices: np.ndarray  # (V, 3) float32, C-contiguous
    triangles: np.ndarray  # (T, 3) int32 indices into vertices

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])


@dataclass(frozen=True)
class Instance:
    """One placement of a geometry in the world. The mesh of a curve, text, surface or metaball
    arrives as an instance of its own object (``instancer == name``); ``instancer`` is the top-level
    instancer (for nested collection instances, the outermost empty)."""

    geometry_key: int
    matrix_world: np.ndarray  # (4, 4) float64
    name: str  # original object's name
    instancer: str | None  # top-level instancer's name, None for scene objects
    is_instance: bool  # DepsgraphObjectInstance.is_instance
    camera: bool = True  # Ray Visibility > Camera (ANDed with the instancer's)
    shadow: bool = True  # Ray Visibility > Shadow: also what AO rays see (ANDed with the instancer's)
    holdout: bool = False  # Holdout (the instancer's for an instance): seen pixels stay empty

    @property
    def label(self) -> str:
        """How warnings name it: "object 'X'", or "object 'X' instanced by 'Y'"."""
        return object_label(self.name, self.instancer)


def object_label(name: str, instancer: str | None) -> str:
    """How warnings name an object and the instancer that placed it (None or itself: none)."""
    return f"object '{name}'" if instancer in (None, name) else f"object '{name}' instanced by '{instancer}'"


def non_finite_warnings(placements: dict[tuple[str, str | None], int | None]) -> list[str]:
    """One warning per (object name, instancer name or None) of `placements`, the number of its
    placements (instances, or None: the object's own entry) whose transform is not finite (a NaN
    location or scale from a driver or a script), which are left out: how many, when they are
    instances, since the object's other instances stay. A carrier whose own transform is not finite
    takes its instances of itself with it: they are not named again."""
    cause = "a non-finite transform (NaN or infinite location, rotation or scale)"
    warnings = []
    for (name, instancer), count in placements.items():
        if count is None:
            warnings.append(f"{object_label(name, instancer)} has {cause}; left out")
        elif not (instancer in (None, name) and (name, None) in placements):
            warnings.append(f"{object_label(name, instancer)}: {count} instance{'s' * (count != 1)} with {cause} "
                            "left out")
    return warnings


@dataclass
class ExtractedScene:
    """The render-visible triangles of one evaluated depsgraph. `instances`: a list of Instance records
    (the per-entry walk) or an instance_table.InstanceTable (the bulk path), read alike."""

    geometries: dict[int, MeshGeometry] = field(default_factory=dict)
    instances: list[Instance] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    extract_ms: float = 0.0
    frame: int = 0
    path: str = "walk"  # how the instances were read: "walk" (scene_walk.py) or "bulk" (bulk_instances.py)

    @property
    def object_names(self) -> list[str]:
        """Original object name for each entry of ``instances``."""
        table = self.table()
        names = [k.name for k in table.kinds]
        return [names[k] for k in table.kind_of.tolist()]

    @property
    def object_count(self) -> int:
        """Number of placed meshes (entries of ``instances``)."""
        return len(self.instances)

    @property
    def triangle_count(self) -> int:
        """Total world-space triangles, instances counted separately."""
        return int(self._instance_triangle_counts().sum())

    def table(self):
        """``instances`` as an instance_table.InstanceTable (arrays: no Python object a row)."""
        from .instance_table import as_table  # it imports this module's Instance
        cached = getattr(self, "_table", None)
        if cached is None or cached[0] is not self.instances or len(cached[1]) != len(self.instances):
            cached = self._table = (self.instances, as_table(self.instances))
        return cached[1]

    def _instance_triangle_counts(self) -> np.ndarray:
        """(I,) int64 triangles of each instance's mesh: a binary search of the few mesh keys a row."""
        keys = self.table().geometry_keys
        mesh_keys = np.fromiter(self.geometries, np.int64, len(self.geometries))
        counts = np.array([g.triangle_count for g in self.geometries.values()], np.int64)
        order = np.argsort(mesh_keys)
        return counts[order[np.searchsorted(mesh_keys, keys, sorter=order)]] if len(keys) else np.zeros(0, np.int64)

    def triangle_object_ids(self) -> np.ndarray:
        """int32 (N,): index into ``instances`` of each world triangle."""
        counts = self._instance_triangle_counts()
        return np.repeat(np.arange(len(self.instances), dtype=np.int32), counts)

    def world_triangles(self) -> np.ndarray:
        """float32 (N, 3, 3) world-space triangles, in ``instances`` order: all instances of one mesh
        in one matmul and one gather, so the Python loop never runs over triangles."""
        counts = self._instance_triangle_counts()
        starts = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)
        out = np.empty((int(counts.sum()), 3, 3), dtype=np.float32)
        table = self.table()
        for key, idx in _rows_by_key(table.geometry_keys).items():
            geom = self.geometries[key]
            world = _transform_points(table.matrices[idx], geom.vertices)  # (K, V, 3)
            _scatter_triangles(out, starts[idx], world, geom.triangles)
        return out


def _rows_by_key(keys: np.ndarray) -> dict[int, np.ndarray]:
    """Row indices of each geometry key, in row order."""
    order = np.argsort(keys, kind="stable")
    unique, first = np.unique(keys[order], return_index=True)
    return {int(k): rows for k, rows in zip(unique, np.split(order, first[1:]))}


def _transform_points(mats: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply K affine 4x4 matrices to (V,3) points -> float32 (K,V,3).

    The product runs in float64 so large translations keep their precision
    until the final cast.
    """
    rot_t = mats[:, :3, :3].transpose(0, 2, 1)
    world = np.matmul(points.astype(np.float64)[None], rot_t)
    world += mats[:, None, :3, 3]
    return world.astype(np.float32)


def _scatter_triangles(out, starts, world, triangles) -> None:
    """Gather (K,V,3) vertices by (T,3) indices into out[start_k : start_k+T], with np.take (faster
    than fancy indexing): few instances slice by slice, many small ones in one gather."""
    n_inst, n_tris = world.shape[0], triangles.shape[0]
    if n_inst <= 16:
        for k in range(n_inst):
            s = int(starts[k])
            np.take(world[k], triangles, axis=0, out=out[s : s + n_tris])
        return
    gathered = np.take(world, triangles, axis=1).reshape(-1, 3, 3)
    s0 = int(starts[0])
    if np.array_equal(starts, s0 + n_tris * np.arange(n_inst)):
        out[s0 : s0 + n_inst * n_tris] = gathered
    else:
        out[(starts[:, None] + np.arange(n_tris)).ravel()] = gathered


def geometry_fingerprint(geom: MeshGeometry) -> int:
    """Cheap 64-bit content hash of the vertex count, vertex and index bytes, for change detection:
    CRC-32 in the low half, Adler-32 in the high half.

    A matching fingerprint keeps a mesh's tree and its pixels, so a change it misses is a stale image.
    CRC-32 is linear, so four bytes chosen after any edit restore it; Adler-32 of the same bytes changes
    with them (docs/choices.md#geometry-fingerprint-crc-32-and-adler-32).
    """
    count = np.int64(geom.vertices.shape[0]).tobytes()
    crc = zlib.crc32(geom.triangles, zlib.crc32(geom.vertices, zlib.crc32(count)))
    adler = zlib.adler32(geom.triangles, zlib.adler32(geom.vertices, zlib.adler32(count)))
    return crc | adler << 32


# Object types whose evaluated geometry is a mesh the preview reads, and those Cycles renders that
# are not triangles.
TRIANGLE_TYPES = frozenset(("MESH", "CURVE", "SURFACE", "FONT", "META"))
NOT_TRIANGLES = {"CURVES": "hair curves", "POINTCLOUD": "a point cloud", "VOLUME": "a volume",
                 "GREASEPENCIL": "grease pencil", "GPENCIL": "grease pencil"}
NOT_TRIANGLE_DATA = {"Curves": "hair curves", "PointCloud": "a point cloud", "Volume": "a volume",
                     "GreasePencil": "grease pencil", "GreasePencilv3": "grease pencil"}  # by data type
