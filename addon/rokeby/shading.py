"""Final renders (Cycles, EEVEE): a shader node group that turns the stored field into the edited
normal of the specular lobe.

For a shading point with normal N seen along V (towards the viewer), the physical reflection is
r = reflect(−V, N). The field stores R(q) as the rotation vector ``rokeby_rotation`` (axis × angle),
so the edited reflection is e = R r and the normal that reflects V into e is n' = normalize(e + V)
(paper §6: only the specular part is edited). With the identity field n' = N exactly, so an
unedited mirror renders as before. When the mirror is frozen, r is reflected from the frozen eye
(``rokeby.freeze_eye``) instead of the camera, so the reflection stays put as the camera moves.

Wiring (``install``): every edited material's Glossy BSDF and, for Principled BSDFs, the Normal
input get n'. A Principled BSDF also shades its diffuse lobe with that input, so this is exact for
metals and mirrors (metallic = 1, no diffuse lobe); splitting the lobes of dielectric Principled
materials is not done yet.
"""

from __future__ import annotations

import bpy

from .evaluate import ATTRIBUTE

GROUP = "Rokeby Edited Normal"
LINK_TAG = "rokeby_edited_normal"


def node_group():
    """The shared node group (made once per file)."""
    ng = bpy.data.node_groups.get(GROUP)
    if ng is not None and ng.bl_idname == "ShaderNodeTree":
        return ng
    ng = bpy.data.node_groups.new(GROUP, "ShaderNodeTree")
    ng.interface.new_socket("Edited Normal", in_out="OUTPUT", socket_type="NodeSocketVector")
    ng.interface.new_socket("Normal", in_out="INPUT", socket_type="NodeSocketVector")
    n = ng.nodes
    out = n.new("NodeGroupOutput")
    gin = n.new("NodeGroupInput")
    geo = n.new("ShaderNodeNewGeometry")
    attr = n.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = ATTRIBUTE

    def math(op, *inputs):
        node = n.new("ShaderNodeVectorMath")
        node.operation = op
        for i, src in enumerate(inputs):
            ng.links.new(src, node.inputs[i])
        return node

    # The shading normal: the group's Normal input when one is linked (a bump map upstream; the
    # unlinked default is the zero vector), else the geometry's.
    linked = n.new("ShaderNodeMath")
    linked.operation = "GREATER_THAN"
    linked.inputs[1].default_value = 0.0
    ng.links.new(math("LENGTH", gin.outputs["Normal"]).outputs["Value"], linked.inputs[0])
    pick = n.new("ShaderNodeMix")
    pick.data_type = "VECTOR"
    ng.links.new(linked.outputs["Value"], pick.inputs["Factor"])
    ng.links.new(geo.outputs["Normal"], pick.inputs[4])  # A
    ng.links.new(gin.outputs["Normal"], pick.inputs[5])  # B
    normal = pick.outputs[1]
    angle = math("LENGTH", attr.outputs["Vector"])
    axis = math("NORMALIZE", attr.outputs["Vector"])
    # Freeze: the reflection is evaluated from the mirror's frozen eye instead of the camera,
    # V_f = normalize(eye - P); the object properties are read through their RNA paths.
    frozen = n.new("ShaderNodeAttribute")
    frozen.attribute_type = "OBJECT"
    frozen.attribute_name = "rokeby.freeze"
    eye = n.new("ShaderNodeAttribute")
    eye.attribute_type = "OBJECT"
    eye.attribute_name = "rokeby.freeze_eye"
    to_eye = math("NORMALIZE", math("SUBTRACT", eye.outputs["Vector"], geo.outputs["Position"]).outputs["Vector"])
    view = n.new("ShaderNodeMix")
    view.data_type = "VECTOR"
    ng.links.new(frozen.outputs["Fac"], view.inputs["Factor"])
    ng.links.new(geo.outputs["Incoming"], view.inputs[4])
    ng.links.new(to_eye.outputs["Vector"], view.inputs[5])
    minus_v = math("SCALE", view.outputs[1])
    minus_v.inputs["Scale"].default_value = -1.0
    r = math("REFLECT", minus_v.outputs["Vector"], normal)
    rot = n.new("ShaderNodeVectorRotate")
    rot.rotation_type = "AXIS_ANGLE"
    ng.links.new(r.outputs["Vector"], rot.inputs["Vector"])
    ng.links.new(axis.outputs["Vector"], rot.inputs["Axis"])
    ng.links.new(angle.outputs["Value"], rot.inputs["Angle"])
    # n' reflects the actual view ray into e (also when e was evaluated from the frozen eye).
    half = math("ADD", rot.outputs["Vector"], geo.outputs["Incoming"])
    edited = math("NORMALIZE", half.outputs["Vector"])
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
