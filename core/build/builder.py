"""build_kdtree: checks the input, then runs the parallel top levels, the subtree builds and the merge."""
import numpy as np

from ..geometry import triangle_boxes, union_of_boxes
from ..inputs import as_triangles
from ..trace.kdtree import KdTree, empty_arrays
from ..trace.layout import NodeArrays
from .lazy import DeferredSubtrees
from .leaf_triangles import BYTES_PER_REFERENCE as LEAF_COPY_BYTES, leaf_boxes, leaf_triangles
from ..memory import MB, MemoryLimitError, check_build_memory, release_before_copy
from .merge import merge_tree
from .options import BuildOptions, make_options
from .subtree import build_subtrees
from ..jit.compile_clock import clock, compile_seconds
from ..jit.threads import thread_count
from .top_levels import build_top_levels


def build_kdtree(triangles, **options):
    """Build a kd-tree over an (N, 3, 3) array of triangle vertex positions.
    Keyword options are `BuildOptions`' fields, each validated; with lazy=True only the top is built now
    (lazy.py). Raises ValueError naming the first bad triangle or setting, or memory.MemoryLimitError
    (a ValueError) when the estimated peak memory is above memory_limit."""
    opts = make_options(options)
    check_build_memory(triangles, opts)
    tris = as_triangles(triangles)
    start, compiled = clock(), compile_seconds()
    timings = {}
    with thread_count(opts.threads) as threads:
        prims, boxes, bounds, dropped = _initial_references(tris)
        timings["prepare"] = _ms_since(start)
        deferred = None
        if len(prims) == 0:
            arrays = empty_arrays()
        else:
            try:
                arrays, deferred = _build_arrays(tris, prims, boxes, bounds, opts, threads, timings)
            except MemoryLimitError:  # raised in a kernel, whose message cannot carry the numbers
                raise MemoryLimitError(
                    f"building a kd-tree over {len(tris):,} triangles outgrew memory_limit "
                    f"({opts.memory_limit / MB:,.1f} MB) while splitting: the triangles need more references "
                    "than the estimate allows, as dense overlapping triangles and settings that force splits "
                    f"(here cost_ratio {opts.cost_ratio:g}, leaf_size {opts.leaf_size}, max_depth "
                    f"{opts.depth_for(len(tris))}, {_budget_text(opts.duplication_budget)}) do; raise memory_limit, "
                    f"or {_budget_advice(opts.duplication_budget)}lower max_depth or cost_ratio") from None
        del prims, boxes  # the initial references; the leaf copy below may take their memory
        release_before_copy(LEAF_COPY_BYTES * len(arrays.leaf_prims), opts.memory_limit)
        leaf_tris = leaf_triangles(tris, arrays.leaf_prims)  # part of the build: the traversal reads it
        leaf_copy = leaf_tris, leaf_boxes(leaf_tris, arrays, bounds)
    timings["compile"] = (compile_seconds() - compiled) * 1000.0  # not in build_ms or the steps' times
    return KdTree(tris, bounds, arrays, options=opts, build_ms=_ms_since(start), dropped=dropped,
                  timings=timings, deferred=deferred, leaf_copy=leaf_copy)


def _initial_references(tris):
    """One reference per triangle with area: its index and box; and the box around them all."""
    boxes, keep = triangle_boxes(tris)
    if keep.all():  # the usual case: every index, without searching the mask
        prims, dropped = np.arange(len(tris), dtype=np.int32), np.empty(0, np.int32)
    else:
        prims = np.flatnonzero(keep).astype(np.int32)
        dropped = np.flatnonzero(~keep).astype(np.int32)
        boxes = np.ascontiguousarray(boxes[keep])
    if len(prims) == 0:
        return prims, boxes, np.zeros(6, np.float32), dropped
    bounds = union_of_boxes(boxes)
    return prims, boxes, bounds, dropped


def _build_arrays(tris, prims, boxes, bounds, opts, threads, timings):
    params = opts.params(len(prims), bounds)
    t = clock()
    top_nodes, tasks = build_top_levels(tris, prims, boxes, bounds, params, opts.top, threads)
    del prims, boxes
    timings["top"] = _ms_since(t)
    t = clock()
    subtrees = build_subtrees(tris, tasks, params, threads)
    timings["subtrees"] = _ms_since(t)
    t = clock()
    arrays = NodeArrays(*merge_tree(top_nodes, subtrees))
    deferred = None
    if opts.lazy:
        deferred = DeferredSubtrees(subtrees, arrays.axis, arrays.child, params, opts.lazy_speculative)
    timings["merge"] = _ms_since(t)
    return arrays, deferred


def _ms_since(start):
    """Milliseconds since the clock() reading `start`, the Numba compiles in between left out."""
    return (clock() - start) * 1000.0


def _budget_text(budget):
    """How the memory error names BuildOptions.duplication_budget: its value, or that it is off."""
    return "duplication_budget off (None)" if budget is None else f"duplication_budget {budget:g}"


def _budget_advice(budget):
    """The memory error's advice on the budget: with it off, splitting may copy straddlers without end."""
    default = BuildOptions.__dataclass_fields__["duplication_budget"].default
    return f"set a duplication_budget ({default:g} by default), or " if budget is None else ""
