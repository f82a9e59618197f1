"""The "KD Preview" tab in the 3D viewport sidebar: settings, buttons, status and the last run."""

from __future__ import annotations

import textwrap

import bpy

from .properties import last_run_of, run_state
from .warmup_display import draw_status

# (label, key in the last-run summary, format) in display order.
RUN_ROWS = (
    ("Frame", "frame", "{}"),
    ("Size", "size", "{}"),
    ("Triangles", "triangles", "{:,}"),
    ("Objects", "objects", "{:,}"),
    ("Lights", "lights", "{}"),
    ("Mode", "mode", "{}"),
    ("Extract", "extract_ms", "{:.1f} ms"),
    ("Build", "build_ms", "{:.1f} ms"),
    ("Trace", "trace_ms", "{:.1f} ms"),
    ("Total", "total_ms", "{:.1f} ms"),
    ("Rays", "rays", "{:,}"),
    ("Speed", "mrays_per_s", "{:.2f} Mrays/s"),
    ("Rays Saved", "rays_saved", "{:,}"),
    ("Rays Reused", "rays_reused", "{:,}"),
    ("Pixels Kept", "pixels_reused", "{:,}"),
    ("Trees Built", "objects_rebuilt", "{:,}"),
    ("Trees Kept", "objects_reused", "{:,}"),
)
LAZY_ROWS = (  # a lazy tree (Lazy Build): how much of it the rays made it build
    ("Subtrees Deferred", "subtrees_total", "{:,}"),  # at the build: left for the rays to ask for
    ("Built On Demand", "subtrees_built", "{:,}"),  # of those, the ones the rays asked for
    ("Lazy Build", "lazy_build_ms", "{:.1f} ms"),
)
TREE_ROWS = (
    ("Nodes", "nodes", "{:,}"),
    ("Leaves", "leaves", "{:,}"),
    ("Empty Leaves", "empty_leaves", "{:,}"),
    ("Depth", "max_depth", "{}"),
    ("SAH Cost", "sah_cost", "{:.2f}"),
    ("Refs / Triangle", "references_per_triangle", "{:.2f}"),
)


def _rows(layout, values: dict, rows) -> None:
    grid = layout.grid_flow(row_major=True, columns=2, align=True)
    for label, key, fmt in rows:
        if key in values:
            grid.label(text=label)
            grid.label(text=fmt.format(values[key]))


def kernels_note(row: dict) -> str:
    """The first frame's kernel time, which its figures leave out (pipeline.FrameResult)."""
    compiled = f"compiled {row['compile_ms'] / 1e3:.1f} s (first use), " if row.get("compile_ms") else ""
    return f"Kernels {compiled}loaded {row.get('load_ms', 0.0) / 1e3:.1f} s: not in the times below"


class _SidebarTab:
    """Where every KD Preview panel lives: the 3D viewport sidebar's "KD Preview" tab."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "KD Preview"


class _SubPanel(_SidebarTab):
    bl_parent_id = "KDPREVIEW_PT_panel"


def wrapped_label(layout, context, text: str, icon: str = "NONE") -> None:
    """`text` as labels wrapped to the sidebar's width (Blender's labels do not wrap and the sidebar
    cuts them at its edge). About 7 pixels a character at UI scale 1; 40 characters without a region."""
    region = getattr(context, "region", None)
    preferences = getattr(context, "preferences", None)
    scale = (preferences.system.ui_scale if preferences is not None else 0.0) or 1.0  # 0 in background mode
    chars = max(20, int(region.width / (7.0 * scale))) if region is not None else 40
    column = layout.column(align=True)
    for i, line in enumerate(textwrap.wrap(text, chars, break_on_hyphens=False) or [""]):
        column.label(text=line, icon=icon if i == 0 or icon == "NONE" else "BLANK1")


class KDPREVIEW_PT_panel(_SidebarTab, bpy.types.Panel):
    """Settings and the Render buttons."""

    bl_label = "KD Preview"
    bl_idname = "KDPREVIEW_PT_panel"

    def draw(self, context):
        settings, state = context.scene.kd_preview, run_state(context)
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        for name in ("mode", "samples", "ao_distance", "resolution_percentage", "error_target", "denoise",
                     "live_update"):
            layout.prop(settings, name)
        draw_status(layout)
        row = layout.row(align=True)
        row.enabled = not state.running
        row.operator("kdpreview.render", icon="RENDER_STILL", text="Render")
        row.operator("kdpreview.render_animation", icon="RENDER_ANIMATION", text="Animation")
        if state.running:
            layout.progress(factor=state.progress, type="BAR", text=state.status or "Rendering…")
            layout.label(text="Esc to cancel", icon="INFO")
        elif state.status:
            wrapped_label(layout, context, state.status, "ERROR" if state.status.startswith("Error") else "NONE")


class KDPREVIEW_PT_tree(_SubPanel, bpy.types.Panel):
    """kd-tree builder settings (collapsed: the defaults suit most scenes)."""

    bl_label = "kd-Tree"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.kd_preview
        self.layout.use_property_split = True
        for name in ("builder", "bins", "leaf_size", "max_depth", "threads", "seed", "memory_limit_mb",
                     "lazy", "rebuild_all"):
            self.layout.prop(settings, name)


class KDPREVIEW_PT_output(_SubPanel, bpy.types.Panel):
    """Where Render Animation writes."""

    bl_label = "Output"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.kd_preview
        self.layout.use_property_split = True
        self.layout.prop(settings, "output_dir")
        self.layout.prop(settings, "output_format")


class KDPREVIEW_PT_last_run(_SubPanel, bpy.types.Panel):
    """Timings and tree statistics of the last finished run."""

    bl_label = "Last Run"

    def draw(self, context):
        last = last_run_of(run_state(context))
        layout = self.layout
        if not last:
            layout.label(text="No run yet")
            return
        last.setdefault("size", f"{last.get('width')} x {last.get('height')}")
        if last.get("first_run"):
            layout.label(text="Includes loading kernels", icon="TIME")
        if last.get("compile_ms") or last.get("load_ms"):
            wrapped_label(layout, context, kernels_note(last), "TIME")
        if last.get("image_reused"):
            layout.label(text="Nothing changed: last image reused", icon="FILE_REFRESH")
        _rows(layout, last, RUN_ROWS)
        tree = last.get("tree", {})
        _rows(layout.box(), tree, TREE_ROWS + (LAZY_ROWS if tree.get("lazy") else ()))
        if "animation" in last:
            animation = last["animation"]
            wrapped_label(layout, context, f"{animation['frames']} frames, report: {animation['report']}")
        for warning in last.get("warnings", []):
            wrapped_label(layout, context, warning, "ERROR")


CLASSES = (KDPREVIEW_PT_panel, KDPREVIEW_PT_tree, KDPREVIEW_PT_output, KDPREVIEW_PT_last_run)

# Registers in order and unregisters in reverse.
register, unregister = bpy.utils.register_classes_factory(CLASSES)
