"""Environment images on disk: OpenEXR and Radiance RGBE (``.hdr``) read and written by the Rust
core, 8-bit PNG/JPEG read through Blender's image loader and sRGB-decoded. Arrays are float32
(H, W, C) with row 0 the top row of the image file; :func:`flip_rows` converts to and from
Blender's bottom-up ``Image.pixels``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core import exr, native


def read_exr(path) -> np.ndarray:
    """An OpenEXR file's RGB (or RGBA, or single-channel Y) pixels as (H, W, C) float32, row 0 at
    the top (read by the Rust core: ``core.exr``, DWAA/DWAB included). A file that is not a
    readable EXR, or has none of those channels, raises ValueError naming it."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    # DWAA/DWAB (Blender's studio worlds are DWAB) decoded too: a few texels may differ from
    # OpenEXR's decoding by a rounding, far below what lighting from the map shows.
    ch = exr.read(path, dwa=True)[0].channels
    px = exr.colour(ch)
    if px is None:
        if "Y" not in ch:
            raise ValueError(f"{path} has no RGB/RGBA/Y channels (has {', '.join(ch)})")
        px = np.asarray(ch["Y"], np.float32)[..., None]
    return np.ascontiguousarray(px, dtype=np.float32)


def write_exr(path, pixels) -> Path:
    """Writes (H, W, 3|4) or (H, W) float pixels (row 0 at the top) as a float32 EXR (channels
    R, G, B[, A] or Y; ZIP compressed)."""
    px = np.asarray(pixels, dtype=np.float32)
    if px.ndim == 2:
        px = px[..., None]
    if px.ndim != 3 or px.shape[2] not in (1, 3, 4):
        raise ValueError(f"pixels: an EXR image must have shape (H, W), (H, W, 3) or (H, W, 4), got {px.shape}")
    if not np.isfinite(px).all():
        raise ValueError("pixels: contain NaN or inf")
    data = exr.encode(exr.split("", px), None, "zip")
    path = Path(path)
    from ..blender import transaction  # noqa: PLC0415
    transaction.write_whole(path, lambda tmp: exr.save(tmp, data))  # no half-written file, the old one kept on failure
    return path


def read_hdr(path) -> np.ndarray:
    """A Radiance RGBE (``.hdr``) file's pixels as (H, W, 3) float32, row 0 at the top (the Rust
    core's decoder: flat and run-length encoded scanlines, the standard ``-Y H +X W``
    orientation; other variants raise ValueError saying what the file holds)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    try:
        return native.module().envmaps.rgbe_decode(path.read_bytes())
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def write_hdr(path, pixels) -> Path:
    """Writes (H, W, 3|4) float pixels (row 0 at the top; alpha dropped) as a run-length encoded
    Radiance RGBE file: 8-bit mantissas with a shared exponent (within 1/128 of each pixel's
    largest channel); negative values become 0, NaN/inf are refused."""
    px = np.asarray(pixels, dtype=np.float32)
    if px.ndim != 3 or px.shape[2] not in (3, 4):
        raise ValueError(f"pixels: a Radiance image must have shape (H, W, 3) or (H, W, 4), got {px.shape}")
    path = Path(path)
    path.write_bytes(native.module().envmaps.rgbe_encode(np.ascontiguousarray(px[..., :3])))
    return path


# 8-bit (LDR) environment images, as Fraser's implementation also loads: read through Blender's
# image loader (the only PNG/JPEG decoder in Rokeby's environment), sRGB-decoded to linear here.
LDR_SUFFIXES = (".png", ".jpg", ".jpeg")


def srgb_to_linear(values) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1, the piecewise curve Blender's 'sRGB'
    colour space uses): v ≤ 0.04045 → v / 12.92, else ((v + 0.055) / 1.055)^2.4."""
    v = np.asarray(values, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((np.maximum(v, 0.0) + 0.055) / 1.055) ** 2.4).astype(np.float32)


def read_ldr(path) -> np.ndarray:
    """An 8-bit (or 16-bit PNG) environment image, PNG or JPEG, as (H, W, 3) float32 linear values
    (the file's sRGB-encoded values decoded with :func:`srgb_to_linear`; an alpha channel is
    kept, undecoded, as a 4th channel), row 0 at the top. Decoded by Blender's image loader (bpy
    is imported here, not at module import)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"read_ldr: {path} does not exist")
    try:
        import bpy  # noqa: PLC0415
    except ImportError:
        raise ValueError(f"read_ldr: {path}: PNG/JPEG environments are decoded by Blender's image loader, and bpy is not importable here") from None
    try:
        img = bpy.data.images.load(str(path.resolve()), check_existing=False)
    except RuntimeError as e:
        raise ValueError(f"read_ldr: {path}: not a readable PNG or JPEG image ({e})") from None
    try:
        img.colorspace_settings.name = "Non-Color"  # the file's values as stored, decoded below
        w, h = img.size
        if w < 1 or h < 1 or not img.has_data:
            raise ValueError(f"read_ldr: {path}: not a readable PNG or JPEG image (no pixels)")
        # Blender's pixels are RGBA whatever the file holds; the depth says whether it had alpha
        # (8-bit: 8 grey, 16 grey+alpha, 24 RGB, 32 RGBA; float buffers: 96 RGB, 128 RGBA).
        alpha = img.depth in (16, 32, 128) if not (img.depth == 16 and img.is_float) else False
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    px = flip_rows(px.reshape(h, w, 4))
    if not np.isfinite(px).all():
        raise ValueError(f"read_ldr: {path}: decoded to non-finite values")
    rgb = srgb_to_linear(np.clip(px[..., :3], 0.0, 1.0))
    if alpha:
        return np.ascontiguousarray(np.concatenate([rgb, px[..., 3:4]], axis=-1))
    return np.ascontiguousarray(rgb)


def read_image(path) -> np.ndarray:
    """An environment image as (H, W, C) float32 linear values with row 0 at the top: HDR,
    OpenEXR (``.exr``) or Radiance (``.hdr``, ``.pic``), or 8-bit PNG/JPEG (``.png``, ``.jpg``,
    ``.jpeg``; sRGB-decoded, :func:`read_ldr`)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        return read_exr(path)
    if suffix in (".hdr", ".pic", ".rgbe"):
        return read_hdr(path)
    if suffix in LDR_SUFFIXES:
        return read_ldr(path)
    raise ValueError(f"read_image: {path}: expected an OpenEXR (.exr), Radiance (.hdr), PNG (.png) or JPEG (.jpg, .jpeg) file")


def flip_rows(pixels: np.ndarray) -> np.ndarray:
    """Top-down (file) rows ↔ bottom-up (Blender ``Image.pixels``) rows."""
    return np.ascontiguousarray(np.asarray(pixels)[::-1] if np.ndim(pixels) == 3 else np.asarray(pixels)[:, ::-1])
