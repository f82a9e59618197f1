"""The ray of one use of a sample (the AO ray, or the shadow ray towards light k), made the same way by
the sampling loop (render_kernels.py), the hard-shadow pass and the sample packets (sample_packets.py),
so every path traces the same ray and images do not depend on which one traced it."""
import numpy as np
from numba import njit

from ..jit.opaque import opaque
from ..trace.array_views import rows
from .lights import DELTA
from .sampling import sample_2d, seeded_sample_2d
from .shading import cosine_direction, sample_light, short_of_light

USE_AO = 0  # the sampler's "use" ids: 0 for AO, 1 + k for light k
AO, SHADOW, AO_SHADOW = 1, 2, 3
MODES = {"ao": AO, "shadow": SHADOW, "ao+shadow": AO_SHADOW}


@njit(cache=True, inline="always")
def uses_of_mode(mode, uses):
    """(first, end) of the uses a sample of `mode` traces, of `uses` (1 + the lights): the AO ray
    (modes with AO), then one ray a light (modes with shadows)."""
    return USE_AO if mode != SHADOW else USE_AO + 1, USE_AO + 1 if mode == AO else uses


@njit(cache=True, inline="always")
def ao_direction(sampler, ao_seeds, s, dim1, normal, out):
    """Sample s's AO direction about `normal` into out, cosine-weighted (shading.cosine_direction) from
    the AO use's 2D sample (sampling.seeded_sample_2d), which it returns."""
    u1, u2 = seeded_sample_2d(sampler, ao_seeds, s, dim1)
    cosine_direction(normal, u1, u2, out)
    return u1, u2


@njit(cache=True, inline="always")
def ray_of_use(use, lights, point, normal, ao_distance, sampler, ps, ao_seeds, s, dim1, direction):
    """The ray of one use of sample s: its direction (into `direction`), its tmax and its weight; the
    AO use's seeds `ao_seeds` (sampling.use_seeds) come made once per pixel.
    USE_AO: cosine-weighted about the normal within ao_distance, weight 1. Light k (use 1 + k): toward a
    sampled light point, tmax a step short of it (shading.short_of_light), weight max(0, N.L) * mask;
    weight 0 needs no ray."""
    if use == USE_AO:  # opaque: the AO sample is made here only, not ahead of the branch (opaque.py)
        ao_direction(sampler, ao_seeds, opaque(s), dim1, normal, direction)
        return ao_distance, 1.0
    light = rows(lights, use - 1, use)[0]
    # A light without extent ignores its sample numbers (lights.DELTA), so none are drawn: Owen-scrambled
    # Sobol costs three nested scrambles a ray (docs/choices.md#no-samples-for-delta-lights).
    u1, u2 = (0.0, 0.0) if light[DELTA] != 0.0 else sample_2d(sampler, ps, s, use, dim1)
    to_light, dist, mask = sample_light(light, (point[0], point[1], point[2]), u1, u2)
    for k in range(3):
        direction[k] = to_light[k]
    cos_nl = normal[0] * direction[0] + normal[1] * direction[1] + normal[2] * direction[2]
    if mask <= 0.0 or cos_nl <= 0.0:
        return dist, 0.0
    return short_of_light(point, direction, dist), cos_nl * mask
