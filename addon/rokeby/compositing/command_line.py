"""The command line of ``python -m rokeby.composite`` (:func:`command_parser`) and the edit options
the farm's recompositing job passes to it (:func:`edit_options`, :func:`one_knob_options`)."""

from __future__ import annotations

import os

from .errors import CompositingError
from .gl import _check_k
from .normal_tools import EDITS
from .recompositing import RECOMPOSITE_BACKENDS


def _pair(text: str) -> tuple[float, float]:
    import argparse  # noqa: PLC0415

    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in pixels, got {text!r}") from None
    return x, y


def _indices(text: str) -> list[int]:
    import argparse  # noqa: PLC0415

    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated object pass indices, got {text!r}") from None


def command_parser(prog: str = "python -m rokeby.composite", description: str | None = None, parser_class=None):
    """The argument parser of ``python -m rokeby.composite`` (its files, sequence options and edit
    options), ``parser_class`` an ``argparse.ArgumentParser`` subclass (how errors are reported)."""
    import argparse  # noqa: PLC0415

    ap = (parser_class or argparse.ArgumentParser)(prog=prog, description=description)
    ap.add_argument("input", help="Blender multilayer EXR with the passes of setup_passes (with --sequence: the folder of frames)")
    ap.add_argument("output", help="recomposited RGB EXR (with --sequence: the output folder)")
    ap.add_argument("--sequence", action="store_true", help="input and output are folders: recomposite every frame")
    ap.add_argument("--pattern", default="*.exr", help="with --sequence: which files are frames, a glob or '#' per digit (default *.exr)")
    ap.add_argument("--frame", type=int, metavar="K", help="with --sequence: only the K-th frame (1-based, frame order): one process per frame")
    ap.add_argument("--skip-existing", action="store_true", help="an output that exists is kept and its frame skipped (resume a stopped run)")
    ap.add_argument("--layer", help="view layer (default: the first in the file)")
    ap.add_argument("--emboss", type=float, metavar="BETA", help="n_z → β n_z, β in (0, 1]")
    ap.add_argument("--ripple", type=float, metavar="STRENGTH", help="fading 2D ripple decal of this strength")
    ap.add_argument("--ripple-center", type=_pair, metavar="X,Y", help="ripple centre in pixels (default: image centre)")
    ap.add_argument("--ripple-wavelength", type=float, default=24.0, metavar="PX")
    ap.add_argument("--ripple-radius", type=float, metavar="PX")
    ap.add_argument("--noise", type=float, metavar="STRENGTH", help="fading procedural noise bump decal of this strength")
    ap.add_argument("--noise-size", type=float, default=16.0, metavar="PX", help="its feature size (default 16)")
    ap.add_argument("--noise-octaves", type=int, default=3, metavar="N")
    ap.add_argument("--noise-seed", type=int, default=0)
    ap.add_argument("--noise-center", type=_pair, metavar="X,Y", help="its centre in pixels (default: image centre)")
    ap.add_argument("--noise-radius", type=float, metavar="PX")
    ap.add_argument("--bump", metavar="HEIGHT", help="height image (EXR or .npy, frame-sized)")
    ap.add_argument("--bump-strength", type=float, default=1.0)
    ap.add_argument("--smooth", type=float, metavar="SIGMA_PX", help="cross-bilateral smoothing of normals with depth")
    ap.add_argument("--smooth-depth", type=float, default=0.02, metavar="REL", help="depth range kernel σ (relative)")
    ap.add_argument("--objects", type=_indices, help="comma-separated object pass indices to edit (default: all)")
    ap.add_argument("--fit", choices=("qp", "ls"), default="qp", help="diffuse SH fit (default: the QP)")
    ap.add_argument("--noise-tolerance", type=float, default=0.0, metavar="KAPPA",
                    help="the QP's constraint D(n) >= D0 - KAPPA*sigma, sigma the pixel noise of the diffuse pass "
                         "(default 0: the paper's QP; about 2-3 for a noisy render)")
    ap.add_argument("--env-size", type=int, default=128, help="texels per paraboloid face")
    ap.add_argument("--kd", type=float, default=1.0, help="diffuse intensity k_D")
    ap.add_argument("--kr", type=float, default=1.0, help="reflection intensity k_R")
    ap.add_argument("--backend", choices=RECOMPOSITE_BACKENDS, default="cpu",
                    help="eqs. 3-5 on the CPU (Rust core, default), or the GLSL shader on a headless EGL context (moderngl) "
                         "or through Blender's gpu module (blender_gpu: bpy in this process; its context costs one tiny EEVEE render)")
    ap.add_argument("--report", metavar="JSON", help="write per-patch reconstruction report and timings")
    return ap


def edit_options(options) -> list[str]:
    """Checks ``options``, edit options of ``python -m rokeby.composite`` (``["--emboss", "0.6"]``:
    everything but the files, ``--sequence``, ``--pattern``, ``--frame``, ``--skip-existing`` and
    ``--report``, which a sequence job sets per frame), as that command will parse them; returns
    them as strings. A bad flag or value, or a ``--bump`` image that is not a file, is a
    ``CompositingError`` naming it."""
    import argparse  # noqa: PLC0415

    class _Raising(argparse.ArgumentParser):
        def error(self, message):
            raise CompositingError(f"edit options: {message}")

    options = [str(v) for v in options]
    if any(v in ("-h", "--help") for v in options):
        raise CompositingError("edit options: --help is not an edit option")
    a = command_parser(parser_class=_Raising).parse_args(["in.exr", "out.exr", *options])
    for flag, given in (("--sequence", a.sequence), ("--pattern", a.pattern != "*.exr"), ("--frame", a.frame is not None),
                        ("--skip-existing", a.skip_existing), ("--report", a.report is not None)):
        if given:
            raise CompositingError(f"edit options: {flag} is not an edit option (the job sets it for each frame)")
    _check_k(a.kd, a.kr)
    if a.bump is not None and not os.path.isfile(a.bump):
        raise CompositingError(f"edit options: --bump: no such file: {a.bump}")
    return options


def one_knob_options(edit: str, amount: float, *, k_d: float = 1.0, k_r: float = 1.0, fit: str = "qp",
                     noise_tolerance: float = 0.0, backend: str = "cpu") -> list[str]:
    """The ``python -m rokeby.composite`` edit options of a one-knob edit as the operators and
    ``recomposite_exr`` apply it (:func:`edit_normals`): the same pixels, frame by frame."""
    if edit not in EDITS:
        raise CompositingError(f"edit: unknown {edit!r} (expected one of {', '.join(map(repr, EDITS))})")
    out = [] if edit == "none" else [f"--{edit}", repr(float(amount))]
    if float(k_d) != 1.0:
        out += ["--kd", repr(float(k_d))]
    if float(k_r) != 1.0:
        out += ["--kr", repr(float(k_r))]
    if fit != "qp":
        out += ["--fit", fit]
    if float(noise_tolerance) != 0.0:
        out += ["--noise-tolerance", repr(float(noise_tolerance))]
    if backend != "cpu":
        out += ["--backend", backend]
    return edit_options(out)
