"""The F-curves and drivers that animate an ID's properties, read alike on every Blender the extension
supports: Blender 4.4 and later keep an action's curves in channel bags, one per slot (the ID's slot is
`AnimData.action_slot`; the legacy `Action.fcurves` gives the first slot's, maybe another ID's, and is
gone in 5.0), 4.2 and 4.3 in `Action.fcurves`. Muted curves, drivers and NLA tracks animate nothing."""


def active_curves(id_data, prefix: str = "") -> list:
    """The unmuted F-curves of the ID's active action whose data path starts with `prefix`."""
    data = getattr(id_data, "animation_data", None)
    if data is None:
        return []
    return [c for c in _action_curves(data, data.action, getattr(data, "action_slot", None))
            if c.data_path.startswith(prefix) and not c.mute]


def animated_paths(id_data, prefix: str = "", *, active: bool = True) -> set[str]:
    """Data paths starting with `prefix` that the ID's active action (unless `active` is False), its
    unmuted NLA strips or its drivers animate."""
    data = getattr(id_data, "animation_data", None)
    if data is None:
        return set()
    curves = _action_curves(data, data.action, getattr(data, "action_slot", None)) if active else []
    for strip in _nla_strips(data):
        curves += _action_curves(data, strip.action, getattr(strip, "action_slot", None))
    curves += list(data.drivers)
    return {c.data_path for c in curves if c.data_path.startswith(prefix) and not c.mute}


def _nla_strips(data) -> list:
    """The NLA strips Blender evaluates: none with the NLA off, a solo track's alone, unmuted ones, the
    strips inside meta strips."""
    if not data.use_nla:
        return []
    tracks = [t for t in data.nla_tracks if t.is_solo] or [t for t in data.nla_tracks if not t.mute]
    found, pending = [], [s for t in tracks for s in t.strips]
    while pending:
        strip = pending.pop()
        if not strip.mute:
            found.append(strip)
            pending += list(strip.strips)  # a meta strip's own
    return [s for s in found if s.action is not None]


def _action_curves(data, action, slot) -> list:
    if action is None:
        return []
    if hasattr(data, "action_slot"):  # 4.4 and later: the slot's channel bags only
        if slot is None:
            return []
        bags = [strip.channelbag(slot) for layer in action.layers for strip in layer.strips]
        return [c for bag in bags if bag is not None for c in bag.fcurves]
    return list(action.fcurves)
