"""Freeform shadow boundary editing (Mattausch, Igarashi, Wimmer) in Blender.

The numerics run in Rust (``rokeby_native.shadows.ShadowEditor`` through :mod:`rokeby.core.native`): smooth
silhouette loops of the caster from the light, shadow handles by ray casting, MLS boundary
deformation and the Laplacian shadow mesh. This module turns Blender objects into the arrays it
needs (evaluated meshes in world space, read with foreach_get) and the result back into Blender:

* the **shadow mesh** object: a copy of the caster's mesh with the edited vertex positions, the
  same vertex groups and armature modifiers (so skeletal animation carries the edit, §6.2), visible
  to shadow rays only (``visible_camera`` and the other ray visibilities off);
* **light and shadow linking** (Cycles, and EEVEE in 4.5; see docs/shadow_editing.md): the
  original light keeps lighting the caster with the caster's own (self-)shadows and no shadow from
  the shadow mesh; a twin of the light lights every other object, blocked by the shadow mesh and
  everything else but the original caster. So receivers show the edited shadow and the caster
  shows no self-shadow artefacts from the shadow mesh.

The parts of an edit refer to each other by pointer (``obj.rokeby_shadow``, props.RokebyShadowLinks):
the shadow mesh to its caster and light, the light to its twin and linking collections, the twin to
its light. Renaming anything keeps the edit; files that stored names are migrated at load (:func:`migrate`).

Edits are made at the current frame in world space. The shadow mesh stores them as local
displacements of the caster's rest vertices (world displacement rotated by the inverse object
matrix); with an armature this is exact for edits made in the rest pose and approximate for
edits made in other poses (the per-vertex skinning rotation is not undone).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import native
from ..blender import compat, transaction
from ..blender import registry as index
from ..core import schema

SHADOW_SUFFIX = " Shadow Mesh"
TWIN_SUFFIX = " (edited shadows)"
EDIT_KEY = schema.SHADOW_EDIT_KEY
RAY_VISIBILITY = ("visible_camera", "visible_diffuse", "visible_glossy", "visible_transmission", "visible_volume_scatter")


class ShadowEditError(ValueError):
    """A shadow edit that cannot be made; nothing in the scene was changed."""


def light_arguments(light) -> dict:
    """``light_position=`` (point, spot, area) or ``light_direction=`` (sun) of a Blender light
    object, in world space."""
    if light is None or getattr(light, "type", None) != "LIGHT":
        raise ShadowEditError(f"light: {getattr(light, 'name', light)!r} is not a light object")
    m = np.array(light.matrix_world, dtype=np.float64)
    if light.data.type == "SUN":
        d = -m[:3, 2]
        return {"light_direction": d / np.linalg.norm(d)}
    return {"light_position": m[:3, 3].copy()}


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


# --- Links between the parts of an edit (props.RokebyShadowLinks, ``obj.rokeby_shadow``) -----------
# Every link is a pointer, so renaming the caster, the light or a derived part keeps the edit, and
# an object made later under an old name takes nothing over. Names of derived parts (shadow mesh,
# twin, collections) follow their owner's name when the edit is applied or its linking made again.

LINKING_TAG = schema.SHADOW_LINKING_TAG  # on the four linking collections: which role (they are ours)
_COLLECTION_ATTRS = ("receivers_caster", "blockers_caster", "receivers_edited", "blockers_edited")


def _registered() -> bool:
    import bpy  # noqa: PLC0415

    return hasattr(bpy.types.Object, schema.OBJECT_SHADOW_PROP)


def _require_registered() -> None:
    if not _registered():
        raise ShadowEditError("the Rokeby add-on is not registered: call rokeby.register() first (in Blender: enable the add-on)")


def _role(ob) -> str:
    """'SHADOW_MESH', 'TWIN', 'SELF_BLOCKER' or 'NONE'."""
    if ob is None or not _registered():
        return "NONE"
    return ob.rokeby_shadow.role


def _in_scene(ob) -> bool:
    """Whether ``ob`` exists for the artist: it is in some scene. An object deleted with X but kept
    in ``bpy.data`` by a reference (one of these links, a linking collection) counts as gone."""
    if ob is None:
        return False
    try:
        return len(ob.users_scene) > 0
    except ReferenceError:
        return False


def _only_in_linking_collections(ob) -> bool:
    """Whether ``ob`` is in no collection but the linking ones (an object deleted with X is)."""
    return all(LINKING_TAG in c for c in ob.users_collection)


def _is_light(ob) -> bool:
    return _in_scene(ob) and ob.type == "LIGHT"


def _stored(o) -> bool:
    """Whether ``o`` has ever had shadow links written (their ID property group exists). Cheap (no
    RNA access)."""
    from ..blender import compat  # noqa: PLC0415

    return compat.stored_group(o, schema.OBJECT_SHADOW_PROP) is not None


INDEX_KIND = "shadow"  # this feature's kind in the add-on's object index (blender.registry)


def _is_shadow_part(ob) -> bool:
    """Shadow meshes, twin lights and lights holding links (``Object.rokeby_shadow``), and in files
    not yet migrated the custom properties of ``schema.SHADOW_LEGACY_KEYS`` (before shadow links
    were pointers: migrate)."""
    return compat.stored_group(ob, schema.OBJECT_SHADOW_PROP) is not None or any(key in ob for key in schema.SHADOW_LEGACY_KEYS)


index.add_kind(INDEX_KIND, _is_shadow_part, order=1)  # after the reflection feature's mirrors


def _parts():
    """(shadow meshes, twin lights, lights holding links) in the file, from the add-on's object
    index (no pass over every object)."""
    meshes, twins, lights = [], [], []
    if not _registered():
        return meshes, twins, lights
    for o in index.objects(INDEX_KIND):
        if not _stored(o) or transaction.doomed(o):
            continue
        links = o.rokeby_shadow
        role = links.role
        if role == "SHADOW_MESH":
            meshes.append(o)
        elif role == "TWIN":
            twins.append(o)
        elif o.type == "LIGHT" and (links.linking_saved or links.twin is not None):
            lights.append(o)
    return meshes, twins, lights


def _self_blockers():
    """Self-shadow meshes in the file (from the add-on's object index)."""
    if not _registered():
        return []
    return [o for o in index.objects(INDEX_KIND) if _stored(o) and o.rokeby_shadow.role == "SELF_BLOCKER"]


def _linking_collection(existing, name: str, role: str):
    """``existing`` (or a new collection called ``name``), emptied and tagged as ours."""
    import bpy  # noqa: PLC0415

    c = existing
    if c is None:
        c = bpy.data.collections.new(name)
    elif not c.name.startswith(name):
        c.name = name
    c[LINKING_TAG] = role
    for o in list(c.objects):
        c.objects.unlink(o)
    return c


def _set_state(coll, obj, state: str):
    coll.objects.link(obj)
    # collection_objects runs parallel to objects (it holds no object reference of its own).
    coll.collection_objects[list(coll.objects).index(obj)].light_linking.link_state = state


RECEIVERS_CASTER, BLOCKERS_CASTER = schema.SHADOW_RECEIVERS_CASTER, schema.SHADOW_BLOCKERS_CASTER
RECEIVERS_EDITED, BLOCKERS_EDITED = schema.SHADOW_RECEIVERS_EDITED, schema.SHADOW_BLOCKERS_EDITED
_OURS = (RECEIVERS_CASTER, BLOCKERS_CASTER, RECEIVERS_EDITED, BLOCKERS_EDITED)


def _collection_name(light_name: str, role: str) -> str:
    return schema.shadow_collection_name(light_name, role)


def _edits_of(light, meshes=None):
    """(caster, shadow mesh) of every shadow edit made from ``light`` whose caster still exists."""
    if light is None:
        return []
    meshes = _parts()[0] if meshes is None else meshes
    out = []
    for ob in meshes:
        links = ob.rokeby_shadow
        if links.light == light and _in_scene(links.caster):
            out.append((links.caster, ob))
    return out


def _owns_twin(light) -> bool:
    twin = light.rokeby_shadow.twin
    return twin is not None and twin.rokeby_shadow.role == "TWIN" and twin.rokeby_shadow.light == light


def _link(light, meshes=None):
    """The light and shadow linking of the edits made from ``light`` (made again whenever a part
    of it is missing): ``light`` lights only the casters, blocked by everything but the shadow
    meshes; a twin of the light (same light data, parented with an identity offset so it follows
    every move) lights every other object, blocked by everything but the casters. The light's own
    linking before the first edit is remembered on it (``rokeby_shadow.receivers_before`` /
    ``blockers_before``) so :func:`remove` restores it."""
    import bpy  # noqa: PLC0415

    ll = light.light_linking
    links = light.rokeby_shadow
    if links.twin is not None and not _owns_twin(light):
        _unlink(light)  # links copied along with the light (Shift+D): start from the copy's own linking
    if not links.linking_saved:
        ours = lambda c: c is not None and LINKING_TAG in c  # noqa: E731
        links.receivers_before = None if ours(ll.receiver_collection) else ll.receiver_collection
        links.blockers_before = None if ours(ll.blocker_collection) else ll.blocker_collection
        links.linking_saved = True
    twin_name = light.name + TWIN_SUFFIX
    twin = links.twin
    if not (_in_scene(twin) and _owns_twin(light)):
        twin = bpy.data.objects.new(twin_name, light.data)
        for c in light.users_collection:
            c.objects.link(twin)
        links.twin = twin
    elif not twin.name.startswith(twin_name):
        twin.name = twin_name
    if twin.data != light.data:
        twin.data = light.data
    tl = twin.rokeby_shadow
    tl.role, tl.light, tl.data_version = "TWIN", light, _data_version()
    twin.parent = light
    twin.matrix_parent_inverse.identity()
    twin.location, twin.rotation_mode, twin.rotation_euler, twin.scale = (0.0, 0.0, 0.0), "XYZ", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)
    edits = _edits_of(light, meshes)
    recv_a, block_a, recv_b, block_b = (
        _linking_collection(getattr(links, attr), _collection_name(light.name, role), role)
        for attr, role in zip(_COLLECTION_ATTRS, _OURS)
    )
    links.receivers_caster, links.blockers_caster, links.receivers_edited, links.blockers_edited = recv_a, block_a, recv_b, block_b
    for caster, shadow_object in edits:
        _set_state(recv_a, caster, "INCLUDE")
        _set_state(block_a, shadow_object, "EXCLUDE")
        _set_state(recv_b, caster, "EXCLUDE")
        _set_state(block_b, caster, "EXCLUDE")
        b = _live_self_blocker(shadow_object)
        if b is not None:
            # Edited self-shadows: the caster is shadowed by its self-shadow mesh in place of itself.
            _set_state(block_a, caster, "EXCLUDE")
            _set_state(block_b, b, "EXCLUDE")
    ll.receiver_collection, ll.blocker_collection = recv_a, block_a
    twin.light_linking.receiver_collection, twin.light_linking.blocker_collection = recv_b, block_b
    return twin


def _live_self_blocker(shadow_object):
    """The self-shadow mesh of ``shadow_object`` if it is in a scene and its own, else None."""
    b = shadow_object.rokeby_shadow.self_blocker
    if b is None or not _in_scene(b) or b.rokeby_shadow.role != "SELF_BLOCKER":
        return None
    return b


def _remove_collections(colls) -> None:

    for c in colls:
        try:
            ours = c is not None and LINKING_TAG in c
        except ReferenceError:  # already removed (listed twice)
            continue
        if ours:
            transaction.remove(c)


def _remove_twin(twin) -> None:
    """Deletes a twin light; the linking collections it used go with it unless its light still uses
    them (for a new twin): ``_collect_orphan_collections`` removes those nothing uses."""

    transaction.remove(twin)
    _collect_orphan_collections()


def _unlink(light) -> None:
    """Takes the linking of ``light``'s edits down: the light gets back the linking it had before
    the first edit and forgets its links; its twin and the four collections go (unless the links
    are a copy's, made by duplicating the light: the original keeps its twin and collections)."""
    links = light.rokeby_shadow
    owner = _owns_twin(light)
    colls = [getattr(links, a) for a in _COLLECTION_ATTRS]
    twin = links.twin
    if links.linking_saved:
        ll = light.light_linking
        ll.receiver_collection, ll.blocker_collection = links.receivers_before, links.blockers_before
    links.twin = None
    links.linking_saved = False
    links.receivers_before = links.blockers_before = None
    for a in _COLLECTION_ATTRS:
        setattr(links, a, None)
    if owner:
        _remove_twin(twin)
        _remove_collections(colls)


def _collect_orphan_collections() -> None:
    """Linking collections nothing uses any more (their light and twin are gone) are removed."""
    import bpy  # noqa: PLC0415

    if transaction.active():  # once the twins and shadow meshes are gone
        transaction.later(_collect_orphan_collections)
        return
    _remove_collections([c for c in bpy.data.collections if c.users == 0 and LINKING_TAG in c])


def _data_version() -> int:
    return schema.SHADOW_DATA_VERSION


def shadow_mesh_of(obj):
    """The shadow-mesh object of ``obj`` (a caster, or a shadow mesh itself), or None."""
    if obj is None or not _registered():
        return None
    if obj.rokeby_shadow.role == "SHADOW_MESH":
        return obj
    if obj.rokeby_shadow.role == "SELF_BLOCKER":
        return next((o for o in _parts()[0] if o.rokeby_shadow.self_blocker == obj), None)
    return next((o for o in _parts()[0] if o.rokeby_shadow.caster == obj), None)


@transaction.atomic(materials=transaction.none)
def remove(obj) -> None:
    """Removes the shadow edit of ``obj`` (a caster or its shadow mesh): the shadow mesh, the twin
    light and the linking; the light's own linking before the edit comes back, so renders are
    exactly as before the edit."""

    ob = shadow_mesh_of(obj)
    if ob is None:
        raise ShadowEditError(f"{getattr(obj, 'name', obj)!r} has no shadow edit")
    light = ob.rokeby_shadow.light
    b = ob.rokeby_shadow.self_blocker
    if b is not None and b.rokeby_shadow.role != "SELF_BLOCKER":
        b = None
    for o in (ob, b):
        if o is None:
            continue
        me = o.data
        transaction.remove(o)
        if me is not None:
            transaction.remove_unused(me)
    if light is not None:
        if _edits_of(light) and _is_light(light):
            _link(light)  # other casters' edits from the same light stay
        else:
            _unlink(light)
    _collect_orphan_collections()


def repair(scene=None) -> list[str]:
    """Keeps shadow edits whole when an artist deletes something they use (called by the
    handlers; writes only when something is broken, so the update it causes settles):

    * caster or light gone (removed, or deleted with X and so in no scene): the shadow mesh is kept
      (undo or a new edit can use it) but hidden from shadow rays, and the linking is taken down,
      so the remaining lights shade as without the edit; an object deleted with X is no longer
      pointed to (Blender purges it, as any object nothing uses), one only in collections that
      left the scene is, and the edit comes back when it does;
    * shadow mesh gone: the twin and the linking go, the light's own linking comes back;
    * twin light or a linking collection gone: made again from the shadow mesh;
    * a copy of a light (Shift+D) that carried the links along gets its own linking back.

    Renames change nothing: every link is a pointer. Returns one message per repair."""
    msgs = []
    meshes, twins, lights = _parts()
    live = []
    for ob in meshes:
        links = ob.rokeby_shadow
        caster, light = links.caster, links.light
        missing = "caster" if not _in_scene(caster) else ("light" if not _is_light(light) else None)
        b = _live_self_blocker(ob)
        if missing is not None:
            if ob.visible_shadow:
                ob.visible_shadow = False
                links.switched_off = True
                msgs.append(f"'{ob.name}': its {missing} is gone; it no longer casts shadows (undo brings it back)")
            if b is not None and b.visible_shadow:
                b.visible_shadow = False
            for attr in ("caster", "light"):
                # Deleted with X but kept in bpy.data by our own references: let Blender purge it,
                # as it does an object nothing uses.
                o = getattr(links, attr)
                if o is not None and not _in_scene(o) and _only_in_linking_collections(o):
                    setattr(links, attr, None)
            continue
        if links.switched_off:  # its caster and light are back (a collection linked to the scene again)
            ob.visible_shadow, links.switched_off = True, False
            if b is not None:
                b.visible_shadow = True
            msgs.append(f"'{ob.name}': its caster and light are back; it casts the edited shadow again")
        if light not in live:
            live.append(light)
    for light in live:
        links = light.rokeby_shadow
        twin = links.twin
        colls = [getattr(links, a) for a in _COLLECTION_ATTRS]
        ll = light.light_linking
        edits = _edits_of(light, meshes)
        whole = (_in_scene(twin) and _owns_twin(light) and twin.parent == light and None not in colls
                 and ll.receiver_collection == colls[0] and ll.blocker_collection == colls[1]
                 and twin.light_linking.receiver_collection == colls[2] and twin.light_linking.blocker_collection == colls[3]
                 and all(c.name in colls[0].objects and s.name in colls[1].objects for c, s in edits)
                 and all((c.name in colls[1].objects) == (b is not None) and (b is None or b.name in colls[3].objects)
                         for c, s, b in ((c, s, _live_self_blocker(s)) for c, s in edits)))
        if not whole:
            _link(light, meshes)
            msgs.append(f"'{light.name}': the twin light or linking of its shadow edit was missing and is made again")
    for light in lights:
        if light not in live:
            copy = not _owns_twin(light)
            _unlink(light)
            msgs.append(f"'{light.name}': " + ("a copy of a light with shadow edits; it gets its own linking back" if copy
                                                 else "its shadow edit is gone; the twin light and the linking are removed"))
    for twin in twins:
        try:
            light = twin.rokeby_shadow.light
        except ReferenceError:
            continue  # removed with its light above
        if light is None or light not in live or light.rokeby_shadow.twin != twin:
            name = light.name if light is not None else "a deleted light"
            _remove_twin(twin)
            msgs.append(f"'{name}': its shadow edit is gone; the twin light and the linking are removed")
    for b in _self_blockers():
        owners = [ob for ob in meshes if ob.rokeby_shadow.self_blocker == b]
        if not owners:

            name, me = b.name, b.data
            transaction.remove(b)
            if me is not None:
                transaction.remove_unused(me)
            msgs.append(f"'{name}': its shadow mesh is gone; the self-shadow mesh is removed")
    if msgs:
        _collect_orphan_collections()
        if scene is not None:
            scene.view_layers[0].update()
    return msgs


def migrate() -> list[str]:
    """Files saved before shadow data version 1 named the parts of an edit (custom properties
    ``rokeby_shadow_of``, ``rokeby_light`` on the shadow mesh, ``rokeby_twin_of`` on the twin,
    ``rokeby_linking_before`` on the light; linking collections called '<light> · <role>'): those
    names become pointers, resolved once, at load (handlers.migrate_file). Returns one message per
    migrated part."""
    import bpy  # noqa: PLC0415

    if not _registered():
        return []
    objs, colls = bpy.data.objects, bpy.data.collections
    version = _data_version()
    msgs = []
    local = [o for o in objs if o.library is None]
    for ob in local:
        if schema.SHADOW_LEGACY_SHADOW_OF_KEY in ob and schema.SHADOW_LEGACY_LIGHT_KEY in ob:
            links = ob.rokeby_shadow
            caster, light = objs.get(str(ob[schema.SHADOW_LEGACY_SHADOW_OF_KEY])), objs.get(str(ob[schema.SHADOW_LEGACY_LIGHT_KEY]))
            links.role, links.caster, links.light, links.data_version = "SHADOW_MESH", caster, light, version
            del ob[schema.SHADOW_LEGACY_SHADOW_OF_KEY], ob[schema.SHADOW_LEGACY_LIGHT_KEY]
            msgs.append(f"'{ob.name}': shadow mesh of {caster.name if caster else None!r} from {light.name if light else None!r}")
    for ob in local:
        if schema.SHADOW_LEGACY_TWIN_OF_KEY in ob:
            light = objs.get(str(ob[schema.SHADOW_LEGACY_TWIN_OF_KEY]))
            light = light if light is not None and light.type == "LIGHT" else None
            t = ob.rokeby_shadow
            t.role, t.light, t.data_version = "TWIN", light, version
            if light is not None and light.rokeby_shadow.twin is None:
                light.rokeby_shadow.twin = ob
            del ob[schema.SHADOW_LEGACY_TWIN_OF_KEY]
            msgs.append(f"'{ob.name}': twin of {light.name if light else None!r}")
    for ob in local:
        if schema.SHADOW_LEGACY_LINKING_BEFORE_KEY in ob:
            before = [str(n) for n in ob[schema.SHADOW_LEGACY_LINKING_BEFORE_KEY]] + ["", ""]
            links = ob.rokeby_shadow
            links.linking_saved = True
            links.receivers_before = colls.get(before[0]) if before[0] else None
            links.blockers_before = colls.get(before[1]) if before[1] else None
            for attr, role in zip(_COLLECTION_ATTRS, _OURS):
                c = colls.get(_collection_name(ob.name, role))
                if c is not None and c.library is None:
                    c[LINKING_TAG] = role
                    setattr(links, attr, c)
            del ob[schema.SHADOW_LEGACY_LINKING_BEFORE_KEY]
            msgs.append(f"'{ob.name}': linking of its shadow edits")
    return msgs


# Self-shadows (the paper's Fig. 1D and Fig. 6). Light linking shades the caster with whatever
# blocks its light, and an object always blocks its own light, so an edited shadow mesh that
# only the receivers see leaves the caster's self-shadows as they were. For edits whose handles
# lie on the caster itself the caster is therefore shadowed by a *self-shadow mesh* in place of
# itself: a copy of the caster moved SELF_OFFSET of its size inwards along the vertex normals
# (so a ray leaving a lit point of the caster cannot hit it: no acne, and elsewhere it casts the
# caster's own shadows), plus the displacement the self-shadow drags alone give (§6.1 solved with
# only their silhouette offsets). The paper's modified shadow volumes (§7.1) have the same aim:
# near the caster the original shadow, at the receiver the edited one.
SELF_SUFFIX = " Self-Shadow Mesh"
SELF_OFFSET = 1e-3  # inward offset of the self-shadow mesh, a fraction of the caster's bounding-box diagonal
SELF_RINGS = 2  # the self-shadow mesh moves this many triangle rings around the dragged silhouette edges
SELF_CUTOFF = 0.02  # self-shadow displacements under this fraction of the largest are dropped (the edit stays local)


def _local_displacement(session: ShadowSession, world: np.ndarray) -> np.ndarray:
    disp = np.asarray(world, np.float64) - session.rest_world
    local = disp @ np.linalg.inv(session.matrix_world[:3, :3]).T  # one 3x3 inverse: fast per drag step
    with np.errstate(over="ignore", invalid="ignore"):
        if not (np.isfinite(world).all() and np.isfinite(local.astype(np.float32)).all()):
            raise ShadowEditError("the edited shadow mesh has non-finite or float32-overflowing positions (a drag too large?); "
                                  "nothing was written: undo the drag (cancel) and drag again")
    return local


def _deform_like(ob, caster) -> None:
    """Places ``ob`` (a copy of the caster's mesh) where the caster is, with its vertex groups and
    armature modifiers (§6.2: a pose moves the copy with the caster), seen by shadow rays only."""
    ob.parent = caster.parent
    ob.parent_type = caster.parent_type
    ob.parent_bone = caster.parent_bone
    ob.matrix_world = caster.matrix_world.copy()
    # Same vertex groups: since Blender 3.0 the names and weights live on the mesh, so the copy
    # already carries them (clearing them here would drop the weights); add any that are missing.
    for g in caster.vertex_groups:
        if ob.vertex_groups.get(g.name) is None:
            ob.vertex_groups.new(name=g.name)
    for mod in list(ob.modifiers):
        ob.modifiers.remove(mod)
    for mod in caster.modifiers:
        if mod.type == "ARMATURE":
            m2 = ob.modifiers.new(mod.name, "ARMATURE")
            for attr in ("object", "use_vertex_groups", "use_bone_envelopes", "use_deform_preserve_volume", "use_multi_modifier", "vertex_group"):
                setattr(m2, attr, getattr(mod, attr))
    for attr in RAY_VISIBILITY:
        setattr(ob, attr, False)
    ob.visible_shadow = True
    ob.hide_select = False
    ob.display_type = "WIRE"


def configuration_key(i: int) -> str:
    """Name of the shape key of keyed configuration ``i`` (§6.2; 0 is the first edit)."""
    return EDIT_KEY if i == 0 else f"{EDIT_KEY} {i + 1}"


def configuration_vectors(shadow_object) -> np.ndarray:
    """(K, 3) unit light vectors, in the caster's local frame, of the K keyed configurations of
    ``shadow_object`` (§6.2): where each of its edits was made."""
    vs = [np.asarray(shadow_object[schema.SHADOW_LIGHT_INITIAL_KEY], np.float64)]
    extra = np.asarray(shadow_object.get(schema.SHADOW_LIGHT_CONFIGURATIONS_KEY, []), np.float64).reshape(-1, 3)
    vs.extend(extra)
    out = np.asarray(vs).reshape(-1, 3)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _write_key(ob, key_name: str, basis: np.ndarray, local: np.ndarray | None) -> None:
    keys = ob.data.shape_keys
    key = keys.key_blocks.get(key_name) or ob.shape_key_add(name=key_name, from_mix=False)
    co = basis if local is None else basis + local.astype(np.float32).ravel()
    key.data.foreach_set("co", co.astype(np.float32))
    key.slider_min, key.slider_max = 0.0, 1.0


def _self_displacement(session: ShadowSession, self_world: np.ndarray, normals_world: np.ndarray) -> np.ndarray:
    """The self-shadow drags' displacement (world, (V, 3)) made safe for the caster: where a vertex
    faces the light and the displacement points out of the caster, it is dropped, so the self-shadow
    mesh never rises above a lit point of the caster (no new shadow on what the light sees
    directly; the paper's §7.1 constraint (1): near the caster the shadow volume is the original
    one). The enlarged silhouette then comes from the half facing away, whose caster points the
    light does not reach anyway; moves into the caster (shrinking a shadow) are always kept."""
    rest = session.rest_world
    d = np.asarray(self_world, np.float64) - rest
    if "light_position" in session.light_kw:
        to_light = np.asarray(session.light_kw["light_position"], np.float64) - rest
    else:
        to_light = np.broadcast_to(-np.asarray(session.light_kw["light_direction"], np.float64), rest.shape)
    facing = np.einsum("ij,ij->i", normals_world, to_light) > 0.0
    outward = np.einsum("ij,ij->i", d, normals_world) > 0.0
    d[facing & outward] = 0.0
    mag = np.linalg.norm(d, axis=1)
    top = float(mag.max()) if len(mag) else 0.0
    if top > 0:
        d[mag < SELF_CUTOFF * top] = 0.0
        # Only at the dragged segments' silhouette edges (SELF_RINGS rings of triangles around
        # their vertices): the Laplacian moves the rest of the part too (a part held only at its
        # silhouette shifts as a whole), and there it would shade the caster where nothing was edited.
        near = np.zeros(len(rest), bool)
        for st in session.drags + [session.pending]:
            if st is not None and st["self"]:
                near[st["vertices"]] = True
        tris = session.triangles
        for _ in range(SELF_RINGS):
            near[tris[near[tris].any(axis=1)].ravel()] = True
        d[~near] = 0.0
    return d


def _self_blocker(ob, caster, light, rest: np.ndarray, key_name: str, self_local: np.ndarray | None):
    """The self-shadow mesh of shadow mesh ``ob`` (made when an edit first has self-shadow drags;
    None while none has); its key ``key_name`` gets ``self_local``, its key values follow ``ob``'s."""
    import bpy  # noqa: PLC0415

    b = ob.rokeby_shadow.self_blocker
    if not _in_scene(b):
        b = None
    if b is None and self_local is None:
        return None
    n = len(rest) // 3
    me = caster.data
    normals = np.empty(n * 3, np.float32)
    me.vertices.foreach_get("normal", normals)
    r3 = rest.reshape(-1, 3).astype(np.float64)
    diag = float(np.linalg.norm(r3.max(axis=0) - r3.min(axis=0))) if n else 0.0
    basis = (r3 - SELF_OFFSET * diag * normals.reshape(-1, 3)).astype(np.float32).ravel()
    name = caster.name + SELF_SUFFIX
    if b is None:
        b = bpy.data.objects.new(name, me.copy())
        for c in caster.users_collection:
            c.objects.link(b)
    elif not b.name.startswith(name):
        b.name = name
    if len(b.data.vertices) != n:
        b.data = me.copy()
    b.data.vertices.foreach_set("co", basis)
    if b.data.shape_keys is None:
        b.shape_key_add(name="Basis", from_mix=False)
    b.data.shape_keys.key_blocks["Basis"].data.foreach_set("co", basis)
    _write_key(b, key_name, basis, self_local)
    for k in ob.data.shape_keys.key_blocks[1:]:  # every configuration of the shadow mesh, same names
        if b.data.shape_keys.key_blocks.get(k.name) is None:
            _write_key(b, k.name, basis, None)
        b.data.shape_keys.key_blocks[k.name].value = k.value
    b.data.update()
    _deform_like(b, caster)
    bl = b.rokeby_shadow
    bl.role, bl.caster, bl.light, bl.data_version = "SELF_BLOCKER", caster, light, _data_version()
    ob.rokeby_shadow.self_blocker = b
    return b


@transaction.atomic(materials=transaction.none)
def apply(session: ShadowSession, *, scene=None, falloff_beta: float = 0.0, add_configuration: bool = False):
    """Makes (or updates) the shadow-mesh object of ``session``'s current edit and sets up the
    light and shadow linking. ``falloff_beta`` (β ≥ 0, §6.2) blends the edit back towards the
    original shadow as the light moves away from where the edit was made, (l_initial · l_current)^β.
    β is stored on the shadow object (custom property ``rokeby_falloff_beta``, editable); when it
    is > 0 the handlers apply it on every scene update and frame change (``sync_falloffs``). 0, the
    default, leaves the edit at full strength and the falloff to scripts (``update_falloff``).

    ``add_configuration=True`` keeps the caster's existing edit and adds this session's as another
    keyed configuration (§6.2, "multiple keyframes for different configurations"): each is a shape
    key with the light vector it was made under, and the handlers blend them by the current light
    vector's angles to those (``configuration_weights``). Re-applying a session updates its own
    configuration. Drags whose handles lie on the caster also edit the caster's self-shadows
    (a self-shadow mesh shadows the caster; see SELF_OFFSET). Returns (shadow object, twin light)."""
    import bpy  # noqa: PLC0415

    beta = float(falloff_beta)
    if not (np.isfinite(beta) and beta >= 0.0):
        raise ShadowEditError(f"falloff_beta: must be finite and >= 0, got {falloff_beta}")

    _require_registered()
    sc = scene if scene is not None else bpy.context.scene
    caster = session.caster_object()
    light = session.light_object()
    if not _in_scene(caster) or not _is_light(light):
        raise ShadowEditError("the caster or the light of this session no longer exists")
    world = np.asarray(session.shadow_mesh(), dtype=np.float64)
    if world.shape != session.rest_world.shape:
        raise ShadowEditError("the caster's vertex count changed since the session started; start a new one")
    local = _local_displacement(session, world)
    self_world = session.self_shadow_mesh()
    self_local = None
    if self_world is not None:
        self_local = _local_displacement(session, session.rest_world + _self_displacement(session, self_world, session.rest_normals))
    me = caster.data
    n = len(me.vertices)
    if n != len(world):
        raise ShadowEditError(f"the shadow mesh has {len(world)} vertices but '{caster.name}' has {n}: modifiers that change "
                              "the topology (subdivision, boolean) must be applied first")
    rest = np.empty(n * 3, np.float32)
    me.vertices.foreach_get("co", rest)
    name = caster.name + SHADOW_SUFFIX
    ob = shadow_mesh_of(caster)
    previous_light = None
    if add_configuration and ob is not None and ob.rokeby_shadow.light != light:
        raise ShadowEditError(f"add_configuration: the edit of '{caster.name}' was made from "
                              f"'{getattr(ob.rokeby_shadow.light, 'name', None)}', this session from '{light.name}'; "
                              "configurations of one edit share its light (move that light instead)")
    if ob is None:
        ob = bpy.data.objects.new(name, me.copy())
        for c in caster.users_collection:
            c.objects.link(ob)
        session.configuration = 0
    else:
        previous_light = ob.rokeby_shadow.light
        if not ob.name.startswith(name):
            ob.name = name
        if ob.data.users == 1 and len(ob.data.vertices) != n:
            ob.data = me.copy()
    if ob.data.shape_keys is not None and len(ob.data.vertices) != n:
        raise ShadowEditError(f"the shadow mesh of '{caster.name}' no longer matches its vertices; remove the shadow edit first")
    configs = configuration_vectors(ob) if schema.SHADOW_LIGHT_INITIAL_KEY in ob else np.zeros((0, 3))
    if add_configuration and len(configs):
        session.configuration = len(configs)
    elif not session.applied or session.configuration >= max(len(configs), 1):
        # A new edit replaces the caster's edit, every configuration of it.
        session.configuration = 0
        _drop_configurations(ob)
    # The edit lives in a shape key on the caster's rest shape, so the falloff of §6.2 can blend
    # between original (0) and shadow mesh (1), and keyed configurations between each other,
    # without touching the mesh again.
    ob.data.vertices.foreach_set("co", rest)
    if ob.data.shape_keys is None:
        ob.shape_key_add(name="Basis", from_mix=False)
    ob.data.shape_keys.key_blocks["Basis"].data.foreach_set("co", rest)
    key_name = configuration_key(session.configuration)
    _write_key(ob, key_name, rest, local)
    lv = list(map(float, session.light_vector))
    if session.configuration == 0:
        ob[schema.SHADOW_LIGHT_INITIAL_KEY] = lv
    else:
        extra = list(ob.get(schema.SHADOW_LIGHT_CONFIGURATIONS_KEY, []))
        i = 3 * (session.configuration - 1)
        extra[i:i + 3] = lv
        ob[schema.SHADOW_LIGHT_CONFIGURATIONS_KEY] = extra
    ob[schema.SHADOW_FALLOFF_BETA_KEY] = beta
    links = ob.rokeby_shadow
    links.role, links.caster, links.light, links.data_version = "SHADOW_MESH", caster, light, _data_version()
    values = configuration_weights(ob, light, beta)
    for i, v in enumerate(values):
        ob.data.shape_keys.key_blocks[configuration_key(i)].value = v
    ob.data.update()
    _deform_like(ob, caster)
    _self_blocker(ob, caster, light, rest, key_name, self_local)
    session.applied = True

    twin = _link(light)
    if previous_light is not None and previous_light != light:
        # The caster's edit moved to another light: the previous one keeps its other edits' linking.
        if _edits_of(previous_light) and _is_light(previous_light):
            _link(previous_light)
        else:
            _unlink(previous_light)
        _collect_orphan_collections()
    sc.view_layers[0].update()
    return ob, twin


def _drop_configurations(ob) -> None:
    """Removes the keyed configurations after the first (keys and light vectors) from shadow mesh
    ``ob`` and its self-shadow mesh."""
    if schema.SHADOW_LIGHT_CONFIGURATIONS_KEY in ob:
        del ob[schema.SHADOW_LIGHT_CONFIGURATIONS_KEY]
    b = ob.rokeby_shadow.self_blocker
    for o in (ob, b):
        keys = None if o is None else o.data.shape_keys
        if keys is None:
            continue
        for k in [k for k in keys.key_blocks if k.name.startswith(EDIT_KEY + " ")]:
            o.shape_key_remove(k)


def configuration_weights(shadow_object, light, beta: float = 0.0, *, caster=None) -> np.ndarray:
    """Shape-key values (K,) of the K keyed configurations of ``shadow_object`` (§6.2) for the
    light's current position: the configurations are blended by the angle θ_i between the current
    light vector and theirs (weights 1/θ_i normalised: along the arc between two configurations
    the blend is linear in the angle, at a configuration it is that one alone), times the falloff
    (l_nearest · l_current)^β. One configuration: just the falloff."""
    caster = caster if caster is not None else shadow_object.rokeby_shadow.caster
    if caster is None:
        raise ShadowEditError(f"the caster of '{shadow_object.name}' no longer exists")
    vs = configuration_vectors(shadow_object)
    cur = _current_light_vector(caster, light)
    c = np.clip(vs @ cur, -1.0, 1.0)
    theta = np.arccos(c)
    nearest = int(np.argmin(theta))
    fall = float(native.module().shadows.falloff_factor(vs[nearest], cur, float(beta))) if beta > 0 else 1.0
    if len(vs) == 1 or theta[nearest] < 1e-9:
        w = np.zeros(len(vs))
        w[nearest] = 1.0
    else:
        w = (1.0 / theta) / np.sum(1.0 / theta)
    return w * fall


def _unit_light_vector(m: np.ndarray, kw: dict) -> np.ndarray:
    """The light direction in the caster's local frame (§6.2: relative changes of object and
    light), from the light to the caster's origin. A light at the origin itself (possible now that
    a light may be inside the caster's bounds, e.g. at a ring's centre) has no direction: the
    local -z axis is used, so no NaN reaches the stored light vectors."""
    lv = kw.get("light_direction")
    if lv is None:
        lv = m[:3, 3] - kw["light_position"]
    cur = np.linalg.solve(m[:3, :3], lv)
    n = np.linalg.norm(cur)
    if not (np.isfinite(n) and n > 1e-9 * max(1.0, float(np.abs(m[:3, 3]).max()))):
        return np.array([0.0, 0.0, -1.0])
    return cur / n


def _current_light_vector(caster, light) -> np.ndarray:
    return _unit_light_vector(np.array(caster.matrix_world, dtype=np.float64), light_arguments(light))


def _set_key_values(ob, values) -> int:
    """Writes the configuration key values of shadow mesh ``ob`` and its self-shadow mesh (only
    those that changed); returns how many changed."""
    written = 0
    targets = [ob]
    b = ob.rokeby_shadow.self_blocker
    if b is not None and b.data.shape_keys is not None:
        targets.append(b)
    for t in targets:
        kb = t.data.shape_keys.key_blocks
        for i, v in enumerate(values):
            k = kb.get(configuration_key(i))
            if k is not None and abs(k.value - v) > 1e-6:
                k.value = float(v)
                written += t is ob
    return written


def falloff_factor(shadow_object, light, beta: float, *, caster=None) -> float:
    """(l_initial · l_current)^β (§6.2; β = 0: no falloff) for the light's current position
    relative to the caster, without writing anything (with keyed configurations, l_initial is the
    nearest configuration's)."""

    if _role(shadow_object) != "SHADOW_MESH":
        raise ShadowEditError(f"{getattr(shadow_object, 'name', shadow_object)!r} is not a Rokeby shadow mesh")
    caster = caster if caster is not None else shadow_object.rokeby_shadow.caster
    if caster is None:
        raise ShadowEditError(f"the caster of '{shadow_object.name}' no longer exists")
    cur = _current_light_vector(caster, light)
    vs = configuration_vectors(shadow_object)
    initial = vs[int(np.argmax(vs @ cur))]
    return float(native.module().shadows.falloff_factor(initial, cur, float(beta)))


def update_falloff(shadow_object, light, beta: float, *, caster=None) -> float:
    """Sets the shadow mesh's edit shape keys (and its self-shadow mesh's) to the falloff times the
    configuration weights (``configuration_weights``) and returns the falloff."""
    k = falloff_factor(shadow_object, light, beta, caster=caster)
    _set_key_values(shadow_object, configuration_weights(shadow_object, light, beta, caster=caster))
    return k


def sync_falloffs(scene) -> int:
    """Brings every shadow mesh's falloff and keyed-configuration blend (§6.2) up to date with its
    light's current position; called by the add-on's depsgraph and frame-change handlers. Writes
    only values that changed (so the write itself settles); returns how many it wrote. Shadow
    meshes whose light or caster is gone keep their values."""

    written = 0
    for ob in _parts()[0]:
        if not index.in_scene(ob, scene):
            continue
        light = ob.rokeby_shadow.light
        keys = ob.data.shape_keys
        if light is None or light.type != "LIGHT" or keys is None or EDIT_KEY not in keys.key_blocks:
            continue
        beta = float(ob.get(schema.SHADOW_FALLOFF_BETA_KEY, 0.0))
        several = len(ob.get(schema.SHADOW_LIGHT_CONFIGURATIONS_KEY, [])) >= 3
        if not (np.isfinite(beta) and beta >= 0.0) or not (beta > 0.0 or several):
            continue  # β = 0 and one configuration: the key stays as apply or a script set it
        try:
            values = configuration_weights(ob, light, beta)
        except (ShadowEditError, ValueError, KeyError, np.linalg.LinAlgError):
            continue
        written += _set_key_values(ob, values)
    return written


# --- Live shadow while dragging (the paper's Fig. 3 B–D) -----------------------------------------
# Each drag step writes the current (uncommitted) shadow mesh into the edit's shape key, so a
# viewport in Rendered shading (EEVEE or Cycles: both honour the linking) and renders show the
# edited shadow during the drag. Solid and Material Preview shading skip the shadow mesh (it is
# displayed as Wire) and Solid has no linked lights. live_begin installs the edit (apply) if the caster has none; live_end
# keeps the result (apply again: everything consistent) or puts back exactly what was there.


@dataclass
class LivePreview:
    session: ShadowSession
    shadow_object: object
    created: bool
    rest: np.ndarray  # (3V,) float32 the caster's rest coordinates (the keys' Basis)
    saved: dict  # (object name-independent) id -> {key name: coordinates} before the drag
    had_blocker: bool
    steps: int = 0


def _key_coords(ob) -> dict:
    out = {}
    if ob is None or ob.data.shape_keys is None:
        return out
    n = len(ob.data.vertices)
    for k in ob.data.shape_keys.key_blocks:
        co = np.empty(n * 3, np.float32)
        k.data.foreach_get("co", co)
        out[k.name] = (co, k.value)
    return out


def live_begin(session: ShadowSession, *, scene=None) -> LivePreview:
    """Starts showing ``session``'s edit live (see :func:`live_step`)."""
    caster = session.caster_object()
    if caster is None:
        raise ShadowEditError("the caster of this session no longer exists")
    ob = shadow_mesh_of(caster)
    created = ob is None
    saved, had_blocker = {}, False
    if created:
        ob, _twin = apply(session, scene=scene)
    else:
        if ob.rokeby_shadow.light != session.light_object():
            raise ShadowEditError(f"the edit of '{caster.name}' is from another light; apply or remove it first")
        b = _live_self_blocker(ob)
        had_blocker = b is not None
        saved = {"mesh": _key_coords(ob), "blocker": _key_coords(b)}
    rest = np.empty(len(caster.data.vertices) * 3, np.float32)
    caster.data.vertices.foreach_get("co", rest)
    return LivePreview(session, ob, created, rest, saved, had_blocker)


def live_step(preview: LivePreview) -> None:
    """Writes the session's current shadow mesh (the drag in progress included; §6.1 by
    back-substitution) into the shadow object's key; self-shadow drags update the self-shadow mesh
    too (made and linked at the first one)."""
    s, ob = preview.session, preview.shadow_object
    local = _local_displacement(s, np.asarray(s.shadow_mesh(), np.float64))
    key_name = configuration_key(s.configuration)
    kb = ob.data.shape_keys.key_blocks
    if kb.get(key_name) is None:
        raise ShadowEditError(f"'{ob.name}' has no key '{key_name}' any more; start the drag again")
    compat.shape_key_points(kb[key_name]).foreach_set("co", preview.rest + local.astype(np.float32).ravel())
    ob.data.update_tag()
    if s.has_self_edits():
        caster, light = s.caster_object(), s.light_object()
        linked = _live_self_blocker(ob) is not None
        self_world = s.self_shadow_mesh()
        self_local = _local_displacement(s, s.rest_world + _self_displacement(s, self_world, s.rest_normals))
        _self_blocker(ob, caster, light, preview.rest, key_name, self_local)
        if not linked:
            _link(light)
    preview.steps += 1


def live_end(preview: LivePreview, *, keep: bool, scene=None) -> None:
    """Ends the live preview: ``keep`` applies the session's (committed) edit; otherwise the
    shadow object and self-shadow mesh get back exactly the keys they had (or are removed when the
    preview made them)."""
    import bpy  # noqa: PLC0415

    s = preview.session
    if keep:
        apply(s, scene=scene)
        return
    caster = s.caster_object()
    if preview.created:
        if caster is not None and shadow_mesh_of(caster) is not None:
            remove(caster)
        return
    ob = preview.shadow_object
    for part, coords in (("mesh", preview.saved.get("mesh", {})), ("blocker", preview.saved.get("blocker", {}))):
        o = ob if part == "mesh" else _live_self_blocker(ob)
        if o is None or o.data.shape_keys is None:
            continue
        for name, (co, value) in coords.items():
            k = o.data.shape_keys.key_blocks.get(name)
            if k is not None:
                k.data.foreach_set("co", co)
                k.value = value
        o.data.update()
    b = _live_self_blocker(ob)
    if b is not None and not preview.had_blocker:
        ob.rokeby_shadow.self_blocker = None
        me = b.data
        transaction.remove(b)
        if me is not None:
            transaction.remove_unused(me)
        light = ob.rokeby_shadow.light
        if _is_light(light):
            _link(light)
    (scene if scene is not None else bpy.context.scene).view_layers[0].update()
