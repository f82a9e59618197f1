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


def bulk_checked_against_walk(read_in_bulk, counts: dict):
    """read_in_bulk wrapped so that every bulk reading is compared with the per-entry walk of the same
    depsgraph: the same rows in the same order (object, instancer, flags, world matrix to the bit, the
    mesh's vertices and triangles) and the same notes (instanced objects, meshed objects, warnings).
    `counts` tallies the readings the bulk path took ("bulk") and gave up ("walk")."""
    from kd_addon.scene_walk import EntryReader

    def checked(depsgraph, reader):
        table = read_in_bulk(depsgraph, reader)
        counts["bulk" if table is not None else "walk"] = counts.get("bulk" if table is not None else "walk", 0) + 1
        if table is None:
            return None
        walker = EntryReader(reader.vis)
        records = walker.without_hidden_carriers([r for r in map(walker.read, depsgraph.object_instances)
                                                  if r is not None])
        _assert_same_rows(table.records(), reader.geometries.geometries, records, walker.geometries.geometries)
        for note in ("instanced_by", "meshed", "not_triangles", "non_finite_placements"):
            assert getattr(reader, note) == getattr(walker, note), note
        return table
    return checked


def _assert_same_rows(bulk, bulk_meshes, walked, walked_meshes) -> None:
    assert len(bulk) == len(walked), (len(bulk), len(walked))
    for i, (b, w) in enumerate(zip(bulk, walked)):
        assert (b.name, b.instancer, b.is_instance, b.camera, b.shadow, b.holdout) == \
               (w.name, w.instancer, w.is_instance, w.camera, w.shadow, w.holdout), i
        assert np.array_equal(b.matrix_world, w.matrix_world), (i, b.matrix_world, w.matrix_world)
        mesh_b, mesh_w = bulk_meshes[b.geometry_key], walked_meshes[w.geometry_key]
        assert mesh_b.name == mesh_w.name, i
        assert np.array_equal(mesh_b.vertices, mesh_w.vertices) and np.array_equal(mesh_b.triangles, mesh_w.triangles), i
