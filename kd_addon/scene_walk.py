"""The walk over ``depsgraph.object_instances`` that turns entries into :class:`Instance` records.

A curve, text, surface or metaball object appears twice in ``object_instances``: with its own type
and as a ``MESH`` instance of itself carrying the evaluated mesh. Cycles renders only the second, and
so does the walk: only entries whose evaluated data is a Mesh are read, so ``to_mesh()`` is never
needed and nothing is counted twice.
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from .dupli_paths import DupliPaths
from .mesh_reading import GeometryReader
from .render_visibility import RenderVisibility, entry_visible, ray_flags, rendered_layers_objects
from .scene_records import NOT_TRIANGLE_DATA, NOT_TRIANGLES, Instance, object_label


class EntryReader:
    """Turns object_instances entries into Instance records.

    Per-entry cost dominates scenes with many instances (every RNA attribute access costs about a
    microsecond), so the visibility verdict and the names are memoized per (instancer, original
    object) pair and each entry touches only the few attributes that can differ between instances.
    """

    def __init__(self, vis: RenderVisibility, render_mode: bool = False):
        self.vis = vis
        # A render's own depsgraph (a render engine's) has applied the render's visibility, instancing
        # paths and Show Instancer already: its entries are taken as they are (show_self), and only the
        # ray flags, Holdout and Indirect Only, which a depsgraph does not apply, are read.
        self.render_mode = render_mode
        self.geometries = GeometryReader()
        self._verdicts: dict[tuple[int, int], tuple[str, str | None, bool, bool, bool] | None] = {}
        self.instanced_by: dict[int, set[int]] = {}  # instancer (original) -> the originals it instanced
        self.not_triangles: dict[tuple[str, str | None], str] = {}
        self.non_finite_placements: dict[tuple[str, str | None], int | None] = {}  # scene_records.non_finite_warnings
        self._own_entries_hidden_if_instancing: list[tuple[int, Instance]] = []
        self.meshed: set[str] = set()  # names of the originals whose own geometry gave triangles
        # The path walk's rule depends on what an instancer instances only, not on whether the
        # instancer itself is shown (a hidden one's entries are all left out anyway, by the verdict).
        self.paths = DupliPaths(vis.in_instanced_collection, vis.descendants)

    def read(self, inst) -> Instance | None:
        """Record for one entry, or None to skip it. Copies everything out at
        once: ``inst.object`` is a temporary the iterator reuses. Every entry
        goes through `paths`, in the depsgraph's order (dupli_paths.py)."""
        ob = inst.object
        parent = inst.parent if inst.is_instance else None
        if self.render_mode:
            if not inst.show_self:
                return None
        elif not self.paths.made_by_render(inst, ob, parent):
            return None
        mesh = ob.data
        if not isinstance(mesh, bpy.types.Mesh):
            if parent is not None:  # an instanced empty or light makes its carrier an instancer too
                self._note_instanced(parent, ob)
            self._note_not_triangles(ob, parent)
            return None
        verdict = self._verdict(ob, parent)
        if verdict is None:
            return None
        name, instancer, camera, shadow, holdout = verdict
        matrix = np.array(inst.matrix_world, dtype=np.float64)
        if not np.isfinite(matrix).all():  # a NaN location or scale (a driver, a script): not placeable
            self.note_non_finite((name, instancer), None if parent is None else 1)
            return None
        key = self.geometries.get(ob, name)
        if key is None:
            return None
        record = Instance(
            geometry_key=key,
            matrix_world=matrix,
            name=name,
            instancer=instancer,
            is_instance=parent is not None,
            camera=camera,
            shadow=shadow,
            holdout=holdout,
        )
        if parent is None and not ob.original.show_instancer_for_render:
            self._own_entries_hidden_if_instancing.append((ob.original.as_pointer(), record))
        if instancer in (None, name):  # by name: a pointer costs two RNA reads an entry
            self.meshed.add(name)
        return record

    def without_hidden_carriers(self, records: list[Instance]) -> list[Instance]:
        """`records` without the own entries of objects whose Show Instancer for renders is off and
        that instanced something in this walk: geometry-nodes carriers, which is_instancer does not
        name (_instancer_hides_self), and, whatever the order of the walk, after their instances."""
        hidden = {id(r) for pointer, r in self._own_entries_hidden_if_instancing if pointer in self.instanced_by}
        return [r for r in records if id(r) not in hidden] if hidden else records

    def note_non_finite(self, key: tuple[str, str | None], instances: int | None) -> None:
        """Count placements of `key` (object name, instancer name) left out for a non-finite transform:
        `instances` of them, or None for the object's own entry."""
        known = self.non_finite_placements.get(key, 0)
        self.non_finite_placements[key] = None if instances is None else known + instances

    def verdict(self, ob, parent) -> tuple[str, str | None, bool, bool, bool] | None:
        """(object name, instancer name, camera, shadow, holdout) of the entries of the evaluated `ob`
        under the top-level instancer `parent` (None: its own entry), None when a render hides them:
        what `read` applies, for readers of many entries at once (bulk_instances.py)."""
        return self._verdict(ob, parent)

    def _note_not_triangles(self, ob, parent) -> None:
        """Warn once per object and instancer about render-visible geometry that is not triangles
        which an object makes (a geometry-nodes point cloud, curves, volume) or an instance brings;
        scene objects of those types are named by left_out_warnings."""
        kind = NOT_TRIANGLE_DATA.get(type(ob.data).__name__)
        if kind is None or (parent is None and ob.original.type in NOT_TRIANGLES):
            return
        verdict = self._verdict(ob, parent)
        if verdict is None:
            return
        name, instancer = verdict[0], verdict[1]
        message = f"{object_label(name, instancer)} makes {kind}, not triangles: left out of the preview"
        self.not_triangles.setdefault((name, instancer), message)

    def _verdict(self, ob, parent) -> tuple[str, str | None, bool, bool, bool] | None:
        """(object name, instancer name, camera, shadow, holdout) when visible, else None; memoized."""
        orig = ob.original
        memo_key = (orig.as_pointer(), parent.as_pointer() if parent else 0)
        if memo_key not in self._verdicts:
            flagged, view_layer = self._flag_holders(ob, parent)
            camera, shadow = ray_flags(*flagged)
            owner = flagged[-1]  # Cycles reads Holdout and Indirect Only from the instancer
            holdout = owner.holdout_get(view_layer=view_layer)
            if not holdout and owner.indirect_only_get(view_layer=view_layer):
                camera = False  # Indirect Only hides from camera rays; a holdout stays a holdout
            visible = (camera or shadow) and (self.render_mode or entry_visible(self.vis, parent, ob))
            instancer = parent.original.name if parent is not None else None
            if parent is not None:  # once per (object, instancer): no extra cost per entry
                self._note_instanced(parent, ob)
            self._verdicts[memo_key] = (orig.name, instancer, camera, shadow, holdout) if visible else None
        return self._verdicts[memo_key]

    def _flag_holders(self, ob, parent) -> tuple[tuple, bpy.types.ViewLayer]:
        """(the object and its instancer if any, the view layer) to read the ray flags, Holdout and
        Indirect Only from. A render's own depsgraph (an engine's, F12 or an animation) animates its
        evaluated copies only, so keyed flags are read there, with its evaluated view layer; the
        viewport's depsgraph is the active one, whose animation is written back to the originals,
        which also hold edits the depsgraph has not evaluated yet."""
        if self.render_mode:
            return ((ob,) if parent is None else (ob, parent)), self.vis.view_layer_eval
        return ((ob.original,) if parent is None else (ob.original, parent.original)), self.vis.view_layer

    def _note_instanced(self, parent, ob) -> None:
        """Record that `parent` instanced `ob` (whatever its type: Blender counts a geometry-nodes
        carrier whose output holds instances of empties or lights as an instancer, which Show Instancer
        > Render off then hides, BKE_object_visibility)."""
        self.instanced_by.setdefault(parent.original.as_pointer(), set()).add(ob.original.as_pointer())


@dataclass(frozen=True)
class SelfEntry:
    """An object's own entry, made up where the viewport depsgraph yields none (the attributes
    EntryReader.read takes from a DepsgraphObjectInstance)."""

    object: bpy.types.Object  # the evaluated object
    is_instance: bool = False
    parent: None = None

    @property
    def matrix_world(self):
        return self.object.matrix_world


def hidden_by_viewport_flag_only(depsgraph, evaluated: set[int], instanced_by: dict[int, set[int]]) -> list:
    """Objects of the rendered layers the viewport depsgraph yields no entry of (`evaluated`: the
    originals it does) only because their Show Instancer for the viewport is off: the flag is off and
    the viewport shows the object (it instanced something this frame, which a hidden object does not,
    or it is visible in the view layer). A final render shows those with Show Instancer for renders on."""
    return [ob for ob in rendered_layers_objects(depsgraph)
            if not ob.show_instancer_for_viewport and ob.as_pointer() not in evaluated
            and (ob.as_pointer() in instanced_by or ob.visible_get(view_layer=depsgraph.view_layer))]
