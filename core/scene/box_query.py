"""The instances whose world boxes meet a box, found down the top-level tree (two_level.py) instead of
by testing every instance: what the sample packets (render/sample_packets.py) trace a chunk's rays
through, on scenes of any number of instances.

The top level is a kd-tree over the instances' world boxes whose inner nodes split at a plane (left child
below it) and whose leaves list instances; a box straddling a plane is listed on both sides. The query
walks every child whose side of the plane the box reaches (comparisons that include the plane itself),
so it reaches every leaf that lists an instance whose box overlaps the query box, tests the boxes it
lists, and reports each overlapping instance once: a per-thread stamp marks the instances this query has
already met.
"""
import numpy as np
from numba import njit

from ..trace.array_views import at
from ..trace.layout import LEAF
from ..trace.traversal import STACK_SIZE


@njit(cache=True, inline="always")
def new_box_query(instances):
    """(found, stamps, stack): a thread's buffers for instances_meeting_box on a scene of `instances`
    instances; stamps[instances] counts the queries made with them."""
    return np.empty(instances, np.int32), np.zeros(instances + 1, np.int64), np.empty(STACK_SIZE, np.int32)


@njit(cache=True, inline="always")
def instances_meeting_box(scene, box, query, most):
    """How many instances of the top level have a world box that overlaps `box` (6,) (min x, y, z, max x,
    y, z; touching counts), each written once into query[0] (found), in the order the walk meets them;
    query from new_box_query. The walk stops once it has found more than `most` (returning most + 1)."""
    found, stamps, stack = query
    axis, split, child, count, items = scene.top_axis, scene.top_split, scene.top_child, scene.top_count, scene.top_items
    if items.shape[0] == 0:
        return 0
    last = stamps.shape[0] - 1
    stamps[last] += 1
    stamp = stamps[last]
    n, node, sp = 0, 0, 0
    while True:
        a = axis[at(node)]
        if a < LEAF:
            s, left = split[at(node)], child[at(node)]
            below, above = box[a] <= s, box[a + 3] >= s
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
                if stamps[at(inst)] != stamp:
                    stamps[at(inst)] = stamp
                    if not _overlap(scene.world_boxes, inst, box):
                        continue
                    found[at(n)] = inst
                    n += 1
                    if n > most:
                        return n
        if sp == 0:
            return n
        sp -= 1
        node = stack[at(sp)]


@njit(cache=True, inline="always")
def _overlap(boxes, inst, box):
    for k in range(3):
        if boxes[inst, k] > box[k + 3] or boxes[inst, k + 3] < box[k]:
            return False
    return True
