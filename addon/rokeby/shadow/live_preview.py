"""The live shadow while dragging (the paper's Fig. 3 B–D): each drag step writes the uncommitted
shadow mesh into the edit's shape key (:func:`live_begin`, :func:`live_step`, :func:`live_end`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blender import compat, transaction
from .configurations import configuration_key
from .errors import ShadowEditError
from .linking import _is_light, _link, _live_self_blocker, remove, shadow_mesh_of
from .session import ShadowSession
from .shadow_mesh import _local_displacement, _self_blocker, _self_displacement, apply


# --- Live shadow while dragging (the paper's Fig. 3 B–D) -----------------------------------------
# Each drag step writes the current (uncommitted) shadow mesh into the edit's shape key, so a
# viewport in Rendered shading (EEVEE or Cycles: both honour the linking) and renders show the
# edited shadow during the drag. Solid and Material Preview shading skip the shadow mesh (it is
# displayed as Wire) and Solid has no linked lights. live_begin installs the edit (apply) if the caster has none; live_end
# keeps the result (apply again: everything consistent) or puts back exactly what was there.


@dataclass
class LivePreview:
    session: ShadowSession
    shadow_object: object
    created: bool
    rest: np.ndarray  # (3V,) float32 the caster's rest coordinates (the keys' Basis)
    saved: dict  # (object name-independent) id -> {key name: coordinates} before the drag
    had_blocker: bool
    steps: int = 0


def _key_coords(ob) -> dict:
    out = {}
    if ob is None or ob.data.shape_keys is None:
        return out
    n = len(ob.data.vertices)
    for k in ob.data.shape_keys.key_blocks:
        co = np.empty(n * 3, np.float32)
        k.data.foreach_get("co", co)
        out[k.name] = (co, k.value)
    return out


def live_begin(session: ShadowSession, *, scene=None) -> LivePreview:
    """Starts showing ``session``'s edit live (see :func:`live_step`)."""
    caster = session.caster_object()
    if caster is None:
        raise ShadowEditError("the caster of this session no longer exists")
    ob = shadow_mesh_of(caster)
    created = ob is None
    saved, had_blocker = {}, False
    if created:
        ob, _twin = apply(session, scene=scene)
    else:
        if ob.rokeby_shadow.light != session.light_object():
            raise ShadowEditError(f"the edit of '{caster.name}' is from another light; apply or remove it first")
        b = _live_self_blocker(ob)
        had_blocker = b is not None
        saved = {"mesh": _key_coords(ob), "blocker": _key_coords(b)}
    rest = np.empty(len(caster.data.vertices) * 3, np.float32)
    caster.data.vertices.foreach_get("co", rest)
    return LivePreview(session, ob, created, rest, saved, had_blocker)


def live_step(preview: LivePreview) -> None:
    """Writes the session's current shadow mesh (the drag in progress included; §6.1 by
    back-substitution) into the shadow object's key; self-shadow drags update the self-shadow mesh
    too (made and linked at the first one)."""
    s, ob = preview.session, preview.shadow_object
    local = _local_displacement(s, np.asarray(s.shadow_mesh(), np.float64))
    key_name = configuration_key(s.configuration)
    kb = ob.data.shape_keys.key_blocks
    if kb.get(key_name) is None:
        raise ShadowEditError(f"'{ob.name}' has no key '{key_name}' any more; start the drag again")
    compat.shape_key_points(kb[key_name]).foreach_set("co", preview.rest + local.astype(np.float32).ravel())
    ob.data.update_tag()
    if s.has_self_edits():
        caster, light = s.caster_object(), s.light_object()
        linked = _live_self_blocker(ob) is not None
        self_world = s.self_shadow_mesh()
        self_local = _local_displacement(s, s.rest_world + _self_displacement(s, self_world, s.rest_normals))
        _self_blocker(ob, caster, light, preview.rest, key_name, self_local)
        if not linked:
            _link(light)
    preview.steps += 1


def live_end(preview: LivePreview, *, keep: bool, scene=None) -> None:
    """Ends the live preview: ``keep`` applies the session's (committed) edit; otherwise the
    shadow object and self-shadow mesh get back exactly the keys they had (or are removed when the
    preview made them)."""
    import bpy  # noqa: PLC0415

    s = preview.session
    if keep:
        apply(s, scene=scene)
        return
    caster = s.caster_object()
    if preview.created:
        if caster is not None and shadow_mesh_of(caster) is not None:
            remove(caster)
        return
    ob = preview.shadow_object
    for part, coords in (("mesh", preview.saved.get("mesh", {})), ("blocker", preview.saved.get("blocker", {}))):
        o = ob if part == "mesh" else _live_self_blocker(ob)
        if o is None or o.data.shape_keys is None:
            continue
        for name, (co, value) in coords.items():
            k = o.data.shape_keys.key_blocks.get(name)
            if k is not None:
                k.data.foreach_set("co", co)
                k.value = value
        o.data.update()
    b = _live_self_blocker(ob)
    if b is not None and not preview.had_blocker:
        ob.rokeby_shadow.self_blocker = None
        me = b.data
        transaction.remove(b)
        if me is not None:
            transaction.remove_unused(me)
        light = ob.rokeby_shadow.light
        if _is_light(light):
            _link(light)
    (scene if scene is not None else bpy.context.scene).view_layers[0].update()
