"""The command line: demo scene, a saved .blend, error exits; in-process (fast) and one real
`python -m kd_addon` run (the README's main job)."""

from __future__ import annotations

import json

import pytest

from tests.addon_support import add_quad, add_sun, add_top_camera, exr_channels, floor_scene, run_python

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import kd_addon  # noqa: E402
from kd_addon import cli, corelib, demo_scene  # noqa: E402
from tests import bpy_scenes as scenes  # noqa: E402

SMALL = ["--demo", "--resolution", "5", "--samples", "2"]  # 48x27 from the demo's 960x540


def frame_rows(out):
    return json.loads((out / "report.json").read_text())["frames"]


def test_demo_scene_is_animated_in_every_way():
    scenes.reset()
    scene = demo_scene.build_demo_scene()
    from kd_addon.extract import extract_scene

    def snapshot(frame):
        scene.frame_set(frame)
        result = extract_scene(bpy.context.evaluated_depsgraph_get())
        return result, result.world_triangles(), result.triangle_object_ids()

    first, tris1, ids = snapshot(1)
    last, tris24, _ = snapshot(24)
    names = first.object_names
    assert names == last.object_names and first.triangle_count == last.triangle_count > 10000
    moved = {name for i, name in enumerate(names) if not np.allclose(tris1[ids == i], tris24[ids == i])}
    assert {"WaveSheet", "TwistColumn", "Monkey", "Cube"} <= moved and "Ground" not in moved
    instanced = [inst for inst in first.instances if inst.instancer and inst.instancer.startswith("Pillar.")]
    assert len(instanced) == 12  # 6 instancers x (shaft + ball)
    lights = {ob.data.type for ob in scene.objects if ob.type == "LIGHT"}
    assert lights == {"SUN", "POINT"} and scene.camera is not None


def test_cli_renders_the_demo(tmp_path, capsys):
    out = tmp_path / "demo"
    assert cli.execute(["render", "--frames", "1-2", "--out", str(out), *SMALL]) == 0
    printed = capsys.readouterr().out
    assert "frame  triangles" in printed and "report:" in printed and "mean frame after the first" in printed
    assert sorted(p.name for p in out.iterdir()) == ["frame_0001.png", "frame_0002.png", "report.json"]
    report = json.loads((out / "report.json").read_text())
    assert report["resolution"] == [48, 27] and report["settings"]["samples"] == 2
    assert report["totals"]["frames"] == 2
    image = bpy.data.images.load(str(out / "frame_0002.png"))
    assert tuple(image.size) == (48, 27)
    assert cli.execute(["render", "--frames", "1-1", "--out", str(tmp_path / "one"), *SMALL]) == 0
    printed = capsys.readouterr().out
    assert "; frame " in printed and "after the first" not in printed  # one frame has no "after the first"


def test_cli_renders_a_saved_blend_with_its_frame_range(tmp_path):
    scenes.reset()
    add_quad("Floor", 5, 5)
    scenes.add_cube("Box", location=(0, 0, 1))
    add_top_camera(location=(0, 0, 12))
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 3, 4
    scene.render.resolution_x, scene.render.resolution_y = 40, 30
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), compress=True)  # zstd: passes the header check too
    scenes.reset()
    out = tmp_path / "out"
    args = ["render", str(blend), "--out", str(out), "--resolution", "100", "--samples", "2", "--format", "exr",
            "--builder", "median", "--threads", "1"]
    assert cli.execute(args) == 0
    rows = frame_rows(out)
    assert [r["frame"] for r in rows] == [3, 4] and rows[0]["triangles"] == 14
    assert (out / "frame_0003.exr").is_file()
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["builder"] == "median" and report["settings"]["threads"] == 1


def test_cli_renders_the_scene_it_is_told_to(tmp_path, capsys):
    """--scene picks one of the file's scenes (with its own frame range and camera) through the view
    layer a render of it takes: its first one enabled for rendering, here the second, which excludes
    a collection the first shows."""
    floor_scene(40, 30)  # the file's current scene: a floor, 2 triangles
    other = bpy.data.scenes.new("Shot B")
    other.camera, other.frame_start, other.frame_end = bpy.context.scene.camera, 7, 7
    other.render.resolution_x, other.render.resolution_y = 40, 30
    scenes.add_cube("NotInLayer2", collection=bpy.data.collections.new("Layer2Excludes"))
    scenes.add_cube("Box", location=(0, 0, 1), collection=other.collection)
    other.collection.children.link(bpy.data.collections["Layer2Excludes"])
    other.view_layers[0].use = False
    other.view_layers.new("Layer 2").layer_collection.children["Layer2Excludes"].exclude = True
    blend = tmp_path / "two_scenes.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "out"
    assert cli.execute(["render", str(blend), "--scene", "Shot B", "--out", str(out), "--samples", "1"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["scene"] == "Shot B" and [(f["frame"], f["triangles"]) for f in report["frames"]] == [(7, 12)]
    assert cli.execute(["render", str(blend), "--scene", "Nope", "--out", str(tmp_path / "x")]) == 1
    assert "no scene named 'Nope' in the file; its scenes: 'Scene', 'Shot B'" in capsys.readouterr().err


@pytest.mark.parametrize("registered", [False, True])
def test_cli_takes_the_files_saved_settings_and_options_override_them(tmp_path, registered):
    """What the panel saved in the .blend is what the command line renders, option by option overridden;
    with the add-on not registered (python -m kd_addon) as well as registered (blender --command)."""
    scenes.reset()
    add_quad("Floor", 5, 5)
    add_top_camera(location=(0, 0, 12))
    add_sun()
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 40, 30
    kd_addon.register()
    try:
        saved = scene.kd_preview
        saved.mode, saved.samples, saved.ao_distance = "ao+shadow", 3, 0.25
        saved.resolution_percentage, saved.output_format, saved.seed = 100, "OPEN_EXR", 7
        saved.denoise = saved.lazy = saved.rebuild_all = True  # on/off switches: --no-X turns them off
        blend = tmp_path / "panel.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        kd_addon.unregister()
    scenes.reset()
    if registered:
        kd_addon.register()
    try:
        out = tmp_path / "out"
        assert cli.execute(["render", str(blend), "--out", str(out), "--frames", "1", "--samples", "2",
                            "--no-denoise", "--no-lazy"]) == 0
    finally:
        if registered:
            kd_addon.unregister()
    settings = json.loads((out / "report.json").read_text())["settings"]
    assert (settings["mode"], settings["samples"], settings["ao_distance"]) == ("ao+shadow", 2, 0.25)
    assert (settings["resolution_percentage"], settings["output_format"], settings["seed"]) == (100, "OPEN_EXR", 7)
    assert (settings["denoise"], settings["lazy"], settings["rebuild_all"]) == (False, False, True)
    assert exr_channels(out / "frame_0001.exr")["A"].shape == (30, 40)
    assert hasattr(bpy.types.Scene, "kd_preview") is False  # the settings group went again


@pytest.mark.parametrize("args, code, message", [
    (["render", "--out", "X", "--frames", "5-2"], 1, "bad frame range '5-2': the end (2) is before the start (5)"),
    (["render", "--out", "X", "--frames", "1-5:0"], 1, "bad frame range '1-5:0': the step must be 1 or more, got 0"),
    (["render", "--out", "X", "--frames", "1,x"], 1, "bad frame range 'x': use N, A-B or A-B:STEP, or a comma list"),
    (["render", "--out", "X", "--frames", ""], 1, "bad frame range '': no frames"),  # not the scene's range
    (["render", "--out", "X", "--frames", "1,,2"], 1, "bad frame range '1,,2': an empty item in the comma list"),
    (["render", "--out", "X", "--frames", "1-6:-1"], 1, "bad frame range '1-6:-1': the step must be 1 or more, got -1"),
    (["render", "--out", "X", "--chunk-size", "-1"], 1, "--chunk-size must be 1 or more (0: automatic), got -1"),
    (["render", "--out", "X", "--retries", "-1"], 1, "--retries must be 0 or more, got -1"),
    (["render", "--out", "X", "--connect-timeout", "0"], 1, "--connect-timeout must be above 0 seconds, got 0"),
    # the flag typed, then the setting behind it (the setting's name alone is not what the user typed)
    (["render", "--out", "X", "--resolution", "0"], 1,
     "--resolution: resolution_percentage must be an integer from 1 to 100"),
    (["render", "--out", "X", "--leaf-size", "0"], 1, "--leaf-size: leaf_size must be an integer from 1"),
    (["render", "--out", "X", "--ao-distance", "-1"], 1, "--ao-distance: ao_distance must be a finite number"),
    (["render", "--out", "X", "--memory-limit", "-1"], 1, "--memory-limit: memory_limit_mb must be an integer"),
    (["render", "--out", "X", "--mode", "normals"], 1, "--mode: mode must be one of auto, ao, shadow, ao+shadow"),
    (["render", "missing.blend", "--out", "X", "--frames", "5-1"], 1, "bad frame range '5-1'"),  # before the file
    (["render", "missing.blend", "--out", "X"], 1, "no such .blend file: missing.blend"),
    (["render", ".", "--out", "X"], 1, ". is a folder, not a .blend file"),
    (["render", "scene.blend", "--demo", "--out", "X"], 1, "give a .blend file or --demo, not both"),
    (["render", "--frames", "1"], 2, "the following arguments are required: --out"),
    (["render", "--out", "X", "--samples", "many"], 2, "argument --samples: invalid int value"),
    (["paint", "--out", "X"], 2, "invalid choice: 'paint'"),
])
def test_usage_and_setting_errors_exit_nonzero_with_the_message(tmp_path, capsys, monkeypatch, args, code, message):
    monkeypatch.chdir(tmp_path)
    assert cli.execute(args) == code
    assert message in capsys.readouterr().err
    assert not (tmp_path / "X").exists()


@pytest.mark.parametrize("content", [b"", b"garbage\n", b"BLEND", b"\x89PNG\r\n\x1a\n" + bytes(64)])
def test_a_file_that_is_no_blend_is_named_and_blender_says_nothing(tmp_path, capfd, content):
    """Blender's own "File format is not supported" must not go to stdout ahead of our error."""
    path = tmp_path / "scene.blend"
    path.write_bytes(content)
    assert cli.execute(["render", str(path), "--out", str(tmp_path / "o")]) == 1
    captured = capfd.readouterr()
    assert f"{path} is not a .blend file (it does not begin with Blender's file header)" in captured.err
    assert captured.out == "" and not (tmp_path / "o").exists()


def test_messages_name_the_program_as_it_was_run(tmp_path, capsys):
    """Under `python -m kd_addon` errors name that program, as argparse's usage errors do, not
    "kdpreview:" (the Blender command's name)."""
    assert cli.main(["render", str(tmp_path / "missing.blend"), "--out", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err.startswith(f"python -m kd_addon: error: no such .blend file: {tmp_path}")
    assert cli.execute(["render", str(tmp_path / "missing.blend"), "--out", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err.startswith("kdpreview: error: no such .blend file")


def test_scene_errors_exit_nonzero_with_the_message(tmp_path, capsys):
    floor_scene(40, 30, camera=False)
    no_camera = tmp_path / "no_camera.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(no_camera))
    add_top_camera()
    bpy.data.objects["Floor"].hide_render = True
    nothing = tmp_path / "nothing.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(nothing))
    assert cli.execute(["render", str(no_camera), "--out", str(tmp_path / "o"), "--frames", "1"]) == 1
    assert "has no active camera" in capsys.readouterr().err
    # Nothing visible is a warning, not an error: the frame is written transparent (objects may appear later).
    assert cli.execute(["render", str(nothing), "--out", str(tmp_path / "o"), "--frames", "1"]) == 0
    assert "warning: frame 1: nothing to render at frame 1" in capsys.readouterr().err
    assert (tmp_path / "o" / "frame_0001.png").is_file()


def test_frames_outside_the_scene_range_render_with_a_note(tmp_path, capsys):
    """--frames beyond the scene's range render, as Blender goes to any frame, with a note naming them
    (without it a typo goes unseen)."""
    floor_scene(40, 30)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end, name = 1, 5, scene.name  # the file's reload removes this scene
    blend = tmp_path / "short.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "o"
    assert cli.execute(["render", str(blend), "--out", str(out), "--frames", "5-7", "--samples", "1"]) == 0
    err = capsys.readouterr().err
    assert (f"note: 2 of the frames (6 ... 7) are outside the frame range 1-5 of scene '{name}'; rendering "
            "them anyway") in err
    assert sorted(p.name for p in out.glob("*.png")) == ["frame_0005.png", "frame_0006.png", "frame_0007.png"]
    assert cli.execute(["render", str(blend), "--out", str(out), "--frames", "2-3", "--samples", "1"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_frames_with_nothing_visible_are_transparent_and_the_sequence_goes_on(tmp_path, capsys):
    floor_scene(40, 30)
    floor = bpy.data.objects["Floor"]
    floor.hide_render = True
    floor.keyframe_insert("hide_render", frame=1)
    floor.hide_render = False
    floor.keyframe_insert("hide_render", frame=3)
    blend = tmp_path / "appears.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "seq"
    assert cli.execute(["render", str(blend), "--out", str(out), "--frames", "1-3", "--format", "exr",
                        "--samples", "2"]) == 0
    err = capsys.readouterr().err
    assert "frame 1: nothing to render" in err and "frame 2: nothing to render" in err and "frame 3" not in err
    report = json.loads((out / "report.json").read_text())
    assert [row["triangles"] for row in report["frames"]] == [0, 0, 2]
    alphas = [exr_channels(out / f"frame_000{f}.exr")["A"] for f in (1, 2, 3)]
    assert (alphas[0] == 0.0).all() and (alphas[1] == 0.0).all() and (alphas[2] == 1.0).all()


def test_unwritable_output_folder_is_named_before_a_frame_renders(tmp_path, capsys):
    """Checked before any render: otherwise the problem shows only when frame 1 is written, after its
    render (minutes on a first run). An --out under a file is refused before the scene loads, so no
    run line or table header precedes the error."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    assert cli.execute(["render", "--frames", "1", "--out", str(blocker / "sub"), *SMALL]) == 1
    out, err = capsys.readouterr()
    assert f"error: cannot write to the output folder {blocker / 'sub'}: {blocker} is a file, not a folder" in err
    assert "frame 1:" not in err and out == ""  # stopped before the run's first line
    assert cli.execute(["render", "--frames", "1", "--out", str(blocker), *SMALL]) == 1  # the file itself
    assert f"{blocker}: {blocker} is a file, not a folder" in capsys.readouterr().err
    assert blocker.read_text() == "not a folder"


def test_report_that_cannot_be_written_is_not_blamed_on_a_frame(tmp_path, capsys):
    (tmp_path / "seq" / "report.json").mkdir(parents=True)  # a folder where the report goes
    assert cli.execute(["render", "--frames", "1-2", "--out", str(tmp_path / "seq"), *SMALL]) == 1
    err = capsys.readouterr().err
    assert f"error: could not write {tmp_path / 'seq' / 'report.json'}" in err and "frame 2:" not in err


@pytest.mark.parametrize("warm", [False, True])
def test_a_first_run_says_that_it_compiles(tmp_path, capsys, monkeypatch, warm):
    """A first run says it compiles: otherwise it prints the table header, then nothing for minutes,
    and looks hung."""
    monkeypatch.setattr(corelib, "cache_is_warm", lambda kernel=corelib.WARM_KERNEL: warm)
    monkeypatch.setenv("KD_PREVIEW_WARMUP", "0")  # the cache is warm: no compile process for a pretended cold one
    assert cli.execute(["render", "--frames", "1", "--out", str(tmp_path), *SMALL]) == 0
    assert ("compiling the kernels (first use)" in capsys.readouterr().out) is not warm


def test_a_compile_inside_a_frame_is_timed_apart_from_it(tmp_path, capsys, monkeypatch):
    """A kernel compiled during a frame (the denoiser's on a first denoised frame, every kernel without
    the warm-up) goes to the frame's compile_ms, out of its times, as the background compile does."""
    import time

    from numba import njit

    import core.render.preview_render as preview_render
    spent = []

    def compiling_image(render, *args, **kwargs):
        start = time.perf_counter()
        for k in range(3):  # functions this process has never compiled: each run compiles them
            njit(cache=False)(lambda x, k=float(k + len(spent)): np.sin(x * k).sum() + np.cos(x + k).sum())(np.ones(3))
        spent.append(time.perf_counter() - start)
        return original(render, *args, **kwargs)

    out = tmp_path / "o"
    assert cli.execute(["render", "--frames", "1", "--out", str(out), *SMALL]) == 0  # kernels loaded
    warm = frame_rows(out)[0]
    original = preview_render.PreviewRender.image
    monkeypatch.setattr(preview_render.PreviewRender, "image", compiling_image)
    assert cli.execute(["render", "--frames", "1", "--out", str(out), *SMALL]) == 0
    row, compiled_ms = frame_rows(out)[0], spent[0] * 1e3
    assert row["compile_ms"] >= 0.8 * compiled_ms
    assert row["total_ms"] < warm["total_ms"] + 0.5 * compiled_ms  # without the compile
    assert "kernels: compiled in" in capsys.readouterr().out


def test_unwritable_output_folder_is_named_before_the_run_starts(tmp_path, capsys, monkeypatch):
    """A folder that cannot be written (a read-only disk, another user's folder; tested through
    os.access, as this suite may run as root) is named before the run's first line."""
    import os
    readonly = tmp_path / "ro"
    readonly.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode, **kw: False if str(path) == str(readonly)
                        else real_access(path, mode, **kw))
    assert cli.execute(["render", "--frames", "1", "--out", str(readonly / "sub"), *SMALL]) == 1
    out, err = capsys.readouterr()
    assert f"error: cannot write to the output folder {readonly / 'sub'}: {readonly} is not writable" in err
    assert out == "" and not (readonly / "sub").exists()


def test_more_threads_than_the_machine_runs_are_noted(tmp_path, capsys):
    import numba
    available = numba.config.NUMBA_NUM_THREADS
    out = str(tmp_path)
    assert cli.execute(["render", "--frames", "1", "--out", out, "--threads", str(available + 3), *SMALL]) == 0
    assert (f"note: threads {available + 3} is more than Numba's {available} threads in this process; using "
            f"{available}" in capsys.readouterr().err)
    assert json.loads((tmp_path / "report.json").read_text())["run"]["threads"] == available
    assert cli.execute(["render", "--frames", "1", "--out", str(tmp_path), "--threads", str(available), *SMALL]) == 0
    assert "note:" not in capsys.readouterr().err


def test_the_star_legend_is_printed_only_with_a_starred_frame(capsys):
    from types import SimpleNamespace
    totals = dict(frames=1, triangles=2, extract_ms=1.0, build_ms=1.0, trace_ms=1.0, mrays_per_s=1.0,
                  mean_total_ms_after_first=3.0, objects_rebuilt=1, objects_reused=0, images_reused=0)
    job = SimpleNamespace(totals=totals, config=SimpleNamespace(settings=SimpleNamespace(rebuild_all=False)),
                          report_path="report.json")
    cli._print_totals(job, False)
    assert "(* =" not in capsys.readouterr().out
    cli._print_totals(job, True)
    assert "(* = includes loading kernels)" in capsys.readouterr().out


def test_empty_output_folder_is_named(capsys):
    assert cli.execute(["render", "--frames", "1", "--out", " ", *SMALL]) == 1
    assert "--out is empty: give the folder to write the frames to" in capsys.readouterr().err


def test_help_exits_zero(capsys):
    assert cli.execute(["render", "--help"]) == 0
    assert "--frames" in capsys.readouterr().out


def test_python_dash_m_main_job(tmp_path):
    """The README's main command, end to end in a fresh process."""
    out = tmp_path / "x"
    proc = run_python(["-m", "kd_addon", "render", "--frames", "1-3", "--out", str(out), "--resolution", "5"])
    assert proc.returncode == 0, proc.stderr
    assert [r["frame"] for r in frame_rows(out)] == [1, 2, 3]
    assert proc.stdout.count("\n") >= 6 and "Mrays/s" in proc.stdout
    bad = run_python(["-m", "kd_addon", "render", "--frames", "x", "--out", str(out)])
    assert bad.returncode == 1 and "bad frame range 'x'" in bad.stderr


def test_denoise_flag_filters_the_frames(tmp_path):
    """--denoise reaches the report and changes the pixels but not which pixels are hit (alpha)."""
    images = {}
    for name, extra in (("raw", []), ("denoised", ["--denoise"])):
        out = tmp_path / name
        assert cli.execute(["render", "--frames", "1", "--out", str(out), "--format", "exr", *SMALL, *extra]) == 0
        report = json.loads((out / "report.json").read_text())
        assert report["settings"]["denoise"] is (name == "denoised")
        image = bpy.data.images.load(str(out / "frame_0001.exr"))
        images[name] = np.array(image.pixels[:], dtype=np.float32).reshape(-1, 4)
    raw, den = images["raw"], images["denoised"]
    np.testing.assert_array_equal(raw[:, 3], den[:, 3])
    assert np.isfinite(den).all() and not np.array_equal(raw[:, :3], den[:, :3])


def test_a_light_switched_off_for_renders_darkens_its_frames_and_the_run_goes_on(tmp_path, capsys):
    """The only light keyed Disable in Renders on frame 2 renders that frame dark with a warning, as a light
    keyed to emit nothing does, rather than stopping the run; a scene with no light stays an error."""
    floor_scene(40, 30)
    sun = add_sun()
    for frame, hidden in ((1, False), (2, True), (3, False)):
        sun.hide_render = hidden
        sun.keyframe_insert("hide_render", frame=frame)
    bpy.context.scene.frame_set(1)
    blend = tmp_path / "switched.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "seq"
    assert cli.execute(["render", str(blend), "--out", str(out), "--frames", "1-3", "--mode", "Shadow",  # any case,
                        "--format", "exr", "--samples", "2"]) == 0  # as --format takes
    assert json.loads((out / "report.json").read_text())["settings"]["mode"] == "shadow"
    err = capsys.readouterr().err
    assert "frame 2: light 'Sun' is not visible in renders on this frame (its Disable in Renders is keyed)" in err
    assert "frame 2: no light of scene 'Scene' emits on this frame: the shadow term is 0" in err
    assert "frame 1: light" not in err and "frame 3: light" not in err
    rgb = [exr_channels(out / f"frame_000{f}.exr")["R"] for f in (1, 2, 3)]
    assert rgb[0].min() > 0.5 and not rgb[1].any()
    np.testing.assert_array_equal(rgb[2], rgb[0])
    sun = bpy.data.objects["Sun"]  # the run loaded the file: `sun` above is gone
    sun.animation_data_clear()
    sun.hide_render = True  # switched off for good, not keyed: an error, as without any light
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.execute(["render", str(blend), "--out", str(tmp_path / "none"), "--frames", "1", "--mode",
                        "shadow"]) == 1
    assert "mode 'shadow' needs a light, but scene 'Scene' has no render-visible light" in capsys.readouterr().err


def test_choices_are_taken_in_any_case(tmp_path):
    """--mode and --builder as --format: "MEDIAN" is the median builder, not an error."""
    out = tmp_path / "cased"
    assert cli.execute(["render", *SMALL, "--frames", "1", "--out", str(out), "--builder", "MEDIAN", "--mode", "AO",
                        "--format", "exr"]) == 0
    settings = json.loads((out / "report.json").read_text())["settings"]
    assert (settings["builder"], settings["mode"], settings["output_format"]) == ("median", "ao", "OPEN_EXR")


def test_out_starting_with_double_slash_is_beside_the_blend(tmp_path, capsys, monkeypatch):
    """Blender's "//" means the .blend's folder (the panel's default output is //kd_preview/): --out
    //renders writes beside the file given, or the file Blender has open, never under the filesystem's
    root; the demo has no file, so there it is an error."""
    scenes.reset()
    add_quad("Floor", 5, 5)
    add_top_camera(location=(0, 0, 12))
    bpy.context.scene.render.resolution_x, bpy.context.scene.render.resolution_y = 20, 15
    blend = tmp_path / "shot" / "scene.blend"
    blend.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    monkeypatch.chdir(tmp_path)  # a relative path would land here, not beside the file
    assert cli.execute(["render", str(blend), "--out", "//renders/a", "--frames", "1", "--samples", "1"]) == 0
    assert (tmp_path / "shot" / "renders" / "a" / "frame_0001.png").is_file()
    # the file Blender has open (blender -b scene.blend --command kdpreview render ...)
    assert cli.execute(["render", "--out", "//renders/b", "--frames", "1", "--samples", "1"]) == 0
    assert (tmp_path / "shot" / "renders" / "b" / "frame_0001.png").is_file()
    link = tmp_path / "link.blend"  # Blender opens the file itself, so "//" is beside the link's target
    link.symlink_to(blend)
    assert cli.execute(["render", str(link), "--out", "//renders/l", "--frames", "1", "--samples", "1"]) == 0
    assert (tmp_path / "shot" / "renders" / "l" / "frame_0001.png").is_file()
    capsys.readouterr()
    assert cli.execute(["render", "--out", "//renders/c", *SMALL]) == 1
    assert "--out //renders/c is relative to the .blend file (Blender's //), but this run has none" in (
        capsys.readouterr().err)
    assert not (tmp_path / "shot" / "renders" / "c").exists()


def test_a_ctrl_c_after_the_run_ended_keeps_its_exit_code():
    """A Ctrl-C in the teardown after `python -m kd_addon` finished (its report written) does not turn
    exit 0 into a death by SIGINT: a script or farm waiting for the run would call it interrupted."""
    script = """
import os, runpy, signal, sys, time
sys.argv = ["kd_addon", "render", "--help"]
try:
    runpy.run_module("kd_addon", run_name="__main__")
except SystemExit:
    os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C during the teardown
    time.sleep(0.5)
    raise
"""
    proc = run_python(script)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    assert "usage:" in proc.stdout and "Traceback" not in proc.stderr


def test_an_output_folder_that_cannot_be_made_says_so(tmp_path, capsys, monkeypatch):
    """A folder whose parent is writable but that cannot be made (/proc/x, a full disk, a name the file
    system refuses) is named as not created, not as not writable, and the run writes nothing."""
    from pathlib import Path

    def refuse(self, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "mkdir", refuse)
    out = tmp_path / "new"
    assert cli.execute(["render", "--out", str(out), "--frames", "1", *SMALL]) == 1
    assert f"error: cannot create the output folder {out}: No space left on device" in capsys.readouterr().err
    assert not out.exists()


def test_negative_frame_ranges_are_taken_as_blender_takes_them(tmp_path):
    """Blender's frames go below 0: `--frames -2--1` is a range, not an unknown option."""
    out = tmp_path / "o"
    assert cli.execute(["render", "--out", str(out), "--frames", "-2--1", *SMALL]) == 0
    assert [row["frame"] for row in json.loads((out / "report.json").read_text())["frames"]] == [-2, -1]
    assert cli._frames_joined(["render", "--frames", "-2-1", "--samples", "2"]) == [
        "render", "--frames=-2-1", "--samples", "2"]
    assert cli._frames_joined(["--frames", "1-3", "--out", "-x"]) == ["--frames", "1-3", "--out", "-x"]
    assert cli._frames_joined(["--fr", "-2-1", "--fra", "-3", "--format", "-x"]) == [
        "--frames=-2-1", "--frames=-3", "--format", "-x"]
    parsed = cli.build_parser().parse_args(cli._frames_joined(["render", "--out", "o", "--fram", "-2-1"]))
    assert parsed.frames == "-2-1"


def test_a_saved_enum_number_that_names_no_item_is_named_by_the_command_line(tmp_path, capsys):
    """A file whose mode is stored as a number no item has (another version's, a script's) fails on the
    command line with the number named, as in the panel (config.read_setting), not as "got ''"."""
    scene = floor_scene(40, 30)
    kd_addon.register()
    try:
        scene.kd_preview["mode"] = 7
        blend = tmp_path / "odd.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        kd_addon.unregister()
    assert cli.execute(["render", str(blend), "--out", str(tmp_path / "o"), "--frames", "1"]) == 1
    assert "mode must be one of auto, ao, shadow, ao+shadow; got stored item number 7" in capsys.readouterr().err
