"""KD Preview settings keyed to change over a command-line run's frames, found from the scene's animation
curves. The command line and the farm read the settings once, at the frame the file was saved at (as the
panel's Animation reads them at the current frame); without the settings group registered a frame change
does not show keyed values, so the curves themselves are read (sequence.py names them for the panel)."""
from .animation_curves import active_curves, animated_paths
from .config import SETTING_NAMES

SETTINGS_PATH = "kd_preview."


def keyed_settings_note(scene, frames, given=()) -> str:
    """A warning naming the render settings whose keyed value on one of `frames` differs from the frame the
    file was saved at, or that NLA strips or drivers animate; "" when none. `given`: settings the command
    line replaced."""
    saved = scene.frame_current
    changed = set()
    for curve in active_curves(scene, SETTINGS_PATH):
        base = curve.evaluate(saved)
        if any(curve.evaluate(f) != base for f in frames):
            changed.add(_setting(curve.data_path))
    changed |= {_setting(path) for path in animated_paths(scene, SETTINGS_PATH, active=False)}  # NLA, drivers
    changed = (changed & set(SETTING_NAMES)) - set(given)  # not the panel's own switches (Live Update)
    if not changed:
        return ""
    return (f"KD Preview settings keyed to change over the frames ({', '.join(sorted(changed))}) are not "
            f"followed: this run uses their values at frame {saved}, the frame the file was saved at (an option "
            "given replaces them); the render engine's animation (blender -b FILE -E KD_PREVIEW -a) follows them "
            "frame by frame")


def _setting(data_path: str) -> str:
    return data_path[len(SETTINGS_PATH):].split("[")[0]
