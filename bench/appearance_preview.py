"""The appearance preview, end to end in a fresh bpy process (gpu context from a tiny EEVEE render; llvmpipe
here, no GPU lent): (1) "a brush stroke updates the preview within a frame": one dab through
rokeby.appearance.paint, then the preview drawn offscreen (the kept batch, the painted values
uploaded, shader, read-back of the pixels, which waits for the GPU), per-point and 1024² texture
targets; (2) the Blender-drawn
preview of each model against a Cycles render of the same sphere under courtyard.exr.

    python bench/appearance_preview.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "addon"))

import bpy  # noqa: E402

from rokeby import appearance, envmaps  # noqa: E402
from rokeby.appearance import glsl as appearance_glsl, preview as appearance_preview  # noqa: E402

W = H = 96
SCALE = 1.1


def _scene(segments, rings):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=1.0)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    mat = bpy.data.materials.new("Paint")
    mat.use_nodes = True
    ball.data.materials.append(mat)
    appearance.setup(ball)
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    return sc, ball, cam


def _gpu_context(sc):
    sc.render.engine = "BLENDER_EEVEE_NEXT"
    sc.render.resolution_x = sc.render.resolution_y = 8
    bpy.ops.render.render()


# Orthographic view along +Y from y = −10: x → screen x, z → screen y, [−1.1, 1.1]².
VP = np.array([[1 / SCALE, 0, 0, 0], [0, 0, 1 / SCALE, 0], [0, 0.01, 0, 0.0], [0, 0, 0, 1.0]])


def _draw(ball, world, off=None):
    """The preview of ``ball`` as (H, W, 4), row 0 at the top: into ``off`` (kept between frames,
    as a viewport's framebuffer is) or a new offscreen buffer."""
    import gpu

    own = off is None
    if own:
        off = gpu.types.GPUOffScreen(W, H, format="RGBA32F")
    with off.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        appearance_preview.draw_object(ball, world, VP, (0.0, -1e4, 0.0))
        px = np.array(fb.read_color(0, 0, W, H, 4, 0, "FLOAT").to_list(), np.float32).reshape(H, W, 4)
    if own:
        off.free()
    return px[::-1]  # row 0 = top


def stroke_to_preview(world_px, strokes: int = 7):
    """Per mesh size and target: a dab; the preview's own work for it (material state, batch
    check, painted values compared and uploaded); the draw and read-back (wall and process CPU
    time, which llvmpipe's threads add to); a redraw with nothing changed (the rasteriser's share:
    the kept batch drawn again); medians."""
    import gpu

    rows = []
    for seg, rings in ((128, 64), (448, 224)):
        for target in ("POINT", "TEXTURE"):
            sc, ball, _cam = _scene(seg, rings)
            if target == "TEXTURE":
                appearance.setup(ball, target="TEXTURE", resolution=1024)
            _gpu_context(sc)
            world = appearance_preview.WorldLight(world_px, atlas_height=64)
            off = gpu.types.GPUOffScreen(W, H, format="RGBA32F")
            _draw(ball, world, off)  # compile the shader, upload the textures, build the batch
            mp = appearance_preview.mesh_preview(ball)
            builds = mp.builds
            paint_t, prep_t, draw_t, cpu_t, redraw_t = [], [], [], [], []
            for k in range(strokes):
                t0 = time.perf_counter()
                appearance.paint(ball, "roughness", [(0.3 * np.cos(k), -0.9, 0.3 * np.sin(k))], 0.2, value=0.1 + 0.1 * k)
                t1 = time.perf_counter()
                # what draw_object does before it draws: the material's state, the batch check, the
                # painted values compared and uploaded (done here, so the draw below finds them current)
                appearance_preview.prepare(ball)
                t2 = time.perf_counter()
                c2 = time.process_time()
                _draw(ball, world, off)
                t3 = time.perf_counter()
                c3 = time.process_time()
                _draw(ball, world, off)
                t4 = time.perf_counter()
                paint_t.append(t1 - t0)
                prep_t.append(t2 - t1)
                draw_t.append(t3 - t2)
                cpu_t.append(c3 - c2)
                redraw_t.append(t4 - t3)
            off.free()
            med = lambda x: 1e3 * float(np.median(x))  # noqa: E731
            rows.append({"vertices": len(ball.data.vertices), "target": target, "paint_ms": med(paint_t), "prep_ms": med(prep_t),
                         "draw_ms": med(draw_t), "draw_cpu_ms": med(cpu_t), "redraw_ms": med(redraw_t),
                         "total_ms": med(np.add(np.add(paint_t, prep_t), draw_t)), "uploads": mp.uploads,
                         "batch_rebuilds": mp.builds - builds})
    return rows


def _luminance(x):
    return x[..., 0] * 0.2126 + x[..., 1] * 0.7152 + x[..., 2] * 0.0722


def against_cycles(world_name):
    path = envmaps.studio_world(world_name)
    world_px = envmaps.read_exr(path)
    sc, ball, cam = _scene(192, 96)
    w = bpy.data.worlds.new("HDR")
    w.use_nodes = True
    env = w.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(path))
    w.node_tree.links.new(env.outputs["Color"], w.node_tree.nodes["Background"].inputs["Color"])
    sc.world = w
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 2 * SCALE
    cam.location = (0.0, -10.0, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    x, z = (xs / W * 2 - 1) * SCALE, (1 - ys / H * 2) * SCALE
    nz = np.sqrt(np.maximum(1 - x * x - z * z, 0))
    mask = nz > 0.5  # n·v > 0.5
    rows = []
    cases = [("white metal", (1.0, 1.0, 1.0), 1.0, 0.3), ("red plastic", (0.8, 0.1, 0.05), 0.0, 0.3), ("red plastic", (0.8, 0.1, 0.05), 0.0, 0.6)]
    for name, base, metal, rough in cases:
        appearance.paint(ball, "diffuse", [0, 0, 0], radius=10.0, value=base)
        appearance.paint(ball, "metallic", [0, 0, 0], radius=10.0, value=metal)
        appearance.paint(ball, "roughness", [0, 0, 0], radius=10.0, value=rough)
        appearance.paint(ball, "specular", [0, 0, 0], radius=10.0, value=0.5)
        sc.render.engine = "CYCLES"
        sc.cycles.samples = 128
        sc.cycles.use_denoising = False
        sc.render.resolution_x, sc.render.resolution_y = W, H
        sc.render.film_transparent = True
        sc.view_settings.view_transform = "Standard"
        sc.render.image_settings.file_format = "OPEN_EXR"
        out = Path(os.environ.get("TMPDIR", "/tmp")) / "rokeby_preview_cycles.exr"
        sc.render.filepath = str(out)
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(str(out))
        ref = np.array(img.pixels[:], np.float32).reshape(H, W, 4)[::-1, :, :3]
        bpy.data.images.remove(img)
        for model in appearance_glsl.MODELS:
            px = _draw(ball, appearance_preview.WorldLight(world_px, atlas_height=64, model=model))[..., :3]
            a, b = _luminance(px[mask]), _luminance(ref[mask])
            rows.append({"world": world_name, "case": name, "roughness": rough, "model": model,
                         "mean_error": float(np.mean(np.abs(a - b)) / np.mean(b)), "ratio": float(np.mean(a) / np.mean(b))})
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", required=True)
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    world_px = envmaps.read_exr(envmaps.studio_world("courtyard"))
    strokes = stroke_to_preview(world_px)
    sc, _ball, _cam = _scene(16, 8)
    _gpu_context(sc)
    import gpu

    renderer = gpu.platform.renderer_get()
    cycles = against_cycles("courtyard")
    Path(args.json).write_text(json.dumps({"strokes": strokes, "cycles": cycles, "renderer": renderer, "cpus": os.cpu_count(),
                                           "load_average": [load0, os.getloadavg()[0]]}))


if __name__ == "__main__":
    main()
