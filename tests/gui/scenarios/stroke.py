"""An appearance stroke in a real window: Paint Appearance from F3, a press-drag-release across the
painted sphere with the Roughness brush, Esc ending the brush; then one Ctrl+Z."""

import bpy
import numpy as np
from mathutils import Vector


def values(name):
    me = bpy.data.objects["Painted"].data
    a = np.empty(len(me.vertices), np.float32)
    me.attributes[name].data.foreach_get("value", a)
    return a


def scenario(ui):
    yield from ui.start()
    appearance = ui.addon("appearance")
    schema = ui.addon("core.schema")
    attr = schema.APPEARANCE_ATTRIBUTES["roughness"]
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    with ui.override():
        bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0, location=(0, 0, 0))
    sphere = bpy.context.view_layer.objects.active
    sphere.name = "Painted"
    appearance.setup(sphere)
    s = bpy.context.scene.rokeby_appearance_brush
    s.brush, s.value, s.radius, s.strength = "roughness", 0.95, 0.3, 1.0
    with ui.override():
        bpy.ops.ed.undo_push(message="set up")
    before = values(attr)
    verts = np.array([v.co[:] for v in sphere.data.vertices])

    # The stroke: from the point of the sphere that faces the view, 0.3 to the side.
    rv3d = ui.region("WINDOW").data
    back = rv3d.view_rotation @ Vector((0, 0, 1))
    side = rv3d.view_rotation @ Vector((1, 0, 0))
    p1 = back.normalized()
    p2 = (back + 0.3 * side).normalized()
    x1, y1 = ui.point_xy(p1)
    x2, y2 = ui.point_xy(p2)
    yield from ui.move(x1, y1)
    yield from ui.search("Paint Appearance")
    yield from ui.drag([(x1 + (x2 - x1) * i / 5, y1 + (y2 - y1) * i / 5) for i in range(6)])
    ui.screenshot("stroke", crop=ui.region_box(ui.region("WINDOW")))
    yield from ui.key("Escape")
    yield from ui.redraws(2)
    after = values(attr)
    changed = np.abs(after - before) > 1e-6
    # Distance of each vertex to the stroke's segment p1-p2 (chord; the dabs lie on the surface between).
    a, b = np.array(p1[:]), np.array(p2[:])
    t = np.clip(((verts - a) @ (b - a)) / max(float((b - a) @ (b - a)), 1e-12), 0, 1)
    dist = np.linalg.norm(verts - (a + t[:, None] * (b - a)), axis=1)
    r = ui.result
    r["changed"] = int(changed.sum())
    r["changed_max_dist"] = float(dist[changed].max()) if changed.any() else None
    r["unchanged_within_radius"] = int(((dist < s.radius) & ~changed).sum())
    r["cutoff"] = float(appearance.CUTOFF)
    r["radius"] = s.radius
    r["max_after"] = float(after.max())
    yield from ui.move(x1, y1 - 200)
    yield from ui.key("ctrl+z")
    yield from ui.until(lambda: np.array_equal(values(attr), before), 20, "Ctrl+Z restoring the painted values")
    r["undo_restores"] = True
