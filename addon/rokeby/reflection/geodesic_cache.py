"""Geodesic distances and region weights of a mirror, cached so a handle move costs one solve.

The geodesic solver (with its factorisation) is kept per mesh (:func:`_solver`), the distances
per constraint surface point (:func:`_geodesic_distances`) and the weights of geodesic and
free-form regions per region and method (:func:`_regions_for_native`), all in the mirror's
runtime state (rokeby.reflection.mirror_state) until its geometry changes. So moving one red
handle solves for that handle only.

While a red handle is dragged in a window (an interactive update), that solve is replaced by a
fast preview (:data:`DRAG_UPDATE`, else :data:`DRAG_METHOD`; the report says so); the mirror's own
method follows when the drag ends (:data:`SETTLE_INTERVAL`, rokeby.reflection.handlers), and
before any render or save, so only the accurate field is ever rendered or saved.
"""

from __future__ import annotations

import numpy as np

from ..core import native
from .mirror_state import _State
from .mirror_surface import _Geometry

# While the artist drags a red handle (interactive updates), the moved constraint's geodesic
# distances are a preview (the mirror's own method recomputes them when the updates pause, before
# any render and before a save). DRAG_UPDATE: the accurate distances d₀ from where the handle was
# last solved, p₀, updated by the change of the straight-line distances,
#   d(v) ≈ max(d₀(v) + |v − p| − |v − p₀|, |v − p|),
# exact next to the handle and never off by more than 2 |p − p₀| (triangle inequality), a
# few milliseconds at 100k vertices. Where that is not a fair guess (the handle moved more than
# DRAG_UPDATE_REACH of the mirror's size from p₀, or across a fold: d₀(p) more than
# DRAG_UPDATE_BEND times |p − p₀|), and with DRAG_UPDATE off, DRAG_METHOD solves instead
# (bench/addon_update.py measures both at 100k vertices).
DRAG_METHOD = "dijkstra"
DRAG_UPDATE = True
DRAG_UPDATE_REACH = 0.15
DRAG_UPDATE_BEND = 1.2
# Updates this far apart (seconds) end a drag: the accurate distances follow (rokeby.reflection.handlers).
SETTLE_INTERVAL = 0.25


def _solver(state: _State, geo: _Geometry, timer):
    """The mirror's GeodesicSolver, kept while its geometry version is unchanged (no hashing of
    the mesh per handle move); its factorisation is made on the first heat query."""
    if state.solver is None or state.solver_version != state.geometry_version:
        state.solver = timer(native.module().geometry.GeodesicSolver, geo.vertices, geo.triangles)
        state.solver_version = state.geometry_version
    return state.solver


def _geodesic_distances(state: _State, geo: _Geometry, points, method: str, timer, drag: bool = False):
    """(K, V) distances from each constraint's surface point, cached per point: only a moved
    handle costs a solve. ``drag`` (an interactive update of a mirror whose distances are cached
    already, so a handle is being moved): the points not in the cache get a preview instead of a
    solve by ``method``: DRAG_UPDATE's update of their anchor, else a DRAG_METHOD solve. Returns
    (distances, whether any row is such a preview)."""
    out = np.empty((len(points), len(geo.vertices)), dtype=np.float32)
    fast = drag and method != DRAG_METHOD and state.distances_ready == (state.geometry_version, method)
    missing = []
    previewed = False
    for k, sp in enumerate(points):
        key = (method, sp.triangle, sp.bary.tobytes())
        d = state.distance_cache.get(key)
        if d is None and fast:
            d = state.distance_cache.get(("drag",) + key[1:])
            if d is None:
                d = state.distance_cache.get((DRAG_METHOD,) + key[1:])
            if d is None and DRAG_UPDATE and len(state.anchors) == len(points):  # same constraints as at the start
                d = _drag_update(state, geo, k, sp)
            previewed |= d is not None
        if d is None:
            missing.append((k, key, sp))
        else:
            out[k] = d
    if missing:
        solve_with = DRAG_METHOD if fast else method
        sources = [(sp.triangle, tuple(float(b) for b in sp.bary)) for _, _, sp in missing]
        solved = timer(_solver(state, geo, timer).distances, sources, method=solve_with)
        for (k, key, _), d in zip(missing, solved):
            out[k] = d
            state.distance_cache[(solve_with,) + key[1:]] = d
        previewed |= fast
    if not previewed:
        state.distances_ready = (state.geometry_version, method)
        state.anchors = [[np.asarray(sp.point, dtype=np.float32), out[k], None] for k, sp in enumerate(points)]
    # Bound the cache: keep what the current constraints use.
    used = {(m, sp.triangle, sp.bary.tobytes()) for sp in points for m in (method, DRAG_METHOD, "drag")}
    if len(state.distance_cache) > 4 * max(len(points), 8):
        state.distance_cache = {k: v for k, v in state.distance_cache.items() if k in used}
    return out, previewed


def _distances_to(geo: _Geometry, point) -> np.ndarray:
    """|v − point| for every vertex, as |v|² − 2 v·point + |point|² in f64 (|v|² and the
    coordinate columns kept with the mesh). Elementwise, not ``@``: numpy's OpenBLAS hands a
    matrix-vector product to its threads, and on a busy 2-core machine waiting for them to be
    scheduled cost milliseconds per call in the drag loop (profiled: the Python share of a step
    fell by half without it and the per-handle inverse below)."""
    if getattr(geo, "_columns", None) is None:
        v = np.asarray(geo.vertices, dtype=np.float64)
        geo._columns = (np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1]), np.ascontiguousarray(v[:, 2]))
        geo._vv = np.einsum("ij,ij->i", v, v)
    q = np.asarray(point, dtype=np.float64)
    x, y, z = geo._columns
    t = x * (-2.0 * q[0])
    t += y * (-2.0 * q[1])
    t += z * (-2.0 * q[2])
    t += geo._vv
    t += float(q @ q)
    np.maximum(t, 0.0, out=t)
    return np.sqrt(t, out=t)


def _drag_update(state: _State, geo: _Geometry, k: int, sp):
    """The drag preview of point ``k`` updated from its anchor (see DRAG_UPDATE), cached; None
    where that is not a fair guess (then DRAG_METHOD solves)."""
    if k >= len(state.anchors):
        return None
    p0, d0, _ = state.anchors[k]
    p = np.asarray(sp.point, dtype=np.float32)
    moved = float(np.linalg.norm(p - p0))
    tri = geo.triangles[sp.triangle]
    along = float(np.dot(sp.bary, d0[tri]))  # d₀ at the new point: the distance dragged over the surface
    if not np.isfinite(along) or moved > DRAG_UPDATE_REACH * geo.size or along > DRAG_UPDATE_BEND * moved + 1e-6 * geo.size:
        return None
    near = _distances_to(geo, p)
    if state.anchors[k][2] is None:  # |v − p₀|: once per drag
        state.anchors[k][2] = _distances_to(geo, p0)
    d = np.maximum(d0 + (near - state.anchors[k][2]), near).astype(np.float32)  # +inf stays +inf (other pieces)
    state.distance_cache[("drag", sp.triangle, sp.bary.tobytes())] = d
    return d


def _regions_for_native(state, geo, specs, points, method, timer):
    regions = []
    face_index = np.array([sp.triangle for sp in points], dtype=np.int64)
    bary = np.array([sp.bary for sp in points], dtype=np.float64).reshape(-1, 3)

    def at_constraints(values):
        if len(points) == 0:
            return np.zeros(0, dtype=np.float32)
        return timer(native.module().geometry.interpolate, values, geo.triangles, face_index, bary)[0]

    for spec in specs:
        if spec[0] == "EUCLIDEAN":
            _, centre, radius, border = spec
            regions.append({"kind": "euclidean", "center": list(centre), "radius": radius, "border": border})
            continue
        key = (spec, method)
        values = state.region_cache.get(key)
        if values is None:  # region weights are kept until the region or the mesh changes
            solver = _solver(state, geo, timer)
            if spec[0] == "GEODESIC":
                _, tri, b, radius, border = spec
                values = timer(solver.geodesic_region, (tri, b), radius, border, method)
            else:
                _, group, border = spec
                values = timer(solver.freeform_region, geo.region_weights[group], border, method)
            state.region_cache[key] = values
        regions.append({"kind": "weights", "values": values, "at_constraints": at_constraints(values)})
    used = {(spec, method) for spec in specs}
    for k in [k for k in state.region_cache if k not in used]:
        del state.region_cache[k]
    return regions


def _preview_note(obj) -> str:
    method = obj.rokeby.geodesic_method.lower()
    return (f"drag preview: the moved handles' geodesic distances are estimated (updated from where the drag started, "
            f"or by {DRAG_METHOD}) until the drag ends, then {method}'s (renders and saved files always use {method})")
