"""Preview images: ambient occlusion, shadows, or both, accumulated progressively.

Value of a hit pixel (geometric normal N facing the camera), background 0 with alpha 0, row 0 on top:
- "ao": AO = (1/pi) * integral of V(w) cos(theta) dw within `ao_distance`, by cosine-weighted rays.
- "shadow": S = (1/L) * sum over lights of colour_l * V_l * max(0, N.L_l) * mask_l, L_l sampled over
  the light's extent, mask_l its cone or spread (shading._light_mask); no falloff or power, so S shows
  where each light reaches whatever its units.
- "ao+shadow": AO * (ambient + (1 - ambient) * S).
Deterministic for a seed. With an error target a pixel stops after `min_samples` once the estimated
standard error of its mean is below it (convergence.py: Sobol's variance decay, pooled over the 5x5
neighbourhood, Laplace's floor), checked at power-of-two sample counts so batching does not change the image.
"""

import numpy as np

from .. import buffer_pool
from ..jit.compile_clock import clock
from ..jit.kernel_cache import holds_version
from .camera import Camera, tiled_packets, tiled_pixels
from .convergence import checks, dependence_radius, is_check, near, next_check, sample_variances, standard_errors
from .denoise import SOBOL_VARIANCE_DECAY, denoise_pixels
from ..inputs import check_image_size
from ..trace.kdtree import KdTree
from ..build.lazy import resolve_suspended
from ..scene.instance_signature import changed_boxes
from .lights import DELTA, NO_SHADOW
from ..memory import check_render_memory
from .pixel_reuse import PixelState, prepared_boxes, segments_touch, settings_key, surface_rays_touch
from ..scene.ray_visibility import CAMERA_RAYS, HOLDOUT, SHADOW_RAYS
from .sample_rays import MODES
from .hit_frames import surface_frames
from .render_kernels import (MEMO_BITS, PACKED_BATCH, PixelFrames, PixelSums, RayMemo, SampleBatch, add_samples,
                             assemble_image, hard_shadow_rays, packed_version_ready)
from .render_options import RenderOptions, check_mode_and_samples, packed_lights
from .sampling import SAMPLERS, SOBOL_DIM1
from ..scene.scene_packets import occluded_in_packets, packet_kernels_ready, packets_apply, trace_camera_packets
from ..trace.packet_traversal import L
from ..scene.scene_queries import trace_valid_rays
from ..jit.threads import thread_count
from ..scene.two_level import TwoLevelScene, as_two_level


class PreviewRender:
    """A progressive preview: call `step()` until `done`, read `image()` at any time.

    `tree` is a KdTree or a TwoLevelScene; a KdTree is traced as a one-instance scene with the
    identity matrix, so both take the same kernels.

    Settings: a RenderOptions (`options`, default RenderOptions()), and/or its fields as keywords (mode,
    samples, ao_distance, lights, seed, sampler, error_target, min_samples, ambient, threads), which
    replace the options' own.

    previous: the last frame's `pixel_state()`. With the same camera, lights and settings, and a scene
    from the same SceneBuilder (whose instance signature says what changed), pixels whose rays cannot
    reach changed geometry are kept as they were (pixel_reuse.py): the image is the full render's,
    `pixels_reused` and `rays_reused` say what that saved. Anything else renders from scratch.

    compile_packets: False to trace the camera rays and hard shadows in packets (scene_packets.py) only
    when their kernels run without a compile (_packet_kernels_ready), else singly: the same hits and image,
    without waiting for that compile (the add-on, whose warm-up's second stage compiles them:
    kd_addon/kernel_warmup.py)."""

    def __init__(self, tree, camera, width, height, options=None, *, previous=None, compile_packets=True,
                 **settings):
        _check_frame(tree, camera, width, height)
        options = RenderOptions.make(options, **settings)
        if previous is not None and not isinstance(previous, PixelState):
            raise ValueError(f"previous must be None or a PreviewRender's pixel_state(), got {type(previous).__name__}")
        check_render_memory(width, height)
        self.tree, self.camera, self.width, self.height = tree, camera, int(width), int(height)
        self.options = options
        self.scene = as_two_level(tree)
        o = options
        self.mode, self.target_samples, self.ao_distance = o.mode, int(o.samples), float(o.ao_distance)
        self.lights = packed_lights(o.mode, o.lights)
        self.seed, self.sampler = int(o.seed) & 0xFFFFFFFF, SAMPLERS.index(o.sampler)
        self.error_target, self.min_samples, self.ambient = o.error_target, int(o.min_samples), float(o.ambient)
        self.checks = checks(self.min_samples, self.target_samples) if o.error_target is not None else []
        self.threads = o.threads
        self.packets = compile_packets or _packet_kernels_ready()  # camera and hard-shadow packets
        self.samples_done = 0
        self.trace_ms = 0.0
        self.rays_saved = 0
        self.pixels_reused = self._pixels_rays_reused = self._rays_before = self.converged_pixels = 0
        self.settings = settings_key(camera, self.width, self.height, o.mode, self.target_samples, self.ao_distance,
                                     self.lights, self.seed, self.sampler, o.error_target, self.min_samples,
                                     self.ambient)
        start = clock()
        buffer_pool.new_frame()  # the kept blocks: about the last frame's arrays
        boxes = self._changed_boxes(previous)
        if boxes is None:
            self._trace_camera()
        else:
            self._continue(previous, boxes)
        self.trace_ms += (clock() - start) * 1e3

    def _trace_camera(self):
        """Every pixel from scratch."""
        self.camera_rays = self.width * self.height
        packets = tiled_packets(self.width, self.height) if self.packets else None
        pixels, depths, points, normals, starts = self._camera_hits(tiled_pixels(self.width, self.height), packets)
        n = len(pixels)
        self._start(pixels, depths, points, normals, starts, buffer_pool.zeros((n, 3)), buffer_pool.zeros(n),
                    buffer_pool.zeros(n, np.int64), buffer_pool.zeros(n, np.int64), np.arange(n, dtype=np.int64),
                    self._memo_rows(n))
        self.known, self.boxes = buffer_pool.zeros(n, np.int64), np.zeros((0, 6))
        self.checked = self._unchecked(len(pixels))
        self._hard_shadows_due = True

    def _unchecked(self, n):
        """(n, checks) NaN: each pixel's sample variance at every check it passes (_retire_converged)."""
        return np.full((n, len(self.checks)), np.nan)

    def _memo_rows(self, n):
        """(n, B) zero visibility bits: one per ray of every sample (render_kernels.py), none when
        more than MEMO_BITS would be needed."""
        bits = self.target_samples * (1 + len(self.lights))
        return np.zeros((n, (bits + 7) // 8 if bits <= MEMO_BITS else 0), np.uint8)

    def _camera_hits(self, traced, packets=None):
        """(pixels, depths, points, normals, ray starts) of the camera rays through pixels `traced` that hit,
        in the order of `traced` (tiled_pixels' order keeps camera and later rays coherent); traced in
        `packets` (tiled_packets) when given, which then covers every pixel."""
        origins, directions, tmin, tmax = self.camera.rays(self.width, self.height, traced)
        if packets is None:
            t, inst, prim, _, _ = trace_valid_rays(self.scene, origins, directions, tmin, tmax, False, self.threads,
                                                   CAMERA_RAYS)
        else:
            t, inst, prim, _, _ = trace_camera_packets(self.scene, origins, directions, tmin, tmax, packets,
                                                       self.threads, CAMERA_RAYS)
        seen = prim >= 0
        if (self.scene.visibility & HOLDOUT).any():  # a holdout leaves its pixels empty
            seen[seen] = (self.scene.visibility[inst[seen]] & HOLDOUT) == 0
        hit = np.flatnonzero(seen)
        points, normals, starts = (buffer_pool.empty((len(hit), 3)), buffer_pool.empty((len(hit), 3)),
                                   buffer_pool.empty((len(hit), 3)))
        with thread_count(self.threads):
            surface_frames(self.scene.arrays, origins, directions, t, inst, prim, hit, points, normals, starts)
        return buffer_pool.take(traced, hit), buffer_pool.take(t, hit), points, normals, starts

    def _start(self, pixels, depths, points, normals, starts, sums, sq_sums, counts, ray_counts, active, memo):
        self.pixels, self.depths, self.points, self.normals, self.starts = pixels, depths, points, normals, starts
        self.sums, self.sq_sums, self.counts, self.ray_counts = sums, sq_sums, counts, ray_counts
        self.active, self.memo = active, memo
        self.memo_reused = buffer_pool.zeros(len(pixels), np.int64)
        self.repeated = buffer_pool.zeros(len(pixels), np.int64)  # rays of lights without extent (render_kernels.py)
        self.alone = buffer_pool.zeros(len(pixels), np.int64)  # rays the sample packets left singly (RayMemo)
        self.pretraced = np.full((len(pixels), len(self.lights)), -1, np.int8)
        self.pretraced_weights = np.empty((0, len(self.lights)))  # none made (RayMemo.weights)
        self._hard_shadows_due = False  # only a frame traced from scratch (_trace_camera)

    def _changed_boxes(self, previous):
        """Where geometry changed since `previous` (a PixelState), or None when its pixels cannot be
        kept: none given, other settings, camera or lights, or a scene without a signature."""
        if previous is None or previous.settings != self.settings:
            return None
        return changed_boxes(previous.signature, self.scene.signature)

    def _continue(self, prev, boxes):
        """Keep the pixels of `prev` whose rays cannot meet a changed box (pixel_reuse.py); sample the
        others again from sample 0, tracing camera rays only where they cross a changed box, and other
        rays only where they can meet one (the rest take last frame's visibility bit)."""
        boxes = prepared_boxes(boxes)
        rays = self.camera.rays(self.width, self.height)
        ends = rays[3].copy()
        ends[prev.pixels] = prev.depths
        with thread_count(self.threads):
            retrace = segments_touch(*rays[:3], ends, boxes)
            kept = np.flatnonzero(~retrace[prev.pixels])
            ao_radius = self.ao_distance if self.mode != "shadow" else 0.0
            touched = surface_rays_touch(prev.starts[kept], ao_radius, self.lights, boxes)
        clean, dirty = self._around_changes(prev, retrace, kept[~touched], kept[touched])
        tiled = tiled_pixels(self.width, self.height)
        traced = tiled[retrace[tiled]]
        self.camera_rays = len(traced)
        new = self._camera_hits(traced)
        fresh = len(dirty) + len(new[0])
        order = np.concatenate([clean, dirty])
        join = lambda old, add: np.concatenate([old[order], add])  # noqa: E731
        self._start(join(prev.pixels, new[0]), join(prev.depths, new[1]), join(prev.points, new[2]),
                    join(prev.normals, new[3]), join(prev.starts, new[4]),
                    np.concatenate([prev.sums[clean], np.zeros((fresh, 3))]),
                    np.concatenate([prev.sq_sums[clean], np.zeros(fresh)]),
                    np.concatenate([prev.counts[clean], np.zeros(fresh, np.int64)]),
                    np.concatenate([prev.ray_counts[clean], np.zeros(fresh, np.int64)]),
                    np.arange(len(clean), len(clean) + fresh, dtype=np.int64),
                    np.concatenate([prev.memo[order], self._memo_rows(len(new[0]))]))
        # last frame's bits that hold traced outcomes: its samples' (render_kernels.py, ray memo)
        self.known = np.concatenate([np.zeros(len(clean), np.int64), prev.counts[dirty] * (1 + len(self.lights)),
                                     np.zeros(len(new[0]), np.int64)])
        self.boxes = boxes
        self.checked = np.concatenate([prev.checked[clean], self._unchecked(fresh)])
        self._rays_before = int(prev.ray_counts[clean].sum())
        self.pixels_reused = len(clean)
        self._pixels_rays_reused = self._rays_before + self.width * self.height - self.camera_rays
        if fresh == 0:
            self.samples_done = self.target_samples

    def _around_changes(self, prev, retrace, clean, dirty):
        """(clean, dirty) with an error target: clean pixels near a retraced or dirty one move to dirty, since
        a stop count depends on the pixels around (convergence.dependence_radius)."""
        if not self.checks:
            return clean, dirty
        changed = retrace.copy()
        changed[prev.pixels[dirty]] = True
        radius = dependence_radius(self.min_samples, self.target_samples)
        moved = near(changed.reshape(self.height, self.width), radius).reshape(-1)[prev.pixels[clean]]
        return clean[~moved], np.concatenate([dirty, clean[moved]])

    def pixel_state(self):
        """This frame's pixels for the next frame's `previous` (None until the render is done)."""
        if not self.done:
            return None
        return PixelState(self.settings, self.scene.signature, self.pixels, self.depths, self.points, self.normals,
                          self.starts, self.sums, self.sq_sums, self.counts, self.ray_counts, self.memo, self.checked)

    @property
    def rays_reused(self):
        """Rays not traced thanks to `previous`: those of kept pixels (and their camera rays), and of
        re-sampled pixels that took last frame's visibility bit."""
        return self._pixels_rays_reused + int(self.memo_reused.sum())

    @property
    def done(self):
        return self.samples_done >= self.target_samples or len(self.active) == 0

    @property
    def rays_traced(self):
        return self.camera_rays + int(self.ray_counts.sum()) - self._rays_before - int(self.memo_reused.sum())

    @property
    def rays_alone(self):
        """Rays of samples traced in packets (sample_packets.py) that no packet answered and the sampling
        loop traced alone: lanes a packet left (a zero direction component, an unbuilt node), the last
        ray of a chunk, and a chunk's rays whose segments may meet more than 16 instances
        (sample_packets.MAX_CHUNK_INSTANCES). Part of rays_traced."""
        return int(self.alone.sum())

    @property
    def hit_pixels(self):
        return len(self.pixels)

    def step(self, samples=1):
        """Add up to `samples` samples to every pixel still sampling; returns how many were added."""
        if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
            raise ValueError(f"step(samples): samples must be an integer >= 1, got {samples!r}")
        samples = min(int(samples), self.target_samples - self.samples_done)
        added = 0
        while added < samples and len(self.active):
            batch = samples - added  # one kernel call: a pixel's rays follow each other while its nodes are in cache
            if self.error_target is not None:  # up to the next convergence check
                batch = min(batch, next_check(self.samples_done, self.min_samples) - self.samples_done)
            start = clock()
            self._add_samples(batch)
            self.trace_ms += (clock() - start) * 1e3
            self.samples_done += batch
            added += batch
            if self.error_target is not None and is_check(self.samples_done, self.min_samples):
                self._retire_converged()
        return added

    def _sample_packets(self, batch):
        """True when this batch's rays go in packets (sample_packets.py: a batch of at least PACKED_BATCH
        samples, and rays the packets take: AO rays, or those of a light with extent that casts shadows),
        else None: the sampling kernel's version without packets, the only one a renderer stepping one
        sample at a time compiles (batch_without_compile keeps a stepping caller there until the packed
        version is cached)."""
        soft = (self.lights[:, DELTA] == 0.0) & (self.lights[:, NO_SHADOW] == 0.0)
        rays = "ao" in self.mode or ("shadow" in self.mode and soft.any())
        return True if rays and batch >= PACKED_BATCH else None

    def batch_without_compile(self, samples):
        """`samples`, or PACKED_BATCH - 1 when a step of that many would run the sampling kernel's packed
        version (_sample_packets) and that version is neither loaded nor cached, so its first call would
        compile for about a minute: the largest batch a caller stepping in growing batches (the add-on)
        takes without waiting for a compile. Batching never changes the image (render_kernels.py)."""
        if self._sample_packets(samples) and not packed_version_ready():
            return PACKED_BATCH - 1
        return samples

    def _add_samples(self, batch):
        """Samples samples_done .. +batch of every active pixel; on a lazy tree, pixels stopped by an
        unbuilt subtree redo the batch once it is built (same samples, so the eager tree's sums)."""
        if self._hard_shadows_due:
            self._hard_shadows_due = False
            self._trace_hard_shadows()

        packed = self._sample_packets(batch)

        def run(active):
            status = buffer_pool.empty(len(active), np.int64)
            add_samples(self.scene.arrays, PixelFrames(self.points, self.normals, self.starts, self.pixels), active,
                        SampleBatch(self.samples_done, batch, MODES[self.mode], self.ao_distance, self.ambient,
                                    self.sampler, self.seed, SOBOL_DIM1), self.lights,
                        PixelSums(self.sums, self.sq_sums, self.counts, self.ray_counts), status,
                        RayMemo(self.memo, self.known, self.boxes, self.memo_reused, self.repeated,
                                self.pretraced, self.pretraced_weights, self.alone), packed)
            return status

        with thread_count(self.threads):
            status = run(self.active)

            def redo(pixels):
                self.scene.refresh()
                status[pixels] = run(self.active[pixels])

            if self.scene.lazy_tree is not None:
                resolve_suspended(self.scene.lazy_tree, status, redo, self.threads)

    def _trace_hard_shadows(self):
        """Before a fresh frame's first sample: the shadow rays of every light without extent that casts
        shadows, one a pixel (every sample's is the same), traced in packets (scene_packets.py) into
        `pretraced`, their weights into `pretraced_weights`, where the sampling kernel takes both. The
        pixels are in tiled order, so a packet's rays leave neighbouring points towards one point or
        direction: coherent rays, as camera rays are.
        Scenes the packets do not take, and a render without packets (self.packets), leave the rays to the
        sampling kernel."""
        hard = np.flatnonzero((self.lights[:, DELTA] != 0.0) & (self.lights[:, NO_SHADOW] == 0.0))
        if "shadow" not in self.mode or not len(hard) or not self.packets or not packets_apply(self.scene, SHADOW_RAYS):
            return
        frames = PixelFrames(self.points, self.normals, self.starts, self.pixels)
        self.pretraced_weights = buffer_pool.full((len(self.points), len(self.lights)), np.nan)
        directions, tmax = buffer_pool.empty(self.points.shape), buffer_pool.empty(len(self.points))
        for k in hard:
            with thread_count(self.threads):
                hard_shadow_rays(frames, self.lights, int(k), SOBOL_DIM1, directions, tmax, self.pretraced_weights)
            lit = self.pretraced_weights[:, k] > 0.0  # pixels facing the light: a ray each
            self.pretraced[:, k] = np.where(lit, self._occluded(directions, tmax, np.flatnonzero(lit)), -1)

    def _occluded(self, directions, tmax, rays):
        """(M,) bool: whether each shadow ray listed in `rays` (from `starts` along `directions`) meets
        something in (0, tmax), traced in packets of consecutive listed rays; the rows not listed are not
        traced and hold no answer. The packets read the rays where they are (no copies of the listed rows).
        The order is read-only, as the camera pass's (tiled_packets): the same compiled packet kernel."""
        order = buffer_pool.full(-(-len(rays) // L) * L, -1, np.int64)
        order[:len(rays)] = rays
        order.setflags(write=False)
        return occluded_in_packets(self.scene, self.starts, directions, buffer_pool.zeros(len(tmax)), tmax, order,
                                   self.threads, SHADOW_RAYS)

    def _retire_converged(self):
        """Stop sampling pixels whose estimated standard error is below the target (convergence.py). Every
        pixel enters as it was after min(its samples, samples_done): a kept pixel of a continued frame
        with more samples by its variance at this check, kept from the frame that sampled it."""
        done, k = self.samples_done, self.checks.index(self.samples_done)
        active = self.active
        self.checked[active, k] = sample_variances(self.sums[active], self.sq_sums[active], self.counts[active])
        past = self.counts >= done
        variances = np.where(past, self.checked[:, k], sample_variances(self.sums, self.sq_sums, self.counts))
        decay = SOBOL_VARIANCE_DECAY if SAMPLERS[self.sampler] == "sobol" else 0.0
        errors = standard_errors(self.width, self.height, self.pixels, variances, np.minimum(self.counts, done), decay)
        converged = errors[active] < self.error_target
        n = self.counts[active].astype(np.float64)
        if converged.any():
            stopped, n_stopped = self.active[converged], n[converged]
            # lights without extent traced their ray at sample 0 only and would repeat it (render_kernels.py);
            # without the memo nothing repeats, repeated is 0 and so is `hard`
            hard = self.repeated[stopped] / np.maximum(n_stopped - 1.0, 1.0)
            rays_per_sample = (self.ray_counts[stopped] - hard) / n_stopped
            remaining = self.target_samples - self.samples_done
            self.rays_saved += int(np.rint(rays_per_sample * remaining).sum())
            self.converged_pixels += int(converged.sum())
            self.active = self.active[~converged]

    def image(self, denoise=False):
        """The current estimate as an (H, W, 4) float32 image (row 0 at the top); with `denoise`, filtered
        by core.denoise (edge-avoiding à-trous, variance-guided; background and alpha unchanged)."""
        if not isinstance(denoise, (bool, np.bool_)):
            raise ValueError(f"denoise must be True or False, got {denoise!r}")
        if denoise:
            decay = SOBOL_VARIANCE_DECAY if SAMPLERS[self.sampler] == "sobol" else 0.0
            return denoise_pixels(self.width, self.height, self.pixels, self.points, self.normals, self.sums,
                                  self.sq_sums, self.counts, variance_decay=decay, threads=self.threads)
        img = np.zeros((self.height * self.width, 4), np.float32)
        with thread_count(self.threads):
            assemble_image(self.pixels, self.sums, self.counts, img)
        return img.reshape(self.height, self.width, 4)

    def sample_counts(self):
        """Samples taken per pixel as an (H, W) int array (0 for background)."""
        out = np.zeros(self.height * self.width, np.int64)
        out[self.pixels] = self.counts
        return out.reshape(self.height, self.width)

    def stats(self):
        return {"samples": self.samples_done, "hit_pixels": self.hit_pixels, "rays": self.rays_traced,
                "rays_saved": self.rays_saved, "trace_ms": self.trace_ms, "pixels_reused": self.pixels_reused,
                "rays_reused": self.rays_reused,
                "converged_pixels": self.converged_pixels}


def render_preview(tree, camera, width, height, denoise=False, options=None, **settings):
    """Render the whole preview at once: the (H, W, 4) float32 image (see PreviewRender for `options`
    and settings; `denoise` as in PreviewRender.image)."""
    render = PreviewRender(tree, camera, width, height, options, **settings)
    render.step(render.target_samples)
    return render.image(denoise)


def frame_ray_count(width, height, mode="ao", samples=16, lights=()):
    """The most rays a render traces: one camera ray a pixel, and for every sample one AO ray (modes
    with "ao") and one shadow ray a light (modes with "shadow"), except that a light without extent
    takes one ray a pixel when its samples repeat it (render_kernels.py, repeated rays). What
    BuildOptions.rays and SceneBuilder.build(rays=...) take for a tree that serves one frame."""
    check_image_size(width, height)
    check_mode_and_samples(mode, samples)
    rows = packed_lights(mode, lights)
    hard = int((rows[:, DELTA] != 0.0).sum()) if "shadow" in mode else 0
    soft = len(rows) * ("shadow" in mode) - hard
    repeats = samples * (1 + len(rows)) <= MEMO_BITS  # the memo holds sample 0's bit (PreviewRender._memo_rows)
    per_pixel = 1 + (("ao" in mode) + soft) * samples + hard * (1 if repeats else samples)
    return int(width) * int(height) * per_pixel


def _check_frame(tree, camera, width, height):
    if not isinstance(tree, (KdTree, TwoLevelScene)):
        raise ValueError(f"tree must be a core.KdTree or core.TwoLevelScene, got {type(tree).__name__}")
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.Camera, got {type(camera).__name__}")
    check_image_size(width, height)


def _packet_kernels_ready():
    """Whether the camera and hard-shadow packets run without a compile: the scene's packet kernels
    (scene_packets.packet_kernels_ready) and the hard-shadow rays' set-up, which they call (a first
    render's compile helper compiles it too: parallel_compile.compile_rendering_kernels)."""
    return packet_kernels_ready() and holds_version(hard_shadow_rays)
