"""Texture targets: ``setup(obj, target='TEXTURE')`` paints images through the UV map instead of
per-point attributes (one per parameter, same nodes downstream, packed into the .blend on save by
``image_packing.py``). Every texel covered by the UV layout has a 3D surface point (the raster),
which the brushes and the viewport preview (:func:`point_values`) read."""

from __future__ import annotations

import numpy as np

from ..blender import transaction
from ..core import schema
from .attributes import read
from .image_packing import _ensure_save_handler, pack_painted
from .parameters import COLORS, PARAMS, _check_mesh, _texture_image


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
    if nodes is None or nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_roughness") is None:
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' is not set up for painting: click Set Up Appearance Painting first (Rokeby ▸ Appearance Painting)")
    nt = mat.node_tree
    uv_name = uv_map if uv_map is not None else obj.data.uv_layers.active.name
    uvn = nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv")
    if uvn is None:
        uvn = nodes.new("ShaderNodeUVMap")
        uvn.name = uvn.label = schema.APPEARANCE_NODE_PREFIX + "uv"
        g = nodes[schema.APPEARANCE_NODE_PREFIX + "global_roughness"]
        uvn.location = (g.location.x - 800, g.location.y)
    uvn.uv_map = uv_name
    ras = _raster(obj, uv_name, resolution)
    for param in PARAMS:
        glob = nodes[schema.APPEARANCE_NODE_PREFIX + "global_" + param]
        tex = nodes.get(schema.APPEARANCE_NODE_PREFIX + "tex_" + param)
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
            tex.name = tex.label = schema.APPEARANCE_NODE_PREFIX + "tex_" + param
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

    mat = material if material is not None else obj.active_material
    nodes = mat.node_tree.nodes if mat is not None and mat.use_nodes else None
    if nodes is None or nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv") is None:
        raise ValueError(f"material: '{getattr(mat, 'name', mat)}' has no texture target to remove")
    nt = mat.node_tree
    for param in PARAMS:
        tex = nodes.get(schema.APPEARANCE_NODE_PREFIX + "tex_" + param)
        glob = nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + param)
        attr = nodes.get(schema.APPEARANCE_NODE_PREFIX + param)
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
    transaction.remove_node(nt, nodes[schema.APPEARANCE_NODE_PREFIX + "uv"])


def target(obj) -> str:
    """'TEXTURE' when the active material reads images through ``rokeby_uv``, else 'POINT'."""
    mat = obj.active_material
    return "TEXTURE" if mat is not None and mat.use_nodes and mat.node_tree.nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv") is not None else "POINT"


def missing_images(obj) -> list[str]:
    """Parameters whose painted image a texture target reads is gone (an artist deleted it):
    painting them is refused until the target is set up again."""
    if target(obj) != "TEXTURE":
        return []
    nodes = obj.active_material.node_tree.nodes
    return [p for p in PARAMS if (t := nodes.get(schema.APPEARANCE_NODE_PREFIX + "tex_" + p)) is None or t.image is None]


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


def point_values(obj, param) -> np.ndarray:
    """``param`` per vertex whatever the target: the attribute (see :func:`read`), or on a texture
    target the image looked up bilinearly (texel centres at (i+½)/res, clamped) at each corner's
    UV and averaged over the vertex's corners. The viewport preview draws these, so it shows a
    texture target at vertex resolution."""
    img = _texture_image(obj, param) if param in PARAMS else None
    if img is None:
        return read(obj, param)
    me = obj.data
    uvn = obj.active_material.node_tree.nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv")
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
