"""Run by tests/reflection/test_glsl.py in a fresh bpy process: the viewport preview as Blender compiles and
draws it (gpu module, GPUShaderCreateInfo from the same shaders/ files), offscreen.

bpy as a module has no GPU context in background mode until a GPU engine has rendered once; a
tiny EEVEE render creates it (on Mesa llvmpipe here). Prints one JSON line: RESULT {...}."""

import json

import numpy as np
import bpy

import rokeby
from rokeby import api
from rokeby.reflection import mirror_state
from rokeby.reflection.viewport import glsl, draw as viewport

W, H = 96, 72


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=1.0)
    mirror = bpy.context.object
    bpy.ops.object.shade_smooth()
    api.add_mirror(mirror)
    eye = np.array([0.4, -4.0, 0.8])
    api.add_constraint(mirror, (0.0, -1.0, 0.1), (1.5, -3.0, 2.0), eye=tuple(eye))
    api.add_constraint(mirror, (0.6, -0.7, -0.3), (-2.0, -2.0, 0.0), eye=tuple(eye))
    api.add_constraint(mirror, (-0.5, -0.8, 0.3), (0.0, -3.0, -2.0), eye=tuple(eye))
    api.add_region(mirror, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=1.2, border=0.5)
    report = api.evaluate(force=True)[mirror.name]
    assert report.status != "ERROR", report.summary()  # no camera or material here: warned, evaluated

    # A shadow-editing session (#7) beside the mirror, for its overlay: a small closed caster, a
    # ground plane and a light above them.
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=0.35, location=(1.6, 0.0, 0.3))
    caster = bpy.context.object
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(1.0, 0.0, -1.2))
    ground = bpy.context.object
    lamp = bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", "POINT"))
    scene.collection.objects.link(lamp)
    lamp.location = (1.6, 0.1, 3.0)
    bpy.context.view_layer.update()
    from rokeby.shadow import ui as shadow_ui

    shadow_ui._SESSIONS[shadow_ui._key(scene)] = api.start_shadow_edit(caster, lamp, [ground], min_loop_vertices=8)
    shadow_ui._refresh(scene, eye=tuple(eye))
    shadow_lines = len(shadow_ui._OVERLAY[shadow_ui._key(scene)]["lines"])

    # Create Blender's GPU context: one tiny EEVEE render.
    from support.bpy_process import gpu_context

    gpu_context(scene)

    import gpu
    from mathutils import Matrix

    from support.gl_harness import look_at, perspective

    vp = perspective(40, W / H, 0.1, 100.0) @ look_at(eye, (0, 0, 0))
    off = gpu.types.GPUOffScreen(W, H, format="RGBA32F")
    out = {}
    with off.bind():
        fb = gpu.state.active_framebuffer_get()
        for name, mode in (("direction", glsl.OUT_DIRECTION), ("position", glsl.OUT_POSITION), ("normal", glsl.OUT_NORMAL)):
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            drew = viewport.draw_mirror(mirror, scene, vp, tuple(eye), output=mode)
            assert drew, viewport.status_of(mirror) or viewport.last_error()
            px = np.array(fb.read_color(0, 0, W, H, 4, 0, "FLOAT").to_list(), np.float32).reshape(H, W, 4)
            out[name] = px
        # The whole draw with overlays, as the handler runs it (built-in shaders read gpu.matrix).
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_identity()
            gpu.matrix.load_projection_matrix(Matrix(vp.tolist()))
            drawn = viewport.draw_scene(scene, vp, tuple(eye), viewport_size=(W, H), view_right=(1, 0, 0), view_up=(0, 0, 1))
        colour = np.array(fb.read_color(0, 0, W, H, 4, 0, "FLOAT").to_list(), np.float32).reshape(H, W, 4)
        # The shadow overlay's own draw callback, as its POST_VIEW handler runs it.
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_identity()
            gpu.matrix.load_projection_matrix(Matrix(vp.tolist()))
            shadow_ui._draw()
        shadow_px = np.array(fb.read_color(0, 0, W, H, 4, 0, "FLOAT").to_list(), np.float32).reshape(H, W, 4)
    off.free()
    orange = (shadow_px[..., 3] > 0) & (np.abs(shadow_px[..., :3] - np.array(shadow_ui.ACTIVE[:3])).max(-1) < 0.05)
    mask = out["direction"][..., 3] > 0
    import rokeby_native as rn

    st = mirror_state.state_of(mirror)
    rows, distances, regions = st.field_inputs
    want = rn.reflection.edited_directions(out["position"][mask][:, :3], out["normal"][mask][:, :3], eye.astype(np.float32), rows, regions=regions)
    got = out["direction"][mask][:, :3].astype(np.float64)
    err = np.arctan2(np.linalg.norm(np.cross(got, want), axis=1), np.sum(got * want, axis=1))
    plain = rn.reflection.edited_directions(out["position"][mask][:, :3], out["normal"][mask][:, :3], eye.astype(np.float32), rows[:0])
    edit = np.arctan2(np.linalg.norm(np.cross(got, plain), axis=1), np.sum(got * plain, axis=1))
    overlay = colour[..., 3] > 0
    print("RESULT " + json.dumps({
        "renderer": gpu.platform.renderer_get(),
        "covered": int(mask.sum()),
        "mean_err": float(err.mean()),
        "max_err": float(err.max()),
        "edited_fraction": float((edit > 1e-3).mean()),
        "drawn": drawn,
        "drawn_pixels": int(overlay.sum()),
        "shadow_lines": shadow_lines,
        "shadow_overlay_pixels": int(orange.sum()),
        "error": viewport.last_error(),
        "status": viewport.status_of(mirror),
    }))
    rokeby.unregister()


main()
