"""Speed-for-accuracy trades not measured elsewhere (run by bench/run.py --only <name>).

* sh: SH order of the irradiance (0, 1, 2 from the core's order-2 projection truncated to its first
  1/4/9 coefficients; 4 from a numpy projection, labelled so) against the exact irradiance.
* qp: the compositing diffuse fit, least squares against the QP (D(n) >= D0), rokeby_native.compositing.sh_fit
  against the peers numpy.linalg.lstsq and quadprog (in .venv-peers) on the same pixels.
* holefill: harmonic hole filling (rokeby_native.compositing.fill_holes) at map sizes 32..512, on a known
  smooth function with a fixed hole on the sphere.

Writes JSON (--json); nothing asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

LUM = np.array([0.2126, 0.7152, 0.0722])


def best_time(fn, repeat=5):
    fn()
    ts = []
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), out


# --- SH order -------------------------------------------------------------------------------

def real_sh(lmax, d):
    """Real SH basis, bands 0..lmax (orthonormal; the sign convention of rokeby_core::compositing::sh for l <= 2),
    by the associated Legendre recurrence; (..., (lmax+1)^2)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    phi = np.arctan2(y, x)
    ct = np.clip(z, -1, 1)
    st = np.sqrt(np.maximum(0, 1 - ct * ct))
    # P[l][m] without the Condon-Shortley phase
    P = {(0, 0): np.ones_like(ct)}
    for m in range(1, lmax + 1):
        P[(m, m)] = (2 * m - 1) * st * P[(m - 1, m - 1)]
    for m in range(0, lmax):
        P[(m + 1, m)] = (2 * m + 1) * ct * P[(m, m)]
    for m in range(0, lmax + 1):
        for l in range(m + 2, lmax + 1):
            P[(l, m)] = ((2 * l - 1) * ct * P[(l - 1, m)] - (l + m - 1) * P[(l - 2, m)]) / (l - m)
    from math import factorial, pi, sqrt

    cols = []
    for l in range(lmax + 1):
        for m in range(-l, l + 1):
            am = abs(m)
            k = sqrt((2 * l + 1) / (4 * pi) * factorial(l - am) / factorial(l + am))
            if m == 0:
                cols.append(k * P[(l, 0)])
            elif m > 0:
                cols.append(sqrt(2) * k * np.cos(m * phi) * P[(l, am)])
            else:
                cols.append(sqrt(2) * k * np.sin(am * phi) * P[(l, am)])
    return np.stack(cols, -1)


def a_hat(l):
    """Cosine-lobe convolution coefficients over π (E/π), Ramamoorthi & Hanrahan 2001."""
    from math import factorial, pi

    if l == 0:
        return 1.0
    if l == 1:
        return 2.0 / 3.0
    if l % 2:
        return 0.0
    a = 2 * pi * (-1) ** (l // 2 - 1) / ((l + 2) * (l - 1)) * factorial(l) / (2 ** l * factorial(l // 2) ** 2)
    return a / pi


def sh_section(quick=False):
    from rokeby import envmaps
    from envmap import WORLDS, fibonacci

    normals = fibonacci(256)
    rows = []
    load0 = os.getloadavg()[0]
    for name in WORLDS:
        im = envmaps.read_exr(envmaps.studio_world(name))
        exact = envmaps.reference(im, "lambert", normals) @ LUM
        t_fit, irr = best_time(lambda: envmaps.irradiance(im, size=32), 3)
        c9 = np.asarray(irr["irradiance_coeffs"], np.float64)
        for order, ncoef in ((0, 1), (1, 4), (2, 9)):
            t_ev, got = best_time(lambda: real_sh(order, normals) @ c9[:, :ncoef].T, 5)
            e = np.abs(got @ LUM - exact) / np.maximum(np.abs(exact), 1e-12)
            rows.append({"world": name, "order": order, "how": "core order-2 projection, truncated" if order < 2 else "core (rokeby_native.envmaps.irradiance)",
                         "fit_ms": 1e3 * t_fit, "eval_us_per_normal": 1e6 * t_ev / len(normals), "mean": float(e.mean()), "max": float(e.max())})
        # numpy projection at orders 2 and 4 over the lat-long texels (solid-angle weighted).
        h, w = im.shape[:2]
        lat = np.pi * (0.5 - (np.arange(h) + 0.5) / h)

        for order in (2, 3, 4):
            def fit():
                # the same lat-long convention as envmaps.sample: check by comparing order 2 with the core
                d = envmaps_dirs(h, w)
                dw = (np.cos(lat) * (np.pi / h) * (2 * np.pi / w))[:, None] * np.ones((1, w))
                B = real_sh(order, d.reshape(-1, 3))
                L = im.reshape(-1, im.shape[-1]).astype(np.float64)
                c = (B * dw.reshape(-1, 1)).T @ L
                scale = np.concatenate([[a_hat(l)] * (2 * l + 1) for l in range(order + 1)])
                return c * scale[:, None]
            t_np, c = best_time(fit, 1)
            t_ev, got = best_time(lambda: real_sh(order, normals) @ c, 5)
            e = np.abs(got @ LUM - exact) / np.maximum(np.abs(exact), 1e-12)
            rows.append({"world": name, "order": order, "how": "numpy projection (bench/tradeoffs.py)", "fit_ms": 1e3 * t_np,
                         "eval_us_per_normal": 1e6 * t_ev / len(normals), "mean": float(e.mean()), "max": float(e.max())})
    return {"rows": rows, "normals": len(normals), "load_average": [load0, os.getloadavg()[0]], "cpus": os.cpu_count()}


_DIRS = {}


def envmaps_dirs(h, w):
    """Texel-centre directions of an h x w lat-long map in the convention of rokeby envmaps
    (found once by matching envmaps.sample on a coordinate image)."""
    if (h, w) in _DIRS:
        return _DIRS[(h, w)]
    from rokeby import envmaps

    lat = np.pi * (0.5 - (np.arange(h) + 0.5) / h)
    lon = 2 * np.pi * (np.arange(w) + 0.5) / w
    LA, LO = np.meshgrid(lat, lon, indexing="ij")
    best = None
    # candidate conventions: azimuth measured from -z/+x/-x/... about +y or +z; pick the one that
    # reproduces envmaps.sample of an image holding its own row/col index.
    idx = np.zeros((h, w, 3), np.float32)
    idx[..., 0] = np.arange(h)[:, None]
    idx[..., 1] = np.arange(w)[None, :]
    cands = []
    for up in ("z", "y"):
        for off in (0, np.pi / 2, np.pi, -np.pi / 2):
            for sgn in (1, -1):
                a = sgn * LO + off
                if up == "z":
                    d = np.stack([np.cos(LA) * np.cos(a), np.cos(LA) * np.sin(a), np.sin(LA)], -1)
                else:
                    d = np.stack([np.cos(LA) * np.cos(a), np.sin(LA), np.cos(LA) * np.sin(a)], -1)
                cands.append(d)
    rng = np.random.default_rng(0)
    ri, rj = rng.integers(1, h - 1, 64), rng.integers(1, w - 1, 64)
    for d in cands:
        got = envmaps.sample(idx, "latlong", d[ri, rj])
        err = np.abs(got[:, 0] - ri).mean() + np.abs(got[:, 1] - rj).mean()
        if best is None or err < best[0]:
            best = (err, d)
    if best[0] > 0.5:
        raise RuntimeError(f"lat-long convention not found (best {best[0]})")
    _DIRS[(h, w)] = best[1]
    return best[1]


# --- QP versus least squares --------------------------------------------------------------------

def qp_section(peers=None, widths=(256, 512, 1024)):
    import rokeby_native as rn
    from compositing import TRUE_SH, bumpy_sphere, sh_basis, sphere_dirs

    rng = np.random.default_rng(6)
    dirs = sphere_dirs()
    truth = sh_basis(dirs) @ TRUE_SH.T
    rows = []
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        for w in widths:
            n, inside, d0, *_ = bumpy_sphere(w, rng)
            nm, dm = n[inside], d0[inside]

            def score(coeffs):
                return float(np.sqrt(((sh_basis(dirs) @ coeffs.T - truth) ** 2).mean()) / np.abs(truth).mean())

            B = sh_basis(nm.astype(np.float64))
            for method in ("ls", "qp"):
                t, f = best_time(lambda: rn.compositing.sh_fit(nm, dm, method), 3)
                viol = float((dm.astype(np.float64) - B @ f["coeffs"].T).max())
                rows.append({"width": w, "pixels": int(len(nm)), "solver": f"rokeby_native.compositing.sh_fit('{method}')", "kind": method,
                             "ms": 1e3 * t, "rel_rms": score(f["coeffs"]), "max_residual": viol, "peer": False})
            if peers:
                np.savez(Path(tmp) / "qp.npz", n=nm.astype(np.float64), d=dm.astype(np.float64))
                subprocess.run([peers, str(ROOT / "bench" / "peer_qp.py"), str(Path(tmp) / "qp.npz"), str(Path(tmp) / "qp_out.npz")], check=True)
                r = np.load(Path(tmp) / "qp_out.npz", allow_pickle=True)
                for key, solver, kind in (("lstsq", "numpy.linalg.lstsq (peer)", "ls"), ("quadprog", "quadprog.solve_qp (peer)", "qp")):
                    if f"{key}_coeffs" not in r:
                        rows.append({"width": w, "pixels": int(len(nm)), "solver": solver, "kind": kind, "error": str(r.get(f"{key}_error", "failed")), "peer": True})
                        continue
                    c = r[f"{key}_coeffs"]
                    rows.append({"width": w, "pixels": int(len(nm)), "solver": solver, "kind": kind, "ms": 1e3 * float(r[f"{key}_s"]),
                                 "rel_rms": score(c), "max_residual": float((dm.astype(np.float64) - B @ c.T).max()), "peer": True})
    return {"rows": rows, "load_average": [load0, os.getloadavg()[0]], "cpus": os.cpu_count()}


# --- hole-filling resolution ---------------------------------------------------------------------

def known(d):
    """A smooth known function on the sphere (3 channels)."""
    return np.stack([0.5 + 0.3 * d[..., 0] + 0.2 * d[..., 1] * d[..., 2],
                     0.4 + 0.1 * np.sin(3 * d[..., 2]) + 0.1 * d[..., 0] * d[..., 1],
                     0.3 + 0.2 * d[..., 1] + 0.1 * np.cos(4 * d[..., 0])], -1)


def paraboloid_texel_dirs(s):
    """(2, S, S, 3) texel-centre directions of a dual-paraboloid map (rokeby_core::envmaps::envmap
    paraboloid_dir: (2u, 2v, ±(1 − u² − v²))/(1 + u² + v²), u from the column, v from the row)."""
    c = (np.arange(s) + 0.5) / s * 2 - 1
    v, u = np.meshgrid(c, c, indexing="ij")
    q = u * u + v * v
    z = (1 - q) / (1 + q)
    f0 = np.stack([2 * u / (1 + q), 2 * v / (1 + q), z], -1)
    f1 = np.stack([2 * u / (1 + q), 2 * v / (1 + q), -z], -1)
    return np.stack([f0, f1]), q <= 1


def holefill_section(sizes=(32, 64, 128, 256, 512)):
    import rokeby_native as rn

    rng = np.random.default_rng(9)
    test = rng.normal(size=(4000, 3))
    test /= np.linalg.norm(test, axis=1, keepdims=True)
    # The hole: a cap of 60° around +x (across the equator of the two faces) and a cap of 35° around +z.
    def in_hole(d):
        return (d[..., 0] > np.cos(np.radians(60))) | (d[..., 2] > np.cos(np.radians(35)))
    th = test[in_hole(test)]
    rows = []
    load0 = os.getloadavg()[0]
    for s in sizes:
        dirs, disk = paraboloid_texel_dirs(s)
        m = known(dirs).astype(np.float32)
        # check the convention: a full map looks up the known function
        conv = float(np.abs(rn.compositing.envmap_lookup(m, test) - known(test)).mean())
        covered = ~in_hole(dirs)
        holes = int((~covered & disk[None]).sum())
        m_in = np.where(covered[..., None], m, 0).astype(np.float32)
        t, filled = best_time(lambda: rn.compositing.fill_holes(m_in, covered), 3 if s <= 256 else 1)
        e = np.abs(rn.compositing.envmap_lookup(filled, th) - known(th))
        rows.append({"size": s, "hole_texels": holes, "ms": 1e3 * t, "mean_abs": float(e.mean()), "max_abs": float(e.max()),
                     "full_map_lookup_err": conv})
    return {"rows": rows, "hole_dirs": int(len(th)), "load_average": [load0, os.getloadavg()[0]], "cpus": os.cpu_count()}


# --- polar method and float32 storage ---------------------------------------------------------------

def precision_section(k=8):
    """Per-point field on the largest shared mesh, K constraints: rokeby_native.reflection.rotation_field
    (float32 storage) with polar='exact' / 'fast', against the float64 numpy reference of
    tests/support/reference.py (batched SVD), which is also timed; and rokeby_native.reflection.ortho on the float64
    matrices of that field, exact / fast, coherent and shuffled order."""
    import rokeby_native as rn

    sys.path.insert(0, str(ROOT / "tests"))
    from support.reference import field_matrices, ortho as ortho_ref, quat_to_matrix, random_constraints, rot_angle
    from rokeby.core.meshio import load_obj

    shared = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
    big = sorted((shared / "meshes").glob("*.obj"), key=lambda p: p.stat().st_size)[-1]
    v, _ = load_obj(big)
    rng = np.random.default_rng(2009)
    c = random_constraints(rng, k, spread=0, max_edit=0.7, min_edit=0.1, at=v)
    off = np.min(np.sum((v[:, None, :].astype(np.float64) - c[None, :, :3]) ** 2, axis=-1), axis=1) > 0
    pts = v[off]
    load0 = os.getloadavg()[0]
    t_ref, want = best_time(lambda: field_matrices(pts.astype(np.float64), c.astype(np.float64)), 3)
    rows = [{"what": "numpy float64 reference (batched SVD, tests/support/reference.py)", "ns_per_point": 1e9 * t_ref / len(pts), "mean": 0.0, "p99": 0.0, "max": 0.0}]
    for polar in ("exact", "fast"):
        t, q = best_time(lambda: rn.reflection.rotation_field(pts, c, polar=polar), 5)
        e = rot_angle(quat_to_matrix(q), want)
        rows.append({"what": f"rokeby_native.reflection.rotation_field, float32 storage, polar='{polar}'", "ns_per_point": 1e9 * t / len(pts),
                     "mean": float(e.mean()), "p99": float(np.percentile(e, 99)), "max": float(e.max())})
    # ortho alone, on the float64 unnormalised matrices of the same field (numpy reference = its SVD)
    d2 = np.sum((pts[:, None, :].astype(np.float64) - c[None, :, :3]) ** 2, axis=-1)
    order = np.lexsort((pts[:, 0], pts[:, 1]))
    w_ = 1.0 / d2[order]
    mats = np.einsum("nk,ki,kj->nij", w_ / w_.max(axis=1, keepdims=True), c[:, 6:9].astype(np.float64), c[:, 3:6].astype(np.float64))
    ref = ortho_ref(mats)
    shuffled = rng.permutation(len(mats))
    for name, fn, perm in (("rokeby_native.reflection.ortho 'exact' (Jacobi SVD, f64)", lambda: rn.reflection.ortho(mats, method="exact"), None),
                           ("rokeby_native.reflection.ortho 'fast' (Newton, coherent order)", lambda: rn.reflection.ortho(mats, method="fast"), None),
                           ("rokeby_native.reflection.ortho 'fast' (Newton, shuffled order)", lambda: rn.reflection.ortho(mats[shuffled], method="fast"), shuffled)):
        t, q = best_time(fn, 5)
        e = rot_angle(quat_to_matrix(q), ref if perm is None else ref[perm])
        rows.append({"what": name, "ns_per_point": 1e9 * t / len(mats), "mean": float(e.mean()), "p99": float(np.percentile(e, 99)), "max": float(e.max())})
    t, _ = best_time(lambda: ortho_ref(mats), 3)
    rows.append({"what": "numpy.linalg.svd batched, f64 (ortho peer, the reference)", "ns_per_point": 1e9 * t / len(mats), "mean": 0.0, "p99": 0.0, "max": 0.0})
    return {"rows": rows, "mesh": big.name, "points": int(len(pts)), "k": k, "load_average": [load0, os.getloadavg()[0]], "cpus": os.cpu_count()}


# --- per-vertex versus per-pixel field ----------------------------------------------------------------

def field_section(k=8, n_pixels=1280 * 960, levels=(0, 1, 2, 3)):
    """The rotation field per vertex (what the add-on stores in the rokeby_rotation attribute and the
    renderer interpolates across each triangle) against the field per pixel (the viewport shader):
    spot.obj subdivided 0-3 times, K constraints, n_pixels random surface points (area-weighted;
    a 1280x960 frame full of mirror). Error: rotation angle between the barycentric nlerp of the
    vertex quaternions and rotation_field evaluated at the point."""
    import rokeby_native as rn

    sys.path.insert(0, str(ROOT / "tests"))
    from support.reference import random_constraints
    from rokeby.core.meshio import load_obj, subdivide_midpoint

    shared = Path(os.environ.get("ROKEBY_SHARED", ROOT.parent / "shared"))
    v0, f0 = load_obj(shared / "meshes" / "spot.obj")
    rng = np.random.default_rng(2009)
    c = random_constraints(rng, k, spread=0, max_edit=0.7, min_edit=0.1, at=v0)
    rows = []
    load0 = os.getloadavg()[0]
    v, f = v0, f0
    for level in range(max(levels) + 1):
        if level in levels:
            v64 = v.astype(np.float64)
            a = v64[f[:, 0]]
            area = 0.5 * np.linalg.norm(np.cross(v64[f[:, 1]] - a, v64[f[:, 2]] - a), axis=1)
            tri = rng.choice(len(f), n_pixels, p=area / area.sum())
            u = rng.random((n_pixels, 2))
            flip = u.sum(1) > 1
            u[flip] = 1 - u[flip]
            bary = np.column_stack([1 - u.sum(1), u[:, 0], u[:, 1]])
            pts = np.einsum("ni,nij->nj", bary, v64[f[tri]]).astype(np.float32)
            t_v, qv = best_time(lambda: rn.reflection.rotation_field(v, c, polar="exact"), 3)

            def interp():
                q = qv[f[tri]].astype(np.float64)  # (n, 3, 4)
                q = q * np.sign(np.einsum("nij,nj->ni", q, q[:, 0]))[..., None]  # one hemisphere
                out = np.einsum("ni,nij->nj", bary, q)
                return out / np.linalg.norm(out, axis=1, keepdims=True)
            t_i, qi = best_time(interp, 1)
            t_p, qp = best_time(lambda: rn.reflection.rotation_field(pts, c, polar="exact"), 1)
            qp64 = qp.astype(np.float64)
            qp64 /= np.linalg.norm(qp64, axis=1, keepdims=True)
            qp64 *= np.sign(np.sum(qi * qp64, axis=1))[:, None]
            # 4 asin(|Δq|/2): accurate for small angles (2 acos(|q·q'|) is not, in float32 rounding)
            ang = 4 * np.arcsin(np.clip(np.linalg.norm(qi - qp64, axis=1) / 2, 0, 1))
            rows.append({"level": level, "vertices": int(len(v)), "triangles": int(len(f)), "per_vertex_ms": 1e3 * t_v,
                         "interp_ms": 1e3 * t_i, "per_pixel_ms": 1e3 * t_p, "mean": float(ang.mean()),
                         "p99": float(np.percentile(ang, 99)), "max": float(ang.max())})
        if level < max(levels):
            v, f = subdivide_midpoint(v, f)
    return {"rows": rows, "pixels": n_pixels, "k": k, "load_average": [load0, os.getloadavg()[0]], "cpus": os.cpu_count()}


# --- what the render reads: the representation of the field -----------------------

def _uv_sphere(segments, rings):
    """Vertices, smooth normals and triangles of Blender's UV sphere (radius 1)."""
    th = np.pi * np.arange(1, rings) / rings
    ph = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.sin(th)[:, None] * np.cos(ph), np.sin(th)[:, None] * np.sin(ph), np.repeat(np.cos(th)[:, None], segments, 1)], -1).reshape(-1, 3)
    v = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]).astype(np.float32)
    tris = []
    for j in range(segments):
        k = (j + 1) % segments
        tris.append((0, 1 + j, 1 + k))
        for i in range(rings - 2):
            a, b = 1 + i * segments + j, 1 + i * segments + k
            c, d = a + segments, b + segments
            tris += [(a, c, d), (a, d, b)]
        last = len(v) - 1
        tris.append((1 + (rings - 2) * segments + j, last, 1 + (rings - 2) * segments + k))
    return v, v.copy(), np.array(tris, dtype=np.int64)


def _grid(n, size=2.0):
    x = np.linspace(-size / 2, size / 2, n)
    xx, yy = np.meshgrid(x, x)
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(n * n)], -1).astype(np.float32)
    nrm = np.tile(np.array([[0, 0, 1]], np.float32), (n * n, 1))
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return v, nrm, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def _row(p, g, eye):
    p, g, eye = (np.asarray(x, dtype=np.float64) for x in (p, g, eye))
    n = p / np.linalg.norm(p) if np.linalg.norm(p) > 0 else np.array([0.0, 0.0, 1.0])
    i = (p - eye) / np.linalg.norm(p - eye)
    r = i - 2 * (i @ n) * n
    e = (g - p) / np.linalg.norm(g - p)
    return np.concatenate([p, r, e])


def representation_section(n_samples=100_000):
    """Each way a renderer can read the field, interpolated across triangles as the renderer does,
    against edited_directions (the per-pixel preview) at random points of the triangles facing the
    eye (area-weighted; the normal interpolated as smooth shading does). Update: the native call and
    the numpy conversion to what is stored (writing to Blender is the same foreach_set for all)."""
    import rokeby_native as rn

    rng = np.random.default_rng(17)
    eye = np.array([0.0, -4.0, 0.0])
    region = [{"kind": "euclidean", "center": [0.2, -1.0, 0.0], "radius": 0.9, "border": 0.5}]
    sphere_rows = np.array([_row((0, -1, 0), (0.6, -3.0, 1.0), eye), _row((0.5, -0.85, 0), (1.2, -3.0, -0.5), eye)], np.float32)
    sphere_rows[1, :3] /= np.linalg.norm(sphere_rows[1, :3])
    sphere_rows[1] = _row(sphere_rows[1, :3], (1.2, -3.0, -0.5), eye)

    def rz(deg, v):
        a = np.radians(deg)
        return np.array([np.cos(a) * v[0] - np.sin(a) * v[1], np.sin(a) * v[0] + np.cos(a) * v[1], v[2]])
    plane_eye = np.array([0.0, -2.2, 2.2])
    plane_rows = []
    for x, turn in ((-0.5, 170.0), (0.5, -170.0)):
        p = np.array([x, 0.0, 0.0])
        i = (p - plane_eye) / np.linalg.norm(p - plane_eye)
        r = i * np.array([1.0, 1.0, -1.0])
        plane_rows.append(np.concatenate([p, r, rz(turn, r)]))
    plane_rows = np.array(plane_rows, np.float32)
    cases = [("sphere", 20, 11, True), ("sphere", 64, 32, False), ("sphere", 64, 32, True), ("sphere", 128, 64, True), ("sphere", 256, 128, True), ("plane ±170°", 11, 0, False)]
    out = []
    for name, a, b, with_region in cases:
        if name == "sphere":
            v, nrm, f = _uv_sphere(a, b)
            rows, e = sphere_rows, eye
        else:
            v, nrm, f = _grid(a)
            rows, e = plane_rows, plane_eye
        kw = {"regions": region} if with_region else {}
        v64 = v.astype(np.float64)
        fn = np.cross(v64[f[:, 1]] - v64[f[:, 0]], v64[f[:, 2]] - v64[f[:, 0]])
        area = 0.5 * np.linalg.norm(fn, axis=1)
        front = np.einsum("ij,ij->i", nrm[f].mean(1), v64[f].mean(1) - e) < 0
        w = np.where(front, area, 0.0)
        tri = rng.choice(len(f), n_samples, p=w / w.sum())
        u = rng.random((n_samples, 2))
        flip = u.sum(1) > 1
        u[flip] = 1 - u[flip]
        bary = np.column_stack([1 - u.sum(1), u[:, 0], u[:, 1]])
        P = np.einsum("ni,nij->nj", bary, v64[f[tri]])
        N = np.einsum("ni,nij->nj", bary, nrm[f[tri]].astype(np.float64))
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        inc = (P - e) / np.linalg.norm(P - e, axis=1, keepdims=True)
        R = inc - 2 * np.einsum("ij,ij->i", inc, N)[:, None] * N
        want = rn.reflection.edited_directions(P.astype(np.float32), N.astype(np.float32), tuple(e), rows, **kw).astype(np.float64)
        above = np.einsum("ij,ij->i", want, N) > 0  # renders fold the rest: compared apart

        def rotate(q, x):
            uu, ww = q[:, :3], q[:, 3:4]
            t = 2 * np.cross(uu, x)
            return x + ww * t + np.cross(uu, t)

        def hemi(q):  # (n, 3, k): quaternions of a triangle in its first corner's hemisphere
            q = q.copy()
            q[..., :4] *= np.where(np.einsum("nij,nj->ni", q[..., :4], q[:, 0, :4]) < 0, -1.0, 1.0)[..., None]
            return q

        def nlerp(q):
            x = np.einsum("ni,nij->nj", bary, q)
            x[:, :4] /= np.linalg.norm(x[:, :4], axis=1, keepdims=True)
            return x

        reps = {}
        # A. rotation vectors per vertex, blended towards I (before this issue).
        t, rv = best_time(lambda: rn.reflection.rotation_field(v, rows, output="rotation_vector", **kw), 3)
        x = np.einsum("ni,nij->nj", bary, rv[f[tri]].astype(np.float64))
        ang = np.linalg.norm(x, axis=1)
        axis = x / np.maximum(ang, 1e-30)[:, None]
        got = R * np.cos(ang)[:, None] + np.cross(axis, R) * np.sin(ang)[:, None] + axis * np.einsum("ij,ij->i", axis, R)[:, None] * (1 - np.cos(ang))[:, None]
        reps["rotation vector per vertex, eq. 7 towards I (before)"] = (got, t, 12 * len(v), "no")
        # B. quaternions per corner, eq. 7 towards r rᵀ at each vertex for the current eye.
        t, qv = best_time(lambda: hemi(rn.reflection.rotation_field(v, rows, normals=nrm, eye=tuple(e), **kw).astype(np.float64)[f]), 3)
        reps["quaternion per corner, eq. 7 at the vertices for the eye"] = (rotate(nlerp(hemi(rn.reflection.rotation_field(v, rows, normals=nrm, eye=tuple(e), **kw).astype(np.float64)[f[tri]])), R), t, 16 * 3 * len(f), "yes")
        # C. the edited direction per vertex for the current eye.
        t, ev = best_time(lambda: rn.reflection.edited_directions(v, nrm, tuple(e), rows, **kw), 3)
        x = np.einsum("ni,nij->nj", bary, ev[f[tri]].astype(np.float64))
        reps["edited direction per vertex for the eye"] = (x / np.linalg.norm(x, axis=1, keepdims=True), t, 12 * len(v), "yes")
        # D. eq. 7's view-independent parts per corner, closed form per pixel (the add-on's pick).
        ramp = with_region
        t, parts = best_time(lambda: hemi(rn.reflection.rotation_field(v, rows, output="view_blend", **kw).astype(np.float64)[f]), 3)
        pi = nlerp(hemi(rn.reflection.rotation_field(v, rows, output="view_blend", **kw).astype(np.float64)[f[tri]]))
        got = rn.reflection.view_blend(pi.astype(np.float32), R.astype(np.float32), ramp=ramp).astype(np.float64)
        reps["view-independent parts per corner, eq. 7 per pixel (the add-on)"] = (got, t, 24 * 3 * len(f), "no")
        # E. the whole field per pixel (the preview's way), timed for a 1280x960 frame.
        t, _ = best_time(lambda: rn.reflection.edited_directions(P.astype(np.float32), N.astype(np.float32), tuple(e), rows, **kw), 3)
        reps["whole field per pixel, 1280x960 on this CPU (the preview's way, in GLSL there)"] = (want, t * 1280 * 960 / n_samples, 0, "yes, every frame")
        for rep, (got, t, mem, eye_dep) in reps.items():
            a = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", got, want)[above] / np.linalg.norm(got[above], axis=1), -1, 1)))
            out.append({"mesh": name, "vertices": int(len(v)), "region": with_region, "representation": rep, "p99": float(np.percentile(a, 99)),
                        "max": float(a.max()), "over_5": float((a > 5).mean()), "update_ms": 1e3 * t, "bytes": int(mem), "eye_dependent": eye_dep})
    return {"rows": out, "samples": n_samples, "load_average": os.getloadavg()[0], "cpus": os.cpu_count()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=["sh", "qp", "holefill", "precision", "field", "representation"])
    ap.add_argument("--json", required=True)
    ap.add_argument("--peers", default=None)
    a = ap.parse_args()
    r = {"sh": sh_section, "qp": lambda: qp_section(a.peers), "holefill": holefill_section, "precision": precision_section, "field": field_section, "representation": representation_section}[a.what]()
    Path(a.json).write_text(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
