"""The viewport preview's shader as data: where its GLSL files are, what they declare, and how the
per-pixel field's inputs are packed for them. No ``gpu`` and no ``bpy`` here, so the moderngl tests
and the Blender draw handler (``rokeby.reflection.viewport.draw``) share every line of it.

The GLSL lives in ``shaders/`` (see shaders/README.md):

- ``rokeby_field_types.glsl``: the std140 block ``RokebyField`` and its limits
  (``RK_MAX_CONSTRAINTS``, ``RK_MAX_REGIONS``),
- ``rokeby_field_lib.glsl``: e(q) = R_a(q) r(q) and the environment lookup,
- ``rokeby_preview_vert.glsl`` / ``rokeby_preview_frag.glsl``: thin stage wrappers.

Blender wants bodies without ``#version`` and declarations through ``GPUShaderCreateInfo``;
standalone OpenGL wants a header. Both are made from :data:`INTERFACE`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ...core import vecmath
from ...core.shaders import shader_dir, standalone_from

FILES = {
    "types": "rokeby_field_types.glsl",
    "lib": "rokeby_field_lib.glsl",
    "vertex": "rokeby_preview_vert.glsl",
    "fragment": "rokeby_preview_frag.glsl",
}


def read_sources() -> dict:
    d = shader_dir()
    return {key: (d / name).read_text() for key, name in FILES.items()}


def _define(name: str) -> int:
    text = (shader_dir() / FILES["types"]).read_text()
    m = re.search(rf"^#define\s+{name}\s+(\d+)", text, re.M)
    if m is None:
        raise RuntimeError(f"{FILES['types']} does not define {name}")
    return int(m.group(1))


MAX_CONSTRAINTS = _define("RK_MAX_CONSTRAINTS")
MAX_REGIONS = _define("RK_MAX_REGIONS")
if MAX_CONSTRAINTS > 128:
    raise RuntimeError("RK_MAX_CONSTRAINTS > 128 does not fit the uvec4 membership masks")

# counts.z
DIST_EUCLIDEAN, DIST_PER_VERTEX, PER_VERTEX_FIELD = 0, 1, 2
# options.y: what e(q) is looked up in
ENV_SKY, ENV_IMAGE, ENV_SCENE = 0, 1, 2
# options.x
OUT_COLOR, OUT_DIRECTION, OUT_POSITION, OUT_NORMAL, OUT_BARY, OUT_VERTEX_IDS = range(6)

# The shader's interface, in GPUShaderCreateInfo's terms.
INTERFACE = {
    "vertex_in": [(0, "VEC3", "rk_position"), (1, "VEC3", "rk_normal"), (2, "VEC3", "rk_vertex_ids")],
    "vertex_out": [("smooth", "VEC3", "rk_v_position"), ("smooth", "VEC3", "rk_v_normal"), ("smooth", "VEC3", "rk_v_bary"), ("flat", "VEC3", "rk_v_vertex_ids")],
    "push_constant": [("MAT4", "rk_view_projection"), ("FLOAT", "rk_depth_bias")],
    "sampler": [(0, "FLOAT_2D", "rk_vertex_data"), (1, "FLOAT_2D", "rk_env"), (2, "FLOAT_2D", "rk_world")],
    "uniform_buf": [(0, "RokebyField", "rk_field")],
    "fragment_out": [(0, "VEC4", "rk_out")],
}
INTERFACE_NAME = "rokeby_preview_iface"

def standalone_sources(version: str = "330 core") -> tuple[str, str]:
    """(vertex, fragment) of the field preview for a plain OpenGL context (moderngl)."""
    return standalone_from(INTERFACE, read_sources(), version)


# --- std140 layout of RokebyField ------------------------------------------------------------

_K, _R = MAX_CONSTRAINTS, MAX_REGIONS
OFFSETS = {}
_o = 0
for _name, _n in (("cp", _K), ("cr", _K), ("ce", _K), ("region_a", _R), ("region_b", _R), ("region_members", _R), ("eye", 1), ("counts", 1), ("vlayout", 1), ("options", 1), ("env_origin", 1), ("world_scale", 1)):
    OFFSETS[_name] = _o
    _o += 16 * _n  # every member is a vec4/uvec4/ivec4 or an array of them: 16-byte stride
BLOCK_SIZE = _o
del _o, _name, _n

VERTEX_TEXTURE_WIDTH = 4096


def _falloff(d: float, radius: float, border: float) -> float:
    """region::falloff, in float64 (one home: rokeby.core.vecmath.region_falloff)."""
    return float(vecmath.region_falloff(d, radius, border))


@dataclass
class Group:
    """A region holding at least one constraint (Rust's Group): the shader's unit of eq. 5."""

    kind: str  # "euclidean" | "weights"
    members: list
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.0
    border: float = 0.0
    slot: int = -1  # column of its per-vertex weights


@dataclass
class FieldPlan:
    """What the shader needs for one mirror, validated: the constraint rows, the region groups,
    where distances come from, and the per-vertex texture (distances, region weights, the stored
    rotation vectors), or the per-vertex fallback when the field exceeds the shader's limits."""

    rows: np.ndarray  # (K, 9) float64, r and e normalised
    groups: list
    has_regions: bool
    mode: int
    n_vertices: int
    vertex_data: np.ndarray  # (H, W, 4) float32
    texels_per_vertex: int
    offsets: tuple  # float offsets of distances, region weights, rotation vector
    message: str = ""
    warnings: list = field(default_factory=list)

    @property
    def per_pixel(self) -> bool:
        return self.mode != PER_VERTEX_FIELD


def _unit_rows(rows) -> np.ndarray:
    a = np.asarray(rows, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 9:
        raise ValueError(f"constraints: expected shape (K, 9) with rows [p, r, e], got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("constraints: not finite")
    a = a.copy()
    for cols, what in ((slice(3, 6), "r (columns 3-5)"), (slice(6, 9), "e (columns 6-8)")):
        n = np.linalg.norm(a[:, cols], axis=1)
        bad = np.flatnonzero(~(n > 1e-20))
        if len(bad):
            raise ValueError(f"constraints: row {bad[0]}: {what} has zero length")
        a[:, cols] /= n[:, None]
    return a


def plan_field(rows, regions=None, *, n_vertices: int, distances=None, rotations=None) -> FieldPlan:
    """Prepare one mirror's field for the shader, from the inputs the evaluator gives
    ``rokeby_native.reflection.rotation_field`` (rows (K, 9), regions as its list of dicts, distances
    (K, V) or None for Euclidean) and, for the fallback, the stored rotation vectors (V, 3).

    More than RK_MAX_CONSTRAINTS constraints, or more than RK_MAX_REGIONS regions holding
    constraints, switch to the per-vertex field (``rotations`` is then required); ``message``
    says so."""
    rows = _unit_rows(rows)
    k = len(rows)
    if not (isinstance(n_vertices, (int, np.integer)) and n_vertices > 0):
        raise ValueError(f"n_vertices: must be a positive integer, got {n_vertices!r}")
    if n_vertices >= 1 << 24:
        raise ValueError(f"mesh has {n_vertices:,} vertices; the preview passes vertex ids as float32 (at most 16,777,215)")
    regions = list(regions or [])
    groups = []
    weight_columns = []
    for j, reg in enumerate(regions):
        name = f"regions[{j}]"
        if not isinstance(reg, dict) or "kind" not in reg:
            raise ValueError(f"{name}: must be a dict with a 'kind'")
        if reg["kind"] == "euclidean":
            c = np.asarray(reg["center"], dtype=np.float64)
            radius, border = float(reg["radius"]), float(reg.get("border", 0.0))
            if c.shape != (3,) or not np.all(np.isfinite(c)):
                raise ValueError(f"{name}: center must be 3 finite numbers")
            if not (math.isfinite(radius) and radius > 0):
                raise ValueError(f"{name}: radius must be finite and > 0, got {radius}")
            if not (math.isfinite(border) and border >= 0):
                raise ValueError(f"{name}: border must be finite and >= 0, got {border}")
            members = [n for n in range(k) if _falloff(float(np.linalg.norm(rows[n, :3] - c)), radius, border) > 0.0]
            if members:
                groups.append(Group("euclidean", members, tuple(c), radius, border))
        elif reg["kind"] == "weights":
            values = np.asarray(reg["values"], dtype=np.float32).ravel()
            at = np.asarray(reg["at_constraints"], dtype=np.float32).ravel()
            if len(values) != n_vertices:
                raise ValueError(f"{name}: values has {len(values)} entries but the mesh has {n_vertices} vertices")
            if len(at) != k:
                raise ValueError(f"{name}: at_constraints has {len(at)} entries but there are {k} constraints")
            for what, arr in (("values", values), ("at_constraints", at)):
                bad = np.flatnonzero(~(np.isfinite(arr) & (arr >= 0) & (arr <= 1)))
                if len(bad):
                    raise ValueError(f"{name}: {what}[{bad[0]}] = {arr[bad[0]]} is not in [0, 1]")
            members = [n for n in range(k) if at[n] > 0.0]
            if members:
                groups.append(Group("weights", members, slot=len(weight_columns)))
                weight_columns.append(values)
        else:
            raise ValueError(f"{name}: unknown kind {reg['kind']!r} (expected 'euclidean' or 'weights')")
    d = None
    if distances is not None:
        d = np.asarray(distances, dtype=np.float32)
        if d.shape != (k, n_vertices):
            raise ValueError(f"distances: expected shape ({k}, {n_vertices}) (constraints x vertices), got {d.shape}")
        if np.any(np.isnan(d) | (d < 0)):
            raise ValueError("distances: NaN or negative entries (unreachable is +inf)")
    rot = None
    if rotations is not None:
        rot = np.asarray(rotations, dtype=np.float32)
        if rot.shape != (n_vertices, 3) or not np.all(np.isfinite(rot)):
            raise ValueError(f"rotations: expected finite (V, 3) = ({n_vertices}, 3) rotation vectors, got {rot.shape}")
    message = ""
    if k > MAX_CONSTRAINTS or len(groups) > MAX_REGIONS:
        why = f"{k} constraints (the shader holds {MAX_CONSTRAINTS})" if k > MAX_CONSTRAINTS else f"{len(groups)} regions with constraints (the shader holds {MAX_REGIONS})"
        if rot is None:
            raise ValueError(f"{why}: the per-vertex fallback needs the stored rotation vectors")
        mode = PER_VERTEX_FIELD
        message = f"{why}: showing the per-vertex field (rokeby_rotation) instead of the per-pixel one"
    elif regions and not groups:
        # Regions exist but hold no constraint: nothing acts anywhere (e = r).
        mode, rows = DIST_EUCLIDEAN, rows[:0]
    else:
        mode = DIST_PER_VERTEX if (d is not None and k > 0) else DIST_EUCLIDEAN
    # Per-vertex record: [distances (K)] [region weights] [rotation vector (3)], padded to texels.
    columns = []
    off_d = off_w = off_rv = 0
    if mode == DIST_PER_VERTEX:
        columns.append(d.T)
    if mode != PER_VERTEX_FIELD and weight_columns:
        off_w = sum(c.shape[1] for c in columns)
        columns.append(np.stack(weight_columns, axis=1))
    if mode == PER_VERTEX_FIELD:
        off_rv = 0
        columns.append(rot)
    if columns:
        record = np.concatenate([np.asarray(c, np.float32).reshape(n_vertices, -1) for c in columns], axis=1)
    else:
        record = np.zeros((n_vertices, 0), np.float32)
    texels = max(1, -(-record.shape[1] // 4))
    padded = np.zeros((n_vertices, texels * 4), np.float32)
    padded[:, : record.shape[1]] = record
    total = n_vertices * texels
    width = min(VERTEX_TEXTURE_WIDTH, total)
    height = -(-total // width)
    flat = np.zeros((height * width, 4), np.float32)
    flat[:total] = padded.reshape(total, 4)
    return FieldPlan(
        rows=rows,
        groups=groups if mode != PER_VERTEX_FIELD else [],
        has_regions=bool(regions) and mode != PER_VERTEX_FIELD and bool(groups),
        mode=mode,
        n_vertices=n_vertices,
        vertex_data=flat.reshape(height, width, 4),
        texels_per_vertex=texels,
        offsets=(off_d, off_w, off_rv),
        message=message,
    )


def pack_field(plan: FieldPlan, eye, *, eye_is_direction: bool = False, output: int = OUT_COLOR, env_image: bool = False, srgb: bool = False,
               env: int | None = None, env_origin=None, parallax: bool = True, world_scale=None) -> bytes:
    """The std140 bytes of ``RokebyField`` for ``plan`` seen from ``eye`` (a point; or, with
    ``eye_is_direction``, the direction towards an orthographic viewer).

    ``env``: what e(q) is looked up in (ENV_SKY, ENV_IMAGE, ENV_SCENE; default ENV_IMAGE with
    ``env_image``, else ENV_SKY). ENV_SCENE needs ``env_origin``, the point the scene was captured
    from; ``parallax`` corrects the lookup for the surface point q (else the centre-only lookup);
    ``world_scale`` (3 numbers): the world's own lat-long image (bound as rk_world) times this
    stands in for the capture's world texels (None: the capture's texels)."""
    if env is None:
        env = ENV_IMAGE if env_image else ENV_SKY
    if env not in (ENV_SKY, ENV_IMAGE, ENV_SCENE):
        raise ValueError(f"env: expected ENV_SKY, ENV_IMAGE or ENV_SCENE, got {env!r}")
    origin = np.zeros(3)
    if env == ENV_SCENE:
        if env_origin is None:
            raise ValueError("env_origin: ENV_SCENE needs the point the scene was captured from")
        origin = np.asarray(env_origin, dtype=np.float64)
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise ValueError(f"env_origin: expected 3 finite numbers, got {env_origin!r}")
    eye = np.asarray(eye, dtype=np.float64)
    if eye.shape != (3,) or not np.all(np.isfinite(eye)):
        raise ValueError(f"eye: expected 3 finite numbers, got {eye!r}")
    buf = np.zeros(BLOCK_SIZE // 4, dtype=np.float32)
    ints = buf.view(np.int32)
    uints = buf.view(np.uint32)

    def put(name, index, values, view=buf):
        o = (OFFSETS[name] + 16 * index) // 4
        view[o : o + len(values)] = values

    if plan.mode == PER_VERTEX_FIELD:
        k = 0
    else:
        k = len(plan.rows)
        for n in range(k):
            put("cp", n, plan.rows[n, 0:3])
            put("cr", n, plan.rows[n, 3:6])
            put("ce", n, plan.rows[n, 6:9])
        for g, grp in enumerate(plan.groups if plan.has_regions else []):
            put("region_a", g, [*grp.center, 0.0 if grp.kind == "euclidean" else 1.0])
            put("region_b", g, [grp.radius, grp.border, float(max(grp.slot, 0)), float(len(grp.members))])
            mask = [0, 0, 0, 0]
            for n in grp.members:
                mask[n // 32] |= 1 << (n % 32)
            put("region_members", g, np.array(mask, dtype=np.uint32), uints)
    put("eye", 0, [*eye, 0.0 if eye_is_direction else 1.0])
    n_groups = len(plan.groups) if plan.has_regions else 0
    put("counts", 0, [k, n_groups, plan.mode, plan.texels_per_vertex], ints)
    put("vlayout", 0, [*plan.offsets, plan.vertex_data.shape[1]], ints)
    put("options", 0, [int(output), int(env), 1 if srgb else 0, 0], ints)
    put("env_origin", 0, [*origin, 1.0 if parallax else 0.0])
    if world_scale is not None and env == ENV_SCENE:
        ws = np.asarray(world_scale, dtype=np.float64)
        if ws.shape != (3,) or not np.all(np.isfinite(ws)):
            raise ValueError(f"world_scale: expected 3 finite numbers, got {world_scale!r}")
        put("world_scale", 0, [*ws, 1.0])
    return buf.tobytes()


def triangle_soup(vertices, normals, triangles) -> dict:
    """Per-corner arrays for the vertex stage: three vertices per triangle with the positions,
    normals and the triangle's three mesh-vertex ids (as float32, exact below 2^24)."""
    v = np.asarray(vertices, dtype=np.float32)
    n = np.asarray(normals, dtype=np.float32)
    t = np.asarray(triangles)
    if v.ndim != 2 or v.shape[1] != 3 or n.shape != v.shape:
        raise ValueError(f"vertices and normals: expected two (V, 3) arrays, got {v.shape} and {n.shape}")
    if t.ndim != 2 or t.shape[1] != 3 or t.dtype.kind not in "iu":
        raise ValueError(f"triangles: expected (T, 3) integer vertex indices, got {t.shape} {t.dtype}")
    if len(t) and (t.min() < 0 or t.max() >= len(v)):
        raise ValueError(f"triangles: vertex index out of range 0..{len(v) - 1}")
    flat = t.reshape(-1)
    ids = np.repeat(t.astype(np.float32), 3, axis=0)
    return {"rk_position": v[flat], "rk_normal": n[flat], "rk_vertex_ids": ids}
