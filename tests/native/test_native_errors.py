"""The native core's errors by kind (docs/errors.md, "The native core"): bad input is a ValueError
whose message starts with the argument at fault; a numerical method that breaks down on valid
input is a rokeby_native.NumericalError, which is a RuntimeError (so `except RuntimeError` keeps
catching it) and not a ValueError."""

import numpy as np
import pytest
import rokeby_native as rn

# A needle triangle: valid (finite, three distinct vertices, area well above the degenerate-face
# cut-off), but its cotangents are ~10⁵, so rounding in the cotangent Laplacian (about 10⁻¹¹ of
# them) is larger than the geodesic Poisson system's regularisation εM/t (about 10⁻¹⁵ here): the
# sparse Cholesky meets a non-positive pivot.
NEEDLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.9037845, 1.01055e-05, 0.0]], np.float32)
FACE = np.array([[0, 1, 2]], np.int64)


def test_a_singular_geodesic_system_is_a_numerical_error():
    with pytest.raises(rn.NumericalError) as info:
        rn.geometry.geodesic_distances(NEEDLE, FACE, [0], method="heat")
    assert isinstance(info.value, RuntimeError) and not isinstance(info.value, ValueError)
    assert "not positive definite" in str(info.value)
    # The same mesh is fine for the methods that solve no linear system.
    d = rn.geometry.geodesic_distances(NEEDLE, FACE, [0], method="dijkstra")
    assert np.all(np.isfinite(d))


def test_a_numerical_error_is_caught_as_a_runtime_error():
    solver = rn.geometry.GeodesicSolver(NEEDLE, FACE)
    with pytest.raises(RuntimeError):
        solver.distances([0], method="heat")
    assert not solver.factored
    # The default method (the dense graph) solves no linear system: fine on the same mesh.
    assert np.all(np.isfinite(solver.distances([0])))


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: rn.reflection.ortho(np.stack([np.eye(3), np.full((3, 3), np.nan)])), "matrices: matrix 1 has a non-finite entry"),
        (lambda: rn.geometry.interpolate(np.zeros(3), FACE, [1], [[1, 0, 0]]), "face_index: entry 0 = 1 is out of range"),
        (lambda: rn.geometry.interpolate(np.zeros(3), FACE, [0], [[np.inf, 0, 0]]), "bary: row 0 is not finite"),
        (lambda: rn.geometry.interpolate(np.array([0.0, np.nan, 0.0]), FACE, [0], [[1, 0, 0]]), "values: contains NaN"),
        (lambda: rn.geometry.interpolate(np.zeros(2), FACE, [0], [[1, 0, 0]]), "faces: face 0 refers to vertex 2"),
        (lambda: rn.geometry.GeodesicSolver(NEEDLE, FACE).freeform_region([0.0, 1.5, 1.0]), "weights: weights[1] = 1.5 is not in [0, 1]"),
        (lambda: rn.geometry.GeodesicSolver(NEEDLE, FACE).freeform_region([0.0, 1.0, 1.0], border=-1.0), "border: must be finite and >= 0"),
        (lambda: rn.geometry.GeodesicSolver(NEEDLE, FACE).geodesic_region(0, radius=0.0), "radius: must be finite and > 0"),
        (lambda: rn.compositing.sh_fit(np.zeros((4, 3)), np.ones((4, 3))), "normals: no usable pixel (4 of 4"),
    ],
)
def test_bad_input_is_a_value_error_naming_the_argument(call, words):
    with pytest.raises(ValueError) as info:
        call()
    assert not isinstance(info.value, rn.NumericalError)
    assert str(info.value).startswith(words.split(":")[0] + ":"), str(info.value)
    assert words in str(info.value)
