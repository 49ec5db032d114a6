"""Numerical extremes: scene scales from 1e-6 to 1e6, 10,000 constraints, constraints
closer than float precision, every pixel on a silhouette, near-degenerate triangles. Nothing may
come back NaN, non-unit or silently different from the same scene at scale 1."""

import numpy as np
import pytest

import rokeby_native as rn

SCALES = [1e-6, 1e-3, 1.0, 1e3, 1e6]


def _scene(rng, n=500, k=6):
    pts = rng.normal(size=(n, 3))
    nrm = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    idx = rng.choice(n, k, replace=False)
    r = rng.normal(size=(k, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    e = r + 0.6 * rng.normal(size=(k, 3))
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    rows = np.hstack([pts[idx], r, e]).astype(np.float32)
    return pts.astype(np.float32), nrm.astype(np.float32), rows


def _same_rotation(a, b, atol):
    # q and -q are the same rotation.
    d = np.minimum(np.abs(a - b).max(1), np.abs(a + b).max(1))
    return d.max() <= atol, d.max()


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("polar", ["exact", "fast"])
def test_field_is_scale_invariant(scale, polar):
    rng = np.random.default_rng(7)
    pts, _, rows = _scene(rng)
    ref = rn.reflection.rotation_field(pts, rows, polar=polar)
    scaled = rows.copy()
    scaled[:, :3] *= scale
    got = rn.reflection.rotation_field(pts * np.float32(scale), scaled, polar=polar)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-5)
    ok, err = _same_rotation(got, ref, 2e-4)
    assert ok, f"scale {scale}: field differs from scale 1 by {err}"


@pytest.mark.parametrize("scale", SCALES)
def test_regions_and_per_pixel_path_are_scale_invariant(scale):
    rng = np.random.default_rng(8)
    pts, nrm, rows = _scene(rng, n=64 * 64)
    eye = np.array([0.0, -5.0, 0.5], np.float32)
    region = {"kind": "euclidean", "center": [0.0, -1.0, 0.0], "radius": 1.2, "border": 0.4}
    ref = rn.reflection.edited_directions(pts.reshape(64, 64, 3), nrm.reshape(64, 64, 3), eye, rows, regions=[region])
    s = np.float32(scale)
    scaled = rows.copy()
    scaled[:, :3] *= s
    reg_s = dict(region, center=[0.0, -scale, 0.0], radius=1.2 * scale, border=0.4 * scale)
    got = rn.reflection.edited_directions((pts * s).reshape(64, 64, 3), nrm.reshape(64, 64, 3), eye * s, scaled, regions=[reg_s])
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, ref, atol=5e-4)


def test_ten_thousand_constraints():
    rng = np.random.default_rng(9)
    pts = rng.normal(size=(3000, 3)).astype(np.float32)
    k = 10_000
    cp = rng.normal(size=(k, 3))
    r = rng.normal(size=(k, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    e = r + 0.3 * rng.normal(size=(k, 3))
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    rows = np.hstack([cp, r, e]).astype(np.float32)
    q = rn.reflection.rotation_field(pts, rows, polar="fast")
    assert q.shape == (3000, 4) and np.isfinite(q).all()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
    # At a constraint's own position its weight 1/d² dominates: the constraint is met.
    at = rn.reflection.rotation_field(rows[:50, :3], rows, polar="exact")
    rot = _rotate(at, rows[:50, 3:6])
    cos = (rot * rows[:50, 6:9]).sum(1)
    assert np.median(cos) > 0.999


def _rotate(q, v):
    xyz, w = q[:, :3].astype(np.float64), q[:, 3:4].astype(np.float64)
    t = 2.0 * np.cross(xyz, v)
    return v + w * t + np.cross(xyz, t)


@pytest.mark.parametrize("gap", [0.0, 1e-12, 1e-9, 1e-7])
def test_constraints_closer_than_float_precision(gap):
    """Two constraints at (almost) the same place asking for different directions: the field
    there is a valid rotation between the two, never NaN."""
    p = np.array([1.0, 2.0, 3.0])
    r = np.array([0.0, 0.0, 1.0])
    e1 = np.array([0.0, 0.6, 0.8])
    e2 = np.array([0.6, 0.0, 0.8])
    rows = np.array([np.r_[p, r, e1], np.r_[p + gap, r, e2]], np.float32)
    pts = np.array([p, p + gap / 2, p + [0.1, 0, 0], p + [1e3, 0, 0]], np.float32)
    for polar in ("exact", "fast"):
        q = rn.reflection.rotation_field(pts, rows, polar=polar)
        assert np.isfinite(q).all()
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
        out = _rotate(q, np.broadcast_to(r, (4, 3)))
        # Between the two edits (both tilt the same amount away from r): never beyond them.
        assert (out @ r >= 0.8 - 1e-4).all()


def test_every_pixel_on_a_silhouette():
    """A G-buffer where every normal is perpendicular to its view ray (grazing everywhere)."""
    rng = np.random.default_rng(10)
    h = w = 48
    eye = np.array([0.0, -4.0, 0.0], np.float32)
    pos = rng.normal(size=(h, w, 3)).astype(np.float32)
    view = pos - eye
    t = rng.normal(size=(h, w, 3))
    nrm = np.cross(view, t)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    nrm = nrm.astype(np.float32)
    _, _, rows = _scene(rng, k=4)
    for k in (0, 4):
        e = rn.reflection.edited_directions(pos, nrm, eye, rows[:k])
        assert np.isfinite(e).all()
        np.testing.assert_allclose(np.linalg.norm(e, axis=-1), 1.0, atol=1e-4)
    e0 = rn.reflection.edited_directions(pos, nrm, eye, rows[:0])
    v = view / np.linalg.norm(view, axis=-1, keepdims=True)
    np.testing.assert_allclose(e0, v, atol=2e-3)  # grazing: the reflection continues the ray


def test_near_degenerate_triangles_in_geodesics():
    """A strip of triangles with slivers of area ~1e-14 next to normal ones: finite, monotone
    distances with both methods, close to the straight line along the strip."""
    n = 60
    xs = np.linspace(0.0, 1.0, n)
    top = np.stack([xs, np.full(n, 0.05), np.zeros(n)], 1)
    bottom = np.stack([xs, np.zeros(n), np.zeros(n)], 1)
    bottom[::2, 0] += 1e-7  # sliver-making perturbation
    verts = np.vstack([bottom, top]).astype(np.float64)
    faces = []
    for i in range(n - 1):
        faces.append([i, i + 1, n + i])
        faces.append([i + 1, n + i + 1, n + i])
    # and a genuinely degenerate (zero-area) triangle glued on
    verts = np.vstack([verts, [[0.5, -1e-9, 0.0]]])
    faces.append([n // 2, n // 2 + 1, len(verts) - 1])
    faces = np.array(faces, np.int64)
    for method in ("dijkstra", "heat"):
        d = rn.geometry.geodesic_distances(verts.astype(np.float32), faces, [0], method=method)[0]
        assert np.isfinite(d[: 2 * n]).all(), method
        along = d[:n]
        assert np.all(np.diff(along[::4]) > 0), method
        assert abs(along[-1] - 1.0) < 0.08, (method, along[-1])


def test_identical_constraints_at_different_places_are_one_constraint():
    """Constraints that all ask for the same r → e (at different points) make M rank 1 with a
    tie-break that prefers nothing: the field is the smallest rotation r → e, as with one of them
    (a rounding-noise tie-break used to pick an arbitrary twist about e)."""
    rng = np.random.default_rng(11)
    r = np.array([0.0, 0.0, 1.0])
    e = np.array([0.6, 0.0, 0.8])
    rows = np.array([np.r_[p, r, e] for p in rng.normal(size=(4, 3))], np.float32)
    pts = rng.normal(size=(300, 3)).astype(np.float32)
    for polar in ("exact", "fast"):
        ok, err = _same_rotation(rn.reflection.rotation_field(pts, rows, polar=polar), rn.reflection.rotation_field(pts, rows[:1], polar=polar), 1e-5)
        assert ok, (polar, err)
    nrm = rng.normal(size=(300, 3))
    nrm = (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)).astype(np.float32)
    eye = np.array([0.0, -5.0, 0.0], np.float32)
    np.testing.assert_allclose(rn.reflection.edited_directions(pts, nrm, eye, rows), rn.reflection.edited_directions(pts, nrm, eye, rows[:1]), atol=1e-5)
