"""What the stable ABI (abi3) costs on the hot paths, in instructions, not seconds.

    python bench/abi_cost.py --site A --site B [--label A --label B]

Each --site is a folder where a rokeby_native wheel was installed with `pip install --no-deps --target`. The
same workload (the per-pixel field, the per-point field, recompositing, and 2,000 tiny calls that measure the
crossing itself) runs once per site under `valgrind --tool=callgrind` on one thread, and the instruction counts
are printed side by side. Instruction counts are repeatable on a shared, noisy machine where seconds are not.
The workload alone (no valgrind) is `python bench/abi_cost.py --workload SITE PART`.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
PARTS = ("start", "edited_directions", "rotation_field", "recomposite", "calls")


def workload(site: str, part: str) -> None:
    sys.path.insert(0, site)
    sys.path.insert(0, str(HERE.parent / "tests"))
    import numpy as np
    import rokeby_native as rn
    from support.reference import random_constraints

    assert Path(rn.__file__).resolve().is_relative_to(Path(site).resolve()), rn.__file__
    rng = np.random.default_rng(7)
    if part == "start":
        return
    if part == "edited_directions":
        h, w = 120, 160
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        pos = np.stack([xs / w - 0.5, ys / w - 0.4, 0.05 * np.sin(8 * xs / w)], -1).astype(np.float32)
        nrm = np.zeros_like(pos)
        nrm[..., 2] = 1
        c = random_constraints(rng, 8, spread=0.5, max_edit=0.7, min_edit=0.1)
        rn.reflection.edited_directions(pos, nrm, np.array([0, -0.6, 1.2], np.float32), c, polar="fast")
    elif part == "rotation_field":
        v = rng.normal(size=(20000, 3)).astype(np.float32)
        c = random_constraints(rng, 8, spread=0, max_edit=0.7, min_edit=0.1, at=v)
        rn.reflection.rotation_field(v, c, polar="fast")
    elif part == "recomposite":
        sys.path.insert(0, str(HERE))
        from compositing import hd_frame

        args, kw = hd_frame(rng, 320, 240, 10, 32)
        rn.compositing.recomposite(*args, **kw)
    elif part == "calls":
        v = rng.normal(size=(4, 3)).astype(np.float32)
        c = random_constraints(rng, 1, spread=0, max_edit=0.7, min_edit=0.1, at=v)
        for _ in range(2000):
            rn.reflection.rotation_field(v, c, polar="fast")


def instructions(site: str, part: str) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cg.out"
        env = dict(os.environ, RAYON_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", sys.executable,
                        __file__, "--workload", site, part], check=True, env=env,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        m = re.search(r"^summary:\s*(\d+)", out.read_text(), re.M) or re.search(r"^totals:\s*(\d+)", out.read_text(), re.M)
        return int(m.group(1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--site", action="append", default=[])
    ap.add_argument("--label", action="append", default=[])
    ap.add_argument("--workload", nargs=2, metavar=("SITE", "PART"))
    a = ap.parse_args()
    if a.workload:
        workload(*a.workload)
        return
    if len(a.site) < 2:
        ap.error("give two --site folders to compare")
    labels = a.label + [Path(s).name for s in a.site[len(a.label):]]
    counts = {s: {p: instructions(s, p) for p in PARTS} for s in a.site}
    print("| part | " + " | ".join(f"{lab} (M instr.)" for lab in labels) + " | ratio |")
    print("|---|" + "---:|" * (len(labels) + 1))
    base = counts[a.site[0]]["start"]
    for p in PARTS[1:]:
        vals = [counts[s][p] - counts[s]["start"] for s in a.site]
        print(f"| {p} | " + " | ".join(f"{x / 1e6:.1f}" for x in vals) + f" | {vals[-1] / vals[0]:.4f} |")
    print(f"\n(interpreter and numpy start-up, subtracted: {base / 1e6:.0f} M instructions)")


if __name__ == "__main__":
    main()
