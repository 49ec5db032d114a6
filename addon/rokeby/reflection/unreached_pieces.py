"""Geodesic distances on meshes of several pieces: where no constraint of a group reaches a
vertex over the surface, that group blends its constraints there by straight-line distance
(Rokeby's rule, applied by the evaluator to the (K, V) distances before the native blend)."""

from __future__ import annotations

import numpy as np

from ..core import vecmath


# Geodesic distances do not cross gaps: a vertex on a piece (connected component) of the mesh that
# no constraint is on is at +inf from every constraint. Rokeby's rule, the same for any number of
# constraints K: where no constraint of a group (all constraints, or the constraints of one
# region) reaches a vertex over the surface, that group blends its constraints there by
# straight-line (Euclidean) distance, exactly as with Distance: Euclidean. With K = 1 that is the
# constant rotation the one constraint gives everywhere (what the core did already); with K >= 2
# the unreached pieces no longer fall back to no edit. Pieces that some constraints reach keep
# their geodesic blend of those.


def _region_falloff(d: np.ndarray, radius: float, border: float) -> np.ndarray:
    """rokeby_core's region falloff (1 in the core, a smooth step over the border, 0 outside)."""
    return vecmath.region_falloff(d, radius, border)


def constraint_groups(rows: np.ndarray, regions=None) -> list:
    """The constraints that blend together (index arrays), as the core forms them: all of them
    without regions, else per region those at which the region's weight is above 0."""
    k = len(rows)
    if not regions:
        return [np.arange(k)] if k else []
    p = np.asarray(rows, dtype=np.float64)[:, :3]
    groups = []
    for reg in regions:
        if reg["kind"] == "euclidean":
            a = _region_falloff(np.linalg.norm(p - np.asarray(reg["center"], dtype=np.float64), axis=1), float(reg["radius"]), float(reg["border"]))
        else:
            a = np.asarray(reg["at_constraints"], dtype=np.float64)
        members = np.flatnonzero(a > 0.0)
        if len(members):
            groups.append(members)
    return groups


def unreached_fallback(distances: np.ndarray, rows: np.ndarray, vertices: np.ndarray, regions=None) -> np.ndarray:
    """(K, V) geodesic distances with Rokeby's rule for unreached pieces applied (see above):
    where no constraint of a group reaches a vertex, its constraints' distances there become
    straight-line distances. A constraint in several groups keeps +inf where one of them is
    reached (it must not enter that group's geodesic blend). Returns a new array when anything
    changed (the cached distances are never modified)."""
    d = np.asarray(distances, dtype=np.float32)
    unreached = ~np.isfinite(d)
    if not unreached.any() or not len(rows):
        return d
    allow = np.zeros_like(unreached)
    first = np.ones(len(rows), dtype=bool)
    for g in constraint_groups(rows, regions):
        nobody = unreached[g].all(axis=0)
        allow[g] = np.where(first[g][:, None], nobody[None, :], allow[g] & nobody[None, :])
        first[g] = False
    fallback = unreached & allow
    if not fallback.any():
        return d
    out = d.copy()
    cols = np.flatnonzero(fallback.any(axis=0))
    p = np.asarray(rows, dtype=np.float64)[:, :3]
    v = np.asarray(vertices, dtype=np.float64)
    for n in np.flatnonzero(fallback.any(axis=1)):
        c = cols[fallback[n, cols]]
        out[n, c] = np.linalg.norm(v[c] - p[n], axis=1)
    return out


def mesh_pieces(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """Connected component (piece) of each vertex over the triangles' edges, labelled by its
    smallest vertex index; -1 for vertices in no triangle. Union by hooking roots to the smaller
    label and pointer jumping: a few numpy passes, no Python loop over vertices."""
    lab = np.arange(n_vertices, dtype=np.int64)
    tri = np.asarray(triangles, dtype=np.int64)
    if len(tri):
        a = tri.ravel()
        b = tri[:, [1, 2, 0]].ravel()
        while True:
            la, lb = lab[a], lab[b]
            diff = la != lb
            if not diff.any():
                break
            lo, hi = np.minimum(la[diff], lb[diff]), np.maximum(la[diff], lb[diff])
            np.minimum.at(lab, hi, lo)
            while True:
                nxt = lab[lab]
                if np.array_equal(nxt, lab):
                    break
                lab = nxt
    used = np.zeros(n_vertices, dtype=bool)
    used[tri.ravel()] = True
    return np.where(used, lab, -1)


def _unreached_pieces(state, geo, distances) -> "tuple | None":
    """(pieces no constraint reaches over the surface, pieces of the mesh), or None when every
    piece is reached."""
    nobody = ~np.isfinite(distances).any(axis=0)
    if not nobody.any():
        return None
    if state.pieces is None or state.pieces[0] != state.geometry_version:
        state.pieces = (state.geometry_version, mesh_pieces(geo.triangles, len(geo.vertices)))
    labels = state.pieces[1]
    total = len(np.unique(labels[labels >= 0]))
    hit = labels[nobody & (labels >= 0)]
    return int(len(np.unique(hit))), int(total)
