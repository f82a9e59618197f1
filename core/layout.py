"""The flat tree layout shared by builder, merge, statistics and traversal.

Node i is four parallel arrays (structure of arrays, seed 004 §4.7):
    axis[i]   int8     0, 1, 2 for an inner node split on x, y, z; LEAF for a leaf
    split[i]  float32  the split position (inner nodes)
    child[i]  int32    inner: index of the left child, the right child is child[i] + 1;
                       leaf: offset of its first triangle index in `leaf_prims`
    count[i]  int32    leaf: number of triangles (0 for an empty leaf); inner: 0
Children are allocated in pairs, so one index names both (13 bytes a node in all).
"""
LEAF = 3
