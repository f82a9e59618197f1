"""The sampling kernel: for each pixel still sampling, add AO and/or light samples to its sums.

One sample is one cosine-weighted AO ray (mode ao), one shadow ray per light facing the surface (mode
shadow), or both multiplied (ao+shadow), each an any-hit query of kind SHADOW_RAYS (as Cycles traces
AO rays). Sample k of pixel p depends only on (p, k, seed), so any batching gives the same sums; a
lazy tree's stopped pixel restores its sums and redoes the batch once the subtree is built.
The ray memo (ray_memo.py) keeps each ray's visibility for the next frame, and a light without extent
(lights.DELTA) repeats sample 0's bit in later samples (counted in `repeated`, not `rays`). Such a
light's ray may also come traced beforehand (`pretraced`: hard_shadow_rays' rays, traced in packets by
the caller, with its weight: `weights`), counted as if sample 0 had traced it and later samples repeated
it. In a batch of PACKED_BATCH samples or more, a pixel's AO rays and its rays towards lights with extent
are traced in packets (sample_packets.py), with the same answers, by a version of the kernel compiled apart.
"""
from typing import NamedTuple

import numpy as np
from numba import njit, prange, types

from ..jit.kernel_cache import holds_version
from ..trace.array_views import keep_alive, rows, unowned
from ..scene.instance_traversal import new_scratch, trace_scene, unowned_scene
from ..trace.layout import NO_HIT
from .lights import COLOR, DELTA, NO_SHADOW
from .sample_packets import CHUNK, answer_chunk, chunk_work_for, in_chunk, in_packets
from .sample_rays import AO_SHADOW, SHADOW, USE_AO, ray_of_use, uses_of_mode
from .ray_memo import TRACE, RayMemo, keep_memo_bit, keep_traced, memo_bit, reused_visibility, unowned_memo
from ..scene.ray_visibility import SHADOW_RAYS
from .sampling import pixel_seed, use_seeds
from ..trace.traversal import block_range, thread_shares

PIXELS_PER_TASK = 64  # pixels a parallel task samples with one set of scratch buffers
PACKED_BATCH = 8  # fewest samples a batch traces its rays in packets with (a progressive step(1) does not)
MEMO_BITS = 512  # most visibility bits kept per pixel (64 bytes): 16 samples x 32 uses, 512 AO samples


class PixelFrames(NamedTuple):
    """The hit pixels, one row each: `points`, `normals` (M, 3) float64, the hit points and their
    geometric normals facing the camera; `starts` (M, 3) float64, the AO and shadow rays' origin, the
    point offset off its surface (hit_frames.surface_frames); `pixels` (M,) int64, their flat image indices."""

    points: np.ndarray
    normals: np.ndarray
    starts: np.ndarray
    pixels: np.ndarray


class SampleBatch(NamedTuple):
    """Which samples add_samples adds and how: samples `first` .. first+count-1, `mode` (AO, SHADOW or
    AO_SHADOW), `ao_distance`, `ambient`, `sampler` (an index into sampling.SAMPLERS), `seed` and
    `dim1` (the Sobol set's second dimension as byte tables, sampling.SOBOL_DIM1)."""

    first: int
    count: int
    mode: int
    ao_distance: float
    ambient: float
    sampler: int
    seed: int
    dim1: np.ndarray


class PixelSums(NamedTuple):
    """Per-pixel accumulators: `sums` (M, 3) and `sq_sums` (M,) (of the sample's grey value) float64,
    `counts` (M,) int64 samples taken, `rays` (M,) int64 rays traced for them."""

    sums: np.ndarray
    sq_sums: np.ndarray
    counts: np.ndarray
    rays: np.ndarray


@njit(cache=True, parallel=True)
def add_samples(scene, frames, active, batch, lights, acc, status, memo, packed):
    """Add the SampleBatch `batch` to every pixel listed in `active` (indices into the PixelFrames
    `frames`), with `lights` (lights.pack_lights rows), into the PixelSums `acc` (counts[i] += count)
    and the RayMemo `memo`. status[a] is NO_HIT when pixel active[a] got its samples, or the suspended
    prim of the unbuilt subtree that stopped it (lazy trees; its sums untouched). `packed`: None, or
    True to trace the rays in packets (sample_packets.py), a version of the kernel compiled apart."""
    n = active.shape[0]
    threads, share, per_band, run = thread_shares(n, PIXELS_PER_TASK)  # balances image regions (traversal.py)
    for k in prange(threads):
        _sample_pixels(scene, frames, active, (k * share, k * share + share, per_band, run, n), batch, lights, acc,
                       status, memo, packed)


def packed_version_ready():
    """Whether add_samples' packed version (`packed` True) runs without a compile: loaded in this process,
    or in Numba's on-disk cache for this machine and these sources. Its first compile takes about a
    minute, so a caller stepping in growing batches stays under PACKED_BATCH until then
    (PreviewRender.batch_without_compile)."""
    return holds_version(add_samples, lambda signature: isinstance(signature[-1], types.Boolean))


@njit(cache=True)
def _sample_pixels(scene, frames, active, blocks, batch, lights, acc, status, memo, packed):
    """The pixels of iterations blocks[0]..blocks[1]-1 (blocks: first, end, per_band, run, pixels;
    traversal.block_range) with one set of scratch buffers, made once a thread (kept out of the parallel
    loop body: Numba's parfor analysis does not cope with the samplers' inlined tuple code). The scene
    and the memo go to the per-ray code as unowned views
    (docs/choices.md#sampling-kernel-scratch-and-views), with the sample packets' buffers
    (sample_packets.chunk_work_for) when the kernel is the packed one."""
    scene = unowned_scene(scene)
    memo = unowned_memo(memo)
    frames = PixelFrames(unowned(frames.points), unowned(frames.normals), unowned(frames.starts),
                         unowned(frames.pixels))
    lights = unowned(lights)
    acc = PixelSums(unowned(acc.sums), unowned(acc.sq_sums), unowned(acc.counts), unowned(acc.rays))
    b = batch  # its Sobol tables as a view too: an owned array counts references where the rays use it
    batch = SampleBatch(b.first, b.count, b.mode, b.ao_distance, b.ambient, b.sampler, b.seed, unowned(b.dim1))
    scratch, scratch_owners = new_scratch()
    packets, answers, weights, owners = chunk_work_for(scene, lights.shape[0] + 1, packed)
    answers, weights = unowned(answers), unowned(weights)
    first, end, per_band, run, n = blocks
    for it in range(first, end):
        start, stop = block_range(it, per_band, run, n, PIXELS_PER_TASK)
        for a in range(start, stop):
            status[a] = _sample_pixel(scene, frames, active[a], batch, lights, acc, scratch, memo,
                                      (packets, answers, weights))
    keep_alive((owners, scratch_owners))


@njit(cache=True, inline="always")
def _sample_pixel(scene, frames, i, batch, lights, acc, scratch, memo, chunk_packets):
    """All of one pixel's new samples. Returns NO_HIT, or the suspended prim of a ray that reached an
    unbuilt subtree, after restoring the pixel's sums. scratch: new_scratch()'s views, whose spare
    3-vector holds each ray's direction; chunk_packets: (packets, answers, weights) of
    sample_packets.chunk_work_for (packets None in the kernel without them).

    Every ray a sample needs (its AO ray, then one per light) that nothing answers beforehand is traced
    at one place in the loop, the one inlined traversal; the pixel's point, normal, ray start and light
    rows are unowned views (array_views.py). Where packets apply, the rays of each CHUNK of samples that
    go in packets (sample_packets.in_chunk) are answered first, and the loop traces only those their
    packets left."""
    first, count, mode, seed = batch.first, batch.count, batch.mode, batch.seed
    sums, sq_sums, counts, rays = acc.sums, acc.sq_sums, acc.counts, acc.rays
    direction = scratch[-1]
    packets, answers, weights = chunk_packets
    point, normal = rows(frames.points, i, i + 1)[0], rows(frames.normals, i, i + 1)[0]
    origin = rows(frames.starts, i, i + 1)[0]
    ps = pixel_seed(frames.pixels[i], seed)
    ao_seeds = use_seeds(ps, USE_AO)
    before = (sums[i, 0], sums[i, 1], sums[i, 2], sq_sums[i], rays[i], memo.reused[i], memo.repeated[i], memo.alone[i])
    n_lights = lights.shape[0]
    uses = 1 + n_lights
    first_use, last_use = uses_of_mode(mode, uses)
    packets_apply = in_packets(packets)
    for chunk in range(first, first + count, CHUNK):
        chunk_end = min(first + count, chunk + CHUNK)
        if packets_apply:
            answer_chunk(scene, packets, (i, point, origin, normal, ps, ao_seeds, uses), (chunk, chunk_end), batch,
                         lights, memo, rays)
        for s in range(chunk, chunk_end):
            ao = 1.0
            lr = lg = lb = 0.0
            for use in range(first_use, last_use):
                from_chunk = packets_apply and in_chunk(lights, use)  # answered (counted, kept), or TRACE
                prim, tmax, weight = TRACE, batch.ao_distance, 1.0
                if from_chunk:
                    prim, weight = answers[use, s - chunk], weights[use, s - chunk]
                    if weight <= 0.0:
                        continue  # behind the surface or outside the light: no ray needed
                if prim == TRACE:
                    tmax, weight = _ray_of_sample(use, lights, (point, normal, ps, ao_seeds, s, i), batch, memo,
                                                  direction)
                    if weight <= 0.0:
                        continue
                    if not from_chunk:
                        prim = _answered_visibility(lights, use, (i, s, uses), origin, direction, tmax, memo, rays)
                if prim == TRACE:
                    _, _, prim, _, _ = trace_scene(scene, origin, direction, 0.0, tmax, True, SHADOW_RAYS, scratch)
                    keep_traced(memo, i, s * uses + use, prim)
                if prim < NO_HIT:
                    return _restore(sums, sq_sums, rays, memo, i, before, prim)
                if use == USE_AO:
                    ao = 1.0 if prim < 0 else 0.0
                elif prim < 0:
                    w = weight / n_lights
                    lr += w * lights[use - 1, COLOR]
                    lg += w * lights[use - 1, COLOR + 1]
                    lb += w * lights[use - 1, COLOR + 2]
            _add_sample(acc, i, mode, batch.ambient, ao, (lr, lg, lb))
    counts[i] += count
    return NO_HIT


@njit(cache=True, inline="always")
def _ray_of_sample(use, lights, at_pixel, batch, memo, direction):
    """(tmax, weight) of ray `use` of a sample, at_pixel = (point, normal, pixel seed, AO seeds, s, i), and
    its direction into `direction`: sample_rays.ray_of_use's, except that the weight of a light's ray made
    beforehand (RayMemo.weights) is taken as it is, with no direction: a weight above 0 means the hard-
    shadow pass traced that ray, so _answered_visibility takes its answer and nothing traces it here."""
    point, normal, ps, ao_seeds, s, i = at_pixel
    if use != USE_AO and memo.weights.shape[0] > 0 and not np.isnan(memo.weights[i, use - 1]):
        return 0.0, memo.weights[i, use - 1]
    return ray_of_use(use, lights, point, normal, batch.ao_distance, batch.sampler, ps, ao_seeds, s, batch.dim1,
                      direction)


@njit(cache=True, inline="always")
def _answered_visibility(lights, use, ray_of, origin, direction, tmax, memo, rays):
    """The any-hit prim of ray `use` of sample s of pixel i (ray_of = (i, s, uses)) when something answers
    it without tracing: a light that casts no shadow (-1: it reaches every surface facing it), sample 0's
    answer repeated or the pretraced one for a light without extent, or last frame's (ray_memo.py);
    otherwise ray_memo.TRACE. Counts the ray in rays[i] as a traced or reused one, as before."""
    i, s, uses = ray_of
    if use != USE_AO and lights[use - 1, NO_SHADOW] != 0.0:
        return -1
    if _repeats(lights, use, s, memo):
        return _repeated_visibility(memo, i, use, s * uses + use)
    if use != USE_AO and memo.pretraced[i, use - 1] >= 0:
        return _pretraced_visibility(memo, i, use, s, s * uses + use, rays)
    rays[i] += 1
    return reused_visibility(memo, i, s * uses + use, origin, direction, tmax)


@njit(cache=True, inline="always")
def _add_sample(acc, i, mode, ambient, ao, light):
    """Add one sample's value to pixel i's sums: AO, the lights' sum `light` (r, g, b), or both
    (module docstring of preview_render)."""
    lr, lg, lb = light
    r = g = b = ao
    if mode == SHADOW:
        r, g, b = lr, lg, lb
    elif mode == AO_SHADOW:
        r = ao * (ambient + (1.0 - ambient) * lr)
        g = ao * (ambient + (1.0 - ambient) * lg)
        b = ao * (ambient + (1.0 - ambient) * lb)
    acc.sums[i, 0] += r
    acc.sums[i, 1] += g
    acc.sums[i, 2] += b
    grey = (r + g + b) / 3.0
    acc.sq_sums[i] += grey * grey


@njit(cache=True, inline="always")
def _restore(sums, sq_sums, rays, memo, i, before, prim):
    """Put pixel i's sums and counts back as they were before the batch; pass on the suspended prim."""
    sums[i, 0], sums[i, 1], sums[i, 2], sq_sums[i], rays[i], memo.reused[i], memo.repeated[i], memo.alone[i] = before
    return prim


@njit(cache=True, inline="always")
def _repeats(lights, use, s, memo):
    """Whether sample s's ray of this use repeats sample 0's, whose bit the memo holds: a light without
    extent, a later sample, and a memo row. Sample 0's bit is this frame's by then: every frame samples
    its pixels in order from 0, and a lazy tree's redo repeats the same batch."""
    return use != USE_AO and s > 0 and lights[use - 1, DELTA] != 0.0 and memo.bits.shape[1] > 0


@njit(cache=True, inline="always")
def _repeated_visibility(memo, i, use, bit):
    """Sample 0's visibility bit for this use, copied into `bit` (every ray keeps its bit, memo rule);
    returns the any-hit prim's sign: 0 occluded, -1 clear."""
    memo.repeated[i] += 1
    occluded = memo_bit(memo.bits, i, use)
    keep_memo_bit(memo.bits, i, bit, occluded)
    return 0 if occluded else -1


@njit(cache=True, inline="always")
def _pretraced_visibility(memo, i, use, s, bit, rays):
    """The visibility of a light without extent traced beforehand (RayMemo.pretraced), kept in the memo
    as a traced ray's bit; counted in rays[i] at sample 0 and as repeated later (_repeated_visibility).
    Returns the any-hit prim's sign: 0 occluded, -1 clear."""
    occluded = memo.pretraced[i, use - 1] == 1
    if s == 0:
        rays[i] += 1
    else:
        memo.repeated[i] += 1
    if bit < 8 * memo.bits.shape[1]:
        keep_memo_bit(memo.bits, i, bit, occluded)
    return 0 if occluded else -1


@njit(cache=True, parallel=True)
def hard_shadow_rays(frames, lights, k, dim1, directions, tmax, weights):
    """The shadow ray of light k, one without extent (every sample's is the same), from each pixel
    of the PixelFrames `frames`, made as the sampling kernel makes it (sample_rays.ray_of_use): its
    direction into directions (M, 3), tmax (M,), and its weight into weights[:, k], above 0 where the pixel faces the
    light inside its mask, 0 where it takes no ray (RayMemo.weights: the sampling kernel then takes it
    and the pretraced answer without making the ray again). The rays start at frames.starts.
    The block index is passed as int64: Numba types a prange's index int64 in one place and uint64 in
    the parallel body, which would compile the block function twice."""
    n = frames.points.shape[0]
    for b in prange((n + PIXELS_PER_TASK - 1) // PIXELS_PER_TASK):
        first = np.int64(b) * PIXELS_PER_TASK
        _hard_shadow_block(frames, lights, k, dim1, (directions, tmax, weights), first,
                           min(n, first + PIXELS_PER_TASK))


@njit(cache=True)
def _hard_shadow_block(frames, lights, k, dim1, out, start, stop):
    """hard_shadow_rays' rays of pixels start..stop-1, with unowned views of the pixels' rows (a view per
    pixel would count references on one shared counter from every thread: array_views.py)."""
    directions, tmax, weights = out
    points, normals, directions, lights = (unowned(frames.points), unowned(frames.normals), unowned(directions),
                                           unowned(lights))
    for i in range(start, stop):
        tmax[i], weights[i, k] = ray_of_use(USE_AO + 1 + k, lights, rows(points, i, i + 1)[0],
                                            rows(normals, i, i + 1)[0], 0.0, 0, 0, (0, 0, 0, 0), 0, dim1,
                                            rows(directions, i, i + 1)[0])


@njit(cache=True, parallel=True)
def assemble_image(pixels, sums, counts, img):
    """Each hit pixel's mean (0 before its first sample) and alpha 1 into the flat (H*W, 4) float32
    image `img`, zero elsewhere, in one pass (docs/choices.md#one-pass-image-assembly)."""
    for i in prange(pixels.shape[0]):
        p = pixels[i]
        n = max(counts[i], 1)
        for k in range(3):
            img[p, k] = sums[i, k] / n if counts[i] > 0 else 0.0
        img[p, 3] = 1.0
