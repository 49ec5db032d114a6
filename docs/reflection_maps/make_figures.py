"""Pictures and timings of docs/reflection_maps.md: ray tracing against reflection maps.

    .venv/bin/python docs/reflection_maps/make_figures.py [--quick]

Renders tiny Cycles images on the CPU (and one EEVEE image), writes the PNGs next to this file
and prints the timing table. --quick skips the 2048-wide capture.
"""

import os
import sys
import time
from pathlib import Path

import bpy
import numpy as np

import rokeby
from rokeby import api, envmaps
from rokeby.reflection import mirror_state
from rokeby.reflection.render import reflmap

OUT = Path(__file__).resolve().parent
SIZE = 128
SAMPLES = 16


def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    mirror_state.reset()
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = SAMPLES
    sc.cycles.use_denoising = False
    sc.cycles.seed = 1
    sc.render.resolution_x = sc.render.resolution_y = SIZE
    sc.render.resolution_percentage = 100
    envmaps.use_studio_world(sc, "forest")
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    return sc, cam


def chrome(name, roughness=0.0):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = roughness
    return mat


def emissive_checker(location, size):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    floor = bpy.context.object
    mat = bpy.data.materials.new("Checker light")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    emit, checker = nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 6.0
    mat.node_tree.links.new(checker.outputs["Color"], emit.inputs["Color"])
    mat.node_tree.links.new(emit.outputs[0], nodes["Material Output"].inputs["Surface"])
    floor.data.materials.append(mat)
    return floor


def red_cube(location, size):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    cube = bpy.context.object
    mat = bpy.data.materials.new("Red")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.8, 0.05, 0.03, 1.0)
    cube.data.materials.append(mat)
    return cube


def render(name=None):
    sc = bpy.context.scene
    path = str(OUT / f"_tmp_{name}.png")
    sc.render.filepath = path
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    dt = time.perf_counter() - t
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)
    bpy.data.images.remove(img)
    os.remove(path)
    return px, dt


def save(name, tiles):
    row = np.concatenate(tiles, axis=1)
    img = bpy.data.images.new(name, row.shape[1], row.shape[0])
    img.pixels.foreach_set(np.ascontiguousarray(row, dtype=np.float32).ravel())
    img.filepath_raw = str(OUT / f"{name}.png")
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)


def diff_tile(a, b, gain=3.0):
    d = np.clip(np.abs(a[..., :3] - b[..., :3]).max(-1) * gain, 0, 1)
    out = np.ones_like(a)
    out[..., 0] = out[..., 1] = out[..., 2] = d
    return out


def both(mirror):
    """(ray traced, reflection map) renders of the current scene, with their times."""
    mirror.rokeby.render_mode = "RAY_TRACED"
    api.install_render_nodes(mirror)
    traced, t_rt = render("rt")
    mirror.rokeby.render_mode = "REFLECTION_MAP"
    api.install_render_nodes(mirror)
    mapped, t_map = render("map")
    return traced, t_rt, mapped, t_map


def main(quick=False):
    rows = []
    # 1. A chrome ball on an emissive checker floor, with the edit of tests/reflection/test_render.py:
    #    the same edit in both modes; the floor shows the parallax.
    sc, cam = scene()
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    ball.name = "Ball"
    ball.data.materials.append(chrome("Chrome"))
    emissive_checker((0.0, 0.0, -1.05), 8.0)
    red_cube((1.7, -1.2, 0.0), 0.7)
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=(0.0, -4.0, 0.0))
    ball.rokeby.constraints[0].target_handle.location.z += 3.0
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.6, border=0.2)
    api.evaluate()
    t = time.perf_counter()
    api.capture_reflection_map(ball, resolution=512, samples=SAMPLES)
    t_cap = time.perf_counter() - t
    traced, t_rt, mapped, t_map = both(ball)
    save("ball_edit", [traced, mapped])
    save("ball_edit_diff", [diff_tile(traced, mapped)])
    rows.append(("chrome ball + edit, floor and cube nearby", t_rt, t_map, t_cap))
    # 2. A chrome torus: it reflects itself (ray traced) and the map cannot (captured with the
    #    torus hidden, from its centre, which is in the hole).
    sc, cam = scene()
    cam.location = (0.0, -4.5, 1.8)
    cam.rotation_euler = (np.radians(68), 0.0, 0.0)
    bpy.ops.mesh.primitive_torus_add(major_radius=1.0, minor_radius=0.4, major_segments=64, minor_segments=24)
    bpy.ops.object.shade_smooth()
    torus = bpy.context.object
    torus.name = "Torus"
    torus.rotation_euler = (np.radians(20), 0.0, 0.0)
    torus.data.materials.append(chrome("Torus chrome"))
    emissive_checker((0.0, 0.0, -0.75), 8.0)
    # In the hole, next to the capture point (the torus's centre): the map sees it from there,
    # huge; the ray tracer sees it from the inner surface. (A capture point inside an object
    # gives a black map: then set rokeby.map_origin.)
    red_cube((0.0, 0.3, 0.05), 0.3)
    api.add_mirror(torus)
    api.capture_reflection_map(torus, resolution=512, samples=SAMPLES)
    traced, t_rt, mapped, t_map = both(torus)
    save("torus_self_reflection", [traced, mapped])
    rows.append(("chrome torus (self-reflection, object in the hole)", t_rt, t_map, None))
    # 3. Rough metal: the ray tracer is noisy at 16 samples, the blurred map level is not.
    sc, cam = scene()
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    rough = bpy.context.object
    rough.name = "Rough"
    rough.data.materials.append(chrome("Brushed", roughness=0.35))
    api.add_mirror(rough)
    api.capture_reflection_map(rough, resolution=512, samples=SAMPLES)
    traced, t_rt, mapped, t_map = both(rough)
    sc.cycles.samples = 256
    rough.rokeby.render_mode = "RAY_TRACED"
    api.install_render_nodes(rough)
    reference, t_ref = render("ref")
    sc.cycles.samples = SAMPLES
    save("rough", [traced, mapped])
    disc = np.hypot(*np.mgrid[-1:1:SIZE * 1j, -1:1:SIZE * 1j]) < 0.6
    err_rt = np.abs(traced - reference)[..., :3].mean(-1)[disc].mean()
    err_map = np.abs(mapped - reference)[..., :3].mean(-1)[disc].mean()
    rows.append(("rough metal (roughness 0.35)", t_rt, t_map, None))
    # EEVEE, one tiny render of the map material.
    sc.render.engine = "BLENDER_EEVEE_NEXT"
    sc.eevee.taa_render_samples = 4
    rough.rokeby.render_mode = "REFLECTION_MAP"
    api.install_render_nodes(rough)
    eevee, t_eevee = render("eevee")
    save("rough_eevee", [eevee])
    sc.render.engine = "CYCLES"
    # Capture times by resolution (the rough ball's scene: forest HDR only).
    caps = []
    for width in (256, 512, 1024) + (() if quick else (2048,)):
        t = time.perf_counter()
        api.capture_reflection_map(rough, resolution=width, samples=SAMPLES)
        caps.append((width, time.perf_counter() - t, rough.rokeby.map_capture_seconds))
    print(f"\n{SIZE}×{SIZE} px, {SAMPLES} samples, Cycles CPU ({os.cpu_count()} cores)")
    print("| scene | ray traced (s) | reflection map (s) | capture 512×256 (s) |")
    for name, a, b, c in rows:
        print(f"| {name} | {a:.1f} | {b:.1f} | {'' if c is None else f'{c:.1f}'} |")
    print(f"rough: mean |error| on the ball against 256 samples ray traced ({t_ref:.1f} s): ray traced {SAMPLES} spp {err_rt:.4f}, map {err_map:.4f}")
    print(f"EEVEE (llvmpipe, 4 samples) map render: {t_eevee:.1f} s")
    print("| width | capture total (s) | of which the render (s) |")
    for w, total, render_s in caps:
        print(f"| {w} × {w // 2} | {total:.1f} | {render_s:.1f} |")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
