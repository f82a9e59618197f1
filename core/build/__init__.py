"""The builder: triangles in, a flat SAH kd-tree out (`builder.build_kdtree`, configured by
`options.BuildOptions`).

The parallel top levels split the few large nodes near the root with min-max binning spread over the
threads (top_levels.py; seed 000, Shevtsov et al. 2007, §3-4), then each thread builds whole subtrees
sequentially from pooled memory (subtree.py, pools.py) and the pieces are merged into one set of arrays
(merge.py). The split choice (split_choice.py) is the binned SAH (split_binned.py, sah.py), the exact SAH
event sweep with triangles clipped to the node box (split_exact.py, clipping.py; seed 004 §3-4) or the
spatial median (split_median.py); partition.py sends references left, right or both. A lazy build
leaves small subtrees unbuilt until a ray first reaches them (lazy.py; seed 003).
"""
