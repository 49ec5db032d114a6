"""Scenes the window scenarios share, made as a user would make them (operators in the window)."""

import bpy


def ball_over_ground(ui):
    """A ball (radius 0.5, 1.5 above the origin) over a 12 m ground plane under a point light:
    the factory scene's meshes removed, one undo step "scene set up"; returns (ball, ground, light)."""
    with ui.override():
        for ob in list(bpy.data.objects):
            if ob.type == "MESH":
                bpy.data.objects.remove(ob)
        bpy.ops.mesh.primitive_plane_add(size=12)
        bpy.context.object.name = "Ground"
        bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.5, location=(0, 0, 1.5))
        bpy.context.object.name = "Ball"
        lamp = next(o for o in bpy.data.objects if o.type == "LIGHT")
        lamp.location = (0.3, 0.2, 4.0)
        lamp.data.type = "POINT"
        bpy.ops.ed.undo_push(message="scene set up")
    return bpy.data.objects["Ball"], bpy.data.objects["Ground"], lamp


def look_down(ui, distance=7.0):
    """The largest 3D view looking straight down at the origin from ``distance``."""
    rv3d = ui.region("WINDOW", ui.area()).data
    rv3d.view_perspective = "PERSP"
    rv3d.view_rotation = (1.0, 0.0, 0.0, 0.0)
    rv3d.view_location = (0.0, 0.0, 0.0)
    rv3d.view_distance = distance


def smooth_sphere(ui, radius=1.0):
    """The factory cube replaced by a smooth UV sphere (48 × 24) of ``radius`` at the origin; returns it."""
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    with ui.override():
        bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=radius, location=(0, 0, 0))
        bpy.ops.object.shade_smooth()
    return bpy.context.view_layer.objects.active


def select_only(ob):
    for o in bpy.context.view_layer.objects:
        o.select_set(o == ob)
    bpy.context.view_layer.objects.active = ob


def grab(ui, ob, dx, dy, steps=4, each=None, finish="click"):
    """G over the 3D view with only ``ob`` selected, the pointer moved by (dx, dy) in ``steps``
    (``each()`` after every one, the window drawn between), then a click (confirm), Esc
    (``finish="esc"``: cancel) or nothing (``None``: the grab still running)."""
    select_only(ob)
    yield from ui.redraws(1)
    x, y = ui.point_xy(ob.matrix_world.translation)
    yield from ui.move(x, y)
    yield from ui.redraws(1)
    yield from ui.key("g")
    yield from ui.redraws(1)
    for i in range(1, steps + 1):
        yield from ui.move(x + dx * i / steps, y + dy * i / steps)
        yield from ui.redraws(1)
        if each is not None:
            each()
    if finish == "click":
        yield from ui.press()
        yield from ui.release()
    elif finish == "esc":
        yield from ui.key("Escape")
    if finish is not None:
        yield from ui.redraws(2)
