"""The camera hits' frames (core/render/hit_frames.py): points on their triangles' planes, unit normals
facing the ray, ray starts off the surface along them; the same bits in any lane of a block."""
import math
import platform
import re

import numba
import numpy as np
import pytest

from core.render import hit_frames
from core.render.shading import OFFSET_RELATIVE
from core.scene.scene_queries import trace_scene_all
from core.scene.two_level import build_two_level
from core import build_kdtree
from tests.meshes import icosphere, mesh_triangles


def _instanced_hits(seed):
    """Hits of random rays on spheres under random affine matrices (rotation, uneven scale, shear, a
    mirror, far translations): (scene, origins, directions, t, inst, prim, hit rows)."""
    rng = np.random.default_rng(seed)
    tree = build_kdtree(mesh_triangles(*icosphere(2)))
    matrices = []
    for k in range(5):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        m = np.eye(4)
        m[:3, :3] = q @ np.diag(rng.uniform(0.2, 3.0, 3)) @ (np.eye(3) + 0.3 * rng.normal(size=(3, 3)))
        m[:3, 3] = rng.uniform(-4, 4, 3) + (1e4 * (k == 4), 0.0, 0.0)
        matrices.append(m)
    matrices[1][:3, 0] *= -1.0  # a mirror
    scene = build_two_level([tree], np.zeros(5, np.int32), np.stack(matrices))
    targets = np.array([m[:3, 3] for m in matrices])[rng.integers(0, 5, 3000)] + rng.normal(0, 0.8, (3000, 3))
    origins = targets + rng.normal(0, 1, (3000, 3)) * 20.0
    directions = targets - origins
    t, inst, prim = trace_scene_all(scene, origins, directions, np.zeros(3000), np.full(3000, np.inf), False, None)[:3]
    return scene, origins, directions, t, inst, prim, np.flatnonzero(prim >= 0)


def _frames(scene, origins, directions, t, inst, prim, hit):
    out = [np.empty((len(hit), 3)) for _ in range(3)]
    hit_frames.surface_frames(scene.arrays, origins, directions, t, inst, prim, hit, *out)
    return out


@pytest.mark.parametrize("seed", range(3))
def test_frames_match_their_definition_under_affine_instances(seed):
    """Against NumPy: the point is o + t d moved onto the triangle's plane, the normal is the world
    normal (inverse transpose) turned against the ray, the start lies OFFSET_RELATIVE times at least
    sum |n_k p_k| along it."""
    scene, origins, directions, t, inst, prim, hit = _instanced_hits(seed)
    assert len(hit) > 1000 and len(set(inst[hit])) == 5
    points, normals, starts = _frames(scene, origins, directions, t, inst, prim, hit)
    tris = scene.arrays.triangles[prim[hit]].astype(np.float64)
    to_world = np.linalg.inv(scene.arrays.world_to_object[inst[hit]][:, :, :3])
    corners = np.einsum("nij,nkj->nki", to_world, tris - scene.arrays.world_to_object[inst[hit]][:, None, :, 3])
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    normal *= -np.sign(np.einsum("ij,ij->i", normal, directions[hit]))[:, None]
    np.testing.assert_allclose(normals, normal, atol=1e-9)
    size = np.abs(corners).max(axis=(1, 2))
    assert np.all(np.abs(np.einsum("ij,ij->i", points - corners[:, 0], normal)) <= 1e-12 * size)
    np.testing.assert_allclose(points, origins[hit] + t[hit, None] * directions[hit], rtol=0, atol=1e-9 * size.max())
    step = np.einsum("ij,ij->i", starts - points, normals)
    np.testing.assert_allclose(starts - points, step[:, None] * normals, rtol=0, atol=1e-3 * step.max())
    assert np.all(step >= OFFSET_RELATIVE * np.abs(normals * points).sum(axis=1) * (1 - 1e-12))


def _per_hit_frame(o, d, t, tri, a):
    """One hit's frame in plain Python floats (IEEE doubles), operation by operation as the per-hit code
    the lanes replaced computed it: the reference the lanes must equal bit for bit."""
    tri = [[float(x) for x in row] for row in tri]
    e1 = [tri[1][k] - tri[0][k] for k in range(3)]
    e2 = [tri[2][k] - tri[0][k] for k in range(3)]
    nx, ny, nz = e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]
    p = [o[k] + t * d[k] for k in range(3)]
    q = [a[k][0] * p[0] + a[k][1] * p[1] + a[k][2] * p[2] + a[k][3] for k in range(3)]
    nn = nx * nx + ny * ny + nz * nz
    above = ((q[0] - tri[0][0]) * nx + (q[1] - tri[0][1]) * ny + (q[2] - tri[0][2]) * nz) / nn
    c0 = (a[1][1] * a[2][2] - a[1][2] * a[2][1], a[1][2] * a[2][0] - a[1][0] * a[2][2], a[1][0] * a[2][1] - a[1][1] * a[2][0])
    c1 = (a[0][2] * a[2][1] - a[0][1] * a[2][2], a[0][0] * a[2][2] - a[0][2] * a[2][0], a[0][1] * a[2][0] - a[0][0] * a[2][1])
    c2 = (a[0][1] * a[1][2] - a[0][2] * a[1][1], a[0][2] * a[1][0] - a[0][0] * a[1][2], a[0][0] * a[1][1] - a[0][1] * a[1][0])
    det = a[0][0] * c0[0] + a[0][1] * c0[1] + a[0][2] * c0[2]
    u = (above * nx, above * ny, above * nz)
    move = [(c0[k] * u[0] + c1[k] * u[1] + c2[k] * u[2]) / det for k in range(3)]
    p = [p[k] - move[k] for k in range(3)]
    moved = abs(move[0]) + abs(move[1]) + abs(move[2])
    w = [a[0][k] * nx + a[1][k] * ny + a[2][k] * nz for k in range(3)]
    length = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    n = [w[k] / length for k in range(3)]
    if n[0] * d[0] + n[1] * d[1] + n[2] * d[2] > 0.0:
        n = [-x for x in n]
    world = abs(n[0] * p[0]) + abs(n[1] * p[1]) + abs(n[2] * p[2])
    q = [a[k][0] * p[0] + a[k][1] * p[1] + a[k][2] * p[2] + a[k][3] for k in range(3)]
    along = sum(abs((nx, ny, nz)[k]) * (abs(a[k][0] * p[0]) + abs(a[k][1] * p[1]) + abs(a[k][2] * p[2]) + abs(a[k][3])
                                         + abs(q[k] - tri[0][k])) for k in range(3))
    step = max(world, along / length, moved) * OFFSET_RELATIVE
    return p, n, [p[k] + n[k] * step for k in range(3)]


def test_the_lanes_equal_the_per_hit_arithmetic_bit_for_bit():
    """Images must not move when the pass changes shape: every hit's point, normal and start equal the
    per-hit arithmetic (_per_hit_frame) in every bit, under affine instances."""
    scene, origins, directions, t, inst, prim, hit = _instanced_hits(11)
    frames = _frames(scene, origins, directions, t, inst, prim, hit)
    arrays = scene.arrays
    for row, r in enumerate(hit):
        tri = arrays.triangles[arrays.tri_start[arrays.mesh_of[inst[r]]] + prim[r]]
        a = [[float(x) for x in line] for line in arrays.world_to_object[inst[r]]]
        expected = _per_hit_frame([float(x) for x in origins[r]], [float(x) for x in directions[r]], float(t[r]), tri, a)
        for got, want in zip(frames, expected):
            assert np.array_equal(got[row].view(np.int64), np.array(want).view(np.int64)), (row, got[row], want)


def test_a_hit_has_the_same_bits_in_every_lane():
    """The vectorised body and the scalar remainder of a block, and any lane of either, give one hit
    the same frame: every hit alone, and the hits shuffled, against all in order."""
    scene, origins, directions, t, inst, prim, hit = _instanced_hits(7)
    whole = _frames(scene, origins, directions, t, inst, prim, hit)
    order = np.random.default_rng(1).permutation(len(hit))
    shuffled = _frames(scene, origins, directions, t, inst, prim, hit[order])
    for a, b in zip(whole, shuffled):
        assert np.array_equal(a[order].view(np.int64), b.view(np.int64))
    for k in range(0, len(hit), 97):
        alone = _frames(scene, origins, directions, t, inst, prim, hit[k:k + 1])
        for a, b in zip(whole, alone):
            assert np.array_equal(a[k].view(np.int64), b[0].view(np.int64))


def test_a_degenerate_triangle_keeps_its_point_and_spoils_no_other_lane():
    """A made-up hit on a zero-area triangle (the triangle test never reports one) among 40 in one block
    (the vectorised body, not only the scalar remainder) keeps o + t d (its normal is undefined), and
    every other lane is exact: the floor z = 0, its normal +z, no offset at exact points."""
    tree = build_kdtree(np.array([[[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32))
    flat = build_two_level([tree], np.zeros(1, np.int32), np.eye(4)[None])
    n = 40
    o = np.stack([0.25 + np.arange(n) / 128, np.full(n, 0.125), np.full(n, 3.0)], axis=1)
    d = np.tile([0.0, 0.0, -1.0], (n, 1))
    prim = np.ones(n, np.int32)
    prim[5] = 0
    points, normals, starts = _frames(flat, o, d, np.full(n, 3.0), np.zeros(n, np.int32), prim, np.arange(n))
    assert np.array_equal(points[5], o[5] + 3.0 * d[5])
    good = np.arange(n) != 5
    assert np.array_equal(points[good], o[good] * (1, 1, 0)) and (normals[good] == (0.0, 0.0, 1.0)).all()
    assert np.array_equal(starts[good], points[good])  # exact points: their error scale, so their offset, is 0


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="reads x86-64 machine code")
def test_the_lane_loop_is_vectorised():
    """The block's arithmetic runs on whole registers (packed divides and square roots): a branch or a
    Python-model division check in the lane loop would leave it scalar, and the pass several times slower."""
    options = {k: v for k, v in hit_frames._frames_block.targetoptions.items() if k not in ("cache", "nopython")}
    block = numba.njit(**options)(hit_frames._frames_block.py_func)  # a fresh, uncached copy to read
    scene, origins, directions, t, inst, prim, hit = _instanced_hits(0)
    frames = tuple(np.empty((len(hit), 3)) for _ in range(3))
    block(scene.arrays, (origins, directions, t, inst, prim), hit, frames, 0, min(len(hit), hit_frames.BLOCK))
    asm = block.inspect_asm(block.signatures[0])
    assert re.search(r"v?divpd\s", asm) and re.search(r"v?sqrtpd\s", asm)
