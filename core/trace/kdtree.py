"""The built tree: flat contiguous arrays (see layout.py), its triangles, and its statistics."""
import numpy as np

from .layout import LEAF, NodeArrays, TreeArrays
from ..build.leaf_triangles import kept_columns, leaf_boxes, leaf_triangles
from .tree_stats import leaf_size_histogram, walk_stats


class KdTree:
    """A kd-tree over a triangle soup. Plain arrays only, so it pickles and kernels take it directly.

    Attributes: `triangles` (N, 3, 3) float32; `bounds` (6,) float32 box of the triangles in the tree;
    `axis`, `split`, `child`, `count` (per node, layout.py) and `leaf_prims` (triangle indices), given
    as one NodeArrays;
    `leaf_triangles` (9, R) float32, the triangles copied into leaf order, and `leaf_boxes`, the boxes of
    their column groups (leaf_triangles.py);
    `options` (the BuildOptions used); `build_ms`; `dropped` (indices of zero-area triangles, which can
    never be hit and are left out); `deferred` (lazy builds: the subtrees not built yet, lazy.py; None
    for an eager tree). Queries on a lazy tree build what they need, so its node arrays grow."""

    def __init__(self, triangles, bounds, nodes, options, build_ms, dropped, timings=None, deferred=None,
                 leaf_copy=None):
        self.triangles = triangles
        self.bounds = bounds
        self.axis, self.split, self.child, self.count, self.leaf_prims = nodes
        if leaf_copy is None:  # (leaf_triangles, leaf_boxes), made by the builder as part of the build
            copy = leaf_triangles(triangles, self.leaf_prims)
            leaf_copy = copy, leaf_boxes(copy, nodes, bounds)
        self.leaf_triangles, self.leaf_boxes = leaf_copy
        self.options = options
        self.build_ms = build_ms
        self.dropped = dropped
        self.timings = dict(timings or {})
        self.deferred = deferred
        self._stats = None

    @property
    def arrays(self):
        """The TreeArrays the traversal kernels take (traversal.trace_ray)."""
        return TreeArrays(self.axis, self.split, self.child, self.count, self.leaf_prims, self.triangles,
                          self.bounds, self.leaf_triangles, self.leaf_boxes, 0)

    @property
    def node_arrays(self):
        return NodeArrays(self.axis, self.split, self.child, self.count, self.leaf_prims)

    def replace_nodes(self, node_arrays):
        """Swap in grown node arrays (a lazy tree after building deferred subtrees)."""
        old_prims = self.leaf_prims
        self.axis, self.split, self.child, self.count, self.leaf_prims = node_arrays
        kept = kept_columns(old_prims, self.leaf_prims)  # a splice appends: the old columns stay
        self.leaf_triangles = leaf_triangles(self.triangles, self.leaf_prims, (kept, self.leaf_triangles))
        self.leaf_boxes = leaf_boxes(self.leaf_triangles, self.node_arrays, self.bounds, (self.leaf_boxes, kept))
        self._stats = None

    @property
    def lazy(self):
        return self.deferred is not None

    @property
    def node_count(self):
        return len(self.axis)

    def stats(self):
        """Triangles, nodes, leaves, empty leaves, depth, references, SAH cost, build time and more.
        On a lazy tree, the tree as built so far (unbuilt subtrees cost as leaves of their references;
        `lazy_build_ms` is the on-demand building so far)."""
        if self._stats is None:
            self._stats = self._compute_stats()
        return dict(self._stats)

    def _compute_stats(self):
        o = self.options
        sah, leaves, empty, depth, refs, _, _, unbuilt = walk_stats(
            self.axis, self.split, self.child, self.count, self.bounds, o.traversal_cost, o.intersection_cost)
        n = len(self.triangles)
        nbytes = sum(a.nbytes for a in (self.axis, self.split, self.child, self.count, self.leaf_prims,
                                         self.leaf_triangles, self.leaf_boxes))
        return {
            "triangles": n,
            "degenerate_dropped": len(self.dropped),
            "nodes": self.node_count,
            "leaves": int(leaves),
            "empty_leaves": int(empty),
            "max_depth": int(depth),
            "references": int(refs),
            "references_per_triangle": refs / max(n - len(self.dropped), 1),
            "sah_cost": float(sah),
            "build_ms": self.build_ms,
            "tree_bytes": int(nbytes),
            "leaf_sizes": leaf_size_histogram(self.axis, self.count),
            "builder": o.builder,
            **{f"{k}_ms": v for k, v in self.timings.items()},
            **self._lazy_stats(unbuilt),
        }

    def _lazy_stats(self, unbuilt):
        if self.deferred is None:
            return {"lazy": False, "subtrees_total": 0, "subtrees_built": 0, "unbuilt_references": 0,
                    "lazy_build_ms": 0.0, "lazy_rounds": 0, "deferred_bytes": 0}
        lazy = self.deferred.stats()
        assert unbuilt == lazy["subtrees_total"] - lazy["subtrees_built"], "unbuilt nodes out of step"
        return lazy

    def __repr__(self):
        s = self.stats()
        lazy = f", lazy: {s['subtrees_built']}/{s['subtrees_total']} subtrees built" if s["lazy"] else ""
        return (f"KdTree({s['triangles']} triangles, {s['nodes']} nodes, depth {s['max_depth']}, "
                f"SAH {s['sah_cost']:.2f}, built in {s['build_ms']:.1f} ms by {s['builder']!r}{lazy})")


def empty_arrays():
    """NodeArrays of a tree with nothing in it: one empty leaf."""
    return NodeArrays(np.array([LEAF], np.int8), np.zeros(1, np.float32), np.zeros(1, np.int32),
                      np.zeros(1, np.int32), np.zeros(0, np.int32))
