"""Vector maths shared by every feature (bpy-free, numpy, vectorised over leading axes).

One home each for the rules the features must agree on:

- :func:`reflect` — the mirror reflection of an incident direction about a normal;
- :func:`refract` and :func:`total_internal_reflection` — Snell refraction with the one total
  internal reflection (TIR) rule of GLSL's and Blender's ``refract``: with c = −i·n and
  k = 1 − η²(1 − c²), the ray is totally internally reflected where k < 0 (and where k is NaN);
  there the refracted direction is the zero vector. The render node groups (Cycles, EEVEE) use
  GLSL's ``refract``, so the Python twins agree with the renders at the boundary too;
- :func:`smooth_step` and :func:`region_falloff` — the region border, as ``rokeby_core::reflection::region``
  defines it (rust/rokeby-core/src/reflection/region.rs ``smooth_step``/``influence``), NaN distances
  (unreachable points) included: they get weight 0.
"""

from __future__ import annotations

import numpy as np


def reflect(incident, normal) -> np.ndarray:
    """Mirror reflection of unit ``incident`` (pointing at the surface) about unit ``normal``:
    i − 2 (i·n) n."""
    i = np.asarray(incident, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    return i - 2.0 * np.sum(i * n, axis=-1, keepdims=True) * n


def _eta(eta, i: np.ndarray):
    """η as a scalar, or with a trailing axis to broadcast against (…, 3) directions."""
    e = np.asarray(eta, dtype=np.float64)
    if e.ndim == 0:
        return float(e)
    return e[..., None] if e.ndim < i.ndim else e


def total_internal_reflection(incident, normal, eta) -> np.ndarray:
    """Where refraction of unit ``incident`` (against unit ``normal``) with η = η_outside /
    η_inside is impossible: k = 1 − η²(1 − c²) < 0 with c = −i·n (NaN counts as TIR). Boolean
    array over the leading axes."""
    i = np.asarray(incident, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    eta = _eta(eta, i)
    c = -np.sum(i * n, axis=-1, keepdims=True)
    k = 1.0 - eta * eta * (1.0 - c * c)
    return ~(k >= 0.0)[..., 0]


def refract(incident, normal, eta) -> np.ndarray:
    """Snell refraction of unit ``incident`` (pointing at the surface, against unit ``normal``)
    with eta = η_outside / η_inside (1/IOR when entering): η i + (η c − √k) n; the zero vector
    where :func:`total_internal_reflection` holds. Vectorised over leading axes."""
    i = np.asarray(incident, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    eta = _eta(eta, i)
    c = -np.sum(i * n, axis=-1, keepdims=True)
    k = 1.0 - eta * eta * (1.0 - c * c)
    ok = k >= 0.0
    t = eta * i + (eta * c - np.sqrt(np.where(ok, k, 0.0))) * n
    return np.where(ok, t, 0.0)


def smooth_step(t) -> np.ndarray:
    """3t² − 2t³ on t clamped to [0, 1]; t ≤ 0 and NaN give 0 (region.rs ``smooth_step``)."""
    t = np.asarray(t, dtype=np.float64)
    t = np.where(t > 0.0, np.minimum(t, 1.0), 0.0)
    return t * t * (3.0 - 2.0 * t)


def region_falloff(d, radius: float, border: float) -> np.ndarray:
    """Influence at distance ``d`` from a region's centre (region.rs ``influence``): 1 for
    d ≤ radius − border, 1 − smooth_step over the border band, 0 for d ≥ radius and for NaN
    distances; a border larger than the radius is clamped to it, a border of 0 is a hard edge."""
    d = np.asarray(d, dtype=np.float64)
    border = min(float(border), float(radius))
    inner = float(radius) - border
    with np.errstate(invalid="ignore", divide="ignore"):
        edge = 1.0 - smooth_step((d - inner) / border) if border > 0.0 else np.zeros_like(d)
    return np.where(d < radius, np.where(d <= inner, 1.0, edge), 0.0)
