"""`make bench`: Rokeby's speed and accuracy, printed next to the reference numbers.

Writes the same tables to docs/benchmarks.md. Nothing here is asserted: timings vary by machine;
tests check behaviour, this reports speed.

Reference figures (Ritschel et al. 2009, §8): per-pixel reflection interpolation on a GeForce GTX
260 at 1280x960: 24.5 megapixels/s with 1 constraint, 18.5 megapixels/s with 32 constraints.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


from common import machine  # noqa: E402
from sections.addon import HEAVY_MARKER, addon_section, heavy_section  # noqa: E402
from sections.appearance import APPEARANCE_MARKER, appearance_section  # noqa: E402
from sections.compositing import COMPOSITING_MARKER, compositing_section  # noqa: E402
from sections.envmaps import ENVMAP_MARKER, envmap_section  # noqa: E402
from sections.reflection import (GEODESIC_MARKER, RENDER_MARKER, ROOFLINE_MARKER, SCENE_PREVIEW_MARKER, VIEWPORT_MARKER,  # noqa: E402
                                 field_section, geodesic_section, render_section, roofline_section, scene_preview_section,
                                 viewport_section)
from sections.shadow import SHADOW_MARKER, shadow_section  # noqa: E402

import tradeoff_sections  # noqa: E402

TRADEOFFS = tradeoff_sections.SECTIONS


def _refresh_section(emit, out, marker, section):
    """Run one section and put it into docs/benchmarks.md in place of its old text (appended
    when the report has none yet)."""
    start = len(out)
    section(emit)
    if not any(line.startswith("Run: ") for line in out[start:start + 4]):
        # each section says which run it came from.
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


def keep_other_sections(new: str, old: str) -> str:
    """The report of a whole run, followed by the old report's ``## `` sections this run does not
    write (measurements made by hand or by other scripts, each with its own date): the guides
    quote them, so a whole run must not drop them."""
    def sections(text):
        parts = text.split("\n## ")
        return [("## " + part).split("\n", 1)[0] for part in parts[1:]], parts[1:]

    written, _ = sections(new)
    headings, bodies = sections(old)
    kept = [body for heading, body in zip(headings, bodies) if heading not in written]
    return new.rstrip("\n") + "".join("\n\n## " + body.rstrip("\n") for body in kept) + "\n"


def main():
    ap = argparse.ArgumentParser(description="Rokeby benchmarks")
    ap.add_argument("--peers", default=None, help="python of .venv-peers (exact geodesics, potpourri3d, libigl, matplotlib)")
    ap.add_argument("--only", choices=["field", "roofline", "geodesic", "addon", "heavy", "render", "viewport", "scene_preview", "envmap", "appearance", "compositing", "shadow", *TRADEOFFS], default=None)
    args = ap.parse_args()
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
    if args.only == "scene_preview":
        _refresh_section(emit, out, SCENE_PREVIEW_MARKER, scene_preview_section)
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
        # one speed-for-accuracy choice (bench/tradeoff_sections.py), with its plot.
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
        # Refresh that section in place; the rest of the report stays.
        _refresh_section(emit, out, GEODESIC_MARKER, lambda e: geodesic_section(e, args.peers))
        return
    if args.only != "field":
        geodesic_section(emit, args.peers)
        roofline_section(emit)

    field_section(emit)
    addon_section(emit)
    heavy_section(emit)
    viewport_section(emit)
    scene_preview_section(emit)
    render_section(emit)
    envmap_section(emit)
    appearance_section(emit)
    # Sections that --only can also run alone.
    compositing_section(emit)
    shadow_section(emit)
    for _marker, section in TRADEOFFS.values():
        section(emit, args.peers)

    docs = ROOT / "docs"
    docs.mkdir(exist_ok=True)
    doc = docs / "benchmarks.md"
    new = "\n".join(out) + "\n"
    doc.write_text(keep_other_sections(new, doc.read_text() if doc.exists() else ""))
    print(f"\nwritten to {docs / 'benchmarks.md'}")


if __name__ == "__main__":
    main()
