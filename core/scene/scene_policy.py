"""Which instances keep their own tree and which are merged into a flat "soup" tree (one per ray
visibility, scene_builder.py).

Seed 000 §5: per-object trees under a top-level tree work "really well" for many non-deforming objects
but give "ambiguous results" where object boxes overlap (a ray visits several trees). So meshes placed
by several instances and objects that changed in an earlier frame keep their own trees (seed 000 §5's
static/dynamic separation); static single objects below SMALL_OBJECT triangles, and all of them when
they overlap beyond OVERLAP_LIMIT, go to the soup (docs/choices.md#soup-thresholds), as do instances
whose matrix cannot be inverted. `soup_zones` keeps float32 soup members near their anchor.
"""
import numpy as np

from ..inputs import FLOAT32_MAX
from .two_level import invertible, transformed_boxes

LAYOUTS = ("auto", "two_level", "flat")
SMALL_OBJECT = 1024
OVERLAP_LIMIT = 0.5
OVERLAP_SAMPLE = 2048  # boxes compared against all others when there are more (seeded sample)
# A soup member's vertices lie within this many of its own box diagonals of its anchor, so float32
# rounds them by at most 2^-24 * 16384 = 2^-10 of the member's size (its own tree: ~2^-24), under a
# pixel until the member spans a thousand. Zones cost render and build time (docs/choices.md#soup-zones-at-16384-box-diagonals).
PRECISION_RATIO = 16384.0
# A member's triangles keep that precision (2^-10 of their size) only within PRECISION_RATIO of their size
# of the anchor. A mesh whose median triangle is under 2^-15 of its box's diagonal has half the diagonal
# beyond that from any anchor (triangles in one spot and a vertex far away): no zone keeps its shape, so
# it keeps its own tree, whose object-space float32 is as precise as its vertices
# (docs/choices.md#meshes-whose-triangles-are-far-smaller-than-their-box-keep-their-own-tree).
DETAIL_RATIO = 0.5 / PRECISION_RATIO
DETAIL_SAMPLE = 4096  # triangles whose sizes stand for a larger mesh's (evenly strided)


def plan_soup(layout, mesh_triangles, mesh_bounds, mesh_of, o2w, dynamic, sparse=None):
    """(I,) bool: which instances are merged into the soup.
    mesh_triangles (M,) triangle counts; mesh_bounds (M, 6) object-space boxes; mesh_of (I,);
    o2w (I, 4, 4) float64; dynamic (M,) bool: the mesh changed or moved in an earlier frame; sparse (M,)
    bool (None: none is): its triangles are far smaller than its box (sparse_mesh), so it keeps its tree
    unless its matrix cannot be inverted ("flat" merges every mesh)."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    singular = ~invertible(o2w) if len(o2w) else np.zeros(0, bool)
    if layout == "flat":
        return np.ones(len(mesh_of), bool)
    if layout == "two_level" or len(mesh_of) == 0:
        return singular
    uses = np.bincount(mesh_of, minlength=len(mesh_triangles))
    candidate = (uses[mesh_of] == 1) & ~dynamic[mesh_of] & ~singular
    if sparse is not None:
        candidate &= ~sparse[mesh_of]
    soup = singular | (candidate & (mesh_triangles[mesh_of] < SMALL_OBJECT))
    big = np.flatnonzero(candidate & ~soup)
    if len(big) > 1 and overlap_depth(transformed_boxes(mesh_bounds[mesh_of[big]], o2w[big])) > OVERLAP_LIMIT:
        soup[big] = True
    return soup


def sparse_mesh(vertices, triangles, box):
    """True when the median triangle of a mesh (object-space (N, 3) vertices, (T, 3) indices; at most
    DETAIL_SAMPLE triangles, evenly strided; the upper median of an even count) spans less than
    DETAIL_RATIO of the diagonal of `box` (6,), the box of the vertices its triangles use. Squared
    lengths and a partition, not a sort: it runs once for every static object of a scene."""
    if len(triangles) == 0:
        return False
    sample = np.asarray(vertices, np.float64)[np.asarray(triangles)[::-(-len(triangles) // DETAIL_SAMPLE)]]
    extents = sample.max(axis=1) - sample.min(axis=1)
    squared = np.einsum("ij,ij->i", extents, extents)
    middle = len(squared) // 2
    diagonal = np.asarray(box[3:], np.float64) - np.asarray(box[:3], np.float64)
    return bool(np.partition(squared, middle)[middle] < DETAIL_RATIO ** 2 * float(diagonal @ diagonal))


def overlap_depth(boxes):
    """Mean over boxes of the share of each box's volume that other boxes cover, summed over them.
    0 for disjoint objects; k when every object is covered k times over (e.g. 1 for pairs that fill
    each other's box). Boxes are padded by 0.1% of the scene's diagonal so flat objects have volume."""
    diag = np.linalg.norm(boxes[:, 3:].max(axis=0) - boxes[:, :3].min(axis=0))
    lo, hi = boxes[:, :3] - 1e-3 * diag, boxes[:, 3:] + 1e-3 * diag
    volume = np.prod(hi - lo, axis=1)
    rows = np.arange(len(boxes))
    if len(rows) > OVERLAP_SAMPLE:
        rows = np.random.default_rng(0).choice(rows, OVERLAP_SAMPLE, replace=False)
    shares = []
    for chunk in np.array_split(rows, max(1, len(rows) // 256)):
        inter = np.clip(np.minimum(hi[chunk, None], hi[None]) - np.maximum(lo[chunk, None], lo[None]), 0, None)
        covered = np.prod(inter, axis=2).sum(axis=1) - volume[chunk]  # minus the box itself
        shares.append(covered / volume[chunk])
    return float(np.concatenate(shares).mean())


def soup_zones(boxes, before=None, split=True, camera=None):
    """The zones of one soup, as a list of (member rows, anchor), the main zone first (its rows may be
    empty). boxes (K, 6): the members' world boxes (inverted when empty); before: the main zone's
    anchor last frame, or None; split False: the main zone alone (the "flat" layout, lazy builds),
    anchored nearest `camera` (3,), the point the scene is traced relative to, if given (main_anchor).
    The main zone (`main_anchor`) keeps every member whose farthest box corner is within PRECISION_RATIO
    of its diagonals of the anchor, re-found until stable so next frame's zone is the same. The rest,
    smallest first, join the nearest zone anchor within (PRECISION_RATIO - 1/2) diagonals of their
    centre, or anchor a new zone at the centre of the power-of-two grid cell holding it."""
    lo, hi = boxes[:, :3], boxes[:, 3:]
    filled = (lo <= hi).all(axis=1)
    size = np.zeros(len(boxes))
    size[filled] = np.linalg.norm(hi[filled] - lo[filled], axis=1)
    main = np.ones(len(boxes), bool)
    anchor = main_anchor(boxes[filled], before, near=None if split else camera)
    while split:  # each pass either keeps every member or removes some: a few passes
        out = main & ~_near(boxes, size, anchor)
        if not out.any():
            break
        main &= ~out
        anchor = main_anchor(boxes[main & filled], before)
    if split:  # members the final anchor is near enough for come back: next frame, with this anchor as
        main = _near(boxes, size, anchor)  # `before`, they would stay, and the soup would be rebuilt
        anchor = main_anchor(boxes[main & filled], anchor)  # (the same point: the box only grew)
    anchors, members = np.zeros((0, 3)), []
    for row in sorted(np.flatnonzero(~main), key=lambda r: (size[r], r)):
        # (capped so that a member 1e35 across still has its triangles within float32's range of the anchor)
        centre, allowed = (lo[row] + hi[row]) / 2, min((PRECISION_RATIO - 0.5) * size[row], FLOAT32_MAX / 4)
        distance = np.linalg.norm(anchors - centre, axis=1)
        if len(anchors) and distance.min() <= allowed:
            members[int(np.argmin(distance))].append(row)
            continue
        cell = 2.0 ** np.floor(np.log2(allowed * 2 / np.sqrt(3.0)))
        anchors = np.vstack([anchors, (np.floor(centre / cell) + 0.5) * cell])
        members.append([row])
    return [(np.flatnonzero(main), anchor)] + [(np.array(sorted(rows), np.int64), a)
                                               for rows, a in zip(members, anchors)]


def _near(boxes, size, anchor):
    """(K,) bool: the member's farthest box corner is within PRECISION_RATIO of its diagonals of
    `anchor`, or it has no extent (empty, or a point: nothing to round)."""
    farthest = np.linalg.norm(np.maximum(np.abs(boxes[:, :3] - anchor), np.abs(boxes[:, 3:] - anchor)), axis=1)
    return (size == 0) | (farthest <= PRECISION_RATIO * size)


def main_anchor(boxes, before=None, near=None):
    """The point a soup's main zone's float32 triangles are relative to, given its members' world boxes
    (K, 6, all filled): the last anchor `before` while it lies within the members' box grown by its
    diagonal (and within float32's range of every vertex), else the box's centre, or with `near` (3,)
    the box's point nearest it (the camera), where float32 keeps the most precision: a soup without
    zones (the "flat" layout, lazy builds) takes every member, and the centre of a box one huge member
    spans can lie far from all the rest, whose triangles it rounded away
    (docs/choices.md#one-soup-anchored-nearest-the-camera). That point is no farther from any vertex, axis
    by axis, than `near` is, so the triangles stay within float32's range wherever the camera's
    coordinates do. Re-anchoring re-rounds every member and so costs kept pixels (instance_signature.py)."""
    if len(boxes) == 0:
        return np.zeros(3) if before is None else before
    lo, hi = boxes[:, :3].min(axis=0), boxes[:, 3:].max(axis=0)
    grow = np.linalg.norm(hi - lo)
    if (before is not None and ((lo - grow <= before) & (before <= hi + grow)).all()
            and (np.maximum(before - lo, hi - before) <= FLOAT32_MAX).all()):
        return before
    return (lo + hi) / 2 if near is None else np.clip(near, lo, hi)
