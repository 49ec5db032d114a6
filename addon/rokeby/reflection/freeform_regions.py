"""Free-form regions: the painted vertex group, followed through renames. A Geometry Nodes reader
modifier per used group copies its weights into a point attribute of the evaluated mesh, which
the evaluator reads with foreach_get (:func:`_vertex_group_weights`).

Vertex groups have no pointer, so a region stores its group's name (what the sidebar shows)
and index, and the mirror the names of all its groups as of the last update
(``vertex_group_names``, JSON). A name that disappeared while the group count stayed the same
and another name, new to the list, took its index, is a rename: the region follows it. Anything
else (a deleted group, groups added and removed at once) leaves the name as it is, and the
region warns naming it."""

from __future__ import annotations

import numpy as np

from ..core import schema
from ..core.errors import RokebyError


def _vertex_group_weights(obj, me, group: str) -> np.ndarray:
    """Per-vertex weights of a vertex group, read without a Python loop: the reader modifier
    (a Geometry Nodes 'Store Named Attribute') copies the group into a float point attribute of
    the evaluated mesh. Only a live, enabled reader counts: a copy of the weights baked into the
    mesh (the reader applied, Convert ▸ Mesh) would no longer follow the painting."""
    if obj.vertex_groups.get(group) is None:
        raise RokebyError(f"vertex group '{group}' was deleted (or renamed while the add-on could not follow)")
    mod = find_reader(obj, group)
    if mod is None:
        raise RokebyError(f"vertex group '{group}' has no reader modifier '{schema.VG_MODIFIER_PREFIX}{group}'")
    if not mod.show_viewport:
        raise RokebyError(f"the reader modifier '{mod.name}' of vertex group '{group}' is disabled in the viewport; enable it")
    attr = me.attributes.get(schema.REGION_ATTRIBUTE_PREFIX + group)
    if attr is None or attr.domain != "POINT" or attr.data_type != "FLOAT":
        raise RokebyError(f"the reader modifier '{mod.name}' of vertex group '{group}' gave no weights (is a modifier above it removing them?)")
    w = np.empty(len(me.vertices), dtype=np.float32)
    attr.data.foreach_get("value", w)
    return np.clip(np.nan_to_num(w, nan=0.0), 0.0, 1.0)


def _reader_tree(ng) -> bool:
    return ng is not None and ng.bl_idname == "GeometryNodeTree" and ng.name.split(".")[0] == schema.VG_NODE_GROUP


def vertex_group_reader():
    """The Geometry Nodes group that copies a vertex group into a float point attribute, so the
    evaluator reads painted weights with foreach_get instead of a loop over vertices."""
    import bpy  # noqa: PLC0415

    ng = bpy.data.node_groups.get(schema.VG_NODE_GROUP)
    if ng is not None and ng.bl_idname == "GeometryNodeTree" and ng.library is None:
        return ng
    ng = bpy.data.node_groups.new(schema.VG_NODE_GROUP, "GeometryNodeTree")
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket("Vertex Group", in_out="INPUT", socket_type="NodeSocketString")
    ng.interface.new_socket("Attribute", in_out="INPUT", socket_type="NodeSocketString")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi = ng.nodes.new("NodeGroupInput")
    go = ng.nodes.new("NodeGroupOutput")
    named = ng.nodes.new("GeometryNodeInputNamedAttribute")
    named.data_type = "FLOAT"
    store = ng.nodes.new("GeometryNodeStoreNamedAttribute")
    store.data_type = "FLOAT"
    store.domain = "POINT"
    ng.links.new(gi.outputs["Geometry"], store.inputs["Geometry"])
    ng.links.new(gi.outputs["Vertex Group"], named.inputs["Name"])
    ng.links.new(gi.outputs["Attribute"], store.inputs["Name"])
    ng.links.new(named.outputs["Attribute"], store.inputs["Value"])
    ng.links.new(store.outputs["Geometry"], go.inputs["Geometry"])
    return ng


def _reader_ids(mod) -> dict:
    return {item.name: item.identifier for item in mod.node_group.interface.items_tree if getattr(item, "in_out", "") == "INPUT"}


def _reader_group(mod) -> "str | None":
    """The vertex group a reader modifier reads (None: none set)."""
    from ..blender import compat  # noqa: PLC0415

    ident = _reader_ids(mod).get("Vertex Group")
    return compat.modifier_input(mod, ident) if ident is not None else None


def find_reader(obj, group: str):
    """The reader modifier of ``group`` on ``obj`` (found by what it reads, not by its name,
    which Blender may have shortened), or None."""
    for mod in obj.modifiers:
        if mod.type == "NODES" and _reader_tree(mod.node_group) and _reader_group(mod) == group:
            return mod
    return None


def _readers(obj) -> list:
    return [mod for mod in obj.modifiers if mod.type == "NODES" and _reader_tree(mod.node_group)]


def ensure_reader(obj, group: str, renamed_from: "str | None" = None) -> "str | None":
    """Make sure ``group`` has a live reader modifier: made when missing (a reader that was
    applied, e.g. by Convert ▸ Mesh, leaves a baked copy of the weights in the mesh: it is
    removed), repointed after a rename. Returns what changed when the evaluated mesh must be
    evaluated again before the weights can be read (None: nothing)."""
    from ..blender import compat  # noqa: PLC0415

    attribute = schema.REGION_ATTRIBUTE_PREFIX + group
    mod = find_reader(obj, group)
    why = None
    if mod is None and renamed_from is not None:
        mod = find_reader(obj, renamed_from)
        why = f"vertex group '{renamed_from}' was renamed to '{group}'; its free-form region follows it"
    if mod is None:
        baked = obj.data.attributes.get(attribute)
        if baked is not None:
            obj.data.attributes.remove(baked)
            why = f"the reader modifier of vertex group '{group}' was applied, which froze its weights; it was added again so the region follows the painting"
        else:
            why = f"vertex group '{group}' had no reader modifier; it was added"
        mod = obj.modifiers.new(schema.VG_MODIFIER_PREFIX + group, "NODES")
        mod.node_group = vertex_group_reader()
        mod.show_in_editmode = False
    ids = _reader_ids(mod)
    if compat.modifier_input(mod, ids["Vertex Group"]) != group or compat.modifier_input(mod, ids["Attribute"]) != attribute:
        compat.set_modifier_input(mod, ids["Vertex Group"], group)
        compat.set_modifier_input(mod, ids["Attribute"], attribute)
        why = why or f"the reader modifier of vertex group '{group}' was repointed"
    if renamed_from is not None and mod.name.startswith(schema.VG_MODIFIER_PREFIX):
        mod.name = schema.VG_MODIFIER_PREFIX + group
    if why is not None:
        obj.update_tag()
    return why


def drop_unused_readers(obj, used=None):
    """Remove the reader modifiers of groups no free-form region uses (and their copies)."""
    if used is None:
        used = {rg.vertex_group for rg in obj.rokeby.regions if rg.kind == "FREEFORM" and rg.vertex_group}
    seen = set()
    for mod in _readers(obj):
        group = _reader_group(mod)
        if group not in used or group in seen:
            obj.modifiers.remove(mod)
        else:
            seen.add(group)


def _renamed(old: str, index: int, names: list, snapshot: "list | None") -> "str | None":
    """The new name of group ``old`` (at ``index`` at the last update) when it was renamed, else None."""
    if snapshot is None or not 0 <= index < len(names) or len(names) != len(snapshot) or snapshot[index] != old:
        return None
    new = names[index]
    return new if new not in snapshot else None


def _group_names(obj) -> "list | None":
    import json  # noqa: PLC0415

    raw = obj.rokeby.vertex_group_names
    try:
        names = json.loads(raw) if raw else None
    except ValueError:
        return None
    return names if isinstance(names, list) else None


def remember_groups(obj):
    """Store the names of ``obj``'s vertex groups as they are now (what rename detection compares with)."""
    import json  # noqa: PLC0415

    now = json.dumps([vg.name for vg in obj.vertex_groups])
    if obj.rokeby.vertex_group_names != now:
        obj.rokeby.vertex_group_names = now


def sync_freeform_regions(obj) -> list:
    """Free-form regions follow their vertex group: renames are followed (see above) and every
    used group gets a live reader modifier. Returns what changed that needs the mirror's mesh
    evaluated again before the weights can be read (empty: the weights can be read now)."""
    s = obj.rokeby
    free = [rg for rg in s.regions if rg.kind == "FREEFORM"]
    if not free and not _readers(obj):
        return []
    names = [vg.name for vg in obj.vertex_groups]
    snapshot = _group_names(obj)
    changes, renamed = [], {}
    for rg in free:
        old = rg.vertex_group
        if not old:
            continue
        if old in names:
            index = names.index(old)
        else:
            new = _renamed(old, rg.vertex_group_index, names, snapshot)
            if new is None:
                continue  # the region warns naming the group (_region_inputs)
            rg.vertex_group, index = new, names.index(new)
            renamed[new] = old
        if rg.vertex_group_index != index:
            rg.vertex_group_index = index
    used = {rg.vertex_group for rg in free if rg.vertex_group in names}
    for group in sorted(used):
        why = ensure_reader(obj, group, renamed.get(group))
        if why is not None:
            changes.append(why)
    # Readers no region uses any more (the group was deleted, the region changed kind or group)
    # go; like every change here, the mirror is then pending (nothing of the evaluated mesh at
    # hand is touched again: it may refer to the removed modifier).
    unused = [mod for mod in _readers(obj) if _reader_group(mod) not in used]
    if unused:
        changes.append("removed the reader modifier" + ("s " if len(unused) > 1 else " ") + ", ".join(f"'{m.name}'" for m in unused) + " that no free-form region uses")
        drop_unused_readers(obj, used)
    if free:
        remember_groups(obj)
    return changes
