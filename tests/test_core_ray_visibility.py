"""Per-instance ray visibility (core/scene/ray_visibility.py): camera rays meet only instances visible to the
camera, AO and shadow rays only instances that cast shadows, and a holdout's pixels stay empty, in every
layout, through soups, queries, renders and pixel reuse.

References: a flat tree or a brute-force tracer over only the triangles a ray kind may meet, and a full
render for frames continued from the last one."""
import numpy as np
import pytest

import core
from core.scene.scene_builder import MeshInput, SceneBuilder
from tests.render_scenes import floor, hit_mask, look_at, look_down, quad
from tests.test_core_pixel_reuse import GROUND, camera as reuse_camera, cube, moved, render
from tests.test_core_two_level import _blob, _random_matrix, _rays
from tests.test_render_reference import boxes_on_floor, brute_force_ao

CAMERA, SHADOW, ALL, HOLDOUT = core.CAMERA_RAYS, core.SHADOW_RAYS, core.ALL_RAYS, core.HOLDOUT


@pytest.mark.parametrize("layout", ["auto", "flat", "two_level"])
def test_queries_meet_only_the_instances_visible_to_the_ray_kind(layout):
    """Shared and single-use meshes (small ones go to per-visibility soups in "auto" and "flat") with
    mixed visibility: each ray kind's hits are those of a flat tree over the instances it may meet, and
    still name the caller's instance and triangle."""
    rng = np.random.default_rng(5)
    meshes = [_blob(rng, 60 + 30 * i) for i in range(8)]
    mesh_of = np.array([0, 1, 2, 2, 3, 4, 5, 5, 6, 7, 0], np.int32)  # 1, 3, 4, 6, 7 placed once
    mats = np.stack([_random_matrix(rng) for _ in mesh_of])
    visibility = np.array([ALL, CAMERA, SHADOW, ALL, CAMERA, SHADOW, 0, CAMERA, ALL, SHADOW, ALL], np.uint8)
    indexed = [(m.reshape(-1, 3), np.arange(3 * len(m)).reshape(-1, 3)) for m in meshes]
    scene = core.build_scene(indexed, mesh_of, mats, layout=layout, visibility=visibility)
    if layout != "two_level":
        assert scene.instance_count < len(mesh_of)  # soups were made, one per visibility
    _assert_hits_as_flat(scene, meshes, mesh_of, mats, visibility, *_rays(rng, 4000))


def _assert_hits_as_flat(scene, meshes, mesh_of, mats, visibility, o, d):
    """Per ray kind: the scene's hits are those of a flat tree over the world triangles of the
    instances that kind meets, named by the caller's instance and triangle."""
    for mask in (CAMERA, SHADOW, ALL):
        seen = np.flatnonzero(np.asarray(visibility) & mask)
        world = [meshes[mesh_of[i]].astype(np.float64) @ mats[i, :3, :3].T + mats[i, :3, 3] for i in seen]
        owner = np.concatenate([np.full(len(w), i) for i, w in zip(seen, world)])
        local = np.concatenate([np.arange(len(w)) for w in world])
        ref = core.intersect(core.build_kdtree(np.concatenate(world)), o, d)
        hits = core.intersect_scene(scene, o, d, ray_mask=mask)
        hit = ref.prim >= 0
        assert hit.sum() > 50
        np.testing.assert_array_equal(hits.prim >= 0, hit)
        np.testing.assert_allclose(hits.t[hit], ref.t[hit], rtol=1e-5, atol=1e-5)
        same = (hits.instance[hit] == owner[ref.prim[hit]]) & (hits.prim[hit] == local[ref.prim[hit]])
        assert same.mean() > 0.995  # float32 world triangles against object space: rare ties differ
        assert set(hits.instance[hit].tolist()) <= set(seen.tolist())
        np.testing.assert_array_equal(core.occluded_scene(scene, o, d, ray_mask=mask), hit)


def test_soups_come_and_go_and_a_switching_object_leaves_them():
    """Static objects of each visibility share a soup, which is kept while its members are; an object
    whose visibility switches is treated like one that moved (a tree of its own from then on), so
    later switches rebuild no soup; an instance no ray meets is left out. Hits stay right throughout."""
    rng = np.random.default_rng(2)
    blobs = [_blob(rng, 80) for _ in range(7)]
    meshes = [MeshInput(k, b.reshape(-1, 3), np.arange(3 * len(b)).reshape(-1, 3), 0) for k, b in enumerate(blobs)]
    mats = np.stack([_random_matrix(rng) for _ in blobs])
    o, d = _rays(rng, 6000)
    builder, rebuilt, counts = SceneBuilder("auto"), [], []
    for vis in ([ALL, ALL, ALL, CAMERA, CAMERA, SHADOW, ALL], [ALL, ALL, ALL, CAMERA, CAMERA, SHADOW, SHADOW],
                [ALL, ALL, ALL, CAMERA, CAMERA, SHADOW, CAMERA], [ALL, ALL, ALL, CAMERA, CAMERA, SHADOW, ALL],
                [0, ALL, ALL, CAMERA, CAMERA, SHADOW, ALL]):
        scene, report = builder.build(meshes, np.arange(7), mats, visibility=vis)
        _assert_hits_as_flat(scene, blobs, np.arange(7), mats, vis, o, d)
        rebuilt.append(report.meshes_rebuilt)
        counts.append(scene.instance_count)
    # frame 0: three soups; frame 1: 6 switches and leaves its soup (its own tree plus the all-rays
    # soup's 3 other members rebuilt); frames 2-3: it switches again and nothing is rebuilt; frame 4:
    # 0 stops no ray, so it leaves too (the soup's 2 other members rebuilt) and is not in the scene
    assert rebuilt == [7, 4, 0, 0, 2] and counts == [3, 4, 4, 4, 4]


def _objects_on_floor():
    """boxes_on_floor's floor and three boxes as four meshes (12 triangles a box)."""
    tris = boxes_on_floor()
    parts = [tris[:2], tris[2:14], tris[14:26], tris[26:38]]
    return [(p.reshape(-1, 3), np.arange(3 * len(p)).reshape(-1, 3)) for p in parts], parts


@pytest.mark.parametrize("layout", ["auto", "two_level"])
def test_converged_ao_with_ray_visibility_matches_brute_force(layout):
    """A box hidden from the camera still occludes; a box that casts no shadows is seen but lets AO
    rays through: the converged AO equals a brute-force tracer whose camera rays see the floor and the
    boxes visible to the camera and whose AO rays meet the floor and the boxes that cast shadows."""
    indexed, parts = _objects_on_floor()
    visibility = np.array([ALL, CAMERA, SHADOW, ALL], np.uint8)
    scene = core.build_scene(indexed, np.arange(4), np.eye(4)[None].repeat(4, 0), layout=layout,
                             visibility=visibility)
    seen = np.concatenate([p for p, v in zip(parts, visibility) if v & CAMERA])
    occluders = np.concatenate([p for p, v in zip(parts, visibility) if v & SHADOW])
    camera = look_at((1.8, -2.2, 1.6), (0.0, 0.2, 0.2), fov=0.9)
    size = 20
    reference, hit = brute_force_ao(seen, camera, size, 0.8, occluders=occluders)
    img = core.render_preview(scene, camera, size, size, samples=512, ao_distance=0.8)
    np.testing.assert_array_equal(np.flatnonzero(hit_mask(img).ravel()), hit)
    diff = np.abs(img[..., 0] - reference)[hit_mask(img)]
    assert diff.mean() < 0.01 and diff.max() < 0.08, (diff.mean(), diff.max())
    everything = core.render_preview(core.build_kdtree(np.concatenate(parts)), camera, size, size, samples=512,
                                     ao_distance=0.8)
    assert (np.abs(everything - img).max(axis=2) > 0.2).sum() >= 10  # the visibility really changed the image


@pytest.mark.parametrize("layout", ["auto", "flat", "two_level"])
def test_holdout_pixels_are_empty_and_the_holdout_still_occludes(layout):
    """Blender's Holdout as Cycles applies it: pixels whose camera ray first meets the holdout box are
    empty (alpha 0, value 0), and the box still occludes the floor's AO; a holdout hidden from the camera
    empties nothing. Against the brute-force tracer with the holdout seen by camera rays only to empty
    its pixels."""
    indexed, parts = _objects_on_floor()
    camera = look_at((1.8, -2.2, 1.6), (0.0, 0.2, 0.2), fov=0.9)
    size = 20
    visibility = np.array([ALL, ALL | HOLDOUT, SHADOW | HOLDOUT, ALL], np.uint8)
    scene = core.build_scene(indexed, np.arange(4), np.eye(4)[None].repeat(4, 0), layout=layout,
                             visibility=visibility)
    reference, hit = brute_force_ao(np.concatenate([parts[0], parts[3]]), camera, size, 0.8,
                                    occluders=np.concatenate(parts), holdouts=parts[1])
    img = core.render_preview(scene, camera, size, size, samples=512, ao_distance=0.8)
    np.testing.assert_array_equal(np.flatnonzero(hit_mask(img).ravel()), hit)
    assert (img[~hit_mask(img)] == 0.0).all()
    diff = np.abs(img[..., 0] - reference)[hit_mask(img)]
    assert diff.mean() < 0.01 and diff.max() < 0.08, (diff.mean(), diff.max())
    _, seen_all = brute_force_ao(np.concatenate([parts[0], parts[1], parts[3]]), camera, size, 0.8, strata=1)
    assert len(seen_all) - len(hit) >= 20  # the holdout box's pixels really were emptied
    assert (reference.ravel()[hit] < 0.95).sum() >= 20  # ... and it still occludes the floor around it


@pytest.mark.parametrize("visibility, seen, value", [(ALL, "roof", 1.0), (CAMERA, "roof", 1.0),
                                                     (SHADOW, "floor", 0.0), (0, "floor", 1.0)])
def test_shadow_of_a_roof_follows_its_ray_visibility(visibility, seen, value):
    """A roof over a floor under a sun straight above, seen from above: the camera sees the roof unless
    it is hidden from camera rays, and the floor under it is dark unless the roof casts no shadows."""
    meshes = [(f.reshape(-1, 3), np.arange(6).reshape(-1, 3)) for f in (floor(0.0, 50.0), floor(1.0, 20.0))]
    scene = core.build_scene(meshes, [0, 1], np.eye(4)[None].repeat(2, 0), layout="two_level",
                             visibility=[ALL, visibility])
    img = core.render_preview(scene, look_down((0, 0, 5), fov=1.0), 16, 16, mode="shadow", samples=4,
                              lights=[core.Light.sun((0, 0, -1))])
    assert hit_mask(img).all()
    np.testing.assert_array_equal(img[..., 0], value)
    hits = core.intersect_scene(scene, [(0.0, 0.0, 5.0)], [(0.0, 0.0, -1.0)], ray_mask=CAMERA)
    assert hits.t[0] == pytest.approx(4.0 if seen == "roof" else 5.0)


@pytest.mark.parametrize("layout", ["auto", "flat", "two_level"])
def test_frames_that_toggle_visibility_continue_exactly(layout):
    """Pixel reuse: an object switching its camera or shadow rays or its holdout off and on is a change (its box is
    retraced); every frame continued from the last equals its full render, and the toggles show."""
    meshes = [MeshInput("ground", *GROUND, 0), MeshInput("a", *cube(0.8), 0), MeshInput("b", *cube(0.5), 0)]
    matrices = np.stack([np.eye(4), moved(-2, 0, 1), moved(2.5, 1, 0.6)])
    cam = reuse_camera()
    lights = [core.Light.sun((0.3, 0.2, -1), angle=0.1)]
    settings = dict(mode="ao+shadow", samples=4, ao_distance=2.0, lights=lights, seed=3)
    builder, state, images, kept = SceneBuilder(layout), None, [], []
    for vis_a in (ALL, CAMERA, SHADOW, SHADOW, ALL, ALL | HOLDOUT, ALL | HOLDOUT, ALL):
        scene = builder.build(meshes, [0, 1, 2], matrices, visibility=[ALL, vis_a, ALL])[0]
        continued = render(scene, cam, state, **settings)
        full = render(scene, cam, **settings)
        np.testing.assert_array_equal(continued.image(), full.image())
        images.append(full.image())
        kept.append(continued.pixels_reused / max(continued.hit_pixels, 1))
        state = continued.pixel_state()
    assert kept[3] == kept[6] == 1.0 and 0.3 < min(kept[1:]) < 1.0  # a repeat keeps all; a toggle retraces
    for k in (0, 1, 3, 4, 6):  # every toggle shows (frames 2 and 3, 5 and 6 are the same)
        assert (np.abs(images[k] - images[k + 1]).max(axis=2) > 0.2).sum() >= 5


def test_bad_visibility_and_ray_masks_are_named():
    mesh = (np.eye(3), np.array([[0, 1, 2]]))
    for bad, words in [([8], "instance 0 has visibility 8"), ([-1], "instance 0 has visibility -1"),
                       ([1.5], "must hold integers"), ([1, 2], "shape (1,)")]:
        with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
            core.build_scene([mesh], [0], np.eye(4)[None], visibility=bad)
    scene = core.build_scene([mesh], [0], np.eye(4)[None])
    for bad in (0, 4, True, 1.0):
        with pytest.raises(ValueError, match="ray_mask must be"):
            core.intersect_scene(scene, [(0.2, 0.2, 1.0)], [(0.0, 0.0, -1.0)], ray_mask=bad)
    with pytest.raises(ValueError, match="lazy build .* same rays"):
        SceneBuilder("flat", lazy=True).build([MeshInput(0, *mesh, 0)], [0, 0], np.eye(4)[None].repeat(2, 0),
                                              visibility=[ALL, CAMERA])
