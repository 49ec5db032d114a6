"""Environment maps: conversions, lookups, SH irradiance and prefiltering."""

from __future__ import annotations

import json
import subprocess
import tempfile
import sys
from pathlib import Path

import numpy as np


from common import ROOT  # noqa: E402


ENVMAP_MARKER = "## Environment maps: "


def envmap_section(emit):
    """prefiltering the HDR worlds bpy ships, speed and error against the seed's
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
    emit("7 non-mirror levels of the per-level mean, and the largest single error. Per level: \"Environment maps: measured errors per level\" below.")
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
