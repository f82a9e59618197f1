"""Which objects and instances a final render shows, decided from the viewport's depsgraph.

The viewport depsgraph also holds render-hidden objects, so the render's rules are applied here:

* A scene object is kept when its original has ``hide_render`` False and the view layer's collection
  tree reaches it through collections neither excluded nor ``hide_render``.
* An instance is kept when its top-level instancer passes that rule and makes the object in a
  render: collection members follow their own and nested collections' ``hide_render``; geometry-nodes
  and particle instances ignore the source's, except for collections they render whole
  (node_instances.py). Paths through instancers a render does not make are dropped (dupli_paths.py).
* Show Instancer for renders off hides an instancer's own geometry (Blender's BKE_object_visibility).
* Ray visibility: an object with camera and shadow rays both off is left out; otherwise each instance
  carries both flags, ANDed with its instancer's. Holdout and Indirect Only are read from the object,
  or for an instance from its top-level instancer only, as Cycles does
  (docs/choices.md#holdout-and-indirect-only-come-from-the-top-level-instancer).

Objects the viewport does not show (eye icon, Disable in Viewports) are not in its depsgraph at all;
extraction_warnings.py names them.
"""

from __future__ import annotations

import bpy

from .dupli_paths import instanced_collection, instancer_kind, instances_things, unhidden_objects
from .node_instances import has_node_modifier, instancing_references, objects_read_as_geometry


class RenderVisibility:
    """Render-visibility decisions, memoized per original object pointer."""

    def __init__(self, depsgraph: bpy.types.Depsgraph):
        self.view_layer = depsgraph.view_layer
        self.view_layer_eval = depsgraph.view_layer_eval  # its bases hold the evaluated objects
        self.scene_objects = _layer_render_objects(self.view_layer.layer_collection)
        for background in set_scenes(depsgraph.scene):
            self.scene_objects |= _layer_render_objects(render_view_layer(background).layer_collection)
        self._collection_memo: dict[int, tuple[frozenset, frozenset]] = {}
        self._expansion_memo: dict[tuple, tuple[frozenset, frozenset]] = {}
        self._render_enabled: set[int] | None = None  # in_render's collections, found when first asked
        self._cuts = 0  # cycles cut short so far (_remember)
        self._kinds: dict[int, tuple] = {}  # object pointer -> dupli_paths.instancer_kind
        self._children: dict[int, list] | None = None  # parent pointer -> its children (descendants)
        self._holders: dict[int, list[int]] = {}  # object pointer -> its collections' pointers (in_render)

    def scene_object(self, orig: bpy.types.Object) -> bool:
        """A non-instanced object: own flag plus collection path."""
        return (not orig.hide_render) and orig.as_pointer() in self.scene_objects

    def in_render(self, ob: bpy.types.Object) -> bool:
        """Whether a render's depsgraph holds `ob` for a vertex or face parent to instance: not
        render-hidden, and in a collection none of whose ancestors on some path is render-disabled."""
        if self._render_enabled is None:
            self._render_enabled = _render_enabled_collections()
            self._holders = _holding_collections()
        if ob.hide_render:
            return False
        return any(c in self._render_enabled for c in self._holders.get(ob.as_pointer(), ()))

    def descendants(self, ob: bpy.types.Object) -> list:
        """ob.children_recursive from one parent map built per extraction: the property scans every
        object of the file on each read."""
        if self._children is None:
            self._children = {}
            for other in bpy.data.objects:
                if other.parent is not None:
                    self._children.setdefault(other.parent.as_pointer(), []).append(other)
        out, todo = [], [ob]
        while todo:
            kids = self._children.get(todo.pop().as_pointer(), [])
            out += kids
            todo += kids
        return out

    def in_instanced_collection(self, instancer: bpy.types.Object, orig) -> bool:
        """Whether `instancer` (of any kind) would make `orig` in a render, through whatever it
        instances, nested, unless a render skips it on the way. An object it cannot be seen to reach
        (a collection computed by nodes) is kept."""
        reach, shown = self._expansion(instancer, frozenset())
        ptr = orig.as_pointer()
        return ptr not in reach or ptr in shown

    def instanced_objects(self, collection: bpy.types.Collection) -> frozenset[int]:
        """Pointers of the objects a render of an instance of `collection` shows, nested instancers'
        included."""
        return self._collection_expansion(collection, frozenset())[1]

    def _expansion(self, ob: bpy.types.Object, stack: frozenset) -> tuple[frozenset, frozenset]:
        """(reach, shown): pointers of every object `ob` can instance, nested instancing included
        (a geometry-nodes carrier inside an instanced collection, Object Info of a collection
        instancer, a parent instancing a carrier on its vertices), and of those a render makes.
        Memoized per object (per collection for plain collection instancers, of which a scene may
        hold thousands)."""
        pointer = ob.as_pointer()  # the memo first: one RNA read an entry
        key = self._kinds.get(pointer)
        if key is None:
            key = self._kinds[pointer] = instancer_kind(ob)
        if key in self._expansion_memo:
            return self._expansion_memo[key]
        collection = instanced_collection(ob)
        if key in stack:
            self._cuts += 1
            return frozenset(), frozenset()
        stack, cuts = stack | {key}, self._cuts
        reach, shown = set(), set()
        if collection is not None:
            self._add(self._collection_expansion(collection, stack), reach, shown)
        if ob.instance_type in INSTANCING_PARENT_TYPES:
            for child in self.descendants(ob):  # those a render's depsgraph holds (make_child_duplis)
                self._add_object(child, self.in_render(child), stack, reach, shown)
        nodes = has_node_modifier(ob)
        if len(ob.particle_systems) or nodes:
            collections, objects = instancing_references(ob)
            for coll in collections:
                self._add(self._collection_expansion(coll, stack), reach, shown)
            geometry = {o.as_pointer() for o in objects_read_as_geometry(ob)} if nodes else set()
            for other in objects:  # named directly: a mesh shown whatever its flags, a render-hidden curve or
                # text not, a child of a vertex or face instancer only as its instances; its own instances
                # unless it is render-hidden and instanced as an object (read as geometry they come along)
                shows = not instanced_by_its_parent(other) and (other.type == "MESH" or not other.hide_render)
                self._add_object(other, shows, stack, reach, shown,
                                 instances_shown=not other.hide_render or other.as_pointer() in geometry)
        return self._remember(self._expansion_memo, key, (frozenset(reach), frozenset(shown)), cuts)

    def _collection_expansion(self, coll: bpy.types.Collection, stack: frozenset) -> tuple[frozenset, frozenset]:
        """(reach, shown) of an instance of `coll`: its objects and its child collections', and what
        they instance; shown: those a render walks (objects and collections not render-hidden)."""
        ptr = coll.as_pointer()
        if ptr in self._collection_memo:
            return self._collection_memo[ptr]
        if ("collection members", ptr) in stack:
            self._cuts += 1
            return frozenset(), frozenset()
        stack, cuts = stack | {("collection members", ptr)}, self._cuts
        reach, shown = set(), set()
        walked = unhidden_objects(coll, "hide_render")
        for ob in coll.all_objects:  # a child of a vertex or face instancer shows only as its instances
            self._add_object(ob, ob.as_pointer() in walked and not instanced_by_its_parent(ob), stack, reach, shown)
        return self._remember(self._collection_memo, ptr, (frozenset(reach), frozenset(shown)), cuts)

    def _remember(self, memo: dict, key, value, cuts: int):
        """Keep `value` unless a cycle was cut short while computing it (then it holds only part of
        what this key reaches from elsewhere: its answer would depend on the order of questions)."""
        if self._cuts == cuts:
            memo[key] = value
        return value

    def _add_object(self, ob, visible: bool, stack: frozenset, reach: set, shown: set,
                    instances_shown: bool | None = None) -> None:
        """Add `ob` and what it instances to reach, and to shown where a render makes them."""
        reach.add(ob.as_pointer())
        if visible:
            shown.add(ob.as_pointer())
        if instances_things(ob):
            self._add(self._expansion(ob, stack), reach, shown if (visible if instances_shown is None
                                                                  else instances_shown) else None)

    @staticmethod
    def _add(expansion: tuple[frozenset, frozenset], reach: set, shown: set | None) -> None:
        reach |= expansion[0]
        if shown is not None:
            shown |= expansion[1]


def _render_enabled_collections() -> set[int]:
    """Pointers of the collections a render can walk into: not render-disabled, and reached from a
    scene's master collection or from a collection no other one holds (one only instanced) through
    collections that are not either."""
    held = {child.as_pointer() for c in bpy.data.collections for child in c.children}
    todo = [scene.collection for scene in bpy.data.scenes]
    todo += [c for c in bpy.data.collections if c.as_pointer() not in held and not c.hide_render]
    out: set[int] = set()
    while todo:
        c = todo.pop()
        if c.as_pointer() not in out:
            out.add(c.as_pointer())
            todo.extend(child for child in c.children if not child.hide_render)
    return out


def _holding_collections() -> dict[int, list[int]]:
    """{object pointer: pointers of the collections holding it, scenes' master collections too}, from
    one pass (Object.users_collection scans every collection on each read)."""
    out: dict[int, list[int]] = {}
    for coll in list(bpy.data.collections) + [scene.collection for scene in bpy.data.scenes]:
        for ob in coll.objects:
            out.setdefault(ob.as_pointer(), []).append(coll.as_pointer())
    return out


def set_scenes(scene: bpy.types.Scene) -> list[bpy.types.Scene]:
    """The chain of background scenes (Scene > Background Scene, its own, ...): a render shows their
    objects too, as the depsgraph holds them."""
    chain, seen = [], {scene.as_pointer()}
    background = scene.background_set
    while background is not None and background.as_pointer() not in seen:  # Blender refuses cycles; be sure
        chain.append(background)
        seen.add(background.as_pointer())
        background = background.background_set
    return chain


def render_view_layer(scene: bpy.types.Scene) -> bpy.types.ViewLayer:
    """The view layer a render takes from a scene that is not the window's (a background scene, the
    command line's --scene): Blender's BKE_view_layer_default_render, the first one enabled for
    rendering, else the first."""
    return next((layer for layer in scene.view_layers if layer.use), scene.view_layers[0])


def _layer_render_objects(layer_coll: bpy.types.LayerCollection) -> set[int]:
    """Original-object pointers reachable through render-enabled collections."""
    out: set[int] = set()
    todo = [layer_coll]
    while todo:
        lc = todo.pop()
        if lc.exclude or lc.collection.hide_render:
            continue
        out.update(ob.as_pointer() for ob in lc.collection.objects)
        todo.extend(lc.children)
    return out


def ray_visible(*objs) -> bool:
    """False only when camera and shadow rays are both off (ANDed over objs)."""
    return any(ray_flags(*objs))


def ray_flags(*objs) -> tuple[bool, bool]:
    """(camera, shadow): Ray Visibility > Camera and > Shadow, ANDed over objs (an instance and its
    instancer)."""
    return all(ob.visible_camera for ob in objs), all(ob.visible_shadow for ob in objs)


def _instancer_hides_self(orig: bpy.types.Object, evaluated: bpy.types.Object) -> bool:
    """Particle / vertex / face / collection instancers may hide themselves."""
    if orig.show_instancer_for_render:
        return False
    return evaluated.is_instancer or len(orig.particle_systems) > 0


def entry_visible(vis: RenderVisibility, parent, ob: bpy.types.Object) -> bool:
    """Render-visibility of one object_instances entry (parent None: not an instance), apart from
    its ray-visibility flags (ray_flags)."""
    orig = ob.original
    if not collection_visible(vis, parent, orig):
        return False
    if parent is not None:  # the instances of an instancer hidden so go with it (Blender skips its duplis)
        if instanced_by_its_parent(parent.original):
            return False
        # An instancer inside an instance (an emitter or a vertex parent in an instanced collection)
        # hides itself as at the top level.
        return orig == parent.original or not _instancer_hides_self(orig, ob)
    return not (_instancer_hides_self(orig, ob) or instanced_by_its_parent(orig))


# Blender hides an object whose parent instances it on its vertices or faces at its own place in a
# final render (depsgraph deg_object_hide_original: render mode, or any instance), not in the
# viewport's depsgraph the preview reads; the instances it makes are kept. Not for metaballs.
INSTANCING_PARENT_TYPES = frozenset(("VERTS", "FACES"))


def instanced_by_its_parent(orig: bpy.types.Object) -> bool:
    parent = orig.parent
    return parent is not None and parent.instance_type in INSTANCING_PARENT_TYPES and orig.type != "META"


def collection_visible(vis: RenderVisibility, parent, orig: bpy.types.Object) -> bool:
    """The collection and hide_render rules of an object_instances entry (parent None: not an
    instance), without the ray-visibility flags."""
    if parent is None:
        return vis.scene_object(orig)
    return vis.scene_object(parent.original) and instanced_visible(vis, parent.original, orig)


def instanced_visible(vis: RenderVisibility, parent: bpy.types.Object, orig: bpy.types.Object) -> bool:
    """Whether the original instancer `parent` makes `orig` in a render, whatever `parent`'s own
    visibility (collection_visible adds that)."""
    if parent == orig:
        return True
    if parent.instance_type in INSTANCING_PARENT_TYPES and _descends_from(orig, parent):
        # Blender instances on vertices or faces the children that the depsgraph holds (object_dupli.cc,
        # make_child_duplis): a render's depsgraph leaves out a child disabled in renders, the viewport's
        # does not (Cycles showed no copies of such a child; the preview showed them all).
        return vis.scene_object(orig)
    return vis.in_instanced_collection(parent, orig)


def _descends_from(orig: bpy.types.Object, ancestor: bpy.types.Object) -> bool:
    """Whether `ancestor` is on `orig`'s parent chain (Blender's is_child for instancing children)."""
    parent = orig.parent
    while parent is not None:
        if parent == ancestor:
            return True
        parent = parent.parent
    return False


def rendered_layers_objects(depsgraph: bpy.types.Depsgraph):
    """The objects of the depsgraph's view layer and of its background scenes' render view layers,
    each once: what a final render may show (an object can be in the scene and a background scene)."""
    seen = set()
    layers = [depsgraph.view_layer] + [render_view_layer(s) for s in set_scenes(depsgraph.scene)]
    for ob in (ob for layer in layers for ob in layer.objects):
        if ob.as_pointer() not in seen:
            seen.add(ob.as_pointer())
            yield ob
