"""A shadow edit in a real window: Edit Shadow Boundaries, then a press on a shadow handle with the
mouse, a drag and a release (the add-on's 3D View shortcut), Ctrl+Z and Ctrl+Shift+Z with X key
events; then Ctrl+Z while the mouse button is held (it cancels that drag only)."""

import importlib

import bpy
import numpy as np
import scenes

ADDON = "bl_ext.user_default.rokeby"


def _shadow_ui():
    return importlib.import_module(ADDON + ".shadow.ui")


def _shadow():
    return importlib.import_module(ADDON + ".shadow")


def state():
    sc = bpy.context.scene
    sess = _shadow_ui().session(sc)
    ball = bpy.data.objects.get("Ball")
    mesh = _shadow().shadow_mesh_of(ball) if ball is not None else None
    return {
        "objects": sorted(o.name for o in bpy.data.objects),
        "session": sess is not None,
        "drags": None if sess is None else len(sess.drags),
        "handles": None if sess is None else sess.handles(0)["points"].tolist(),
        "shadow_mesh": mesh is not None,
    }


def scenario(ui):
    yield from ui.start()
    _ball, _ground, lamp = scenes.ball_over_ground(ui)
    area = ui.area()
    scenes.look_down(ui)
    yield from ui.redraws(2)
    with ui.override():
        bpy.context.view_layer.objects.active = bpy.data.objects["Ball"]
        # 'EXEC_DEFAULT', True: the undo step a click on the button pushes (Python calls push none by default)
        ui.result["start"] = sorted(bpy.ops.rokeby.shadow_start("EXEC_DEFAULT", True, light=lamp.name, min_loop_vertices=10))
    yield from ui.redraws(3)
    ui.result["started"] = state()
    ui.screenshot("started")

    sess = _shadow_ui().session(bpy.context.scene)
    h = np.array(sess.handles(0)["points"], np.float64)
    m = int(np.argmax(h[:, 0]))
    c = h.mean(axis=0)
    x0, y0 = ui.point_xy(h[m])
    ui.result["press_at"] = [x0, y0]
    # 1. Press on the handle, drag outward, release: one drag, the shadow mesh made.
    yield from ui.drag([(x0, y0)] + [ui.point_xy(c + (h[m] - c) * f) for f in (1.1, 1.2, 1.3)])
    ui.result["shortcut_dragged"] = state()["drags"] == 1
    if not ui.result["shortcut_dragged"]:
        # No shortcut (an add-on without one): the drag started as F3 starts it, the mouse on the handle.
        yield from ui.move(x0, y0)
        yield from ui.redraws(1)
        with ui.override():
            ui.result["invoked"] = sorted(bpy.ops.rokeby.shadow_drag("INVOKE_DEFAULT"))
        for f in (1.1, 1.2, 1.3):
            yield from ui.move(*ui.point_xy(c + (h[m] - c) * f))
            yield from ui.redraws(1)
        yield from ui.press()
        yield from ui.release()
        yield from ui.redraws(2)
    ui.result["dragged"] = state()
    ui.screenshot("dragged")
    # 2. Ctrl+Z: that drag only.
    yield from ui.move(400, 400)
    yield from ui.key("ctrl+z")
    yield from ui.redraws(3)
    ui.result["undone"] = state()
    ui.screenshot("undone")
    # 3. Ctrl+Shift+Z: the drag again.
    yield from ui.key("ctrl+shift+z")
    yield from ui.redraws(3)
    ui.result["redone"] = state()
    # 4. A second drag with Ctrl+Z while the button is held: cancelled, nothing else undone.
    h = np.array(_shadow_ui().session(bpy.context.scene).handles(0)["points"], np.float64)
    yield from ui.move(*ui.point_xy(h[m]))
    yield from ui.redraws(1)
    yield from ui.press()
    yield from ui.move(*ui.point_xy(c + (h[m] - c) * 1.25))
    yield from ui.redraws(1)
    yield from ui.key("ctrl+z")
    yield from ui.redraws(1)
    yield from ui.release()
    yield from ui.redraws(2)
    ui.result["mid_drag_undo"] = state()
    ui.screenshot("mid-drag-undo")
    # 5. The sidebar's Drag Shadow Boundary button: run from the sidebar with the mouse on it (as its
    # click runs it), then a press on the handle in the view, a drag and a release.
    area.spaces.active.show_region_ui = True
    yield from ui.redraws(2)
    side = ui.region("UI", area)
    bx, by = ui.screen_xy(side, side.width / 2, side.height / 2)
    yield from ui.move(bx, by)
    yield from ui.redraws(1)
    with ui.override(area, "UI"):
        ui.result["button"] = sorted(bpy.ops.rokeby.shadow_drag("INVOKE_DEFAULT"))
    yield from ui.redraws(1)
    h = np.array(_shadow_ui().session(bpy.context.scene).handles(0)["points"], np.float64)
    k = int(np.argmin(h[:, 1]))  # the handle nearest the viewer's bottom edge, clear of the sidebar
    yield from ui.move(*ui.point_xy(h[k]))
    yield from ui.redraws(1)
    yield from ui.press()
    for f in (1.1, 1.2):
        yield from ui.move(*ui.point_xy(c + (h[k] - c) * f))
        yield from ui.redraws(1)
    yield from ui.release()
    yield from ui.redraws(2)
    ui.result["button_dragged"] = state()
    ui.screenshot("button-dragged")
