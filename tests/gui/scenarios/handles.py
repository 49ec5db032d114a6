"""Handles moved with the mouse in a real window: the green and the red handle each grabbed with G,
moved by X pointer motion and confirmed with a click (the field updates, the status stays OK); a G
drag cancelled with Esc (nothing moves); Ctrl+Z after a confirmed drag (the handle goes back);
Shift+Alt+C and a click on the mirror (a constraint added where the click landed)."""

import bpy
from mathutils import Vector

import scenes

OUT = {}


def vec(v):
    return [round(float(x), 5) for x in v]


def scenario(ui):
    yield from ui.start()
    api = ui.addon("api")
    mirror_state = ui.addon("reflection.mirror_state")
    scene = bpy.context.scene
    sphere = scenes.smooth_sphere(ui)
    sphere.name = "Mirror"
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.05
    sphere.data.materials.append(mat)
    mirror = api.add_mirror(sphere)
    api.add_constraint(mirror, (0.66, -0.62, 0.44))  # the green handle on the physical reflection
    api.evaluate(scene, force=True)
    c = sphere.rokeby.constraints[0]
    green, red = c.target_handle, c.surface_handle
    gname, rname = green.name, red.name  # undo replaces the objects: look them up by name after it
    with ui.override():
        # The factory view (the sphere and both handles in sight); the set-up is one undo step.
        bpy.ops.ed.undo_push(message="scene set up")
    yield from ui.redraws(2)
    ui.screenshot("handles-start", crop=ui.region_box(ui.region("WINDOW")))
    r = ui.result

    # Green handle: G, move, click.
    g0 = green.location.copy()
    yield from scenes.grab(ui, green, 30, -15)
    yield from ui.until(lambda: (green.location - g0).length > 1e-3, 10, "the green handle moved")
    yield from ui.until(lambda: mirror_state.report_of(sphere) is not None, 20, "a report")
    rep = mirror_state.report_of(sphere)
    r["green"] = {"before": vec(g0), "after": vec(green.location), "status": rep.status, "messages": list(rep.messages)}
    ui.screenshot("green-moved", crop=ui.region_box(ui.region("WINDOW")))
    # Ctrl+Z with the pointer over the 3D view: the handle goes back.
    yield from ui.key("ctrl+z")
    yield from ui.until(lambda: (bpy.data.objects[gname].location - g0).length < 1e-5, 20, "Ctrl+Z restoring the green handle")
    green = bpy.data.objects[gname]
    r["green"]["after_undo"] = vec(green.location)

    # Esc cancels a G drag: nothing moves.
    g1 = green.location.copy()
    yield from scenes.grab(ui, green, 60, 50, finish="esc")
    r["green_esc"] = {"before": vec(g1), "after": vec(green.location)}

    # Red handle: G, move, click (it slides on the mirror's surface).
    red = bpy.data.objects[rname]
    r0 = red.location.copy()
    yield from scenes.grab(ui, red, -12, -8)
    yield from ui.until(lambda: (red.location - r0).length > 1e-3, 10, "the red handle moved")
    yield from ui.redraws(2)
    sphere = bpy.data.objects["Mirror"]
    rep = mirror_state.report_of(sphere)
    r["red"] = {"before": vec(r0), "after": vec(red.location), "radius_after": round(red.matrix_world.translation.length, 4),
                "status": rep.status if rep else None, "messages": list(rep.messages) if rep else None}
    ui.screenshot("red-moved", crop=ui.region_box(ui.region("WINDOW")))
    yield from ui.key("ctrl+z")
    yield from ui.until(lambda: (bpy.data.objects[rname].location - r0).length < 1e-5, 20, "Ctrl+Z restoring the red handle")
    r["red"]["after_undo"] = vec(bpy.data.objects[rname].location)

    # Shift+Alt+C, then a click on the mirror: a new constraint whose red handle is where the click hit.
    sphere = bpy.data.objects["Mirror"]
    n0 = len(sphere.rokeby.constraints)
    scenes.select_only(sphere)
    p = Vector((-0.5, -0.7, 0.5)).normalized()
    x, y = ui.point_xy(p)
    yield from ui.move(x, y)
    yield from ui.redraws(1)
    yield from ui.key("shift+alt+c")
    yield from ui.redraws(1)
    yield from ui.press()
    yield from ui.release()
    yield from ui.until(lambda: len(bpy.data.objects["Mirror"].rokeby.constraints) == n0 + 1, 20, "a constraint added by the click")
    sphere = bpy.data.objects["Mirror"]
    new = sphere.rokeby.constraints[-1]
    r["added"] = {"count_before": n0, "count_after": len(sphere.rokeby.constraints),
                  "red_at": vec(new.surface_handle.matrix_world.translation), "aimed_at": vec(p),
                  "clicked_px": vec((x, y)), "red_px": vec(ui.point_xy(new.surface_handle.matrix_world.translation))}
    yield from ui.redraws(2)
    ui.screenshot("constraint-added", crop=ui.region_box(ui.region("WINDOW")))
