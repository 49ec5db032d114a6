"""Freeform shadow boundary editing (Mattausch, Igarashi, Wimmer; issue 7) in Blender.

The numerics run in Rust (``rokeby_native.ShadowEditor`` through :mod:`rokeby.native`): smooth
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

from . import native

SHADOW_SUFFIX = " Shadow Mesh"
TWIN_SUFFIX = " (edited shadows)"
EDIT_KEY = "Rokeby shadow edit"
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
        return self.editor.drag(loop, tuple(int(i) for i in fixed), int(moved), np.asarray(target, dtype=np.float64), **kwargs)

    def commit(self):
        self.editor.commit()

    def shadow_mesh(self) -> np.ndarray:
        return self.editor.shadow_mesh()


def start(caster, light, receivers=None, *, scene=None, min_loop_vertices: int = 20, w_z: float = 2.5,
          constraint_weight: float = 10.0) -> ShadowSession:
    """Starts editing the shadow of the closed mesh ``caster`` from ``light`` on ``receivers``
    (default: every other visible mesh of the scene). Errors (open caster, light inside the
    caster's bounds, nothing under the light) are :class:`ShadowEditError` naming the cause."""
    import bpy  # noqa: PLC0415 - Blender only

    from . import api  # noqa: PLC0415

    sc = scene if scene is not None else bpy.context.scene
    if caster is None or caster.type != "MESH":
        raise ShadowEditError(f"caster: {getattr(caster, 'name', caster)!r} is not a mesh object")
    kw = light_arguments(light)
    if _role(caster) == "SHADOW_MESH":
        owner = caster.rokeby_shadow.caster
        raise ShadowEditError(f"caster: '{caster.name}' is the shadow mesh of "
                              f"{repr(owner.name) if owner is not None else 'a deleted caster'}; edit from the caster itself")
    if _role(light) == "TWIN":
        owner = light.rokeby_shadow.light
        raise ShadowEditError(f"light: '{light.name}' is the twin of {repr(owner.name) if owner is not None else 'a deleted light'} "
                              "made for edited shadows; edit from that light")
    if receivers is None:
        receivers = [o for o in sc.objects if o.type == "MESH" and o != caster and _role(o) != "SHADOW_MESH" and o.visible_get()]
    vl = sc.view_layers[0] if bpy.context.view_layer is None else bpy.context.view_layer
    vl.update()
    dg = bpy.context.evaluated_depsgraph_get()
    cm = api.mesh_arrays(caster, dg)
    rm = [api.mesh_arrays(o, dg) for o in receivers]
    rv, rf = _merged(rm)
    try:
        ed = native.module().ShadowEditor(cm.vertices, cm.triangles.astype(np.int64), rv, rf, normals=cm.normals,
                                          min_loop_vertices=int(min_loop_vertices), w_z=float(w_z),
                                          constraint_weight=float(constraint_weight), **kw)
    except ValueError as exc:
        raise ShadowEditError(f"cannot edit the shadow of '{caster.name}' from '{light.name}': {exc}") from exc
    m = np.array(caster.matrix_world, dtype=np.float64)
    lv = kw.get("light_direction")
    if lv is None:
        lv = m[:3, 3] - kw["light_position"]
    # Light direction in the caster's local frame (§6.2: relative changes of object and light).
    lv_local = np.linalg.solve(m[:3, :3], lv)
    return ShadowSession(ed, caster.session_uid, light.session_uid, [o.session_uid for o in receivers], lv_local / np.linalg.norm(lv_local),
                         np.asarray(cm.vertices, np.float64), m)


# --- Links between the parts of an edit (props.RokebyShadowLinks, ``obj.rokeby_shadow``) -----------
# Every link is a pointer, so renaming the caster, the light or a derived part keeps the edit, and
# an object made later under an old name takes nothing over. Names of derived parts (shadow mesh,
# twin, collections) follow their owner's name when the edit is applied or its linking made again.

LINKING_TAG = "rokeby_shadow_linking"  # on the four linking collections: which role (they are ours)
_COLLECTION_ATTRS = ("receivers_caster", "blockers_caster", "receivers_edited", "blockers_edited")


def _registered() -> bool:
    import bpy  # noqa: PLC0415

    return hasattr(bpy.types.Object, "rokeby_shadow")


def _require_registered() -> None:
    if not _registered():
        raise ShadowEditError("the Rokeby add-on is not registered: call rokeby.register() first (in Blender: enable the add-on)")


def _role(ob) -> str:
    """'SHADOW_MESH', 'TWIN' or 'NONE'."""
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
    from . import compat  # noqa: PLC0415

    return compat.stored_group(o, "rokeby_shadow") is not None


def _parts():
    """(shadow meshes, twin lights, lights holding links) in the file, from the registry of what
    the add-on owns (no pass over every object)."""
    from . import registry  # noqa: PLC0415

    meshes, twins, lights = [], [], []
    if not _registered():
        return meshes, twins, lights
    for o in registry.shadow_objects():
        if not _stored(o):
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


RECEIVERS_CASTER, BLOCKERS_CASTER = "receivers (caster)", "blockers (caster)"
RECEIVERS_EDITED, BLOCKERS_EDITED = "receivers (edited)", "blockers (edited)"
_OURS = (RECEIVERS_CASTER, BLOCKERS_CASTER, RECEIVERS_EDITED, BLOCKERS_EDITED)


def _collection_name(light_name: str, role: str) -> str:
    return f"{light_name} · {role}"


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
    ll.receiver_collection, ll.blocker_collection = recv_a, block_a
    twin.light_linking.receiver_collection, twin.light_linking.blocker_collection = recv_b, block_b
    return twin


def _remove_collections(colls) -> None:
    import bpy  # noqa: PLC0415

    for c in colls:
        try:
            ours = c is not None and LINKING_TAG in c
        except ReferenceError:  # already removed (listed twice)
            continue
        if ours:
            bpy.data.collections.remove(c)


def _remove_twin(twin) -> None:
    """Deletes a twin light; the linking collections it used go with it unless its light still uses
    them (for a new twin): ``_collect_orphan_collections`` removes those nothing uses."""
    import bpy  # noqa: PLC0415

    bpy.data.objects.remove(twin, do_unlink=True)
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

    _remove_collections([c for c in bpy.data.collections if c.users == 0 and LINKING_TAG in c])


def _data_version() -> int:
    from .props import SHADOW_DATA_VERSION  # noqa: PLC0415

    return SHADOW_DATA_VERSION


def shadow_mesh_of(obj):
    """The shadow-mesh object of ``obj`` (a caster, or a shadow mesh itself), or None."""
    if obj is None or not _registered():
        return None
    if obj.rokeby_shadow.role == "SHADOW_MESH":
        return obj
    return next((o for o in _parts()[0] if o.rokeby_shadow.caster == obj), None)


def remove(obj) -> None:
    """Removes the shadow edit of ``obj`` (a caster or its shadow mesh): the shadow mesh, the twin
    light and the linking; the light's own linking before the edit comes back, so renders are
    exactly as before the edit."""
    import bpy  # noqa: PLC0415

    ob = shadow_mesh_of(obj)
    if ob is None:
        raise ShadowEditError(f"{getattr(obj, 'name', obj)!r} has no shadow edit")
    light = ob.rokeby_shadow.light
    me = ob.data
    bpy.data.objects.remove(ob, do_unlink=True)
    if me is not None and me.users == 0:
        bpy.data.meshes.remove(me)
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
        if missing is not None:
            if ob.visible_shadow:
                ob.visible_shadow = False
                links.switched_off = True
                msgs.append(f"'{ob.name}': its {missing} is gone; it no longer casts shadows (undo brings it back)")
            for attr in ("caster", "light"):
                # Deleted with X but kept in bpy.data by our own references: let Blender purge it,
                # as it does an object nothing uses.
                o = getattr(links, attr)
                if o is not None and not _in_scene(o) and _only_in_linking_collections(o):
                    setattr(links, attr, None)
            continue
        if links.switched_off:  # its caster and light are back (a collection linked to the scene again)
            ob.visible_shadow, links.switched_off = True, False
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
                 and all(c.name in colls[0].objects and s.name in colls[1].objects for c, s in edits))
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
        if "rokeby_shadow_of" in ob and "rokeby_light" in ob:
            links = ob.rokeby_shadow
            caster, light = objs.get(str(ob["rokeby_shadow_of"])), objs.get(str(ob["rokeby_light"]))
            links.role, links.caster, links.light, links.data_version = "SHADOW_MESH", caster, light, version
            del ob["rokeby_shadow_of"], ob["rokeby_light"]
            msgs.append(f"'{ob.name}': shadow mesh of {caster.name if caster else None!r} from {light.name if light else None!r}")
    for ob in local:
        if "rokeby_twin_of" in ob:
            light = objs.get(str(ob["rokeby_twin_of"]))
            light = light if light is not None and light.type == "LIGHT" else None
            t = ob.rokeby_shadow
            t.role, t.light, t.data_version = "TWIN", light, version
            if light is not None and light.rokeby_shadow.twin is None:
                light.rokeby_shadow.twin = ob
            del ob["rokeby_twin_of"]
            msgs.append(f"'{ob.name}': twin of {light.name if light else None!r}")
    for ob in local:
        if "rokeby_linking_before" in ob:
            before = [str(n) for n in ob["rokeby_linking_before"]] + ["", ""]
            links = ob.rokeby_shadow
            links.linking_saved = True
            links.receivers_before = colls.get(before[0]) if before[0] else None
            links.blockers_before = colls.get(before[1]) if before[1] else None
            for attr, role in zip(_COLLECTION_ATTRS, _OURS):
                c = colls.get(_collection_name(ob.name, role))
                if c is not None and c.library is None:
                    c[LINKING_TAG] = role
                    setattr(links, attr, c)
            del ob["rokeby_linking_before"]
            msgs.append(f"'{ob.name}': linking of its shadow edits")
    return msgs


def apply(session: ShadowSession, *, scene=None, falloff_beta: float = 0.0):
    """Makes (or updates) the shadow-mesh object of ``session``'s current edit and sets up the
    light and shadow linking. ``falloff_beta`` (β ≥ 0, §6.2) blends the edit back towards the
    original shadow as the light moves away from where the edit was made, (l_initial · l_current)^β.
    β is stored on the shadow object (custom property ``rokeby_falloff_beta``, editable); when it
    is > 0 the handlers apply it on every scene update and frame change (``sync_falloffs``). 0, the
    default, leaves the edit at full strength and the falloff to scripts (``update_falloff``).
    Returns (shadow object, twin light)."""
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
    disp = world - session.rest_world
    local = np.linalg.solve(session.matrix_world[:3, :3], disp.T).T
    with np.errstate(over="ignore", invalid="ignore"):
        if not (np.isfinite(world).all() and np.isfinite(local.astype(np.float32)).all()):
            raise ShadowEditError("the edited shadow mesh has non-finite or float32-overflowing positions (a drag too large?); "
                                  "nothing was written: undo the drag (cancel) and drag again")
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
    if ob is None:
        ob = bpy.data.objects.new(name, me.copy())
        for c in caster.users_collection:
            c.objects.link(ob)
    else:
        previous_light = ob.rokeby_shadow.light
        if not ob.name.startswith(name):
            ob.name = name
        if ob.data.users == 1 and len(ob.data.vertices) != n:
            ob.data = me.copy()
    # The edit lives in a shape key on the caster's rest shape, so the falloff of §6.2 can blend
    # between original (0) and shadow mesh (1) without touching the mesh again.
    ob.data.vertices.foreach_set("co", rest)
    if ob.data.shape_keys is None:
        ob.shape_key_add(name="Basis", from_mix=False)
    key = ob.data.shape_keys.key_blocks.get(EDIT_KEY) or ob.shape_key_add(name=EDIT_KEY, from_mix=False)
    ob.data.shape_keys.key_blocks["Basis"].data.foreach_set("co", rest)
    key.data.foreach_set("co", (rest.reshape(-1, 3) + local.astype(np.float32)).ravel())
    key.slider_min, key.slider_max = 0.0, 1.0
    key.value = 1.0
    ob.data.update()
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
    links = ob.rokeby_shadow
    links.role, links.caster, links.light, links.data_version = "SHADOW_MESH", caster, light, _data_version()
    ob["rokeby_light_initial"] = list(map(float, session.light_vector))
    ob["rokeby_falloff_beta"] = beta

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


def falloff_factor(shadow_object, light, beta: float, *, caster=None) -> float:
    """(l_initial · l_current)^β (§6.2; β = 0: no falloff) for the light's current position
    relative to the caster, without writing anything."""

    if _role(shadow_object) != "SHADOW_MESH":
        raise ShadowEditError(f"{getattr(shadow_object, 'name', shadow_object)!r} is not a Rokeby shadow mesh")
    caster = caster if caster is not None else shadow_object.rokeby_shadow.caster
    if caster is None:
        raise ShadowEditError(f"the caster of '{shadow_object.name}' no longer exists")
    kw = light_arguments(light)
    m = np.array(caster.matrix_world, dtype=np.float64)
    lv = kw.get("light_direction")
    if lv is None:
        lv = m[:3, 3] - kw["light_position"]
    cur = np.linalg.solve(m[:3, :3], lv)
    initial = np.asarray(shadow_object["rokeby_light_initial"], dtype=np.float64)
    return float(native.module().shadow_falloff(initial, cur, float(beta)))


def update_falloff(shadow_object, light, beta: float, *, caster=None) -> float:
    """Sets the shadow mesh's edit shape key to ``falloff_factor`` and returns it."""
    k = falloff_factor(shadow_object, light, beta, caster=caster)
    shadow_object.data.shape_keys.key_blocks[EDIT_KEY].value = k
    return k


def sync_falloffs(scene) -> int:
    """Brings every shadow mesh's falloff (§6.2) up to date with its light's current position;
    called by the add-on's depsgraph and frame-change handlers. Writes only values that changed
    (so the write itself settles); returns how many it wrote. Shadow meshes whose light or caster
    is gone keep their value."""

    written = 0
    from . import registry  # noqa: PLC0415

    for ob in _parts()[0]:
        if not registry.in_scene(ob, scene):
            continue
        light = ob.rokeby_shadow.light
        keys = ob.data.shape_keys
        if light is None or light.type != "LIGHT" or keys is None or EDIT_KEY not in keys.key_blocks:
            continue
        beta = float(ob.get("rokeby_falloff_beta", 0.0))
        if not (np.isfinite(beta) and beta > 0.0):
            continue  # β = 0: no automatic falloff; the key stays as apply or a script set it
        try:
            k = falloff_factor(ob, light, beta)
        except (ShadowEditError, ValueError, np.linalg.LinAlgError):
            continue
        if abs(k - keys.key_blocks[EDIT_KEY].value) > 1e-6:
            keys.key_blocks[EDIT_KEY].value = k
            written += 1
    return written
