"""Final renders (Cycles, EEVEE): shader node groups that turn the stored field into the edited
normal of the specular lobe.

For a shading point with normal N seen along V (towards the viewer), the physical reflection is
r = reflect(−V, N). The field stores R(q) as the rotation vector ``rokeby_rotation`` (axis × angle),
so the edited reflection is e = R r (paper eq. 6) and the normal that reflects V into e is
n' = normalize(e + V) (paper §6: only the specular part is edited). With the identity field n' = N
exactly, so an unedited mirror renders as before. When the mirror is frozen, r is reflected from
the frozen eye (``rokeby.freeze_eye``) instead of the camera, so the reflection stays put as the
camera moves.

Two groups, made once per file and rebuilt in place when an older version is found:

* "Rokeby Edited Direction": e, r, V and the shading normal N, in world space. Everything that
  looks something up in the edited direction (this module, reflection maps) starts from it.
* "Rokeby Edited Normal": n' for the BSDFs. Edits that send e below the surface (e·N < 0, paper
  §6.3 "extreme edits") are folded back about the tangent plane, e ← e − 2 min(e·N, 0) N, before
  n' is formed: the result is continuous across the horizon (no jump, no black), where a ray
  tracer would otherwise clamp every such pixel to the same grazing direction. A tiny N term keeps
  n' defined where e = −V exactly. Reflection-map mode looks e up unfolded, as the paper does.
"""

from __future__ import annotations

import bpy

from .evaluate import ATTRIBUTE

DIRECTION_GROUP = "Rokeby Edited Direction"
GROUP = "Rokeby Edited Normal"
LINK_TAG = "rokeby_edited_normal"
VERSION_KEY = "rokeby_version"
VERSION = 2


def vector_math(ng, op, *inputs, scale=None):
    """A Vector Math node of ``op`` fed by ``inputs`` (sockets); returns the node."""
    node = ng.nodes.new("ShaderNodeVectorMath")
    node.operation = op
    for i, src in enumerate(inputs):
        ng.links.new(src, node.inputs[i])
    if scale is not None:
        node.inputs["Scale"].default_value = scale
    return node


def scalar_math(ng, op, *inputs, values=()):
    """A Math node of ``op``: ``inputs`` are sockets, ``values`` fill the remaining inputs."""
    node = ng.nodes.new("ShaderNodeMath")
    node.operation = op
    for i, src in enumerate(inputs):
        ng.links.new(src, node.inputs[i])
    for j, v in enumerate(values):
        node.inputs[len(inputs) + j].default_value = v
    return node


def mix_vector(ng, factor, a, b):
    """(1 − factor)·a + factor·b for vector sockets; returns the output socket."""
    node = ng.nodes.new("ShaderNodeMix")
    node.data_type = "VECTOR"
    ng.links.new(factor, node.inputs["Factor"])
    ng.links.new(a, node.inputs[4])
    ng.links.new(b, node.inputs[5])
    return node.outputs[1]


def _fresh_group(name, sockets):
    """The group ``name`` emptied for (re)building if it is missing or older than VERSION;
    None if it is current. Rebuilding in place keeps every material that uses it pointing at it."""
    ng = bpy.data.node_groups.get(name)
    if ng is not None and ng.bl_idname == "ShaderNodeTree" and ng.get(VERSION_KEY) == VERSION:
        return None
    if ng is None or ng.bl_idname != "ShaderNodeTree":
        ng = bpy.data.node_groups.new(name, "ShaderNodeTree")
    ng.nodes.clear()
    ng.interface.clear()
    for sock_name, in_out, kind in sockets:
        ng.interface.new_socket(sock_name, in_out=in_out, socket_type=kind)
    ng[VERSION_KEY] = VERSION
    return ng


def direction_group():
    """"Rokeby Edited Direction": Normal in (a bump map upstream; unlinked → the geometry's
    normal); Direction e = R r, Reflection r, View V (towards the camera) and Normal N out."""
    vec = "NodeSocketVector"
    ng = _fresh_group(DIRECTION_GROUP, [
        ("Direction", "OUTPUT", vec), ("Reflection", "OUTPUT", vec), ("View", "OUTPUT", vec),
        ("Normal", "OUTPUT", vec), ("Normal", "INPUT", vec),
    ])
    if ng is None:
        return bpy.data.node_groups[DIRECTION_GROUP]
    n = ng.nodes
    out = n.new("NodeGroupOutput")
    gin = n.new("NodeGroupInput")
    geo = n.new("ShaderNodeNewGeometry")
    attr = n.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = ATTRIBUTE
    # The shading normal: the group's Normal input when one is linked (the unlinked default is the
    # zero vector), else the geometry's.
    linked = scalar_math(ng, "GREATER_THAN", vector_math(ng, "LENGTH", gin.outputs["Normal"]).outputs["Value"], values=(0.0,))
    normal = mix_vector(ng, linked.outputs["Value"], geo.outputs["Normal"], gin.outputs["Normal"])
    angle = vector_math(ng, "LENGTH", attr.outputs["Vector"])
    axis = vector_math(ng, "NORMALIZE", attr.outputs["Vector"])
    # Freeze: the reflection is evaluated from the mirror's frozen eye instead of the camera,
    # V_f = normalize(eye − P); the object properties are read through their RNA paths.
    frozen = n.new("ShaderNodeAttribute")
    frozen.attribute_type = "OBJECT"
    frozen.attribute_name = "rokeby.freeze"
    eye = n.new("ShaderNodeAttribute")
    eye.attribute_type = "OBJECT"
    eye.attribute_name = "rokeby.freeze_eye"
    to_eye = vector_math(ng, "NORMALIZE", vector_math(ng, "SUBTRACT", eye.outputs["Vector"], geo.outputs["Position"]).outputs["Vector"])
    view = mix_vector(ng, frozen.outputs["Fac"], geo.outputs["Incoming"], to_eye.outputs["Vector"])
    minus_v = vector_math(ng, "SCALE", view, scale=-1.0)
    r = vector_math(ng, "REFLECT", minus_v.outputs["Vector"], normal)
    rot = n.new("ShaderNodeVectorRotate")
    rot.rotation_type = "AXIS_ANGLE"
    ng.links.new(r.outputs["Vector"], rot.inputs["Vector"])
    ng.links.new(axis.outputs["Vector"], rot.inputs["Axis"])
    ng.links.new(angle.outputs["Value"], rot.inputs["Angle"])
    ng.links.new(rot.outputs["Vector"], out.inputs["Direction"])
    ng.links.new(r.outputs["Vector"], out.inputs["Reflection"])
    # V is the actual view ray (also when e was evaluated from the frozen eye): n' must reflect it.
    ng.links.new(geo.outputs["Incoming"], out.inputs["View"])
    ng.links.new(normal, out.inputs["Normal"])
    return ng


def node_group():
    """"Rokeby Edited Normal": Normal in, Edited Normal n' out (see the module docstring)."""
    vec = "NodeSocketVector"
    ng = _fresh_group(GROUP, [("Edited Normal", "OUTPUT", vec), ("Normal", "INPUT", vec)])
    if ng is None:
        return bpy.data.node_groups[GROUP]
    out = ng.nodes.new("NodeGroupOutput")
    gin = ng.nodes.new("NodeGroupInput")
    d = ng.nodes.new("ShaderNodeGroup")
    d.node_tree = direction_group()
    ng.links.new(gin.outputs["Normal"], d.inputs["Normal"])
    e, v, normal = d.outputs["Direction"], d.outputs["View"], d.outputs["Normal"]
    # Fold an edited direction that points below the surface back above it: e − 2 min(e·N, 0) N.
    below = scalar_math(ng, "MINIMUM", vector_math(ng, "DOT_PRODUCT", e, normal).outputs["Value"], values=(0.0,))
    twice = scalar_math(ng, "MULTIPLY", below.outputs["Value"], values=(-2.0,))
    lift = vector_math(ng, "SCALE", normal)
    ng.links.new(twice.outputs["Value"], lift.inputs["Scale"])
    folded = vector_math(ng, "ADD", e, lift.outputs["Vector"])
    # n' = normalize(e + V + 1e-4 N): the N term only matters where e = −V (a grazing fold).
    tiny = vector_math(ng, "SCALE", normal, scale=1e-4)
    half = vector_math(ng, "ADD", vector_math(ng, "ADD", folded.outputs["Vector"], v).outputs["Vector"], tiny.outputs["Vector"])
    edited = vector_math(ng, "NORMALIZE", half.outputs["Vector"])
    ng.links.new(edited.outputs["Vector"], out.inputs["Edited Normal"])
    return ng


def _targets(tree):
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeBsdfGlossy" or node.bl_idname == "ShaderNodeBsdfAnisotropic":
            yield node, node.inputs["Normal"]
        elif node.bl_idname == "ShaderNodeBsdfPrincipled":
            yield node, node.inputs["Normal"]


def install(material) -> int:
    """Insert the node group in ``material`` and feed the specular normals; returns how many BSDF
    inputs were rewired. An input already driven (e.g. by a bump map) passes through the group."""
    if material is None or not material.use_nodes:
        return 0
    tree = material.node_tree
    group = next((nd for nd in tree.nodes if nd.bl_idname == "ShaderNodeGroup" and nd.get(LINK_TAG)), None)
    if group is None:
        group = tree.nodes.new("ShaderNodeGroup")
        group.node_tree = node_group()
        group[LINK_TAG] = True
        group.label = "Rokeby: edited reflections"
        group.location = (-400, -300)
    count = 0
    for bsdf, socket in _targets(tree):
        previous = [lk for lk in socket.links if lk.from_node != group]
        if previous:
            src = previous[0].from_socket
            tree.links.new(src, group.inputs["Normal"])
        tree.links.new(group.outputs["Edited Normal"], socket)
        count += 1
    return count


def uninstall(material) -> bool:
    """Remove the group from ``material``, restoring any normal input it was passing through."""
    if material is None or not material.use_nodes:
        return False
    tree = material.node_tree
    groups = [nd for nd in tree.nodes if nd.bl_idname == "ShaderNodeGroup" and nd.get(LINK_TAG)]
    for group in groups:
        upstream = [lk.from_socket for lk in group.inputs["Normal"].links]
        targets = [lk.to_socket for lk in group.outputs["Edited Normal"].links]
        tree.nodes.remove(group)
        if upstream:
            for sock in targets:
                tree.links.new(upstream[0], sock)
    return bool(groups)
