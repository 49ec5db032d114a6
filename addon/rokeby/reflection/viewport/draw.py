"""Live viewport preview of edited reflections (paper §6.1).

A POST_VIEW draw handler on the 3D View draws every mirror that shows its preview with the
per-pixel field shader of ``shaders/`` (the same files the moderngl tests check against
``rokeby_native.reflection.edited_directions``): e(q) = R_a(q) r(q) at every pixel, looked up in the
mirror's reflection map when it has one, else in the world's equirectangular image, else in a
built-in sky with a 15° grid. Overlays: the red and green handles, a red-to-green line per
constraint, region borders (the outer and inner circle of Euclidean regions, facing the view; the
edge and the full-effect core of geodesic and free-form regions as lines on the surface).

Inputs are the evaluator's (``mirror_state.state_of``): its world-space mesh, its constraint rows,
geodesic distances and region weights, so the preview and the stored field agree. Beyond
RK_MAX_CONSTRAINTS constraints or RK_MAX_REGIONS regions the shader interpolates the stored
per-vertex field instead, and ``status_of`` says so (the sidebar shows it).

Nothing here touches ``gpu`` at import or register time: the shader, batches and textures are made
lazily on the first draw. The draw callback never raises; errors are kept for the sidebar and
printed once.
"""

from __future__ import annotations

import numpy as np
import bpy

from ...blender import compat
from ...blender.gpu import create_shader
from .. import mirror_state, scene_inputs
from . import glsl, gpu_capture, scene_env
from ...core import schema

DEPTH_BIAS = 2e-5
_CIRCLE_SEGMENTS = 64
RED, GREEN = (1.0, 0.15, 0.1, 1.0), (0.15, 1.0, 0.2, 1.0)
REGION_COLOUR, CORE_COLOUR = (1.0, 0.8, 0.1, 1.0), (1.0, 0.55, 0.0, 1.0)

_handle = None
_shader = None
_shader_error: str | None = None
_cache: dict = {}
_status: dict = {}
_last_error: str | None = None
_printed: set = set()


def status_of(obj) -> str | None:
    """The preview's message for a mirror (fallback in use, an error), or None."""
    return _status.get(getattr(obj, "name", None))


def last_error() -> str | None:
    """The last error of the draw callback (shader compilation included), or None."""
    return _shader_error or _last_error


def _report(key: str, text: str):
    if key not in _printed:
        _printed.add(key)
        print(f"Rokeby viewport preview: {text}")


# --- GPU resources (made on first draw) ----------------------------------------------------------


def shader():
    """The preview shader, compiled once from shaders/ through GPUShaderCreateInfo."""
    global _shader, _shader_error
    if _shader is None and _shader_error is None:
        try:
            _shader = create_shader(glsl.INTERFACE, glsl.INTERFACE_NAME, glsl.read_sources())
        except Exception as exc:  # noqa: BLE001 - a driver's compile error, a missing file
            _shader_error = f"shader: {type(exc).__name__}: {exc}"
            _report("shader", _shader_error)
    return _shader


class _MirrorGPU:
    def __init__(self):
        self.geometry_key = None
        self.batch = None
        self.plan_key = None
        self.plan = None
        self.vertex_tex = None
        self.ubo = None
        self.iso_key = None
        self.iso = None
        self.scene_serial = None
        self.scene_tex = None
        self.world_tex = None


def _float_texture(array: np.ndarray):
    import gpu  # noqa: PLC0415

    a = np.ascontiguousarray(array, dtype=np.float32)
    h, w, _ = a.shape
    return gpu.types.GPUTexture((w, h), format="RGBA32F", data=gpu.types.Buffer("FLOAT", a.size, a.ravel()))


_dummy = None


def _dummy_texture():
    global _dummy
    if _dummy is None:
        _dummy = _float_texture(np.zeros((1, 1, 4), np.float32))
    return _dummy


def environment_image(obj, scene):
    """The lat-long image the preview looks up: the mirror's captured reflection map in
    reflection-map mode, else the world's Environment Texture (equirectangular), else None."""
    s = obj.rokeby
    if getattr(s, "render_mode", "") == "REFLECTION_MAP" and getattr(s, "map_image", None) is not None:
        return s.map_image
    return scene_env.world_image(scene)


def _mirror_gpu(obj, st) -> _MirrorGPU:
    """Batch (per geometry version) and field texture (per field update) of one mirror."""
    from gpu_extras.batch import batch_for_shader  # noqa: PLC0415

    entry = _cache.setdefault(obj.session_uid, _MirrorGPU())
    geo = st.geometry
    key = (st.geometry_version, len(geo.vertices), len(geo.triangles))
    if entry.geometry_key != key:
        entry.batch = batch_for_shader(shader(), "TRIS", glsl.triangle_soup(geo.vertices, geo.normals, geo.triangles))
        entry.geometry_key = key
        entry.plan_key = None
        entry.iso_key = None
    pkey = (id(st.field_inputs), id(st.rotations), key)
    if entry.plan_key != pkey:
        rows, distances, regions = st.field_inputs
        entry.plan = glsl.plan_field(rows, regions, n_vertices=len(geo.vertices), distances=distances, rotations=st.rotations)
        entry.vertex_tex = _float_texture(entry.plan.vertex_data)
        entry.plan_key = pkey
    return entry


def scene_texture(obj, entry):
    """The GPU texture of ``obj``'s scene capture (remade when a new capture arrives), or None."""
    cap = scene_env.current(obj)
    if cap is None:
        entry.scene_tex, entry.scene_serial = None, None
        return None, None
    if entry.scene_serial != cap.serial:
        entry.scene_tex = _float_texture(cap.texels)
        entry.scene_serial = cap.serial
    return entry.scene_tex, cap


def draw_mirror(obj, scene, view_projection, eye, *, eye_is_direction=False, output=glsl.OUT_COLOR, srgb=False, parallax=True, use_scene=True) -> bool:
    """Draw one mirror with the preview shader into the bound framebuffer. ``view_projection``:
    world -> clip (4x4, row-major maths convention). Returns whether it drew.

    What e(q) is looked up in: the mirror's reflection map in reflection-map mode (what its
    renders show), else the scene captured from the mirror (``scene_env``; corrected for the
    surface point q with ``parallax``, else the centre-only lookup), else, until the first capture
    arrives, the world's lat-long image or the built-in sky."""
    import gpu  # noqa: PLC0415
    from mathutils import Matrix  # noqa: PLC0415

    st = mirror_state.state_of(obj)
    if st is None or st.geometry is None or st.field_inputs is None:
        _status[obj.name] = "preview: waiting for the first evaluation"
        return False
    sh = shader()
    if sh is None:
        _status[obj.name] = f"preview off: {_shader_error}"
        return False
    try:
        entry = _mirror_gpu(obj, st)
    except ValueError as exc:
        _status[obj.name] = f"preview: {exc}"
        return False
    if entry.plan.message:
        _status[obj.name] = "preview: " + entry.plan.message
    else:
        _status.pop(obj.name, None)
    if obj.rokeby.freeze:
        eye, eye_is_direction = tuple(obj.rokeby.freeze_eye), False
    map_mode = getattr(obj.rokeby, "render_mode", "") == "REFLECTION_MAP" and getattr(obj.rokeby, "map_image", None) is not None
    env, env_mode, origin, world, world_scale = None, glsl.ENV_SKY, None, None, None
    if use_scene and not map_mode:
        env, cap = scene_texture(obj, entry)
        if env is not None:
            env_mode, origin = glsl.ENV_SCENE, cap.origin
            image = bpy.data.images.get(cap.world_image) if cap.world_image else None
            if image is not None and cap.world_scale is not None:
                try:
                    world, world_scale = gpu.texture.from_image(image), cap.world_scale
                except Exception:  # noqa: BLE001 - the capture's own world texels serve
                    world = None
        else:
            scene_env.request()  # captured from the event loop, never from inside a draw
    if env is None:
        image = environment_image(obj, scene)
        if image is not None:
            try:
                env = gpu.texture.from_image(image)
                env_mode = glsl.ENV_IMAGE
            except Exception as exc:  # noqa: BLE001 - an image that cannot be loaded
                _status[obj.name] = f"preview: image '{image.name}' cannot be used ({exc}); showing the built-in sky"
    data = glsl.pack_field(entry.plan, eye, eye_is_direction=eye_is_direction, output=output, env=env_mode, env_origin=origin, parallax=parallax, srgb=srgb,
                           world_scale=world_scale)
    if entry.ubo is None:
        entry.ubo = gpu.types.GPUUniformBuf(data)
    else:
        entry.ubo.update(data)
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    sh.bind()
    sh.uniform_float("rk_view_projection", Matrix(np.asarray(view_projection, dtype=np.float64).tolist()))
    sh.uniform_float("rk_depth_bias", DEPTH_BIAS)
    sh.uniform_sampler("rk_vertex_data", entry.vertex_tex)
    sh.uniform_sampler("rk_env", env if env is not None else _dummy_texture())
    sh.uniform_sampler("rk_world", world if world is not None else _dummy_texture())
    sh.uniform_block("rk_field", entry.ubo)
    entry.batch.draw(sh)
    gpu.state.depth_mask_set(False)
    gpu.state.depth_test_set("NONE")
    return True


# --- overlays ------------------------------------------------------------------------------------


def iso_segments(vertices, triangles, values, level: float) -> np.ndarray:
    """Line segments (2S, 3) where the per-vertex ``values`` cross ``level`` (marching triangles,
    vectorised): the border of a geodesic or free-form region on the surface."""
    v = np.asarray(vertices, np.float32)
    t = np.asarray(triangles)
    a = np.asarray(values, np.float32)[t]
    above = a > level
    n_above = above.sum(1)
    mixed = (n_above == 1) | (n_above == 2)
    t, a, above = t[mixed], a[mixed], above[mixed]
    if len(t) == 0:
        return np.zeros((0, 3), np.float32)
    pts, crossing = [], []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        denom = a[:, j] - a[:, i]
        s = np.where(denom != 0, (level - a[:, i]) / np.where(denom != 0, denom, 1), 0.5)
        pts.append(v[t[:, i]] + s[:, None] * (v[t[:, j]] - v[t[:, i]]))
        crossing.append(above[:, i] != above[:, j])
    pts = np.stack(pts, 1)  # (M, 3 edges, 3)
    crossing = np.stack(crossing, 1)  # exactly two per mixed triangle
    order = np.argsort(~crossing, axis=1, kind="stable")[:, :2]
    seg = np.take_along_axis(pts, order[:, :, None], axis=1)
    return seg.reshape(-1, 3).astype(np.float32)


def circle(center, radius, right, up, segments=_CIRCLE_SEGMENTS) -> np.ndarray:
    """A circle facing the view as line segments (2N, 3)."""
    ang = np.linspace(0.0, 2 * np.pi, segments + 1)
    ring = np.asarray(center, np.float64) + radius * (np.cos(ang)[:, None] * np.asarray(right, np.float64) + np.sin(ang)[:, None] * np.asarray(up, np.float64))
    return np.stack([ring[:-1], ring[1:]], 1).reshape(-1, 3).astype(np.float32)


def overlay_geometry(obj, scene, view_right, view_up) -> dict:
    """What the overlays draw, as arrays: handle points and colours, constraint lines and
    colours, region border segments (outer and core)."""
    handles, handle_colours, lines, line_colours = [], [], [], []
    for c in obj.rokeby.constraints:
        if not c.enabled:
            continue
        red = c.surface_handle if scene_inputs.object_in_scene(c.surface_handle, scene) else None
        green = c.target_handle if scene_inputs.object_in_scene(c.target_handle, scene) else None
        ends = []
        for ob, colour in ((red, RED), (green, GREEN)):
            if ob is not None:
                p = tuple(ob.matrix_world.translation)
                handles.append(p)
                handle_colours.append(colour)
                ends.append((p, colour))
        if len(ends) == 2:
            for p, colour in ends:
                lines.append(p)
                line_colours.append(colour)
    outer, core = [], []
    st = mirror_state.state_of(obj)
    for rg in obj.rokeby.regions:
        if rg.enabled and rg.kind == "EUCLIDEAN" and scene_inputs.object_in_scene(rg.center, scene) and rg.radius > 0:
            centre = np.array(rg.center.matrix_world.translation)
            outer.append(circle(centre, rg.radius, view_right, view_up))
            inner = rg.radius - min(rg.border, rg.radius)
            if inner > 0:
                core.append(circle(centre, inner, view_right, view_up))
    if st is not None and st.geometry is not None and st.field_inputs is not None:
        entry = _cache.setdefault(obj.session_uid, _MirrorGPU())
        key = (id(st.field_inputs), st.geometry_version)
        if entry.iso_key != key:
            o, k = [], []
            for reg in st.field_inputs[2]:
                if reg.get("kind") == "weights":
                    o.append(iso_segments(st.geometry.vertices, st.geometry.triangles, reg["values"], 1e-3))
                    k.append(iso_segments(st.geometry.vertices, st.geometry.triangles, reg["values"], 1.0 - 1e-3))
            entry.iso, entry.iso_key = (o, k), key
        outer += entry.iso[0]
        core += entry.iso[1]
    stack = lambda parts: np.concatenate(parts).astype(np.float32) if parts else np.zeros((0, 3), np.float32)  # noqa: E731
    return {
        "handles": np.array(handles, np.float32).reshape(-1, 3),
        "handle_colours": np.array(handle_colours, np.float32).reshape(-1, 4),
        "lines": np.array(lines, np.float32).reshape(-1, 3),
        "line_colours": np.array(line_colours, np.float32).reshape(-1, 4),
        "region_outer": stack(outer),
        "region_core": stack(core),
    }


def draw_overlays(obj, scene, viewport_size, view_right, view_up):
    """Handles, constraint lines and region borders, with Blender's built-in shaders (their
    matrices are the gpu.matrix stack: the view's, in a draw handler)."""
    import gpu  # noqa: PLC0415
    from gpu_extras.batch import batch_for_shader  # noqa: PLC0415

    g = overlay_geometry(obj, scene, view_right, view_up)
    gpu.state.blend_set("ALPHA")
    gpu.state.depth_test_set("NONE")
    if len(g["lines"]):
        sh = compat.builtin_shader("POLYLINE_SMOOTH_COLOR")
        sh.bind()
        sh.uniform_float("viewportSize", viewport_size)
        sh.uniform_float("lineWidth", 2.0)
        batch_for_shader(sh, "LINES", {"pos": g["lines"], "color": g["line_colours"]}).draw(sh)
    sh = compat.builtin_shader("POLYLINE_UNIFORM_COLOR")
    for key, colour, width in (("region_outer", REGION_COLOUR, 2.0), ("region_core", CORE_COLOUR, 1.0)):
        if len(g[key]):
            sh.bind()
            sh.uniform_float("viewportSize", viewport_size)
            sh.uniform_float("lineWidth", width)
            sh.uniform_float("color", colour)
            batch_for_shader(sh, "LINES", {"pos": g[key]}).draw(sh)
    if len(g["handles"]):
        sh = compat.builtin_shader("POINT_FLAT_COLOR")  # FLAT_COLOR where missing (4.2)
        gpu.state.point_size_set(9.0)
        sh.bind()
        batch_for_shader(sh, "POINTS", {"pos": g["handles"], "color": g["handle_colours"]}).draw(sh)
        gpu.state.point_size_set(1.0)
    gpu.state.blend_set("NONE")


def steps_aside(scene, shading: str | None) -> bool:
    """Whether the mirrors' preview stays out of a view with ``shading`` (its shading type): in
    Rendered shading the renderer's own edited result is shown, unless the scene asks for the
    overlay there too (``Scene.rokeby_preview_rendered``). Handles and region borders stay."""
    return shading == "RENDERED" and not getattr(scene, schema.SCENE_PREVIEW_RENDERED_PROP, False)


def draw_scene(scene, view_projection, eye, *, eye_is_direction=False, viewport_size=(1, 1), view_right=(1, 0, 0), view_up=(0, 0, 1), overlays=True, shading=None,
               parallax=True) -> int:
    """Draw the preview of every mirror of ``scene`` that shows it; returns how many were drawn.
    ``shading``: the view's shading type (see ``steps_aside``)."""
    drawn = 0
    aside = steps_aside(scene, shading)
    for obj in scene_inputs.mirrors_of(scene):
        s = obj.rokeby
        if not (s.enabled and s.show_preview) or obj.type != "MESH" or not obj.visible_get():
            _status.pop(obj.name, None)
            continue
        if not aside and draw_mirror(obj, scene, view_projection, eye, eye_is_direction=eye_is_direction, parallax=parallax):
            drawn += 1
        if overlays:
            draw_overlays(obj, scene, viewport_size, view_right, view_up)
    return drawn


def _draw_callback():
    global _last_error
    try:
        context = bpy.context
        scene = context.scene
        if scene is None or not getattr(scene, schema.SCENE_VIEWPORT_PREVIEW_PROP, False):
            return
        from ...blender import prefs  # noqa: PLC0415

        if not prefs.get(context).gpu_viewport_preview:  # the machine's opt-out (add-on preferences)
            return
        if gpu_capture.CAPTURING[0]:  # the scene is being drawn from a mirror for its capture
            return
        rv3d, region = context.region_data, context.region
        if rv3d is None or region is None or context.scene is None:
            return
        view_inv = rv3d.view_matrix.inverted()
        if rv3d.is_perspective:
            eye, is_dir = tuple(view_inv.translation), False
        else:
            eye, is_dir = tuple(view_inv.col[2].xyz), True
        draw_scene(
            context.scene,
            np.array(rv3d.perspective_matrix),
            eye,
            eye_is_direction=is_dir,
            viewport_size=(region.width, region.height),
            view_right=tuple(view_inv.col[0].xyz),
            view_up=tuple(view_inv.col[1].xyz),
            shading=getattr(getattr(context.space_data, "shading", None), "type", None),
            parallax=prefs.get(context).preview_parallax,
        )
        scene_env.check_look(context.scene, context.space_data)
        _last_error = None
    except Exception as exc:  # noqa: BLE001 - a draw callback must never raise into Blender
        _last_error = f"{type(exc).__name__}: {exc}"
        _report(_last_error, _last_error)


def _redraw(self, context):
    wm = getattr(context, "window_manager", None)
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def register():
    global _handle
    # On the Scene, so the switch is saved with the .blend (a WindowManager property is not).
    bpy.types.Scene.rokeby_viewport_preview = bpy.props.BoolProperty(
        name="Viewport Preview",
        description="Draw edited reflections live in the 3D viewport (per-pixel field on the GPU, with handles and region borders; "
                    "the add-on's preferences can switch GPU previews off for this machine)",
        default=False,
        update=_redraw,
    )
    setattr(bpy.types.Scene, schema.SCENE_PREVIEW_RENDERED_PROP, bpy.props.BoolProperty(
        name="Preview in Rendered",
        description="Draw the reflection preview over Rendered shading too. Off: Rendered shading shows the renderer's "
                    "own edited reflections (Cycles, EEVEE) and only the handles are drawn over them",
        default=False,
        update=_redraw,
    ))
    scene_env.register()
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(_draw_callback, (), "WINDOW", "POST_VIEW")


def free():
    """Drop every GPU resource (they are remade on the next draw)."""
    global _shader, _shader_error, _dummy
    _cache.clear()
    _status.clear()
    _printed.clear()
    _shader = _shader_error = _dummy = None


def unregister():
    global _handle, _last_error
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    if hasattr(bpy.types.Scene, schema.SCENE_VIEWPORT_PREVIEW_PROP):
        del bpy.types.Scene.rokeby_viewport_preview
    if hasattr(bpy.types.Scene, schema.SCENE_PREVIEW_RENDERED_PROP):
        delattr(bpy.types.Scene, schema.SCENE_PREVIEW_RENDERED_PROP)
    scene_env.unregister()
    free()
    _last_error = None
