"""Copies of a mirror (Shift+D, Alt+D, or any copy of the object) get handles of their own.

A copy starts with the original's settings, constraints and regions, and so with pointers to the
original's handles: its red handles would be kept on the original by their Shrinkwrap, and
moving a handle of one would edit both. The rule: a mirror with a constraint whose red handle
(or a geodesic region whose centre) is kept on another mirror that uses the same handle is a copy
of that mirror. Before it is evaluated, every handle it shares with the original (red, green,
region centres) is duplicated for it:

- in the same collections, named after the copy;
- its "Rokeby: stay on mirror" Shrinkwrap kept on the copy;
- placed where the original's sits relative to the original, moved with the copy: the duplicate is
  parented to the copy (with the parent inverse of the original's transform), so while the artist
  places a fresh Shift+D copy its handles come along; Alt+P ▸ Clear Parent and Keep Transform
  detaches them. A handle parented to something else (a highlight's green handle follows its
  light) keeps that parent and stays where it is.

The copy keeps its constraints' generating eyes and views. Handles selected and duplicated
together with the mirror are already the copy's own (Blender remaps the pointers), so nothing
happens then. A Euclidean region centre that several mirrors use on purpose stays shared unless
the mirror is a copy found by the rule above.
"""

from __future__ import annotations

from ..core import schema


def shrinkwrap_target(handle):
    """The object a handle's "Rokeby: stay on mirror" Shrinkwrap keeps it on (None: it has none,
    or no target)."""
    for con in handle.constraints:
        if con.type == "SHRINKWRAP" and con.name.startswith(schema.SHRINKWRAP_NAME):
            return con.target
    return None


def _handles(mirror):
    s = mirror.rokeby
    for c in s.constraints:
        yield c.surface_handle
        yield c.target_handle
    for rg in s.regions:
        yield rg.center


def original_of(mirror):
    """The mirror that ``mirror`` is a copy of (see the module docstring), or None."""
    s = mirror.rokeby
    kept = [c.surface_handle for c in s.constraints] + [rg.center for rg in s.regions if rg.kind == "GEODESIC"]
    for h in kept:
        if h is None:
            continue
        try:
            target = shrinkwrap_target(h)
        except ReferenceError:
            continue
        if target is None or target == mirror or target.type != "MESH" or not target.rokeby.is_mirror:
            continue
        if any(x == h for x in _handles(target)):
            return target
    return None


def separate_copies(mirrors) -> list:
    """Give every copy among ``mirrors`` handles of its own; returns one line per copy, saying
    what was done (empty: nothing to do, the usual case, at the cost of a look at each red
    handle's constraints)."""
    lines = []
    for m in mirrors:
        try:
            orig = original_of(m)
        except ReferenceError:
            continue
        if orig is not None:
            n = _own_handles(m, orig)
            lines.append(f"'{m.name}' is a copy of mirror '{orig.name}': it got {n} handle(s) of its own")
    return lines


def _own_handles(copy, orig) -> int:
    import bpy  # noqa: PLC0415

    shared = {h for h in _handles(orig) if h is not None}
    made: dict = {}

    def own(h):
        if h is None or h not in shared:
            return h
        if h in made:
            return made[h]
        new = h.copy()  # constraints, display, animation and parent come along
        new.name = (copy.name + h.name[len(orig.name):]) if h.name.startswith(orig.name) else f"{h.name} ({copy.name})"
        colls = list(h.users_collection) or [bpy.context.scene.collection]
        for coll in colls:
            if coll.library is None and new.name not in coll.objects:
                coll.objects.link(new)
        for con in new.constraints:
            if getattr(con, "target", None) == orig:
                con.target = copy
        if new.parent is None:
            # world = copy · orig⁻¹ · basis: where it sat on the original, now on the copy
            new.parent = copy
            new.matrix_parent_inverse = orig.matrix_world.inverted()
        elif new.parent == orig:
            new.parent = copy  # same parent inverse: same place relative to the copy
        made[h] = new
        return new

    s = copy.rokeby
    for c in s.constraints:
        c.surface_handle = own(c.surface_handle)
        c.target_handle = own(c.target_handle)
    for rg in s.regions:
        rg.center = own(rg.center)
    return len(made)


__all__ = ["original_of", "separate_copies"]
