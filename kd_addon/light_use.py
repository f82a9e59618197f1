"""Which of a scene's lights a frame uses: the core.Light of each that lights the preview's surfaces,
and the mode "auto" resolves to (docs/choices.md#automatic-mode-ao-and-shadows-where-a-light-emits)."""

from __future__ import annotations

import math

from . import scene_input


def resolved_mode(core, mode: str, lights: list) -> str:
    """`mode`, with "auto" made "ao+shadow" when one of the scene's lights emits (usable_light) and
    "ao" otherwise (docs/choices.md#automatic-mode-ao-and-shadows-where-a-light-emits)."""
    if mode != "auto":
        return mode
    return "ao+shadow" if any(isinstance(used, core.Light) for _, used in classified(core, lights)) else "ao"


class EmitsNothing(ValueError):
    """A scene light that lights no surface of the preview; in mode "auto" one leaves the frame at AO
    without a word (a light core refuses is named: refused_lights)."""


def usable_light(core, light: scene_input.LightInput):
    """The core.Light of a scene light; EmitsNothing or core's ValueError saying why it cannot be used."""
    power = light.keywords.get("power", light.keywords.get("strength"))
    if not power > 0.0:
        raise EmitsNothing(f"its power is {power:g}, so it emits no light")
    if light.emits_nothing:
        raise EmitsNothing(f"{light.emits_nothing}, so it emits no light")
    color = light.keywords["color"]
    if all(math.isfinite(c) for c in color) and not max(color) > 0.0:  # NaN or inf: core names the colour
        raise EmitsNothing("its colour is black, so it emits no light")
    if light.portal:
        raise EmitsNothing("it is a Cycles light portal, which emits no light")
    if light.no_diffuse:
        raise EmitsNothing(f"{light.no_diffuse}, so it lights no diffuse surface")
    return getattr(core.Light, light.kind)(**light.keywords)


def classified(core, lights: list) -> list:
    """(scene light, its core.Light or the ValueError why it cannot be used) for each of `lights`."""
    out = []
    for light in lights:
        try:
            out.append((light, usable_light(core, light)))
        except ValueError as error:
            out.append((light, error))
    return out


def refused_lights(core, lights: list) -> list:
    """(light, error) of the scene lights that emit but that core refuses (a setting it cannot take)."""
    return [(light, used) for light, used in classified(core, lights)
            if isinstance(used, ValueError) and not isinstance(used, EmitsNothing)]
