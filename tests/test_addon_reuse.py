"""Reuse across frames in the add-on: kept trees for static and rigidly moving objects, rebuilt trees
for deforming ones, the last image when nothing changed, and `rebuild_all` / `--rebuild-all`.

The scene: a static ground quad, a cube whose location is keyed (rigid motion, frames 1-10), a quad
with a keyed shape key (deforms, frames 1-10), an orthographic camera and a sun. Reference for the
images: the same frames rendered with rebuild_all, from an empty cache.
"""

from __future__ import annotations

import json

import pytest

from tests.addon_support import add_quad, add_sun, add_top_camera

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from kd_addon import cli, pipeline, tree_cache  # noqa: E402
from kd_addon.config import make_config  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402


def animated_scene():
    scene = bpy.context.scene
    add_quad("Ground", 4.0, 2.0)
    mover = scenes.add_cube("Mover", scale=0.4, location=(-2.0, 0.0, 0.4))
    for frame, x in ((1, -2.0), (10, 2.0)):
        mover.location.x = x
        mover.keyframe_insert("location", frame=frame)
    keyed = scenes.add_shape_key_plane("Keyed", lift=1.0)
    keyed.location = (1.0, -1.0, 0.0)
    add_top_camera(location=(0.0, 0.0, 10.0), ortho_scale=8.0)
    add_sun(rotation=(0.5, 0.0, 0.0))
    scene.render.resolution_x, scene.render.resolution_y = 48, 24
    settings = scene.kd_preview
    settings.resolution_percentage, settings.samples, settings.ao_distance = 100, 4, 1.0
    settings.mode = "ao+shadow"
    return scene


def render(scene, frame, **changes):
    scene.frame_set(frame)
    for name, value in changes.items():
        setattr(scene.kd_preview, name, value)
    return pipeline.render_frame(scene, bpy.context.evaluated_depsgraph_get(), make_config(scene.kd_preview))


def test_the_first_denoised_frame_is_marked_as_a_first_run(addon, monkeypatch):
    """The kernels' warm-up runs a default frame, without the denoiser: the first frame that denoises
    compiles or loads its kernels in its own time, so it carries first_run (the CLI's "*"); the next
    does not."""
    scene = animated_scene()
    tree_cache.clear()
    render(scene, 1)  # the tracing kernels loaded
    for ready in ("_kernels_ready", "_reuse_kernels_ready"):  # only the denoiser may mark a frame
        monkeypatch.setattr(pipeline, ready, True)
    monkeypatch.setattr(pipeline, "_denoiser_ready", False)
    frames = [render(scene, f, denoise=True) for f in (2, 3)]
    assert [r.first_run for r in frames] == [True, False]


def test_rebuild_all_lays_a_frame_out_as_a_fresh_process_does(addon):
    """A builder's layout follows the motion of the frames it saw (core SceneBuilder: an object that moved
    leaves the merged soup for a tree of its own), which can move a few edge pixels by a sample against a
    fresh process's render of the frame. Rebuild All takes a new builder every frame, so frame 3 after
    frames 1 and 2 is frame 3 rendered alone; with reuse the builder is kept."""
    scene = animated_scene()

    def builders_over(frames, **settings):
        tree_cache.clear()
        seen = []
        for frame in frames:
            result = render(scene, frame, **settings)
            seen += [builder for _, builder in tree_cache._builders.values()]
        return seen, result

    fresh, after = builders_over((1, 2, 3), rebuild_all=True)
    assert len(fresh) == 3 and len({id(b) for b in fresh}) == 3
    _, alone = builders_over((3,), rebuild_all=True)
    np.testing.assert_array_equal(after.image, alone.image)
    kept, _ = builders_over((1, 2, 3), rebuild_all=False)  # render() leaves its settings set
    assert len({id(b) for b in kept}) == 1


def test_static_and_moved_objects_keep_their_trees_deforming_ones_are_rebuilt(addon):
    scene = animated_scene()
    tree_cache.clear()
    reused = [render(scene, f) for f in (1, 2, 3, 4)]
    tree_cache.clear()
    rebuilt = [render(scene, f, rebuild_all=True) for f in (1, 2, 3, 4)]
    counts = [(r.objects_rebuilt, r.objects_reused) for r in reused]
    # frame 1 builds all; frame 2 learns which objects change (they leave the static soup, which is
    # rebuilt once); from frame 3 only the deforming quad is rebuilt, the moved cube keeps its tree
    assert counts[0] == (3, 0) and sum(counts[1]) == 3
    assert counts[2] == counts[3] == (1, 2)
    assert all((r.objects_rebuilt, r.objects_reused) == (3, 0) for r in rebuilt)
    assert not any(r.image_reused for r in reused + rebuilt)
    for a, b in zip(reused, rebuilt):
        np.testing.assert_array_equal(a.image, b.image)  # reuse changes the work, never the pixels
    # pixels whose rays cannot reach the moving cube or the deforming quad keep last frame's samples
    assert reused[0].pixels_reused == 0 and all(r.pixels_reused == 0 for r in rebuilt)
    for a, b in zip(reused[1:], rebuilt[1:]):
        assert 0 < a.pixels_reused < (b.image[..., 3] > 0).sum()
        assert a.rays < b.rays and a.rays + a.rays_reused >= b.rays
    assert not np.array_equal(reused[2].image, reused[3].image)  # the animation does show


def test_image_reused_only_when_nothing_changed(addon):
    scene = animated_scene()
    tree_cache.clear()
    first = render(scene, 11)  # the animation ended at frame 10: frames 11 and 12 are identical
    same = render(scene, 12)
    assert not first.image_reused and same.image_reused and same.frame == 12
    assert same.rays == 0 and same.build_ms == 0.0 and same.objects_reused == 3
    np.testing.assert_array_equal(first.image, same.image)
    assert render(scene, 12).image_reused

    bpy.data.objects["Cam"].location.x += 0.1
    assert not render(scene, 12).image_reused
    bpy.data.objects["Sun"].data.energy += 1.0  # no effect on the pixels, but a light changed
    assert not render(scene, 12).image_reused
    assert not render(scene, 12, samples=5).image_reused
    assert render(scene, 12).image_reused
    assert not render(scene, 12, rebuild_all=True).image_reused
    assert render(scene, 12, rebuild_all=False, output_format="OPEN_EXR").image_reused  # no effect on pixels
    window = scenes.link(bpy.data.objects.new("Window", bpy.data.lights.new("Window", "AREA")))
    window.location = (0.0, 0.0, 3.0)
    assert not render(scene, 12).image_reused
    window.data.cycles.is_portal = True  # review: the key left the portal flag out, and the last image came back
    window.data.update_tag()
    portal = render(scene, 12)
    assert not portal.image_reused and any("light 'Window' left out" in w for w in portal.warnings)


def test_an_ao_image_is_reused_whatever_the_lights_do(addon):
    """Mode "ao" traces no light, so animated lights must not stop the last image's reuse (a scene whose
    lights move every frame would render every frame anew, 11-39 ms against ~2 ms)."""
    scene = animated_scene()
    scene.kd_preview.mode = "ao"
    tree_cache.clear()
    first = render(scene, 11)
    sun = bpy.data.objects["Sun"]
    sun.data.energy += 1.0
    sun.rotation_euler.x += 0.4
    scenes.link(bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))).location = (0.0, 0.0, 3.0)
    same = render(scene, 12)
    assert same.image_reused and same.rays == 0
    np.testing.assert_array_equal(first.image, same.image)
    scene.kd_preview.mode = "ao+shadow"  # where the lights count, the same change renders anew
    lit = render(scene, 12)
    sun.rotation_euler.x -= 0.4
    assert not lit.image_reused and not render(scene, 12).image_reused


def test_cli_rebuild_all_flag_and_report_columns(addon, tmp_path, capsys):
    scene = animated_scene()
    scene.frame_start, scene.frame_end = 10, 12
    blend = tmp_path / "anim.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    rows = {}
    for flag in ((), ("--rebuild-all",)):
        out = tmp_path / ("all" if flag else "reuse")
        assert cli.execute(["render", str(blend), "--out", str(out), *flag]) == 0
        rows[bool(flag)] = json.loads((out / "report.json").read_text())["frames"]
    printed = capsys.readouterr().out
    assert "rebuilt" in printed and "2 of 3 images reused" in printed and "(--rebuild-all)" in printed
    assert "px kept" in printed and "rays reused" in printed
    assert all(r["pixels_reused"] > 0 for r in rows[False][1:]) and all(r["pixels_reused"] == 0 for r in rows[True])
    assert [r["image_reused"] for r in rows[False]] == [False, True, True]
    assert [r["objects_reused"] for r in rows[False]][1:] == [3, 3]
    assert all(r["objects_reused"] == 0 and not r["image_reused"] for r in rows[True])
    assert all(r["objects_rebuilt"] == 3 for r in rows[True])


@pytest.mark.parametrize("value", ["yes", 1])
def test_rebuild_all_must_be_a_bool(value):
    class Source:
        rebuild_all = value

    with pytest.raises(ValueError, match="rebuild_all must be True or False"):
        make_config(Source())


def test_lazy_build_setting_renders_the_same_image_and_skips_hidden_geometry(addon):
    """The Lazy Build setting: one flat tree built on demand. A 20k-triangle sheet under the ground is
    reached by no camera or AO ray, so most of its subtrees stay unbuilt; the image is the eager one."""
    scene = animated_scene()
    scenes.add_wavy_sheet("Hidden", 100, location=(0.0, 0.0, -3.0))
    tree_cache.clear()
    eager = render(scene, 1, rebuild_all=True)
    lazy = render(scene, 1, rebuild_all=True, lazy=True)
    np.testing.assert_array_equal(lazy.image, eager.image)
    stats = lazy.tree_stats
    assert stats["lazy"] and 0 < stats["subtrees_built"] < stats["subtrees_total"] / 2
    assert not eager.tree_stats.get("lazy")


@pytest.mark.parametrize("warmup", ["on", "off"])
def test_first_frame_continuing_another_is_marked_as_a_first_run(addon, monkeypatch, warmup):
    """Without the kernels' compile process (KD_PREVIEW_WARMUP=0), a process's first frame compiles or
    loads the tracing kernels, its first continued frame the pixel-reuse ones: both carry first_run (the
    CLI's "*"), later frames do not. With it, the first frame loads them all before its own work and
    reports that apart (load_ms): no frame carries first_run."""
    from kd_addon import kernel_warmup

    scene = animated_scene()
    tree_cache.clear()
    monkeypatch.setattr(pipeline, "_kernels_ready", False)
    monkeypatch.setattr(pipeline, "_reuse_kernels_ready", False)
    monkeypatch.setattr(kernel_warmup, "_warmup", kernel_warmup._Warmup())
    monkeypatch.setenv(kernel_warmup.SWITCH, "1" if warmup == "on" else "0")
    frames = [render(scene, f) for f in (1, 2, 3)]
    assert frames[1].pixels_reused > 0
    if warmup == "off":
        assert [r.first_run for r in frames] == [True, True, False] and frames[0].load_ms == 0
    else:
        assert [r.first_run for r in frames] == [False, False, False]
        assert frames[0].load_ms > 0 and frames[1].load_ms == 0 and frames[1].compile_ms == 0
