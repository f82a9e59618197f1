"""The float32 node step's outward rounding (traversal._down32, _up32) and per-ray constants
(traversal.ray_constants32) against exact float64 comparisons."""
import numpy as np
import pytest

from core.trace.traversal import RAY32, _down32, _up32, ray_constants32

EDGES = [0.0, -0.0, 1.0, -1.0, 1e-45, -1e-45, 5e-324, -5e-324, 1e-40, -1e-40, 3.3e38, 3.5e38, -3.5e38, 1e300,
         -1e300, np.inf, -np.inf, 0.1, 1 / 3, 123456.789]


def test_rounding_brackets_every_value():
    rng = np.random.default_rng(7)
    values = np.concatenate([EDGES, rng.standard_normal(20000) * 10.0 ** rng.integers(-50, 45, 20000)])
    for t in values:
        lo, hi = _down32(t), _up32(t)
        assert np.float32(lo) == lo and np.float32(hi) == hi  # float32 values (Numba boxes them as floats)
        assert np.float64(lo) <= t <= np.float64(hi), t
        if abs(t) < 1e38 and abs(t) > 1e-37:  # normal range: within two float32 ulps
            assert np.float64(hi) - np.float64(lo) <= 4 * np.spacing(np.float32(abs(t))), t


@pytest.mark.parametrize("o, d", [((0.0, 1.0, -2.0), (1.0, -0.0, 0.0)), ((1e30, 0.0, 0.0), (-1.0, 1.0, 1.0)),
                                  ((0.0, 0.0, 0.0), (1e-45, 1.0, 1.0)), ((0.5, 0.5, 0.5), (0.3, -0.7, 1e300)),
                                  ((0.3, -1.7, 0.9), (0.37, -0.61, 1e-3)), ((1.9, 1e-7, -3.0), (-1e-5, 2.5, 7.0))])
def test_constants_bound_the_plane_distance(o, d):
    """For planes p, the float32 distance widened by err holds the exact (p - o) / d (rationals), and no
    constant is NaN; zero components get 1 / d = -inf and no widening, unsafe rays an infinite one."""
    from fractions import Fraction
    box = np.array([-2.0, -2.0, -2.0, 2.0, 2.0, 2.0], np.float32)
    o, d = np.array(o), np.array(d)
    inv = np.array([1.0 / x if x != 0.0 else 0.0 for x in d])
    ray32 = np.empty(RAY32, np.float32)
    ray_constants32(box, o, d, inv, ray32)
    assert not np.isnan(ray32).any()
    for k in range(3):
        if d[k] == 0.0:
            assert ray32[3 + k] == -np.inf and ray32[6 + k] == 0.0 and ray32[9 + k] == 0.0
            continue
        for p in np.linspace(-2.0, 2.0, 41, dtype=np.float32):
            ts = (p - ray32[k]) * ray32[3 + k]
            err = ray32[6 + k] * abs(p) + ray32[9 + k]
            exact = (Fraction(float(p)) - Fraction(o[k])) / Fraction(d[k])
            if err == np.inf:  # an overflow-prone ray (SAFE32): every plane straddled
                continue
            assert Fraction(float(ts - err)) <= exact <= Fraction(float(ts + err))
