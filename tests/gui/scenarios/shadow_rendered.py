"""A shadow edit seen in Rendered shading in a real window: after a press-drag-release on a shadow
handle, the shadow mesh (a copy of the ball that only shadow rays see) must not draw its wire cage
over the ball in Rendered or Material Preview shading, while Solid shading keeps showing it as a
wire. Screenshots of the Rendered view with overlays on and off are compared over the ball."""

import importlib

import bpy
import numpy as np
import scenes

ADDON = "bl_ext.user_default.rokeby"


def scenario(ui):
    yield from ui.start()
    ball, _ground, lamp = scenes.ball_over_ground(ui)
    scenes.look_down(ui)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.preview_samples = 4
    sc.cycles.use_preview_denoising = False
    yield from ui.redraws(2)
    with ui.override():
        bpy.context.view_layer.objects.active = ball
        bpy.ops.rokeby.shadow_start("EXEC_DEFAULT", True, light=lamp.name, min_loop_vertices=10)
    yield from ui.redraws(2)
    shadow_ui = importlib.import_module(ADDON + ".shadow.ui")
    shadow = importlib.import_module(ADDON + ".shadow")
    h = np.array(shadow_ui.session(sc).handles(0)["points"], np.float64)
    m = int(np.argmax(h[:, 0]))
    c = h.mean(axis=0)
    yield from ui.drag([ui.point_xy(c + (h[m] - c) * f) for f in (1.0, 1.1, 1.25, 1.4)])
    mesh = shadow.shadow_mesh_of(ball)
    r = ui.result
    r["shadow_mesh"] = mesh is not None
    if mesh is None:
        return
    space = ui.area().spaces.active
    r["display_solid"] = mesh.display_type
    ui.screenshot("solid", crop=ui.region_box(ui.region("WINDOW")))
    # Nothing selected (an outline is not the cage), the session ended: only the render and overlays.
    with ui.override():
        bpy.ops.rokeby.shadow_stop()
        bpy.ops.object.select_all(action="DESELECT")
    space.shading.type = "RENDERED"
    yield from ui.redraws(2)
    yield 3.0  # Cycles' few viewport samples
    yield from ui.redraws(2)
    r["display_rendered"] = mesh.display_type
    region = ui.region("WINDOW")
    on = ui.screenshot("rendered", crop=ui.region_box(region))
    space.overlay.show_overlays = False
    yield from ui.redraws(2)
    yield 1.0
    yield from ui.redraws(1)
    off = ui.screenshot("rendered-no-overlays", crop=ui.region_box(region))
    space.overlay.show_overlays = True
    a, b = ui.pixels(on)[..., :3], ui.pixels(off)[..., :3]
    # The ball's disc on screen (its centre and a point on its rim, seen from above).
    box = ui.region_box(region)
    cx, cy = ui.point_xy(ball.matrix_world.translation)
    ex, ey = ui.point_xy(ball.matrix_world.translation + ball.matrix_world.col[0].xyz * 0.45)
    rad = float(np.hypot(ex - cx, ey - cy))
    yy, xx = np.mgrid[0:a.shape[0], 0:a.shape[1]]
    disc = (xx + box[0] - cx) ** 2 + (yy + box[1] - cy) ** 2 < rad ** 2
    diff = np.abs(a - b).max(axis=2)[disc]
    r["ball_pixels"] = int(disc.sum())
    r["ball_pixels_changed_by_overlays"] = int((diff > 0.1).sum())
    space.shading.type = "MATERIAL"
    yield from ui.redraws(2)
    r["display_material"] = mesh.display_type
    space.shading.type = "SOLID"
    yield from ui.redraws(2)
    r["display_solid_again"] = mesh.display_type
