"""Run by tests/appearance/test_appearance.py in a fresh bpy process: what the appearance preview keeps
between redraws, texture targets at texel resolution, and the global sliders, drawn through
Blender's gpu module offscreen (a tiny EEVEE render makes the GPU context; llvmpipe here).
Prints RESULT {...}."""

import json

import numpy as np
import bpy

from support.bpy_process import gpu_context, offscreen_pixels
from rokeby import appearance, envmaps
from rokeby.appearance import preview as appearance_preview
from rokeby.appearance import attributes

W = H = 96
S = 1 / 1.1
# Orthographic view along +Y from y = −10: x → screen x, z → screen y, [−1.1, 1.1]².
VP = np.array([[S, 0, 0, 0], [0, 0, S, 0], [0, 0.01, 0, 0.0], [0, 0, 0, 1.0]])


def ball(segments, rings, name):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=1.0)
    bpy.ops.object.shade_smooth()
    ob = bpy.context.object
    ob.name = name
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    ob.data.materials.append(mat)
    appearance.setup(ob)
    return ob


def draw(ob, world, depsgraph=None):
    """The preview of ``ob`` (row 0 = bottom)."""
    return offscreen_pixels(lambda: appearance_preview.draw_object(ob, world, VP, (0.0, -1e4, 0.0), depsgraph), W, H)


def paint_all(ob, base, metallic, roughness):
    """Sets the per-point values exactly (a dab's Gaussian would leave them a little short)."""
    n = len(ob.data.vertices)
    attributes._write(ob, "diffuse", np.tile(np.append(np.asarray(base, np.float32), 1.0), (n, 1)))
    attributes._write(ob, "metallic", np.full(n, metallic, np.float32))
    attributes._write(ob, "roughness", np.full(n, roughness, np.float32))


def screen(p):
    """Pixel (column, row from the bottom) of a world point."""
    return int((p[0] * S + 1) / 2 * W), int((p[2] * S + 1) / 2 * H)


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    gpu_context(scene)
    world = appearance_preview.WorldLight(envmaps.read_exr(envmaps.studio_world("courtyard")), atlas_height=64)
    out = {}

    # 1. What is kept: the batch across redraws and strokes; the painted values re-uploaded per stroke.
    a = ball(64, 32, "cache")
    paint_all(a, (1.0, 1.0, 1.0), 1.0, 0.4)
    p0 = draw(a, world)
    p1 = draw(a, world)
    mp = appearance_preview.mesh_preview(a)
    out["redraw"] = {"builds": mp.builds, "uploads": mp.uploads, "identical": bool(np.array_equal(p0, p1))}
    appearance.paint(a, "roughness", [0.0, -1.0, 0.0], radius=0.2, value=0.0)
    p2 = draw(a, world)
    c, r = screen((0.0, -1.0, 0.0))
    top = (slice(int(0.8 * H), int(0.9 * H)), slice(int(0.45 * W), int(0.55 * W)))  # z ≈ 0.8: beyond the dab's reach
    out["stroke"] = {"builds": mp.builds, "uploads": mp.uploads, "changed_at_dab": float(np.abs(p2[r, c, :3] - p1[r, c, :3]).max()),
                     "changed_far": float(np.abs(p2[top][..., :3] - p1[top][..., :3]).max())}
    pos = np.empty(3 * len(a.data.vertices), np.float32)
    a.data.attributes["position"].data.foreach_get("vector", pos)
    a.data.attributes["position"].data.foreach_set("vector", pos * 0.5)  # sculpted smaller
    a.data.update()
    p3 = draw(a, world)
    out["moved"] = {"builds": mp.builds, "covered_before": float((p2[..., 3] > 0).mean()), "covered_after": float((p3[..., 3] > 0).mean())}
    bpy.data.objects.remove(a)

    # 2. A texture target filled with the per-point values draws what the per-point target draws
    #    (the images are half floats on the GPU).
    b = ball(64, 32, "same")
    paint_all(b, (0.9, 0.3, 0.2), 0.3, 0.35)
    pt = draw(b, world)
    appearance.setup(b, target="TEXTURE", resolution=256)
    tx = draw(b, world)
    inside = (pt[..., 3] > 0) & (tx[..., 3] > 0)
    out["texture_vs_point"] = float(np.abs(tx[inside, :3] - pt[inside, :3]).max() / np.abs(pt[inside, :3]).max())
    out["texture_builds"] = appearance_preview.mesh_preview(b).builds  # UVs added: rebuilt once
    bpy.data.objects.remove(b)

    # 3. A dab far smaller than a face shows at texel resolution: a red dot of about its size, which
    #    the values at the vertices (what per-point targets and the former preview drew) do not show.
    d = ball(24, 12, "dot")
    paint_all(d, (1.0, 1.0, 1.0), 0.0, 0.5)
    appearance.setup(d, target="TEXTURE", resolution=1024)
    t = np.radians(7.5)  # the middle of a face next to the equator, facing the camera
    centre = np.array([np.sin(t) * np.cos(t), -np.cos(t) * np.cos(t), np.sin(t)])
    radius = 0.06
    before = draw(d, world)
    appearance.paint(d, "diffuse", [centre], radius=radius, value=(1.0, 0.0, 0.0))
    px = draw(d, world)
    inside = (px[..., 3] > 0) & (before[..., 3] > 0)
    green = np.where(inside, px[..., 1] / np.maximum(before[..., 1], 1e-6), 1.0)  # 1 where unchanged, ~0 where red
    c, r = screen(centre)
    at_vertices = appearance.point_values(d, "diffuse")
    out["dot"] = {"green_at_centre": float(green[r - 1:r + 2, c - 1:c + 2].min()), "red_pixels": int((green < 0.5).sum()),
                  "disk_pixels": float(np.pi * (radius * S * W / 2) ** 2), "changed_pixels": int((np.abs(green - 1) > 1e-3).sum()),
                  "vertex_green": float(at_vertices[:, 1].min())}
    bpy.data.objects.remove(d)

    # 4. The global sliders, as the material's rokeby_global_* nodes apply them.
    e = ball(64, 32, "globals")
    paint_all(e, (1.0, 1.0, 1.0), 0.0, 0.8)
    mat = e.active_material
    appearance.set_global(mat, "roughness", 0.25)
    appearance.set_global(mat, "diffuse", (0.5, 0.25, 1.0))
    g = draw(e, world)
    appearance.set_global(mat, "roughness", 1.0)
    appearance.set_global(mat, "diffuse", (1.0, 1.0, 1.0))
    paint_all(e, (0.5, 0.25, 1.0), 0.0, 0.2)
    h = draw(e, world)
    paint_all(e, (0.5, 0.25, 1.0), 0.0, 0.5)
    appearance.set_global(mat, "roughness", 4.0)  # 0.5 × 4 = 2, clamped to 1 like the node
    k4 = draw(e, world)
    paint_all(e, (0.5, 0.25, 1.0), 0.0, 1.0)
    appearance.set_global(mat, "roughness", 1.0)
    k1 = draw(e, world)
    inside = g[..., 3] > 0
    rel = lambda x, y: float(np.abs(x[inside, :3] - y[inside, :3]).max() / np.abs(y[inside, :3]).max())  # noqa: E731
    out["globals"] = {"slider_vs_painted": rel(g, h), "slider_effect": rel(g, k1), "clamped": rel(k4, k1)}
    bpy.data.objects.remove(e)

    # 5. The viewport handler's draw (draw_view) with a 3D view's matrices: the eye and the
    #    view-projection it takes from the view (the same up to a depth offset and an eye 10 further
    #    away), only painted meshes drawn.
    from types import SimpleNamespace

    from mathutils import Matrix

    f = ball(64, 32, "view")
    paint_all(f, (0.2, 0.6, 0.9), 0.5, 0.3)
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0.0, -2.0, 0.0))  # not painted: not drawn, would cover the ball
    envmaps.use_studio_world(scene, "courtyard")
    view = Matrix(((1, 0, 0, 0), (0, 0, 1, 0), (0, -1, 0, -10), (0, 0, 0, 1)))  # from y = −10 along +Y, z up
    proj = Matrix(((S, 0, 0, 0), (0, S, 0, 0), (0, 0, -0.01, 0), (0, 0, 0, 1)))  # orthographic, nearer = smaller depth
    rv3d = SimpleNamespace(view_matrix=view, perspective_matrix=proj @ view, is_perspective=False)
    world_v = appearance_preview.world_light(scene)
    import gpu

    drawn = []
    pv = offscreen_pixels(lambda: drawn.append(appearance_preview.draw_view(scene, rv3d, list(scene.objects))), W, H)
    drawn = drawn[0]
    direct = draw(f, world_v)
    # 7. With the depsgraph (as the viewport handler draws): the mesh its modifiers make. A coarse
    #    ball with a Subdivision Surface modifier draws as that mesh applied (a copy made with
    #    new_from_object, drawn without modifiers), not as its cage, and a dab painted on the cage
    #    comes through the modifier.
    bpy.data.objects.remove(f)
    coarse = ball(8, 4, "subdivided")
    paint_all(coarse, (0.9, 0.9, 0.9), 0.0, 0.5)
    sub = coarse.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = 2
    bpy.context.view_layer.update()
    cage = draw(coarse, world_v)
    dg = bpy.context.evaluated_depsgraph_get()

    smooth = draw(coarse, world_v, dg)
    appearance.paint(coarse, "diffuse", [0.0, -1.0, 0.0], radius=0.8, value=(1.0, 0.0, 0.0))
    bpy.context.view_layer.update()
    dg = bpy.context.evaluated_depsgraph_get()
    red = draw(coarse, world_v, dg)
    applied = bpy.data.objects.new("applied", bpy.data.meshes.new_from_object(coarse.evaluated_get(dg)))
    scene.collection.objects.link(applied)
    same_as_applied = float(np.abs(draw(applied, world_v) - red).max())
    c, r = screen((0.0, -1.0, 0.0))
    out["modifiers"] = {"cage_covered": float((cage[..., 3] > 0).mean()), "evaluated_covered": float((smooth[..., 3] > 0).mean()),
                        "green_ratio_at_dab": float(red[r, c, 1] / max(smooth[r, c, 1], 1e-6)),
                        "vs_applied": same_as_applied,
                        "evaluated_vertices": len(coarse.evaluated_get(dg).data.vertices), "cage_vertices": len(coarse.data.vertices)}

    # 6. The brush cursor: the circle drawn with Blender's polyline shader through the view's matrices.
    from rokeby.appearance import ui as appearance_ui

    def cursor():
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_matrix(view)
            gpu.matrix.load_projection_matrix(proj)
            appearance_ui.draw_cursor(appearance_ui.brush_circle((0.0, -1.0, 0.0), (0.0, -1.0, 0.0), 0.5), (W, H))

    pc = offscreen_pixels(cursor, W, H)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    rad = np.hypot(xs - W / 2, ys - H / 2) / (W / 2) / S  # world units from the circle's centre
    lit = pc[..., 3] > 0.1
    out["cursor"] = {"lit": int(lit.sum()), "radius_min": float(rad[lit].min()), "radius_max": float(rad[lit].max())}
    out["view"] = {"drawn": drawn, "eye": list(appearance_preview.view_eye(rv3d)), "vs_draw_object": float(np.abs(pv - direct).max())}
    print("RESULT " + json.dumps(out))


main()
