"""A float64 numpy reference of Ritschel et al. 2009, eqs. 3, 5, 6 and 7, written independently of
the Rust core (SVD-based polar decomposition), for well-conditioned configurations."""

import numpy as np


def random_constraints(rng, k, spread=1.0, max_edit=1.0, min_edit=0.05, at=None):
    """K constraints [p, r, e] with random directions and edits of `min_edit`..`max_edit` radians;
    points uniform in a cube of half-size `spread`, or drawn from the points `at` (e.g. vertices)."""
    p = rng.uniform(-spread, spread, (k, 3))
    if at is not None:
        p = at[rng.choice(len(at), k, replace=False)]
    r = rng.normal(size=(k, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    axis = np.cross(r, rng.normal(size=(k, 3)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    ang = rng.uniform(min_edit, max_edit, k)
    e = r * np.cos(ang)[:, None] + np.cross(axis, r) * np.sin(ang)[:, None]
    return np.hstack([p, r, e]).astype(np.float32)


def ortho(m: np.ndarray) -> np.ndarray:
    """Closest rotation to each 3×3 matrix (..., 3, 3)."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


def field_matrices(points, constraints, distances=None) -> np.ndarray:
    p, r, e = constraints[:, 0:3], constraints[:, 3:6], constraints[:, 6:9]
    r = r / np.linalg.norm(r, axis=1, keepdims=True)
    e = e / np.linalg.norm(e, axis=1, keepdims=True)
    pts = np.asarray(points, np.float64)
    if distances is None:
        d2 = np.sum((pts[:, None, :] - p[None, :, :]) ** 2, axis=-1)  # (N, K)
    else:
        d2 = np.asarray(distances, np.float64).T ** 2
    w = 1.0 / d2
    m = np.einsum("nk,ki,kj->nij", w, e, r)
    return ortho(m)


def region_blend(rot, a, x):
    """Eq. 7: ortho(a R + (1 - a) X) per point."""
    return ortho(a[:, None, None] * rot + (1.0 - a)[:, None, None] * x)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = (q[..., i].astype(np.float64) for i in range(4))
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def rot_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of the rotation taking matrices a to b (..., 3, 3), accurate for small angles."""
    d = np.swapaxes(a, -1, -2) @ b
    axial = np.stack([d[..., 2, 1] - d[..., 1, 2], d[..., 0, 2] - d[..., 2, 0], d[..., 1, 0] - d[..., 0, 1]], -1)
    tr = d[..., 0, 0] + d[..., 1, 1] + d[..., 2, 2]
    return np.arctan2(0.5 * np.linalg.norm(axial, axis=-1), 0.5 * (tr - 1.0))


def dir_angle(a, b):
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def rotation_vectors(quats: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (x, y, z, w), w >= 0 → (N, 3) rotation vectors axis × angle."""
    q = np.asarray(quats, dtype=np.float64)
    u, w = q[:, :3], np.clip(q[:, 3], -1.0, 1.0)
    s = np.linalg.norm(u, axis=1)
    angle = 2.0 * np.arctan2(s, w)
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0 / np.maximum(w, 1e-300))
    return (u * scale[:, None]).astype(np.float32)


def uv_sphere(c, r, lat=24, lon=32):
    """A closed UV sphere (poles as single vertices) of radius r at c: (V, 3) float32 vertices and
    (F, 3) int64 outward-facing triangles."""
    th = np.pi * np.arange(1, lat) / lat
    ph = 2 * np.pi * np.arange(lon) / lon
    ring = np.stack([np.outer(np.sin(th), np.cos(ph)), np.outer(np.sin(th), np.sin(ph)), np.repeat(np.cos(th)[:, None], lon, 1)], -1).reshape(-1, 3)
    v = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * r + np.asarray(c)
    idx = lambda i, j: 1 + (i - 1) * lon + (j % lon)  # noqa: E731
    f = [(0, idx(1, j), idx(1, j + 1)) for j in range(lon)]
    for i in range(1, lat - 1):
        for j in range(lon):
            a, b, cc, d = idx(i, j), idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1)
            f += [(a, cc, d), (a, d, b)]
    s = len(v) - 1
    f += [(s, idx(lat - 1, j + 1), idx(lat - 1, j)) for j in range(lon)]
    return v.astype(np.float32), np.asarray(f, np.int64)
