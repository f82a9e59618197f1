"""What one scene keeps between frames: its mesh trees (core.SceneBuilder) and its last image.

Each mesh gets a key stable across frames (mesh name, first object placing it, its instancer,
occurrence), but a tree is reused only when the mesh's fingerprint (scene_records.geometry_fingerprint)
is unchanged, so a key mix-up costs a rebuild, never a wrong image. `image_key` digests everything
that affects the pixels; an unchanged key reuses the last image, and core keeps the last frame's
pixels whose rays cannot reach what changed. State lives per scene (`session_uid`) and per `group` of
trees: the panel, the command line and final renders share the default group; the viewport's Rendered
shading, whose depsgraph evaluates geometry as the viewport does, keeps its own trees so the two never
rebuild each other's. Within a group each `lane` (an extra pass's term) keeps its own last image and
pixels over the group's trees; a final render drops the lanes of views and passes it no longer makes,
and the frame's memory check counts the other lanes' pixels (held_bytes). `clear()` drops it all.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from .scene_records import ExtractedScene, geometry_fingerprint

# Settings that cannot change the image (output format, the reuse switch itself).
NOT_IN_IMAGE = ("output_format", "rebuild_all")


@dataclass
class SceneState:
    """One scene's builder (per build options) and its last finished image."""

    builder: object
    build_options: dict
    image_key: bytes | None = None
    image: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    pixels: object = None  # the last finished frame's core PixelState (pixel reuse)
    depth: np.ndarray | None = None  # the last finished image's view-axis depth per pixel (H, W)


_builders: dict[tuple, tuple[dict, object]] = {}  # (scene uid, group) -> (build options, core.SceneBuilder)
_states: dict[tuple, SceneState] = {}  # (scene uid, group, lane) -> its state


def state_for(scene, core, build_options: dict, group: str = "", lane: str = "", fresh: bool = False) -> SceneState:
    """The state of the scene's `group` and `lane`; fresh trees when the build options changed (trees
    built otherwise differ). `fresh` (Rebuild All): a new builder, so the frame is also laid out as a
    first frame is: a builder's layout follows the motion of the frames it saw (core SceneBuilder), which
    can move a few edge pixels by a sample against a fresh process's render."""
    uid = _uid(scene)
    kept = _builders.get((uid, group))
    if fresh or kept is None or kept[0] != build_options:
        # A lazy tree must be the scene's one mesh tree (core.build_two_level): one flat tree then.
        layout = "flat" if build_options.get("lazy") else "auto"
        kept = _builders[(uid, group)] = (dict(build_options), core.SceneBuilder(layout, **build_options))
    state = _states.get((uid, group, lane))
    if state is None or state.builder is not kept[1]:
        state = _states[(uid, group, lane)] = SceneState(kept[1], dict(build_options))
    return state


def held_bytes(scene, group: str = "", lane: str = "") -> int:
    """Bytes of the last images and pixel states that the scene's other lanes and groups keep: they stay
    in memory while (group, lane) renders (its own last pixels are memory.render_bytes' keeps_previous)."""
    uid = _uid(scene)
    return sum(_state_bytes(state) for (u, g, l), state in _states.items() if u == uid and (g, l) != (group, lane))


def keep_lanes(scene, group: str, lanes, prefix: str) -> None:
    """Forget the scene's lanes of `group` named with `prefix` but not among `lanes`: a view layer's
    final-render views and passes that its frame does not render (their pixels would be held, and
    counted by the memory check, for good)."""
    uid, lanes = _uid(scene), set(lanes)
    for key in [k for k in _states if k[:2] == (uid, group) and k[2].startswith(prefix) and k[2] not in lanes]:
        del _states[key]


def _uid(scene):
    return getattr(scene, "session_uid", None) or id(scene)


def _state_bytes(state: SceneState) -> int:
    pixel_arrays = [a for a in state.pixels if isinstance(a, np.ndarray)] if state.pixels is not None else []
    return sum(a.nbytes for a in [state.image, state.depth, *pixel_arrays] if a is not None)


def clear() -> None:
    """Forget every scene's trees and images (frees their memory)."""
    _builders.clear()
    _states.clear()


def mesh_inputs(core, extracted: ExtractedScene):
    """(MeshInputs, mesh_of (I,), matrices (I, 4, 4), visibility (I,) core ray-visibility and holdout bits)
    for core.SceneBuilder.build, from the instances' arrays (instance_table.py): no Python step a row."""
    table = extracted.table()
    keys = np.fromiter(extracted.geometries, np.int64, len(extracted.geometries))
    owner_rows = _first_rows(table.geometry_keys, keys)
    seen: dict[tuple, int] = {}
    meshes = []
    for (geom_key, geom), row in zip(extracted.geometries.items(), owner_rows):
        kind = table.kinds[table.kind_of[row]] if row >= 0 else None
        base = (geom.name, *((kind.name, kind.instancer) if kind else ("", None)))
        seen[base] = seen.get(base, -1) + 1
        meshes.append(core.MeshInput((*base, seen[base]), geom.vertices, geom.triangles, geometry_fingerprint(geom)))
    order = np.argsort(keys)
    mesh_of = order[np.searchsorted(keys, table.geometry_keys, sorter=order)].astype(np.int64)
    visibility = table.visibility(core.CAMERA_RAYS, core.SHADOW_RAYS, core.HOLDOUT)
    return meshes, mesh_of, table.matrices, visibility


def _first_rows(row_keys: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """(len(keys),) the first row placing each key, -1 where none does."""
    unique, first = np.unique(row_keys, return_index=True)
    at = np.clip(np.searchsorted(unique, keys), 0, max(len(unique) - 1, 0))
    found = (unique[at] == keys) if len(unique) else np.zeros(len(keys), bool)
    return np.where(found, first[at] if len(unique) else -1, -1)


def image_key(meshes, mesh_of, matrices, visibility, camera_keywords: dict, lights: list, size: tuple,
              settings: dict, rows_token: bytes | None = None) -> bytes:
    """Digest of everything the image depends on (see the module docstring). `rows_token`: the
    instances' InstanceTable.token, which stands for the matrices and visibility (hashing a million
    matrices would cost a static frame more than reading them)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(repr([(m.key, m.fingerprint) for m in meshes]).encode())
    h.update(np.ascontiguousarray(mesh_of).tobytes())
    if rows_token is not None:
        h.update(b"rows" + rows_token)
    else:
        h.update(np.ascontiguousarray(matrices, np.float64).tobytes())
        h.update(np.ascontiguousarray(visibility, np.uint8).tobytes())
    _update(h, camera_keywords)
    for light in lights:  # what it is, does and is warned about: a portal toggled must render anew
        h.update(f"{light.name}:{light.kind}:{light.portal}:{light.emits_nothing!r}:{light.no_diffuse!r}:"
                 f"{light.unapplied!r}".encode())
        _update(h, light.keywords)
    h.update(repr(size).encode())
    h.update(repr(sorted((k, v) for k, v in settings.items() if k not in NOT_IN_IMAGE)).encode())
    return h.digest()


def _update(h, keywords: dict) -> None:
    for name in sorted(keywords):
        value = keywords[name]
        h.update(name.encode())
        if isinstance(value, np.ndarray):
            h.update(np.ascontiguousarray(value, np.float64).tobytes())
        elif isinstance(value, (list, tuple)):
            h.update(np.asarray(value, np.float64).tobytes())
        else:
            h.update(repr(value).encode())
