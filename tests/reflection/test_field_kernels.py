"""each field kernel (f32 lanes: portable, AVX2, AVX-512, forced with ROKEBY_SIMD) against
the scalar f64 reference (ROKEBY_SIMD=scalar, exact polar), the oracle, through rokeby_native: the
per-pixel directions and the per-vertex field the add-on writes agree within 1e-5 rad."""

import numpy as np
import pytest
import rokeby_native as rn

from support.reference import dir_angle, quat_to_matrix, random_constraints, rot_angle
from rokeby import api

KERNELS = ["portable", "avx2", "avx512"]
TOL = 1e-5


def mirror(h, w):
    """A curved mirror z = 0.3 (x² + y²): a (h, w) G-buffer of positions and normals."""
    ys, xs = np.mgrid[0:h, 0:w]
    x, y = 2 * (xs + 0.5) / w - 1, 2 * (ys + 0.5) / h - 1
    pos = np.stack([x, y, 0.3 * (x * x + y * y)], -1).astype(np.float32)
    nrm = np.stack([-0.6 * x, -0.6 * y, np.ones_like(x)], -1)
    return pos, (nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)).astype(np.float32)


def force(monkeypatch, kernel):
    """Sets ROKEBY_SIMD; a kernel this CPU lacks is skipped (forcing it runs a narrower one, which
    its own parameter already tests)."""
    monkeypatch.setenv("ROKEBY_SIMD", kernel)
    if rn.reflection.field_kernel() != kernel:
        pytest.skip(f"this CPU lacks {kernel} (ROKEBY_SIMD={kernel} runs {rn.reflection.field_kernel()})")


def test_rokeby_simd_forces_a_kernel_and_never_an_unsupported_one(monkeypatch):
    monkeypatch.setenv("ROKEBY_SIMD", "scalar")
    assert rn.reflection.field_kernel() == "scalar"
    monkeypatch.setenv("ROKEBY_SIMD", "portable")
    assert rn.reflection.field_kernel() == "portable"
    monkeypatch.setenv("ROKEBY_SIMD", "avx512")
    assert rn.reflection.field_kernel() in ("avx512", "avx2", "portable")
    monkeypatch.delenv("ROKEBY_SIMD")
    assert rn.reflection.field_kernel() != "scalar"  # the widest this CPU runs


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("k", [1, 8, 32])
def test_per_pixel_kernel_matches_the_f64_reference(monkeypatch, rng, kernel, k):
    pos, nrm = mirror(37, 53)
    eye = np.array([0.25, -2.5, 3.0], np.float32)
    c = random_constraints(rng, k, spread=0.8, max_edit=0.8)
    c[:, :3] = pos.reshape(-1, 3)[rng.choice(37 * 53, k, replace=False)]  # on the mirror, one on a pixel
    monkeypatch.setenv("ROKEBY_SIMD", "scalar")
    want = rn.reflection.edited_directions(pos, nrm, eye, c, polar="exact")
    force(monkeypatch, kernel)
    got = rn.reflection.edited_directions(pos, nrm, eye, c, polar="fast")
    assert got.shape == want.shape
    assert np.max(dir_angle(got.reshape(-1, 3), want.reshape(-1, 3))) <= TOL


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("region", [False, True], ids=["everywhere", "euclidean-region"])
def test_per_vertex_field_as_the_addon_writes_it_matches_the_f64_reference(monkeypatch, rng, kernel, region):
    pos, _ = mirror(41, 43)
    pts = pos.reshape(-1, 3)
    c = random_constraints(rng, 8, spread=0.8, max_edit=0.8)
    c[:, :3] = pts[rng.choice(len(pts), 8, replace=False)]
    kw = {"regions": [{"kind": "euclidean", "center": (0.1, 0.0, 0.1), "radius": 0.8, "border": 0.3}]} if region else {}
    monkeypatch.setenv("ROKEBY_SIMD", "scalar")
    want = rn.reflection.rotation_field(pts, c, output="view_blend", polar="exact", **kw)
    force(monkeypatch, kernel)
    got = rn.reflection.rotation_field(pts, c, output="view_blend", polar="fast", **kw)
    assert np.max(rot_angle(quat_to_matrix(got[:, :4]), quat_to_matrix(want[:, :4]))) <= TOL
    np.testing.assert_allclose(got[:, 4:], want[:, 4:], atol=1e-6)
    # What the renderer makes of it per shading point agrees too.
    r = api.reflect(np.tile([[0.0, 0.3, -1.0]], (len(pts), 1)) / np.hypot(0.3, 1.0), np.tile([[0.0, 0.0, 1.0]], (len(pts), 1)))
    e_got = rn.reflection.view_blend(got, r.astype(np.float32))
    e_want = rn.reflection.view_blend(want, r.astype(np.float32))
    assert np.max(dir_angle(e_got, e_want)) <= TOL


@pytest.mark.parametrize("kernel", KERNELS)
def test_exact_polar_by_the_f64_lanes_is_the_scalar_svd(monkeypatch, rng, kernel):
    """polar="exact" through a vector kernel (f64 lanes of Newton's method, verified to about 1e-13
    rad of the SVD, the SVD elsewhere) gives the scalar SVD's answer: the same f64 rotation rounded
    to float32 twice, so within 3e-7 rad."""
    pos, nrm = mirror(29, 31)
    eye = np.array([0.25, -2.5, 3.0], np.float32)
    pts = pos.reshape(-1, 3)
    c = random_constraints(rng, 8, spread=0.8, max_edit=0.8)
    c[:, :3] = pts[rng.choice(len(pts), 8, replace=False)]
    monkeypatch.setenv("ROKEBY_SIMD", "scalar")
    want_px = rn.reflection.edited_directions(pos, nrm, eye, c, polar="exact")
    want_pt = rn.reflection.rotation_field(pts, c, output="view_blend", polar="exact")
    force(monkeypatch, kernel)
    got_px = rn.reflection.edited_directions(pos, nrm, eye, c, polar="exact")
    got_pt = rn.reflection.rotation_field(pts, c, output="view_blend", polar="exact")
    assert np.max(dir_angle(got_px.reshape(-1, 3), want_px.reshape(-1, 3))) <= 3e-7
    assert np.max(rot_angle(quat_to_matrix(got_pt[:, :4]), quat_to_matrix(want_pt[:, :4]))) <= 3e-7
