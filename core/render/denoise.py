"""Edge-avoiding à-trous denoising of a preview estimate, guided by its per-pixel sample variance.

Dammertz et al. 2010's edge-avoiding à-trous wavelet transform: `iterations` passes of a 5x5 B3-spline
kernel with taps 2^i pixels apart in pass i, each tap weighted by SVGF's edge-stopping functions
(Schied et al. 2017) without the temporal part:
- normal: max(0, N_p . N_q) ^ sigma_normal on the geometric normals;
- plane: exp(-|N_p . (X_q - X_p)| / (sigma_plane * f_p * r)), f_p p's pixel footprint (world distance
  to its nearest 4-neighbour hit), r the tap distance in pixels: scale invariant;
- luminance: exp(-|l_p - l_q| / (sigma_luminance * sqrt(var_p))), var_p the variance of p's estimate,
  propagated as var' = sum w^2 var / (sum w)^2 (SVGF eq. 4-5), so the filter fades out as it converges.
var_p is the grey value's per-sample variance pooled over p's 5x5 neighbourhood (a pixel's own is often
0 at few samples), divided by n_p ** (1 + variance_decay) (docs/choices.md#sobol-variance-decay).
Pixels without hit or samples stay exactly 0, alpha is 1 on hit pixels; deterministic (no atomics).
"""
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..jit.threads import thread_count
from ..trace.traversal import block_range, interleaved_blocks
from .denoise_inputs import checked_denoise_inputs

ITERATIONS = 4  # taps 1, 2, 4, 8 pixels apart: a 61x61 footprint (docs/choices.md#four-denoise-passes)
SIGMA_LUMINANCE = 4.0  # SVGF's sigma_l
SIGMA_NORMAL = 128.0  # SVGF's sigma_n
SIGMA_PLANE = 1.0  # tangent-plane distance allowed per pixel footprint per pixel of tap distance
SOBOL_VARIANCE_DECAY = 0.5  # stratified sampling of a 2-D visibility: variance ~ n^-3/2 (module docstring)
_HUGE = 1e30  # stands for an infinite ratio without producing inf (0 * inf would be NaN)
_ROUNDING = 1e-7  # luminance differences this small relative to the value are equal (see atrous_pass)
_CUTOFF = 40.0  # taps with weight below exp(-40) are skipped
# Rows go to the threads band by band (traversal.interleaved_blocks; docs/choices.md#denoise-rows-in-bands)
ROWS_PER_TASK = 2
# fast maths without 'nnan' / 'ninf' / 'reassoc': the guards above rely on IEEE comparisons, and the
# sums keep their order, so the image is the same for any thread count
_FAST = {"contract", "afn", "arcp", "nsz"}


class FilterSettings(NamedTuple):
    """The filter's tuning, each with its default: `iterations` (ITERATIONS passes), `sigma_luminance`
    (SIGMA_LUMINANCE), `sigma_normal` (SIGMA_NORMAL), `sigma_plane` (SIGMA_PLANE)."""

    iterations: int = ITERATIONS
    sigma_luminance: float = SIGMA_LUMINANCE
    sigma_normal: float = SIGMA_NORMAL
    sigma_plane: float = SIGMA_PLANE


def denoise_pixels(width, height, pixels, points, normals, sums, sq_sums, counts, *, variance_decay=0.0,
                   threads=None, settings=FilterSettings()):
    """The denoised (H, W, 4) float32 image of a PreviewRender's accumulators (row 0 at the top).
    pixels (M,): flat indices of the hit pixels; points, normals (M, 3); sums (M, 3), sq_sums (M,) (of the
    grey value), counts (M,): the per-pixel sample sums; variance_decay: a pixel mean's variance falls as
    n^-(1 + variance_decay) (0 for independent samples, 0.5 for scrambled Sobol); settings: FilterSettings."""
    pixels, (points, normals, sums, sq_sums, counts), variance_decay = checked_denoise_inputs(
        width, height, pixels, (points, normals, sums, sq_sums, counts), variance_decay, settings)
    iterations, sigma_luminance, sigma_normal, sigma_plane = settings
    width, height = int(width), int(height)
    n = width * height
    valid = np.zeros(n, np.bool_)
    sampled = counts > 0
    valid[pixels[sampled]] = True
    cnt = np.zeros(n)
    cnt[pixels] = counts
    s1 = np.zeros(n)
    s2 = np.zeros(n)
    col = np.zeros((n, 3))
    s1[pixels] = sums.sum(axis=1) / 3.0
    s2[pixels] = sq_sums
    col[pixels] = sums / np.maximum(counts, 1)[:, None]
    pos = np.zeros((n, 3))
    nrm = np.zeros((n, 3))
    pos[pixels] = points
    nrm[pixels] = normals
    alpha = np.zeros(n, np.float32)
    alpha[pixels] = 1.0
    out = np.zeros((n, 4), np.float32)
    out[:, 3] = alpha
    if valid.any():
        with thread_count(threads):
            foot = np.zeros(n)
            footprints(valid, pos, height, width, foot)
            var = np.zeros(n)
            pooled_variance(valid, pos, nrm, foot, (s1, s2, cnt), height, width, float(sigma_normal),
                            float(sigma_plane), float(variance_decay), var)
            col_b, var_b = np.empty_like(col), np.empty_like(var)
            rec = np.empty((n, 9))
            pack_geometry(pos, nrm, rec)
            for i in range(int(iterations)):
                pack_estimates(col, var, rec)
                atrous_pass(valid, rec, foot, col, height, width, 1 << i, float(sigma_luminance),
                            float(sigma_normal), float(sigma_plane), col_b, var_b)
                col, col_b, var, var_b = col_b, col, var_b, var
        out[valid, :3] = col[valid]
    return out.reshape(height, width, 4)


@njit(cache=True, inline="always")
def _exp_neg(e):
    """exp(-e) for 0 <= e <= _CUTOFF as (1 - e/128)^128: seven multiplications, within 0.4% of exp at
    e = 1 and 3% at e = 4 (weights that small hardly matter), and cheaper than exp in the filter's loop
    (docs/choices.md#approximate-exp-and-log-in-the-denoiser)."""
    t = 1.0 - e * (1.0 / 128.0)
    t *= t
    t *= t
    t *= t
    t *= t
    t *= t
    t *= t
    return t * t


@njit(cache=True, inline="always")
def _neg_log(c):
    """-log(c) for exp(-_CUTOFF / sigma_normal) <= c <= 1 by its series in x = 1 - c to the cubic term:
    within 0.7% where it is used (x <= 0.27 at SVGF's sigma_n = 128), and three multiplications instead
    of a log or of c ** 128 by squaring (eight steps per tap)."""
    x = 1.0 - c
    return x * (1.0 + x * (0.5 + x * (1.0 / 3.0)))


@njit(cache=True, parallel=True)
def footprints(valid, pos, height, width, foot):
    """World distance from each valid pixel's hit point to its nearest valid 4-neighbour's (0: none).
    The nearest one, so a silhouette pixel measures along its own surface, not across the gap."""
    for y in prange(height):
        for x in range(width):
            p = y * width + x
            if not valid[p]:
                continue
            best = np.inf
            for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                yy, xx = y + dy, x + dx
                if 0 <= yy < height and 0 <= xx < width and valid[yy * width + xx]:
                    q = yy * width + xx
                    d = np.sqrt((pos[q, 0] - pos[p, 0]) ** 2 + (pos[q, 1] - pos[p, 1]) ** 2
                                + (pos[q, 2] - pos[p, 2]) ** 2)
                    best = min(best, d)
            foot[p] = best if best < np.inf else 0.0


@njit(cache=True, parallel=True, fastmath=_FAST)
def pooled_variance(valid, pos, nrm, foot, moments, height, width, sigma_normal, sigma_plane, decay, var):
    """Variance of each valid pixel's mean grey value: the per-sample variance pooled over the 5x5
    neighbourhood, Bessel-corrected by the pooled sample count, over n_p ** (1 + decay). A neighbour
    pools when its normal and plane weights would be at least exp(-1) (a hard test: no exp per tap,
    which made this step cost more than a filter pass). moments: the per-pixel (sum of grey values,
    sum of their squares, sample count)."""
    s1, s2, cnt = moments
    min_cos = 1.0 - 1.0 / sigma_normal  # sigma_n (1 - c) <= -sigma_n log(c) <= 1
    iterations, per_band, run = interleaved_blocks(height, ROWS_PER_TASK)  # balanced: see ROWS_PER_TASK
    for task in prange(iterations):
        first, last = block_range(task, per_band, run, height, ROWS_PER_TASK)
        for y in range(first, last):
            for x in range(width):
                p = y * width + x
                if not valid[p]:
                    continue
                w_n = w_1 = w_2 = 0.0
                for dy in range(-2, 3):
                    yy = y + dy
                    if yy < 0 or yy >= height:
                        continue
                    for dx in range(-2, 3):
                        xx = x + dx
                        if xx < 0 or xx >= width:
                            continue
                        q = yy * width + xx
                        if not valid[q]:
                            continue
                        if q != p:
                            c = nrm[p, 0] * nrm[q, 0] + nrm[p, 1] * nrm[q, 1] + nrm[p, 2] * nrm[q, 2]
                            if c < min_cos:
                                continue
                            d = abs(nrm[p, 0] * (pos[q, 0] - pos[p, 0]) + nrm[p, 1] * (pos[q, 1] - pos[p, 1])
                                    + nrm[p, 2] * (pos[q, 2] - pos[p, 2]))
                            e = sigma_normal * (1.0 - c)
                            if d > sigma_plane * foot[p] * np.sqrt(float(dx * dx + dy * dy)) * (1.0 - e):
                                continue
                        w_n += cnt[q]
                        w_1 += s1[q]
                        w_2 += s2[q]
                mean = w_1 / w_n
                v = max(w_2 / w_n - mean * mean, 0.0)
                if w_n > 1.0:
                    v *= w_n / (w_n - 1.0)
                var[p] = v / cnt[p] ** (1.0 + decay)


@njit(cache=True, parallel=True)
def pack_geometry(pos, nrm, rec):
    """Columns 0-6 of the per-pixel records atrous_pass reads: normal, n.x (its tangent plane's offset),
    hit point. One record per tap read instead of five arrays; written once, the passes only change
    the estimates (pack_estimates)."""
    for p in prange(pos.shape[0]):
        plane = 0.0
        for k in range(3):
            rec[p, k] = nrm[p, k]
            rec[p, 4 + k] = pos[p, k]
            plane += nrm[p, k] * pos[p, k]
        rec[p, 3] = plane


@njit(cache=True, parallel=True)
def pack_estimates(col, var, rec):
    """Columns 7-8 of the records: the variance and luminance of each pixel's current estimate."""
    for p in prange(col.shape[0]):
        rec[p, 7] = var[p]
        rec[p, 8] = (col[p, 0] + col[p, 1] + col[p, 2]) / 3.0


@njit(cache=True, parallel=True, fastmath=_FAST)
def atrous_pass(valid, rec, foot, col, height, width, step, sigma_luminance, sigma_normal, sigma_plane,
                col_out, var_out):
    """One edge-avoiding à-trous pass with taps `step` pixels apart (Dammertz et al. 2010, eq. 3, with
    SVGF's weights and variance propagation) over the pack_geometry / pack_estimates records. The normal, plane and
    luminance weights are one exponential per tap: max(0, c) ** sigma_n = exp(-sigma_n * -log c)."""
    h = np.array([1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0])  # B3 spline (Dammertz et al.)
    inv_r = np.zeros(25)  # 1 / (tap distance in pixels), per tap
    for j in range(5):
        for i in range(5):
            if i != 2 or j != 2:
                inv_r[j * 5 + i] = 1.0 / (step * np.sqrt(float((i - 2) * (i - 2) + (j - 2) * (j - 2))))
    min_cos = np.exp(-_CUTOFF / sigma_normal)  # below it, c ** sigma_normal < exp(-_CUTOFF)
    iterations, per_band, run = interleaved_blocks(height, ROWS_PER_TASK)  # balanced: see ROWS_PER_TASK
    for task in prange(iterations):
        first, last = block_range(task, per_band, run, height, ROWS_PER_TASK)
        for y in range(first, last):
            for x in range(width):
                p = y * width + x
                if not valid[p]:
                    continue
                nx, ny, nz, plane, lp = rec[p, 0], rec[p, 1], rec[p, 2], rec[p, 3], rec[p, 8]
                # 1 / scale of the plane and luminance ratios; a zero scale (isolated pixel, zero variance)
                # gives _HUGE, so only exactly equal taps (ratio 0) keep their weight: never 0 * inf = NaN.
                inv_plane = 1.0 / (sigma_plane * foot[p]) if foot[p] > 0.0 else _HUGE
                # + a relative 1e-7: a zero-variance pixel (all samples equal) would otherwise reject a tap
                # whose mean differs by a rounding error, and rounding depends on the scene's scale
                sd = sigma_luminance * np.sqrt(rec[p, 7]) + _ROUNDING * abs(lp)
                inv_lum = 1.0 / sd if sd > 0.0 else _HUGE
                sw = sw2v = r = g = b = 0.0
                for j in range(5):
                    yy = y + (j - 2) * step
                    if yy < 0 or yy >= height:
                        continue
                    for i in range(5):
                        xx = x + (i - 2) * step
                        if xx < 0 or xx >= width:
                            continue
                        q = yy * width + xx
                        if not valid[q]:
                            continue
                        w = h[j] * h[i]
                        if q != p:
                            c = nx * rec[q, 0] + ny * rec[q, 1] + nz * rec[q, 2]
                            if c < min_cos:
                                continue
                            e = sigma_normal * _neg_log(min(c, 1.0))
                            d = abs(nx * rec[q, 4] + ny * rec[q, 5] + nz * rec[q, 6] - plane)
                            if d > 0.0:
                                e += min(d * inv_plane, _HUGE) * inv_r[j * 5 + i]
                            dl = abs(lp - rec[q, 8])
                            if dl > 0.0:
                                e += min(dl * inv_lum, _HUGE)
                            if e > _CUTOFF:
                                continue
                            w *= _exp_neg(e)
                        sw += w
                        sw2v += w * w * rec[q, 7]
                        r += w * col[q, 0]
                        g += w * col[q, 1]
                        b += w * col[q, 2]
                col_out[p, 0] = r / sw
                col_out[p, 1] = g / sw
                col_out[p, 2] = b / sw
                var_out[p] = sw2v / (sw * sw)
