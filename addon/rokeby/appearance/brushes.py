"""Brush strokes (:func:`paint`). A stroke is a list of dabs; a dab at world position c with radius
r changes every point p by w = strength · exp(−‖p − c‖² / (2 (r/2)²)) (Gaussian falloff, e⁻² ≈ 0.14
at the radius): ``value ← value + w (target − value)`` for mode 'MIX', or
``value ← clamp(value ± w · amount)`` for 'ADD'/'SUBTRACT'; on per-point attributes or on the
texels of a texture target. Fraser's stretch brush also sets the anisotropy's direction. All
vectorised with numpy."""

from __future__ import annotations

import math

import numpy as np

from .attributes import _finite32, _write, read
from .image_packing import _ensure_save_handler, pack_painted
from ..core import schema
from .parameters import BRUSHES, COLORS, MAX_COLOR, PARAMS, _check_mesh, _texture_image
from .texture import _raster, _world_index, missing_images


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
        vals[idx] = _dab_values(vals[idx], w, target, mode, param, lo, hi)
    _write(obj, param, vals)
    if brush == "stretch" and len(path) >= 2:
        _stretch_direction(obj, pts, m, path, len(path) - len(c), radius, strength, np.unique(np.concatenate(reached)))
    return vals.astype(np.float32)


def _dab_values(v, w, target, mode: str, param: str, lo, hi) -> np.ndarray:
    """Values ``v`` after a dab of weights ``w``: towards ``target`` (MIX) or by it (ADD, SUBTRACT),
    then kept in the parameter's range (the anisotropic rotation wraps, colours stay ≥ 0)."""
    v = v + w * (target - v) if mode == "MIX" else v + (1.0 if mode == "ADD" else -1.0) * w * target
    if param == "anisotropic_rotation":
        return np.mod(v, 1.0)
    if param not in COLORS:
        return np.clip(v, lo, hi)
    return np.maximum(v, 0.0)


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
    tan = mat.node_tree.nodes.get(schema.APPEARANCE_NODE_PREFIX + "tangent") if mat is not None and mat.use_nodes else None
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


def _paint_texture(obj, img, param, c, radius, strength, mode, target):
    nodes = obj.active_material.node_tree.nodes
    uvn = nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv")
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
        v = _dab_values(v, w, target, mode, param, lo, hi)
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


def _stretch_direction_texture(obj, path, first, radius, strength):
    """:func:`_stretch_direction` on the texels of the ``anisotropic_rotation`` image: each texel's
    frame from its surface point and its triangle's interpolated vertex normal."""
    mat = obj.active_material
    tan = mat.node_tree.nodes.get(schema.APPEARANCE_NODE_PREFIX + "tangent")
    if tan is None or not tan.outputs["Tangent"].is_linked:
        raise ValueError("brush: 'stretch' directions are relative to the radial tangent that Set Up Appearance Painting wires; this material's Tangent input is driven by something else")
    img = _texture_image(obj, "anisotropic_rotation")
    if img is None:
        raise ValueError(f"obj: '{obj.name}' has no texture for 'anisotropic_rotation'")
    res = img.size[0]
    ras = _raster(obj, mat.node_tree.nodes[schema.APPEARANCE_NODE_PREFIX + "uv"].uv_map, res)
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
