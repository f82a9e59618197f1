"""Extraction's records: their layout, world triangles, mesh reading and the geometry fingerprint."""

from __future__ import annotations

import zlib

import bpy
import numpy as np
import pytest

from kd_addon.extract import extract_scene
from kd_addon.mesh_reading import read_mesh
from kd_addon.scene_records import MeshGeometry, geometry_fingerprint
from tests import bpy_scenes as scenes

pytestmark = pytest.mark.usefixtures("extraction_path")  # each test on the walk and the bulk path


def test_empty_scene(scene):
    result = extract_scene()
    assert result.object_count == 0 and result.triangle_count == 0
    assert result.world_triangles().shape == (0, 3, 3)
    assert result.triangle_object_ids().shape == (0,)


def test_records_layout_and_world_triangles_match_naive(scene):
    source = scenes.new_collection("S", exclude=True)
    scenes.add_cube("A", scale=0.3, collection=source)
    for i in range(20):  # >16 instances exercises the batched scatter path
        inst = scenes.add_collection_instance(f"I{i}", source, location=(i, i % 3, 0))
        inst.rotation_euler = (0.1 * i, 0, 0.2 * i)
        inst.scale = (1 + 0.05 * i,) * 3
    scenes.add_gn_instancer("G", count=3)
    scenes.add_cube("Solo", location=(0, -4, 0))
    result = extract_scene()
    for geom in result.geometries.values():
        assert geom.vertices.dtype == np.float32 and geom.vertices.flags.c_contiguous
        assert geom.triangles.dtype == np.int32 and geom.triangles.shape[1] == 3
    naive = []
    for inst in result.instances:
        geom = result.geometries[inst.geometry_key]
        assert inst.matrix_world.dtype == np.float64 and inst.matrix_world.shape == (4, 4)
        homo = np.c_[geom.vertices.astype(float), np.ones(len(geom.vertices))]
        naive.append((homo @ inst.matrix_world.T)[:, :3][geom.triangles])
    np.testing.assert_allclose(result.world_triangles(), np.concatenate(naive), atol=1e-5)
    ids = result.triangle_object_ids()
    assert ids.dtype == np.int32
    counts = [result.geometries[i.geometry_key].triangle_count for i in result.instances]
    np.testing.assert_array_equal(np.bincount(ids), counts)


def test_read_mesh_matches_loop_triangle_vertices(scene):
    # Quads, a concave quad and a concave n-gon: Blender's own triangulation.
    verts = [(0, 0, 0), (4, 0, 0), (4, 4, 0), (2, 1, 0), (0, 4, 0), (6, 0, 0), (7, 1, 0), (6, 2, 0), (6.3, 1, 0)]
    obj = scenes.add_mesh("Odd", verts, [(0, 1, 2, 3, 4), (5, 6, 7, 8)])
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    got_verts, got_tris = read_mesh(mesh)
    reference = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", reference)
    np.testing.assert_array_equal(got_tris, reference.reshape(-1, 3))
    np.testing.assert_allclose(got_verts, verts)


def test_fingerprint_tracks_geometry_changes(scene):
    scenes.add_shape_key_plane("Keyed")
    prints = {}
    for frame in (1, 1, 10):
        scene.frame_set(frame)
        (geom,) = extract_scene().geometries.values()
        prints.setdefault(frame, set()).add(geometry_fingerprint(geom))
    assert len(prints[1]) == 1 and prints[1] != prints[10]


def _with_crc32_restored(data: bytes, changed: bytes, at: int) -> bytes:
    """`changed` with the four bytes at `at` chosen so that its CRC-32 is `data`'s. CRC-32 is affine
    over GF(2): flipping bit i changes the CRC by a fixed vector e_i whatever the other bytes, and the
    e_i of 32 consecutive bits are independent, so the wanted difference is the XOR of some of them."""
    def effect(i):
        flipped = bytearray(changed)
        flipped[at + i // 8] ^= 1 << (i % 8)
        return zlib.crc32(bytes(flipped)) ^ zlib.crc32(changed)

    basis = []  # (vector, which bits make it), one per leading bit, largest first
    for i in range(32):
        vector, bits = effect(i), 1 << i
        for b_vector, b_bits in basis:
            if vector ^ b_vector < vector:  # vector has b_vector's leading bit
                vector, bits = vector ^ b_vector, bits ^ b_bits
        basis = sorted(basis + [(vector, bits)], reverse=True)
    target, flips = zlib.crc32(changed) ^ zlib.crc32(data), 0
    for b_vector, b_bits in basis:
        if target ^ b_vector < target:
            target, flips = target ^ b_vector, flips ^ b_bits
    assert target == 0
    out = bytearray(changed)
    out[at:at + 4] = (int.from_bytes(out[at:at + 4], "little") ^ flips).to_bytes(4, "little")
    return bytes(out)


def test_a_change_that_keeps_the_crc_changes_the_fingerprint():
    """A mesh edited so that its vertex bytes keep their CRC-32 (which a CRC-32 fingerprint would call
    unchanged, keeping a stale tree and image) gets another fingerprint."""
    vertices = np.arange(30, dtype=np.float32).reshape(10, 3)
    triangles = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    edited = vertices.copy()
    edited[2] = (5.0, -1.0, 7.5)
    forged = np.frombuffer(_with_crc32_restored(vertices.tobytes(), edited.tobytes(), at=36), np.float32)
    forged = forged.reshape(10, 3).copy()
    assert zlib.crc32(forged) == zlib.crc32(vertices) and not np.array_equal(forged, vertices)
    before = geometry_fingerprint(MeshGeometry(0, "M", vertices, triangles))
    assert geometry_fingerprint(MeshGeometry(0, "M", forged, triangles)) != before
    assert geometry_fingerprint(MeshGeometry(0, "M", vertices.copy(), triangles.copy())) == before
