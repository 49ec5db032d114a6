"""Hardening, crash 1 (run in its own process by tests/workflows/test_hardening.py: a segfault must not take
pytest down): another depsgraph handler deletes a constraint's red handle (or a geodesic region's
centre) in the same update that Rokeby's handler evaluates. On the old main Blender died in
``closest_point_on_mesh`` on the evaluated mesh the ID removal had freed.

    python hardening_crash_check.py {handle|handle-subsurf|region}

Prints ``RESULT {json}``: the report the handler made, and how far its field is from a fresh
evaluation afterwards."""

import json
import sys

import bpy
import numpy as np

import rokeby
from rokeby import api
from rokeby.reflection import mirror_state

case = sys.argv[1]
bpy.ops.wm.read_factory_settings(use_empty=True)
rokeby.register()
bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
ball = bpy.context.object
ball.name = "Ball"
if case.endswith("subsurf"):
    ball.modifiers.new("Subdivision", "SUBSURF").levels = 1
cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
bpy.context.scene.collection.objects.link(cam)
bpy.context.scene.camera = cam
cam.location = (0.0, -4.0, 0.0)
api.add_mirror(ball)
api.add_constraint(ball, (0.0, -1.0, 0.0), (1.0, -3.0, 2.0), eye=(0.0, -4.0, 0.0))
api.add_constraint(ball, (0.3, -0.9, 0.2), (1.0, -3.0, -2.0), eye=(0.0, -4.0, 0.0))
api.add_region(ball, "GEODESIC", center=(0.2, -0.9, 0.3), radius=0.8)
api.add_region(ball, "GEODESIC", center=(-0.2, -0.9, -0.3), radius=0.8)
api.evaluate()
victim = ball.rokeby.regions[0].center if case == "region" else ball.rokeby.constraints[0].surface_handle
removed = []


def other_addons_handler(scene, depsgraph):
    """Runs before Rokeby's: deletes the handle once, in the update that moved the mirror."""
    if not removed:
        removed.append(victim.name)
        bpy.data.objects.remove(victim)


bpy.app.handlers.depsgraph_update_post.insert(0, other_addons_handler)
try:
    # The update both handlers see: the mirror and the other constraint's handle moved.
    ball.location.x += 0.1
    ball.rokeby.constraints[1].surface_handle.location.x += 0.02
    bpy.context.view_layer.update()
finally:
    bpy.app.handlers.depsgraph_update_post.remove(other_addons_handler)
victim = None  # a Python reference to a removed ID: never touched again
rep = api.report(ball)
in_handler = api.stored_field(ball).copy()
mirror_state.reset()
api.evaluate(force=True)
fresh = api.stored_field(ball)
print("RESULT " + json.dumps({
    "removed": removed,
    "status": rep.status,
    "messages": rep.messages,
    "constraints_used": rep.constraints_used,
    "finite": bool(np.all(np.isfinite(in_handler))),
    "field_vs_fresh": float(np.abs(in_handler - fresh).max()),
}), flush=True)
