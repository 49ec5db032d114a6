"""Benchmark: what the edit costs a Cycles render of the demo scene ("Performance").

The Rokeby Venus of `make demo` (rokeby.demo_scene) is rendered with the mirror's render node
group installed (the edit: the edited normal n' = normalize(R r + V) read from the field
attribute) and with it removed (the physical mirror), at the same resolution, samples and seed.
The two are alternated and repeated; medians are reported. Wall time of bpy.ops.render.render
(scene sync, BVH, path tracing, denoising) and the CPU time of the process over all threads
(steadier than wall time on a shared machine), CPU device.

    python bench/demo_render.py [--repeat 3] [--width 640 --height 360 --samples 24] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))


def _render() -> tuple[float, float]:
    """(wall seconds, CPU seconds of this process over all threads) of one render. On a shared
    machine the CPU time is the steadier measure of the work done."""
    import bpy

    t, c = time.perf_counter(), time.process_time()
    bpy.ops.render.render()
    return time.perf_counter() - t, time.process_time() - c


def measure(width: int, height: int, samples: int, repeat: int) -> dict:
    import bpy

    import rokeby
    from rokeby import api, demo_scene as ds

    demo = ds.build(SHARED, width=width, height=height, samples=samples)
    rokeby.register()
    info = ds.edit(demo)  # installs the node group
    if info["report"].status != "OK" or info["wired"] < 1:
        raise SystemExit(f"demo scene not edited: {info['report'].summary()}, {info['wired']} inputs wired")
    load_before = os.getloadavg()[0]
    _render()  # warm-up: kernels, textures, images
    times = {"edited": [], "physical": []}
    cpu = {"edited": [], "physical": []}
    for i in range(repeat):
        order = ("edited", "physical") if i % 2 == 0 else ("physical", "edited")
        for what in order:
            if what == "edited":
                api.install_render_nodes(demo.mirror)
            else:
                api.remove_render_nodes(demo.mirror)
            wall, c = _render()
            times[what].append(wall)
            cpu[what].append(c)
    sc = bpy.context.scene
    return {
        "width": width,
        "height": height,
        "samples": samples,
        "denoiser": sc.cycles.denoiser if sc.cycles.use_denoising else "off",
        "threads": sc.render.threads,
        "repeat": repeat,
        "physical_s": times["physical"],
        "edited_s": times["edited"],
        "physical_median_s": statistics.median(times["physical"]),
        "edited_median_s": statistics.median(times["edited"]),
        "physical_cpu_s": cpu["physical"],
        "edited_cpu_s": cpu["edited"],
        "physical_cpu_median_s": statistics.median(cpu["physical"]),
        "edited_cpu_median_s": statistics.median(cpu["edited"]),
        "mirror_vertices": len(demo.mirror.data.vertices),
        "load_average": [load_before, os.getloadavg()[0]],
        "cpus": os.cpu_count(),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--samples", type=int, default=24)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    r = measure(args.width, args.height, args.samples, args.repeat)
    print(f"demo scene {r['width']}x{r['height']}, {r['samples']} samples, denoiser {r['denoiser']}, {r['threads']} threads, {r['repeat']} renders each:")
    for what, label in (("physical", "physical mirror (no node group)"), ("edited", "edited mirror (node group)     ")):
        print(f"  {label}: wall median {r[what + '_median_s']:6.2f} s {[round(t, 2) for t in r[what + '_s']]}, CPU median {r[what + '_cpu_median_s']:6.2f} s {[round(t, 2) for t in r[what + '_cpu_s']]}")
    print(f"  load average {r['load_average'][0]:.1f} before, {r['load_average'][1]:.1f} after, on {r['cpus']} CPUs")
    print(f"  ratio edited / physical: wall {r['edited_median_s'] / r['physical_median_s']:.3f}, CPU {r['edited_cpu_median_s'] / r['physical_cpu_median_s']:.3f}")
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
