"""Mesh arrays of the Blender layer: an evaluated mesh as numpy arrays through ``foreach_get``
(never a Python loop over vertices), and the object-to-world transform of positions and normals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import words


def to_world(co, nrm, matrix, what: str, error=ValueError):
    """Object-space positions and normals (flat or (V, 3)) to world space as float32 (V, 3):
    positions by ``matrix``, normals by its inverse transpose, renormalised. A singular or
    non-finite result raises ``error``, naming ``what``."""
    m = np.asarray(matrix, dtype=np.float64)
    lin = m[:3, :3]
    if not abs(np.linalg.det(lin)) > 1e-30:
        raise error(f"{what} has a singular transform (zero scale)")
    v = np.asarray(co, dtype=np.float64).reshape(-1, 3) @ lin.T + m[:3, 3]
    n = np.asarray(nrm, dtype=np.float64).reshape(-1, 3) @ np.linalg.inv(lin)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(n))):
        raise error(f"{what} has non-finite vertex positions or transform")
    return v.astype(np.float32), n.astype(np.float32)


@dataclass
class MeshArrays:
    """An evaluated mesh as arrays: vertices and vertex normals (V, 3) float32, triangles (F, 3)
    int32, in world space unless asked otherwise."""

    vertices: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray


def mesh_arrays(obj, depsgraph=None, *, world: bool = True, error=ValueError) -> MeshArrays:
    """Vertices, vertex normals and triangles of ``obj``'s evaluated mesh (modifiers, shape keys
    and armatures applied), read with foreach_get. A singular or non-finite transform raises
    ``error`` (a ValueError)."""
    import bpy  # noqa: PLC0415 - Blender only

    if obj is None:
        raise ValueError("obj: is None")
    if obj.type != "MESH":
        raise ValueError(f"obj: '{obj.name}' is {words.kind(obj.type)}, not a mesh")
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
    if world:
        co, nrm = to_world(co, nrm, np.array(obj.matrix_world, dtype=np.float64), f"obj: '{obj.name}'", error)
    else:
        co, nrm = co.reshape(-1, 3), nrm.reshape(-1, 3)
        if not (np.all(np.isfinite(co)) and np.all(np.isfinite(nrm))):
            raise ValueError(f"obj: '{obj.name}' has non-finite vertex positions")
    return MeshArrays(co, nrm, tri.reshape(-1, 3))
