"""`make bench`: Rokeby's speed and accuracy, printed next to the reference numbers.

Writes the same tables to docs/benchmarks.md. Nothing here is asserted: timings vary by machine;
tests check behaviour, this reports speed.

Reference figures (Ritschel et al. 2009, §8): per-pixel reflection interpolation on a GeForce GTX
260 at 1280x960: 24.5 megapixels/s with 1 constraint, 18.5 megapixels/s with 32 constraints.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import tempfile
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import rokeby_native as rn  # noqa: E402

from reference import field_matrices, ortho as ortho_ref, quat_to_matrix, random_constraints, rot_angle  # noqa: E402
from rokeby.meshio import load_obj, subdivide_midpoint  # noqa: E402

SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
PAPER = {1: 24.5, 32: 18.5}


def timeit(fn, repeat=5):
    fn()  # warm-up (thread pool, caches)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def constraints(rng, k, spread, centre=None, max_edit=0.7):
    return random_constraints(rng, k, spread=spread, max_edit=max_edit, min_edit=0.1, at=centre)


def full_frame_gbuffer(w, h):
    """Every pixel on a gently curved mirror (a full 1280x960 frame of reflecting surface)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = xs / w - 0.5, (ys / h - 0.5) * h / w
    z = 0.05 * np.sin(8 * x) + 0.05 * np.cos(6 * y)
    pos = np.stack([x, y, z], -1)
    nrm = np.stack([-0.4 * np.cos(8 * x), 0.3 * np.sin(6 * y), np.ones_like(x)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    return pos.astype(np.float32), nrm.astype(np.float32)


def machine():
    cpu = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import bpy  # noqa: F401 - version only

    return f"{cpu}, {os.cpu_count()} cores; Python {platform.python_version()}, numpy {np.__version__}, rokeby_native {rn.__version__}, Blender {bpy.app.version_string}"


def rel_errors(d, exact, faces, source):
    """Mean and max relative error over vertices outside the source's 1-ring that exact reaches."""
    ring = np.unique(faces[(faces == source).any(axis=1)])
    mask = np.isfinite(exact) & (exact > 0)
    mask[ring] = False
    ok = mask & np.isfinite(d)
    rel = np.abs(d[ok] - exact[ok]) / exact[ok]
    missing = int(np.count_nonzero(mask & ~np.isfinite(d)))
    return float(rel.mean()), float(rel.max()), missing


# Peak resident memory of the solver alone, in a fresh process. VmHWM (not ru_maxrss, which a
# child inherits from its parent across exec) is the high-water mark of this address space.
SOLVER_MEMORY = """
import sys, numpy as np, rokeby_native as rn
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
data = np.load(sys.argv[1])
v, f = np.array(data["vertices"]), np.array(data["faces"])
base = hwm()
s = rn.GeodesicSolver(v, f, boundary=sys.argv[2])
s.distances([0])
print(hwm() - base)
"""


GEODESIC_MARKER = "## Geodesic distances: "
GEODESIC_RECOMMENDATION = """Recommendation: heat (the add-on's default; `boundary='neumann'` or 'average' give the same error) for
renders and anything judged by eye: about 1-2% mean error, as accurate as potpourri3d with a faster query, and
more accurate than libigl (whose query is faster on the large meshes: 18 ms against 45 ms on nefertiti, but
24% mean error on homer and 51% at 1.6M triangles); it also runs on meshes where both peers fail (bunny). Use
Dijkstra while dragging on very large meshes (at 1.6M triangles a heat query takes seconds, Dijkstra ~0.1 s),
accepting 5-10% mean and 30-80% maximum error. Exact MMP (pygeodesic) is for validation only: its query is
50-100x slower than heat's and it fails on some meshes (teapot)."""


def geodesic_section(emit, peers_python):
    emit("## Geodesic distances: speed and accuracy against exact polyhedral geodesics")
    emit()
    emit("Three source vertices per mesh (taken from faces a quarter, half and three quarters through the")
    emit("face list), one distance field each. Error: mean (averaged over the three fields) and maximum of")
    emit("|d - d_exact| / d_exact over the vertices outside the source's 1-ring that the")
    emit("exact solver reaches (pygeodesic's MMP, Surazhsky et al. 2005). Precomputation is done once per")
    emit("mesh (graph, intrinsic Delaunay flips and Cholesky factorisations for the heat methods); a query")
    emit("is one handle move. Peers run in the same session, in .venv-peers. The 1.6M-triangle mesh (nefertiti")
    emit("subdivided twice) is scored at its original vertices against the exact distances on nefertiti: midpoint")
    emit("subdivision changes neither the surface nor those vertices.")
    emit()
    emit("| mesh | triangles | method | precompute (s) | query (ms) | mean error | max error |")
    emit("|---|---:|---|---:|---:|---:|---:|")
    rows = []
    meshes = [p.name for p in sorted((SHARED / "meshes").glob("*.obj"), key=lambda p: p.stat().st_size)]
    big = None
    exact_of = {}
    for name in meshes + ["nefertiti.obj x2 midpoint subdivision"]:
        original = None
        if name.endswith("subdivision"):
            v, f = load_obj(SHARED / "meshes" / "nefertiti.obj")
            original = (len(v), f)
            for _ in range(2):
                v, f = subdivide_midpoint(v, f)
            big = (v, f)
        else:
            v, f = load_obj(SHARED / "meshes" / name)
        # Sources from the (original) faces; midpoint subdivision keeps the original vertices first
        # and the surface unchanged, so the original mesh's exact distances score the big one there.
        src_faces = original[1] if original else f
        sources = [int(src_faces[len(src_faces) * k // 4, 0]) for k in (1, 2, 3)]
        skip_exact = len(f) > 300_000
        peers = {}
        if peers_python:
            with tempfile.TemporaryDirectory() as tmp:
                np.savez(f"{tmp}/in.npz", vertices=v, faces=f, sources=np.array(sources), skip_exact=skip_exact)
                r = subprocess.run([peers_python, str(ROOT / "bench" / "peer_geodesics.py"), f"{tmp}/in.npz", f"{tmp}/out.npz"], capture_output=True, text=True)
                if r.returncode == 0:
                    peers = dict(np.load(f"{tmp}/out.npz"))
                else:
                    emit(f"(peers failed on {name}: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode})")
        exact = peers["exact_d"] if "exact_d" in peers else None
        if exact is not None:
            exact_of[name] = exact
        n_scored = len(v)
        if original is not None and "nefertiti.obj" in exact_of:
            n_scored = original[0]
            exact = exact_of["nefertiti.obj"]
        if "exact_error" in peers:
            emit(f"| {name} | {len(f):,} | exact MMP (pygeodesic) | fails: {str(peers['exact_error']).splitlines()[0][:70]} | | | |")
        results = []
        for label, method, boundary in (("rokeby heat", "heat", "average"), ("rokeby heat (neumann)", "heat", "neumann"), ("rokeby dijkstra", "dijkstra", "average")):
            t = time.perf_counter()
            solver = rn.GeodesicSolver(v, f, boundary=boundary)
            solver.distances(sources[:1], method=method)
            first = time.perf_counter() - t
            query = timeit(lambda: solver.distances(sources[:1], method=method), repeat=3)
            d = np.vstack([solver.distances([s_], method=method)[0] for s_ in sources])
            results.append((label, max(first - query, 0.0), query, d))
        for peer, label in (("potpourri3d", "potpourri3d heat"), ("libigl", "libigl heat")):
            if f"{peer}_d" in peers:
                results.append((label, float(peers[f"{peer}_pre"]), float(peers[f"{peer}_query"]), peers[f"{peer}_d"]))
            elif f"{peer}_error" in peers:
                msg = str(peers[f"{peer}_error"]).splitlines()[0][:70]
                emit(f"| {name} | {len(f):,} | {label} | fails: {msg} | | | |")
        for label, pre, query, d in results:
            if exact is not None:
                errs = [rel_errors(np.asarray(d[k][:n_scored], np.float64), exact[k], src_faces, sources[k]) for k in range(len(sources))]
                mean, mx, missing = float(np.mean([e[0] for e in errs])), max(e[1] for e in errs), sum(e[2] for e in errs)
                err = f"{100 * mean:.2f} % | {100 * mx:.1f} %" + (f" ({missing} unreached)" if missing else "")
            else:
                mean, err = None, "— | —"
            emit(f"| {name} | {len(f):,} | {label} | {pre:.3f} | {query * 1e3:.1f} | {err} |")
            rows.append({"mesh": name.split(" ")[0], "method": label, "query_ms": query * 1e3, "mean_err": mean})
        if exact is not None and original is None:
            emit(f"| {name} | {len(f):,} | exact MMP (pygeodesic) | {float(peers['exact_pre']):.3f} | {float(peers['exact_query']) * 1e3:.1f} | 0 | 0 |")
    emit()
    if big is not None:
        v, f = big
        solver = rn.GeodesicSolver(v, f)
        srcs = [[0, len(v) // 4, len(v) // 2, 3 * len(v) // 4]]
        one = timeit(lambda: solver.distances([0], method="dijkstra"), repeat=3)
        four = timeit(lambda: solver.distances(srcs, method="dijkstra"), repeat=3)
        emit(f"Multi-source Dijkstra on nefertiti x2 ({len(f):,} triangles, {len(v):,} vertices): {one * 1e3:.0f} ms for one")
        emit(f"source, {four * 1e3:.0f} ms for a set of four; the paper: 139 ms on the 525k-triangle Lucy (3x fewer triangles).")
        with tempfile.TemporaryDirectory() as tmp:
            np.savez(f"{tmp}/m.npz", vertices=v, faces=f)
            for boundary in ("average", "neumann"):
                r = subprocess.run([sys.executable, "-c", SOLVER_MEMORY, f"{tmp}/m.npz", boundary], capture_output=True, text=True)
                mb = r.stdout.strip() or r.stderr.strip()[-200:]
                emit(f"Peak memory of GeodesicSolver(boundary={boundary!r}) with its factorisations on that mesh: {float(mb):.0f} MB (goal: under 1 GB)." if r.returncode == 0 else f"memory measurement failed: {mb}")
            for label, name, levels in (("homer x3", "homer.obj", 3), ("nefertiti x1", "nefertiti.obj", 1)):
                mv, mf = load_obj(SHARED / "meshes" / name)
                for _ in range(levels):
                    mv, mf = subdivide_midpoint(mv, mf)
                np.savez(f"{tmp}/m1.npz", vertices=mv, faces=mf)
                r = subprocess.run([sys.executable, "-c", SOLVER_MEMORY, f"{tmp}/m1.npz", "average"], capture_output=True, text=True)
                if r.returncode == 0:
                    emit(f"On {label} ({len(mf):,} triangles) the same solver peaks at {float(r.stdout):.0f} MB.")
        emit()
    if peers_python and rows:
        with tempfile.TemporaryDirectory() as tmp:
            json.dump(rows, open(f"{tmp}/rows.json", "w"))
            png = ROOT / "docs" / "geodesic_speed_accuracy.png"
            r = subprocess.run([peers_python, str(ROOT / "bench" / "peer_geodesics.py"), "--plot", f"{tmp}/rows.json", str(png)], capture_output=True, text=True)
            emit("![speed against accuracy](geodesic_speed_accuracy.png)" if r.returncode == 0 else f"(plot failed: {r.stderr.strip()[-200:]})")
            emit()
    emit(GEODESIC_RECOMMENDATION)
    emit()


def addon_section(emit):
    """Issue #4: handle move → updated attribute through the add-on's depsgraph handler (bpy in a
    fresh process, bench/addon_update.py)."""
    import json
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "addon.json"
        subprocess.run([sys.executable, str(ROOT / "bench" / "addon_update.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL)
        rows = json.loads(out.read_text())
    emit("## Add-on: from a handle move to the updated field attribute, 8 constraints")
    emit()
    emit("The green handle of one of 8 constraints moves; `view_layer.update()` runs the depsgraph handler,")
    emit("which re-checks the mirror, recomputes the field and writes it with `foreach_set` (the render rows and the")
    emit("`rokeby_rotation` attribute), as in a Blender window: the render-vs-preview estimate waits for the pause")
    emit("(background scripts and renders run it every update: about 10 ms more at 100k vertices). Python: reading")
    emit("handles, projecting the red handles onto the surface, writing the attributes. Rust: rokeby_native (field,")
    emit("render rows, geodesic solves). Whole update: Blender's depsgraph update including the handler (and its")
    emit("copy of the mesh's attributes). Medians of 30 moves. Goal: under 16 ms (one viewport frame at 60 Hz).")
    emit()
    emit("Next update: the depsgraph update that re-evaluates the mesh the attribute write tagged (`me.update_tag()`,")
    emit("issue 23; it no longer recomputes normals inside the handler).")
    emit()
    emit("| mirror | vertices | distance | polar | Python (ms) | Rust (ms) | handler total (ms) | whole update (ms) | next update (ms) | goal (ms) |")
    emit("|---|---:|---|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        dist = "Euclidean" if r["metric"] == "EUCLIDEAN" else f"geodesic, {r['method'].lower()}"
        emit(f"| {r['mesh']} | {r['vertices']:,} | {dist} | {r['polar'].lower()} | {r['python_ms']:.1f} | {r['rust_ms']:.1f} | {r['python_ms'] + r['rust_ms']:.1f} | {r['update_ms']:.1f} | {r.get('after_ms', float('nan')):.1f} | 16 |")
    emit()
    emit("On this shared 2-core machine the same configuration varies by up to about 40% between runs.")
    emit()
    emit("Geodesic distances are cached per constraint, so a green-handle move costs no solve; moving a red")
    emit("handle costs one solve (heat or Dijkstra) for that constraint only.")
    emit()


RENDER_MARKER = "## Render: "


def render_section(emit):
    """Issue #5: what the edit costs a Cycles render of the `make demo` scene (bpy in a fresh
    process, bench/demo_render.py)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "render.json"
        subprocess.run([sys.executable, str(ROOT / "bench" / "demo_render.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL)
        r = json.loads(out.read_text())
    emit(RENDER_MARKER + "what the edit costs a Cycles render of the demo scene")
    emit()
    emit(f"The Rokeby Venus of `make demo` ({r['width']}x{r['height']}, {r['samples']} samples, denoiser {r['denoiser']}, CPU device,")
    emit(f"{r['threads']} threads), rendered with the mirror's node group installed (the edit) and removed (the physical")
    emit(f"mirror), alternated, {r['repeat']} renders each after a warm-up; medians. Wall: bpy.ops.render.render (sync, BVH,")
    emit("path tracing, denoising). CPU: the process's CPU time over all threads, steadier on a shared machine.")
    emit()
    emit("| mirror | wall median (s) | CPU median (s) | wall, each (s) | CPU, each (s) |")
    emit("|---|---:|---:|---|---|")
    for what, label in (("physical", "physical (no node group)"), ("edited", "edited (node group)")):
        emit(f"| {label} | {r[what + '_median_s']:.2f} | {r[what + '_cpu_median_s']:.2f} | {', '.join(f'{t:.2f}' for t in r[what + '_s'])} | {', '.join(f'{t:.2f}' for t in r[what + '_cpu_s'])} |")
    emit()
    emit(f"Ratio edited / physical: wall {r['edited_median_s'] / r['physical_median_s']:.3f}, CPU {r['edited_cpu_median_s'] / r['physical_cpu_median_s']:.3f}.")
    emit(f"Load average {r['load_average'][0]:.1f} before and {r['load_average'][1]:.1f} after the renders, on {r['cpus']} CPUs: other jobs shared")
    emit("the machine, so single renders vary by tens of percent; a ratio within that spread means no measurable cost.")
    emit()


VIEWPORT_MARKER = "## Viewport preview: "


def viewport_section(emit):
    """Issue #5: the viewport preview's shader per frame (moderngl on headless EGL, in a fresh
    process, bench/viewport.py)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "viewport.json"
        subprocess.run([sys.executable, str(ROOT / "bench" / "viewport.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL)
        info, *rows = json.loads(out.read_text())
    emit(VIEWPORT_MARKER + "the per-pixel field shader, time per frame")
    emit()
    emit(f"The GLSL of `shaders/` (the shader the add-on draws with) on {info['renderer']}, through moderngl on a")
    emit(f"headless EGL context: {info['mesh']} seen from the front, K random constraints, Euclidean distances")
    emit("or per-vertex geodesic (Dijkstra) distances interpolated per pixel; output: the environment colour in")
    emit("direction e. Draw + glFinish, medians of 3 frames. **No GPU machine was lent to this task**: these are CPU")
    emit("numbers (llvmpipe runs both sides of every branch, so even K = 1 pays for the whole shader). The paper:")
    emit("9.4-29.1 fps for its whole scenes at 1280x960 on a GeForce GTX 260, reflection editing alone 24.5")
    emit("megapixels/s with 1 constraint and 18.5 with 32.")
    emit()
    emit("| resolution | K | distances | mirror pixels | ms / frame | fps | megapixels/s (mirror) | paper (GTX 260) |")
    emit("|---|---:|---|---:|---:|---:|---:|---|")
    for r in rows:
        paper = {1: "24.5 MP/s", 32: "18.5 MP/s"}.get(r["k"], "—")
        emit(f"| {r['width']}x{r['height']} | {r['k']} | {r['metric']} | {r['coverage']:.0%} | {r['ms']:.0f} | {r['fps']:.2f} | {r['mpix_s']:.2f} | {paper} |")
    emit()
    emit(f"Load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (other jobs shared the machine).")
    emit()


ENVMAP_MARKER = "## Environment maps: "


def envmap_section(emit):
    """Issue #8: prefiltering the HDR worlds bpy ships, speed and error against the seed's
    brute-force sum (in a fresh process, bench/envmap.py)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "envmap.json"
        subprocess.run([sys.executable, str(ROOT / "bench" / "envmap.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL)
        r = json.loads(out.read_text())
    emit(ENVMAP_MARKER + "prefiltering a 1024x512 HDR world (sunset.exr), 8 levels")
    emit()
    emit("rokeby_native.env_prefilter (multi-scale ring convolution, docs/envmaps.md), all 8 levels of one call,")
    emit("medians of 5 calls. CPU: the process's CPU time over all threads. Goal: under 1 s for 8 roughness levels.")
    emit()
    emit("| lobe | levels | K (texels per ring radius) | wall (s) | CPU (s) | level heights |")
    emit("|---|---:|---:|---:|---:|---|")
    for s in r["speed"]:
        emit(f"| {s['lobe']} | {s['levels']} | {s['k']:g} | {s['wall_s']:.3f} | {s['cpu_s']:.3f} | {', '.join(map(str, s['heights']))} |")
    emit()
    it, ct = r["irradiance_time"], r["convert_time"]
    emit(f"Order-2 SH irradiance (projection + 32x64 map): {it['wall_s'] * 1e3:.0f} ms; {ct['what']}: {ct['wall_s'] * 1e3:.0f} ms.")
    emit()
    emit("Error against the brute-force sum over all 524,288 texels (Fraser eq. 2, same lobe normalisation),")
    emit("relative error of luminance: at texel centres of each level's map (the algorithm) and at random")
    emit("directions through bilinear lookups (what a shader sees), 32 directions per level; mean over the")
    emit("7 non-mirror levels of the per-level mean, and the largest single error. Per level: docs/envmaps.md.")
    emit()
    emit("| world | lobe | K | texel mean | texel max | lookup mean | lookup max |")
    emit("|---|---|---:|---:|---:|---:|---:|")
    groups = {}
    for a in r["accuracy"]:
        groups.setdefault((a["world"], a["lobe"], a["k"]), []).append(a)
    for (world, lobe, k), g in groups.items():
        tm = 100 * float(np.mean([a["texel_mean"] for a in g]))
        lm = 100 * float(np.mean([a["lookup_mean"] for a in g]))
        emit(f"| {world} | {lobe} | {k:g} | {tm:.2f} % | {100 * max(a['texel_max'] for a in g):.1f} % | {lm:.2f} % | {100 * max(a['lookup_max'] for a in g):.1f} % |")
    emit()
    emit("Order-2 SH irradiance E(n)/π against the exact irradiance (brute-force sum), 256 normals, luminance:")
    emit()
    emit("| world | peak radiance | mean error | max error |")
    emit("|---|---:|---:|---:|")
    for a in r["irradiance"]:
        emit(f"| {a['world']} | {a['peak']:.0f} | {100 * a['mean']:.1f} % | {100 * a['max']:.0f} % |")
    emit()
    emit(f"Load average {r['load_average'][0]:.1f} before and {r['load_average'][1]:.1f} after, on {r['cpus']} CPUs (other jobs shared the machine).")
    emit()


APPEARANCE_MARKER = "## Appearance preview: "


def appearance_section(emit):
    """Issue #8 end to end: a brush stroke until the preview's pixels are back, and the
    Blender-drawn preview of each model against Cycles (bench/appearance_preview.py, fresh bpy)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "appearance.json"
        subprocess.run([sys.executable, str(ROOT / "bench" / "appearance_preview.py"), "--json", str(out)], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        r = json.loads(out.read_text())
    emit(APPEARANCE_MARKER + "a brush stroke until the preview is drawn, and the preview against Cycles")
    emit()
    emit(f"Blender's gpu module offscreen in background mode ({r['renderer']}: a CPU rasteriser, no GPU lent), a")
    emit(f"{W_PREVIEW}x{W_PREVIEW} frame kept between frames. One dab (`appearance.paint`, roughness, radius 0.2 on a unit UV")
    emit("sphere, into the per-point attribute or a 1024² image texture); then what `appearance_preview.draw_object`")
    emit("does for it before drawing (*preview's work*: the material's state, the batch check, the painted values")
    emit("compared and, after a per-point stroke, uploaded as one texture; a texture stroke is read from the image")
    emit("Blender refreshes); then the draw of the mesh's kept batch and the pixels read back, which waits for the")
    emit("rasteriser (wall time, and process CPU time with llvmpipe's threads). *Redraw* is the same draw again")
    emit("with nothing changed: what llvmpipe itself takes for the mesh. Medians of 7. Goal: within a frame (33 ms).")
    emit()
    emit("| vertices | target | dab (ms) | preview's work (ms) | draw + read-back (ms) | its CPU time (ms) | redraw, nothing changed (ms) | stroke to pixels (ms) | batch rebuilds |")
    emit("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for s in r["strokes"]:
        emit(f"| {s['vertices']:,} | {s['target'].lower()} | {s['paint_ms']:.1f} | {s['prep_ms']:.1f} | {s['draw_ms']:.1f} | {s['draw_cpu_ms']:.1f} | "
             f"{s['redraw_ms']:.1f} | {s['total_ms']:.1f} | {s['batch_rebuilds']} |")
    emit()
    emit("Before the batch was kept (stop 14, batch rebuilt from the attributes on every draw): 24 ms at 8,066")
    emit("vertices and 128 ms at 99,906, per stroke.")
    emit()
    emit("The preview as Blender draws it against a Cycles render (128 samples, no denoising) of the same painted")
    emit("sphere under courtyard.exr, orthographic, relative error of luminance over the pixels with n·v > 0.5")
    emit("(includes Cycles' noise), and the ratio of the means (energy):")
    emit()
    emit("| sphere | roughness | Principled (GGX + albedo table) | Phong | Torrance–Sparrow |")
    emit("|---|---:|---:|---:|---:|")
    groups = {}
    for c in r["cycles"]:
        groups.setdefault((c["case"], c["roughness"]), {})[c["model"]] = c
    for (case, rough), g in groups.items():
        cells = [f"{100 * g[m]['mean_error']:.1f} % (×{g[m]['ratio']:.3f})" for m in ("PRINCIPLED", "PHONG", "TORRANCE_SPARROW")]
        emit(f"| {case} | {rough:g} | " + " | ".join(cells) + " |")
    emit()
    emit(f"Load average {r['load_average'][0]:.1f} before and {r['load_average'][1]:.1f} after, on {r['cpus']} CPUs.")
    emit()


W_PREVIEW = 96

COMPOSITING_MARKER = "## Compositing-stage shape editing: "


def compositing_section(emit):
    """Issue #6: reconstruction stages and recompositing (bench/compositing.py in fresh processes,
    on 1 thread like the paper's single core, and on all threads)."""
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for threads in (1, os.cpu_count()):
            out = Path(tmp) / f"comp{threads}.json"
            env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
            subprocess.run([sys.executable, str(ROOT / "bench" / "compositing.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL, env=env)
            runs[threads] = json.loads(out.read_text())
        loop_json = Path(tmp) / "loop.json"
        loop_run = subprocess.run([sys.executable, str(ROOT / "bench" / "composite_edit_loop.py"), "--json", str(loop_json)],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        edit_loop = json.loads(loop_json.read_text()) if loop_run.returncode == 0 else {"error": loop_run.stderr[-400:]}
    one, many = runs[1], runs[os.cpu_count()]
    emit(COMPOSITING_MARKER + "reconstruction stages and recompositing (Zubiaga et al. 2016)")
    emit()
    emit("Synthetic, exact inputs (bench/compositing.py): an orthographic sphere of the given width whose normals")
    emit("carry a procedural bump (the Gauss map folds, sheets overlap), shaded by a known order-2 SH diffuse")
    emit("environment with 20% of pixels darkened by half (occlusion) plus noise, and a known reflection environment.")
    emit("Medians of 3 runs; `1 thr` = RAYON_NUM_THREADS=1 (the paper's single core), `N thr` = all cores.")
    emit("The paper's single-core i7-4790K timings (Table 1; its image sizes are not given): diffuse 14-184 ms,")
    emit("partial reflection 26-470 ms, hole filling 192-6000 ms. Goal: a tenth of those on this machine.")
    emit()
    emit("| patch | pixels | map | diffuse LS (ms) 1 thr / N thr | diffuse QP (ms) 1 thr / N thr | partial refl. (ms) 1 thr / N thr | hole texels | hole filling (ms) 1 thr / N thr | blur (ms) | coverage |")
    emit("|---|---:|---:|---|---|---|---:|---|---:|---:|")
    for a, b in zip(one["stages"], many["stages"]):
        emit(f"| {a['width']}² {a['region']} | {a['pixels']:,} | 2x{a['env_size']}² | {a['diffuse_ls_ms']:.1f} / {b['diffuse_ls_ms']:.1f} | {a['diffuse_qp_ms']:.1f} / {b['diffuse_qp_ms']:.1f} | "
             f"{a['partial_ms']:.0f} / {b['partial_ms']:.0f} | {a['hole_texels']:,} | {a['fill_ms']:.1f} / {b['fill_ms']:.1f} | {b['blur_ms']:.1f} | {a['coverage']:.0%} |")
    emit()
    emit("Diffuse fit against the true (unoccluded) environment, relative RMS over the sphere, and the largest")
    emit("residual D0 - D(n) (the QP's constraint: never positive):")
    emit()
    emit("| patch | LS rel. RMS | QP rel. RMS | LS max residual | QP max residual | QP active-set steps (R, G, B) | reflection map mean abs. error |")
    emit("|---|---:|---:|---:|---:|---|---:|")
    for a in one["stages"]:
        emit(f"| {a['width']}² {a['region']}, map 2x{a['env_size']}² | {a['diffuse_ls_rel_rms']:.3f} | {a['diffuse_qp_rel_rms']:.3f} | {a['ls_max_residual']:.3f} | {a['qp_max_residual']:.1e} | {', '.join(map(str, a['qp_iterations']))} | {a['reflection_mean_abs_err']:.4f} |")
    emit()
    r1, rn_ = one["recomposite"], many["recomposite"]
    emit(f"Recompositing (eqs. 3-5), {r1['width']}x{r1['height']}, {r1['patches']} patches (SH + 2x{r1['env_size']}² map each),")
    emit(f"{r1['edited_fraction']:.0%} of the pixels edited: {r1['recomposite_ms']:.0f} ms on 1 thread, {rn_['recomposite_ms']:.0f} ms on {os.cpu_count()};")
    emit(f"unmodified normals (every pixel takes the exact-identity path): {rn_['recomposite_identity_ms']:.0f} ms. Goal: under 33 ms.")
    if "glsl_ms" in rn_:
        emit(f"GLSL path (shaders/rokeby_recomposite_frag.glsl, moderngl/EGL on {rn_['glsl_renderer']}; no GPU lent), same frame with uploads and")
        emit(f"read-back: {rn_['glsl_ms']:.0f} ms per frame; largest difference from the Rust core {rn_['glsl_max_rel_diff']:.1e} relative (float32 shader).")
        if "glsl_session_ms" in rn_:
            emit(f"The next frame of an interactive session (RecompositeSession: only the edited normals written): "
                 f"{rn_['glsl_session_ms']:.0f} ms; the draw and read-back alone: {rn_['glsl_draw_only_ms']:.0f} ms (llvmpipe's shading).")
    else:
        emit(f"GLSL path not measured: {rn_.get('glsl_error', 'no result')}.")
    emit(f"Peak memory of the benchmark process after it: {rn_['peak_rss_mb']:.0f} MB ({rn_['inputs_mb']:.0f} MB of it the float32 input buffers).")
    emit()
    emit("*Recomposite Render*'s loop (bench/composite_edit_loop.py: `api.recomposite_exr` on a Cycles frame with three")
    emit("objects and the passes, in bpy): the first edit of the file reads and reconstructs it; each further edit of the")
    emit("same frame (one change in the operator's redo panel) costs the normal edit, eqs. 3-5 and writing the Blender image.")
    if "error" in edit_loop:
        emit(f"Not measured: {edit_loop['error']}")
    else:
        emit()
        emit("| backend | frame | first edit (open) | next edit: normals | eqs. 3-5 | image | total |")
        emit("|---|---|---:|---:|---:|---:|---:|")
        for key, label in (("cpu", "CPU (Rust)"), ("blender_gpu", f"Blender gpu ({edit_loop.get('renderer', '?')})")):
            r = edit_loop.get(key)
            if r is None:
                emit(f"| {label} | not measured: {edit_loop.get(key + '_error', '?')} | | | | | |")
                continue
            emit(f"| {label} | {edit_loop['width']}x{edit_loop['height']}, {r['edited']:,} px edited | {r['first_ms']:.0f} ms ({r['first_open_ms']:.0f}) "
                 f"| {r['edit_ms']:.1f} ms | {r['recomposite_ms']:.0f} ms | {r['show_ms']:.0f} ms | {r['total_ms']:.0f} ms |")
    emit()
    emit(f"Load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (other jobs shared the machine).")
    emit()


HEAVY_MARKER = "## Heavy scenes: "


def heavy_section(emit):
    """Issue 18, problem 5: a depsgraph update in a scene of 3,000 and 10,000 objects with the
    add-on disabled, enabled with no Rokeby data, and enabled with one mirror (bench/heavy_scene.py
    in a fresh process). Not a timed test: printed side by side."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "heavy.json"
        subprocess.run([sys.executable, str(ROOT / "bench" / "heavy_scene.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL)
        rows = json.loads(out.read_text())
    emit(HEAVY_MARKER + "what the add-on costs a depsgraph update")
    emit()
    emit("bench/heavy_scene.py: N small cubes sharing one mesh; one of them moves and `view_layer.update()` is timed")
    emit("(Blender's whole depsgraph update with every handler). Disabled (unregistered) and enabled runs alternate in")
    emit(f'{rows[0]["rounds"]} rounds of {rows[0]["steps"]} updates; medians. "Handler": the CPU time of the add-on\'s own depsgraph handler, steadier on a shared')
    emit("machine. One mirror: a 482-vertex sphere with 2 constraints and a region, unrelated to the object that moves")
    emit('(it is still re-checked every update, which costs the same at any N); "handle move": an update that moves its')
    emit("green handle (the field is recomputed). Goal (issue 18): no Rokeby data within 5% of disabled; with one mirror,")
    emit("no growth with the number of unrelated objects. The handlers keep a registry of what the add-on owns")
    emit("(rokeby.registry) instead of scanning `scene.objects`; what still grows with N is one `len(bpy.data.objects)`")
    emit("per update (a walk of a linked list in C: about 0.4 ms at 10,000 objects).")
    emit()
    emit("| objects | disabled (ms) | enabled, no Rokeby data (ms) | over disabled | handler (ms, % of disabled) | disabled, file with a mirror (ms) | enabled, one mirror (ms) | over disabled | handler (ms, % of disabled) | handle move (ms) | handler (ms) |")
    emit("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        emit(f"| {r['objects']:,} | {r['disabled_ms']:.1f} | {r['no_data_ms']:.1f} | {100 * (r['no_data_ms'] / r['disabled_ms'] - 1):+.1f}% | "
             f"{r['no_data_handler_ms']:.2f} ({100 * r['no_data_handler_ms'] / r['disabled_ms']:.1f}%) | "
             f"{r['disabled_mirror_file_ms']:.1f} | {r['mirror_ms']:.1f} | {100 * (r['mirror_ms'] / r['disabled_mirror_file_ms'] - 1):+.1f}% | "
             f"{r['mirror_handler_ms']:.2f} ({100 * r['mirror_handler_ms'] / r['disabled_mirror_file_ms']:.1f}%) | "
             f"{r['handle_move_ms']:.1f} | {r['handle_move_handler_ms']:.2f} |")
    emit()
    emit(f"Load average {os.getloadavg()[0]:.1f} at the end, on {os.cpu_count()} CPUs. On a shared machine whole updates vary between")
    emit("rounds by more than the add-on's share (the \"over disabled\" columns then move either way); the handler columns are")
    emit("the add-on's own cost, in ms and as a share of the disabled update.")
    emit()


SHADOW_MARKER = "## Shadow boundary editing: "


def shadow_section(emit):
    """Issue #7: silhouettes, handles, a drag step and the shadow mesh on the shared meshes of the
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
    # Issue 22: the live shadow while dragging, per drag step in Blender (bench/shadow_live.py).
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "live.json"
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "addon"), os.environ.get("PYTHONPATH", "")]))
        subprocess.run([sys.executable, str(ROOT / "bench" / "shadow_live.py"), "--json", str(out)], check=True, stdout=subprocess.DEVNULL, env=env)
        live = json.loads(out.read_text())["rows"]
    emit("Live shadow while dragging (issue 22, bench/shadow_live.py, medians of 7 steps): drag = `session.drag`, "
         "step = `shadow.live_step` (shadow mesh by back-substitution, written into the edit key), depsgraph = `view_layer.update()`.")
    emit()
    emit("| paper model | shared mesh | tris | drag (ms) | step (ms) | depsgraph (ms) | per step (ms) |")
    emit("|---|---|---:|---:|---:|---:|---:|")
    for r in live:
        if "error" in r:
            emit(f"| {r['paper']} | {r['mesh']} | {r['triangles']:,} | error: {r['error']} |")
            continue
        emit(f"| {r['paper']} | {r['mesh']} | {r['triangles']:,} | {r['drag_ms']:.1f} | {r['live_step_ms']:.1f} | "
             f"{r['depsgraph_ms']:.1f} | {r['total_ms']:.1f} |")
    emit()


import tradeoff_sections  # noqa: E402

TRADEOFFS = tradeoff_sections.SECTIONS


ROOFLINE_MARKER = "## Field kernels against this machine's roofline"


def roofline_section(emit):
    """Issue 23: the field kernels (f32 lanes: portable, AVX2, AVX-512; the scalar f64 reference)
    beside this machine's own f32 FMA peak and stream-triad bandwidth, measured in the same run by
    rust/rokeby-core/examples/field_roofline.rs, with the goals and the paper's GPU figure."""
    import subprocess

    r = subprocess.run(["cargo", "run", "--quiet", "--release", "-p", "rokeby-core", "--example", "field_roofline"],
                       cwd=ROOT, capture_output=True, text=True, check=True)
    emit(ROOFLINE_MARKER + " (issue 23)")
    emit()
    emit("The per-pixel field (`edited_directions`) and the per-vertex field (`rotation_field`, view-blend output as")
    emit("the add-on writes it) per kernel: `scalar` is the f64 reference (the tests' oracle), the others are the f32")
    emit("lanes this CPU runs (forced with `ROKEBY_SIMD=scalar|portable|avx2|avx512`). GFLOP/s counts the lanes'")
    emit("algorithm (28 flops per constraint, two Newton steps of 160 as measured per block, 70 for r(q) and R r; one constraint is a")
    emit("constant rotation, 70), so its share of the measured peak is the roofline share. `max diff`: the largest angle")
    emit("(rad) from the f64 reference with the exact polar method; `f64 lanes`: the share the lanes hand to the scalar f64")
    emit("path. The goals table: the best kernel against each goal, the paper's GPU, and the memory floor (36 bytes per")
    emit("pixel at the triad rate). Medians of 7 runs; the machine is shared, so")
    emit("instruction counts (callgrind, docs/benchmarks.md below) confirm the ratios.")
    emit()
    emit("```")
    for line in r.stdout.rstrip().splitlines():
        emit(line)
    emit("```")
    emit()


def _refresh_section(emit, out, marker, section):
    """Run one section and put it into docs/benchmarks.md in place of its old text (appended
    when the report has none yet)."""
    start = len(out)
    section(emit)
    if not any(line.startswith("Run: ") for line in out[start:start + 4]):
        # Issue 9: each section says which run it came from.
        out[start + 1:start + 1] = ["", f"Run: {time.strftime('%Y-%m-%d %H:%M')}, `bench/run.py --only` ({os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the end)."]
    doc = ROOT / "docs" / "benchmarks.md"
    old = doc.read_text() if doc.exists() else ""
    new = "\n".join(out[start:]).rstrip("\n") + "\n"
    if marker in old:
        head, _, tail = old.partition(marker)
        rest = tail.split("\n## ", 1)
        doc.write_text(head + new + ("\n## " + rest[1] if len(rest) == 2 else ""))
    elif old:
        doc.write_text(old.rstrip("\n") + "\n\n" + new)
    else:
        doc.write_text("\n".join(out) + "\n")


def main():
    ap = argparse.ArgumentParser(description="Rokeby benchmarks")
    ap.add_argument("--peers", default=None, help="python of .venv-peers (exact geodesics, potpourri3d, libigl, matplotlib)")
    ap.add_argument("--only", choices=["field", "roofline", "geodesic", "addon", "heavy", "render", "viewport", "envmap", "appearance", "compositing", "shadow", *TRADEOFFS], default=None)
    args = ap.parse_args()
    rng = np.random.default_rng(2009)
    out = []

    def emit(line=""):
        print(line, flush=True)
        out.append(line)

    emit("# Rokeby benchmarks")
    emit()
    emit(f"Machine: {machine()}")
    emit()
    if args.peers and args.only is None:
        emit(f"Peers (.venv-peers): {tradeoff_sections.peer_versions(args.peers)}")
        emit()
        emit(f"Run: {time.strftime('%Y-%m-%d %H:%M')}, the whole `make bench` (sections refreshed later with `--only` say so).")
        emit()
    if args.only is None:
        emit(tradeoff_sections.INDEX)
        emit()
    (ROOT / "docs").mkdir(exist_ok=True)
    if args.only == "viewport":
        _refresh_section(emit, out, VIEWPORT_MARKER, viewport_section)
        return
    if args.only == "roofline":
        _refresh_section(emit, out, ROOFLINE_MARKER, roofline_section)
        return
    if args.only == "compositing":
        _refresh_section(emit, out, COMPOSITING_MARKER, compositing_section)
        return
    if args.only == "envmap":
        _refresh_section(emit, out, ENVMAP_MARKER, envmap_section)
        return
    if args.only == "appearance":
        _refresh_section(emit, out, APPEARANCE_MARKER, appearance_section)
        return
    if args.only in TRADEOFFS:
        # Issue 9: one speed-for-accuracy choice (bench/tradeoff_sections.py), with its plot.
        marker, section = TRADEOFFS[args.only]
        _refresh_section(emit, out, marker, lambda e: section(e, args.peers))
        tradeoff_sections.refresh_peers_line(args.peers)
        return
    if args.only == "shadow":
        _refresh_section(emit, out, SHADOW_MARKER, shadow_section)
        return
    if args.only == "heavy":
        _refresh_section(emit, out, HEAVY_MARKER, heavy_section)
        return
    if args.only in ("addon", "render"):
        start = len(out)
        (addon_section if args.only == "addon" else render_section)(emit)
        doc = ROOT / "docs" / "benchmarks.md"
        old = doc.read_text() if doc.exists() else ""
        marker = "## Add-on: " if args.only == "addon" else RENDER_MARKER
        if marker in old:
            # Refresh that section of the full report in place.
            head, _, tail = old.partition(marker)
            rest = tail.split("\n## ", 1)
            after = "\n## " + rest[1] if len(rest) == 2 else ""
            doc.write_text(head + "\n".join(out[start:]).rstrip("\n") + "\n" + after)
        elif old:
            # Not in the report yet: append the section, keep the rest.
            doc.write_text(old.rstrip("\n") + "\n\n" + "\n".join(out[start:]).rstrip("\n") + "\n")
        else:
            doc.write_text("\n".join(out) + "\n")
        return
    if args.only == "geodesic":
        # Refresh that section in place (it used to overwrite the whole report).
        _refresh_section(emit, out, GEODESIC_MARKER, lambda e: geodesic_section(e, args.peers))
        return
    if args.only != "field":
        geodesic_section(emit, args.peers)
        roofline_section(emit)

    # 1. Per-pixel path at the paper's resolution.
    w, h = 1280, 960
    pos, nrm = full_frame_gbuffer(w, h)
    eye = np.array([0.0, -0.6, 1.2], np.float32)
    emit(f"## Per-pixel edited directions, {w}x{h} G-buffer (every pixel on the mirror)")
    emit()
    emit("| constraints K | polar | time (ms) | megapixels/s | paper, GTX 260 (MP/s) |")
    emit("|---:|---|---:|---:|---:|")
    for k in (1, 4, 32):
        c = constraints(rng, k, 0.5)
        for polar in ("exact", "fast"):
            dt = timeit(lambda: rn.edited_directions(pos, nrm, eye, c, polar=polar), repeat=3)
            ref = f"{PAPER[k]}" if k in PAPER else "—"
            emit(f"| {k} | {polar} | {dt * 1e3:.1f} | {w * h / dt / 1e6:.2f} | {ref} |")
    emit()

    # 2. Per-point path on the largest shared mesh.
    meshes = sorted((SHARED / "meshes").glob("*.obj"), key=lambda p: p.stat().st_size)
    big = meshes[-1]
    v, f = load_obj(big)
    emit(f"## Per-point rotation field on {big.name} ({len(v):,} vertices)")
    emit()
    emit("| constraints K | polar | time (ms) | million points/s |")
    emit("|---:|---|---:|---:|")
    for k in (1, 8, 32):
        c = constraints(rng, k, 0, centre=v)
        for polar in ("exact", "fast"):
            dt = timeit(lambda: rn.rotation_field(v, c, polar=polar))
            emit(f"| {k} | {polar} | {dt * 1e3:.2f} | {len(v) / dt / 1e6:.2f} |")
    emit()

    # 3. Polar decomposition variants on the matrices a real field produces.
    c = constraints(rng, 8, 0, centre=v)
    p = v[::2].astype(np.float64)
    pts_sorted = p[np.lexsort((p[:, 0], p[:, 1]))]  # coherent order, like neighbouring pixels
    d2 = np.sum((pts_sorted[:, None, :] - c[None, :, :3]) ** 2, axis=-1)
    keep = d2.min(axis=1) > 0  # points on a constraint take the interpolation branch, not ortho
    pts_sorted, d2 = pts_sorted[keep], d2[keep]
    w_ = 1.0 / d2
    mats = np.einsum("nk,ki,kj->nij", w_ / w_.max(axis=1, keepdims=True), c[:, 6:9].astype(np.float64), c[:, 3:6].astype(np.float64))
    ref = ortho_ref(mats)
    shuffled = rng.permutation(len(mats))
    emit(f"## Polar decomposition (ortho of eq. 5), {len(mats):,} matrices of a real 8-constraint field")
    emit()
    emit("| method | time per matrix (ns) | mean error (rad) | max error (rad) |")
    emit("|---|---:|---:|---:|")
    rows = [
        ("exact: one-sided Jacobi SVD, f64 (Rust)", lambda: rn.ortho(mats, method="exact"), None),
        ("fast: Newton on SO(3), warm start, coherent order (Rust)", lambda: rn.ortho(mats, method="fast"), None),
        ("fast: Newton on SO(3), incoherent (shuffled) order (Rust)", lambda: rn.ortho(mats[shuffled], method="fast"), shuffled),
        ("numpy.linalg.svd batched, f64 (peer)", lambda: ortho_ref(mats), "numpy"),
    ]
    for name, fn, perm in rows:
        dt = timeit(fn, repeat=3)
        res = fn()
        if isinstance(perm, str):
            got = res
            want = ref
        else:
            got = quat_to_matrix(res)
            want = ref if perm is None else ref[perm]
        err = rot_angle(got, want)
        emit(f"| {name} | {dt / len(mats) * 1e9:.0f} | {err.mean():.1e} | {err.max():.1e} |")
    emit()

    # 4. float32 storage against a float64 reference.
    c = constraints(rng, 8, 0, centre=v)
    off = np.min(np.sum((v[:, None, :].astype(np.float64) - c[None, :, :3]) ** 2, axis=-1), axis=1) > 0
    got = quat_to_matrix(rn.rotation_field(v[off], c))
    want = field_matrices(v[off].astype(np.float64), c.astype(np.float64))
    err = rot_angle(got, want)
    emit("## float32 storage versus a float64 reference (numpy SVD), per-point field, K = 8")
    emit()
    emit(f"mean {err.mean():.1e} rad, 99th percentile {np.percentile(err, 99):.1e} rad, max {err.max():.1e} rad over the {int(off.sum()):,} vertices of {big.name} not on a constraint.")
    emit()
    emit("Recommendation: `polar=\"fast\"` (the default of the per-pixel path) gives the exact path's answer")
    emit("to within rounding on coherent inputs and is faster; `polar=\"exact\"` (the per-point default) costs")
    emit("the same on every input and is the reference.")
    emit()
    addon_section(emit)
    heavy_section(emit)
    viewport_section(emit)
    render_section(emit)
    envmap_section(emit)
    appearance_section(emit)
    # Sections that used to exist only through --only (a whole run dropped them from the report).
    compositing_section(emit)
    shadow_section(emit)
    for _marker, section in TRADEOFFS.values():
        section(emit, args.peers)

    docs = ROOT / "docs"
    docs.mkdir(exist_ok=True)
    (docs / "benchmarks.md").write_text("\n".join(out) + "\n")
    print(f"\nwritten to {docs / 'benchmarks.md'}")


if __name__ == "__main__":
    main()
