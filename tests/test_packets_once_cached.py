"""Renders that take the camera and hard-shadow packets only once their kernels are compiled
(PreviewRender's compile_packets=False, the add-on's renders): before then the same image from single
rays, no packet kernel called; the readiness check (preview_render._packet_kernels_ready) against a cache
that holds them or not; and the warm-up's stages, of which only the second compiles them
(core/jit/first_frame.py)."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import core
import core.render.preview_render as preview_render
from core.jit import first_frame, parallel_compile
from core.scene import instance_packets, scene_packets
from core.scene.two_level import build_two_level
from core.trace import packet_traversal
from tests.render_scenes import box, floor, look_at

ROOT = Path(__file__).resolve().parent.parent
AREA = np.array([[1.0, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 2.0], [0, 0, 0, 1]])  # facing down, above the box
LIGHTS = [core.Light.point((-0.6, 1.5, 1.5)), core.Light.sun((0.3, -0.6, -1.0)),
          core.Light.spot((0.3, 1.2, 2.0), (-0.1, -0.3, -1.0), spot_size=0.9), core.Light.area(AREA, size=0.5)]


def packet_calls(monkeypatch):
    """Count the calls of the renderer's two packet entries (camera rays, hard shadows), which still run."""
    calls = []
    for name in ("trace_camera_packets", "occluded_in_packets"):
        real = getattr(preview_render, name)
        monkeypatch.setattr(preview_render, name, lambda *a, _real=real, _name=name: calls.append(_name) or _real(*a))
    return calls


def kernel_calls(monkeypatch):
    """Count the calls of the packet traversal itself, wherever the scene packets call it from."""
    calls = []
    real = packet_traversal.trace_packets
    for module in (scene_packets, instance_packets):
        monkeypatch.setattr(module, "trace_packets", lambda *a: calls.append(1) or real(*a))
    return calls


def scenes():
    """A flat tree, one placed instance and two instances: each taken by the packets (packets_apply)."""
    ground, objects = floor(0.0, half=2.0), box((0.4, 0.3, 0.3), (0.2, 0.25, 0.3))
    placed = np.eye(4)
    placed[:3, 3] = (0.1, -0.2, 0.05)
    both = [core.build_kdtree(ground), core.build_kdtree(objects)]
    return {"flat": core.build_kdtree(np.concatenate([ground, objects])),
            "placed": build_two_level([core.build_kdtree(objects)], [0], placed[None]),
            "two": build_two_level(both, [0, 1], np.stack([np.eye(4), placed]))}


def image(scene, **keywords):
    render = core.PreviewRender(scene, look_at((0.3, -2.2, 2.4), (0.0, 0.1, 0.2), fov=1.0), 32, 24, samples=4,
                                mode="ao+shadow", lights=LIGHTS, ao_distance=0.5, **keywords)
    render.step(4)
    return render.image()


@pytest.mark.parametrize("name", ["flat", "placed", "two"])
def test_before_the_packets_are_compiled_a_render_traces_singly_with_the_same_image(name, monkeypatch):
    """compile_packets=False: while _packet_kernels_ready() is False no packet entry is called and the
    image is bit for bit the one in packets (hard shadows then traced by the sampling kernel); once it is
    True the render takes the packets. The default (scripts) takes them whatever the cache holds."""
    scene = scenes()[name]
    calls = packet_calls(monkeypatch)
    monkeypatch.setattr(preview_render, "_packet_kernels_ready", lambda: False)
    in_packets = image(scene)
    assert sorted(set(calls)) == ["occluded_in_packets", "trace_camera_packets"]
    calls.clear()
    np.testing.assert_array_equal(image(scene, compile_packets=False), in_packets)
    assert calls == []
    monkeypatch.setattr(preview_render, "_packet_kernels_ready", lambda: True)
    np.testing.assert_array_equal(image(scene, compile_packets=False), in_packets)
    assert sorted(set(calls)) == ["occluded_in_packets", "trace_camera_packets"]


def test_the_packet_kernels_are_ready_once_loaded_or_cached(tmp_path):
    """_packet_kernels_ready: False in a process whose cache holds none of them, True once packets ran
    here, and True in a new process reading this session's cache, without loading a kernel."""
    script = ("from core.render import preview_render as p\nfrom core.trace.packet_traversal import trace_packets\n"
              "print(p._packet_kernels_ready(), len(trace_packets.signatures), len(p.hard_shadow_rays.signatures))")
    run = dict(cwd=ROOT, capture_output=True, text=True, check=True, timeout=600)
    empty = subprocess.run([sys.executable, "-c", script], env=dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path)), **run)
    assert empty.stdout.split("\n")[-2] == "False 0 0"
    for scene in scenes().values():
        image(scene)
    assert preview_render._packet_kernels_ready()
    cached = subprocess.run([sys.executable, "-c", script], env=dict(os.environ), **run)
    assert cached.stdout.split("\n")[-2] == "True 0 0"


ONE_VERSION = """
import sys
sys.path.insert(0, {root!r})
from core.jit import first_frame
from core.render import render_kernels
from core.scene import instance_packets, scene_packets
from core.trace import packet_traversal
from tests.test_packets_once_cached import image, scenes
first_frame.compile_packet_kernels()
for scene in scenes().values():
    image(scene)
kernels = (packet_traversal.trace_packets, scene_packets._rays_to_object, *instance_packets.KERNELS,
           render_kernels.hard_shadow_rays)
print([len(kernel.signatures) for kernel in kernels])
"""


def test_a_renderers_packets_run_one_version_of_each_kernel_the_readiness_check_reads():
    """_packet_kernels_ready takes any version of each kernel as the renderer's: in a fresh process, the
    second stage's packets and renders of a flat tree, a placed instance and two instances (camera rays
    and hard shadows of every kind of light) run exactly one version of each."""
    out = subprocess.run([sys.executable, "-c", ONE_VERSION.format(root=str(ROOT))], cwd=ROOT, capture_output=True,
                         text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split("\n")[-2] == "[1, 1, 1, 1, 1]"


@pytest.mark.slow
def test_only_the_warm_ups_second_stage_runs_the_packets(monkeypatch):
    """The first frames (which the add-on's first render waits for) call no packet traversal while the
    packets' kernels are not ready; the second stage calls it for one and for several instances."""
    monkeypatch.setenv(parallel_compile.HELPER_SWITCH, "0")  # the helper's side runs here
    monkeypatch.setattr(preview_render, "_packet_kernels_ready", lambda: False)
    calls, entries = kernel_calls(monkeypatch), []
    for module, name in ((scene_packets, "_trace_in_packets"), (scene_packets, "trace_instances_in_packets")):
        real = getattr(module, name)
        monkeypatch.setattr(module, name, lambda *a, _real=real, _name=name: entries.append(_name) or _real(*a))
    first_frame.compile_first_frames()
    assert calls == [] and entries == []
    first_frame.compile_second_stage()
    assert calls and sorted(set(entries)) == ["_trace_in_packets", "trace_instances_in_packets"]
