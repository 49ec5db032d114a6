"""Rokeby's exact geodesics (method="exact") against pygeodesic's exact MMP, the goal: the same
distances to 1e-5 relative at a quarter of MMP's query time on the shared meshes.

    make native .venv-peers/.deps && .venv/bin/python bench/exact_vs_mmp.py [--rounds N]

The sources of `make bench`'s geodesic section (the first vertex of the faces a quarter, half and
three quarters through the face list). Per round and mesh, in one session: Rokeby as `make bench`
times it (a fresh solver, then the three sources as one call, in parallel on the machine's cores;
the time divided by three), Rokeby one source per call (one after another), and pygeodesic in
.venv-peers (numpy 2), one source per call as bench/peer_geodesics.py does; medians over the
rounds. Error: the largest |d - d_mmp| / d_mmp over the vertices MMP reaches, the sources left out.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))
import rokeby_native as rn  # noqa: E402

from rokeby.core.meshio import load_obj  # noqa: E402

SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
MESHES = ("teapot.obj", "spot.obj", "homer.obj", "fandisk.obj")

# Run by the peers' python: ROUNDS rounds of one source per call; the times and the distances.
MMP = """
import sys, time
import numpy as np
import pygeodesic.geodesic as geo
data = np.load(sys.argv[1])
v, f, sources, rounds = data["vertices"], data["faces"].astype(np.int32), data["sources"], int(data["rounds"])
out = {}
try:
    alg = geo.PyGeodesicAlgorithmExact(v, f)
    times = []
    for _ in range(rounds):
        rows = []
        t = time.perf_counter()
        for s in sources:
            d, _ = alg.geodesicDistances(np.array([s], dtype=np.int32), None)
            rows.append(np.where(d > 1e30, np.inf, d))
        times.append((time.perf_counter() - t) / len(sources))
    out = {"times": np.array(times), "d": np.array(rows)}
except Exception as exc:
    out = {"error": f"{type(exc).__name__}: {exc}"}
np.savez(sys.argv[2], **out)
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--peers", default=str(ROOT / ".venv-peers" / "bin" / "python"))
    args = ap.parse_args()
    print(f"{args.rounds} rounds, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start")
    print("| mesh | faces | rokeby exact, bench's way (ms/source) | rokeby exact, one source per call | pygeodesic MMP | ratio MMP / rokeby (bench's way) | max rel. difference |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name in MESHES:
        v, f = load_obj(SHARED / "meshes" / name)
        sources = [int(f[len(f) * k // 4, 0]) for k in (1, 2, 3)]
        bench_way, one_by_one = [], []
        for _ in range(args.rounds):
            t = time.perf_counter()
            d = rn.geometry.GeodesicSolver(v, f).distances(sources, method="exact")
            bench_way.append((time.perf_counter() - t) / len(sources))
            solver = rn.geometry.GeodesicSolver(v, f)
            solver.distances(sources[:1], method="exact")  # the per-mesh tables, made on first use
            t = time.perf_counter()
            for s in sources:
                solver.distances([s], method="exact")
            one_by_one.append((time.perf_counter() - t) / len(sources))
        with tempfile.TemporaryDirectory() as tmp:
            np.savez(f"{tmp}/in.npz", vertices=v.astype(np.float64), faces=f, sources=np.array(sources), rounds=args.rounds)
            subprocess.run([args.peers, "-c", MMP, f"{tmp}/in.npz", f"{tmp}/out.npz"], check=True)
            peer = dict(np.load(f"{tmp}/out.npz"))
        mine = statistics.median(bench_way) * 1e3
        alone = statistics.median(one_by_one) * 1e3
        if "error" in peer:
            print(f"| {name} | {len(f):,} | {mine:.1f} | {alone:.1f} | fails: {str(peer['error'])[:60]} | | |")
            continue
        mmp = statistics.median(peer["times"]) * 1e3
        ref = peer["d"]
        ok = np.isfinite(ref) & (ref > 0)
        rel = np.abs(d.astype(np.float64)[ok] - ref[ok]) / ref[ok]
        print(f"| {name} | {len(f):,} | {mine:.1f} | {alone:.1f} | {mmp:.1f} | {mmp / mine:.2f} | {rel.max():.1e} |")
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
