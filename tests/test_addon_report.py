"""report.json records the run: the input .blend, the versions, threads, CPU and start time, and one
settings block in which "auto" means a setting left to the add-on and null one turned off."""

from __future__ import annotations

import json
import os
import platform
import time
import tomllib
from datetime import datetime, timezone
from pathlib import Path

import bpy
import numba
import numpy as np

from kd_addon import cli
from tests import bpy_scenes as scenes
from tests.addon_support import REPO, add_quad, add_sun, add_top_camera


def saved_scene(tmp_path) -> Path:
    scenes.reset()
    add_quad("Floor", 5, 5)
    scenes.add_cube("Box", location=(0, 0, 1))
    add_top_camera(location=(0, 0, 12))
    add_sun()
    bpy.context.scene.render.resolution_x, bpy.context.scene.render.resolution_y = 40, 30
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    return blend


def test_the_report_records_the_run(tmp_path):
    blend = saved_scene(tmp_path)
    before = time.time()
    assert cli.execute(["render", str(blend), "--out", str(tmp_path / "out"), "--frames", "1", "--samples", "2",
                        "--resolution", "100", "--threads", "1"]) == 0
    after = time.time()
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    run = report["run"]
    assert run["blend_file"] == str(blend)
    manifest = tomllib.loads((REPO / "blender_manifest.toml").read_text())
    assert run["versions"] == {"kd_preview": manifest["version"], "blender": bpy.app.version_string,
                               "python": platform.python_version(), "numba": numba.__version__,
                               "numpy": np.__version__}
    assert run["threads"] == 1 and run["cpu"]["logical_cores"] == os.cpu_count()
    if platform.system() == "Linux":
        assert run["cpu"]["name"] in Path("/proc/cpuinfo").read_text()
    started = datetime.strptime(run["started"], "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=timezone.utc).timestamp()
    assert int(before) <= started <= after
    settings = report["settings"]
    assert (settings["threads"], settings["max_depth"], settings["mode"]) == (1, "auto", "auto")
    assert settings["error_target"] is None and settings["memory_limit_mb"] is None
    assert not {"build_options", "render_options", "machine"} & set(report)  # no second convention
    row = report["frames"][0]
    assert row["mode"] == "ao+shadow"  # what "auto" chose: the scene has a sun
    assert {"compile_ms", "load_ms"} <= set(row) and "compile" in report["timings"]


def test_a_run_without_a_file_says_so(tmp_path):
    """The built-in demo (no .blend) records no input file, and every thread when Threads is automatic."""
    assert cli.execute(["render", "--demo", "--out", str(tmp_path), "--frames", "1", "--samples", "1",
                        "--resolution", "3"]) == 0
    run = json.loads((tmp_path / "report.json").read_text())["run"]
    assert run["blend_file"] is None and run["threads"] == numba.config.NUMBA_NUM_THREADS
