"""Warnings naming what a final render shows and the preview leaves out, or renders differently.

The preview reads the viewport's depsgraph, so objects hidden in the viewport, geometry that is not
triangles (hair curves, point clouds, volumes, grease pencil), hair strands, lights hidden in the
viewport and view-layer settings are named here rather than silently dropped.
"""

from __future__ import annotations

import bpy

from .dupli_paths import instanced_collection, instances_things, unhidden_objects
from .node_instances import has_node_modifier, node_references
from .render_visibility import (INSTANCING_PARENT_TYPES, RenderVisibility, instanced_by_its_parent, ray_visible,
                                rendered_layers_objects)
from .scene_records import NOT_TRIANGLES, TRIANGLE_TYPES, Instance

# Drawn by Blender over any engine's final image (with the view layer's Filter > Grease Pencil on), so there
# only the rays miss it.
DRAWN_OVER_RENDERS = {"GREASEPENCIL", "GPENCIL"}


def surfaces_off_warnings(view_layer) -> list[str]:
    """A view layer whose Filter > Surfaces is off renders no surfaces at all (Cycles: no hit pixel)."""
    if view_layer.use_solid:
        return []
    return [f"view layer '{view_layer.name}' has Filter > Surfaces off: a final render shows no surfaces, so the "
            "preview renders none"]


def unused_layer_warnings(depsgraph) -> list[str]:
    """The preview renders the window's view layer (or the command line's --scene's render layer);
    a final render writes only the layers enabled for rendering."""
    layer = depsgraph.view_layer
    if layer.use:
        return []
    return [f"view layer '{layer.name}' is not enabled for rendering (Use for Rendering off): the preview "
            "renders it, a final render writes only the enabled layers"]


def objects_shown(depsgraph, vis: RenderVisibility, instances: list[Instance]) -> list[bpy.types.Object]:
    """The original objects a final render shows in the scene (hidden in the viewport or not), those
    the preview instanced, and those geometry nodes read (an Object Info source's evaluation shapes
    the realized copy too), each once."""
    out = {ob.as_pointer(): ob for ob in rendered_layers_objects(depsgraph) if vis.scene_object(ob)}
    for name in {r.name for r in instances if r.is_instance}:
        ob = bpy.data.objects.get(name)
        if ob is not None:
            out.setdefault(ob.as_pointer(), ob)
    for ob in [ob for ob in out.values() if has_node_modifier(ob)]:
        collections, objects = node_references(ob)  # sources the nodes read, realized ones too
        for source in objects + [member for c in collections for member in c.all_objects]:
            out.setdefault(source.as_pointer(), source)
    return list(out.values())


def left_out_warnings(depsgraph: bpy.types.Depsgraph, vis: RenderVisibility, instanced_by: dict[int, set[int]],
                      evaluated: set[int], not_made: set[int] = frozenset(),
                      meshed: set[str] = frozenset(), render_mode: bool = False) -> list[str]:
    """A warning per render-visible thing a final render shows and the preview leaves out: objects
    hidden in the viewport or not triangles, collection instancers hidden there, members disabled in
    viewports of collections rendered whole, and hair strands. `instanced_by`: the originals the
    depsgraph instanced, by original instancer. `evaluated`: pointers of the originals the viewport
    shows (those only its Show Instancer flag keeps out included). `not_made`: originals instanced
    on a path a render does not make (dupli_paths.py). `meshed`: names of the originals whose own
    geometry gave triangles (a point cloud whose nodes output a mesh is named only for the rest).
    `render_mode`: the depsgraph is a final render's own, which leaves nothing out for being hidden
    in the viewport: only what is not triangles and hair strands are named."""
    warnings = []
    instancers = {}
    instanced = set().union(*instanced_by.values()) | not_made
    for ob in rendered_layers_objects(depsgraph):
        kind = ob.type
        if kind in TRIANGLE_TYPES and ob.as_pointer() in evaluated:
            if len(ob.particle_systems):
                warnings += _strand_warnings(ob, vis) + ([] if render_mode else _pick_warnings(ob, vis))
            for collection in [] if render_mode else _collections_rendered_whole(ob, vis):
                instancers.setdefault(collection.as_pointer(), (collection, []))[1].append(ob)
            continue  # the common case first, cheapest
        if ob.instance_type == "COLLECTION" and ob.instance_collection is not None and vis.scene_object(ob):
            if ob.as_pointer() in evaluated and not render_mode:
                instancers.setdefault(ob.instance_collection.as_pointer(), (ob.instance_collection, []))[1].append(ob)
            elif ray_visible(ob) and not render_mode:
                warnings.append(f"object '{ob.name}' is hidden in the viewport (eye icon, Disable in Viewports or a "
                                f"hidden collection): the preview leaves out the instances of collection "
                                f"'{ob.instance_collection.name}' it makes, a final render shows them")
        if ((kind in TRIANGLE_TYPES or kind in NOT_TRIANGLES) and vis.scene_object(ob) and ray_visible(ob)
                and not _renders_nothing(ob)):
            if kind in NOT_TRIANGLES:
                if not _own_elements(ob.evaluated_get(depsgraph)):
                    pass  # its nodes made it all triangles or instances, or it is empty
                elif render_mode and kind in DRAWN_OVER_RENDERS:
                    if not depsgraph.view_layer.use_grease_pencil:
                        continue  # the layer's Filter > Grease Pencil is off: no render draws it
                    warnings.append(f"object '{ob.name}' is {NOT_TRIANGLES[kind]}, not triangles: Blender draws it "
                                    "over the image, but the preview's rays pass through it (no AO or shadow)")
                elif ob.name not in meshed:
                    warnings.append(f"object '{ob.name}' is {NOT_TRIANGLES[kind]}, not triangles: left out of "
                                    "the preview")
                else:
                    warnings.append(f"object '{ob.name}' is {NOT_TRIANGLES[kind]}: the preview shows the triangles its "
                                    f"geometry nodes make and leaves the rest out")
            elif not render_mode and not (instanced_by_its_parent(ob) and ob.as_pointer() in instanced):
                # (a child its parent instances shows only as those instances, which the eye icon keeps)
                what = ("it and the instances it makes" if ob.instance_type in INSTANCING_PARENT_TYPES
                        or len(ob.particle_systems) else "it")
                warnings.append(f"object '{ob.name}' is hidden in the viewport (eye icon, Disable in Viewports or "
                                f"a hidden collection): the preview reads the viewport's scene and leaves {what} out, "
                                "a final render shows it")
    for collection, hosts in instancers.values():
        members = list(_members(collection, (), {collection.as_pointer()}))
        pointers = {ob.as_pointer() for ob, _, _ in members}
        hosts = [h for h in hosts if _shows_instances_of(h, pointers, instanced_by)]
        if hosts:
            warnings += _hidden_member_warnings(collection, members, hosts, vis, instanced)
            shown = vis.instanced_objects(collection)  # emitters inside: named as at the top
            warnings += [w for ob, _, _ in members if len(ob.particle_systems) and ob.as_pointer() in shown
                         for w in _pick_warnings(ob, vis, instanced=True) if w not in warnings]
    return warnings


def _own_elements(evaluated) -> bool:
    """Whether an evaluated point cloud or curves object still holds points or curves of its own (its
    geometry nodes may turn them all into a mesh); True where that cannot be counted (volumes, grease
    pencil)."""
    data = evaluated.data
    for name in ("curves", "points"):
        elements = getattr(data, name, None)
        if elements is not None:
            return len(elements) > 0
    return True


def _hidden_member_warnings(collection, members: list, hosts: list, vis: RenderVisibility,
                            instanced: set[int]) -> list[str]:
    """Members (`_members` of the collection: nested collection instances' too) a render of the
    collection's instances shows that the viewport's depsgraph did not instance (the object or a
    collection on its path disabled in viewports), one warning each, naming the first of `hosts` (the
    objects instancing the collection) whose instances of it rays can see."""
    shown = vis.instanced_objects(collection)  # nested instances' render-visible members included
    out, named = [], set()
    for ob, owner, chain in members:
        # a collection instancer disabled in viewports takes its copies with it: named itself, once,
        # even where a visible sibling instances the same collection
        nesting = instanced_collection(ob) is not None and _nests(ob) and ob.hide_viewport
        if ((ob.type not in TRIANGLE_TYPES and not nesting) or ob.type == "META" or ob.as_pointer() not in shown
                or ob.as_pointer() in instanced or vis.scene_object(ob) or _renders_nothing(ob)
                or any(inner.as_pointer() in named for inner in chain)):
            continue  # scene objects are named as such; no render instances a metaball (object_dupli.cc: no_draw)
        host = next((h for h in hosts if ray_visible(ob, *chain, h) and (not chain or _nests(h))), None)
        if host is not None:
            where = f"object '{ob.name}' in collection '{owner.name}' (instanced by '{host.name}'{_through(chain)})"
            if instanced_by_its_parent(ob):
                continue  # shows only as its parent's instances, which the parent's own line covers
            if not ob.hide_viewport and not ob.show_instancer_for_viewport and instances_things(ob):
                if not ob.show_instancer_for_render:
                    continue  # hidden in renders too
                out.append(f"{where} has Show Instancer > Viewport off: the preview leaves its own mesh out there, "
                           "a final render shows it")  # its instances are made
                continue
            why = ("is disabled in viewports" if ob.hide_viewport else
                   "is not instanced in the viewport (a collection or instancer on its path is disabled in viewports)")
            out.append(f"{where} {why}: the preview leaves its instances out, a final render shows them")
            named.add(ob.as_pointer())
    return out


def _through(chain) -> str:
    """" through 'A' through 'B'": the instancers a collection member is nested through."""
    return "".join(f" through '{inner.name}'" for inner in chain)


def _nests(host) -> bool:
    """Whether `host`'s instances of a collection expand the collection instances among its members: a
    collection instancer's and geometry nodes' do, particles' do not (object_dupli.cc makes particles'
    instances without recursing)."""
    return host.instance_type == "COLLECTION" or has_node_modifier(host)


def _shows_instances_of(host, members: set[int], instanced_by: dict[int, set[int]]) -> bool:
    """Whether the viewport's depsgraph shows `host`'s instances of a collection (`members`: pointers
    of its objects, nested ones too) as instances, so that a member missing from them is missing from
    the preview. A collection instancer's always are. A geometry-nodes host or an emitter counts only
    once it instanced one of the members: its nodes may realize the instances (Realize Instances) or
    not use the Collection Info node at all, and its modifier may be shown in renders only; then no
    member is an instance for a reason other than its own. (A collection all of whose members are
    disabled in viewports is then not named: better a missing warning than a wrong one.)"""
    return host.instance_type == "COLLECTION" or not instanced_by.get(host.as_pointer(), set()).isdisjoint(members)


def _renders_nothing(ob) -> bool:
    """A mesh without faces, modifiers (particles included) or instancing: nothing for any render to
    show, so hiding it in the viewport loses nothing (rig widgets, guides, hook targets)."""
    return (ob.type == "MESH" and len(ob.data.polygons) == 0 and len(ob.modifiers) == 0
            and ob.instance_type == "NONE")


def _members(collection, chain: tuple, stack: set):
    """(object, the collection it is a member of, the instancers inside `collection` it is nested
    through) for every object of `collection` and of the collections its render-visible members
    instance, outer members first; a collection already on the path is not entered again."""
    nested = []
    for ob in collection.all_objects:
        yield ob, collection, chain
        inner = ob.instance_collection if ob.instance_type == "COLLECTION" else None
        if inner is not None and not ob.hide_render and inner.as_pointer() not in stack:
            nested.append((ob, inner))
    for ob, inner in nested:
        yield from _members(inner, chain + (ob,), stack | {inner.as_pointer()})


def _strand_warnings(ob, vis: RenderVisibility) -> list[str]:
    """Hair particle systems drawn as strands (Render As: Path), which Cycles renders as curves."""
    if not (vis.scene_object(ob) and ray_visible(ob)):
        return []
    shown = _render_shown_systems(ob)
    return [f"object '{ob.name}': hair particles '{system.name}' are strands, not triangles: left out of the preview"
            for system in ob.particle_systems
            if system.as_pointer() in shown and system.settings.type == "HAIR"
            and system.settings.render_type == "PATH"]


def _pick_warnings(ob, vis: RenderVisibility, instanced: bool = False) -> list[str]:
    """Particle systems that render one member of a collection per particle (Whole Collection off):
    a final render picks among the render-visible members, the viewport among the viewport-enabled
    ones, so where the two sets differ the preview's particle-to-object assignment is not a final
    render's (the render-hidden members' particles are left out, see RenderVisibility). `instanced`: ob is
    a member a collection instance renders (left_out_warnings decided), not a scene object."""
    if not ((instanced or vis.scene_object(ob)) and ray_visible(ob)):
        return []
    shown = _render_shown_systems(ob)
    out = []
    for system in ob.particle_systems:
        settings = system.settings
        coll = settings.instance_collection
        if (system.as_pointer() in shown and settings.render_type == "COLLECTION" and coll is not None
                and not settings.use_whole_collection
                and unhidden_objects(coll, "hide_render") != unhidden_objects(coll, "hide_viewport")):
            out.append(f"object '{ob.name}': particle system '{system.name}' gives each particle one object of "
                       f"collection '{coll.name}', which a final render picks among the render-visible members "
                       "only: the preview's particle-to-object assignment differs from a final render's (it leaves "
                       "the render-hidden members' particles out)")
    return out


def _collections_rendered_whole(ob, vis: RenderVisibility) -> list:
    """The collections ob renders whole through geometry nodes (Collection Info, node_instances.py) or
    render-shown particle systems (Render As: Collection, Whole Collection on): their members follow
    the collection-instance rule, so a member disabled in viewports is left out of the preview as a
    collection instance's is (_hidden_member_warnings); a final render shows such a member in all three
    ways (docs/choices.md#collections-instanced-by-nodes-or-particles-follow-the-collection-instance-rule)."""
    nodes = has_node_modifier(ob)
    if not (nodes or len(ob.particle_systems)) or not (vis.scene_object(ob) and ray_visible(ob)):
        return []
    collections = node_references(ob)[0] if nodes else []
    shown = _render_shown_systems(ob)
    return collections + [system.settings.instance_collection for system in ob.particle_systems
                          if system.as_pointer() in shown and system.settings.render_type == "COLLECTION"
                          and system.settings.instance_collection is not None
                          and system.settings.use_whole_collection]


def _render_shown_systems(ob) -> set[int]:
    """Pointers of ob's particle systems whose modifier is shown in renders."""
    return {m.particle_system.as_pointer() for m in ob.modifiers if m.type == "PARTICLE_SYSTEM" and m.show_render}


def hidden_light_warnings(depsgraph: bpy.types.Depsgraph, vis: RenderVisibility,
                          instanced_lights: set[int] = frozenset()) -> list[str]:
    """A warning per render-visible light of the scene or its background scenes hidden in the
    viewport: its depsgraph does not evaluate it, so the preview cannot use it, while a final render
    does; and per light member of a collection a collection instancer renders whole that the viewport
    did not instance (`instanced_lights`: pointers of the originals of the lights it did), disabled in
    viewports or in a collection that is. `vis`: the render-visibility table, shared with the caller."""
    evaluated = {ob.original.as_pointer() for ob in depsgraph.objects}
    out = [f"light '{ob.name}' is hidden in the viewport (eye icon, Disable in Viewports or a hidden collection): "
           "the preview leaves it out, a final render uses it"
           for ob in rendered_layers_objects(depsgraph)
           if ob.type == "LIGHT" and ob.as_pointer() not in evaluated and vis.scene_object(ob)]
    named, walked = set(), set()
    if not any(ob.type == "LIGHT" for ob in bpy.data.objects):
        return out
    for host in rendered_layers_objects(depsgraph):
        collection = instanced_collection(host)
        if (collection is None or collection.as_pointer() in walked or host.as_pointer() not in evaluated
                or not vis.scene_object(host)):
            continue
        walked.add(collection.as_pointer())
        shown = vis.instanced_objects(collection)
        for ob, owner, chain in _members(collection, (), {collection.as_pointer()}):
            if (ob.type == "LIGHT" and ob.as_pointer() in shown and ob.as_pointer() not in instanced_lights
                    and ob.as_pointer() not in named):
                named.add(ob.as_pointer())
                out.append(f"light '{ob.name}' in collection '{owner.name}' (instanced by '{host.name}'"
                           f"{_through(chain)}) is not instanced in the viewport (disabled in viewports, or a "
                           "collection on its path is): the preview leaves it out, a final render uses it")
    return out
