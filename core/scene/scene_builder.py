"""Building two-level scenes frame after frame, keeping every tree whose input did not change.

Each mesh has a key stable across frames (an object's name) and a fingerprint that changes with its
geometry (a CRC of its bytes). An unchanged mesh keeps its object-space tree however its instances
move; a changed one is rebuilt and counts as dynamic from then on (built for the frame's `rays`), as
does a single-use mesh that moved. The soup (scene_policy.py) is kept while its members' keys,
fingerprints and matrices are unchanged, stored relative to an anchor so a moving camera never
rebuilds it; each ray visibility gets its own soup. Every matrix is shifted by minus `origin` (the
camera position) in float64 before anything is rounded, so nothing far from the origin loses precision.
"""
import hashlib
from typing import Hashable, NamedTuple

import numpy as np

from ..jit.compile_clock import clock
from ..build.builder import build_kdtree
from ..inputs import FLOAT32_MAX, as_real_array, first_row_beyond_float32, is_real_dtype
from .instance_signature import instance_signature, mesh_digest
from ..build.options import make_options
from .ray_visibility import ALL_RAYS, as_visibility, stops_rays
from .scene_policy import LAYOUTS, plan_soup, soup_zones, sparse_mesh
from .two_level import build_two_level, check_placement, transformed_boxes


class MeshInput(NamedTuple):
    """One mesh: `key` (stable across frames), object-space `vertices` (V, 3), `triangles` (T, 3)
    vertex indices, and a `fingerprint` that changes whenever vertices or triangles change."""

    key: Hashable
    vertices: np.ndarray
    triangles: np.ndarray
    fingerprint: Hashable


class BuildReport(NamedTuple):
    """What a build did: meshes (objects) whose tree was built or kept, soup membership, timings."""

    meshes_rebuilt: int
    meshes_reused: int
    instanced_meshes: int
    soup_objects: int
    soup_rebuilt: bool
    build_ms: float
    top_ms: float


class CallerIds(NamedTuple):
    """How the built scene's instances and triangles map back to the caller's (build() reorders them:
    instances with their own tree first, in the caller's order, then the soup instances, one per
    visibility and zone, whose trees hold their members' triangles one after the other). own: (J,) caller
    instance of scene instance j < J; members: (K,) caller instance of soup member k, soup after soup;
    offsets: (K + 1,) member k's first triangle, counted over all soups in that order; soup_base: (S,)
    the count at soup s's first triangle."""

    own: np.ndarray
    members: np.ndarray
    offsets: np.ndarray
    soup_base: np.ndarray

    def map(self, inst, prim):
        """(instance, prim) arrays of scene hits -> the caller's instance and its mesh's triangle
        (-1 stays -1, a miss)."""
        inst, prim = np.asarray(inst, np.int64), np.asarray(prim, np.int64)
        out_inst, out_prim = np.full_like(inst, -1), np.full_like(prim, -1)
        hit = inst >= 0
        own = hit & (inst < len(self.own))
        out_inst[own], out_prim[own] = self.own[inst[own]], prim[own]
        soup = hit & ~own
        counted = prim[soup] + self.soup_base[inst[soup] - len(self.own)]
        member = np.searchsorted(self.offsets, counted, side="right") - 1
        out_inst[soup], out_prim[soup] = self.members[member], counted - self.offsets[member]
        return out_inst.astype(np.int32), out_prim.astype(np.int32)


class SceneBuilder:
    """Builds a TwoLevelScene per frame, reusing trees across calls (see the module docstring).
    layout: "auto" (scene_policy.plan_soup), "two_level" (every mesh its own tree) or "flat" (one soup
    tree per visibility, no zones: the single-tree baseline and the lazy build's layout). Other
    keywords are BuildOptions."""

    def __init__(self, layout="auto", **options):
        if layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
        self.layout = layout
        self.options = make_options(options).as_dict()
        self._trees = {}  # key -> (fingerprint, KdTree)
        self._fingerprints = {}  # key -> fingerprint seen last frame
        self._placements = {}  # key of a single-use mesh -> its matrix and visibility last frame
        self._dynamic = set()  # keys that changed or moved in an earlier frame
        self._deforming = set()  # keys whose geometry changed in an earlier frame: rebuilt every frame
        self._soups = {}  # (visibility, zone) -> (signature, KdTree, anchor): _soup_zones
        self._sparse = {}  # key -> (fingerprint, scene_policy.sparse_mesh of its triangles)

    def build(self, meshes, mesh_of, matrices, origin=None, reuse=True, visibility=None, rays=None):
        """(TwoLevelScene, BuildReport) for one frame. meshes: list of MeshInput; mesh_of (I,) index
        into meshes per instance; matrices (I, 4, 4) object-to-world; origin (3,) subtracted from
        every position (float64) before anything is rounded; visibility (I,) ray_visibility bits per
        instance (None: every instance stops every ray); rays: this frame's ray count (e.g.
        render.frame_ray_count), for the trees of deforming meshes (module docstring), or None."""
        start = clock()
        mesh_of, o2w = check_placement(len(meshes), mesh_of, matrices)
        mesh_of = mesh_of.astype(np.int64)
        visibility = as_visibility(visibility, len(mesh_of))
        origin = _checked_origin(origin)
        for i, m in enumerate(meshes):
            if not isinstance(m, MeshInput):
                raise ValueError(f"meshes[{i}] must be a core.MeshInput (build_scene also takes (vertices, "
                                 f"triangles) pairs), got {type(m).__name__}")
        keys = [m.key for m in meshes]
        try:
            unique = len(set(keys)) == len(keys)
        except TypeError:
            raise ValueError(f"mesh keys must be hashable, got {[k for k in keys if not _hashable(k)][0]!r}") from None
        if not unique:
            raise ValueError("mesh keys must be unique within a frame")
        for m in meshes:
            _check_mesh(m)
        if rays is not None:
            make_options({"rays": rays})  # a bad count is named before anything is built
        bounds = _bounds(meshes)
        with np.errstate(invalid="ignore"):  # an empty mesh's inverted box gives NaN: an empty box to soup_zones
            world_boxes = transformed_boxes(bounds[mesh_of], o2w)
        met = stops_rays(visibility)  # an instance no ray meets is left out altogether
        filled = (bounds[mesh_of, :3] <= bounds[mesh_of, 3:]).all(axis=1)
        _check_world_extent(world_boxes, mesh_of, origin, met & filled)
        self._track_changes(meshes, mesh_of, o2w, visibility)
        shown = np.flatnonzero(met)
        soup = np.zeros(len(mesh_of), bool)
        dynamic = np.array([k in self._dynamic for k in keys], bool)
        soup[shown] = plan_soup(self.layout, np.array([len(m.triangles) for m in meshes], np.int64), bounds,
                                mesh_of[shown], o2w[shown], dynamic,
                                self._sparse_meshes(meshes, bounds, mesh_of[shown], dynamic))
        if self.options["lazy"]:
            soup[shown] = self._lazy_plan(soup[shown], mesh_of[shown])
            if len(set(visibility[soup].tolist())) > 1:
                raise ValueError("a lazy build has to be the scene's one tree, so the instances merged into it must "
                                 f"stop the same rays: got visibilities {sorted(set(visibility[soup].tolist()))}")
        own = ~soup & met
        trees, new_mesh_of, rebuilt, reused = self._mesh_trees(meshes, mesh_of, own, reuse, rays)
        shifted = o2w[own]  # a boolean index copies
        shifted[:, :3, 3] -= origin
        scene_visibility = [visibility[own]]
        rounding = np.zeros((len(mesh_of), 4))
        groups, soups, soup_rebuilt = [], {}, False
        for key, group, anchor in self._soup_zones(soup, visibility, world_boxes, origin):
            soups[key] = self._soup_tree(meshes, mesh_of, o2w, group, reuse, key, anchor)
            _, soup_tree, anchor = soups[key]
            built = soups[key] is not self._soups.get(key)
            soup_rebuilt |= built
            members = len(set(mesh_of[group].tolist()))
            rebuilt, reused = (rebuilt + members, reused) if built else (rebuilt, reused + members)
            trees.append(soup_tree)
            new_mesh_of = np.append(new_mesh_of, len(trees) - 1)
            place = np.eye(4)
            place[:3, 3] = anchor - origin
            shifted = np.concatenate([shifted, place[None]])
            scene_visibility.append([key[0]])
            rounding[group] = (1.0, *anchor)
            groups.append(group)
        self._soups = soups
        self._forget_absent(keys)
        t = clock()
        scene = build_two_level(trees, new_mesh_of, shifted, np.concatenate(scene_visibility).astype(np.uint8),
                                **self.options)
        top_ms = (clock() - t) * 1e3
        scene.signature = instance_signature([mesh_digest(m.key, m.fingerprint) for m in meshes], bounds, mesh_of,
                                             o2w, origin, rounding, visibility)
        scene.origin = origin.copy()
        scene.caller_ids = _caller_ids(meshes, mesh_of, np.flatnonzero(own), groups)
        report = BuildReport(rebuilt, reused, len(trees) - len(groups), int(soup.sum()), soup_rebuilt,
                             (clock() - start) * 1e3, top_ms)
        return scene, report

    def _sparse_meshes(self, meshes, bounds, mesh_of, dynamic):
        """(M,) bool scene_policy.sparse_mesh of the meshes an "auto" eager build's soup may take (placed
        once by the instances rays meet, `mesh_of`; not dynamic), kept per key while its fingerprint
        holds; the others False (the other layouts and lazy builds do not ask). bounds: _bounds(meshes)."""
        out = np.zeros(len(meshes), bool)
        if self.layout != "auto" or self.options["lazy"]:
            return out
        uses = np.bincount(mesh_of, minlength=len(meshes))
        for i in np.flatnonzero((uses == 1) & ~dynamic):
            m = meshes[i]
            cached = self._sparse.get(m.key)
            if cached is None or cached[0] != m.fingerprint:
                cached = self._sparse[m.key] = (m.fingerprint, sparse_mesh(m.vertices, m.triangles, bounds[i]))
            out[i] = cached[1]
        return out

    def _lazy_plan(self, soup, mesh_of):
        """A lazy build has to be the scene's one tree: one mesh kept apart or one soup. Where the plan gives
        more, "auto" merges everything, as "flat" does; "two_level" is refused, naming the meshes."""
        apart = sorted(set(mesh_of[~soup].tolist()))
        if len(apart) + bool(soup.any()) <= 1:
            return soup
        if self.layout == "auto":
            return np.ones_like(soup)
        raise ValueError(f"lazy=True needs one tree, but layout 'two_level' keeps meshes {apart} apart: use layout "
                         "'auto' or 'flat' (which merge them into one lazy tree), or build eagerly")

    def _track_changes(self, meshes, mesh_of, o2w, visibility):
        """Mark keys whose geometry changed, or whose single instance moved or changed visibility (which
        moves it to another soup), since last frame."""
        uses = np.bincount(mesh_of, minlength=len(meshes))
        for i, m in enumerate(meshes):
            before = self._fingerprints.get(m.key)
            if before is not None and before != m.fingerprint:
                self._dynamic.add(m.key)
                self._deforming.add(m.key)
            self._fingerprints[m.key] = m.fingerprint
        for inst in np.flatnonzero(uses[mesh_of] == 1):
            key = meshes[mesh_of[inst]].key
            before = self._placements.get(key)
            if before is not None and (not np.array_equal(before[0], o2w[inst]) or before[1] != visibility[inst]):
                self._dynamic.add(key)
            self._placements[key] = (o2w[inst], visibility[inst])

    def _mesh_trees(self, meshes, mesh_of, instanced, reuse, rays):
        """Object-space trees of the meshes instanced this frame, kept or built: (trees, new mesh_of of the
        instanced instances, built count, kept count); a deforming mesh's tree is built for `rays` rays."""
        used = np.unique(mesh_of[instanced])
        index = np.full(len(meshes), -1, np.int64)
        index[used] = np.arange(len(used))
        trees, rebuilt = [], 0
        for i in used:
            m = meshes[i]
            cached = self._trees.get(m.key)
            if not (reuse and cached is not None and cached[0] == m.fingerprint):
                options = self.options
                if rays is not None and options["rays"] is None and m.key in self._deforming:
                    options = {**options, "rays": rays}
                cached = (m.fingerprint, build_kdtree(_gather(m), **options))
                self._trees[m.key] = cached
                rebuilt += 1
            trees.append(cached[1])
        return trees, index[mesh_of[instanced]], rebuilt, len(used) - rebuilt

    def _soup_zones(self, soup, visibility, world_boxes, origin):
        """(key, members, anchor) of each soup tree: one per visibility (the usual one first) and, in "auto"
        and eager builds, per zone (scene_policy.soup_zones; a soup without zones anchored nearest
        `origin`, the camera); key (visibility, None | anchor)."""
        out = []
        for kind in sorted(set(visibility[soup].tolist()), key=lambda k: (k != ALL_RAYS, -k)):
            group = np.flatnonzero(soup & (visibility == kind))
            boxes = world_boxes[group]
            before = self._soups.get((kind, None))
            before = before[2] if before is not None else None
            zones = soup_zones(boxes, before, split=self.layout == "auto" and not self.options["lazy"], camera=origin)
            for z, (rows, anchor) in enumerate(zones):
                if len(rows):
                    out.append(((kind, None if z == 0 else tuple(anchor.tolist())), group[rows], anchor))
        return out

    def _soup_tree(self, meshes, mesh_of, o2w, members, reuse, key, anchor):
        """(signature, tree, anchor) of the soup `key`, its members' world triangles relative to `anchor`; last
        frame's soup itself when the members' keys, fingerprints and matrices are unchanged."""
        signature = [(meshes[mesh_of[i]].key, meshes[mesh_of[i]].fingerprint, o2w[i].tobytes()) for i in members]
        before = self._soups.get(key)
        if reuse and before is not None and before[0] == signature:
            return before
        parts = [(_gather(meshes[mesh_of[i]]).astype(np.float64), o2w[i]) for i in members]
        world = [tris @ m[:3, :3].T + m[:3, 3] for tris, m in parts]
        stacked = np.concatenate(world) if world else np.zeros((0, 3, 3))
        return signature, build_kdtree((stacked - anchor).astype(np.float32), **self.options), anchor

    def _forget_absent(self, keys):
        present = set(keys)
        for table in (self._trees, self._fingerprints, self._placements, self._sparse):
            for key in [k for k in table if k not in present]:
                del table[key]
        self._dynamic &= present
        self._deforming &= present


def _caller_ids(meshes, mesh_of, own, groups):
    """CallerIds of a scene whose own-tree instances are `own` and whose soups hold `groups` in order."""
    members = np.concatenate(groups) if groups else np.zeros(0, np.int64)
    sizes = [len(meshes[mesh_of[i]].triangles) for i in members]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    firsts = np.cumsum([0] + [len(g) for g in groups[:-1]]).astype(np.int64)
    return CallerIds(own, members, offsets, offsets[firsts] if groups else np.zeros(0, np.int64))


def _checked_origin(origin):
    if origin is None:
        return np.zeros(3)
    out = as_real_array("origin", origin)
    if out.shape != (3,) or not np.isfinite(out).all():
        raise ValueError(f"origin must be 3 finite numbers, got {np.asarray(origin).tolist()}")
    return out


def _gather(mesh):
    """(T, 3, 3) float32 object-space triangles of a MeshInput checked by _check_mesh."""
    return np.asarray(mesh.vertices, np.float32)[np.asarray(mesh.triangles)]


def _check_mesh(mesh):
    """A ValueError naming the mesh for wrong shapes, an unhashable fingerprint, vertices that are not
    real numbers, non-integer or out-of-range indices, and the first triangle with a NaN or inf vertex
    (or the first such vertex, if no triangle uses one). All before anything merges the mesh: in a soup
    a NaN spreads to the merged meshes' common centre, and the error would name another triangle."""
    for name, a in (("vertices", mesh.vertices), ("triangles", mesh.triangles)):
        shape = np.shape(a)
        if not (len(shape) == 2 and shape[1] == 3) and not (name == "triangles" and np.size(a) == 0):
            raise ValueError(f"mesh {mesh.key!r}: {name} must have shape (N, 3), got {shape}")
    if not _hashable(mesh.fingerprint):  # compared with last frame's: an array failed a frame late, unnamed
        raise ValueError(f"mesh {mesh.key!r}: fingerprint must be hashable (e.g. an int such as a CRC of the vertex "
                         f"and index bytes), got {type(mesh.fingerprint).__name__}")
    tris, verts = np.asarray(mesh.triangles), np.asarray(mesh.vertices)
    if not is_real_dtype(verts.dtype):  # as build_kdtree's triangles (complex parts would be dropped)
        raise ValueError(f"mesh {mesh.key!r}: vertices must be real numbers (float32 or float64; integers are taken "
                         f"too), got dtype {verts.dtype}")
    if tris.size and tris.dtype.kind not in "iu":
        raise ValueError(f"mesh {mesh.key!r}: triangles must be integer vertex indices, got dtype {tris.dtype}")
    if tris.size and (tris.min() < 0 or tris.max() >= len(verts)):
        raise ValueError(f"mesh {mesh.key!r}: triangle indices must be in [0, {len(verts)})")
    if np.isfinite(verts).all():
        v = first_row_beyond_float32(verts)
        if v >= 0:
            raise ValueError(f"mesh {mesh.key!r}: vertex {v} is beyond float32's range (+-{FLOAT32_MAX:.4g}), in "
                             f"which meshes are stored: {verts[v].tolist()}")
        return
    finite = np.isfinite(verts).all(axis=1)
    uses_bad = ~finite[tris.reshape(-1, 3).astype(np.intp, copy=False)].all(axis=1)
    if uses_bad.any():
        t = int(np.flatnonzero(uses_bad)[0])
        raise ValueError(f"mesh {mesh.key!r}: triangle {t} has a non-finite vertex coordinate (NaN or inf): "
                         f"{verts[tris[t]].tolist()}")
    v = int(np.flatnonzero(~finite)[0])
    raise ValueError(f"mesh {mesh.key!r}: vertex {v} is not finite: {verts[v].tolist()}")


def _hashable(key):
    try:
        hash(key)
    except TypeError:
        return False
    return True


class PlacementRangeError(ValueError):
    """Instances whose matrices place their meshes beyond float32's range of the scene origin.
    `instances`: the indices (into mesh_of) of every such instance, so that a caller can leave them out,
    as the add-on does for non-finite placements, and build the rest."""

    def __init__(self, message, instances):
        super().__init__(message)
        self.instances = instances


def _check_world_extent(world_boxes, mesh_of, origin, checked):
    """A PlacementRangeError naming the first `checked` instance (rays meet it, its mesh is not empty) whose
    matrix carries its mesh beyond float32's range from `origin` (its world triangles would be inf), and
    listing all of them. world_boxes (I, 6): the instances' world boxes."""
    shifted = world_boxes - np.concatenate([origin, origin])
    with np.errstate(invalid="ignore"):
        beyond = np.flatnonzero(checked & ~(np.abs(shifted) <= FLOAT32_MAX).all(axis=1))
    if len(beyond):
        i = int(beyond[0])
        others = f" (and {len(beyond) - 1} more)" if len(beyond) > 1 else ""
        raise PlacementRangeError(f"instance {i} (mesh {int(mesh_of[i])}){others}: its matrix places the mesh beyond "
                                  f"float32's range (|coordinate| > {FLOAT32_MAX:.3g} from the scene origin): move it "
                                  "or the origin closer", beyond)


def _bounds(meshes):
    """(M, 6) float32 object-space boxes of the vertices the meshes' triangles use (inverted when a mesh
    has none). Loose vertices do not count: a stray vertex far from a small mesh would pick the soup's
    anchor and zone, and the mesh stored in float32 far from that anchor would lose its shape."""
    out = np.empty((len(meshes), 6), np.float32)
    for i, m in enumerate(meshes):
        v, tris = np.asarray(m.vertices, np.float32), np.asarray(m.triangles)
        if len(v) == 0 or tris.size == 0:
            out[i] = (np.inf,) * 3 + (-np.inf,) * 3
            continue
        used = np.zeros(len(v), bool)
        used[tris.reshape(-1)] = True
        if not used.all():
            v = v[used]
        out[i] = np.concatenate([v.min(axis=0), v.max(axis=0)])
    return out


def build_scene(meshes, mesh_of, matrices, origin=None, layout="auto", visibility=None, **options):
    """One frame's TwoLevelScene without reuse: meshes are (vertices, triangles) pairs or MeshInputs;
    visibility (I,) ray_visibility bits per instance (None: all rays)."""
    inputs = [_mesh_input(i, m) for i, m in enumerate(meshes)]
    return SceneBuilder(layout, **options).build(inputs, mesh_of, matrices, origin, visibility=visibility)[0]


def _mesh_input(i, mesh):
    """meshes[i] of build_scene as a MeshInput: key i, and a fingerprint of the arrays' contents, so that
    two scenes built from different meshes never share a signature (a render continued from one with
    `previous=` would otherwise keep the other's pixels). Hashing reads every byte once (tens of ms for a
    million triangles); SceneBuilder with MeshInputs takes the caller's own fingerprints instead."""
    if isinstance(mesh, MeshInput):
        return mesh
    if not isinstance(mesh, (tuple, list)) or len(mesh) != 2:
        raise ValueError(f"meshes[{i}] must be a (vertices, triangles) pair or a core.MeshInput, got "
                         + (f"a {type(mesh).__name__} of length {len(mesh)}" if isinstance(mesh, (tuple, list))
                            else type(mesh).__name__))
    vertices, triangles = mesh
    return MeshInput(i, vertices, triangles, _contents_digest(vertices, triangles))


def _contents_digest(*arrays):
    """A digest of the arrays' dtypes, shapes and bytes (None where one is not an array of numbers:
    _check_mesh then names the problem)."""
    digest = hashlib.blake2b(digest_size=16)
    for a in arrays:
        try:
            a = np.ascontiguousarray(a)
        except (TypeError, ValueError):
            return None
        if a.dtype.kind not in "biuf":
            return None
        digest.update(f"{a.dtype.str}{a.shape}".encode())
        digest.update(a.view(np.uint8).reshape(-1) if a.size else b"")
    return digest.hexdigest()
