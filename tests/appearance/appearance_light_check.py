"""Run by tests/appearance/test_appearance_light.py in a fresh bpy process: Fraser's two preview views as
Blender compiles and draws them (gpu module, the viewport handler's draw_view), offscreen. A
painted black plastic ball (radius 0.5, red specular colour) under the courtyard world and, beside
it, a copy under the point light. Prints RESULT {...}."""

import json
from types import SimpleNamespace

import numpy as np
import bpy
from mathutils import Matrix

from support.bpy_process import gpu_context, offscreen_pixels
from rokeby import appearance, envmaps
from rokeby.appearance import glsl as appearance_glsl, preview as appearance_preview
from rokeby.appearance import attributes

W, H = 128, 64
# Orthographic from y = −10 along +Y, z up; screen x ∈ [−1, 3], z ∈ [−1, 1].
VIEW = Matrix(((1, 0, 0, 0), (0, 0, 1, 0), (0, -1, 0, -10), (0, 0, 0, 1)))
PROJ = Matrix(((0.5, 0, 0, -0.5), (0, 1, 0, 0), (0, 0, -0.01, 0), (0, 0, 0, 1)))
RV3D = SimpleNamespace(view_matrix=VIEW, perspective_matrix=PROJ @ VIEW, is_perspective=False)


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    gpu_context(scene)
    envmaps.use_studio_world(scene, "courtyard")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=0.5)
    bpy.ops.object.shade_smooth()
    ob = bpy.context.object
    mat = bpy.data.materials.new("Plastic")
    mat.use_nodes = True
    ob.data.materials.append(mat)
    appearance.setup(ob)
    n = len(ob.data.vertices)
    attributes._write(ob, "diffuse", np.tile(np.float32([0.02, 0.02, 0.02, 1.0]), (n, 1)))
    attributes._write(ob, "specular", np.full(n, 1.0, np.float32))
    attributes._write(ob, "roughness", np.full(n, 0.25, np.float32))
    attributes._write(ob, "metallic", np.zeros(n, np.float32))

    def view(light, pos=(2.0, -3.0, 0.0)):
        return offscreen_pixels(lambda: appearance_preview.draw_view(scene, RV3D, [ob], "PRINCIPLED", None, light, pos, 20.0), W, H)

    env = view("ENVIRONMENT")
    beside = view("BESIDE")
    off = appearance_preview.beside_offset(ob, RV3D)
    left, right = slice(0, W // 2), slice(W // 2, W)
    out = {"offset": [float(x) for x in off],
           "env_covered_left": float((env[:, left, 3] > 0).mean()), "env_covered_right": float((env[:, right, 3] > 0).mean()),
           "beside_covered_right": float((beside[:, right, 3] > 0).mean()),
           "left_same": float(np.abs(beside[:, left] - env[:, left]).max())}

    def centroid(img):
        lum = img[:, right, :3].sum(-1)
        w = np.where(lum >= 0.5 * lum.max(), lum, 0.0)
        ys, xs = np.mgrid[0:H, 0:W // 2]
        return float((w * xs).sum() / w.sum()), float((w * ys).sum() / w.sum())

    out["highlight_light_right"] = centroid(beside)
    out["highlight_light_left"] = centroid(view("BESIDE", (-2.0, -3.0, 0.0)))
    out["highlight_light_up"] = centroid(view("BESIDE", (0.0, -3.0, 2.0)))
    # the point-lit copy against its numpy twin at the disk's pixels (normals of the analytic sphere)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    x, z = xs / W * 4 - 1, ys / H * 2 - 1
    c = off[0]
    inside = (x - c) ** 2 + z**2 < 0.8 * 0.25
    nn = np.stack([(x - c) / 0.5, -np.sqrt(np.maximum(1 - ((x - c) ** 2 + z**2) / 0.25, 0)), z / 0.5], -1)[inside]
    pts = nn * 0.5 + off
    want = appearance_glsl.shade_point_reference(nn, np.array([0.0, -1.0, 0.0]), pts, np.array([2.0, -3.0, 0.0]) + off, 20.0,
                                                 np.full(3, 0.02), 1.0, 0.25, 0.0)
    out["point_rel"] = float(np.abs(beside[inside][:, :3] - want).mean() / np.abs(want).mean())
    # the specular colour painted red: the point-lit highlight turns red
    attributes._write(ob, "specular_tint", np.tile(np.float32([1.0, 0.0, 0.0, 1.0]), (n, 1)))
    red = view("BESIDE")
    lum = red[:, right, :3].sum(-1)
    top = red[:, right, :3][lum >= 0.5 * lum.max()].mean(axis=0)
    white = beside[:, right, :3][beside[:, right, :3].sum(-1) >= 0.5 * beside[:, right, :3].sum(-1).max()].mean(axis=0)
    out["highlight_white"] = [float(v) for v in white]
    out["highlight_red"] = [float(v) for v in top]

    # The same on a texture target, painted with the brush: the preview reads the painted image
    # (the per-point attribute stays white), in both views.
    attributes._write(ob, "specular_tint", np.ones((n, 4), np.float32))
    appearance.setup(ob, target="TEXTURE", resolution=64)

    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    centre_disc = (xs / W * 4 - 1) ** 2 + (ys / H * 2 - 1) ** 2 < 0.25 ** 2  # n·v > 0.87 on the left ball

    def green_share(img, half):
        """G / R of the environment-lit ball's middle (off-grazing: Fresnel's white edge left out),
        or of the point-lit copy's highlight."""
        if half is left:
            px = img[centre_disc][:, :3]
        else:
            px = img[:, half, :3]
            px = px[px.sum(-1) >= 0.5 * px.sum(-1).max()]
        m = px.mean(axis=0)
        return float(m[1] / m[0])

    env0, beside0 = view("ENVIRONMENT"), view("BESIDE")
    for _ in range(3):  # dabs over the whole ball: the tint goes most of the way to red everywhere
        appearance.paint(ob, "specular_tint", [[0.0, -0.5, 0.0]], radius=2.0, value=(1.0, 0.0, 0.0))
    env1, beside1 = view("ENVIRONMENT"), view("BESIDE")
    out["texture"] = {"attribute_green_min": float(appearance.read(ob, "specular_tint")[:, 1].min()),
                      "image_green_max": float(appearance.point_values(ob, "specular_tint")[:, 1].max()),
                      "env_green_share": [green_share(env0, left), green_share(env1, left)],
                      "point_green_share": [green_share(beside0, right), green_share(beside1, right)]}
    print("RESULT " + json.dumps(out))


main()
