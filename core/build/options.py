"""Build settings: one object, every field with a documented default, validated once at the boundary.

`BuildOptions` is what users pass (as keywords to `build_kdtree`); `BuildParams` is the plain tuple of
numbers the Numba kernels see.
"""
from dataclasses import dataclass, asdict
from math import isfinite, log2
from typing import NamedTuple, Optional

import numpy as np

from ..geometry import half_area
from ..memory import subtree_bytes_per_reference

BUILDERS = ("binned", "exact", "median")
TOP_STRATEGIES = ("sah", "clustering")
SPLIT_AXES = ("all", "longest")

# The traversal stack has one slot per level, so the depth is capped where the stack ends.
DEPTH_LIMIT = 60


# Below this many rays a triangle, clipping, snapping and the all-axes search cost more build time
# than they save in tracing (docs/choices.md#refinement-off-below-4-rays-a-triangle).
REFINE_RAYS_PER_TRIANGLE = 4


@dataclass(frozen=True)
class BuildOptions:
    """Settings of the kd-tree builder.

    builder: "binned" (min-max binned SAH, seed 000 §3.3-3.4), "exact" (O(N log N) event sweep, seed
        004 §3.1: the quality reference) or "median" (spatial median, the SAH only deciding when to stop).
    bins: min-max bins per axis for "binned" (seed 000 found 32 sufficient).
    exact_below: "binned" sweeps exactly in nodes of at most this many references (seed 000 switches at
        `bins`; 0: binning everywhere, docs/choices.md#binning-everywhere).
    snap: "binned" also tries the box boundaries nearest its best bin boundary below the top levels
        (split_binned.snap_to_boundaries; docs/choices.md#snapping-to-box-boundaries-snap-on).
    split_axes: "all" or "longest" (below the top levels bin the longest axis, as fast BVH builders do
        (Wald 2007), and the other two only where it offers no plane better than a leaf).
    leaf_size: nodes with at most this many references become leaves without trying a split.
    max_depth: None means 1.2*log2(N) + 2 (seed 003 §3.5), capped at 60.
    traversal_cost, intersection_cost: SAH costs of one traversal step and one ray/triangle test
        (docs/choices.md#intersection-cost-03).
    empty_bonus: share of the intersection cost forgiven for an empty child, in [0, 1)
        (docs/choices.md#empty-space-bonus-02).
    cost_ratio: a node stays a leaf when its best split costs more than cost_ratio times the leaf
        (seed 003 §3.5 uses 0.9 to favour time to image).
    clip: clip straddling triangles to each child for tight boxes ("perfect splits", seed 002, Havran).
    skip: while binning large nodes bin every log10(n)-th reference (seed 000 §3.3).
    top: the parallel top levels: "sah" (binned SAH at every top node) or "clustering" (seed 000 §4.1:
        equal-count sub-domains from one high-resolution binning).
    threads: worker threads; None uses every core Numba sees.
    lazy: on-demand construction (seed 003 §3): defer every node of at most `lazy_subtree_size`
        references until a ray first enters it; results equal the eager tree's.
    lazy_subtree_size: the largest deferred subtree, in references (docs/choices.md#lazy-building-subtrees-of-4096-references-no-speculation).
    lazy_speculative: also build each requested subtree's neighbours in build order (seed 003 §4).
    memory_limit: bytes; a build whose estimated peak (memory.py) or pools exceed it raises
        memory.MemoryLimitError (a ValueError) before allocating more. None: no limit.
    duplication_budget: references per starting triangle that splitting straddlers may make, spent
        evenly along every path (subtree.py); stops dense coplanar triangles from splitting to max_depth
        (docs/choices.md#duplication-budget-16). None: no budget.
    rays: how many rays the tree will answer (one render: core.frame_ray_count). Given, a node is split
        only when the rays expected to enter it save more than the split costs to build (sah.beats_leaf,
        seed 003 §3.5); below REFINE_RAYS_PER_TRIANGLE a triangle it also turns `clip`, `snap` and the
        all-axes search off (BuildOptions.params says what the build used). None: no build term."""

    builder: str = "binned"
    bins: int = 32
    exact_below: int = 0
    snap: bool = True
    split_axes: str = "all"
    leaf_size: int = 2
    max_depth: Optional[int] = None
    traversal_cost: float = 1.0
    intersection_cost: float = 0.3
    empty_bonus: float = 0.2
    cost_ratio: float = 1.0
    clip: bool = True
    skip: bool = False
    top: str = "sah"
    threads: Optional[int] = None
    lazy: bool = False
    lazy_subtree_size: int = 4096
    lazy_speculative: bool = False
    memory_limit: Optional[int] = None
    duplication_budget: Optional[float] = 16.0
    rays: Optional[int] = None

    def __post_init__(self):
        for name in self.__dataclass_fields__:  # numpy scalars (np.int64(4), np.True_) are the values they hold
            if isinstance(getattr(self, name), np.generic):
                object.__setattr__(self, name, getattr(self, name).item())
        _check_choice("builder", self.builder, BUILDERS)
        _check_choice("top", self.top, TOP_STRATEGIES)
        _check_choice("split_axes", self.split_axes, SPLIT_AXES)
        _check_int("bins", self.bins, 2, 4096)
        _check_int("exact_below", self.exact_below, 0, 1 << 30)
        _check_int("leaf_size", self.leaf_size, 1, 1 << 20)
        if self.max_depth is not None:
            _check_int("max_depth", self.max_depth, 0, DEPTH_LIMIT)
        if self.duplication_budget is not None:
            _check_float("duplication_budget", self.duplication_budget, 1.0, None)
        if self.threads is not None:
            _check_int("threads", self.threads, 1, 1024)
        if self.memory_limit is not None:
            _check_int("memory_limit", self.memory_limit, 1, 1 << 62)  # None, not 0, means no limit
        if self.rays is not None:
            _check_int("rays", self.rays, 1, 1 << 62)
        _check_float("traversal_cost", self.traversal_cost, 0.0, None)
        _check_float("intersection_cost", self.intersection_cost, 0.0, None, low_open=True)
        _check_float("empty_bonus", self.empty_bonus, 0.0, 1.0, high_open=True)
        _check_float("cost_ratio", self.cost_ratio, 0.0, None, low_open=True)
        _check_int("lazy_subtree_size", self.lazy_subtree_size, 1, 1 << 30)
        for name in ("clip", "skip", "snap", "lazy", "lazy_speculative"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"build option {name!r} must be True or False, got {getattr(self, name)!r}")

    def depth_for(self, n_triangles):
        """The maximum depth used for a tree over `n_triangles`."""
        if self.max_depth is not None:
            return self.max_depth
        return min(DEPTH_LIMIT, int(1.2 * log2(max(n_triangles, 1)) + 2))

    def params(self, n_triangles, bounds=None):
        """The numbers the Numba kernels need, as a `BuildParams` tuple (`bounds`: the root box, which
        the `rays` term needs)."""
        refine = self.rays is None or self.rays >= REFINE_RAYS_PER_TRIANGLE * n_triangles
        return BuildParams(
            builder=BUILDERS.index(self.builder),
            bins=self.bins,
            exact_below=self.exact_below,
            snap=self.snap and refine,
            longest_axis_only=self.split_axes == "longest" or not refine,
            leaf_size=self.leaf_size,
            max_depth=self.depth_for(n_triangles),
            traversal_cost=float(self.traversal_cost),
            intersection_cost=float(self.intersection_cost),
            empty_bonus=float(self.empty_bonus),
            cost_ratio=float(self.cost_ratio),
            clip=self.clip and refine,
            skip=self.skip,
            defer_size=self.lazy_subtree_size if self.lazy else 0,
            rays_per_area=_rays_per_area(self.rays, bounds),
            bytes_per_reference=subtree_bytes_per_reference(self.memory_limit, n_triangles),
            duplication_budget=np.inf if self.duplication_budget is None else float(self.duplication_budget),
        )

    def as_dict(self):
        return asdict(self)


class BuildParams(NamedTuple):
    """BuildOptions resolved to plain numbers for the kernels (builder is an index into BUILDERS)."""

    builder: int
    bins: int
    exact_below: int
    snap: bool
    longest_axis_only: bool  # split_axes "longest", or few rays a triangle
    leaf_size: int
    max_depth: int
    traversal_cost: float
    intersection_cost: float
    empty_bonus: float
    cost_ratio: float
    clip: bool
    skip: bool
    defer_size: int  # build_subtree defers nodes of at most this many references (0: none, eager)
    rays_per_area: float  # BuildOptions.rays / the root's half area: rays entering a node per unit of
    # its half area, as the SAH assumes (0: no build term)
    bytes_per_reference: float  # memory_limit's share: bytes a subtree may hold per starting reference (0: none)
    duplication_budget: float  # the root's room (BuildOptions.duplication_budget; inf: none)


def _rays_per_area(rays, bounds):
    if rays is None or bounds is None:
        return 0.0
    area = half_area(np.asarray(bounds, np.float64))
    return float(rays / area) if area > 0.0 and np.isfinite(area) else 0.0


BINNED, EXACT, MEDIAN = 0, 1, 2


def make_options(options):
    """BuildOptions from a dict of keywords, naming any unknown one."""
    known = BuildOptions.__dataclass_fields__
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise TypeError(f"unknown build option(s) {unknown}; known: {sorted(known)}")
    return BuildOptions(**options)


def _check_choice(name, value, choices):
    if not isinstance(value, str) or value not in choices:  # not a list, whose `in` would fail unnamed
        raise ValueError(f"build option {name!r} must be one of {choices}, got {value!r}")


def _check_int(name, value, low, high):
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"build option {name!r} must be an integer, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"build option {name!r} must be in [{low}, {high}], got {value}")


def _check_float(name, value, low, high, low_open=False, high_open=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not isfinite(value):
        raise ValueError(f"build option {name!r} must be a finite number, got {value!r}")
    if low is not None and (value < low or (low_open and value == low)):
        raise ValueError(f"build option {name!r} must be {'>' if low_open else '>='} {low}, got {value}")
    if high is not None and (value > high or (high_open and value == high)):
        raise ValueError(f"build option {name!r} must be {'<' if high_open else '<='} {high}, got {value}")
