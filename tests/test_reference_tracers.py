"""Self-check of benchmarks/reference_tracers.py against a float64 brute-force
Möller–Trumbore oracle on a small seeded triangle soup.

The Blender BVHTree tracer runs in a child process: importing ``bpy`` changes
process-wide state (e.g. Numba's threading layer becomes TBB), which must not
leak into other tests in this pytest session.
"""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]

RTOL = 1e-4
EDGE_EPS = 1e-5  # barycentric margin below which float32 tracers may legitimately disagree


def _soup(seed=7, n_tri=300, n_rays=2000):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1.0, 1.0, size=(n_tri, 1, 3))
    tris = centres + rng.uniform(-0.4, 0.4, size=(n_tri, 3, 3))
    tris = tris.astype(np.float32)  # what the tracers see; the oracle uses the same values in float64
    origins = rng.uniform(-1.5, 1.5, size=(n_rays, 3)).astype(np.float32)
    dirs = rng.normal(size=(n_rays, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs *= rng.uniform(0.3, 3.0, size=(n_rays, 1))  # non-unit: t is parametric
    dirs = dirs.astype(np.float32)
    return tris, origins, dirs


def _oracle(tris, origins, dirs):
    """Möller–Trumbore in float64 for every ray/triangle pair.

    Returns (t_closest, prim, ambiguous, all_t) where all_t is (R, N) with inf
    for non-hits and ``ambiguous`` flags rays that graze an edge/vertex, are
    near-parallel to a triangle or start on one: float32 tracers may differ.
    """
    v = tris.astype(np.float64)
    o = origins.astype(np.float64)[:, None, :]
    d = dirs.astype(np.float64)[:, None, :]
    e1 = (v[:, 1] - v[:, 0])[None]
    e2 = (v[:, 2] - v[:, 0])[None]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v[None, :, 0]
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        w = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
    b = 1.0 - u - w
    nonpar = np.abs(det) > 1e-12
    inside = nonpar & (u >= 0) & (w >= 0) & (b >= 0)
    hit = inside & (t >= 0)
    all_t = np.where(hit, t, np.inf)
    prim = np.argmin(all_t, axis=1)
    t_closest = all_t[np.arange(len(prim)), prim]
    prim = np.where(np.isfinite(t_closest), prim, -1)

    margin = np.minimum(np.minimum(np.abs(u), np.abs(w)), np.abs(b))
    area2 = np.linalg.norm(np.cross(e1, e2), axis=-1)
    cos = np.abs(det) / (area2 * np.linalg.norm(d, axis=-1))
    near_edge = nonpar & (margin < EDGE_EPS) & (t > -1e-6)
    grazing = inside & (cos < 1e-4)
    at_origin = inside & (np.abs(t) < 1e-5)
    ambiguous = np.any(near_edge | grazing | at_origin, axis=1)
    return t_closest, prim, ambiguous, all_t


def _check_closest(t, prim, tris, origins, dirs):
    t_ref, prim_ref, ambiguous, all_t = _oracle(tris, origins, dirs)
    ok = ~ambiguous
    assert ok.mean() > 0.95, "test soup too degenerate"
    hit_ref = np.isfinite(t_ref)
    assert 0.2 < hit_ref[ok].mean() < 0.9, "test soup should give both hits and misses"

    assert t.shape == prim.shape == (len(origins),)
    hit = np.isfinite(t)
    np.testing.assert_array_equal(hit[ok], hit_ref[ok])
    np.testing.assert_array_equal(prim[ok] >= 0, hit_ref[ok])
    both = ok & hit_ref
    np.testing.assert_allclose(t[both], t_ref[both], rtol=RTOL)
    # Primitive ids: skip rays whose two nearest hits are too close to order reliably.
    second = np.sort(all_t, axis=1)[:, 1]
    separated = both & (second > t_ref * (1 + 10 * RTOL))
    np.testing.assert_array_equal(prim[separated], prim_ref[separated])
    # The reported primitive really is hit at the reported t.
    rows = np.flatnonzero(both)
    np.testing.assert_allclose(all_t[rows, prim[rows]], t[rows], rtol=RTOL)


def _tmax(origins, dirs, tris, seed=11):
    t_ref, _, _, _ = _oracle(tris, origins, dirs)
    rng = np.random.default_rng(seed)
    finite = np.where(np.isfinite(t_ref), t_ref, 1.0)
    return (finite * rng.uniform(0.0, 2.0, size=len(origins))).astype(np.float32)


def _check_occluded(occ, tris, origins, dirs, tmax):
    _, _, ambiguous, all_t = _oracle(tris, origins, dirs)
    tm = tmax.astype(np.float64)[:, None]
    occ_ref = np.any(all_t <= tm, axis=1)
    near_tmax = np.any(np.abs(all_t - tm) <= RTOL * tm, axis=1)
    ok = ~ambiguous & ~near_tmax
    assert occ.dtype == bool and occ.shape == (len(origins),)
    assert 0.1 < occ_ref[ok].mean() < 0.9
    np.testing.assert_array_equal(occ[ok], occ_ref[ok])


def test_embree_tracer_matches_oracle():
    pytest.importorskip("embreex")
    from benchmarks.reference_tracers import EmbreeTracer

    tris, origins, dirs = _soup()
    tracer = EmbreeTracer(tris)
    assert tracer.build_seconds >= 0
    t, prim = tracer.closest(origins, dirs)
    _check_closest(t, prim, tris, origins, dirs)

    tmax = _tmax(origins, dirs, tris)
    occ = tracer.occluded(origins, dirs, tmax)
    _check_occluded(occ, tris, origins, dirs, tmax)
    # scalar tmax
    occ_scalar = tracer.occluded(origins, dirs, 0.5)
    _check_occluded(occ_scalar, tris, origins, dirs, np.full(len(origins), 0.5, np.float32))


_BVH_CHILD = r"""
import sys
import numpy as np
from benchmarks.reference_tracers import BlenderBVHTracer
z = np.load(sys.argv[1])
tracer = BlenderBVHTracer(z["tris"])
t, prim = tracer.closest(z["origins"], z["dirs"])
occ = tracer.occluded(z["origins"], z["dirs"], z["tmax"])
np.savez(sys.argv[2], t=t, prim=prim, occ=occ)
"""


def test_blender_bvh_tracer_matches_oracle(tmp_path):
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("bpy is not installed")
    tris, origins, dirs = _soup()
    tmax = _tmax(origins, dirs, tris)
    inp, out = tmp_path / "in.npz", tmp_path / "out.npz"
    np.savez(inp, tris=tris, origins=origins, dirs=dirs, tmax=tmax)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run(
        [sys.executable, "-c", _BVH_CHILD, str(inp), str(out)],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    with np.load(out) as r:
        t, prim, occ = r["t"], r["prim"], r["occ"]
    _check_closest(t, prim, tris, origins, dirs)
    _check_occluded(occ, tris, origins, dirs, tmax)
