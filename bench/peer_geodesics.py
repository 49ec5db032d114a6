"""Peers of Rokeby's geodesic distances, run in .venv-peers (numpy 2) by bench/run.py.

    python bench/peer_geodesics.py IN.npz OUT.npz

IN holds vertices (V, 3), faces (F, 3) and sources (S,) vertex indices. OUT receives, per peer, the
distances (S, V) and its timings (precomputation once, then seconds per query), or an error
message when a peer refuses the mesh:
  exact       pygeodesic's exact polyhedral geodesics (MMP, Surazhsky et al. 2005): ground truth
  potpourri3d potpourri3d.MeshHeatMethodDistanceSolver (geometry-central's heat method,
              intrinsic-Delaunay robust Laplacian)
  libigl      igl.heat_geodesics_precompute / heat_geodesics_solve
"""

import sys
import time

import numpy as np


def run(name, fn, out):
    try:
        d, pre, per = fn()
        out[f"{name}_d"] = d
        out[f"{name}_pre"] = pre
        out[f"{name}_query"] = per
    except Exception as exc:  # a peer refusing a mesh is a result worth reporting
        out[f"{name}_error"] = f"{type(exc).__name__}: {exc}"


def main(src, dst):
    data = np.load(src)
    v = data["vertices"].astype(np.float64)
    f = data["faces"].astype(np.int64)
    sources = data["sources"].astype(np.int64)
    skip_exact = bool(data["skip_exact"]) if "skip_exact" in data else False
    out = {}

    def exact():
        import pygeodesic.geodesic as geo

        t = time.perf_counter()
        alg = geo.PyGeodesicAlgorithmExact(v, f.astype(np.int32))
        pre = time.perf_counter() - t
        rows, t = [], time.perf_counter()
        for s in sources:
            d, _ = alg.geodesicDistances(np.array([s], dtype=np.int32), None)
            rows.append(np.where(d > 1e30, np.inf, d))
        return np.array(rows), pre, (time.perf_counter() - t) / len(sources)

    def potpourri():
        import potpourri3d as pp3d

        t = time.perf_counter()
        solver = pp3d.MeshHeatMethodDistanceSolver(v, f)
        pre = time.perf_counter() - t
        rows, t = [], time.perf_counter()
        for s in sources:
            rows.append(solver.compute_distance(int(s)))
        return np.array(rows), pre, (time.perf_counter() - t) / len(sources)

    def libigl():
        import igl

        t = time.perf_counter()
        hd = igl.HeatGeodesicsData()
        igl.heat_geodesics_precompute(v, f, hd)
        pre = time.perf_counter() - t
        rows, t = [], time.perf_counter()
        for s in sources:
            rows.append(igl.heat_geodesics_solve(hd, np.array([s], dtype=np.int64)))
        return np.array(rows), pre, (time.perf_counter() - t) / len(sources)

    if not skip_exact:
        run("exact", exact, out)
    run("potpourri3d", potpourri, out)
    run("libigl", libigl, out)
    np.savez(dst, **out)


def plot(json_path, png_path):
    """Speed/accuracy plot from the table bench/run.py measured (written as JSON)."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = json.load(open(json_path))
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=120)
    markers = {"rokeby dense graph (default)": "*", "rokeby graph (SVG)": "P", "rokeby heat": "o", "rokeby heat (neumann)": "s", "rokeby dijkstra": "^", "potpourri3d heat": "D", "libigl heat": "v"}
    meshes = sorted({r["mesh"] for r in rows})
    colours = dict(zip(meshes, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    for r in rows:
        if r.get("mean_err") is None:
            continue
        ax.scatter(r["query_ms"], 100 * r["mean_err"], marker=markers.get(r["method"], "x"), color=colours[r["mesh"]], s=40)
    for m, mk in markers.items():
        ax.scatter([], [], marker=mk, color="gray", label=m)
    for mesh, c in colours.items():
        ax.scatter([], [], marker="o", color=c, label=mesh)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per query after precomputation (ms, log)")
    ax.set_ylabel("mean relative error vs exact (%, log)")
    ax.set_title("Geodesic distance: speed against accuracy (mean over three sources)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(png_path)


if __name__ == "__main__":
    if sys.argv[1] == "--plot":
        plot(sys.argv[2], sys.argv[3])
    else:
        main(sys.argv[1], sys.argv[2])
