"""Hypothesis strategies shared by the property tests: coordinates drawn from a coarse grid part of the
time, so that coincident events, planar triangles, shared edges and rays along split planes come up
often, and triangle soups made of them."""
import numpy as np
from hypothesis import strategies as st

grid = st.integers(-4, 4).map(lambda i: i / 2.0)
free = st.floats(-2.0, 2.0, allow_nan=False, width=32)
coordinate = st.one_of(grid, free)


def draw_soup(draw, max_triangles):
    """(N, 3, 3) float64 triangles, 1 <= N <= max_triangles, vertices from `coordinate`."""
    n = draw(st.integers(1, max_triangles))
    return np.array(draw(st.lists(coordinate, min_size=9 * n, max_size=9 * n)), np.float64).reshape(n, 3, 3)
