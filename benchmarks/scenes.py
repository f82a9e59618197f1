"""Benchmark scenes for KD Preview, built once and cached on disk.

Scenes
------
``suzanne-251k``
    Blender's Suzanne with a Subdivision Surface modifier at level 4
    (251,904 triangles) plus a 6x6 ground plane at z=-1 (2 triangles):
    251,906 triangles in total.  Built with the ``bpy`` module; the
    ``.blend`` holds the subdivided mesh (the modifier applied).
``suzanne-1m``
    The same at level 5: 1,007,616 + 2 = 1,007,618 triangles.
``soup-1m`` / ``soup-100k``
    Seeded random triangle soups (numpy only): 1,000,000 / 100,000 small
    triangles with centres uniform in the box [-0.5, 0.5]^3, vertices within
    +-h of the centre per axis, h = 0.005 for 1M and scaling with the mean
    centre spacing N^(-1/3) (h = 0.0108 for 100k).  Both are nearly opaque
    boxes; the 1M soup is N^(1/3) ~ 2.2x optically thicker.  The camera sits
    2.5 units in front of the box looking at it along +Y.

Every scene has a camera: ``camera_matrix`` is the 4x4 camera-to-world matrix
(Blender convention: the camera looks down its local -Z, +Y is up) and
``camera_fov`` the full field of view in radians along the *larger* image
dimension (Blender's sensor fit AUTO).  ``benchmarks/camera.py`` turns those
into rays.

Cache
-----
``benchmarks/data/<name>.npz`` (uncompressed, so loading takes milliseconds)
holds ``triangles`` float32 (N, 3, 3) world-space, ``camera_matrix`` float64
(4, 4), ``camera_fov`` float64 and a format version.  The Suzanne scenes also
get ``benchmarks/data/<name>.blend`` (same scene, ``scene.camera`` set) so
Cycles benchmarks can open it.  Files are written to a temporary name and
renamed, so concurrent builders cannot leave a half-written cache behind.

API
---
``load_scene(name) -> Scene`` builds on first use and loads afterwards.  The
Blender scenes are built in a child process (``python benchmarks/scenes.py
NAME``) unless ``bpy`` is already imported, so that the caller never imports
``bpy`` by accident (importing ``bpy`` switches Numba's threading layer from
OpenMP to the TBB bundled with ``bpy``).

Command line: ``python benchmarks/scenes.py [--force] [names...]`` prebuilds
the named scenes (all scenes without names).
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional, Tuple

import numpy as np

DATA_DIR = Path(__file__).resolve().parent / "data"

# Bump when the content of a scene changes: stale caches are rebuilt. 2: the .blend holds Suzanne's
# Subdivision applied (Cycles would evaluate a live modifier inside its timed render: ~0.15 s of its
# 2-spp time; our side starts from the cached triangles).
FORMAT_VERSION = 2

# Blender's default camera: 50 mm lens on a 36 mm sensor, sensor fit AUTO.
DEFAULT_LENS_MM = 50.0
DEFAULT_SENSOR_MM = 36.0
DEFAULT_FOV = 2.0 * math.atan(0.5 * DEFAULT_SENSOR_MM / DEFAULT_LENS_MM)  # 0.6911 rad

SUZANNE_CAMERA_LOCATION = (0.0, -4.0, 1.2)
SUZANNE_CAMERA_ROTATION_X_DEG = 75.0


@dataclass(eq=False)
class Scene:
    """A benchmark scene: world-space triangles and a pinhole camera.

    triangles:     float32 (N, 3, 3), world space
    camera_matrix: float64 (4, 4), camera-to-world (Blender ``matrix_world``)
    camera_fov:    full field of view in radians along the larger image
                   dimension (Blender ``camera.data.angle`` with sensor fit AUTO)
    blend_path:    the saved .blend of the scene (Blender scenes only)
    """

    name: str
    triangles: np.ndarray
    camera_matrix: np.ndarray
    camera_fov: float
    blend_path: Optional[Path] = None

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])


# --------------------------------------------------------------------------
# Scene registry
# --------------------------------------------------------------------------

# name -> (kind, parameters)
_SPECS: Dict[str, Tuple[str, dict]] = {
    "suzanne-251k": ("blender", {"level": 4, "expected_monkey_tris": 251_904}),
    "suzanne-1m": ("blender", {"level": 5, "expected_monkey_tris": 1_007_616}),
    "soup-1m": ("soup", {"n": 1_000_000, "seed": 20_251_101}),
    "soup-100k": ("soup", {"n": 100_000, "seed": 20_251_102}),
}

SCENE_NAMES = tuple(_SPECS)


def npz_path(name: str) -> Path:
    return DATA_DIR / f"{name}.npz"


def blend_path(name: str) -> Optional[Path]:
    """Path of the scene's .blend file (None for numpy-only scenes); not built here."""
    _check_name(name)
    return DATA_DIR / f"{name}.blend" if _SPECS[name][0] == "blender" else None


def _check_name(name: str) -> None:
    if name not in _SPECS:
        raise KeyError(f"unknown scene {name!r}; known scenes: {', '.join(SCENE_NAMES)}")


# --------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------


def _is_cached(name: str) -> bool:
    path = npz_path(name)
    if not path.is_file():
        return False
    bp = blend_path(name)
    if bp is not None and not bp.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            return int(z["format_version"]) == FORMAT_VERSION
    except Exception:  # corrupt or foreign file: rebuild
        return False


def load_scene(name: str) -> Scene:
    """Load scene ``name`` from the cache, building (and caching) it first if needed."""
    _check_name(name)
    if not _is_cached(name):
        build_scene(name)
    with np.load(npz_path(name), allow_pickle=False) as z:
        return Scene(
            name=name,
            triangles=z["triangles"],
            camera_matrix=z["camera_matrix"],
            camera_fov=float(z["camera_fov"]),
            blend_path=blend_path(name),
        )


def build_scene(name: str, in_process: Optional[bool] = None) -> None:
    """(Re)build scene ``name`` and write its cache files.

    Blender scenes are built in a child process unless ``bpy`` is already
    imported (or ``in_process=True``).
    """
    _check_name(name)
    kind, params = _SPECS[name]
    if kind == "soup":
        tris, cam, fov = _build_soup(**params)
        _write_npz(name, tris, cam, fov)
        return
    if in_process is None:
        in_process = "bpy" in sys.modules
    if in_process:
        _build_blender_scene(name, **params)
    else:
        cmd = [sys.executable, str(Path(__file__).resolve()), "--force", name]
        subprocess.run(cmd, check=True)
        if not _is_cached(name):
            raise RuntimeError(f"building {name!r} in a child process left no valid cache")


def _write_npz(name: str, triangles: np.ndarray, camera_matrix: np.ndarray, fov: float) -> None:
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    final = npz_path(name)
    tmp = final.with_name(f"{final.stem}.tmp{os.getpid()}.npz")
    np.savez(
        tmp,
        triangles=np.ascontiguousarray(triangles, dtype=np.float32),
        camera_matrix=np.asarray(camera_matrix, dtype=np.float64),
        camera_fov=np.float64(fov),
        format_version=np.int64(FORMAT_VERSION),
    )
    os.replace(tmp, final)


# --------------------------------------------------------------------------
# Random soups (numpy only)
# --------------------------------------------------------------------------


def _camera_matrix_xyz(location, rotation_deg) -> np.ndarray:
    """4x4 camera-to-world matrix for an XYZ Euler rotation (Blender's default order)."""
    ax, ay, az = (math.radians(a) for a in rotation_deg)
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = rz @ ry @ rx
    m[:3, 3] = location
    return m


def _build_soup(n: int, seed: int):
    rng = np.random.default_rng(seed)
    # Vertex offsets are uniform in a cube of half-size h around the centre;
    # h = 0.005 for 1M triangles and scales as N^(-1/3).
    h = 0.005 * (1_000_000 / n) ** (1.0 / 3.0)
    centres = rng.uniform(-0.5, 0.5, size=(n, 1, 3))
    tris = (centres + rng.uniform(-h, h, size=(n, 3, 3))).astype(np.float32)
    # Camera 2.5 units in front of the box (-Y side) looking along +Y.
    cam = _camera_matrix_xyz((0.0, -2.5, 0.0), (90.0, 0.0, 0.0))
    return tris, cam, DEFAULT_FOV


# --------------------------------------------------------------------------
# Blender scenes
# --------------------------------------------------------------------------


def _world_triangles(depsgraph, obj) -> np.ndarray:
    """World-space triangles (N, 3, 3) float32 of ``obj`` as evaluated in ``depsgraph``.

    Uses foreach_get into numpy buffers of the exact RNA dtype (a plain memcpy):
    loop_triangles "loops" (corner indices), the ".corner_vert" attribute
    (corner -> vertex) and the "position" attribute.  On the level-5 Suzanne this
    took 0.14 s against 0.16 s via loop_triangles "vertices" and 0.17 s via
    vertices "co"; the loop_triangles read dominates all of them.
    """
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        looptris = mesh.loop_triangles
        n_tri = len(looptris)
        corners = np.empty(3 * n_tri, dtype=np.int32)
        looptris.foreach_get("loops", corners)

        attrs = mesh.attributes
        corner_vert = np.empty(len(mesh.loops), dtype=np.int32)
        if ".corner_vert" in attrs:
            attrs[".corner_vert"].data.foreach_get("value", corner_vert)
        else:  # older Blender without the internal attribute exposed
            mesh.loops.foreach_get("vertex_index", corner_vert)

        pos = np.empty(3 * len(mesh.vertices), dtype=np.float32)
        attrs["position"].data.foreach_get("vector", pos)
        pos = pos.reshape(-1, 3).astype(np.float64)
        m = np.array(ev.matrix_world, dtype=np.float64)
        world = (pos @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
        return world[corner_vert[corners]].reshape(n_tri, 3, 3)
    finally:
        ev.to_mesh_clear()


def _build_blender_scene(name: str, level: int, expected_monkey_tris: int) -> None:
    import bpy

    t0 = time.perf_counter()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene

    bpy.ops.mesh.primitive_monkey_add()
    monkey = bpy.context.active_object
    subsurf = monkey.modifiers.new(name="Subdivision", type="SUBSURF")
    subsurf.levels = level
    subsurf.render_levels = level

    bpy.ops.mesh.primitive_plane_add(size=6, location=(0.0, 0.0, -1.0))
    plane = bpy.context.active_object

    bpy.ops.object.camera_add(
        location=SUZANNE_CAMERA_LOCATION,
        rotation=(math.radians(SUZANNE_CAMERA_ROTATION_X_DEG), 0.0, 0.0),
    )
    cam = bpy.context.active_object
    cam.data.lens = DEFAULT_LENS_MM
    cam.data.sensor_width = DEFAULT_SENSOR_MM
    cam.data.sensor_fit = "AUTO"
    scene.camera = cam

    depsgraph = bpy.context.evaluated_depsgraph_get()
    monkey_tris = _world_triangles(depsgraph, monkey)
    plane_tris = _world_triangles(depsgraph, plane)
    assert monkey_tris.shape[0] == expected_monkey_tris, (
        f"{name}: subdivided Suzanne has {monkey_tris.shape[0]} triangles, expected {expected_monkey_tris}"
    )
    assert plane_tris.shape[0] == 2, f"{name}: plane has {plane_tris.shape[0]} triangles"
    triangles = np.concatenate([monkey_tris, plane_tris])
    # The .blend gets the subdivided mesh itself, so a Cycles render of it does no subdivision either.
    monkey.data = bpy.data.meshes.new_from_object(monkey.evaluated_get(depsgraph))
    monkey.modifiers.remove(subsurf)

    camera_matrix = np.array(cam.matrix_world, dtype=np.float64)
    camera_fov = float(cam.data.angle)

    DATA_DIR.mkdir(parents=True, exist_ok=True)
    final_blend = blend_path(name)
    tmp_blend = final_blend.with_name(f"{final_blend.stem}.tmp{os.getpid()}.blend")
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_blend), copy=True)
    os.replace(tmp_blend, final_blend)
    # The .npz goes last: its presence (with the right version) marks a complete build.
    _write_npz(name, triangles, camera_matrix, camera_fov)
    print(
        f"built {name}: {triangles.shape[0]:,} triangles in {time.perf_counter() - t0:.1f} s "
        f"-> {npz_path(name)}, {final_blend}",
        flush=True,
    )


# --------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Build and cache the KD Preview benchmark scenes.")
    parser.add_argument("names", nargs="*", help=f"scenes to build (default: all of {', '.join(SCENE_NAMES)})")
    parser.add_argument("--force", action="store_true", help="rebuild even if a valid cache exists")
    args = parser.parse_args(argv)
    names = args.names or list(SCENE_NAMES)
    for name in names:
        _check_name(name)
    for name in names:
        if args.force or not _is_cached(name):
            t0 = time.perf_counter()
            # We are the builder process: build Blender scenes right here.
            build_scene(name, in_process=True)
            print(f"{name}: built in {time.perf_counter() - t0:.1f} s", flush=True)
        t0 = time.perf_counter()
        sc = load_scene(name)
        print(
            f"{name}: {sc.n_triangles:,} triangles, fov {sc.camera_fov:.6f} rad, "
            f"loaded in {1e3 * (time.perf_counter() - t0):.0f} ms",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
