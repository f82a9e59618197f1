"""The surface area heuristic: cost of a split, and whether a split beats a leaf.

Splitting box B at `pos` into L and R costs (seed 001 eq. 5; pbrt), bonus = empty_bonus for an empty child:
    C = Ct + Ci * (1 - bonus) * (A(L) * nL + A(R) * nR) / A(B)
A leaf costs Ci * n; a node splits when the best C < cost_ratio * Ci * n (seed 003 §3.5) and, given a
ray count, the split saves its rays more than it costs to build.
"""
from numba import njit

from ..geometry import half_area, half_area_cut


@njit(cache=True, inline="always")
def split_cost(box, inv_area, axis, pos, n_left, n_right, params):
    """SAH cost of splitting `box` at `pos` on `axis` with n_left / n_right references."""
    area_left = half_area_cut(box, axis, box[axis], pos)
    area_right = half_area_cut(box, axis, pos, box[axis + 3])
    return cost_of_areas(area_left, area_right, inv_area, n_left, n_right, params)


@njit(cache=True, inline="always")
def cost_of_areas(area_left, area_right, inv_area, n_left, n_right, params):
    """The SAH cost from the children's half areas (inv_area: 1 / the node's half area)."""
    bonus = params.empty_bonus if (n_left == 0 or n_right == 0) else 0.0
    weighted = (area_left * n_left + area_right * n_right) * inv_area
    return params.traversal_cost + params.intersection_cost * (1.0 - bonus) * weighted


# Building a split costs about this many traversal steps per reference of the node
# (docs/choices.md#build-cost-per-reference).
BUILD_COST_PER_REFERENCE = 4.0


@njit(cache=True, inline="always")
def improves_on_leaf(cost, n, params):
    """The SAH's own test: a split of this cost is cheaper than cost_ratio times a leaf of n."""
    return cost < params.cost_ratio * params.intersection_cost * n


@njit(cache=True, inline="always")
def beats_leaf(cost, n, node_box, params):
    """True when a split of this cost is worth more than keeping `n` references in a leaf. With a
    ray count (params.rays_per_area > 0) the rays expected to enter the node (rays x its area / the
    root's) times the cost saved each must also exceed the build work, BUILD_COST_PER_REFERENCE steps a
    reference (seed 003 §3.5 terminates for time to image); only the node's own split is weighed."""
    if not improves_on_leaf(cost, n, params):
        return False
    leaf = params.intersection_cost * n
    if params.rays_per_area == 0.0:
        return True
    rays = params.rays_per_area * half_area(node_box)
    return (leaf - cost) * rays > BUILD_COST_PER_REFERENCE * params.traversal_cost * n


@njit(cache=True, inline="always")
def valid_position(box, axis, pos):
    """A split plane must lie strictly inside the node, or a child would be the node again."""
    return box[axis] < pos < box[axis + 3]
