"""Run by tests/reflection/test_scene_preview.py in a fresh bpy process: the viewport preview of a
mirror in a scene (tests/support/scene_preview.py), drawn offscreen through Blender's gpu module
with the shaders of shaders/ and looking up the scene captured from the mirror, against a Cycles
render of the same camera, on the mirror's pixels.

Arguments: an output folder (the images are saved there as .npy: render, preview corrected,
preview centre-only, mirror mask), "edited" to add a constraint whose green handle sits on the
magenta cube, "world=NAME" for another of Blender's bundled studio-light worlds. Prints one JSON line: RESULT {...}."""

import json
import os
import time
import sys

import numpy as np
import bpy  # noqa: F401 - loads Blender (and Cycles, for _cycles below)

from support import scene_preview as S

OUT = sys.argv[1]
EDITED = "edited" in sys.argv[2:]
W = H = 96
SS = 4  # the preview is drawn at SS x SS pixels per render pixel and averaged: the pixel's footprint, as Cycles integrates it
CAPTURE_WIDTH, CAPTURE_SAMPLES = 256, 32
# Both Cycles images are denoised (OpenImageDenoise) where this Blender has it: the comparison is of
# what each shows, not of two noise patterns.
import _cycles  # noqa: E402 - Cycles is loaded with bpy

DENOISE = bool(getattr(_cycles, "with_openimagedenoise", False))


def main():
    world = next((a[6:] for a in sys.argv[2:] if a.startswith("world=")), S.WORLD)
    sc, mirror, objects = S.build(size=W, samples=64, world_name=world)
    sc.cycles.use_denoising = DENOISE
    res_denoise = DENOISE
    from rokeby import api
    from rokeby.reflection.viewport import draw, glsl, scene_env

    res = {"edited": EDITED, "denoised": res_denoise, "world": world}
    red = None
    if EDITED:
        cube = objects["Magenta"]
        # the green handle on the top of the cube (on the floor in front of the ball), the red
        # handle on the ball's lower left, the edit confined to a region around it
        green = np.array(cube.location) + np.array([0.0, 0.0, 0.25])
        red = np.array([-0.45, -0.8, -0.35])
        red /= np.linalg.norm(red)
        api.add_constraint(mirror, tuple(red), tuple(green))
        api.add_region(mirror, "EUCLIDEAN", center=tuple(red), radius=0.7, border=0.4)
    report = api.evaluate(force=True)[mirror.name]
    res["status"] = report.status
    res["summary"] = report.summary()
    if EDITED:
        red = np.array(mirror.rokeby.constraints[0].surface_handle.matrix_world.translation)
        res["red"] = red.tolist()

    t0 = time.perf_counter()
    reference = S.render(sc, os.path.join(OUT, "render.exr"))
    res["render_seconds"] = time.perf_counter() - t0
    cap = scene_env.capture(mirror, sc, width=CAPTURE_WIDTH, samples=CAPTURE_SAMPLES, denoise=DENOISE)
    res["capture_seconds"] = cap.seconds
    res["capture_bytes"] = cap.nbytes
    res["world_scale"] = cap.world_scale
    res["captures"] = scene_env.stats["captures"]

    from support.bpy_process import gpu_context

    try:
        gpu_context(sc)
        import gpu

        off = gpu.types.GPUOffScreen(W * SS, H * SS, format="RGBA32F")
    except Exception as exc:  # noqa: BLE001 - a Blender without a GPU context in background mode
        print("RESULT " + json.dumps({"skip": f"no GPU context in background mode after an EEVEE render: {type(exc).__name__}: {exc}"}))
        return
    res["renderer"] = gpu.platform.renderer_get()
    vp = S.camera_view_projection(sc, W * SS, H * SS)
    eye = tuple(sc.camera.matrix_world.translation)
    images = {}
    with off.bind():
        fb = gpu.state.active_framebuffer_get()
        for key, kwargs in (("corrected", {"parallax": True}), ("centre", {"parallax": False}),
                            ("position", {"output": glsl.OUT_POSITION})):
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            drew = draw.draw_mirror(mirror, sc, vp, eye, **kwargs)
            assert drew, draw.status_of(mirror) or draw.last_error()
            px = np.array(fb.read_color(0, 0, W * SS, H * SS, 4, 0, "FLOAT").to_list(), np.float32).reshape(H, SS, W, SS, 4)
            if key == "position":
                images[key] = px[:, SS // 2, :, SS // 2]
            else:
                cover = px[..., 3].mean((1, 3))
                rgb = px[..., :3].sum((1, 3)) / np.maximum(px[..., 3].sum((1, 3)), 1e-6)[..., None]
                images[key] = np.concatenate([rgb, (cover > 0.999)[..., None].astype(np.float32)], -1)
        # Rendered shading: the preview steps aside (only overlays), unless asked for there.
        sc.rokeby_viewport_preview = True
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        res["drawn_rendered"] = draw.draw_scene(sc, vp, eye, shading="RENDERED", overlays=False)
        res["drawn_material"] = draw.draw_scene(sc, vp, eye, shading="MATERIAL", overlays=False)
        setattr(sc, "rokeby_preview_rendered", True)
        res["drawn_rendered_opt_in"] = draw.draw_scene(sc, vp, eye, shading="RENDERED", overlays=False)
    off.free()
    res["captures_after_draws"] = scene_env.stats["captures"]

    mask = images["corrected"][..., 3] > 0
    inner = mask.copy()  # whole mirror pixels away from the outline (Cycles' pixel filter reaches 1 px out)
    for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        inner &= np.roll(mask, (dy, dx), (0, 1))
    res["mirror_pixels"] = int(inner.sum())
    for key in ("corrected", "centre"):
        diff = np.abs(images[key][..., :3] - reference).mean(-1)[inner]
        res[key] = {"mean": float(diff.mean()), "p95": float(np.percentile(diff, 95))}
    if EDITED:
        pos = images["position"]
        d = np.linalg.norm(pos[..., :3] - red, axis=-1)
        d[~mask] = np.inf
        y, x = np.unravel_index(np.argmin(d), d.shape)
        res["red_pixel"] = [int(y), int(x), float(d[y, x])]
        # the 3 x 3 pixels around the red handle
        patch = lambda im: im[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2, :3].reshape(-1, 3).mean(0).tolist()  # noqa: E731
        res["at_red"] = {"corrected": patch(images["corrected"]), "centre": patch(images["centre"]), "render": patch(reference)}
        res["magenta"] = list(S.OBJECTS[0][4])
    for key in ("corrected", "centre"):
        np.save(os.path.join(OUT, f"{key}.npy"), images[key][..., :3])
    np.save(os.path.join(OUT, "render.npy"), reference)
    np.save(os.path.join(OUT, "mask.npy"), inner)
    print("RESULT " + json.dumps(res))


main()
