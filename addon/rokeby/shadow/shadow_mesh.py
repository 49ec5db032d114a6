"""The shadow-mesh object of an edit (:func:`apply`): a copy of the caster's mesh with the edited
vertex positions in a shape key, the same vertex groups and armature modifiers (so skeletal
animation carries the edit, §6.2), visible to shadow rays only (``visible_camera`` and the other
ray visibilities off); and, for edits of the caster's self-shadows, its self-shadow mesh.

Edits are made at the current frame in world space. The shadow mesh stores them as local
displacements of the caster's rest vertices (world displacement rotated by the inverse object
matrix); with an armature this is exact for edits made in the rest pose and approximate for
edits made in other poses (the per-vertex skinning rotation is not undone)."""

from __future__ import annotations

import numpy as np

from ..blender import transaction
from ..core import schema
from .configurations import _drop_configurations, configuration_key, configuration_vectors, configuration_weights
from .errors import ShadowEditError
from .linking import (
    _collect_orphan_collections,
    _data_version,
    _edits_of,
    _in_scene,
    _is_light,
    _link,
    _require_registered,
    _unlink,
    shadow_mesh_of,
)
from .session import ShadowSession

SHADOW_SUFFIX = " Shadow Mesh"
RAY_VISIBILITY = ("visible_camera", "visible_diffuse", "visible_glossy", "visible_transmission", "visible_volume_scatter")


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
    with np.errstate(over="ignore", invalid="ignore"):  # an overflowing drag is refused below, not warned about
        disp = np.asarray(world, np.float64) - session.rest_world
        local = disp @ np.linalg.inv(session.matrix_world[:3, :3]).T  # one 3x3 inverse: fast per drag step
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
