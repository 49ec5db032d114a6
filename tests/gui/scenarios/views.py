"""Return to View (Shift+Alt+V) after the view was turned, and Add Region at a clicked point: the
3D cursor placed on the mirror with Shift+right-click, then Add Region ▸ Euclidean from F3 search."""

import bpy


def vec(v):
    return [round(float(x), 5) for x in v]


def scenario(ui):
    yield from ui.start()
    api = ui.addon("api")
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    with ui.override():
        bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=1.0, location=(0, 0, 0))
    sphere = bpy.context.view_layer.objects.active
    sphere.name = "Mirror"
    api.add_mirror(sphere)
    region = ui.region("WINDOW")
    rv3d = region.data
    made_from = (rv3d.view_rotation.copy(), rv3d.view_distance)
    with ui.override():
        # Made from the current view (the operator takes the view it runs in).
        bpy.ops.rokeby.constraint_add(mirror="Mirror", surface_point=(0.66, -0.62, 0.44))
        bpy.ops.ed.undo_push(message="scene set up")
    r = ui.result
    sphere = bpy.data.objects["Mirror"]
    r["constraints"] = len(sphere.rokeby.constraints)

    # Turn the view (numpad 7: top), then Shift+Alt+V over the 3D view.
    cx, cy = ui.screen_xy(region, region.width * 0.3, region.height * 0.3)
    yield from ui.move(cx, cy)
    yield from ui.key("KP_7")
    yield from ui.until(lambda: rv3d.view_rotation.rotation_difference(made_from[0]).angle > 0.1, 10, "the view turned")
    r["turned_deg"] = round(rv3d.view_rotation.rotation_difference(made_from[0]).angle * 57.29578, 2)
    yield from ui.redraws(1)
    yield from ui.key("shift+alt+v")
    yield from ui.until(lambda: rv3d.view_rotation.rotation_difference(made_from[0]).angle < 1e-3, 10, "the view back")
    r["returned_deg"] = round(rv3d.view_rotation.rotation_difference(made_from[0]).angle * 57.29578, 4)
    yield from ui.redraws(2)
    ui.screenshot("returned-to-view", crop=ui.region_box(region))

    # Shift+right-click on the mirror places the 3D cursor on its surface; F3 ▸ Add Region ▸ Euclidean.
    sphere = bpy.data.objects["Mirror"]
    for o in bpy.context.view_layer.objects:
        o.select_set(o == sphere)
    bpy.context.view_layer.objects.active = sphere
    x, y = ui.point_xy((0.0, -1.0, 0.0))
    yield from ui.move(x, y)
    yield from ui.redraws(1)
    ui.xdo("keydown", "shift")
    yield from ui.press(3)
    yield from ui.release(3)
    ui.xdo("keyup", "shift")
    cursor0 = bpy.context.scene.cursor.location.copy()
    yield from ui.redraws(2)
    r["cursor"] = vec(bpy.context.scene.cursor.location)
    n0 = len(sphere.rokeby.regions)
    yield from ui.search("Add Region Euclidean", run=False)
    ui.screenshot("f3-add-region")
    yield from ui.key("Return")
    yield from ui.redraws(2)
    # The entry opens the kind menu: its first item (Euclidean) with Return.
    if len(bpy.data.objects["Mirror"].rokeby.regions) == n0:
        ui.screenshot("region-kind-menu")
        yield from ui.key("Return")
    yield from ui.until(lambda: len(bpy.data.objects["Mirror"].rokeby.regions) == n0 + 1, 15, "a region added")
    sphere = bpy.data.objects["Mirror"]
    rg = sphere.rokeby.regions[-1]
    r["region"] = {"kind": rg.kind, "center": vec(rg.center.matrix_world.translation), "cursor": vec(cursor0)}
    yield from ui.redraws(2)
    ui.screenshot("region-added", crop=ui.region_box(region))
