"""Run by tests/workflows/test_compat.py in a fresh bpy process: the built-in shader that ``rokeby.blender.compat``
picks for round points draws here. Makes Blender's GPU context with one tiny render by the engine
id compat picks (bpy_process.gpu_context), draws one fat point into an offscreen buffer and prints
one JSON line: RESULT {...}."""

import json

import bpy

from support.bpy_process import gpu_context, offscreen_pixels
from rokeby.blender import compat


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    gpu_context(scene)  # renders with compat.eevee_engine()
    import gpu
    from gpu_extras.batch import batch_for_shader
    from mathutils import Matrix

    try:
        gpu.shader.from_builtin("POINT_FLAT_COLOR")
        have_points = True
    except ValueError:
        have_points = False

    def draw():
        sh = compat.builtin_shader("POINT_FLAT_COLOR")
        gpu.state.point_size_set(5.0)
        sh.bind()
        batch_for_shader(sh, "POINTS", {"pos": [(0.0, 0.0, 0.0)], "color": [(0.2, 0.9, 0.4, 1.0)]}).draw(sh)
        gpu.state.point_size_set(1.0)

    with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
        gpu.matrix.load_identity()
        gpu.matrix.load_projection_matrix(Matrix.Identity(4))
        px = offscreen_pixels(draw, 16, 16)
    lit = px[..., 3] > 0.5
    print("RESULT " + json.dumps({
        "engine": scene.render.engine,
        "picked": compat.builtin_shader_name("POINT_FLAT_COLOR"),
        "has_point_flat_color": have_points,
        "lit": int(lit.sum()),
        "colour": px[lit][:, :3].mean(0).tolist() if lit.any() else None,
    }))


main()
