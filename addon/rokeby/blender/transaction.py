"""All or nothing for the operations that edit Blender data: ``all_or_nothing()``
records what an operation of the add-on may change and, when the operation raises, puts it back,
so an exception half way (a bug, a bad value found late, a full disk, Esc) leaves the file exactly
as it was. Feature-agnostic (the Blender layer); the features wrap their operations in it.

What is recorded: which data-blocks exist (those made since are removed again); the custom
properties of objects, meshes, materials, lights, collections, images, node groups and scenes
(the add-on's property groups live there); every node tree's nodes, links, node properties, group
assignments and input values (``blender.nodes.snapshot``); the add-on's mesh attributes (``rokeby*``,
data included) and shape-key positions; which objects and child collections each collection
holds; objects' ray visibility, pass index, display, parent, data and light linking; materials'
pass index; the view layers' passes and AOVs and the output format.

Deleting inside an operation cannot be undone, so the operations delete through ``remove``:
inside ``all_or_nothing`` an object is taken out of its collections at once (the rest of the
operation sees it gone from the scene, ``doomed`` tells) and every data-block is deleted only when
the operation has succeeded; ``later`` defers clean-ups (orphan collections) the same way."""

from __future__ import annotations

import contextlib

import numpy as np

from ..core import schema

_KINDS = ("objects", "meshes", "materials", "node_groups", "images", "lights", "cameras", "collections", "worlds", "texts")
_OBJECT_FLAGS = ("hide_render", "visible_camera", "visible_diffuse", "visible_glossy", "visible_transmission",
                 "visible_volume_scatter", "visible_shadow", "pass_index", "display_type", "hide_select")

_active: list = []


# Registered properties (obj.rokeby, ...) are kept apart from custom properties from Blender 5.0
# (compat.system_properties); a record holds them under this key beside the custom ones.
_SYSTEM = "\x00system"


def _plain_props(container) -> dict:
    out = {}
    for k in container.keys():
        v = container[k]
        out[k] = v.to_dict() if hasattr(v, "to_dict") else (v.to_list() if hasattr(v, "to_list") else v)
    return out


def _system(owner):
    from . import compat  # noqa: PLC0415  (bpy-free at import)

    return compat.system_properties(owner)


def _idprops(owner) -> dict:
    out = _plain_props(owner)
    sysg = _system(owner)
    if sysg is not None and len(sysg.keys()):
        out[_SYSTEM] = _plain_props(sysg)
    return out


def _has_props(owner) -> bool:
    if len(owner.keys()):
        return True
    sysg = _system(owner)
    return sysg is not None and bool(len(sysg.keys()))


def _load_into(container, saved: dict) -> None:
    for k in [k for k in container.keys() if k not in saved]:
        del container[k]
    for k, v in saved.items():
        cur = container.get(k)
        if isinstance(v, dict) and hasattr(cur, "clear") and hasattr(cur, "update"):
            cur.clear()
            cur.update(v)
        else:
            container[k] = v


def _load_idprops(owner, saved: dict) -> None:
    saved = dict(saved)
    system = saved.pop(_SYSTEM, {})
    _load_into(owner, saved)
    sysg = _system(owner)
    if sysg is not None:
        _load_into(sysg, system)


def _groups_used(trees) -> list:
    """The node groups ``trees`` use, at any depth, and the add-on's own (rebuilt in place)."""
    import bpy  # noqa: PLC0415

    out, todo = {}, list(trees)
    while todo:
        t = todo.pop()
        for nd in t.nodes:
            g = getattr(nd, "node_tree", None)
            if g is not None and g.library is None and g.as_pointer() not in out:
                out[g.as_pointer()] = g
                todo.append(g)
    for g in bpy.data.node_groups:
        if g.library is None and g.name.startswith(schema.NODE_GROUP_PREFIX):
            out.setdefault(g.as_pointer(), g)
    return list(out.values())


class Transaction:
    def __init__(self, materials=None):
        """``materials``: the materials whose node trees the operation may edit (None: all; a
        big file's every tree costs about 1.4 ms per material to record)."""

        import bpy  # noqa: PLC0415

        from . import nodes as node_trees  # noqa: PLC0415

        d = bpy.data
        self.removed: list = []
        self.renamed: list = []
        self.nodes: list = []
        self.hooks: list = []
        self.undo_hooks: list = []
        self.end_hooks: list = []
        self.ids = {k: {i.as_pointer() for i in getattr(d, k)} for k in _KINDS}
        owners = [*d.objects, *d.meshes, *d.materials, *d.lights, *d.collections, *d.images, *d.node_groups, *d.scenes]
        self.props = [(o, _idprops(o)) for o in owners if o.library is None and _has_props(o)]
        self.bare = [o for o in owners if o.library is None and not _has_props(o)]
        mats = d.materials if materials is None else [m for m in dict.fromkeys(materials) if m is not None]
        trees = [m.node_tree for m in mats if m.node_tree is not None and m.library is None]
        trees += [g for g in d.node_groups if g.library is None] if materials is None else _groups_used(trees)
        self.trees = []
        for t in trees:
            snap = node_trees.snapshot(t, ())
            snap["values"] = {(nd.as_pointer(), s.identifier): _copy(s.default_value)
                              for nd in t.nodes for s in nd.inputs if hasattr(s, "default_value")}
            snap["node_props"] = [(nd, _idprops(nd)) for nd in t.nodes]
            self.trees.append((t, snap))
        self.attributes = []
        for me in d.meshes:
            if me.library is not None:
                continue
            ours = {}
            for a in me.attributes:
                if a.name.startswith("rokeby"):
                    ours[a.name] = (a.domain, a.data_type, _read(a))
            names = {a.name for a in me.attributes}
            keys = None
            if me.shape_keys is not None:
                keys = {}
                for kb in me.shape_keys.key_blocks:
                    co = np.empty(len(kb.data) * 3, np.float32)
                    kb.data.foreach_get("co", co)
                    keys[kb.name] = (co, kb.value)
            self.attributes.append((me, names, ours, keys))
        self.members = [(c, set(c.objects), set(c.children)) for c in d.collections if c.library is None]
        self.members += [(sc.collection, set(sc.collection.objects), set(sc.collection.children)) for sc in d.scenes]
        self.objects = []
        for ob in d.objects:
            if ob.library is not None:
                continue
            ll = getattr(ob, "light_linking", None)
            self.objects.append((ob, {a: getattr(ob, a) for a in _OBJECT_FLAGS if hasattr(ob, a)}, ob.data, ob.parent,
                                 ob.matrix_basis.copy(),  # not matrix_world: stale until the depsgraph runs
                                 (ll.receiver_collection, ll.blocker_collection) if ll is not None else None,
                                 [_modifier(m) for m in ob.modifiers]))
        self.materials = [(m, m.pass_index, m.use_nodes) for m in d.materials if m.library is None]
        self.render = [(s, _rna_values(s)) for sc in d.scenes for s in (sc.render, sc.render.image_settings, sc.cycles)
                       if s is not None]
        self.layers = []
        for sc in d.scenes:
            st = sc.render.image_settings
            self.layers.append((sc, sc.camera, (st.file_format, st.color_depth, st.color_mode), [
                (vl, {a: getattr(vl, a) for a in dir(vl) if a.startswith("use_pass_")}, [a.name for a in vl.aovs])
                for vl in sc.view_layers]))

    # --- deleting ---------------------------------------------------------------------------------

    def remove(self, idb) -> None:
        import bpy  # noqa: PLC0415

        if isinstance(idb, bpy.types.Object):
            for c in list(idb.users_collection):
                c.objects.unlink(idb)
        elif isinstance(idb, bpy.types.Collection):
            for parent in [*bpy.data.collections, *(sc.collection for sc in bpy.data.scenes)]:
                if idb in set(parent.children):
                    parent.children.unlink(idb)
        if not self.doomed(idb):
            # Its name is free at once, as after a deletion (a replacement may take it).
            self.renamed.append((idb, idb.name))
            idb.name = f"{idb.name} (deleted)"
        self.removed.append(idb)

    def doomed(self, idb) -> bool:
        try:
            return any(idb == r for r in self.removed)
        except ReferenceError:
            return False

    # --- the end ----------------------------------------------------------------------------------

    def commit(self) -> None:
        import bpy  # noqa: PLC0415

        for idb in self.removed:
            try:
                coll = _collection_of(idb)
                if isinstance(idb, bpy.types.Object):
                    coll.remove(idb, do_unlink=True)
                else:
                    coll.remove(idb)
            except ReferenceError:  # removed with something else
                pass
        for tree, node in self.nodes:
            try:
                tree.nodes.remove(node)
            except (ReferenceError, RuntimeError):  # removed with its tree, or twice
                pass
        for fn in self.hooks:  # clean-ups after success: best effort, never an error
            try:
                fn()
            except Exception as exc:  # noqa: BLE001
                print(f"rokeby: clean-up after the operation failed: {exc}")

    def rollback(self) -> None:  # noqa: C901 - one pass per kind of data
        import bpy  # noqa: PLC0415

        from . import nodes as node_trees  # noqa: PLC0415

        d = bpy.data
        for fn in reversed(self.undo_hooks):
            try:
                fn()
            except Exception:  # noqa: BLE001 - a clean-up of temporary files: the rest still goes back
                pass
        alive = {i.as_pointer() for k in _KINDS for i in getattr(d, k)} | {sc.as_pointer() for sc in d.scenes}
        self.props = [(o, s) for o, s in self.props if o.as_pointer() in alive]
        self.bare = [o for o in self.bare if o.as_pointer() in alive]
        for ob, flags, data, parent, matrix, linking, mods in self.objects:
            try:
                _load_modifiers(ob, mods)
                if ob.data != data:
                    ob.data = data
                if ob.parent != parent:
                    ob.parent = parent
                if ob.matrix_basis != matrix:
                    ob.matrix_basis = matrix
                for a, v in flags.items():
                    if getattr(ob, a) != v:
                        setattr(ob, a, v)
                if linking is not None:
                    ll = ob.light_linking
                    if (ll.receiver_collection, ll.blocker_collection) != linking:
                        ll.receiver_collection, ll.blocker_collection = linking
            except ReferenceError:
                pass
        for coll, objects, children in self.members:
            for ob in set(coll.objects) - objects:
                coll.objects.unlink(ob)
            for ob in objects - set(coll.objects):
                coll.objects.link(ob)
            for ch in set(coll.children) - children:
                coll.children.unlink(ch)
            for ch in children - set(coll.children):
                coll.children.link(ch)
        for tree, snap in self.trees:
            node_trees.restore(tree, snap)
            nodes = {nd.as_pointer(): nd for nd in tree.nodes}
            for (ptr, ident), value in snap["values"].items():
                nd = nodes.get(ptr)
                sock = next((s for s in nd.inputs if s.identifier == ident), None) if nd is not None else None
                if sock is not None and _copy(sock.default_value) != value:
                    sock.default_value = value
            for nd, saved in snap["node_props"]:
                if nd.as_pointer() in nodes and _idprops(nd) != saved:
                    _load_idprops(nd, saved)
        for me, names, ours, keys in self.attributes:
            for name in [a.name for a in me.attributes if a.name not in names and not a.name.startswith(".")]:
                a = me.attributes.get(name)
                if a is not None:
                    me.attributes.remove(a)
            for name, (domain, kind, values) in ours.items():
                a = me.attributes.get(name)
                if a is None:
                    a = me.attributes.new(name, kind, domain)
                elif values is not None and np.array_equal(_read(a), values):
                    continue
                _write(a, values)
            if keys is not None and me.shape_keys is not None:
                for kb in me.shape_keys.key_blocks:
                    if kb.name in keys:
                        co, value = keys[kb.name]
                        if len(kb.data) * 3 == len(co):
                            kb.data.foreach_set("co", co)
                        kb.value = value
        for m, pass_index, use_nodes in self.materials:
            if m.pass_index != pass_index:
                m.pass_index = pass_index
            if m.use_nodes != use_nodes:
                m.use_nodes = use_nodes
        for sc, camera, fmt, layers in self.layers:
            if sc.camera != camera:
                sc.camera = camera
            st = sc.render.image_settings
            if (st.file_format, st.color_depth, st.color_mode) != fmt:
                st.file_format = fmt[0]
                st.color_depth, st.color_mode = fmt[1], fmt[2]
            for vl, passes, aovs in layers:
                for a, v in passes.items():
                    if getattr(vl, a) != v:
                        setattr(vl, a, v)
                for aov in [a for a in vl.aovs if a.name not in aovs]:
                    vl.aovs.remove(aov)
        for struct, values in self.render:
            for a, v in values.items():
                try:
                    if getattr(struct, a) != v:
                        setattr(struct, a, v)
                except (AttributeError, TypeError, ValueError):
                    pass
        for owner, saved in self.props:
            if _idprops(owner) != saved:  # untouched ones are left alone
                _load_idprops(owner, saved)
        for owner in self.bare:
            _load_idprops(owner, {})
        # Data-blocks made since go (objects first: they use the rest).
        for kind in _KINDS:
            new = [i for i in getattr(d, kind) if i.as_pointer() not in self.ids[kind]]
            for i in new:
                if kind == "objects":
                    d.objects.remove(i, do_unlink=True)
                else:
                    getattr(d, kind).remove(i)
        for idb, name in reversed(self.renamed):
            try:
                idb.name = name
            except ReferenceError:
                pass


def _rna_values(struct) -> dict:
    """The plain settings of ``struct`` (render settings: what a capture or a pass set-up sets)."""
    out = {}
    for p in struct.bl_rna.properties:
        if p.is_readonly or p.type not in {"BOOLEAN", "INT", "FLOAT", "ENUM", "STRING"} or getattr(p, "is_array", False):
            continue
        if p.type == "ENUM" and p.is_enum_flag:
            continue
        out[p.identifier] = getattr(struct, p.identifier)
    return out


def _modifier(m) -> tuple:
    from . import compat  # noqa: PLC0415  (bpy-free at import)

    return (m.name, m.type, getattr(m, "node_group", None), compat.modifier_inputs(m) if m.type == "NODES" else {},
            m.show_viewport, m.show_render, m.show_in_editmode)


def _load_modifiers(ob, mods) -> None:
    """Modifiers added since go; geometry-node modifiers removed since (the add-on's are) come
    back with their group, inputs and place in the stack."""
    from . import compat  # noqa: PLC0415  (bpy-free at import)

    names = [m[0] for m in mods]
    for m in [m for m in ob.modifiers if m.name not in names]:
        ob.modifiers.remove(m)
    for i, (name, kind, group, props, show_v, show_r, show_e) in enumerate(mods):
        m = ob.modifiers.get(name)
        if m is None and kind == "NODES":
            m = ob.modifiers.new(name, kind)
            m.node_group = group
            m.show_viewport, m.show_render, m.show_in_editmode = show_v, show_r, show_e
            compat.set_modifier_inputs(m, props)
            at = list(ob.modifiers).index(m)
            if at != i and i < len(ob.modifiers):
                ob.modifiers.move(at, i)
        elif m is not None and kind == "NODES":
            if m.node_group != group:
                m.node_group = group
            compat.set_modifier_inputs(m, props)


def _collection_of(idb):
    """The ``bpy.data`` collection holding ``idb``."""
    import bpy  # noqa: PLC0415

    t = bpy.types
    for kind, cls in (("objects", t.Object), ("meshes", t.Mesh), ("materials", t.Material), ("node_groups", t.NodeTree),
                      ("images", t.Image), ("lights", t.Light), ("cameras", t.Camera), ("collections", t.Collection),
                      ("worlds", t.World), ("texts", t.Text)):
        if isinstance(idb, cls):
            return getattr(bpy.data, kind)
    raise TypeError(f"transaction.remove: cannot delete a {type(idb).__name__}")


_ATTR = {"FLOAT": ("value", 1), "INT": ("value", 1), "FLOAT_VECTOR": ("vector", 3), "FLOAT_COLOR": ("color", 4),
         "FLOAT2": ("vector", 2), "QUATERNION": ("value", 4), "BOOLEAN": ("value", 1), "INT8": ("value", 1)}
_DTYPE = {"INT": np.int32, "BOOLEAN": bool, "INT8": np.int8}


def _read(a):
    key, width = _ATTR.get(a.data_type, (None, 0))
    if key is None:
        return None
    buf = np.empty(len(a.data) * width, _DTYPE.get(a.data_type, np.float32))
    a.data.foreach_get(key, buf)
    return buf


def _write(a, values) -> None:
    key, _w = _ATTR.get(a.data_type, (None, 0))
    if key is not None and values is not None:
        a.data.foreach_set(key, values)


def _copy(v):
    return tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v


@contextlib.contextmanager
def all_or_nothing(materials=None):
    """Run the ``with`` block all or nothing (see the module); ``materials``: the only materials
    whose node trees it may edit (None: any). Nested blocks belong to the outermost one."""
    if _active:
        yield _active[-1]
        return
    tx = Transaction(materials)
    _active.append(tx)
    try:
        yield tx
        while tx.end_hooks:  # still part of the operation: a failure here rolls back too
            tx.end_hooks.pop(0)()
    except BaseException:
        _active.pop()
        tx.rollback()
        raise
    _active.pop()
    tx.commit()


def atomic(fn=None, *, materials=None):
    """Decorator: ``fn`` runs inside ``all_or_nothing``; ``materials(*args, **kwargs)`` names
    the materials it may edit (default: any). ``@atomic`` or ``@atomic(materials=…)``."""
    import functools  # noqa: PLC0415

    def wrap(fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            if _active:  # nested: the outer operation's record covers it
                return fn(*args, **kwargs)
            with all_or_nothing(None if materials is None else list(materials(*args, **kwargs))):
                return fn(*args, **kwargs)
        return wrapper
    return wrap if fn is None else wrap(fn)


def none(*_args, **_kwargs) -> list:
    """For ``atomic(materials=none)``: the operation edits no material."""
    return []


def of_object(obj=None, material=None, *_args, **kwargs) -> list:
    """For ``atomic(materials=of_object)``: ``material`` (or ``kwargs['material']``) and the
    materials of ``obj``."""
    out = [material, kwargs.get("material")]
    try:
        out += [s.material for s in obj.material_slots]
    except (AttributeError, ReferenceError):
        pass
    import bpy  # noqa: PLC0415

    return [m for m in out if isinstance(m, bpy.types.Material)]


def remove(idb) -> None:
    """Delete the data-block ``idb``: now outside ``all_or_nothing``, when it succeeds inside
    (an object leaves its collections at once)."""
    import bpy  # noqa: PLC0415

    if _active:
        _active[-1].remove(idb)
        return
    kind = _collection_of(idb)
    if isinstance(idb, bpy.types.Object):
        kind.remove(idb, do_unlink=True)
    else:
        kind.remove(idb)


def write_whole(path, write) -> None:
    """``write(tmp)`` to a temporary file next to ``path``, then renamed over it: a failed or
    interrupted write leaves no partial file, and an existing ``path`` as it was. bpy-free."""
    import os  # noqa: PLC0415

    folder, name = os.path.split(os.path.abspath(str(path)))
    tmp = os.path.join(folder, f".{name}.partial-{os.getpid()}{os.path.splitext(name)[1]}")
    try:
        write(tmp)
        os.replace(tmp, str(path))
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def remove_node(tree, node) -> None:
    """Delete ``node`` from ``tree``: now outside ``all_or_nothing``; inside, its links go at once
    and it is tagged ``schema.DOOMED_KEY`` (the add-on's node tests skip it), deleted when the operation
    succeeds."""
    if not _active:
        tree.nodes.remove(node)
        return
    for lk in [lk for lk in tree.links if lk.from_node == node or lk.to_node == node]:
        tree.links.remove(lk)
    node[schema.DOOMED_KEY] = True
    _active[-1].nodes.append((tree, node))


def live(node) -> bool:
    """Whether ``node`` is not waiting for its deletion (``remove_node``)."""
    return not node.get(schema.DOOMED_KEY)


def remove_unused(idb) -> None:
    """Delete ``idb`` if nothing uses it: checked now outside ``all_or_nothing``, once the
    deletions are done when it succeeds inside."""
    def drop():
        try:
            if idb.users == 0:
                _collection_of(idb).remove(idb)
        except ReferenceError:
            pass
    later(drop)


def at_end(fn) -> None:
    """Run ``fn`` as the last step of the running operation (still undone if it fails), or now."""
    if _active:
        _active[-1].end_hooks.append(fn)
    else:
        fn()


def on_rollback(fn) -> None:
    """Run ``fn`` if the running operation fails (e.g. delete its temporary files)."""
    if _active:
        _active[-1].undo_hooks.append(fn)


def active() -> bool:
    """Whether an operation runs inside ``all_or_nothing``."""
    return bool(_active)


def later(fn) -> None:
    """Run ``fn`` now outside ``all_or_nothing``, after the deletions when it succeeds inside."""
    if _active:
        _active[-1].hooks.append(fn)
    else:
        fn()


def doomed(idb) -> bool:
    """Whether ``idb`` is deleted when the running operation succeeds."""
    return bool(_active) and _active[-1].doomed(idb)
