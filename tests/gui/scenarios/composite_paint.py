"""Compositing-stage editing in a real window (Debian's Blender, which loads its own OpenEXR
library): Set Up Compositing Passes and Render and Recomposite (the operators the sidebar buttons
run, each one undo step), the recomposited frame opened in an Image Editor, Paint Normals found
with F3 there, a press-drag-release stroke across the frame, Esc ending the brush, Ctrl+Z undoing
the stroke."""

import os

import bpy
import numpy as np

import scenes


def image_pixels(img):
    px = np.empty(img.size[0] * img.size[1] * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(img.size[1], img.size[0], 4)


def scenario(ui):
    yield from ui.start()
    schema = ui.addon("core.schema")
    sc = bpy.context.scene
    sphere = scenes.smooth_sphere(ui)
    mat = bpy.data.materials.new("Glossy")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.3
    sphere.data.materials.append(mat)
    cam = sc.camera
    cam.location = (0.0, -5.0, 0.0)
    cam.rotation_euler = (1.5708, 0.0, 0.0)
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 8
    sc.cycles.use_denoising = False  # Debian's Blender is built without OpenImageDenoise: any F12 with it fails
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 160, 120, 100
    with ui.override():
        bpy.ops.ed.undo_push(message="scene set up")
    r = ui.result
    exr = os.path.join(ui.out, "frame.exr")
    with ui.override():
        r["setup"] = sorted(bpy.ops.rokeby.composite_setup_passes("EXEC_DEFAULT", True))
        r["render"] = sorted(bpy.ops.rokeby.composite_render("EXEC_DEFAULT", True, filepath=exr))
    yield from ui.redraws(2)
    img = bpy.data.images.get(schema.RECOMPOSITED_IMAGE)
    r["exr_written"] = os.path.isfile(exr)
    r["image"] = None if img is None else list(img.size)
    if img is None:
        return
    before = image_pixels(img).copy()
    r["image_finite"] = bool(np.isfinite(before).all())
    # The 3D view becomes an Image Editor showing the recomposited frame (as a user switches an area).
    area = ui.area()
    area.type = "IMAGE_EDITOR"
    yield from ui.redraws(2)
    space = area.spaces.active
    space.image = img
    with ui.override(area):
        bpy.ops.image.view_all(fit_view=True)
    yield from ui.redraws(2)
    region = ui.region("WINDOW", area)
    ui.screenshot("recomposited", crop=ui.region_box(region))

    def screen_of(col, row):
        rx, ry = region.view2d.view_to_region(col / img.size[0], row / img.size[1], clip=False)
        return ui.screen_xy(region, rx, ry)

    row = img.size[1] // 2
    x1, y1 = screen_of(40, row)
    x2, y2 = screen_of(120, row)
    # F3 in the Image Editor, "Paint Normals", Return: the brush runs.
    yield from ui.move(x1, y1 - 30)
    yield from ui.redraws(1)
    yield from ui.search("Paint Normals")
    r["brush_running"] = any(op.bl_idname == "ROKEBY_OT_composite_brush" for op in ui.window.modal_operators)
    yield from ui.drag([(x1 + (x2 - x1) * i / 6, y1 + (y2 - y1) * i / 6) for i in range(7)])
    ui.screenshot("stroke", crop=ui.region_box(region))
    yield from ui.key("Escape")
    yield from ui.redraws(2)
    r["brush_ended"] = not any(op.bl_idname == "ROKEBY_OT_composite_brush" for op in ui.window.modal_operators)
    img = bpy.data.images[schema.RECOMPOSITED_IMAGE]
    after = image_pixels(img)
    changed = np.abs(after - before)[..., :3].max(axis=2) > 1e-5
    rows, cols = np.nonzero(changed)
    r["changed"] = int(changed.sum())
    r["changed_rows"] = [int(rows.min()), int(rows.max())] if len(rows) else None
    r["changed_cols"] = [int(cols.min()), int(cols.max())] if len(cols) else None
    r["stroke_row"] = row
    r["after_finite"] = bool(np.isfinite(after).all())
    yield from ui.move(x1, y1 - 40)
    yield from ui.key("ctrl+z")
    yield from ui.redraws(3)
    img = bpy.data.images[schema.RECOMPOSITED_IMAGE]
    r["undo_max_diff"] = float(np.abs(image_pixels(img) - before).max())
