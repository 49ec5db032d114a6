"""The painted values in the material: :func:`setup` wires each parameter into the Principled BSDF
through a Multiply node named ``rokeby_global_<param>`` whose second value is that parameter's
global slider (:func:`set_global`; 1 = as painted); the colours (``COLORS``) go through a Mix
(Multiply) node with their global tint. :func:`remove` puts the material back as it was;
:func:`migrate` gives files painted before a parameter existed its nodes."""

from __future__ import annotations

import math

import numpy as np

from ..blender import transaction
from ..core import schema
from .parameters import COLORS, MAX_COLOR, PARAMS, _check_mesh
from .texture import _check_texture_args, remove_texture, setup_texture


def _principled(mat):
    out = next((n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output), None)
    if out is not None and out.inputs["Surface"].is_linked:
        n = out.inputs["Surface"].links[0].from_node
        if n.type == "BSDF_PRINCIPLED":
            return n
    return next((n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


# What setup does with a painted Principled input that another node (a texture) already drives.
LINKED = ("REFUSE", "REPLACE")
# schema.APPEARANCE_REPLACED_KEY, on a rokeby_global_<param> node: [node name, output identifier] of the link it
# replaced (setup(linked='REPLACE')), put back by remove().


def _foreign_links(bsdf) -> list:
    """(param, socket name, link) of each painted Principled input driven by a node that is not
    Rokeby's."""
    out = []
    for param, (_attr_name, socket_name, _d, _r) in PARAMS.items():
        sock = bsdf.inputs[socket_name]
        if sock.is_linked:
            link = sock.links[0]
            if not link.from_node.name.startswith(schema.APPEARANCE_NODE_PREFIX):
                out.append((param, socket_name, link))
    return out


@transaction.atomic(materials=transaction.of_object)
def setup(obj, material=None, target: str = "POINT", resolution: int = 1024, uv_map: str | None = None,
          linked: str = "REFUSE"):
    """Creates the attributes (filled with the material's current values) and wires them into the
    Principled BSDF of ``material`` (default: the object's active material; a new one if none).
    Idempotent: existing attributes and nodes are kept. Returns the material.

    ``target``: 'POINT' (per-point attributes, the default) or 'TEXTURE': an image per parameter
    (``resolution``², float, on the UV map ``uv_map``, default the active one) filled from the
    attributes and read through the UV map in place of them (see :func:`setup_texture`).

    ``linked``: what to do when a painted input (Base Color, Roughness, …) is driven by another
    node, e.g. an Image Texture. 'REFUSE' (default): a ValueError naming the inputs and their
    nodes, nothing changed. 'REPLACE': the painted values take those inputs over (they start
    from the inputs' unlinked values); the replaced links are recorded and :func:`remove` puts
    them back (the texture nodes stay in the material, unlinked, meanwhile)."""
    import bpy

    _check_mesh(obj)
    target = str(target).upper()
    if target not in ("POINT", "TEXTURE"):
        raise ValueError(f"target: expected 'POINT' or 'TEXTURE', got {target!r}")
    linked = str(linked).upper()
    if linked not in LINKED:
        raise ValueError(f"linked: expected 'REFUSE' or 'REPLACE', got {linked!r}")
    if target == "TEXTURE":
        _check_texture_args(obj, resolution, uv_map)  # before anything changes
    mat = material if material is not None else obj.active_material
    if mat is None:
        mat = bpy.data.materials.new(f"{obj.name} Painted")
        mat.use_nodes = True
        obj.data.materials.append(mat)
    had_nodes = mat.use_nodes
    if not mat.use_nodes:
        mat.use_nodes = True
    bsdf = _principled(mat)
    if bsdf is None:
        mat.use_nodes = had_nodes
        raise ValueError(f"material: '{mat.name}' has no Principled BSDF to paint into")
    foreign = _foreign_links(bsdf)
    if foreign and linked == "REFUSE":
        mat.use_nodes = had_nodes
        what = ", ".join(f"{sock} (from '{link.from_node.name}')" for _p, sock, link in foreign)
        raise ValueError(f"material: in '{mat.name}', {what} {'is' if len(foreign) == 1 else 'are'} driven by other nodes, "
                         "which painting would replace; nothing was changed. Unlink them, or set up with Replace Texture Links "
                         "(linked='REPLACE' from Python); Remove Appearance Painting puts the links back")
    replaced = {param: [link.from_node.name, link.from_socket.identifier] for param, _s, link in foreign}
    nt = mat.node_tree
    me = obj.data
    n = len(me.vertices)
    tangent_in = bsdf.inputs["Tangent"]
    if not tangent_in.is_linked:
        # The tangent Cycles and EEVEE use when none is given, made explicit: stroke directions
        # are turned into anisotropic rotations relative to it (paint(..., 'stretch')).
        tan = nt.nodes.new("ShaderNodeTangent")
        tan.name = tan.label = schema.APPEARANCE_NODE_PREFIX + "tangent"
        tan.direction_type = "RADIAL"
        tan.axis = "Z"
        tan.location = (bsdf.location.x - 250, bsdf.location.y - 520)
        nt.links.new(tan.outputs["Tangent"], tangent_in)
    for param, (attr, socket_name, default, _) in PARAMS.items():
        sock = bsdf.inputs[socket_name]
        if attr not in me.attributes:
            if param in COLORS:
                a = me.attributes.new(attr, "FLOAT_COLOR", "POINT")
                a.data.foreach_set("color", np.tile(np.array(sock.default_value, np.float32), n))
            else:
                a = me.attributes.new(attr, "FLOAT", "POINT")
                a.data.foreach_set("value", np.full(n, float(sock.default_value), np.float32))
        node_attr = nt.nodes.get(schema.APPEARANCE_NODE_PREFIX + param)
        if node_attr is None:
            node_attr = nt.nodes.new("ShaderNodeAttribute")
            node_attr.name = node_attr.label = schema.APPEARANCE_NODE_PREFIX + param
            node_attr.attribute_type = "GEOMETRY"
            node_attr.attribute_name = attr
            node_attr.location = (bsdf.location.x - 500, bsdf.location.y - 80 * list(PARAMS).index(param))
        glob = nt.nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + param)
        if glob is None:
            if param in COLORS:
                glob = nt.nodes.new("ShaderNodeMix")
                glob.data_type = "RGBA"
                glob.blend_type = "MULTIPLY"
                glob.inputs["Factor"].default_value = 1.0
                glob.inputs[7].default_value = (1.0, 1.0, 1.0, 1.0)  # B: the global tint
                nt.links.new(node_attr.outputs["Color"], glob.inputs[6])  # A
                out = glob.outputs[2]  # Result (colour)
            else:
                glob = nt.nodes.new("ShaderNodeMath")
                glob.operation = "MULTIPLY"
                glob.use_clamp = param != "anisotropic_rotation"
                glob.inputs[1].default_value = 1.0
                nt.links.new(node_attr.outputs["Fac"], glob.inputs[0])
                out = glob.outputs[0]
            glob.name = glob.label = schema.APPEARANCE_NODE_PREFIX + "global_" + param
            glob.location = (bsdf.location.x - 250, node_attr.location.y)
            if param in replaced:
                glob[schema.APPEARANCE_REPLACED_KEY] = replaced[param]
            nt.links.new(out, sock)
    if target == "TEXTURE":
        setup_texture(obj, resolution, uv_map, mat)
    return mat


@transaction.atomic(materials=transaction.of_object)
def remove(obj, material=None, delete_attributes: bool = False) -> None:
    """Undoes :func:`setup` on ``material`` (default: the active one): every Rokeby node goes
    (texture target included), the links ``setup(linked='REPLACE')`` replaced come back, so the
    material is as it was before. The painted attributes stay on the mesh (setup again reuses
    them) unless ``delete_attributes``."""
    _check_mesh(obj)
    mat = material if material is not None else obj.active_material
    nodes = mat.node_tree.nodes if mat is not None and mat.node_tree is not None else None
    if nodes is None or not any(nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + p) is not None for p in PARAMS):
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' is not set up for painting")
    if nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv") is not None:
        remove_texture(obj, mat)
    bsdf = _principled(mat)
    nt = mat.node_tree
    for param, (attr, socket_name, _d, _r) in PARAMS.items():
        glob = nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + param)
        rec = list(glob.get(schema.APPEARANCE_REPLACED_KEY, [])) if glob is not None else []
        for name in (schema.APPEARANCE_NODE_PREFIX + "global_" + param, schema.APPEARANCE_NODE_PREFIX + param):
            node = nodes.get(name)
            if node is not None:
                transaction.remove_node(nt, node)
        if len(rec) == 2 and bsdf is not None:
            src = nodes.get(rec[0])
            out = next((o for o in src.outputs if o.identifier == rec[1]), None) if src is not None else None
            if out is not None:
                nt.links.new(out, bsdf.inputs[socket_name])
        if delete_attributes and obj.data.attributes.get(attr) is not None:
            obj.data.attributes.remove(obj.data.attributes[attr])
    tan = nodes.get(schema.APPEARANCE_NODE_PREFIX + "tangent")
    if tan is not None:
        transaction.remove_node(nt, tan)


def set_global(mat, param: str, value) -> None:
    """Fraser's global sliders: scales ``param`` over the whole object (1 = as painted; for
    the colours an RGB tint)."""
    if param not in PARAMS:
        raise ValueError(f"param: unknown parameter {param!r} (expected one of {', '.join(PARAMS)})")
    node = mat.node_tree.nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + param) if mat is not None and mat.use_nodes else None
    if node is None:
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' is not set up for painting: click Set Up Appearance Painting first (Rokeby ▸ Appearance Painting)")
    if param in COLORS:
        v = np.asarray(value, np.float64).ravel()
        if v.size == 3:
            v = np.append(v, 1.0)
        if v.size != 4 or not np.isfinite(v).all() or (v < 0).any() or (v > MAX_COLOR).any():
            raise ValueError(f"value: a tint is 3 or 4 finite values in [0, {MAX_COLOR:g}], got {value!r}")
        node.inputs[7].default_value = tuple(float(x) for x in v)
    else:
        if not (isinstance(value, (int, float)) and math.isfinite(value) and 0 <= value <= MAX_COLOR):
            raise ValueError(f"value: a global scale must be finite and ≥ 0 (at most {MAX_COLOR:g}), got {value!r}")
        node.inputs[1].default_value = float(value)


def migrate() -> list[str]:
    """Files painted before a parameter existed (the specular colour) get it at load:
    each painted mesh's material (with ``rokeby_global_roughness``) lacking a parameter's nodes is
    set up again (idempotent: what exists is kept; the new attribute and, on a texture target, its
    image start from the material's value, so the render does not change). Returns what was done,
    or why a material was left as it was (a linked library, or the new input driven by another
    node: painting that parameter then asks for Set Up)."""
    import bpy

    done = []
    for ob in bpy.data.objects:
        if ob.type != "MESH" or ob.library is not None or ob.data.library is not None or len(ob.data.vertices) == 0:
            continue
        for slot in ob.material_slots:
            mat = slot.material
            nodes = mat.node_tree.nodes if mat is not None and mat.use_nodes and mat.node_tree is not None else None
            if nodes is None or nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_roughness") is None or mat.library is not None:
                continue
            missing = [p for p in PARAMS if nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + p) is None
                       or (nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv") is not None and nodes.get(schema.APPEARANCE_NODE_PREFIX + "tex_" + p) is None)]
            if not missing:
                continue
            uvn = nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv")
            kw = {}
            if uvn is not None:
                img = next((t.image for p in PARAMS if (t := nodes.get(schema.APPEARANCE_NODE_PREFIX + "tex_" + p)) is not None and t.image is not None), None)
                kw = {"target": "TEXTURE", "resolution": img.size[0] if img is not None else 1024,
                      "uv_map": uvn.uv_map if uvn.uv_map in ob.data.uv_layers else None}
            try:
                setup(ob, mat, **kw)
            except ValueError as e:
                done.append(f"'{mat.name}' on '{ob.name}' kept without {', '.join(missing)}: {e}")
                continue
            done.append(f"'{mat.name}' on '{ob.name}': added {', '.join(missing)}")
    return done
