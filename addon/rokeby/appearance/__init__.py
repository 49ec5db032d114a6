"""Appearance painting under environment light (Fraser, "Interactive Real-Time BRDF
Editing under Environment Lighting", §"Painting"): per-point BRDF parameters stored as mesh
attributes and wired into the material's Principled BSDF, brushes with a radius and Gaussian
falloff that write them, and global sliders that scale them for the whole object.

Fraser's brushes and their attributes (point domain, on the original mesh, so modifiers
interpolate them and Cycles and EEVEE both render them):

============  =============================  ==========================================
brush         attribute                      Principled BSDF input
============  =============================  ==========================================
diffuse       ``rokeby_base_color`` (RGBA)   Base Color
specular      ``rokeby_specular``            Specular IOR Level (k_s)
sharpen/blur  ``rokeby_roughness``           Roughness (sharpen lowers, blur raises)
stretch       ``rokeby_anisotropic``         Anisotropic, and its direction ``rokeby_anisotropic_rotation``
                                             (Anisotropic Rotation) from the stroke direction
metallic      ``rokeby_metallic``            Metallic (energy between diffuse and specular)
specular_tint ``rokeby_specular_tint`` (RGBA) Specular Tint (Fraser's Step 6: the highlight's colour)
============  =============================  ==========================================

Each scalar attribute reaches its input through a Multiply node named ``rokeby_global_<param>``
whose second value is that parameter's global slider (1 = as painted); the colours (:data:`COLORS`)
go through a Mix (Multiply) node with their global tint. A stroke is a list of dabs; a dab at world position c with
radius r changes every point p by w = strength · exp(−‖p − c‖² / (2 (r/2)²)) (Gaussian falloff,
e⁻² ≈ 0.14 at the radius): ``value ← value + w (target − value)`` for mode 'MIX', or
``value ← clamp(value ± w · amount)`` for 'ADD'/'SUBTRACT'. All vectorised with numpy.

``setup(obj, target='TEXTURE')`` paints images through the UV map instead (one per parameter,
same nodes downstream, packed into the .blend on save): see the texture-targets section below.
"""

from __future__ import annotations

import math

import numpy as np

from ..blender import hooks, transaction
from ..core import schema, words

# brush → (attribute, Principled input, default when the material has no value, clamp range)
PARAMS = {
    "diffuse": (schema.APPEARANCE_ATTRIBUTES["diffuse"], "Base Color", (0.8, 0.8, 0.8, 1.0), (0.0, 1.0)),
    "specular": (schema.APPEARANCE_ATTRIBUTES["specular"], "Specular IOR Level", 0.5, (0.0, 1.0)),
    "roughness": (schema.APPEARANCE_ATTRIBUTES["roughness"], "Roughness", 0.5, (0.0, 1.0)),
    "anisotropic": (schema.APPEARANCE_ATTRIBUTES["anisotropic"], "Anisotropic", 0.0, (0.0, 1.0)),
    "anisotropic_rotation": (schema.APPEARANCE_ATTRIBUTES["anisotropic_rotation"], "Anisotropic Rotation", 0.0, (0.0, 1.0)),
    "metallic": (schema.APPEARANCE_ATTRIBUTES["metallic"], "Metallic", 0.0, (0.0, 1.0)),
    # Fraser's proposed Step 6 ("change the colour of specular highlights"): Blender's specular
    # tint, the colour of the dielectric reflection at normal incidence (F0 · tint; on metals it
    # tints the grazing edge, Blender's F82 tint).
    "specular_tint": (schema.APPEARANCE_ATTRIBUTES["specular_tint"], "Specular Tint", (1.0, 1.0, 1.0, 1.0), (0.0, 1.0)),
}
# The colour parameters (RGBA attributes, Mix (Multiply) global nodes, RGB brushes).
COLORS = ("diffuse", "specular_tint")
# Largest colour component a brush or tint accepts: room for HDR albedo tricks, far from float32's
# overflow (3.4e38), so no painted or blended value can become inf in the attribute or image.
MAX_COLOR = 1e4
# Fraser's brush names on top of the parameters.
BRUSHES = {"sharpen": ("roughness", "SUBTRACT"), "blur": ("roughness", "ADD"), "stretch": ("anisotropic", "ADD")}
NODE_PREFIX = schema.APPEARANCE_NODE_PREFIX


def _principled(mat):
    out = next((n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output), None)
    if out is not None and out.inputs["Surface"].is_linked:
        n = out.inputs["Surface"].links[0].from_node
        if n.type == "BSDF_PRINCIPLED":
            return n
    return next((n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


def _check_mesh(obj):
    if obj is None:
        raise ValueError("obj: is None")
    if obj.type != "MESH":
        raise ValueError(f"obj: '{obj.name}' is {words.kind(obj.type)}, not a mesh")
    if len(obj.data.vertices) == 0:
        raise ValueError(f"obj: '{obj.name}' has no vertices to paint")


# What setup does with a painted Principled input that another node (a texture) already drives.
LINKED = ("REFUSE", "REPLACE")
# Custom property on a rokeby_global_<param> node: [node name, output identifier] of the link it
# replaced (setup(linked='REPLACE')), put back by remove().
REPLACED_KEY = schema.APPEARANCE_REPLACED_KEY


def _foreign_links(bsdf) -> list:
    """(param, socket name, link) of each painted Principled input driven by a node that is not
    Rokeby's."""
    out = []
    for param, (_attr_name, socket_name, _d, _r) in PARAMS.items():
        sock = bsdf.inputs[socket_name]
        if sock.is_linked:
            link = sock.links[0]
            if not link.from_node.name.startswith(NODE_PREFIX):
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
        tan.name = tan.label = NODE_PREFIX + "tangent"
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
        node_attr = nt.nodes.get(NODE_PREFIX + param)
        if node_attr is None:
            node_attr = nt.nodes.new("ShaderNodeAttribute")
            node_attr.name = node_attr.label = NODE_PREFIX + param
            node_attr.attribute_type = "GEOMETRY"
            node_attr.attribute_name = attr
            node_attr.location = (bsdf.location.x - 500, bsdf.location.y - 80 * list(PARAMS).index(param))
        glob = nt.nodes.get(NODE_PREFIX + "global_" + param)
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
            glob.name = glob.label = NODE_PREFIX + "global_" + param
            glob.location = (bsdf.location.x - 250, node_attr.location.y)
            if param in replaced:
                glob[REPLACED_KEY] = replaced[param]
            nt.links.new(out, sock)
    if target == "TEXTURE":
        setup_texture(obj, resolution, uv_map, mat)
    return mat


def _attr(obj, param):
    if param not in PARAMS:
        raise ValueError(f"param: unknown parameter {param!r} (expected one of {', '.join(PARAMS)})")
    attr = PARAMS[param][0]
    a = obj.data.attributes.get(attr)
    if a is None:
        raise ValueError(f"obj: '{obj.name}' has no attribute {attr!r}: click Set Up Appearance Painting first (Rokeby ▸ Appearance Painting)")
    return a


def read(obj, param) -> np.ndarray:
    """The painted values of ``param``: (N,) floats, or (N, 4) RGBA for the colours ('diffuse', 'specular_tint')."""
    a = _attr(obj, param)
    n = len(obj.data.vertices)
    if param in COLORS:
        v = np.empty(4 * n, np.float32)
        a.data.foreach_get("color", v)
        return v.reshape(n, 4)
    v = np.empty(n, np.float32)
    a.data.foreach_get("value", v)
    return v


def _finite32(values, what: str) -> np.ndarray:
    """``values`` as float32, refused (nothing written) when any is NaN or overflows to inf."""
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.ascontiguousarray(values, np.float32)
    if not np.isfinite(out).all():
        raise ValueError(f"{what}: the stroke would write non-finite values; nothing was painted")
    return out


def _write(obj, param, values):
    values = _finite32(values, "value")
    a = _attr(obj, param)
    a.data.foreach_set("color" if param in COLORS else "value", np.ascontiguousarray(values, np.float32).ravel())
    obj.data.update()


# Dabs touch the points within CUTOFF·radius: the Gaussian is below e^(−2·CUTOFF²) = 1e-7 of its
# peak beyond (CUTOFF = 2.84), so no stored float32 value in [0, 1] changes there.
CUTOFF = 2.84


def falloff(points, centre, radius: float, strength: float = 1.0) -> np.ndarray:
    """Gaussian brush weights w = strength · exp(−‖p − c‖² / (2 (radius/2)²)) for (N, 3) points."""
    d2 = np.sum((np.asarray(points, np.float64) - np.asarray(centre, np.float64)) ** 2, axis=1)
    s = 0.5 * radius
    return strength * np.exp(-d2 / (2.0 * s * s))


def _reach(pts, dab, radius):
    """Indices of the points a dab reaches (see CUTOFF)."""
    d = pts - dab
    return np.flatnonzero(np.einsum("ij,ij->i", d, d) < (CUTOFF * radius) ** 2)


def paint(obj, brush: str, centres, radius: float, value=None, strength: float = 1.0, mode: str | None = None, previous=None,
          pack: bool = True) -> np.ndarray:
    """One stroke of ``brush`` (a parameter of PARAMS or Fraser's 'sharpen', 'blur', 'stretch')
    through world-space ``centres`` ((3,) or (K, 3) dabs, applied in order). ``value`` is the
    target (mode 'MIX', an RGB(A) colour for 'diffuse' and 'specular_tint') or the amount (modes 'ADD'/'SUBTRACT';
    default 0.25). ``previous``: the stroke's point before these dabs (not painted again; it
    gives 'stretch' its direction when a stroke arrives one dab at a time). ``pack``: on a
    texture target, pack the changed images afterwards (~50 ms at 1024²), so an undo step taken
    now keeps the stroke; an interactive stroke packs once when it ends instead of every dab.
    Returns the new values."""
    _check_mesh(obj)
    param, default_mode = BRUSHES.get(brush, (brush, "MIX"))
    img = _texture_image(obj, param) if param in PARAMS else None
    if param not in PARAMS:
        raise ValueError(f"brush: unknown brush {brush!r} (expected one of {', '.join(list(PARAMS) + list(BRUSHES))})")
    if img is None and param in missing_images(obj):
        raise ValueError(f"obj: the painted {param!r} image of material '{obj.active_material.name}' is gone (deleted?): undo, "
                         "or click Make Missing Images (Appearance Painting panel) to make it again from the per-point "
                         "values")
    mode = (mode or default_mode).upper()
    if mode not in ("MIX", "ADD", "SUBTRACT"):
        raise ValueError(f"mode: expected 'MIX', 'ADD' or 'SUBTRACT', got {mode!r}")
    if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius: must be a positive finite number, got {radius!r}")
    if not (isinstance(strength, (int, float)) and math.isfinite(strength) and 0 <= strength <= 1):
        raise ValueError(f"strength: must be in [0, 1], got {strength!r}")
    c = np.asarray(centres, np.float64)
    c = c.reshape(1, 3) if c.shape == (3,) else c
    if c.ndim != 2 or c.shape[1] != 3 or len(c) == 0:
        raise ValueError(f"centres: expected shape (3,) or (K, 3), got {np.shape(centres)}")
    if not np.isfinite(c).all():
        raise ValueError("centres: contain NaN or inf")
    path = c
    if previous is not None:
        prev = np.asarray(previous, np.float64).reshape(-1)
        if prev.shape != (3,) or not np.isfinite(prev).all():
            raise ValueError(f"previous: expected 3 finite values, got {previous!r}")
        path = np.vstack([prev, c])
    if value is None:
        if mode == "MIX":
            raise ValueError(f"value: brush {brush!r} in mode 'MIX' needs a target value")
        value = 0.25
    lo, hi = PARAMS[param][3]
    if param in COLORS:
        v = np.asarray(value, np.float64).ravel()
        if v.size == 3:
            v = np.append(v, 1.0)
        if v.size != 4 or not np.isfinite(v).all() or (v < 0).any() or (v > MAX_COLOR).any():
            raise ValueError(f"value: a {'diffuse' if param == 'diffuse' else 'specular tint'} colour is 3 or 4 finite values in [0, {MAX_COLOR:g}], got {value!r}")
        target = v
    else:
        if not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise ValueError(f"value: must be a finite number, got {value!r}")
        if value < 0:
            raise ValueError(f"value: must be ≥ 0 (a {'target' if mode == 'MIX' else 'amount'}; use mode 'SUBTRACT' to lower), got {value}")
        target = float(value)
    if img is not None:
        out = _paint_texture(obj, img, param, c, radius, strength, mode, target)
        if brush == "stretch" and len(path) >= 2:
            _stretch_direction_texture(obj, path, len(path) - len(c), radius, strength)
        if pack:
            pack_painted(obj)
        return out
    m = np.asarray(obj.matrix_world, np.float64)
    co = np.empty(3 * len(obj.data.vertices), np.float32)
    obj.data.attributes["position"].data.foreach_get("vector", co)  # the fast path of `co`
    pts = co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    vals = read(obj, param).astype(np.float64)
    reached = []
    for dab in c:
        idx = _reach(pts, dab, radius)
        reached.append(idx)
        w = falloff(pts[idx], dab, radius, strength)
        if param in COLORS:
            w = w[:, None]
        v = vals[idx]
        if mode == "MIX":
            v = v + w * (target - v)
        else:
            v = v + (1.0 if mode == "ADD" else -1.0) * w * target
        if param == "anisotropic_rotation":
            v = np.mod(v, 1.0)
        elif param not in COLORS:
            v = np.clip(v, lo, hi)
        else:
            v = np.maximum(v, 0.0)
        vals[idx] = v
    _write(obj, param, vals)
    if brush == "stretch" and len(path) >= 2:
        _stretch_direction(obj, pts, m, path, len(path) - len(c), radius, strength, np.unique(np.concatenate(reached)))
    return vals.astype(np.float32)


def _radial_tangent_frame(obj, m, idx):
    """World-space (T, B, N) per vertex for the radial-Z tangent (Cycles' svm_node_tangent:
    data = (−(g_y − ½), g_x − ½, 0) of the generated coordinates, object_normal_transform,
    T = N × normalize(data × N)) and B = N × T, where T turns at rotation ¼."""
    me = obj.data
    n = len(me.vertices)
    co = np.empty(3 * n, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    co = co.reshape(n, 3).astype(np.float64)
    nrm = np.empty(3 * n, np.float32)
    me.vertex_normals.foreach_get("vector", nrm)
    return _radial_frame_at(co, co[idx], nrm.reshape(n, 3)[idx].astype(np.float64), m)


def _radial_frame_at(co, p, nrm, m):
    """The radial-Z tangent frame at object-space points ``p`` with normals ``nrm`` (``co``: all
    vertex positions, whose bounds give the generated coordinates)."""
    lo, hi = co.min(axis=0), co.max(axis=0)
    g = (p - lo) / np.where(hi > lo, hi - lo, 1.0)
    inv = np.linalg.inv(m[:3, :3])  # both transformed as normals (object_normal_transform)
    data = np.stack([-(g[:, 1] - 0.5), g[:, 0] - 0.5, np.zeros(len(p))], axis=-1) @ inv
    nw = nrm @ inv
    nw /= np.maximum(np.linalg.norm(nw, axis=1, keepdims=True), 1e-30)
    x = np.cross(data, nw)
    x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-30)
    t = np.cross(nw, x)
    return t, np.cross(nw, t), nw


def _stretch_direction(obj, pts, m, path, first, radius, strength, idx):
    """Fraser's stretch brush also sets the direction: the anisotropic rotation ρ turns T about N
    by 2πρ (Cycles: rotate_around_axis(T, N, 2πρ)) onto the stroke direction s at each dab,
    ρ = atan2(s·B, s·T)/2π. Anisotropy is a line, not an arrow, so ρ is blended on its double
    angle: (cos 4πρ, sin 4πρ) mixed with the dab's Gaussian weights."""
    mat = obj.active_material
    tan = mat.node_tree.nodes.get(NODE_PREFIX + "tangent") if mat is not None and mat.use_nodes else None
    if tan is None or not tan.outputs["Tangent"].is_linked:
        raise ValueError("brush: 'stretch' directions are relative to the radial tangent that Set Up Appearance Painting wires; this material's Tangent input is driven by something else")
    t, b, _ = _radial_tangent_frame(obj, m, idx)
    all_rho = read(obj, "anisotropic_rotation").astype(np.float64)
    rho = all_rho[idx]
    pts = pts[idx]
    vec = np.stack([np.cos(4 * np.pi * rho), np.sin(4 * np.pi * rho)], axis=-1)
    for k in range(first, len(path)):  # the dabs; path[:first] only gives directions
        s = path[min(k + 1, len(path) - 1)] - path[max(k - 1, 0)]
        if not np.linalg.norm(s) > 0:
            continue
        target = np.arctan2(b @ s, t @ s)  # per point: the stroke direction's angle from T
        goal = np.stack([np.cos(2 * target), np.sin(2 * target)], axis=-1)
        w = falloff(pts, path[k], radius, strength)[:, None]
        vec = vec + w * (goal - vec)
    rho = np.mod(np.arctan2(vec[:, 1], vec[:, 0]) / (4 * np.pi), 0.5)
    rho[rho > 0.5 - 1e-7] = 0.0  # −0 and rounding: ½ ≡ 0 for a line
    all_rho[idx] = rho
    _write(obj, "anisotropic_rotation", all_rho)


def set_global(mat, param: str, value) -> None:
    """Fraser's global sliders: scales ``param`` over the whole object (1 = as painted; for
    the colours an RGB tint)."""
    if param not in PARAMS:
        raise ValueError(f"param: unknown parameter {param!r} (expected one of {', '.join(PARAMS)})")
    node = mat.node_tree.nodes.get(NODE_PREFIX + "global_" + param) if mat is not None and mat.use_nodes else None
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


# --- texture targets -----------------------------------------------------------------------------
# setup(obj, target='TEXTURE') adds, per parameter, an Image Texture node ``rokeby_tex_<param>``
# (image ``rokeby <material> <param>``, float, Non-Color for the scalars) read through one UV Map
# node ``rokeby_uv``, linked into the same ``rokeby_global_<param>`` node in place of the
# attribute node (which stays, unlinked). Brushes then write the image: every texel covered by
# the UV layout has a 3D surface point (numpy barycentric rasterisation of the UV triangles,
# cached per mesh, UV map and resolution), and a dab updates the texels within CUTOFF·radius of it
# with the same Gaussian in 3D distance. The images are packed into the .blend when it is saved
# (a save_pre handler; OpenEXR, full float), so they travel with the file like Blender's own
# generated images once packed. remove_texture() restores the material exactly.

TEXTURE_MARGIN = 1.0  # texels outside a UV triangle, up to this far from it, get its clamped point (seam bleed)
_RASTER: dict = {}


def _check_texture_args(obj, resolution, uv_map):
    if not (isinstance(resolution, int) and not isinstance(resolution, bool) and 8 <= resolution <= 16384):
        raise ValueError(f"resolution: a texture side is an integer in [8, 16384], got {resolution!r}")
    uvs = obj.data.uv_layers
    if len(uvs) == 0:
        raise ValueError(f"obj: '{obj.name}' has no UV map, which a texture target needs (add one, e.g. UV › Smart UV Project, or use target='POINT'); nothing was changed")
    if uv_map is not None and uv_map not in uvs:
        raise ValueError(f"uv_map: '{obj.name}' has no UV map {uv_map!r} (it has {', '.join(u.name for u in uvs)}); nothing was changed")


def _image_name(mat, param):
    return schema.appearance_image_name(mat.name, param)


@transaction.atomic(materials=transaction.of_object)
def setup_texture(obj, resolution: int = 1024, uv_map: str | None = None, material=None):
    """Switches ``material`` (default: the active one, set up by :func:`setup`) to image-texture
    targets: one ``resolution``² float image per parameter, filled from the painted attributes
    through the UV map (texels outside the layout get the material's value). Idempotent."""
    import bpy

    _check_mesh(obj)
    _check_texture_args(obj, resolution, uv_map)
    mat = material if material is not None else obj.active_material
    nodes = mat.node_tree.nodes if mat is not None and mat.use_nodes else None
    if nodes is None or nodes.get(NODE_PREFIX + "global_roughness") is None:
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' is not set up for painting: click Set Up Appearance Painting first (Rokeby ▸ Appearance Painting)")
    nt = mat.node_tree
    uv_name = uv_map if uv_map is not None else obj.data.uv_layers.active.name
    uvn = nodes.get(NODE_PREFIX + "uv")
    if uvn is None:
        uvn = nodes.new("ShaderNodeUVMap")
        uvn.name = uvn.label = NODE_PREFIX + "uv"
        g = nodes[NODE_PREFIX + "global_roughness"]
        uvn.location = (g.location.x - 800, g.location.y)
    uvn.uv_map = uv_name
    ras = _raster(obj, uv_name, resolution)
    for param in PARAMS:
        glob = nodes[NODE_PREFIX + "global_" + param]
        tex = nodes.get(NODE_PREFIX + "tex_" + param)
        if tex is not None and tex.image is not None:
            continue
        img = bpy.data.images.get(_image_name(mat, param))
        if img is None or tuple(img.size) != (resolution, resolution):
            if img is not None:
                bpy.data.images.remove(img)
            img = bpy.data.images.new(_image_name(mat, param), resolution, resolution, alpha=True, float_buffer=True)
        if param not in COLORS:
            img.colorspace_settings.name = "Non-Color"
        img[schema.APPEARANCE_PAINTED_KEY] = True
        # fill from the attributes: barycentric interpolation of the vertex values at each texel
        vals = read(obj, param).astype(np.float64)
        px = np.empty((resolution * resolution, 4), np.float32)
        if param in COLORS:
            px[:] = vals.mean(axis=0)
            px[ras["texel"]] = np.einsum("nk,nkc->nc", ras["bary"], vals[ras["tri_verts"]])
        else:
            px[:, :3] = float(np.median(vals))
            px[:, 3] = 1.0
            px[ras["texel"], :3] = np.einsum("nk,nk->n", ras["bary"], vals[ras["tri_verts"]])[:, None]
        img.pixels.foreach_set(px.ravel())
        img.update()
        if tex is None:
            tex = nodes.new("ShaderNodeTexImage")
            tex.name = tex.label = NODE_PREFIX + "tex_" + param
            tex.location = (glob.location.x - 520, glob.location.y)
        tex.image = img
        tex.interpolation = "Linear"
        tex.extension = "EXTEND"
        nt.links.new(uvn.outputs["UV"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], glob.inputs[6] if param in COLORS else glob.inputs[0])
    _ensure_save_handler()
    pack_painted(obj)
    return mat


@transaction.atomic(materials=transaction.of_object)
def remove_texture(obj, material=None, delete_images: bool = True) -> None:
    """Back to per-point targets: removes the Image Texture and UV Map nodes and relinks the
    attribute nodes, so the material is exactly as :func:`setup` left it (nodes, links, values);
    the images are deleted unless ``delete_images`` is False."""
    import bpy

    mat = material if material is not None else obj.active_material
    nodes = mat.node_tree.nodes if mat is not None and mat.use_nodes else None
    if nodes is None or nodes.get(NODE_PREFIX + "uv") is None:
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' has no texture target to remove")
    nt = mat.node_tree
    for param in PARAMS:
        tex = nodes.get(NODE_PREFIX + "tex_" + param)
        glob = nodes.get(NODE_PREFIX + "global_" + param)
        attr = nodes.get(NODE_PREFIX + param)
        if tex is not None:
            img = tex.image
            transaction.remove_node(nt, tex)
            if delete_images and img is not None:
                transaction.remove_unused(img)  # once the node is gone
        if glob is not None and attr is not None:
            if param in COLORS:
                nt.links.new(attr.outputs["Color"], glob.inputs[6])
            else:
                nt.links.new(attr.outputs["Fac"], glob.inputs[0])
    transaction.remove_node(nt, nodes[NODE_PREFIX + "uv"])


@transaction.atomic(materials=transaction.of_object)
def remove(obj, material=None, delete_attributes: bool = False) -> None:
    """Undoes :func:`setup` on ``material`` (default: the active one): every Rokeby node goes
    (texture target included), the links ``setup(linked='REPLACE')`` replaced come back, so the
    material is as it was before. The painted attributes stay on the mesh (setup again reuses
    them) unless ``delete_attributes``."""
    _check_mesh(obj)
    mat = material if material is not None else obj.active_material
    nodes = mat.node_tree.nodes if mat is not None and mat.node_tree is not None else None
    if nodes is None or not any(nodes.get(NODE_PREFIX + "global_" + p) is not None for p in PARAMS):
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' is not set up for painting")
    if nodes.get(NODE_PREFIX + "uv") is not None:
        remove_texture(obj, mat)
    bsdf = _principled(mat)
    nt = mat.node_tree
    for param, (attr, socket_name, _d, _r) in PARAMS.items():
        glob = nodes.get(NODE_PREFIX + "global_" + param)
        rec = list(glob.get(REPLACED_KEY, [])) if glob is not None else []
        for name in (NODE_PREFIX + "global_" + param, NODE_PREFIX + param):
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
    tan = nodes.get(NODE_PREFIX + "tangent")
    if tan is not None:
        transaction.remove_node(nt, tan)


def target(obj) -> str:
    """'TEXTURE' when the active material reads images through ``rokeby_uv``, else 'POINT'."""
    mat = obj.active_material
    return "TEXTURE" if mat is not None and mat.use_nodes and mat.node_tree.nodes.get(NODE_PREFIX + "uv") is not None else "POINT"


def missing_images(obj) -> list[str]:
    """Parameters whose painted image a texture target reads is gone (an artist deleted it):
    painting them is refused until the target is set up again."""
    if target(obj) != "TEXTURE":
        return []
    nodes = obj.active_material.node_tree.nodes
    return [p for p in PARAMS if (t := nodes.get(NODE_PREFIX + "tex_" + p)) is None or t.image is None]


def _tex_node(obj, param):
    mat = obj.active_material
    if mat is None or not mat.use_nodes:
        return None
    return mat.node_tree.nodes.get(NODE_PREFIX + "tex_" + param)


def _texture_image(obj, param):
    tex = _tex_node(obj, param)
    if tex is None or tex.image is None or not tex.outputs["Color"].is_linked:
        return None
    return tex.image


def _raster(obj, uv_name: str, res: int) -> dict:
    """Per covered texel (flat index j·res + i, Blender's bottom-up pixel order): its triangle's
    vertices, barycentric weights and object-space surface point. Texel centres ((i+½)/res,
    (j+½)/res) inside a UV triangle take it (the deepest one where triangles overlap); uncovered
    texels within TEXTURE_MARGIN texels of a triangle take its nearest point (clamped weights), so
    bilinear lookups at island borders don't bleed the background. Cached per mesh, UV map,
    resolution and the positions/UVs/triangles' contents."""
    me = obj.data
    if uv_name not in me.uv_layers:
        raise ValueError(f"obj: '{obj.name}' has no UV map {uv_name!r}, which its texture target reads (restore it, or click Back to Per-Point Attributes)")
    n = len(me.vertices)
    co = np.empty(3 * n, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    lvi = np.empty(len(me.loops), np.int32)
    uv = np.empty(2 * len(me.loops), np.float32)
    cv, ua = me.attributes.get(".corner_vert"), me.attributes.get(uv_name)
    if cv is not None and ua is not None and ua.data_type == "FLOAT2" and ua.domain == "CORNER":
        cv.data.foreach_get("value", lvi)  # the attribute fast paths (the loops' are ~100× slower)
        ua.data.foreach_get("vector", uv)
    else:
        me.loops.foreach_get("vertex_index", lvi)
        me.uv_layers[uv_name].data.foreach_get("uv", uv)
    key = (me.as_pointer(), uv_name, res)
    digest = hash((co.tobytes(), uv.tobytes(), lvi.tobytes(), len(me.polygons)))
    hit = _RASTER.get(key)
    if hit is not None and hit["digest"] == digest:
        return hit
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    loops = np.empty(3 * nt, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    tv = np.empty(3 * nt, np.int32)
    me.loop_triangles.foreach_get("vertices", tv)
    co = co.reshape(n, 3).astype(np.float64)
    tv = tv.reshape(nt, 3)
    P = uv.reshape(-1, 2).astype(np.float64)[loops.reshape(nt, 3)] * res - 0.5  # texel-centre units
    a, b, c = P[:, 0], P[:, 1], P[:, 2]
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    edge = np.stack([np.linalg.norm(b - c, axis=1), np.linalg.norm(c - a, axis=1), np.linalg.norm(a - b, axis=1)], 1)
    alt = np.abs(den)[:, None] / np.maximum(edge, 1e-30)  # altitude over each vertex's opposite edge
    lo = np.clip(np.floor(P.min(axis=1) - TEXTURE_MARGIN), 0, res - 1).astype(np.int64)
    hi = np.clip(np.ceil(P.max(axis=1) + TEXTURE_MARGIN), 0, res - 1).astype(np.int64)
    w, h = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    ok = np.abs(den) > 1e-12
    counts = np.where(ok, w * h, 0)
    texel_l, tri_l, l_l, depth_l = [], [], [], []
    start = 0
    csum = np.cumsum(counts)
    while start < nt:  # chunks of triangles with at most ~4M candidate texels (not a texel loop)
        stop = int(np.searchsorted(csum, (csum[start - 1] if start else 0) + 4_000_000, side="right"))
        stop = max(stop, start + 1)
        ts = np.arange(start, min(stop, nt))
        cnt = counts[ts]
        t = np.repeat(ts, cnt)
        off = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        x = lo[t, 0] + off % w[t]
        y = lo[t, 1] + off // w[t]
        qa, qb, qc = a[t], b[t], c[t]
        l0 = ((qb[:, 1] - qc[:, 1]) * (x - qc[:, 0]) + (qc[:, 0] - qb[:, 0]) * (y - qc[:, 1])) / den[t]
        l1 = ((qc[:, 1] - qa[:, 1]) * (x - qc[:, 0]) + (qa[:, 0] - qc[:, 0]) * (y - qc[:, 1])) / den[t]
        lam = np.stack([l0, l1, 1.0 - l0 - l1], 1)
        depth = (lam * alt[t]).min(axis=1)  # signed texel distance inside the nearest edge line
        keep = depth >= -TEXTURE_MARGIN
        texel_l.append((y * res + x)[keep])
        tri_l.append(t[keep])
        l_l.append(lam[keep])
        depth_l.append(depth[keep])
        start = int(ts[-1]) + 1
    texel = np.concatenate(texel_l) if texel_l else np.zeros(0, np.int64)
    tri = np.concatenate(tri_l) if tri_l else np.zeros(0, np.int64)
    lam = np.concatenate(l_l) if l_l else np.zeros((0, 3))
    depth = np.concatenate(depth_l) if depth_l else np.zeros(0)
    order = np.lexsort((-depth, texel))  # per texel, deepest first
    texel, tri, lam, depth = texel[order], tri[order], lam[order], depth[order]
    first = np.ones(len(texel), bool)
    first[1:] = texel[1:] != texel[:-1]
    texel, tri, lam = texel[first], tri[first], lam[first]
    lam = np.clip(lam, 0.0, None)
    lam /= lam.sum(axis=1, keepdims=True)
    verts = tv[tri]
    pts = np.einsum("nk,nkc->nc", lam, co[verts])
    out = {"digest": digest, "texel": texel, "tri_verts": verts, "bary": lam, "points": pts}
    _RASTER[key] = out
    return out


def _world_index(ras, m):
    """(m, order, points[order], x[order]): the texels' world points sorted by x for transform m
    (cached in ``ras``), so a dab only measures the slab |x − c_x| < CUTOFF·radius."""
    world = ras.get("world")
    if world is None or not np.array_equal(world[0], m):
        p = ras["points"] @ m[:3, :3].T + m[:3, 3]
        order = np.argsort(p[:, 0], kind="stable")
        world = ras["world"] = (m, order, np.ascontiguousarray(p[order]), np.ascontiguousarray(p[order, 0]))
    return world


def read_texture(obj, param) -> np.ndarray:
    """The painted image of ``param`` on a texture target: (res, res) floats, or (res, res, 4)
    RGBA for the colours; row 0 is v = 0 (Blender's pixel order)."""
    if param not in PARAMS:
        raise ValueError(f"param: unknown parameter {param!r} (expected one of {', '.join(PARAMS)})")
    img = _texture_image(obj, param)
    if img is None:
        raise ValueError(f"obj: '{obj.name}' has no texture target for {param!r}: set the Target to Image Texture and click Set Up Appearance Painting first")
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(h, w, 4)
    return px if param in COLORS else px[..., 0].copy()


def _paint_texture(obj, img, param, c, radius, strength, mode, target):
    nodes = obj.active_material.node_tree.nodes
    uvn = nodes.get(NODE_PREFIX + "uv")
    uv_name = uvn.uv_map if uvn is not None and uvn.uv_map else (obj.data.uv_layers.active.name if obj.data.uv_layers.active else "")
    res = img.size[0]
    if img.size[1] != res:
        raise ValueError(f"image: '{img.name}' is {img.size[0]}×{img.size[1]}; texture targets are square")
    ras = _raster(obj, uv_name, res)
    m = np.asarray(obj.matrix_world, np.float64)
    _, order, pts, xs = _world_index(ras, m)
    px = np.empty(res * res * 4, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(-1, 4)
    tex = ras["texel"]
    lo, hi = PARAMS[param][3]
    touched = []
    r = CUTOFF * radius
    for dab in c:
        i0, i1 = np.searchsorted(xs, [dab[0] - r, dab[0] + r])
        near = i0 + _reach(pts[i0:i1], dab, radius)
        if len(near) == 0:
            continue
        touched.append(near)
        w = falloff(pts[near], dab, radius, strength)
        rows = tex[order[near]]
        if param in COLORS:
            v = px[rows].astype(np.float64)
            w = w[:, None]
        else:
            v = px[rows, 0].astype(np.float64)
        v = v + w * (target - v) if mode == "MIX" else v + (1.0 if mode == "ADD" else -1.0) * w * target
        if param == "anisotropic_rotation":
            v = np.mod(v, 1.0)
        elif param not in COLORS:
            v = np.clip(v, lo, hi)
        else:
            v = np.maximum(v, 0.0)
        if param in COLORS:
            px[rows] = v
        else:
            px[rows, :3] = v[:, None]
    if touched:
        _finite32(px, "value")
        img.pixels.foreach_set(px.ravel())
        img.update()
        _ensure_save_handler()  # a file reopened in a new session: the next save packs this
    px = px.reshape(res, res, 4)
    return px.copy() if param in COLORS else px[..., 0].copy()


# Painted image → pointer of the packed data its pixels in memory came from. Blender's global
# undo stores packed data but not the pixels in memory: an image whose packed data an undo or redo
# swapped must be reloaded from it (``reload_after_undo``).
_PACKED: dict = {}


def pack(img) -> None:
    """Packs a painted image (OpenEXR, full float) into the .blend: saving, and every painting
    operator's undo step, keep its pixels."""
    img.file_format = "OPEN_EXR"
    img.use_half_precision = False
    # Packing again an image whose packed data is current re-reads it from its file: the painted
    # image has none, and Blender 5.0 then drops the packed data. Pack only what changed.
    if img.is_dirty or img.packed_file is None:
        img.pack()
    _PACKED[img.name] = img.packed_file.as_pointer()


def pack_painted(obj=None) -> int:
    """Packs the painted images of ``obj``'s active material (default: all) that changed since
    they were last packed; returns how many."""
    import bpy

    imgs = bpy.data.images if obj is None else [t.image for p in PARAMS if (t := _tex_node(obj, p)) is not None and t.image is not None]
    done = 0
    for img in imgs:
        if img.get(schema.APPEARANCE_PAINTED_KEY) and (img.is_dirty or img.packed_file is None or _PACKED.get(img.name) != img.packed_file.as_pointer()):
            pack(img)
            done += 1
    return done


def reload_after_undo(*_args) -> int:
    """undo_post/redo_post: painted images whose packed data the step replaced show it again."""
    import bpy

    done = 0
    for img in bpy.data.images:
        pf = img.packed_file if img.get(schema.APPEARANCE_PAINTED_KEY) else None
        if pf is not None and _PACKED.get(img.name) != pf.as_pointer():
            img.reload()
            _PACKED[img.name] = img.packed_file.as_pointer()
            done += 1
    return done


def _pack_painted_images(*_args):
    """save_pre: packs the painted images that changed into the .blend."""
    pack_painted()


def _ensure_save_handler():
    hooks.add("appearance", "save_pre", _rokeby_pack_painted_images)  # once, however often asked


def _rokeby_pack_painted_images(*args):
    _pack_painted_images(*args)


try:  # persistent: survives loading another file in the same session
    from bpy.app.handlers import persistent as _persistent

    _rokeby_pack_painted_images = _persistent(_rokeby_pack_painted_images)
except ImportError:  # pragma: no cover - outside Blender
    pass


def point_values(obj, param) -> np.ndarray:
    """``param`` per vertex whatever the target: the attribute (see :func:`read`), or on a texture
    target the image looked up bilinearly (texel centres at (i+½)/res, clamped) at each corner's
    UV and averaged over the vertex's corners. The viewport preview draws these, so it shows a
    texture target at vertex resolution."""
    img = _texture_image(obj, param) if param in PARAMS else None
    if img is None:
        return read(obj, param)
    me = obj.data
    uvn = obj.active_material.node_tree.nodes.get(NODE_PREFIX + "uv")
    uv_name = uvn.uv_map if uvn is not None and uvn.uv_map in me.uv_layers else None
    if uv_name is None:
        raise ValueError(f"obj: '{obj.name}' lacks the UV map its texture target reads")
    uv = np.empty(2 * len(me.loops), np.float32)
    me.uv_layers[uv_name].data.foreach_get("uv", uv)
    lv = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", lv)
    im = read_texture(obj, param).astype(np.float64)
    res = im.shape[0]
    uv = uv.reshape(-1, 2).astype(np.float64)
    x = np.clip(uv[:, 0] * res - 0.5, 0, res - 1)
    y = np.clip(uv[:, 1] * res - 0.5, 0, res - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), res - 2)
    y0 = np.minimum(np.floor(y).astype(np.int64), res - 2)
    fx, fy = x - x0, y - y0
    if im.ndim == 3:
        fx, fy = fx[:, None], fy[:, None]
    v = im[y0, x0] * (1 - fx) * (1 - fy) + im[y0, x0 + 1] * fx * (1 - fy) + im[y0 + 1, x0] * (1 - fx) * fy + im[y0 + 1, x0 + 1] * fx * fy
    n = len(me.vertices)
    cnt = np.maximum(np.bincount(lv, minlength=n), 1)
    if v.ndim == 2:
        out = np.stack([np.bincount(lv, v[:, k], minlength=n) for k in range(v.shape[1])], axis=1) / cnt[:, None]
    else:
        out = np.bincount(lv, v, minlength=n) / cnt
    return out.astype(np.float32)


def _stretch_direction_texture(obj, path, first, radius, strength):
    """:func:`_stretch_direction` on the texels of the ``anisotropic_rotation`` image: each texel's
    frame from its surface point and its triangle's interpolated vertex normal."""
    mat = obj.active_material
    tan = mat.node_tree.nodes.get(NODE_PREFIX + "tangent")
    if tan is None or not tan.outputs["Tangent"].is_linked:
        raise ValueError("brush: 'stretch' directions are relative to the radial tangent that Set Up Appearance Painting wires; this material's Tangent input is driven by something else")
    img = _texture_image(obj, "anisotropic_rotation")
    if img is None:
        raise ValueError(f"obj: '{obj.name}' has no texture for 'anisotropic_rotation'")
    res = img.size[0]
    ras = _raster(obj, mat.node_tree.nodes[NODE_PREFIX + "uv"].uv_map, res)
    m = np.asarray(obj.matrix_world, np.float64)
    _, order, spts, xs = _world_index(ras, m)
    r = CUTOFF * radius
    near = []
    for d in path[first:]:
        i0, i1 = np.searchsorted(xs, [d[0] - r, d[0] + r])
        near.append(order[i0 + _reach(spts[i0:i1], d, radius)])
    idx = np.unique(np.concatenate(near))
    if len(idx) == 0:
        return
    me = obj.data
    n = len(me.vertices)
    co = np.empty(3 * n, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    nrm = np.empty(3 * n, np.float32)
    me.vertex_normals.foreach_get("vector", nrm)
    nv = np.einsum("nk,nkc->nc", ras["bary"][idx], nrm.reshape(n, 3).astype(np.float64)[ras["tri_verts"][idx]])
    t, b, _ = _radial_frame_at(co.reshape(n, 3).astype(np.float64), ras["points"][idx], nv, m)
    px = np.empty(res * res * 4, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(-1, 4)
    rows = ras["texel"][idx]
    rho = px[rows, 0].astype(np.float64)
    p = ras["points"][idx] @ m[:3, :3].T + m[:3, 3]
    vec = np.stack([np.cos(4 * np.pi * rho), np.sin(4 * np.pi * rho)], axis=-1)
    for k in range(first, len(path)):
        s = path[min(k + 1, len(path) - 1)] - path[max(k - 1, 0)]
        if not np.linalg.norm(s) > 0:
            continue
        ang = np.arctan2(b @ s, t @ s)
        goal = np.stack([np.cos(2 * ang), np.sin(2 * ang)], axis=-1)
        w = falloff(p, path[k], radius, strength)[:, None]
        vec = vec + w * (goal - vec)
    rho = np.mod(np.arctan2(vec[:, 1], vec[:, 0]) / (4 * np.pi), 0.5)
    rho[rho > 0.5 - 1e-7] = 0.0
    px[rows, :3] = rho[:, None]
    img.pixels.foreach_set(px.ravel())
    img.update()


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
            if nodes is None or nodes.get(NODE_PREFIX + "global_roughness") is None or mat.library is not None:
                continue
            missing = [p for p in PARAMS if nodes.get(NODE_PREFIX + "global_" + p) is None
                       or (nodes.get(NODE_PREFIX + "uv") is not None and nodes.get(NODE_PREFIX + "tex_" + p) is None)]
            if not missing:
                continue
            uvn = nodes.get(NODE_PREFIX + "uv")
            kw = {}
            if uvn is not None:
                img = next((t.image for p in PARAMS if (t := nodes.get(NODE_PREFIX + "tex_" + p)) is not None and t.image is not None), None)
                kw = {"target": "TEXTURE", "resolution": img.size[0] if img is not None else 1024,
                      "uv_map": uvn.uv_map if uvn.uv_map in ob.data.uv_layers else None}
            try:
                setup(ob, mat, **kw)
            except ValueError as e:
                done.append(f"'{mat.name}' on '{ob.name}' kept without {', '.join(missing)}: {e}")
                continue
            done.append(f"'{mat.name}' on '{ob.name}': added {', '.join(missing)}")
    return done
