"""Bad input gets a clear Python exception that names the argument: never a panic, an interpreter
crash, or NaN in the output."""

import numpy as np
import pytest
import rokeby_native as rn

P = np.zeros((4, 3), np.float32) + np.arange(4, dtype=np.float32)[:, None]
C = np.array([[0, 0, 0, 0, 0, 1, 0, 1, 1]], np.float32)
N = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
EYE = np.array([0.0, -5.0, 5.0], np.float32)


@pytest.mark.parametrize(
    "kwargs, exc, words",
    [
        (dict(points=np.zeros((4, 2), np.float32)), ValueError, "points: expected shape (N, 3)"),
        (dict(points=np.zeros(3, np.float32)), ValueError, "points: expected shape"),
        (dict(points=np.zeros((0, 3), np.float32)), ValueError, "points: is empty"),
        (dict(points=np.zeros((4, 3), bool)), TypeError, "points: must be an array of floats"),
        (dict(points=np.zeros((4, 3), np.complex64)), TypeError, "points"),
        (dict(points="not an array"), TypeError, "points"),
        (dict(points=np.array([[0, 0, np.nan]], np.float32)), ValueError, "points: row 0 has a non-finite"),
        (dict(points=np.array([[0, 0, 1e39]], np.float64)), ValueError, "points: value 2 (1e39) is beyond float32"),
        (dict(constraints=np.zeros((1, 8), np.float32)), ValueError, "constraints: expected shape (K, 9)"),
        (dict(constraints=np.array([[0, 0, 0, 0, 0, 0, 0, 1, 0]], np.float32)), ValueError, "row 0: r (columns 3-5) has zero length"),
        (dict(constraints=np.array([[0, 0, 0, 0, 0, 1, 0, 0, 0]], np.float32)), ValueError, "row 0: e (columns 6-8) has zero length"),
        (dict(constraints=np.array([[np.inf, 0, 0, 0, 0, 1, 0, 1, 0]], np.float32)), ValueError, "row 0: p (columns 0-2) is not finite"),
        (dict(distances=np.ones((2, 4))), ValueError, "distances: expected shape (1, 4)"),
        (dict(distances=np.array([[1, np.nan, 1, 1]])), ValueError, "distances: entry (0, 1)"),
        (dict(distances=np.array([[1, -1.0, 1, 1]])), ValueError, "distances: entry (0, 1)"),
        (dict(regions={"kind": "euclidean"}), TypeError, "regions: must be a list"),
        (dict(regions=[42]), TypeError, "regions[0]: must be a dict"),
        (dict(regions=[{"kind": "sphere"}]), ValueError, "regions[0]: unknown kind"),
        (dict(regions=[{"kind": "euclidean", "center": [0, 0, 0]}]), ValueError, "regions[0]: missing key \"radius\""),
        (dict(regions=[{"kind": "euclidean", "center": [0, 0, 0], "radius": -1}]), ValueError, "regions[0]: radius must be finite and > 0"),
        (dict(regions=[{"kind": "euclidean", "center": [0, 0], "radius": 1}]), ValueError, "regions[0].center: expected shape (3,)"),
        (dict(regions=[{"kind": "weights", "values": np.ones(3), "at_constraints": [1.0]}]), ValueError, "regions[0]: values has 3 entries but there are 4 points"),
        (dict(regions=[{"kind": "weights", "values": np.full(4, 2.0), "at_constraints": [1.0]}]), ValueError, "regions[0]: values[0] = 2 is not in [0, 1]"),
        (dict(normals=N), ValueError, "eye: required when normals are given"),
        (dict(normals=N[:2], eye=EYE), ValueError, "normals: expected shape (4, 3)"),
        (dict(normals=N * 0, eye=EYE), ValueError, "normals: row 0 has zero length"),
        (dict(polar="quick"), ValueError, "polar: unknown method"),
    ],
)
def test_rotation_field_rejects(kwargs, exc, words):
    args = dict(points=P, constraints=C)
    args.update(kwargs)
    points, constraints = args.pop("points"), args.pop("constraints")
    with pytest.raises(exc) as info:
        rn.reflection.rotation_field(points, constraints, **args)
    assert words in str(info.value)


@pytest.mark.parametrize(
    "change, exc, words",
    [
        (dict(normals=N[:3]), ValueError, "normals: expected shape (4, 3) like positions"),
        (dict(normals=np.zeros((4, 3), np.float32)), ValueError, "normals: row 0 has zero length"),
        (dict(eye=np.zeros(2)), ValueError, "eye: expected shape (3,)"),
        (dict(eye=np.array([np.nan, 0, 0])), ValueError, "eye: is not finite"),
        (dict(eye=P[2]), ValueError, "eye: coincides with point 2"),
        (dict(positions=np.zeros((2, 2, 0, 3))), ValueError, "positions: is empty"),
        (dict(positions=np.zeros((4, 4))), ValueError, "positions: expected shape (..., 3)"),
        (dict(positions=np.zeros((4, 3), bool)), TypeError, "positions: must be an array of floats"),
    ],
)
def test_edited_directions_rejects(change, exc, words):
    args = dict(positions=P, normals=N, eye=EYE, constraints=C)
    args.update(change)
    with pytest.raises(exc) as info:
        rn.reflection.edited_directions(args["positions"], args["normals"], args["eye"], args["constraints"])
    assert words in str(info.value)


def test_ortho_rejects_bad_matrices():
    with pytest.raises(ValueError, match="matrices: expected shape"):
        rn.reflection.ortho(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="matrices: matrix 1 has a non-finite"):
        rn.reflection.ortho(np.stack([np.eye(3), np.full((3, 3), np.inf)]))


def test_degenerate_matrices_give_rotations_not_nan():
    m = np.stack([np.zeros((3, 3)), np.diag([1.0, 0, 0]), np.diag([1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, -1.0]), np.full((3, 3), 1e-30), np.full((3, 3), 1e30)])
    for method in ("exact", "fast"):
        q = rn.reflection.ortho(m, method=method)
        assert np.all(np.isfinite(q))
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)


def test_integer_coordinates_are_accepted():
    a = rn.reflection.rotation_field(P.astype(np.int32), C)
    np.testing.assert_array_equal(a, rn.reflection.rotation_field(P, C))


def test_inputs_are_not_modified():
    p, c = P.copy(), C.copy()
    rn.reflection.rotation_field(p, c)
    np.testing.assert_array_equal(p, P)
    np.testing.assert_array_equal(c, C)
