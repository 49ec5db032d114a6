"""How far renders, which interpolate the stored field between vertices, land from the viewport
preview, which evaluates it per pixel; and what keeps the two close.

The render nodes read the field's view-independent parts per vertex (per face corner where a
polygon's quaternions straddle the antipodal seam) and form eq. 7's R_a r per shading point, as
the preview does. Across a region's edge, vertices outside it take the region's rotation from a
neighbour (:func:`extend_rotations_outward`), so a triangle there does not blend it with the
identity; one Euclidean region with a border reaches renders as its border ramp
(:func:`ramp_form`). :func:`_estimate` samples the centres of triangles that face the eye and
words the notes the mirror's report carries: renders land more than :data:`AGREEMENT_DEGREES`
from the preview (the mesh is too coarse for the field), or the edited reflection points below
the surface on more than :data:`FOLDED_SHARE` of what the eye sees (renders fold it back above).
"""

from __future__ import annotations

import time

import numpy as np

from ..core import native

# The render/preview agreement the status promises (degrees, 99th percentile at triangle centres).
AGREEMENT_DEGREES = 1.0
# A larger share of the visible surface reflecting below itself is reported.
FOLDED_SHARE = 0.05
# At most this many triangles are sampled for the interpolation-error estimate.
AGREEMENT_SAMPLES = 4000


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """Every directed edge (i, j) of the triangles, both directions, (6F, 2)."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return np.concatenate([e, e[:, ::-1]])


def extend_rotations_outward(parts: np.ndarray, edges: np.ndarray, rings: int = 2) -> np.ndarray:
    """Vertices where no region acts (a = 0) take R from a neighbour where one does, ``rings``
    edges out (``edges``: ``mesh_edges`` of the triangles). Their weight stays 0, so nothing changes there; but a triangle across a region's
    edge then interpolates the region's rotation, as the preview sees it, instead of blending it
    with the identity (which a weight of a few tenths would turn into a visible error)."""
    out = np.array(parts, dtype=np.float32)
    e = edges
    if len(e) == 0:
        return out
    outside = (out[:, 4] <= 0.0) & (out[:, 5] <= 0.0)
    filled = ~outside
    for _ in range(rings):
        take = outside[e[:, 0]] & filled[e[:, 1]] & ~filled[e[:, 0]]
        if not take.any():
            break
        dst, src = e[take, 0], e[take, 1]
        out[dst, :4] = out[src, :4]
        filled[dst] = True
    return out


def ramp_form(specs) -> bool:
    """Whether the region weight reaches renders as the border ramp u (one Euclidean region with
    a border): see rokeby_core's FieldOutput::ViewBlend."""
    return len(specs) == 1 and specs[0][0] == "EUCLIDEAN" and specs[0][3] > 0.0 and specs[0][2] > 0.0


def _interpolation_error(geo, parts, eye, rows, kwargs, timer, ramp=False):
    """How far the renderer's interpolation of the per-corner field between vertices lands from
    the per-pixel field (what the viewport preview evaluates), in degrees at the centres of the
    triangles that face the eye: (99th percentile, max, samples). The region weights and
    distances are interpolated there as the preview does."""
    tri = geo.triangles
    if len(tri) == 0 or len(rows) == 0:
        return None
    if len(tri) > AGREEMENT_SAMPLES:
        tri = tri[np.linspace(0, len(tri) - 1, AGREEMENT_SAMPLES).astype(np.int64)]
    c = geo.vertices[tri].astype(np.float64).mean(1)
    n = geo.normals[tri].astype(np.float64).sum(1)
    nl = np.linalg.norm(n, axis=1)
    incident = c - eye
    il = np.linalg.norm(incident, axis=1)
    ok = (nl > 1e-6) & (il > 1e-12)
    ok[ok] &= np.einsum("ij,ij->i", n[ok], incident[ok]) < 0.0  # seen from the front
    if not ok.any():
        return None
    tri, c, n, incident = tri[ok], c[ok], n[ok] / nl[ok, None], incident[ok] / il[ok, None]
    q = parts[tri].astype(np.float64)  # (S, 3, 6)
    sign = np.where(np.einsum("sij,sj->si", q[..., :4], q[:, 0, :4]) < 0.0, -1.0, 1.0)
    q[..., :4] *= sign[..., None]
    qi = q.mean(1)  # the renderer's interpolation at the centre: (q, a) averaged
    qi[:, :4] /= np.maximum(np.linalg.norm(qi[:, :4], axis=1, keepdims=True), 1e-300)
    r = incident - 2.0 * np.einsum("ij,ij->i", incident, n)[:, None] * n
    got = np.asarray(timer(native.view_blend, qi.astype(np.float32), r.astype(np.float32), ramp=ramp), dtype=np.float64)
    dkw = {"polar": kwargs["polar"]}
    if kwargs.get("distances") is not None:
        dkw["distances"] = np.ascontiguousarray(np.asarray(kwargs["distances"])[:, tri].mean(2), dtype=np.float32)
    if kwargs.get("regions"):
        regs = []
        for reg in kwargs["regions"]:
            if reg["kind"] == "weights":
                reg = dict(reg, values=np.ascontiguousarray(np.asarray(reg["values"])[tri].mean(1), dtype=np.float32))
            regs.append(reg)
        dkw["regions"] = regs
    want = timer(native.edited_directions, c.astype(np.float32), n.astype(np.float32), tuple(float(x) for x in eye), rows, **dkw)
    want = np.asarray(want, dtype=np.float64)
    cos = np.einsum("ij,ij->i", got, want) / np.maximum(np.linalg.norm(got, axis=1), 1e-300)
    ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    # Where e points below the surface, renders fold it back above (rokeby.reflection.render.shading) while the
    # preview looks it up as it is: those samples are counted apart.
    below = np.einsum("ij,ij->i", want, n) < 0.0
    kept = ang[~below] if (~below).any() else np.zeros(1)
    # Their share of the picture: each triangle weighted by the solid angle it covers from the eye.
    v = geo.vertices[tri].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    seen = area * np.abs(np.einsum("ij,ij->i", n, incident)) / np.maximum(il[ok] ** 2, 1e-300)
    share = float(seen[below].sum() / seen.sum()) if seen.sum() > 0 else 0.0
    return float(np.percentile(kept, 99)), float(kept.max()), int(len(ang)), share


def _estimate(state, args, timer=None):
    """Run the render-vs-preview estimate (``_interpolation_error``) and turn it into the notes
    the report carries; returns the figures."""
    geo, parts, eye, rows, kwargs, ramp = args
    est = _interpolation_error(geo, parts, eye, rows, kwargs, timer or (lambda fn, *a, **k: fn(*a, **k)), ramp)
    notes = []
    if est is not None and est[0] > AGREEMENT_DEGREES:
        notes.append(
            f"the mesh is too coarse for this field: between vertices renders differ from the per-pixel preview by up to {est[1]:.1f}° "
            f"(99th percentile {est[0]:.1f}° over {est[2]:,} triangles); subdivide the mirror's mesh where the reflection changes fast, or widen the region border")
    if est is not None and est[3] > FOLDED_SHARE:
        notes.append(
            f"on {100 * est[3]:.0f}% of the mirror as the render eye sees it the edited reflection points below the surface: renders fold it back "
            "above (no black), the preview shows it unfolded; make that edit smaller or confine it with a region")
    state.field_notes, state.estimate_args = notes, None
    state.estimate_time = time.perf_counter()
    return est
