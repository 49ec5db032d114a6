"""The field on the evaluated surface, for mirrors whose modifiers change the vertex count and
mirrors sharing a mesh: each such mirror writes its field to a carrier of its own (a mesh of the
evaluated topology, "Rokeby field: <mirror>", owned by that mirror) that its "Rokeby field"
modifier (the "Rokeby Field Transfer" node group) copies onto its evaluated mesh."""

from __future__ import annotations

from ..core import schema


# 2: the refraction field is copied too (zeros, read as the identity, where the carrier has none).
TRANSFER_VERSION = 2
FIELD_ATTRIBUTES = (schema.ROTATION_ATTRIBUTE, schema.RENDER_ATTRIBUTE, schema.RENDER_ATTRIBUTE_WA, schema.REFRACTION_ATTRIBUTE)


def carrier_of(obj):
    """The carrier object of ``obj`` (a mesh of the evaluated topology holding its field), or
    None. A carrier owned by another mirror (``obj`` is a Shift+D or Alt+D copy of it) is not
    ``obj``'s: it gets its own. (Carriers saved before owners existed are claimed at load time,
    ``claim_carriers``.)"""
    c = getattr(obj.rokeby, "field_carrier", None)
    try:
        if c is None or c.type != "MESH":
            return None
        owner = c.parent
        return c if owner is None or owner == obj else None
    except ReferenceError:
        return None


def strip_field(me) -> bool:
    """Remove the field attributes from the mesh ``me`` (a shared mesh holds none: each mirror
    using it carries its own); returns whether there were any."""
    if me is None or me.library is not None:
        return False
    found = False
    for name in FIELD_ATTRIBUTES:
        # Looked up anew each time: removing an attribute invalidates Python references to the
        # others (a list of them removed the wrong ones and left rokeby_render_rotation behind).
        attr = me.attributes.get(name)
        if attr is not None:
            me.attributes.remove(attr)
            found = True
    if found:
        me.update()
    return found


def claim_carriers():
    """Load-time migration: a carrier saved without an owner (before copies were handled) is
    claimed by the mirror it is named after, else by the first mirror pointing at it; the others
    (copies that shared it) get their own at their next evaluation."""
    import bpy  # noqa: PLC0415

    users: dict = {}
    for ob in bpy.data.objects:
        s = getattr(ob, "rokeby", None)
        c = s.field_carrier if s is not None else None
        if c is not None and ob.library is None and c.library is None and c.parent is None:
            users.setdefault(c.name, (c, []))[1].append(ob)
    for c, obs in users.values():
        named = [o for o in obs if c.name == schema.CARRIER_PREFIX + o.name]
        c.parent = (named or obs)[0]


def _transfer_group():
    """"Rokeby Field Transfer": copies the render rows and the rotation vectors (reflection and
    refraction) of the Source object's mesh onto the modified geometry, by index (the carrier has
    the same topology), on face corners (a point attribute of the carrier adapts to its corners).
    An attribute the carrier lacks arrives as zeros, which the render nodes read as a missing
    one: the identity."""
    import bpy  # noqa: PLC0415

    ng = bpy.data.node_groups.get(schema.TRANSFER_GROUP)
    if ng is not None and ng.bl_idname == "GeometryNodeTree" and ng.get(schema.VERSION_KEY) == TRANSFER_VERSION:
        return ng
    if ng is None or ng.bl_idname != "GeometryNodeTree":
        ng = bpy.data.node_groups.new(schema.TRANSFER_GROUP, "GeometryNodeTree")
    ng.nodes.clear()
    ng.interface.clear()
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket("Source", in_out="INPUT", socket_type="NodeSocketObject")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gin, gout = ng.nodes.new("NodeGroupInput"), ng.nodes.new("NodeGroupOutput")
    info = ng.nodes.new("GeometryNodeObjectInfo")
    ng.links.new(gin.outputs["Source"], info.inputs["Object"])
    index = ng.nodes.new("GeometryNodeInputIndex")
    geometry = gin.outputs["Geometry"]
    for name, domain in ((schema.RENDER_ATTRIBUTE, "CORNER"), (schema.RENDER_ATTRIBUTE_WA, "CORNER"), (schema.ROTATION_ATTRIBUTE, "POINT"),
                         (schema.REFRACTION_ATTRIBUTE, "POINT")):
        read = ng.nodes.new("GeometryNodeInputNamedAttribute")
        read.data_type = "FLOAT_VECTOR"
        read.inputs["Name"].default_value = name
        sample = ng.nodes.new("GeometryNodeSampleIndex")
        sample.data_type, sample.domain = "FLOAT_VECTOR", domain
        ng.links.new(info.outputs["Geometry"], sample.inputs["Geometry"])
        ng.links.new(read.outputs["Attribute"], sample.inputs["Value"])
        ng.links.new(index.outputs["Index"], sample.inputs["Index"])
        store = ng.nodes.new("GeometryNodeStoreNamedAttribute")
        store.data_type, store.domain = "FLOAT_VECTOR", domain
        store.inputs["Name"].default_value = name
        ng.links.new(geometry, store.inputs["Geometry"])
        ng.links.new(sample.outputs[0], store.inputs["Value"])
        geometry = store.outputs["Geometry"]
    ng.links.new(geometry, gout.inputs["Geometry"])
    ng[schema.VERSION_KEY] = TRANSFER_VERSION
    return ng


def ensure_carrier(obj, depsgraph):
    """The carrier of ``obj`` with the evaluated mesh's topology (rebuilt when it changes), and
    the 'Rokeby field' modifier at the end of the stack reading it. A copy of a mirror gets a
    carrier of its own (one owned by another mirror is left to it)."""
    import bpy  # noqa: PLC0415

    ob_eval = obj.evaluated_get(depsgraph)
    me_eval = ob_eval.data
    carrier = carrier_of(obj)
    if carrier is None or len(carrier.data.vertices) != len(me_eval.vertices) or len(carrier.data.loops) != len(me_eval.loops):
        mesh = bpy.data.meshes.new_from_object(ob_eval, preserve_all_data_layers=False)
        mesh.name = schema.CARRIER_PREFIX + obj.name
        if carrier is None:
            carrier = bpy.data.objects.new(schema.CARRIER_PREFIX + obj.name, mesh)  # in no scene: never drawn
            carrier.parent = obj
        else:
            old = carrier.data
            carrier.data = mesh
            if old.users == 0:
                bpy.data.meshes.remove(old)
        obj.rokeby.field_carrier = carrier
    if carrier.parent is None:
        carrier.parent = obj
    mod = obj.modifiers.get(schema.TRANSFER_MODIFIER)
    if mod is None or mod.type != "NODES":
        mod = obj.modifiers.new(schema.TRANSFER_MODIFIER, "NODES")
        mod.show_in_editmode = False
    if mod.node_group is None or mod.node_group.name != schema.TRANSFER_GROUP or mod.node_group.get(schema.VERSION_KEY) != TRANSFER_VERSION:
        mod.node_group = _transfer_group()
    from ..blender import compat  # noqa: PLC0415

    ident = next(i.identifier for i in mod.node_group.interface.items_tree if getattr(i, "in_out", "") == "INPUT" and i.name == "Source")
    if compat.modifier_input(mod, ident) != carrier:
        compat.set_modifier_input(mod, ident, carrier)
    return carrier


def remove_carrier(obj) -> bool:
    """Remove the transfer modifier and the carrier of ``obj`` (the vertex count matches again,
    or the mirror goes)."""

    found = False
    mod = obj.modifiers.get(schema.TRANSFER_MODIFIER)
    if mod is not None:
        obj.modifiers.remove(mod)
        found = True
    carrier = carrier_of(obj)
    if carrier is None and obj.rokeby.field_carrier is not None:
        obj.rokeby.field_carrier = None  # another mirror's (this one is its copy): left to it
    if carrier is not None:
        mesh = carrier.data
        obj.rokeby.field_carrier = None
        from ..blender import transaction  # noqa: PLC0415

        transaction.remove(carrier)
        if mesh is not None:
            transaction.remove_unused(mesh)
        found = True
    return found
