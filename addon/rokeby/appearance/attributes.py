"""The painted per-point values: the mesh attributes of the parameters, read and written with
foreach_get/foreach_set (non-finite values are refused, nothing written)."""

from __future__ import annotations

import numpy as np

from .parameters import COLORS, PARAMS


def _attr(obj, param):
    if param not in PARAMS:
        raise ValueError(f"param: unknown parameter {param!r} (expected one of {', '.join(PARAMS)})")
    attr = PARAMS[param][0]
    a = obj.data.attributes.get(attr)
    if a is None:
        raise ValueError(f"obj: '{obj.name}' has no attribute {attr!r}: click Set Up Appearance Painting first (Rokeby ▸ Appearance Painting)")
    return a


def read(obj, param) -> np.ndarray:
    """The painted values of ``param``: (N,) floats, or (N, 4) RGBA for the colours ('diffuse', 'specular_tint')."""
    a = _attr(obj, param)
    n = len(obj.data.vertices)
    if param in COLORS:
        v = np.empty(4 * n, np.float32)
        a.data.foreach_get("color", v)
        return v.reshape(n, 4)
    v = np.empty(n, np.float32)
    a.data.foreach_get("value", v)
    return v


def _finite32(values, what: str) -> np.ndarray:
    """``values`` as float32, refused (nothing written) when any is NaN or overflows to inf."""
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.ascontiguousarray(values, np.float32)
    if not np.isfinite(out).all():
        raise ValueError(f"{what}: the stroke would write non-finite values; nothing was painted")
    return out


def _write(obj, param, values):
    values = _finite32(values, "value")
    a = _attr(obj, param)
    a.data.foreach_set("color" if param in COLORS else "value", np.ascontiguousarray(values, np.float32).ravel())
    obj.data.update()
