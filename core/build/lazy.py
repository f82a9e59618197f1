"""On-demand (lazy) construction (seed 003 §3): deferred subtrees are built when rays first reach them.

Nodes of at most `lazy_subtree_size` references stay UNBUILT (layout.py), their references kept here.
A ray reaching one stops and reports it; the caller builds all requested subtrees at once, in
parallel, exactly as the eager build would (subtree.py), splices them in (merge.py) and retraces the
stopped rays, so results equal the eager tree's. Seed 003 interleaves building and tracing in one
GPU task pool; on a few CPU cores this alternation keeps one traversal and one builder.
"""

import numpy as np

from ..jit.compile_clock import clock
from ..trace.layout import NO_HIT, UNBUILT, subtree_of
from .leaf_triangles import BYTES_PER_REFERENCE as LEAF_COPY_BYTES
from ..memory import MB, MemoryLimitError
from .merge import splice_subtrees
from .subtree import build_subtrees
from ..jit.threads import thread_count
from .top_levels import Task


# When one round asks for at least this share of the unbuilt subtrees, build the rest with them: the
# scene is mostly visible, and each further round costs a retrace (docs/choices.md#lazy-build-all-share).
BUILD_ALL_SHARE = 0.5
NODE_BYTES = 13  # axis, split, child, count (layout.py)


class DeferredSubtrees:
    """The subtrees a lazy build left for later, and what has been built of them since: subtree k is node
    `node[k]` (axis UNBUILT, child k) with references prims/boxes[start[k]:start[k+1]], box `box[k]`,
    depth `depth[k]` and room `room[k]`. Plain arrays: it pickles."""

    def __init__(self, subtrees, axis, child, params, speculative):
        parts = [s[5:] for s in subtrees]
        sizes = np.concatenate([np.diff(p[1]) for p in parts]).astype(np.int64)
        self.start = np.concatenate([[0], np.cumsum(sizes)])
        self.depth = np.concatenate([p[2] for p in parts])
        self.box = np.concatenate([p[3] for p in parts])
        self.prims = np.concatenate([p[4] for p in parts])
        self.boxes = np.concatenate([p[5] for p in parts])
        self.room = np.concatenate([p[6] for p in parts])
        unbuilt = np.flatnonzero(axis == UNBUILT)
        self.node = np.empty(len(sizes), np.int64)
        self.node[child[unbuilt]] = unbuilt
        self.built = np.zeros(len(sizes), bool)
        self.params = params._replace(defer_size=0)  # a deferred subtree is built whole
        self.speculative = speculative
        self.build_ms = 0.0
        self.rounds = 0

    @property
    def total(self):
        return len(self.built)

    def stats(self):
        """The lazy fields of KdTree.stats() (see README, Lazy (on-demand) building)."""
        return {"lazy": True, "subtrees_total": self.total, "subtrees_built": int(self.built.sum()),
                "unbuilt_references": int(np.diff(self.start)[~self.built].sum()),
                "lazy_build_ms": self.build_ms, "lazy_rounds": self.rounds,
                "deferred_bytes": int(self.prims.nbytes + self.boxes.nbytes)}

    def select(self, requested):
        """The unbuilt subtrees to build for these requests: the requested ones and, if speculative, their
        neighbours in build order (usually a sibling or cousin; seed 003 §4 "speculative unlocking")."""
        ids = np.unique(requested)
        if self.speculative:
            ids = np.unique(np.clip(np.concatenate([ids - 1, ids, ids + 1]), 0, self.total - 1))
        ids = ids[~self.built[ids]]
        unbuilt = np.flatnonzero(~self.built)
        if len(ids) >= BUILD_ALL_SHARE * len(unbuilt):  # the rays see most of what is left
            return unbuilt
        return ids

    def tasks(self, ids):
        return [Task(int(self.node[k]), self.prims[self.start[k]:self.start[k + 1]],
                     self.boxes[self.start[k]:self.start[k + 1]], self.box[k], int(self.depth[k]),
                     float(self.room[k]))
                for k in ids]


def build_requested(tree, requested, threads=None):
    """Build the deferred subtrees `requested` (indices, repeats allowed) and splice them into `tree`."""
    deferred = tree.deferred
    ids = deferred.select(requested)
    if len(ids) == 0:
        return
    start = clock()
    with thread_count(threads) as n_threads:
        subtrees = build_subtrees(tree.triangles, deferred.tasks(ids), deferred.params, n_threads)
    _check_memory_limit(tree, subtrees)
    tree.replace_nodes(splice_subtrees(tree.node_arrays, deferred.node[ids], subtrees))
    deferred.built[ids] = True
    if deferred.built.all():  # nothing left to build: let the kept references go
        deferred.prims, deferred.boxes = deferred.prims[:0], deferred.boxes[:0]
    deferred.rounds += 1
    deferred.build_ms += (clock() - start) * 1e3


def _check_memory_limit(tree, subtrees):
    """Refuse a round whose subtrees would grow the tree past its memory_limit, before splicing them
    (the tree stays usable). Each subtree's own check has a 1 MB floor (memory.MIN_SUBTREE_BUDGET),
    and a lazy tree's many small subtrees would add those floors up past the limit."""
    limit = tree.options.memory_limit
    if limit is None:
        return
    held = sum(a.nbytes for a in tree.node_arrays) + tree.leaf_triangles.nbytes + tree.leaf_boxes.nbytes
    held += tree.deferred.prims.nbytes + tree.deferred.boxes.nbytes
    nodes = sum(len(s[0]) for s in subtrees)
    references = sum(len(s[4]) for s in subtrees)
    grown = held + NODE_BYTES * nodes + (4 + LEAF_COPY_BYTES) * references
    if grown > limit:
        raise MemoryLimitError(
            f"a lazy kd-tree over {len(tree.triangles):,} triangles would outgrow memory_limit "
            f"({limit / MB:,.1f} MB) building the subtrees its rays reach ({grown / MB:,.1f} MB): raise "
            "memory_limit, or lower max_depth or cost_ratio; the tree keeps what earlier rounds built, not "
            "this round")


def resolve_suspended(tree, status, retrace, threads=None):
    """Finish work that stopped at unbuilt subtrees: while some items (rays, pixels) have a suspended
    status (<= -2, layout.suspended_prim), build the subtrees they name and call retrace(indices), which
    must redo those items from the start and update status[indices]. Nothing to do on an eager tree."""
    pending = np.flatnonzero(status < NO_HIT)
    while len(pending):
        build_requested(tree, subtree_of(status[pending]), threads)
        retrace(pending)
        pending = pending[status[pending] < NO_HIT]
