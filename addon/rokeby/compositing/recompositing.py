"""Recompositing (eqs. 3–5) with edited normals: reflectance passes DiffCol/GlossCol multiply the
reconstructed illumination (the paper's §6 extension); unmodified normals give the input image
back bit for bit. :func:`recomposite` for one image, :class:`RecompositeSession` for many edits of
one frame (a slider, a brush), on the CPU (Rust core) or a GLSL backend (``gl.py``, ``blender_gpu.py``)."""

from __future__ import annotations

import time

import numpy as np

from ..core import native
from .errors import CompositingError
from .gl import _check_k, _check_output, gl_recompositor, recomposite_frame
from .passes import Passes
from .reconstruction import Reconstruction


RECOMPOSITE_BACKENDS = ("cpu", "blender_gpu", "moderngl")


def recomposite(p: Passes, rec: Reconstruction, edited_normals: np.ndarray, *, k_d: float = 1.0,
                k_r: float = 1.0, use_occlusion: bool = True, backend: str = "cpu") -> tuple[np.ndarray, dict]:
    """Eqs. 3–5: the image (H, W, 3) with the edited screen-space normals. Returns (image, stats).

    ``backend``: 'cpu' (the Rust core, f32), 'blender_gpu' (the GLSL shader drawn by Blender's
    ``gpu`` module, ``rokeby.compositing.blender_gpu.recomposite_blender``; in background mode the first call makes the GPU
    context with one 8×8 EEVEE render) or 'moderngl' (the same shader on a headless EGL context).
    All three agree within 1e-4 relative and give unmodified normals back bit for bit. For many
    edits of one frame (a slider), ``RecompositeSession`` packs and uploads the passes once."""
    if backend == "cpu":  # one frame: the passes read in place, not copied into a session's core
        h, w = p.shape
        e = np.asarray(edited_normals)
        if e.shape != (h, w, 3):
            raise CompositingError(f"edited_normals: expected shape {(h, w, 3)} like the passes, got {e.shape}")
        _check_k(k_d, k_r)
        a, kw = _recomposite_args(p, rec, use_occlusion)
        out = native.module().compositing.recomposite(a[0], a[1], e, *a[3:], **kw, k_d=k_d, k_r=k_r)
        _check_output(out, a[6])
        return out
    return RecompositeSession(p, rec, use_occlusion=use_occlusion, backend=backend)(edited_normals, k_d=k_d, k_r=k_r)


def _recomposite_args(p: Passes, rec: Reconstruction, use_occlusion: bool) -> tuple[tuple, dict]:
    """``rokeby_native.compositing.recomposite``'s arguments (edited_normals None) and keywords for a frame."""
    ao = p.ao.mean(-1) if p.ao.ndim == 3 else p.ao
    args = (rec.ids, rec.normals, None, rec.view, p.diff_dir + p.diff_ind, p.gloss_dir + p.gloss_ind, p.image, rec.patches)
    kw = {"alpha_d": np.clip(ao, 0, 1) if use_occlusion else None,
          "alpha_r": np.clip(p.reflocc, 0, 1) if use_occlusion else None,
          "diffuse_color": p.diff_col, "reflection_color": p.gloss_col}
    return args, kw


class RecompositeSession:
    """Interactive recompositing of one rendered frame: an artist's slider loop. The passes and the
    reconstruction are checked and packed once, here; each call takes new edited normals (and
    k_D, k_R) and returns (image, stats) as ``recomposite`` does. On the CPU backend the passes
    are held by the Rust core (``rokeby_native.compositing.Recompositor``), each call passes only the edited
    normals and writes into ``out`` (or a new array), the GIL released, and the core refuses
    overflow itself (no pass over the result here). On a GLSL backend only the edited normals go to
    the GPU again: the other ten images and the reflection maps stay there, as long as no other
    frame is drawn by the same backend in between (then the next call uploads all). The passes and
    the reconstruction are read when the session is made (and, on a GLSL backend, uploaded on its
    first call): change them in place and make a new session. ``timings`` holds the last call's
    seconds ('check', 'recomposite', 'total')."""

    def __init__(self, p: Passes, rec: Reconstruction, *, use_occlusion: bool = True, backend: str = "cpu"):
        if backend not in RECOMPOSITE_BACKENDS:
            raise CompositingError(f"backend: unknown {backend!r} (expected one of {', '.join(map(repr, RECOMPOSITE_BACKENDS))})")
        self.shape = p.shape
        self.backend = backend
        self._args, self._kw = _recomposite_args(p, rec, use_occlusion)
        self._frame = None  # the GLSL backends' packed frame, made on the first call
        self._buffer = None
        self._native = None
        if backend == "cpu":  # the core holds the passes now: only the GLSL backends need the arrays again
            self._core()
            self._args = (None, None, None, None, None, None, p.image, rec.patches)
            self._kw = {}
        self.timings: dict = {}

    @property
    def buffer(self) -> np.ndarray:
        """A (H, W, 3) float32 array of the session's, for ``out=`` when the caller copies the image
        elsewhere before the next call (into a Blender image): no new array per edit."""
        if self._buffer is None:
            self._buffer = np.empty((*self.shape, 3), np.float32)
        return self._buffer

    def _check(self, edited_normals) -> np.ndarray:
        h, w = self.shape
        e = np.asarray(edited_normals)
        if e.shape != (h, w, 3):
            raise CompositingError(f"edited_normals: expected shape {(h, w, 3)} like the passes, got {e.shape}")
        return e

    def __call__(self, edited_normals, *, k_d: float = 1.0, k_r: float = 1.0, out: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
        """``out``: a (H, W, 3) float32 C-contiguous array to write the image into (CPU backend;
        e.g. ``buffer``), returned; None: a new one."""
        t0 = time.perf_counter()
        e = self._check(edited_normals)
        _check_k(k_d, k_r)
        if self.backend == "cpu":
            t1 = time.perf_counter()
            if out is None:
                out = np.empty((*self.shape, 3), np.float32)
            result = out, self._run(out, e, None, None, k_d, k_r)
        else:
            if self._frame is None:
                a = self._args
                self._frame = recomposite_frame(a[0], a[1], e, *a[3:], **self._kw, k_d=k_d, k_r=k_r)
                changed = None
            else:
                self._frame.set_edit(e, k_d, k_r)
                changed = ("rk_edited",)  # the backend uploads all if it drew another frame since
            t1 = time.perf_counter()
            result = self._backend().draw(self._frame, changed)
            _check_output(result, self._args[6])
            if out is not None:
                out[...] = result[0]
                result = out, result[1]
        t2 = time.perf_counter()
        self.timings = {"check": t1 - t0, "recomposite": t2 - t1, "total": t2 - t0}
        return result

    def _core(self):
        """The passes copied into the Rust core once (``rokeby_native.compositing.Recompositor``): the CPU
        backend's frames and every backend's windows."""
        if self._native is None:
            a = self._args
            self._native = native.module().compositing.Recompositor(a[0], a[1], *a[3:], **self._kw)
        return self._native

    def _run(self, out, edited, rows, cols, k_d, k_r) -> dict:
        try:
            return self._core().run(out, edited, rows, cols, k_d, k_r)
        except ValueError as exc:
            if "overflows float32" in str(exc):
                raise CompositingError(f"the recomposited image has non-finite pixels where the render is finite (k_d, k_r or "
                                       f"the edit too large for float32?); {exc}") from None
            raise CompositingError(str(exc)) from None

    def window(self, edited_normals, rows: slice, cols: slice, *, k_d: float = 1.0, k_r: float = 1.0,
               out: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
        """Eqs. 3–5 on the pixels rows × cols only, by the Rust core whatever the backend: the
        equations are per pixel, so the result equals those pixels of a whole-frame call. For a
        brush that changes a small part of the frame (``rokeby.compositing.brush``).
        ``edited_normals``: the window's ñ (rh, rw, 3), or the whole frame's (H, W, 3) of which
        the window is read. ``out``: None (a new (rh, rw, 3) array), an (rh, rw, 3) array, or the
        whole (H, W, 3) image of which only the window is written; float32, C-contiguous."""
        e = np.asarray(edited_normals)
        h, w = self.shape
        rr, cc = range(h)[rows], range(w)[cols]
        wshape = (len(rr), len(cc), 3)
        if e.shape not in (wshape, (h, w, 3)):
            raise CompositingError(f"edited_normals: expected shape {wshape} like the window (or {(h, w, 3)}), got {e.shape}")
        _check_k(k_d, k_r)
        if out is None:
            out = np.empty(wshape, np.float32)
        return out, self._run(out, e, rows, cols, k_d, k_r)

    def _backend(self):
        if self.backend == "blender_gpu":
            from . import blender_gpu as in_blender  # noqa: PLC0415 - not gl.py's recomposite_gpu

            in_blender.ensure_context()
            return in_blender.blender_recompositor()
        return gl_recompositor()
