"""rokeby.api — the scripting API of Rokeby, used by the operators and by background scripts.

Data moves as numpy arrays (``foreach_get``/``foreach_set``), never with Python loops over
vertices. Functions that need Blender import ``bpy`` lazily, so the maths helpers work in any
Python with numpy and rokeby_native.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from . import native

__all__ = [
    "reflect",
    "constraint_row",
    "physical_reflected_point",
    "MeshArrays",
    "mesh_arrays",
    "rotation_field",
    "edited_directions",
    "rotate",
    "quat_angle",
    "geodesic_solver",
    "geodesic_distances",
]


def _vec3(value, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,):
        raise ValueError(f"{name}: expected 3 numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: is not finite ({a.tolist()})")
    return a


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not n > 1e-20:
        raise ValueError(f"{name}: has zero length")
    return v / n


def reflect(incident, normal) -> np.ndarray:
    """Mirror reflection of unit ``incident`` (pointing at the surface) about unit ``normal``."""
    i = np.asarray(incident, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    return i - 2.0 * np.sum(i * n, axis=-1, keepdims=True) * n


def constraint_row(surface_point, normal, reflected_point, eye) -> np.ndarray:
    """One constraint row [p, r, e] (float32, 9 values) from the handles of the paper's UI:
    the red handle ``surface_point`` p on the mirror (with the surface ``normal`` there), the green
    handle ``reflected_point`` that should appear reflected at p, and the generating ``eye``.
    r is the physical reflection of the view ray at p; e points from p to the green handle.
    """
    p = _vec3(surface_point, "surface_point")
    n = _unit(_vec3(normal, "normal"), "normal")
    g = _vec3(reflected_point, "reflected_point")
    eye = _vec3(eye, "eye")
    i = _unit(p - eye, "surface_point - eye")
    r = _unit(reflect(i, n), "reflected direction")
    e = _unit(g - p, "reflected_point - surface_point")
    return np.concatenate([p, r, e]).astype(np.float32)


def physical_reflected_point(surface_point, normal, eye, distance: float) -> np.ndarray:
    """Where the physically correct reflected ray from ``surface_point`` is at ``distance``: the
    green handle of a fresh constraint (which therefore changes nothing until it moves)."""
    p = _vec3(surface_point, "surface_point")
    n = _unit(_vec3(normal, "normal"), "normal")
    i = _unit(p - _vec3(eye, "eye"), "surface_point - eye")
    if not (np.isfinite(distance) and distance > 0):
        raise ValueError(f"distance: must be finite and > 0, got {distance}")
    return p + distance * _unit(reflect(i, n), "reflected direction")


@dataclass
class MeshArrays:
    """An evaluated mesh as arrays: vertices and vertex normals (V, 3) float32, triangles (F, 3)
    int32, in world space unless asked otherwise."""

    vertices: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray


def mesh_arrays(obj, depsgraph=None, *, world: bool = True) -> MeshArrays:
    """Vertices, vertex normals and triangles of ``obj``'s evaluated mesh (modifiers, shape keys
    and armatures applied), read with foreach_get."""
    import bpy  # noqa: PLC0415 - Blender only

    if obj is None:
        raise ValueError("obj: is None")
    if obj.type != "MESH":
        raise ValueError(f"obj: '{obj.name}' is a {obj.type}, not a mesh")
    dg = depsgraph if depsgraph is not None else bpy.context.evaluated_depsgraph_get()
    ob_eval = obj.evaluated_get(dg)
    me = ob_eval.to_mesh()
    try:
        me.calc_loop_triangles()
        nv, nt = len(me.vertices), len(me.loop_triangles)
        if nt == 0:
            raise ValueError(f"obj: '{obj.name}' has no faces")
        co = np.empty(nv * 3, dtype=np.float32)
        me.vertices.foreach_get("co", co)
        nrm = np.empty(nv * 3, dtype=np.float32)
        me.vertex_normals.foreach_get("vector", nrm)
        tri = np.empty(nt * 3, dtype=np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
    finally:
        ob_eval.to_mesh_clear()
    co = co.reshape(-1, 3)
    nrm = nrm.reshape(-1, 3)
    if world:
        m = np.array(obj.matrix_world, dtype=np.float64)
        co = (co @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
        try:
            nm = np.linalg.inv(m[:3, :3]).T
        except np.linalg.LinAlgError:
            raise ValueError(f"obj: '{obj.name}' has a singular transform (zero scale)") from None
        nrm = nrm.astype(np.float64) @ nm.T
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
        nrm = nrm.astype(np.float32)
    if not (np.all(np.isfinite(co)) and np.all(np.isfinite(nrm))):
        raise ValueError(f"obj: '{obj.name}' has non-finite vertex positions or transform")
    return MeshArrays(co, nrm, tri.reshape(-1, 3))


def rotation_field(points, constraints, **kwargs) -> np.ndarray:
    """The MLS rotation field at ``points`` as (N, 4) quaternions (x, y, z, w); see
    ``rokeby_native.rotation_field`` for the keyword arguments (distances, regions, normals, eye,
    polar)."""
    return native.rotation_field(points, constraints, **kwargs)


def edited_directions(positions, normals, eye, constraints, **kwargs) -> np.ndarray:
    """Edited reflection directions per pixel/point; see ``rokeby_native.edited_directions``."""
    return native.edited_directions(positions, normals, eye, constraints, **kwargs)


def rotate(quats: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Apply unit quaternions (..., 4) as (x, y, z, w) to vectors (..., 3), vectorised."""
    q = np.asarray(quats, dtype=np.float64)
    v = np.asarray(vectors, dtype=np.float64)
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_angle(quats: np.ndarray) -> np.ndarray:
    """Rotation angle in radians of each quaternion (..., 4), accurate for small angles."""
    q = np.asarray(quats, dtype=np.float64)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


# GeodesicSolvers by mesh: the factorisation is the expensive part and is reused for every handle
# move; a change of topology (faces) or of positions (which change the Laplacian) makes a new one.
_SOLVER_CACHE: "OrderedDict[tuple, object]" = OrderedDict()
_SOLVER_CACHE_SIZE = 8


def _digest(a: np.ndarray) -> str:
    a = np.ascontiguousarray(a)
    return hashlib.blake2b(a.tobytes(), digest_size=16).hexdigest() + str(a.shape) + str(a.dtype)


def geodesic_solver(vertices, faces, *, boundary: str = "average"):
    """A ``rokeby_native.GeodesicSolver`` for this mesh, reused while neither its faces (topology)
    nor its vertex positions change; otherwise a new one (keeps the 8 most recent meshes)."""
    v = np.asarray(vertices, dtype=np.float32)
    f = np.asarray(faces)
    key = (_digest(f), _digest(v), boundary)
    solver = _SOLVER_CACHE.get(key)
    if solver is None:
        solver = native.module().GeodesicSolver(v, f, boundary=boundary)
        _SOLVER_CACHE[key] = solver
        while len(_SOLVER_CACHE) > _SOLVER_CACHE_SIZE:
            _SOLVER_CACHE.popitem(last=False)
    else:
        _SOLVER_CACHE.move_to_end(key)
    return solver


def geodesic_distances(vertices, faces, sources, *, method: str = "heat", boundary: str = "average") -> np.ndarray:
    """Geodesic distances (S, V) through the cached solver of this mesh; see
    ``rokeby_native.GeodesicSolver.distances`` for the forms ``sources`` may take."""
    return geodesic_solver(vertices, faces, boundary=boundary).distances(sources, method=method)
