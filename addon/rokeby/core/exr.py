"""OpenEXR files, read and written by the Rust core (``rokeby_native.exr_io.read``/``write``,
the pure-Rust ``exr`` crate).

Every EXR the add-on and ``python -m rokeby.composite`` read or write goes through here. No
OpenEXR C library is loaded for it: a Blender build that links its own OpenEXR (Debian's does)
would otherwise have two copies of the same C symbols in one process, and the add-on's reader
would call into Blender's library and crash Blender.

Pixels are numpy arrays over the data window, row 0 at its top (as OpenEXR stores them): float32
for half channels (widened exactly) and float channels, uint32 for uint channels, the values
OpenEXR reads bit for bit. Compressions read: none, RLE, ZIPS, ZIP (Blender's default), PIZ,
PXR24, B44, B44A. DWAA and DWAB (the pure-Rust decoder of these lossy codecs differs from
OpenEXR's in a few pixels) are refused with an error saying so, unless the caller takes them
(``dwa=True``: environment maps, among them Blender's own DWAB studio worlds); deep and
subsampled files are refused. A file that is not a readable EXR raises ``ValueError`` naming the
file and what is wrong; a missing or unreadable file stays an ``OSError``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import native

# The compressions the writer takes (OpenEXR's names).
WRITE_COMPRESSIONS = ("none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a")


@dataclass
class Part:
    """One part of an EXR file: ``channels`` name → (H, W) array in the file's (alphabetical)
    order, ``types`` name → "half" | "float" | "uint", ``header`` the string/int/float
    attributes, windows as (xmin, ymin, xmax, ymax) inclusive."""

    name: str | None
    channels: dict
    types: dict
    header: dict
    data_window: tuple
    display_window: tuple
    compression: str
    tiled: bool = False

    @property
    def shape(self) -> tuple[int, int]:
        x0, y0, x1, y1 = self.data_window
        return (y1 - y0 + 1, x1 - x0 + 1)


class ExrError(ValueError):
    """A file that is not a readable EXR: ``path`` and ``why`` (what is wrong with it)."""

    def __init__(self, path: str, why: str):
        super().__init__(f"{path}: {why}")
        self.path, self.why = path, why


def decode(data: bytes, name: str = "data", dwa: bool = False) -> list[Part]:
    """The parts of the EXR file bytes ``data``; ``name`` (the file) starts any error message.
    ``dwa``: decode DWAA/DWAB files too (a few pixels may differ from OpenEXR's decoding by a
    rounding) instead of refusing them."""
    try:
        parts = native.module().exr_io.read(data, dwa)
    except ValueError as exc:
        why = str(exc)
        raise ExrError(name, why[len("data: "):] if why.startswith("data: ") else why) from None
    return [Part(name=p["name"], channels=p["channels"], types=p["types"], header=p["header"],
                 data_window=tuple(p["data_window"]), display_window=tuple(p["display_window"]),
                 compression=p["compression"], tiled=p["tiled"]) for p in parts]


def read(path, dwa: bool = False) -> list[Part]:
    """The parts of the EXR file ``path`` (``OSError`` when it cannot be opened, ``ValueError``
    naming it when it is not a readable EXR); ``dwa`` as for :func:`decode`."""
    path = Path(path)
    return decode(path.read_bytes(), str(path), dwa)


def encode(channels: dict, header: dict | None = None, compression: str = "zip", half=()) -> bytes:
    """The bytes of a one-part scanline EXR: ``channels`` name → (H, W) float array (one shape,
    row 0 at the top; float, or half for the names in ``half``), ``header`` name → string
    attributes, ``compression`` one of ``WRITE_COMPRESSIONS``."""
    chans = {k: np.ascontiguousarray(v, np.float32) for k, v in channels.items()}
    return native.module().exr_io.write(chans, dict(header or {}), compression, list(half))


def save(path, data: bytes) -> None:
    """Writes encoded EXR bytes to ``path`` (callers that must never leave half a file save to a
    temporary name and rename it: ``blender.transaction.write_whole``)."""
    with open(path, "wb") as f:
        f.write(data)


def write(path, channels: dict, header: dict | None = None, compression: str = "zip", half=()) -> None:
    """Writes :func:`encode`'s file to ``path``."""
    save(path, encode(channels, header, compression, half))


def split(prefix: str, pixels: np.ndarray) -> dict:
    """(H, W, C) pixels as the channels ``prefix`` + R, G, B[, A] (C = 3, 4), or ``prefix`` + Y
    for (H, W) / (H, W, 1): the names OpenEXR gives a colour image."""
    px = np.asarray(pixels)
    if px.ndim == 2:
        px = px[..., None]
    if px.ndim != 3 or px.shape[2] not in (1, 3, 4):
        raise ValueError(f"pixels must have shape (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got {px.shape}")
    names = {1: "Y", 3: "RGB", 4: "RGBA"}[px.shape[2]]
    return {prefix + c: px[..., i] for i, c in enumerate(names)}


def colour(channels: dict, prefix: str = "") -> np.ndarray | None:
    """The (H, W, 3|4) float32 stack of ``prefix`` + R, G, B (and A when it is there), or None
    when one of R, G, B is missing: what OpenEXR's Python reader groups as one RGB(A) channel."""
    keys = [prefix + c for c in "RGB"]
    if not all(k in channels for k in keys):
        return None
    if prefix + "A" in channels:
        keys.append(prefix + "A")
    return np.stack([np.asarray(channels[k], np.float32) for k in keys], -1)


def grouped(channels: dict) -> dict:
    """``channels`` as OpenEXR's Python reader returns them by default: each R, G, B[, A] set
    stacked into one (H, W, 3|4) array named by its prefix ("RGB"/"RGBA" without one), every
    other channel on its own, in the order of their first channel."""
    out = {}
    for k in channels:
        prefix, dot, last = k.rpartition(".")
        prefix += dot
        rgb = colour(channels, prefix) if last in ("R", "G", "B", "A") else None
        if rgb is None:
            out[k] = channels[k]
            continue
        g = prefix[:-1] if prefix else ("RGBA" if rgb.shape[2] == 4 else "RGB")
        if g not in out:
            out[g] = rgb
    return out
