"""One preview frame: extract -> two-level scene (trees kept across frames) -> progressive trace.

`FrameJob` splits the frame into short calls (`tick`) so a modal operator stays responsive;
`render_frame` runs one to the end. Nothing here writes images or touches the scene, so a cancelled
or failed frame leaves everything as it was.

Triangles are float32, so the scene is placed relative to the camera: instance matrices (float64)
are shifted by minus the camera position before rounding, and camera and lights by the same offset.
Unchanged meshes keep their trees and unchanged images are reused (tree_cache.py; `rebuild_all`
turns that off). Every kernel call holds KERNEL_LOCK (Numba's workqueue layer aborts when two
threads launch parallel kernels) and runs on a worker thread that `tick` polls for at most
POLL_SECONDS, so a cancel is seen even in the middle of a build.
"""

from __future__ import annotations

import collections
import contextlib
import importlib
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from . import background, corelib, kernel_warmup, memory_limit, scene_input, sampling_steps, tree_cache
from .background import BackgroundCall
from .config import RenderConfig, frame_size
from .errors import Cancelled, PreviewError
from .extract import extract_scene
from .light_use import classified, refused_lights, resolved_mode
from .scene_records import ExtractedScene

KERNEL_LOCK = threading.Lock()
POLL_SECONDS = 0.05  # longest a tick waits for the worker: the bound on cancel latency
COMPILING_STATUS = "Compiling kernels (first run)…"
LOADING_STATUS = "Loading compiled kernels (first run)…"
WARMUP_WAIT_NOTE = ": the render starts when they are ready"  # after kernel_warmup's "compiling kernels …"
DENOISE_COMPILING_STATUS = "Compiling the denoiser (first use)…"
WAITING_STATUS = "Waiting for the cancelled run to end…"  # its kernel call: short, for the progress bar
_kernels_ready = False  # set once a frame has traced in this process: no compile cost left
# ... except the pixel-reuse kernels, first run by the first frame continued from the one before,
_reuse_kernels_ready = False
_denoiser_ready = False  # ... and the denoiser's, first run by the first denoised frame


def waits_for_a_compile(status: str) -> bool:
    """Whether a FrameJob.status says the frame waits for kernels' first compile (the warm-up's, this
    process's or the denoiser's), which a background render prints (engine_final)."""
    return status.lower().startswith("compiling")


def _now() -> tuple[float, float]:
    """A reading for _ms_since: (wall seconds, seconds Numba has compiled in this process). A frame's times
    leave a compile inside them out (it goes to compile_ms, FrameJob._spent), as they leave out the
    background compile a first frame waits for."""
    return corelib.compile_reading()


def _ms_since(t0: tuple[float, float], t1: tuple[float, float] | None = None) -> float:
    """Milliseconds from the _now() reading t0 to t1 (default: now), the compiles in between left out."""
    wall, compiled = t1 or _now()
    return ((wall - t0[0]) - (compiled - t0[1])) * 1e3


def _compile_ms(t0: tuple[float, float], t1: tuple[float, float] | None = None) -> float:
    """Milliseconds Numba compiled in this process between the _now() readings t0 and t1 (default: now)."""
    return ((t1 or _now())[1] - t0[1]) * 1e3


@dataclass
class FrameResult:
    """A finished frame: the image (H, W, 4) float32, row 0 at the top, plus what it cost."""

    frame: int
    image: np.ndarray
    triangles: int
    objects: int
    lights: int
    extract_ms: float
    build_ms: float
    trace_ms: float
    total_ms: float
    rays: int
    rays_saved: int
    samples: int
    first_run: bool  # kernels were loaded from cache in this frame's time (a compile goes to compile_ms)
    objects_rebuilt: int = 0  # meshes whose kd-tree was built this frame
    objects_reused: int = 0  # meshes whose kd-tree was kept from an earlier frame
    image_reused: bool = False  # nothing affecting the image changed: the last image was reused
    pixels_reused: int = 0  # pixels kept from the last frame: none of their rays can reach what changed
    rays_reused: int = 0  # rays those pixels (and their camera rays) did not need again
    tree_stats: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    compile_helper: str | None = None  # a first frame's helper process (core/jit/parallel_compile.py): its outcome
    mode: str = ""  # the mode rendered: the setting, or what "auto" chose
    compile_ms: float = 0.0  # kernel compiles: the background one waited for (kernel_warmup.py) and any in
    # this process during the frame (pipeline._now); not in total_ms
    load_ms: float = 0.0  # loading the compiled kernels into this process before the frame; not in total_ms
    depth: np.ndarray | None = None  # (H, W) view-axis distance of each pixel's hit, inf where nothing is hit
    holdouts: bool = False  # an object the camera sees is a holdout: its pixels are alpha 0, as the background

    @property
    def height(self) -> int:
        return int(self.image.shape[0])

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def mrays_per_s(self) -> float:
        return self.rays / (self.trace_ms * 1e3) if self.trace_ms > 0 else 0.0

    def summary(self) -> dict:
        """Everything but the image, JSON-ready (report rows, the panel's last-run box)."""
        row = {k: getattr(self, k) for k in (
            "frame", "width", "height", "triangles", "objects", "lights", "extract_ms", "build_ms",
            "trace_ms", "total_ms", "rays", "rays_saved", "mrays_per_s", "samples", "first_run", "mode", "objects_rebuilt",
            "objects_reused", "image_reused", "pixels_reused", "rays_reused", "compile_helper", "compile_ms",
            "load_ms")}
        # Not the tree stats' build_ms (the sum over trees, kept ones included): the row's is the frame's.
        row["tree"] = {k: _plain(v) for k, v in self.tree_stats.items() if k not in ("build_ms", "compile_ms")}
        if self.tree_stats.get("instances"):  # the top level's duplication (two_level.TOP_LEVEL_DUPLICATION)
            row["tree"]["top_references_per_instance"] = self.tree_stats["top_references"] / self.tree_stats["instances"]
        row["warnings"] = list(self.warnings)
        return row


def _plain(value):
    """numpy scalars -> Python numbers, so json.dumps accepts tree stats."""
    return value.item() if isinstance(value, np.generic) else value


@dataclass(frozen=True)
class FrameView:
    """A frame's size in pixels and its camera, set by the caller instead of read from the scene."""
    width: int
    height: int
    camera: scene_input.CameraInput


@dataclass
class _SceneRead:
    """What a frame renders, read from the scene on the main thread."""
    inputs: scene_input.SceneInputs
    extracted: ExtractedScene
    instances: tuple  # (meshes, mesh_of, matrices, visibility) for core.SceneBuilder.build
    unapplied: list  # warnings: what a lazy build cannot apply
    image_key: bytes


class FrameJob:
    """One frame of one scene, driven by `tick()` until `done`.

    The first ticks read the scene (once no cancelled run's kernel call still runs:
    background.SCENE_READ_WAIT) and build the tree on the worker; later ticks add samples to the
    unconverged pixels, in batches growing toward `step_seconds` a step (sampling_steps.py). `depsgraph`: the
    evaluated depsgraph, or a function returning it when read.

    A render engine sets the rest: `view` the frame's size and camera where they are not the scene
    camera's at the panel's resolution (a final render's region, the viewport's view), `group` and
    `lane` the trees and last image it continues from (tree_cache.state_for), `poll_seconds` the
    longest a tick waits for the worker, `step_seconds` what a sampling step's batch grows toward.
    """

    def __init__(self, scene, depsgraph, config: RenderConfig, *, view: FrameView | None = None,
                 group: str = "", lane: str = "", poll_seconds: float | None = None,
                 step_seconds: float | None = None):
        self.scene, self.depsgraph, self.config = scene, depsgraph, config
        self.view, self.group, self.lane = view, group, lane
        self.poll_seconds = POLL_SECONDS if poll_seconds is None else poll_seconds
        self.step_seconds = sampling_steps.STEP_SECONDS if step_seconds is None else step_seconds
        self.renderer = None
        self._timings = {"extract_ms": 0.0, "build_ms": 0.0, "trace_ms": 0.0, "other_ms": 0.0}
        self._info: dict = {}
        self._first_run = not _kernels_ready
        self._state = None  # tree_cache.SceneState
        self._image_key = None
        self._reused_image = None
        self._finished = None  # (image, lazy tree's stats or None, PixelState) once the worker made the image
        self._pending: BackgroundCall | None = None  # the kernel call running on the worker
        self._kernel_ms = {"compile_ms": 0.0, "load_ms": 0.0}  # timed apart from the frame (_await_kernels)
        self._compiled_ms = 0.0  # compiled in this process inside the frame's timed spans (_spent)
        self._kernels_checked = False
        self._waiting_since = None  # when the first tick found the kernels' compile running
        self.mode = None  # the mode this frame renders in: the setting, "auto" resolved (light_use.resolved_mode)
        self._depth = None  # the finished image's depth_image
        self._last_step = None  # (samples, ms) of the last sampling step, for the next one's batch

    # -- state the operators show ------------------------------------------

    @property
    def done(self) -> bool:
        if self._pending is not None:
            return False
        return self._reused_image is not None or self._finished is not None

    @property
    def progress(self) -> float:
        """0..1: the traced fraction of the target samples."""
        if self._reused_image is not None:
            return 1.0
        if self.renderer is None:
            return 0.0
        return min(1.0, self.renderer.samples_done / max(1, self.renderer.target_samples))

    @property
    def status(self) -> str:
        if background.abandoned_work_running(besides=self._pending):
            return WAITING_STATUS  # a cancelled run's build or denoiser compile holds the kernel lock
        warmup = kernel_warmup.status()
        if not _kernels_ready and warmup.state == kernel_warmup.COMPILING:
            return warmup.text + WARMUP_WAIT_NOTE
        if not _kernels_ready:
            return LOADING_STATUS if corelib.cache_is_warm() else COMPILING_STATUS
        if self.renderer is None:
            return "Building kd-tree…" if self._pending is not None else "Reading scene…"
        if self.renderer.done and self.config.denoise:
            first_use = not (_denoiser_ready or corelib.cache_is_warm(corelib.DENOISE_KERNEL))
            return DENOISE_COMPILING_STATUS if first_use else "Denoising…"
        return f"Tracing: {self.renderer.samples_done}/{self.renderer.target_samples} samples"

    # -- work ---------------------------------------------------------------

    def tick(self) -> bool:
        """Do the next short piece of work (at most POLL_SECONDS of waiting for the worker, or
        reading the scene); return True when the frame is finished."""
        if self._pending is not None:
            if not self._pending.wait(self.poll_seconds):
                return False
            pending, self._pending = self._pending, None
            pending.result()  # the worker's exception, if any, is raised here
        elif self.renderer is None and self._reused_image is None:
            if self._await_kernels():
                return False
            if not background.wait_for_work(self.poll_seconds):
                return False  # a cancelled run's kernel call still runs: read the scene after it
            if callable(self.depsgraph):
                self.depsgraph = self.depsgraph()
            self.prepare()
        elif self.renderer is not None and not self.renderer.done:
            self.step()
        elif self.renderer is not None and not self.done:
            self.finish()
        return self.done

    def _await_kernels(self) -> bool:
        """A process's first frame: wait (POLL_SECONDS at a time) for the kernels' background compile,
        starting it if nothing did (kernel_warmup), then load them on the worker; both are timed apart
        from the frame (compile_ms, load_ms), so its figures are a warm frame's. True while waiting.
        Without a warm-up (switched off, or it failed) the frame compiles what it needs as before."""
        if _kernels_ready or self._kernels_checked:
            return False
        warmup = kernel_warmup.start()
        if warmup.state == kernel_warmup.COMPILING:
            self._waiting_since = self._waiting_since or time.perf_counter()  # ticks apart: from the first
            warmup = kernel_warmup.wait(timeout=POLL_SECONDS)
            self._kernel_ms["compile_ms"] = (time.perf_counter() - self._waiting_since) * 1e3  # another process's
            if warmup.state == kernel_warmup.COMPILING:
                return True
        self._kernels_checked = True
        if warmup.state != kernel_warmup.READY:
            return False
        t1 = _now()
        core = corelib.load_core()  # on this thread, as prepare() imports it
        self._kernel_ms["load_ms"] += self._spent(t1)
        self._pending = BackgroundCall(KERNEL_LOCK, self._load_kernels, core)
        return True

    def _load_kernels(self, core) -> None:
        """On the worker: run core's made-up frames, which load every kernel of a default frame."""
        global _kernels_ready, _reuse_kernels_ready
        t0 = _now()
        importlib.import_module(core.__name__ + ".jit.first_frame").compile_first_frames()
        self._kernel_ms["load_ms"] += self._spent(t0)
        self._first_run, _kernels_ready, _reuse_kernels_ready = False, True, True

    def prepare(self) -> None:
        """Camera, lights and meshes from the scene (here: bpy is not thread-safe); then the last image
        if nothing changed, else, on the worker, the two-level scene (reusing unchanged trees) and the
        renderer."""
        t0 = _now()
        read = self._read_scene()
        core = corelib.load_core()
        inputs, extracted = read.inputs, read.extracted
        self._state = tree_cache.state_for(self.scene, core, self.config.build_options, self.group, self.lane,
                                           fresh=self.config.settings.rebuild_all)
        reuse = not self.config.settings.rebuild_all
        memory_limit.check_frame(extracted.triangle_count, inputs.width, inputs.height, self.config,
                                 keeps_previous=reuse and self._state.pixels is not None,
                                 held=tree_cache.held_bytes(self.scene, self.group, self.lane))
        self._image_key = read.image_key
        self._timings["other_ms"] += self._spent(t0) - self._timings["extract_ms"]  # extraction: its own row
        self._info = dict(triangles=extracted.triangle_count, objects=extracted.object_count,
                          lights=len(inputs.lights), frame=extracted.frame, mode=self.mode,
                          holdouts=any(kind.holdout and kind.camera for kind in extracted.table().kinds),
                          warnings=inputs.warnings + extracted.warnings + read.unapplied)
        if reuse and self._state.image is not None and self._state.image_key == self._image_key:
            self._reused_image = self._state.image
            self._info.update(self._state.info, objects_reused=len(read.instances[0]), image_reused=True)
            return
        camera, lights = self._camera_and_lights(core, inputs)
        self._pending = BackgroundCall(KERNEL_LOCK, self._build_and_start, core, read.instances, extracted.instances,
                                       inputs.camera.position, reuse, camera, lights, inputs.width, inputs.height)

    @property
    def image_key(self) -> bytes | None:
        """The key of the image this job renders (tree_cache.image_key); None until it read the scene."""
        return self._image_key

    def _read_scene(self) -> _SceneRead:
        inputs = self._scene_inputs()
        extracted = self._extract()
        core = corelib.load_core()
        self.mode = resolved_mode(core, self.config.settings.mode, inputs.lights)
        meshes, mesh_of, matrices, visibility = tree_cache.mesh_inputs(core, extracted)
        visibility, unapplied = self._lazy_visibility(core, extracted, visibility)
        # an AO image does not depend on the lights: animated lights must not stop its reuse
        lights = inputs.lights if self.mode != "ao" else []
        key = tree_cache.image_key(meshes, mesh_of, matrices, visibility, inputs.camera.keywords(), lights,
                                   (inputs.width, inputs.height), self.config.as_dict(), extracted.table().token)
        return _SceneRead(inputs, extracted, (meshes, mesh_of, matrices, visibility), unapplied, key)

    def _lazy_visibility(self, core, extracted: ExtractedScene, visibility: np.ndarray):
        """(visibility, warnings): a lazy build traces the scene as one tree, which cannot tell objects'
        ray visibility or holdout apart, so when they differ between objects they are not applied (every
        instance stops every ray, none is a holdout) and each object they would have changed is named."""
        if not self.config.build_options.get("lazy") or len(set(visibility.tolist())) <= 1:
            return visibility, []
        names = sorted({i.label for i in extracted.instances if not (i.camera and i.shadow) or i.holdout})
        return np.full_like(visibility, core.ALL_RAYS), [
            f"{name}: Ray Visibility and Holdout not applied with Lazy Build on (the scene is traced as one tree)"
            for name in names]

    def _build_and_start(self, core, instances, placed, origin, reuse, camera, lights, width, height) -> None:
        """On the worker, holding KERNEL_LOCK: the scene, then the renderer. `placed`: the extracted
        instances, in the order of `instances`' rows."""
        options = self._render_options()
        rays = core.frame_ray_count(width, height, options["mode"], options["samples"], lights)
        # A process's first frame: with an empty kernel cache a helper process compiles the sampling
        # kernel while this one builds and then compiles the camera pass (core/jit/parallel_compile.py); the
        # block ends once both are done, and that end, all compiling, goes to compile_ms.
        t0 = _now()
        alongside = (core.rendering_kernels_alongside(self.config.denoise, packets=False) if self._first_run
                     else contextlib.nullcontext())
        with alongside as helper:
            scene, report = self._build_placeable(core, instances, placed, origin, reuse, rays)
            built = _now()
        self._timings["build_ms"] = self._spent(t0, built)
        if helper is not None:
            self._kernel_ms["compile_ms"] += (time.perf_counter() - built[0]) * 1e3
            self._info["compile_helper"] = helper.outcome
        self._info.update(tree_stats=scene.stats(), objects_rebuilt=report.meshes_rebuilt,
                          objects_reused=report.meshes_reused)
        self._start_tracing(core, scene, camera, lights, width, height, self._state.pixels if reuse else None)

    def _scene_inputs(self) -> scene_input.SceneInputs:
        render = self.scene.render
        if self.view is None:
            width, height = frame_size(render.resolution_x, render.resolution_y, self.config.resolution_percentage)
        else:
            width, height = self.view.width, self.view.height
        uses_lights = self.config.settings.mode != "ao"  # lights do not change an AO image
        inputs = scene_input.read_scene(self.scene, self.depsgraph, width, height, lights=uses_lights,
                                        camera=None if self.view is None else self.view.camera)
        if not uses_lights:
            return inputs
        scene_input.check_lights_present(inputs, self.depsgraph, self.config.settings.mode, self.scene.name)
        inputs.warnings += inputs.hidden_lights
        return inputs

    def _camera_and_lights(self, core, inputs: scene_input.SceneInputs):
        """Camera and lights moved by the same offset as the triangles. A light that emits nothing or
        that core rejects is left out, and settings not applied are named; with no light left the frame
        renders with a shadow term of 0 (a light may emit again later in the animation)."""
        offset = inputs.camera.position
        try:
            camera = core.Camera(**inputs.camera.keywords()).translated(offset)
        except ValueError as error:  # core's own checks, e.g. clip start >= clip end
            raise PreviewError(f"the scene's camera cannot be used: {error}") from None
        if self.mode == "ao":
            if self.config.settings.mode == "auto":  # a light core refuses, not a dark one, made it AO
                self._info["warnings"] += [f"light '{light.name}' left out: {error}; mode Automatic renders AO"
                                           for light, error in refused_lights(core, inputs.lights)]
            return camera, []
        lights, left_out, unapplied = [], [], []
        for light, used in classified(core, inputs.lights):
            if isinstance(used, ValueError):
                left_out.append(f"light '{light.name}' left out: {used}")
                continue
            lights.append(used.translated(offset))
            unapplied += [f"light '{light.name}': {what} not applied by the preview" for what in light.unapplied]
        self._info["warnings"] += left_out + unapplied
        self._info["lights"] = len(lights)
        if not lights:  # the scene's lights all emit nothing on this frame (a Strength animated to 0, say):
            self._info["warnings"].append(  # S is 0, as Cycles' image is black; core takes no empty list
                f"no light of scene '{self.scene.name}' emits on this frame: the shadow term is 0")
            lights = [core.Light.sun((0.0, 0.0, -1.0), color=(0.0, 0.0, 0.0), cast_shadow=False)]
        return camera, lights

    def _render_options(self) -> dict:
        """The config's render options with this frame's mode ("auto" resolved)."""
        return dict(self.config.render_options, mode=self.mode)

    def _start_tracing(self, core, scene, camera, lights, width, height, previous) -> None:
        """The renderer (its constructor traces the camera rays: trace time), continued from the last
        frame's pixels where their rays cannot reach what changed; the first such frame of a process
        also counts as a first run (it loads the pixel-reuse kernels). Packets once cached: kernel_warmup.py."""
        global _reuse_kernels_ready
        t0 = _now()
        try:
            self.renderer = core.PreviewRender(scene, camera, width, height, previous=previous, lights=lights,
                                               compile_packets=False, **self._render_options())
        except ValueError as error:  # core's own checks (its MemoryLimitError is one): a message, not a traceback
            raise PreviewError(f"the frame cannot be rendered: {error}") from None
        self._timings["trace_ms"] += self._spent(t0)
        if previous is not None and previous.settings == self.renderer.settings and not _reuse_kernels_ready:
            self._first_run, _reuse_kernels_ready = True, True

    def _extract(self) -> ExtractedScene:
        t0 = _now()
        extracted = extract_scene(self.depsgraph)
        if extracted.triangle_count == 0:
            # A warning, not an error: in an animation, objects may appear later (keyed hide_render), and
            # Cycles renders such a frame transparent rather than stopping the sequence.
            extracted.warnings.append(f"nothing to render at frame {self.scene.frame_current}: the scene has no "
                                      "render-visible mesh triangles (objects hidden from renders, or with Ray "
                                      "Visibility > Camera and Shadow both off, count as none), so the frame is "
                                      "transparent")
        self._timings["extract_ms"] = _ms_since(t0)
        return extracted

    def _build_placeable(self, core, instances, placed, origin: np.ndarray, reuse: bool, rays: int):
        """_build, leaving out (and naming) the instances placed beyond float32's range of the camera,
        as extraction leaves out a non-finite placement: the rest of the frame renders."""
        meshes, mesh_of, matrices, visibility = instances
        try:
            return self._build(meshes, mesh_of, matrices, visibility, origin, reuse, rays)
        except core.PlacementRangeError as error:
            keep = np.ones(len(mesh_of), bool)
            keep[error.instances] = False
            labels = collections.Counter(placed[i].label for i in error.instances)
            self._info["warnings"] += [
                f"{label}{f' ({n} instances)' if n > 1 else ''} is placed beyond float32's range of the camera "
                "(a coordinate past 3.4e38 after its scale and location); left out" for label, n in labels.items()]
            return self._build(meshes, mesh_of[keep], matrices[keep], visibility[keep], origin, reuse, rays)

    def _build(self, meshes, mesh_of, matrices, visibility, origin: np.ndarray, reuse: bool, rays: int):
        """On the worker, holding KERNEL_LOCK. `rays`: the frame's ray count, for the trees of deforming
        meshes (core.SceneBuilder)."""
        return self._state.builder.build(meshes, mesh_of, matrices, origin=origin, reuse=reuse,
                                         visibility=visibility, rays=rays)

    def current_image(self) -> np.ndarray | None:
        """The image so far (H, W, 4) while no kernel call runs (the viewport's progressive display;
        Numba's parallel layer takes one kernel launch at a time), else None."""
        if self._pending is not None or not KERNEL_LOCK.acquire(blocking=False):
            return None
        try:
            if self._reused_image is not None:
                return self._reused_image
            return None if self.renderer is None else self.renderer.image()
        finally:
            KERNEL_LOCK.release()

    def step(self) -> None:
        """More samples per unconverged pixel (sampling_steps.next_batch), on the worker."""
        batch = sampling_steps.next_batch(self.renderer, self._last_step, self.step_seconds)
        self._pending = BackgroundCall(KERNEL_LOCK, self._step_once, batch)

    def _step_once(self, samples: int) -> None:
        global _kernels_ready
        t0 = _now()
        added = self.renderer.step(samples)
        ms = self._spent(t0)
        self._timings["trace_ms"] += ms
        self._last_step = (max(1, added), ms)
        _kernels_ready = True

    def finish(self) -> None:
        """The image from the samples, on the worker: the denoiser's first use compiles it, and
        Blender's UI (and Esc) must stay responsive meanwhile."""
        self._pending = BackgroundCall(KERNEL_LOCK, self._finish_once)

    def _finish_once(self) -> None:
        global _denoiser_ready
        t0 = _now()
        image = np.array(self.renderer.image(denoise=self.config.denoise), dtype=np.float32, copy=True)
        lazy = self.renderer.scene.lazy_tree is not None  # then the stats of what the rays made it build
        self._finished = (image, self.renderer.scene.stats() if lazy else None, self.renderer.pixel_state())
        self._depth = depth_image(self.renderer)
        self._timings["other_ms"] += self._spent(t0)
        if self.config.denoise and not _denoiser_ready:  # the warm-up leaves the denoiser out: its kernels
            self._first_run = True  # loaded in this frame's time (a compile goes to compile_ms), marked "*"
        _denoiser_ready = _denoiser_ready or self.config.denoise

    def _spent(self, t0: tuple[float, float], t1: tuple[float, float] | None = None) -> float:
        """_ms_since(t0, t1) for one of this frame's timed spans (spans do not nest), whose compiles are
        added to the frame's compile_ms (the process's: another job's compile meanwhile counts too)."""
        self._compiled_ms += _compile_ms(t0, t1)
        return _ms_since(t0, t1)

    def _kernel_times(self) -> dict:
        """compile_ms and load_ms: the background compile waited for, the loads, and what compiled in
        this process inside the frame's timed spans (left out of their times)."""
        return dict(self._kernel_ms, compile_ms=self._kernel_ms["compile_ms"] + self._compiled_ms)

    def result(self) -> FrameResult:
        """The finished frame; call only once `done`. Also remembers it for image reuse."""
        if not self.done:
            raise RuntimeError("FrameJob.result() called before the frame finished")
        t = self._timings
        if self._reused_image is not None:
            depth = None if self._state.depth is None else self._state.depth.copy()
            return FrameResult(image=self._reused_image.copy(), extract_ms=t["extract_ms"], build_ms=0.0, trace_ms=0.0,
                               total_ms=sum(t.values()), rays=0, rays_saved=0, first_run=False, **self._kernel_times(),
                               pixels_reused=int((self._reused_image[..., 3] > 0).sum()), depth=depth, **self._info)
        image, lazy_stats, pixels = self._finished
        if lazy_stats is not None:
            self._info["tree_stats"] = lazy_stats
        result = FrameResult(image=image, extract_ms=t["extract_ms"], build_ms=t["build_ms"], trace_ms=t["trace_ms"],
                             total_ms=sum(t.values()), rays=int(self.renderer.rays_traced),
                             rays_saved=int(self.renderer.rays_saved), samples=int(self.renderer.samples_done),
                             first_run=self._first_run, pixels_reused=int(self.renderer.pixels_reused),
                             rays_reused=int(self.renderer.rays_reused), depth=self._depth, **self._kernel_times(),
                             **self._info)
        self._state.image_key, self._state.image, self._state.pixels = self._image_key, image.copy(), pixels
        self._state.depth = self._depth.copy()
        self._state.info = dict(samples=result.samples, tree_stats=result.tree_stats,
                                rays_reused=result.rays + result.rays_reused)
        return result


_active_job = None  # at most one preview job per process; see claim()


def claim(job) -> None:
    """Mark `job` as the one running preview job; raise PreviewError if another runs.

    Operators, the command line and the live-update handler all go through this, so a
    frame change caused by a running job never starts a second one.
    """
    global _active_job
    if _active_job is not None:
        raise PreviewError("a KD Preview render is already running")
    _active_job = job


def release(job) -> None:
    """End `job`'s claim (no-op if it does not hold it)."""
    global _active_job
    if _active_job is job:
        _active_job = None


def release_any() -> None:
    """End whichever job holds the claim: the add-on is being disabled, and no claim may outlive it
    (a kernel call it abandoned still holds the kernel lock, which the next job waits for)."""
    global _active_job
    _active_job = None


def job_running() -> bool:
    return _active_job is not None


def run_job(job, cancel=None, progress=None) -> None:
    """Tick `job` until done. `cancel()` is polled before every tick (True: raise Cancelled);
    `progress(fraction, status)` is called after every tick."""
    while True:
        if cancel is not None and cancel():
            raise Cancelled("cancelled")
        done = job.tick()
        if progress is not None:
            progress(job.progress, job.status)
        if done:
            return


def depth_image(renderer) -> np.ndarray:
    """(H, W) float32 view-axis distance of every pixel's camera hit, inf where none: the camera's ray
    directions have unit length along the view axis (core.Camera.rays), so a hit's t is its depth."""
    depth = np.full(renderer.height * renderer.width, np.inf, np.float32)
    depth[renderer.pixels] = renderer.depths
    return depth.reshape(renderer.height, renderer.width)


def image_key_now(scene, depsgraph, config: RenderConfig) -> bytes:
    """The key of the image a frame of the scene as it is now would make (FrameJob.image_key), so that
    a Live Update render of an earlier state can be told stale. Reads the scene (main thread) and builds
    nothing; PreviewError when the scene cannot be rendered."""
    return FrameJob(scene, depsgraph, config)._read_scene().image_key


def render_frame(scene, depsgraph, config: RenderConfig, *, cancel=None, progress=None) -> FrameResult:
    """Render the scene's current frame (depsgraph must be evaluated at it) to the end."""
    job = FrameJob(scene, depsgraph, config)
    run_job(job, cancel, progress)
    return job.result()
