"""Benchmark: what the add-on costs a heavy scene's depsgraph updates (problem 5).

A scene of N unrelated objects (3,000 and 10,000 small cubes sharing one mesh, as instanced props
are built), one of them moved per update and ``view_layer.update()`` timed (Blender's depsgraph
update including every ``depsgraph_update_post`` handler), in three configurations:

* add-on disabled (unregistered: no handlers);
* add-on enabled, no Rokeby data in the file;
* add-on enabled, one mirror (a 482-vertex sphere, 2 constraints, a region, a camera and a chrome
  material), the moved object unrelated to it; and, for scale, an update that moves the mirror's
  green handle (the field is recomputed).

Disabled and enabled runs alternate in rounds so that load on the machine affects both alike;
each figure is the median over the rounds of the median of ``--steps`` updates. The handler's
own CPU time (``time.thread_time``, its share of the update) is measured too, which is steadier
on a shared machine.

    python bench/heavy_scene.py [--json OUT] [--sizes 3000 10000] [--rounds 3] [--steps 12]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time


def _scene(n: int):
    import bpy
    import bmesh

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    me = bpy.data.meshes.new("Prop")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=0.1)
    bm.to_mesh(me)
    bm.free()
    side = int(math.ceil(n ** (1 / 3)))
    for i in range(n):
        ob = bpy.data.objects.new(f"Prop {i:05d}", me)
        ob.location = (i % side, (i // side) % side, i // (side * side))
        sc.collection.objects.link(ob)
    sc.view_layers[0].update()
    return sc


def _add_mirror(sc):
    import bpy

    from rokeby import api

    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, location=(-5.0, -5.0, 0.0))
    ball = bpy.context.object
    ball.name = "Mirror"
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    ball.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (-5.0, -9.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    api.add_mirror(ball)
    api.add_constraint(ball, (-5.0, -6.0, 0.0), (-4.0, -8.0, 2.0))
    api.add_constraint(ball, (-5.3, -5.9, 0.2))
    api.add_region(ball, "EUCLIDEAN", center=(-5.0, -6.0, 0.0), radius=0.8)
    api.evaluate()
    return ball


class _HandlerClock:
    """Wraps the add-on's depsgraph handler to add up its own time."""

    def __init__(self):
        self.seconds = 0.0
        self.fn = None

    def install(self):
        import bpy

        from rokeby.reflection import handlers

        lst = bpy.app.handlers.depsgraph_update_post
        if handlers.on_depsgraph_update in lst:
            lst.remove(handlers.on_depsgraph_update)
            orig = handlers.on_depsgraph_update

            def timed(scene, depsgraph):
                t = time.thread_time()
                try:
                    orig(scene, depsgraph)
                finally:
                    self.seconds += time.thread_time() - t

            self.fn, self.orig = timed, orig
            lst.append(timed)

    def remove(self):
        import bpy

        lst = bpy.app.handlers.depsgraph_update_post
        if self.fn is not None and self.fn in lst:
            lst.remove(self.fn)
            lst.append(self.orig)
        self.fn = None


def _updates(sc, mover, steps: int, clock=None):
    vl = sc.view_layers[0]
    x0 = mover.location.x
    for k in range(3):  # warm-up: the first update after (un)registering rebuilds state
        mover.location.x = x0 + 0.001 * (k + 1)
        vl.update()
    times, handler = [], []
    for k in range(steps):
        mover.location.x = x0 + 0.001 * (k + 4) * (1 if k % 2 else -1)
        h0 = clock.seconds if clock else 0.0
        t = time.perf_counter()
        vl.update()
        times.append(time.perf_counter() - t)
        handler.append((clock.seconds - h0) if clock else 0.0)
    mover.location.x = x0
    vl.update()
    return statistics.median(times) * 1e3, statistics.median(handler) * 1e3


def measure(n: int, rounds: int, steps: int) -> dict:
    import bpy

    import rokeby

    sc = _scene(n)
    mover = bpy.data.objects[f"Prop {n // 2:05d}"]

    def phase(enabled_label):
        off, on, hon = [], [], []
        for _ in range(rounds):
            rokeby.unregister()
            off.append(_updates(sc, mover, steps)[0])
            rokeby.register()
            clock = _HandlerClock()
            clock.install()
            total, own = _updates(sc, mover, steps, clock)
            clock.remove()
            on.append(total)
            hon.append(own)
        return {"disabled_ms": statistics.median(off), enabled_label + "_ms": statistics.median(on),
                enabled_label + "_handler_ms": statistics.median(hon)}

    row = {"objects": n, "rounds": rounds, "steps": steps}
    rokeby.register()
    row.update(phase("no_data"))
    rokeby.register()
    ball = _add_mirror(sc)
    mirror = phase("mirror")
    row["disabled_mirror_file_ms"] = mirror.pop("disabled_ms")
    row.update(mirror)
    # For scale: an update that moves the mirror's green handle (the field is recomputed).
    rokeby.register()
    green = ball.rokeby.constraints[0].target_handle
    clock = _HandlerClock()
    clock.install()
    row["handle_move_ms"], row["handle_move_handler_ms"] = _updates(sc, green, steps, clock)
    clock.remove()
    rep = rokeby.api.report(ball)
    row["mirror_status"] = rep.status if rep is not None else "none"
    rokeby.unregister()
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None)
    ap.add_argument("--sizes", type=int, nargs="+", default=[3000, 10000])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=12)
    args = ap.parse_args()
    rows = [measure(n, args.rounds, args.steps) for n in args.sizes]
    for r in rows:
        print(json.dumps(r))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
