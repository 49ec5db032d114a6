"""What the add-on owns in the open file, so that its handlers never scan ``scene.objects``.

Production files hold tens of thousands of objects; the depsgraph and frame handlers run on
every update. Instead of looking at every object each time, the handlers ask this registry:

* **mirrors** (``rokeby.is_mirror``) and **shadow-edit objects** (shadow meshes, twin lights and
  lights holding links: ``Object.rokeby_shadow``; in files not yet migrated the custom properties
  in ``SHADOW_KEYS``) are found by one pass over
  ``bpy.data.objects`` when the registry is rebuilt, and kept by reference (keyed by
  ``session_uid``, so renames change nothing);
* the rebuild happens after loading a file, after undo/redo, when Rokeby data is added or removed
  through the add-on (``invalidate``), when the number of objects changes (``len`` of
  ``bpy.data.objects``: duplicates, deletions, appends) and when a depsgraph update reports changed
  collections (``note_depsgraph``); a reference that turned stale (an object deleted and another
  added in the same step) triggers it too;
* which mirrors are in a scene is cached per scene and dropped on the same events;
* the **handles and region centres, carriers and edited materials of each mirror** are remembered
  (``refresh``, a few pointer reads per mirror and update), so that when a mirror is deleted with
  X what only it used goes with it (``tidy``), and a handle deleted with X (which Blender keeps
  alive through the constraint's pointer) is released: the pointer is cleared, so the row is
  flagged, and the object freed.

With no Rokeby data in the file, an update costs one ``len(bpy.data.objects)`` and a flag test.
"""

from __future__ import annotations

import contextlib

import bpy

from ..blender import transaction
from ..blender.compat import stored_group
from ..core import schema

# Custom properties of the objects a shadow edit makes (rokeby.shadow).
SHADOW_KEYS = schema.SHADOW_LEGACY_KEYS  # before shadow links were pointers (shadow.migrate)
# On handles and region centres the add-on made (api); older files: membership of HANDLE_COLLECTION.
MADE_KEY = schema.MADE_KEY
HANDLE_COLLECTION = schema.HANDLE_COLLECTION

_mirrors: dict = {}  # session_uid -> mirror object
_shadow: dict = {}  # session_uid -> shadow mesh or twin light
_count = -1  # len(bpy.data.objects) at the last rebuild
_stale = True
_members: dict = {}  # scene session_uid -> frozenset of mirror uids in that scene
_records: dict = {}  # mirror uid -> (its name, what it uses: dict of lists)
_counts = None  # object uid -> how many Rokeby pointers use it (None: recount)
_STATS = {"rebuilds": 0, "scanned": 0, "released": 0, "removed": 0}


def stats() -> dict:
    """Counters since the add-on was registered: rebuilds (passes over ``bpy.data.objects``),
    scanned (objects looked at by them), released (handles deleted with X whose pointer was
    cleared), removed (objects removed because only a deleted mirror used them)."""
    return dict(_STATS)


def reset_stats():
    for k in _STATS:
        _STATS[k] = 0


def invalidate():
    """Rokeby data was added or removed: rebuild at the next use."""
    global _stale, _counts
    _stale, _counts = True, None


def pointers_changed():
    """A constraint, region or mirror setting changed (property update): recount pointer users."""
    global _counts
    _counts = None


def pointer_counts() -> dict:
    """How many of the add-on's pointers use each object (by ``session_uid``)."""
    global _counts
    found = mirrors()
    if _counts is None:
        _counts = _refcounts(found)
    return _counts


def reset():
    """After loading a file or undo/redo: forget everything (the file is the truth again)."""
    global _stale, _count, _counts
    _counts = None
    _mirrors.clear()
    _shadow.clear()
    _members.clear()
    _records.clear()
    _stale, _count = True, -1


def note_depsgraph(depsgraph):
    """Called first by the depsgraph handler: a changed collection (objects linked, unlinked,
    deleted or added, a collection excluded) may change what is in which scene."""
    global _stale
    try:
        if depsgraph.id_type_updated("COLLECTION"):
            _members.clear()
            _stale = True
    except (AttributeError, ReferenceError, TypeError):
        _stale = True


def _is_mirror(ob) -> bool:
    group = stored_group(ob, schema.OBJECT_PROP)
    return group is not None and hasattr(group, "get") and bool(group.get("is_mirror", 0))


def _is_shadow_part(ob) -> bool:
    """Shadow meshes, twin lights and lights holding links (``Object.rokeby_shadow``), and in files
    not yet migrated the custom properties of ``SHADOW_KEYS``."""
    return stored_group(ob, schema.OBJECT_SHADOW_PROP) is not None or any(key in ob for key in SHADOW_KEYS)


def _rebuild(n):
    global _stale, _count, _counts
    _counts = None
    _STATS["rebuilds"] += 1
    _STATS["scanned"] += n
    mirrors, shadow = {}, {}
    for ob in bpy.data.objects:
        if _is_mirror(ob):
            mirrors[ob.session_uid] = ob
        elif _is_shadow_part(ob):
            shadow[ob.session_uid] = ob
    _mirrors.clear()
    _mirrors.update(mirrors)
    _shadow.clear()
    _shadow.update(shadow)
    _members.clear()
    _stale, _count = False, len(bpy.data.objects)


_pinned = 0


@contextlib.contextmanager
def pinned():
    """For the length of a handler run: count the objects once at the start, not on every use
    (``len(bpy.data.objects)`` walks a list: 0.4 ms at 10,000 objects). What the add-on itself
    adds or removes meanwhile calls ``invalidate``, or shows as a stale reference."""
    global _pinned
    ensure()
    _pinned += 1
    try:
        yield
    finally:
        _pinned -= 1


def ensure():
    """Rebuild if something structural changed since the last use (cheap when nothing did)."""
    if _pinned and not _stale:
        return
    n = len(bpy.data.objects)
    if _stale or n != _count:
        _rebuild(n)


def _valid(objs: dict) -> list:
    """The live objects of ``objs``; a stale reference triggers one rebuild."""
    for _attempt in range(2):
        out = []
        try:
            for ob in objs.values():
                ob.name  # noqa: B018 - raises ReferenceError for a removed object
                out.append(ob)
            return out
        except ReferenceError:
            invalidate()
            ensure()
    return []


def in_scene(ob, scene) -> bool:
    """Whether ``ob`` is linked into ``scene``, by identity: a lookup by name finds the wrong
    object when a linked asset and its library override share the name."""
    return any(s == scene for s in ob.users_scene)


def mirrors(scene=None) -> list:
    """Every mirror in the file, or those linked into ``scene``."""
    ensure()
    found = [ob for ob in _valid(_mirrors) if ob.rokeby.is_mirror]
    if scene is None:
        return found
    key = scene.session_uid
    inside = _members.get(key)
    if inside is None:
        inside = _members[key] = frozenset(ob.session_uid for ob in found if in_scene(ob, scene))
    return [ob for ob in found if ob.session_uid in inside]


def shadow_objects() -> list:
    """Shadow meshes and twin lights of shadow edits (rokeby.shadow)."""
    ensure()
    return _valid(_shadow)


def has_data() -> bool:
    """Whether the handlers have anything to do: mirrors, shadow edits, or what a deleted mirror
    left behind."""
    ensure()
    return bool(_mirrors or _shadow or _records)


# --- what each mirror uses ---------------------------------------------------------------------


def _pointers(mirror):
    """(row, attribute, object) of every object pointer of ``mirror``'s Rokeby data."""
    s = mirror.rokeby
    out = []
    for c in s.constraints:
        for attr in ("surface_handle", "target_handle"):
            ob = getattr(c, attr)
            if ob is not None:
                out.append((c, attr, ob))
    for rg in s.regions:
        if rg.center is not None:
            out.append((rg, "center", rg.center))
    if s.map_origin is not None:
        out.append((s, "map_origin", s.map_origin))
    return out


def _uses(mirror) -> dict:
    from .render import rendering  # noqa: PLC0415

    carrier = getattr(mirror.rokeby, "field_carrier", None)
    return {
        "objects": [ob for _row, _attr, ob in _pointers(mirror)],
        "carrier": [carrier] if carrier is not None else [],
        "materials": rendering.edited_materials(mirror),
    }


def refresh(found=None) -> None:
    """Remember what each mirror uses now (called by the handlers after ``tidy``)."""
    pointers_changed()
    for m in mirrors() if found is None else found:
        try:
            _records[m.session_uid] = (m.name, _uses(m))
        except ReferenceError:
            continue


def made_by_addon(ob) -> bool:
    """Whether the add-on made ``ob`` (a handle or region centre), so that it goes with the last
    mirror using it; empties an artist brought (a region centre of their own) stay."""
    if ob.get(MADE_KEY):
        return True
    coll = bpy.data.collections.get(HANDLE_COLLECTION)
    return coll is not None and any(o == ob for o in coll.objects)


def _refcounts(found) -> dict:
    counts: dict = {}
    for m in found:
        for _row, _attr, ob in _pointers(m):
            counts[ob.session_uid] = counts.get(ob.session_uid, 0) + 1
    return counts


def release_deleted(found=None) -> list:
    """Handles and region centres deleted with X (Blender only unlinks an object that a pointer
    still uses): their pointers are cleared, so the rows are flagged (the report says the handle
    was deleted), and the object, now unused, is removed. Returns one message per object."""
    found = mirrors() if found is None else found
    counts = _refcounts(found)
    msgs = []
    for m in found:
        for row, attr, ob in _pointers(m):
            try:
                if ob.library is not None or ob.users - int(ob.use_fake_user) > counts.get(ob.session_uid, 0):
                    continue  # still in a collection (or used by something else): alive
                name = ob.name
            except ReferenceError:
                continue
            for m2 in found:
                for row2, attr2, ob2 in _pointers(m2):
                    if ob2 == ob:
                        setattr(row2, attr2, None)
            if ob.users == 0:
                bpy.data.objects.remove(ob)
            _STATS["released"] += 1
            msgs.append(f"'{m.name}': '{name}' was deleted; its row is flagged (undo brings it back)")
    return msgs


def tidy(found=None) -> list:
    """After deletions: release handles deleted with X (``release_deleted``), and remove what a
    deleted mirror alone used (its handles and region centres the add-on made, its field carrier,
    the render nodes in materials no other mirror edits, an emptied handle collection, unused node
    groups). Returns messages for the console."""
    found = mirrors() if found is None else found
    pointers_changed()
    msgs = release_deleted(found)
    live = {m.session_uid for m in found}
    gone = [uid for uid in _records if uid not in live]
    if gone:
        try:
            present = {ob.session_uid for ob in bpy.data.objects}
        except ReferenceError:  # pragma: no cover - defensive
            present = set()
        leftovers = {"objects": [], "carrier": [], "materials": []}
        for uid in gone:
            name, uses = _records.pop(uid)
            if uid in present:
                continue  # not deleted: Remove Mirror (which cleans up itself) or is_mirror unset
            for key, items in uses.items():
                leftovers[key].extend(items)
            msgs.append(f"'{name}' was deleted: the handles, centres and render nodes only it used are removed")
        if any(leftovers.values()):
            release(found, **leftovers)
    return msgs


def _alive(ob) -> bool:
    try:
        ob.name  # noqa: B018
        return True
    except (ReferenceError, AttributeError):
        return False


def release(found, objects=(), carrier=(), materials=()) -> None:
    """Remove what no mirror of ``found`` uses any more: add-on-made handles and centres in
    ``objects``, unused ``carrier`` objects, the render nodes of ``materials`` no mirror keeps;
    then the handle collection when empty and the add-on's unused node groups."""
    from .render import rendering  # noqa: PLC0415

    used = _refcounts(found)
    for ob in dict.fromkeys(o for o in objects if _alive(o)):
        if ob.library is None and used.get(ob.session_uid, 0) == 0 and made_by_addon(ob):
            transaction.remove(ob)
            _STATS["removed"] += 1
    for ob in dict.fromkeys(o for o in carrier if _alive(o)):
        if ob.users == 0:
            mesh = ob.data
            transaction.remove(ob)
            if mesh is not None:
                transaction.remove_unused(mesh)
            _STATS["removed"] += 1
    kept = {mat for m in found if rendering.kept(m) for mat in rendering.edited_materials(m)}
    for mat in dict.fromkeys(m for m in materials if _alive(m)):
        if mat not in kept and mat.library is None:
            rendering.uninstall_material(mat)
    drop_empty_handle_collection()
    drop_unused_node_groups()


def drop_empty_handle_collection() -> bool:
    """Remove the "Rokeby Handles" collection once it holds nothing (it is made with the first
    handle, so a file goes back to the collections it had)."""
    coll = bpy.data.collections.get(HANDLE_COLLECTION)
    if coll is None or coll.library is not None or len(coll.objects) or len(coll.children) or transaction.doomed(coll):
        return False
    transaction.remove(coll)
    return True


def _our_group(ng) -> bool:
    names = {schema.NORMAL_GROUP, schema.DIRECTION_GROUP, schema.REFRACTION_GROUP, schema.REFLMAP_SHARED_GROUP,
             schema.VG_NODE_GROUP, schema.TRANSFER_GROUP}
    return ng.name in names or ng.name.startswith(schema.REFLMAP_MIRROR_GROUP_PREFIX) or ng.get(schema.COPY_OF_KEY) is not None


def drop_unused_node_groups() -> int:
    """Remove the add-on's node groups that nothing uses any more (the edited-normal and
    direction groups, the vertex-group reader, the field transfer, reflection-map groups,
    group-local copies), so that removing the last mirror leaves ``bpy.data`` as it was."""
    removed = 0
    while True:
        doomed = [ng for ng in bpy.data.node_groups
                  if ng.users == 0 and not ng.use_fake_user and ng.library is None and _our_group(ng)]
        if not doomed:
            return removed
        if transaction.active():
            # Inside an operation: removed when it succeeds (and what they used, with them).
            transaction.later(drop_unused_node_groups)
            return removed
        for ng in doomed:
            bpy.data.node_groups.remove(ng)
            removed += 1


def of_mirrors(obj=None, *_args, **_kwargs) -> list:
    """For ``transaction.atomic(materials=registry.of_mirrors)``: the materials of ``obj`` and of every mirror (the
    render nodes of all of them may be synced)."""
    obs = [*mirrors(), obj]
    out = []
    for ob in obs:
        try:
            out += [s.material for s in ob.material_slots if s.material is not None]
        except (AttributeError, ReferenceError):
            continue
    return out
