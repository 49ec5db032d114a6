"""Command line: local shape editing of one rendered frame (one frame per process, so that any
render farm can run a sequence as independent tasks).

    python -m rokeby.composite in.exr out.exr --emboss 0.5
    python -m rokeby.composite in.exr out.exr --ripple 0.4 --ripple-center 120,80 --ripple-wavelength 20
    python -m rokeby.composite in.exr out.exr --noise 1.5 --noise-size 12 --noise-seed 3
    python -m rokeby.composite in.exr out.exr --bump height.exr --bump-strength 2 --smooth 3

``in.exr`` is a Blender multilayer EXR rendered after ``rokeby.compositing.setup_passes``. The
output is an RGB EXR of the recomposited image. Edits apply in that order: smoothing, emboss,
ripple, noise, bump. ``--objects 1,3`` limits them to those object pass indices. Exit status 0,
or 2 with one line naming what is wrong (a missing or unreadable file, a missing output folder, a
bad edit, a backend that cannot start); the files are checked before any work. The output is
written whole and then renamed into place, so a crash never leaves half a frame;
``--skip-existing`` exits 0 at once when the output is there (a rerun resumes). A sequence:

    python -m rokeby.composite --sequence frames/ out/ --pattern "shot_####.exr" --emboss 0.6 --skip-existing
    python -m rokeby.composite --sequence frames/ out/ --frame 7 --emboss 0.6   # one frame per process (a farm task)

``--sequence`` takes folders: the frames are the files matching ``--pattern`` (a glob, or '#' per
frame digit), in frame order, written under their own names; progress on stderr, one line per
frame; frames that fail are named at the end and the others still run (exit 1); a rerun with
``--skip-existing`` does only what is missing. ``--frame K`` (1-based, in that order) runs only
frame K, e.g. ``--frame $SLURM_ARRAY_TASK_ID``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from . import compositing as C
from .compositing import gl
from .core import exr
from .blender import transaction



def _read_height(path: str, shape) -> np.ndarray:
    try:
        if path.endswith(".npy"):
            h = np.load(path)
        else:
            # The first channel as OpenEXR's reader groups them (an RGB[A] set is one, averaged below).
            ch = exr.grouped(exr.read(path)[0].channels)
            h = np.asarray(ch[next(iter(ch))], np.float32)
    except exr.ExrError as exc:
        raise C.CompositingError(f"--bump: cannot read the height image {path}: {exc.why}") from None
    except (OSError, ValueError, StopIteration) as exc:  # unreadable, no channel
        raise C.CompositingError(f"--bump: cannot read the height image {path}: {exc}") from None
    h = np.asarray(h, np.float32)
    if h.ndim == 3:
        h = h[..., :3].mean(-1)
    if h.ndim != 2 or h.shape != tuple(shape):
        size = "×".join(str(v) for v in h.shape[::-1])
        raise C.CompositingError(f"--bump: height image {path} is {size}, the frame is {shape[1]}×{shape[0]}")
    return h


def _missing_files(a) -> str | None:
    """The first input file that does not exist, or output folder that does not, as one line."""
    for flag, path in (("input", a.input), ("--bump", a.bump)):
        if path is not None and not os.path.isfile(path):
            return f"{flag}: no such file: {path}"
    for flag, path in (("output", a.output), ("--report", a.report)):
        if path is not None:
            folder = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(folder):
                return f"{flag}: the folder {folder} does not exist"
    return None
class _Parser(argparse.ArgumentParser):
    """Bad flags: one line naming the problem, exit 2 (argparse's usage block goes to --help)."""

    def error(self, message):
        self.exit(2, f"rokeby.composite: {message} (see --help)\n")



def main(argv=None) -> int:
    """The tool: 0 on success; 2 with one line on stderr naming the problem for a bad file, flag
    or value, an unwritable output or a resource limit (never a traceback for those)."""
    import signal  # noqa: PLC0415

    from .core import native  # noqa: PLC0415

    def interrupted(_sig, _frame):
        native.cancel()  # a native call in flight stops at its next row
        raise KeyboardInterrupt

    # Ctrl-C, and a scheduler's cancel (SIGTERM: a farm task, a batch job), stop at the next row.
    old = {sig: signal.signal(sig, interrupted) for sig in (signal.SIGINT, signal.SIGTERM)} if _main_thread() else {}
    try:
        with native.cancellable():
            return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C / SIGINT / SIGTERM: one line, status 130, no (partial) output file
        print("rokeby.composite: cancelled", file=sys.stderr)
        return 130
    except (C.CompositingError, ValueError, OSError, MemoryError) as exc:
        what = "out of memory" if isinstance(exc, MemoryError) else " ".join(str(exc).split())
        print(f"rokeby.composite: {what or type(exc).__name__}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


def _main_thread() -> bool:
    import threading  # noqa: PLC0415

    return threading.current_thread() is threading.main_thread()


def _main(argv) -> int:
    ap = C.command_parser(description=__doc__.split("\n\n")[0], parser_class=_Parser)
    a = ap.parse_args(argv)
    if a.sequence:
        return _sequence(a)
    if a.frame is not None:
        ap.error("--frame needs --sequence")
    return _frame(a)


def _sequence(a) -> int:
    """--sequence: every frame (or frame --frame) of the input folder through :func:`_frame`."""
    if not os.path.isdir(a.input):
        raise C.CompositingError(f"input: {a.input} is not a folder (--sequence takes folders)")
    frames = C.sequence_frames(a.input, a.pattern)
    if not frames:
        raise C.CompositingError(f"input: no frames matching '{a.pattern}' in {a.input}")
    if os.path.realpath(a.output) == os.path.realpath(a.input):
        raise C.CompositingError("output: the output folder must differ from the input folder (the frames would be overwritten)")
    if a.frame is not None:
        if not 1 <= a.frame <= len(frames):
            raise C.CompositingError(f"--frame: {a.frame} is not in 1..{len(frames)} (the frames matching '{a.pattern}')")
        todo = [(a.frame, frames[a.frame - 1])]
    else:
        todo = list(enumerate(frames, 1))
    os.makedirs(a.output, exist_ok=True)
    failed = []
    for k, path in todo:
        one = argparse.Namespace(**vars(a))
        one.input, one.output = path, os.path.join(a.output, os.path.basename(path))
        done_before = a.skip_existing and os.path.exists(one.output)
        rc = _frame(one)
        state = "skipped (done before)" if done_before else ("done" if rc == 0 else "failed")
        print(f"rokeby.composite: frame {k}/{len(frames)} {os.path.basename(path)}: {state}", file=sys.stderr, flush=True)
        if rc != 0:
            failed.append(os.path.basename(path))
    if failed:
        print(f"rokeby.composite: {len(failed)} frame(s) failed: {', '.join(failed)} (run again with --skip-existing to redo only them)",
              file=sys.stderr)
        return 1
    return 0


def _frame(a) -> int:
    """One frame: ``a.input`` recomposited into ``a.output`` (0, or 2 with one line on stderr)."""
    if a.skip_existing and os.path.exists(a.output):
        return 0
    # Files are checked before the (slow) reconstruction: a missing one is one line and status 2.
    problem = _missing_files(a)
    if problem is not None:
        print(f"rokeby.composite: {problem}", file=sys.stderr)
        return 2
    try:  # before any work, named by its flag
        gl._check_k(a.kd, a.kr)
    except C.CompositingError as exc:
        print(f"rokeby.composite: argument {'--kd' if str(exc).startswith('k_d') else '--kr'}: {exc} (see --help)", file=sys.stderr)
        return 2

    t0 = time.perf_counter()
    try:
        p = C.read_exr(a.input, a.layer)
    except (C.CompositingError, OSError, RuntimeError) as exc:
        print(f"rokeby.composite: {exc}", file=sys.stderr)
        return 2
    t_read = time.perf_counter()
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rec = C.reconstruct(p, method=a.fit, env_size=a.env_size, noise_tolerance=a.noise_tolerance)
        except C.CompositingError as exc:
            print(f"rokeby.composite: {exc}", file=sys.stderr)
            return 2
    for w in caught:
        print(f"rokeby.composite: warning: {w.message}", file=sys.stderr)
    t_rec = time.perf_counter()
    mask = rec.ids >= 0
    if a.objects:
        wanted = set(a.objects)
        mask &= np.isin(np.rint(p.index_ob).astype(int), sorted(wanted))
    n = rec.normals
    try:
        if a.smooth:
            n = C.bilateral_smooth(n, p.depth, sigma_s=a.smooth, sigma_d=a.smooth_depth, mask=mask)
        if a.emboss is not None:
            n = C.emboss(n, a.emboss, mask=mask)
        if a.ripple:
            c = a.ripple_center
            h = C.ripple(p.shape, None if c is None else (c[1], c[0]), a.ripple_wavelength, a.ripple_radius)
            n = C.bump(n, h, a.ripple, mask=mask)
        if a.noise:
            c = a.noise_center
            h = C.noise_decal(p.shape, a.noise_size, a.noise_octaves, a.noise_seed, None if c is None else (c[1], c[0]),
                              a.noise_radius)
            n = C.bump(n, h, a.noise, mask=mask)
        if a.bump:
            n = C.bump(n, _read_height(a.bump, p.shape), a.bump_strength, mask=mask)
    except (C.CompositingError, OSError, ValueError) as exc:  # a bad edit: say which, write nothing
        print(f"rokeby.composite: {exc}", file=sys.stderr)
        return 2
    t_edit = time.perf_counter()
    try:
        out, stats = C.recomposite(p, rec, n, k_d=a.kd, k_r=a.kr, backend=a.backend)
    except (C.CompositingError, RuntimeError, ImportError) as exc:  # no GPU context, no EGL, …
        print(f"rokeby.composite: --backend {a.backend}: {exc}", file=sys.stderr)
        return 2
    t_comp = time.perf_counter()
    try:
        C.write_exr(a.output, out, p.header)  # written whole (transaction.write_whole): a crash leaves no half frame
    except (OSError, RuntimeError) as exc:  # a read-only folder, a full disk
        print(f"rokeby.composite: output: cannot write {a.output}: {exc}", file=sys.stderr)
        return 2
    t_end = time.perf_counter()
    if a.report:
        rep = {
            "patches": [r.__dict__ for r in rec.reports],
            "stats": dict(stats),
            "backend": a.backend,
            "seconds": {"read": t_read - t0, "reconstruct": t_rec - t_read, "edit": t_edit - t_rec,
                        "recomposite": t_comp - t_edit, "write": t_end - t_comp, **rec.timings},
        }
        try:
            text = json.dumps(rep, indent=1, default=str)

            def dump(tmp):
                with open(tmp, "w") as f:
                    f.write(text)
            transaction.write_whole(a.report, dump)
        except OSError as exc:
            print(f"rokeby.composite: --report: cannot write {a.report}: {exc}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
