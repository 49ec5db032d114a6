"""Undo and redo of every Rokeby operator: undo puts the scene exactly as it was, redo exactly as
the operator left it, and the field follows.

bpy's undo stack works in background mode, but operators called from Python there do not push
their own undo step: the test pushes it after each one, as Blender's UI does for an operator
with the UNDO flag (which every Rokeby operator that changes data carries; checked here)."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api, evaluate  # noqa: E402
from rokeby.evaluate import ATTRIBUTE  # noqa: E402


def _rna(value, depth=0):
    """A comparable dump of an RNA struct (property groups of the add-on), pointers by name."""
    if value is None:
        return None
    if isinstance(value, bpy.types.ID):
        return value.name
    if hasattr(value, "bl_rna") and depth < 4:
        out = {}
        for prop in value.bl_rna.properties:
            if prop.identifier in ("rna_type", "name") and prop.identifier == "rna_type":
                continue
            v = getattr(value, prop.identifier)
            if prop.type == "COLLECTION":
                out[prop.identifier] = [_rna(item, depth + 1) for item in v]
            elif prop.type == "POINTER":
                out[prop.identifier] = _rna(v, depth + 1)
            elif getattr(prop, "is_array", False):
                out[prop.identifier] = tuple(round(float(x), 5) if isinstance(x, float) else x for x in v)
            elif isinstance(v, float):
                out[prop.identifier] = round(v, 5)
            else:
                out[prop.identifier] = v
        return out
    return str(value)


def snapshot():
    state = {}
    for ob in bpy.data.objects:
        entry = {
            "parent": ob.parent.name if ob.parent else None,
            "location": tuple(round(x, 5) for x in ob.location),
            "constraints": [c.type for c in ob.constraints],
            "modifiers": [m.name for m in ob.modifiers],
            "selected": ob.select_get(),
        }
        if ob.type == "MESH":
            entry["rokeby"] = _rna(ob.rokeby)
            attr = ob.data.attributes.get(ATTRIBUTE)
            if attr is not None:
                vals = np.zeros(len(attr.data) * 3, np.float32)
                attr.data.foreach_get("vector", vals)
                entry["field"] = np.round(vals, 4).tobytes()
        state[ob.name] = entry
    for mat in bpy.data.materials:
        tree = mat.node_tree
        state[f"material {mat.name}"] = (
            sorted((n.name, n.bl_idname) for n in tree.nodes),
            sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier) for lk in tree.links),
        )
    state["images"] = sorted(im.name for im in bpy.data.images)
    active = bpy.context.view_layer.objects.active
    state["active"] = active.name if active else None
    return state


@pytest.fixture
def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    evaluate.reset()
    sc = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
    ball = bpy.context.object
    ball.name = "Ball"
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    ball.data.materials.append(mat)
    glass = bpy.data.materials.new("Glass")
    glass.use_nodes = True
    glass.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value = 1.33
    glass.node_tree.nodes["Principled BSDF"].inputs["Transmission Weight"].default_value = 1.0
    ball.data.materials.append(glass)
    ball.vertex_groups.new(name="Patch").add(list(range(40)), 1.0, "REPLACE")
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    lamp.location = (1.5, -2.0, 2.5)
    sc.collection.objects.link(lamp)
    bpy.context.view_layer.objects.active = ball
    bpy.ops.ed.undo_push(message="scene")
    return ball


def _with_mirror(ball):
    bpy.ops.rokeby.mirror_add(mirror=ball.name)
    bpy.ops.rokeby.constraint_add(mirror=ball.name, surface_point=(0.0, -1.0, 0.0))
    bpy.ops.rokeby.region_add(mirror=ball.name, use_center=True, center=(0.0, -1.0, 0.0), radius=0.6)
    ball.rokeby.constraints[0].target_handle.location.z += 2.0
    api.evaluate()
    bpy.ops.ed.undo_push(message="mirror set up")


def _select_only(*objs):
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob in objs)


CASES = {
    "mirror_add": (None, lambda b: bpy.ops.rokeby.mirror_add(mirror=b.name)),
    "mirror_remove": (_with_mirror, lambda b: bpy.ops.rokeby.mirror_remove(mirror=b.name)),
    "constraint_add": (_with_mirror, lambda b: bpy.ops.rokeby.constraint_add(mirror=b.name, surface_point=(0.5, -0.8, 0.2))),
    "highlight_add": (_with_mirror, lambda b: (_select_only(bpy.data.objects["Lamp"]), bpy.ops.rokeby.highlight_add(mirror=b.name))[1]),
    "constraint_remove": (_with_mirror, lambda b: bpy.ops.rokeby.constraint_remove(mirror=b.name, index=0)),
    "constraint_select": (_with_mirror, lambda b: bpy.ops.rokeby.constraint_select(mirror=b.name, index=0)),
    "region_add": (_with_mirror, lambda b: bpy.ops.rokeby.region_add(mirror=b.name, kind="FREEFORM", vertex_group="Patch")),
    "region_remove": (_with_mirror, lambda b: bpy.ops.rokeby.region_remove(mirror=b.name, index=0)),
    "freeze": (_with_mirror, lambda b: bpy.ops.rokeby.freeze(mirror=b.name, action="FREEZE")),
    "material_toggle": (_with_mirror, lambda b: bpy.ops.rokeby.material_toggle(mirror=b.name, material="Glass")),
    "render_nodes": (_with_mirror, lambda b: bpy.ops.rokeby.render_nodes(mirror=b.name)),
    "ior_from_material": (_with_mirror, lambda b: bpy.ops.rokeby.ior_from_material(mirror=b.name, material="Glass")),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_undo_and_redo(scene, name):
    setup, run = CASES[name]
    if setup is not None:
        setup(scene)
    before = snapshot()
    assert run(scene) == {"FINISHED"}
    op = getattr(bpy.types, "ROKEBY_OT_" + name)
    assert "UNDO" in op.bl_options
    bpy.ops.ed.undo_push(message=op.bl_label)
    api.evaluate()
    after = snapshot()
    assert after != before, f"{name} changed nothing: the test would prove nothing"
    bpy.ops.ed.undo()
    api.evaluate()
    assert snapshot() == before, f"undo of {name} did not restore the scene"
    bpy.ops.ed.redo()
    api.evaluate()
    assert snapshot() == after, f"redo of {name} did not give the operator's result again"


def test_undo_of_a_handle_drag_brings_the_field_back(scene):
    _with_mirror(scene)
    field = api.stored_field(scene).copy()
    green = scene.rokeby.constraints[0].target_handle
    green.location.x += 1.5
    bpy.ops.ed.undo_push(message="drag")
    api.evaluate()
    assert not np.allclose(api.stored_field(scene), field, atol=1e-4)
    bpy.ops.ed.undo()
    scene = bpy.data.objects["Ball"]  # undo reloads the data: fetch the object again
    api.evaluate()
    np.testing.assert_allclose(api.stored_field(scene), field, atol=1e-5)


# Operators not in CASES, and why.
NOT_COVERED = {
    "return_to_view": "moves a 3D view, which background mode does not have (no scene data changes)",
    "update": "recomputes the field from the scene as it is: undoing it changes nothing",
    "reflection_map": "a Cycles capture; tests/test_reflmap.py covers its data",
}


def test_every_operator_is_covered():
    from rokeby import operators  # noqa: PLC0415

    names = {cls.bl_idname.split(".", 1)[1] for cls in operators.classes}
    assert names - set(CASES) - set(NOT_COVERED) == set(), "a new operator needs an undo/redo case"
