"""Final renders (Cycles, EEVEE): shader node groups that turn the stored field into the edited
normal of the specular lobe.

For a shading point with normal N seen along V (towards the viewer), the physical reflection is
r = reflect(−V, N). The field is stored for renders per face corner as its view-independent
parts: the region rotation R as a unit quaternion (``rokeby_render_rotation`` x, y, z and
``rokeby_render_rotation_wa`` (w, a, 0), kept in one hemisphere per polygon so that interpolation
across a face never tears at half turns) and the region weight a. The nodes form eq. 7's
R_a r = ortho(a R + (1 − a) r rᵀ) r per shading point in closed form (``view_blend_nodes``), for
the r of the render camera or of the frozen eye: the field the viewport preview evaluates per
pixel. The edited reflection is e = R_a r (paper eq. 6) and the normal that reflects V into e is
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

import uuid

import bpy

from ...blender import transaction
from ...core.errors import RokebyError
from ...blender import nodes
from ...core import schema

RENDER_ATTRIBUTE, RENDER_ATTRIBUTE_WA = schema.RENDER_ATTRIBUTE, schema.RENDER_ATTRIBUTE_WA  # evaluate writes them

# 3: the field is read as per-corner quaternions (RENDER_ATTRIBUTE) instead of rotation vectors.
VERSION = 3


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


def _rotate_nodes(ng, u, w, k, v, inverse=False):
    """v rotated by the quaternion q = (u, w) scaled by k = 2 / |q|² (so q need not be unit):
    R v = v + k (w (u × v) + u × (u × v)); the inverse rotation negates the w term."""
    c1 = vector_math(ng, "CROSS_PRODUCT", u, v)
    wc1 = vector_math(ng, "SCALE", c1.outputs["Vector"])
    ng.links.new(w, wc1.inputs["Scale"])
    c2 = vector_math(ng, "CROSS_PRODUCT", u, c1.outputs["Vector"])
    t = vector_math(ng, "SUBTRACT" if inverse else "ADD", c2.outputs["Vector"], wc1.outputs["Vector"])
    kt = vector_math(ng, "SCALE", t.outputs["Vector"])
    ng.links.new(k, kt.inputs["Scale"])
    return vector_math(ng, "ADD", v, kt.outputs["Vector"]).outputs["Vector"]


def view_blend_nodes(ng, u, wa, r):
    """Eq. 7 per shading point (rokeby_core::reflection::field::view_blend, derived there): the corner
    attributes give the region rotation R = (u, w) and weight a (``wa`` = (w, a, 0), or
    (w, −1, u) for a = smoothstep(u)); with
    s = Rᵀ r, φ = ∠(r, s), θ = atan2((1 − a) sin φ, 2a + (1 − a) cos φ) and t the unit part of s
    orthogonal to r, R_a r = R (cos θ r + sin θ t). A missing attribute reads u = 0, w = a = 0,
    and the division by zero gives 0 in shader nodes, so e = r (objects sharing the material)."""
    parts = ng.nodes.new("ShaderNodeSeparateXYZ")
    ng.links.new(wa, parts.inputs[0])
    w, a_stored, u_ramp = parts.outputs["X"], parts.outputs["Y"], parts.outputs["Z"]
    # (w, −1, u) marks the ramp form (one Euclidean region): a = smoothstep(u) per shading point,
    # rokeby_core::reflection::region::smooth_step (3t² − 2t³ on [0, 1]) as Map Range's Smooth Step does.
    ramp = scalar_math(ng, "LESS_THAN", a_stored, values=(-0.5,)).outputs["Value"]
    step = ng.nodes.new("ShaderNodeMapRange")
    step.interpolation_type = "SMOOTHSTEP"
    step.clamp = True
    ng.links.new(u_ramp, step.inputs["Value"])
    diff = scalar_math(ng, "SUBTRACT", step.outputs["Result"], a_stored).outputs["Value"]
    a = scalar_math(ng, "MULTIPLY_ADD", ramp, diff, a_stored).outputs["Value"]
    norm2 = scalar_math(ng, "ADD", vector_math(ng, "DOT_PRODUCT", u, u).outputs["Value"], scalar_math(ng, "MULTIPLY", w, w).outputs["Value"])
    k = scalar_math(ng, "DIVIDE", values=(2.0,))
    ng.links.new(norm2.outputs["Value"], k.inputs[1])
    k = k.outputs["Value"]
    s = _rotate_nodes(ng, u, w, k, r, inverse=True)
    cos_phi = vector_math(ng, "DOT_PRODUCT", r, s).outputs["Value"]
    along = vector_math(ng, "SCALE", r)
    ng.links.new(cos_phi, along.inputs["Scale"])
    perp = vector_math(ng, "SUBTRACT", s, along.outputs["Vector"]).outputs["Vector"]
    sin_phi = vector_math(ng, "LENGTH", perp).outputs["Value"]
    t = vector_math(ng, "NORMALIZE", perp).outputs["Vector"]
    b = scalar_math(ng, "SUBTRACT", values=(1.0,))
    ng.links.new(a, b.inputs[1])
    b = b.outputs["Value"]
    y = scalar_math(ng, "MULTIPLY", b, sin_phi).outputs["Value"]
    x = scalar_math(ng, "ADD", scalar_math(ng, "MULTIPLY", a, values=(2.0,)).outputs["Value"], scalar_math(ng, "MULTIPLY", b, cos_phi).outputs["Value"]).outputs["Value"]
    theta = scalar_math(ng, "ARCTAN2", y, x).outputs["Value"]
    cos_t = scalar_math(ng, "COSINE", theta).outputs["Value"]
    sin_t = scalar_math(ng, "SINE", theta).outputs["Value"]
    rc = vector_math(ng, "SCALE", r)
    ng.links.new(cos_t, rc.inputs["Scale"])
    ts = vector_math(ng, "SCALE", t)
    ng.links.new(sin_t, ts.inputs["Scale"])
    r_blend = vector_math(ng, "ADD", rc.outputs["Vector"], ts.outputs["Vector"]).outputs["Vector"]
    return _rotate_nodes(ng, u, w, k, r_blend)


def _fresh_group(name, sockets):
    """The group ``name`` emptied for (re)building if it is missing or older than VERSION;
    None if it is current. Rebuilding in place keeps every material that uses it pointing at it."""
    ng = bpy.data.node_groups.get(name)
    if ng is not None and ng.bl_idname == "ShaderNodeTree" and ng.get(schema.VERSION_KEY) == VERSION:
        return None
    if ng is None or ng.bl_idname != "ShaderNodeTree":
        ng = bpy.data.node_groups.new(name, "ShaderNodeTree")
    ng.nodes.clear()
    ng.interface.clear()
    for sock_name, in_out, kind in sockets:
        ng.interface.new_socket(sock_name, in_out=in_out, socket_type=kind)
    ng[schema.VERSION_KEY] = VERSION
    return ng


def direction_group():
    """"Rokeby Edited Direction": Normal in (a bump map upstream; unlinked → the geometry's
    normal); Direction e = R r, Reflection r, View V (towards the camera) and Normal N out."""
    vec = "NodeSocketVector"
    ng = _fresh_group(schema.DIRECTION_GROUP, [
        ("Direction", "OUTPUT", vec), ("Reflection", "OUTPUT", vec), ("View", "OUTPUT", vec),
        ("Normal", "OUTPUT", vec), ("Normal", "INPUT", vec),
    ])
    if ng is None:
        return bpy.data.node_groups[schema.DIRECTION_GROUP]
    n = ng.nodes
    out = n.new("NodeGroupOutput")
    gin = n.new("NodeGroupInput")
    geo = n.new("ShaderNodeNewGeometry")
    quat_xyz = n.new("ShaderNodeAttribute")
    quat_xyz.attribute_type = "GEOMETRY"
    quat_xyz.attribute_name = RENDER_ATTRIBUTE
    quat_wa = n.new("ShaderNodeAttribute")
    quat_wa.attribute_type = "GEOMETRY"
    quat_wa.attribute_name = RENDER_ATTRIBUTE_WA
    # The shading normal: the group's Normal input when one is linked (the unlinked default is the
    # zero vector), else the geometry's.
    linked = scalar_math(ng, "GREATER_THAN", vector_math(ng, "LENGTH", gin.outputs["Normal"]).outputs["Value"], values=(0.0,))
    normal = mix_vector(ng, linked.outputs["Value"], geo.outputs["Normal"], gin.outputs["Normal"])
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
    e = view_blend_nodes(ng, quat_xyz.outputs["Vector"], quat_wa.outputs["Vector"], r.outputs["Vector"])
    ng.links.new(e, out.inputs["Direction"])
    ng.links.new(r.outputs["Vector"], out.inputs["Reflection"])
    # V is the actual view ray (also when e was evaluated from the frozen eye): n' must reflect it.
    ng.links.new(geo.outputs["Incoming"], out.inputs["View"])
    ng.links.new(normal, out.inputs["Normal"])
    return ng


def node_group():
    """"Rokeby Edited Normal": Normal in, Edited Normal n' out (see the module docstring)."""
    vec = "NodeSocketVector"
    ng = _fresh_group(schema.NORMAL_GROUP, [("Edited Normal", "OUTPUT", vec), ("Normal", "INPUT", vec)])
    if ng is None:
        return bpy.data.node_groups[schema.NORMAL_GROUP]
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


# --- wiring materials ------------------------------------------------------------------------
# Every node the add-on puts in a material carries schema.LINK_TAG (older files: True) and a schema.ROLE_KEY.
SPECULAR_BSDFS = ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic")
# BSDFs inside a node group are edited in a copy of the group local to the material
# (schema.COPY_OF_KEY on the copy, schema.ORIGINAL_TREE_KEY on the material's group node).
_SEP = "\x1f"


def _ours(node) -> bool:
    return bool(node.get(schema.LINK_TAG)) and not node.get(schema.DOOMED_KEY)


def _tag(node, role, label, source=None):
    node[schema.LINK_TAG] = True
    node[schema.ROLE_KEY] = role
    node.label = label
    if source is not None:
        node[schema.SOURCE_KEY] = source
    return node


def _is_normal_group(node) -> bool:
    """One of our edited-normal group nodes (files from before roles have the tag only)."""
    return _ours(node) and node.bl_idname == "ShaderNodeGroup" and node.get(schema.ROLE_KEY, "normal") == "normal"


def feed_through(tree, socket, is_ours, new_group):
    """Feed a group's "Edited Normal" output to ``socket`` (a BSDF's normal input); a normal
    already linked there (a bump map) passes through the group's "Normal" input. A group for
    which ``is_ours`` holds is already in place and is returned as it is (idempotent);
    ``new_group()`` makes the node otherwise."""
    links = list(socket.links)
    if links and is_ours(links[0].from_node):
        return links[0].from_node
    group = new_group()
    if links:
        tree.links.new(links[0].from_socket, group.inputs["Normal"])
    tree.links.new(group.outputs["Edited Normal"], socket)
    return group


def _feed_edited_normal(tree, socket, label, location):
    """Feed n' to ``socket`` (a BSDF's Normal or Coat Normal) through its own group node."""

    def new_group():
        group = _tag(tree.nodes.new("ShaderNodeGroup"), "normal", label)
        group.node_tree = node_group()
        group.location = location
        return group

    return feed_through(tree, socket, _is_normal_group, new_group)


def node_signature(node, *settings: str) -> str:
    """A node's inputs (values and links) and the named settings, to notice artists' edits of a
    node that parts stand in for (shading's Principled split, refraction's Glass split)."""
    parts = [str(getattr(node, name)) for name in settings]
    for sock in node.inputs:
        if sock.is_linked:
            lk = sock.links[0]
            parts.append(f"{sock.identifier}<{lk.from_node.name}.{lk.from_socket.identifier}")
        elif hasattr(sock, "default_value"):
            v = sock.default_value
            parts.append(f"{sock.identifier}={tuple(v) if hasattr(v, '__len__') else v!r}")
    return "|".join(parts)


def record_outgoing(node, key: str) -> list:
    """Store where ``node``'s BSDF output is linked (as node name and socket identifier) in the
    custom property ``key``, for ``recorded_targets`` to find again; returns the records."""
    outgoing = [f"{lk.to_node.name}{_SEP}{lk.to_socket.identifier}" for lk in node.outputs["BSDF"].links]
    node[key] = outgoing
    return outgoing


def recorded_targets(tree, entries) -> list:
    """The input sockets that ``record_outgoing`` records name (those still in ``tree``)."""
    targets = []
    for entry in entries:
        node_name, _, ident = str(entry).partition(_SEP)
        node = tree.nodes.get(node_name)
        sock = next((sk for sk in node.inputs if sk.identifier == ident), None) if node else None
        if sock is not None:
            targets.append(sock)
    return targets


def _fixed(socket, value) -> bool:
    """The input is unlinked and holds ``value``."""
    return not socket.is_linked and abs(socket.default_value - value) < 1e-6


def _is_metal(bsdf) -> bool:
    return _fixed(bsdf.inputs["Metallic"], 1.0)


def _has_coat(bsdf) -> bool:
    return not _fixed(bsdf.inputs["Coat Weight"], 0.0)


def _signature(bsdf) -> str:
    """The Principled BSDF's inputs and settings, to notice artists' edits."""
    return node_signature(bsdf, "distribution", "subsurface_method")


def _split_key(bsdf) -> str:
    """What the parts of ``bsdf`` carry in schema.SOURCE_KEY: its split id (files from before ids: its name)."""
    return str(bsdf.get(schema.SPLIT_ID_KEY, bsdf.name))


def _tag_part(node, role, label, bsdf):
    _tag(node, role, label, _split_key(bsdf))
    node[schema.SOURCE_NAME_KEY] = bsdf.name
    return node


def _clone(tree, bsdf, role, overrides, location):
    """A copy of the Principled BSDF ``bsdf`` (values and links) with ``overrides`` set unlinked."""
    part = tree.nodes.new(bsdf.bl_idname)
    part.distribution = bsdf.distribution
    part.subsurface_method = bsdf.subsurface_method
    for src, dst in zip(bsdf.inputs, part.inputs):
        if hasattr(src, "default_value"):
            dst.default_value = src.default_value
        for lk in src.links:
            tree.links.new(lk.from_socket, dst)
    for name, value in overrides.items():
        sock = part.inputs[name]
        for lk in list(sock.links):
            tree.links.remove(lk)
        sock.default_value = value
    part.location = location
    part.hide = True
    return _tag_part(part, role, f"Rokeby: {role} part of {bsdf.name}", bsdf)


def _value_socket(tree, socket, bsdf, location):
    """An output socket carrying ``socket``'s value: its upstream link, or a Value node."""
    if socket.is_linked:
        return socket.links[0].from_socket
    node = _tag_part(tree.nodes.new("ShaderNodeValue"), "value", f"Rokeby: {socket.name} of {bsdf.name}", bsdf)
    node.outputs[0].default_value = socket.default_value
    node.location = location
    return node.outputs[0]


def _split(tree, bsdf) -> None:
    """Split a dielectric (or partly metallic) Principled BSDF so only its specular lobes see n'.

    Blender's Principled BSDF shades every lobe with its one Normal input, so feeding it n' would
    also move the diffuse shading, which the paper keeps (§6). It is replaced in the node tree by
        Mix(metallic, (1 − F) · Diffuse(N) + Specular(n'), Metal(n'))
    where Diffuse is a copy with its specular layer, coat and metal off (diffuse, subsurface, sheen,
    transmission, emission), Specular a copy with black base (the dielectric specular layer and the
    coat), Metal a copy with metallic = 1, and F = min(1, 2 · Specular IOR Level) · Fresnel(IOR)
    stands for the light the specular layer takes from the diffuse one. Alpha wraps the sum. The
    original node stays in the tree, unlinked, holding the artist's values; ``sync`` copies later
    edits of it into the parts and ``uninstall`` puts it back in place.
    """
    x, y = bsdf.location
    if schema.SPLIT_ID_KEY not in bsdf:
        bsdf[schema.SPLIT_ID_KEY] = uuid.uuid4().hex
    outgoing = recorded_targets(tree, record_outgoing(bsdf, schema.SPLIT_KEY))
    bsdf[schema.SIGNATURE_KEY] = _signature(bsdf)
    normal_in = bsdf.inputs["Normal"]
    black = (0.0, 0.0, 0.0, 1.0)
    diffuse = _clone(tree, bsdf, "diffuse", {"Metallic": 0.0, "Specular IOR Level": 0.0, "Coat Weight": 0.0, "Alpha": 1.0}, (x + 300, y + 200))
    specular = _clone(tree, bsdf, "specular", {
        "Base Color": black, "Metallic": 0.0, "Subsurface Weight": 0.0, "Transmission Weight": 0.0,
        "Sheen Weight": 0.0, "Emission Strength": 0.0, "Alpha": 1.0}, (x + 300, y + 150))
    _feed_edited_normal(tree, specular.inputs["Normal"], schema.FRAME_EDITED_REFLECTIONS, (x, y - 420))
    if _has_coat(bsdf):
        _feed_edited_normal(tree, specular.inputs["Coat Normal"], schema.FRAME_EDITED_COAT, (x, y - 520))
    # (1 − F) Diffuse: Mix(F, Diffuse, black).
    fresnel = _tag_part(tree.nodes.new("ShaderNodeFresnel"), "fresnel", f"Rokeby: specular layer of {bsdf.name}", bsdf)
    fresnel.location = (x + 300, y + 300)
    tree.links.new(_value_socket(tree, bsdf.inputs["IOR"], bsdf, (x + 100, y + 300)), fresnel.inputs["IOR"])
    if normal_in.is_linked:
        tree.links.new(normal_in.links[0].from_socket, fresnel.inputs["Normal"])
    level = scalar_math(tree, "MULTIPLY", _value_socket(tree, bsdf.inputs["Specular IOR Level"], bsdf, (x + 100, y + 350)), values=(2.0,))
    weight = scalar_math(tree, "MULTIPLY", level.outputs[0], fresnel.outputs["Fac"])
    weight.use_clamp = True
    for node in (level, weight):
        _tag_part(node, "math", f"Rokeby: specular layer of {bsdf.name}", bsdf)
    nothing = _tag_part(tree.nodes.new("ShaderNodeEmission"), "black", schema.FRAME_NOTHING, bsdf)
    nothing.inputs["Strength"].default_value = 0.0
    attenuated = _tag_part(tree.nodes.new("ShaderNodeMixShader"), "attenuate", f"Rokeby: diffuse under the specular layer of {bsdf.name}", bsdf)
    tree.links.new(weight.outputs[0], attenuated.inputs["Fac"])
    tree.links.new(diffuse.outputs["BSDF"], attenuated.inputs[1])
    tree.links.new(nothing.outputs["Emission"], attenuated.inputs[2])
    total = _tag_part(tree.nodes.new("ShaderNodeAddShader"), "sum", f"Rokeby: {bsdf.name} with edited specular", bsdf)
    tree.links.new(attenuated.outputs["Shader"], total.inputs[0])
    tree.links.new(specular.outputs["BSDF"], total.inputs[1])
    result = total.outputs["Shader"]
    if not _fixed(bsdf.inputs["Metallic"], 0.0):
        metal = _clone(tree, bsdf, "metal", {"Metallic": 1.0, "Emission Strength": 0.0, "Alpha": 1.0}, (x + 300, y + 100))
        _feed_edited_normal(tree, metal.inputs["Normal"], schema.FRAME_EDITED_REFLECTIONS, (x, y - 620))
        if _has_coat(bsdf):
            _feed_edited_normal(tree, metal.inputs["Coat Normal"], schema.FRAME_EDITED_COAT, (x, y - 720))
        mix = _tag_part(tree.nodes.new("ShaderNodeMixShader"), "metallic", f"Rokeby: metallic of {bsdf.name}", bsdf)
        tree.links.new(_value_socket(tree, bsdf.inputs["Metallic"], bsdf, (x + 100, y + 400)), mix.inputs["Fac"])
        tree.links.new(result, mix.inputs[1])
        tree.links.new(metal.outputs["BSDF"], mix.inputs[2])
        result = mix.outputs["Shader"]
    if not _fixed(bsdf.inputs["Alpha"], 1.0):
        clear = _tag_part(tree.nodes.new("ShaderNodeBsdfTransparent"), "transparent", schema.FRAME_ALPHA, bsdf)
        mix = _tag_part(tree.nodes.new("ShaderNodeMixShader"), "alpha", f"Rokeby: alpha of {bsdf.name}", bsdf)
        tree.links.new(_value_socket(tree, bsdf.inputs["Alpha"], bsdf, (x + 100, y + 450)), mix.inputs["Fac"])
        tree.links.new(clear.outputs["BSDF"], mix.inputs[1])
        tree.links.new(result, mix.inputs[2])
        result = mix.outputs["Shader"]
    for sock in outgoing:
        tree.links.new(result, sock)


def _parts_of(tree, key) -> list:
    """The nodes standing in for the split BSDF whose parts carry ``key``, with the edited-normal
    groups that feed them. Found by tag, never by a node's name (artists rename nodes)."""
    parts = [nd for nd in tree.nodes if _ours(nd) and str(nd.get(schema.SOURCE_KEY)) == key]
    for part in list(parts):
        for sock in part.inputs:
            parts.extend(lk.from_node for lk in sock.links if _is_normal_group(lk.from_node))
    return list({nd.as_pointer(): nd for nd in parts}.values())


def _live_targets(parts) -> list:
    """The artist's input sockets the parts feed now (wherever those nodes were renamed or moved)."""
    inside = {nd.as_pointer() for nd in parts}
    return [lk.to_socket for nd in parts for out in nd.outputs for lk in out.links
            if lk.to_node.as_pointer() not in inside and not _ours(lk.to_node)]


def _unsplit(tree, bsdf) -> None:
    """Remove the parts standing in for ``bsdf`` and put it back where they were linked."""
    parts = _parts_of(tree, _split_key(bsdf))
    if not parts and schema.SPLIT_ID_KEY not in bsdf:
        # A file from before split ids, the BSDF renamed since: its parts carry the old name. Adopt
        # the one set of parts no split BSDF claims (with several, they stay for _recreate).
        claimed = {_split_key(nd) for nd in tree.nodes if schema.SPLIT_KEY in nd}
        free = {str(nd[schema.SOURCE_KEY]) for nd in tree.nodes if _ours(nd) and schema.SOURCE_KEY in nd} - claimed
        if len(free) == 1:
            parts = _parts_of(tree, free.pop())
    targets = _live_targets(parts) or recorded_targets(tree, bsdf.get(schema.SPLIT_KEY, []))
    for node in parts:
        transaction.remove_node(tree, node)
    for sock in targets:
        tree.links.new(bsdf.outputs["BSDF"], sock)
    for key in (schema.SPLIT_KEY, schema.SIGNATURE_KEY, schema.SPLIT_ID_KEY):
        if key in bsdf:
            del bsdf[key]


def _upstream(socket):
    """The artist's output socket linked to ``socket`` (None when unlinked or fed by our node)."""
    if socket.is_linked and not _ours(socket.links[0].from_node):
        return socket.links[0].from_socket
    return None


def _recreate(tree, key) -> None:
    """The Principled BSDF whose parts carry ``key`` was deleted (e.g. Clean Up ▸ Delete Unused
    Nodes removes it: it is unlinked while split). Build it again from its parts (every value,
    link and setting it had: the diffuse part holds all but the four inputs it overrides, which the
    specular part and the metallic/alpha mixes hold), link it where the parts fed, remove them."""
    parts = _parts_of(tree, key)
    by_role = {nd.get(schema.ROLE_KEY): nd for nd in parts if nd.get(schema.SOURCE_KEY) is not None}
    diffuse, specular = by_role["diffuse"], by_role["specular"]
    bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.name = str(diffuse.get(schema.SOURCE_NAME_KEY, bsdf.name))
    bsdf.distribution = diffuse.distribution
    bsdf.subsurface_method = diffuse.subsurface_method
    bsdf.location = (diffuse.location.x - 300, diffuse.location.y - 200)
    sources = {sock.identifier: diffuse for sock in diffuse.inputs}
    sources["Specular IOR Level"] = sources["Coat Weight"] = specular
    for dst in bsdf.inputs:
        src_node = sources.get(dst.identifier, diffuse)
        src = next(sk for sk in src_node.inputs if sk.identifier == dst.identifier)
        if hasattr(src, "default_value"):
            dst.default_value = src.default_value
        up = _upstream(src)
        if up is not None:
            tree.links.new(up, dst)
    for role, ident, default in (("metallic", "Metallic", 0.0), ("alpha", "Alpha", 1.0)):
        dst = bsdf.inputs[ident]
        mix = by_role.get(role)
        if mix is None:
            dst.default_value = default
            continue
        fac = mix.inputs["Fac"]
        up = _upstream(fac)
        if up is not None:
            tree.links.new(up, dst)
        elif fac.is_linked and fac.links[0].from_node.bl_idname == "ShaderNodeValue":
            dst.default_value = fac.links[0].from_node.outputs[0].default_value
        else:
            dst.default_value = fac.default_value
    targets = _live_targets(parts)
    for node in parts:
        transaction.remove_node(tree, node)
    for sock in targets:
        tree.links.new(bsdf.outputs["BSDF"], sock)


_NODE_KEYS = (schema.SPLIT_KEY, schema.SIGNATURE_KEY, schema.SPLIT_ID_KEY, schema.ORIGINAL_TREE_KEY)


def _snapshot(tree, keys=_NODE_KEYS) -> dict:
    """What an install may change in ``tree`` (rokeby.blender.nodes.snapshot, with our keys)."""
    return nodes.snapshot(tree, keys)


atomic = nodes.atomic  # all or nothing on one node tree (rokeby.blender.nodes)
_restore = nodes.restore


def install(material) -> int:
    """Make ``material``'s specular lobes use the edited normal; returns how many BSDFs now do.

    Glossy/Anisotropic BSDFs and metallic Principled BSDFs (metallic = 1) get n' at their Normal
    (and Coat Normal) input; other Principled BSDFs are split so that the diffuse lobe keeps the
    original normal (see ``_split``). A normal already linked there (a bump map) passes through.
    Installing twice changes nothing. Atomic: an exception half way leaves the node tree exactly
    as it was (``_restore``)."""
    if material is None or not material.use_nodes or material.node_tree is None:
        return 0
    tree = material.node_tree
    return atomic(tree, _NODE_KEYS, lambda: _install_tree(tree, material))


def _bsdfs_inside(tree, seen=None) -> bool:
    """Whether ``tree`` (a node group) holds a BSDF the add-on edits, at any depth."""
    seen = set() if seen is None else seen
    if tree is None or tree.name in seen:
        return False
    seen.add(tree.name)
    for node in tree.nodes:
        if node.bl_idname in SPECULAR_BSDFS or node.bl_idname == "ShaderNodeBsdfPrincipled":
            return True
        if node.bl_idname == "ShaderNodeGroup" and _bsdfs_inside(node.node_tree, seen):
            return True
    return False


def _local_copy(node, material):
    """The group-local copy of ``node``'s node group that this material's edit goes into (made on
    first use): the original group, used by other materials, stays unedited."""
    tree = node.node_tree
    if tree.get(schema.COPY_OF_KEY) is not None:
        return tree
    copy = tree.copy()
    copy.name = f"{tree.name} (Rokeby: {material.name})"
    copy[schema.COPY_OF_KEY] = tree
    node[schema.ORIGINAL_TREE_KEY] = tree
    node.node_tree = copy
    return copy


def _install_tree(tree, material) -> int:
    count = 0
    # By name: re-splitting a BSDF removes nodes of this very loop's snapshot (a removed node's
    # Python object must not be touched again).
    for name in [nd.name for nd in tree.nodes]:
        node = tree.nodes.get(name)
        if node is None or _ours(node):
            continue
        x, y = node.location
        if node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None:
            if node.node_tree.get(schema.COPY_OF_KEY) is not None or _bsdfs_inside(node.node_tree):
                count += _install_tree(_local_copy(node, material), material)
        elif node.bl_idname in SPECULAR_BSDFS:
            _feed_edited_normal(tree, node.inputs["Normal"], schema.FRAME_EDITED_REFLECTIONS, (x - 250, y - 300))
            count += 1
        elif node.bl_idname == "ShaderNodeBsdfPrincipled":
            if schema.SPLIT_KEY in node:
                if node.get(schema.SIGNATURE_KEY) != _signature(node):
                    _unsplit(tree, node)
                    _split(tree, node)
            elif _is_metal(node):
                _feed_edited_normal(tree, node.inputs["Normal"], schema.FRAME_EDITED_REFLECTIONS, (x - 250, y - 300))
                if _has_coat(node):
                    _feed_edited_normal(tree, node.inputs["Coat Normal"], schema.FRAME_EDITED_COAT, (x - 250, y - 400))
            else:
                _split(tree, node)
            count += 1
    return count


def _copies_in(tree) -> list:
    """The group-local copies used by ``tree`` (and by those, recursively)."""
    out = []
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None and node.node_tree.get(schema.COPY_OF_KEY) is not None:
            out.append(node.node_tree)
            out.extend(_copies_in(node.node_tree))
    return out


def sync(material) -> bool:
    """Bring split parts up to date after an artist edited the original Principled BSDF (values,
    links, metallic becoming 1 or not); returns whether anything was rebuilt."""
    if material is None or not material.use_nodes or material.node_tree is None:
        return False
    return any([_sync_tree(t) for t in [material.node_tree, *_copies_in(material.node_tree)]])


def _sync_tree(tree) -> bool:
    stale = [nd for nd in tree.nodes if schema.SPLIT_KEY in nd and nd.get(schema.SIGNATURE_KEY) != _signature(nd)]
    for bsdf in stale:
        _unsplit(tree, bsdf)
        if not _is_metal(bsdf):
            _split(tree, bsdf)
        else:
            _feed_edited_normal(tree, bsdf.inputs["Normal"], schema.FRAME_EDITED_REFLECTIONS, (bsdf.location.x - 250, bsdf.location.y - 300))
    return bool(stale)


def installed(material) -> bool:
    if material is None or not material.use_nodes or material.node_tree is None:
        return False
    tree = material.node_tree
    return any(_ours(nd) or schema.ORIGINAL_TREE_KEY in nd for nd in tree.nodes)


def uninstall(material) -> bool:
    """Take everything the add-on put in ``material`` out again, restoring the links it replaced
    (bump maps feed their BSDFs again, split Principled BSDFs are linked where they were)."""
    if material is None or not material.use_nodes or material.node_tree is None:
        return False
    found = installed(material)
    _uninstall_tree(material.node_tree)
    return found


def _uninstall_tree(tree) -> None:
    # Checked before anything changes: a BSDF that cannot be built again refuses the removal.
    for key in {str(nd[schema.SOURCE_KEY]) for nd in tree.nodes if _ours(nd) and schema.SOURCE_KEY in nd}:
        if not any(schema.SPLIT_KEY in nd and _split_key(nd) == key for nd in tree.nodes):
            roles = {nd.get(schema.ROLE_KEY) for nd in tree.nodes if _ours(nd) and str(nd.get(schema.SOURCE_KEY)) == key}
            if "diffuse" not in roles or "specular" not in roles:
                raise RokebyError(
                    f"material node tree '{tree.name}': the Principled BSDF that Rokeby split was deleted together "
                    "with its diffuse/specular parts; its settings are lost, so the render nodes are not removed "
                    "(undo the deletion, or delete the nodes labelled 'Rokeby:' by hand)")
    for node in [nd for nd in tree.nodes if schema.ORIGINAL_TREE_KEY in nd]:
        copy, original = node.node_tree, node[schema.ORIGINAL_TREE_KEY]
        del node[schema.ORIGINAL_TREE_KEY]
        if original is not None:
            node.node_tree = original
        if copy is not None and copy.get(schema.COPY_OF_KEY) is not None and copy.users == 0:
            transaction.remove(copy)
    for bsdf in [nd for nd in tree.nodes if schema.SPLIT_KEY in nd]:
        _unsplit(tree, bsdf)
    # Parts whose Principled BSDF is gone (deleted as "unused"): it is built again from them.
    for key in dict.fromkeys(str(nd[schema.SOURCE_KEY]) for nd in tree.nodes if _ours(nd) and nd.get(schema.ROLE_KEY) == "diffuse" and schema.SOURCE_KEY in nd):
        _recreate(tree, key)
    for group in [nd for nd in tree.nodes if _ours(nd) and nd.bl_idname == "ShaderNodeGroup"]:
        upstream = [lk.from_socket for lk in group.inputs["Normal"].links] if "Normal" in group.inputs else []
        targets = [lk.to_socket for out in group.outputs for lk in out.links]
        transaction.remove_node(tree, group)
        if upstream:
            for sock in targets:
                tree.links.new(upstream[0], sock)
    for node in [nd for nd in tree.nodes if _ours(nd)]:
        transaction.remove_node(tree, node)
