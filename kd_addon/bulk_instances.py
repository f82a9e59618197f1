"""Geometry-nodes instances read in bulk: transforms and reference indices as arrays, meshes once each.

Walking ``depsgraph.object_instances`` costs microseconds an entry in Python, most of a frame of a
scene with a million scattered instances. Blender 4.3+ gives an evaluated object's ``GeometrySet``
(``Object.evaluated_geometry()``), whose ``instances_pointcloud()`` holds the attributes
``instance_transform`` (4x4 float32, column-major) and ``.reference_index``, and whose
``instance_references()`` lists what is instanced: these are read with ``foreach_get``, nested
GeometrySets level by level (docs/choices.md#bulk-instance-extraction).

The result is what the per-entry walk (scene_walk.py) gives, row for row: the same world matrices, to
the bit (Blender composes them in float32 with mul_m4_m4m4's pairwise sums, which instance_rows.compose
repeats),
the same order (an instance's mesh, then its own instances, depth first), the same records and
visibility (the walk's EntryReader decides, once per carrier and object). Whatever the bulk reading
cannot express as the walk does (collection references, particles, vertex or face instancing, curves
and other non-mesh geometry, instances a render-hidden path may block, Show Instancer off in the
viewport) makes `read_in_bulk` return None, and the caller walks instead: nothing is half-read.
"""

from __future__ import annotations

import bpy
import numpy as np

from .dupli_paths import instances_things
from .node_instances import has_node_modifier
from .instance_rows import Gathered, InstanceSet, Reference, compose_rows
from .instance_table import InstanceTable, as_table, concatenated
from .render_visibility import instanced_by_its_parent
from .scene_walk import EntryReader, SelfEntry

AVAILABLE = hasattr(bpy.types.Object, "evaluated_geometry")  # Blender 4.3 and later
ENABLED = True  # tests switch it off to run the walk on the same scenes (both paths must agree)
_memos: dict = {}  # (session_uid, name) of a carrier -> its rows last frame (instance_rows.CarrierRows)

# Object types whose own entry the walk reads or skips without instancing anything.
_PLAIN_TYPES = frozenset(("MESH", "EMPTY", "LIGHT", "CAMERA", "LIGHT_PROBE", "LIGHTPROBE", "SPEAKER", "ARMATURE",
                          "LATTICE"))


class NotInBulk(Exception):
    """The scene holds something only the per-entry walk reads as a render would."""


def forget() -> None:
    """Drop the rows kept from the last reading (hundreds of MB for a million instances)."""
    _memos.clear()


def usable(depsgraph: bpy.types.Depsgraph) -> bool:
    """Whether the bulk path may read this scene: bpy offers it, it is on, and every object of the file
    is of a kind whose own entry and instances it reads as the walk does."""
    if not (AVAILABLE and ENABLED) or depsgraph.scene.background_set is not None:
        return False
    if depsgraph.mode == "RENDER":  # a render's own depsgraph: its entries' show_self decide, read by the walk
        return False
    return all(_plain(ob) for ob in bpy.data.objects)


def _plain(ob: bpy.types.Object) -> bool:
    return (ob.type in _PLAIN_TYPES and ob.instance_type == "NONE" and not len(ob.particle_systems)
            and ob.show_instancer_for_viewport and not instanced_by_its_parent(ob))


def light_entries(depsgraph: bpy.types.Depsgraph):
    """The entries scene_input.read_lights looks for lights in: the objects' own (SelfEntry) where the
    bulk path reads the scene and no instance is anything but a mesh (so none is a light), else every
    object_instances entry, which costs microseconds an instance."""
    if usable(depsgraph) and not any(_instances_other_than_meshes(ob) for ob in depsgraph.objects
                                     if ob.type == "MESH" and has_node_modifier(ob.original)):
        return [SelfEntry(ob) for ob in depsgraph.objects]
    return depsgraph.object_instances


def _instances_other_than_meshes(carrier) -> bool:
    """Whether any instance reference under the carrier, nested ones too, is an object other than a
    mesh (a light, say) or a collection."""
    todo = [carrier.evaluated_geometry()]
    while todo:
        for reference in todo.pop().instance_references():
            if isinstance(reference, bpy.types.GeometrySet):
                todo.append(reference)
            elif reference is not None and not (isinstance(reference, bpy.types.Object) and reference.type == "MESH"):
                return True
    return False


def read_in_bulk(depsgraph: bpy.types.Depsgraph, reader: EntryReader) -> InstanceTable | None:
    """Every placement of the depsgraph in the walk's order, or None when the walk must read it."""
    segments: list = []
    own: list = []
    alive: list = []  # every GeometrySet read, until the end: a freed one's mesh address may come back as
    # another's, and the mesh reader keys meshes by address
    memos: dict = {}
    try:
        for ob in depsgraph.objects:
            own.append(reader.read(SelfEntry(ob)))
            if ob.type == "MESH" and has_node_modifier(ob.original):  # is_instancer is off for them here
                segments.append([r for r in own if r is not None])
                own = []
                segments.append(_carrier_rows(ob, reader, alive, memos))
    except NotInBulk:
        return None
    _memos.clear()  # only the carriers of this reading are kept
    _memos.update(memos)
    segments.append([r for r in own if r is not None])
    return concatenated([as_table(reader.without_hidden_carriers(s)) if isinstance(s, list) else s
                         for s in segments])


def _carrier_rows(carrier, reader: EntryReader, alive: list, memos: dict) -> InstanceTable:
    """The placements a geometry-nodes carrier's instances give, as the walk would record them; last
    frame's rows when everything they are made of is unchanged (module docstring)."""
    if reader.paths.walks(carrier.original):
        raise NotInBulk  # a render-hidden path may block some: dupli_paths.py decides entry by entry
    geometry = carrier.evaluated_geometry()
    alive.append(geometry)
    world = np.array(carrier.matrix_world, np.float32).T  # Blender's column-major layout
    gathered = _gather(geometry, carrier, reader, alive)
    memo_key = (carrier.original.session_uid, carrier.original.name)
    memo = _memos.get(memo_key)
    if memo is None or not memo.matches(world, gathered):
        memo = compose_rows(world, gathered)
    memos[memo_key] = memo
    for key, instances in memo.non_finite.items():
        reader.note_non_finite(key, instances)
    reader.meshed.update(memo.meshed)
    return memo.table(gathered.keys)


def _gather(geometry, carrier, reader: EntryReader, alive: list) -> Gathered:
    """Every GeometrySet holding instances under the carrier's, read once each (transforms, reference
    indices), and what each reference places: a mesh slot and kind, a nested GeometrySet."""
    gathered = Gathered()
    queue = [geometry]
    while len(gathered.sets) < len(queue):
        current = queue[len(gathered.sets)]
        _check_components(current)
        cloud = current.instances_pointcloud()
        if cloud is None or len(cloud.points) == 0:
            gathered.sets.append(InstanceSet(np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int32), ()))
            continue
        references = current.instance_references()
        transforms, reference_of = _instance_arrays(cloud, len(references))
        alive.append(references)
        used = np.bincount(reference_of, minlength=len(references)) > 0  # the walk meets only these
        refs = tuple(_resolve(reference, carrier, reader, gathered, queue) if used[index] else Reference(-1, -1, -1)
                     for index, reference in enumerate(references))
        gathered.sets.append(InstanceSet(transforms, reference_of, refs))
    return gathered


def _resolve(reference, carrier, reader: EntryReader, gathered: Gathered, queue: list) -> Reference:
    """What one instance reference places (its mesh's slot and kind, the nested GeometrySet's index)."""
    if reference is None:
        return Reference(-1, -1, -1)
    if isinstance(reference, bpy.types.Object):
        if reference.type not in ("MESH", "EMPTY", "LIGHT", "CAMERA") or instances_things(reference.original):
            raise NotInBulk  # curves, text, nested instancers: the walk reads their entries
        verdict = reader.verdict(reference, carrier)  # an instanced empty makes its carrier an instancer too
        key = reader.geometries.get(reference, verdict[0]) if verdict and reference.type == "MESH" else None
        return Reference(*gathered.place(reader, key, verdict), -1)
    if not isinstance(reference, bpy.types.GeometrySet):
        raise NotInBulk  # a collection: its members follow the collection rules of a render
    _check_components(reference)
    slot = kind = nested = -1
    if reference.mesh is not None:  # entries of the carrier itself, named and seen as it
        verdict = reader.verdict(carrier, carrier)
        key = reader.geometries.get_mesh(carrier, reference.mesh, verdict[0]) if verdict else None
        slot, kind = gathered.place(reader, key, verdict)
    cloud = reference.instances_pointcloud()
    if cloud is not None and len(cloud.points):
        nested = len(queue)
        queue.append(reference)
    return Reference(slot, kind, nested)


def _check_components(geometry) -> None:
    """Point clouds, curves, volumes and grease pencil among the instances: the walk names them."""
    if any(getattr(geometry, part, None) is not None for part in ("pointcloud", "curves", "volume", "grease_pencil")):
        raise NotInBulk


def _instance_arrays(cloud, reference_count: int) -> tuple[np.ndarray, np.ndarray]:
    """(transforms (K, 4, 4) float32 as Blender stores them (column-major), reference indices (K,)).
    Attributes under other names (a later Blender) send the scene to the walk."""
    count = len(cloud.points)
    transforms = np.empty(count * 16, np.float32)
    matrix = cloud.attributes.get("instance_transform")
    index = cloud.attributes.get(".reference_index")
    if matrix is None or (index is None and reference_count > 1):
        raise NotInBulk
    matrix.data.foreach_get("value", transforms)
    references = np.zeros(count, np.int32)
    if index is not None:
        index.data.foreach_get("value", references)
    if len(references) and not 0 <= references.min() <= references.max() < max(reference_count, 1):
        raise NotInBulk
    return transforms.reshape(count, 4, 4), references
