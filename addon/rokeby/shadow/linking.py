"""Light and shadow linking of shadow edits (Cycles, and EEVEE in 4.5; see docs/shadow_editing.md):
the original light keeps lighting the caster with the caster's own (self-)shadows and no shadow
from the shadow mesh; a twin of the light lights every other object, blocked by the shadow mesh
and everything else but the original caster. So receivers show the edited shadow and the caster
shows no self-shadow artefacts from the shadow mesh.

The parts of an edit refer to each other by pointer (``obj.rokeby_shadow``, props.RokebyShadowLinks):
the shadow mesh to its caster and light, the light to its twin and linking collections, the twin to
its light. This module finds the parts (the add-on's object index), makes and takes down the
linking, and removes an edit (:func:`remove`)."""

from __future__ import annotations

from ..blender import compat, transaction
from ..blender import registry as index
from ..core import schema
from .errors import ShadowEditError

TWIN_SUFFIX = " (edited shadows)"


# --- Links between the parts of an edit (props.RokebyShadowLinks, ``obj.rokeby_shadow``) -----------
# Every link is a pointer, so renaming the caster, the light or a derived part keeps the edit, and
# an object made later under an old name takes nothing over. Names of derived parts (shadow mesh,
# twin, collections) follow their owner's name when the edit is applied or its linking made again.

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
    return all(schema.SHADOW_LINKING_TAG in c for c in ob.users_collection)


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
    c[schema.SHADOW_LINKING_TAG] = role
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
        ours = lambda c: c is not None and schema.SHADOW_LINKING_TAG in c  # noqa: E731
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
            ours = c is not None and schema.SHADOW_LINKING_TAG in c
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
    _remove_collections([c for c in bpy.data.collections if c.users == 0 and schema.SHADOW_LINKING_TAG in c])


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
