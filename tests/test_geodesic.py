"""Geodesic distances through the Python API, on real meshes and bad input."""

import numpy as np
import pytest
import rokeby_native as rn

from rokeby.meshio import load_obj
from conftest import mesh_path


@pytest.fixture(scope="module")
def spot_solver():
    v, f = load_obj(mesh_path("spot.obj"))
    return v, f, rn.GeodesicSolver(v, f)


def flat_grid(n=41):
    ys, xs = np.mgrid[0:n, 0:n] / (n - 1)
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], -1)
    a = (np.arange(n - 1)[None, :] + (n * np.arange(n - 1))[:, None]).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n + 1], -1), np.stack([a, a + n + 1, a + n], -1)])
    return v.astype(np.float32), f.astype(np.int32)


def test_source_forms_and_shapes(spot_solver):
    v, f, s = spot_solver
    d = s.distances([0, 10, 20], method="dijkstra")
    assert d.shape == (3, len(v)) and d.dtype == np.float32
    np.testing.assert_array_equal(d, s.distances(np.array([0, 10, 20]), method="dijkstra"))
    assert d[0, 0] == 0 and d[1, 10] == 0
    # A set of sources: the distance to the nearest.
    both = s.distances([[0, 10]], method="dijkstra")
    np.testing.assert_allclose(both[0], np.minimum(d[0], d[1]))
    # A surface point in the middle of a face.
    p = s.distances([(5, (0.2, 0.3, 0.5))], method="heat")
    corners = v[f[5]].astype(np.float64)
    x = np.array([0.2, 0.3, 0.5]) @ corners
    np.testing.assert_allclose(p[0, f[5]], np.linalg.norm(corners - x, axis=1), atol=1e-6)
    at = rn.interpolate(p, f, [5], [[0.2, 0.3, 0.5]])
    assert at.shape == (1, 1) and at[0, 0] < 0.05 * np.linalg.norm(v.max(0) - v.min(0))


def test_solver_keeps_its_factorisation(spot_solver):
    v, f, _ = spot_solver
    s = rn.GeodesicSolver(v, f)
    assert not s.factored
    a = s.distances([3])
    assert s.factored
    np.testing.assert_array_equal(a, s.distances([3]))
    np.testing.assert_allclose(a, rn.geodesic_distances(v, f, [3]), atol=1e-6)


def test_heat_is_more_accurate_than_dijkstra_on_a_plane():
    v, f = flat_grid(61)
    src = 30 * 61 + 30
    want = np.linalg.norm(v - v[src], axis=1).astype(np.float64)
    far = want > 0.05
    err = {}
    for method in ("heat", "dijkstra"):
        d = rn.geodesic_distances(v, f, [src], method=method)[0]
        err[method] = np.mean(np.abs(d[far] - want[far]) / want[far])
    assert err["heat"] < 0.02
    assert err["dijkstra"] > 2 * err["heat"]


def test_distances_behave_like_a_metric_on_a_real_mesh(spot_solver):
    v, f, s = spot_solver
    d = s.distances([100, 2000], method="heat")
    assert np.all(np.isfinite(d)) and np.all(d >= 0)
    # Symmetric within the method's accuracy; Dijkstra (edge paths) never under the heat method by
    # much, and never below the straight line.
    assert abs(d[0, 2000] - d[1, 100]) / d[0, 2000] < 0.03
    dj = s.distances([100], method="dijkstra")[0]
    chord = np.linalg.norm(v - v[100], axis=1)
    assert np.all(dj >= chord - 1e-6)
    assert np.median((dj - d[0])[chord > 0.1] / chord[chord > 0.1]) > 0


def test_real_scan_with_islands_gives_inf_not_nan():
    v, f = load_obj(mesh_path("stanford-bunny.obj"))
    s = rn.GeodesicSolver(v, f)
    for method in ("dijkstra", "heat"):
        d = s.distances([0], method=method)[0]
        assert not np.any(np.isnan(d))
        assert np.isinf(d).sum() > 0  # the scan has small separate pieces
    assert np.array_equal(np.isinf(s.distances([0], method="heat")), np.isinf(s.distances([0], method="dijkstra")))


@pytest.mark.parametrize(
    "call, exc, words",
    [
        (lambda v, f: rn.geodesic_distances(v, f.astype(np.float32), [0]), TypeError, "faces: must be an array of integers"),
        (lambda v, f: rn.geodesic_distances(v[:, :2], f, [0]), ValueError, "vertices: expected shape (V, 3)"),
        (lambda v, f: rn.geodesic_distances(v, f[:, :2], [0]), ValueError, "faces: expected shape (F, 3)"),
        (lambda v, f: rn.geodesic_distances(v, f + len(v), [0]), ValueError, "faces: face 0 refers to vertex"),
        (lambda v, f: rn.geodesic_distances(v, -f - 1, [0]), ValueError, "faces: face 0 refers to vertex -1"),
        (lambda v, f: rn.geodesic_distances(v[:0], f[:0], [0]), ValueError, "vertices: the mesh has no vertices"),
        (lambda v, f: rn.geodesic_distances(v, f[:0], [0]), ValueError, "faces: the mesh has no faces"),
        (lambda v, f: rn.geodesic_distances(np.where(np.arange(len(v))[:, None] == 3, np.nan, v), f, [0]), ValueError, "vertices: vertex 3 is not finite"),
        (lambda v, f: rn.geodesic_distances(v, f, [len(v)]), ValueError, "sources: source 0: vertex"),
        (lambda v, f: rn.geodesic_distances(v, f, [-1]), ValueError, "sources: source 0: vertex index -1 is negative"),
        (lambda v, f: rn.geodesic_distances(v, f, []), ValueError, "sources: is empty"),
        (lambda v, f: rn.geodesic_distances(v, f, [(len(f), (1, 0, 0))]), ValueError, "sources: source 0: face"),
        (lambda v, f: rn.geodesic_distances(v, f, [(0, (0, 0, 0))]), ValueError, "barycentric"),
        (lambda v, f: rn.geodesic_distances(v, f, ["x"]), TypeError, "sources: source 0 must be"),
        (lambda v, f: rn.geodesic_distances(v, f, [0], method="mmp"), ValueError, "method: unknown method"),
        (lambda v, f: rn.interpolate(np.zeros(len(v)), f, [0], [[1, 0]]), ValueError, "bary: expected shape (1, 3)"),
        (lambda v, f: rn.interpolate(np.zeros(len(v)), f, [len(f)], [[1, 0, 0]]), ValueError, "face_index: entry 0"),
    ],
)
def test_bad_input(call, exc, words):
    v, f = flat_grid(5)
    with pytest.raises(exc) as info:
        call(v, f)
    assert words in str(info.value)
