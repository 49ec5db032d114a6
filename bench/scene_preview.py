"""The viewport preview's scene capture: its cost, and how the preview agrees with Cycles.

1. Capture cost: ``scene_env.capture`` (a Cycles panorama pair from the mirror's centre: colour,
   then distance) of tests/support/scene_preview.py's scene at several widths: seconds (median of
   3) and memory per mirror.
2. Agreement: tests/reflection/blender_scene_preview_check.py (the preview drawn offscreen through
   Blender's gpu module against a Cycles render of the same camera, on the mirror's pixels) for
   several of Blender's bundled HDR worlds, plain and with a constraint whose green handle sits on
   a near cube: mean and 95th percentile of |linear RGB difference|, distance-corrected and
   centre-only lookups.
3. ``--pictures``: docs/scene_preview_render.png (render | preview) and
   docs/scene_preview_parallax.png (centre-only | corrected), from the edited run.

``--json PATH`` writes the rows (bench/sections/reflection.py reads them)."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "bench"))

WIDTHS = (128, 256, 512)
SAMPLES = 16
WORLDS = ("sunset.exr", "forest.exr", "courtyard.exr", "city.exr")


def capture_cost(repeats: int = 3) -> list:
    """In a fresh process (bpy): seconds and bytes per capture at each width."""
    code = f"""
import json, statistics, sys
sys.path.insert(0, {str(ROOT / 'tests')!r})
from support import scene_preview as S
from rokeby.reflection.viewport import scene_env
sc, mirror, _ = S.build(size=16, samples=1)
rows = []
for w in {WIDTHS!r}:
    secs = [scene_env.capture(mirror, sc, width=w, samples={SAMPLES}).seconds for _ in range({repeats})]
    cap = scene_env.current(mirror)
    rows.append({{"width": w, "height": w // 2, "samples": {SAMPLES}, "seconds": statistics.median(secs), "bytes": cap.nbytes}})
print("RESULT " + json.dumps(rows))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[7:])


def shader_cost(width: int = 1280, height: int = 720, k: int = 8, frames: int = 3) -> list:
    """ms per frame of the preview shader (moderngl, headless EGL) with the scene lookup, corrected
    and centre-only, on a ball filling the view: what the march along q + t e costs per pixel."""
    import time

    from support.gl_harness import Renderer, create_context, look_at, perspective
    from support.reference import random_constraints
    from rokeby.reflection.viewport import glsl
    from rokeby.core import latlong

    ctx = create_context()
    lat = np.linspace(-np.pi / 2, np.pi / 2, 65)
    lon = np.linspace(0, 2 * np.pi, 128, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    v = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1).reshape(-1, 3).astype(np.float32)
    tris = np.array([(i * 128 + j, i * 128 + (j + 1) % 128, (i + 1) * 128 + (j + 1) % 128) for i in range(64) for j in range(128)]
                    + [(i * 128 + j, (i + 1) * 128 + (j + 1) % 128, (i + 1) * 128 + j) for i in range(64) for j in range(128)], np.int32)
    r = Renderer(ctx, width, height)
    r.set_mesh(v, v, tris)
    # a capture: objects at 1.5-6 radii over half the directions, the world elsewhere
    u, vv = np.meshgrid((np.arange(512) + 0.5) / 512, (np.arange(256) + 0.5) / 256)
    d = latlong.uv_to_direction(u, vv)
    texels = np.zeros((256, 512, 4), np.float32)
    texels[..., :3] = 0.5 + 0.5 * d
    near = np.sin(7 * d[..., 0]) * np.sin(5 * d[..., 2]) > 0
    texels[..., 3] = np.where(near, 1.0 / (1.5 + 4.5 * (0.5 + 0.5 * d[..., 1])), 0.0)
    r.set_scene_capture(texels, (0.0, 0.0, 0.0))
    eye = np.array([0.0, -2.6, 0.3])
    vp = perspective(40, width / height, 0.1, 100.0) @ look_at(eye, (0, 0, 0))
    rows = random_constraints(np.random.default_rng(7), k, max_edit=0.3, at=v)
    r.set_plan(glsl.plan_field(rows, n_vertices=len(v)))
    out = []
    for parallax in (True, False):
        r.render(vp, eye, glsl.OUT_COLOR, parallax=parallax)
        ts = []
        for _ in range(frames):
            t0 = time.perf_counter()
            r.render(vp, eye, glsl.OUT_COLOR, parallax=parallax, finish=False)
            ctx.finish()
            ts.append(time.perf_counter() - t0)
        out.append({"width": width, "height": height, "k": k, "parallax": parallax, "ms": 1e3 * statistics.median(ts), "renderer": ctx.info["GL_RENDERER"]})
    return out


def agreement(world: str, edited: bool, out: Path) -> dict:
    args = [sys.executable, str(ROOT / "tests" / "reflection" / "blender_scene_preview_check.py"), str(out), f"world={world}"]
    if edited:
        args.append("edited")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT / "tests"), os.environ.get("PYTHONPATH")) if p)}
    r = subprocess.run(args, capture_output=True, text=True, env=env)
    line = next((ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if line is None:
        raise RuntimeError(f"{world}: no result: {r.stderr[-2000:]}")
    return json.loads(line[7:])


def _display(img):
    """Linear HDR to display: x / (1 + x), then the sRGB curve; row 0 at the top."""
    x = np.clip(img / (1.0 + img), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return s[::-1]


def pictures(folder: Path, scale: int = 3):
    from compositing_validate import write_png

    ims = {k: np.load(folder / f"{k}.npy") for k in ("render", "corrected", "centre")}
    mask = np.load(folder / "mask.npy")
    # the preview has nothing outside the mirror: show the render's pixels there
    outside = ~(np.load(folder / "corrected.npy").any(-1))
    for k in ("corrected", "centre"):
        ims[k] = np.where(outside[..., None], ims["render"] * 0.35, ims[k])
    gap = np.ones((ims["render"].shape[0], 2, 3))
    up = lambda a: np.repeat(np.repeat(a, scale, 0), scale, 1)  # noqa: E731
    write_png(ROOT / "docs" / "scene_preview_render.png", up(np.concatenate([_display(ims["render"]), gap, _display(ims["corrected"])], 1)))
    write_png(ROOT / "docs" / "scene_preview_parallax.png", up(np.concatenate([_display(ims["centre"]), gap, _display(ims["corrected"])], 1)))
    return int(mask.sum())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", default=None)
    ap.add_argument("--pictures", action="store_true", help="write docs/scene_preview_*.png")
    ap.add_argument("--worlds", nargs="*", default=list(WORLDS))
    args = ap.parse_args()
    rows = {"capture": capture_cost(), "agreement": [], "shader": shader_cost()}
    for row in rows["shader"]:
        print(f"shader {row['width']}x{row['height']}, K = {row['k']}, {'corrected' if row['parallax'] else 'centre-only'}: {row['ms']:.0f} ms ({row['renderer']})")
    for c in rows["capture"]:
        print(f"capture {c['width']}x{c['height']}, {c['samples']} samples: {c['seconds']:.2f} s, {c['bytes'] / 2**20:.2f} MiB")
    with tempfile.TemporaryDirectory() as tmp:
        for world in args.worlds:
            for edited in (False, True):
                out = Path(tmp) / f"{world}-{edited}"
                out.mkdir()
                res = agreement(world, edited, out)
                if "skip" in res:
                    print(f"{world}: skipped: {res['skip']}")
                    continue
                row = {"world": world, "edited": edited, "corrected": res["corrected"], "centre": res["centre"],
                       "renderer": res["renderer"], "pixels": res["mirror_pixels"]}
                rows["agreement"].append(row)
                print(f"{world} {'edited' if edited else 'plain'}: corrected mean {res['corrected']['mean']:.3f} p95 {res['corrected']['p95']:.3f}; "
                      f"centre-only mean {res['centre']['mean']:.3f} p95 {res['centre']['p95']:.3f}")
                if args.pictures and edited and world == args.worlds[0]:
                    pictures(out)
    if args.json:
        Path(args.json).write_text(json.dumps(rows))


if __name__ == "__main__":
    main()
