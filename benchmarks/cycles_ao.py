"""Cycles' Ambient Occlusion pass as a reference for KD Preview's "ao" mode (CPU, bpy module).

API
---
``render_cycles_ao(blend_path, width, height, samples, ao_distance=1.0, threads=2)
-> (image, seconds)``: ``image`` is the (H, W) float32 AO pass, row 0 = top row, background 0;
``seconds`` is the wall time of the ``bpy.ops.render.render()`` call, which includes Cycles' scene
sync (mesh export from the depsgraph), the Embree BVH build, kernel setup and the sampling itself.
``render_cycles(...)`` takes the same arguments plus options and returns a ``CyclesAO`` with the
alpha of the combined pass (the hit mask), the time split at Cycles' first "Sample 0/N" status
(``sync_seconds``: sync + BVH + device update; ``sample_seconds``: the rest) and the settings used.

Blender runs in a child process (``python benchmarks/cycles_ao.py --child SPEC.json``): importing
``bpy`` in the benchmark process would switch Numba's threading layer to the TBB bundled with bpy.
The child opens the .blend, changes the settings below in memory only (the file is never saved),
renders, writes the render result as an uncompressed float32 multilayer EXR with
``Image.save_render`` (after the timed call), reads the "Ambient Occlusion" and "Combined" passes
back and hands them over in a temporary .npz.

Command line::

    python benchmarks/cycles_ao.py BLEND --size 512 512 --samples 16 --ao-distance 1.0 --out ao.npy

What Cycles' AO pass computes (Cycles source as shipped in the bpy 5.0.1 wheel, under
``bpy/5.0/scripts/addons_core/cycles/source/``; host-side files are in blender/blender ``intern/cycles``)
-------------------------------------------------------------------------------------------------------
- It is written only for surfaces hit directly by camera rays: ``film_write_direct_light``
  (kernel/film/light_passes.h:497-502) adds an AO shadow path's throughput to ``pass_ao`` only when
  the path has ``PATH_RAY_SHADOW_FOR_AO`` and ``PATH_RAY_CAMERA``. The pass exists and is traced
  whenever the view layer has it (scene/film.cpp ``get_kernel_features``: ``PASS_AO`` ->
  ``KERNEL_FEATURE_AO_PASS``), independently of Fast GI / world AO factor.
- Cosine-weighted: ``integrate_surface_ao`` (kernel/integrator/shade_surface.h:615-699) draws ONE
  direction per sample with ``sample_cos_hemisphere(ao_N, ...)`` (kernel/sample/mapping.h:67-80,
  pdf = cos/pi) and traces a shadow ray of length ``kernel_data.integrator.ao_bounces_distance``
  (shade_surface.h:652). The shadow path throughput is the camera path throughput (1 for a pinhole
  camera) times ``surface_shader_alpha`` (shade_surface.h:679) and is recorded only if the ray is
  unoccluded. Averaged over samples, the pass is (1/pi) * integral of V(w) cos(theta) dw: the same
  estimand as KD Preview's AO, one AO ray per camera sample. Cycles' ``ao_additive_factor`` /
  ``ao_weight`` only scale what goes into the *combined* pass (light_passes.h:503-506).
- Normal: ``ao_N`` comes from ``surface_shader_ao`` (kernel/integrator/surface_shader.h:1027-1046):
  the weighted average of the DIFFUSE closures' normals, or ``sd->N`` if there are none. Both are the
  SHADING normal (bump/normal maps included), flipped to face the incoming ray together with ``Ng``
  (kernel/geom/shader_data.h:107-113). ``sd->N`` is the interpolated vertex normal only for
  smooth-shaded faces (``SHADER_SMOOTH_NORMAL``, kernel/geom/triangle_intersect.h:156-157);
  for flat faces it equals the geometric normal. Objects without a material get Cycles' default
  surface, a Diffuse BSDF (scene/shader.cpp ``ShaderManager::add_default``), whose normal is ``sd->N``.
- Occluders: the AO ray is an ordinary shadow ray (``PATH_RAY_SHADOW`` visibility,
  kernel/integrator/intersect_shadow.h:19-28): every triangle of every object visible to shadow rays
  blocks it, front or back face alike (no culling), except the hit triangle itself (``ray.self``)
  and neighbours removed by ``integrate_surface_ray_offset``. Transparent-BSDF surfaces attenuate it
  instead of blocking (transparent shadows); our scenes have none.
- Distance: ``ao_bounces_distance = ao_distance`` (scene/integrator.cpp ``device_update``), and the
  Blender sync sets ``ao_distance`` from the WORLD's ``light_settings.distance`` (``World.aodist``),
  or 10 if the scene has NO world (blender/shader.cpp ``BlenderSync::sync_world``, "Fast GI" block).
  The per-object ``cycles.ao_distance`` only applies to Fast-GI AO bounces
  (kernel/integrator/intersect_closest.h:370-378), not to the pass.
- Misses: background pixels receive no AO contribution, so they are 0 (like ours). The pass is
  normalised by the sample count, so a pixel whose filter samples hit the surface only partly
  (silhouettes) gets coverage x AO; alpha of the combined pass (film transparent) is that coverage.

Settings used (all verified to exist in bpy 5.0.1) and why
-----------------------------------------------------------
- ``render.engine = 'CYCLES'``, ``cycles.device = 'CPU'``, ``render.threads_mode = 'FIXED'``,
  ``render.threads = threads``; ``resolution_x/y = width/height``, ``resolution_percentage = 100``,
  no border, ``render.use_single_layer = True`` (only the active view layer).
- ``cycles.samples = samples``, ``cycles.use_adaptive_sampling = False``,
  ``cycles.use_denoising = False``, ``cycles.seed = seed``: exactly ``samples`` AO rays per pixel.
- ``view_layer.use_pass_ambient_occlusion = True``; ``render.film_transparent = True`` so the
  combined pass' alpha is the hit coverage.
- ``world.light_settings.distance = ao_distance`` (a world "AOWorld" is created if there is none,
  otherwise Cycles would use 10); ``cycles.use_fast_gi = False``.
- Pixel filter: ``cycles.pixel_filter_type = 'BLACKMAN_HARRIS'``, ``cycles.filter_width = 0.01``
  (the RNA minimum). NOT 'BOX': Blender's sync forces the box filter to width 1.0 whatever
  ``filter_width`` says (``filter_width = (filter_type == FILTER_BOX) ? 1.0f : ...`` in
  ``BlenderSync::sync_film``, intern/cycles/blender/sync.cpp; measured: BOX at 0.01 gives the same
  partial coverage as BOX at 1.0). The camera ray of sample s goes through raster
  ``x + table(u_s)`` (kernel/camera/camera.h:441-444), where the table (FILTER_TABLE_SIZE = 1024,
  kernel/types.h:33) is the filter's inverted CDF made symmetric around 0.5 (scene/film.cpp
  ``filter_table`` + util/math_cdf.cpp ``util_cdf_invert``): values in 0.5 +- w for
  Blackman-Harris (width doubled), 0.5 +- 1.5 w for Gaussian; sample 0 uses u = (0.5, 0.5), the
  exact centre (kernel/integrator/init_from_camera.h:27-28). With w = 0.01 the rays are within
  +-0.01 px of the pixel centre (measured with a slanted edge: coverage switches from 1 to 0
  between 0.02 px on either side of the edge). Cycles' default, Blackman-Harris 1.5 px, blurs
  over ~3 px. Quirk: the symmetric inversion fills entries 0..1022 only, entry 1023 stays 0, so
  for u in (1022/1023, 1) a ray lands anywhere between the pixel centre and the pixel's corner
  (raster offset interpolated towards 0): about 0.1 % of samples per axis. Near a silhouette
  this gives e.g. 255/256 coverage; on AO it is negligible.
- ``lean=True`` (default): remove work the AO pass does not need so that the time is not inflated
  by the combined pass: ``cycles.max_bounces = 0`` (no indirect paths), the world Background
  strength set to 0 and ``world.cycles.sampling_method = 'NONE'`` (no world-light shadow rays).
  The AO pass is bit-identical with ``lean=False`` (checked: 256x256, 16 spp, max |diff| = 0;
  the random dimensions do not depend on these settings); on suzanne-251k at 512x512, 64 spp,
  2 threads, idle machine, lean took 6.8 s (13.3 CPU s) against 9.5 s (18.8 CPU s). What remains
  per sample: camera ray, shader evaluation of the default diffuse surface, one AO shadow ray and
  one BSDF continuation ray that is traced and then terminated (kernel max_bounce = 1,
  kernel/integrator/path_state.h:142-145).
- ``render.use_compositing = False``, ``use_sequencer = False``, ``use_motion_blur = False``,
  ``use_persistent_data = False``; the camera's depth of field is switched off.

Validation (suzanne-251k, 128x128, 1024 spp, ao_distance 1, against
``core.render_preview(..., samples=1024)``): identical hit masks (10,500 pixels, 0 differ);
on those pixels mean |diff| 0.0016, RMSE 0.0030, mean diff (ours - Cycles) +0.00002, far below
the i.i.d. noise of two 1024-sample estimates (RMS 0.012: both samplers are low-discrepancy).
The only outliers (2 pixels, |diff| 0.115) sit on Suzanne's silhouette, where an edge passes
within the 0.01 px filter footprint of the pixel centre, so Cycles mixes two surfaces.

Caveats: Cycles' timing includes its scene sync and BVH build (``sync_seconds`` separates them),
and kernel/CPU dispatch differs from ours; Cycles uses Embree 4 (libembree4 in the wheel) for CPU
ray queries. On a shared machine the wall time depends on the other load; ``cpu_seconds`` helps
to tell. With ``threads=1`` Cycles 5.0.1 was seen keeping a second thread busy (CPU ~2x wall).
The pass uses the SHADING normal: the comparison with KD Preview (geometric normal) is
apples-to-apples only for flat-shaded meshes without bump/normal maps (true for the Suzanne scenes:
every face has ``sharp_face`` set, also after the Subdivision modifier). On smooth-shaded faces even a
material whose Diffuse BSDF takes the true normal does not make them match: Cycles also moves the AO
ray's start by the object's *Shadow Terminator > Geometry Offset* (default 0.1), which an outside
review measured as Cycles reading 0.003-0.0125 darker on smooth text, curves and metaballs (text:
RMSE 0.041 against 0.0096 between two Cycles seeds); with the offset at 0 they agreed within noise.
"""

from __future__ import annotations

import argparse
import json
import re
import resource
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

AO_PASS_NAMES = ("Ambient Occlusion", "AO")  # Blender 5.0 writes "Ambient Occlusion"
MIN_FILTER_WIDTH = 0.01  # RNA hard minimum of cycles.filter_width


@dataclass
class CyclesAO:
    """Result of one Cycles render of the AO pass.

    ao:             (H, W) float32 AO pass (channel R; R = G = B), row 0 = top, background 0
    alpha:          (H, W) float32 alpha of the combined pass = fraction of samples that hit
    seconds:        wall time of bpy.ops.render.render() (sync + BVH + sampling)
    sync_seconds:   from the call to Cycles' "Sample 0/N" status (sync, BVH build, device update)
    sample_seconds: seconds - sync_seconds
    cpu_seconds:    CPU time (user + system, all threads) of the child during the render call;
                    about threads x seconds on an idle machine, less when cores are shared
    settings:       what the child set and read back (engine, threads, filter, distance, ...)
    """

    ao: np.ndarray
    alpha: np.ndarray
    seconds: float
    sync_seconds: Optional[float]
    sample_seconds: Optional[float]
    cpu_seconds: Optional[float] = None
    settings: dict = field(default_factory=dict)


def render_cycles_ao(blend_path, width, height, samples, ao_distance=1.0, threads=2):
    """Cycles' AO pass of ``blend_path``: ((H, W) float32 image, row 0 = top; render seconds).

    The seconds are the wall time of ``bpy.ops.render.render()`` in the child process, including
    Cycles' scene sync and BVH build. See the module docstring for the settings.
    """
    r = render_cycles(blend_path, width, height, samples, ao_distance=ao_distance, threads=threads)
    return r.ao, r.seconds


def render_cycles_ao_adaptive(blend_path, width, height, samples, threshold, min_samples=0, ao_distance=1.0,
                              threads=2):
    """Cycles' AO pass with its adaptive sampling (render_cycles' ``adaptive``): ((H, W) float32 image,
    render seconds, mean samples a pixel took or None when Cycles does not report them)."""
    r = render_cycles(blend_path, width, height, samples, ao_distance=ao_distance, threads=threads,
                      adaptive=(threshold, min_samples))
    return r.ao, r.seconds, r.settings.get("mean_samples")


def render_cycles(blend_path, width, height, samples, ao_distance=1.0, threads=2, *, lean=True,
                  filter_width=MIN_FILTER_WIDTH, filter_type="BLACKMAN_HARRIS", seed=0, python=None,
                  timeout=None, adaptive=None) -> CyclesAO:
    """Render the AO pass in a child process and return a ``CyclesAO`` (see module docstring).

    python: interpreter with bpy (default: this one, sys.executable).
    adaptive: None (every pixel takes ``samples``) or (threshold, min_samples): Cycles' own adaptive
    sampling (``cycles.adaptive_threshold``, ``cycles.adaptive_min_samples``, 0 = Cycles' automatic
    choice), ``samples`` the most a pixel takes. Cycles measures a pixel's noise on the Combined pass,
    which a lean render leaves black (every pixel would stop at the minimum), so the world is lit white
    (strength 1, still no light sampling and no bounces): Combined is then the surface's cosine-weighted
    view of the sky, whose noise follows the AO pass's. See ``render_cycles_ao_adaptive``.
    """
    blend_path = Path(blend_path).resolve()
    if not blend_path.is_file():
        raise FileNotFoundError(f"no .blend at {blend_path}")
    for name, v in (("width", width), ("height", height), ("samples", samples), ("threads", threads)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
    if not (np.isfinite(ao_distance) and ao_distance > 0):
        raise ValueError(f"ao_distance must be finite and > 0, got {ao_distance!r}")
    if filter_width < MIN_FILTER_WIDTH:
        raise ValueError(f"filter_width must be >= {MIN_FILTER_WIDTH} (Blender's minimum)")
    with tempfile.TemporaryDirectory(prefix="cycles_ao_") as tmp:
        tmp = Path(tmp)
        spec = {
            "blend": str(blend_path), "width": int(width), "height": int(height),
            "samples": int(samples), "ao_distance": float(ao_distance), "threads": int(threads),
            "lean": bool(lean), "filter_width": float(filter_width), "filter_type": str(filter_type),
            "seed": int(seed), "exr": str(tmp / "render.exr"), "out": str(tmp / "result.npz"),
            "adaptive": None if adaptive is None else [float(adaptive[0]), int(adaptive[1])],
        }
        spec_path = tmp / "spec.json"
        spec_path.write_text(json.dumps(spec))
        cmd = [python or sys.executable, str(Path(__file__).resolve()), "--child", str(spec_path)]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0 or not Path(spec["out"]).is_file():
            tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-30:])
            raise RuntimeError(f"Cycles child process failed (exit {proc.returncode}):\n{tail}")
        with np.load(spec["out"], allow_pickle=False) as z:
            info = json.loads(str(z["info"]))
            return CyclesAO(ao=z["ao"].copy(), alpha=z["alpha"].copy(), seconds=info.pop("seconds"),
                            sync_seconds=info.pop("sync_seconds"),
                            sample_seconds=info.pop("sample_seconds"),
                            cpu_seconds=info.pop("cpu_seconds"), settings=info)


# --------------------------------------------------------------------------
# Child process (imports bpy)
# --------------------------------------------------------------------------


def _child(spec_path: str) -> int:
    import bpy

    spec = json.loads(Path(spec_path).read_text())
    bpy.ops.wm.open_mainfile(filepath=spec["blend"], load_ui=False)
    scene = bpy.context.scene
    view_layer = bpy.context.view_layer
    if scene.camera is None:
        raise RuntimeError(f"{spec['blend']}: the scene has no camera")

    render = scene.render
    render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    render.threads_mode = "FIXED"
    render.threads = spec["threads"]
    render.resolution_x, render.resolution_y = spec["width"], spec["height"]
    render.resolution_percentage = 100
    render.use_border = False
    render.use_single_layer = True
    render.film_transparent = True
    render.use_compositing = False
    render.use_sequencer = False
    render.use_motion_blur = False
    render.use_persistent_data = False
    scene.camera.data.dof.use_dof = False

    cyc.samples = spec["samples"]
    cyc.use_adaptive_sampling = spec["adaptive"] is not None
    if spec["adaptive"] is not None:
        cyc.adaptive_threshold, cyc.adaptive_min_samples = spec["adaptive"]
        view_layer.cycles.pass_debug_sample_count = True  # what the mean samples a pixel are read from
    cyc.use_denoising = False
    cyc.seed = spec["seed"]
    cyc.use_animated_seed = False
    cyc.pixel_filter_type = spec["filter_type"]
    cyc.filter_width = spec["filter_width"]
    cyc.use_fast_gi = False

    if scene.world is None:
        scene.world = bpy.data.worlds.new("AOWorld")
    world = scene.world
    world.light_settings.distance = spec["ao_distance"]
    if spec["lean"]:
        sky = 1.0 if spec["adaptive"] is not None else 0.0  # adaptive sampling reads Combined's noise
        cyc.max_bounces = 0
        world.color = (sky, sky, sky)
        world.cycles.sampling_method = "NONE"
        if world.node_tree is not None:
            for node in world.node_tree.nodes:
                if node.type == "BACKGROUND":
                    node.inputs["Strength"].default_value = sky
                    node.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)

    view_layer.use_pass_ambient_occlusion = True

    # Time stamps of Cycles' status messages: the first "Sample 0/N" ends sync + BVH build.
    first_sample, last_sample = [], [0]

    def on_stats(stats, *_):
        found = re.search(r"\bSample (\d+)/\d+", str(stats))
        if found:
            last_sample[0] = max(last_sample[0], int(found.group(1)))
        if found and not first_sample:
            first_sample.append(time.perf_counter())

    bpy.app.handlers.render_stats.append(on_stats)
    ru0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    bpy.ops.render.render()
    seconds = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu_seconds = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    bpy.app.handlers.render_stats.remove(on_stats)
    sync_seconds = first_sample[0] - t0 if first_sample else None

    settings = render.image_settings
    settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "NONE"
    bpy.data.images["Render Result"].save_render(spec["exr"], scene=scene)
    channels, reader = read_exr(spec["exr"])

    def find(suffixes):
        for s in suffixes:
            for want in (f"{view_layer.name}.{s}", s):
                hits = [c for c in channels if c == want or c.endswith("." + want)]
                if hits:
                    return channels[hits[0]]
        raise RuntimeError(f"none of {suffixes} in the EXR channels {sorted(channels)}")

    ao = find([f"{n}.R" for n in AO_PASS_NAMES])
    alpha = find(["Combined.A"])
    mean_samples = None
    if spec["adaptive"] is not None:
        # the pass holds a pixel's samples over the most any pixel took, which the last status names
        counts = find(["Debug Sample Count.X", "Debug Sample Count.R", "Debug Sample Count.V"])
        mean_samples = float(counts[alpha > 0.5].mean()) * max(last_sample[0], 1)
    if ao.shape != (spec["height"], spec["width"]):
        raise RuntimeError(f"AO pass has shape {ao.shape}, expected {(spec['height'], spec['width'])}")
    info = {
        "seconds": seconds,
        "sync_seconds": sync_seconds,
        "sample_seconds": seconds - sync_seconds if sync_seconds is not None else None,
        "cpu_seconds": cpu_seconds,
        "blender": bpy.app.version_string,
        "exr_reader": reader,
        "engine": render.engine, "device": cyc.device, "threads_mode": render.threads_mode,
        "threads": render.threads, "samples": cyc.samples,
        "use_adaptive_sampling": cyc.use_adaptive_sampling, "use_denoising": cyc.use_denoising,
        "adaptive_threshold": cyc.adaptive_threshold, "adaptive_min_samples": cyc.adaptive_min_samples,
        "mean_samples": mean_samples,
        "pixel_filter_type": cyc.pixel_filter_type, "filter_width": cyc.filter_width,
        "world_ao_distance": world.light_settings.distance, "max_bounces": cyc.max_bounces,
        "world_sampling_method": world.cycles.sampling_method, "lean": spec["lean"],
        "resolution": [render.resolution_x, render.resolution_y, render.resolution_percentage],
    }
    np.savez(spec["out"], ao=np.ascontiguousarray(ao, np.float32),
             alpha=np.ascontiguousarray(alpha, np.float32), info=np.array(json.dumps(info)))
    return 0


def read_exr(path):
    """{channel name: (H, W) float32, row 0 = top} of an EXR, with OpenImageIO if bpy ships it."""
    try:
        oiio = _import_bundled_oiio()
    except ImportError:
        return _read_exr_uncompressed(path), "numpy"
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise RuntimeError(f"OpenImageIO cannot open {path}: {oiio.geterror()}")
    out = {}
    try:
        sub = 0
        while inp.seek_subimage(sub, 0):
            spec = inp.spec()
            pixels = inp.read_image(sub, 0, 0, spec.nchannels, "float")
            pixels = pixels.reshape(spec.height, spec.width, spec.nchannels)
            for i, name in enumerate(spec.channelnames):
                out[name] = np.array(pixels[:, :, i], np.float32)
            sub += 1
    finally:
        inp.close()
    return out, "OpenImageIO"


def _import_bundled_oiio():
    """OpenImageIO's Python bindings live in bpy's own site-packages (bpy/5.0/python/lib/...)."""
    try:
        import OpenImageIO
        return OpenImageIO
    except ImportError:
        pass
    import bpy
    base = Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib"
    for site in sorted(base.glob("python3*/site-packages")):
        if (site / "OpenImageIO").is_dir():
            sys.path.append(str(site))
            import OpenImageIO
            return OpenImageIO
    raise ImportError("OpenImageIO bindings not found in bpy")


def _read_exr_uncompressed(path):
    """Minimal reader for the EXRs written here: scanline, NONE compression, HALF/FLOAT channels,
    single- or multi-part. Returns {channel name: (H, W) float32, row 0 = top}."""
    data = Path(path).read_bytes()
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != 20000630:
        raise ValueError(f"{path} is not an OpenEXR file")
    if version & 0x200 or version & 0x800:
        raise ValueError(f"{path}: tiled/deep EXR not supported")
    multipart = bool(version & 0x1000)
    pos = 8

    def cstr(p):
        end = data.index(b"\0", p)
        return data[p:end].decode(), end + 1

    headers = []
    while True:
        if data[pos] == 0:  # end of the header list (multipart) / empty header
            pos += 1
            break
        attrs = {}
        while data[pos] != 0:
            name, pos = cstr(pos)
            _type, pos = cstr(pos)
            (size,) = struct.unpack_from("<i", data, pos)
            pos += 4
            attrs[name] = data[pos:pos + size]
            pos += size
        pos += 1
        headers.append(attrs)
        if not multipart:
            break
    parts = []
    for attrs in headers:
        if attrs["compression"][0] != 0:
            raise ValueError(f"{path}: compressed EXR not supported")
        xmin, ymin, xmax, ymax = struct.unpack("<iiii", attrs["dataWindow"])
        chans, p, raw = [], 0, attrs["channels"]
        while raw[p] != 0:
            end = raw.index(b"\0", p)
            cname = raw[p:end].decode()
            ptype, _linear, xs, ys = struct.unpack_from("<iB3xii", raw, end + 1)
            if ptype not in (1, 2) or xs != 1 or ys != 1:
                raise ValueError(f"{path}: channel {cname} type {ptype} sampling {xs}x{ys} unsupported")
            chans.append((cname, ptype))
            p = end + 1 + 16
        w, h = xmax - xmin + 1, ymax - ymin + 1
        n_chunks = struct.unpack("<i", attrs["chunkCount"])[0] if "chunkCount" in attrs else h
        parts.append((chans, w, h, ymin, n_chunks))
    offsets = []
    for _, _, _, _, n_chunks in parts:
        offsets.append(np.frombuffer(data, "<u8", n_chunks, pos))
        pos += 8 * n_chunks
    out = {}
    for k, (chans, w, h, ymin, _) in enumerate(parts):
        planes = {c: np.zeros((h, w), np.float32) for c, _ in chans}
        for off in offsets[k]:
            p = int(off) + (4 if multipart else 0)
            y, size = struct.unpack_from("<ii", data, p)
            p += 8
            row = y - ymin
            for cname, ptype in chans:  # one scanline per chunk without compression
                dt = "<f4" if ptype == 2 else "<f2"
                planes[cname][row] = np.frombuffer(data, dt, w, p)
                p += w * (4 if ptype == 2 else 2)
        out.update(planes)
    return out


# --------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        return _child(argv[1])
    parser = argparse.ArgumentParser(description="Render Cycles' AO pass of a .blend (CPU) to .npy.")
    parser.add_argument("blend", help="the .blend to render (its scene camera is used)")
    parser.add_argument("--size", nargs=2, type=int, default=[512, 512], metavar=("W", "H"))
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--ao-distance", type=float, default=1.0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--full", action="store_true",
                        help="keep the combined pass' bounces and world light (lean=False)")
    parser.add_argument("--out", help="write the (H, W) float32 AO image here (.npy, row 0 = top)")
    args = parser.parse_args(argv)
    r = render_cycles(args.blend, args.size[0], args.size[1], args.samples,
                      ao_distance=args.ao_distance, threads=args.threads, lean=not args.full)
    if args.out:
        np.save(args.out, r.ao)
    sync = f"{r.sync_seconds:.3f}" if r.sync_seconds is not None else "?"
    print(f"Cycles AO {args.size[0]}x{args.size[1]} {args.samples} spp, {args.threads} threads: "
          f"render {r.seconds:.3f} s (sync+BVH {sync} s, CPU {r.cpu_seconds:.2f} s), hit pixels {(r.alpha > 0.5).sum()}, "
          f"mean AO on hits {r.ao[r.alpha > 0.5].mean() if (r.alpha > 0.5).any() else float('nan'):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
