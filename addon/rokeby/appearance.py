"""Appearance painting under environment light (issue 8; Fraser, "Interactive Real-Time BRDF
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
============  =============================  ==========================================

Each scalar attribute reaches its input through a Multiply node named ``rokeby_global_<param>``
whose second value is that parameter's global slider (1 = as painted); the colour goes through a
Mix (Multiply) node with the global tint. A stroke is a list of dabs; a dab at world position c with
radius r changes every point p by w = strength · exp(−‖p − c‖² / (2 (r/2)²)) (Gaussian falloff,
e⁻² ≈ 0.14 at the radius): ``value ← value + w (target − value)`` for mode 'MIX', or
``value ← clamp(value ± w · amount)`` for 'ADD'/'SUBTRACT'. All vectorised with numpy.
"""

from __future__ import annotations

import math

import numpy as np

# brush → (attribute, Principled input, default when the material has no value, clamp range)
PARAMS = {
    "diffuse": ("rokeby_base_color", "Base Color", (0.8, 0.8, 0.8, 1.0), (0.0, 1.0)),
    "specular": ("rokeby_specular", "Specular IOR Level", 0.5, (0.0, 1.0)),
    "roughness": ("rokeby_roughness", "Roughness", 0.5, (0.0, 1.0)),
    "anisotropic": ("rokeby_anisotropic", "Anisotropic", 0.0, (0.0, 1.0)),
    "anisotropic_rotation": ("rokeby_anisotropic_rotation", "Anisotropic Rotation", 0.0, (0.0, 1.0)),
    "metallic": ("rokeby_metallic", "Metallic", 0.0, (0.0, 1.0)),
}
# Fraser's brush names on top of the parameters.
BRUSHES = {"sharpen": ("roughness", "SUBTRACT"), "blur": ("roughness", "ADD"), "stretch": ("anisotropic", "ADD")}
NODE_PREFIX = "rokeby_"


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
        raise ValueError(f"obj: '{obj.name}' is a {obj.type}, not a mesh")
    if len(obj.data.vertices) == 0:
        raise ValueError(f"obj: '{obj.name}' has no vertices to paint")


def setup(obj, material=None):
    """Creates the attributes (filled with the material's current values) and wires them into the
    Principled BSDF of ``material`` (default: the object's active material; a new one if none).
    Idempotent: existing attributes and nodes are kept. Returns the material."""
    import bpy

    _check_mesh(obj)
    mat = material if material is not None else obj.active_material
    if mat is None:
        mat = bpy.data.materials.new(f"{obj.name} Painted")
        mat.use_nodes = True
        obj.data.materials.append(mat)
    if not mat.use_nodes:
        mat.use_nodes = True
    bsdf = _principled(mat)
    if bsdf is None:
        raise ValueError(f"material: '{mat.name}' has no Principled BSDF to paint into")
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
            if param == "diffuse":
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
            if param == "diffuse":
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
            nt.links.new(out, sock)
    return mat


def _attr(obj, param):
    if param not in PARAMS:
        raise ValueError(f"param: unknown parameter {param!r} (expected one of {', '.join(PARAMS)})")
    attr = PARAMS[param][0]
    a = obj.data.attributes.get(attr)
    if a is None:
        raise ValueError(f"obj: '{obj.name}' has no attribute {attr!r}: call rokeby.appearance.setup(obj) first")
    return a


def read(obj, param) -> np.ndarray:
    """The painted values of ``param``: (N,) floats, or (N, 4) RGBA for 'diffuse'."""
    a = _attr(obj, param)
    n = len(obj.data.vertices)
    if param == "diffuse":
        v = np.empty(4 * n, np.float32)
        a.data.foreach_get("color", v)
        return v.reshape(n, 4)
    v = np.empty(n, np.float32)
    a.data.foreach_get("value", v)
    return v


def _write(obj, param, values):
    a = _attr(obj, param)
    a.data.foreach_set("color" if param == "diffuse" else "value", np.ascontiguousarray(values, np.float32).ravel())
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


def paint(obj, brush: str, centres, radius: float, value=None, strength: float = 1.0, mode: str | None = None, previous=None) -> np.ndarray:
    """One stroke of ``brush`` (a parameter of PARAMS or Fraser's 'sharpen', 'blur', 'stretch')
    through world-space ``centres`` ((3,) or (K, 3) dabs, applied in order). ``value`` is the
    target (mode 'MIX', an RGB(A) colour for 'diffuse') or the amount (modes 'ADD'/'SUBTRACT';
    default 0.25). ``previous``: the stroke's point before these dabs (not painted again; it
    gives 'stretch' its direction when a stroke arrives one dab at a time). Returns the new
    values."""
    _check_mesh(obj)
    param, default_mode = BRUSHES.get(brush, (brush, "MIX"))
    if param not in PARAMS:
        raise ValueError(f"brush: unknown brush {brush!r} (expected one of {', '.join(list(PARAMS) + list(BRUSHES))})")
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
    if param == "diffuse":
        v = np.asarray(value, np.float64).ravel()
        if v.size == 3:
            v = np.append(v, 1.0)
        if v.size != 4 or not np.isfinite(v).all() or (v < 0).any():
            raise ValueError(f"value: a diffuse colour is 3 or 4 finite values ≥ 0, got {value!r}")
        target = v
    else:
        if not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise ValueError(f"value: must be a finite number, got {value!r}")
        if value < 0:
            raise ValueError(f"value: must be ≥ 0 (a {'target' if mode == 'MIX' else 'amount'}; use mode 'SUBTRACT' to lower), got {value}")
        target = float(value)
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
        if param == "diffuse":
            w = w[:, None]
        v = vals[idx]
        if mode == "MIX":
            v = v + w * (target - v)
        else:
            v = v + (1.0 if mode == "ADD" else -1.0) * w * target
        if param == "anisotropic_rotation":
            v = np.mod(v, 1.0)
        elif param != "diffuse":
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
    lo, hi = co.min(axis=0), co.max(axis=0)
    g = (co[idx] - lo) / np.where(hi > lo, hi - lo, 1.0)
    inv = np.linalg.inv(m[:3, :3])  # both transformed as normals (object_normal_transform)
    data = np.stack([-(g[:, 1] - 0.5), g[:, 0] - 0.5, np.zeros(len(idx))], axis=-1) @ inv
    nw = nrm.reshape(n, 3)[idx].astype(np.float64) @ inv
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
        raise ValueError("brush: 'stretch' directions are relative to the radial tangent that setup() wires; this material's Tangent input is driven by something else")
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
    'diffuse' an RGB tint)."""
    if param not in PARAMS:
        raise ValueError(f"param: unknown parameter {param!r} (expected one of {', '.join(PARAMS)})")
    node = mat.node_tree.nodes.get(NODE_PREFIX + "global_" + param) if mat is not None and mat.use_nodes else None
    if node is None:
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' is not set up for painting: call rokeby.appearance.setup(obj) first")
    if param == "diffuse":
        v = np.asarray(value, np.float64).ravel()
        if v.size == 3:
            v = np.append(v, 1.0)
        if v.size != 4 or not np.isfinite(v).all() or (v < 0).any():
            raise ValueError(f"value: a tint is 3 or 4 finite values ≥ 0, got {value!r}")
        node.inputs[7].default_value = tuple(float(x) for x in v)
    else:
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
            raise ValueError(f"value: a global scale must be finite and ≥ 0, got {value!r}")
        node.inputs[1].default_value = float(value)
