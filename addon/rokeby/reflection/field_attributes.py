"""The field in the mirror's mesh (or its carrier): the rotation vectors as the point attribute
``rokeby_rotation`` (and the refraction field's), and the view-independent parts the render nodes
read, each written with one foreach_set per attribute."""

from __future__ import annotations

import numpy as np

from ..core import native, schema
from ..core.errors import RokebyError


def write_attribute(obj, values: np.ndarray, name: str = schema.ROTATION_ATTRIBUTE, *, update: bool = True):
    """Write (V, 3) rotation vectors to the mirror mesh's point attribute ``name`` in one foreach_set."""
    me = obj.data
    if me.library is not None or not getattr(me, "is_editable", True):
        where = f" from library '{me.library.filepath}'" if me.library is not None else ""
        raise RokebyError(f"mesh '{me.name}' is linked{where} and cannot store the field: make it local or a library override")
    if not np.all(np.isfinite(values)):
        raise RokebyError("the computed field is not finite (not written)")
    if len(values) != len(me.vertices):
        raise RokebyError(f"field has {len(values)} values, mesh '{me.name}' has {len(me.vertices)} vertices")
    _vector_attribute(me, name, "POINT").data.foreach_set("vector", np.ascontiguousarray(values, dtype=np.float32).ravel())
    if update:
        # Attribute-only: tag the mesh for re-evaluation; me.update() would also recompute its
        # normals and caches (8-12 ms at 100k vertices in the drag loop).
        me.update_tag()


def _vector_attribute(me, name: str, domain: str):
    """The FLOAT_VECTOR attribute ``name`` on ``domain`` of ``me``, made (or remade, when one of
    another type or domain has that name) for writing."""
    attr = me.attributes.get(name)
    if attr is not None and (attr.domain != domain or attr.data_type != "FLOAT_VECTOR"):
        me.attributes.remove(attr)
        attr = None
    return attr if attr is not None else me.attributes.new(name, "FLOAT_VECTOR", domain)


def _corner_topology(me, state):
    """(corner → vertex, corner → its polygon's first corner's vertex), read once per topology
    (of the mirror's mesh, or of its carrier: their corner counts differ)."""
    key = (me.name, len(me.loops), len(me.polygons), state.geometry_version if state is not None else None)
    if state is not None and state.corner_topology is not None and state.corner_topology[0] == key:
        return state.corner_topology[1]
    corner_vert = np.empty(len(me.loops), dtype=np.int32)
    me.loops.foreach_get("vertex_index", corner_vert)
    start = np.empty(len(me.polygons), dtype=np.int32)
    total = np.empty(len(me.polygons), dtype=np.int32)
    me.polygons.foreach_get("loop_start", start)
    me.polygons.foreach_get("loop_total", total)
    # Corners are stored polygon by polygon (contiguous offsets), so repeating each polygon's
    # first corner gives every corner its polygon's first corner. (int64: what the core takes.)
    corner_vert = corner_vert.astype(np.int64)
    ref_vert = corner_vert[np.repeat(start, total)]
    topo = (corner_vert, ref_vert)
    if state is not None:
        state.corner_topology = (key, topo)
    return topo


def write_render_attribute(obj, parts: np.ndarray, state=None, *, ramp: bool = False, update: bool = True, timer=None):
    """Write the field's view-independent parts (V, 6) = (x, y, z, w, a, u) for renders
    (schema.RENDER_ATTRIBUTE: x, y, z; schema.RENDER_ATTRIBUTE_WA: (w, a, 0), or with ``ramp`` (one Euclidean
    region) (w, −1, u): the nodes then take a = smoothstep(u) per shading point), what
    rokeby.reflection.render.shading's node group reads, in two foreach_set calls: per vertex while every
    polygon's quaternions share a hemisphere, per face corner otherwise (half turns)."""
    me = obj.data
    if not np.all(np.isfinite(parts)):
        raise RokebyError("the computed field is not finite (not written)")
    if len(parts) != len(me.vertices):
        raise RokebyError(f"field has {len(parts)} values, mesh '{me.name}' has {len(me.vertices)} vertices")
    run = timer if timer is not None else (lambda fn, *a, **k: fn(*a, **k))
    per_corner, xyz, wa = run(native.view_blend_render_rows, parts, *_corner_topology(me, state), ramp=ramp)
    domain = "CORNER" if per_corner else "POINT"
    for name, values in ((schema.RENDER_ATTRIBUTE, xyz), (schema.RENDER_ATTRIBUTE_WA, wa)):
        _vector_attribute(me, name, domain).data.foreach_set("vector", np.ascontiguousarray(values, dtype=np.float32).ravel())
    if update:
        me.update_tag()  # attribute-only, as in write_attribute


def remove_render_attribute(obj) -> bool:
    me = obj.data
    found = False
    for name in (schema.RENDER_ATTRIBUTE, schema.RENDER_ATTRIBUTE_WA):
        attr = me.attributes.get(name) if me is not None else None
        if attr is not None:
            if me.library is not None:
                raise RokebyError(f"mesh '{me.name}' is linked and its attribute '{name}' cannot be removed")
            me.attributes.remove(attr)
            found = True
    if found:
        me.update()
    return found


def _has_render_attribute(obj) -> bool:
    me = obj.data
    return all(
        (a := me.attributes.get(name)) is not None and a.data_type == "FLOAT_VECTOR"
        and len(a.data) == {"CORNER": len(me.loops), "POINT": len(me.vertices)}.get(a.domain, -1)
        for name in (schema.RENDER_ATTRIBUTE, schema.RENDER_ATTRIBUTE_WA)
    )


def remove_attribute(obj, name: str) -> bool:
    """Remove the point attribute ``name`` from the mirror's mesh (if it has it)."""
    me = obj.data
    attr = me.attributes.get(name) if me is not None else None
    if attr is None:
        return False
    if me.library is not None:
        raise RokebyError(f"mesh '{me.name}' is linked and its attribute '{name}' cannot be removed")
    me.attributes.remove(attr)
    me.update()
    return True


def _has_attribute(obj, name: str) -> bool:
    attr = obj.data.attributes.get(name)
    return attr is not None and attr.domain == "POINT" and attr.data_type == "FLOAT_VECTOR" and len(attr.data) == len(obj.data.vertices)


def read_attribute(obj, name: str = schema.ROTATION_ATTRIBUTE) -> np.ndarray | None:
    """The stored rotation vectors (V, 3) of a mirror (``name``: which field), or None."""
    me = obj.data
    attr = me.attributes.get(name) if me is not None else None
    if attr is None:
        return None
    out = np.empty(len(me.vertices) * 3, dtype=np.float32)
    attr.data.foreach_get("vector", out)
    return out.reshape(-1, 3)
