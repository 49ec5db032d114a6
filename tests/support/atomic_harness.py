"""Fault injection for "all or nothing": a snapshot of everything an operation of the
add-on may change (materials' and node groups' node trees, objects' custom properties, attributes,
shape keys, modifiers and linking, collections, images, the scene's passes and render settings,
and the files of a folder), and ``each_fault``, which runs an operation once for every internal
step, with an exception injected at that step.

The steps are the calls of Python functions of the add-on (``addon/rokeby``) made by the
operation (found with ``sys.settrace``), optionally every executed line: a fault at the k-th
stands for any helper, node creation or file write failing there. Calls made from Blender's
handlers and property-update callbacks while the operation runs (a depsgraph update, setting a
property) are not faulted: Blender prints and swallows their exceptions, they never reach the
operation."""

from __future__ import annotations

import hashlib
import math
import os
import re
import sys
from pathlib import Path

import numpy as np

ADDON = str(Path(__file__).resolve().parents[2] / "addon" / "rokeby")


class InjectedFault(Exception):
    """The exception ``each_fault`` injects."""


# --- the snapshot ---------------------------------------------------------------------------------

_RANDOM_ID = re.compile(r"[0-9a-f]{12,32}")


def _plain(v, depth=0):
    """A comparable plain value for an ID property, an RNA value or a bpy struct. (Called about a
    million times per fault-injection test: the common scalar types are tested first, by type.)"""
    t = type(v)
    if t is float:
        return round(v, 6) if math.isfinite(v) else repr(v)
    if t is int or t is bool or v is None:
        return v
    if t is str:  # fresh random ids per run (split ids, map ids): compared by presence only
        return _RANDOM_ID.sub("<id>", v)
    import bpy  # noqa: PLC0415

    if isinstance(v, str):
        return _RANDOM_ID.sub("<id>", v)
    if isinstance(v, (bool, int)):
        return v
    if isinstance(v, float):
        return round(v, 6) if math.isfinite(v) else repr(v)
    if isinstance(v, bpy.types.ID):
        return ("ID", type(v).__name__, v.name, getattr(v.library, "name", None))
    if depth > 6:
        return repr(type(v))
    if isinstance(v, dict):
        return {str(k): _plain(x, depth + 1) for k, x in v.items() if not str(k).endswith("_seconds")}
    if isinstance(v, (list, tuple)):
        return tuple(_plain(x, depth + 1) for x in v)
    if hasattr(v, "to_dict"):
        return _plain(v.to_dict(), depth + 1)
    if hasattr(v, "to_list"):
        return _plain(v.to_list(), depth + 1)
    if isinstance(v, bpy.types.bpy_struct):
        return ("struct", type(v).__name__)
    try:
        return tuple(_plain(x, depth + 1) for x in v)
    except TypeError:
        return repr(v)


def _idprops(owner) -> dict:
    """Custom properties and, where Blender keeps them apart (5.0+), the registered ones."""
    from rokeby.blender import compat

    out = {}
    for prefix, container in (("", owner), ("system:", compat.system_properties(owner))):
        if container is None:
            continue
        try:
            # An empty property group is what reading a registered property makes: not a change.
            got = {prefix + k: _plain(container[k]) for k in container.keys() if not k.endswith("_seconds")}
        except (TypeError, AttributeError):
            continue
        out.update({k: v for k, v in got.items() if v != {}})
    return out


def _socket_value(s):
    return _plain(s.default_value) if hasattr(s, "default_value") else None


def tree_state(tree) -> dict | None:
    """Nodes (type, label, location, settings that matter, custom properties, the group they use,
    every input's value), links and, for a group, its interface."""
    if tree is None:
        return None
    nodes = {}
    for n in tree.nodes:
        nodes[n.name] = {
            "type": n.bl_idname, "label": n.label, "mute": n.mute,
            "location": (round(n.location.x, 3), round(n.location.y, 3)),
            "parent": n.parent.name if n.parent else None,
            "props": _idprops(n),
            "group": n.node_tree.name if getattr(n, "node_tree", None) is not None else None,
            "image": n.image.name if getattr(n, "image", None) is not None else None,
            "settings": {a: _plain(getattr(n, a)) for a in ("distribution", "subsurface_method", "data_type", "blend_type",
                                                             "operation", "attribute_name", "attribute_type", "layer_name",
                                                             "uv_map", "interpolation", "projection", "space", "aov_name")
                         if hasattr(n, a)},
            "inputs": [(s.identifier, _socket_value(s)) for s in n.inputs],
            "outputs": [(s.identifier, _socket_value(s)) for s in n.outputs],
        }
    links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier, lk.is_muted)
                   for lk in tree.links)
    interface = None
    if hasattr(tree, "interface"):
        interface = [(it.item_type, it.name, getattr(it, "in_out", None), getattr(it, "socket_type", None),
                      _plain(getattr(it, "default_value", None))) for it in tree.interface.items_tree]
    return {"nodes": nodes, "links": links, "interface": interface, "props": _idprops(tree)}


def _digest(a) -> str:
    return hashlib.blake2b(np.ascontiguousarray(a).tobytes(), digest_size=12).hexdigest()


_ATTR = {  # data type: (foreach key, components, dtype)
    "FLOAT": ("value", 1, np.float32), "INT": ("value", 1, np.int32), "BOOLEAN": ("value", 1, bool),
    "INT8": ("value", 1, np.int8), "FLOAT_VECTOR": ("vector", 3, np.float32), "FLOAT_COLOR": ("color", 4, np.float32),
    "BYTE_COLOR": ("color", 4, np.float32), "FLOAT2": ("vector", 2, np.float32), "INT32_2D": ("value", 2, np.int32),
    "QUATERNION": ("value", 4, np.float32),
}


def _attribute(attr):
    n = len(attr.data)
    if attr.data_type not in _ATTR:
        return (attr.domain, attr.data_type, n)
    key, width, dtype = _ATTR[attr.data_type]
    buf = np.empty(n * width, dtype=dtype)
    try:
        attr.data.foreach_get(key, buf)
    except (TypeError, AttributeError, RuntimeError):
        return (attr.domain, attr.data_type, n)
    return (attr.domain, attr.data_type, n, _digest(buf))


def mesh_state(me) -> dict:
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    out = {
        "co": _digest(co), "props": _idprops(me),
        # Blender's internal attributes (".select_edge", ".uv_seam", ...) are editor state, not what an
        # operation edits; 5.0 leaves some uninitialised, so they differ between identical builds.
        "attributes": {a.name: _attribute(a) for a in me.attributes if not a.name.startswith(".")},
        "materials": [m.name if m else None for m in me.materials],
        "uv_layers": [uv.name for uv in me.uv_layers],
        "shape_keys": None,
    }
    if me.shape_keys is not None:
        keys = {}
        for kb in me.shape_keys.key_blocks:
            kco = np.empty(len(kb.data) * 3)
            kb.data.foreach_get("co", kco)
            keys[kb.name] = (_digest(kco), round(kb.value, 6), kb.mute, kb.relative_key.name)
        out["shape_keys"] = keys
    return out


def object_state(ob) -> dict:
    out = {
        "type": ob.type, "data": getattr(ob.data, "name", None), "parent": ob.parent.name if ob.parent else None,
        "matrix": _plain(tuple(tuple(r) for r in ob.matrix_basis)),  # matrix_world is stale until the depsgraph runs
        "flags": {a: getattr(ob, a) for a in ("hide_render", "hide_viewport", "visible_camera", "visible_diffuse",
                                               "visible_glossy", "visible_transmission", "visible_volume_scatter",
                                               "visible_shadow", "is_holdout", "is_shadow_catcher", "pass_index",
                                               "display_type")},
        "props": _idprops(ob),
        "slots": [(s.link, s.material.name if s.material else None) for s in ob.material_slots],
        "modifiers": [(m.name, m.type, m.show_viewport, m.show_render,
                       getattr(getattr(m, "node_group", None), "name", None),
                       getattr(getattr(m, "object", None), "name", None), _idprops(m)) for m in ob.modifiers],
        "vertex_groups": [vg.name for vg in ob.vertex_groups],
        "collections": sorted(c.name for c in ob.users_collection),
    }
    ll = getattr(ob, "light_linking", None)
    if ll is not None:
        out["light_linking"] = (getattr(ll.receiver_collection, "name", None), getattr(ll.blocker_collection, "name", None))
    return out


def _image_state(img) -> tuple:
    pixels = None
    if img.source != "FILE" and img.has_data and img.size[0] * img.size[1] <= 1 << 20:  # files: see files_state
        buf = np.empty(img.size[0] * img.size[1] * img.channels, dtype=np.float32)
        img.pixels.foreach_get(buf)
        pixels = _digest(buf)
    return (img.source, _plain(img.filepath), tuple(img.size), img.packed_file is not None, img.users, _idprops(img), pixels)


def _scene_state(sc) -> dict:
    r = sc.render
    layers = {}
    for vl in sc.view_layers:
        layers[vl.name] = {
            "passes": {a: getattr(vl, a) for a in dir(vl) if a.startswith("use_pass_")},
            "cycles": {a: getattr(vl.cycles, a) for a in dir(vl.cycles) if a.startswith("use_pass_") or a.startswith("denoising_store")},
            "aovs": [(a.name, a.type) for a in vl.aovs],
            "props": _idprops(vl),
        }
    return {
        "camera": sc.camera.name if sc.camera else None, "world": sc.world.name if sc.world else None,
        "frame": sc.frame_current, "props": _idprops(sc),
        "render": {a: _plain(getattr(r, a)) for a in ("engine", "resolution_x", "resolution_y", "resolution_percentage",
                                                      "filepath", "film_transparent", "use_compositing", "use_border",
                                                      "use_single_layer", "use_file_extension")},
        "image_settings": (r.image_settings.file_format, r.image_settings.color_depth, r.image_settings.color_mode),
        "samples": sc.cycles.samples,
        "layers": layers,
        "compositor": tree_state(getattr(sc, "node_tree", None)) if getattr(sc, "use_nodes", False) else None,
        "world_tree": tree_state(sc.world.node_tree) if sc.world and sc.world.use_nodes else None,
    }


def files_state(folder) -> dict:
    """{relative path: digest} of every file under ``folder`` (none when it does not exist)."""
    folder = Path(folder)
    if not folder.exists():
        return {}
    return {re.sub(r"[0-9a-f]{12}", "<id>", str(p.relative_to(folder))): hashlib.blake2b(p.read_bytes(), digest_size=12).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def snapshot(folders=()) -> dict:
    """Everything an operation of the add-on may change, as plain comparable values."""
    import bpy  # noqa: PLC0415

    d = bpy.data
    return {
        "counts": {k: len(getattr(d, k)) for k in ("objects", "meshes", "materials", "node_groups", "images", "lights",
                                                   "cameras", "collections", "worlds", "texts", "scenes", "actions")},
        "objects": {ob.name: object_state(ob) for ob in d.objects},
        "meshes": {me.name: mesh_state(me) for me in d.meshes},
        "materials": {m.name: (m.use_nodes, _idprops(m), tree_state(m.node_tree)) for m in d.materials},
        "node_groups": {g.name: (g.bl_idname, g.use_fake_user, tree_state(g)) for g in d.node_groups},
        "images": {i.name: _image_state(i) for i in d.images},
        "lights": {li.name: (li.type, round(li.energy, 6), _plain(li.color), _idprops(li)) for li in d.lights},
        "collections": {c.name: (sorted(o.name for o in c.objects), sorted(ch.name for ch in c.children), _idprops(c))
                        for c in d.collections},
        "scenes": {sc.name: _scene_state(sc) for sc in d.scenes},
        "files": {str(f): files_state(f) for f in folders},
    }


def diff(a, b, path="", out=None, limit=12) -> list[str]:
    """Where two snapshots differ (at most ``limit`` places)."""
    out = [] if out is None else out
    if len(out) >= limit:
        return out
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if k not in a:
                out.append(f"{path}/{k}: added {str(b[k])[:160]}")
            elif k not in b:
                out.append(f"{path}/{k}: removed (was {str(a[k])[:160]})")
            else:
                diff(a[k], b[k], f"{path}/{k}", out, limit)
    elif a != b:
        if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b):
            for i, (x, y) in enumerate(zip(a, b)):
                diff(x, y, f"{path}[{i}]", out, limit)
        else:
            out.append(f"{path}: {str(a)[:200]} -> {str(b)[:200]}")
    return out


# --- the injection --------------------------------------------------------------------------------

class Injector:
    """Raises ``InjectedFault`` at the k-th step (1-based) of the add-on's code run inside the
    ``with`` block: a call of one of its Python functions, or (``lines=True``) also every line."""

    def __init__(self, k: int, *, lines: bool = False, root: str = ADDON, skip=("handlers.py", "props.py"), own=("transaction.py",)):
        self.k, self.lines, self.root, self.skip, self.own = k, lines, root, skip, own
        self.count = 0
        self.where = None
        self._generators = []  # frames of generators already entered: resuming one is no new step

    def _ours(self, frame) -> bool:
        fn = frame.f_code.co_filename
        if not fn.startswith(self.root) or os.path.basename(fn) in self.own:
            return False  # the rollback itself is not what is tested
        caller = frame.f_back
        if caller is not None and caller.f_code.co_name in ("commit", "rollback") and \
                os.path.basename(caller.f_code.co_filename) in self.own:
            return False  # clean-ups after success, undo hooks: best effort by design
        f = frame
        while f is not None:  # not inside a handler Blender runs during the operation
            if f.f_code.co_filename.startswith(self.root) and os.path.basename(f.f_code.co_filename) in self.skip:
                return False
            f = f.f_back
        return True

    def _step(self, frame):
        self.count += 1
        if self.count == self.k:
            self.where = f"{frame.f_code.co_name} ({os.path.basename(frame.f_code.co_filename)}:{frame.f_lineno})"
            sys.settrace(None)
            raise InjectedFault(f"injected fault at step {self.k}: {self.where}")

    def _local(self, frame, event, arg):
        if event == "line":
            self._step(frame)
        return self._local

    def _trace(self, frame, event, arg):
        if event != "call" or self.count >= self.k or not self._ours(frame):
            return None
        if frame.f_code.co_flags & 0x2A0:  # a generator, coroutine or async generator
            if any(f is frame for f in self._generators):
                return self._local if self.lines else None
            self._generators.append(frame)
        self._step(frame)
        return self._local if self.lines else None

    def __enter__(self):
        self._old = sys.gettrace()
        sys.settrace(self._trace)
        return self

    def __exit__(self, *exc):
        sys.settrace(self._old)
        return False

    @property
    def fired(self) -> bool:
        return self.where is not None


def each_fault(make, op, *, folders=(), lines: bool = False, max_steps: int = 5000, stride: int = 1,
               check=None) -> dict:
    """Run ``op(ctx)`` (``ctx = make()``, a fresh scene) with a fault injected at step k, for
    k = 1, 2, … until the operation runs to its end without reaching step k. After every run that
    raised (the injected fault or any exception it became) the snapshot must be exactly the one
    from before; a run that completed in spite of the fault (caught inside) must give the same
    snapshot as a run without faults. Runs from the same scene while the faults leave it
    unchanged, from ``make()`` again after a run that completed. ``check(ctx)`` runs after a
    completed run (e.g. asserts the operation's effect). Returns counts for the report."""
    ctx = make()
    before = snapshot(folders)
    with Injector(10**12) as probe:  # no fault: the reference result and the number of steps
        op(ctx)
    if check is not None:
        check(ctx)
    after = snapshot(folders)
    assert diff(before, after), "the operation changed nothing: the test cannot tell an undone operation from a done one"
    total = probe.count
    ctx = make()
    d = diff(before, snapshot(folders))
    assert not d, "make() is not deterministic: " + "; ".join(d)
    raised = completed = 0
    k = 1
    while k <= min(total + 1, max_steps):
        inj = Injector(k, lines=lines)
        try:
            with inj:
                op(ctx)
        except Exception as exc:  # noqa: BLE001 - any exception: the scene must be as before
            if not inj.fired:
                raise
            raised += 1
            d = diff(before, snapshot(folders))
            assert not d, f"fault at step {k} ({inj.where}), raised {type(exc).__name__}: {exc}; the scene/disk changed:\n  " + "\n  ".join(d)
        else:
            if not inj.fired:
                break
            completed += 1
            d = diff(after, snapshot(folders))
            assert not d, f"fault at step {k} ({inj.where}) was caught inside and the operation completed differently:\n  " + "\n  ".join(d)
            if check is not None:
                check(ctx)
            ctx = make()
            before = snapshot(folders)
        k += stride
    return {"steps": total, "raised": raised, "completed": completed}
