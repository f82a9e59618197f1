"""KD Preview core: a parallel SAH kd-tree and robust ray queries, in numpy and Numba (never bpy).

Public API:
    build_kdtree(triangles, **options) -> KdTree     (options: see BuildOptions)
    intersect(tree, origins, directions, tmin=0.0, tmax=inf) -> Hits(t, prim, u, v)
    occluded(tree, origins, directions, tmin=0.0, tmax=inf) -> (R,) bool
    KdTree.stats() -> dict
"""
from .build import build_kdtree
from .kdtree import KdTree
from .options import BuildOptions
from .queries import Hits, intersect, occluded

__all__ = ["build_kdtree", "intersect", "occluded", "KdTree", "Hits", "BuildOptions"]
