"""RenderOptions: every setting of a preview render, with its default, validated once, frozen.

PreviewRender and render_preview take one (options=) and/or the same names as keywords, which build or
amend one. The lights are a setting; the image size, camera and scene are not (they are the frame).
"""
from dataclasses import dataclass, fields, replace

import numpy as np

from ..inputs import as_number
from .lights import Light, pack_lights
from .sample_rays import MODES
from .sampling import SAMPLERS


@dataclass(frozen=True)
class RenderOptions:
    """Preview render settings (PreviewRender, render_preview); each checked when the object is made.

    mode: "ao" (default), "shadow" or "ao+shadow" (what a pixel's value is: preview_render.py).
    samples: 16; samples per pixel, an integer >= 1.
    ao_distance: 1.0; how far AO rays look for occluders, finite and >= 0.
    lights: (); core.Light objects, at least one for the modes with shadows (kept as a tuple).
    seed: 0; any integer, taken modulo 2^32: sampling is deterministic for a seed.
    sampler: "sobol" (Owen-scrambled Sobol) or "random" (independent numbers; sampling.py).
    error_target: None (off); > 0, a pixel stops sampling once the estimated standard error of its mean is
        below it (convergence.py: Sobol's variance decay, pooled over its 5x5 neighbourhood, Laplace's floor),
        checked when the sample count reaches a power of two.
    min_samples: 8; samples a pixel takes before the error target may stop it, an integer >= 2 (the first
        check is the power of two at or above it).
    ambient: 0.25; in [0, 1], the light an occluded-from-the-lights point still gets in "ao+shadow".
    threads: None (all Numba threads) or an integer >= 1.
    """

    mode: str = "ao"
    samples: int = 16
    ao_distance: float = 1.0
    lights: tuple = ()
    seed: int = 0
    sampler: str = "sobol"
    error_target: float | None = None
    min_samples: int = 8
    ambient: float = 0.25
    threads: int | None = None

    def __post_init__(self):
        check_mode_and_samples(self.mode, self.samples)
        _check_sampling(self)
        _check_ambient_seed_threads(self.ambient, self.seed, self.threads)
        object.__setattr__(self, "lights", _as_tuple(self.lights))
        packed_lights(self.mode, self.lights)

    @classmethod
    def make(cls, options=None, **settings):
        """`options` (a RenderOptions, or None for the defaults) with the keyword `settings` replacing
        its fields; a TypeError names an unknown one."""
        if options is None:
            return cls(**settings)
        if not isinstance(options, cls):
            raise ValueError(f"options must be a core.RenderOptions, got {type(options).__name__}")
        return replace(options, **settings) if settings else options

    def as_dict(self):
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _as_tuple(lights):
    """A list or other iterable of lights as a tuple; one Light or a non-iterable as given, for
    pack_lights to name."""
    if isinstance(lights, Light):
        return lights
    try:
        return tuple(lights)
    except TypeError:
        return lights


def check_mode_and_samples(mode, samples):
    if not isinstance(mode, str) or mode not in MODES:  # a list would fail unhashable, unnamed
        raise ValueError(f"mode must be one of {sorted(MODES)}, got {mode!r}")
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise ValueError(f"samples must be an integer >= 1, got {samples!r}")


def packed_lights(mode, lights):
    """pack_lights(lights); a ValueError when a mode with shadows gets none."""
    rows = pack_lights(lights)
    if mode != "ao" and len(rows) == 0:
        raise ValueError(f"mode {mode!r} needs at least one light")
    return rows


def _check_sampling(o):
    if not (np.isfinite(as_number("ao_distance", o.ao_distance)) and o.ao_distance >= 0):
        raise ValueError(f"ao_distance must be finite and >= 0, got {o.ao_distance!r}")
    if o.sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {SAMPLERS}, got {o.sampler!r}")
    if o.error_target is not None and not (np.isfinite(as_number("error_target", o.error_target))
                                           and o.error_target > 0):
        raise ValueError(f"error_target must be None or > 0, got {o.error_target!r}")
    if isinstance(o.min_samples, bool) or not isinstance(o.min_samples, (int, np.integer)) or o.min_samples < 2:
        raise ValueError(f"min_samples must be an integer >= 2, got {o.min_samples!r}")


def _check_ambient_seed_threads(ambient, seed, threads):
    if isinstance(ambient, bool) or not isinstance(ambient, (int, float, np.integer, np.floating)) \
            or not 0.0 <= ambient <= 1.0:
        raise ValueError(f"ambient must be in [0, 1], got {ambient!r}")
    if not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    if threads is not None and (not isinstance(threads, (int, np.integer)) or threads < 1):
        raise ValueError(f"threads must be None or an integer >= 1, got {threads!r}")
