"""KD Preview core: a parallel SAH kd-tree and robust ray queries, in numpy and Numba (never bpy).

Public API:
    build_kdtree(triangles, **options) -> KdTree     (options: see BuildOptions)
    intersect(tree, origins, directions, tmin=0.0, tmax=inf) -> Hits(t, prim, u, v)
    occluded(tree, origins, directions, tmin=0.0, tmax=inf) -> (R,) bool
    KdTree.stats() -> dict
    Camera(matrix_world, fov) / Camera(matrix_world, ortho_scale=s); clip_start, clip_end, shift
    Light.point / Light.sun / Light.spot / Light.area
    render_preview(tree, camera, width, height, options=None, mode="ao", samples=16, ...) -> (H, W, 4) float32
    RenderOptions(mode="ao", samples=16, ...): the render settings, validated and frozen; the keywords
        of render_preview and PreviewRender build one (or replace fields of `options`)
    PreviewRender(tree, camera, width, height, options=None, ..., previous=None)   progressive: step(), image(), done;
        pixel_state() -> PixelState: continue the next frame from it (previous=), keeping the pixels
        whose rays cannot reach what changed (scenes from a SceneBuilder)
    frame_ray_count(width, height, mode, samples, lights) -> int: the most rays a render traces (for the
        build option rays, which trims a tree that serves few rays: see BuildOptions)
    memory.build_bytes / memory.render_bytes: peak-memory estimates; MemoryLimitError
Two-level scenes (a kd-tree per mesh in object space under a top-level tree over instances):
    build_two_level(mesh_trees, mesh_of, matrices, visibility=None, **options) -> TwoLevelScene
    build_scene(meshes, mesh_of, matrices, origin=None, layout="auto", visibility=None, **options)
    SceneBuilder(layout="auto", **options).build(MeshInputs, mesh_of, matrices, origin, reuse, visibility,
        rays) -> (scene, report); rays: the frame's ray count, for the trees of deforming meshes;
        PlacementRangeError (a ValueError; .instances) when matrices place meshes beyond float32's range
    intersect_scene / occluded_scene (scene or tree, origins, directions, ..., ray_mask=ALL_RAYS)
        -> SceneHits / (R,) bool
    Per-instance ray visibility (Blender's Ray Visibility, as Cycles applies it): visibility bits
    CAMERA_RAYS | SHADOW_RAYS; camera rays meet only instances visible to the camera, AO and shadow
    rays only those that cast shadows. | HOLDOUT (Blender's Holdout): a pixel whose camera ray hits the
    instance stays empty (alpha 0); the instance still occludes and shadows.
    A TwoLevelScene renders wherever a KdTree does.
First-render compile on two cores (an empty Numba cache):
    with rendering_kernels_alongside(denoise=False): <build>   a helper process compiles the rendering
        kernels meanwhile (parallel_compile.py); KD_PREVIEW_COMPILE_HELPER=0 turns it off
Denoising (edge-avoiding à-trous, variance-guided; the raw estimate stays the default):
    render_preview(..., denoise=True) / PreviewRender.image(denoise=True) -> (H, W, 4) float32
    denoise_pixels(width, height, pixels, points, normals, sums, sq_sums, counts) -> (H, W, 4) float32
"""
from .jit import kernel_cache  # first: kernels are keyed by all of core's sources when decorated
from .jit import inline_copy  # noqa: F401  (before any kernel compiles: halves a cold compile)
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
