"""What the reflection feature owns in the open file, so that its handlers never scan ``scene.objects``.

Production files hold tens of thousands of objects; the depsgraph and frame handlers run on
every update. Instead of looking at every object each time, the handlers ask this registry:

* **mirrors** (``rokeby.is_mirror``) are this feature's kind in the add-on's object index
  (``rokeby.blender.registry``: one pass over ``bpy.data.objects`` when it is rebuilt, objects kept
  by reference; the shadow feature indexes its shadow meshes and twin lights there too). The
  index is rebuilt after loading a file, after undo/redo, when Rokeby data is added or removed
  through the add-on (``invalidate``), when the number of objects changes and when a depsgraph
  update reports changed collections (``note_depsgraph``); which mirrors are in a scene is cached
  per scene and dropped on the same events;
* the **handles and region centres, carriers and edited materials of each mirror** are remembered
  (``refresh``, a few pointer reads per mirror and update), so that when a mirror is deleted with
  X what only it used goes with it (``tidy``), and a handle deleted with X (which Blender keeps
  alive through the constraint's pointer) is released: the pointer is cleared, so the row is
  flagged, and the object freed.

With no Rokeby data in the file, an update costs one ``len(bpy.data.objects)`` and a flag test.
"""

from __future__ import annotations

import bpy

from ..blender import registry as index
from ..blender import transaction
from ..core import schema
from . import pointers
from .pointers import _pointers, _refcounts, mirrors, pointers_changed
from .render import rendering

# schema.MADE_KEY is on handles and region centres the add-on made (api); older files: membership of
# schema.HANDLE_COLLECTION.

_records: dict = {}  # mirror uid -> (its name, what it uses: dict of lists)
_STATS = {"released": 0, "removed": 0}


def stats() -> dict:
    """Counters since the add-on was registered: rebuilds (passes over ``bpy.data.objects``),
    scanned (objects looked at by them), released (handles deleted with X whose pointer was
    cleared), removed (objects removed because only a deleted mirror used them)."""
    return {**index.stats(), **_STATS}


def reset_stats():
    index.reset_stats()
    for k in _STATS:
        _STATS[k] = 0


def reset():
    """After loading a file or undo/redo: forget everything (the file is the truth again)."""
    _records.clear()
    pointers.reset()


def has_data() -> bool:
    """Whether the handlers have anything to do: mirrors, other features' objects (shadow
    edits), or what a deleted mirror left behind."""
    return index.has_objects() or bool(_records)


# --- what each mirror uses ---------------------------------------------------------------------


def _uses(mirror) -> dict:
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
    if ob.get(schema.MADE_KEY):
        return True
    coll = bpy.data.collections.get(schema.HANDLE_COLLECTION)
    return coll is not None and any(o == ob for o in coll.objects)


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
    coll = bpy.data.collections.get(schema.HANDLE_COLLECTION)
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
