"""What the evaluator keeps about each mirror between updates, and what it reports.

:class:`_State` is a mirror's runtime state (its geometry, caches, last field and report; not
saved: rebuilt after a reload), kept per ``session_uid``; :class:`MirrorReport` is what one
evaluation of a mirror did, shown in the sidebar and returned by the API. ``stats()`` counts the
evaluations asked for, the fields recomputed, those skipped because nothing had changed, and the
errors. The rest reads the state for the sidebar, the viewport, the handlers and the API (the last
field, the report, whether a field is a drag preview).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .mirror_surface import _Geometry
from .scene_inputs import mirrors_of


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
    # DRAG_METHOD's (rokeby.reflection.geodesic_cache); the mirror's own method replaces them when
    # the drag ends (renders and saves never see it).
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
        # an interactive update after that is a handle being moved
        # (see geodesic_cache._geodesic_distances).
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
