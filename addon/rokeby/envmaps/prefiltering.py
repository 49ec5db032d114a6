"""Lighting from an environment: specular prefiltering across roughness levels (GGX, Phong,
Torrance–Sparrow lobes; ``rokeby_core::envmaps::prefilter``), order-2 SH irradiance (Ramamoorthi &
Hanrahan 2001), the brute-force reference sum the tests validate them against, and the lookup
between prefiltered levels that a preview shader does. Formulas and measured errors:
docs/envmaps.md."""

from __future__ import annotations

import numpy as np

from ..core import native
from .layouts import sample

LOBES = ("phong", "ggx", "torrance_sparrow")

# Blender roughness of the default prefiltered levels (GGX, α = roughness²): level 0 is the
# environment itself.
ROUGHNESS_LEVELS = tuple(i / 7 for i in range(8))


def prefilter(image, lobe: str = "ggx", params=ROUGHNESS_LEVELS, texels_per_radius: float = 6.0, tail: float = 1e-5) -> list:
    """Specular prefiltering of a lat-long image: one lat-long array per lobe parameter (GGX or
    Phong/Torrance–Sparrow σ), each at its own resolution (see docs/envmaps.md)."""
    return native.module().envmaps.prefilter(image, lobe, [float(p) for p in params], float(texels_per_radius), float(tail))


def irradiance(image, size: int = 32) -> dict:
    """Order-2 SH irradiance: {'coeffs', 'irradiance_coeffs', 'image'} (E(n)/π map, size × 2·size)."""
    return native.module().envmaps.irradiance(image, int(size))


def sh_irradiance(irradiance_coeffs, normals) -> np.ndarray:
    """E(n)/π from ``irradiance(...)['irradiance_coeffs']`` at (..., 3) normals, (..., C): the
    order-2 SH basis of the Rust core (``rokeby_core::compositing::sh``, Ramamoorthi & Hanrahan
    2001) at the normalised normals."""
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    coeffs = np.atleast_2d(np.asarray(irradiance_coeffs, dtype=np.float64))
    return native.module().compositing.sh_eval(coeffs, n.astype(np.float32)).astype(np.float64)


def reference(image, lobe: str, directions, param: float = 0.0) -> np.ndarray:
    """The seed's brute-force sum over every texel (the validation reference): lobe 'phong',
    'ggx', 'torrance_sparrow' (normalised like the prefiltered maps) or 'lambert' (E(n)/π)."""
    return native.module().envmaps.prefilter_reference(image, lobe, directions, float(param))


def lookup_levels(levels, params, directions, param) -> np.ndarray:
    """Prefiltered radiance at (..., 3) reflected ``directions`` for a lobe parameter between the
    prefiltered ones: bilinear in each level's map, linear between the two levels that bracket
    ``param`` (a scalar, or one value per direction) — what a preview shader does with the chain."""
    params = np.asarray(params, np.float64)
    if params.ndim != 1 or len(params) != len(levels) or len(levels) == 0:
        raise ValueError(f"params: need one value per level ({len(levels)}), got shape {params.shape}")
    order = np.argsort(params)
    ps = params[order]
    d = np.asarray(directions, np.float64)
    p = np.broadcast_to(np.asarray(param, np.float64), d.shape[:-1])
    if not np.isfinite(p).all():
        raise ValueError("param: contains NaN or inf")
    samples = np.stack([sample(levels[i], "latlong", d) for i in order], axis=0)
    x = np.clip(p, ps[0], ps[-1])
    hi = np.clip(np.searchsorted(ps, x, side="right"), 1, len(ps) - 1) if len(ps) > 1 else np.zeros(x.shape, int)
    lo = np.maximum(hi - 1, 0)
    span = np.where(ps[hi] > ps[lo], ps[hi] - ps[lo], 1.0)
    t = np.clip((x - ps[lo]) / span, 0.0, 1.0)[..., None]
    idx = np.indices(x.shape)
    a = samples[(lo, *idx)]
    b = samples[(hi, *idx)]
    return (1 - t) * a + t * b
