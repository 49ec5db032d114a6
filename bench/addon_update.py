"""Benchmark: time from a handle move to the updated field attribute.

A mirror of about 100k vertices (a UV sphere, 99,602 vertices) and the real nefertiti.obj scan
(49,971 vertices), 8 constraints, the green handle of one constraint moved per step through the
depsgraph handler, as when dragging in the viewport. Prints the evaluator's own split (Python:
reading handles and the mesh, projecting the red handles, converting and writing the attribute;
Rust: rokeby_native) and the whole view_layer.update() including Blender's depsgraph work.

Red-handle drags with geodesic distances: the red handle of one constraint moves per
step (each step a new surface point, so a new solve); during the drag the moved constraint's
distances come from geodesic_cache.DRAG_METHOD (a preview), and on release (``handlers.settle_previews``,
what the end-of-drag timer runs) the mirror's own method recomputes them. Printed: the drag step,
the release, one accurate solve by itself, and a step that solves accurately every time (what a
drag cost before the preview).

    python bench/addon_update.py [--json OUT] [--quick] [--red-only]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _scene(kind: str, shared: Path):
    import bpy

    import rokeby
    from rokeby import api

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    if kind == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=400, ring_count=250, radius=1.0)
        mirror = bpy.context.object
        bpy.ops.object.shade_smooth()
    else:
        bpy.ops.wm.obj_import(filepath=str(shared / "meshes" / "nefertiti.obj"), forward_axis="Y", up_axis="Z")
        mirror = bpy.context.selected_objects[0]
    mirror.name = "Mirror"
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    mirror.data.materials.clear()
    mirror.data.materials.append(mat)
    api.add_mirror(mirror)
    m = api.mesh_arrays(mirror)
    centre = m.vertices.mean(0)
    size = float(np.linalg.norm(m.vertices.max(0) - m.vertices.min(0)))
    eye = centre + np.array([0.0, -2.0 * size, 0.3 * size])
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(cam)
    cam.location = eye
    bpy.context.scene.camera = cam  # the render eye: renders are set up as in a real scene
    facing = np.einsum("ij,ij->i", m.normals, (eye - m.vertices) / np.linalg.norm(eye - m.vertices, axis=1, keepdims=True))
    rng = np.random.default_rng(4)
    picks = rng.choice(np.flatnonzero(facing > 0.5), 8, replace=False)
    for i in picks:
        api.add_constraint(mirror, m.vertices[i], m.vertices[i] + size * (rng.normal(size=3) * 0.3 + [0, -1, 0.5]), eye=eye)
    return mirror, size


def measure(kind: str, shared: Path, metric: str, method: str, polar: str, steps: int = 30) -> dict:
    import bpy

    from rokeby import api

    from rokeby.reflection import evaluate, handlers

    mirror, size = _scene(kind, shared)
    # A drag in a Blender window: the render-vs-preview estimate waits for the pause (its timer
    # is not run here), as the add-on does outside background mode.
    handlers.WINDOW_UPDATES = True
    evaluate._schedule = lambda fn, seconds: None
    mirror.rokeby.metric, mirror.rokeby.geodesic_method, mirror.rokeby.polar = metric, method, polar
    api.evaluate(force=True)  # factorisation and caches
    green = mirror.rokeby.constraints[3].target_handle
    py, rs, total, after = [], [], [], []
    for k in range(steps):
        green.location.x += 0.01 * size * (1 if k % 2 == 0 else -1)
        t0 = time.perf_counter()
        bpy.context.view_layer.update()  # the depsgraph handler evaluates and writes the attribute
        total.append((time.perf_counter() - t0) * 1e3)
        rep = api.report(mirror)
        # Random large edits may warn (e.g. reflections folded below the surface); never ERROR.
        assert rep.recomputed and rep.status != "ERROR", rep.summary()
        py.append(rep.python_ms)
        rs.append(rep.native_ms)
        t1 = time.perf_counter()
        bpy.context.view_layer.update()  # the update the attribute write tagged (mesh re-evaluation)
        after.append((time.perf_counter() - t1) * 1e3)
    return {
        "mesh": kind,
        "vertices": len(mirror.data.vertices),
        "metric": metric,
        "method": method,
        "polar": polar,
        "python_ms": float(np.median(py)),
        "rust_ms": float(np.median(rs)),
        "update_ms": float(np.median(total)),
        # the following depsgraph update re-evaluates the mesh the write tagged.
        "after_ms": float(np.median(after)),
    }


def measure_red(shared: Path, method: str, update: bool = True, steps: int = 20, accurate_steps: int = 5) -> dict:
    """A red-handle drag on the 100k sphere with geodesic distances by ``method``; the preview
    updates the accurate distances (``update``, geodesic_cache.DRAG_UPDATE) or solves by DRAG_METHOD."""
    import bpy

    from rokeby import api
    from rokeby.reflection import evaluate, geodesic_cache, handlers, mirror_state

    geodesic_cache.DRAG_UPDATE = update
    mirror, size = _scene("sphere", shared)
    handlers.WINDOW_UPDATES = True
    evaluate._schedule = lambda fn, seconds: None  # the end-of-drag timer is run by hand below
    mirror.rokeby.metric, mirror.rokeby.geodesic_method, mirror.rokeby.polar = "GEODESIC", method, "FAST"
    api.evaluate(force=True)  # graph / factorisation and caches
    red = mirror.rokeby.constraints[3].surface_handle

    def drag(n, interactive):
        handlers.WINDOW_UPDATES = interactive
        py, rs, total, cpu = [], [], [], []
        for _ in range(n):
            red.location.x += 0.004 * size  # a new surface point each step: a new solve
            t0, c0 = time.perf_counter(), time.process_time()
            bpy.context.view_layer.update()
            total.append((time.perf_counter() - t0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
            rep = api.report(mirror)
            assert rep.recomputed and rep.status != "ERROR" and rep.drag_preview == interactive, rep.summary()
            py.append(rep.python_ms)
            rs.append(rep.native_ms)
            bpy.context.view_layer.update()  # the update the attribute write tagged
        return float(np.median(py)), float(np.median(rs)), float(np.median(total)), float(np.median(cpu))

    step = drag(steps, True)
    # How far the preview's distances of the moved constraint are from the accurate ones, at the
    # end of the drag (0.28 of the radius from where it started).
    preview_row = np.array(mirror_state.state_of(mirror).field_inputs[1][3])
    handlers.settle_previews()
    accurate_row = np.array(mirror_state.state_of(mirror).field_inputs[1][3])
    ok = np.isfinite(accurate_row) & (accurate_row > 1e-6 * size)
    err = np.abs(preview_row[ok] - accurate_row[ok]) / accurate_row[ok]
    drag(1, True)
    releases, release_cpu = [], []
    for _ in range(3):
        t0, c0 = time.perf_counter(), time.process_time()
        assert handlers.settle_previews() == 1
        releases.append((time.perf_counter() - t0) * 1e3)
        release_cpu.append((time.process_time() - c0) * 1e3)
        rel = api.report(mirror)
        assert not rel.drag_preview and rel.recomputed, rel.summary()
        drag(1, True)  # a preview again, for the next release
    handlers.settle_previews()
    accurate = drag(accurate_steps, False)
    # One accurate solve by itself (the solver of the mirror, its graph or factorisation made).
    solver = mirror_state.state_of(mirror).solver
    tri = mirror_state.state_of(mirror).geometry.triangles
    rng = np.random.default_rng(7)
    solves, solve_cpu, drag_solves, drag_cpu = [], [], [], []
    for f in rng.choice(len(tri), 7, replace=False):
        for m, wall, cpu in ((method.lower(), solves, solve_cpu), (geodesic_cache.DRAG_METHOD, drag_solves, drag_cpu)):
            t0, c0 = time.perf_counter(), time.process_time()
            solver.distances([(int(f), (0.2, 0.3, 0.5))], method=m)
            wall.append((time.perf_counter() - t0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
    handlers.WINDOW_UPDATES = None
    return {
        "mesh": "sphere",
        "vertices": len(mirror.data.vertices),
        "method": method,
        "drag_method": "update" if update else geodesic_cache.DRAG_METHOD,
        "preview_error_mean": float(err.mean()),
        "preview_error_p99": float(np.percentile(err, 99)),
        "solver": geodesic_cache.DRAG_METHOD,
        "step_python_ms": step[0],
        "step_rust_ms": step[1],
        "step_update_ms": step[2],
        # CPU time of the process (all threads) over the step: steadier than wall time on a
        # loaded machine, and above it only when several threads work (or idle ones spin).
        "step_cpu_ms": step[3],
        "release_cpu_ms": float(np.median(release_cpu)),
        "solve_cpu_ms": float(np.median(solve_cpu)),
        "drag_solve_ms": float(np.median(drag_solves)),
        "drag_solve_cpu_ms": float(np.median(drag_cpu)),
        "release_ms": float(np.median(releases)),
        "release_rust_ms": float(rel.native_ms),
        "solve_ms": float(np.median(solves)),
        "accurate_step_update_ms": accurate[2],
        "accurate_step_rust_ms": accurate[1],
        "accurate_step_cpu_ms": accurate[3],
        "load_average": os.getloadavg()[0],
    }


def print_red(r):
    print(f"red-handle drag, sphere {r['vertices']:,} v, geodesic {r['method'].lower()} (preview: {r['drag_method']}), wall/CPU ms: "
          f"step {r['step_update_ms']:.1f}/{r['step_cpu_ms']:.1f} (Python {r['step_python_ms']:.1f}, Rust {r['step_rust_ms']:.1f}; goal 16)  "
          f"release {r['release_ms']:.1f}/{r['release_cpu_ms']:.1f}  one accurate solve {r['solve_ms']:.1f}/{r['solve_cpu_ms']:.1f} (goal 50)  "
          f"one {r['solver']} solve {r['drag_solve_ms']:.1f}/{r['drag_solve_cpu_ms']:.1f}  "
          f"accurate every step {r['accurate_step_update_ms']:.1f}/{r['accurate_step_cpu_ms']:.1f}  "
          f"preview vs accurate {100 * r['preview_error_mean']:.2f}% mean, {100 * r['preview_error_p99']:.2f}% p99  (load {r['load_average']:.1f})", flush=True)


# (mirror's method, preview by update): the update, and Dijkstra's solve, on the default graph.
RED_METHODS = (("GRAPH", True), ("GRAPH", False), ("HEAT", True))

CONFIGS = [
    ("EUCLIDEAN", "HEAT", "FAST"),
    ("EUCLIDEAN", "HEAT", "EXACT"),
    ("GEODESIC", "DIJKSTRA", "FAST"),
    ("GEODESIC", "HEAT", "FAST"),
]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", type=Path)
    ap.add_argument("--shared", type=Path, default=Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared")))
    ap.add_argument("--quick", action="store_true", help="the 100k sphere only, Euclidean and geodesic (heat), fast polar")
    ap.add_argument("--red-only", action="store_true", help="only the red-handle drags")
    args = ap.parse_args(argv)
    rows = []
    red = []
    for method, update in RED_METHODS[:1] if args.quick else RED_METHODS:
        r = measure_red(args.shared, method, update)
        red.append(r)
        print_red(r)
    for kind in () if args.red_only else ("sphere",) if args.quick else ("sphere", "nefertiti"):
        for metric, method, polar in [CONFIGS[0], CONFIGS[3]] if args.quick else CONFIGS:
            r = measure(kind, args.shared, metric, method, polar)
            rows.append(r)
            print(f"{kind:>9} {r['vertices']:>7,} v  {metric:<9} {method if metric == 'GEODESIC' else '':<8} {polar:<5}  python {r['python_ms']:6.2f} ms  rust {r['rust_ms']:6.2f} ms  whole update {r['update_ms']:6.2f} ms  re-evaluation {r['after_ms']:6.2f} ms", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"green": rows, "red": red}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
