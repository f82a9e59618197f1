"""Made-up frames that run every kernel a default render runs, so a process started ahead of the
first render (the add-on's kernel warm-up, kd_addon/kernel_warmup.py) can fill Numba's on-disk cache
with them, and the render itself only loads them.

They take the add-on's path through core with the default settings: a SceneBuilder over several meshes
(instanced, merged into a soup, and one large enough for its own tree), the rendering kernels compiled by
the helper beside the build and camera pass (parallel_compile.py, warmup=True), an ao+shadow render with
one light of each kind, then a second frame with one object moved that continues from the first one's
pixels (the pixel-reuse kernels), the tree statistics the panel shows, and last the factory scene's first
frame: one cube, a one-instance scene. Their camera rays and hard shadows go singly, as the add-on's do
until the packets' kernels are cached (PreviewRender's compile_packets=False).
compile_second_stage is the warm-up's second stage, which no render waits for: the camera and hard-shadow
packets' kernels of both scenes (scene_packets.py), the sampling kernel's packed version (sample packets in
batches of 8 or more samples), each taken by the add-on once it is cached (kd_addon/kernel_warmup.py), and
the denoiser, which a first denoised frame would otherwise compile (several seconds).
Numba compiles one version per argument types, so the arrays have the add-on's dtypes
(tree_cache.mesh_inputs). Sizes, modes and sample counts are runtime values and need no second compile.
"""
from contextlib import nullcontext

import numpy as np

from ..render.camera import Camera
from ..render.lights import Light
from ..render.preview_render import PreviewRender, frame_ray_count
from ..render.render_kernels import PACKED_BATCH
from ..render.render_options import RenderOptions
from ..scene.ray_visibility import CAMERA_RAYS, SHADOW_RAYS
from ..scene.scene_builder import MeshInput, SceneBuilder
from .parallel_compile import rendering_kernels_alongside

WIDTH, HEIGHT, SAMPLES = 12, 8, 2


def grid_mesh(cells: int, lift: float = 0.0):
    """(vertices (V, 3) float32, triangles (T, 3) int32): a bumpy cells x cells grid over [-1, 1]^2."""
    u = np.linspace(-1.0, 1.0, cells + 1)
    x, y = np.meshgrid(u, u)
    z = lift + 0.1 * np.sin(3 * x) * np.cos(2 * y)
    vertices = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)
    corner = (np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)[None, :]).ravel()
    quads = np.stack([corner, corner + 1, corner + cells + 2, corner + cells + 1], axis=1)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)
    return vertices, triangles


def cube_mesh():
    """The default cube's 8 vertices and 12 triangles."""
    vertices = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float32)
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = [tri for a, b, c, d in faces for tri in ((a, b, c), (a, c, d))]
    return vertices, np.array(triangles, np.int32)


def _meshes():
    """A large ground grid (its own tree), a cube placed three times (instanced) and a small plate."""
    ground, cube, plate = grid_mesh(48, -1.0), cube_mesh(), grid_mesh(2, 0.5)
    return [MeshInput(("Ground", "Ground", None, 0), *ground, b"ground"),
            MeshInput(("Cube", "Cube", None, 0), *cube, b"cube"),
            MeshInput(("Plate", "Plate", None, 0), *plate, b"plate")]


def _placements(shift: float):
    """(mesh_of (I,) int64, matrices (I, 4, 4), visibility (I,) uint8); `shift` moves one cube."""
    mesh_of = np.array([0, 1, 1, 1, 2], np.int64)
    matrices = np.repeat(np.eye(4)[None], len(mesh_of), axis=0)
    matrices[1:4, :3, :3] *= 0.3
    matrices[1:4, :3, 3] = [[-0.5 + shift, 0.0, -0.6], [0.5, 0.2, -0.6], [0.0, -0.5, -0.6]]
    visibility = np.full(len(mesh_of), CAMERA_RAYS | SHADOW_RAYS, np.uint8)
    return mesh_of, matrices, visibility


def _lights(offset):
    area = np.eye(4)
    area[:3, 3] = (1.0, 1.0, 2.0)
    lights = [Light.point((1.0, -1.0, 2.0), radius=0.1), Light.sun((0.2, 0.1, -1.0), angle=0.05),
              Light.spot((-1.0, 1.0, 2.0), (0.3, -0.3, -1.0), 0.8), Light.area(area, size=0.5)]
    return [light.translated(offset) for light in lights]


def _camera(offset) -> Camera:
    matrix = np.eye(4)
    matrix[:3, 3] = (0.0, 0.0, 4.0)
    return Camera(matrix, 0.8, clip_start=0.1, clip_end=100.0).translated(offset)


def _frame(builder: SceneBuilder, scene_inputs, previous, first: bool, batch: int = 1,
           mode: str = "ao+shadow", denoise: bool = False, packets: bool = False):
    """One frame as the add-on renders it (kd_addon/pipeline.py), relative to the camera's position, in
    steps of `batch` samples, in `mode`, its image denoised or not; `scene_inputs`: (meshes, mesh_of,
    matrices, visibility). The first frame's build and camera pass run beside the helper's compile
    (parallel_compile.py: the warm-up's split). `packets`: camera rays and hard shadows in packets
    (compiling their kernels), else as the add-on traces them (PreviewRender's compile_packets=False)."""
    offset = np.array([0.0, 0.0, 4.0])
    lights = _lights(offset)
    options = RenderOptions(mode=mode, samples=max(SAMPLES, batch), lights=lights)
    rays = frame_ray_count(WIDTH, HEIGHT, options.mode, options.samples, lights)
    meshes, mesh_of, matrices, visibility = scene_inputs
    with rendering_kernels_alongside(warmup=True) if first else nullcontext():
        scene, _ = builder.build(meshes, mesh_of, matrices, origin=offset, visibility=visibility, rays=rays)
        scene.stats()  # the panel's tree figures (tree_stats.walk_stats)
        render = PreviewRender(scene, _camera(offset), WIDTH, HEIGHT, options, previous=previous,
                               compile_packets=packets)
    while not render.done:
        render.step(batch)
    render.image(denoise=denoise)
    return render.pixel_state()


def _one_cube():
    """The factory scene's objects: one cube at the origin, seen by every ray."""
    cube = MeshInput(("Cube", "Cube", None, 0), *cube_mesh(), b"cube")
    return [cube], np.zeros(1, np.int64), np.eye(4)[None], np.full(1, CAMERA_RAYS | SHADOW_RAYS, np.uint8)


def compile_first_frames() -> None:
    """Run a first frame, a second one continued from it (see the module docstring), and a first frame
    of one object (the factory scene: a one-instance scene)."""
    builder = SceneBuilder("auto")
    pixels = _frame(builder, (_meshes(), *_placements(0.0)), None, first=True)
    _frame(builder, (_meshes(), *_placements(0.2)), pixels, first=False)
    _frame(SceneBuilder("auto"), _one_cube(), None, first=False)


def compile_packet_kernels() -> None:
    """The camera and hard-shadow packets' kernels with the add-on's argument types: the first frame's
    scene (several instances, taken one at a time: instance_packets.py) and the factory scene's (one
    placed instance: its rays carried into object space), traced in packets."""
    _frame(SceneBuilder("auto"), (_meshes(), *_placements(0.0)), None, first=False, packets=True)
    _frame(SceneBuilder("auto"), _one_cube(), None, first=False, packets=True)


def compile_second_stage() -> None:
    """The packets' kernels (compile_packet_kernels), then the sampling kernel's packed version (sample
    packets in batches of PACKED_BATCH or more samples: render/sample_packets.py), which the add-on's first
    steps of one sample never run: the factory scene's frame in one batch, mode ao (one version serves
    every mode), its image denoised (the denoiser's kernels, which no undenoised frame runs). The add-on
    compiles these after the first frames, in a process of lower priority (kd_addon/kernel_warmup.py),
    and takes each once it is cached; a stage stopped part-way runs again."""
    compile_packet_kernels()
    _frame(SceneBuilder("auto"), _one_cube(), None, first=False, batch=PACKED_BATCH, mode="ao", denoise=True)
