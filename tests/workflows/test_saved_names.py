"""Saved-data guards: every name the add-on writes into a .blend (or an EXR) and every property it
registers on Blender's types, compared with a checked-in snapshot (tests/data/saved_names.json).

Files keep what the add-on wrote under these names: renaming one, reordering an enum or dropping a
property silently changes (or loses) what saved scenes hold. A change here is deliberate only with a
load-time migration (handlers.migrate_file, schema.DATA_VERSION) and a regenerated snapshot:

    ROKEBY_UPDATE_SNAPSHOT=1 PYTHONPATH=$PWD/addon python -m pytest tests/workflows/test_saved_names.py

See docs/saved-data.md."""

from __future__ import annotations

import difflib
import importlib
import json
import os
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
from rokeby.blender import compat  # noqa: E402

import feature_fixtures  # noqa: E402  (tests/blend_fixtures, on pytest's pythonpath)
from support import DATA  # noqa: E402

# One snapshot per Blender release: what a release itself names (its EXR pass names, the passes a
# view layer has on by default) differs, and a file saved by one release must keep its meaning there.
BLENDER = "%d.%d" % tuple(bpy.app.version[:2])
SNAPSHOT = DATA / ("saved_names.json" if BLENDER == "4.5" else f"saved_names-blender-{BLENDER}.json")

# Per-scene random ids (reflection-map file stems) and the temporary folder, normalised away.
_HEX_ID = re.compile(r"(?<![0-9a-f])[0-9a-f]{12}(?![0-9a-f])")
# The bpy types the add-on may hang properties on.
_HOSTS = ("Object", "Scene", "Material", "Mesh", "Image", "Light", "World", "Collection", "NodeTree",
          "ViewLayer", "WindowManager", "Camera")


def _norm(s: str, tmp: str = "") -> str:
    s = str(s)
    if tmp:
        s = s.replace(tmp, "<tmp>")
    return _HEX_ID.sub("<id>", s)


def _python_items(struct_identifier: str, prop_identifier: str):
    """The items list the add-on gave the EnumProperty (None where it cannot be found)."""
    cls = bpy.types.PropertyGroup.bl_rna_get_subclass_py(struct_identifier) or getattr(bpy.types, struct_identifier, None)
    for k in getattr(cls, "__mro__", ()):
        ann = k.__dict__.get("__annotations__", {}).get(prop_identifier)
        if isinstance(ann, str):  # ``from __future__ import annotations``: evaluated as Blender does
            ann = eval(ann, vars(sys.modules[k.__module__]))  # noqa: S307 - the add-on's own annotation
        if ann is not None and hasattr(ann, "keywords"):
            return ann.keywords.get("items")
    return None


def _has_explicit_numbers(items) -> bool:
    return (not callable(items)) and all(len(it) >= 4 and isinstance(it[-1], int) and not isinstance(it[-1], bool) for it in items)


def _rna_struct(struct, seen) -> dict:
    out = {}
    for p in struct.properties:
        if p.identifier == "rna_type":
            continue
        d = {"type": p.type}
        if p.type == "ENUM":
            d["items"] = [[it.identifier, it.value] for it in p.enum_items]
            items = _python_items(struct.identifier, p.identifier)
            d["explicit_numbers"] = items is not None and _has_explicit_numbers(items)
            if p.is_enum_flag:
                d["flag"] = True
        elif p.type in ("POINTER", "COLLECTION"):
            ft = p.fixed_type
            d["fixed_type"] = ft.identifier
            # Recurse into the add-on's property groups only (ID types are Blender's own).
            if ft.identifier not in seen and ft.base is not None and ft.base.identifier == "PropertyGroup":
                seen.add(ft.identifier)
                d["properties"] = _rna_struct(ft, seen)
        elif p.type in ("INT", "FLOAT", "BOOLEAN") and getattr(p, "is_array", False):
            d["array_length"] = p.array_length
        out[p.identifier] = d
    return out


def registered_properties() -> dict:
    """``rokeby*`` properties on Blender's types, recursively: names, types, enum (identifier,
    number) pairs and whether the add-on numbered the items explicitly."""
    out = {}
    for host in _HOSTS:
        t = getattr(bpy.types, host)
        for p in t.bl_rna.properties:
            if p.identifier.lower().startswith("rokeby"):
                seen = set()
                entry = {"type": p.type}
                if p.type in ("POINTER", "COLLECTION"):
                    entry["fixed_type"] = p.fixed_type.identifier
                    entry["properties"] = _rna_struct(p.fixed_type, seen)
                out[f"{host}.{p.identifier}"] = entry
    return out


def _node_entries(tree, tmp) -> list:
    out = []
    for n in tree.nodes:
        default = n.bl_label if hasattr(n, "bl_label") else ""
        named = not re.fullmatch(re.escape(default) + r"(\.\d{3})?", n.name)
        rec = [n.bl_idname]
        if named:
            rec.append("name=" + _norm(n.name, tmp))
        if n.label:
            rec.append("label=" + _norm(n.label, tmp))
        rec += ["prop=" + k for k in sorted(n.keys())]
        if getattr(n, "node_tree", None) is not None:
            rec.append("group=" + _norm(n.node_tree.name, tmp))
        if n.bl_idname == "ShaderNodeAttribute":
            rec.append("attribute=" + _norm(n.attribute_name, tmp))
        if n.bl_idname == "ShaderNodeOutputAOV":
            rec.append("aov=" + n.aov_name)
        if n.bl_idname == "ShaderNodeUVMap":
            rec.append("uv_map=" + n.uv_map)
        if len(rec) > 1:
            out.append(" ".join(rec))
    return sorted(set(out))


def _ids_with_keys(tmp):
    out = {}
    for coll in ("objects", "meshes", "materials", "node_groups", "images", "collections", "scenes",
                 "lights", "worlds", "cameras"):
        for idb in getattr(bpy.data, coll):
            keys = [k for k in idb.keys() if not k.startswith("_")]
            if keys:
                out[f"{coll}/{_norm(idb.name, tmp)}"] = sorted(keys)
    return out


def saved_names(sc, tmp: str = "") -> dict:
    """Every name in the current file a reader of the file (the add-on, a script, the user) goes by."""
    d = bpy.data
    out = {
        "objects": sorted(_norm(o.name, tmp) for o in d.objects),
        "collections": sorted(_norm(c.name, tmp) for c in d.collections),
        "node_groups": {},
        "materials": {},
        "custom_properties": _ids_with_keys(tmp),
        "mesh_attributes": sorted({f"{a.name} {a.domain} {a.data_type}" for m in d.meshes for a in m.attributes
                                   if not a.name.startswith(".")}),
        "modifiers": sorted({f"{_norm(md.name, tmp)} {md.type}" + (f" group={_norm(md.node_group.name, tmp)}" if getattr(md, "node_group", None) else "")
                             for o in d.objects for md in o.modifiers}),
        "vertex_groups": sorted({_norm(g.name, tmp) for o in d.objects for g in o.vertex_groups}),
        "shape_keys": sorted({_norm(k.name, tmp) for key in d.shape_keys for k in key.key_blocks}),
        "images": sorted(f"{_norm(i.name, tmp)} file={_norm(i.filepath, tmp)} packed={i.packed_file is not None}" for i in d.images),
        "view_layers": {},
    }
    for ng in d.node_groups:
        iface = sorted(f"{it.in_out} {it.name} {getattr(it, 'socket_type', '')}" for it in ng.interface.items_tree if it.item_type == "SOCKET")
        out["node_groups"][_norm(ng.name, tmp)] = {"type": ng.bl_idname, "interface": iface, "nodes": _node_entries(ng, tmp)}
    tree = compat.compositor_tree(sc)
    if tree is not None:  # the scene's compositor
        out["compositor"] = _node_entries(tree, tmp)
    for m in d.materials:
        if m.node_tree is not None:
            out["materials"][_norm(m.name, tmp)] = _node_entries(m.node_tree, tmp)
    for vl in sc.view_layers:
        passes = sorted(p.identifier for p in vl.bl_rna.properties if p.identifier.startswith("use_pass_") and getattr(vl, p.identifier) is True)
        out["view_layers"][vl.name] = {"aovs": sorted(f"{a.name} {a.type}" for a in vl.aovs), "passes": passes}
    return out


def exr_names(tmp_path) -> dict:
    """Layer/channel names of the EXRs the compositing tools write (write_exr) and read (Blender's
    multilayer render after setup_passes)."""
    import OpenEXR

    from rokeby import api, compositing

    def channels(path):
        with OpenEXR.File(str(path), separate_channels=True) as f:
            return sorted(f"{part.name()}:{ch}" if len(f.parts) > 1 else ch for part in f.parts for ch in part.channels)

    out = {}
    p = tmp_path / "written.exr"
    compositing.write_exr(str(p), np.zeros((2, 3, 3), np.float32))
    out["write_exr"] = channels(p)
    sc = feature_fixtures.build_compositing()
    api.setup_compositing_passes(sc)
    sc.render.resolution_x = sc.render.resolution_y = 4
    sc.cycles.samples = 1
    sc.render.filepath = str(tmp_path / "passes.exr")
    bpy.ops.render.render(write_still=True)
    out["render_after_setup_passes"] = channels(tmp_path / "passes.exr")
    return out


def _recomposite(sc, tmp_path):
    """What Render and Recomposite leaves in the file (entry points newer than the previous
    release, so not in feature_fixtures.py): the recomposited image, its compositor node and a
    normal-brush stroke on it."""
    from rokeby import api

    sc.render.resolution_x = sc.render.resolution_y = 16
    sc.cycles.samples = 2
    with warnings.catch_warnings():  # a 16-pixel frame: patches too small to edit are named, not wanted here
        warnings.simplefilter("ignore", RuntimeWarning)
        api.recomposite_render(str(tmp_path / "recomposite.exr"), edit="emboss", amount=0.5, scene=sc)
    api.use_in_compositor(scene=sc)
    # a stroke of the normal brush: its record and source on the image
    brush = api.open_normal_brush(str(tmp_path / "recomposite.exr"), "Rokeby Recomposited")
    api.paint_normals(brush, [(8.0, 4.0), (8.0, 12.0)], radius=3.0, strength=0.5, mode="emboss")
    sc.render.resolution_x = sc.render.resolution_y = feature_fixtures.SIZE
    sc.cycles.samples = feature_fixtures.SAMPLES


def collect(tmp_path) -> dict:
    tmp = str(tmp_path)
    snap = {"features": {}}
    for feature, sc in feature_fixtures.scenes():
        if feature == "compositing":
            _recomposite(sc, tmp_path)
        # Saved and opened again: what is in the file, after the add-on's load handlers ran.
        path = tmp_path / f"{feature}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
        bpy.ops.wm.open_mainfile(filepath=str(path))
        snap["features"][feature] = saved_names(bpy.context.scene, tmp)
    snap["exr"] = exr_names(tmp_path)
    snap["registered_properties"] = registered_properties()
    return snap


def _diff(old: dict, new: dict) -> str:
    a = json.dumps(old, indent=1, sort_keys=True, ensure_ascii=False).splitlines()
    b = json.dumps(new, indent=1, sort_keys=True, ensure_ascii=False).splitlines()
    return "\n".join(difflib.unified_diff(a, b, "snapshot", "now", lineterm="", n=2))


def test_saved_names_match_the_snapshot(tmp_path):
    now = json.loads(json.dumps(collect(tmp_path), sort_keys=True))
    if os.environ.get("ROKEBY_UPDATE_SNAPSHOT") == "1":
        SNAPSHOT.parent.mkdir(parents=True, exist_ok=True)
        SNAPSHOT.write_text(json.dumps(now, indent=1, sort_keys=True, ensure_ascii=False) + "\n")
        pytest.skip(f"ROKEBY_UPDATE_SNAPSHOT=1: wrote {SNAPSHOT} (review the diff and commit it)")
    if not SNAPSHOT.exists():
        pytest.fail(f"{SNAPSHOT} is missing: generate it with ROKEBY_UPDATE_SNAPSHOT=1")
    old = json.loads(SNAPSHOT.read_text())
    if now != old:
        pytest.fail(
            "Names the add-on writes into .blend/EXR files, or the properties it registers, changed.\n"
            "Saved files keep the old names: a changed name, property, enum identifier or enum number needs a\n"
            "load-time migration (handlers.migrate_file, bump schema.DATA_VERSION) so older files keep their meaning.\n"
            "If the change is deliberate and migrated (or only adds names), regenerate the snapshot:\n"
            "    ROKEBY_UPDATE_SNAPSHOT=1 PYTHONPATH=$PWD/addon python -m pytest tests/workflows/test_saved_names.py\n"
            "and commit tests/data/saved_names.json with the change.\n\n" + _diff(old, now))


def _enum_properties():
    """(where, items) for every EnumProperty the add-on declares, on every class of every module
    of the package (property groups, operators, preferences)."""
    import rokeby

    rokeby.register()
    found = []
    pkg = Path(rokeby.__file__).parent
    for f in sorted(pkg.rglob("*.py")):  # the feature packages too (docs/architecture.md)
        parts = f.relative_to(pkg).with_suffix("").parts
        name = ".".join(("rokeby", *parts[:-1])) if parts[-1] == "__init__" else ".".join(("rokeby", *parts))
        if parts == ("__init__",) or f.stem == "__main__" or name not in sys.modules:
            continue  # every module register() pulls in is imported; the rest declare no Blender classes
        mod = importlib.import_module(name)
        for cname, cls in vars(mod).items():
            if not isinstance(cls, type) or cls.__module__ != name:
                continue
            for pname, ann in cls.__dict__.get("__annotations__", {}).items():
                if isinstance(ann, str):  # ``from __future__ import annotations``: Blender evaluates it so
                    if "EnumProperty(" not in ann:
                        continue
                    ann = eval(ann, vars(mod))  # noqa: S307 - the add-on's own annotation, as Blender does
                if getattr(ann, "function", None) is bpy.props.EnumProperty:
                    found.append((f"{name}.{cname}.{pname}", ann.keywords.get("items")))
    return found


def test_every_enum_the_addon_declares_numbers_its_items():
    """Blender stores an enum's item number: without explicit numbers, inserting or reordering an
    item silently changes what saved files mean. Each item is (id, name, description[, icon], number)."""
    found = _enum_properties()
    assert len(found) >= 20, f"the walk found only {len(found)} EnumProperty declarations: {found}"
    bad = [(where, items if callable(items) else [it[0] for it in items if not (len(it) >= 4 and isinstance(it[-1], int))])
           for where, items in found if not _has_explicit_numbers(items)]
    assert not bad, ("EnumProperty items without explicit numbers (add the number as the last element, equal to the "
                     f"item's index in the last release, and never reuse one): {bad}")
    for where, items in found:
        numbers = [it[-1] for it in items]
        assert len(set(numbers)) == len(numbers), f"{where}: item numbers repeat: {numbers}"


def test_snapshot_records_explicit_numbers_for_every_registered_enum():
    """The snapshot's registered properties: every enum is numbered by the add-on."""
    props = registered_properties()
    assert "Object.rokeby" in props and "Object.rokeby_shadow" in props

    def enums(d, path=""):
        for k, v in d.items():
            if v.get("type") == "ENUM":
                yield f"{path}{k}", v
            yield from enums(v.get("properties", {}), f"{path}{k}.")

    listed = list(enums(props))
    assert listed, "no enum found under the rokeby properties"
    missing = [p for p, v in listed if not v["explicit_numbers"]]
    assert not missing, f"registered enums without explicit item numbers: {missing}"
