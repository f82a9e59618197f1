"""Bad input: clear errors naming the first bad index or the expected shape, never a crash."""
import numpy as np
import pytest

import core


@pytest.fixture
def tree():
    rng = np.random.default_rng(0)
    return core.build_kdtree(rng.normal(size=(50, 3, 3)))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_triangle_is_named(bad):
    tris = np.zeros((10, 3, 3))
    tris[:, 1, 0] = 1
    tris[:, 2, 1] = 1
    tris[7, 2, 1] = bad
    with pytest.raises(ValueError, match="triangle 7 "):
        core.build_kdtree(tris)


@pytest.mark.parametrize("shape", [(10, 3), (10, 4, 3), (10, 3, 2), (3, 3, 3, 1)])
def test_wrong_triangle_shape(shape):
    with pytest.raises(ValueError, match=r"\(N, 3, 3\)"):
        core.build_kdtree(np.zeros(shape))


def test_wrong_triangle_dtype():
    with pytest.raises(ValueError, match="float32 or float64"):
        core.build_kdtree(np.zeros((2, 3, 3), dtype=complex))


def test_float64_and_float32_give_same_tree():
    rng = np.random.default_rng(1)
    tris = rng.normal(size=(300, 3, 3))
    a, b = core.build_kdtree(tris), core.build_kdtree(tris.astype(np.float32))
    np.testing.assert_array_equal(a.split, b.split)


@pytest.mark.parametrize("which", ["origins", "directions"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_ray_is_named(tree, which, bad):
    o, d = np.zeros((5, 3)), np.ones((5, 3))
    (o if which == "origins" else d)[3, 1] = bad
    with pytest.raises(ValueError, match="ray 3 "):
        core.intersect(tree, o, d)
    with pytest.raises(ValueError, match="ray 3 "):
        core.occluded(tree, o, d)


def test_zero_direction_is_named(tree):
    d = np.ones((4, 3))
    d[2] = [0.0, -0.0, 0.0]
    with pytest.raises(ValueError, match="ray 2 has a zero direction"):
        core.intersect(tree, np.zeros((4, 3)), d)


def test_too_short_direction_is_named(tree):
    d = np.ones((4, 3))
    d[1] = [1e-45, 0.0, -1e-30]
    with pytest.raises(ValueError, match="ray 1 has a direction too short"):
        core.occluded(tree, np.zeros((4, 3)), d)


@pytest.mark.parametrize("o_shape, d_shape", [((5,), (5,)), ((5, 2), (5, 2)), ((5, 3), (4, 3))])
def test_ray_shapes(tree, o_shape, d_shape):
    with pytest.raises(ValueError, match=r"\(R, 3\)"):
        core.intersect(tree, np.zeros(o_shape), np.ones(d_shape))


def test_ray_limits(tree):
    o, d = np.zeros((3, 3)), np.ones((3, 3))
    with pytest.raises(ValueError, match="tmin must be >= 0; ray 1"):
        core.intersect(tree, o, d, tmin=np.array([0.0, -1.0, 0.0]))
    with pytest.raises(ValueError, match="tmax must be a scalar or have shape"):
        core.intersect(tree, o, d, tmax=np.ones(4))
    with pytest.raises(ValueError, match="tmax of ray 0 is NaN"):
        core.intersect(tree, o, d, tmax=np.array([np.nan, 1, 1]))


def test_empty_ray_batch(tree):
    h = core.intersect(tree, np.zeros((0, 3)), np.zeros((0, 3)))
    assert h.t.shape == (0,) and h.prim.dtype == np.int32
