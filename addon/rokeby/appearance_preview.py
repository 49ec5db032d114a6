"""Viewport preview of painted appearance under the world HDR (issue 8): the painted mesh drawn
through Blender's gpu module with the shaders/rokeby_appearance_*.glsl files (interface in
:mod:`rokeby.appearance_glsl`): the prefiltered chain of the chosen model's lobe in one atlas
texture, order-2 SH irradiance, the GGX albedo table, per-point base colour/specular/roughness/
metallic. Models: Blender's BSDF (GGX split sum), the seed's Phong, Fraser's Torrance–Sparrow.

:class:`WorldLight` prefilters a lat-long world once per model (Rust, about a quarter to half a
second for 1024×512) and keeps its GPU textures; :func:`draw_object` draws one painted object with
a view-projection matrix and eye position (the draw handler passes the region's; tests pass their
own, offscreen).
"""

from __future__ import annotations

import numpy as np

from . import appearance, appearance_glsl, envmaps, glsl

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
        self._ubo = None

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

    def block(self, view_projection, eye):
        """The uniform block for one draw (one GPU buffer per world, updated in place)."""
        import gpu

        data = appearance_glsl.pack_block(view_projection, eye, len(self.levels), self.model, self.sh)
        if self._ubo is None:
            self._ubo = gpu.types.GPUUniformBuf(data)
        else:
            self._ubo.update(data)
        return self._ubo


def _mesh_arrays(obj):
    me = obj.data
    n = len(me.vertices)
    pos = np.empty(3 * n, np.float32)
    me.attributes["position"].data.foreach_get("vector", pos)
    nor = np.empty(3 * n, np.float32)
    me.vertex_normals.foreach_get("vector", nor)
    me.calc_loop_triangles()
    tris = np.empty(3 * len(me.loop_triangles), np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    base = appearance.point_values(obj, "diffuse")  # a texture target looked up at the vertices
    par = np.stack([appearance.point_values(obj, p) for p in ("specular", "roughness", "metallic")], axis=-1)
    return pos.reshape(n, 3), nor.reshape(n, 3), base, par, tris.reshape(-1, 3)


def draw_object(obj, world: WorldLight, view_projection, eye) -> None:
    """Draws ``obj`` (set up with rokeby.appearance.setup) into the bound framebuffer."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    pos, nor, base, par, tris = _mesh_arrays(obj)
    sh = shader()
    batch = batch_for_shader(sh, "TRIS", {"pos": pos, "nor": nor, "base": base, "par": par}, indices=tris)
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    sh.bind()
    sh.uniform_float("rk_model", obj.matrix_world)
    sh.uniform_block("rk_appearance", world.block(view_projection, eye))
    sh.uniform_sampler("rk_env_atlas", world.texture())
    sh.uniform_sampler("rk_brdf_lut", world.lut_texture())
    batch.draw(sh)
    gpu.state.depth_test_set("NONE")
    gpu.state.depth_mask_set(False)


# --- the viewport draw handler ---------------------------------------------------------------

_handle = None
_world_cache: dict = {}
last_error: str | None = None


def world_pixels(scene):
    """The scene world's equirectangular Environment Texture as (H, W, 4) float32, row 0 at the
    top, or None when the world has none."""
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
            return envmaps.flip_rows(px.reshape(h, w, 4))
    return None


def world_light(scene, model: str = "PRINCIPLED"):
    """The scene world prefiltered for ``model`` (cached per image, size and model), or None."""
    world = scene.world
    node = None
    if world is not None and world.use_nodes:
        node = next((n for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT" and n.image is not None), None)
    if node is None:
        return None
    key = (node.image.name, tuple(node.image.size), node.image.filepath, str(model).upper())
    if key not in _world_cache:
        px = world_pixels(scene)
        if px is None:
            return None
        _world_cache.clear()
        _world_cache[key] = WorldLight(px, model=model)
    return _world_cache[key]


def _draw():
    global last_error
    import bpy

    ctx = bpy.context
    rv3d = ctx.region_data
    if rv3d is None:
        return
    try:
        settings = getattr(ctx.window_manager, "rokeby_appearance_brush", None)
        light = world_light(ctx.scene, settings.preview_model if settings is not None else "PRINCIPLED")
        if light is None:
            last_error = "the world has no equirectangular Environment Texture to preview under"
            return
        inv = rv3d.view_matrix.inverted()
        eye = inv.translation if rv3d.is_perspective else inv.translation + inv.col[2].xyz * 1e4
        for ob in ctx.visible_objects:
            if ob.type == "MESH" and appearance.PARAMS["roughness"][0] in ob.data.attributes:
                draw_object(ob, light, np.array(rv3d.perspective_matrix), tuple(eye))
        last_error = None
    except Exception as e:  # noqa: BLE001 - a draw handler must not raise into Blender's redraw
        last_error = f"{type(e).__name__}: {e}"


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
