"""Per-instance ray visibility: which kinds of rays an instance stops (Blender's Object > Visibility >
Ray Visibility, as Cycles applies it).

An instance's visibility is a bit set, and so is a ray's kind: they meet only when they share a bit.
Camera rays carry CAMERA_RAYS; AO and shadow rays carry SHADOW_RAYS, as Cycles traces AO rays as shadow
rays (benchmarks/cycles_ao.py); plain queries carry ALL_RAYS. HOLDOUT is not a ray kind: a pixel whose
camera ray hits a holdout instance is left empty (alpha 0), while the instance still occludes and
shadows (docs/choices.md#holdout-as-cycles-applies-it).
"""
import numpy as np

CAMERA_RAYS = 1
SHADOW_RAYS = 2
ALL_RAYS = CAMERA_RAYS | SHADOW_RAYS
HOLDOUT = 4
ALL_BITS = ALL_RAYS | HOLDOUT


def as_visibility(visibility, n_instances):
    """(I,) uint8 visibility bits, ALL_RAYS for every instance when `visibility` is None; a ValueError
    names the first instance whose value is not an integer in [0, ALL_BITS]."""
    if visibility is None:
        return np.full(n_instances, ALL_RAYS, np.uint8)
    raw = np.asarray(visibility)
    if raw.shape != (n_instances,):
        raise ValueError(f"visibility must have shape ({n_instances},), one value per instance, got {raw.shape}")
    if raw.dtype.kind == "f" and np.array_equal(raw, np.round(raw)):
        raw = raw.astype(np.int64)  # whole numbers stored as floats, as mesh_of takes them
    if n_instances and raw.dtype.kind not in "iu":
        raise ValueError(f"visibility must hold integers (CAMERA_RAYS | SHADOW_RAYS | HOLDOUT bits), got dtype "
                         f"{raw.dtype}")
    bad = np.flatnonzero((raw < 0) | (raw > ALL_BITS))
    if len(bad):
        raise ValueError(f"instance {int(bad[0])} has visibility {int(raw[bad[0]])}: it must be a combination of "
                         f"CAMERA_RAYS ({CAMERA_RAYS}), SHADOW_RAYS ({SHADOW_RAYS}) and HOLDOUT ({HOLDOUT}), "
                         f"in [0, {ALL_BITS}]")
    return raw.astype(np.uint8)


def stops_rays(visibility):
    """Per instance: whether any kind of ray meets it (an instance that stops none is left out)."""
    return (np.asarray(visibility) & ALL_RAYS) != 0


def as_ray_mask(ray_mask):
    """The kind of a query's rays, checked: an integer in [1, ALL_RAYS]."""
    if isinstance(ray_mask, (bool, np.bool_)) or not isinstance(ray_mask, (int, np.integer)) \
            or not 1 <= ray_mask <= ALL_RAYS:
        raise ValueError(f"ray_mask must be CAMERA_RAYS ({CAMERA_RAYS}), SHADOW_RAYS ({SHADOW_RAYS}) or ALL_RAYS "
                         f"({ALL_RAYS}), got {ray_mask!r}")
    return int(ray_mask)
