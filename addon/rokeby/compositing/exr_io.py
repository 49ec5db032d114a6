"""EXR files: the passes of a Blender multilayer EXR read (by the Rust core, ``core.exr``; missing
passes are named), a recomposited image written, and the frames of a sequence listed."""

from __future__ import annotations

import glob
import os
import re

import numpy as np

from ..blender import transaction
from ..core import exr
from .errors import CompositingError, MissingPasses
from .passes import PASSES, Passes, exr_pass_names


def _layer_channels(part_channels: dict, layer: str | None):
    layers = sorted({k.split(".")[0] for k in part_channels if "." in k})
    if layer is None:
        if not layers:
            raise CompositingError("not a Blender multilayer EXR (no 'Layer.Pass' channels)")
        layer = layers[0]
    elif layer not in layers:
        raise CompositingError(f"view layer {layer!r} not in the EXR (it has {layers})")
    return layer


def read_exr(path: str, layer: str | None = None) -> Passes:
    """Reads a Blender multilayer EXR (one view layer, default the first) into ``Passes``. A file
    that is not a readable EXR (truncated, corrupted, a compression or layout the reader does not
    take) is a ``CompositingError`` naming it and what is wrong; a missing or unreadable one stays
    an ``OSError``."""
    try:
        parts = exr.read(path)
    except exr.ExrError as exc:
        raise CompositingError(f"{path}: not a readable multilayer EXR (truncated or corrupted?): {exc.why}") from None
    if not parts:
        raise CompositingError(f"{path}: not a readable multilayer EXR (truncated or corrupted?): it has no image parts")
    return _passes(path, parts, layer)


def _pass_pixels(chans: dict, bases: list) -> "np.ndarray | None":
    """The pixels of the first of ``bases`` (``Layer.Pass``) the channels hold: R, G, B[, A] (the
    group OpenEXR's reader makes of them), or X[YZ], R[GB], V, Z; None when none is there."""
    for base in bases:
        rgb = exr.colour(chans, base + ".")
        if rgb is not None:
            return rgb
        for suffixes in ("XYZ", "RGB", "X", "V", "Z", "R"):
            keys = [f"{base}.{c}" for c in suffixes]
            if all(k in chans for k in keys):
                return np.stack([np.asarray(chans[k], np.float32) for k in keys], -1)
    return None


def _passes(path, parts: list, layer: str | None) -> Passes:
    # Blender 5.0+ writes a multilayer EXR as one part per pass by default (up to 4.5, and with
    # "interleave", one part): the channel names carry the layer and pass either way.
    chans = {}
    for p in parts:
        chans.update(p.channels)
    layer = _layer_channels(chans, layer)
    arrays, missing = {}, []
    for name, (attr, ch) in PASSES.items():
        a = _pass_pixels(chans, [f"{layer}.{n}" for n in exr_pass_names(name)])
        if a is None:
            missing.append(name)
            continue
        if a.ndim == 2:
            a = a[..., None]
        if ch == 1:
            a = a[..., 0]
        elif a.shape[-1] >= 3:
            a = a[..., :3]
        else:
            raise CompositingError(f"pass {name}: expected 3 channels, got {a.shape[-1]}")
        arrays[attr] = np.ascontiguousarray(a)
    if missing:
        raise MissingPasses(missing, str(path))
    comb = exr.colour(chans, f"{layer}.Combined.")
    alpha = comb[..., 3].copy() if comb is not None and comb.shape[2] == 4 else None
    header = {k: v for k, v in parts[0].header.items() if isinstance(v, (str, int, float))}
    p = Passes(alpha=alpha, header=header, **arrays)
    p.validate()
    return p


def write_exr(path: str, image: np.ndarray, header: dict | None = None) -> None:
    """Writes an (H, W, 3) float32 image as an RGB EXR (float channels R, G, B, ZIP compressed,
    the string attributes of ``header`` but File and Date), whole or not at all."""
    hdr = {k: v for k, v in (header or {}).items() if isinstance(v, str) and k not in ("File", "Date")}
    data = exr.encode(exr.split("", np.asarray(image, np.float32)[..., :3]), hdr, "zip")
    transaction.write_whole(path, lambda tmp: exr.save(tmp, data))  # no half-written file, the old one kept on failure


def sequence_frames(directory: str, pattern: str = "*.exr") -> list[str]:
    """The frames of a sequence, in frame order: files in ``directory`` matching ``pattern``, a
    glob ('*.exr', 'shot_*.exr') or a frame-number pattern with '#' for each digit
    ('shot_####.exr'). Numbers sort by value (frame_2 before frame_10). The add-on's sequence
    operator and ``python -m rokeby.composite --sequence`` both list frames with this."""
    if not directory or not os.path.isdir(directory):
        raise CompositingError(f"folder: {directory!r} is not a folder")
    if "#" in pattern:
        regex = re.compile("^" + re.sub(r"#+", lambda m: rf"\d{{{len(m.group())}}}", re.escape(pattern).replace(r"\#", "#")) + "$")
        names = [n for n in os.listdir(directory) if regex.match(n)]
    else:
        names = [os.path.basename(f) for f in glob.glob(os.path.join(glob.escape(directory), pattern))]
    key = lambda n: [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", n)]  # noqa: E731
    return [os.path.join(directory, n) for n in sorted(names, key=key) if os.path.isfile(os.path.join(directory, n))]
