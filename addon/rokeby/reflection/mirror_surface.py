"""The mirror's surface as the evaluator reads it: the evaluated mesh in world space
(:class:`_Geometry`, :func:`read_geometry`) and the nearest surface point of a handle
(:func:`project_to_surface`: numpy for a new shape, a BVH once a shape is queried again)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blender import meshes
from ..core import meshio
from ..core.errors import RokebyError
from .freeform_regions import _vertex_group_weights


class _Geometry:
    """The field mesh of a mirror in world space, with what the projections need."""

    def __init__(self, vertices, normals, triangles, tri_poly, source):
        self.vertices = vertices
        self.normals = normals
        self.triangles = triangles
        self.tri_poly = tri_poly  # polygon of each loop triangle (sorted), for closest-point lookups
        self.source = source  # "evaluated" or "transfer" (see read_geometry)
        self.local = None  # object-space positions (V, 3) float32, for the surface queries
        self.uses = 0  # evaluations that used this shape (a BVH pays off from the second on)
        self.queries = 0  # surface queries answered by nearest_triangle
        self.max_edge = None  # longest triangle edge in object space, for nearest_triangle
        self.size = float(np.linalg.norm(vertices.max(0) - vertices.min(0))) if len(vertices) else 0.0
        self.region_weights: dict[str, np.ndarray] = {}
        self.region_problems: dict[str, str] = {}  # vertex group → why it could not be read
        self.bvh = None
        self._poly_start = None
        self.edges = None  # mesh_edges(triangles), made on first use
        self.shared = False  # the mesh had other users when read (see shares_mesh)
        self._open_seams = None  # meshio.open_seams, made on first use

    @property
    def open_seams(self) -> int:
        """Boundary edges on unwelded seams (meshio.open_seams), counted once per shape."""
        if self._open_seams is None:
            self._open_seams = meshio.open_seams(self.vertices, self.triangles)
        return self._open_seams

    def triangles_of_polygon(self, poly: int) -> range:
        if self._poly_start is None:
            # loop triangles are stored polygon by polygon: one searchsorted for all polygons
            n_poly = int(self.tri_poly[-1]) + 1 if len(self.tri_poly) else 0
            self._poly_start = np.searchsorted(self.tri_poly, np.arange(n_poly + 1))
        if not 0 <= poly < len(self._poly_start) - 1:
            return range(0)
        return range(int(self._poly_start[poly]), int(self._poly_start[poly + 1]))

    def same_positions(self, other: "_Geometry | None") -> bool:
        return (
            other is not None
            and other.source == self.source
            and other.vertices.shape == self.vertices.shape
            and other.triangles.shape == self.triangles.shape
            and np.array_equal(other.vertices, self.vertices)
            and np.array_equal(other.triangles, self.triangles)
            and other.region_weights.keys() == self.region_weights.keys()
            and all(np.array_equal(other.region_weights[k], v) for k, v in self.region_weights.items())
        )


def _finite_matrix(m, what: str) -> np.ndarray:
    a = np.array(m, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise RokebyError(f"{what} has a non-finite transform (NaN or inf)")
    return a


def to_world(co, nrm, matrix, what: str):
    """Object-space positions and normals to world space (rokeby.blender.meshes.to_world); a
    singular or non-finite result is a RokebyError naming ``what``."""
    return meshes.to_world(co, nrm, matrix, what, RokebyError)


def shares_mesh(obj) -> bool:
    """Whether ``obj``'s mesh is used by other objects too (Alt+D, Ctrl+L ▸ Link Object Data):
    its field then lives in a carrier of its own, never in the shared mesh."""
    me = obj.data
    return me is not None and me.users - int(me.use_fake_user) > 1


def read_geometry(obj, depsgraph, mirror_matrix: np.ndarray, freeform_groups=()) -> _Geometry:
    """The mirror's mesh in world space: always the evaluated mesh (modifiers, shape keys,
    armatures), the surface the render shows. When a modifier changes the vertex count
    (Subdivision), or the mesh is shared with other objects, source is "transfer": the field goes
    to the mirror's own carrier mesh of that topology, which the 'Rokeby field' modifier at the
    end of the stack copies onto the evaluated mesh."""
    ob_eval = obj.evaluated_get(depsgraph)
    me = ob_eval.data
    shared = shares_mesh(obj)
    source = "evaluated" if len(me.vertices) == len(obj.data.vertices) and not shared else "transfer"
    nv = len(me.vertices)
    if nv == 0 or len(me.polygons) == 0:
        raise RokebyError(f"mirror '{obj.name}' has no faces")
    co = np.empty(nv * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    nrm = np.empty(nv * 3, dtype=np.float32)
    me.vertex_normals.foreach_get("vector", nrm)
    nt = len(me.loop_triangles)
    if nt == 0:
        me.calc_loop_triangles()
        nt = len(me.loop_triangles)
    tri = np.empty(nt * 3, dtype=np.int32)
    me.loop_triangles.foreach_get("vertices", tri)
    tri_poly = np.empty(nt, dtype=np.int32)
    me.loop_triangle_polygons.foreach_get("value", tri_poly)
    v, n = to_world(co, nrm, mirror_matrix, f"mirror '{obj.name}'")
    geo = _Geometry(v, n, tri.reshape(-1, 3), tri_poly, source)
    geo.shared = shared
    geo.local = co.reshape(-1, 3)
    for group in freeform_groups:
        # A group that cannot be read is the region's problem (a warning naming the group, the
        # region left out), not the mirror's: the other regions and constraints still evaluate.
        try:
            geo.region_weights[group] = _vertex_group_weights(obj, me, group)
        except RokebyError as exc:
            geo.region_problems[group] = str(exc)
    return geo


def _bvh(geo: _Geometry):
    """A BVH over the triangles of ``geo`` in object space (kept while the local positions and
    triangles are unchanged, also across transforms), built from the copied arrays: surface
    queries never touch Blender's evaluated mesh, which another handler's ID removal in the same
    update can free under us."""
    if geo.bvh is None:
        from mathutils.bvhtree import BVHTree  # noqa: PLC0415

        pts = geo.local if geo.local is not None else geo.vertices
        geo.bvh = BVHTree.FromPolygons(pts.tolist(), geo.triangles.tolist(), all_triangles=True)
    return geo.bvh


# Surface queries on a new shape answered without a BVH; beyond them the BVH is built.
NUMPY_QUERIES = 16


def nearest_triangle(geo: _Geometry, query) -> int:
    """Index of a triangle of ``geo`` nearest the object-space point ``query``, with numpy and no
    acceleration structure (O(V + T) per query, about 2 ms at 100k vertices): for a shape that is
    queried once or twice (a deforming mirror on a frame change), where building a BVH would
    cost far more. The nearest surface point lies in a triangle with a vertex within d + L of
    the query (d: distance to the nearest vertex, L: the longest edge), so only those are
    measured exactly."""
    pts = geo.local if geo.local is not None else geo.vertices
    tri = geo.triangles
    x = np.asarray(query, np.float64)
    d2 = np.einsum("ij,ij->i", pts - x.astype(np.float32), pts - x.astype(np.float32)).astype(np.float64)
    if geo.max_edge is None:
        a, b, c = (pts[tri[:, k]] for k in range(3))
        geo.max_edge = float(np.sqrt(max(np.einsum("ij,ij->i", b - a, b - a).max(), np.einsum("ij,ij->i", c - b, c - b).max(),
                                         np.einsum("ij,ij->i", a - c, a - c).max()))) if len(tri) else 0.0
    reach = float(np.sqrt(d2.min())) + geo.max_edge
    near = d2 <= reach * reach * (1.0 + 1e-6) + 1e-30
    cand = np.flatnonzero(near[tri].any(axis=1))
    if len(cand) == 0:
        cand = np.arange(len(tri))
    a, b, c = (pts[tri[cand, k]].astype(np.float64) for k in range(3))
    best = np.full(len(cand), np.inf)
    # The three edges (segments), then the interior (projection onto the plane, when inside).
    for p0, p1 in ((a, b), (b, c), (c, a)):
        e = p1 - p0
        ee = np.einsum("ij,ij->i", e, e)
        t = np.clip(np.einsum("ij,ij->i", x - p0, e) / np.maximum(ee, 1e-300), 0.0, 1.0)
        q = p0 + t[:, None] * e
        best = np.minimum(best, np.einsum("ij,ij->i", x - q, x - q))
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    ok = nn > 1e-300
    h = np.einsum("ij,ij->i", x - a, n) / np.where(ok, nn, 1.0)
    p = x - h[:, None] * n
    inside = ok.copy()
    for p0, p1 in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(p1 - p0, p - p0), n) >= 0.0
    plane = h * h * nn
    best = np.where(inside, np.minimum(best, plane), best)
    return int(cand[int(np.argmin(best))])


def _barycentric(p, a, b, c) -> np.ndarray:
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
    d20, d21 = v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    if abs(den) < 1e-300:
        return np.array([1.0, 0.0, 0.0])
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    bary = np.clip(np.array([1.0 - v - w, v, w]), 0.0, 1.0)
    return bary / bary.sum()


@dataclass
class SurfacePoint:
    point: np.ndarray  # world position on the surface
    normal: np.ndarray  # smooth (interpolated) unit normal there
    triangle: int
    bary: np.ndarray
    offset: float  # distance of the queried point from the surface


def project_to_surface(obj, depsgraph, geo: _Geometry, world_point, mirror_matrix) -> SurfacePoint:
    """The surface point of the mirror nearest ``world_point``: triangle, barycentric coordinates
    and the interpolated vertex normal (the normal the renderers shade with)."""
    x = np.asarray(world_point, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise RokebyError(f"mirror '{getattr(obj, 'name', '?')}': the point to project is not finite")
    if geo.local is not None:
        # One inverse per mirror transform, not per handle: numpy's OpenBLAS wakes its threads
        # even for a 4×4 inverse, which on a busy machine took milliseconds of waiting (4 ms
        # median after an idle pause, 0.01 ms in a tight loop, load average 7 on 2 cores).
        key = np.asarray(mirror_matrix, dtype=np.float64).tobytes()
        cached = getattr(geo, "_inverse", None)
        if cached is None or cached[0] != key:
            geo._inverse = cached = (key, np.linalg.inv(mirror_matrix))
        inv = cached[1]
        query = inv[:3, :3] @ x + inv[:3, 3]
    else:
        query = x
    if geo.bvh is None and geo.uses < 2 and geo.queries < NUMPY_QUERIES:
        geo.queries += 1
        tri_index = nearest_triangle(geo, query)  # a new shape: no BVH yet (see nearest_triangle)
    else:
        _loc, _n, tri_index, _d = _bvh(geo).find_nearest(query.tolist())
    if tri_index is None:
        raise RokebyError(f"mirror '{getattr(obj, 'name', '?')}': no surface point found")
    # The nearest triangle in object space, and its neighbours of the same polygon (in world
    # space the nearest may differ under a non-uniform scale).
    candidates = geo.triangles_of_polygon(int(geo.tri_poly[tri_index])) if len(geo.tri_poly) > tri_index else [tri_index]
    if len(candidates) == 0:
        candidates = [tri_index]
    best = None
    for t in candidates:
        ia, ib, ic = geo.triangles[t]
        a, b, c = (geo.vertices[i].astype(np.float64) for i in (ia, ib, ic))
        bary = _barycentric(x, a, b, c)
        p = bary[0] * a + bary[1] * b + bary[2] * c
        d = float(np.linalg.norm(p - x))
        if best is None or d < best[0]:
            best = (d, t, bary, p)
    d, t, bary, p = best
    n = bary @ geo.normals[geo.triangles[t]].astype(np.float64)
    nn = np.linalg.norm(n)
    if not nn > 1e-20:  # opposite normals cancel (a sliver fold): use the face normal
        ia, ib, ic = geo.triangles[t]
        n = np.cross(geo.vertices[ib] - geo.vertices[ia], geo.vertices[ic] - geo.vertices[ia]).astype(np.float64)
        nn = max(np.linalg.norm(n), 1e-300)
    return SurfacePoint(p, n / nn, int(t), bary, d)
