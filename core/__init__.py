"""KD Preview core: a parallel SAH kd-tree and robust ray queries, in numpy and Numba (never bpy).

Public API:
    build_kdtree(triangles, **options) -> KdTree (options: BuildOptions); KdTree.stats() -> dict
    intersect(tree, origins, directions, tmin=0.0, tmax=inf) -> Hits(t, prim, u, v)
    occluded(tree, origins, directions, tmin=0.0, tmax=inf) -> (R,) bool
    Camera(matrix_world, fov) / Camera(matrix_world, ortho_scale=s); Light.point / sun / spot / area
    RenderOptions(mode="ao", samples=16, ...): the render settings, validated and frozen
    render_preview(tree, camera, width, height, options=None, **settings) -> (H, W, 4) float32
    PreviewRender(tree, camera, width, height, options=None, previous=None, compile_packets=True, **settings):
        step(), image(), done, pixel_state(); keywords build a RenderOptions or replace fields of `options`
    PixelState: a finished frame's pixels, passed as `previous` to keep what did not change
    frame_ray_count(width, height, mode, samples, lights) -> int: the build option `rays` for one frame
    memory.build_bytes / memory.render_bytes: peak-memory estimates; MemoryLimitError when above a limit
    build_two_level(mesh_trees, mesh_of, matrices, visibility=None, **options) -> TwoLevelScene
    build_scene(meshes, mesh_of, matrices, origin=None, layout="auto", visibility=None, **options)
    SceneBuilder(layout, **options).build(MeshInputs, ...) -> (scene, BuildReport): trees reused per frame
    PlacementRangeError: a ValueError whose .instances lie beyond float32's range
    intersect_scene / occluded_scene(scene or tree, origins, directions, ...) -> SceneHits / (R,) bool
    CAMERA_RAYS, SHADOW_RAYS, ALL_RAYS, HOLDOUT: per-instance ray visibility bits (as Cycles applies them)
    rendering_kernels_alongside(denoise=False, packets=True): a `with` block in which a helper compiles the renderer
    denoise_pixels(width, height, pixels, points, normals, sums, sq_sums, counts) -> (H, W, 4) float32
"""
from .jit import kernel_cache  # first: kernels are keyed by all of core's sources when decorated
from .jit import inline_copy, inline_memo  # noqa: F401  (before any kernel compiles: the two modules' docstrings)
from .build.builder import build_kdtree
from .render.camera import Camera
from .render.denoise import denoise_pixels
from .render.lights import Light
from .render.preview_render import PreviewRender, frame_ray_count, render_preview
from .render.render_options import RenderOptions
from .trace.kdtree import KdTree
from .memory import MemoryLimitError
from .build.options import BuildOptions
from .jit.parallel_compile import rendering_kernels_alongside
from .render.pixel_reuse import PixelState
from .trace.queries import Hits, intersect, occluded
from .scene.ray_visibility import ALL_RAYS, CAMERA_RAYS, HOLDOUT, SHADOW_RAYS
from .scene.scene_builder import BuildReport, MeshInput, PlacementRangeError, SceneBuilder, build_scene
from .scene.scene_queries import SceneHits, intersect_scene, occluded_scene
from .scene.two_level import TwoLevelScene, build_two_level

__all__ = ["denoise_pixels",
           "build_kdtree", "intersect", "occluded", "KdTree", "Hits", "BuildOptions", "Camera", "Light",
           "render_preview", "PreviewRender", "RenderOptions", "frame_ray_count", "TwoLevelScene",
           "build_two_level", "build_scene", "SceneBuilder",
           "MeshInput", "BuildReport", "SceneHits", "intersect_scene", "occluded_scene", "MemoryLimitError",
           "PlacementRangeError", "PixelState", "rendering_kernels_alongside", "CAMERA_RAYS", "SHADOW_RAYS",
           "ALL_RAYS", "HOLDOUT"]
