"""Scene extraction: evaluated depsgraph -> per-mesh triangle records + instance list.

Everything Cycles would render as triangles is read from
``depsgraph.object_instances``: meshes after modifiers, armatures, shape keys
and geometry nodes, and the tessellated meshes of curves, text, surfaces and
metaballs. Each distinct evaluated mesh becomes one :class:`MeshGeometry`
(object space, read once), each placement of it one :class:`Instance` with a
float64 world matrix, so later stages can build one kd-tree per mesh and a
top-level tree over the instances.

How bpy 5.0 hands over non-mesh objects
    A curve, text, surface or metaball object appears twice in
    ``object_instances``: once with its own type (``CURVE``, ``FONT``, ...) and
    once as a ``MESH`` instance of itself (``is_instance`` True, ``parent`` is
    the object) carrying the evaluated mesh component. Cycles renders only the
    second, and so do we: only entries whose evaluated data is a Mesh are read,
    and ``to_mesh()`` is never needed (calling it on the ``CURVE`` entry as
    well would count the geometry twice). Hair curves, point clouds, volumes
    and grease pencil are not triangles and are skipped with a warning naming
    them; empties, lights, cameras and meshes without faces are skipped quietly.

Render visibility (the viewport depsgraph also holds render-hidden objects)
    * A scene object is kept when its *original* has ``hide_render`` False and
      it is reachable from the view layer's collection tree through collections
      that are neither excluded nor ``hide_render``.
    * An instance is kept when its instancer (``DepsgraphObjectInstance.parent``,
      the top-level instancer) passes the rule above. For collection instances
      the instanced object must also be render-visible inside the instanced
      collection (own ``hide_render``, nested collection ``hide_render`` and
      nested collection instances), as Blender does when it instances a
      collection for a final render. Geometry-nodes and particle instances
      ignore the source object's ``hide_render`` (hiding the source is the usual
      workflow and Cycles still renders the copies), except for members of a
      collection that a Collection Info node instances whole or as a child
      collection it separates, or that particles render (*Render As:
      Collection*, whole or picked; node_instances.py): those follow the
      collection-instance rule, as in Cycles. Particles that pick one member
      each pick among the render-visible members in a render, among the
      viewport-enabled ones in the viewport: where the two differ the preview
      cannot reproduce the render's pick, and a warning says so.
    * An instance whose path goes through an instancer a render does not make
      or that is render-hidden (Blender makes no instances from a render-hidden
      object, at any depth) is left out, even where the same object is reached
      through a visible path too, and the instances of a render-hidden source
      of an Object Info node with them (its own mesh still shows): the
      verdicts above are per (object, top-level instancer), so each entry's
      path is walked on its own (dupli_paths.py).
    * Show Instancer: an object that instances things (particles,
      vertex/face/collection instancing, geometry nodes whose output holds
      instances) is left out itself when ``show_instancer_for_render`` is off
      (Blender's BKE_object_visibility in render mode). ``is_instancer`` is
      False for a geometry-nodes carrier, so a carrier's own entry is dropped
      once the walk has seen it instance something (outside review: Cycles hid
      such a plate, the preview showed it). The viewport's flag
      (``show_instancer_for_viewport``) is the one the viewport depsgraph
      applies: with it off and the render's on, the depsgraph yields the
      instances but not the object itself, so its evaluated mesh is read
      from ``evaluated_get`` (before: left out, with a warning that wrongly
      called it hidden).
    * Ray visibility: an object with ``visible_camera`` False *and*
      ``visible_shadow`` False is left out: it can neither be seen nor occlude.
      Otherwise each Instance carries the two flags (``camera``, ``shadow``),
      combined with the instancer's for instances (logical AND, as Cycles
      does): camera rays pass through an object hidden from them, and AO and
      shadow rays through one that casts no shadows (Cycles traces its AO rays
      as shadow rays).
    * Holdout (``is_holdout`` or a holdout collection: ``holdout_get`` of the
      view layer) is read from the object itself, and for an instance from its
      top-level instancer only, as Cycles does (measured: a holdout member of an
      instanced collection, or a holdout source object of geometry-nodes
      instances, changed nothing; a holdout instancer made all its instances
      holdouts). Indirect Only (a collection setting, ``indirect_only_get``) is
      read the same way and turns camera rays off, unless the object is a
      holdout: Cycles' AO pass and alpha were bit-identical to camera rays off
      for an object, a collection instancer and a geometry-nodes carrier, and
      to the holdout alone for a holdout in an Indirect Only collection.
    * Limitation (the preview follows the viewport here): objects the viewport
      does not show -- eye icon (``hide_set``), ``hide_viewport``, collections
      disabled in viewports -- are not yielded by the viewport depsgraph, so
      they are missing even though a final render would include them. Each
      frame's warnings name every such render-visible object, and every
      render-visible object that is not triangles (hair curves, point clouds,
      volumes, grease pencil), which Cycles renders and the preview cannot.
    * The viewport depsgraph evaluates *viewport* settings: Subdivision
      "Levels Viewport", metaball ``resolution``, geometry-nodes "Is Viewport",
      modifiers enabled in the viewport. The preview shows that geometry.

Geometry whose evaluated positions contain NaN or inf is left out with a
warning naming the object. Geometry keys are ``Mesh.as_pointer()`` values of
evaluated meshes: unique and stable *within one extraction* only.

This module imports bpy, numpy and its sibling bpy-only modules (never ``core``).
"""

from __future__ import annotations

import time
import zlib
from dataclasses import dataclass, field

import bpy
import numpy as np

from .cycles_culling import culling_warning
from .dupli_paths import (DupliPaths, instanced_collection, instancer_kind, instances_things,
                          unhidden_objects)
from .node_instances import (has_node_modifier, instancing_references, node_references,
                             objects_read_as_geometry)
from .viewport_evaluation import viewport_evaluation_warning

# --------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------


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
    """One placement of a geometry in the world.

    ``is_instance`` mirrors ``DepsgraphObjectInstance.is_instance``; note that
    the mesh of a curve, text, surface or metaball arrives as an instance of
    its own object (``instancer == name``). ``instancer`` is the top-level
    instancer (for nested collection instances, the outermost empty).
    """

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


@dataclass
class ExtractedScene:
    """The render-visible triangles of one evaluated depsgraph."""

    geometries: dict[int, MeshGeometry] = field(default_factory=dict)
    instances: list[Instance] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    extract_ms: float = 0.0
    frame: int = 0

    @property
    def object_names(self) -> list[str]:
        """Original object name for each entry of ``instances``."""
        return [inst.name for inst in self.instances]

    @property
    def object_count(self) -> int:
        """Number of placed meshes (entries of ``instances``)."""
        return len(self.instances)

    @property
    def triangle_count(self) -> int:
        """Total world-space triangles, instances counted separately."""
        return int(self._instance_triangle_counts().sum())

    def _instance_triangle_counts(self) -> np.ndarray:
        return np.array(
            [self.geometries[i.geometry_key].triangle_count for i in self.instances],
            dtype=np.int64,
        )

    def triangle_object_ids(self) -> np.ndarray:
        """int32 (N,): index into ``instances`` of each world triangle."""
        counts = self._instance_triangle_counts()
        return np.repeat(np.arange(len(self.instances), dtype=np.int32), counts)

    def world_triangles(self) -> np.ndarray:
        """float32 (N, 3, 3) world-space triangles, in ``instances`` order.

        Vectorized per geometry: all instances of one mesh are transformed in
        one matmul and gathered with np.take, so the Python loop runs over
        distinct meshes (and over the instances of a mesh only when there are
        few of them), never over triangles.
        """
        counts = self._instance_triangle_counts()
        starts = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)
        out = np.empty((int(counts.sum()), 3, 3), dtype=np.float32)
        for key, idx in self._instances_by_geometry().items():
            geom = self.geometries[key]
            mats = np.stack([self.instances[i].matrix_world for i in idx])
            world = _transform_points(mats, geom.vertices)  # (K, V, 3)
            _scatter_triangles(out, starts[idx], world, geom.triangles)
        return out

    def _instances_by_geometry(self) -> dict[int, np.ndarray]:
        groups: dict[int, list[int]] = {}
        for i, inst in enumerate(self.instances):
            groups.setdefault(inst.geometry_key, []).append(i)
        return {k: np.array(v, dtype=np.int64) for k, v in groups.items()}


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
    """Gather (K,V,3) vertices by (T,3) indices into out[start_k : start_k+T].

    np.take(..., out=...) is ~3x faster than world[k][triangles]; few
    instances are written slice by slice, many small ones in one gather and
    one (slice or fancy-index) assignment.
    """
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
    CRC-32 alone missed a random change once in 2^32, and is linear, so particular changes keep it (four
    bytes chosen after any edit restore it: tests/test_extract.py makes one); Adler-32, a different
    function of the same bytes, changes with them. Measured over 1M float32 vertices (12 MB), this
    host: crc32 3.6 ms, adler32 4.1 ms; blake2b 16 ms, md5 19 ms, sha1 7.5 ms (with the CPU's SHA
    instructions; 2-3x that without).
    """
    count = np.int64(geom.vertices.shape[0]).tobytes()
    crc = zlib.crc32(geom.triangles, zlib.crc32(geom.vertices, zlib.crc32(count)))
    adler = zlib.adler32(geom.triangles, zlib.adler32(geom.vertices, zlib.adler32(count)))
    return crc | adler << 32


# --------------------------------------------------------------------------
# Reading one mesh
# --------------------------------------------------------------------------


def read_mesh(mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Object-space (vertices float32 (V,3), triangles int32 (T,3)) of a Mesh.

    Uses only bulk foreach_get paths that are plain memcpys. Measured with
    bpy 5.0.1 on a 1M-triangle grid (500k vertices):
      positions: attributes["position"] "vector" into float32   0.2-0.5 ms
                 (vertices.foreach_get("co") 20 ms; float64 buffer 38 ms)
      corners:   loop_triangles "loops" into *uint32*            0.7 ms
                 (the same into int32: 86-140 ms, the property is unsigned
                  so any other dtype drops to a per-item path)
                 loop_triangles "vertices" (uint32 32 ms, int32 190 ms)
      .corner_vert "value" into int32                            0.3 ms
      gather corner_vert[loops]                                  4-5 ms
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
    else:  # ~100 ms per 1M corners, but stays correct
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


# --------------------------------------------------------------------------
# Render visibility
# --------------------------------------------------------------------------


class _Visibility:
    """Render-visibility decisions, memoized per original object pointer."""

    def __init__(self, depsgraph: bpy.types.Depsgraph):
        self.view_layer = depsgraph.view_layer
        self.scene_objects = _layer_render_objects(self.view_layer.layer_collection)
        for background in _set_scenes(depsgraph.scene):
            self.scene_objects |= _layer_render_objects(render_view_layer(background).layer_collection)
        self._collection_memo: dict[int, tuple[frozenset, frozenset]] = {}
        self._expansion_memo: dict[tuple, tuple[frozenset, frozenset]] = {}
        self._render_enabled: set[int] | None = None  # in_render's collections, found when first asked
        self._cuts = 0  # cycles cut short so far (_remember)
        self._kinds: dict[int, tuple] = {}  # object pointer -> dupli_paths.instancer_kind
        self._children: dict[int, list] | None = None  # parent pointer -> its children (descendants)
        self._holders: dict[int, list[int]] = {}  # object pointer -> its collections' pointers (in_render)

    def scene_object(self, orig: bpy.types.Object) -> bool:
        """A non-instanced object: own flag plus collection path."""
        return (not orig.hide_render) and orig.as_pointer() in self.scene_objects

    def in_render(self, ob: bpy.types.Object) -> bool:
        """Whether a render's depsgraph holds `ob` for a vertex or face parent to instance: not
        render-hidden, and in a collection none of whose ancestors on some path is render-disabled
        (outside reviews: a child in a render-disabled collection, or below one, was copied onto its
        parent's vertices, 159 pixels where Cycles drew none)."""
        if self._render_enabled is None:
            self._render_enabled = _render_enabled_collections()
            self._holders = _holding_collections()
        if ob.hide_render:
            return False
        return any(c in self._render_enabled for c in self._holders.get(ob.as_pointer(), ()))

    def descendants(self, ob: bpy.types.Object) -> list:
        """ob.children_recursive from one parent map built per extraction: the property scans every
        object of the file on each read (outside review: 1.9 s of 7.7 for 500 vertex parents)."""
        if self._children is None:
            self._children = {}
            for other in bpy.data.objects:
                if other.parent is not None:
                    self._children.setdefault(other.parent.as_pointer(), []).append(other)
        out, todo = [], [ob]
        while todo:
            kids = self._children.get(todo.pop().as_pointer(), [])
            out += kids
            todo += kids
        return out

    def in_instanced_collection(self, instancer: bpy.types.Object, orig) -> bool:
        """Whether `instancer` (a collection instancer, a vertex or face instancing parent, geometry
        nodes or particles, node_instances.py) would make `orig` in a render, through whatever it
        instances, nested: every object it can reach counts unless its render skips it (render-hidden,
        or in a render-hidden collection or instancer on the way). An object it cannot be seen to reach
        (a collection computed by nodes) is kept."""
        reach, shown = self._expansion(instancer, frozenset())
        ptr = orig.as_pointer()
        return ptr not in reach or ptr in shown

    def instanced_objects(self, collection: bpy.types.Collection) -> frozenset[int]:
        """Pointers of the objects a render of an instance of `collection` shows, nested instancers'
        included."""
        return self._collection_expansion(collection, frozenset())[1]

    def _expansion(self, ob: bpy.types.Object, stack: frozenset) -> tuple[frozenset, frozenset]:
        """(reach, shown): pointers of every object `ob` can instance, nested instancing included
        (a geometry-nodes carrier inside an instanced collection, Object Info of a collection
        instancer, a parent instancing a carrier on its vertices), and of those a render makes.
        Memoized per object (per collection for plain collection instancers, of which a scene may
        hold thousands)."""
        pointer = ob.as_pointer()  # the memo first: one RNA read an entry (outside review's timing)
        key = self._kinds.get(pointer)
        if key is None:
            key = self._kinds[pointer] = instancer_kind(ob)
        if key in self._expansion_memo:
            return self._expansion_memo[key]
        collection = instanced_collection(ob)
        if key in stack:
            self._cuts += 1
            return frozenset(), frozenset()
        stack, cuts = stack | {key}, self._cuts
        reach, shown = set(), set()
        if collection is not None:
            self._add(self._collection_expansion(collection, stack), reach, shown)
        if ob.instance_type in _INSTANCING_PARENT_TYPES:
            for child in self.descendants(ob):  # those a render's depsgraph holds (make_child_duplis)
                self._add_object(child, self.in_render(child), stack, reach, shown)
        nodes = has_node_modifier(ob)
        if len(ob.particle_systems) or nodes:
            collections, objects = instancing_references(ob)
            for coll in collections:
                self._add(self._collection_expansion(coll, stack), reach, shown)
            geometry = {o.as_pointer() for o in objects_read_as_geometry(ob)} if nodes else set()
            for other in objects:  # named directly: a mesh shown whatever its flags, a render-hidden curve or
                # text not (outside review against Cycles), a child of a vertex or face instancer only as its
                # instances; its own instances unless it is render-hidden and instanced as an object (read
                # as geometry they come along)
                shows = not _instanced_by_its_parent(other) and (other.type == "MESH" or not other.hide_render)
                self._add_object(other, shows, stack, reach, shown,
                                 instances_shown=not other.hide_render or other.as_pointer() in geometry)
        return self._remember(self._expansion_memo, key, (frozenset(reach), frozenset(shown)), cuts)

    def _collection_expansion(self, coll: bpy.types.Collection, stack: frozenset) -> tuple[frozenset, frozenset]:
        """(reach, shown) of an instance of `coll`: its objects and its child collections', and what
        they instance; shown: those a render walks (objects and collections not render-hidden)."""
        ptr = coll.as_pointer()
        if ptr in self._collection_memo:
            return self._collection_memo[ptr]
        if ("collection members", ptr) in stack:
            self._cuts += 1
            return frozenset(), frozenset()
        stack, cuts = stack | {("collection members", ptr)}, self._cuts
        reach, shown = set(), set()
        walked = unhidden_objects(coll, "hide_render")
        for ob in coll.all_objects:  # a child of a vertex or face instancer shows only as its instances
            self._add_object(ob, ob.as_pointer() in walked and not _instanced_by_its_parent(ob), stack, reach, shown)
        return self._remember(self._collection_memo, ptr, (frozenset(reach), frozenset(shown)), cuts)

    def _remember(self, memo: dict, key, value, cuts: int):
        """Keep `value` unless a cycle was cut short while computing it (then it holds only part of
        what this key reaches from elsewhere: its answer would depend on the order of questions)."""
        if self._cuts == cuts:
            memo[key] = value
        return value

    def _add_object(self, ob, visible: bool, stack: frozenset, reach: set, shown: set,
                    instances_shown: bool | None = None) -> None:
        """Add `ob` and what it instances to reach, and to shown where a render makes them."""
        reach.add(ob.as_pointer())
        if visible:
            shown.add(ob.as_pointer())
        if instances_things(ob):
            self._add(self._expansion(ob, stack), reach, shown if (visible if instances_shown is None
                                                                  else instances_shown) else None)

    @staticmethod
    def _add(expansion: tuple[frozenset, frozenset], reach: set, shown: set | None) -> None:
        reach |= expansion[0]
        if shown is not None:
            shown |= expansion[1]


def _render_enabled_collections() -> set[int]:
    """Pointers of the collections a render can walk into: not render-disabled, and reached from a
    scene's master collection or from a collection no other one holds (one only instanced) through
    collections that are not either."""
    held = {child.as_pointer() for c in bpy.data.collections for child in c.children}
    todo = [scene.collection for scene in bpy.data.scenes]
    todo += [c for c in bpy.data.collections if c.as_pointer() not in held and not c.hide_render]
    out: set[int] = set()
    while todo:
        c = todo.pop()
        if c.as_pointer() not in out:
            out.add(c.as_pointer())
            todo.extend(child for child in c.children if not child.hide_render)
    return out


def _holding_collections() -> dict[int, list[int]]:
    """{object pointer: pointers of the collections holding it, scenes' master collections too}, from
    one pass (Object.users_collection scans every collection on each read)."""
    out: dict[int, list[int]] = {}
    for coll in list(bpy.data.collections) + [scene.collection for scene in bpy.data.scenes]:
        for ob in coll.objects:
            out.setdefault(ob.as_pointer(), []).append(coll.as_pointer())
    return out


def _set_scenes(scene: bpy.types.Scene) -> list[bpy.types.Scene]:
    """The chain of background scenes (Scene > Background Scene, its own, ...): a render shows their
    objects too, as the depsgraph holds them (outside QA: left out, so Cycles showed more)."""
    chain, seen = [], {scene.as_pointer()}
    background = scene.background_set
    while background is not None and background.as_pointer() not in seen:  # Blender refuses cycles; be sure
        chain.append(background)
        seen.add(background.as_pointer())
        background = background.background_set
    return chain


def render_view_layer(scene: bpy.types.Scene) -> bpy.types.ViewLayer:
    """The view layer a render takes from a scene that is not the window's (a background scene, the
    command line's --scene): Blender's BKE_view_layer_default_render, the first one enabled for
    rendering, else the first."""
    return next((layer for layer in scene.view_layers if layer.use), scene.view_layers[0])


def _layer_render_objects(layer_coll: bpy.types.LayerCollection) -> set[int]:
    """Original-object pointers reachable through render-enabled collections."""
    out: set[int] = set()
    todo = [layer_coll]
    while todo:
        lc = todo.pop()
        if lc.exclude or lc.collection.hide_render:
            continue
        out.update(ob.as_pointer() for ob in lc.collection.objects)
        todo.extend(lc.children)
    return out


def _ray_visible(*objs) -> bool:
    """False only when camera and shadow rays are both off (ANDed over objs)."""
    return any(ray_flags(*objs))


def ray_flags(*objs) -> tuple[bool, bool]:
    """(camera, shadow): Ray Visibility > Camera and > Shadow, ANDed over objs (an instance and its
    instancer)."""
    return all(ob.visible_camera for ob in objs), all(ob.visible_shadow for ob in objs)


def _instancer_hides_self(orig: bpy.types.Object, evaluated: bpy.types.Object) -> bool:
    """Particle / vertex / face / collection instancers may hide themselves."""
    if orig.show_instancer_for_render:
        return False
    return evaluated.is_instancer or len(orig.particle_systems) > 0


def _entry_visible(vis: _Visibility, parent, ob: bpy.types.Object) -> bool:
    """Render-visibility of one object_instances entry (parent None: not an instance), apart from
    its ray-visibility flags (ray_flags)."""
    orig = ob.original
    if not collection_visible(vis, parent, orig):
        return False
    if parent is not None:  # the instances of an instancer hidden so go with it (Blender skips its duplis)
        if _instanced_by_its_parent(parent.original):
            return False
        # An instancer inside an instance (an emitter or a vertex parent in an instanced collection)
        # hides itself as at the top level (outside review against Cycles: 46 pixels against 1,024).
        return orig == parent.original or not _instancer_hides_self(orig, ob)
    return not (_instancer_hides_self(orig, ob) or _instanced_by_its_parent(orig))


# Blender hides an object whose parent instances it on its vertices or faces at its own place in a
# final render (depsgraph deg_object_hide_original: render mode, or any instance), not in the
# viewport's depsgraph the preview reads; the instances it makes are kept. Not for metaballs.
_INSTANCING_PARENT_TYPES = frozenset(("VERTS", "FACES"))


def _instanced_by_its_parent(orig: bpy.types.Object) -> bool:
    parent = orig.parent
    return parent is not None and parent.instance_type in _INSTANCING_PARENT_TYPES and orig.type != "META"


def collection_visible(vis: _Visibility, parent, orig: bpy.types.Object) -> bool:
    """The collection and hide_render rules of an object_instances entry (parent None: not an
    instance), without the ray-visibility flags."""
    if parent is None:
        return vis.scene_object(orig)
    return vis.scene_object(parent.original) and instanced_visible(vis, parent.original, orig)


def instanced_visible(vis: _Visibility, parent: bpy.types.Object, orig: bpy.types.Object) -> bool:
    """Whether the original instancer `parent` makes `orig` in a render, whatever `parent`'s own
    visibility (collection_visible adds that)."""
    if parent == orig:
        return True
    if parent.instance_type in _INSTANCING_PARENT_TYPES and _descends_from(orig, parent):
        # Blender instances on vertices or faces the children that the depsgraph holds (object_dupli.cc,
        # make_child_duplis): a render's depsgraph leaves out a child disabled in renders, the viewport's
        # does not (Cycles showed no copies of such a child; the preview showed them all).
        return vis.scene_object(orig)
    return vis.in_instanced_collection(parent, orig)


def _descends_from(orig: bpy.types.Object, ancestor: bpy.types.Object) -> bool:
    """Whether `ancestor` is on `orig`'s parent chain (Blender's is_child for instancing children)."""
    parent = orig.parent
    while parent is not None:
        if parent == ancestor:
            return True
        parent = parent.parent
    return False


# --------------------------------------------------------------------------
# Extraction
# --------------------------------------------------------------------------


class _GeometryReader:
    """Reads each evaluated mesh once; a rejected mesh warns once, naming every object that uses it."""

    def __init__(self):
        self.geometries: dict[int, MeshGeometry] = {}
        self.rejected: set[int] = set()
        self.non_finite: dict[int, tuple[str, set[str]]] = {}  # key -> (mesh name, its objects)

    def get(self, ob: bpy.types.Object, object_name: str) -> int | None:
        """Geometry key for the evaluated object `ob`'s mesh, or None when it has no usable triangles."""
        mesh = ob.data
        key = mesh.as_pointer()
        if key in self.geometries:
            return key
        if key in self.rejected:
            if key in self.non_finite:
                self.non_finite[key][1].add(object_name)
            return None
        verts, tris = read_object_mesh(ob, mesh)
        if len(tris) and not np.isfinite(verts).all():  # 0.5 ms per 1M verts
            self.non_finite[key] = (mesh.name, {object_name})
            tris = tris[:0]
        if len(tris) == 0:
            self.rejected.add(key)
            return None
        self.geometries[key] = MeshGeometry(key, mesh.name, verts, tris)
        return key

    @property
    def warnings(self) -> list[str]:
        out = []
        for mesh_name, users in self.non_finite.values():
            names = ", ".join(f"'{n}'" for n in sorted(users))
            if len(users) == 1:
                out.append(f"object {names} has non-finite vertex coordinates; left out")
            else:
                out.append(f"objects {names} (sharing mesh '{mesh_name}') have non-finite vertex coordinates; "
                           "left out")
        return out


def extract_scene(depsgraph: bpy.types.Depsgraph | None = None) -> ExtractedScene:
    """Extract every render-visible triangle mesh of an evaluated depsgraph.

    With no argument, uses ``bpy.context.evaluated_depsgraph_get()``. Call
    ``scene.frame_set(f)`` first to extract another frame.
    """
    t0 = time.perf_counter()
    if depsgraph is None:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    vis = _Visibility(depsgraph)
    walker = _EntryReader(vis)
    instances = [r for r in map(walker.read, depsgraph.object_instances) if r is not None]
    instances = walker.without_hidden_carriers(instances)
    surfaces_off = _surfaces_off_warnings(depsgraph.view_layer)
    evaluated = {ob.original.as_pointer() for ob in depsgraph.objects}
    flag_hidden = _hidden_by_viewport_flag_only(depsgraph, evaluated, walker.instanced_by)
    shown = [ob for ob in flag_hidden if ob.type == "MESH" and ob.show_instancer_for_render and vis.scene_object(ob)]
    instances += [r for r in map(walker.read, (_SelfEntry(ob.evaluated_get(depsgraph)) for ob in shown))
                  if r is not None]
    viewport_shown = evaluated | {ob.as_pointer() for ob in flag_hidden}
    shown_objects = _objects_shown(depsgraph, vis, instances)
    if surfaces_off:
        instances = []
    return ExtractedScene(
        geometries=walker.geometries.geometries,
        instances=instances,
        warnings=(surfaces_off + _unused_layer_warnings(depsgraph) + walker.geometries.warnings
                  + list(walker.non_finite_placements.values()) + list(walker.not_triangles.values())
                  + left_out_warnings(depsgraph, vis, walker.instanced_by, viewport_shown, walker.paths.blocked,
                                    walker.meshed)
                  + viewport_evaluation_warning(shown_objects, depsgraph.scene)
                  + culling_warning(shown_objects, depsgraph.scene)),
        extract_ms=(time.perf_counter() - t0) * 1e3,
        frame=depsgraph.scene.frame_current,
    )


def _surfaces_off_warnings(view_layer) -> list[str]:
    """A view layer whose Filter > Surfaces is off renders no surfaces at all (Cycles: no hit pixel;
    the preview drew them all, outside review)."""
    if view_layer.use_solid:
        return []
    return [f"view layer '{view_layer.name}' has Filter > Surfaces off: a final render shows no surfaces, so the "
            "preview renders none"]


def _objects_shown(depsgraph, vis: _Visibility, instances: list[Instance]) -> list[bpy.types.Object]:
    """The original objects a final render shows in the scene (hidden in the viewport or not), those
    the preview instanced, and those geometry nodes read (an Object Info source's evaluation shapes
    the realized copy too), each once."""
    out = {ob.as_pointer(): ob for ob in _rendered_layers_objects(depsgraph) if vis.scene_object(ob)}
    for name in {r.name for r in instances if r.is_instance}:
        ob = bpy.data.objects.get(name)
        if ob is not None:
            out.setdefault(ob.as_pointer(), ob)
    for ob in [ob for ob in out.values() if has_node_modifier(ob)]:
        collections, objects = node_references(ob)  # sources the nodes read, realized ones too
        for source in objects + [member for c in collections for member in c.all_objects]:
            out.setdefault(source.as_pointer(), source)
    return list(out.values())


@dataclass(frozen=True)
class _SelfEntry:
    """An object's own entry, made up where the viewport depsgraph yields none (the attributes
    _EntryReader.read takes from a DepsgraphObjectInstance)."""

    object: bpy.types.Object  # the evaluated object
    is_instance: bool = False
    parent: None = None

    @property
    def matrix_world(self):
        return self.object.matrix_world


def _hidden_by_viewport_flag_only(depsgraph, evaluated: set[int], instanced_by: dict[int, set[int]]) -> list:
    """Objects of the rendered layers the viewport depsgraph yields no entry of (`evaluated`: the
    originals it does) only because their Show Instancer for the viewport is off: the flag is off and
    the viewport shows the object (it instanced something this frame, which a hidden object does not,
    or it is visible in the view layer). A final render shows those with Show Instancer for renders on."""
    return [ob for ob in _rendered_layers_objects(depsgraph)
            if not ob.show_instancer_for_viewport and ob.as_pointer() not in evaluated
            and (ob.as_pointer() in instanced_by or ob.visible_get(view_layer=depsgraph.view_layer))]


def _unused_layer_warnings(depsgraph) -> list[str]:
    """The preview renders the window's view layer (or the command line's --scene's render layer);
    a final render writes only the layers enabled for rendering (outside review: a disabled window
    layer rendered without a word)."""
    layer = depsgraph.view_layer
    if layer.use:
        return []
    return [f"view layer '{layer.name}' is not enabled for rendering (Use for Rendering off): the preview "
            "renders it, a final render writes only the enabled layers"]


# Object types whose evaluated geometry is a mesh the preview reads, and those Cycles renders that
# are not triangles.
TRIANGLE_TYPES = frozenset(("MESH", "CURVE", "SURFACE", "FONT", "META"))
NOT_TRIANGLES = {"CURVES": "hair curves", "POINTCLOUD": "a point cloud", "VOLUME": "a volume",
                 "GREASEPENCIL": "grease pencil", "GPENCIL": "grease pencil"}
NOT_TRIANGLE_DATA = {"Curves": "hair curves", "PointCloud": "a point cloud", "Volume": "a volume",
                     "GreasePencil": "grease pencil", "GreasePencilv3": "grease pencil"}  # by data type


def left_out_warnings(depsgraph: bpy.types.Depsgraph, vis: _Visibility, instanced_by: dict[int, set[int]],
                      evaluated: set[int], not_made: set[int] = frozenset(),
                      meshed: set[str] = frozenset()) -> list[str]:
    """A warning per render-visible thing a final render shows and the preview leaves out: objects of
    the scene and its background scenes hidden in the viewport (the viewport depsgraph does not
    evaluate them) or not triangles, collection instancers hidden there (their instances go with
    them), members of collections that instancers, geometry nodes or particles render whole, disabled
    in viewports (`instanced_by`: the original objects the depsgraph instanced, by original
    instancer), and hair particles drawn as strands. `evaluated`: pointers of the originals the
    viewport shows, those its Show Instancer flag alone keeps out of the depsgraph's entries included
    (they are read anyway when a render shows them, _hidden_by_viewport_flag_only). `not_made`: originals
    the viewport instanced on a path a render does not make (dupli_paths.py), not missing either.
    `meshed`: names of the originals whose own evaluated geometry gave triangles (a point cloud or curves object
    whose geometry nodes output a mesh is named only for what is left of its points or curves)."""
    warnings = []
    instancers = {}
    for ob in _rendered_layers_objects(depsgraph):
        kind = ob.type
        if kind in TRIANGLE_TYPES and ob.as_pointer() in evaluated:
            if len(ob.particle_systems):
                warnings += _strand_warnings(ob, vis) + _pick_warnings(ob, vis)
            for collection in _collections_rendered_whole(ob, vis):
                instancers.setdefault(collection.as_pointer(), (collection, []))[1].append(ob)
            continue  # the common case first: ~1.5 us an object
        if ob.instance_type == "COLLECTION" and ob.instance_collection is not None and vis.scene_object(ob):
            if ob.as_pointer() in evaluated:
                instancers.setdefault(ob.instance_collection.as_pointer(), (ob.instance_collection, []))[1].append(ob)
            elif _ray_visible(ob):
                warnings.append(f"object '{ob.name}' is hidden in the viewport (eye icon, Disable in Viewports or a "
                                f"hidden collection): the preview leaves out the instances of collection "
                                f"'{ob.instance_collection.name}' it makes, a final render shows them")
        if ((kind in TRIANGLE_TYPES or kind in NOT_TRIANGLES) and vis.scene_object(ob) and _ray_visible(ob)
                and not _renders_nothing(ob)):
            if kind in NOT_TRIANGLES:
                if not _own_elements(ob.evaluated_get(depsgraph)):
                    pass  # its nodes made it all triangles or instances (outside reviews), or it is empty
                elif ob.name not in meshed:
                    warnings.append(f"object '{ob.name}' is {NOT_TRIANGLES[kind]}, not triangles: left out of "
                                    "the preview")
                else:
                    warnings.append(f"object '{ob.name}' is {NOT_TRIANGLES[kind]}: the preview shows the triangles its "
                                    f"geometry nodes make and leaves the rest out")
            else:
                what = ("it and the instances it makes" if ob.instance_type in _INSTANCING_PARENT_TYPES
                        or len(ob.particle_systems) else "it")
                warnings.append(f"object '{ob.name}' is hidden in the viewport (eye icon, Disable in Viewports or "
                                f"a hidden collection): the preview reads the viewport's scene and leaves {what} out, "
                                "a final render shows it")
    instanced = set().union(*instanced_by.values()) | not_made
    for collection, hosts in instancers.values():
        members = list(_members(collection, (), {collection.as_pointer()}))
        pointers = {ob.as_pointer() for ob, _, _ in members}
        hosts = [h for h in hosts if _shows_instances_of(h, pointers, instanced_by)]
        if hosts:
            warnings += _hidden_member_warnings(collection, members, hosts, vis, instanced)
            shown = vis.instanced_objects(collection)  # emitters inside: named as at the top (outside review)
            warnings += [w for ob, _, _ in members if len(ob.particle_systems) and ob.as_pointer() in shown
                         for w in _pick_warnings(ob, vis, instanced=True) if w not in warnings]
    return warnings


def _own_elements(evaluated) -> bool:
    """Whether an evaluated point cloud or curves object still holds points or curves of its own (its
    geometry nodes may turn them all into a mesh); True where that cannot be counted (volumes, grease
    pencil)."""
    data = evaluated.data
    for name in ("curves", "points"):
        elements = getattr(data, name, None)
        if elements is not None:
            return len(elements) > 0
    return True


def _hidden_member_warnings(collection, members: list, hosts: list, vis: _Visibility,
                            instanced: set[int]) -> list[str]:
    """Members (`_members` of the collection: nested collection instances' too) a render of the
    collection's instances shows that the viewport's depsgraph did not instance (the object or a
    collection on its path disabled in viewports), one warning each, naming the first of `hosts` (the
    objects instancing the collection) whose instances of it rays can see."""
    shown = vis.instanced_objects(collection)  # nested instances' render-visible members included
    out, named = [], set()
    for ob, owner, chain in members:
        # a collection instancer disabled in viewports takes its copies with it: named itself, once
        # (outside review: with a visible sibling instancing the same collection nothing was named)
        nesting = instanced_collection(ob) is not None and _nests(ob) and ob.hide_viewport
        if ((ob.type not in TRIANGLE_TYPES and not nesting) or ob.type == "META" or ob.as_pointer() not in shown
                or ob.as_pointer() in instanced or vis.scene_object(ob) or _renders_nothing(ob)
                or any(inner.as_pointer() in named for inner in chain)):
            continue  # scene objects are named as such; no render instances a metaball (object_dupli.cc: no_draw)
        host = next((h for h in hosts if _ray_visible(ob, *chain, h) and (not chain or _nests(h))), None)
        if host is not None:
            where = f"object '{ob.name}' in collection '{owner.name}' (instanced by '{host.name}'{_through(chain)})"
            if _instanced_by_its_parent(ob):
                continue  # shows only as its parent's instances, which the parent's own line covers
            if not ob.hide_viewport and not ob.show_instancer_for_viewport and instances_things(ob):
                if not ob.show_instancer_for_render:
                    continue  # hidden in renders too (outside review: named as shown by a render)
                out.append(f"{where} has Show Instancer > Viewport off: the preview leaves its own mesh out there, "
                           "a final render shows it")  # its instances are made (outside review)
                continue
            why = ("is disabled in viewports" if ob.hide_viewport else
                   "is not instanced in the viewport (a collection or instancer on its path is disabled in viewports)")
            out.append(f"{where} {why}: the preview leaves its instances out, a final render shows them")
            named.add(ob.as_pointer())
    return out


def _through(chain) -> str:
    """" through 'A' through 'B'": the instancers a collection member is nested through."""
    return "".join(f" through '{inner.name}'" for inner in chain)


def _nests(host) -> bool:
    """Whether `host`'s instances of a collection expand the collection instances among its members: a
    collection instancer's and geometry nodes' do, particles' do not (object_dupli.cc makes particles'
    instances without recursing; Cycles showed none, outside review)."""
    return host.instance_type == "COLLECTION" or has_node_modifier(host)


def _shows_instances_of(host, members: set[int], instanced_by: dict[int, set[int]]) -> bool:
    """Whether the viewport's depsgraph shows `host`'s instances of a collection (`members`: pointers
    of its objects, nested ones too) as instances, so that a member missing from them is missing from
    the preview. A collection instancer's always are. A geometry-nodes host or an emitter counts only
    once it instanced one of the members: its nodes may realize the instances (Realize Instances) or
    not use the Collection Info node at all, and its modifier may be shown in renders only; then no
    member is an instance for a reason other than its own. (A collection all of whose members are
    disabled in viewports is then not named: better a missing warning than a wrong one.)"""
    return host.instance_type == "COLLECTION" or not instanced_by.get(host.as_pointer(), set()).isdisjoint(members)


def _renders_nothing(ob) -> bool:
    """A mesh without faces, modifiers (particles included) or instancing: nothing for any render to
    show, so hiding it in the viewport loses nothing (rig widgets, guides, hook targets)."""
    return (ob.type == "MESH" and len(ob.data.polygons) == 0 and len(ob.modifiers) == 0
            and ob.instance_type == "NONE")


def _members(collection, chain: tuple, stack: set):
    """(object, the collection it is a member of, the instancers inside `collection` it is nested
    through) for every object of `collection` and of the collections its render-visible members
    instance, outer members first; a collection already on the path is not entered again."""
    nested = []
    for ob in collection.all_objects:
        yield ob, collection, chain
        inner = ob.instance_collection if ob.instance_type == "COLLECTION" else None
        if inner is not None and not ob.hide_render and inner.as_pointer() not in stack:
            nested.append((ob, inner))
    for ob, inner in nested:
        yield from _members(inner, chain + (ob,), stack | {inner.as_pointer()})


def _strand_warnings(ob, vis: _Visibility) -> list[str]:
    """Hair particle systems drawn as strands (Render As: Path), which Cycles renders as curves."""
    if not (vis.scene_object(ob) and _ray_visible(ob)):
        return []
    shown = _render_shown_systems(ob)
    return [f"object '{ob.name}': hair particles '{system.name}' are strands, not triangles: left out of the preview"
            for system in ob.particle_systems
            if system.as_pointer() in shown and system.settings.type == "HAIR"
            and system.settings.render_type == "PATH"]


def _pick_warnings(ob, vis: _Visibility, instanced: bool = False) -> list[str]:
    """Particle systems that render one member of a collection per particle (Whole Collection off):
    a final render picks among the render-visible members, the viewport among the viewport-enabled
    ones, so where the two sets differ the preview's particle-to-object assignment is not a final
    render's (the render-hidden members' particles are left out, see _Visibility). `instanced`: ob is
    a member a collection instance renders (left_out_warnings decided), not a scene object."""
    if not ((instanced or vis.scene_object(ob)) and _ray_visible(ob)):
        return []
    shown = _render_shown_systems(ob)
    out = []
    for system in ob.particle_systems:
        settings = system.settings
        coll = settings.instance_collection
        if (system.as_pointer() in shown and settings.render_type == "COLLECTION" and coll is not None
                and not settings.use_whole_collection
                and unhidden_objects(coll, "hide_render") != unhidden_objects(coll, "hide_viewport")):
            out.append(f"object '{ob.name}': particle system '{system.name}' gives each particle one object of "
                       f"collection '{coll.name}', which a final render picks among the render-visible members "
                       "only: the preview's particle-to-object assignment differs from a final render's (it leaves "
                       "the render-hidden members' particles out)")
    return out


def _collections_rendered_whole(ob, vis: _Visibility) -> list:
    """The collections ob renders whole through geometry nodes (Collection Info, node_instances.py) or
    render-shown particle systems (Render As: Collection, Whole Collection on): their members follow
    the collection-instance rule, so a member disabled in viewports is left out of the preview as a
    collection instance's is (_hidden_member_warnings). Measured with Cycles (bpy 5.0.1): a final
    render shows such a member in all three ways, and a child collection disabled in viewports that
    Separate Children instances."""
    nodes = has_node_modifier(ob)
    if not (nodes or len(ob.particle_systems)) or not (vis.scene_object(ob) and _ray_visible(ob)):
        return []
    collections = node_references(ob)[0] if nodes else []
    shown = _render_shown_systems(ob)
    return collections + [system.settings.instance_collection for system in ob.particle_systems
                          if system.as_pointer() in shown and system.settings.render_type == "COLLECTION"
                          and system.settings.instance_collection is not None
                          and system.settings.use_whole_collection]


def _render_shown_systems(ob) -> set[int]:
    """Pointers of ob's particle systems whose modifier is shown in renders."""
    return {m.particle_system.as_pointer() for m in ob.modifiers if m.type == "PARTICLE_SYSTEM" and m.show_render}


def hidden_light_warnings(depsgraph: bpy.types.Depsgraph, vis: _Visibility,
                          instanced_lights: set[int] = frozenset()) -> list[str]:
    """A warning per render-visible light of the scene or its background scenes hidden in the
    viewport: its depsgraph does not evaluate it, so the preview cannot use it, while a final render
    does; and per light member of a collection a collection instancer renders whole that the viewport
    did not instance (`instanced_lights`: pointers of the originals of the lights it did), disabled in
    viewports or in a collection that is (outside review: Cycles lit 153 pixels, the preview none, in
    silence). `vis`: the render-visibility table, shared with the caller."""
    evaluated = {ob.original.as_pointer() for ob in depsgraph.objects}
    out = [f"light '{ob.name}' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): "
           "the preview leaves it out, a final render uses it"
           for ob in _rendered_layers_objects(depsgraph)
           if ob.type == "LIGHT" and ob.as_pointer() not in evaluated and vis.scene_object(ob)]
    named, walked = set(), set()
    if not any(ob.type == "LIGHT" for ob in bpy.data.objects):
        return out
    for host in _rendered_layers_objects(depsgraph):
        collection = instanced_collection(host)
        if (collection is None or collection.as_pointer() in walked or host.as_pointer() not in evaluated
                or not vis.scene_object(host)):
            continue
        walked.add(collection.as_pointer())
        shown = vis.instanced_objects(collection)
        for ob, owner, chain in _members(collection, (), {collection.as_pointer()}):
            if (ob.type == "LIGHT" and ob.as_pointer() in shown and ob.as_pointer() not in instanced_lights
                    and ob.as_pointer() not in named):
                named.add(ob.as_pointer())
                out.append(f"light '{ob.name}' in collection '{owner.name}' (instanced by '{host.name}'"
                           f"{_through(chain)}) is not instanced in the viewport (disabled in viewports, or a "
                           "collection on its path is): the preview leaves it out, a final render uses it")
    return out


def _rendered_layers_objects(depsgraph: bpy.types.Depsgraph):
    """The objects of the depsgraph's view layer and of its background scenes' render view layers,
    each once: what a final render may show (an object can be in the scene and a background scene)."""
    seen = set()
    layers = [depsgraph.view_layer] + [render_view_layer(s) for s in _set_scenes(depsgraph.scene)]
    for ob in (ob for layer in layers for ob in layer.objects):
        if ob.as_pointer() not in seen:
            seen.add(ob.as_pointer())
            yield ob


class _EntryReader:
    """Turns object_instances entries into Instance records.

    Per-entry cost dominates scenes with many instances (bpy 5.0.1, 100k
    geometry-nodes instances: the bare iteration is ~60 ms, every RNA
    attribute access ~1 us), so the visibility verdict and the names are
    memoized per (instancer, original object) pair and each entry touches
    only the few attributes that can differ between instances.
    """

    def __init__(self, vis: _Visibility):
        self.vis = vis
        self.geometries = _GeometryReader()
        self._verdicts: dict[tuple[int, int], tuple[str, str | None, bool, bool, bool] | None] = {}
        self.instanced_by: dict[int, set[int]] = {}  # instancer (original) -> the originals it instanced
        self.not_triangles: dict[tuple[str, str | None], str] = {}
        self.non_finite_placements: dict[tuple[str, str | None], str] = {}  # one warning each
        self._own_entries_hidden_if_instancing: list[tuple[int, Instance]] = []
        self.meshed: set[str] = set()  # names of the originals whose own geometry gave triangles
        # The path walk's rule depends on what an instancer instances only, not on whether the
        # instancer itself is shown (a hidden one's entries are all left out anyway, by the verdict).
        self.paths = DupliPaths(vis.in_instanced_collection, vis.descendants)

    def read(self, inst) -> Instance | None:
        """Record for one entry, or None to skip it. Copies everything out at
        once: ``inst.object`` is a temporary the iterator reuses. Every entry
        goes through `paths`, in the depsgraph's order (dupli_paths.py)."""
        ob = inst.object
        parent = inst.parent if inst.is_instance else None
        if not self.paths.made_by_render(inst, ob, parent):
            return None
        mesh = ob.data
        if not isinstance(mesh, bpy.types.Mesh):
            if parent is not None:  # an instanced empty or light makes its carrier an instancer too
                self._note_instanced(parent, ob)
            self._note_not_triangles(ob, parent)
            return None
        verdict = self._verdict(ob, parent)
        if verdict is None:
            return None
        name, instancer, camera, shadow, holdout = verdict
        matrix = np.array(inst.matrix_world, dtype=np.float64)
        if not np.isfinite(matrix).all():  # a NaN location or scale (a driver, a script): not placeable
            self.non_finite_placements.setdefault(
                (name, instancer), f"{object_label(name, instancer)} has a non-finite transform (NaN or infinite "
                "location, rotation or scale); left out")
            return None
        key = self.geometries.get(ob, name)
        if key is None:
            return None
        record = Instance(
            geometry_key=key,
            matrix_world=matrix,
            name=name,
            instancer=instancer,
            is_instance=parent is not None,
            camera=camera,
            shadow=shadow,
            holdout=holdout,
        )
        if parent is None and not ob.original.show_instancer_for_render:
            self._own_entries_hidden_if_instancing.append((ob.original.as_pointer(), record))
        if instancer in (None, name):  # by name: a pointer costs two RNA reads an entry
            self.meshed.add(name)
        return record

    def without_hidden_carriers(self, records: list[Instance]) -> list[Instance]:
        """`records` without the own entries of objects whose Show Instancer for renders is off and
        that instanced something in this walk: geometry-nodes carriers, which is_instancer does not
        name (_instancer_hides_self), and, whatever the order of the walk, after their instances."""
        hidden = {id(r) for pointer, r in self._own_entries_hidden_if_instancing if pointer in self.instanced_by}
        return [r for r in records if id(r) not in hidden] if hidden else records

    def _note_not_triangles(self, ob, parent) -> None:
        """Warn once per object and instancer about render-visible geometry that is not triangles
        which an object makes (a geometry-nodes point cloud, curves, volume) or an instance brings;
        scene objects of those types are named by left_out_warnings."""
        kind = NOT_TRIANGLE_DATA.get(type(ob.data).__name__)
        if kind is None or (parent is None and ob.original.type in NOT_TRIANGLES):
            return
        verdict = self._verdict(ob, parent)
        if verdict is None:
            return
        name, instancer = verdict[0], verdict[1]
        message = f"{object_label(name, instancer)} makes {kind}, not triangles: left out of the preview"
        self.not_triangles.setdefault((name, instancer), message)

    def _verdict(self, ob, parent) -> tuple[str, str | None, bool, bool, bool] | None:
        """(object name, instancer name, camera, shadow, holdout) when visible, else None; memoized."""
        orig = ob.original
        memo_key = (orig.as_pointer(), parent.as_pointer() if parent else 0)
        if memo_key not in self._verdicts:
            camera, shadow = ray_flags(orig) if parent is None else ray_flags(orig, parent.original)
            owner = orig if parent is None else parent.original  # Cycles reads these from the instancer
            holdout = owner.holdout_get(view_layer=self.vis.view_layer)
            if not holdout and owner.indirect_only_get(view_layer=self.vis.view_layer):
                camera = False  # Indirect Only hides from camera rays; a holdout stays a holdout
            visible = (camera or shadow) and _entry_visible(self.vis, parent, ob)
            instancer = parent.original.name if parent is not None else None
            if parent is not None:  # once per (object, instancer): no extra cost per entry
                self._note_instanced(parent, ob)
            self._verdicts[memo_key] = (orig.name, instancer, camera, shadow, holdout) if visible else None
        return self._verdicts[memo_key]

    def _note_instanced(self, parent, ob) -> None:
        """Record that `parent` instanced `ob` (whatever its type: Blender counts a geometry-nodes
        carrier whose output holds instances of empties or lights as an instancer, which Show Instancer
        > Render off then hides, BKE_object_visibility; checked against Cycles)."""
        self.instanced_by.setdefault(parent.original.as_pointer(), set()).add(ob.original.as_pointer())
