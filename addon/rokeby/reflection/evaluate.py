"""Evaluation of Rokeby mirrors: scene → arrays → rokeby_native → one mesh attribute.

For each mirror the evaluator gathers, as numpy arrays, the evaluated mesh in world space, one
constraint row [p, r, e] per constraint (p: the red handle projected onto the surface, r: the
physical reflection of the ray from the constraint's generating eye, e: towards the green handle),
and the region weights. It then computes the rotation field R(q) (paper eq. 5 and 7) per vertex
and writes it as the rotation vector (axis × angle) point attribute ``rokeby_rotation`` of the
mirror's mesh with a single ``foreach_set``.

Refraction constraints (``kind == 'REFRACTION'``, paper §7.1) give a second, independent field from
rows [p, t, e_t]: t = refract(view, N, 1/η) the physical transmitted direction at p from the
generating eye (η: the mirror's ``ior``), e_t towards the green handle. It uses the same distances,
regions and caches and is written as ``rokeby_refraction``; the attribute is removed while the
mirror has no usable refraction constraint. Each field is recomputed only when its own rows change.

Dirty tracking: the inputs of a mirror are condensed into a fingerprint (handle positions, view
eyes, region settings, the mirror's transform and, when Blender reports that its geometry changed
or the frame changed, its evaluated vertex positions). When the fingerprint is unchanged nothing is
recomputed; ``stats()`` counts both cases. Geodesic distances are cached per constraint surface
point, and the geodesic solver (with its factorisation) per mesh, so a handle move costs one solve
for the handle that moved. While a red handle is dragged in a window (``interactive``), that solve
is replaced by a fast preview (DRAG_UPDATE, else DRAG_METHOD; said in the report); the mirror's own method follows
when the drag ends, and before any render or save (rokeby.reflection.handlers), so only the accurate field is
ever rendered or saved.

Shared meshes (Alt+D copies, Ctrl+L ▸ Link Object Data): a mesh used by more than one object
holds no field. Each mirror using it writes its field to a carrier of its own ("Rokeby field:
<mirror>", owned by that mirror) that its "Rokeby field" modifier copies onto its evaluated mesh,
so one mirror's edit never overwrites another's and removing one never deletes another's
(``shares_mesh``, ``ensure_carrier``). Copies of a mirror get handles of their own
(rokeby.reflection.duplicates).

Nothing here raises into Blender's handlers: a mirror that cannot be evaluated gets an ERROR
report (shown in the sidebar) and keeps its previous attribute values; every other mirror still
evaluates. Values are checked to be finite before they are written.
"""

from __future__ import annotations

import hashlib
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..core import native, vecmath, words
from ..core import schema
from .duplicates import shrinkwrap_target  # noqa: F401 - the handles' Shrinkwrap (duplicates: the copies' rule)
from .field_attributes import _has_attribute, _has_render_attribute, remove_attribute, write_attribute, write_render_attribute
from .field_carriers import carrier_of, ensure_carrier, remove_carrier, strip_field
from .freeform_regions import sync_freeform_regions
from .mirror_surface import _finite_matrix, _Geometry, project_to_surface, read_geometry, shares_mesh
from .unreached_pieces import _unreached_pieces, unreached_fallback

ATTRIBUTE = schema.ROTATION_ATTRIBUTE
# What final renders read (rokeby.reflection.render.shading): the field's view-independent parts per vertex (per
# face corner where a polygon's quaternions straddle the antipodal seam),
# the region rotation R as a unit quaternion (x, y, z in RENDER_ATTRIBUTE; w and the region weight
# a in RENDER_ATTRIBUTE_WA as (w, a, 0)). The render nodes form eq. 7's R_a r per shading point for
# the render camera's (or the frozen eye's) own r, as the per-pixel preview does. The corners of
# each polygon are kept in one hemisphere of the quaternion sphere, so interpolation across a face
# never crosses the antipodal seam that rotation vectors have at half turns.
RENDER_ATTRIBUTE = schema.RENDER_ATTRIBUTE
RENDER_ATTRIBUTE_WA = schema.RENDER_ATTRIBUTE_WA
# The render/preview agreement the status promises (degrees, 99th percentile at triangle centres).
AGREEMENT_DEGREES = 1.0
# A camera and a constraint's generating eye that see its target this far apart are reported.
EYE_MISMATCH_DEGREES = 3.0
# A larger share of the visible surface reflecting below itself is reported.
FOLDED_SHARE = 0.05
# While the artist drags, the estimate runs at most this often (seconds), and once after.
ESTIMATE_INTERVAL = 0.4
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
# At most this many triangles are sampled for the interpolation-error estimate.
AGREEMENT_SAMPLES = 4000
# The second field, from refraction constraints [p, t, e_t] (present only while the mirror has some).
REFRACTION_ATTRIBUTE = schema.REFRACTION_ATTRIBUTE
# A red handle farther than this fraction of the mirror's size from its surface is reported.
OFF_SURFACE_TOLERANCE = 1e-3


from ..core.errors import RokebyError  # noqa: E402


@dataclass
class MirrorReport:
    """What the last evaluation of one mirror did: shown in the sidebar, returned by the API."""

    mirror: str
    status: str = "OK"  # OK | WARNING | ERROR | DISABLED
    messages: list = field(default_factory=list)
    recomputed: bool = False
    constraints_used: int = 0
    vertices: int = 0
    field_mesh: str = "evaluated"  # evaluated | base
    python_ms: float = 0.0
    native_ms: float = 0.0
    # The eye the render field is evaluated for: "camera", "frozen" or "none" (view-independent).
    eye: str = "none"
    # What F12 shows: filled in by rokeby.reflection.render.rendering (True: the edit renders; False: why not).
    renders: "bool | None" = None
    render_note: str = ""
    # Estimated render-vs-preview difference between vertices, degrees: (99th percentile, max).
    interpolation_error: "tuple | None" = None
    # A free-form region's reader modifier was (re)made or repointed: the weights are read at the
    # next evaluation of the mesh; until then the previous field stays (the status says why).
    pending: bool = False
    # Geodesic distances: (pieces of the mesh no constraint reaches over the surface, pieces).
    unreached_pieces: "tuple | None" = None
    # The shown field is a drag preview: the moved constraints' distances are DRAG_UPDATE's or
    # DRAG_METHOD's; the mirror's own method replaces them when the drag ends (renders and saves
    # never see it).
    drag_preview: bool = False

    # Messages that do not change the status (see note()).
    notes: list = field(default_factory=list)

    def note(self, text: str):
        """A message that does not change the status (a documented rule at work, not a problem)."""
        self.messages.append(text)
        self.notes.append(text)

    def warn(self, text: str):
        self.messages.append(text)
        if self.status == "OK":
            self.status = "WARNING"

    def summary(self) -> str:
        head = {"OK": "ok", "WARNING": "warning", "ERROR": "error", "DISABLED": "disabled"}[self.status]
        return f"{self.mirror}: {head}" + (": " + "; ".join(self.messages) if self.messages else "")


class _State:
    """Runtime state of one mirror (not saved: rebuilt after a reload)."""

    def __init__(self):
        self.fingerprint: bytes | None = None
        self.geometry: _Geometry | None = None
        self.geometry_version = 0
        self.solver = None
        self.solver_version = -1
        self.distance_cache: dict = {}
        self.region_cache: dict = {}
        self.report: MirrorReport | None = None
        self.rotations: np.ndarray | None = None
        # What the render nodes read, per vertex of the field mesh: (parts (V, 6), ramp form).
        self.view_parts: tuple | None = None
        self.refractions: np.ndarray | None = None
        self.field_fingerprints: dict = {}
        # What the reflection field was last computed from (rows, distances or None, regions),
        # for the viewport preview, which evaluates the same field per pixel (rokeby.reflection.viewport.draw).
        self.field_inputs: tuple | None = None
        # What the interpolation-error estimate found (kept with the report while nothing changes),
        # when it last ran, and what a deferred one will estimate (None: nothing pending).
        self.field_notes: list = []
        self.estimate_time = -1e9
        self.estimate_args = None
        self.corner_topology = None
        # Geodesic metric: (geometry version, piece label per vertex), and the status line about
        # pieces no constraint reaches (kept with the report while nothing changes).
        self.pieces = None
        self.reach_note: "str | None" = None
        # What the mirror's own mesh data held when api.evaluate last looked (mesh_fingerprint).
        self.mesh_fingerprint: bytes | None = None
        # The stored fields used drag-time distances (a preview) for moved constraints; the
        # next non-interactive evaluation recomputes them with the mirror's method. When the
        # last interactive evaluation ran (perf_counter), for the end-of-drag timer.
        self.preview = False
        self.interactive_time = -1e9
        # (geometry version, method) of the last distances computed all by the mirror's method:
        # an interactive update after that is a handle being moved (see _geodesic_distances).
        self.distances_ready = None
        # Per constraint point (in query order), the last accurate (point, distance row): what a
        # drag preview updates (DRAG_UPDATE).
        self.anchors: list = []


_STATE: dict[int, _State] = {}
_DIRTY: set[int] = set()
_STATS = {"checks": 0, "recomputations": 0, "skipped": 0, "errors": 0}


def stats() -> dict:
    """Counters since the last reset: checks (mirror evaluations asked for), recomputations
    (fields actually computed and written), skipped (nothing had changed), errors."""
    return dict(_STATS)


def reset_stats():
    for k in _STATS:
        _STATS[k] = 0


def reset():
    """Forget all runtime state (after loading a file); the next update recomputes everything."""
    _STATE.clear()
    _DIRTY.clear()


def mark_dirty(obj):
    """Ask for a re-read of this mirror's geometry at the next update (property callbacks)."""
    try:
        _DIRTY.add(obj.session_uid)
    except (AttributeError, ReferenceError):
        pass
    from . import pointers  # noqa: PLC0415

    pointers.pointers_changed()


def report_of(obj) -> MirrorReport | None:
    st = _STATE.get(obj.session_uid)
    return st.report if st else None


def state_of(obj) -> "_State | None":
    """The evaluator's runtime state of a mirror (geometry, field inputs, report), or None."""
    try:
        return _STATE.get(obj.session_uid)
    except (AttributeError, ReferenceError):
        return None


HEAT_SEAMS_STATUS = "Heat crosses open seams"


def heat_seams(obj) -> int:
    """How many boundary edges of the mirror's last read mesh lie on unwelded seams, when it
    measures geodesics with the heat method (0 otherwise, or before its first evaluation). Heat's
    distances cross such seams (22 % off on the Utah teapot, docs/geodesics.md), so the sidebar
    marks heat unsuitable there; the method's tooltip says why and what to use instead."""
    s = obj.rokeby
    st = state_of(obj)
    if s.metric != "GEODESIC" or s.geodesic_method != "HEAT" or st is None or st.geometry is None:
        return 0
    return st.geometry.open_seams


def rotations_of(obj) -> np.ndarray | None:
    """The last computed field of a mirror as (V, 4) quaternions (x, y, z, w)."""
    st = _STATE.get(obj.session_uid)
    return quaternions(st.rotations) if st is not None and st.rotations is not None else None


def refractions_of(obj) -> np.ndarray | None:
    """The last computed refraction field of a mirror as (V, 4) quaternions (None: no refraction
    constraint)."""
    st = _STATE.get(obj.session_uid)
    return quaternions(st.refractions) if st is not None and st.refractions is not None else None


def quaternions(rotvec: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors → (N, 4) unit quaternions (x, y, z, w), w >= 0."""
    v = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(v, axis=1)
    half = 0.5 * angle
    scale = np.where(angle > 1e-12, np.sin(half) / np.maximum(angle, 1e-300), 0.5)
    return np.concatenate([v * scale[:, None], np.cos(half)[:, None]], axis=1).astype(np.float32)


class _NativeTimer:
    def __init__(self):
        self.seconds = 0.0

    def __call__(self, fn, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - t0


# --- reading the scene ---------------------------------------------------------------------------


def object_in_scene(obj, scene) -> bool:
    """Whether ``obj`` (a handle or region centre) is still there: not removed, and linked into
    some collection. Deleting with X only unlinks an object that a constraint's pointer still
    uses, so an object whose only users are pointers counts as deleted. Costs no scan of
    ``scene.objects`` (rokeby.reflection.registry); ``scene`` is kept for callers."""
    if obj is None:
        return False
    try:
        users = obj.users - int(obj.use_fake_user)
    except ReferenceError:
        return False
    return users > _pointer_users(obj)


def _pointer_users(obj) -> int:
    """How many of the users of ``obj`` are the add-on's own pointers (constraints, regions, a
    map origin) of the mirrors in the file."""
    from . import pointers  # noqa: PLC0415

    return pointers.pointer_counts().get(obj.session_uid, 0)


def reflect(incident, normal):
    return vecmath.reflect(incident, normal)


def refract(incident, normal, eta):
    """Snell refraction of unit ``incident`` (pointing at the surface, against unit ``normal``)
    with eta = η_outside / η_inside; None on total internal reflection (the one rule:
    rokeby.core.vecmath.total_internal_reflection)."""
    if vecmath.total_internal_reflection(incident, normal, eta):
        return None
    return vecmath.refract(incident, normal, eta)


def valid_ior(value) -> float:
    """The IOR as a float, or a RokebyError saying why it cannot be used."""
    ior = float(value)
    if not (np.isfinite(ior) and ior > 0.0):
        raise RokebyError(f"IOR must be finite and > 0, got {ior}")
    return ior


def check_mirror(obj):
    """A RokebyError unless ``obj`` is a local mesh object with faces (one a mirror can be)."""
    if obj is None:
        raise RokebyError("mirror: is None")
    try:
        name, kind = obj.name, obj.type
    except ReferenceError:
        raise RokebyError("mirror: the object was deleted") from None
    if kind != "MESH":
        raise RokebyError(f"mirror: '{name}' is {words.kind(kind)}, not a mesh")
    if len(obj.data.polygons) == 0:
        raise RokebyError(f"mirror: '{name}' has no faces")
    if obj.library is not None or obj.data.library is not None:
        raise RokebyError(f"mirror: '{name}' is linked from a library; make it local (or a library override with local mesh data)")
    return obj


def require_mirror(obj):
    """``obj`` if it is a Rokeby mirror (check_mirror and is_mirror), else a RokebyError."""
    check_mirror(obj)
    if not obj.rokeby.is_mirror:
        raise RokebyError(f"mirror: '{obj.name}' is not a Rokeby mirror: make it one with Add Mirror (Object ▸ Rokeby ▸ Add Mirror)")
    return obj


# --- one mirror ----------------------------------------------------------------------------------


def render_eye(obj, scene, depsgraph, size: float = 1.0):
    """The eye final renders see ``obj`` from, as (point or None, kind): the frozen eye of a
    frozen mirror ("frozen"), else the scene camera ("camera"; an orthographic camera's eye is
    placed far behind it along its view axis), else (None, "none")."""
    s = obj.rokeby
    if s.freeze:
        eye = np.array(s.freeze_eye, dtype=np.float64)
        if not np.all(np.isfinite(eye)):
            raise RokebyError(f"mirror '{obj.name}': its frozen eye is not finite")
        return eye, "frozen"
    cam = scene.camera
    if cam is None:
        return None, "none"
    m = _finite_matrix(cam.evaluated_get(depsgraph).matrix_world, f"camera '{cam.name}'")
    eye = m[:3, 3].copy()
    if cam.type == "CAMERA" and cam.data.type == "ORTHO":
        back = m[:3, 2] / max(np.linalg.norm(m[:3, 2]), 1e-300)  # a camera looks along its local −Z
        eye = eye + back * 1e4 * max(size, float(cam.data.ortho_scale), 1e-6)
    return eye, "camera"


def _angle_deg(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300), -1.0, 1.0))))


def _constraint_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, kind="REFLECTION", ior=None, eye_now=None):
    """Constraint rows [p, r, e] (``kind`` REFLECTION) or [p, t, e_t] (REFRACTION, with the
    mirror's ``ior``) and their surface points; bad constraints are reported and skipped.

    r is the physical direction seen from ``eye_now`` (the render eye) when the mirror's
    generating eye is the scene camera, else from each constraint's stored eye; in that case a
    render eye that sees the target more than EYE_MISMATCH_DEGREES away is reported."""
    rows, points = [], []
    refraction = kind == "REFRACTION"
    from_camera = getattr(obj.rokeby, "eye_source", "CREATION") == "CAMERA" and eye_now is not None
    for k, c in enumerate(obj.rokeby.constraints):
        label = f"constraint {k + 1} ('{c.name}')" if c.name else f"constraint {k + 1}"
        if not c.enabled or getattr(c, "kind", "REFLECTION") != kind:
            continue
        try:
            red, green = c.surface_handle, c.target_handle
            if not object_in_scene(red, scene):
                raise RokebyError(f"{label}: its red (surface) handle was deleted")
            if not object_in_scene(green, scene):
                raise RokebyError(f"{label}: its green ({'transmitted' if refraction else 'reflected'}) handle was deleted")
            if getattr(c, "light_name", "") and green.parent is None:
                report.warn(f"{label}: the light '{c.light_name}' its green handle followed was deleted or unparented; the handle stays where it is")
            kept_on = shrinkwrap_target(red)
            if kept_on is not None and kept_on != obj:
                report.warn(f"{label}: red handle '{red.name}' is kept on '{kept_on.name}' (its Shrinkwrap), not on this mirror; "
                            "give this mirror its own constraint, or set the Shrinkwrap's target to it")
            red_m = _finite_matrix(red.evaluated_get(depsgraph).matrix_world, f"{label}: red handle '{red.name}'")
            green_m = _finite_matrix(green.evaluated_get(depsgraph).matrix_world, f"{label}: green handle '{green.name}'")
            eye = np.array(eye_now if from_camera else c.eye, dtype=np.float64)
            if not np.all(np.isfinite(eye)):
                raise RokebyError(f"{label}: its generating eye is not finite")
            sp = project_to_surface(obj, depsgraph, geo, red_m[:3, 3], mirror_matrix)
            if sp.offset > OFF_SURFACE_TOLERANCE * max(geo.size, 1e-12):
                parent = red.parent
                why = f" (it is parented to '{parent.name}')" if parent is not None and parent != obj else ""
                report.warn(f"{label}: red handle '{red.name}' is {sp.offset:.3g} off the surface{why}; the nearest surface point is used")
            view = sp.point - eye
            if not np.linalg.norm(view) > 1e-12 * max(geo.size, 1e-30):
                raise RokebyError(f"{label}: the generating eye lies on the surface point")
            if refraction:
                r = _transmitted(view / np.linalg.norm(view), sp.normal, ior, label)
            else:
                r = reflect(view / np.linalg.norm(view), sp.normal)
            to_green = green_m[:3, 3] - sp.point
            if not np.linalg.norm(to_green) > 1e-9 * max(geo.size, 1e-30):
                raise RokebyError(f"{label}: the green handle sits on the surface point, so it gives no direction")
            e = to_green / np.linalg.norm(to_green)
            if not refraction and e @ sp.normal < 0.0:
                if getattr(c, "light_name", ""):
                    report.warn(f"{label}: no light reaches the red handle (the light is {np.degrees(np.arcsin(min(1.0, -e @ sp.normal))):.0f}° behind the surface there), so no highlight shows; move the red handle to the lit side")
                else:
                    report.warn(f"{label}: the green handle is {np.degrees(np.arcsin(min(1.0, -e @ sp.normal))):.0f}° behind the surface at the red handle; renders fold the reflection back above it, so it cannot show that point")
            if not from_camera and eye_now is not None and not refraction:
                view_now = sp.point - eye_now
                if np.linalg.norm(view_now) > 0.0:
                    off = _angle_deg(reflect(view_now / np.linalg.norm(view_now), sp.normal), r)
                    if off > EYE_MISMATCH_DEGREES:
                        report.warn(f"{label}: from the render eye its reflection lands {off:.1f}° away from the green handle (it was made from another view); set Generating Eye to Scene Camera, or render from its view (Return to View)")
            rows.append(np.concatenate([sp.point, r / np.linalg.norm(r), e]))
            points.append(sp)
        except RokebyError as exc:
            report.warn(str(exc))
    return (np.array(rows, dtype=np.float32).reshape(-1, 9), points)


SHRINKWRAP_NAME = schema.SHRINKWRAP_NAME


def _transmitted(incident, normal, ior, label):
    """Physical transmitted direction t at a refraction constraint, or a RokebyError saying why
    there is none."""
    if incident @ normal > 0.0:
        raise RokebyError(f"{label}: the generating eye sees the back of the surface at the red handle; refraction constraints edit where rays enter (the side the normals face)")
    t = refract(incident, normal, 1.0 / ior)
    if t is None:
        raise RokebyError(f"{label}: total internal reflection at the red handle (IOR {ior:g} < 1 at this angle), so there is no transmitted ray to edit")
    return t


def _region_inputs(obj, scene, depsgraph, geo, mirror_matrix, report):
    """Region specs as plain tuples (for the fingerprint) — the weights are made later."""
    specs = []
    for k, rg in enumerate(obj.rokeby.regions):
        label = f"region {k + 1} ('{rg.name}')" if rg.name else f"region {k + 1}"
        if not rg.enabled:
            continue
        try:
            radius, border = float(rg.radius), float(rg.border)
            if not (np.isfinite(radius) and np.isfinite(border) and radius >= 0 and border >= 0):
                raise RokebyError(f"{label}: radius and border must be finite and >= 0")
            if rg.kind == "FREEFORM":
                if not rg.vertex_group:
                    raise RokebyError(f"{label}: no vertex group chosen (Regions ▸ Vertex group); the region is left out")
                if obj.vertex_groups.get(rg.vertex_group) is None:
                    raise RokebyError(f"{label}: vertex group '{rg.vertex_group}' was deleted; the region is left out until you choose a group")
                if rg.vertex_group not in geo.region_weights:
                    why = geo.region_problems.get(rg.vertex_group, f"vertex group '{rg.vertex_group}' could not be read")
                    raise RokebyError(f"{label}: {why}; the region is left out")
                specs.append(("FREEFORM", rg.vertex_group, border))
                continue
            if not object_in_scene(rg.center, scene):
                raise RokebyError(f"{label}: its centre empty was deleted")
            cm = _finite_matrix(rg.center.evaluated_get(depsgraph).matrix_world, f"{label}: centre '{rg.center.name}'")
            if rg.kind == "EUCLIDEAN":
                specs.append(("EUCLIDEAN", tuple(cm[:3, 3]), radius, border))
            else:
                sp = project_to_surface(obj, depsgraph, geo, cm[:3, 3], mirror_matrix)
                specs.append(("GEODESIC", sp.triangle, tuple(sp.bary), radius, border))
        except RokebyError as exc:
            report.warn(str(exc))
    return specs


def _fingerprint(obj, geo_version, mirror_matrix, rows, regions, extra=()) -> bytes:
    s = obj.rokeby
    h = hashlib.blake2b(digest_size=20)
    h.update(repr((s.enabled, s.metric, s.geodesic_method, s.polar, geo_version, regions, extra)).encode())
    h.update(np.ascontiguousarray(mirror_matrix).tobytes())
    h.update(np.ascontiguousarray(rows).tobytes())
    return h.digest()


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


def rotate(quats: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Apply unit quaternions (..., 4) as (x, y, z, w) to vectors (..., 3), vectorised."""
    q = np.asarray(quats, dtype=np.float64)
    v = np.asarray(vectors, dtype=np.float64)
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """Every directed edge (i, j) of the triangles, both directions, (6F, 2)."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return np.concatenate([e, e[:, ::-1]])


def extend_rotations_outward(parts: np.ndarray, edges: np.ndarray, rings: int = 2) -> np.ndarray:
    """Vertices where no region acts (a = 0) take R from a neighbour where one does, ``rings``
    edges out (``edges``: ``mesh_edges`` of the triangles). Their weight stays 0, so nothing changes there; but a triangle across a region's
    edge then interpolates the region's rotation, as the preview sees it, instead of blending it
    with the identity (which a weight of a few tenths would turn into a visible error)."""
    out = np.array(parts, dtype=np.float32)
    e = edges
    if len(e) == 0:
        return out
    outside = (out[:, 4] <= 0.0) & (out[:, 5] <= 0.0)
    filled = ~outside
    for _ in range(rings):
        take = outside[e[:, 0]] & filled[e[:, 1]] & ~filled[e[:, 0]]
        if not take.any():
            break
        dst, src = e[take, 0], e[take, 1]
        out[dst, :4] = out[src, :4]
        filled[dst] = True
    return out


def ramp_form(specs) -> bool:
    """Whether the region weight reaches renders as the border ramp u (one Euclidean region with
    a border): see rokeby_core's FieldOutput::ViewBlend."""
    return len(specs) == 1 and specs[0][0] == "EUCLIDEAN" and specs[0][3] > 0.0 and specs[0][2] > 0.0


def _interpolation_error(geo, parts, eye, rows, kwargs, timer, ramp=False):
    """How far the renderer's interpolation of the per-corner field between vertices lands from
    the per-pixel field (what the viewport preview evaluates), in degrees at the centres of the
    triangles that face the eye: (99th percentile, max, samples). The region weights and
    distances are interpolated there as the preview does."""
    tri = geo.triangles
    if len(tri) == 0 or len(rows) == 0:
        return None
    if len(tri) > AGREEMENT_SAMPLES:
        tri = tri[np.linspace(0, len(tri) - 1, AGREEMENT_SAMPLES).astype(np.int64)]
    c = geo.vertices[tri].astype(np.float64).mean(1)
    n = geo.normals[tri].astype(np.float64).sum(1)
    nl = np.linalg.norm(n, axis=1)
    incident = c - eye
    il = np.linalg.norm(incident, axis=1)
    ok = (nl > 1e-6) & (il > 1e-12)
    ok[ok] &= np.einsum("ij,ij->i", n[ok], incident[ok]) < 0.0  # seen from the front
    if not ok.any():
        return None
    tri, c, n, incident = tri[ok], c[ok], n[ok] / nl[ok, None], incident[ok] / il[ok, None]
    q = parts[tri].astype(np.float64)  # (S, 3, 6)
    sign = np.where(np.einsum("sij,sj->si", q[..., :4], q[:, 0, :4]) < 0.0, -1.0, 1.0)
    q[..., :4] *= sign[..., None]
    qi = q.mean(1)  # the renderer's interpolation at the centre: (q, a) averaged
    qi[:, :4] /= np.maximum(np.linalg.norm(qi[:, :4], axis=1, keepdims=True), 1e-300)
    r = incident - 2.0 * np.einsum("ij,ij->i", incident, n)[:, None] * n
    got = np.asarray(timer(native.view_blend, qi.astype(np.float32), r.astype(np.float32), ramp=ramp), dtype=np.float64)
    dkw = {"polar": kwargs["polar"]}
    if kwargs.get("distances") is not None:
        dkw["distances"] = np.ascontiguousarray(np.asarray(kwargs["distances"])[:, tri].mean(2), dtype=np.float32)
    if kwargs.get("regions"):
        regs = []
        for reg in kwargs["regions"]:
            if reg["kind"] == "weights":
                reg = dict(reg, values=np.ascontiguousarray(np.asarray(reg["values"])[tri].mean(1), dtype=np.float32))
            regs.append(reg)
        dkw["regions"] = regs
    want = timer(native.edited_directions, c.astype(np.float32), n.astype(np.float32), tuple(float(x) for x in eye), rows, **dkw)
    want = np.asarray(want, dtype=np.float64)
    cos = np.einsum("ij,ij->i", got, want) / np.maximum(np.linalg.norm(got, axis=1), 1e-300)
    ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    # Where e points below the surface, renders fold it back above (rokeby.reflection.render.shading) while the
    # preview looks it up as it is: those samples are counted apart.
    below = np.einsum("ij,ij->i", want, n) < 0.0
    kept = ang[~below] if (~below).any() else np.zeros(1)
    # Their share of the picture: each triangle weighted by the solid angle it covers from the eye.
    v = geo.vertices[tri].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    seen = area * np.abs(np.einsum("ij,ij->i", n, incident)) / np.maximum(il[ok] ** 2, 1e-300)
    share = float(seen[below].sum() / seen.sum()) if seen.sum() > 0 else 0.0
    return float(np.percentile(kept, 99)), float(kept.max()), int(len(ang)), share


def _estimate(state, args, timer=None):
    """Run the render-vs-preview estimate (``_interpolation_error``) and turn it into the notes
    the report carries; returns the figures."""
    geo, parts, eye, rows, kwargs, ramp = args
    est = _interpolation_error(geo, parts, eye, rows, kwargs, timer or (lambda fn, *a, **k: fn(*a, **k)), ramp)
    notes = []
    if est is not None and est[0] > AGREEMENT_DEGREES:
        notes.append(
            f"the mesh is too coarse for this field: between vertices renders differ from the per-pixel preview by up to {est[1]:.1f}° "
            f"(99th percentile {est[0]:.1f}° over {est[2]:,} triangles); subdivide the mirror's mesh where the reflection changes fast, or widen the region border")
    if est is not None and est[3] > FOLDED_SHARE:
        notes.append(
            f"on {100 * est[3]:.0f}% of the mirror as the render eye sees it the edited reflection points below the surface: renders fold it back "
            "above (no black), the preview shows it unfolded; make that edit smaller or confine it with a region")
    state.field_notes, state.estimate_args = notes, None
    state.estimate_time = time.perf_counter()
    return est


def _defer_estimate(obj, state, args):
    """Estimate once the updates pause (``ESTIMATE_INTERVAL`` after the last one), then refresh
    the mirror's report; a render or an API evaluation estimates at once instead."""
    first = state.estimate_args is None
    state.estimate_args = args
    if not first:
        return
    uid = obj.session_uid

    def later():
        st = _STATE.get(uid)
        if st is None or st.estimate_args is None:
            return None
        if time.perf_counter() - st.estimate_time < ESTIMATE_INTERVAL:
            return ESTIMATE_INTERVAL  # still dragging: look again later
        est = _estimate(st, st.estimate_args)
        rep = st.report
        if rep is not None and rep.status != "ERROR":
            rep.interpolation_error = est
            base = [m for m in rep.messages if not (m.startswith("the mesh is too coarse") or " the edited reflection points below the surface" in m)]
            warned = [m for m in base if m not in rep.notes]
            rep.messages, rep.status = base, ("DISABLED" if rep.status == "DISABLED" else "OK" if not warned else rep.status)
            for msg in st.field_notes:
                rep.warn(msg)
        import bpy  # noqa: PLC0415

        for window in getattr(bpy.context.window_manager, "windows", ()):
            for area in window.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()
        return None

    _schedule(later, ESTIMATE_INTERVAL)


def _preview_note(obj) -> str:
    method = obj.rokeby.geodesic_method.lower()
    return (f"drag preview: the moved handles' geodesic distances are estimated (updated from where the drag started, "
            f"or by {DRAG_METHOD}) until the drag ends, then {method}'s (renders and saved files always use {method})")


def previews(scene=None) -> list:
    """The mirrors (of ``scene``, or any) whose stored field is a drag preview."""
    from . import pointers  # noqa: PLC0415

    out = []
    for ob in (mirrors_of(scene) if scene is not None else pointers.mirrors()):
        st = state_of(ob)
        if st is not None and st.preview:
            out.append(ob)
    return out


def last_interactive_update() -> float:
    """perf_counter() of the latest interactive evaluation of any mirror (-1e9: none)."""
    return max((st.interactive_time for st in _STATE.values()), default=-1e9)


def _schedule(fn, seconds: float):
    """Run ``fn`` from Blender's event loop after ``seconds`` (again after what it returns)."""
    import bpy  # noqa: PLC0415

    bpy.app.timers.register(fn, first_interval=seconds)


def evaluate_mirror(obj, scene, depsgraph, *, force=False, reread_geometry=False, interactive=False) -> MirrorReport:
    """Evaluate one mirror if its inputs changed (or ``force``); never raises. ``interactive``
    (the depsgraph handler, while the artist drags): the render-vs-preview estimate runs at most
    every ESTIMATE_INTERVAL seconds, and once more when the updates pause; a moved red handle's
    geodesic distances come from DRAG_METHOD (a drag preview, ``report.drag_preview``). Any
    evaluation that is not interactive recomputes a preview with the mirror's own method."""
    t0 = time.perf_counter()
    timer = _NativeTimer()
    _STATS["checks"] += 1
    name = getattr(obj, "name", "?")
    report = MirrorReport(name)
    uid = obj.session_uid
    state = _STATE.setdefault(uid, _State())
    try:
        if obj.type != "MESH":
            raise RokebyError(f"mirror '{name}' is {words.kind(obj.type)}, not a mesh")
        if obj.library is not None:
            # Read-only: its field cannot follow this scene's camera or edits (no carrier, no
            # attribute can be written to it); a library override is a mirror of its own.
            raise RokebyError(f"mirror '{name}' is linked from library '{obj.library.filepath}' and cannot store the field: "
                              "make it local or a library override")
        settings = obj.rokeby
        if obj.mode == "EDIT":
            # Edit Mode writes its own mesh back on exit; the field follows when it does.
            report.warn("paused while the mirror is in Edit Mode")
            _DIRTY.add(uid)
            state.report = report
            return report
        changes = sync_freeform_regions(obj)
        if changes:
            # The reader's weights are in the next evaluation of the mesh; the ones at hand are
            # stale, so nothing is computed now and the previous field stays, as the status says.
            _DIRTY.add(uid)
            state.fingerprint = None
            for msg in changes:
                report.warn(f"{msg}; the field follows at the next update (until then renders show the previous one)")
            report.pending = True
            state.report = report
            return report
        mirror_matrix = _finite_matrix(obj.evaluated_get(depsgraph).matrix_world, f"mirror '{name}'")
        groups = sorted({rg.vertex_group for rg in settings.regions if rg.enabled and rg.kind == "FREEFORM" and rg.vertex_group})
        geo = state.geometry
        if (geo is None or reread_geometry or force or uid in _DIRTY or geo.shared != shares_mesh(obj)
                or not np.array_equal(getattr(geo, "matrix", None), mirror_matrix)):
            _DIRTY.discard(uid)
            try:
                new = read_geometry(obj, depsgraph, mirror_matrix, groups)
            except RokebyError:
                state.geometry = None
                raise
            new.matrix = mirror_matrix
            if not new.same_positions(geo):
                state.geometry_version += 1
                state.distance_cache.clear()
                state.region_cache.clear()
            else:
                new.bvh, new._poly_start, new.edges = geo.bvh, geo._poly_start, geo.edges
                new.uses, new.max_edge = geo.uses, geo.max_edge
            if new.bvh is None and geo is not None and geo.local is not None \
                    and np.array_equal(geo.local, new.local) and np.array_equal(geo.triangles, new.triangles):
                # moved, not reshaped: the object-space BVH (or the count towards one) still holds
                new.bvh, new.uses, new.max_edge = geo.bvh, geo.uses, geo.max_edge
            state.geometry = geo = new
        geo.uses += 1
        report.vertices = len(geo.vertices)
        report.field_mesh = geo.source
        eye_now, report.eye = render_eye(obj, scene, depsgraph, geo.size)
        if settings.freeze and not getattr(settings, "freeze_eye_set", True):
            report.warn("frozen, but no eye was stored (it had no constraint and the scene no camera): renders reflect from the frozen eye "
                        f"{tuple(round(float(x), 3) for x in settings.freeze_eye)}; unfreeze and freeze again, or set the frozen eye")
        t_rows, t_points, ior = np.zeros((0, 9), np.float32), [], None
        if not settings.enabled:
            rows, points, specs = np.zeros((0, 9), np.float32), [], []
        else:
            rows, points = _constraint_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, eye_now=eye_now)
            specs = _region_inputs(obj, scene, depsgraph, geo, mirror_matrix, report)
            if eye_now is None and len(settings.constraints):
                report.warn("the scene has no camera, so the render eye is unknown: constraints use the views they were made from and region borders blend view-independently; set a scene camera (or freeze the mirror)")
            if any(c.enabled and getattr(c, "kind", "REFLECTION") == "REFRACTION" for c in settings.constraints):
                try:
                    ior = valid_ior(settings.ior)
                except RokebyError as exc:
                    report.warn(f"mirror '{name}': {exc}; its refraction constraints are skipped")
                else:
                    t_rows, t_points = _constraint_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, "REFRACTION", ior, eye_now=eye_now)
        # The stored field does not depend on the eye (renders blend eq. 7 per pixel); the rows
        # carry it when constraints are seen from the camera.
        fp_reflection = _fingerprint(obj, state.geometry_version, mirror_matrix, rows, specs)
        fp_refraction = _fingerprint(obj, state.geometry_version, mirror_matrix, t_rows, specs, (ior,))
        fp = fp_reflection + fp_refraction
        # The drag has ended (or a render, a save or the API asks): fields shown with drag-time
        # distances are recomputed with the mirror's own method, whatever else changed.
        settle = state.preview and not interactive
        if interactive:
            state.interactive_time = time.perf_counter()
        if fp == state.fingerprint and not force and not settle and state.report is not None and state.report.status != "ERROR":
            _STATS["skipped"] += 1
            if geo.shared:
                strip_field(obj.data)  # e.g. left by this mirror before its mesh was linked to another object
            kept = state.report
            kept.recomputed = False
            # Same field, but the warnings describe the scene as it is now (e.g. a deleted light
            # whose highlight handle stayed where it was).
            kept.messages, kept.status, kept.notes = list(report.messages), report.status, list(report.notes)
            if state.reach_note is not None:
                kept.note(state.reach_note)
            if state.preview:
                kept.note(_preview_note(obj))
            for msg in state.field_notes:
                kept.warn(msg)
            kept.eye = report.eye
            return kept
        report.constraints_used = len(rows) + len(t_rows)
        method = {"HEAT": "heat", "DIJKSTRA": "dijkstra", "EXACT": "exact", "GRAPH": "graph", "DENSE_GRAPH": "dense_graph"}[settings.geodesic_method]
        polar = "exact" if settings.polar == "EXACT" else "fast"
        distances = None
        previewed = False
        if len(rows) + len(t_rows) and settings.metric == "GEODESIC":
            # One query for both kinds: the per-point cache keeps every current constraint's solve.
            distances, previewed = _geodesic_distances(state, geo, points + t_points, method, timer, drag=interactive)
            if np.all(np.isinf(distances)):
                report.warn("no constraint reaches this mesh over its surface; it takes the field of straight-line distances")
            report.unreached_pieces = _unreached_pieces(state, geo, distances)
        state.reach_note = None
        if report.unreached_pieces is not None:
            n, total = report.unreached_pieces
            state.reach_note = (
                f"{n} of {total} pieces of the mesh have no constraint on them: geodesic distances do not cross gaps, "
                "so there the constraints blend by straight-line distance")
            report.note(state.reach_note)
        old = state.field_fingerprints
        transfer = geo.source == "transfer"
        target = carrier_of(obj) if transfer else obj
        stored = target is not None and _has_attribute(target, ATTRIBUTE) and _has_render_attribute(target)
        if force or settle or old.get(ATTRIBUTE) != fp_reflection or not stored:
            kwargs = {"polar": polar}
            if specs:
                kwargs["regions"] = _regions_for_native(state, geo, specs, points, method, timer)
            if distances is not None and len(rows):
                kwargs["distances"] = unreached_fallback(distances[: len(rows)], rows, geo.vertices, kwargs.get("regions"))
            # One field for the preview and the render: the parts of eq. 7 that do not depend on
            # the view, blended towards r rᵀ per shading point by the render nodes.
            parts = timer(native.rotation_field, geo.vertices, rows, output="view_blend", **kwargs)
            if specs:
                if geo.edges is None:
                    geo.edges = mesh_edges(geo.triangles)
                parts = extend_rotations_outward(parts, geo.edges)
            # The view-independent form for scripts and tools (eq. 7 towards I).
            rv = timer(native.view_blend_rotation_vectors, parts)
            ramp = ramp_form(specs)
            if transfer:
                target = ensure_carrier(obj, depsgraph)
            else:
                remove_carrier(obj)
            write_attribute(target, rv, update=False)
            write_render_attribute(target, parts, state, ramp=ramp, timer=timer)
            state.view_parts = (parts, ramp)
            state.rotations = rv
            state.field_inputs = (rows, kwargs.get("distances"), kwargs.get("regions") or [])
            report.interpolation_error = None
            if eye_now is None or not len(rows):
                state.field_notes, state.estimate_args = [], None
            else:
                args = (geo, parts, eye_now, rows, kwargs, ramp)
                if interactive and time.perf_counter() - state.estimate_time < ESTIMATE_INTERVAL:
                    # In the middle of a drag: the last estimate stands, a new one follows when
                    # the updates pause (a timer), so each drag step pays only for the field.
                    report.interpolation_error = state.report.interpolation_error if state.report is not None else None
                    _defer_estimate(obj, state, args)
                else:
                    report.interpolation_error = _estimate(state, args, timer)
            for msg in state.field_notes:
                report.warn(msg)
            old[ATTRIBUTE] = fp_reflection
        elif state.report is not None:
            report.interpolation_error = state.report.interpolation_error
            for msg in state.field_notes:
                report.warn(msg)
        # The refraction field goes where the reflection field went (the mirror's own carrier when
        # the mesh is shared or its vertex count changes).
        target = (carrier_of(obj) or ensure_carrier(obj, depsgraph)) if transfer else obj
        if not len(t_rows):
            old.pop(REFRACTION_ATTRIBUTE, None)
            state.refractions = None
            remove_attribute(target, REFRACTION_ATTRIBUTE)
        elif force or settle or old.get(REFRACTION_ATTRIBUTE) != fp_refraction or not _has_attribute(target, REFRACTION_ATTRIBUTE):
            kwargs = {"polar": polar}
            if specs:
                kwargs["regions"] = _regions_for_native(state, geo, specs, t_points, method, timer)
            if distances is not None:
                kwargs["distances"] = unreached_fallback(distances[len(rows):], t_rows, geo.vertices, kwargs.get("regions"))
            tv = timer(native.rotation_field, geo.vertices, t_rows, output="rotation_vector", **kwargs)
            write_attribute(target, tv, REFRACTION_ATTRIBUTE)
            state.refractions = tv
            old[REFRACTION_ATTRIBUTE] = fp_refraction
        if transfer and geo.shared:
            # Every object using a shared mesh carries its own field: none stays in the mesh,
            # where it would render on objects that are not (or no longer) this mirror.
            strip_field(obj.data)
        state.fingerprint = fp
        state.preview = report.drag_preview = previewed
        if previewed:
            report.note(_preview_note(obj))
        report.recomputed = True
        if not settings.enabled:
            report.status = "DISABLED"
        _STATS["recomputations"] += 1
    except RokebyError as exc:
        report.status = "ERROR"
        report.messages.append(str(exc))
        state.fingerprint = None
        _STATS["errors"] += 1
    except native.NativeUnavailable as exc:
        report.status = "ERROR"
        report.messages.append(str(exc))
        _STATS["errors"] += 1
    except (ValueError, TypeError, RuntimeError, ReferenceError) as exc:
        report.status = "ERROR"
        report.messages.append(f"{type(exc).__name__}: {exc}")
        state.fingerprint = None
        _STATS["errors"] += 1
    report.native_ms = timer.seconds * 1e3
    report.python_ms = (time.perf_counter() - t0) * 1e3 - report.native_ms
    state.report = report
    return report


def mesh_fingerprint(obj) -> bytes:
    """A cheap digest of ``obj``'s own mesh data (positions, corners, polygons, shape keys): a
    script that edits them (``foreach_set``, ``bmesh.to_mesh``) tags nothing that the API sees."""
    me = obj.data
    h = hashlib.blake2b(digest_size=16)
    nv, nl, npoly = len(me.vertices), len(me.loops), len(me.polygons)
    h.update(repr((me.session_uid, nv, nl, npoly)).encode())
    co = np.empty(nv * 3, np.float32)
    me.vertices.foreach_get("co", co)
    h.update(co.tobytes())
    idx = np.empty(nl, np.int32)
    me.loops.foreach_get("vertex_index", idx)
    h.update(idx.tobytes())
    start = np.empty(npoly, np.int32)
    me.polygons.foreach_get("loop_start", start)
    h.update(start.tobytes())
    keys = me.shape_keys
    if keys is not None:
        for kb in keys.key_blocks:
            kco = np.empty(len(kb.data) * 3, np.float32)
            kb.data.foreach_get("co", kco)
            h.update(kb.name.encode() + kco.tobytes())
    return h.digest()


def edited_meshes(scene) -> set:
    """Mirrors of ``scene`` whose mesh data changed since the last call (or were never seen):
    their meshes are tagged so the next depsgraph update re-evaluates them from the edited data,
    and the caller re-reads their geometry. For ``rokeby.api.evaluate``, which runs with the
    handlers suspended and so never sees Blender's geometry updates."""
    out = set()
    for ob in mirrors_of(scene):
        try:
            if ob.type != "MESH" or ob.mode == "EDIT" or ob.library is not None or ob.data.library is not None:
                continue
            fp = mesh_fingerprint(ob)
        except (AttributeError, ReferenceError):
            continue
        state = _STATE.setdefault(ob.session_uid, _State())
        if state.mesh_fingerprint != fp:
            ob.data.update_tag()
            state.mesh_fingerprint = fp
            out.add(ob)
    return out


def mirrors_of(scene) -> list:
    """The mirrors linked into ``scene``, from the add-on's registry (no scan of its objects)."""
    from . import pointers  # noqa: PLC0415

    return pointers.mirrors(scene)


def evaluate_scene(scene, depsgraph, *, force=False, geometry_changed=None, all_geometry=False, interactive=False, settle=True) -> dict:
    """Evaluate every mirror of ``scene``; ``geometry_changed``: original IDs Blender reported
    with new geometry (their meshes are re-read), ``all_geometry``: re-read every mirror's mesh
    (a frame change can deform any of them); ``interactive``: see ``evaluate_mirror``;
    ``settle``: when a mirror is pending (a free-form region's reader modifier was remade or
    repointed), update ``depsgraph`` and evaluate it again at once, so the status never describes
    weights older than the painting. Blender would re-evaluate the tagged mesh after the
    depsgraph handler anyway, but without calling the handlers again, so the field would wait
    for the next edit."""
    out = {}
    changed = geometry_changed or set()
    mirrors = mirrors_of(scene)
    from . import duplicates  # noqa: PLC0415

    # Shift+D / Alt+D copies get handles of their own before anything reads them.
    if duplicates.separate_copies(mirrors):
        depsgraph.update()  # the new handles are evaluated (their Shrinkwrap, their parent)
    local_names = {ob.name for ob in mirrors if ob.library is None}
    for ob in mirrors:
        reread = all_geometry or ob in changed or (ob.type == "MESH" and ob.data in changed)
        rep = evaluate_mirror(ob, scene, depsgraph, force=force, reread_geometry=reread, interactive=interactive)
        # A mirror linked from a library shares its name with its library override, which keeps
        # the plain name; the linked one is listed with its library's file name.
        key = ob.name if ob.library is None or ob.name not in local_names else f"{ob.name} ({os.path.basename(ob.library.filepath)})"
        out[key] = rep
    pending = [name for name, rep in out.items() if rep.pending]
    if settle and pending:
        depsgraph.update()  # our own handlers are guarded against re-entrance (handlers._busy)
        by_name = {ob.name: ob for ob in mirrors}
        for name in pending:
            ob = by_name.get(name)
            if ob is not None:
                out[name] = evaluate_mirror(ob, scene, depsgraph, force=force, reread_geometry=True, interactive=interactive)
    # Forget objects that are no longer mirrors (deleted, or Remove Mirror).
    from . import pointers  # noqa: PLC0415

    live = {ob.session_uid for ob in pointers.mirrors()}
    for uid in [u for u in _STATE if u not in live]:
        del _STATE[uid]
    return out
