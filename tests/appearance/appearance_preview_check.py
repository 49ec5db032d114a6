"""Run by tests/appearance/test_appearance.py in a fresh bpy process: the appearance preview as Blender
compiles and draws it (gpu module, GPUShaderCreateInfo), offscreen, against its numpy twin.
A tiny EEVEE render creates the GPU context in background mode. Prints RESULT {...}."""

import json

import numpy as np
import bpy

from support.bpy_process import gpu_context, offscreen_pixels
from rokeby import appearance, envmaps
from rokeby.appearance import glsl as appearance_glsl, preview as appearance_preview

W = H = 64


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=192, ring_count=96, radius=1.0)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    appearance.setup(ball)
    appearance.paint(ball, "metallic", [0, 0, 0], radius=10.0, value=1.0)
    appearance.paint(ball, "diffuse", [0, 0, 0], radius=10.0, value=(1.0, 1.0, 1.0))
    appearance.paint(ball, "roughness", [0, 0, 0], radius=10.0, value=0.4)
    gpu_context(scene)

    import gpu

    world = appearance_preview.WorldLight(envmaps.read_exr(envmaps.studio_world("courtyard")), atlas_height=64)
    # Orthographic view along +Y from y = −10: x → screen x, z → screen y, [−1.1, 1.1]².
    s = 1 / 1.1
    vp = np.array([[s, 0, 0, 0], [0, 0, s, 0], [0, 0.01, 0, 0.0], [0, 0, 0, 1.0]])  # nearer (−y) = smaller depth
    px = offscreen_pixels(lambda: appearance_preview.draw_object(ball, world, vp, (0.0, -1e4, 0.0)), W, H)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    x, z = (xs / W * 2 - 1) * 1.1, (ys / H * 2 - 1) * 1.1  # read_color row 0 = bottom
    inside = x * x + z * z < 0.8
    n = np.stack([x, -np.sqrt(np.maximum(1 - x * x - z * z, 0)), z], -1)[inside]
    want = appearance_glsl.shade_reference(world.atlas, len(world.levels), world.sh, n, np.array([0.0, -1.0, 0.0]), np.ones(3), 0.5, 0.4, 1.0)
    got = px[inside][:, :3]
    rel = float(np.abs(got - want).mean() / np.abs(want).mean())
    # Control: the same twin with the world turned half a turn about z (the atlas rolled by W/2).
    turned = np.roll(world.atlas, world.atlas.shape[1] // 2, axis=1)
    wrong = appearance_glsl.shade_reference(turned, len(world.levels), world.sh, n, np.array([0.0, -1.0, 0.0]), np.ones(3), 0.5, 0.4, 1.0)
    rel_wrong = float(np.abs(got - wrong).mean() / np.abs(wrong).mean())
    print("RESULT " + json.dumps({"renderer": gpu.platform.renderer_get(), "rel": rel, "rel_turned": rel_wrong, "covered": float((px[..., 3] > 0).mean()), "pixels": int(inside.sum())}))


main()
