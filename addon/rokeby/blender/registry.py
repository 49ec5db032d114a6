"""An index of the objects the add-on's features own in the open file, so that handlers never scan
``scene.objects`` (feature-agnostic: each feature adds its *kind* of object with ``add_kind``).

Production files hold tens of thousands of objects; the depsgraph and frame handlers run on
every update. Instead of looking at every object each time, they ask this index:

* each kind (a name and a test on an object, e.g. the reflection feature's mirrors, the shadow
  feature's shadow meshes and twin lights) is found by one pass over ``bpy.data.objects`` when
  the index is rebuilt, and kept by reference (keyed by ``session_uid``, so renames change
  nothing); an object belongs to the first kind (lowest ``order``) whose test it passes;
* the rebuild happens after loading a file, after undo/redo (``reset``), when a feature adds or
  removes its data (``invalidate``), when the number of objects changes (``len`` of
  ``bpy.data.objects``: duplicates, deletions, appends) and when a depsgraph update reports changed
  collections (``note_depsgraph``); a reference that turned stale (an object deleted and another
  added in the same step) triggers it too;
* which objects of a kind are in a scene is cached per scene and dropped on the same events;
* ``generation`` changes with every invalidation and rebuild, so a feature can cache what it
  derives from the index (reflection.registry's pointer counts).

With no such objects in the file, an update costs one ``len(bpy.data.objects)`` and a flag test.
"""

from __future__ import annotations

import contextlib

import bpy

_kinds: dict = {}  # kind -> (order, test)
_objects: dict = {}  # kind -> {session_uid: object}
_count = -1  # len(bpy.data.objects) at the last rebuild
_stale = True
_members: dict = {}  # (kind, scene session_uid) -> frozenset of uids of that kind in that scene
_generation = 0
_STATS = {"rebuilds": 0, "scanned": 0}


def add_kind(kind: str, test, order: int = 0) -> None:
    """Index the objects passing ``test`` under ``kind`` (an object goes to the kind of lowest
    ``order`` whose test it passes). Adding a kind again replaces its test."""
    _kinds[kind] = (order, test)
    _objects.setdefault(kind, {})
    invalidate()


def stats() -> dict:
    """Counters since the add-on was registered: rebuilds (passes over ``bpy.data.objects``) and
    scanned (objects looked at by them)."""
    return dict(_STATS)


def reset_stats():
    for k in _STATS:
        _STATS[k] = 0


def generation() -> int:
    """Changes with every invalidation and rebuild."""
    return _generation


def invalidate():
    """A feature's data was added or removed: rebuild at the next use."""
    global _stale, _generation
    _stale = True
    _generation += 1


def reset():
    """After loading a file or undo/redo: forget everything (the file is the truth again)."""
    global _stale, _count, _generation
    for objs in _objects.values():
        objs.clear()
    _members.clear()
    _stale, _count = True, -1
    _generation += 1


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


def _rebuild(n):
    global _stale, _count, _generation
    _generation += 1
    _STATS["rebuilds"] += 1
    _STATS["scanned"] += n
    tests = sorted(((order, kind, test) for kind, (order, test) in _kinds.items()), key=lambda t: (t[0], t[1]))
    found = {kind: {} for kind in _kinds}
    for ob in bpy.data.objects:
        for _order, kind, test in tests:
            if test(ob):
                found[kind][ob.session_uid] = ob
                break
    for kind, objs in found.items():
        _objects[kind] = objs
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


def _valid(kind: str) -> list:
    """The live objects of ``kind``; a stale reference triggers one rebuild."""
    for _attempt in range(2):
        out = []
        try:
            for ob in _objects.get(kind, {}).values():
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


def objects(kind: str, scene=None) -> list:
    """The objects of ``kind`` in the file, or those linked into ``scene``."""
    ensure()
    found = _valid(kind)
    if scene is None:
        return found
    key = (kind, scene.session_uid)
    inside = _members.get(key)
    if inside is None:
        inside = _members[key] = frozenset(ob.session_uid for ob in found if in_scene(ob, scene))
    return [ob for ob in found if ob.session_uid in inside]


def has_objects() -> bool:
    """Whether any kind has objects in the file."""
    ensure()
    return any(_objects.values())
