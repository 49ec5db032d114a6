"""Environment-map layouts and lookups: lat-long (H, W, C; Blender's equirectangular convention,
+X at the image centre), cube (6, S, S, C; +X, −X, +Y, −Y, +Z, −Z), sphere or mirror ball
(S, S, C) and dual paraboloid (2, S, S, C); conversions between them and bilinear, seam-correct
lookups E(d), computed by the Rust core (``rokeby_core::envmaps::envmap``)."""

from __future__ import annotations

import numpy as np

from ..core import native

LAYOUTS = ("latlong", "cube", "sphere", "paraboloid")


def convert(image, layout_in: str, layout_out: str, size: int, supersample: int = 1) -> np.ndarray:
    """The environment ``image`` (``layout_in``) on ``layout_out``: lat-long maps are size × 2·size,
    faces size × size; each texel averages supersample² bilinear, seam-correct lookups."""
    return native.module().envmaps.convert(image, layout_in, layout_out, int(size), int(supersample))


def sample(image, layout: str, directions) -> np.ndarray:
    """Bilinear, seam-correct lookups E(d): (..., 3) directions → (..., C)."""
    return native.module().envmaps.sample(image, layout, directions)
