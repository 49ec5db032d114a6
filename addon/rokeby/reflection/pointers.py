"""The reflection feature's mirrors and the objects their pointers use (handles, region centres,
map origins): the lower half of ``registry``, which the evaluator and the render set-up read
without importing what the registry's tidying needs (rendering).

Mirrors are this feature's kind in the add-on's object index (``rokeby.blender.registry``);
``pointer_counts`` counts, per object, the mirrors' pointers that use it, recounted after a
property update (``pointers_changed``) or a rebuild of the index.
"""

from __future__ import annotations

from ..blender import registry as index
from ..blender.compat import stored_group
from ..core import schema

MIRROR_KIND = "mirror"  # this feature's kind in the object index (blender.registry)

_counts = None  # (index generation, {object uid: how many Rokeby pointers use it}); None: recount


def reset():
    """After loading a file or undo/redo (registry.reset): forget the counts and the index."""
    global _counts
    _counts = None
    index.reset()


def invalidate():
    """Rokeby data was added or removed: rebuild at the next use."""
    global _counts
    _counts = None
    index.invalidate()


def pointers_changed():
    """A constraint, region or mirror setting changed (property update): recount pointer users."""
    global _counts
    _counts = None


def pointer_counts() -> dict:
    """How many of the add-on's pointers use each object (by ``session_uid``)."""
    global _counts
    found = mirrors()
    if _counts is None or _counts[0] != index.generation():
        _counts = (index.generation(), _refcounts(found))
    return _counts[1]


def _is_mirror(ob) -> bool:
    group = stored_group(ob, schema.OBJECT_PROP)
    return group is not None and hasattr(group, "get") and bool(group.get("is_mirror", 0))


index.add_kind(MIRROR_KIND, _is_mirror, order=0)


def mirrors(scene=None) -> list:
    """Every mirror in the file, or those linked into ``scene``."""
    found = [ob for ob in index.objects(MIRROR_KIND) if ob.rokeby.is_mirror]
    if scene is None:
        return found
    inside = {ob.session_uid for ob in index.objects(MIRROR_KIND, scene)}
    return [ob for ob in found if ob.session_uid in inside]


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


def _refcounts(found) -> dict:
    counts: dict = {}
    for m in found:
        for _row, _attr, ob in _pointers(m):
            counts[ob.session_uid] = counts.get(ob.session_uid, 0) + 1
    return counts


def of_mirrors(obj=None, *_args, **_kwargs) -> list:
    """For ``transaction.atomic(materials=pointers.of_mirrors)``: the materials of ``obj`` and of every mirror (the
    render nodes of all of them may be synced)."""
    obs = [*mirrors(), obj]
    out = []
    for ob in obs:
        try:
            out += [s.material for s in ob.material_slots if s.material is not None]
        except (AttributeError, ReferenceError):
            continue
    return out
