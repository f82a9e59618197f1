"""KD Preview core: a parallel SAH kd-tree and robust ray queries, in numpy and Numba (never bpy)."""
