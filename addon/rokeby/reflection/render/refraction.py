"""Final renders of edited refractions (paper §7.1, "Refractions"; Fig. 8).

A refraction constraint fixes a refracting position p and the edited *transmitted* direction e_t
there (no refracted position). The evaluator stores the MLS rotation field of the rows
[p, t, e_t] as the point attribute ``rokeby_refraction``; this module turns it into the normal a
Refraction BSDF must use so that it sends the view ray into e_t.

The generalised half vector. Snell's law in vector form, η₁ (i × n) = η₂ (t × n), says that the
tangential parts of η₁ i and η₂ t agree, so η₁ i − η₂ t is parallel to the normal n. With the
view ray i = −V (V towards the viewer), η₁ = 1 outside and η₂ = η the material's IOR, the normal
that refracts V into a wanted e_t is therefore

    n'_t = normalize(−(V + η e_t))            (η > 1; for η < 1 the opposite sign)

(Walter et al. 2007 call −(η_i i + η_o o) the generalised half vector of refraction). For the
physical t = refract(−V, N, 1/η) this is exactly N, so an unedited field renders as before.

What refraction can reach. For η > 1 a ray entering through some normal n' with n'·V > 0 leaves
along a direction within α_max = arccos(1/η) of −V (for η < 1: arccos η), and it must travel
below the surface. Edits outside that set are moved into it continuously, never switched to a
constant: first an e_t above the tangent plane is folded back below it (about the plane
e·N = −m, m = 0.02, or the physical t's own depth when that is less), then an e_t farther than
the reachable cone from −V is pulled onto the cone cos α = c, c = c_max + 0.05 (1 − c_max),
c_max = min(η, 1/η), or onto the physical t's cone where grazing views make that one wider. With
e_t inside the cone n'_t·V > 0 holds. Last, n'_t may not tip so far that the mirror reflection of
the view about it goes below the surface (Cycles then bends such a normal itself, sending the
transmitted ray out through the surface: the path dies, a dark pixel): r = reflect(−V, n'_t) is
folded about the plane r·N = ε (ε = 0.05, or V·N when less) and n'_t = normalize(V + r) rebuilt;
the transmitted direction is then refract(−V, n'_t), below the surface for η > 1. Every step
leaves the identity untouched and is continuous. No black and no NaN pixels: measured in
tests/reflection/test_refraction.py.

Back faces (rays leaving the object) keep N: the edit acts where rays enter, as in the paper,
where the exiting direction is the edited one. The same holds where the physical ray has no
transmitted direction (total internal reflection, η < 1), where the shading normal faces away
from the viewer, and for an unusable IOR (≤ 0.001, ≥ 1000, NaN, or within 1e-4 of 1, where
refraction cannot be edited at all). On an open mesh (a single glass sheet) the same happens:
the entering ray is edited, and Cycles then treats it as inside the material until it meets
another surface, as for an unedited open sheet.

Materials (``install``/``uninstall``):

* Refraction BSDF: its Normal is fed n'_t through the group; a bump map already linked there
  passes through the group.
* Glass BSDF: it reflects and refracts with one normal, so it is split into
  Mix(Fresnel(IOR), Refraction(n'_t), Glossy), with the Glass's colour, roughness, IOR and
  distribution (the Glossy's normal is the original one, or n' from rokeby.reflection.render.shading when that
  installs too, so Glass reflections follow reflection edits and its refractions refraction edits).
  For sharp glass (roughness 0) this is the same sum Cycles' Glass evaluates; for rough glass the
  Fresnel factor is taken at the shading normal instead of per microfacet (a small difference).
  The Glass node stays in the tree, unlinked, holding the artist's values; installing again after
  editing it rebuilds the parts, and ``uninstall`` links it back where it was.
* Principled BSDF transmission is NOT edited: Blender's Principled BSDF shades all its lobes with
  one Normal input, and its transmission lobe cannot be separated from its glass reflection
  without rebuilding the whole node. Use a Glass or Refraction BSDF for edited refraction.

The mirror's IOR (``rokeby.ior``, read by the group as an object attribute like the Freeze
settings) must match the BSDF's IOR for e_t to come out exactly; ``rokeby.api.ior_from_material``
copies it from the material. Freeze: the physical t is refracted from ``rokeby.freeze_eye`` while
the mirror is frozen; n'_t refracts the actual view ray into the edited direction.
"""

from __future__ import annotations

import uuid

import bpy
import numpy as np

from . import shading
from ...blender import transaction
from ...core.errors import RokebyError
from .shading import mix_vector, scalar_math, vector_math
from ...core import schema, vecmath

VERSION = 2

BELOW_MARGIN = 0.02  # m: edited directions are kept at least this far below the tangent plane
REACH_MARGIN = 0.05  # μ: fraction of the reachable cone (in cos) kept clear of its grazing edge
REFLECT_MARGIN = 0.05  # ε: reflect(−V, n'_t) is kept this far above the tangent plane
IOR_RANGE = (1e-3, 1e3)
IOR_ONE = 1e-4


# --- the maths, in numpy (the node group computes the same, node by node) ------------------------


def _dot(a, b):
    return np.sum(a * b, axis=-1, keepdims=True)


def _normalize(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0.0, v / np.where(n > 0.0, n, 1.0), 0.0)


def _refract(i, n, eta):
    """GLSL/Blender refract: zero vector on total internal reflection (rokeby.core.vecmath)."""
    return vecmath.refract(i, n, eta)


def _rotate(rotvec, v):
    """Rodrigues rotation of ``v`` by rotation vectors (axis × angle)."""
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    axis = _normalize(rotvec)
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * _dot(axis, v) * (1.0 - c)


def half_vector(view, edited, ior):
    """The generalised half vector n'_t = normalize(∓(V + η e_t)) that refracts ``view`` (towards
    the viewer) into ``edited`` (the transmitted direction); sign so that n'_t·V > 0 for
    reachable directions."""
    v = np.asarray(view, np.float64)
    e = np.asarray(edited, np.float64)
    eta = np.asarray(ior, np.float64)[..., None] if np.ndim(ior) else float(ior)
    sign = np.where(eta > 1.0, -1.0, 1.0)
    return _normalize(sign * (v + eta * e))


def reachable_cos(ior):
    """cos of the widest angle between −V and a transmitted direction that refraction into a
    material of this IOR can reach: min(η, 1/η)."""
    eta = np.asarray(ior, np.float64)
    return np.minimum(eta, 1.0 / eta)


def edited_normal(view, normal, ior, rotvec=None, *, frozen_view=None, backfacing=None):
    """What the node group computes, for arrays of shading points: the normal n'_t (M, 3) and the
    transmitted direction it produces, e_t after the reachable-cone clamp (M, 3).

    ``view``: V towards the viewer, ``normal``: shading normal N (unit, (M, 3)); ``ior``: η (scalar
    or (M,)); ``rotvec``: the field R_t as rotation vectors (None: identity); ``frozen_view``: the
    view the physical t is refracted from (Freeze); ``backfacing``: (M,) bools.
    """
    v = np.asarray(view, np.float64).reshape(-1, 3)
    n = np.asarray(normal, np.float64).reshape(-1, 3)
    eta_raw = np.broadcast_to(np.asarray(ior, np.float64), (len(v),))[:, None]
    with np.errstate(invalid="ignore"):
        ok_eta = (eta_raw > IOR_RANGE[0]) & (eta_raw < IOR_RANGE[1]) & (np.abs(eta_raw - 1.0) > IOR_ONE)
    eta = np.minimum(np.maximum(np.nan_to_num(eta_raw, nan=IOR_RANGE[0]), IOR_RANGE[0]), IOR_RANGE[1])
    d = -v
    t_view = _refract(d, n, 1.0 / eta)  # physical, from the actual view
    vf = v if frozen_view is None else np.asarray(frozen_view, np.float64).reshape(-1, 3)
    t = _refract(-vf, n, 1.0 / eta)
    e = t if rotvec is None else _rotate(np.asarray(rotvec, np.float64).reshape(-1, 3), t)
    # Keep e below the tangent plane: fold about e·N = −m (m no deeper than the physical t).
    m = np.minimum(BELOW_MARGIN, -_dot(t_view, n))
    over = np.maximum(_dot(e, n) + m, 0.0)
    e = _normalize(e - 2.0 * over * n)
    # Pull e into the reachable cone around d (or the physical t's cone where that is wider).
    c_max = reachable_cos(eta)
    c = np.minimum(c_max + REACH_MARGIN * (1.0 - c_max), _dot(d, t_view))
    a = _dot(e, d)
    u = _normalize(e - a * d)
    e = np.where(a < c, c * d + np.sqrt(np.maximum(1.0 - c * c, 0.0)) * u, e)
    h = half_vector(v, e, eta[:, 0])
    # Keep reflect(−V, n'_t) above the tangent plane (Cycles would otherwise bend n'_t itself, and
    # the transmitted ray with it, above the surface): fold it about r·N = ε and rebuild n'_t.
    r = -v + 2.0 * _dot(v, h) * h
    eps = np.minimum(REFLECT_MARGIN, _dot(v, n))
    r = _normalize(r - 2.0 * np.minimum(_dot(r, n) - eps, 0.0) * n)
    h = _normalize(v + r)
    e = _refract(d, h, 1.0 / eta)
    ok = ok_eta & (_dot(t, t) > 0.25) & (_dot(t_view, t_view) > 0.25) & (_dot(v, n) > 1e-4)
    if backfacing is not None:
        ok &= ~np.asarray(backfacing, bool).reshape(-1, 1)
    return np.where(ok, h, n), e


# --- the node group ------------------------------------------------------------------------------


def _fresh_group():
    """Our group emptied for (re)building when missing or older than this module's VERSION (or
    shading's, whose ``_fresh_group`` it goes through); None when it is current."""
    ng = bpy.data.node_groups.get(schema.REFRACTION_GROUP)
    if ng is not None and ng.get(schema.REFRACTION_VERSION_KEY) != VERSION and schema.VERSION_KEY in ng:
        del ng[schema.VERSION_KEY]  # makes shading._fresh_group rebuild it
    vec = "NodeSocketVector"
    ng = shading._fresh_group(schema.REFRACTION_GROUP, [("Edited Normal", "OUTPUT", vec), ("Transmitted", "OUTPUT", vec), ("Normal", "INPUT", vec)])
    if ng is not None:
        ng[schema.REFRACTION_VERSION_KEY] = VERSION
    return ng


def node_group():
    """"Rokeby Edited Refraction Normal": Normal in (a bump map upstream; unlinked → the
    geometry's normal); Edited Normal n'_t and Transmitted e_t out (see the module docstring)."""
    ng = _fresh_group()
    if ng is None:
        return bpy.data.node_groups[schema.REFRACTION_GROUP]
    nodes = ng.nodes

    def dot(a, b):
        return vector_math(ng, "DOT_PRODUCT", a, b).outputs["Value"]

    def scale(v, s):
        node = vector_math(ng, "SCALE", v)
        ng.links.new(s, node.inputs["Scale"])
        return node.outputs["Vector"]

    def vop(op, *vs, value=None):
        return vector_math(ng, op, *vs, scale=value).outputs["Vector"]

    def op(kind, *inputs, values=()):
        return scalar_math(ng, kind, *inputs, values=values).outputs["Value"]

    out = nodes.new("NodeGroupOutput")
    gin = nodes.new("NodeGroupInput")
    geo = nodes.new("ShaderNodeNewGeometry")
    # N: the linked Normal input (a bump map), else the geometry's (as shading.direction_group).
    linked = op("GREATER_THAN", vector_math(ng, "LENGTH", gin.outputs["Normal"]).outputs["Value"], values=(0.0,))
    normal = mix_vector(ng, linked, geo.outputs["Normal"], gin.outputs["Normal"])
    view = geo.outputs["Incoming"]
    d = vop("SCALE", view, value=-1.0)
    # η from the mirror (object attribute, like Freeze), made finite before anything uses it.
    ior_attr = nodes.new("ShaderNodeAttribute")
    ior_attr.attribute_type = "OBJECT"
    ior_attr.attribute_name = "rokeby.ior"
    raw = ior_attr.outputs["Fac"]
    eta = op("MINIMUM", op("MAXIMUM", raw, values=(IOR_RANGE[0],)), values=(IOR_RANGE[1],))
    ok_eta = op("MULTIPLY", op("GREATER_THAN", raw, values=(IOR_RANGE[0],)), op("LESS_THAN", raw, values=(IOR_RANGE[1],)))
    ok_eta = op("MULTIPLY", ok_eta, op("GREATER_THAN", op("ABSOLUTE", op("SUBTRACT", raw, values=(1.0,))), values=(IOR_ONE,)))
    inv_eta = op("DIVIDE", _const(ng, 1.0), eta)

    def refract_about(incident, about):
        node = vector_math(ng, "REFRACT", incident, about)
        ng.links.new(inv_eta, node.inputs["Scale"])
        return node.outputs["Vector"]

    def refract(incident):
        return refract_about(incident, normal)

    t_view = refract(d)
    # Freeze: the physical t is refracted from the frozen eye (rokeby.freeze_eye).
    frozen = nodes.new("ShaderNodeAttribute")
    frozen.attribute_type = "OBJECT"
    frozen.attribute_name = "rokeby.freeze"
    eye = nodes.new("ShaderNodeAttribute")
    eye.attribute_type = "OBJECT"
    eye.attribute_name = "rokeby.freeze_eye"
    to_eye = vop("NORMALIZE", vop("SUBTRACT", eye.outputs["Vector"], geo.outputs["Position"]))
    t_frozen = refract(vop("SCALE", to_eye, value=-1.0))
    t = mix_vector(ng, frozen.outputs["Fac"], t_view, t_frozen)
    # e_t = R_t t from the stored rotation vectors (axis × angle).
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = schema.REFRACTION_ATTRIBUTE
    rot = nodes.new("ShaderNodeVectorRotate")
    rot.rotation_type = "AXIS_ANGLE"
    ng.links.new(t, rot.inputs["Vector"])
    ng.links.new(vop("NORMALIZE", attr.outputs["Vector"]), rot.inputs["Axis"])
    ng.links.new(vector_math(ng, "LENGTH", attr.outputs["Vector"]).outputs["Value"], rot.inputs["Angle"])
    e = rot.outputs["Vector"]
    # Fold below the tangent plane: e ← normalize(e − 2 max(e·N + m, 0) N), m = min(0.02, −t·N).
    m = op("MINIMUM", op("MULTIPLY", dot(t_view, normal), values=(-1.0,)), values=(BELOW_MARGIN,))
    over = op("MAXIMUM", op("ADD", dot(e, normal), m), values=(0.0,))
    e = vop("NORMALIZE", vop("SUBTRACT", e, scale(normal, op("MULTIPLY", over, values=(2.0,)))))
    # Reachable cone: c = min(c_max + μ (1 − c_max), d·t), c_max = min(η, 1/η).
    c_max = op("MINIMUM", eta, inv_eta)
    c_lim = op("ADD", c_max, op("MULTIPLY", op("SUBTRACT", _const(ng, 1.0), c_max), values=(REACH_MARGIN,)))
    c = op("MINIMUM", c_lim, dot(d, t_view))
    a = dot(e, d)
    u = vop("NORMALIZE", vop("SUBTRACT", e, scale(d, a)))
    sine = op("SQRT", op("MAXIMUM", op("SUBTRACT", _const(ng, 1.0), op("MULTIPLY", c, c)), values=(0.0,)))
    on_cone = vop("ADD", scale(d, c), scale(u, sine))
    e = mix_vector(ng, op("LESS_THAN", a, c), e, on_cone)
    # n'_t = normalize(s (V + η e)), s = −1 for η > 1, +1 for η < 1.
    sign = op("SUBTRACT", _const(ng, 1.0), op("MULTIPLY", op("GREATER_THAN", eta, values=(1.0,)), values=(2.0,)))
    half = vop("NORMALIZE", scale(vop("ADD", view, scale(e, eta)), sign))
    # Keep reflect(−V, n'_t) above the tangent plane: fold it about r·N = ε, n'_t = normalize(V + r).
    r = vop("REFLECT", d, half)
    eps = op("MINIMUM", dot(view, normal), values=(REFLECT_MARGIN,))
    low = op("MINIMUM", op("SUBTRACT", dot(r, normal), eps), values=(0.0,))
    r = vop("NORMALIZE", vop("SUBTRACT", r, scale(normal, op("MULTIPLY", low, values=(2.0,)))))
    half = vop("NORMALIZE", vop("ADD", view, r))
    e = refract_about(d, half)
    # Keep N on back faces, where t does not exist, where N faces away, and for an unusable IOR.
    ok = op("MULTIPLY", ok_eta, op("GREATER_THAN", dot(t, t), values=(0.25,)))
    ok = op("MULTIPLY", ok, op("GREATER_THAN", dot(t_view, t_view), values=(0.25,)))
    ok = op("MULTIPLY", ok, op("GREATER_THAN", dot(view, normal), values=(1e-4,)))
    ok = op("MULTIPLY", ok, op("SUBTRACT", _const(ng, 1.0), geo.outputs["Backfacing"]))
    ng.links.new(mix_vector(ng, ok, normal, half), out.inputs["Edited Normal"])
    ng.links.new(e, out.inputs["Transmitted"])
    return ng


def _const(ng, value):
    node = ng.nodes.new("ShaderNodeValue")
    node.outputs[0].default_value = value
    return node.outputs[0]


# --- wiring materials ----------------------------------------------------------------------------


def _ours(node) -> bool:
    return bool(node.get(schema.REFRACTION_TAG))


def _shading_ours(node) -> bool:
    return bool(node.get(schema.LINK_TAG))


def _tag(node, role, label, source=None):
    node[schema.REFRACTION_TAG] = role
    node.label = label
    if source is not None:
        node[schema.REFRACTION_SOURCE_KEY] = source
    return node


def _is_group(node) -> bool:
    return node.bl_idname == "ShaderNodeGroup" and node.get(schema.REFRACTION_TAG) == "normal"


def _feed(tree, socket, location, source=None):
    """Feed n'_t to ``socket`` through its own group node (``shading.feed_through``)."""

    def new_group():
        group = _tag(tree.nodes.new("ShaderNodeGroup"), "normal", schema.FRAME_EDITED_REFRACTION, source)
        group.node_tree = node_group()
        group.location = location
        return group

    return shading.feed_through(tree, socket, _is_group, new_group)


def _signature(glass) -> str:
    return shading.node_signature(glass, "distribution")


def _copy_input(tree, src, dst):
    dst.default_value = src.default_value
    for lk in src.links:
        tree.links.new(lk.from_socket, dst)


def _split(tree, glass) -> None:
    """Stand Mix(Fresnel(IOR), Refraction(n'_t), Glossy) in for ``glass`` (see the module
    docstring); the Glass node stays, unlinked, with the artist's values."""
    x, y = glass.location
    sid = uuid.uuid4().hex[:12]
    outgoing = shading.recorded_targets(tree, shading.record_outgoing(glass, schema.REFRACTION_SPLIT_KEY))
    glass[schema.REFRACTION_SPLIT_ID_KEY] = sid
    glass[schema.REFRACTION_SIGNATURE_KEY] = _signature(glass)
    refr = _tag(tree.nodes.new("ShaderNodeBsdfRefraction"), "refraction", f"Rokeby: refraction part of {glass.name}", sid)
    refr.distribution = "BECKMANN" if glass.distribution == "BECKMANN" else "GGX"
    glossy = _tag(tree.nodes.new("ShaderNodeBsdfGlossy"), "reflection", f"Rokeby: reflection part of {glass.name}", sid)
    glossy.distribution = glass.distribution
    fresnel = _tag(tree.nodes.new("ShaderNodeFresnel"), "fresnel", f"Rokeby: Fresnel of {glass.name}", sid)
    mix = _tag(tree.nodes.new("ShaderNodeMixShader"), "mix", f"Rokeby: {glass.name} split", sid)
    for name in ("Color", "Roughness"):
        _copy_input(tree, glass.inputs[name], refr.inputs[name])
        _copy_input(tree, glass.inputs[name], glossy.inputs[name])
    _copy_input(tree, glass.inputs["IOR"], refr.inputs["IOR"])
    _copy_input(tree, glass.inputs["IOR"], fresnel.inputs["IOR"])
    normal = glass.inputs["Normal"]
    if normal.is_linked:
        src = normal.links[0].from_socket
        tree.links.new(src, glossy.inputs["Normal"])
        tree.links.new(src, fresnel.inputs["Normal"])
        tree.links.new(src, refr.inputs["Normal"])
    _feed(tree, refr.inputs["Normal"], (x + 50, y - 350), sid)
    tree.links.new(fresnel.outputs["Fac"], mix.inputs["Fac"])
    tree.links.new(refr.outputs["BSDF"], mix.inputs[1])
    tree.links.new(glossy.outputs["BSDF"], mix.inputs[2])
    for node, (dx, dy) in ((refr, (300, 0)), (glossy, (300, -150)), (fresnel, (300, 150)), (mix, (500, 0))):
        node.location = (x + dx, y + dy)
    for sock in outgoing:
        tree.links.new(mix.outputs["Shader"], sock)


def _unsplit(tree, glass) -> None:
    """Remove the parts standing in for ``glass`` and link it back where it was."""
    targets = shading.recorded_targets(tree, glass.get(schema.REFRACTION_SPLIT_KEY, []))
    sid = glass.get(schema.REFRACTION_SPLIT_ID_KEY)
    parts = [nd for nd in tree.nodes if _ours(nd) and nd.get(schema.REFRACTION_SOURCE_KEY) == sid]
    names = {nd.name for nd in parts}
    # Edited-normal groups of rokeby.reflection.render.shading that feed only the parts (the Glossy's n') go too.
    for part in list(parts):
        for sock in part.inputs:
            for lk in sock.links:
                up = lk.from_node
                if _shading_ours(up) and up.bl_idname == "ShaderNodeGroup" and up.name not in names:
                    if all(l2.to_node.name in names for out in up.outputs for l2 in out.links):
                        parts.append(up)
                        names.add(up.name)
    # Where the parts feed now (found by tag: the Material Output may have been renamed since).
    live = [lk.to_socket for nd in parts for out in nd.outputs for lk in out.links
            if lk.to_node.name not in names and not _ours(lk.to_node) and not _shading_ours(lk.to_node)]
    targets = live or targets
    for node in parts:
        transaction.remove_node(tree, node)
    for sock in targets:
        tree.links.new(glass.outputs["BSDF"], sock)
    for key in (schema.REFRACTION_SPLIT_KEY, schema.REFRACTION_SPLIT_ID_KEY, schema.REFRACTION_SIGNATURE_KEY):
        if key in glass:
            del glass[key]


def install(material) -> int:
    """Feed the edited refraction normal to ``material``'s Refraction BSDFs and split its Glass
    BSDFs (see the module docstring); returns how many BSDFs now refract with n'_t. A normal
    already linked there (a bump map) passes through. Installing twice changes nothing, except
    that a Glass BSDF edited since it was split is split again from its new values."""
    if material is None or not material.use_nodes or material.node_tree is None:
        return 0
    tree = material.node_tree
    # Atomic: an exception half way leaves the node tree exactly as it was.
    return shading.atomic(tree, (schema.REFRACTION_SPLIT_KEY, schema.REFRACTION_SPLIT_ID_KEY, schema.REFRACTION_SIGNATURE_KEY), lambda: _install_tree(tree))


def _install_tree(tree) -> int:
    count = 0
    # By name: re-splitting removes nodes of this loop's snapshot (never touch a removed node).
    for name in [nd.name for nd in tree.nodes]:
        node = tree.nodes.get(name)
        if node is None or _ours(node) or _shading_ours(node):
            continue
        x, y = node.location
        if node.bl_idname == "ShaderNodeBsdfRefraction":
            _feed(tree, node.inputs["Normal"], (x - 250, y - 300))
            count += 1
        elif node.bl_idname == "ShaderNodeBsdfGlass":
            if schema.REFRACTION_SPLIT_KEY in node:
                if node.get(schema.REFRACTION_SIGNATURE_KEY) != _signature(node):
                    _unsplit(tree, node)
                    _split(tree, node)
            else:
                _split(tree, node)
            count += 1
    return count


def installed(material) -> bool:
    return material is not None and material.use_nodes and material.node_tree is not None and any(_ours(nd) for nd in material.node_tree.nodes)


def uninstall(material) -> bool:
    """Take everything this module put in ``material`` out again: split Glass BSDFs are linked
    where they were, bump maps feed their Refraction BSDFs again. Returns whether anything was
    there."""
    if material is None or not material.use_nodes or material.node_tree is None:
        return False
    tree = material.node_tree
    found = installed(material)
    for glass in [nd for nd in tree.nodes if schema.REFRACTION_SPLIT_KEY in nd]:
        _unsplit(tree, glass)
    for group in [nd for nd in tree.nodes if _is_group(nd)]:
        upstream = [lk.from_socket for lk in group.inputs["Normal"].links]
        targets = [lk.to_socket for out in group.outputs for lk in out.links]
        transaction.remove_node(tree, group)
        if upstream:
            for sock in targets:
                tree.links.new(upstream[0], sock)
    for node in [nd for nd in tree.nodes if _ours(nd)]:
        transaction.remove_node(tree, node)
    return found


def material_ior(material) -> "float | None":
    """The IOR of ``material``'s first Glass or Refraction BSDF, else of its first Principled BSDF
    with transmission; None when it has none. A linked IOR is refused (it has no one value)."""
    if material is None or not material.use_nodes or material.node_tree is None:
        return None
    nodes = [nd for nd in material.node_tree.nodes if not _ours(nd) and not _shading_ours(nd)]
    found = [nd for nd in nodes if nd.bl_idname in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction")]
    found += [
        nd for nd in nodes
        if nd.bl_idname == "ShaderNodeBsdfPrincipled"
        and (nd.inputs["Transmission Weight"].is_linked or nd.inputs["Transmission Weight"].default_value > 0.0)
    ]
    if not found:
        return None
    sock = found[0].inputs["IOR"]
    if sock.is_linked:
        raise RokebyError(f"material '{material.name}': the IOR of '{found[0].name}' is linked (no single value); set the mirror's IOR by hand")
    ior = float(sock.default_value)
    if not (np.isfinite(ior) and ior > 0.0):
        raise RokebyError(f"material '{material.name}': the IOR of '{found[0].name}' is {ior}, not > 0")
    return ior
