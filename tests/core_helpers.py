"""Shared checks for the core tests: builders to run and comparison against the oracles."""
import hashlib

import numpy as np
import pytest

import core
from core import Hits
from tests.oracles import brute_watertight, moller_trumbore

BUILDERS = [
    pytest.param({}, id="binned"),
    pytest.param({"threads": 1}, id="binned-1thread"),
    pytest.param({"clip": False, "exact_below": 64}, id="binned-noclip-exact64"),
    pytest.param({"skip": True, "top": "clustering"}, id="binned-skip-clustering"),
    pytest.param({"builder": "exact"}, id="exact"),
    pytest.param({"builder": "median"}, id="median"),
    pytest.param({"rays": 1000}, id="binned-rays1000"),  # trimmed for few rays (sah.beats_leaf), unrefined
    pytest.param({"rays": 100_000}, id="binned-rays1e5"),  # trimmed, but enough rays to clip and snap
    pytest.param({"split_axes": "longest", "threads": 1}, id="binned-longest-axis"),
]


def assert_same_as_brute(tree, tris, origins, directions, tmin=0.0, tmax=np.inf):
    """Closest hit and any hit agree with the tree-less brute force using the same triangle test."""
    hits = core.intersect(tree, origins, directions, tmin, tmax)
    t, prim, _ = oracle_once(brute_watertight, tris, origins, directions, tmin, tmax)
    hit = prim >= 0
    keep = ~_origin_on_hit_triangle(t, tmin, origins)
    hits, t, prim, hit = Hits(*(a[keep] for a in hits)), t[keep], prim[keep], hit[keep]
    origins, directions = origins[keep], directions[keep]
    tmin, tmax = (np.broadcast_to(v, keep.shape)[keep] for v in (tmin, tmax))
    missed = np.flatnonzero((hits.prim >= 0) != hit)
    assert len(missed) == 0, f"{len(missed)} rays disagree on hit/miss, first {missed[:5]}"
    # t is float32 by contract: compare at that precision (a t of 1e-46 is 0 in float32)
    np.testing.assert_allclose(hits.t[hit], t[hit].astype(np.float32), rtol=1e-6)
    assert np.all(np.isinf(hits.t[~hit])) and np.all(hits.prim[~hit] == -1)
    np.testing.assert_array_equal(core.occluded(tree, origins, directions, tmin, tmax), hit)
    return hits


def _origin_on_hit_triangle(t, tmin, origins):
    """Rays whose brute-force hit lies within rounding of tmin: the origin is on that triangle, the true
    t is tmin itself (outside the open interval) and the triangle test's rounding decides. The tree may
    then rightly never test that triangle: a triangle lying in a split plane sits on one side, and a ray
    starting on the plane visits only the side it leaves to (found by HYPOTHESIS_PROFILE=long, exact
    builder: t = 1.7e-17 for a ray from a vertex of a triangle in the plane x = 0)."""
    scale = 1.0 + np.abs(origins).max(axis=1)
    return np.isfinite(t) & (t - tmin < 1e-12 * scale)


def assert_same_as_moller_trumbore(tree, tris, origins, directions, tmin=0.0, tmax=np.inf):
    """Closest hits agree with an independent Moller-Trumbore brute force (generic rays only)."""
    hits = core.intersect(tree, origins, directions, tmin, tmax)
    t, prim = oracle_once(moller_trumbore, tris, origins, directions, tmin, tmax)
    hit = prim >= 0
    np.testing.assert_array_equal(hits.prim >= 0, hit)
    np.testing.assert_allclose(hits.t[hit], t[hit], rtol=1e-6)
    assert (hits.prim[hit] == prim[hit]).mean() > 0.999  # ties between coincident triangles aside
    return hits


def random_rays(rng, n, extent=2.0):
    return rng.uniform(-extent, extent, (n, 3)), rng.normal(size=(n, 3))


_ORACLE_RESULTS = {}


def oracle_once(oracle, *inputs):
    """oracle(*inputs), computed once per distinct input in a test session: a test parametrized over
    BUILDERS compares each builder's tree with the same triangles and rays, and the brute force took
    most of its time (the closed meshes: ~4.5 s a variant, nine variants). Keyed by the inputs' bytes,
    so any other input computes afresh; each caller gets its own copies."""
    key = hashlib.blake2b(oracle.__qualname__.encode(), digest_size=20)
    for value in inputs:
        array = np.ascontiguousarray(value)
        key.update(f"{array.dtype}{array.shape}".encode())
        key.update(array.tobytes())
    digest = key.digest()
    if digest not in _ORACLE_RESULTS:
        _ORACLE_RESULTS[digest] = oracle(*inputs)
    return tuple(np.copy(part) for part in _ORACLE_RESULTS[digest])
