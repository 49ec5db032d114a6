"""Minimal Wavefront OBJ reader (vertices and faces, polygons fan-triangulated) in numpy.

For scripts, tests and benchmarks that run without Blender's importer. Texture and normal indices
(``f 1/2/3``) and negative (relative) indices are understood; everything else is ignored.
"""

from __future__ import annotations

import numpy as np


def load_obj(path) -> tuple[np.ndarray, np.ndarray]:
    """Return (vertices (V, 3) float32, triangles (F, 3) int32)."""
    verts: list[list[float]] = []
    tris: list[tuple[int, int, int]] = []
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            if line.startswith("v "):
                parts = line.split()
                verts.append([float(parts[1]), float(parts[2]), float(parts[3])])
            elif line.startswith("f "):
                idx = []
                for tok in line.split()[1:]:
                    i = int(tok.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(verts) + i)
                if len(idx) < 3:
                    raise ValueError(f"{path}:{lineno}: face with fewer than 3 vertices")
                for k in range(1, len(idx) - 1):
                    tris.append((idx[0], idx[k], idx[k + 1]))
    v = np.asarray(verts, dtype=np.float32).reshape(-1, 3)
    f = np.asarray(tris, dtype=np.int32).reshape(-1, 3)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"{path}: face index out of range")
    return v, f


def vertex_normals(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (unit; zero-area neighbourhoods get +Z)."""
    v = verts.astype(np.float64)
    fn = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, tris[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(length > 1e-30, n / np.maximum(length, 1e-30), np.array([0.0, 0.0, 1.0]))
    return out.astype(np.float32)


def subdivide_midpoint(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One level of midpoint subdivision: every triangle into four, a new vertex at the middle of
    every edge (shared between the faces of that edge). Keeps the surface exactly; quadruples the
    triangle count (for benchmark meshes of the size of the paper's 525k-triangle Lucy)."""
    f = np.asarray(tris, dtype=np.int64)
    v = np.asarray(verts)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(e, axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    mid = (v[uniq[:, 0]].astype(np.float64) + v[uniq[:, 1]]) / 2
    nv = len(v)
    m = inv.reshape(3, -1).T + nv  # midpoints of edges (0,1), (1,2), (2,0) per face
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    m01, m12, m20 = m[:, 0], m[:, 1], m[:, 2]
    new_f = np.concatenate([np.stack([a, m01, m20], 1), np.stack([m01, b, m12], 1), np.stack([m20, m12, c], 1), np.stack([m01, m12, m20], 1)])
    return np.vstack([v, mid.astype(v.dtype)]), new_f.astype(np.int32)


def open_seams(verts: np.ndarray, tris: np.ndarray, tolerance: float = 1e-7) -> int:
    """Boundary edges that lie on another boundary edge: the two sides of an unwelded seam
    (duplicate vertices at the same positions, as along the Utah teapot's patches). The surface
    is cut there, so geodesic distances must go around, which the heat method does not do
    (docs/geodesics.md); the sidebar warns about heat on such meshes. Positions within
    ``tolerance`` of the mesh's size count as the same."""
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    verts = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    if len(tris) == 0 or len(verts) == 0:
        return 0
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    boundary = edges[count == 1]
    if len(boundary) < 2:
        return 0
    finite = np.isfinite(verts).all(axis=1)
    size = float(np.ptp(verts[finite], axis=0).max()) if finite.any() else 0.0
    cell = tolerance * size if size > 0 else 1.0
    q = np.round(np.where(finite[:, None], verts, 0.0) / cell).astype(np.int64)
    _, place = np.unique(q, axis=0, return_inverse=True)
    place = place.reshape(-1)
    pe = np.sort(place[boundary], axis=1)
    pe = pe[pe[:, 0] != pe[:, 1]]
    if len(pe) < 2:
        return 0
    _, inverse, n = np.unique(pe, axis=0, return_inverse=True, return_counts=True)
    return int((n[inverse.reshape(-1)] >= 2).sum())
