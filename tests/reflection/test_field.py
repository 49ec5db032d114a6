"""The MLS reflection-rotation field through the Python API: its maths against an independent
float64 reference, on random configurations and on a real mesh."""

import numpy as np
import pytest
import rokeby_native as rn
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from support.reference import dir_angle, field_matrices, quat_to_matrix, random_constraints, region_blend, rot_angle
from rokeby import api


def realistic_constraints(rng, k, spread=1.0, max_edit=1.0):
    """K constraints at separated points with edits of up to `max_edit` radians."""
    return random_constraints(rng, k, spread=spread, max_edit=max_edit)


@pytest.mark.parametrize("k", [1, 2, 4, 8, 32])
@pytest.mark.parametrize("polar", ["exact", "fast"])
def test_matches_float64_reference(rng, k, polar):
    c = realistic_constraints(rng, k)
    pts = rng.uniform(-1.5, 1.5, (400, 3)).astype(np.float32)
    got = quat_to_matrix(rn.reflection.rotation_field(pts, c, polar=polar))
    if k == 1:
        # Rank 1: every rotation taking r to e fits; the documented answer is the smallest.
        r, e = c[0, 3:6].astype(np.float64), c[0, 6:9].astype(np.float64)
        ax = np.cross(r, e)
        ang = np.arctan2(np.linalg.norm(ax), r @ e)
        ax /= np.linalg.norm(ax)
        kx = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
        ref = np.broadcast_to(np.eye(3) + np.sin(ang) * kx + (1 - np.cos(ang)) * kx @ kx, got.shape)
    else:
        ref = field_matrices(pts.astype(np.float64), c.astype(np.float64))
    err = rot_angle(got, ref)
    assert np.max(err) < 1e-4, f"max deviation {np.max(err):.2e} rad from the float64 reference"
    assert np.median(err) < 1e-6


@pytest.mark.parametrize("polar", ["exact", "fast"])
def test_rotations_are_proper_and_unit(rng, polar):
    c = realistic_constraints(rng, 6, max_edit=3.1)
    pts = rng.uniform(-3, 3, (2000, 3)).astype(np.float32)
    q = rn.reflection.rotation_field(pts, c, polar=polar)
    assert q.dtype == np.float32 and q.shape == (2000, 4)
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    m = quat_to_matrix(q)
    np.testing.assert_allclose(np.swapaxes(m, 1, 2) @ m, np.broadcast_to(np.eye(3), m.shape), atol=1e-5)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-5)


def test_constraints_interpolated_on_real_mesh(spot, rng):
    v, f, n = spot
    eye = v.mean(0) + np.array([0.0, -3.0, 0.5])
    picks = rng.choice(len(v), 5, replace=False)
    rows = []
    for i in picks:
        row = api.constraint_row(v[i], n[i], v[i] + rng.normal(size=3), eye)
        rows.append(row)
    c = np.array(rows)
    for polar in ("exact", "fast"):
        q = rn.reflection.rotation_field(v, c, polar=polar)
        e_at = api.rotate(q[picks], c[:, 3:6])
        assert np.max(dir_angle(e_at, c[:, 6:9])) < 1e-4


def test_fresh_constraint_changes_nothing(spot):
    """A constraint whose green handle sits on the physical reflected ray is the identity edit."""
    v, f, n = spot
    eye = np.array([0.3, -4.0, 1.0])
    i = 123
    green = api.physical_reflected_point(v[i], n[i], eye, 2.5)
    c = api.constraint_row(v[i], n[i], green, eye)[None]
    q = rn.reflection.rotation_field(v, c)
    assert np.max(api.quat_angle(q)) < 1e-5


def test_scale_invariance_on_real_mesh(spot, rng):
    v, f, n = spot
    c = realistic_constraints(rng, 4, spread=0.5)
    c[:, :3] = v[rng.choice(len(v), 4, replace=False)]
    base = quat_to_matrix(rn.reflection.rotation_field(v, c))
    for s in (1e-4, 1e4):
        cs = c.copy()
        cs[:, :3] *= s
        got = quat_to_matrix(rn.reflection.rotation_field(v * np.float32(s), cs))
        assert np.max(rot_angle(base, got)) < 1e-4, f"scale {s}"


def test_equivariance(rng):
    c = realistic_constraints(rng, 5).astype(np.float64)
    pts = rng.uniform(-1, 1, (300, 3))
    a, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    a *= np.sign(np.linalg.det(a))
    t = np.array([3.0, -1.0, 2.0])
    c2 = np.hstack([c[:, :3] @ a.T + t, c[:, 3:6] @ a.T, c[:, 6:9] @ a.T])
    r1 = quat_to_matrix(rn.reflection.rotation_field(pts, c))
    r2 = quat_to_matrix(rn.reflection.rotation_field(pts @ a.T + t, c2))
    assert np.max(rot_angle(a @ r1 @ a.T, r2)) < 1e-4


def test_no_constraints_is_identity(rng):
    pts = rng.uniform(-1, 1, (10, 3))
    q = rn.reflection.rotation_field(pts, np.zeros((0, 9)))
    np.testing.assert_array_equal(q, np.tile([0, 0, 0, 1], (10, 1)))
    nrm = np.tile([0.0, 0.0, 1.0], (10, 1))
    eye = np.array([0.0, 0.0, 5.0])
    e = rn.reflection.edited_directions(pts, nrm, eye, np.zeros((0, 9)))
    r = api.reflect((pts - eye) / np.linalg.norm(pts - eye, axis=1, keepdims=True), nrm)
    np.testing.assert_allclose(e, r, atol=1e-6)


def test_antiparallel_edit_is_a_half_turn(rng):
    r = np.array([0.2, -0.3, 0.9])
    r /= np.linalg.norm(r)
    c = np.concatenate([[0, 0, 0], r, -r])[None]
    q1 = rn.reflection.rotation_field(rng.uniform(-1, 1, (50, 3)), c)
    q2 = rn.reflection.rotation_field(rng.uniform(-1, 1, (50, 3)), c)
    np.testing.assert_allclose(api.rotate(q1, r), np.broadcast_to(-r, (50, 3)), atol=1e-6)
    np.testing.assert_array_equal(q1[0], q2[0])  # deterministic


def test_coincident_constraints_and_query_on_them():
    p = [0.1, 0.2, 0.3]
    r = np.array([0.0, 0.0, 1.0])
    e1 = np.array([0.6, 0.0, 0.8])
    e2 = np.array([-0.6, 0.0, 0.8])
    c = np.array([np.r_[p, r, e1], np.r_[p, r, e2]])
    q = rn.reflection.rotation_field(np.array([p, [1.0, 1.0, 1.0]]), c)
    assert np.all(np.isfinite(q))
    np.testing.assert_allclose(api.rotate(q, r), np.broadcast_to(r, (2, 3)), atol=1e-6)


def test_thousand_constraints(rng):
    c = realistic_constraints(rng, 1000, spread=10.0)
    pts = np.vstack([c[::50, :3], rng.uniform(-10, 10, (200, 3))]).astype(np.float32)
    q = rn.reflection.rotation_field(pts, c)
    assert np.all(np.isfinite(q))
    hit = api.rotate(q[:20], c[::50, 3:6])
    assert np.max(dir_angle(hit, c[::50, 6:9])) < 1e-4


def test_geodesic_style_distances_are_used(rng):
    """Precomputed distances replace Euclidean ones: passing the Euclidean distances explicitly
    gives the same field, and making a constraint unreachable (+inf) removes its influence."""
    c = realistic_constraints(rng, 3)
    pts = rng.uniform(-1, 1, (100, 3)).astype(np.float32)
    d = np.linalg.norm(pts[None, :, :].astype(np.float64) - c[:, None, :3], axis=-1)
    a = quat_to_matrix(rn.reflection.rotation_field(pts, c))
    b = quat_to_matrix(rn.reflection.rotation_field(pts, c, distances=d))
    assert np.max(rot_angle(a, b)) < 1e-5
    d[2] = np.inf
    only01 = quat_to_matrix(rn.reflection.rotation_field(pts, c[:2]))
    got = quat_to_matrix(rn.reflection.rotation_field(pts, c, distances=d))
    assert np.max(rot_angle(only01, got)) < 1e-5


def test_euclidean_region_is_equation_7(rng):
    c = realistic_constraints(rng, 3, spread=0.3)
    region = {"kind": "euclidean", "center": [0.0, 0.0, 0.0], "radius": 1.0, "border": 0.6}
    pts = rng.uniform(-1.2, 1.2, (500, 3))
    got = quat_to_matrix(rn.reflection.rotation_field(pts, c, regions=[region]))
    dist = np.linalg.norm(pts, axis=1)
    t = np.clip((dist - 0.4) / 0.6, 0, 1)
    a = 1 - t * t * (3 - 2 * t)
    ref = region_blend(field_matrices(pts, c.astype(np.float64)), a, np.broadcast_to(np.eye(3), (500, 3, 3)))
    inside = a > 0
    assert np.max(rot_angle(got[inside], ref[inside])) < 1e-4
    assert np.max(rot_angle(got[~inside], np.broadcast_to(np.eye(3), got[~inside].shape))) < 1e-7


def test_region_with_view_blends_towards_r_rT(rng):
    """With normals and an eye, eq. 7 uses r(q) r(q)ᵀ, and the per-pixel path agrees."""
    c = realistic_constraints(rng, 3, spread=0.3)
    region = {"kind": "euclidean", "center": [0.0, 0.0, 0.0], "radius": 1.0, "border": 0.8}
    pts = rng.uniform(-1.0, 1.0, (300, 3))
    nrm = rng.normal(size=(300, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    eye = np.array([0.0, -5.0, 1.0])
    inc = (pts - eye) / np.linalg.norm(pts - eye, axis=1, keepdims=True)
    r = api.reflect(inc, nrm)
    q = rn.reflection.rotation_field(pts, c, regions=[region], normals=nrm, eye=eye)
    dist = np.linalg.norm(pts, axis=1)
    t = np.clip((dist - 0.2) / 0.8, 0, 1)
    a = 1 - t * t * (3 - 2 * t)
    ref = region_blend(field_matrices(pts, c.astype(np.float64)), a, np.einsum("ni,nj->nij", r, r))
    e_ref = np.einsum("nij,nj->ni", ref, r)
    assert np.max(dir_angle(api.rotate(q, r), e_ref)) < 1e-4
    for polar in ("exact", "fast"):
        e = rn.reflection.edited_directions(pts, nrm, eye, c, regions=[region], polar=polar)
        assert np.max(dir_angle(e, e_ref)) < 1e-4


def test_per_point_region_weights_and_membership(rng):
    """Free-form/geodesic regions arrive as per-point a(q) plus a(pₙ); constraints with a(pₙ) = 0
    act nowhere; a region without constraints changes nothing."""
    c = realistic_constraints(rng, 2)
    pts = rng.uniform(-1, 1, (200, 3)).astype(np.float32)
    vals = np.zeros(200, np.float32)
    vals[:100] = 1.0
    vals[100:150] = 0.5
    only0 = rn.reflection.rotation_field(pts, c[:1])
    got = rn.reflection.rotation_field(pts, c, regions=[{"kind": "weights", "values": vals, "at_constraints": [1.0, 0.0]}])
    np.testing.assert_allclose(got[:100], only0[:100], atol=1e-6)
    assert np.all(api.quat_angle(got[150:]) < 1e-7)
    half = api.quat_angle(got[100:150])
    assert np.all(half < api.quat_angle(only0[100:150]) + 1e-6)
    empty = rn.reflection.rotation_field(pts, c, regions=[{"kind": "weights", "values": vals, "at_constraints": [0.0, 0.0]}])
    assert np.all(api.quat_angle(empty) < 1e-7)


def test_per_pixel_gbuffer_shape_and_agreement(rng):
    h, w = 24, 32
    ys, xs = np.mgrid[0:h, 0:w]
    pos = np.stack([xs / w - 0.5, ys / h - 0.5, 0.1 * np.sin(xs / 5.0)], -1).astype(np.float32)
    nrm = np.stack([-0.1 * np.cos(xs / 5.0) / 5.0, np.zeros_like(xs, float), np.ones_like(xs, float)], -1).astype(np.float32)
    eye = np.array([0.0, -1.0, 2.0], np.float32)
    c = realistic_constraints(rng, 4, spread=0.4)
    e = rn.reflection.edited_directions(pos, nrm, eye, c)
    assert e.shape == (h, w, 3) and e.dtype == np.float32
    flat = pos.reshape(-1, 3)
    q = rn.reflection.rotation_field(flat, c)
    inc = flat - eye
    inc /= np.linalg.norm(inc, axis=1, keepdims=True)
    nn = nrm.reshape(-1, 3) / np.linalg.norm(nrm.reshape(-1, 3), axis=1, keepdims=True)
    r = api.reflect(inc, nn)
    assert np.max(dir_angle(e.reshape(-1, 3), api.rotate(q, r))) < 1e-4


def test_float64_and_strided_inputs_are_accepted(rng):
    c = realistic_constraints(rng, 3)
    pts = rng.uniform(-1, 1, (64, 3))
    strided = np.asfortranarray(pts.astype(np.float32))
    a = rn.reflection.rotation_field(pts, c.astype(np.float64))
    b = rn.reflection.rotation_field(strided, c)
    np.testing.assert_allclose(a, b, atol=1e-6)


finite = st.floats(-1e3, 1e3, allow_nan=False, width=32)


@given(
    p=arrays(np.float32, (3, 3), elements=finite),
    r=arrays(np.float32, (3, 3), elements=st.floats(-1, 1, width=32)),
    e=arrays(np.float32, (3, 3), elements=st.floats(-1, 1, width=32)),
    q=arrays(np.float32, (5, 3), elements=finite),
)
def test_any_valid_input_gives_rotations(p, r, e, q):
    """Adversarial arrays (coincident points, parallel and antiparallel directions, points on
    constraints): either a clear ValueError for zero-length directions, or proper rotations."""
    c = np.hstack([p, r, e])
    zero = (np.linalg.norm(r.astype(np.float64), axis=1) <= 1e-20) | (np.linalg.norm(e.astype(np.float64), axis=1) <= 1e-20)
    for polar in ("exact", "fast"):
        if zero.any():
            with pytest.raises(ValueError, match="constraints"):
                rn.reflection.rotation_field(q, c, polar=polar)
            continue
        out = rn.reflection.rotation_field(np.vstack([q, p]), c, polar=polar)
        assert np.all(np.isfinite(out))
        np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-5)


def test_ortho_methods_agree(rng):
    m = rng.normal(size=(500, 3, 3))
    a = quat_to_matrix(rn.reflection.ortho(m, method="exact"))
    b = quat_to_matrix(rn.reflection.ortho(m, method="fast"))
    from support.reference import ortho

    ref = ortho(m)
    assert np.max(rot_angle(a, ref)) < 1e-5
    assert np.max(rot_angle(b, ref)) < 1e-5


def test_gil_is_released_during_the_work(rng):
    """Another Python thread keeps running while the core works (Blender's UI thread would)."""
    import threading

    c = realistic_constraints(rng, 32)
    pts = rng.uniform(-1, 1, (400_000, 3)).astype(np.float32)
    started, done = threading.Event(), threading.Event()
    ticks_during = []

    def work():
        started.set()
        rn.reflection.rotation_field(pts, c, polar="exact")
        done.set()

    t = threading.Thread(target=work)
    t.start()
    started.wait()
    ticks = 0
    while not done.is_set():
        ticks += 1
    t.join()
    ticks_during.append(ticks)
    # With the GIL held, this loop could not run at all while the call was in progress (a few
    # thousand ticks at most around it); released, it spins freely for the whole call.
    assert ticks_during[0] > 100_000, ticks_during


def test_rotation_vector_output_matches_the_quaternions(rng):
    from rokeby.reflection import mirror_state

    pts = rng.normal(size=(500, 3)).astype(np.float32)
    c = random_constraints(rng, 6)
    c[0, 6:9] = -c[0, 3:6]  # a half turn at one constraint
    pts[:2] = c[:2, :3]
    q = rn.reflection.rotation_field(pts, c, polar="exact")
    v = rn.reflection.rotation_field(pts, c, polar="exact", output="rotation_vector")
    assert v.shape == (500, 3) and np.all(np.isfinite(v))
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 2 * np.arctan2(np.linalg.norm(q[:, :3], axis=1), q[:, 3]), atol=2e-6)
    np.testing.assert_allclose(mirror_state.quaternions(v), q, atol=2e-6)
    assert np.linalg.norm(v, axis=1).max() <= np.pi + 1e-6
    with pytest.raises(ValueError, match="output: expected"):
        rn.reflection.rotation_field(pts, c, output="euler")
