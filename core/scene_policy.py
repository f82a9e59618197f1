"""Which instances keep their own tree and which are merged into a flat "soup" tree (SceneBuilder
makes one per ray visibility, see scene_builder.py).

Seed 000 §5: a tree per object under a top-level tree "works really well in case of large number of
non-deforming objects" but gives "ambiguous results" otherwise: where object boxes overlap, a ray
visits several objects' trees where one flat tree would have separated their triangles. So:

- a mesh placed by several instances always keeps its own tree (flattening copies it per instance);
- objects that changed (deformed or moved) in an earlier frame stay separate, so the static rest is not
  rebuilt with them (seed 000 §5's static/dynamic separation);
- static single objects below SMALL_OBJECT triangles go to the soup: a tree of their own saves little
  and costs a top-level leaf and a ray transform;
- if the remaining static single objects overlap heavily (OVERLAP_LIMIT, see `overlap_depth`), they
  go to the soup too;
- an instance whose matrix cannot be inverted (zero scale) can only be flattened.
Figures behind SMALL_OBJECT and OVERLAP_LIMIT: benchmarks/bench_two_level.py and the README.
"""
import numpy as np

from .two_level import invertible, transformed_boxes

LAYOUTS = ("auto", "two_level", "flat")
SMALL_OBJECT = 1024
OVERLAP_LIMIT = 0.5
OVERLAP_SAMPLE = 2048  # boxes compared against all others when there are more (seeded sample)


def plan_soup(layout, mesh_triangles, mesh_bounds, mesh_of, o2w, dynamic):
    """(I,) bool: which instances are merged into the soup.

    mesh_triangles (M,) triangle counts; mesh_bounds (M, 6) object-space boxes; mesh_of (I,);
    o2w (I, 4, 4) float64; dynamic (M,) bool: the mesh changed or moved in an earlier frame.
    """
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    singular = ~invertible(o2w) if len(o2w) else np.zeros(0, bool)
    if layout == "flat":
        return np.ones(len(mesh_of), bool)
    if layout == "two_level" or len(mesh_of) == 0:
        return singular
    uses = np.bincount(mesh_of, minlength=len(mesh_triangles))
    candidate = (uses[mesh_of] == 1) & ~dynamic[mesh_of] & ~singular
    soup = singular | (candidate & (mesh_triangles[mesh_of] < SMALL_OBJECT))
    big = np.flatnonzero(candidate & ~soup)
    if len(big) > 1 and overlap_depth(transformed_boxes(mesh_bounds[mesh_of[big]], o2w[big])) > OVERLAP_LIMIT:
        soup[big] = True
    return soup


def overlap_depth(boxes):
    """Mean over boxes of the share of each box's volume that other boxes cover, summed over them.

    0 for disjoint objects; k when every object is covered k times over (e.g. 1 for pairs that fill
    each other's box). Boxes are padded by 0.1% of the scene's diagonal so flat objects have volume.
    """
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
