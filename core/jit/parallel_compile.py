"""A first render's JIT compile on two cores: a helper process compiles the rendering kernels into
Numba's on-disk cache while this process builds the tree (compiling the builder's kernels) and then
makes the camera pass (compiling the camera rays' traversal; their hit frames load the helper's).

The helper compiles the top level's box-tree builder first (this process's build loads it), then
surface_frames, the sampling kernel, the image and the denoiser if asked, into the shared cache
(docs/choices.md#the-first-renders-compile-on-two-cores); a kernel needed here before it is saved is
compiled here too. Pixel-reuse kernels compile on the first continued frame.
"""
import os
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..render.camera import Camera
from ..trace.kdtree import KdTree
from .kernel_cache import CORE_CACHE_FOLDER_VARIABLE, CORE_FOLDER, core_cache_folders
from ..trace.layout import LEAF, NodeArrays
from ..render.lights import Light
from ..build.options import BuildOptions
from ..render.preview_render import PreviewRender
from ..render.hit_frames import surface_frames
from ..render.render_kernels import add_samples
from ..scene.two_level import as_two_level, build_two_level

CORE_PACKAGE = __package__.rpartition(".")[0]  # core's module name: "core", or bl_ext.<repo>.<id>.core


def rendering_kernels_cached() -> bool:
    """Whether Numba's cache already holds the sampling kernel for these sources (then a helper would
    only load kernels, which this process does as fast). Reads the kernel's cache index (internal API;
    numba is pinned, as for kernel_cache.py): an index whose stamp does not match reads as empty."""
    cache = getattr(add_samples, "_cache", None)
    try:
        return bool(cache._cache_file._load_index())
    except (AttributeError, OSError, EOFError, ValueError):
        return False


def hand_made_tree() -> KdTree:
    """A two-triangle square in z = 0 as a one-leaf tree, with the node arrays' real dtypes (layout.py),
    made without any builder kernel."""
    tris = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]], [[-1, -1, 0], [1, 1, 0], [-1, 1, 0]]], np.float32)
    flat = tris.reshape(-1, 3)
    bounds = np.concatenate([flat.min(axis=0), flat.max(axis=0)]).astype(np.float32)
    nodes = NodeArrays(np.array([LEAF], np.int8), np.zeros(1, np.float32), np.zeros(1, np.int32),
                       np.array([2], np.int32), np.arange(2, dtype=np.int32))
    return KdTree(tris, bounds, nodes, BuildOptions(), 0.0, np.zeros(0, np.int32))


def compile_scene_wrapping() -> None:
    """The builder kernels a render of a KdTree runs (the one-instance top level), compiled here."""
    as_two_level(hand_made_tree())


def _hand_made_render(render_class, packets=True):
    """A 4 x 4 ao+shadow render of the hand-made tree seen from 3 above, two samples a pixel (modes,
    sizes and sample counts are runtime values: one render compiles what every render uses); `packets`:
    PreviewRender's compile_packets."""
    camera = Camera(np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]), 0.9)
    return render_class(as_two_level(hand_made_tree()), camera, 4, 4, mode="ao+shadow", samples=2,
                        lights=[Light.point((0.0, 0.0, 2.0))], compile_packets=packets)


def compile_camera_pass(packets=True) -> None:
    """The camera pass, run here after the build: a PreviewRender's constructor traces the camera rays
    (in packets unless `packets` is False and their kernels are not cached, as the render's own will be)
    and makes their hit frames (surface_frames: loaded if the helper saved it, else compiled here)."""
    _hand_made_render(PreviewRender, packets)


class _SamplingOnly(PreviewRender):
    """A render that makes up its camera hits without tracing camera rays, so their traversal does not
    compile in the helper: the camera looks straight down at the plane z = 0 (t = 3 / -d_z), and the
    real surface_frames makes the hit frames. The arrays have the real pass's types (int32 instance and
    triangle indices, int64 pixel indices, float64 rays, depths and (M, 3) frames, C-contiguous and
    writable): Numba compiles one version per type signature, and the real render must find this one."""

    def _camera_hits(self, traced, packets=None):  # packets: the camera pass's, not traced here
        origins, directions, _, _ = self.camera.rays(self.width, self.height, traced)
        t = -origins[:, 2] / directions[:, 2]
        first = np.zeros(len(traced), np.int32)
        hit = np.arange(len(traced), dtype=np.int64)
        points, normals, starts = np.empty((len(hit), 3)), np.empty((len(hit), 3)), np.empty((len(hit), 3))
        surface_frames(self.scene.arrays, origins, directions, t, first, first.copy(), hit, points, normals, starts)
        return traced[hit], t[hit], points, normals, starts

    def _occluded(self, directions, tmax, rays):  # made up too: the packet kernels are not the helper's
        return np.zeros(len(rays), bool)


def compile_top_level() -> None:
    """The top level's box-tree builder (box_tree.build_box_subtree, several seconds), which a scene of
    several instances builds after its meshes' trees: compiled here first, while this process's parent
    compiles the mesh builder, it is cached by the time the parent's build reaches it
    (docs/choices.md#the-first-frames-compile-without-the-packet-kernels)."""
    shifted = np.eye(4)
    shifted[0, 3] = 3.0
    build_two_level([hand_made_tree()], np.zeros(2, np.int32), np.stack([np.eye(4), shifted]), threads=1)


def compile_rendering_kernels(denoise=False) -> None:
    """What the helper runs: the top level's builder (compile_top_level), then hit frames, AO and shadow
    samples (rays that hit and miss), the image and the denoiser if asked; sizes, modes and sample counts
    are runtime values, so one render covers all."""
    compile_top_level()
    render = _hand_made_render(_SamplingOnly)
    render.step(render.target_samples)
    render.image(denoise=denoise)


HELPER_SWITCH = "KD_PREVIEW_COMPILE_HELPER"  # "0": no helper process (e.g. where spawning one is not allowed)
HELPER_TIMEOUT = 900.0  # seconds: a guard against a helper that never ends, far above its 1.5-4 minutes


@contextmanager
def rendering_kernels_alongside(denoise=False, warmup=False, packets=True):
    """Compile the rendering kernels in a helper process while the `with` block runs (a build), unless
    the cache holds the sampling kernel or HELPER_SWITCH is "0" (`denoise`: compile the denoiser too);
    yields the helper or None. On leaving, run the camera pass here, then wait for the helper (at most
    HELPER_TIMEOUT); if the block raised, end it at once. No helper runs afterwards. `warmup`: the
    kernel warm-up's made-up frame (first_frame.py), whose block makes its own camera pass: none runs
    on leaving. `packets`: the camera pass's compile_packets (PreviewRender), as the render's own."""
    helper = None
    if os.environ.get(HELPER_SWITCH, "1") != "0" and not rendering_kernels_cached():
        compile_scene_wrapping()
        try:
            helper = RenderingKernelsHelper(denoise)
        except (OSError, ValueError, subprocess.SubprocessError):
            helper = None  # no interpreter to start (an embedded Python): this process compiles it all
    try:
        yield helper
    except BaseException:
        if helper is not None:
            helper.stop()
        raise
    if helper is not None:
        try:
            if not warmup:
                compile_camera_pass(packets)
        finally:
            helper.wait(HELPER_TIMEOUT)
            helper.stop()


class RenderingKernelsHelper:
    """The helper process; start it once compile_scene_wrapping() has run here. It imports core under
    this process's module name (in Blender `bl_ext.<repo>.<id>.core`: a kernel's pickled environment
    names its module), with parent packages stubbed so the add-on's bpy-importing `__init__` does not
    run; writes where this process reads (kernel_cache.CORE_CACHE_FOLDER_VARIABLE); runs one thread and
    keeps its stderr for `outcome`. A failed helper costs only its time."""

    def __init__(self, denoise=False):
        self._errors = tempfile.TemporaryFile()  # the helper's stderr: its last line names a failure
        self.stopped = False
        env = dict(os.environ, NUMBA_NUM_THREADS="1",
                   PYTHONPATH=os.pathsep.join(p for p in sys.path if p and os.path.isdir(p)))
        env[CORE_CACHE_FOLDER_VARIABLE] = core_cache_folders()  # where this process reads
        env["KD_PREVIEW_HELPER_PARENT"] = str(os.getpid())  # the helper ends when this process is gone
        self.process = subprocess.Popen(
            [sys.executable, "-c", _HELPER_CODE, CORE_PACKAGE, str(CORE_FOLDER), "1" if denoise else "0"], env=env,
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._errors,
            creationflags=getattr(subprocess, "CREATE_NO_WINDOW", 0))  # Windows: no console window

    def wait(self, timeout=None) -> bool:
        """Wait for the helper (at most `timeout` seconds); True when it finished and succeeded."""
        try:
            return self.process.wait(timeout) == 0
        except subprocess.TimeoutExpired:
            return False

    def stop(self) -> None:
        """End the helper if it still runs. What it saved stays valid: Numba writes each cache file to
        a temporary name and renames it, and an index entry whose data is missing reads as a miss."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
            self.stopped = True

    @property
    def outcome(self) -> str:
        """"running", "finished", "stopped" (ended here: the block raised, or HELPER_TIMEOUT) or
        "failed (exit code N)"; the add-on reports it with the frame that started the helper."""
        code = self.process.poll()
        if code is None:
            return "running"
        if self.stopped:
            return "stopped"
        if code == 0:
            return "finished"
        self._errors.seek(0)
        lines = self._errors.read().decode(errors="replace").strip().splitlines()
        return f"failed (exit code {code}" + (f": {lines[-1]})" if lines else ")")


# The helper's program (argv: core's module name, its folder, "1" for the denoiser; its task the rendering
# kernels): helper_program.py, which the kernel warm-up runs with tasks of its own.
_HELPER_CODE = (Path(__file__).with_name("helper_program.py")).read_text(encoding="utf-8")
