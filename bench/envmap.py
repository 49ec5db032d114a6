"""Benchmark: environment-map prefiltering on the HDR worlds bpy ships.

* speed: 8 prefiltered levels of a 1024x512 world (GGX roughness 0, 1/7, ..., 1; Phong and
  Torrance–Sparrow ladders too), wall and CPU time, for K = 4, 6 (default), 8 texels per ring radius;
* accuracy: each level against the seed's brute-force sum over all 524,288 texels (Fraser eq. 2),
  at texel centres of the level's map (the algorithm) and at random directions through bilinear
  lookups (what a shader sees); relative error of luminance;
* SH irradiance (order 2) against the exact brute-force irradiance on all eight worlds.

    python bench/envmap.py [--json OUT] [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np

from rokeby import envmaps

WORLDS = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")
LUM = np.array([0.2126, 0.7152, 0.0722])
LADDERS = {
    "ggx": list(envmaps.ROUGHNESS_LEVELS),
    "phong": [4096.0, 1024.0, 256.0, 64.0, 16.0, 4.0, 1.0, 0.0],
    "torrance_sparrow": [0.0, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.7],
}


def fibonacci(n):
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    a = np.pi * (3 - np.sqrt(5)) * np.arange(n)
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=-1)


def texel_dirs(h, w, rows, cols):
    """Directions through texel centres of an H×W lat-long map (Blender's convention, row 0 top)."""
    u = (cols + 0.5) / w
    v = 1 - (rows + 0.5) / h
    phi = (0.5 - u) * 2 * np.pi
    lat = (v - 0.5) * np.pi
    return np.stack([np.cos(lat) * np.cos(phi), np.cos(lat) * np.sin(phi), np.sin(lat)], axis=-1)


def timed(fn, repeat):
    fn()
    walls, cpus = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return statistics.median(walls), statistics.median(cpus)


def rel(got, ref):
    g, r = np.asarray(got, np.float64) @ LUM, np.asarray(ref, np.float64) @ LUM
    e = np.abs(g - r) / np.maximum(np.abs(r), 1e-12)
    return float(e.mean()), float(e.max())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", default=None)
    ap.add_argument("--quick", action="store_true", help="fewer worlds and directions")
    args = ap.parse_args()
    worlds = {n: envmaps.read_exr(envmaps.studio_world(n)) for n in WORLDS}
    out = {"cpus": os.cpu_count(), "speed": [], "accuracy": [], "irradiance": []}
    load0 = os.getloadavg()[0]

    # Speed: 8 levels of a 1024x512 world.
    im = worlds["sunset"]
    for lobe, ladder in LADDERS.items():
        for k in ((4.0, 6.0, 8.0) if lobe == "ggx" else (6.0,)):
            wall, cpu = timed(lambda: envmaps.prefilter(im, lobe, ladder, texels_per_radius=k), 3 if args.quick else 5)
            shapes = [lv.shape[0] for lv in envmaps.prefilter(im, lobe, ladder, texels_per_radius=k)]
            out["speed"].append({"lobe": lobe, "k": k, "levels": len(ladder), "wall_s": wall, "cpu_s": cpu, "heights": shapes})
    wall, cpu = timed(lambda: envmaps.irradiance(im, size=32), 5)
    out["irradiance_time"] = {"wall_s": wall, "cpu_s": cpu}
    wall, cpu = timed(lambda: envmaps.convert(im, "latlong", "cube", 256), 3)
    out["convert_time"] = {"what": "latlong 1024x512 -> cube 6x256x256", "wall_s": wall, "cpu_s": cpu}

    # Accuracy of the prefiltered levels against the brute-force sum.
    rng = np.random.default_rng(8)
    n = 16 if args.quick else 32
    acc_worlds = ("sunset", "courtyard") if args.quick else ("sunset", "courtyard", "interior")
    for name in acc_worlds:
        im = worlds[name]
        runs = [(lobe, k) for lobe in LADDERS for k in ((4.0, 6.0, 8.0) if lobe == "ggx" else (6.0,))]
        for lobe, k in runs:
            ladder = LADDERS[lobe]
            levels = envmaps.prefilter(im, lobe, ladder, texels_per_radius=k)
            for p, lv in zip(ladder, levels):
                if np.array_equal(lv, im):
                    continue  # the mirror level is the world itself
                h, w = lv.shape[:2]
                rows, cols = rng.integers(0, h, n), rng.integers(0, w, n)
                d = texel_dirs(h, w, rows, cols)
                t_mean, t_max = rel(lv[rows, cols], envmaps.reference(im, lobe, d, param=p))
                d2 = rng.normal(size=(n, 3))
                l_mean, l_max = rel(envmaps.sample(lv, "latlong", d2), envmaps.reference(im, lobe, d2, param=p))
                out["accuracy"].append({"world": name, "lobe": lobe, "k": k, "param": p, "height": h, "texel_mean": t_mean, "texel_max": t_max, "lookup_mean": l_mean, "lookup_max": l_max})

    # SH irradiance against the exact irradiance.
    normals = fibonacci(128 if args.quick else 256)
    for name, im in worlds.items():
        irr = envmaps.irradiance(im, size=32)
        sh = envmaps.sh_irradiance(irr["irradiance_coeffs"], normals)
        exact = envmaps.reference(im, "lambert", normals)
        m, x = rel(sh, exact)
        out["irradiance"].append({"world": name, "mean": m, "max": x, "peak": float(im.max()), "mean_radiance": float(im.mean())})
    out["load_average"] = [load0, os.getloadavg()[0]]
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    else:
        print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
