"""Appearance painting: a stroke and the preview's redraw."""

from __future__ import annotations

import json
import subprocess
import tempfile
import sys
from pathlib import Path


from common import ROOT  # noqa: E402


APPEARANCE_MARKER = "## Appearance preview: "


W_PREVIEW = 96


def appearance_section(emit):
    """Appearance painting end to end: a brush stroke until the preview's pixels are back, and the
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
