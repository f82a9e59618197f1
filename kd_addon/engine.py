"""KD Preview as a render engine: Render Properties' engine list, F12 / Ctrl-F12 / `-E KD_PREVIEW`, and
the viewport's Rendered shading.

Registration, the RenderEngine class and its Render Properties panels live here; a final render is
engine_final.py's, the viewport's preview engine_viewport.py's, and the drawing (the only part that
needs a GPU) is `draw_image` below. The sidebar panel (panel.py) stays for the timings and tree figures.
"""

from __future__ import annotations

import bpy
import numpy as np

from . import engine_final, engine_viewport
from .config import make_config
from .errors import PreviewError
from .pipeline import FrameView

ENGINE_ID = "KD_PREVIEW"
# Blender's own Render Properties panels that apply to any engine's image (colour management); each
# Blender version has some of them (RENDER_PT_color_management_working_space is 5.0's).
SHARED_PANELS = ("RENDER_PT_color_management", "RENDER_PT_color_management_working_space",
                 "RENDER_PT_color_management_advanced", "RENDER_PT_color_management_curves",
                 "RENDER_PT_color_management_display_settings", "RENDER_PT_color_management_white_balance")


class KDPreviewRenderEngine(bpy.types.RenderEngine):
    """Ray-traced ambient occlusion and shadows from KD Preview's kd-trees."""

    bl_idname = ENGINE_ID
    bl_label = "KD Preview"
    bl_use_preview = False  # no material previews: the preview shades no material

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.session = None  # engine_viewport.ViewportSession, made by the first viewport draw
        self.texture = None  # (image the texture was made from, gpu.types.GPUTexture)

    def render(self, depsgraph):
        engine_final.FinalRender(self, depsgraph).run()

    def update_render_passes(self, scene=None, renderlayer=None):
        engine_final.update_render_passes(self, scene, renderlayer)

    def view_update(self, context, depsgraph):
        if self.session is None:
            self.session = engine_viewport.ViewportSession(depsgraph.scene)
        if engine_viewport.changes_image(engine_viewport.update_rows(depsgraph)):
            self.session.scene_changed()

    def view_draw(self, context, depsgraph):
        scene = depsgraph.scene
        if self.session is None:
            self.session = engine_viewport.ViewportSession(scene)
        region, view = context.region, context.region_data
        try:
            config = make_config(scene.kd_preview)
            width, height = engine_viewport.viewport_size(region.width, region.height,
                                                          config.resolution_percentage)
            camera = engine_viewport.camera_from_matrices(view.view_matrix, view.window_matrix, width, height)
            working = self.session.advance(depsgraph, FrameView(width, height, camera), config)
        except PreviewError as error:
            self.session.error, working = str(error), False
        self.update_stats("", self.session.status)
        if self.session.image is not None:
            draw_image(self, scene, self.session.image, region.width, region.height)
        if working:
            self.tag_redraw()  # refine while idle: the next draw adds the next samples


def draw_image(engine, scene, image, width: int, height: int) -> None:
    """Draw the preview image (H, W, 4, row 0 at the top, scene linear) over the width x height region,
    through the scene's view transform (the engine's display-space shader), as Blender's own engines do."""
    import gpu
    from gpu_extras.presets import draw_texture_2d

    if engine.texture is None or engine.texture[0] is not image:
        rows = np.ascontiguousarray(image[::-1], np.float32).reshape(-1)  # the texture's rows go from the bottom
        buffer = gpu.types.Buffer("FLOAT", len(rows), rows)
        engine.texture = (image, gpu.types.GPUTexture((image.shape[1], image.shape[0]), format="RGBA16F",
                                                      data=buffer))
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(engine.texture[1], (0, 0), width, height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")


class _RenderProperties:
    """Render Properties' panels while KD Preview is the scene's engine."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE_ID}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def _props(self, context, names) -> None:
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        for name in names:
            layout.prop(context.scene.kd_preview, name)


class KDPREVIEW_PT_render_settings(_RenderProperties, bpy.types.Panel):
    bl_label = "KD Preview"
    bl_idname = "KDPREVIEW_PT_render_settings"

    def draw(self, context):
        self._props(context, ("mode", "samples", "ao_distance", "error_target", "denoise", "seed"))
        self.layout.label(text="Viewport: Resolution % of the view (final renders: Output > Format)", icon="INFO")
        self.layout.prop(context.scene.kd_preview, "resolution_percentage")


class KDPREVIEW_PT_render_tree(_RenderProperties, bpy.types.Panel):
    bl_label = "kd-Tree"
    bl_parent_id = "KDPREVIEW_PT_render_settings"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        self._props(context, ("builder", "bins", "leaf_size", "max_depth", "threads", "memory_limit_mb",
                              "lazy", "rebuild_all"))


CLASSES = (KDPreviewRenderEngine, KDPREVIEW_PT_render_settings, KDPREVIEW_PT_render_tree)


def _shared_panels():
    return [panel for panel in (getattr(bpy.types, name, None) for name in SHARED_PANELS)
            if panel is not None and hasattr(panel, "COMPAT_ENGINES")]


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for panel in _shared_panels():
        panel.COMPAT_ENGINES.add(ENGINE_ID)


def unregister():
    for panel in _shared_panels():
        panel.COMPAT_ENGINES.discard(ENGINE_ID)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
