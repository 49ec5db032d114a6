"""Shadow edits stay whole when an artist deletes, restores or duplicates one of their parts
(:func:`repair`, run by the add-on's update step), and files that stored the parts' names get
pointers at load (:func:`migrate`). Renaming anything keeps an edit: every link is a pointer."""

from __future__ import annotations

from ..blender import transaction
from ..core import schema
from .linking import (
    _COLLECTION_ATTRS,
    _OURS,
    _collect_orphan_collections,
    _collection_name,
    _data_version,
    _edits_of,
    _in_scene,
    _is_light,
    _link,
    _live_self_blocker,
    _only_in_linking_collections,
    _owns_twin,
    _parts,
    _registered,
    _remove_twin,
    _self_blockers,
    _unlink,
)


def repair(scene=None) -> list[str]:
    """Keeps shadow edits whole when an artist deletes something they use (called by the
    handlers; writes only when something is broken, so the update it causes settles):

    * caster or light gone (removed, or deleted with X and so in no scene): the shadow mesh is kept
      (undo or a new edit can use it) but hidden from shadow rays, and the linking is taken down,
      so the remaining lights shade as without the edit; an object deleted with X is no longer
      pointed to (Blender purges it, as any object nothing uses), one only in collections that
      left the scene is, and the edit comes back when it does;
    * shadow mesh gone: the twin and the linking go, the light's own linking comes back;
    * twin light or a linking collection gone: made again from the shadow mesh;
    * a copy of a light (Shift+D) that carried the links along gets its own linking back.

    Renames change nothing: every link is a pointer. Returns one message per repair."""
    msgs = []
    meshes, twins, lights = _parts()
    live = []
    for ob in meshes:
        links = ob.rokeby_shadow
        caster, light = links.caster, links.light
        missing = "caster" if not _in_scene(caster) else ("light" if not _is_light(light) else None)
        b = _live_self_blocker(ob)
        if missing is not None:
            if ob.visible_shadow:
                ob.visible_shadow = False
                links.switched_off = True
                msgs.append(f"'{ob.name}': its {missing} is gone; it no longer casts shadows (undo brings it back)")
            if b is not None and b.visible_shadow:
                b.visible_shadow = False
            for attr in ("caster", "light"):
                # Deleted with X but kept in bpy.data by our own references: let Blender purge it,
                # as it does an object nothing uses.
                o = getattr(links, attr)
                if o is not None and not _in_scene(o) and _only_in_linking_collections(o):
                    setattr(links, attr, None)
            continue
        if links.switched_off:  # its caster and light are back (a collection linked to the scene again)
            ob.visible_shadow, links.switched_off = True, False
            if b is not None:
                b.visible_shadow = True
            msgs.append(f"'{ob.name}': its caster and light are back; it casts the edited shadow again")
        if light not in live:
            live.append(light)
    for light in live:
        links = light.rokeby_shadow
        twin = links.twin
        colls = [getattr(links, a) for a in _COLLECTION_ATTRS]
        ll = light.light_linking
        edits = _edits_of(light, meshes)
        whole = (_in_scene(twin) and _owns_twin(light) and twin.parent == light and None not in colls
                 and ll.receiver_collection == colls[0] and ll.blocker_collection == colls[1]
                 and twin.light_linking.receiver_collection == colls[2] and twin.light_linking.blocker_collection == colls[3]
                 and all(c.name in colls[0].objects and s.name in colls[1].objects for c, s in edits)
                 and all((c.name in colls[1].objects) == (b is not None) and (b is None or b.name in colls[3].objects)
                         for c, s, b in ((c, s, _live_self_blocker(s)) for c, s in edits)))
        if not whole:
            _link(light, meshes)
            msgs.append(f"'{light.name}': the twin light or linking of its shadow edit was missing and is made again")
    for light in lights:
        if light not in live:
            copy = not _owns_twin(light)
            _unlink(light)
            msgs.append(f"'{light.name}': " + ("a copy of a light with shadow edits; it gets its own linking back" if copy
                                                 else "its shadow edit is gone; the twin light and the linking are removed"))
    for twin in twins:
        try:
            light = twin.rokeby_shadow.light
        except ReferenceError:
            continue  # removed with its light above
        if light is None or light not in live or light.rokeby_shadow.twin != twin:
            name = light.name if light is not None else "a deleted light"
            _remove_twin(twin)
            msgs.append(f"'{name}': its shadow edit is gone; the twin light and the linking are removed")
    for b in _self_blockers():
        owners = [ob for ob in meshes if ob.rokeby_shadow.self_blocker == b]
        if not owners:

            name, me = b.name, b.data
            transaction.remove(b)
            if me is not None:
                transaction.remove_unused(me)
            msgs.append(f"'{name}': its shadow mesh is gone; the self-shadow mesh is removed")
    if msgs:
        _collect_orphan_collections()
        if scene is not None:
            scene.view_layers[0].update()
    return msgs


def migrate() -> list[str]:
    """Files saved before shadow data version 1 named the parts of an edit (custom properties
    ``rokeby_shadow_of``, ``rokeby_light`` on the shadow mesh, ``rokeby_twin_of`` on the twin,
    ``rokeby_linking_before`` on the light; linking collections called '<light> · <role>'): those
    names become pointers, resolved once, at load (handlers.migrate_file). Returns one message per
    migrated part."""
    import bpy  # noqa: PLC0415

    if not _registered():
        return []
    objs, colls = bpy.data.objects, bpy.data.collections
    version = _data_version()
    msgs = []
    local = [o for o in objs if o.library is None]
    for ob in local:
        if schema.SHADOW_LEGACY_SHADOW_OF_KEY in ob and schema.SHADOW_LEGACY_LIGHT_KEY in ob:
            links = ob.rokeby_shadow
            caster, light = objs.get(str(ob[schema.SHADOW_LEGACY_SHADOW_OF_KEY])), objs.get(str(ob[schema.SHADOW_LEGACY_LIGHT_KEY]))
            links.role, links.caster, links.light, links.data_version = "SHADOW_MESH", caster, light, version
            del ob[schema.SHADOW_LEGACY_SHADOW_OF_KEY], ob[schema.SHADOW_LEGACY_LIGHT_KEY]
            msgs.append(f"'{ob.name}': shadow mesh of {caster.name if caster else None!r} from {light.name if light else None!r}")
    for ob in local:
        if schema.SHADOW_LEGACY_TWIN_OF_KEY in ob:
            light = objs.get(str(ob[schema.SHADOW_LEGACY_TWIN_OF_KEY]))
            light = light if light is not None and light.type == "LIGHT" else None
            t = ob.rokeby_shadow
            t.role, t.light, t.data_version = "TWIN", light, version
            if light is not None and light.rokeby_shadow.twin is None:
                light.rokeby_shadow.twin = ob
            del ob[schema.SHADOW_LEGACY_TWIN_OF_KEY]
            msgs.append(f"'{ob.name}': twin of {light.name if light else None!r}")
    for ob in local:
        if schema.SHADOW_LEGACY_LINKING_BEFORE_KEY in ob:
            before = [str(n) for n in ob[schema.SHADOW_LEGACY_LINKING_BEFORE_KEY]] + ["", ""]
            links = ob.rokeby_shadow
            links.linking_saved = True
            links.receivers_before = colls.get(before[0]) if before[0] else None
            links.blockers_before = colls.get(before[1]) if before[1] else None
            for attr, role in zip(_COLLECTION_ATTRS, _OURS):
                c = colls.get(_collection_name(ob.name, role))
                if c is not None and c.library is None:
                    c[schema.SHADOW_LINKING_TAG] = role
                    setattr(links, attr, c)
            del ob[schema.SHADOW_LEGACY_LINKING_BEFORE_KEY]
            msgs.append(f"'{ob.name}': linking of its shadow edits")
    return msgs
