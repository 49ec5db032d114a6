"""Sections of docs/benchmarks.md for the speed-for-accuracy choices (bench/run.py
--only sh_order | qp | holefill | precision | reflmap). Each runs its measurement in a fresh process
(bench/tradeoffs.py, bench/reflmap_vs_rt.py), emits a table with the run's date, writes a
time-against-error PNG under docs/bench/ with matplotlib from .venv-peers (--peers; without it the
old PNG stays), and ends with a recommendation."""

from __future__ import annotations

import datetime
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PLOTS = ROOT / "docs" / "bench"

SH_MARKER = "## SH order of the irradiance: "
QP_MARKER = "## Diffuse fit: QP versus least squares"
HOLEFILL_MARKER = "## Hole-filling resolution: "
PRECISION_MARKER = "## Polar method and float32 storage: "
REFLMAP_MARKER = "## Reflection map versus ray traced render: "


def _stamp():
    return f"Run: {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')} ({os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start; a shared machine)."


def _measure(script, args, peers=None):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r.json"
        cmd = [sys.executable, str(ROOT / "bench" / script), *args, "--json", str(out)]
        if peers:
            cmd += ["--peers", peers]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        return json.loads(out.read_text())


def _plot(peers, name, spec, emit, alt):
    """Write docs/bench/<name>.png with the peers' matplotlib and link it."""
    png = PLOTS / f"{name}.png"
    if peers:
        PLOTS.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            sp = Path(tmp) / "spec.json"
            sp.write_text(json.dumps(spec))
            subprocess.run([peers, str(ROOT / "bench" / "plot_tradeoffs.py"), str(sp), str(png)], check=True)
    if png.exists():
        emit(f"![{alt}](bench/{png.name})")
        emit()


def peer_versions(peers):
    """'numpy 2.x, scipy ..., pygeodesic ..., ...' of the peers' environment."""
    code = ("import importlib.metadata as m\n"
            "out=[]\n"
            "for p in ('numpy','scipy','potpourri3d','libigl','pygeodesic','quadprog','matplotlib'):\n"
            "    try: out.append(f'{p} {m.version(p)}')\n"
            "    except Exception: out.append(f'{p} not installed')\n"
            "import platform; print('Python '+platform.python_version()+', '+', '.join(out))")
    return subprocess.run([peers, "-c", code], check=True, capture_output=True, text=True).stdout.strip()


def refresh_peers_line(peers):
    """Keep a 'Peers (.venv-peers): ...' line under the Machine line of docs/benchmarks.md."""
    if not peers:
        return
    doc = ROOT / "docs" / "benchmarks.md"
    lines = doc.read_text().split("\n")
    line = f"Peers (.venv-peers): {peer_versions(peers)}"
    lines = [x for x in lines if not x.startswith("Peers (.venv-peers):")]
    for i, x in enumerate(lines):
        if x.startswith("Machine:"):
            lines[i + 1:i + 1] = ["", line] if lines[i + 1].strip() else ["", line]
            break
    text = "\n".join(lines)
    while "\n\n\n" in text:
        text = text.replace("\n\n\n", "\n\n")
    doc.write_text(text)


# --- SH order -------------------------------------------------------------------------------------

def sh_order_section(emit, peers=None):
    r = _measure("tradeoffs.py", ["sh"])
    emit(SH_MARKER + "order 0 / 1 / 2 / 3 / 4 against the exact irradiance")
    emit()
    emit(_stamp())
    emit()
    emit("E(n)/π of the eight HDR worlds bpy ships against the brute-force irradiance (rokeby.envmaps.reference,")
    emit(f"'lambert'), {r['normals']} Fibonacci normals, relative error of luminance. Orders 0 and 1 are the core's order-2")
    emit("projection (rokeby_native.envmaps.irradiance) truncated to its first 1 and 4 coefficients (the same projection, so")
    emit("the same fit time); orders 3 and 4 are a numpy projection of the lat-long texels (bench/tradeoffs.py), not in the")
    emit("core; its order-2 twin reproduces the core's order 2 to the printed digits. Order 3 equals order 2 for irradiance:")
    emit("the clamped-cosine coefficient Â₃ is 0 (Ramamoorthi & Hanrahan 2001), measured here too. The numpy fit times are")
    emit("a numpy implementation's (Python-level basis over 524,288 texels), not what a core order 4 would cost.")
    emit("Evaluation: numpy, per normal, on this CPU")
    emit("(a shader evaluates the 9-term quadratic in a few multiply-adds).")
    emit()
    emit("| order (coefficients) | how | fit (ms), mean over worlds | evaluate (µs / normal) | mean error, mean over worlds | worst world's mean | largest error |")
    emit("|---|---|---:|---:|---:|---:|---:|")
    groups = {}
    for x in r["rows"]:
        groups.setdefault((x["order"], x["how"]), []).append(x)
    pts = {}
    for (order, how), g in groups.items():
        fit = float(np.mean([x["fit_ms"] for x in g]))
        ev = float(np.mean([x["eval_us_per_normal"] for x in g]))
        mean = float(np.mean([x["mean"] for x in g]))
        worst = max(g, key=lambda x: x["mean"])
        big = max(x["max"] for x in g)
        emit(f"| {order} ({(order + 1) ** 2}) | {how} | {fit:.0f} | {ev:.2f} | {100 * mean:.1f} % | {100 * worst['mean']:.1f} % ({worst['world']}) | {100 * big:.0f} % |")
        pts.setdefault(how.startswith("numpy"), []).append((fit, mean, order))
    emit()
    emit("Per world, mean error by order:")
    emit()
    worlds = list(dict.fromkeys(x["world"] for x in r["rows"]))
    emit("| world | " + " | ".join(f"order {o}" for o in (0, 1, 2, 3, 4)) + " |")
    emit("|---|" + "---:|" * 5)
    for w in worlds:
        cell = {}
        for x in r["rows"]:
            if x["world"] == w and (x["order"] not in cell or not x["how"].startswith("numpy")):
                cell[x["order"]] = x["mean"]
        emit(f"| {w} | " + " | ".join(f"{100 * cell[o]:.1f} %" for o in (0, 1, 2, 3, 4)) + " |")
    emit()
    emit("Paper (Ramamoorthi & Hanrahan 2001): 9 coefficients (order 2) give average errors of about 1% on their light")
    emit("probes (maximum under 5%; 9% bound under their assumptions). Here order 2 meets that on soft worlds (sunset 1.6%)")
    emit("and not on worlds with a small, very bright sun or lamps (studio, sunrise: 12-24% mean), whose irradiance has")
    emit("energy above band 2; order 4 roughly halves those errors. No peer library fits SH irradiance here.")
    emit()
    series = []
    for is_np, name in ((False, "core projection (orders 0-2; 0 and 1 truncated)"), (True, "numpy projection (orders 2, 3, 4)")):
        p = sorted(pts.get(is_np, []), key=lambda t: t[2])
        if p:
            series.append({"name": name, "x": [t[0] for t in p], "y": [100 * t[1] for t in p], "labels": [f"order {t[2]}" for t in p], "line": False})
    _plot(peers, "sh_order", {"title": "SH irradiance: fit time against error (mean over 8 worlds)", "xlabel": "fit time (ms)",
                              "ylabel": "mean relative error (%)", "logy": True, "logx": True, "series": series}, emit, "SH order: time against error")
    by = {(o, h.startswith("numpy")): float(np.mean([x["fit_ms"] for x in g])) for (o, h), g in groups.items()}
    err = {o: float(np.mean([x["mean"] for x in g])) for (o, h), g in groups.items() if not h.startswith("numpy") or o > 2}
    emit(f"Recommendation: keep order 2 (the core's; 9 coefficients, {by[(2, False)]:.0f} ms to fit a 1024x512 world): orders 0 and 1 are")
    emit(f"{err[1] / err[2]:.0f}-{err[0] / err[2]:.0f}x worse for no saving in the fit. Use a higher order (here: numpy, order 4, {by[(4, True)] / by[(2, False)]:.0f}x the fit time) only for")
    emit("worlds dominated by a small bright source, where order 2 is off by 10-25% on average; order 3 buys nothing")
    emit("(Â₃ = 0).")
    emit()


# --- QP versus least squares ------------------------------------------------------------------------

def qp_section(emit, peers=None):
    r = _measure("tradeoffs.py", ["qp"], peers)
    emit(QP_MARKER + " (compositing diffuse fit), with the numpy and quadprog peers")
    emit()
    emit(_stamp())
    emit()
    emit("The order-2 SH fit of eq. 1 (Zubiaga et al. 2016) on the bumpy sphere of bench/compositing.py (20% of pixels")
    emit("darkened by half, noise 0.01): least squares, or the QP that keeps the fit above every pixel (D(n) ≥ D0, §3.1).")
    emit("rokeby_native.compositing.sh_fit (median of 3, all cores) against numpy.linalg.lstsq and quadprog.solve_qp (Goldfarb-Idnani,")
    emit("dense, one run each, .venv-peers) on the same pixels, per channel. Error: relative RMS against the true")
    emit("(unoccluded) environment over the sphere; max residual: the largest D0 - D(n) (the QP's constraint).")
    emit()
    emit("| sphere | pixels | solver | time (ms) | rel. RMS | max residual |")
    emit("|---|---:|---|---:|---:|---:|")
    series = {}
    for x in r["rows"]:
        if "error" in x:
            emit(f"| {x['width']}² | {x['pixels']:,} | {x['solver']} | fails: {x['error']} | | |")
            continue
        emit(f"| {x['width']}² | {x['pixels']:,} | {x['solver']} | {x['ms']:.1f} | {x['rel_rms']:.4f} | {x['max_residual']:.1e} |")
        s = series.setdefault(x["solver"], {"name": x["solver"], "x": [], "y": [], "labels": [], "line": True})
        s["x"].append(x["ms"])
        s["y"].append(x["rel_rms"])
        s["labels"].append(f"{x['width']}²")
    emit()
    emit("The paper (single-core i7-4790K, Table 1; QP, image sizes not given): diffuse 14-184 ms.")
    emit("quadprog and rokeby's QP reach the same optimum (rel. RMS equal to 4 digits; both keep the constraint")
    t = {(x["width"], x["solver"]): x["ms"] for x in r["rows"] if "ms" in x}
    ws = sorted({x["width"] for x in r["rows"]})

    def ratio(a_, b_):
        v = [t[(w, a_)] / t[(w, b_)] for w in ws if (w, a_) in t and (w, b_) in t]
        return f"{min(v):.1f}-{max(v):.1f}x" if v else "?"
    ls_, qp_, np_, quad_ = "rokeby_native.compositing.sh_fit('ls')", "rokeby_native.compositing.sh_fit('qp')", "numpy.linalg.lstsq (peer)", "quadprog.solve_qp (peer)"
    emit(f"to rounding); rokeby's least squares is {ratio(np_, ls_)} faster than numpy's lstsq. The QP is not consistently more accurate")
    emit("against the truth than least squares here (better at 512², worse at 256² and 1024²): its constraint holds")
    emit("the fit up to the brightest, noisiest pixels; what it buys is a fit that never lies below an unoccluded pixel,")
    emit("which is what the compositing edit's α_D (occlusion) factor needs.")
    emit()
    _plot(peers, "qp_vs_ls", {"title": "Diffuse SH fit: time against error", "xlabel": "time (ms)", "ylabel": "relative RMS against the true environment",
                              "logx": True, "series": list(series.values())}, emit, "QP versus least squares: time against error")
    emit("Recommendation: use the QP (`method='qp'`, the default of rokeby.compositing.reconstruct) when the passes carry")
    emit(f"occlusion (AO, contact shadows): it costs {ratio(qp_, ls_)} least squares and is {ratio(quad_, qp_)} faster than quadprog on the same QP. Use")
    emit("least squares (`method='ls'`) for unoccluded or already-divided-by-AO inputs, or for interactive previews.")
    emit()


# --- hole-filling resolution -----------------------------------------------------------------------

def holefill_section(emit, peers=None):
    r = _measure("tradeoffs.py", ["holefill"])
    emit(HOLEFILL_MARKER + "map size against time and error of the harmonic fill")
    emit()
    emit(_stamp())
    emit()
    emit("rokeby_native.compositing.fill_holes on a dual-paraboloid map (2 x S x S) holding a known smooth function of direction")
    emit("(bench/tradeoffs.py `known`, the reflection environment of bench/compositing.py), with a hole of two caps")
    emit(f"(60° around +x, across the faces' equator, and 35° around +z). Error: mean and max |filled - known| at {r['hole_dirs']:,}")
    emit("random directions in the hole, through rokeby_native.compositing.envmap_lookup (values ~0.2-1). The last column checks the")
    emit("map convention: the unfilled full map looked up at random directions. Median of 3 (512: one run).")
    emit()
    emit("| map | hole texels | fill (ms) | mean error | max error | full-map lookup error |")
    emit("|---|---:|---:|---:|---:|---:|")
    for x in r["rows"]:
        emit(f"| 2x{x['size']}² | {x['hole_texels']:,} | {x['ms']:.1f} | {x['mean_abs']:.4f} | {x['max_abs']:.3f} | {x['full_map_lookup_err']:.1e} |")
    emit()
    emit("The error does not go to zero: the fill is harmonic, the known function is not, so beyond 64² the error is the")
    emit("model's, not the grid's (docs/compositing.md: a harmonic test function is reproduced to 6e-4). The paper")
    emit("(Zubiaga et al. 2016, Table 1, single core): hole filling 192-6000 ms, map size not given. No peer here.")
    emit()
    rows = r["rows"]
    _plot(peers, "holefill", {"title": "Harmonic hole filling: time against error", "xlabel": "fill time (ms)", "ylabel": "mean |error| in the hole",
                              "logx": True, "series": [{"name": "rokeby_native.compositing.fill_holes", "x": [x["ms"] for x in rows],
                                                        "y": [x["mean_abs"] for x in rows], "labels": [f"2x{x['size']}²" for x in rows]}]},
          emit, "hole filling: time against error")
    emit("Recommendation: 128² per face (the default `env_size` of reconstruct) : the fill error is within a few percent")
    emit("of its limit from 64² on, and the cost grows ~4-5x per doubling (0.7-1 s at 512² in our runs). Go to 256² only when the covered")
    emit("part of the map needs the detail (sharp reflections), not for the holes.")
    emit()


# --- polar method and float32 ----------------------------------------------------------------------

def precision_section(emit, peers=None):
    r = _measure("tradeoffs.py", ["precision"])
    emit(PRECISION_MARKER + f"per-point field on {r['mesh']}, K = {r['k']}")
    emit()
    emit(_stamp())
    emit()
    emit(f"{r['points']:,} vertices not on a constraint. Error: rotation angle against the float64 numpy reference")
    emit("(tests/support/reference.py: eq. 5 summed in float64, batched numpy SVD); for rokeby_native.reflection.ortho, against numpy's SVD of")
    emit("the same float64 matrices (coherent: vertices sorted along y then x, like neighbouring pixels). Medians of 5.")
    emit()
    emit("| what | time (ns / point) | mean error (rad) | 99th pct (rad) | max error (rad) |")
    emit("|---|---:|---:|---:|---:|")
    for x in r["rows"]:
        emit(f"| {x['what']} | {x['ns_per_point']:.0f} | {x['mean']:.1e} | {x['p99']:.1e} | {x['max']:.1e} |")
    emit()
    emit("The float32 path's error (~5e-8 rad at most) is float32 rounding of the stored quaternions; float64 (numpy) costs")
    emit("7-17x the time and changes nothing visible (1e-7 rad is far below a pixel). The paper (Ritschel et al. 2009) uses")
    emit("float32 on the GPU and gives no error figure. Peer: numpy's batched SVD (the reference).")
    emit()
    series = []
    for x in r["rows"]:
        series.append({"name": x["what"][:60], "x": [x["ns_per_point"]], "y": [max(x["max"], 1e-12)], "line": False,
                       "labels": ["reference (error 0)" if x["max"] == 0 else ""]})
    _plot(peers, "precision", {"title": "Polar method and float32: time against max error (0 drawn at 1e-12)", "xlabel": "ns per point",
                               "ylabel": "max rotation error (rad)", "logx": True, "logy": True, "series": series}, emit,
          "polar method and float32: time against error")
    emit("Recommendation: keep float32 storage and `polar='fast'` (the per-pixel default); use `polar='exact'` when the")
    emit("input order is incoherent (random points) and you want a cost that does not depend on it. Float64 is not worth")
    emit("its cost anywhere in Rokeby.")
    emit()


# --- reflection map versus ray tracing --------------------------------------------------------------

def reflmap_section(emit, peers=None, quick=False):
    r = _measure("reflmap_vs_rt.py", ["--quick"] if quick else [])
    emit(REFLMAP_MARKER + "Cycles, time against error, map resolutions 256-2048")
    emit()
    emit(_stamp())
    emit()
    emit(f"bench/reflmap_vs_rt.py: a chrome ball under the forest HDR world, nothing near it, {r['size']}x{r['size']} pixels,")
    emit(f"Cycles CPU ({r['threads'] or 'all'} threads, Blender {r['blender']}), no denoising. Reference: the ball ray traced at 256 samples.")
    emit("Reflection maps: captured once per resolution (16 samples; the capture hides the ball, so roughness 0 and 0.35 share it),")
    emit("then the ball rendered with the map lookup at 16 samples. Error: mean |pixel - reference| on the ball, 8-bit PNG values")
    emit("in 0-1. One run each: tiny renders are dominated by Cycles' scene setup, and the machine is shared (±20 %).")
    emit()
    emit("| roughness | mode | setting | render (s) | capture (s) | of which Cycles (s) | mean error |")
    emit("|---:|---|---|---:|---:|---:|---:|")
    series = {}
    for x in r["rows"]:
        cap = "" if x["capture_s"] is None else f"{x['capture_s']:.1f}"
        capr = "" if x.get("capture_render_s") is None else f"{x['capture_render_s']:.1f}"
        emit(f"| {x['roughness']:g} | {x['mode']} | {x['setting']} | {x['render_s']:.1f} | {cap} | {capr} | {x['error']:.4f} |")
        if x["error"] == 0.0:
            continue
        key = f"{x['mode']}, roughness {x['roughness']:g}"
        is_map = x["capture_s"] is not None
        s = series.setdefault(key, {"name": key + (" (render only)" if is_map else ""), "x": [], "y": [], "labels": [], "line": not is_map})
        s["x"].append(x["render_s"])
        s["y"].append(x["error"])
        s["labels"].append("" if is_map else x["setting"].split(",")[0])
        if is_map:
            k2 = f"reflection map incl. capture, roughness {x['roughness']:g}"
            s2 = series.setdefault(k2, {"name": k2, "x": [], "y": [], "labels": []})
            s2["x"].append(x["render_s"] + x["capture_s"])
            s2["y"].append(x["error"])
            s2["labels"].append(x["setting"].split(" map")[0])
    emit()
    emit("At this size every render takes 1-3 s, mostly Cycles' setup, so render times barely separate the modes; the error")
    emit("does. Sharp mirror: a map rendered at 16 samples is about as close to the reference as ray tracing at 64; the error")
    emit("grows slightly with the map's resolution, because a small map's bilinear lookup pre-filters the sharp reflection")
    emit("like the reference's anti-aliasing, while a large one's detail aliases at 16 samples on a 96-pixel ball. Rough")
    emit("metal: the map stays at the error of its blurred level's approximate lobe (about that of ray tracing at 16")
    emit("samples) at every resolution; ray tracing keeps converging (64 samples halve it). Capture time grows with the map.")
    emit()
    emit("The paper (Ritschel et al. 2009, §6.3) renders with reflection maps on the GPU and gives no time-against-error")
    emit("figure for them; no peer renderer here.")
    emit()
    _plot(peers, "reflmap_vs_rt", {"title": "Reflection map vs ray traced (Cycles, tiny): time against error", "xlabel": "time (s)",
                                   "ylabel": "mean |error| against 256 spp", "logx": True, "series": list(series.values())},
          emit, "reflection map versus ray tracing: time against error")
    emit("Recommendation: ray trace (the default) unless renders must be fast and noise-free with a static scene and")
    emit("nothing near the mirror: then capture once at 256x128-512x256 for a sharp mirror (1024x512 only when the mirror")
    emit("fills much of a large frame: a map needs about as many texels as the mirror has pixels), and accept the")
    emit("approximate lobe for rough metal, which more map resolution does not improve; for accurate rough metal, ray")
    emit("trace with more samples. Never use the map when near objects or self-reflections matter")
    emit("(docs/reflection_maps.md).")
    emit()


# --- per-vertex versus per-pixel field --------------------------------------------------------------

FIELD_MARKER = "## Per-vertex versus per-pixel rotation field: "


def field_section(emit, peers=None):
    r = _measure("tradeoffs.py", ["field"])
    emit(FIELD_MARKER + f"spot.obj subdivided 0-3 times, K = {r['k']}")
    emit()
    emit(_stamp())
    emit()
    emit("Per vertex: rokeby_native.reflection.rotation_field at the vertices (what the add-on writes to the `rokeby_rotation`")
    emit("attribute), interpolated across each triangle (barycentric nlerp of the quaternions; a renderer does this")
    emit(f"for free, here numpy). Per pixel: rotation_field at every one of {r['pixels']:,} random surface points")
    emit("(area-weighted: a 1280x960 frame full of mirror; the viewport shader's way, and the paper's). Error: rotation")
    emit("angle between the two at those points (4 asin(|Δq|/2), exact for small angles). Same polar ('exact') for both.")
    emit()
    emit("| subdivisions | vertices | per vertex: field (ms) | + interpolation, numpy (ms) | per pixel: field (ms) | mean error (rad) | 99th pct (rad) | max error (rad) |")
    emit("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for x in r["rows"]:
        emit(f"| {x['level']} | {x['vertices']:,} | {x['per_vertex_ms']:.1f} | {x['interp_ms']:.0f} | {x['per_pixel_ms']:.0f} | {x['mean']:.1e} | {x['p99']:.1e} | {x['max']:.1e} |")
    emit()
    emit("The per-vertex error falls about 4x per subdivision (h²); the field's steepest parts are next to the")
    emit("constraints. The paper (Ritschel et al. 2009) evaluates per pixel on a GTX 260: 24.5 MP/s with 1 constraint,")
    emit("18.5 with 32 (this machine's CPU per-pixel rates: the per-pixel table above). No peer implements this field.")
    emit()
    rows = r["rows"]
    _plot(peers, "field_vertex_pixel", {"title": "Per-vertex vs per-pixel field (spot, 1280x960 points)", "xlabel": "time (ms)",
                                        "ylabel": "mean rotation error against per pixel (rad)", "logx": True, "logy": True,
                                        "series": [{"name": "per vertex (field only; interpolation is the renderer's)", "x": [x["per_vertex_ms"] for x in rows],
                                                    "y": [x["mean"] for x in rows], "labels": [f"{x['vertices']:,} verts" for x in rows]},
                                                   {"name": "per pixel (reference, error 0 drawn at 1e-7)", "x": [float(np.median([x["per_pixel_ms"] for x in rows]))],
                                                    "y": [1e-7], "labels": ["1280x960"], "line": False}]},
          emit, "per-vertex versus per-pixel field: time against error")
    emit("Recommendation: per vertex (the add-on's attribute, the default for renders) once the mirror has ~10k+")
    emit("vertices where it is curved: the error is then below 3e-4 rad on average (a few hundredths of a degree)")
    emit("at a small fraction of the per-pixel cost, and it is paid once per edit, not per frame. Use the per-pixel")
    emit("path (viewport shader, `edited_directions`) for coarse meshes, for constraints close together, or when the")
    emit("edit must not depend on the tessellation.")
    emit()


REPRESENTATION_MARKER = "## What the render reads: "


def representation_section(emit, peers=None):
    r = _measure("tradeoffs.py", ["representation"])
    emit(REPRESENTATION_MARKER + "representations of the field, render against preview")
    emit()
    emit(_stamp())
    emit()
    emit("A renderer reads the field from mesh data and interpolates it across each triangle; the viewport preview")
    emit("evaluates it per pixel (`edited_directions`, eq. 7 towards r rᵀ). Each row emulates one way of storing it:")
    emit(f"barycentric interpolation at {r['samples']:,} random points of the triangles facing the eye (area-weighted,")
    emit("smooth normals), against the per-pixel field there; points whose edited direction is below the surface are")
    emit("left out (renders fold them, the status counts them apart). Two constraints, eye (0, −4, 0); the region is")
    emit("a Euclidean sphere of radius 0.9 with a 0.5 border; the plane has ±170° edits (121 vertices). Update: the")
    emit("native call plus the numpy conversion to what is stored, medians of 3 (the add-on then writes it with")
    emit("foreach_set). Memory: what is stored per mirror. Eye-dependent: must be recomputed when the camera moves.")
    emit("The add-on's own Cycles renders agree with these figures (tests/reflection/test_wysiwyg.py).")
    emit()
    emit("Goal: render against preview, 99th percentile under 1° on a ~2k-vertex sphere with and without a")
    emit("region and on the ±170° plane.")
    emit()
    emit("| mesh | vertices | region | representation | p99 (°) | goal p99 (°) | max (°) | > 5° | update (ms) | memory (bytes) | eye-dependent |")
    emit("|---|---:|---|---|---:|---|---:|---:|---:|---:|---|")
    for x in r["rows"]:
        goal = ("< 1: met" if x["p99"] < 1.0 else "< 1: missed") if x["vertices"] in (1986, 121) else "—"
        emit(f"| {x['mesh']} | {x['vertices']:,} | {'yes' if x['region'] else 'no'} | {x['representation']} | {x['p99']:.2f} | {goal} | {x['max']:.2f} | "
             f"{100 * x['over_5']:.1f}% | {x['update_ms']:.1f} | {x['bytes']:,} | {x['eye_dependent']} |")
    emit()
    emit("The pick: the view-independent parts (the region's rotation R as a quaternion, per face corner kept in one")
    emit("hemisphere per polygon where a polygon straddles the seam, else per vertex at a quarter of the memory shown;")
    emit("and the weight a, or the border ramp for one Euclidean region), with eq. 7 formed in")
    emit("closed form per shading point by the render nodes. It is the only stored form that follows the preview")
    emit("inside a region's border (where the blend towards r rᵀ depends on each pixel's r), it does not tear at")
    emit("half turns (rotation vectors do: ~100° on the ±170° plane), it needs no recomputation when the camera")
    emit("moves, and its error falls as h² with the mesh (rows for 202 → 32k vertices). It costs 24 bytes per face")
    emit("corner. The edited direction per vertex is cheaper but depends on the eye and is 4x further off in the")
    emit("border; the whole field per pixel is what the viewport shader does, but Cycles nodes would need a node tree")
    emit("per mirror rebuilt on every drag. Where the interpolation error stays above 1° (the 202-vertex sphere),")
    emit("the add-on's status says so with its own estimate of this figure.")
    emit()


INDEX = """Speed against accuracy, one section each (table, time-against-error plot, peers, papers, recommendation):
geodesic method (Geodesic distances), per-vertex versus per-pixel field, polar method and float32 versus float64
(Polar method and float32 storage), reflection map versus ray traced render and map resolutions, SH order,
QP versus least squares, hole-filling resolution; also the prefiltering ring density K (Environment maps, table only)."""


SECTIONS = {
    "sh_order": (SH_MARKER, sh_order_section),
    "qp": (QP_MARKER, qp_section),
    "holefill": (HOLEFILL_MARKER, holefill_section),
    "precision": (PRECISION_MARKER, precision_section),
    "reflmap": (REFLMAP_MARKER, reflmap_section),
    "field_vertex_pixel": (FIELD_MARKER, field_section),
    "render_representation": (REPRESENTATION_MARKER, representation_section),
}
