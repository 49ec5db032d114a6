"""Shadow editing: the shadow mesh and the live drag."""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import sys
from pathlib import Path


from common import ROOT, against_goal  # noqa: E402


SHADOW_MARKER = "## Shadow boundary editing: "


def shadow_section(emit):
    """silhouettes, handles, a drag step and the shadow mesh on the shared meshes of the
    sizes of the paper's Table 1 (bench/shadow.py in fresh processes, 1 thread and all threads)."""
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for threads in (1, os.cpu_count()):
            out = Path(tmp) / f"shadow{threads}.json"
            env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
            subprocess.run([sys.executable, str(ROOT / "bench" / "shadow.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL, env=env)
            runs[threads] = json.loads(out.read_text())
    one, many = runs[1], runs[os.cpu_count()]
    emit(SHADOW_MARKER + "against Table 1 of Mattausch et al.")
    emit()
    emit("bench/shadow.py: each caster at unit radius over an 80k-triangle height-field terrain, a point light above;")
    emit("setup = ShadowEditor (silhouettes, BVH, receiver check); handles = shadow rays of the longest loop;")
    emit("edit = one drag step of a third of that loop (MLS + new handles; the paper's per-frame figure also renders);")
    emit("smesh = the first shadow_mesh() (Laplacian assembly, sparse Cholesky, solve), again = a later one (back-substitution).")
    emit("Medians of 5 (setup: 3); smesh first is one run. `1 thr` = RAYON_NUM_THREADS=1 (the paper used one core).")
    emit("Paper (i7-3770K, one core, GTX 580): smesh 0.2 / 1.01 / 1.28 s, editing + hard shadows 20 / 32 / 101 ms. Goal: a fifth.")
    emit()
    emit("| paper model (tris) | shared mesh | tris | loops (active) | longest loop | setup (ms) 1 / N thr | handles (ms) | edit (ms) 1 / N thr | paper edit (ms) | smesh (s) 1 / N thr | paper smesh (s) | again (ms) |")
    emit("|---|---|---:|---:|---:|---|---:|---|---:|---|---:|---:|")
    for a, b in zip(one["rows"], many["rows"]):
        pt, ps, pe = one["paper"][a["paper"]]
        if "error" in a:
            emit(f"| {a['paper']} ({pt:,}) | {a['mesh']} | {a['triangles']:,} | error: {a['error']} |")
            continue
        emit(f"| {a['paper']} ({pt:,}) | {a['mesh']} | {a['triangles']:,} | {a['loops']} ({a['active_loops']}) | {a['loop_vertices']} | "
             f"{a['setup_s'] * 1e3:.0f} / {b['setup_s'] * 1e3:.0f} | {b['handles_s'] * 1e3:.1f} | {a['edit_s'] * 1e3:.1f} / {b['edit_s'] * 1e3:.1f} | {pe * 1e3:.0f} | "
             f"{a['smesh_first_s']:.2f} / {b['smesh_first_s']:.2f} | {ps:.2f} | {b['smesh_again_s'] * 1e3:.0f} |")
    emit()
    emit(f"Load average {many['load_average']:.1f} at the end, on {many['cpus']} CPUs (other jobs shared the machine).")
    emit()
    # the live shadow while dragging, per drag step in Blender (bench/shadow_live.py).
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "live.json"
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "addon"), os.environ.get("PYTHONPATH", "")]))
        subprocess.run([sys.executable, str(ROOT / "bench" / "shadow_live.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL, env=env)
        live = json.loads(out.read_text())["rows"]
    emit("Live shadow while dragging (bench/shadow_live.py, medians of the 7 steps after a drag's first): "
         "drag = `session.drag`, step = `shadow.live_step` (the shadow mesh, incremental within an affine drag, written "
         "into the edit key), native = `ShadowEditor.shadow_mesh` alone, depsgraph = `view_layer.update()`; first = the "
         "drag's first step after the mouse press (the operator prepares the drag there: press), and without a press (the "
         "responses to x and y back-substituted at the first step); full solve = a step that back-substitutes the "
         "whole system (a rigid drag; every step before the incremental update). A frame is 16.7 ms.")
    emit()
    emit("| paper model | shared mesh | tris | drag (ms) | step (ms) | native (ms) | depsgraph (ms) | per step (ms) | in a frame | press (ms) | first step (ms) | first step without press (ms) | full-solve step (ms) |")
    emit("|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|")
    for r in live:
        if "error" in r:
            emit(f"| {r['paper']} | {r['mesh']} | {r['triangles']:,} | error: {r['error']} |")
            continue
        emit(f"| {r['paper']} | {r['mesh']} | {r['triangles']:,} | {r['drag_ms']:.1f} | {r['live_step_ms']:.1f} | "
             f"{r['native_mesh_ms']:.1f} | {r['depsgraph_ms']:.1f} | {r['total_ms']:.1f} | "
             f"{'yes' if r['total_ms'] < 1000 / 60 else 'no'} | {r['press_ms']:.1f} | {r['first_step_ms']:.1f} | "
             f"{r['first_step_unprepared_ms']:.1f} | {r['full_solve_step_ms']:.1f} |")
    emit()
    for r in live:  # goal: the shadow drag's press under 30 ms at 100k vertices
        if "press_ms" in r:
            emit(f"- shadow press, {r['mesh']} ({r.get('vertices', 0):,} vertices, {r['triangles']:,} tris; goal at 100k vertices): "
                 f"{against_goal(r['press_ms'], 30.0, 'ms')}")
    emit()
