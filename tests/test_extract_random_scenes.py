"""Random instancing scenes against a render's own depsgraph (tests/render_depsgraph.py).

Each seed builds a scene from the pieces a render's instancing rules combine: nested collections
(excluded from the view layer or not, disabled in renders or not), objects disabled in renders,
collection instancers, geometry-nodes carriers (Collection Info, Object Info as instance or realized),
parents instancing their children on vertices, particles rendering an object or a collection, and
ray visibility flags. Everything stays visible in the viewport with the viewport's settings equal to
the render's (where they differ the preview follows the viewport by design and names it), so the
preview must make exactly the render's instances, object by object.
"""
from __future__ import annotations

import bpy
import numpy as np
import pytest

from kd_addon.extract import extract_scene
from tests import bpy_scenes as scenes
from tests.render_depsgraph import differences, render_entries

pytestmark = pytest.mark.usefixtures("extraction_path")  # each test on the walk and the bulk path


class _RandomScene:
    def __init__(self, seed):
        self.rng = np.random.default_rng(seed)
        self.collections = []  # collection k may only instance collections built before it: no cycles
        self.count = 0

    def chance(self, p):
        return bool(self.rng.random() < p)

    def name(self, kind):
        self.count += 1
        return f"{kind}{self.count}"

    def place(self):
        return tuple(self.rng.uniform(-6, 6, 3).round(2))

    def build(self):
        for _ in range(int(self.rng.integers(2, 5))):
            self.collections.append(self.collection())
        home = bpy.context.scene.collection
        for _ in range(int(self.rng.integers(2, 6))):
            self.thing(home, len(self.collections))

    def collection(self):
        coll = scenes.new_collection(self.name("C"), exclude=self.chance(0.6))
        coll.hide_render = self.chance(0.15)
        if self.collections and self.chance(0.3):  # a child collection, disabled in renders or not
            child = bpy.data.collections.new(self.name("Child"))
            coll.children.link(child)
            child.hide_render = self.chance(0.4)
            scenes.add_cube(self.name("Cube"), scale=0.2, location=self.place(), collection=child)
        built = len(self.collections)
        for _ in range(int(self.rng.integers(1, 4))):
            self.thing(coll, built)
        return coll

    def thing(self, coll, built):
        """One object in `coll`: a cube, or an instancer of what was built before (collections
        self.collections[:built], or an object it makes itself)."""
        kinds = ["cube", "cube"] + (["collection", "nodes collection", "particles collection", "points"] if built else [])
        kinds += ["object info", "vertices", "particles object"]
        kind = kinds[int(self.rng.integers(len(kinds)))]
        source = self.collections[int(self.rng.integers(built))] if built else None
        if kind == "cube":
            ob = scenes.add_cube(self.name("Cube"), scale=0.3, location=self.place(), collection=coll)
        elif kind == "collection":
            ob = scenes.add_collection_instance(self.name("Inst"), source, location=self.place(), collection=coll)
        elif kind == "nodes collection":
            ob = self._move(scenes.add_info_node_host(self.name("Carrier"), source, location=self.place(),
                                                      realize=self.chance(0.3)), coll)
        elif kind == "points":  # Instance on Points of a Collection Info, its children separated or not
            ob = self._move(scenes.add_collection_points_host(self.name("Points"), source, count=2,
                                                              separate_children=self.chance(0.5),
                                                              location=self.place()), coll)
        elif kind == "object info":
            target = self._loose_target()
            ob = self._move(scenes.add_info_node_host(self.name("Info"), target, location=self.place()), coll)
            info = next(n for n in ob.modifiers["GN"].node_group.nodes if n.bl_idname == "GeometryNodeObjectInfo")
            info.inputs["As Instance"].default_value = self.chance(0.6)
        elif kind == "vertices":  # or faces
            ob = scenes.add_mesh(self.name("Parent"), [(0, 0, 0), (1.5, 0, 0), (1.5, 1.5, 0)], [(0, 1, 2)],
                                 location=self.place(), collection=coll)
            ob.instance_type = "VERTS" if self.chance(0.7) else "FACES"
            child = scenes.add_cube(self.name("Kid"), scale=0.2, collection=coll)
            child.parent = ob
            child.hide_render = self.chance(0.2)
        else:
            obj = self._loose_target() if kind == "particles object" else None
            ob = self._move(scenes.add_particle_emitter(self.name("Emitter"), count=3, obj=obj, location=self.place(),
                                                        collection=source if obj is None else None, size=2.0), coll)
            ob.show_instancer_for_render = ob.show_instancer_for_viewport = self.chance(0.5)
        ob.hide_render = self.chance(0.15)
        ob.visible_camera, ob.visible_shadow = self.chance(0.85), self.chance(0.85)
        if kind != "cube" and self.chance(0.2):  # hides its own mesh (viewport and renders alike)
            ob.show_instancer_for_render = ob.show_instancer_for_viewport = False
        return ob

    def _loose_target(self):
        """An object off in the distance for an Object Info node or particles to show: a cube, or a
        collection instancer of one of the collections (which Object Info expands)."""
        if self.collections and self.chance(0.4):
            target = scenes.add_collection_instance(self.name("Target"), self.collections[-1], location=(0, 0, -40))
        elif self.collections and self.chance(0.3):
            target = scenes.add_info_node_host(self.name("Target"), self.collections[-1], location=(0, 0, -40))
        else:
            target = scenes.add_cube(self.name("Target"), scale=0.25, location=(0, 0, -40))
        target.hide_render = self.chance(0.3)
        return target

    @staticmethod
    def _move(ob, coll):
        if coll != bpy.context.scene.collection:
            bpy.context.scene.collection.objects.unlink(ob)
            coll.objects.link(ob)
        return ob


# Known gaps: an instancer with Show Instancer off in the viewport yields no entry of its own, so under
# geometry-nodes instances (whose levels number instances, not collection members) nothing tells its
# instances from a sibling's: seed 134 (a render-hidden carrier's), seed 256 (a collection's
# render-hidden member reached through a carrier beside one that names it directly). See
# docs/extraction.md#known-gaps. Strict: a fix makes these fail until they are taken off the list.
KNOWN_GAPS = {134, 256}


QUICK_SEEDS = 20  # the seeds the quick check (-m "not slow") runs; the full run runs all 300


def _seed(seed: int):
    marks = [pytest.mark.xfail(strict=True, reason="known gap")] if seed in KNOWN_GAPS else []
    return pytest.param(seed, marks=marks + ([pytest.mark.slow] if seed >= QUICK_SEEDS else []))


@pytest.mark.parametrize("seed", [_seed(s) for s in range(300)])
def test_random_instancing_scene_matches_a_render_depsgraph(scene, seed):
    """Object by object: the same triangle counts and areas, and the same bounds unless an instancer
    hides itself (Show Instancer off): then bpy's render-mode object_instances gave some of its
    instances the matrix of the entry before them (seeds 63 and 367: a cube reported at another
    object's place, where a Cycles render of seed 63 drew it at the preview's)."""
    _RandomScene(seed).build()
    placement = all(ob.show_instancer_for_render for ob in bpy.data.objects)
    assert differences(extract_scene(), render_entries(), placement) == []
