"""The compositing feature's entry points for scripts and operators (Zubiaga et al. 2016): render
with the passes, reconstruct, edit the normals, recomposite and show the frame; ``rokeby.api``
re-exports the names of ``__all__``. Bad arguments are ``RokebyError`` (a ValueError) naming them,
checked before any rendering or reading.
"""

from __future__ import annotations

__all__ = [
    "setup_compositing_passes",
    "recomposite_render",
    "recomposite_exr",
    "recomposite_exr_pixels",
    "use_in_compositor",
    "open_normal_brush",
    "paint_normals",
]

import time

from .. import compositing as comp
from ..core import native, schema
from ..core.errors import RokebyError


def _cancellable(fn):
    """``fn`` is an operation ``rokeby.core.native.cancel()`` can stop (see ``native.cancellable``)."""
    import functools  # noqa: PLC0415

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with native.cancellable():
            return fn(*args, **kwargs)
    return wrapper


def _scene(scene):
    import bpy  # noqa: PLC0415

    return scene if scene is not None else bpy.context.scene


def setup_compositing_passes(scene=None, view_layer=None) -> list[str]:
    """Enables the passes and AOVs that compositing-stage shape editing needs (see
    ``rokeby.compositing.setup_passes``); returns their names."""
    return comp.setup_passes(_scene(scene), view_layer)


@_cancellable
def recomposite_render(path: str, *, edit: str = "emboss", amount: float = 0.5, scene=None,
                       image_name: str = schema.RECOMPOSITED_IMAGE, k_d: float = 1.0, k_r: float = 1.0,
                       backend: str = "cpu", warn: bool = True, fit: str = "qp", noise_tolerance: float = 0.0):
    """Renders ``scene`` with the compositing passes to the multilayer EXR ``path``, reconstructs
    its environments, edits the normals (``edit``: 'emboss' with β = amount, 'ripple' or 'noise'
    (a procedural decal) with strength amount, 'smooth' with σ = amount pixels, or 'none') and shows the recomposited frame as the
    Blender image ``image_name``. ``backend``: 'cpu' (the Rust core), 'blender_gpu' (the GLSL
    shader drawn by Blender's gpu module) or 'moderngl' (see ``rokeby.compositing.recomposite``).
    The frame stays open for ``recomposite_exr`` (further edits without rendering again).
    ``warn``: reconstruction warnings (patches left unedited, large holes) as Python warnings.
    ``fit``, ``noise_tolerance``: the diffuse fit, 'qp' (the paper's; κ = noise_tolerance relaxes it
    by κ standard deviations of the pass's noise) or 'ls' (faster, and on noisy renders measured
    closer to the true environment; see docs/compositing.md). Returns (image, reconstruction
    report list)."""
    if backend not in comp.RECOMPOSITE_BACKENDS:  # before rendering
        raise RokebyError(f"backend: unknown {backend!r} (expected one of {', '.join(map(repr, comp.RECOMPOSITE_BACKENDS))})")
    if edit not in comp.EDITS:
        raise RokebyError(f"edit: unknown {edit!r} (expected one of {', '.join(map(repr, comp.EDITS))})")
    _check_fit(fit, noise_tolerance)
    p = comp.render_passes(_scene(scene), path)
    comp.close_render()
    opened = comp.open_render(path, backend=backend, passes=p, warn=warn, method=fit, noise_tolerance=noise_tolerance)
    img, _stats = _recomposite_opened(opened, edit, amount, k_d, k_r, image_name)
    return img, opened.reconstruction.reports


@_cancellable
def recomposite_exr(path: str, *, edit: str = "emboss", amount: float = 0.5, image_name: str = schema.RECOMPOSITED_IMAGE,
                    k_d: float = 1.0, k_r: float = 1.0, backend: str = "cpu", warn: bool = True, fit: str = "qp",
                    noise_tolerance: float = 0.0):
    """Edits a frame already rendered with the compositing passes (the multilayer EXR ``path``, say
    from ``recomposite_render``) without rendering: as ``recomposite_render`` otherwise. The last
    file stays open (``compositing.open_render``), so a second edit of the same unchanged file
    skips reading and reconstructing it and, on a GLSL backend, uploads only the edited normals.
    Returns (image, stats): stats has 'edited', 'masked', 'reused' (the frame was open), the
    seconds of 'open', 'edit', 'recomposite' and 'show', and 'warnings' (the reconstruction's,
    when this call reconstructed; ``warn`` also raises them as Python warnings). ``fit`` and
    ``noise_tolerance`` as for ``recomposite_render``: another fit of the open frame reconstructs
    again without reading the file."""
    out, stats = recomposite_exr_pixels(path, edit=edit, amount=amount, k_d=k_d, k_r=k_r, backend=backend, warn=warn,
                                        fit=fit, noise_tolerance=noise_tolerance)
    t0 = time.perf_counter()
    img = comp.show_image(image_name, out)
    record_edit(img, path, edit, amount, k_d, k_r, fit, noise_tolerance)
    stats["show_s"] = time.perf_counter() - t0
    return img, stats


def record_edit(img, path, edit, amount, k_d, k_r, fit, noise_tolerance):
    """The image shows this one-knob edit now: Paint Normals opened on it paints on top of it."""
    from . import brush  # noqa: PLC0415

    brush.record_edit(img, path, edit=edit, amount=amount, k_d=k_d, k_r=k_r, fit=fit, noise_tolerance=noise_tolerance)


@_cancellable
def recomposite_exr_pixels(path: str, *, edit: str = "emboss", amount: float = 0.5, k_d: float = 1.0, k_r: float = 1.0,
                           backend: str = "cpu", warn: bool = True, fit: str = "qp", noise_tolerance: float = 0.0):
    """``recomposite_exr`` without showing the result: returns (pixels (H, W, 3) float32, stats)
    and touches no Blender data, so with the 'cpu' backend it may run on a worker thread (the
    Recomposite Render operator does, stopping on Esc through ``rokeby.core.native.cancel()``)."""
    if edit not in comp.EDITS:  # before reading the file
        raise RokebyError(f"edit: unknown {edit!r} (expected one of {', '.join(map(repr, comp.EDITS))})")
    _check_fit(fit, noise_tolerance)
    t0 = time.perf_counter()
    opened = comp.open_render(path, backend=backend, warn=warn, method=fit, noise_tolerance=noise_tolerance)
    t1 = time.perf_counter()
    n = comp.edit_normals(opened.passes, opened.reconstruction, edit, amount)
    t2 = time.perf_counter()
    out, stats = opened.session(n, k_d=k_d, k_r=k_r)
    t3 = time.perf_counter()
    stats = {**stats, "reused": opened.reused, "edit_s": t2 - t1, "recomposite_s": t3 - t2, "show_s": 0.0, "open_s": t1 - t0,
             "warnings": opened.reconstruction.warnings() if opened.reconstructed else []}
    return out, stats


def _check_fit(fit, noise_tolerance):
    """The diffuse fit's arguments, checked before any rendering or reading."""
    if fit not in ("qp", "ls"):
        raise RokebyError(f"fit: unknown {fit!r} (expected 'qp' or 'ls')")
    if not 0 <= noise_tolerance < float("inf"):
        raise RokebyError(f"noise_tolerance: must be finite and ≥ 0 (in noise standard deviations), got {noise_tolerance}")
    if noise_tolerance > 0 and fit != "qp":
        raise RokebyError("noise_tolerance: only the 'qp' fit has constraints to relax")


def use_in_compositor(image_name: str = schema.RECOMPOSITED_IMAGE, *, scene=None):
    """Feeds the recomposited image ``image_name`` into the scene's compositor: an Image node
    (``schema.COMPOSITOR_NODE``) that later recomposites of that image keep current, linked to
    a Viewer for the backdrop; chain it with other compositor nodes. Returns the node."""
    import bpy  # noqa: PLC0415

    img = bpy.data.images.get(image_name)
    if img is None:
        raise comp.CompositingError(f"image_name: there is no image '{image_name}': click Render and Recomposite "
                                    "(or Recomposite Render) first")
    return comp.feed_compositor(_scene(scene), img)


def open_normal_brush(path: str, image_name: str = schema.RECOMPOSITED_IMAGE):
    """Opens the multilayer EXR ``path`` for painting normal edits on the Blender image
    ``image_name`` (*Paint Normals*; ``rokeby.compositing.brush.open_brush``). Returns the
    ``BrushSession`` that ``paint_normals`` takes."""
    from . import brush  # noqa: PLC0415

    return brush.open_brush(path, image_name)


def paint_normals(session, points, *, radius: float = 20.0, strength: float = 0.5, mode: str = "emboss") -> dict:
    """One brush stroke through ``points`` ((row, col) pixels, row 0 at the top): 'emboss', 'bump'
    or 'smooth' of ``radius`` pixels and ``strength`` in (0, 1], recomposited into the session's
    image (``rokeby.compositing.brush.paint_stroke``)."""
    from . import brush  # noqa: PLC0415

    return brush.paint_stroke(session, points, radius, strength, mode)


def _recomposite_opened(opened, edit, amount, k_d, k_r, image_name):
    t0 = time.perf_counter()
    n = comp.edit_normals(opened.passes, opened.reconstruction, edit, amount)
    t1 = time.perf_counter()
    out, stats = opened.session(n, k_d=k_d, k_r=k_r)
    t2 = time.perf_counter()
    img = comp.show_image(image_name, out)
    record_edit(img, opened.path, edit, amount, k_d, k_r, *opened.fit)
    stats = {**stats, "reused": opened.reused, "edit_s": t1 - t0, "recomposite_s": t2 - t1,
             "show_s": time.perf_counter() - t2}
    return img, stats
