"""The rendered frame open for editing (:func:`open_render`): its passes, reconstruction and
recompositing session kept between edits of the same file, so an edit after the first costs only
the edit and the recompositing."""

from __future__ import annotations

from dataclasses import dataclass

from .errors import CompositingError
from .exr_io import read_exr
from .passes import Passes
from .reconstruction import Reconstruction, reconstruct
from .recompositing import RECOMPOSITE_BACKENDS, RecompositeSession


@dataclass
class RenderEdit:
    """A rendered frame open for editing: its passes, its reconstruction and a recompositing
    session, kept by ``open_render`` between edits of the same file."""

    path: str
    passes: Passes
    reconstruction: Reconstruction
    session: RecompositeSession
    fit: tuple = ("qp", 0.0)  # the reconstruction's (method, noise_tolerance)
    reused: bool = False  # whether open_render found the file already open
    reconstructed: bool = True  # whether the last open_render reconstructed it


_OPEN: dict = {}  # the one frame open for editing (its arrays are ~150 MB at 1920×1080)


def _file_key(path: str) -> tuple:
    import os  # noqa: PLC0415

    st = os.stat(path)  # the change time and inode too: a coarse-clock filesystem may keep mtime and size
    return os.path.realpath(path), st.st_mtime_ns, st.st_ctime_ns, st.st_ino, st.st_size


def open_render(path: str, *, backend: str = "cpu", passes: Passes | None = None, warn: bool = True,
                method: str = "qp", noise_tolerance: float = 0.0) -> RenderEdit:
    """The multilayer EXR ``path`` (rendered after ``setup_passes``) read, reconstructed and ready to
    recomposite. The last file opened stays open: opening it again while the file is unchanged
    (same modification and change times, inode and size) reuses its passes; with the same diffuse
    fit (``method``, ``noise_tolerance``: see ``reconstruct``) its reconstruction, and with the same
    backend its session too (on a GLSL backend the passes stay on the GPU), so that trying edit
    after edit costs only the edit and the recompositing. A changed file is read again.
    ``passes``: the file's passes if the caller has just read them (``render_passes``); ``warn``:
    reconstruction warnings as Python warnings (when reconstructing; ``.reconstruction.warnings()``
    lists them in any case)."""
    if backend not in RECOMPOSITE_BACKENDS:
        raise CompositingError(f"backend: unknown {backend!r} (expected one of {', '.join(map(repr, RECOMPOSITE_BACKENDS))})")
    fit = (method, float(noise_tolerance))
    try:
        key = _file_key(path)
    except OSError as exc:
        raise CompositingError(f"{path}: cannot open the rendered passes ({exc.strerror or exc})") from None
    got = _OPEN.get("frame")
    if got is not None and got[0] == key:
        opened = got[1]
        opened.reconstructed = opened.fit != fit
        if opened.reconstructed:  # another diffuse fit of the same passes: reconstruct, no reading
            opened.reconstruction = reconstruct(opened.passes, method=method, noise_tolerance=noise_tolerance, warn=warn)
            opened.fit = fit
            opened.session = RecompositeSession(opened.passes, opened.reconstruction, backend=backend)
        elif opened.session.backend != backend:  # same reconstruction, another backend: a new session
            opened.session = RecompositeSession(opened.passes, opened.reconstruction, backend=backend)
        opened.reused = True
        return opened
    _OPEN.clear()  # before reading the next one: only one frame's arrays at a time
    p = passes if passes is not None else read_exr(path)
    rec = reconstruct(p, method=method, noise_tolerance=noise_tolerance, warn=warn)
    opened = RenderEdit(path=path, passes=p, reconstruction=rec,
                        session=RecompositeSession(p, rec, backend=backend), fit=fit)
    _OPEN["frame"] = (key, opened)
    return opened


def close_render() -> None:
    """Forgets the frame ``open_render`` keeps (and its memory)."""
    _OPEN.clear()
