"""The renderer's sample rays in packets (core.render.sample_packets): a render in batches of PACKED_BATCH
or more samples, which trace AO rays and the rays towards lights with extent in packets, gives the image,
sample counts, ray counts and memo bits of the same render in steps of one sample, whose kernel traces
every ray alone through the two-level traversal. Scenes: one instance, the same with a second one far
away, and several instances that occlude one another (mirrored, rotated, one that shadow rays do not see,
one out of reach). Cases: a soup, a lattice (triangles in split planes, points on them), a rotated and
scaled instance far from the origin, AO, shadows and both with lights of every kind, with and without
extent, a chunk of samples and a short one reached in one step or several, adaptive sampling, a lazy
tree."""
import numpy as np
import pytest

import core
from core.render.render_kernels import PACKED_BATCH
from core.scene.ray_visibility import CAMERA_RAYS, SHADOW_RAYS
from core.scene.two_level import build_two_level
from tests.meshes import lattice, random_soup
from tests.render_scenes import look_at

FAR = 1e4  # the second instance's distance: beyond every AO ray
ALONE = 0.03  # most of a packed render's rays that may fall to single rays (assert_same_render)


def with_far_instance(tree, matrix):
    """The scene [tree at matrix] and the same with a small soup FAR away (two instances, one beyond every
    AO ray's reach)."""
    far = core.build_kdtree(random_soup(np.random.default_rng(1), 20))
    away = np.eye(4)
    away[:3, 3] = matrix[:3, 3] + FAR
    one = build_two_level([tree], [0], matrix[None])
    two = build_two_level([tree, far], [0, 1], np.stack([matrix, away]))
    return one, two


def rendered(scene, camera, steps, **settings):
    render = core.PreviewRender(scene, camera, 40, 32, **settings)
    for n in steps:
        render.step(n)
    return render


def assert_same_render(scene, camera, steps, alone_below=None, **settings):
    """The render in `steps` equals the one in steps of one sample (no packets); returns its image. With
    `alone_below`, the packets answered all but that share of the rays (the rest fell to single rays,
    which give the same answers: only this count shows them)."""
    a, b = rendered(scene, camera, steps, **settings), rendered(scene, camera, (1,) * sum(steps), **settings)
    np.testing.assert_array_equal(a.image(), b.image())
    np.testing.assert_array_equal(a.sample_counts(), b.sample_counts())
    np.testing.assert_array_equal(a.memo, b.memo)  # every ray's visibility bit, for the next frame
    assert a.rays_traced == b.rays_traced
    if alone_below is not None:
        assert a.rays_alone < alone_below * a.rays_traced, (a.rays_alone, a.rays_traced)
    return a.image()


def shadowed_share(image):
    """The share of hit pixels below the brightest (some light rays met something)."""
    hit = image[..., 3] > 0
    grey = image[..., :3].mean(axis=2)[hit]
    return float((grey < 0.999 * grey.max()).mean())


def occluded_share(image):
    """The share of hit pixels darkened by AO (some rays met something): a case that exercises hits."""
    hit = image[..., 3] > 0
    return float((image[..., 0][hit] < 1.0).mean())


def soft_and_hard_lights():
    """A light of every kind: with extent (packets take their rays), without (a ray repeated from sample 0),
    and one that casts no shadow (no ray)."""
    down = _placed((0.0, 0.0, 3.0))
    return [core.Light.point((2.0, -3.0, 4.0)), core.Light.area(down, size=1.0),
            core.Light.point((-2.0, -2.5, 2.0), radius=0.6), core.Light.sun((-0.3, 0.5, -1.0), angle=0.3),
            core.Light.spot((1.0, -2.0, 2.5), (-0.4, 0.8, -1.0), spot_size=1.2, radius=0.3),
            core.Light.point((0.0, -3.0, 1.0), radius=0.5, cast_shadow=False)]


@pytest.mark.parametrize("steps", [(70,), (1, 2, 67), (64, 6)])
@pytest.mark.parametrize("mode", ["ao", "ao+shadow", "shadow"])
def test_soup_renders_as_single_rays(mode, steps):
    """70 samples: a chunk of CHUNK (64) samples and a short one, in one call or cut into steps."""
    tree = core.build_kdtree(random_soup(np.random.default_rng(2), 3000, size=0.2))
    packed, single = with_far_instance(tree, np.eye(4))
    lights = soft_and_hard_lights()
    for scene in (packed, single):
        image = assert_same_render(scene, look_at((2.5, -3.0, 1.5), (0.0, 0.0, 0.0)), steps, ALONE, mode=mode,
                                   samples=70, ao_distance=0.8, lights=lights if mode != "ao" else ())
        assert occluded_share(image) > 0.3 if mode != "shadow" else shadowed_share(image) > 0.1
    if mode == "shadow":  # the lights with extent alone cast shadows (their rays are the packets')
        soft = lights[1:5]  # soft_and_hard_lights' lights with extent that cast shadows
        image = assert_same_render(packed, look_at((2.5, -3.0, 1.5), (0.0, 0.0, 0.0)), steps, ALONE, mode=mode,
                                   samples=70, lights=soft)
        assert shadowed_share(image) > 0.1


@pytest.mark.parametrize("builder, offset", [("binned", 0.0), ("median", 0.0), ("binned", 2.0 ** 20)])
def test_lattice_renders_as_single_rays(builder, offset):
    """Every triangle in a split plane and every ray start on one (the camera inside a cell looks at its
    walls); also far from the origin."""
    tree = core.build_kdtree(lattice(4), builder=builder)
    packed, single = with_far_instance(tree, _placed((offset, offset, offset)))
    camera = look_at(np.array([2.5, 2.45, 2.4]) + offset, np.array([2.0, 3.0, 2.0]) + offset, fov=1.6)
    for scene in (packed, single):
        image = assert_same_render(scene, camera, (16,), ALONE, samples=16, ao_distance=1.0)
        assert occluded_share(image) > 0.3


def test_transformed_instance_renders_as_single_rays():
    """A rotated, scaled instance far from the origin: the rays go into object space as the
    single-ray traversal takes them."""
    verts_tris = random_soup(np.random.default_rng(3), 2000, size=0.3)
    angle, offset = 0.6, 3.0e5
    m = np.eye(4)
    m[:3, :3] = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    m[:3, :3] = m[:3, :3] @ np.diag([2.0, 0.7, 1.3])
    m[:3, 3] = offset
    packed, single = with_far_instance(core.build_kdtree(verts_tris), m)
    camera = look_at(np.array([5.0, -6.0, 3.0]) + offset, np.full(3, offset))
    for scene in (packed, single):
        image = assert_same_render(scene, camera, (9, 24), ALONE, samples=33, ao_distance=1.2)
        assert occluded_share(image) > 0.3


def test_adaptive_sampling_renders_as_single_rays():
    tree = core.build_kdtree(random_soup(np.random.default_rng(4), 2000, size=0.2))
    packed, single = with_far_instance(tree, np.eye(4))
    camera = look_at((2.5, -3.0, 1.5), (0.0, 0.0, 0.0))
    assert_same_render(packed, camera, (128,), samples=128, ao_distance=0.8, error_target=0.05, min_samples=8)
    counts = rendered(packed, camera, (128,), samples=128, ao_distance=0.8, error_target=0.05,
                      min_samples=8).sample_counts()
    assert (counts[counts > 0] < 128).any()  # some pixels stopped early


def test_several_instances_render_as_single_rays():
    """Instances whose AO rays meet one another: a soup, a plate under it, a mirrored and rotated copy of
    the soup beside it, a copy that shadow rays do not see (its occlusion must not count), one copy out of
    every ray's reach; and the same scene far from the origin."""
    soup = core.build_kdtree(random_soup(np.random.default_rng(9), 1500, size=0.2))
    plate = core.build_kdtree(np.array([[[-3, -3, -0.7], [3, -3, -0.7], [3, 3, -0.7]],
                                        [[-3, -3, -0.7], [3, 3, -0.7], [-3, 3, -0.7]]], np.float32))
    mirrored = _placed((1.1, 0.3, 0.0))
    c, s_ = np.cos(0.7), np.sin(0.7)
    mirrored[:3, :3] = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]]) @ np.diag([-1.0, 1.0, 1.3])
    for offset in (0.0, 2.0 ** 18):
        matrices = np.stack([_placed((offset, offset, offset)), _placed((offset, offset, offset)),
                             mirrored + np.pad(np.full((3, 1), offset), ((0, 1), (3, 0))),
                             _placed((offset - 1.1, offset, offset)), _placed((offset + FAR, offset, offset))])
        visibility = np.array([SHADOW_RAYS | CAMERA_RAYS] * 3 + [CAMERA_RAYS, SHADOW_RAYS | CAMERA_RAYS], np.uint8)
        scene = build_two_level([soup, plate], [0, 1, 0, 0, 0], matrices, visibility=visibility)
        camera = look_at(np.array([0.5, -4.0, 2.0]) + offset, np.full(3, offset), fov=1.2)
        image = assert_same_render(scene, camera, (24,), ALONE, samples=24, ao_distance=0.9)
        assert occluded_share(image) > 0.3
        for mode in ("shadow", "ao+shadow"):
            lit = assert_same_render(scene, camera, (24,), ALONE, samples=24, mode=mode, ao_distance=0.9,
                                     lights=[core.Light.point(np.array([0.4, -1.0, 2.5]) + offset, radius=0.5),
                                             core.Light.sun((0.2, 0.1, -1.0), angle=0.2)])
            assert shadowed_share(lit) > 0.1
        unseen = build_two_level([soup, plate], [0, 1, 0, 0, 0], matrices)  # the copy at x - 1.1 occludes now
        assert not np.array_equal(image, rendered(unseen, camera, (24,), samples=24, ao_distance=0.9).image())


def _grid_of_copies(offset=0.0):
    """Thirty-six soup copies on a 6 x 6 grid (every fifth rotated and scaled, one that shadow rays do not
    see) over one plate under all of them, and four copies beyond every ray's reach: (meshes, mesh_of,
    matrices, visibility, the plate's instance)."""
    soup = core.build_kdtree(random_soup(np.random.default_rng(11), 300, size=0.06, extent=0.3))
    plate = core.build_kdtree(np.array([[[-4, -4, -0.4], [4, -4, -0.4], [4, 4, -0.4]],
                                        [[-4, -4, -0.4], [4, 4, -0.4], [-4, 4, -0.4]]], np.float32))
    matrices = []
    for k in range(36):
        m = _placed((offset + 0.9 * (k % 6) - 2.25, offset + 0.9 * (k // 6) - 2.25, offset))
        if k % 5 == 0:
            c, s_ = np.cos(0.4 * k), np.sin(0.4 * k)
            m[:3, :3] = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]]) @ np.diag([1.3, 0.8, 1.1])
        matrices.append(m)
    matrices += [_placed((offset, offset, offset))]  # the plate
    matrices += [_placed((offset + FAR * k, offset, offset)) for k in (1, 2, 3, 4)]
    visibility = np.full(len(matrices), SHADOW_RAYS | CAMERA_RAYS, np.uint8)
    visibility[14] = CAMERA_RAYS
    return [soup, plate], [0] * 36 + [1, 0, 0, 0, 0], np.stack(matrices), visibility, 36


def test_many_instances_render_as_single_rays():
    """Forty-one instances (scene/box_query.py finds those a chunk's rays may meet down the top level): a
    grid of copies whose AO and light rays meet their neighbours, one that shadow rays do not see, a
    plate that several top-level leaves list (found once), copies out of reach; also far from the origin.
    The AO rays, which reach a few copies, are answered by the packets; a low sun's, which cross many,
    take the single rays."""
    for offset in (0.0, 2.0 ** 18):
        meshes, mesh_of, matrices, visibility, plate = _grid_of_copies(offset)
        scene = build_two_level(meshes, mesh_of, matrices, visibility=visibility)
        assert (scene.arrays.top_items == plate).sum() > 1  # the plate straddles top-level planes
        camera = look_at(np.array([0.3, -3.5, 3.0]) + offset, np.full(3, offset), fov=1.3)
        image = assert_same_render(scene, camera, (24,), ALONE, samples=24, ao_distance=0.9)
        assert occluded_share(image) > 0.3
        lights = [core.Light.point(np.array([0.4, -1.0, 2.5]) + offset, radius=0.5),
                  core.Light.sun((0.3, 0.2, -1.0), angle=0.2)]
        for mode in ("shadow", "ao+shadow"):
            lit = assert_same_render(scene, camera, (24,), samples=24, mode=mode, ao_distance=0.9, lights=lights)
            assert shadowed_share(lit) > 0.1
        # a low sun: its rays cross more than MAX_CHUNK_INSTANCES copies, so most chunks go to single rays
        low = [core.Light.sun((1.0, 0.3, -0.15), angle=0.1)]
        assert shadowed_share(assert_same_render(scene, camera, (24,), samples=24, mode="shadow", lights=low)) > 0.1
        grazing = rendered(scene, camera, (24,), samples=24, mode="shadow", lights=low)
        assert grazing.rays_alone > grazing.hit_pixels  # more than the one ray a pixel's chunk may leave


def test_box_query_finds_every_instance_a_box_meets_once():
    """scene/box_query.instances_meeting_box against every instance's world box: the instances of the top
    level seen by the rays' kind whose box overlaps the query box (touching counts, NaN too) are found,
    each once, and no other; the walk stops once it found more than it was asked for."""
    from numba import njit

    from core.scene.box_query import instances_meeting_box, new_box_query

    @njit
    def query_all(arrays, boxes, most, ray_mask):
        query = new_box_query(most)
        found = []
        for b in range(boxes.shape[0]):
            n = instances_meeting_box(arrays, boxes[b], query, most, ray_mask)
            found.append(query[0][:n].copy())
        return found

    rng = np.random.default_rng(12)
    meshes, mesh_of, matrices, visibility, _ = _grid_of_copies()
    empty = core.build_kdtree(np.zeros((0, 3, 3), np.float32))
    scene = build_two_level([*meshes, empty], [*mesh_of, 2], np.concatenate([matrices, np.eye(4)[None]]),
                            visibility=np.append(visibility, SHADOW_RAYS))
    world = scene.arrays.world_boxes
    in_top = set(scene.arrays.top_items.tolist())
    lo = rng.uniform(-3.5, 3.5, (300, 3))
    boxes = np.concatenate([lo, lo + rng.uniform(0.0, 1.5, (300, 3)) ** 2], axis=1)
    boxes[:20, :3], boxes[:20, 3:] = world[:20, :3], world[:20, :3]  # a box touching an instance's corner
    boxes[20] = [-1e30, -1e30, -1e30, 1e30, 1e30, 1e30]
    boxes[21, 2] = np.nan  # a box with NaN reaches every instance it may
    for mask in (SHADOW_RAYS, CAMERA_RAYS):
        listed = in_top & set(np.flatnonzero(scene.arrays.visibility & mask).tolist())
        for k, (box, found) in enumerate(zip(boxes, query_all(scene.arrays, boxes, len(world), mask))):
            assert len(set(found.tolist())) == len(found)
            meets = ~((world[:, :3] > box[3:]).any(axis=1) | (world[:, 3:] < box[:3]).any(axis=1))
            assert set(found.tolist()) == set(np.flatnonzero(meets).tolist()) & listed, k
        assert len(query_all(scene.arrays, boxes[20:21], len(world), mask)[0]) == len(listed)
        assert len(query_all(scene.arrays, boxes[20:21], 5, mask)[0]) == 6  # the walk stops past `most`
    assert 14 not in query_all(scene.arrays, boxes[20:21], len(world), SHADOW_RAYS)[0]  # camera rays only


def test_lazy_tree_renders_as_the_eager_tree():
    """A lazy tree's packet meets unbuilt nodes: its lanes stop at them as single rays and the batch is
    redone once they are built, so the image is the eager tree's."""
    tris = random_soup(np.random.default_rng(5), 4000, size=0.2)
    camera = look_at((2.5, -3.0, 1.5), (0.0, 0.0, 0.0))
    soft = [core.Light.point((-2.0, 3.0, 0.5), radius=0.5)]  # behind the soup: its rays cross unbuilt parts
    for settings in (dict(samples=20, ao_distance=0.8), dict(samples=20, mode="shadow", lights=soft)):
        eager = rendered(core.build_kdtree(tris), camera, (20,), **settings)
        lazy = core.build_kdtree(tris, lazy=True, lazy_subtree_size=256)
        got = core.PreviewRender(lazy, camera, 40, 32, **settings)
        built_by_camera = lazy.stats()["subtrees_built"]
        got.step(20)
        assert lazy.stats()["subtrees_built"] > built_by_camera  # the sample rays met unbuilt subtrees
        np.testing.assert_array_equal(got.image(), eager.image())
        np.testing.assert_array_equal(got.sample_counts(), eager.sample_counts())
        assert got.rays_traced == eager.rays_traced


def _placed(position):
    m = np.eye(4)
    m[:3, 3] = position
    return m


def test_only_batches_of_eight_or_more_take_the_packed_kernel(monkeypatch):
    """The sampling kernel's `packed` argument: None (the version without packets, the only one a
    progressive renderer compiles) for steps under PACKED_BATCH samples and shadow renders whose lights
    have no extent (no ray to put in packets); True for a batch of 8 or more samples of an AO render, or
    of one with a light of extent, on a scene of one, two or many instances."""
    import core.render.preview_render as preview_render

    calls = []
    kernel = preview_render.add_samples

    def recording(*args):
        calls.append(args[-1])
        return kernel(*args)

    monkeypatch.setattr(preview_render, "add_samples", recording)
    tree = core.build_kdtree(random_soup(np.random.default_rng(6), 500, size=0.2))
    packed, single = with_far_instance(tree, np.eye(4))
    camera = look_at((2.5, -3.0, 1.5), (0.0, 0.0, 0.0))
    many = build_two_level([tree], [0] * 40, np.stack([_placed((3.0 * k, 0.0, 0.0)) for k in range(40)]))
    hard, soft = core.Light.point((2.0, -3.0, 4.0)), core.Light.point((2.0, -3.0, 4.0), radius=0.2)
    unshadowed = core.Light.point((2.0, -3.0, 4.0), radius=0.2, cast_shadow=False)
    cases = [(packed, "ao", (1, 2, 4, 8), [None, None, None, True], [hard]),
             (packed, "ao+shadow", (7, 9), [None, True], [hard]),
             (packed, "ao", (7, 9), [None, True], [hard]),
             (packed, "shadow", (16,), [None], [hard, unshadowed]),
             (packed, "shadow", (7, 9), [None, True], [hard, soft]),
             (single, "ao", (16,), [True], [hard]),
             (many, "ao", (4, 12), [None, True], [hard]),
             (many, "shadow", (16,), [True], [soft])]
    for scene, mode, steps, expected, lights in cases:
        calls.clear()
        rendered(scene, camera, steps, mode=mode, samples=sum(steps), ao_distance=0.8, lights=lights)
        assert calls == expected, (mode, steps)


def test_a_batch_that_would_compile_the_packed_version_is_cut_below_it(monkeypatch):
    """PreviewRender.batch_without_compile: a batch that would take the packed kernel (8+ samples with AO
    or a light of extent) is cut to PACKED_BATCH - 1 while that version is neither loaded nor cached; other batches
    keep their size. A batch so cut gives the image of the batch asked for."""
    import core.render.preview_render as preview_render
    from core.render.render_kernels import PACKED_BATCH

    tree = core.build_kdtree(random_soup(np.random.default_rng(7), 500, size=0.2))
    packed, _ = with_far_instance(tree, np.eye(4))
    many = build_two_level([tree], [0] * 40, np.stack([_placed((3.0 * k, 0.0, 0.0)) for k in range(40)]))
    camera = look_at((2.5, -3.0, 1.5), (0.0, 0.0, 0.0))
    light = [core.Light.point((2.0, -3.0, 4.0))]
    for ready, expected in ((False, PACKED_BATCH - 1), (True, 16)):
        monkeypatch.setattr(preview_render, "packed_version_ready", lambda: ready)
        render = core.PreviewRender(packed, camera, 8, 8, samples=16, mode="ao")
        assert [render.batch_without_compile(n) for n in (1, 7, 16)] == [1, 7, expected]
        soft = core.PreviewRender(packed, camera, 8, 8, samples=16, mode="shadow",
                                  lights=[core.Light.sun((0.0, 0.0, -1.0), angle=0.1)])
        assert soft.batch_without_compile(16) == expected
        assert core.PreviewRender(many, camera, 8, 8, samples=16, mode="ao").batch_without_compile(16) == expected
        hard = core.PreviewRender(packed, camera, 8, 8, samples=16, mode="shadow", lights=light)
        assert hard.batch_without_compile(16) == 16
    cut = rendered(packed, camera, (PACKED_BATCH - 1, 16 - PACKED_BATCH + 1), samples=16, ao_distance=0.8)
    np.testing.assert_array_equal(cut.image(), rendered(packed, camera, (16,), samples=16, ao_distance=0.8).image())


def test_the_packed_version_is_ready_once_loaded_or_cached(tmp_path):
    """render_kernels.packed_version_ready: False in a process whose cache holds no packed version, True
    once a batch ran it here (it then sits in the cache, which a later process reads)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from core.render.render_kernels import PACKED_BATCH, packed_version_ready

    script = "import core.render.render_kernels as k; print(k.packed_version_ready())"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", script], cwd=Path(core.__file__).parent.parent, env=env,
                         capture_output=True, text=True, check=True, timeout=300)
    assert out.stdout.split()[-1] == "False"
    tree = core.build_kdtree(random_soup(np.random.default_rng(8), 200, size=0.2))
    rendered(tree, look_at((2.5, -3.0, 1.5), (0.0, 0.0, 0.0)), (PACKED_BATCH,), samples=PACKED_BATCH)
    assert packed_version_ready()
    out = subprocess.run([sys.executable, "-c", script], cwd=Path(core.__file__).parent.parent, env=dict(os.environ),
                         capture_output=True, text=True, check=True, timeout=300)
    assert out.stdout.split()[-1] == "True"  # this session's cache now holds it, read without loading it
