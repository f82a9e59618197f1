"""Reading an evaluated Blender mesh into numpy: positions and loop triangles in bulk.

Triangles come from ``calc_loop_triangles()`` and ``foreach_get`` into preallocated arrays, each mesh
read once per extraction however many objects use it.
"""

from __future__ import annotations

import bpy
import numpy as np

from .scene_records import MeshGeometry


def read_mesh(mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Object-space (vertices float32 (V,3), triangles int32 (T,3)) of a Mesh.

    Uses only bulk foreach_get paths that are plain memcpys: "position" into float32, the loop
    triangles' "loops" into uint32 (the property is unsigned: any other dtype drops to a per-item
    path), ".corner_vert" into int32, then one gather
    (docs/choices.md#read-meshes-with-bulk-attribute-reads).
    """
    mesh.calc_loop_triangles()  # cached in 5.0: a no-op when already built
    n_tris = len(mesh.loop_triangles)
    n_verts = len(mesh.vertices)
    verts = np.empty(n_verts * 3, dtype=np.float32)
    if n_verts:
        mesh.attributes["position"].data.foreach_get("vector", verts)
    if n_tris == 0:
        return verts.reshape(-1, 3), np.empty((0, 3), dtype=np.int32)
    corners = np.empty(n_tris * 3, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("loops", corners)
    corner_vert = np.empty(len(mesh.loops), dtype=np.int32)
    attr = mesh.attributes.get(".corner_vert")  # internal name; guard renames
    if attr is not None:
        attr.data.foreach_get("value", corner_vert)
    else:  # a per-item path: slow, but stays correct
        mesh.loops.foreach_get("vertex_index", corner_vert)
    tris = np.take(corner_vert, corners.view(np.int32)).reshape(-1, 3)
    return verts.reshape(-1, 3), tris


def read_object_mesh(ob: bpy.types.Object, mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """read_mesh of an evaluated object's mesh `mesh`, Edit Mode included. An object in Edit Mode
    evaluates to a wrapper around its edit mesh that has no "position" attribute and, without
    modifiers, no triangles: the preview lost the object being modelled, or failed (KeyError) with a
    modifier. to_mesh() flushes the edit mesh with every layer, as Cycles does (object_to_mesh in
    intern/cycles/blender/util.h); the copy is freed at once."""
    if not mesh.is_editmode:
        return read_mesh(mesh)
    try:
        return read_mesh(ob.to_mesh())
    finally:
        ob.to_mesh_clear()


def without_non_finite(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """(vertices, triangles, how many triangles were dropped): the triangles that use a NaN or infinite
    vertex left out, as Cycles leaves them, and such vertices (now unused) set to 0, which core accepts."""
    finite = np.isfinite(verts).all(axis=1)
    kept = finite[tris].all(axis=1)
    verts = np.where(finite[:, None], verts, np.float32(0.0))
    return verts, tris[kept], int(len(tris) - kept.sum())


class GeometryReader:
    """Reads each evaluated mesh once; a mesh with non-finite vertices warns once, naming every object
    that uses it and how many of its triangles were left out."""

    def __init__(self):
        self.geometries: dict[int, MeshGeometry] = {}
        self.rejected: set[int] = set()
        # key -> (mesh name, its objects, triangles left out, triangles read)
        self.non_finite: dict[int, tuple[str, set[str], int, int]] = {}

    def get(self, ob: bpy.types.Object, object_name: str) -> int | None:
        """Geometry key for the evaluated object `ob`'s mesh, or None when it has no usable triangles."""
        return self.get_mesh(ob, ob.data, object_name)

    def get_mesh(self, ob: bpy.types.Object, mesh: bpy.types.Mesh, object_name: str) -> int | None:
        """`get` of a mesh `ob` places other than its own data (a geometry-nodes instance's mesh)."""
        key = mesh.as_pointer()
        if key in self.geometries or key in self.rejected:
            if key in self.non_finite:
                self.non_finite[key][1].add(object_name)
            return key if key in self.geometries else None
        verts, tris = read_object_mesh(ob, mesh)
        if len(tris) and not np.isfinite(verts).all():
            verts, kept, dropped = without_non_finite(verts, tris)
            if dropped:  # a loose non-finite vertex costs nothing: said nothing, as in Cycles
                self.non_finite[key] = (mesh.name, {object_name}, dropped, len(tris))
            tris = kept
        if len(tris) == 0:
            self.rejected.add(key)
            return None
        self.geometries[key] = MeshGeometry(key, mesh.name, verts, tris)
        return key

    @property
    def warnings(self) -> list[str]:
        out = []
        for mesh_name, users, dropped, read in self.non_finite.values():
            names = ", ".join(f"'{n}'" for n in sorted(users))
            what = "left out" if dropped == read else f"the {dropped:,} of its {read:,} triangles that use them left out"
            if len(users) == 1:
                out.append(f"object {names} has non-finite vertex coordinates; {what}")
            else:
                out.append(f"objects {names} (sharing mesh '{mesh_name}') have non-finite vertex coordinates; {what}")
        return out
