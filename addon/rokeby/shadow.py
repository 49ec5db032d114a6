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


@dataclass
class ShadowSession:
    """One editing session: the native editor and what it was made from."""

    editor: object
    caster: str
    light: str
    receivers: list
    light_vector: np.ndarray
    rest_world: np.ndarray
    matrix_world: np.ndarray
    history: list = field(default_factory=list)

    def loops(self):
        return self.editor.loops()

    def handles(self, loop: int = 0, eye=None):
        return self.editor.handles(loop, eye)

    def drag(self, loop: int, fixed, moved: int, target, **kwargs):
        """One drag step (receiver point ``target`` under the cursor), relative to the last commit."""
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
    if receivers is None:
        receivers = [o for o in sc.objects if o.type == "MESH" and o is not caster and not o.name.endswith(SHADOW_SUFFIX)
                     and o.visible_get()]
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
    return ShadowSession(ed, caster.name, light.name, [o.name for o in receivers], lv_local / np.linalg.norm(lv_local),
                         np.asarray(cm.vertices, np.float64), m)


def _linking_collection(name: str):
    import bpy  # noqa: PLC0415

    c = bpy.data.collections.get(name)
    if c is None:
        c = bpy.data.collections.new(name)
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


def _edits_of(light_name: str):
    """(caster, shadow mesh) of every shadow edit made from the light named ``light_name`` whose
    caster still exists."""
    import bpy  # noqa: PLC0415

    out = []
    for ob in _shadow_meshes():
        caster = bpy.data.objects.get(str(ob["rokeby_shadow_of"]))
        if str(ob["rokeby_light"]) == light_name and caster is not None:
            out.append((caster, ob))
    return out


def _link(light):
    """The light and shadow linking of the edits made from ``light`` (made again whenever a part
    of it is missing): ``light`` lights only the casters, blocked by everything but the shadow
    meshes; a twin of the light (same light data, parented with an identity offset so it follows
    every move) lights every other object, blocked by everything but the casters. The light's own
    linking before the first edit is remembered on it (``rokeby_linking_before``) so
    :func:`remove` restores it."""
    import bpy  # noqa: PLC0415

    ll = light.light_linking
    if "rokeby_linking_before" not in light:
        ours = lambda c: c is not None and c.name.startswith(light.name + " · ") and c.name.rsplit(" · ", 1)[1] in _OURS  # noqa: E731
        light["rokeby_linking_before"] = [
            "" if c is None or ours(c) else c.name for c in (ll.receiver_collection, ll.blocker_collection)
        ]
    twin_name = light.name + TWIN_SUFFIX
    twin = bpy.data.objects.get(twin_name)
    if twin is None:
        twin = bpy.data.objects.new(twin_name, light.data)
        for c in light.users_collection:
            c.objects.link(twin)
    twin["rokeby_twin_of"] = light.name
    twin.parent = light
    twin.matrix_parent_inverse.identity()
    twin.location, twin.rotation_mode, twin.rotation_euler, twin.scale = (0.0, 0.0, 0.0), "XYZ", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)
    edits = _edits_of(light.name)
    recv_a = _linking_collection(_collection_name(light.name, RECEIVERS_CASTER))
    block_a = _linking_collection(_collection_name(light.name, BLOCKERS_CASTER))
    recv_b = _linking_collection(_collection_name(light.name, RECEIVERS_EDITED))
    block_b = _linking_collection(_collection_name(light.name, BLOCKERS_EDITED))
    for caster, shadow_object in edits:
        _set_state(recv_a, caster, "INCLUDE")
        _set_state(block_a, shadow_object, "EXCLUDE")
        _set_state(recv_b, caster, "EXCLUDE")
        _set_state(block_b, caster, "EXCLUDE")
    ll.receiver_collection, ll.blocker_collection = recv_a, block_a
    twin.light_linking.receiver_collection, twin.light_linking.blocker_collection = recv_b, block_b
    return twin


def _unlink(light_name: str) -> None:
    """Takes an edit's linking down: the twin and the four collections go, the light (if it is
    still there) gets back the linking it had before the first edit."""
    import bpy  # noqa: PLC0415

    light = bpy.data.objects.get(light_name)
    if light is not None and light.type == "LIGHT":
        before = list(light.get("rokeby_linking_before", ["", ""]))
        ll = light.light_linking
        ll.receiver_collection = bpy.data.collections.get(before[0]) if before[0] else None
        ll.blocker_collection = bpy.data.collections.get(before[1]) if before[1] else None
        if "rokeby_linking_before" in light:
            del light["rokeby_linking_before"]
    for ob in [o for o in bpy.data.objects if o.get("rokeby_twin_of") == light_name]:
        bpy.data.objects.remove(ob, do_unlink=True)
    for role in _OURS:
        c = bpy.data.collections.get(_collection_name(light_name, role))
        if c is not None:
            bpy.data.collections.remove(c)


def _shadow_meshes():
    from . import registry  # noqa: PLC0415 - what the add-on owns: no pass over every object

    return [o for o in registry.shadow_objects() if "rokeby_shadow_of" in o and "rokeby_light" in o]


def shadow_mesh_of(obj):
    """The shadow-mesh object of ``obj`` (a caster, or a shadow mesh itself), or None."""
    if obj is None:
        return None
    if "rokeby_shadow_of" in obj:
        return obj
    return next((o for o in _shadow_meshes() if o["rokeby_shadow_of"] == obj.name), None)


def remove(obj) -> None:
    """Removes the shadow edit of ``obj`` (a caster or its shadow mesh): the shadow mesh, the twin
    light and the linking; the light's own linking before the edit comes back, so renders are
    exactly as before the edit."""
    import bpy  # noqa: PLC0415

    ob = shadow_mesh_of(obj)
    if ob is None:
        raise ShadowEditError(f"{getattr(obj, 'name', obj)!r} has no shadow edit")
    light_name = str(ob["rokeby_light"])
    me = ob.data
    bpy.data.objects.remove(ob, do_unlink=True)
    if me is not None and me.users == 0:
        bpy.data.meshes.remove(me)
    light = bpy.data.objects.get(light_name)
    if _edits_of(light_name) and light is not None and light.type == "LIGHT":
        _link(light)  # other casters' edits from the same light stay
    else:
        _unlink(light_name)


def repair(scene=None) -> list[str]:
    """Keeps shadow edits whole when an artist deletes something they use (called by the
    handlers; writes only when something is broken, so the update it causes settles):

    * caster or light gone: the shadow mesh is kept (undo or a new light can use it) but hidden
      from shadow rays, and the linking is taken down, so the remaining lights shade as without
      the edit;
    * shadow mesh gone: the twin and the linking go, the light's own linking comes back;
    * twin light or a linking collection gone: made again from the shadow mesh.

    Returns one message per repair."""
    import bpy  # noqa: PLC0415

    msgs = []
    live = set()
    for ob in _shadow_meshes():
        caster = bpy.data.objects.get(str(ob["rokeby_shadow_of"]))
        light = bpy.data.objects.get(str(ob["rokeby_light"]))
        missing = "caster" if caster is None else ("light" if light is None or light.type != "LIGHT" else None)
        if missing is not None:
            if ob.visible_shadow:
                ob.visible_shadow = False
                msgs.append(f"'{ob.name}': its {missing} is gone; it no longer casts shadows (undo brings it back)")
            continue
        live.add(light.name)
    for name in sorted(live):
        light = bpy.data.objects[name]
        twin = bpy.data.objects.get(name + TWIN_SUFFIX)
        colls = [bpy.data.collections.get(_collection_name(name, r)) for r in _OURS]
        ll = light.light_linking
        edits = _edits_of(name)
        whole = (twin is not None and twin.get("rokeby_twin_of") == name and twin.parent == light and None not in colls
                 and ll.receiver_collection == colls[0] and ll.blocker_collection == colls[1]
                 and twin.light_linking.receiver_collection == colls[2] and twin.light_linking.blocker_collection == colls[3]
                 and all(c.name in colls[0].objects and s.name in colls[1].objects for c, s in edits))
        if not whole:
            _link(light)
            msgs.append(f"'{name}': the twin light or linking of its shadow edit was missing and is made again")
    from . import registry  # noqa: PLC0415

    for twin in [o for o in registry.shadow_objects() if "rokeby_twin_of" in o]:
        name = str(twin["rokeby_twin_of"])
        if name not in live:
            _unlink(name)
            msgs.append(f"'{name}': its shadow edit is gone; the twin light and the linking are removed")
    if msgs and scene is not None:
        scene.view_layers[0].update()
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

    sc = scene if scene is not None else bpy.context.scene
    caster = bpy.data.objects.get(session.caster)
    light = bpy.data.objects.get(session.light)
    if caster is None or light is None:
        raise ShadowEditError("the caster or the light of this session no longer exists")
    world = np.asarray(session.shadow_mesh(), dtype=np.float64)
    if world.shape != session.rest_world.shape:
        raise ShadowEditError("the caster's vertex count changed since the session started; start a new one")
    disp = world - session.rest_world
    local = np.linalg.solve(session.matrix_world[:3, :3], disp.T).T
    me = caster.data
    n = len(me.vertices)
    if n != len(world):
        raise ShadowEditError(f"the shadow mesh has {len(world)} vertices but '{caster.name}' has {n}: modifiers that change "
                              "the topology (subdivision, boolean) must be applied first")
    rest = np.empty(n * 3, np.float32)
    me.vertices.foreach_get("co", rest)
    name = caster.name + SHADOW_SUFFIX
    ob = bpy.data.objects.get(name)
    if ob is None:
        ob = bpy.data.objects.new(name, me.copy())
        for c in caster.users_collection:
            c.objects.link(ob)
    elif ob.data.users == 1 and len(ob.data.vertices) != n:
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
    ob["rokeby_shadow_of"] = caster.name
    ob["rokeby_light_initial"] = list(map(float, session.light_vector))
    ob["rokeby_light"] = light.name
    ob["rokeby_falloff_beta"] = beta

    twin = _link(light)
    sc.view_layers[0].update()
    return ob, twin


def falloff_factor(shadow_object, light, beta: float, *, caster=None) -> float:
    """(l_initial · l_current)^β (§6.2; β = 0: no falloff) for the light's current position
    relative to the caster, without writing anything."""
    import bpy  # noqa: PLC0415

    if shadow_object is None or "rokeby_shadow_of" not in shadow_object:
        raise ShadowEditError(f"{getattr(shadow_object, 'name', shadow_object)!r} is not a Rokeby shadow mesh")
    caster = caster if caster is not None else bpy.data.objects.get(shadow_object["rokeby_shadow_of"])
    if caster is None:
        raise ShadowEditError(f"the caster '{shadow_object['rokeby_shadow_of']}' of this shadow mesh no longer exists")
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
    import bpy  # noqa: PLC0415

    written = 0
    for ob in _shadow_meshes():
        light = bpy.data.objects.get(str(ob["rokeby_light"]))
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
