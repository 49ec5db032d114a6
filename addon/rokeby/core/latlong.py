"""The lat-long (equirectangular) convention, bpy-free: world directions ↔ texture coordinates.

Blender's convention (its Environment Texture node, Z up): u = 0.5 − atan2(y, x)/2π, so +X at
u = 0.5, +Y at u = 0.25, −Y at u = 0.75, −X on the seam; v = 0.5 + latitude/π, row 0 at the bottom.
The same formulas as ``rokeby_core::envmaps::envmap::latlong_uv`` / ``latlong_dir``
(rust/rokeby-core/src/envmaps/envmap.rs), which the environment-map conversions use.
"""

from __future__ import annotations

import numpy as np


def direction_to_uv(d) -> np.ndarray:
    """(…, 3) world directions → (…, 2) texture coordinates (u, v) in [0, 1]²."""
    d = np.asarray(d, dtype=np.float64)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)
    v = 0.5 + np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])) / np.pi
    return np.stack([u % 1.0, v], axis=-1)


def uv_to_direction(u, v) -> np.ndarray:
    """Texture coordinates → unit world directions (…, 3); the inverse of :func:`direction_to_uv`."""
    phi = (0.5 - np.asarray(u, dtype=np.float64)) * 2 * np.pi
    lat = (np.asarray(v, dtype=np.float64) - 0.5) * np.pi
    return np.stack([np.cos(lat) * np.cos(phi), np.cos(lat) * np.sin(phi), np.sin(lat)], axis=-1)
