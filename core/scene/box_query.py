"""The instances whose world boxes meet a box, found down the top-level tree (two_level.py) instead of
by testing every instance: what the sample packets (render/sample_packets.py) trace a chunk's rays
through, on scenes of any number of instances.

The top level is a kd-tree over the instances' world boxes whose inner nodes split at a plane (left child
below it) and whose leaves list instances; a box straddling a plane is listed on both sides. The query
walks every child whose side of the plane the box reaches (comparisons that include the plane itself),
so it reaches every leaf that lists an instance whose box overlaps the query box, tests the boxes it
lists, and reports each overlapping instance once. Its caller asks for a few (sample_packets.py: at most
16), so the list it keeps is that short, and a repeat is found by scanning it.
"""
import numpy as np
from numba import njit

from ..trace.array_views import at
from ..trace.layout import LEAF
from ..trace.traversal import STACK_SIZE


@njit(cache=True, inline="always")
def new_box_query(most):
    """(found, stack): a thread's buffers for instances_meeting_box with at most `most` instances asked for."""
    return np.empty(most + 1, np.int32), np.empty(STACK_SIZE, np.int32)


@njit(cache=True, inline="always")
def instances_meeting_box(scene, box, query, most, ray_mask):
    """How many instances of the top level seen by rays of kind `ray_mask` (ray_visibility.py) have a
    world box that overlaps `box` (6,) (min x, y, z, max x, y, z; touching counts), each written once
    into query[0] (found), in the order the walk meets them; query from new_box_query(most). The walk
    stops once it has found more than `most` (returning most + 1). A box with NaN reaches every child."""
    found, stack = query
    axis, split, child, count, items = scene.top_axis, scene.top_split, scene.top_child, scene.top_count, scene.top_items
    if items.shape[0] == 0:
        return 0
    n, node, sp = 0, 0, 0
    while True:
        a = axis[at(node)]
        if a < LEAF:
            s, left = split[at(node)], child[at(node)]
            below, above = not box[a] > s, not box[a + 3] < s
            if below and above:
                stack[at(sp)] = left + 1
                sp += 1
            if below or above:
                node = left if below else left + 1
                continue
        else:
            first = child[at(node)]
            for j in range(first, first + count[at(node)]):
                inst = items[at(j)]
                if scene.visibility[inst] & ray_mask != 0 and _overlap(scene.world_boxes, inst, box) \
                        and not _listed(found, n, inst):
                    found[at(n)] = inst
                    n += 1
                    if n > most:
                        return n
        if sp == 0:
            return n
        sp -= 1
        node = stack[at(sp)]


@njit(cache=True, inline="always")
def _listed(found, n, inst):
    """Whether inst is among found[:n] (an instance straddling planes is listed by several leaves)."""
    for k in range(n):
        if found[at(k)] == inst:
            return True
    return False


@njit(cache=True, inline="always")
def _overlap(boxes, inst, box):
    """Whether instance inst's box overlaps `box` (touching counts; NaN counts as overlapping)."""
    for k in range(3):
        if boxes[inst, k] > box[k + 3] or boxes[inst, k + 3] < box[k]:
            return False
    return True
