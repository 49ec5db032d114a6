"""Open Job Description job bundles for render farms (docs/farm.md):

    python -m rokeby.farm render FILE.blend BUNDLE_DIR --frames A-B [--chunk N] [--zip ZIP] [--output DIR]
    python -m rokeby.farm recomposite IN_DIR OUT_DIR BUNDLE_DIR --pattern P [--chunk N] [--zip ZIP] [EDIT OPTIONS]

EDIT OPTIONS are those of ``python -m rokeby.composite`` (``--emboss 0.6``, ``--ripple 0.4
--ripple-center 120,80``, ``--kd``, ``--fit ls`` …), checked now. Without ``--zip``, the extension
zip is built from the project checkout (as `make dist`) or packed from the installed extension.
Prints the bundle folder; exit status 0, or 2 with one line on stderr naming what is wrong.
"""

from __future__ import annotations

import argparse
import sys

from ..core.errors import RokebyError
from .api import write_recomposite_job, write_render_job


class _Parser(argparse.ArgumentParser):
    """Bad flags: one line naming the problem, exit 2."""

    def error(self, message):
        self.exit(2, f"rokeby.farm: {message} (see --help)\n")


def main(argv=None) -> int:
    ap = _Parser(prog="python -m rokeby.farm", description=__doc__.split("\n\n")[0],
                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    sub = ap.add_subparsers(dest="job", required=True, parser_class=_Parser)
    r = sub.add_parser("render", help="a job that renders a saved .blend's frames with the add-on installed on each worker")
    r.add_argument("blend")
    r.add_argument("bundle_dir")
    r.add_argument("--frames", required=True, help="A-B (or A)")
    r.add_argument("--chunk", type=int, default=1, help="frames per task (one Blender process each)")
    r.add_argument("--zip", default=None, help="the extension zip (default: built from the checkout, or the installed extension)")
    r.add_argument("--output", default=None, help="the frames' folder on the workers (default <blend's folder>/render)")
    c = sub.add_parser("recomposite", help="a job that recomposites a folder of multilayer EXRs frame by frame (python -m rokeby.composite)",
                       epilog="Any further options are python -m rokeby.composite's edit options.")
    c.add_argument("input_dir")
    c.add_argument("output_dir")
    c.add_argument("bundle_dir")
    c.add_argument("--pattern", default="*.exr", help="which files are frames: a glob, or '#' per frame digit (default *.exr)")
    c.add_argument("--chunk", type=int, default=1, help="frames per task (one Blender process each)")
    c.add_argument("--zip", default=None, help="the extension zip (default: built from the checkout, or the installed extension)")
    a, rest = ap.parse_known_args(argv)
    if rest and a.job != "recomposite":
        ap.error(f"unrecognized arguments: {' '.join(rest)}")
    try:
        if a.job == "render":
            bundle = write_render_job(a.blend, a.bundle_dir, frames=a.frames, chunk=a.chunk, zip_path=a.zip, output_dir=a.output)
        else:
            bundle = write_recomposite_job(a.input_dir, a.output_dir, a.bundle_dir, pattern=a.pattern, edit_options=rest,
                                           chunk=a.chunk, zip_path=a.zip)
    except (RokebyError, OSError) as exc:
        print(f"rokeby.farm: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    print(bundle)
    return 0


if __name__ == "__main__":
    sys.exit(main())
