"""Undo and redo of every Rokeby operator: undo puts the scene exactly as it was, redo exactly as
the operator left it, and the field follows.

bpy's undo stack works in background mode, but operators called from Python there do not push
their own undo step: the test pushes it after each one, as Blender's UI does for an operator
with the UNDO flag (which every Rokeby operator that changes data carries; checked here)."""

from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from support.scenes import add_front_camera, add_point_lamp, empty_scene  # noqa: E402


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


_FLOAT_KEYS = {"FLOAT": ("value", 1), "FLOAT_VECTOR": ("vector", 3), "FLOAT_COLOR": ("color", 4), "FLOAT2": ("vector", 2)}


def _attributes(me):
    """Every float attribute of a mesh (the field, painted appearance, positions), rounded."""
    out = {}
    for a in me.attributes:
        key = _FLOAT_KEYS.get(a.data_type)
        if key is None or a.name.startswith("."):
            continue
        vals = np.zeros(len(a.data) * key[1], np.float32)
        a.data.foreach_get(key[0], vals)
        out[a.name] = np.round(vals, 4).tobytes()
    return out


def _pixels(im):
    if im.type != "IMAGE" or not im.has_data:
        return None
    px = np.zeros(len(im.pixels), np.float32)
    im.pixels.foreach_get(px)
    return np.round(px, 4).tobytes()


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
            entry["attributes"] = _attributes(ob.data)
            entry["visible_shadow"] = ob.visible_shadow
            keys = ob.data.shape_keys
            entry["shape_keys"] = [(k.name, round(k.value, 5)) for k in keys.key_blocks] if keys else None
        if ob.type == "LIGHT":
            ll = ob.light_linking
            entry["linking"] = tuple(c.name if c else None for c in (ll.receiver_collection, ll.blocker_collection))
        state[ob.name] = entry
    state["collections"] = sorted((c.name, tuple(sorted(o.name for o in c.objects))) for c in bpy.data.collections)
    vl = bpy.context.view_layer
    state["passes"] = (tuple(p.identifier for p in vl.bl_rna.properties if p.identifier.startswith("use_pass") and getattr(vl, p.identifier)),
                       tuple(a.name for a in vl.aovs))
    for mat in bpy.data.materials:
        tree = mat.node_tree
        state[f"material {mat.name}"] = (
            sorted((n.name, n.bl_idname) for n in tree.nodes),
            sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier) for lk in tree.links),
        )
    state["images"] = sorted((im.name, tuple(im.size), _pixels(im)) for im in bpy.data.images)
    sc = bpy.context.scene
    tree = compat.compositor_tree(sc)
    state["compositor"] = None if tree is None else (
        sorted((n.name, n.bl_idname, n.image.name if getattr(n, "image", None) else None) for n in tree.nodes),
        sorted((lk.from_node.name, lk.to_node.name, lk.to_socket.identifier) for lk in tree.links))
    active = bpy.context.view_layer.objects.active
    state["active"] = active.name if active else None
    return state


@pytest.fixture
def scene():
    sc = empty_scene()
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
    add_front_camera(sc)
    add_point_lamp(sc)
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


def _active(ob):
    bpy.context.view_layer.objects.active = ob


def _tiny_renders():
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.samples = 1
    sc.cycles.use_denoising = False
    sc.render.resolution_x, sc.render.resolution_y = 48, 36


def _with_passes(ball):
    _tiny_renders()
    bpy.ops.rokeby.composite_setup_passes()
    bpy.ops.ed.undo_push(message="passes")


def _with_painting(ball, target="POINT"):
    from rokeby import appearance  # noqa: PLC0415

    _active(ball)
    appearance.setup(ball, ball.data.materials[0], target=target, resolution=32)
    bpy.ops.ed.undo_push(message="appearance")


def _with_shadow_session(ball):
    from rokeby.shadow import ui as shadow_ui  # noqa: PLC0415

    bpy.ops.mesh.primitive_plane_add(size=12, location=(0.0, 0.0, -1.5))
    bpy.context.object.name = "Ground"
    _active(ball)
    bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10)
    sess = shadow_ui.session(bpy.context.scene)
    h = sess.handles(0)["points"].astype(np.float64)
    n, c = len(h), h.mean(axis=0)
    sess.drag(0, ((n - n // 5) % n, n // 5), 0, c + (h[0] - c) * 1.3)
    sess.commit()
    bpy.ops.ed.undo_push(message="shadow session")


def _with_shadow_edit(ball):
    _with_shadow_session(ball)
    bpy.ops.rokeby.shadow_apply()
    _active(ball)
    bpy.ops.ed.undo_push(message="shadow edit")


def _composite_render(ball, tmp):
    return bpy.ops.rokeby.composite_render(edit="EMBOSS", amount=0.5, filepath=str(tmp / "undo.exr"), image_name="Recomposited")


def _with_rendered_frame(ball):
    import tempfile  # noqa: PLC0415

    _with_passes(ball)
    path = str(Path(tempfile.gettempdir()) / "rokeby_undo_frame.exr")  # rewritten by every run
    assert bpy.ops.rokeby.composite_render(edit="NONE", filepath=path, image_name="Rendered") == {"FINISHED"}
    bpy.ops.ed.undo_push(message="rendered")


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
    "distance_set": (_with_mirror, lambda b: bpy.ops.rokeby.distance_set(mirror=b.name, metric="GEODESIC")),
    "material_toggle": (_with_mirror, lambda b: bpy.ops.rokeby.material_toggle(mirror=b.name, material="Glass")),
    # Installing is automatic now (a mirror with a constraint renders its edit): the operator's
    # undoable change is taking the nodes out (Edit Final Renders off).
    "render_nodes": (_with_mirror, lambda b: bpy.ops.rokeby.render_nodes(mirror=b.name, action="REMOVE")),
    "ior_from_material": (_with_mirror, lambda b: bpy.ops.rokeby.ior_from_material(mirror=b.name, material="Glass")),
    # Compositing (#6), appearance painting (#8), shadow editing (#7).
    "composite_setup_passes": (lambda b: _tiny_renders(), lambda b: bpy.ops.rokeby.composite_setup_passes()),
    "composite_render": (_with_passes, _composite_render),
    "composite_edit": (_with_rendered_frame, lambda b: bpy.ops.rokeby.composite_edit(edit="EMBOSS", amount=0.5, image_name="Edited")),
    "composite_to_compositor": (_with_rendered_frame, lambda b: bpy.ops.rokeby.composite_to_compositor(image_name="Rendered")),
    "appearance_setup": (lambda b: _active(b), lambda b: bpy.ops.rokeby.appearance_setup()),
    "appearance_paint": (_with_painting, lambda b: bpy.ops.rokeby.appearance_paint(stroke=[{"name": "", "location": (0.0, -1.0, 0.0)}])),
    "appearance_texture_remove": (lambda b: _with_painting(b, "TEXTURE"), lambda b: bpy.ops.rokeby.appearance_texture_remove()),
    "appearance_remove": (_with_painting, lambda b: bpy.ops.rokeby.appearance_remove()),
    "shadow_apply": (_with_shadow_session, lambda b: bpy.ops.rokeby.shadow_apply()),
    "shadow_remove": (_with_shadow_edit, lambda b: bpy.ops.rokeby.shadow_remove()),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_undo_and_redo(scene, name, tmp_path):
    setup, run = CASES[name]
    if setup is not None:
        setup(scene)
    before = snapshot()
    assert (run(scene, tmp_path) if run is _composite_render else run(scene)) == {"FINISHED"}
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


def test_undo_and_redo_of_texture_strokes(scene):
    """Global undo keeps packed data but not pixels in memory: a stroke on a texture target is
    packed by the operator and reloaded after undo/redo, so Ctrl-Z takes the stroke back."""
    from rokeby import appearance  # noqa: PLC0415

    _with_painting(scene, "TEXTURE")
    stroke = [{"name": "", "location": (0.0, -1.0, 0.0)}]
    wm = bpy.context.scene.rokeby_appearance_brush
    wm.brush, wm.value, wm.radius, wm.strength = "roughness", 0.9, 0.5, 1.0
    values = []
    for v in (0.9, 0.05):
        wm.value = v
        assert bpy.ops.rokeby.appearance_paint(stroke=stroke) == {"FINISHED"}
        bpy.ops.ed.undo_push(message="stroke")
        values.append(appearance.read_texture(bpy.data.objects["Ball"], "roughness").copy())
    assert np.abs(values[1] - values[0]).max() > 0.5
    bpy.ops.ed.undo()
    np.testing.assert_array_equal(appearance.read_texture(bpy.data.objects["Ball"], "roughness"), values[0])
    bpy.ops.ed.redo()
    np.testing.assert_array_equal(appearance.read_texture(bpy.data.objects["Ball"], "roughness"), values[1])


# Operators not in CASES, and why.
NOT_COVERED = {
    "return_to_view": "moves a 3D view, which background mode does not have (no scene data changes)",
    "update": "recomputes the field from the scene as it is: undoing it changes nothing",
    "reflection_map": "a Cycles capture; tests/reflection/test_reflmap.py covers its data",
    "preview_capture": "captures the scene for the viewport preview, kept outside the file (no scene data changes; tests/reflection/test_scene_capture.py)",
    "appearance_preview": "switches a viewport draw handler on or off: no scene data changes",
    "appearance_render_difference": "a measurement: stores the figure in the brush settings, edits nothing (tests/appearance/test_appearance_render_model.py)",
    "shadow_start": "one undo step each; the session (kept outside the file) follows undo/redo: tests/shadow/test_shadow_undo.py",
    "shadow_drag": "one undo step per confirmed drag, the session and the live shadow mesh follow: tests/shadow/test_shadow_undo.py",
    "shadow_stop": "one undo step; undo brings the session back: tests/shadow/test_shadow_undo.py",
    "composite_sequence": "writes recomposited frames to files outside the .blend (tests/workflows/test_interface.py)",
    "farm_export": "writes a job bundle outside the .blend (tests/workflows/test_farm_jobs.py)",
    "farm_export_recomposite": "writes a job bundle outside the .blend (tests/workflows/test_farm_jobs.py)",
    "composite_brush": "pushes one undo step per stroke itself (no UNDO flag); undo/redo tested in tests/compositing/test_compositing_brush.py",
}


def test_every_operator_is_covered():
    rokeby.register()
    names = set(dir(bpy.ops.rokeby))  # every operator the registered add-on offers
    assert len(names) > 20
    assert names - set(CASES) - set(NOT_COVERED) == set(), "a new operator needs an undo/redo case"
    assert set(NOT_COVERED) & set(CASES) == set()
