"""The first render's helper process (core/jit/parallel_compile.py) and the lock that lets several processes
write one kernel cache (core/jit/kernel_cache.py)."""
import os
import select
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from core.jit import kernel_cache, parallel_compile

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
from numba import njit

@njit(cache=True)
def twice(x):
    return 2 * x
"""
COMPILE_PROBE = """
import sys, time
sys.path[:0] = [{root!r}, {folder!r}]
from core.jit import kernel_cache
kernel_cache.register({folder!r}, sources={folder!r})
asking = kernel_cache.locked_cache_folder

def announced(folder):  # says when the save asks for the lock, so the test need not guess
    print("asking", flush=True)
    return asking(folder)

kernel_cache.locked_cache_folder = announced
import probe
probe.twice(21)
print(time.time())
"""


@pytest.mark.slow
@pytest.mark.skipif(os.name == "nt", reason="the lock is held here with fcntl")
def test_a_cache_index_save_waits_for_the_lock(tmp_path):
    """A process compiling a registered kernel writes its cache index only once the folder's lock is
    free: it returns after the holder released the lock, and its entry is then in the index."""
    folder = tmp_path / "src"
    folder.mkdir()
    (folder / "probe.py").write_text(PROBE)
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    script = COMPILE_PROBE.format(root=str(ROOT), folder=str(folder))
    # Where the child's cache files go: the same locator here, on the same file.
    probe_cache = _probe_cache_folder(folder, cache)
    probe_cache.mkdir(parents=True, exist_ok=True)
    child = None
    try:
        with kernel_cache.locked_cache_folder(str(probe_cache)):
            child = subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE, text=True)
            assert select.select([child.stdout], [], [], 120)[0], "the child never reached its cache save"
            assert child.stdout.readline().strip() == "asking"
            time.sleep(2)  # without the lock, the save (milliseconds) and the exit would be done by now
            assert child.poll() is None, "the child finished while the lock was held"
            assert not list(probe_cache.glob("*.nbi")), "the child wrote its index while the lock was held"
            released = time.time()
        out, _ = child.communicate(timeout=120)
    finally:
        if child is not None and child.poll() is None:
            child.kill()
    assert child.returncode == 0
    assert float(out.split()[-1]) >= released
    assert len(list(probe_cache.glob("*twice*.nbi"))) == 1 and len(list(probe_cache.glob("*twice*.nbc"))) == 1


def _probe_cache_folder(folder: Path, cache: Path) -> Path:
    """The folder Numba's cache locator picks for folder/probe.py under NUMBA_CACHE_DIR=cache,
    asked in a fresh process (the locator reads NUMBA_CACHE_DIR once)."""
    code = textwrap.dedent(f"""
        import sys
        sys.path[:0] = [{str(ROOT)!r}, {str(folder)!r}]
        from core.jit import kernel_cache
        kernel_cache.register({str(folder)!r}, sources={str(folder)!r})
        import probe
        print(probe.twice._cache._cache_path)
    """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    return Path(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                               check=True).stdout.strip())


FAKE_CORE = """
import sys
from pathlib import Path

def compile_rendering_kernels(denoise):
    Path(sys.argv[2], "ran.txt").write_text(f"{__name__} denoise={denoise}")
"""


def test_the_helper_imports_core_under_an_extension_package_name(tmp_path):
    """Installed, core is `bl_ext.<repo>.<id>.core` and the add-on's __init__ imports bpy: the helper
    imports core under that name without running the parents' __init__ files."""
    core_folder = tmp_path / "bl_ext" / "user_default" / "kd_preview" / "core"
    (core_folder / "jit").mkdir(parents=True)
    for folder in (core_folder, core_folder / "jit"):
        (folder / "__init__.py").write_text("")
    (core_folder / "jit" / "parallel_compile.py").write_text(FAKE_CORE)
    for parent in core_folder.parents[:3]:
        (parent / "__init__.py").write_text("raise ImportError('a parent package ran')\n")
    name = "bl_ext.user_default.kd_preview.core"
    for flag, denoise in (("1", True), ("0", False)):
        run = subprocess.run([sys.executable, "-c", parallel_compile._HELPER_CODE, name, str(core_folder), flag],
                             capture_output=True, text=True, cwd=tmp_path)
        assert run.returncode == 0, run.stderr
        assert (core_folder / "ran.txt").read_text() == f"{name}.jit.parallel_compile denoise={denoise}"


SLOW_FAKE_CORE = """
import os, sys, time
from pathlib import Path

def compile_rendering_kernels(denoise):
    Path(sys.argv[2], "helper.pid").write_text(str(os.getpid()))
    time.sleep(300)
"""

PARENT = """
import os, subprocess, sys, time
from pathlib import Path
code, name, folder = Path(sys.argv[1]).read_text(), sys.argv[2], Path(sys.argv[3])
helper = subprocess.Popen([sys.executable, "-c", code, name, str(folder), "0"], stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL, env=dict(os.environ, KD_PREVIEW_HELPER_PARENT=str(os.getpid())))
while not (folder / "helper.pid").exists():
    time.sleep(0.1)
time.sleep(2.0)
print("alive" if helper.poll() is None else "ended", flush=True)
os._exit(0)  # as `python -m kd_addon` ends after Ctrl-C: the helper is never stopped
"""


@pytest.mark.slow
@pytest.mark.skipif(os.name == "nt", reason="the helper watches its parent's pid (POSIX getppid)")
def test_the_helper_ends_when_its_parent_is_gone(tmp_path):
    """The helper lives while its parent does and ends within a second or two once the parent is gone
    without stopping it: otherwise Ctrl-C during a first run's compile would leave it compiling for
    ~70 s after the command line has exited."""
    core_folder = tmp_path / "pkg" / "core"
    (core_folder / "jit").mkdir(parents=True)
    for folder in (core_folder, core_folder.parent, core_folder / "jit"):
        (folder / "__init__.py").write_text("")
    (core_folder / "jit" / "parallel_compile.py").write_text(SLOW_FAKE_CORE)
    (tmp_path / "helper.py").write_text(parallel_compile._HELPER_CODE)
    parent = subprocess.run([sys.executable, "-c", PARENT, str(tmp_path / "helper.py"), "pkg.core", str(core_folder)],
                            capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert parent.stdout.strip() == "alive", parent.stderr
    pid = int((core_folder / "helper.pid").read_text())
    deadline = time.monotonic() + 15.0
    while _running(pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _running(pid), "the helper outlived its parent"


def _running(pid: int) -> bool:
    """True while process `pid` exists and is not a zombie (an orphan's exit may wait for a reaper)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return False
    except OSError:  # no /proc (macOS): ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True
    return state != "Z"


def test_the_helper_renders_with_the_rendering_kernels_and_exits_cleanly(tmp_path, monkeypatch):
    """The helper's program, started as the first render starts it (here on this run's cache, so it
    mostly loads kernels): it renders the hand-made tree and exits with status 0. It uses this
    process's cache folder even when NUMBA_CACHE_DIR, set after core's kernels were decorated, names
    another (Numba re-reads it before every compile, a test module set it): it writes nothing there."""
    elsewhere = tmp_path / "elsewhere"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(elsewhere))
    parallel_compile.compile_scene_wrapping()
    helper = parallel_compile.RenderingKernelsHelper()
    try:
        helper.wait(600)
    finally:
        helper.stop()
    assert helper.outcome == "finished", helper.outcome
    assert parallel_compile.rendering_kernels_cached()
    assert not list(elsewhere.rglob("render_kernels*")), "the helper compiled into NUMBA_CACHE_DIR"


def test_no_helper_when_the_kernels_are_cached_or_it_is_switched_off(monkeypatch):
    parallel_compile.compile_rendering_kernels()  # in this process: they are in the cache now
    with parallel_compile.rendering_kernels_alongside() as helper:
        assert helper is None
    monkeypatch.setattr(parallel_compile, "rendering_kernels_cached", lambda: False)
    monkeypatch.setenv(parallel_compile.HELPER_SWITCH, "0")
    with parallel_compile.rendering_kernels_alongside() as helper:
        assert helper is None


def test_a_failing_block_ends_the_helper_at_once(monkeypatch):
    """A build that raises must not leave a helper writing the cache while this process goes on."""
    monkeypatch.setattr(parallel_compile, "rendering_kernels_cached", lambda: False)
    monkeypatch.delenv(parallel_compile.HELPER_SWITCH, raising=False)
    with pytest.raises(ValueError, match="bad build"):
        with parallel_compile.rendering_kernels_alongside() as helper:
            assert helper is not None
            raise ValueError("bad build")
    assert helper.process.poll() is not None


def test_the_two_sides_compile_what_a_real_render_runs():
    """The helper's made-up camera hits and top level, and the camera pass run here, must give the kernels
    the real render's argument types: otherwise a first frame would compile its kernels again after the wait.
    After both sides ran in this process, the warm-up's packet frames (first_frame.py: real frames) add
    no version to a rendering kernel; after those, renders of a built tree, of a two-level scene and of
    one placed instance (raw and denoised, every mode) add no version to any kernel."""
    import numpy as np

    import core
    from core.build import box_tree
    from core.jit import first_frame
    from core.render import camera as camera_module
    from core.render import denoise, hit_frames, render_kernels
    from core.scene import instance_packets, instance_traversal, scene_packets
    from core.trace import packet_traversal

    parallel_compile.compile_rendering_kernels(denoise=True)
    parallel_compile.compile_camera_pass()
    kernels = [render_kernels.add_samples, hit_frames.surface_frames, render_kernels.assemble_image,
               camera_module._pixel_rays, instance_traversal.trace_scene_rays, box_tree.build_box_subtree]
    kernels += [k for k in vars(denoise).values() if hasattr(k, "signatures")]
    sides = {k: len(k.signatures) for k in kernels}
    assert all(sides[k] > 0 for k in kernels[:6]), "a side did not run a rendering kernel"
    first_frame.compile_packet_kernels()
    assert {k: len(k.signatures) for k in kernels} == sides, "the sides compiled another argument type"
    kernels += [packet_traversal.trace_packets, scene_packets._rays_to_object, *instance_packets.KERNELS]
    before = {k: len(k.signatures) for k in kernels}
    tris = np.array([[[-1, -1, 0], [1, -1, 0], [0, 1, 0]], [[-1, -1, 0.5], [1, -1, 0.5], [0, 1, 0.5]]], np.float32)
    vertices, faces = tris.reshape(-1, 3), np.arange(6, dtype=np.int32).reshape(2, 3)
    placed = np.eye(4)
    placed[:3, 3] = (0.3, -0.2, -1.0)
    scenes = [core.build_kdtree(tris), core.build_scene([(vertices, faces)], [0, 0], np.stack([np.eye(4)] * 2)),
              core.build_scene([(vertices, faces)], [0], placed[None])]
    camera = core.Camera(np.array([[1.0, 0, 0, 0.2], [0, 1, 0, 0.1], [0, 0, 1, 3], [0, 0, 0, 1]]), 0.9)
    for scene in scenes:
        for mode in ("ao", "shadow", "ao+shadow"):
            render = core.PreviewRender(scene, camera, 9, 7, mode=mode, samples=2,
                                        lights=[core.Light.point((0.0, 0.0, 2.0))])
            render.step(2)
            assert render.image()[..., 3].sum() > 0
            render.image(denoise=True)
    assert {k: len(k.signatures) for k in kernels} == before


@pytest.mark.parametrize("packets", [True, False])
def test_the_camera_pass_beside_a_helper_takes_packets_as_asked(monkeypatch, packets):
    """rendering_kernels_alongside(packets=...) runs its camera pass with that compile_packets (the add-on
    passes False: its renders take packets only once cached, so the pass compiles none either)."""
    from core.render import preview_render

    class Helper:
        def __init__(self, denoise=False):
            pass
        wait = stop = lambda self, timeout=None: True

    made = []
    original = preview_render.PreviewRender.__init__
    monkeypatch.setattr(preview_render.PreviewRender, "__init__", lambda self, *a, **k: made.append(
        k.get("compile_packets")) or original(self, *a, **k))
    monkeypatch.setattr(parallel_compile, "rendering_kernels_cached", lambda: False)
    monkeypatch.setattr(parallel_compile, "RenderingKernelsHelper", Helper)
    monkeypatch.delenv(parallel_compile.HELPER_SWITCH, raising=False)
    with parallel_compile.rendering_kernels_alongside(packets=packets) as helper:
        assert isinstance(helper, Helper)
    assert made == [packets]


SIDES = """
import sys
sys.path.insert(0, {root!r})
from core.jit import parallel_compile
from core.render import hit_frames, render_kernels
from core.scene import instance_traversal
parallel_compile.compile_scene_wrapping()
getattr(parallel_compile, sys.argv[1])()
print(*(len(k.signatures) for k in (render_kernels.add_samples, hit_frames.surface_frames,
                                     instance_traversal.trace_scene_rays)))
"""


def test_the_helper_makes_the_hit_frames_and_traces_no_camera_ray():
    """The split (module docstring): the helper's side runs the sampling kernel and surface_frames but
    not the camera rays' traversal, which this process compiles after the build; the camera pass runs
    the traversal and surface_frames and no sampling. Each side in a fresh process (loading what this
    run's cache holds): (add_samples, surface_frames, trace_scene_rays) versions it ran."""
    script = SIDES.format(root=str(ROOT))
    ran = {}
    for side in ("compile_rendering_kernels", "compile_camera_pass"):
        run = subprocess.run([sys.executable, "-c", script, side], capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, run.stderr
        ran[side] = [int(n) for n in run.stdout.split()[-3:]]
    assert ran == {"compile_rendering_kernels": [1, 1, 0], "compile_camera_pass": [0, 1, 1]}


def test_the_hand_made_tree_renders_like_a_built_one():
    """The helper's tree is a valid KdTree: its render equals one of a built tree over the same square."""
    import numpy as np

    import core

    tree = parallel_compile.hand_made_tree()
    built = core.build_kdtree(tree.triangles)
    camera = core.Camera(np.array([[1.0, 0, 0, 0.2], [0, 1, 0, 0.1], [0, 0, 1, 3], [0, 0, 0, 1]]), 0.9)
    args = dict(mode="ao+shadow", samples=4, lights=[core.Light.point((0.0, 0.0, 2.0))])
    a, b = core.render_preview(tree, camera, 16, 12, **args), core.render_preview(built, camera, 16, 12, **args)
    assert a[..., 3].sum() > 0 and (a[..., 3] == 0).any()  # the square and background both in view
    np.testing.assert_array_equal(a, b)
