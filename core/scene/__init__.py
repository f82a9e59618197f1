"""Two-level scenes: one kd-tree per mesh in object space under a top-level kd-tree over the instances'
world boxes (two_level.py; seed 000, Shevtsov et al. 2007, §5), so an object that only moves keeps its
tree. scene_builder.py builds and reuses such scenes across frames (scene_policy.py decides which meshes
get their own tree and which are merged into a world-space soup; instance_signature.py says what
changed); instance_traversal.py carries rays into each instance and through its tree, honouring
Blender's per-object ray visibility (ray_visibility.py); scene_queries.py is the public
`intersect_scene` / `occluded_scene`.
"""
