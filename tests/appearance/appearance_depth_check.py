"""Run by tests/appearance/test_appearance_depth.py in a fresh bpy process: the appearance preview
drawn over the surfaces the 3D view has already drawn (Solid shading: the same meshes in grey, their
depth sampled with a sub-pixel jitter, as the viewport's anti-aliasing samples it), through
Blender's gpu module, offscreen. Counts the ball's pixels where the grey shows through the preview
(the speckle), and the pixels of a grey cube in front of the ball that stay grey (the preview must
not draw over it). Prints RESULT {...}."""

import json
from types import SimpleNamespace

import numpy as np
import bpy
from mathutils import Matrix, Vector

from support.bpy_process import gpu_context, offscreen_pixels
from rokeby import appearance, envmaps
from rokeby.appearance import preview as appearance_preview

W = H = 160
GREY = (0.25, 0.25, 0.25, 1.0)
JITTERS = ((0.0, 0.0), (0.5, 0.0), (0.0, -0.5), (0.35, 0.35), (-0.5, 0.5))


def _triangles(ob):
    me = ob.data
    me.calc_loop_triangles()
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    tri = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", tri)
    m = np.array(ob.matrix_world, np.float32)
    world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return world[tri].astype(np.float32)


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    appearance.setup(ball)
    appearance.paint(ball, "diffuse", [0, 0, 0], radius=10.0, value=(1.0, 1.0, 1.0))
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(0.0, -1.25, 0.0))  # just in front of the ball, not painted
    cube = bpy.context.object
    gpu_context(scene)

    import gpu
    from gpu_extras.batch import batch_for_shader

    world = appearance_preview.WorldLight(envmaps.read_exr(envmaps.studio_world("courtyard")), atlas_height=32)
    # A perspective view from y = −6 along +Y, the viewport's default clip range 0.01–1000.
    view = Matrix(((1, 0, 0, 0), (0, 0, 1, 0), (0, -1, 0, -6), (0, 0, 0, 1)))
    n, f, s = 0.01, 1000.0, 2.5
    proj = Matrix(((s, 0, 0, 0), (0, s, 0, 0), (0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)), (0, 0, -1, 0)))
    rv3d = SimpleNamespace(view_matrix=view, window_matrix=proj, perspective_matrix=proj @ view, is_perspective=True)
    eye = appearance_preview.view_eye(rv3d)
    vp = np.array(rv3d.perspective_matrix)
    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    solid = [batch_for_shader(shader, "TRIS", {"pos": _triangles(o).reshape(-1, 3)}) for o in (ball, cube)]
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    u, v = xs / W * 2 - 1, ys / H * 2 - 1
    inside = (u * u + v * v) < (0.9 * s / np.sqrt(35.0)) ** 2  # well inside the ball's disk
    half = s * 0.2 / (6.0 - 1.45)  # the cube's front face on screen (NDC half-size)
    cube_px = (np.abs(u) < 0.8 * half) & (np.abs(v) < 0.8 * half)
    near_cube = (np.abs(u) < 1.3 * half) & (np.abs(v) < 1.3 * half)
    out = {"renderer": gpu.platform.renderer_get(), "ball_pixels": int((inside & ~near_cube).sum()), "cube_pixels": int(cube_px.sum()),
           "jitters": {}}
    for jx, jy in JITTERS:
        jitter = Matrix.Translation(Vector((2 * jx / W, 2 * jy / H, 0.0)))

        def draw():
            gpu.state.depth_test_set("LESS_EQUAL")
            gpu.state.depth_mask_set(True)
            with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
                gpu.matrix.load_projection_matrix(jitter @ proj)
                gpu.matrix.load_matrix(view)
                shader.bind()
                shader.uniform_float("color", GREY)
                for b in solid:
                    b.draw(shader)
            appearance_preview.draw_object(ball, world, vp, eye)

        px = offscreen_pixels(draw, W, H)
        grey = np.all(np.abs(px[..., :3] - np.array(GREY[:3])) < 1e-3, axis=-1)
        out["jitters"][f"{jx},{jy}"] = {"speckle": int((grey & inside & ~near_cube).sum()), "cube_grey": int((grey & cube_px).sum())}
    print("RESULT " + json.dumps(out))


main()
