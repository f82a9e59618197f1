"""Triangles far larger than the distances they are seen at: a ground plane of half-size up to 1e12.

The watertight test's t is a mean of the vertices' distances along the ray, so it rounds with the
triangle's reach (4e-4 at 1e12), and secondary rays start off a surface by a
bound on the hit point's own rounding, not by one scaled with the triangle's reach
(docs/choices.md#the-hit-distance-on-huge-triangles). References are analytic: the plane z = 0 is met
at t = -oz / dz.
"""
import numpy as np
import pytest

import core
from core.trace.packet_traversal import intersect_packets
from tests.render_scenes import box, floor, hit_mask, look_at

SIZES = [1e3, 1e8, 1e12]


def ground(half):
    """The square [-half, half]^2 at z = 0 in two triangles, float32 as Blender stores it."""
    return floor(0.0, half=half).astype(np.float32)


def t_rounding(half):
    """What t may carry from the ground's reach: 16 float64 roundings of its width. Hits return t in
    float32, whose rounding (the tests' rtol) dominates below a half-size of about 1e12."""
    return 16 * 2.0 ** -53 * (2 * half)


def rays_onto_ground(count=400, seed=3):
    """Rays from 7.5 units above the ground in every downward direction, from steep to grazing (the
    dominant axis in the plane: t's barycentric mean then spans the ground's full reach)."""
    rng = np.random.default_rng(seed)
    o = np.column_stack([rng.uniform(-3, 3, count), rng.uniform(-3, 3, count), np.full(count, 7.5)])
    d = np.column_stack([rng.normal(size=count), rng.normal(size=count), -rng.uniform(0.01, 1.0, count)])
    return o, d


@pytest.mark.parametrize("half", SIZES)
def test_a_huge_ground_is_hit_near_its_analytic_distance(half):
    o, d = rays_onto_ground()
    hits = core.intersect(core.build_kdtree(ground(half)), o, d)
    assert (hits.prim >= 0).all(), f"{(hits.prim < 0).sum()} of {len(o)} rays missed"
    want = -o[:, 2] / d[:, 2]
    np.testing.assert_allclose(hits.t, want, rtol=2.0 ** -22, atol=t_rounding(half))


@pytest.mark.parametrize("half", SIZES)
def test_packets_meet_a_huge_ground_as_single_rays_do(half):
    """Packet lanes compute the single-ray test's t, u, v bit for bit, also where t rounds coarsely."""
    tree = core.build_kdtree(np.concatenate([ground(half), box([0.0, 0.0, 0.5], [0.5, 0.5, 0.5])]).astype(np.float32))
    camera = look_at([4.0, -6.0, 1.0], [0.0, 0.0, 0.3], fov=1.2)
    o, d, _, _ = camera.rays(32, 24)
    got = intersect_packets(tree, o, d, 32)
    want = core.intersect(tree, o, d)
    for name in ("prim", "t", "u", "v"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    on_ground = (want.prim >= 0) & (want.prim < 2)
    assert on_ground.sum() > 200
    np.testing.assert_allclose(want.t[on_ground], -o[on_ground, 2] / d[on_ground, 2], rtol=2.0 ** -22,
                               atol=t_rounding(half))


@pytest.mark.parametrize("half", [1e12])
def test_contact_ao_under_a_cube_does_not_depend_on_the_grounds_size(half):
    """A unit cube on a ground of half-size 10 and on one of half-size `half`: the same AO image within
    noise. The rays' start offset scaled with the hit triangle's reach, so at half-size 1e12 the AO rays
    started about a unit above it and the cube's contact shadow faded."""
    cube = box([0.0, 0.0, 0.5], [0.5, 0.5, 0.5])
    camera = look_at([2.5, -3.0, 1.5], [0.0, 0.0, 0.3], fov=0.9)
    images = [core.render_preview(core.build_kdtree(np.concatenate([ground(h), cube]).astype(np.float32)), camera,
                                  48, 36, samples=64, ao_distance=1.0) for h in (10.0, half)]
    seen = hit_mask(images[0])  # the small ground leaves the horizon empty; the huge one fills it
    assert seen.sum() > 1000 and hit_mask(images[1])[seen].all()
    near, huge = images[0][..., 0][seen], images[1][..., 0][seen]
    assert near.min() <= 0.5  # the contact shadow is there to lose
    assert np.abs(near - huge).mean() < 0.005
