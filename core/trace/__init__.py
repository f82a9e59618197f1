"""Ray queries against one kd-tree: the node encoding (layout.py), the `KdTree` arrays and their
statistics (kdtree.py, tree_stats.py), the one front-to-back traversal that serves both closest hit and
any hit (traversal.py; seed 004 §6), the watertight ray-triangle test (triangle_test.py) and the public
`intersect` / `occluded` (queries.py). array_views.py holds the unchecked array views the kernels use.
"""
