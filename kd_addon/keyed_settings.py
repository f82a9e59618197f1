"""KD Preview settings keyed to change over a command-line run's frames, found from the scene's animation
curves. The command line and the farm read the settings once, at the frame the file was saved at (as the
panel's Animation reads them at the current frame); without the settings group registered a frame change
does not show keyed values, so the curves themselves are read (sequence.py names them for the panel)."""

SETTINGS_PATH = "kd_preview."


def keyed_settings_note(scene, frames, given=()) -> str:
    """A warning naming the settings whose keyed value on one of `frames` differs from the frame the file
    was saved at, or driven ones; "" when none. `given`: settings the command line replaced."""
    curves, drivers = _settings_curves(scene)
    saved = scene.frame_current
    changed = {_setting(c) for c in curves if any(c.evaluate(f) != c.evaluate(saved) for f in frames)}
    changed |= {_setting(d) for d in drivers}
    changed -= set(given)
    if not changed:
        return ""
    return (f"KD Preview settings keyed to change over the frames ({', '.join(sorted(changed))}) are not "
            f"followed: this run uses their values at frame {saved}, the frame the file was saved at (an option "
            "given replaces them); the render engine's animation (blender -b FILE -E KD_PREVIEW -a) follows them "
            "frame by frame")


def _setting(curve) -> str:
    return curve.data_path[len(SETTINGS_PATH):].split("[")[0]


def _settings_curves(scene):
    """(keyframe curves, drivers) of the scene's KD Preview settings: from a layered action's channel bag
    for the scene's slot (Blender 4.4 and later), else the action's own curves (4.2, 4.3)."""
    data = scene.animation_data
    if data is None:
        return [], []
    drivers = [d for d in data.drivers if d.data_path.startswith(SETTINGS_PATH)]
    action, curves = data.action, []
    if action is not None:
        slot = getattr(data, "action_slot", None)
        if getattr(action, "layers", None) and slot is not None:
            for layer in action.layers:
                for strip in layer.strips:
                    bag = strip.channelbag(slot)
                    curves += list(bag.fcurves) if bag is not None else []
        elif hasattr(action, "fcurves"):
            curves = list(action.fcurves)
    return [c for c in curves if c.data_path.startswith(SETTINGS_PATH)], drivers
