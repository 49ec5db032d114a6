"""One shadow-editing session: the native editor (``rokeby_native.shadows.ShadowEditor`` through
:mod:`rokeby.core.native`: smooth silhouette loops of the caster from the light, shadow handles by
ray casting, MLS boundary deformation and the Laplacian shadow mesh) made from Blender objects
(evaluated meshes in world space, read with foreach_get), its drags, commits and undo history."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import native
from .errors import ShadowEditError
from .light import _unit_light_vector, light_arguments
from .linking import _role


def _merged(meshes) -> tuple[np.ndarray, np.ndarray]:
    vs, fs, off = [], [], 0
    for m in meshes:
        vs.append(m.vertices)
        fs.append(m.triangles.astype(np.int64) + off)
        off += len(m.vertices)
    if not vs:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int64)
    return np.concatenate(vs), np.concatenate(fs)


def _object_by_uid(uid: int):
    import bpy  # noqa: PLC0415

    return next((o for o in bpy.data.objects if o.session_uid == uid), None)


# Bound of the drag parameters (noise amplitude and frequency, MLS alpha): far beyond any useful
# edit, far below what overflows float32 positions.
MAX_DRAG_PARAMETER = 1e6


@dataclass
class ShadowSession:
    """One editing session: the native editor and what it was made from. The caster and the light
    are held by Blender's session id, so renaming either during a session changes nothing."""

    editor: object
    caster_uid: int
    light_uid: int
    receivers: list  # session ids of the receivers
    light_vector: np.ndarray
    rest_world: np.ndarray
    matrix_world: np.ndarray
    history: list = field(default_factory=list)
    drags: list = field(default_factory=list)  # committed drags, replayable (self-shadow part, §6.1 is linear)
    pending: dict | None = None  # the uncommitted drag
    configuration: int = 0  # which keyed configuration (§6.2) this session's edit is (set by apply)
    applied: bool = False  # applied once: applying again updates its configuration only
    rest_normals: np.ndarray | None = None  # (V, 3) world vertex normals at the start
    light_kw: dict = field(default_factory=dict)  # light_position= or light_direction= (world) at the start
    triangles: np.ndarray | None = None  # (F, 3) the caster's triangles
    _edges: dict = field(default_factory=dict)  # loop -> (K, 2) its silhouette edges' vertices

    def caster_object(self):
        """The caster (None once it is deleted)."""
        return _object_by_uid(self.caster_uid)

    def light_object(self):
        """The light (None once it is deleted)."""
        return _object_by_uid(self.light_uid)

    @property
    def caster(self) -> str:
        """The caster's current name ("" once it is deleted)."""
        ob = self.caster_object()
        return "" if ob is None else ob.name

    @property
    def light(self) -> str:
        """The light's current name ("" once it is deleted)."""
        ob = self.light_object()
        return "" if ob is None else ob.name

    def loops(self):
        return self.editor.loops()

    def handles(self, loop: int = 0, eye=None):
        return self.editor.handles(loop, eye)

    def drag(self, loop: int, fixed, moved: int, target, **kwargs):
        """One drag step (receiver point ``target`` under the cursor), relative to the last commit.
        Numbers that would overflow the shadow mesh's float32 positions are refused (ValueError
        naming the argument): |noise_amplitude|, |noise_frequency| and |mls_alpha| at most
        MAX_DRAG_PARAMETER, the target finite."""
        for name in ("noise_amplitude", "noise_frequency", "mls_alpha"):
            if name in kwargs:
                x = kwargs[name]
                if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
                    raise TypeError(f"{name}: expected a number, got {x!r}")
                if not (np.isfinite(x) and abs(x) <= MAX_DRAG_PARAMETER):
                    raise ValueError(f"{name}: must be finite and at most {MAX_DRAG_PARAMETER:g} in size, got {x!r}")
        step = {"loop": int(loop), "fixed": tuple(int(i) for i in fixed), "moved": int(moved),
                "target": np.asarray(target, dtype=np.float64).copy(), "kwargs": dict(kwargs)}
        r = self.editor.drag(step["loop"], step["fixed"], step["moved"], step["target"], **kwargs)
        # A self-shadow drag: most handles of the deformed segment lie on the caster itself
        # (the paper's Fig. 6, the cap's shadow on the face).
        seg = np.asarray(r["segment"], np.int64)
        h = r["handles"]
        on = np.asarray(h["on_caster"], bool)[seg] & np.asarray(h["hit"], bool)[seg]
        step["self"] = bool(len(seg) and on.mean() > 0.5)
        # Where it acts: the segment's silhouette points before and after (the self-shadow mesh
        # keeps the displacement near them only).
        if step["loop"] not in self._edges:  # a loop's silhouette edges are fixed for the session
            self._edges[step["loop"]] = np.asarray(self.editor.loops()[step["loop"]]["edges"], np.int64)
        step["vertices"] = np.unique(self._edges[step["loop"]][seg])
        self.pending = step
        return r

    def prepare_drag(self, loop: int, fixed, moved: int, *, style: str = "affine", noise_amplitude: float = 0.0) -> bool:
        """The mouse press of a drag (the arguments as :meth:`drag` takes them): makes the steps
        that follow, the first included, update the shadow mesh by an O(V) sum instead of a
        back-substitution (docs/shadow_editing.md). Returns whether it could (not for rigid or
        noisy drags, per-loop frusta or with an uncommitted step). Changes no edit."""
        return bool(self.editor.prepare_drag(int(loop), tuple(int(i) for i in fixed), int(moved), style=style,
                                             noise_amplitude=float(noise_amplitude)))

    def commit(self):
        self.editor.commit()
        if self.pending is not None:
            self.drags.append(self.pending)
            self.pending = None

    def cancel(self):
        """Drops the uncommitted drag."""
        self.editor.cancel()
        self.pending = None

    def reset(self):
        """Forgets every edit."""
        self.editor.reset()
        self.drags.clear()
        self.pending = None

    def has_self_edits(self) -> bool:
        return any(d["self"] for d in self.drags) or bool(self.pending and self.pending["self"])

    def _replay(self, steps, pending=None):
        self.editor.reset()
        for d in steps:
            self.editor.drag(d["loop"], d["fixed"], d["moved"], d["target"], **d["kwargs"])
            self.editor.commit()
        if pending is not None:
            self.editor.drag(pending["loop"], pending["fixed"], pending["moved"], pending["target"], **pending["kwargs"])

    def self_shadow_mesh(self):
        """The shadow mesh (V, 3) of the self-shadow drags alone (§6.1 solved with only their
        silhouette offsets; the solve is linear in them, so this is the self-shadow loops' part of
        :meth:`shadow_mesh`), or None when no drag edits a self-shadow. The editor's state is
        replayed afterwards (its factorisation is kept)."""
        if not self.has_self_edits():
            return None
        pend = self.pending if self.pending is not None and self.pending["self"] else None
        try:
            self._replay([d for d in self.drags if d["self"]], pend)
            return np.asarray(self.editor.shadow_mesh(), np.float64)
        finally:
            self._replay(self.drags, self.pending)

    def shadow_mesh(self) -> np.ndarray:
        return self.editor.shadow_mesh()


def start(caster, light, receivers=None, *, scene=None, min_loop_vertices: int = 20, w_z: float = 2.5,
          constraint_weight: float = 10.0) -> ShadowSession:
    """Starts editing the shadow of the closed mesh ``caster`` from ``light`` on ``receivers``
    (default: every other visible mesh of the scene). Errors (open caster, light inside the
    caster's volume, nothing under the light) are :class:`ShadowEditError` naming the cause."""
    import bpy  # noqa: PLC0415 - Blender only

    from ..blender import meshes  # noqa: PLC0415

    sc = scene if scene is not None else bpy.context.scene
    if caster is None or caster.type != "MESH":
        raise ShadowEditError(f"caster: {getattr(caster, 'name', caster)!r} is not a mesh object")
    kw = light_arguments(light)
    if _role(caster) == "SHADOW_MESH":
        owner = caster.rokeby_shadow.caster
        raise ShadowEditError(f"caster: '{caster.name}' is the shadow mesh of "
                              f"{repr(owner.name) if owner is not None else 'a deleted caster'}; edit from the caster itself")
    if _role(caster) == "SELF_BLOCKER":
        owner = caster.rokeby_shadow.caster
        raise ShadowEditError(f"caster: '{caster.name}' is the self-shadow mesh of "
                              f"{repr(owner.name) if owner is not None else 'a deleted caster'}; edit from the caster itself")
    if _role(light) == "TWIN":
        owner = light.rokeby_shadow.light
        raise ShadowEditError(f"light: '{light.name}' is the twin of {repr(owner.name) if owner is not None else 'a deleted light'} "
                              "made for edited shadows; edit from that light")
    if receivers is None:
        receivers = [o for o in sc.objects if o.type == "MESH" and o != caster and _role(o) not in ("SHADOW_MESH", "SELF_BLOCKER")
                     and o.visible_get()]
    vl = sc.view_layers[0] if bpy.context.view_layer is None else bpy.context.view_layer
    vl.update()
    dg = bpy.context.evaluated_depsgraph_get()
    cm = meshes.mesh_arrays(caster, dg)
    rm = [meshes.mesh_arrays(o, dg) for o in receivers]
    rv, rf = _merged(rm)
    opts = {"min_loop_vertices": int(min_loop_vertices), "w_z": float(w_z), "constraint_weight": float(constraint_weight), **kw}
    try:
        # A point light inside the caster's bounds gets one frustum per silhouette loop (§5.2).
        ed = native.module().shadows.ShadowEditor(cm.vertices, cm.triangles.astype(np.int64), rv, rf, normals=cm.normals, **opts)
    except ValueError as exc:
        raise ShadowEditError(f"cannot edit the shadow of '{caster.name}' from '{light.name}': {exc}") from exc
    m = np.array(caster.matrix_world, dtype=np.float64)
    return ShadowSession(ed, caster.session_uid, light.session_uid, [o.session_uid for o in receivers], _unit_light_vector(m, kw),
                         np.asarray(cm.vertices, np.float64), m, rest_normals=np.asarray(cm.normals, np.float64), light_kw=kw,
                         triangles=np.asarray(cm.triangles, np.int64))
