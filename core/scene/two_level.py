"""The two-level scene (seed 000 §5; Wald 2004): one kd-tree per mesh in object space, instances that
place the meshes with affine matrices, and a top-level kd-tree over the instances' world boxes.

Rays reach each instance's object space by its world-to-object matrix (float64) and the one kd-tree
traversal (instance_traversal.py); an object that only moves keeps its tree. The mesh trees are packed
into contiguous arrays with per-mesh offsets, so kernels take plain arrays, all in one named tuple
(SceneArrays; `mesh_tree` views one mesh's tree).
"""
from typing import NamedTuple

import numpy as np

from ..jit.compile_clock import clock
from ..build.box_tree import build_box_tree
from ..geometry import half_area
from ..trace.kdtree import KdTree, empty_arrays
from ..trace.layout import LEAF
from ..build.options import make_options
from .instance_transforms import affine_boxes, affine_inverses, relative_determinants
from .ray_visibility import as_visibility
from ..jit.threads import thread_count
from ..inputs import as_real_array

# An instance test (a matrix product, then the mesh tree's own traversal) costs the SAH this many triangle
# tests: at the default intersection_cost (0.3, options.py) the top level keeps the 1.5 it was tuned with
# before the triangle test's cost fell.
INSTANCE_TEST_COST = 5.0
# References an instance box may make in the top level (the builder's duplication budget, capped): boxes of
# scattered instances nearly touch, and a larger budget splits them over and over for no faster trace
# (docs/choices.md#a-top-level-budget-of-three-references-an-instance).
TOP_LEVEL_DUPLICATION = 3.0
SINGULAR = 1e-12  # |det| of the linear part below this times its column norms' product: not invertible


class SceneArrays(NamedTuple):
    """What the scene kernels read of a two-level scene (instance_traversal.trace_scene), by name.

    The top-level tree over the instances (layout.py): `top_axis`, `top_split`, `top_child`,
    `top_count`, `top_items` (instance indices in leaf order), `top_bounds` (6,) float32. Per instance:
    `world_to_object` (I, 3, 4) float64, `mesh_of` (I,) int32, `visibility` (I,) uint8 ray_visibility
    bits. The mesh trees packed (pack_meshes): `node_start`, `ref_start`, `tri_start`, `box_start` ((M + 1,)
    int64 offsets of each mesh's nodes, leaf references, triangles and leaf boxes), `axis`, `split`, `child`, `count`,
    `leaf_prims`, `triangles`, `mesh_bounds` (M, 6) float32, `leaf_triangles` (9, R) float32 and the
    boxes of its column groups `leaf_boxes` (leaf_triangles.py).
    Last, `world_boxes` (I, 6) float32: each instance's world box, rounded outward (world_boxes()), which
    the traversal clips before entering an instance (docs/choices.md#instance-boxes-tested-before-entering).
    """

    top_axis: np.ndarray
    top_split: np.ndarray
    top_child: np.ndarray
    top_count: np.ndarray
    top_items: np.ndarray
    top_bounds: np.ndarray
    world_to_object: np.ndarray
    mesh_of: np.ndarray
    node_start: np.ndarray
    ref_start: np.ndarray
    tri_start: np.ndarray
    box_start: np.ndarray
    axis: np.ndarray
    split: np.ndarray
    child: np.ndarray
    count: np.ndarray
    leaf_prims: np.ndarray
    triangles: np.ndarray
    mesh_bounds: np.ndarray
    leaf_triangles: np.ndarray
    leaf_boxes: np.ndarray
    visibility: np.ndarray
    world_boxes: np.ndarray


class TwoLevelScene:
    """Meshes (object-space KdTrees), instances and the top-level tree over the instances.

    Attributes: `meshes` (list of KdTree); `mesh_of` (I,) int32; `object_to_world` (I, 4, 4) float64;
    `world_to_object` (I, 3, 4) float64; `world_boxes` (I, 6) float32 (rounded outward);
    `top` (axis, split, child, count, items, bounds) of the top-level tree; `build_ms` (top level only);
    `visibility` (I,) uint8 ray_visibility bits, checked by build_two_level (None: every instance stops
    every ray)."""

    def __init__(self, meshes, mesh_of, object_to_world, world_to_object, world_boxes, top, build_ms,
                 visibility=None):
        self.meshes = list(meshes)
        self.mesh_of = mesh_of
        self.visibility = as_visibility(None, len(mesh_of)) if visibility is None else visibility
        self.object_to_world, self.world_to_object = object_to_world, world_to_object
        self.world_boxes = world_boxes
        self.top = top
        self.build_ms = build_ms
        self.signature = None  # an InstanceSignature when a SceneBuilder made it (pixel reuse across frames)
        # What a SceneBuilder / build_scene subtracted from every position: the scene's coordinates are
        # world minus origin, so rays, cameras and lights must be shifted too (Camera.translated(origin),
        # Light.translated(origin), origins - origin).
        self.origin = np.zeros(3)
        self.caller_ids = None  # a SceneBuilder's CallerIds: its caller's instance and triangle indices
        self._packed = pack_meshes(self.meshes)

    @property
    def arrays(self):
        """The SceneArrays the instance traversal takes (see instance_traversal.trace_scene)."""
        return SceneArrays(*self.top, self.world_to_object, self.mesh_of, *self._packed, self.visibility,
                           self.world_boxes)

    @property
    def lazy_tree(self):
        """The scene's one mesh tree when it is lazy (its unbuilt subtrees are built as rays reach them,
        then `refresh` re-packs it), else None."""
        return self.meshes[0] if len(self.meshes) == 1 and self.meshes[0].lazy else None

    def refresh(self):
        """Re-pack the mesh arrays after a lazy mesh tree grew (no copy for one mesh)."""
        self._packed = pack_meshes(self.meshes)

    @property
    def instance_count(self):
        return len(self.mesh_of)

    @property
    def triangles(self):
        """Triangles over all instances (an instanced mesh counts once per instance)."""
        sizes = np.array([len(m.triangles) for m in self.meshes], np.int64)
        return int(sizes[self.mesh_of].sum()) if len(self.mesh_of) else 0

    def stats(self):
        """The mesh trees' statistics summed (nodes, leaves, references, bytes), their deepest depth and
        their SAH cost averaged by triangles, plus the top level's own figures. One mesh: its stats."""
        per_mesh = [m.stats() for m in self.meshes]
        axis, _, _, count, _, _ = self.top
        out = dict(per_mesh[0]) if len(per_mesh) == 1 else _summed(per_mesh)
        out.update(triangles=self.triangles, unique_triangles=sum(s["triangles"] for s in per_mesh),
                   meshes=len(self.meshes), instances=self.instance_count, top_nodes=int(len(axis)),
                   top_references=int(count[axis == LEAF].sum()), top_build_ms=self.build_ms)
        return out

    def __repr__(self):
        return (f"TwoLevelScene({len(self.meshes)} meshes, {self.instance_count} instances, "
                f"{self.triangles} triangles)")


def _summed(per_mesh):
    tris = sum(s["triangles"] for s in per_mesh)
    out = {k: sum(s[k] for s in per_mesh) for k in ("nodes", "leaves", "empty_leaves", "references",
                                                      "tree_bytes", "build_ms", "degenerate_dropped")}
    out["max_depth"] = max([s["max_depth"] for s in per_mesh], default=0)
    out["references_per_triangle"] = out["references"] / max(tris - out["degenerate_dropped"], 1)
    out["sah_cost"] = sum(s["sah_cost"] * s["triangles"] for s in per_mesh) / max(tris, 1)
    return out


def build_two_level(meshes, mesh_of, matrices, visibility=None, **options):
    """The top level over prebuilt object-space mesh trees: meshes (KdTrees), mesh_of (I,) mesh of each
    instance, matrices (I, 4, 4) object-to-world, visibility (I,) ray_visibility bits (None: all rays).
    Keywords are BuildOptions for the top level (boxes: `clip` is ignored); a bad instance raises
    a ValueError naming it."""
    lazy = [i for i, m in enumerate(meshes) if isinstance(m, KdTree) and m.lazy]
    if lazy and len(meshes) > 1:
        raise ValueError(f"mesh {lazy[0]} is a lazy tree: a two-level scene with several meshes takes eagerly "
                         "built mesh trees (one lazy mesh, placed by any number of instances, is fine)")
    opts = make_options(options)
    mesh_of, o2w = _check_instances(meshes, mesh_of, matrices)
    visibility = as_visibility(visibility, len(mesh_of))
    start = clock()
    w2o = world_to_object(o2w)
    boxes = world_boxes(mesh_bounds(meshes), mesh_of, o2w)
    top = build_top_level(boxes, opts)
    return TwoLevelScene(meshes, mesh_of, o2w, w2o, boxes, top, (clock() - start) * 1e3, visibility)


def as_two_level(tree):
    """A flat KdTree as a one-instance scene with the identity matrix (the renderer's one code path)."""
    if isinstance(tree, TwoLevelScene):
        return tree
    if not isinstance(tree, KdTree):
        raise ValueError(f"expected a core.KdTree or core.TwoLevelScene, got {type(tree).__name__}")
    return _identity_instance(tree)


def _identity_instance(tree):
    """build_two_level([tree], [0], [identity]) without the placement checks and the matrix algebra, which
    the identity passes and leaves as they are, signs of zero included: its inverse is itself with a
    translation of -0.0 (affine_inverses negates a sum of zeros), and the tree's float32 box is its own
    world box with -0.0 made +0.0 (world_boxes adds each coordinate to 0.0; mesh_bounds is already
    inverted for a mesh with nothing to hit). A frame renders a flat tree through this
    (docs/choices.md#the-python-between-a-frames-passes)."""
    start = clock()
    boxes = mesh_bounds([tree]) + np.float32(0.0)
    top = build_top_level(boxes, make_options({"threads": 1}))
    inverse = np.eye(3, 4)
    inverse[:, 3] = -0.0
    return TwoLevelScene([tree], np.zeros(1, np.int32), np.eye(4)[None], inverse[None], boxes, top,
                         (clock() - start) * 1e3, as_visibility(None, 1))


def _check_instances(meshes, mesh_of, matrices):
    for i, m in enumerate(meshes):
        if not isinstance(m, KdTree):
            raise ValueError(f"mesh {i} must be a core.KdTree, got {type(m).__name__}")
    mesh_of, o2w = check_placement(len(meshes), mesh_of, matrices)
    singular = np.flatnonzero(~invertible(o2w))
    if len(singular):
        raise ValueError(f"instance {int(singular[0])} has a singular matrix (zero scale on some axis): "
                         "flatten it into world triangles instead")
    return mesh_of, o2w


def check_placement(n_meshes, mesh_of, matrices):
    """(mesh_of int32 (I,), matrices float64 (I, 4, 4)) checked: integer mesh indices in range, one
    finite affine matrix (bottom row 0 0 0 1) per instance. Raises ValueError naming the instance."""
    raw = np.asarray(mesh_of).reshape(-1)
    if raw.dtype.kind not in "iub" and not (raw.dtype.kind == "f" and np.array_equal(raw, np.round(raw))):
        raise ValueError(f"mesh_of must hold integer mesh indices, got {raw[:5].tolist()}")
    out_of_range = (raw < 0) | (raw >= n_meshes)  # before the int32 cast, which wraps 2**32 + 1 to 1
    if out_of_range.any():
        bad = int(np.flatnonzero(out_of_range)[0])
        raise ValueError(f"instance {bad} names mesh {raw[bad]}, but there are {n_meshes} meshes")
    mesh_of = np.ascontiguousarray(raw, np.int32)
    o2w = np.ascontiguousarray(as_real_array("matrices (one 4x4 an instance)", matrices))
    if o2w.shape != (len(mesh_of), 4, 4):
        raise ValueError(f"matrices must have shape ({len(mesh_of)}, 4, 4), one per instance, got {o2w.shape}")
    finite = np.isfinite(o2w).reshape(len(o2w), 16).all(axis=1)
    if not finite.all():
        raise ValueError(f"instance {int(np.flatnonzero(~finite)[0])} has a non-finite matrix")
    affine = (o2w[:, 3] == (0.0, 0.0, 0.0, 1.0)).all(axis=1)
    if not affine.all():
        bad = int(np.flatnonzero(~affine)[0])
        raise ValueError(f"instance {bad}'s matrix is not affine: its bottom row is {o2w[bad, 3].tolist()}, "
                         "not [0, 0, 0, 1]")
    return mesh_of, o2w


def invertible(matrices):
    """(I,) bool: the 3x3 linear part can be inverted reliably (relative determinant test)."""
    return relative_determinants(np.ascontiguousarray(matrices, np.float64)) > SINGULAR


def world_to_object(o2w):
    """(I, 3, 4) float64 inverses of the object-to-world matrices."""
    if len(o2w) == 0:
        return np.zeros((0, 3, 4))
    return affine_inverses(np.ascontiguousarray(o2w, np.float64))


def mesh_bounds(meshes):
    """(M, 6) float32 object-space boxes; inverted (inf, -inf) for a mesh with nothing to hit."""
    out = np.empty((len(meshes), 6), np.float32)
    for i, m in enumerate(meshes):
        # triangles with area, not leaf_prims: a lazy tree may not have built any leaf yet
        out[i] = m.bounds if len(m.triangles) > len(m.dropped) else (np.inf,) * 3 + (-np.inf,) * 3
    return out


def world_boxes(bounds, mesh_of, o2w):
    """(I, 6) float32 world boxes of the instances, rounded outward to float32 so the stored box
    always contains the instance; inverted for an instance of a mesh with nothing to hit."""
    if len(mesh_of) == 0:
        return np.zeros((0, 6), np.float32)
    empty = bounds[mesh_of, 0] > bounds[mesh_of, 3]
    world = transformed_boxes(np.where(np.isfinite(bounds), bounds, 0.0)[mesh_of], o2w)
    world[empty, :3], world[empty, 3:] = np.inf, -np.inf
    return np.concatenate([_round_down(world[:, :3]), _round_up(world[:, 3:])], axis=1)


def transformed_boxes(bounds, o2w, origin=(0.0, 0.0, 0.0)):
    """(K, 6) float64 boxes around the 8 transformed corners of each object-space box (K, 6), minus
    `origin` (the translation shifted before anything is summed)."""
    return affine_boxes(np.ascontiguousarray(bounds, np.float64), np.ascontiguousarray(o2w, np.float64),
                        np.asarray(origin, np.float64))


def _round_down(x):
    f = x.astype(np.float32)
    with np.errstate(over="ignore"):  # past float32's largest: -inf, which still holds the box
        return np.where(f > x, np.nextafter(f, np.float32(-np.inf)), f).astype(np.float32)


def _round_up(x):
    f = x.astype(np.float32)
    with np.errstate(over="ignore"):  # past float32's largest: inf, which still holds the box
        return np.where(f < x, np.nextafter(f, np.float32(np.inf)), f).astype(np.float32)


def build_top_level(boxes, opts):
    """(axis, split, child, count, items, bounds) of a kd-tree over instance boxes, built by the box
    builder (build/box_tree.py: the binned SAH without triangles, in parallel); boxes straddling a plane
    are referenced from both sides. Instances with an empty box are left out."""
    keep = np.flatnonzero(boxes[:, 0] <= boxes[:, 3]).astype(np.int32)
    if len(keep) == 0:
        return (*empty_arrays(), np.zeros(6, np.float32))
    sub = np.ascontiguousarray(boxes[keep])
    bounds = np.concatenate([sub[:, :3].min(axis=0), sub[:, 3:].max(axis=0)]).astype(np.float32)
    if len(keep) == 1 or half_area(bounds) == 0.0:
        # One box, or every box on one point or line (instances scaled to ~1e-17): no area for the SAH
        # to divide by, and no split would separate rays: a leaf.
        axis, split, child, count, _ = empty_arrays()
        count[0] = len(keep)
        return axis, split, child, count, keep, bounds
    budget = min(opts.duplication_budget or np.inf, TOP_LEVEL_DUPLICATION)
    box_opts = make_options({**opts.as_dict(), "clip": False, "lazy": False, "duplication_budget": budget,
                             "intersection_cost": opts.intersection_cost * INSTANCE_TEST_COST})
    with thread_count(opts.threads) as threads:
        axis, split, child, count, leaf = build_box_tree(sub, bounds, box_opts.params(len(keep), bounds), threads)
    return axis, split, child, count, keep[leaf].astype(np.int32), bounds


def pack_meshes(meshes):
    """Every mesh tree's arrays concatenated, with offsets: (node_start, ref_start, tri_start, box_start,
    axis, split, child, count, leaf_prims, triangles, mesh_bounds, leaf_triangles, leaf_boxes). Child
    indices, leaf offsets and column groups stay local to their mesh, so `mesh_tree` hands trace_ray views
    that look like a stand-alone tree; leaf_triangles, (9, R) with the meshes' columns side by side, is
    passed whole with the mesh's first column (ref_start)."""
    if len(meshes) == 1:  # the common flat case: no copy
        m = meshes[0]
        starts = [np.array([0, len(a)], np.int64) for a in (m.axis, m.leaf_prims, m.triangles, m.leaf_boxes)]
        return (*starts, m.axis, m.split, m.child, m.count, m.leaf_prims, m.triangles, m.bounds[None].copy(),
                m.leaf_triangles, m.leaf_boxes)
    if not meshes:
        axis, split, child, count, prims = empty_arrays()
        zero = np.zeros(1, np.int64)
        return (zero, zero, zero, zero, axis[:0], split[:0], child[:0], count[:0], prims,
                np.zeros((0, 3, 3), np.float32), np.zeros((0, 6), np.float32), np.zeros((9, 0), np.float32),
                np.zeros((0, 6), np.float32))
    starts = [_offsets([len(getattr(m, name)) for m in meshes])
              for name in ("axis", "leaf_prims", "triangles", "leaf_boxes")]
    parts = [np.concatenate([getattr(m, name) for m in meshes])
             for name in ("axis", "split", "child", "count", "leaf_prims", "triangles")]
    return (*starts, *parts, np.stack([m.bounds for m in meshes]).astype(np.float32),
            np.concatenate([m.leaf_triangles for m in meshes], axis=1), np.concatenate([m.leaf_boxes for m in meshes]))


def _offsets(sizes):
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
