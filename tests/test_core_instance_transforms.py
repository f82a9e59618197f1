"""core/scene/instance_transforms.py against NumPy's linear algebra and the eight transformed corners."""
import numpy as np
import pytest

from core.scene.instance_transforms import affine_boxes, affine_inverses, relative_determinants
from core.scene.two_level import SINGULAR, invertible, transformed_boxes


def random_affine(n, seed, translation=10.0):
    """Rotations, mirrors, non-uniform scales and shears, with translations up to `translation`."""
    rng = np.random.default_rng(seed)
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = rng.normal(size=(n, 3, 3)) * rng.uniform(1e-3, 1e3, (n, 1, 1))
    m[:, :3, 3] = rng.uniform(-translation, translation, (n, 3))
    m[:, 3, 3] = 1.0
    return m


def corner_boxes(bounds, o2w, origin):
    """The eight corners transformed one by one, then their min and max."""
    corners = np.stack([bounds[:, [3 if i & 1 else 0, 4 if i & 2 else 1, 5 if i & 4 else 2]] for i in range(8)], 1)
    world = np.einsum("ijk,ick->icj", o2w[:, :3, :3], corners) + (o2w[:, :3, 3] - origin)[:, None]
    return np.concatenate([world.min(axis=1), world.max(axis=1)], axis=1)


@pytest.mark.parametrize("translation", [10.0, 1e7])
def test_inverses_match_numpy(translation):
    m = random_affine(2000, 1, translation)
    inv = affine_inverses(m)
    reference = np.linalg.inv(m)[:, :3, :]
    scale = np.abs(reference).max(axis=2, keepdims=True)
    assert np.all(np.abs(inv - reference) <= 1e-9 * scale)
    # the inverse really inverts: points mapped there and back
    p = np.random.default_rng(2).uniform(-5, 5, (2000, 3))
    world = np.einsum("ijk,ik->ij", m[:, :3, :3], p) + m[:, :3, 3]
    back = np.einsum("ijk,ik->ij", inv[:, :, :3], world) + inv[:, :, 3]
    assert np.allclose(back, p, rtol=0, atol=1e-6 * (1 + translation))


def test_relative_determinants_match_numpy_and_flag_singular():
    m = random_affine(500, 3)
    m[::7, :3, 2] = m[::7, :3, 0] * 2.0  # a column repeated: singular
    m[1, :3, :3] = 0.0
    m[2, :3, :3] = np.diag([1e-9, 1.0, 1.0])  # tiny but invertible: a flattened object
    lin = m[:, :3, :3]
    with np.errstate(invalid="ignore"):  # 0 / 0 for the zero matrix
        reference = np.abs(np.linalg.det(lin)) / np.prod(np.linalg.norm(lin, axis=1), axis=1)
    got = relative_determinants(m)
    both = np.isfinite(reference)
    assert np.allclose(got[both], reference[both], rtol=1e-9, atol=1e-15)
    assert not invertible(m)[::7].any() and not invertible(m)[1]
    assert invertible(m)[2]
    assert np.array_equal(invertible(m), reference > SINGULAR)


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (1e6, -3e5, 42.0)])
def test_boxes_equal_the_transformed_corners(origin):
    m = random_affine(3000, 4, 1e6)
    rng = np.random.default_rng(5)
    lo = rng.uniform(-3, 1, (3000, 3))
    bounds = np.concatenate([lo, lo + rng.uniform(0, 4, (3000, 3))], axis=1)
    bounds[:10, 3:] = bounds[:10, :3]  # points and flat boxes
    got = transformed_boxes(bounds, m, origin)
    want = corner_boxes(bounds, m, np.asarray(origin))
    size = np.abs(want).max(axis=1, keepdims=True)
    assert np.all(np.abs(got - want) <= 1e-13 * size)


def test_a_box_with_a_non_finite_end_is_nan_so_compares_empty():
    bounds = np.array([[np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf], [0, 0, 0, 1, 1, 1.0]])
    out = affine_boxes(bounds, random_affine(2, 6), np.zeros(3))
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()
    assert not (out[0, :3] <= out[0, 3:]).any()


def test_empty_inputs():
    assert affine_inverses(np.zeros((0, 4, 4))).shape == (0, 3, 4)
    assert transformed_boxes(np.zeros((0, 6)), np.zeros((0, 4, 4))).shape == (0, 6)
    assert invertible(np.zeros((0, 4, 4))).shape == (0,)
