"""Viewport preview of painted appearance under the world HDR: the painted mesh drawn
through Blender's gpu module with the shaders/rokeby_appearance_*.glsl files (interface in
:mod:`rokeby.appearance.glsl`): the prefiltered chain of the chosen model's lobe in one atlas
texture, order-2 SH irradiance, the GGX albedo table, the painted base colour/specular/roughness/
metallic and the material's global sliders. Models: Blender's BSDF (GGX split sum), the seed's
Phong, Fraser's Torrance–Sparrow.

Per-point targets are fetched per vertex from one float texture (``rk_points``), texture targets
are read from their images at each fragment's UV (texel resolution, bilinear like the material's
Image Texture nodes). Each mesh keeps a :class:`MeshPreview` between redraws: the geometry batch
is rebuilt only when positions, normals, topology or the UVs change, and a brush stroke on a
per-point target re-uploads only ``rk_points`` (a texture target's images are Blender's own GPU
textures, refreshed by Blender when painted).

:class:`WorldLight` prefilters a lat-long world once per model (Rust, about a quarter to half a
second for 1024×512) and keeps its GPU textures; :func:`draw_object` draws one painted object with
a view-projection matrix and eye position (the draw handler passes the region's; tests pass their
own, offscreen).
"""

from __future__ import annotations

import numpy as np

from .. import appearance, envmaps
from . import glsl as appearance_glsl
from . import parameters
from ..blender import gpu as glsl
from ..core import schema

_shader = None


def shader():
    """The preview shader (compiled once per session) from shaders/ through GPUShaderCreateInfo."""
    global _shader
    if _shader is not None:
        return _shader
    _shader = glsl.create_shader(appearance_glsl.INTERFACE, appearance_glsl.INTERFACE_NAME, appearance_glsl.read_sources())
    return _shader


def _texture(rgba: np.ndarray):
    import gpu

    h, w = rgba.shape[:2]
    buf = gpu.types.Buffer("FLOAT", h * w * 4, np.ascontiguousarray(rgba, np.float32).ravel().tolist())
    return gpu.types.GPUTexture((w, h), format="RGBA32F", data=buf)


class WorldLight:
    """A lat-long world (H, W, 3+) prefiltered for the preview with ``model``'s lobe
    (appearance_glsl.MODELS) at Blender's roughness 0, 1/7, …, 1 in one atlas, and the irradiance
    SH coefficients."""

    def __init__(self, pixels, atlas_height: int = 128, model: str = "PRINCIPLED"):
        self.model = str(model).upper()
        params = appearance_glsl.level_params(self.model)
        px = np.asarray(pixels, np.float32)[..., :3]
        self.levels = envmaps.prefilter(px, appearance_glsl.LOBE[self.model], params)
        self.atlas = appearance_glsl.atlas(self.levels, height=min(atlas_height, px.shape[0]))
        self.sh = np.asarray(envmaps.irradiance(px, size=8)["irradiance_coeffs"], np.float32)  # (3, 9)
        self._texture = None
        self._lut = None
        self._ubos = {}

    def texture(self):
        if self._texture is None:
            # GPU textures run bottom-up: the atlas row 0 (top) becomes texel row 0 via the shader's
            # own (1 − v) flip, so upload in array order.
            h, w = self.atlas.shape[:2]
            self._texture = _texture(np.concatenate([self.atlas, np.ones((h, w, 1), np.float32)], axis=-1))
        return self._texture

    def lut_texture(self):
        if self._lut is None:
            lut = appearance_glsl.brdf_lut()
            s = lut.shape[0]
            self._lut = _texture(np.concatenate([lut, np.zeros((s, s, 1), np.float32), np.ones((s, s, 1), np.float32)], axis=-1))
        return self._lut

    def block(self, view_projection, eye, slot=0, **material):
        """The uniform block for one draw (one GPU buffer per world and ``slot``, updated in place:
        the environment-lit and the point-lit view of one redraw use two slots); ``material``:
        pack_block's textures, tint, scale, specular tint and light."""
        import gpu

        data = appearance_glsl.pack_block(view_projection, eye, len(self.levels), self.model, self.sh, **material)
        ubo = self._ubos.get(slot)
        if ubo is None:
            ubo = self._ubos[slot] = gpu.types.GPUUniformBuf(data)
        else:
            ubo.update(data)
        return ubo


POINTS_WIDTH = 4095  # rk_points: texels per row (three per vertex: a vertex never straddles rows)


def _read_mesh(obj, uv_name):
    """What decides the geometry batch, read with the attribute fast paths (a fraction of a ms at
    100k vertices): positions, corner vertices, the face count and, for texture targets, the UV
    map. Vertex normals follow from these (and are slow to read after a stroke's mesh update,
    which makes Blender recompute them), so they are read only when the batch is rebuilt."""
    me = obj.data
    n, nl = len(me.vertices), len(me.loops)
    pos = np.empty(3 * n, np.float32)
    me.attributes["position"].data.foreach_get("vector", pos)
    cv = np.empty(nl, np.int32)
    me.attributes[".corner_vert"].data.foreach_get("value", cv)
    uv = None
    if uv_name is not None:
        uv = np.empty(2 * nl, np.float32)
        me.uv_layers[uv_name].data.foreach_get("uv", uv)
    return {"pos": pos, "corner_vert": cv, "faces": np.array([len(me.polygons)]), "uv": uv}


def _same(a, b) -> bool:
    return a.keys() == b.keys() and all((x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
                                        for x, y in ((a[k], b[k]) for k in a))


def _point_values(obj) -> np.ndarray:
    """(N, 12) float32: per vertex the painted base colour (rgba); specular, roughness, metallic, 0;
    specular tint (rgb), 1 — rk_points' three texels per vertex. A mesh painted before the
    specular colour existed (not migrated: a linked library) previews with a white tint."""
    n = len(obj.data.vertices)
    out = np.zeros((n, 4 * appearance_glsl.TEXELS_PER_POINT), np.float32)
    out[:, 0:4] = appearance.read(obj, "diffuse")
    for k, param in enumerate(appearance_glsl.POINT_PARAMS):
        out[:, 4 + k] = appearance.read(obj, param)
    if appearance.PARAMS["specular_tint"][0] in obj.data.attributes:
        out[:, 8:12] = appearance.read(obj, "specular_tint")
    else:
        out[:, 8:12] = 1.0
    return out


def _points_texture(values):
    import gpu

    n, k = len(values), appearance_glsl.TEXELS_PER_POINT
    rows = max(1, -(-k * n // POINTS_WIDTH))
    flat = np.zeros((rows * POINTS_WIDTH, 4), np.float32)
    flat[: k * n] = values.reshape(k * n, 4)
    return gpu.types.GPUTexture((POINTS_WIDTH, rows), format="RGBA32F", data=gpu.types.Buffer("FLOAT", flat.size, flat.ravel()))


class MeshPreview:
    """What the preview keeps for one mesh between redraws: the geometry batch (positions,
    normals, UVs, vertex ids; rebuilt only when :func:`_read_mesh` differs) and the rk_points
    texture of the painted per-point values (re-uploaded only when they differ). A brush stroke
    thus costs one texture upload, not a batch. ``builds`` and ``uploads`` count both."""

    def __init__(self):
        self.mesh_state = None
        self.batch = None
        self.values = None
        self.points = None
        self.builds = 0
        self.uploads = 0

    def geometry(self, obj, shader, uv_name):
        state = _read_mesh(obj, uv_name)
        if self.batch is None or not _same(state, self.mesh_state):
            self.batch = _build_batch(obj, shader, state)
            self.mesh_state = state
            self.builds += 1
        return self.batch

    def points_texture(self, obj):
        values = _point_values(obj)
        if self.points is None or not np.array_equal(values, self.values):
            self.points = _points_texture(values)
            self.values = values
            self.uploads += 1
        return self.points


def _build_batch(obj, shader, state):
    """The indexed triangle batch: one drawn vertex per mesh vertex, or per distinct (vertex, UV)
    pair when a texture target needs UVs (seams split)."""
    from gpu_extras.batch import batch_for_shader

    me = obj.data
    n = len(me.vertices)
    if n >= appearance_glsl.MAX_VERTICES:
        raise ValueError(f"obj: '{obj.name}' has {n} vertices; the preview draws meshes below {appearance_glsl.MAX_VERTICES}")
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    pos = state["pos"].reshape(n, 3)
    nor = np.empty(3 * n, np.float32)
    me.vertex_normals.foreach_get("vector", nor)
    nor = nor.reshape(n, 3)
    if state["uv"] is None:
        tris = np.empty(3 * nt, np.int32)
        me.loop_triangles.foreach_get("vertices", tris)
        vid = np.arange(n, dtype=np.float32)
        uv = np.zeros((n, 2), np.float32)
        attrs = {"pos": pos, "nor": nor, "uv": uv, "vid": vid}
    else:
        corners = np.empty(3 * nt, np.int32)
        me.loop_triangles.foreach_get("loops", corners)
        uvc = state["uv"].reshape(-1, 2)
        key = np.empty((len(uvc), 2), np.int64)
        key[:, 0] = state["corner_vert"]
        key[:, 1] = uvc.view(np.int64).ravel()  # the UV's bits: equal UVs share a drawn vertex
        uniq, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.ravel()
        tris = inverse[corners].astype(np.int32)
        v = uniq[:, 0]
        vid = v.astype(np.float32)
        attrs = {"pos": pos[v], "nor": nor[v], "uv": np.ascontiguousarray(uvc[first]), "vid": vid}
    return batch_for_shader(shader, "TRIS", attrs, indices=tris.reshape(-1, 3))


_previews: dict = {}


def mesh_preview(obj, evaluated: bool = False) -> MeshPreview:
    """The :class:`MeshPreview` of ``obj``'s mesh (kept per mesh datablock; ``evaluated``: the one
    for the mesh its modifiers make)."""
    key = (obj.data.as_pointer(), bool(evaluated))
    mp = _previews.get(key)
    if mp is None:
        if len(_previews) >= 64:  # meshes that went away: drop the oldest
            _previews.pop(next(iter(_previews)))
        mp = _previews[key] = MeshPreview()
    return mp


def material_state(obj):
    """(texture bits, {param: GPU texture of its image}, tint, scale, specular tint): what the
    material's texture targets and global sliders (rokeby_global_* nodes) add to the painted values."""
    import gpu

    bits, textures = 0, {}
    for param, bit in appearance_glsl.TEXTURE_BITS.items():
        img = parameters._texture_image(obj, param)
        if img is not None:
            bits |= bit
            textures[param] = gpu.texture.from_image(img)
    tint, scale, spec_tint = (1.0, 1.0, 1.0, 1.0), [1.0, 1.0, 1.0], (1.0, 1.0, 1.0)
    mat = obj.active_material
    nodes = mat.node_tree.nodes if mat is not None and mat.use_nodes else None
    if nodes is not None:
        g = nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_diffuse")
        if g is not None:
            tint = tuple(g.inputs[7].default_value)
        for k, param in enumerate(appearance_glsl.POINT_PARAMS):
            g = nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + param)
            if g is not None:
                scale[k] = float(g.inputs[1].default_value)
        g = nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_specular_tint")
        if g is not None:
            spec_tint = tuple(g.inputs[7].default_value)[:3]
    return bits, textures, tint, tuple(scale), spec_tint


def _uv_name(obj, me=None):
    uvn = obj.active_material.node_tree.nodes.get(schema.APPEARANCE_NODE_PREFIX + "uv")
    me = obj.data if me is None else me
    if uvn is None or uvn.uv_map not in me.uv_layers:
        raise ValueError(f"obj: '{obj.name}' lacks the UV map its texture target reads")
    return uvn.uv_map


_dummy = None


def _dummy_texture():
    global _dummy
    if _dummy is None:
        import gpu

        _dummy = gpu.types.GPUTexture((1, 1), format="RGBA32F", data=gpu.types.Buffer("FLOAT", 4, [0.0, 0.0, 0.0, 1.0]))
    return _dummy


def prepare(obj, depsgraph=None):
    """What a draw of ``obj`` needs before it draws, brought up to date: (its MeshPreview, the
    geometry batch, the rk_points texture, :func:`material_state`). Cheap when nothing changed."""
    src = obj.evaluated_get(depsgraph) if depsgraph is not None else obj
    state = material_state(obj)
    mp = mesh_preview(obj, evaluated=depsgraph is not None)
    batch = mp.geometry(src, shader(), _uv_name(obj, src.data) if state[0] else None)
    return mp, batch, mp.points_texture(src), state


def draw_object(obj, world: WorldLight, view_projection, eye, depsgraph=None, point_light=None, offset=(0.0, 0.0, 0.0)) -> MeshPreview:
    """Draws ``obj`` (set up with rokeby.appearance.setup) into the bound framebuffer: per-point
    targets per vertex, texture targets at their texels, with the material's global sliders.
    With a ``depsgraph`` the mesh its modifiers make is drawn (the painted attributes and UVs as
    the modifiers carry them, as the render sees them), else the object's own mesh.
    ``point_light``: None for the environment-lit view, or (world position, intensity) for
    Fraser's point-light view; ``offset``: a world translation of the drawn copy (the point-lit
    view drawn beside the object). Returns the mesh's :class:`MeshPreview` (its batch and painted
    values are kept for the next draw)."""
    import gpu
    from mathutils import Matrix

    mp, batch, points, (bits, textures, tint, scale, spec_tint) = prepare(obj, depsgraph)
    sh = shader()
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    sh.bind()
    model = np.array(obj.matrix_world, np.float64)
    model[:3, 3] += np.asarray(offset, np.float64)
    lit = {} if point_light is None else {"light": "POINT", "light_position": tuple(point_light[0]), "light_intensity": float(point_light[1])}
    sh.uniform_float("rk_model", obj.matrix_world if not np.any(offset) else Matrix(model.tolist()))
    sh.uniform_block("rk_appearance", world.block(view_projection, eye, slot=int(point_light is not None), textures=bits, tint=tint,
                                                  scale=scale, spec_tint=spec_tint, model_matrix=model, **lit))
    sh.uniform_sampler("rk_env_atlas", world.texture())
    sh.uniform_sampler("rk_brdf_lut", world.lut_texture())
    sh.uniform_sampler("rk_points", points)
    for param in appearance_glsl.TEXTURE_BITS:
        sh.uniform_sampler(appearance_glsl.TEXTURE_SAMPLERS[param], textures.get(param) or _dummy_texture())
    batch.draw(sh)
    gpu.state.depth_test_set("NONE")
    gpu.state.depth_mask_set(False)
    return mp


# --- the viewport draw handler ---------------------------------------------------------------

_handle = None
_world_cache: dict = {}
last_error: str | None = None


def _stored_linear(img) -> bool:
    """Whether a byte image's ``pixels`` are linear values as stored (data and linear colour
    spaces); else they are display-encoded and decoded with the sRGB curve."""
    cs = img.colorspace_settings
    return bool(getattr(cs, "is_data", False)) or cs.name == "Non-Color" or cs.name.startswith(("Linear", "ACES"))


def world_pixels(scene):
    """The scene world's equirectangular Environment Texture as (H, W, 4) float32 linear values,
    row 0 at the top, or None when the world has none.

    Blender gives float images (EXR, HDR, 16-bit PNG) in linear values, but 8-bit images (PNG,
    JPEG) as their stored codes: an sRGB world is decoded here (:func:`envmaps.srgb_to_linear`,
    as Cycles reads it), so an LDR world lights the preview as it lights the render."""
    world = scene.world
    if world is None or not world.use_nodes:
        return None
    for node in world.node_tree.nodes:
        if node.type == "TEX_ENVIRONMENT" and node.image is not None and node.projection == "EQUIRECTANGULAR" and not node.mute:
            img = node.image
            w, h = img.size
            if w < 2 or h < 2:
                return None
            px = np.empty(w * h * 4, np.float32)
            img.pixels.foreach_get(px)
            px = envmaps.flip_rows(px.reshape(h, w, 4))
            if not img.is_float and not _stored_linear(img):
                px[..., :3] = envmaps.srgb_to_linear(px[..., :3])
            return px
    return None


def world_light(scene, model: str = "PRINCIPLED"):
    """The scene world prefiltered for ``model`` (cached per image, size and model), or None."""
    world = scene.world
    node = None
    if world is not None and world.use_nodes:
        node = next((n for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT" and n.image is not None), None)
    if node is None:
        return None
    img = node.image
    key = (img.name, tuple(img.size), img.filepath, img.is_float, img.colorspace_settings.name, str(model).upper())
    if key not in _world_cache:
        px = world_pixels(scene)
        if px is None:
            return None
        _world_cache.clear()
        _world_cache[key] = WorldLight(px, model=model)
    return _world_cache[key]


def view_eye(rv3d):
    """The eye of a 3D view (its RegionView3D): the camera point, or far along the view axis for an
    orthographic view (parallel rays)."""
    inv = rv3d.view_matrix.inverted()
    return tuple(inv.translation if rv3d.is_perspective else inv.translation + inv.col[2].xyz * 1e4)


PREVIEW_LIGHTS = ("ENVIRONMENT", "POINT", "BESIDE")
BESIDE_GAP = 1.25  # the point-lit copy's offset in bounding diameters along the view's right


def beside_offset(obj, rv3d) -> np.ndarray:
    """Where Fraser's second view goes: the world translation that puts a copy of ``obj`` to the
    right of it on screen, BESIDE_GAP of its (world) bounding diameters away."""
    m = np.array(obj.matrix_world, np.float64)
    corners = np.array([tuple(c) for c in obj.bound_box], np.float64) @ m[:3, :3].T + m[:3, 3]
    diameter = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    right = np.array(rv3d.view_matrix.inverted().col[0].xyz, np.float64)
    return right / max(np.linalg.norm(right), 1e-30) * BESIDE_GAP * max(diameter, 1e-6)


def draw_view(scene, rv3d, objects, model: str = "PRINCIPLED", depsgraph=None, light: str = "ENVIRONMENT",
              light_position=(3.0, -3.0, 4.0), light_intensity: float = 10.0) -> int:
    """What the POST_VIEW handler draws for one 3D view: every painted mesh among ``objects``
    under ``scene``'s world, with the view's matrices (with a ``depsgraph``: as its modifiers
    make it). ``light``: 'ENVIRONMENT' (the world), 'POINT' (the point light at
    ``light_position``, world space, of ``light_intensity`` W/sr) or 'BESIDE' (Fraser's interface:
    the object under the world and, to its right on screen, a copy under the point light, placed
    relative to the copy as ``light_position`` is to the object). Returns how many objects were
    drawn; raises ValueError when the world has nothing to preview under."""
    light = str(light).upper()
    if light not in PREVIEW_LIGHTS:
        raise ValueError(f"light: expected one of {', '.join(PREVIEW_LIGHTS)}, got {light!r}")
    world = world_light(scene, model)
    if world is None:
        raise ValueError("the world has no equirectangular Environment Texture to preview under")
    eye, vp = view_eye(rv3d), np.array(rv3d.perspective_matrix)
    lp = np.asarray(light_position, np.float64)
    drawn = 0
    for ob in objects:
        if ob.type == "MESH" and appearance.PARAMS["roughness"][0] in ob.data.attributes:
            if light == "POINT":
                draw_object(ob, world, vp, eye, depsgraph, point_light=(lp, light_intensity))
            else:
                draw_object(ob, world, vp, eye, depsgraph)
            if light == "BESIDE":
                off = beside_offset(ob, rv3d)
                draw_object(ob, world, vp, eye, depsgraph, point_light=(lp + off, light_intensity), offset=off)
            drawn += 1
    return drawn


def _draw():
    global last_error
    import bpy

    from ..blender import prefs

    ctx = bpy.context
    rv3d = ctx.region_data
    if rv3d is None or not prefs.get(ctx).gpu_viewport_preview:  # the machine's opt-out (add-on preferences)
        return
    try:
        settings = getattr(ctx.scene, schema.SCENE_APPEARANCE_BRUSH_PROP, None)
        if settings is None:
            draw_view(ctx.scene, rv3d, ctx.visible_objects, "PRINCIPLED", ctx.evaluated_depsgraph_get())
        else:
            draw_view(ctx.scene, rv3d, ctx.visible_objects, settings.preview_model, ctx.evaluated_depsgraph_get(),
                      settings.preview_light, tuple(settings.light_location), settings.light_intensity)
        last_error = None
    except Exception as e:  # noqa: BLE001 - a draw handler must not raise into Blender's redraw
        last_error = str(e) if isinstance(e, ValueError) else f"{type(e).__name__}: {e}"


def enable(on: bool = True) -> bool:
    """Adds (or removes) the POST_VIEW draw handler; returns whether it is on."""
    global _handle
    import bpy

    if on and _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW", "POST_VIEW")
    elif not on and _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    return _handle is not None


def enabled() -> bool:
    return _handle is not None
