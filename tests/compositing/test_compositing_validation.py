"""The conventions bench/compositing_validate.py relies on, without Cycles ("validation,
measured"): an environment whose order-2 irradiance is known in closed form, on Blender's lat-long
layout; ``envmaps.irradiance`` gives E(n)/π of it; a synthetic G-buffer of an orthographic sphere
under that environment, seen by a rotated camera exactly as the Cycles passes carry it (world-space
Normal pass, the world axes in z-forward camera space as AOVs, D0 = E(n)/π, R0 = the GGX-prefiltered
radiance at the reflected direction) is reconstructed by ``compositing.reconstruct``, and the
bench's comparison with the true environment (screen → world by ``n @ R``, R world → screen) must
find the reconstruction equal to the truth. A convention bug (R for Rᵀ, E for E/π, a flipped
lat-long) fails here."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from rokeby import compositing as C
from rokeby import envmaps

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("compositing_validate", ROOT / "bench" / "compositing_validate.py")
V = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(V)

U = np.array([0.36, -0.48, 0.8])  # unit


def radiance(d):
    """L(d) per channel: SH bands 0, 1 and 2 only (so its order-2 irradiance is exact)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([1.0 + 0.6 * (d @ U) + 0.8 * x * y,
                     0.8 + 0.3 * z + 0.5 * (3 * z * z - 1) / 2,
                     0.6 - 0.4 * x + 0.7 * y * z], -1)


def irradiance_over_pi(n):
    """E(n)/π of ``radiance``: Â_l/π = 1, 2/3, 1/4 per band (Ramamoorthi & Hanrahan 2001)."""
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    return np.stack([1.0 + 2 / 3 * 0.6 * (n @ U) + 0.25 * 0.8 * x * y,
                     0.8 + 2 / 3 * 0.3 * z + 0.25 * 0.5 * (3 * z * z - 1) / 2,
                     0.6 - 2 / 3 * 0.4 * x + 0.25 * 0.7 * y * z], -1)


def latlong(h):
    """``radiance`` on Blender's equirect layout (docs/envmaps.md): texel centres, row 0 at the top,
    d = (cos φ cos λ, sin φ cos λ, sin λ), φ = 2π(½ − u), λ = π(v − ½)."""
    w = 2 * h
    u = (np.arange(w) + 0.5) / w
    v = 1 - (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (0.5 - u)[None, :]
    lam = np.pi * (v - 0.5)[:, None]
    d = np.stack(np.broadcast_arrays(np.cos(phi) * np.cos(lam), np.sin(phi) * np.cos(lam), np.sin(lam) + 0 * phi), -1)
    return radiance(d).astype(np.float32)


def euler_xyz(rx, ry, rz):
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    X = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Z @ Y @ X  # Blender's XYZ Euler: camera → world


@pytest.fixture(scope="module")
def truth():
    return V.true_environment(latlong(128))


@pytest.fixture(scope="module")
def sphere(truth):
    """An orthographic unit sphere (w × w) with the bench's camera rotation, as Cycles' passes hold it."""
    w = 128
    cam_to_world = euler_xyz(*V.CAMERA_ROTATION)
    rot = cam_to_world.T  # world → screen
    yy, xx = (np.mgrid[0:w, 0:w] + 0.5) / w * 2.2 - 1.1
    yy = -yy  # row 0 at the top
    rr = xx**2 + yy**2
    on = rr < 1
    ns = np.stack([xx, yy, np.sqrt(np.clip(1 - rr, 0, 1))], -1)
    ns[~on] = 0
    nw = ns @ rot  # world-space Normal pass
    flip = np.array([1.0, 1.0, -1.0])
    img = np.zeros((w, w, 3), np.float32)
    rs = 2 * ns[..., 2:3] * ns - np.array([0, 0, 1.0])
    d0 = np.where(on[..., None], envmaps.sh_irradiance(truth["irradiance_coeffs"], np.where(on[..., None], nw, 1)), 0)
    r0 = np.where(on[..., None], envmaps.sample(truth["level"], "latlong", np.where(on[..., None], rs @ rot, 1)), 0)
    f = lambda a: np.ascontiguousarray(a, np.float32)  # noqa: E731
    p = C.Passes(image=img, normal=f(nw), diff_dir=f(d0), diff_ind=f(0 * d0), diff_col=f(on[..., None] + 0 * d0),
                 gloss_dir=f(r0), gloss_ind=f(0 * r0), gloss_col=f(on[..., None] + 0 * r0),
                 index_ob=f(on), index_ma=f(on), ao=f(on[..., None] + 0 * d0), depth=f(np.where(on, 7 - ns[..., 2], 1e10)),
                 reflocc=f(on), camera_x=f(np.where(on[..., None], flip * rot[:, 0], 0)),
                 camera_y=f(np.where(on[..., None], flip * rot[:, 1], 0)),
                 incoming_cam=f(np.where(on[..., None], np.array([0, 0, -1.0]), 0)))
    return p, rot, ns[on]


def test_irradiance_is_e_over_pi_on_blenders_latlong(truth):
    n = V.fibonacci_sphere(500)
    got = envmaps.sh_irradiance(truth["irradiance_coeffs"], n)
    np.testing.assert_allclose(got, irradiance_over_pi(n), atol=2e-3 * 1.0)


def test_ls_reconstruction_matches_the_true_sh_after_the_camera_rotation(sphere, truth):
    p, rot, shown = sphere
    np.testing.assert_allclose(C.camera_rotation(p.camera_x, p.camera_y), rot, atol=1e-6)
    rec = C.reconstruct(p, method="ls", warn=False)
    sh = rec.patches[0]["sh"]
    fib = V.fibonacci_sphere(2000)
    err = V.diffuse_against_true(sh, truth["irradiance_coeffs"], rot, {"shown": shown, "front": fib[fib[:, 2] > 0], "full": fib})
    assert max(err.values()) < 1e-5, err  # measured 2e-7 (float32 passes)
    # ... and against the closed form, in world space
    d = rec.normals[rec.ids == 0]
    import rokeby_native as rn
    np.testing.assert_allclose(rn.compositing.sh_eval(sh, d), irradiance_over_pi(V.to_world(d, rot)), atol=3e-3)
    # The comparison is not blind to the frame: R for Rᵀ, or no rotation, is far off.
    for wrong in (rot.T, np.eye(3)):
        bad = V.diffuse_against_true(sh, truth["irradiance_coeffs"], wrong, {"full": fib})
        assert bad["full"] > 0.05, bad
    # The QP on noise-free, unoccluded data is the same fit.
    qp = C.reconstruct(p, method="qp", warn=False).patches[0]["sh"]
    assert V.diffuse_against_true(qp, truth["irradiance_coeffs"], rot, {"full": fib})["full"] < 1e-3


def test_reflection_map_matches_the_prefiltered_environment(sphere, truth):
    p, rot, _shown = sphere
    rec = C.reconstruct(p, method="ls", warn=False)
    part = V._partial(rec, p, 0)
    fib = V.fibonacci_sphere(4000)
    got = V.reflection_against_true(rec.patches[0]["env"], truth["level"], rot, fib, part["covered"])
    assert got["covered_fraction"] > 0.9, got
    assert got["covered_rel_mean_abs"] < 0.003, got  # measured 4e-4
    assert abs(got["covered_median_ratio"] - 1) < 0.002, got
    bad = V.reflection_against_true(rec.patches[0]["env"], truth["level"], rot.T, fib, part["covered"])
    assert bad["covered_rel_mean_abs"] > 5 * got["covered_rel_mean_abs"], (got, bad)


def test_png_writer_round_trips(tmp_path):
    import struct
    import zlib

    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:21, 0:17] / 21
    img = np.stack([xx, yy, np.sin(7 * xx * yy)], -1)
    img[5:9, 3:8] = rng.random((4, 5, 3))
    V.write_png(tmp_path / "a.png", img)
    data = (tmp_path / "a.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = struct.unpack(">II", data[16:24])
    raw = zlib.decompress(data[41:-12])
    stride = 3 * w
    out, prev = [], np.zeros(stride, np.int32)
    for i in range(h):  # undo the PNG filters
        k, row = raw[i * (stride + 1)], np.frombuffer(raw[i * (stride + 1) + 1:(i + 1) * (stride + 1)], np.uint8).astype(np.int32)
        x = np.zeros(stride, np.int32)
        for j in range(stride):
            a = x[j - 3] if j >= 3 else 0
            b = prev[j]
            c = prev[j - 3] if j >= 3 else 0
            pred = [0, a, b, (a + b) // 2, (a if abs(b - c) <= abs(a - c) and abs(b - c) <= abs(a + b - 2 * c) else b if abs(a - c) <= abs(a + b - 2 * c) else c)][k]
            x[j] = (row[j] + pred) % 256
        out.append(x)
        prev = x
    np.testing.assert_array_equal(np.array(out).reshape(h, w, 3), np.floor(np.clip(img, 0, 1) * 255 + 0.5).astype(np.int32))
