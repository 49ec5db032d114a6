"""``python -m rokeby.farm render FILE.blend BUNDLE_DIR [--frames A-B] [--chunk N] [--zip ZIP] [--output DIR]``:
writes an Open Job Description job bundle (docs/farm.md). Exit status 0, or 2 with one line on
stderr naming what is wrong."""

from __future__ import annotations

import argparse
import sys

from ..core.errors import RokebyError
from .api import write_render_job


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m rokeby.farm", description="Job bundles for render farms (Open Job Description).")
    sub = ap.add_subparsers(dest="job", required=True)
    r = sub.add_parser("render", help="a job that renders a saved .blend's frames with the add-on installed on each worker")
    r.add_argument("blend")
    r.add_argument("bundle_dir")
    r.add_argument("--frames", required=True, help="A-B (or A)")
    r.add_argument("--chunk", type=int, default=1, help="frames per task (one Blender process each)")
    r.add_argument("--zip", default=None, help="the extension zip (default dist/rokeby-<version>.zip)")
    r.add_argument("--output", default=None, help="the frames' folder on the workers (default <blend's folder>/render)")
    a = ap.parse_args(argv)
    try:
        bundle = write_render_job(a.blend, a.bundle_dir, frames=a.frames, chunk=a.chunk, zip_path=a.zip, output_dir=a.output)
    except (RokebyError, OSError) as exc:
        print(f"rokeby.farm: {exc}", file=sys.stderr)
        return 2
    print(bundle)
    return 0


if __name__ == "__main__":
    sys.exit(main())
