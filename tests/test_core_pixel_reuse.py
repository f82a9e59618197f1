"""Pixel reuse across frames (core/render/pixel_reuse.py): a frame continued from the last one's pixel state
is the image a full render of that frame gives, and it keeps the pixels nothing changed near.

The reference is an independent full render of the same scene (no previous state). Random animated
scenes exercise moves, deformations, instances added and removed, shared meshes, every light kind and
mode, and adaptive sampling; the conservative ray-versus-box tests are checked against sampled rays."""
import numpy as np
import pytest

import core
from core.render.pixel_reuse import MAX_BOXES, prepared_boxes, segments_touch, surface_rays_touch
from core.render.ray_memo import TRACE, RayMemo, keep_memo_bit, reused_visibility
from core.render.render_kernels import MEMO_BITS
from core.scene.scene_builder import MeshInput, SceneBuilder
from core.render.shading import cosine_direction, offset_origin, sample_light
from tests.render_scenes import look_at

SIZE = (48, 36)


def cube(size=1.0):
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * size
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                  [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, f


GROUND = (np.array([[-12, -12, 0], [12, -12, 0], [12, 12, 0], [-12, 12, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))


def camera():
    m = np.eye(4)
    a = np.radians(55)
    m[:3, :3] = [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    m[:3, 3] = (0, -16, 10)
    return core.Camera(m, np.radians(55))


def moved(x, y, z, angle=0.0):
    m = np.eye(4)
    c, s = np.cos(angle), np.sin(angle)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = (x, y, z)
    return m


class Animation:
    """A ground plane and a few objects (some sharing a mesh) that random frames move, deform, add
    and remove: the meshes, instances and matrices SceneBuilder takes."""

    def __init__(self, rng):
        self.rng = rng
        self.meshes = {"ground": [*GROUND, 0]}
        self.instances = [("ground", np.eye(4))]
        for k in range(rng.integers(2, 5)):
            self.meshes[f"m{k}"] = [*cube(rng.uniform(0.3, 1.2)), 0]
            for _ in range(rng.integers(1, 3)):  # a mesh placed once or twice
                self.instances.append((f"m{k}", self._place()))

    def _place(self):
        return moved(*self.rng.uniform(-7, 7, 2), self.rng.uniform(0.5, 2.5), self.rng.uniform(0, 6))

    def step(self):
        rng, movable = self.rng, range(1, len(self.instances))
        kind = rng.integers(5)
        if kind == 0 and len(movable):  # rigid move of one instance
            i = rng.choice(movable)
            key, m = self.instances[i]
            self.instances[i] = (key, m @ moved(*rng.uniform(-0.6, 0.6, 3), rng.uniform(-0.5, 0.5)))
        elif kind == 1:  # deform one mesh
            key = rng.choice([k for k in self.meshes if k != "ground"])
            v, f, version = self.meshes[key]
            self.meshes[key] = [v + rng.normal(0, 0.1, v.shape), f, version + 1]
        elif kind == 2:  # a new object
            key = f"n{len(self.meshes)}"
            self.meshes[key] = [*cube(rng.uniform(0.2, 0.8)), 0]
            self.instances.append((key, self._place()))
        elif kind == 3 and len(movable) > 1:  # one instance gone
            del self.instances[rng.choice(movable)]
        # kind 4: nothing changes

    def build(self, builder, origin):
        keys = sorted({k for k, _ in self.instances})
        inputs = [MeshInput(k, self.meshes[k][0], self.meshes[k][1], self.meshes[k][2]) for k in keys]
        mesh_of = [keys.index(k) for k, _ in self.instances]
        return builder.build(inputs, mesh_of, np.stack([m for _, m in self.instances]), origin=origin)[0]


def random_lights(rng, offset):
    area = moved(*rng.uniform(-3, 3, 2), 7.0)
    choices = [core.Light.point(rng.uniform(-5, 5, 3) + (0, 0, 8), radius=rng.choice([0.0, 0.7])),
               core.Light.sun(rng.normal(0, 0.4, 3) + (0, 0, -1), angle=rng.choice([0.0, 0.2])),
               core.Light.spot((0, -2, 9), (0, 0.2, -1), spot_size=0.9, radius=0.3),
               core.Light.area(area, size=1.5)]
    picked = rng.choice(len(choices), size=rng.integers(1, 3), replace=False)
    return [choices[i].translated(offset) for i in picked]


def render(scene, cam, previous=None, **settings):
    r = core.PreviewRender(scene, cam, *SIZE, previous=previous, **settings)
    r.step(r.target_samples)
    return r


@pytest.mark.parametrize("layout", ["two_level", "auto", "flat"])
@pytest.mark.parametrize("seed", range(12))
def test_random_animation_matches_full_renders(seed, layout):
    """Each frame continued from the last equals a full render of it, bit for bit, in every layout:
    kept pixels keep their hit points, so the signature must count an object whose triangles were
    rounded differently (soup re-anchored, moved in or out of the soup) as changed."""
    rng = np.random.default_rng(seed)
    anim, cam = Animation(rng), camera()
    origin = cam.position
    settings = dict(mode=rng.choice(["ao", "shadow", "ao+shadow"]), samples=int(rng.choice([4, 8])),
                    ao_distance=float(rng.uniform(0.5, 3.0)), seed=seed,
                    error_target=[None, 0.05][seed % 2], min_samples=4)
    settings["lights"] = random_lights(rng, origin) if settings["mode"] != "ao" else ()
    builder, local_cam, state, reused = SceneBuilder(layout), cam.translated(origin), None, 0
    for _ in range(5):
        scene = anim.build(builder, origin)
        continued = render(scene, local_cam, state, **settings)
        full = render(scene, local_cam, **settings)
        np.testing.assert_array_equal(continued.image(), full.image())
        np.testing.assert_array_equal(continued.sample_counts(), full.sample_counts())
        assert continued.rays_traced <= full.rays_traced
        assert continued.rays_traced + continued.rays_reused >= full.rays_traced
        reused += continued.pixels_reused
        state = continued.pixel_state()
        anim.step()
    assert reused > 0


def test_small_move_keeps_far_pixels_and_traces_few_rays():
    anim = Animation(np.random.default_rng(3))
    cam = camera()
    builder, local = SceneBuilder("two_level"), cam.translated(cam.position)
    first = render(anim.build(builder, cam.position), local, samples=8)
    key, m = anim.instances[1]
    anim.instances[1] = (key, m @ moved(0.2, 0, 0))
    second = render(anim.build(builder, cam.position), local, first.pixel_state(), samples=8)
    assert second.pixels_reused > 0.5 * second.hit_pixels
    assert second.rays_traced < 0.5 * first.rays_traced
    assert second.camera_rays < SIZE[0] * SIZE[1]
    # re-sampled pixels near the cube take last frame's bit for rays that cannot reach it
    assert second.memo_reused.sum() > 0
    assert second.rays_traced + second.rays_reused == first.rays_traced


def test_more_samples_than_memo_bits_still_continue_exactly():
    """Beyond MEMO_BITS rays a pixel keeps no visibility bits: re-sampled pixels trace everything."""
    anim, cam = Animation(np.random.default_rng(4)), camera()
    builder, local = SceneBuilder("two_level"), cam.translated(cam.position)
    settings = dict(samples=MEMO_BITS + 8, mode="ao")
    first = render(anim.build(builder, cam.position), local, **settings)
    assert first.memo.shape[1] == 0
    key, m = anim.instances[1]
    anim.instances[1] = (key, m @ moved(0.2, 0, 0))
    scene = anim.build(builder, cam.position)
    second = render(scene, local, first.pixel_state(), **settings)
    assert second.pixels_reused > 0 and second.memo_reused.sum() == 0
    np.testing.assert_array_equal(second.image(), render(scene, local, **settings).image())


@pytest.mark.parametrize("layout", ["two_level", "flat"])
def test_pixels_that_stopped_early_and_now_need_more_samples_continue_exactly(layout):
    """With an error target, a pixel whose AO rays were all blocked stopped after ~20 samples last frame;
    once one of its two roofs is gone it needs all 48 this frame. Last frame's visibility bits exist only
    for the samples it took: the rays towards the roof that stayed must be traced from sample ~20 on,
    not read from the memo (which would count them as escaping)."""
    def slab(x0, x1, z0, z1):
        v = np.array([[x, y, z] for x in (x0, x1) for y in (-6, 6) for z in (z0, z1)], float)
        return v, cube()[1]
    meshes = [MeshInput("ground", *GROUND, 0), MeshInput("left", *slab(-6, 0, 0.5, 0.6), 0),
              MeshInput("right", *slab(0, 6, 0.5, 0.6), 0)]
    cam = look_at((-0.5, -9.0, 0.25), (-0.5, 0.0, 0.1), fov=0.5)
    settings = dict(samples=48, ao_distance=3.0, error_target=0.05, min_samples=4)
    builder = SceneBuilder(layout)
    first = render(builder.build(meshes, [0, 1, 2], np.stack([np.eye(4)] * 3))[0], cam, **settings)
    scene = builder.build(meshes, [0, 1, 2], np.stack([np.eye(4), np.eye(4), moved(50, 0, 0)]))[0]
    second = render(scene, cam, first.pixel_state(), **settings)
    full = render(scene, cam, **settings)
    np.testing.assert_array_equal(second.image(), full.image())
    np.testing.assert_array_equal(second.sample_counts(), full.sample_counts())
    before, after = first.sample_counts(), full.sample_counts()
    more = (before > 0) & (before < after)
    assert more.sum() >= 20 and second.memo_reused.sum() > 0  # the case: early stops now sampled further


def test_build_scene_of_other_meshes_keeps_no_pixel_of_the_last():
    """build_scene keys meshes by their index: two scenes of different meshes with the same boxes and
    placements must still differ by signature (their contents), or `previous=` keeps the wrong pixels."""
    cam = camera()
    v, f = cube()
    flipped = (v, f[:, ::-1][::2])  # half the faces, the same box
    first = render(core.build_scene([GROUND, (v, f)], [0, 1], np.stack([np.eye(4), moved(0, 0, 1)])), cam, samples=2)
    other = core.build_scene([GROUND, flipped], [0, 1], np.stack([np.eye(4), moved(0, 0, 1)]))
    continued = render(other, cam, previous=first.pixel_state(), samples=2)
    np.testing.assert_array_equal(continued.image(), render(other, cam, samples=2).image())
    assert not np.array_equal(continued.image(), first.image())


def test_build_scene_names_a_mesh_that_is_not_a_pair():
    for bad, what in ((np.zeros((3, 3)), "ndarray"), (None, "NoneType"), ({0: 1}, "dict"),
                      ((np.zeros((3, 3)), np.zeros((1, 3), int), 7), "a tuple of length 3")):
        with pytest.raises(ValueError, match=rf"meshes\[1\] must be a \(vertices, triangles\) pair or a "
                                             rf"core.MeshInput, got {what}"):
            core.build_scene([GROUND, bad], [0], np.eye(4)[None])


def test_unchanged_frame_traces_nothing():
    anim, cam = Animation(np.random.default_rng(5)), camera()
    builder, local = SceneBuilder(), cam.translated(cam.position)
    first = render(anim.build(builder, cam.position), local, samples=4)
    second = core.PreviewRender(anim.build(builder, cam.position), local, *SIZE, samples=4,
                                previous=first.pixel_state())
    assert second.done and second.rays_traced == 0 and second.pixels_reused == first.hit_pixels
    np.testing.assert_array_equal(second.image(), first.image())


@pytest.mark.parametrize("change", ["camera", "light", "samples", "ao_distance", "mode"])
def test_other_settings_render_from_scratch(change):
    anim, cam = Animation(np.random.default_rng(7)), camera()
    builder = SceneBuilder()
    light = core.Light.point((1, 2, 9))
    settings = dict(samples=4, mode="ao+shadow", lights=[light.translated(cam.position)])
    first = render(anim.build(builder, cam.position), cam.translated(cam.position), **settings)
    if change == "camera":  # a moved camera moves the origin too: nothing can be kept
        m = cam.matrix_world.copy()
        m[0, 3] += 0.1
        cam = core.Camera(m, cam.fov)
    elif change == "light":
        settings["lights"] = [core.Light.point((1, 2, 9.5)).translated(cam.position)]
    elif change == "mode":
        settings["mode"] = "ao"
    else:
        settings[change] = {"samples": 8, "ao_distance": 2.0}[change]
    scene = anim.build(builder, cam.position)
    second = render(scene, cam.translated(cam.position), first.pixel_state(), **settings)
    assert second.pixels_reused == 0
    np.testing.assert_array_equal(second.image(), render(scene, cam.translated(cam.position), **settings).image())


def test_unfinished_render_has_no_state():
    anim, cam = Animation(np.random.default_rng(1)), camera()
    r = core.PreviewRender(anim.build(SceneBuilder(), cam.position), cam.translated(cam.position), *SIZE, samples=4)
    r.step(2)
    assert r.pixel_state() is None


def test_object_leaving_the_soup_keeps_no_stale_pixels():
    """A cube rises off a floor (layout auto: all three objects start in the soup; the cube leaves it
    when it first moves). Re-centring the soup on the floor and wall would re-round the floor by a
    float32 ulp and leave kept ray starts under it, so from the second move on kept pixels near the
    cube would see the floor itself and turn dark (up to 0.5 of AO)."""
    floor = (np.array([[-6, -6, 0], [6, -6, 0], [6, 6, 0], [-6, 6, 0]], float) + (0.1, 0.3, 0.0), GROUND[1])
    wall = (np.array([[-6, 4, 0], [6, 4, 0], [6, 4, 3], [-6, 4, 3]], float), GROUND[1])
    meshes = [MeshInput("floor", *floor, 0), MeshInput("wall", *wall, 0), MeshInput("cube", *cube(0.3), 0)]
    cam = camera()
    builder, local, state = SceneBuilder("auto"), cam.translated(cam.position), None
    for z in (0.0, 0.3125, 1.0, 1.6875, 2.0):
        matrices = np.stack([np.eye(4), np.eye(4), moved(0.7, 1.3, z)])
        scene, _ = builder.build(meshes, [0, 1, 2], matrices, origin=cam.position)
        continued = render(scene, local, state, samples=32, ao_distance=1.0)
        np.testing.assert_array_equal(continued.image(), render(scene, local, samples=32, ao_distance=1.0).image())
        state = continued.pixel_state()
    assert continued.pixels_reused > 0


@pytest.mark.parametrize("change", ["removed", "moved"])
def test_a_far_soup_member_that_vanishes_leaves_no_stale_pixels(change):
    """A 1-unit cube 300 units from the centre of a 1,000-unit ground, both in the soup, stored in
    float32 relative to the ground's centre: the cube's front face is rounded by up to 1.5e-5 towards
    the camera 4 units away, more than the changed box's pad for rounding relative to the camera
    (~6e-6). When the cube vanishes or moves away, its pixels' camera segments must not end short of
    its padded box and keep last frame's hits on it (484 of 1,778 pixels would show the cube).
    The ground's x offset is the one of [0.1, 0.2] that rounds the face furthest towards the camera."""
    x = 300.0
    offset = min(np.linspace(0.1, 0.2, 4001),
                 key=lambda o: float(np.float32(x - np.float32(o))) - (x - float(np.float32(o))))
    ground = (np.array([[-500, -50, 0], [500, -50, 0], [500, 50, 0], [-500, 50, 0]], float), GROUND[1])
    meshes = [MeshInput("ground", *ground, 0), MeshInput("cube", *cube(0.5), 0)]
    cam = look_at((x - 4.0, 0.0, 0.5), (x + 1.0, 0.0, 0.5))
    local = cam.translated(cam.position)
    builder = SceneBuilder("auto")
    first = [moved(offset, 0, 0), moved(x + 0.5, 0, 0.5)]
    scene, _ = builder.build(meshes, [0, 1], np.stack(first), origin=cam.position)
    state = render(scene, local, samples=4, ao_distance=1.0).pixel_state()
    if change == "removed":
        scene, _ = builder.build(meshes, [0], first[0][None], origin=cam.position)
    else:
        scene, _ = builder.build(meshes, [0, 1], np.stack([first[0], moved(x + 0.5, 3.0, 0.5)]), origin=cam.position)
    continued = render(scene, local, state, samples=4, ao_distance=1.0)
    np.testing.assert_array_equal(continued.image(), render(scene, local, samples=4, ao_distance=1.0).image())


def test_soup_anchor_stays_while_inside_and_re_anchoring_marks_members_changed():
    """The soup keeps its anchor when a member leaves but the anchor is still inside the rest's box
    (their rows, hence their pixels, stay); once it falls outside, the rest is re-centred, hence
    re-rounded, and counts as changed."""
    from core.scene.instance_signature import changed_boxes
    small = [MeshInput(f"c{k}", *cube(0.5), 0) for k in range(3)]
    builder = SceneBuilder("auto")
    place = [moved(-4, 0, 1), moved(0, 0, 1), moved(4, 0, 1)]  # all three in the soup, anchor (0, 0, 1)
    first, _ = builder.build(small, [0, 1, 2], np.stack(place))
    place[2] = moved(4, 0, 2)  # c2 leaves; the anchor is inside c0 and c1's box
    second, _ = builder.build(small, [0, 1, 2], np.stack(place))
    boxes = changed_boxes(first.signature, second.signature)
    assert len(boxes) == 2 and (boxes[:, 0] > 3).all()  # only c2, at its old and new place
    place[1] = moved(0, 0, 2)  # c1 leaves; the anchor is outside c0's box: c0 is re-rounded
    third, _ = builder.build(small, [0, 1, 2], np.stack(place))
    boxes = changed_boxes(second.signature, third.signature)
    assert len(boxes) == 4 and (boxes[:, 0] < -4.4).sum() == 2  # c1 twice, and c0 twice
    # c0's box, grown by its float32 rounding relative to the anchor (at most 2^-23 of 4.5 + 0.5)
    np.testing.assert_allclose(third.signature.boxes[0], [-4.5, -0.5, 0.5, -3.5, 0.5, 1.5], rtol=0, atol=1e-6)


def test_lazy_scene_continues_exactly():
    anim, cam = Animation(np.random.default_rng(2)), camera()
    builder, local, state = SceneBuilder("flat", lazy=True, lazy_subtree_size=8), cam.translated(cam.position), None
    eager = SceneBuilder("flat")
    for _ in range(3):
        continued = render(anim.build(builder, cam.position), local, state, samples=4)
        full = render(anim.build(eager, cam.position), local, samples=4)
        np.testing.assert_array_equal(continued.image(), full.image())
        state = continued.pixel_state()
        key, m = anim.instances[1]
        anim.instances[1] = (key, m @ moved(0.3, 0, 0))


def _segments_meet_box(o, dirs, lengths, box):
    """Reference: sample each segment o + t d, t in [0, length], densely and test the points against
    the box shrunk a little (so the kernel's conservative answer must include every case found)."""
    t = np.linspace(0.0, 1.0, 1001)[None, :, None] * lengths[:, None, None]
    pts = o + t * dirs[:, None, :]
    inside = ((pts >= box[:3] + 1e-9) & (pts <= box[3:] - 1e-9)).all(axis=2)
    return inside.any(axis=1)


def test_segment_box_test_is_exact_on_axis_aligned_rays():
    box = np.array([[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]])
    origins = np.array([[0.5, 0.5, -1.0], [1.0, 0.5, -1.0], [1.0 + 1e-9, 0.5, -1.0], [0.5, 0.5, -1.0],
                        [-1.0, -1.0, 0.5]])
    directions = np.array([[0.0, 0.0, 1.0], [0.0, -0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 1.0, 0.0]])
    inside = segments_touch(origins, directions, np.zeros(5), np.full(5, np.inf), box)
    np.testing.assert_array_equal(inside, [True, True, False, False, True])
    short = segments_touch(origins[:1], directions[:1], np.zeros(1), np.full(1, 0.99), box)
    assert not short[0]


WIDE_LIGHTS = [core.Light.point((1, 2, 8), radius=2.0), core.Light.sun((0.3, -0.2, -1), angle=0.6),
               core.Light.spot((-2, 1, 7), (0.2, 0, -1), spot_size=1.2, radius=1.5),
               core.Light.area(moved(2, -1, 6, 0.4), shape="RECTANGLE", size=3.0, size_y=1.0)]


@pytest.mark.parametrize("light", range(len(WIDE_LIGHTS)))
def test_surface_ray_test_covers_every_sampled_ray(light):
    """Every AO or shadow ray the renderer can trace from a point (sampled with the renderer's own
    samplers) that meets a box is flagged by the conservative test. Boxes are small and placed near
    the rays' paths, off their axis by up to the light's size, where a test ignoring it would fail."""
    rng = np.random.default_rng(light)
    lights = core.render.lights.pack_lights([WIDE_LIGHTS[light]])
    n, found = np.array([0.0, 0.0, 1.0]), 0
    for _ in range(120):
        p = rng.uniform(-4, 4, 3) * (1, 1, 0)
        o = np.array(offset_origin(p, n, 10.0))
        d, dist, mask = sample_light(lights[0], tuple(o), *rng.random(2))
        d = np.array(d)
        along = rng.uniform(0.1, 0.9) * min(dist, 8.0)
        centre = o + along * d + rng.normal(0, 0.3, 3)
        box = np.concatenate([centre - 0.15, centre + 0.15])[None]
        ao_distance = rng.uniform(0.2, 3.0)
        flagged = surface_rays_touch(o[None], ao_distance, lights, box)[0]
        dirs, lengths, lit = np.empty((80, 3)), np.empty(80), np.empty(80, bool)
        for k, (u1, u2) in enumerate(rng.random((80, 2))):
            dirs[k], dist, mask = sample_light(lights[0], tuple(o), u1, u2)
            lengths[k], lit[k] = min(dist, 40.0), mask > 0
        hit_light = _segments_meet_box(o, dirs, lengths, box[0]) & lit
        for k, (u1, u2) in enumerate(rng.random((80, 2))):
            cosine_direction(n, u1, u2, dirs[k])
        hit_ao = _segments_meet_box(o, dirs, np.full(80, ao_distance), box[0])
        assert flagged or not (hit_ao.any() or hit_light.any())
        found += hit_light.any()
    assert found > 10  # the placement does put boxes on sampled shadow rays


def test_many_boxes_merge_into_a_cover():
    rng = np.random.default_rng(0)
    lo = rng.uniform(-10, 10, (500, 3))
    boxes = np.concatenate([lo, lo + rng.uniform(0, 1, (500, 3))], axis=1)
    merged = prepared_boxes(boxes)
    assert len(merged) == MAX_BOXES
    covered = [((merged[:, :3] <= b[:3]) & (merged[:, 3:] >= b[3:])).all(axis=1).any() for b in boxes]
    assert all(covered)


def test_memo_answers_clear_and_occluded_rays_without_a_trace():
    """ray_memo.reused_visibility: a ray pixel 0 traced last frame (bit < known) that meets no changed
    box takes its kept bit, clear (-1) as well as occluded (0), counted as reused; a ray beyond `known`
    or meeting a changed box is left to be traced (TRACE), uncounted. A clear answer must not be taken
    for "trace it" (-1 is also the traversal's miss)."""
    bits = np.zeros((1, 2), np.uint8)
    keep_memo_bit(bits, 0, 3, True)
    memo = RayMemo(bits, np.array([9]), np.zeros((0, 6)), np.zeros(1, np.int64), np.zeros(1, np.int64),
                   np.full((1, 0), -1, np.int8), np.empty((0, 0)), np.zeros(1, np.int64))
    o, d = np.zeros(3), np.array([0.0, 0.0, 1.0])
    assert reused_visibility(memo, 0, 2, o, d, 1.0) == -1
    assert reused_visibility(memo, 0, 3, o, d, 1.0) == 0
    assert memo.reused[0] == 2
    assert reused_visibility(memo, 0, 9, o, d, 1.0) == TRACE  # not traced last frame
    changed = memo._replace(boxes=prepared_boxes([[-1.0, -1.0, 0.5, 1.0, 1.0, 0.6]]))
    assert reused_visibility(changed, 0, 2, o, d, 1.0) == TRACE  # the ray meets a changed box
    assert reused_visibility(changed, 0, 2, o, -d, 1.0) == -1  # this one does not
    assert memo.reused[0] == 3
