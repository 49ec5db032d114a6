"""Benchmark: the live shadow while dragging (the paper's Fig. 3 B–D) in Blender.

Per drag step the modal operator runs ``session.drag`` (MLS + handles, native) and
``shadow.live_step`` (the shadow mesh, written into the shadow object's shape key); the viewport
then evaluates the depsgraph (``view_layer.update``: the shape key applied). The first step of a
drag back-substitutes the responses to the dragged point's x and y (four columns) unless the drag was
prepared on the mouse press (``prepare_drag``, as the operator does: ``press_ms``); the medians are of the steps after
the first, which update the shadow mesh incrementally (affine drags); ``full_solve_step_ms`` is a step of a rigid drag,
which back-substitutes the whole system every step (the cost of every step before).
Casters are bench/shadow.py's shared meshes (spot subdivided once, the bunny with its holes
closed, nefertiti) at unit radius over the 80k-triangle terrain, a point light above; medians of
``--steps`` steps of one drag (the cursor moving outwards).

    PYTHONPATH=addon python bench/shadow_live.py [--steps 7] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import shadow as native_bench  # noqa: E402  (bench/shadow.py: meshes, terrain, placement)


def _object(bpy, name, v, f):
    me = bpy.data.meshes.new(name)
    me.from_pydata(np.asarray(v, np.float64).tolist(), [], np.asarray(f, np.int64).tolist())
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=7)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    import bpy

    import rokeby
    from rokeby import api, shadow

    rows = []
    tv, tf = native_bench.terrain()
    for paper_name, what, v, f in native_bench.models():
        bpy.ops.wm.read_factory_settings(use_empty=True)
        rokeby.register()
        sc = bpy.context.scene
        ground = _object(bpy, "Terrain", tv, tf)
        caster = _object(bpy, "Caster", native_bench.place(v), f)
        lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
        sc.collection.objects.link(lamp)
        lamp.location = (0.8, 0.5, 5.0)
        sc.view_layers[0].update()
        row = {"paper": paper_name, "mesh": what, "triangles": int(len(f)), "vertices": len(caster.data.vertices)}
        try:
            s = api.start_shadow_edit(caster, lamp, [ground], min_loop_vertices=20)
        except shadow.ShadowEditError as exc:
            row["error"] = str(exc)
            rows.append(row)
            print(row, flush=True)
            continue
        loops = s.loops()
        k = int(np.argmax([len(lp["points"]) for lp in loops]))
        h = s.handles(k)
        m = len(h["points"])
        centre = h["points"][h["hit"]].mean(axis=0)
        mid = m // 2
        fixed = (mid - m // 6, mid + m // 6)
        t0 = time.perf_counter()
        live = shadow.live_begin(s)  # installs the edit (first shadow_mesh: the factorisation)
        row["begin_s"] = time.perf_counter() - t0

        def steps(style, n, press=False):
            drag, step, update, native = [], [], [], []
            if press:  # the operator's mouse press (ShadowSession.prepare_drag)
                t0 = time.perf_counter()
                s.prepare_drag(k, fixed, mid, style=style)
                row["press_ms"] = 1e3 * (time.perf_counter() - t0)
            for i in range(n):
                target = centre + (h["points"][mid] - centre) * (1.05 + 0.03 * i)
                t0 = time.perf_counter()
                s.drag(k, fixed, mid, target, style=style)
                t1 = time.perf_counter()
                shadow.live_step(live)
                t2 = time.perf_counter()
                sc.view_layers[0].update()
                t3 = time.perf_counter()
                s.shadow_mesh()  # the native part of the step alone (not in the totals)
                t4 = time.perf_counter()
                drag.append(t1 - t0)
                step.append(t2 - t1)
                update.append(t3 - t2)
                native.append(t4 - t3)
            s.cancel()
            return drag, step, update, native

        # The default (affine) drag without a press: its first step back-substitutes the responses
        # to x and y; then as the operator runs it, prepared on the press: every step, the first
        # included, is incremental (ShadowEditor::shadow_mesh, O(V)).
        drag, step, update, native = steps("affine", 2)
        row["first_step_unprepared_ms"] = 1e3 * (drag[0] + step[0] + update[0])
        drag, step, update, native = steps("affine", args.steps + 1, press=True)
        row["first_step_ms"] = 1e3 * (drag[0] + step[0] + update[0])
        drag, step, update, native = drag[1:], step[1:], update[1:], native[1:]
        row.update(drag_ms=1e3 * statistics.median(drag), live_step_ms=1e3 * statistics.median(step),
                   depsgraph_ms=1e3 * statistics.median(update), native_mesh_ms=1e3 * statistics.median(native),
                   total_ms=1e3 * statistics.median(np.add(np.add(drag, step), update)))
        # Reference: a rigid drag is not affine in the dragged point, so every step back-substitutes
        # the whole system (what every step cost before the incremental update).
        _, rstep, _, _ = steps("rigid", max(3, args.steps // 2))
        row["full_solve_step_ms"] = 1e3 * statistics.median(rstep)
        shadow.live_end(live, keep=False)
        rows.append(row)
        print(row, flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows}, indent=1))


if __name__ == "__main__":
    main()
