"""Instances that a final render does not make because they come through a render-hidden instancer.

Blender makes no instances from an object with *Disable in Renders* set, at any depth
(object_dupli.cc, get_dupli_generator), and a render walks only an instanced collection's
render-visible members. The viewport's depsgraph applies the viewport's flags instead, so it yields
instances a render never makes. render_visibility.py decides per (object, top-level instancer) pair,
which cannot tell an object reached through a hidden instancer from the same object reached through
a visible path, so this walks the instance tree itself.

`depsgraph.object_instances` yields a top-level object's instances depth first, each instancer right
before its instances, and `persistent_id` holds one index a nesting level (INT_MAX when unused), so an
entry's ancestors are among the latest entries of smaller depth. Geometry-nodes levels without an
object yield no entry, so an ancestor is believed only when the entry's levels continue its own
(_descends) and it could make the entry. Where that cannot be told (a collection computed by nodes)
the entry is kept. Each entry asks only its parent (_blocked), whose flag carries its ancestors'.
"""
from __future__ import annotations

import bpy

from .node_instances import has_node_modifier, instancing_references

UNUSED_LEVEL = 2 ** 31 - 1  # persistent_id's filler beyond an entry's depth (INT_MAX)
_INSTANCING_TYPES = frozenset(("COLLECTION", "VERTS", "FACES"))


class DupliPaths:
    """Feed it every object_instances entry in order; `made_by_render` says whether a render makes it.

    `generated(instancer, orig)` (originals) is the caller's rule for whether a render makes `orig`
    under `instancer` as far as collections go, whatever the instancer's own visibility
    (render_visibility.RenderVisibility.in_instanced_collection). The walk runs only under top-level
    instancers that can reach another instancing object, in files with a render-hidden collection or
    object, as it costs several microseconds an entry (docs/choices.md#walk-instance-paths-only-where-a-render-can-differ)."""

    def __init__(self, generated, descendants=lambda ob: ob.children_recursive):
        self._generated = generated
        self._descendants = descendants  # children_recursive, or the caller's faster copy of it
        self._active: bool | None = None  # decided at the first instance entry (most frames have none)
        self._tops: dict[int, tuple[bool, tuple]] = {}  # top-level instancer -> (walk its entries, kind)
        self._parent = 0
        self._stack: list[tuple[tuple, int, bool, bool]] = []  # (levels, original's pointer, makes nothing,
        # made by a plain collection instancer)
        self.blocked: set[int] = set()  # originals some entry of which a render does not make
        self._makes_nothing: dict[tuple[int, int], bool] = {}
        self._objects: dict[int, bpy.types.Object] = {}
        self._made: dict[tuple[int, int], bool] = {}
        self._reach: dict[tuple, tuple[frozenset[int], bool]] = {}
        self._numbered: dict[int, tuple[list, frozenset[int]]] = {}  # collection -> _hidden_member's tables

    def made_by_render(self, inst, ob, parent) -> bool:
        """`ob` and `parent` are the entry's object and top-level instancer (None: not an instance),
        as the caller has read them."""
        if parent is None:
            self._stack.clear()
            return True
        if self._active is None:
            self._active = _anything_render_hidden()
        if not self._active:
            return True
        parent_ptr = parent.as_pointer()
        if parent_ptr != self._parent:  # a top-level object's instances come in one run
            self._parent = parent_ptr
            self._stack.clear()
        top = self._tops.get(parent_ptr)
        if top is None:
            top = self._tops[parent_ptr] = (self._reach_of(parent.original)[1], instancer_kind(parent.original))
        walk, kind = top
        if not walk:
            return True
        pid = _levels(inst.persistent_id)
        while self._stack and len(self._stack[-1][0]) >= len(pid):
            self._stack.pop()
        orig = ob.original
        pointer = orig.as_pointer()
        key = (kind, pointer)
        own = self._makes_nothing.get(key)
        if own is None:  # per (kind of instancer, object): most entries repeat one
            own = self._makes_nothing[key] = orig.hide_render or not self._generated(parent.original, orig)
            self._objects[pointer] = orig
        blocked, maker = self._blocked(pid, pointer, parent.original if kind[0] == "collection" else None)
        self._stack.append((pid, pointer, blocked or own, maker))
        if blocked:
            self.blocked.add(pointer)
        return not blocked

    def walks(self, instancer: bpy.types.Object) -> bool:
        """Whether `made_by_render` may block an entry under the top-level instancer `instancer` (an
        original): a reader that skips it must then leave that instancer's entries to it."""
        if self._active is None:
            self._active = _anything_render_hidden()
        return self._active and self._reach_of(instancer)[1]

    def _blocked(self, pid: tuple, pointer: int, plain_top) -> tuple[bool, bool]:
        """Whether the entry's parent, the nearest stacked entry it descends from (its levels continue
        the parent's and the parent could make it), makes nothing (itself hidden, or on a path a render
        does not make: the flag is inherited down the stack), or instances a collection whose render
        skips the entry's object (render-hidden there, or in a hidden child collection). Only the
        parent is asked: a farther entry whose levels the entry's also continue (geometry nodes' +1
        numbering makes such twins) may be a sibling of the parent's line, wrongly blocked if hidden.

        Returns (blocked, whether the entry's own level was made by a plain collection instancer:
        the top-level instancer `plain_top` (None when it is not one), or its parent). A member of a
        plain collection carries its own index at its level, and so do its instances
        (make_duplis_collection recurses with the member's id, no +1), so a stacked entry made so is
        a parent only with that exact index, and an index no stacked entry has names the member
        whose instances the entry is (_hidden_member: a member without an entry of its own)."""
        for parent_pid, parent, makes_nothing, plain_level in reversed(self._stack):
            if plain_level and pid[len(pid) - len(parent_pid)] != parent_pid[0]:
                continue
            if not (_descends(pid, parent_pid) and self._makes(parent, pointer)):
                continue
            instancer = self._objects[parent]
            maker = _plain_collection_instancer(instancer)
            if makes_nothing:
                return True, maker
            if maker and len(pid) > len(parent_pid) + 1 and self._hidden_member(
                    instancer.instance_collection, pid[len(pid) - len(parent_pid) - 1], pointer):
                return True, maker
            return not self._generated(instancer, self._objects[pointer]), maker
        if plain_top is not None and len(pid) > 1:
            return self._hidden_member(plain_top.instance_collection, pid[-1], pointer), True
        return False, plain_top is not None

    def _hidden_member(self, collection, index: int, pointer: int) -> bool:
        """Whether the member an instance of `collection` numbers `index` is another object than the
        entry's and one a render skips. make_duplis_collection counts every base of the collection's
        object cache (all_objects), viewport-hidden ones too (checked: with A hidden in the viewport,
        B's persistent_id is (1, ...))."""
        key = collection.as_pointer()
        if key not in self._numbered:
            self._numbered[key] = (list(collection.all_objects),
                                   frozenset(unhidden_objects(collection, "hide_render")))
        members, rendered = self._numbered[key]
        if index >= len(members):
            return False
        member = members[index].as_pointer()
        return member != pointer and member not in rendered

    def _makes(self, ancestor: int, pointer: int) -> bool:
        """Whether object `ancestor` can instance object `pointer`, directly or through what it instances
        (a carrier's own geometry-nodes instances are entries of the carrier itself); memoized."""
        key = (ancestor, pointer)
        made = self._made.get(key)
        if made is None:
            made = self._made[key] = ancestor == pointer or pointer in self._reach_of(self._objects[ancestor])[0]
        return made

    def _reach_of(self, ob: bpy.types.Object, stack: frozenset = frozenset()) -> tuple[frozenset[int], bool]:
        """(pointers of every object `ob` can instance, nested instancing included; whether one of
        them instances things itself), memoized (per collection for collection instancers: a scene
        may hold thousands of one collection's instancers). A collection computed by nodes is not
        seen: its members then count as not instanced by `ob`, and their entries are kept, as before."""
        key = instancer_kind(ob)
        if key in self._reach:
            return self._reach[key]
        objects = list(_instanced_directly(ob, self._descendants))
        reach, nested, pointer = set(), False, ob.as_pointer()
        for other in objects:
            other_key = other.as_pointer()
            reach.add(other_key)
            if other_key != pointer and other_key not in stack and instances_things(other):
                nested = True
                reach |= self._reach_of(other, stack | {pointer})[0]
        self._reach[key] = (frozenset(reach), nested)
        return self._reach[key]


def unhidden_objects(coll: bpy.types.Collection, hidden: str) -> set[int]:
    """Pointers of the objects of `coll` and of its child collections that have the flag `hidden`
    ("hide_render" or "hide_viewport") off, as has every collection on their path: the members a
    render, or the viewport, walks in an instance of `coll` (and picks particle instances from)."""
    out: set[int] = set()
    todo = [] if getattr(coll, hidden) else [coll]
    while todo:
        c = todo.pop()
        out.update(ob.as_pointer() for ob in c.objects if not getattr(ob, hidden))
        todo.extend(child for child in c.children if not getattr(child, hidden))
    return out


def _plain_collection_instancer(ob) -> bool:
    return instancer_kind(ob)[0] == "collection"


def instancer_kind(ob) -> tuple:
    """What decides the instances an object makes: the collection it instances, or the object itself
    (vertex or face instancing, particles, geometry nodes)."""
    collection = instanced_collection(ob)
    if collection is not None and not ob.particle_systems and not has_node_modifier(ob):
        return ("collection", collection.as_pointer())
    return ("object", ob.as_pointer())


def _levels(persistent_id) -> tuple:
    """The nesting levels an entry's persistent_id uses, innermost first (the rest hold UNUSED_LEVEL)."""
    levels = tuple(persistent_id)
    return levels[:len(levels) - levels.count(UNUSED_LEVEL)]


def _descends(pid: tuple, ancestor_pid: tuple) -> bool:
    """Whether an entry's levels continue an ancestor's: its outer levels are the ancestor's, except
    that geometry nodes number the instances of a collection member's own instances from the member's
    index plus one (object_dupli.cc: make_dupli(..., id++), then make_recursive_duplis(..., id)). A
    sibling at a deeper level (geometry-nodes levels that hold no object yield no entry) fails this."""
    gap = len(pid) - len(ancestor_pid)
    if gap <= 0:
        return False
    outer = pid[gap:]
    return outer == ancestor_pid or (outer[0] == ancestor_pid[0] + 1 and outer[1:] == ancestor_pid[1:])


def instanced_collection(ob):
    return ob.instance_collection if ob.instance_type == "COLLECTION" else None


def _instanced_directly(ob: bpy.types.Object, descendants):
    """The objects `ob` instances itself: its instance collection's (children included), its
    children when it instances on vertices or faces, those its geometry nodes and particles name."""
    collection = instanced_collection(ob)
    if collection is not None:
        yield from collection.all_objects
    if ob.instance_type in ("VERTS", "FACES"):
        yield from descendants(ob)
    if len(ob.particle_systems) or has_node_modifier(ob):
        collections, objects = instancing_references(ob)
        for collection in collections:
            yield from collection.all_objects
        yield from objects


def instances_things(ob: bpy.types.Object) -> bool:
    """Whether `ob` may instance objects: a collection, its children on vertices or faces, or
    through particles or geometry nodes."""
    return ob.instance_type in _INSTANCING_TYPES or len(ob.particle_systems) > 0 or has_node_modifier(ob)


def _anything_render_hidden() -> bool:
    """Whether the file has anything a path can hide instances by: a render-hidden collection or object
    (an instancer, or a member that a collection instance on the path skips). Without one no entry is
    walked."""
    return any(c.hide_render for c in bpy.data.collections) or any(ob.hide_render for ob in bpy.data.objects)
