"""The appearance brush (Paint Appearance) in a real window: Ctrl+Z pressed before its first stroke,
a stroke with the mouse, Ctrl+Z after it and once more, and a click on the sidebar's tabs while the
brush runs (X input events throughout)."""

import importlib

import bpy
import numpy as np

ADDON = "bl_ext.user_default.rokeby"


def roughness():
    app = importlib.import_module(ADDON + ".appearance")
    ob = bpy.data.objects.get("Ball")
    if ob is None or app.PARAMS["roughness"][0] not in ob.data.attributes:
        return None
    return app.read(ob, "roughness").tolist()


def scenario(ui):
    yield from ui.start()
    area = ui.area()
    area.spaces.active.show_region_ui = True
    yield from ui.redraws(2)
    side = ui.region("UI", area)
    ui.result["tab_before"] = side.active_panel_category
    with ui.override():
        for ob in list(bpy.data.objects):
            if ob.type == "MESH":
                bpy.data.objects.remove(ob)
        bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0)
        bpy.context.object.name = "Ball"
        bpy.ops.ed.undo_push(message="scene set up")
        ui.result["setup"] = sorted(bpy.ops.rokeby.appearance_setup("EXEC_DEFAULT", True))
        s = bpy.context.scene.rokeby_appearance_brush
        s.brush, s.radius, s.strength, s.value = "roughness", 0.4, 1.0, 0.95
    rv3d = ui.region("WINDOW", area).data
    rv3d.view_perspective = "PERSP"
    rv3d.view_rotation = (0.7071068, 0.7071068, 0.0, 0.0)  # from the front (−Y)
    rv3d.view_location = (0.0, 0.0, 0.0)
    rv3d.view_distance = 6.0
    yield from ui.redraws(2)
    set_up = roughness()
    ui.result["set_up"] = set_up is not None
    x, y = ui.point_xy((0.0, -1.0, 0.0))
    yield from ui.move(x, y)
    yield from ui.redraws(1)
    with ui.override():
        ui.result["brush"] = sorted(bpy.ops.rokeby.appearance_paint("INVOKE_DEFAULT"))
    yield from ui.redraws(1)
    # 1. Ctrl+Z before any stroke of this brush.
    yield from ui.key("ctrl+z")
    yield from ui.redraws(2)
    ui.result["undo_before_stroke_kept_setup"] = roughness() is not None
    # 2. A stroke across the front of the ball.
    yield from ui.move(x, y)
    yield from ui.redraws(1)
    yield from ui.press()
    for dx in (10, 20, 30, 40):
        yield from ui.move(x + dx, y)
        yield from ui.redraws(1)
    yield from ui.release()
    yield from ui.redraws(2)
    stroked = roughness()
    ui.result["stroke_changed"] = int(np.sum(np.abs(np.array(stroked) - np.array(set_up)) > 1e-3)) if stroked and set_up else None
    ui.screenshot("stroked")
    # 3. Ctrl+Z: the stroke only; 4. once more: refused (Set Up Appearance Painting stays).
    yield from ui.key("ctrl+z")
    yield from ui.redraws(2)
    r = roughness()
    ui.result["undo_stroke_back_to_setup"] = r is not None and np.allclose(r, set_up)
    yield from ui.key("ctrl+z")
    yield from ui.redraws(2)
    ui.result["second_undo_kept_setup"] = roughness() is not None
    # 5. A click on the sidebar's tabs while the brush runs goes to the tabs.
    try:
        yield from ui.show_sidebar_tab("Rokeby", area)
        ui.result["tab_clicked"] = side.active_panel_category
    except RuntimeError as exc:
        ui.result["tab_clicked"] = f"not clicked: {exc}"
    ui.screenshot("sidebar-while-brushing")
    yield from ui.move(x, y)
    yield from ui.key("Escape")
    yield from ui.redraws(2)
