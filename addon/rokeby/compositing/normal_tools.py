"""Normal-editing tools on screen-space normals (H, W, 3); ``mask`` (H, W) limits the edit:
``emboss`` (n_z → β n_z), ``bump`` (height image) with ``ripple`` (the paper's fading 2D ripple
decal) or ``noise_decal``, ``bilateral_smooth`` (cross-bilateral on (n_x, n_y) with depth); and
the one-knob edits of the operators and ``rokeby.api`` (:func:`edit_normals`)."""

from __future__ import annotations

import math

import numpy as np

from ..core import native
from .errors import CompositingError
from .passes import Passes
from .reconstruction import Reconstruction


def _native_edit(fn, *args, **kw) -> np.ndarray:
    """A normal tool of the Rust core (``rokeby_core::compositing::normals``), its ValueErrors as CompositingError."""
    try:
        return fn(*args, **kw)
    except ValueError as exc:
        raise CompositingError(str(exc)) from None


def emboss(normals: np.ndarray, beta: float, mask=None) -> np.ndarray:
    """Normal embossing (LUMO): n_z → β n_z, renormalised; β ∈ (0, 1] makes the surface bulge.
    Background pixels (|n|₁ = 0), pixels outside ``mask`` (H, W; > 0.5 edits) and pixels the edit
    leaves unchanged keep their input bits (``rokeby_core::compositing::normals``, rows in parallel)."""
    if not 0 < beta <= 1:
        raise CompositingError(f"beta: must be in (0, 1], got {beta}")
    return _native_edit(native.module().compositing.normals_emboss, normals, beta, mask)


def _decal_place(shape, center, radius):
    """(row, col, radius) of a decal: the frame's centre and 0.35·min(H, W) by default; given
    ones must be finite (and the radius positive)."""
    h, w = shape
    cy, cx = (h / 2, w / 2) if center is None else (float(center[0]), float(center[1]))
    if not (math.isfinite(cy) and math.isfinite(cx)):
        raise CompositingError(f"center: must be finite pixel coordinates, got {center!r}")
    if radius is None:
        radius = 0.35 * min(h, w)
    elif not (math.isfinite(radius) and radius > 0):
        raise CompositingError(f"radius: must be positive and finite (pixels), got {radius}")
    return cy, cx, float(radius)


def ripple(shape, center=None, wavelength: float = 24.0, radius: float | None = None) -> np.ndarray:
    """The paper's fading 2D ripple height field (pixels): cos(2π d/λ)·(1 − d/radius)₊²."""
    h, w = shape
    cy, cx, radius = _decal_place(shape, center, radius)
    if not (math.isfinite(wavelength) and wavelength > 0):
        raise CompositingError(f"wavelength: must be positive and finite (pixels), got {wavelength}")
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    d = np.hypot(yy - cy, xx - cx)
    return (np.cos(2 * math.pi * d / wavelength) * np.clip(1 - d / radius, 0, None) ** 2).astype(np.float32)


def noise_decal(shape, size: float = 16.0, octaves: int = 3, seed: int = 0, center=None,
                radius: float | None = None) -> np.ndarray:
    """A procedural noise bump decal (H, W): fractal gradient noise of feature size ``size`` pixels
    and ``octaves`` octaves, seeded, faded like ``ripple`` by (1 − d/radius)₊² around ``center``
    ((row, col) pixels; default the frame's centre, radius 0.35·min(H, W)). Heights in pixels,
    within about ±size/4, so that ``bump(n, noise_decal(...), s)`` tilts normals alike at any size."""
    h, w = shape
    cy, cx, radius = _decal_place(shape, center, radius)
    if not (isinstance(seed, (int, np.integer)) and 0 <= seed < 2 ** 32):
        raise CompositingError(f"seed: expected an integer in [0, 2^32), got {seed!r}")
    if not (isinstance(octaves, (int, np.integer)) and 1 <= octaves <= 8):
        raise CompositingError(f"octaves: must be 1 to 8, got {octaves!r}")
    return _native_edit(native.module().compositing.normals_noise_decal, int(h), int(w), float(size), int(octaves), int(seed),
                        (float(cx), float(cy)), float(radius))


def bump(normals: np.ndarray, height: np.ndarray, strength: float = 1.0, mask=None) -> np.ndarray:
    """Bump mapping in screen space: ñ = normalize(n − s ∇h), ∇h = (∂h/∂col, −∂h/∂row, 0)
    (rows go down, screen y goes up; the gradient as ``np.gradient`` takes it); ``height`` (H, W)
    in pixels of height per pixel. Kept pixels as for ``emboss``."""
    height = np.asarray(height)
    if height.shape != np.shape(normals)[:2]:
        raise CompositingError(f"height: expected shape {np.shape(normals)[:2]} like the normals, got {height.shape}")
    return _native_edit(native.module().compositing.normals_bump, normals, height, float(strength), mask)


def bilateral_smooth(normals: np.ndarray, depth: np.ndarray, sigma_s: float = 3.0, sigma_d: float = 0.02,
                     mask=None) -> np.ndarray:
    """Cross-bilateral filter of the projected normals (n_x, n_y) with a depth range kernel
    (relative depth difference, σ_d), so occluding contours are kept; n_z = √(1 − |n̄|²). Window
    radius ⌈2σ_s⌉ (σ_s ≤ 50 pixels); pixels without a finite depth or normal neither move nor
    weigh. Kept pixels as for ``emboss``."""
    return _native_edit(native.module().compositing.normals_bilateral, normals, depth, float(sigma_s), float(sigma_d), mask)


EDITS = ("emboss", "ripple", "noise", "smooth", "none")


def edit_normals(p: Passes, rec: Reconstruction, edit: str, amount: float) -> np.ndarray:
    """The one-knob edits of the operators and ``rokeby.api`` on the patches' pixels: 'emboss'
    (β = amount), 'ripple' or 'noise' (a decal at the centre, strength amount), 'smooth'
    (cross-bilateral with depth, σ = amount pixels) or 'none' (the shown normals: material edits
    k_D, k_R only)."""
    n = rec.normals
    on = rec.ids >= 0
    if edit == "emboss":
        return emboss(n, amount, mask=on)
    if edit == "ripple":
        return bump(n, ripple(p.shape), amount, mask=on)
    if edit == "noise":
        return bump(n, noise_decal(p.shape), amount, mask=on)
    if edit == "smooth":
        return bilateral_smooth(n, p.depth, sigma_s=amount, mask=on)
    if edit == "none":
        return n
    raise CompositingError(f"edit: unknown {edit!r} (expected one of {', '.join(map(repr, EDITS))})")
