"""KD Preview settings keyed to change over a command-line run's frames, found from the scene's animation
curves. The command line and the farm read the settings once, at the frame the file was saved at (as the
panel's Animation reads them at the current frame); without the settings group registered a frame change
does not show keyed values, so the curves themselves are read (sequence.py names them for the panel)."""
from .animation_curves import active_curves, animated_paths
from .config import SETTING_NAMES

SETTINGS_PATH = "kd_preview."


def keyed_settings_note(scene, frames, given=(), stored=None) -> str:
    """A warning naming the render settings whose keyed value on one of `frames` differs from the frame the
    file was saved at, or that NLA strips or drivers animate, and those edited after they were keyed; ""
    when none. `given`: settings the command line replaced; `stored`: stored_setting_values."""
    saved = scene.frame_current
    curves = active_curves(scene, SETTINGS_PATH)
    others = {_setting(path) for path in animated_paths(scene, SETTINGS_PATH, active=False)}  # NLA, drivers
    changed = set(others)
    for curve in curves:
        base = curve.evaluate(saved)
        if any(curve.evaluate(f) != base for f in frames):
            changed.add(_setting(curve.data_path))
    changed = (changed & set(SETTING_NAMES)) - set(given)  # not the panel's own switches (Live Update)
    edited = (_edited_after_keys(scene, curves, others, stored or {}) & set(SETTING_NAMES)) - set(given)
    notes = []
    if changed:
        notes.append(f"KD Preview settings keyed to change over the frames ({', '.join(sorted(changed))}) are not "
                     f"followed: this run uses their values at frame {saved}, the frame the file was saved at (an "
                     "option given replaces them); the render engine's animation (blender -b FILE -E KD_PREVIEW -a) "
                     "follows them frame by frame")
    if edited:
        notes.append(f"KD Preview settings edited after they were keyed ({', '.join(sorted(edited))}): this run uses "
                     f"the edited values saved in the file, not their keys at frame {saved}; Blender puts the keyed "
                     "values back at its next frame change, as the render engine's animation does (key the edit to "
                     "keep it)")
    return "; ".join(notes)


def _edited_after_keys(scene, curves, others: set[str], stored: dict) -> set[str]:
    """Settings keyed by `curves` whose stored value is not their curve's (clamped to the setting's bounds,
    as Blender stores it) at the (sub)frame the file was saved at; not the `others` that drivers or NLA
    strips also animate (their stored value is not the curve's)."""
    if not stored:
        return set()
    at = scene.frame_current + scene.frame_subframe
    edited = set()
    for curve in curves:
        name = _setting(curve.data_path)
        value, low, high = stored.get(name, (None, None, None))
        if name not in others and _edited(value, _clamped(curve.evaluate(at), low, high)):
            edited.add(name)
    return edited


def _clamped(keyed: float, low, high) -> float:
    """The curve's value as Blender stores it in a setting bounded by [low, high] (None: unbounded)."""
    keyed = keyed if low is None else max(low, keyed)
    return keyed if high is None else min(high, keyed)


def _edited(value, keyed: float) -> bool:
    """Whether a stored value is not what its curve gives at that frame: an integer, enum or switch
    that an interpolated key sets keeps within 1 of it, a float within float32's rounding."""
    if value is None:
        return False
    if isinstance(value, int):
        return abs(value - keyed) >= 1.0
    return abs(float(value) - keyed) > 1e-6 * max(1.0, abs(keyed))


def stored_setting_values(settings) -> dict:
    """{setting: (value as the file stores it, hard minimum, hard maximum)} from the registered settings group
    `settings`: an enum's item number, as its curve holds it; None where the setting was never set; the
    bounds of integer and float settings, else None."""
    bounds = {p.identifier: (p.hard_min, p.hard_max) for p in settings.bl_rna.properties if p.type in ("INT", "FLOAT")}
    return {name: (settings.get(name), *bounds.get(name, (None, None))) for name in SETTING_NAMES}


def _setting(data_path: str) -> str:
    return data_path[len(SETTINGS_PATH):].split("[")[0]
