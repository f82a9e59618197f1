"""Shared helpers for the scene-extraction tests (tests/test_extract*.py)."""

from __future__ import annotations

import numpy as np

from kd_addon.scene_records import ExtractedScene


def triangles_of(result: ExtractedScene, name: str) -> np.ndarray:
    """World triangles (n,3,3) of every instance whose object is `name`."""
    ids = result.triangle_object_ids()
    keep = [i for i, n in enumerate(result.object_names) if n == name]
    return result.world_triangles()[np.isin(ids, keep)]


def bounds(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts = tris.reshape(-1, 3)
    return pts.min(axis=0), pts.max(axis=0)


def instances_by_host(result: ExtractedScene) -> dict[str | None, list[str]]:
    by_host: dict[str | None, list[str]] = {}
    for inst in result.instances:
        by_host.setdefault(inst.instancer, []).append(inst.name)
    return by_host
