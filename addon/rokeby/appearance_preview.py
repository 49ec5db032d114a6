"""Viewport preview of painted appearance under the world HDR (issue 8): the painted mesh drawn
through Blender's gpu module with :data:`rokeby.appearance_glsl.GLSL` (prefiltered GGX chain in
one atlas texture, order-2 SH irradiance, per-point base colour/specular/roughness/metallic).

:class:`WorldLight` prefilters a lat-long world once (Rust, about half a second for 1024×512) and
keeps its GPU texture; :func:`draw_object` draws one painted object with a view-projection
matrix and eye position (the draw handler passes the region's; tests pass their own, offscreen).
"""

from __future__ import annotations

import numpy as np

from . import appearance, appearance_glsl, envmaps

_shader = None


def _library() -> str:
    # In a GPUShaderCreateInfo the uniforms are declared by the info (push constants, samplers).
    return "\n".join(line for line in appearance_glsl.GLSL.splitlines() if not line.startswith("uniform "))


def shader():
    """The preview shader (compiled once per session)."""
    global _shader
    if _shader is not None:
        return _shader
    import gpu

    iface = gpu.types.GPUStageInterfaceInfo("rk_appearance_iface")
    iface.smooth("VEC3", "v_pos")
    iface.smooth("VEC3", "v_nor")
    iface.smooth("VEC4", "v_base")
    iface.smooth("VEC3", "v_par")
    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, "VEC3", "pos")
    info.vertex_in(1, "VEC3", "nor")
    info.vertex_in(2, "VEC4", "base")
    info.vertex_in(3, "VEC3", "par")
    info.vertex_out(iface)
    info.push_constant("MAT4", "rk_vp")
    info.push_constant("MAT4", "rk_model")
    info.push_constant("VEC3", "rk_eye")
    info.push_constant("INT", "rk_env_levels")
    info.push_constant("VEC3", "rk_sh", 9)
    info.sampler(0, "FLOAT_2D", "rk_env_atlas")
    info.fragment_out(0, "VEC4", "frag")
    info.vertex_source(
        "void main() {\n"
        "  vec4 w = rk_model * vec4(pos, 1.0);\n"
        "  v_pos = w.xyz;\n"
        "  v_nor = transpose(inverse(mat3(rk_model))) * nor;\n"
        "  v_base = base;\n"
        "  v_par = par;\n"
        "  gl_Position = rk_vp * w;\n"
        "}\n"
    )
    info.fragment_source(
        _library()
        + "\nvoid main() {\n"
        "  vec3 n = normalize(v_nor);\n"
        "  vec3 v = normalize(rk_eye - v_pos);\n"
        "  frag = vec4(rk_shade(n, v, v_base.rgb, v_par.x, v_par.y, v_par.z), 1.0);\n"
        "}\n"
    )
    _shader = gpu.shader.create_from_info(info)
    return _shader


class WorldLight:
    """A lat-long world (H, W, 3+) prefiltered for the preview: the GGX chain at Blender's
    roughness 0, 1/7, …, 1 in one atlas, and the irradiance SH coefficients."""

    def __init__(self, pixels, atlas_height: int = 128):
        px = np.asarray(pixels, np.float32)[..., :3]
        self.levels = envmaps.prefilter(px, "ggx", envmaps.ROUGHNESS_LEVELS)
        self.atlas = appearance_glsl.atlas(self.levels, height=min(atlas_height, px.shape[0]))
        self.sh = np.asarray(envmaps.irradiance(px, size=8)["irradiance_coeffs"], np.float32)  # (3, 9)
        self._texture = None

    def texture(self):
        if self._texture is None:
            import gpu

            h, w = self.atlas.shape[:2]
            rgba = np.concatenate([self.atlas, np.ones((h, w, 1), np.float32)], axis=-1)
            # GPU textures run bottom-up: the atlas row 0 (top) becomes texel row 0 via the shader's
            # own (1 − v) flip, so upload in array order.
            buf = gpu.types.Buffer("FLOAT", h * w * 4, rgba.ravel().tolist())
            self._texture = gpu.types.GPUTexture((w, h), format="RGBA32F", data=buf)
        return self._texture


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
    from mathutils import Matrix

    pos, nor, base, par, tris = _mesh_arrays(obj)
    sh = shader()
    batch = batch_for_shader(sh, "TRIS", {"pos": pos, "nor": nor, "base": base, "par": par}, indices=tris)
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    sh.bind()
    sh.uniform_float("rk_vp", Matrix(np.asarray(view_projection, np.float64).tolist()))
    sh.uniform_float("rk_model", obj.matrix_world)
    sh.uniform_float("rk_eye", tuple(float(x) for x in eye))
    sh.uniform_int("rk_env_levels", len(world.levels))
    coeffs = np.ascontiguousarray(world.sh.T, np.float32).ravel()  # 9 vec3, one per SH term
    sh.uniform_vector_float(sh.uniform_from_name("rk_sh"), gpu.types.Buffer("FLOAT", 27, coeffs.tolist()), 3, 9)
    sh.uniform_sampler("rk_env_atlas", world.texture())
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


def world_light(scene):
    """The scene world prefiltered (cached per image and size), or None."""
    world = scene.world
    node = None
    if world is not None and world.use_nodes:
        node = next((n for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT" and n.image is not None), None)
    if node is None:
        return None
    key = (node.image.name, tuple(node.image.size), node.image.filepath)
    if key not in _world_cache:
        px = world_pixels(scene)
        if px is None:
            return None
        _world_cache.clear()
        _world_cache[key] = WorldLight(px)
    return _world_cache[key]


def _draw():
    global last_error
    import bpy

    ctx = bpy.context
    rv3d = ctx.region_data
    if rv3d is None:
        return
    try:
        light = world_light(ctx.scene)
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
