"""Settings (saved with the .blend, on the scene) and run state (not saved, on the window manager).

`KDPreviewSettings` uses config.Settings' names, so `config.make_config(scene.kd_preview)` validates
it exactly as command-line arguments. The run state is not a setting, so it lives on the window
manager: not saved with the file, not travelling with a linked scene.
"""

from __future__ import annotations

import json

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from .config import DEFAULTS, MAX_DEPTH, MAX_LEAF_SIZE, MAX_MEMORY_LIMIT_MB, MAX_SAMPLES


# "//" paths are relative to the .blend: said so where Blender knows the option (4.5 on; 4.2 refuses
# it), else setting one warns 'does not support blend relative "//" prefix'.
PATH_OPTIONS = {"ANIMATABLE"} | ({"PATH_SUPPORTS_BLEND_RELATIVE"} if "is_path_supports_blend_relative" in
                                bpy.types.Property.bl_rna.properties else set())


def _setting_changed(settings, _context) -> None:
    """A setting that changes the image (or Live Update itself) changed. From a script that makes no
    depsgraph update (checked in Blender 5.2; the panel's edits make one), so Live Update would not
    render it until the next edit: schedule its render here too."""
    from . import live_update  # not at the top: live_update imports this module

    live_update.setting_changed(settings)


class KDPreviewSettings(bpy.types.PropertyGroup):
    """KD Preview render settings of a scene."""

    mode: EnumProperty(
        name="Mode", default=DEFAULTS.mode,
        # Numbered: files saved before "auto" keep their mode (an enum is saved as its number).
        items=[("auto", "Automatic", "AO + Shadows when one of the scene's lights emits, else Ambient Occlusion",
                "NONE", 3),
               ("ao", "Ambient Occlusion", "Occlusion within AO Distance", "NONE", 0),
               ("shadow", "Shadows", "Direct light from the scene's lights, with shadows", "NONE", 1),
               ("ao+shadow", "AO + Shadows", "Both, multiplied", "NONE", 2)], update=_setting_changed)
    samples: IntProperty(name="Samples", description="Samples per pixel", default=DEFAULTS.samples,
                         min=1, max=MAX_SAMPLES, soft_max=1024, update=_setting_changed)
    ao_distance: FloatProperty(name="AO Distance", description="Length of ambient-occlusion rays",
                               default=DEFAULTS.ao_distance, min=1e-6, soft_max=100.0, subtype="DISTANCE",
                               unit="LENGTH", update=_setting_changed)
    resolution_percentage: IntProperty(name="Resolution", description="Percent of the scene's base render resolution (X and Y; its own % is not applied)",
                                       default=DEFAULTS.resolution_percentage, min=1, max=100, subtype="PERCENTAGE",
                                       update=_setting_changed)
    builder: EnumProperty(
        name="Builder", default=DEFAULTS.builder,
        items=[("binned", "Binned SAH", "Min-max binned SAH: fast, near-exact quality"),
               ("exact", "Exact SAH", "Full event sweep: best tree, slowest build"),
               ("median", "Spatial Median", "Cheapest build, slower tracing")], update=_setting_changed)
    leaf_size: IntProperty(name="Leaf Size", description="Nodes with this many triangles or fewer become leaves",
                           default=DEFAULTS.leaf_size, min=1, max=MAX_LEAF_SIZE, soft_max=64,
                           update=_setting_changed)
    max_depth: IntProperty(name="Max Depth", description="Tree depth limit (0 = automatic)",
                           default=DEFAULTS.max_depth, min=0, max=MAX_DEPTH, update=_setting_changed)
    bins: IntProperty(name="Bins", description="SAH bins per axis (binned builder)", default=DEFAULTS.bins,
                      min=2, max=4096, soft_max=256, update=_setting_changed)
    threads: IntProperty(name="Threads", description="Worker threads (0 = all cores)", default=DEFAULTS.threads,
                         min=0, max=1024, update=_setting_changed)
    error_target: FloatProperty(name="Error Target",
                                description="Stop sampling a pixel once its standard error is below this (0 = off)",
                                default=DEFAULTS.error_target, min=0.0, soft_max=0.1, precision=4,
                                update=_setting_changed)
    denoise: BoolProperty(name="Denoise",
                          description="Filter the finished image with an edge-avoiding à-trous denoiser guided by "
                                      "each pixel's sample variance (smooth at low sample counts; fades out as "
                                      "pixels converge)",
                          default=DEFAULTS.denoise, update=_setting_changed)
    seed: IntProperty(name="Seed", description="Sampler seed", default=DEFAULTS.seed, min=0, update=_setting_changed)
    memory_limit_mb: IntProperty(name="Memory Limit (MiB)",
                                 description="Refuse a frame whose estimated peak memory is above this (0 = no limit)",
                                 default=DEFAULTS.memory_limit_mb, min=0, max=MAX_MEMORY_LIMIT_MB,
                                 soft_max=65536, update=_setting_changed)
    lazy: BoolProperty(name="Lazy Build",
                       description="Build the kd-tree on demand, only where rays go (same image; pays when "
                                   "most of the scene is hidden)",
                       default=DEFAULTS.lazy, update=_setting_changed)
    rebuild_all: BoolProperty(name="Rebuild All",
                              description="Rebuild every kd-tree and re-trace every frame instead of reusing "
                                          "unchanged objects' trees and unchanged images (for comparisons)",
                              default=DEFAULTS.rebuild_all, update=_setting_changed)
    output_format: EnumProperty(name="Format", default=DEFAULTS.output_format,
                                items=[("PNG", "PNG", "16-bit sRGB PNG"), ("OPEN_EXR", "OpenEXR", "Linear float EXR")])
    output_dir: StringProperty(name="Output Folder", description="Where Render Animation writes frames and report.json",
                               default="//kd_preview/", subtype="DIR_PATH", options=PATH_OPTIONS)
    live_update: BoolProperty(name="Live Update",
                              description="Re-render the preview whenever the frame changes, and after edits "
                                          "once they pause",
                              default=False, update=_setting_changed)


class KDPreviewRunState(bpy.types.PropertyGroup):
    """What the panel shows about the current and the last run (never saved)."""

    running: BoolProperty(name="Running", default=False)
    status: StringProperty(name="Status", default="")
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype="FACTOR")
    last_run: StringProperty(name="Last Run", description="JSON summary of the last finished run", default="")
    # No methods here: the bpy 4.2 module crashes at exit (SIGSEGV) once a PropertyGroup with a Python
    # method has been registered, even after unregistering it (the command line registers this group).


def set_last_run(state: KDPreviewRunState, summary: dict) -> None:
    state.last_run = json.dumps(summary)


def last_run_of(state: KDPreviewRunState) -> dict:
    """The last finished run's summary ({} before the first, or if the stored text is not JSON)."""
    try:
        return json.loads(state.last_run) if state.last_run else {}
    except ValueError:
        return {}


CLASSES = (KDPreviewSettings, KDPreviewRunState)


def run_state(context=None) -> KDPreviewRunState:
    return (context or bpy.context).window_manager.kd_preview_state


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.kd_preview = PointerProperty(type=KDPreviewSettings)
    bpy.types.WindowManager.kd_preview_state = PointerProperty(type=KDPreviewRunState)


def unregister():
    del bpy.types.WindowManager.kd_preview_state
    del bpy.types.Scene.kd_preview
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
