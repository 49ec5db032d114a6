"""Deleting anything the shadow, appearance and compositing editors use (for #6–#8),
at any time: what is derived is made again or taken down, what the artist made is kept, the
render shows what the remaining objects mean, every refusal names what is gone, and undo brings
everything back.

Shadow edits (the caster, the light, its twin, the shadow mesh, a linking collection, a receiver)
are checked by pixels: deleting the shadow mesh gives exactly the unedited render, deleting the
caster gives the render of a scene that never had it."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from support import shadow as ts  # noqa: E402
from rokeby import appearance, shadow  # noqa: E402
from rokeby.shadow import linking  # noqa: E402
from support.ui import Layout  # noqa: E402


@pytest.fixture
def registered():
    rokeby.register()
    yield
    rokeby.unregister()


def _settle(sc):
    """What the UI does after a deletion: a depsgraph update, which runs the add-on's handlers."""
    sc.view_layers[0].update()


def _plain_render(tmp_path, without=None):
    bpy_, sc, *_ = ts.blender_scene()
    if without is not None:
        bpy.data.objects.remove(bpy.data.objects[without], do_unlink=True)
    return ts.render(bpy_, sc, tmp_path / "plain.png")


def _edited(tmp_path):
    bpy_, sc, ball, lamp, ground, _s, ob, twin = ts.edited_scene()
    _settle(sc)
    edited = ts.render(bpy_, sc, tmp_path / "edited.png")
    bpy.ops.ed.undo_push(message="shadow edit")
    return sc, edited


def _twins():
    return [o.name for o in bpy.data.objects if o.rokeby_shadow.role == "TWIN"]


def _draw_shadow_panel():
    from rokeby.shadow.ui import ROKEBY_PT_shadow  # noqa: PLC0415

    log = []
    ROKEBY_PT_shadow.draw(type("P", (), {"layout": Layout(log)})(), bpy.context)
    return log


SHADOW_ROLES = ["shadow mesh", "twin light", "light", "caster", "linking collection", "receiver"]


@pytest.mark.parametrize("role", SHADOW_ROLES)
def test_delete_anything_a_shadow_edit_uses(role, registered, tmp_path):
    plain = _plain_render(tmp_path) if role == "shadow mesh" else None
    without_ball = _plain_render(tmp_path, without="Ball") if role == "caster" else None
    sc, edited = _edited(tmp_path)
    if plain is not None:
        assert np.abs(edited - plain).max() > 0.1  # the edit shows, so "back to plain" means something
    victim = {
        "shadow mesh": "Ball" + shadow.SHADOW_SUFFIX,
        "twin light": "Lamp" + shadow.TWIN_SUFFIX,
        "light": "Lamp",
        "caster": "Ball",
        "receiver": "Ground",
    }.get(role)
    if role == "linking collection":
        bpy.data.collections.remove(bpy.data.collections[linking._collection_name("Lamp", shadow.BLOCKERS_EDITED)])
    else:
        bpy.data.objects.remove(bpy.data.objects[victim], do_unlink=True)
    _settle(sc)
    _settle(sc)  # a second update finds nothing left to repair
    assert shadow.repair(sc) == []
    lamp = bpy.data.objects.get("Lamp")
    mesh = bpy.data.objects.get("Ball" + shadow.SHADOW_SUFFIX)
    after = ts.render(bpy, sc, tmp_path / "after.png")
    assert np.isfinite(after).all()
    if role in ("twin light", "linking collection", "receiver"):
        # Derived parts are made again: the edit renders as before.
        assert _twins() == ["Lamp" + shadow.TWIN_SUFFIX]
        if role != "receiver":
            np.testing.assert_allclose(after, edited, atol=1e-6)
    elif role == "shadow mesh":
        # The edit is gone: twin and linking go, the render is the unedited one.
        assert _twins() == [] and lamp.light_linking.receiver_collection is None and lamp.light_linking.blocker_collection is None
        assert not [c for c in bpy.data.collections if c.name.startswith("Lamp · ")]
        np.testing.assert_allclose(after, plain, atol=1e-6)
    elif role == "caster":
        # The shadow mesh is kept (nothing the artist made is lost) but casts no shadow.
        assert _twins() == [] and mesh is not None and not mesh.visible_shadow
        np.testing.assert_allclose(after, without_ball, atol=1e-6)
    elif role == "light":
        assert _twins() == [] and mesh is not None and not mesh.visible_shadow
    assert isinstance(_draw_shadow_panel(), list)
    # Undo brings the deleted object and the whole edit back.
    bpy.ops.ed.undo_push(message="delete")
    bpy.ops.ed.undo()
    sc = bpy.context.scene
    _settle(sc)
    assert bpy.data.objects["Ball" + shadow.SHADOW_SUFFIX].visible_shadow and _twins() == ["Lamp" + shadow.TWIN_SUFFIX]
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "undone.png"), edited, atol=1e-6)


def test_removing_a_shadow_edit_restores_the_lights_own_linking(registered, tmp_path):
    bpy_, sc, ball, lamp, ground = ts.blender_scene()
    plain = ts.render(bpy_, sc, tmp_path / "plain.png")
    own = bpy.data.collections.new("artist receivers")
    lamp.light_linking.receiver_collection = own
    own.objects.link(ball)
    own.objects.link(ground)
    from rokeby import api  # noqa: PLC0415

    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n, c = len(h), h.mean(axis=0)
    s.drag(0, ((n - n // 5) % n, n // 5), 0, c + (h[0] - c) * 1.35)
    s.commit()
    api.apply_shadow_edit(s)
    assert lamp.light_linking.receiver_collection.name != "artist receivers"
    bpy.context.view_layer.objects.active = ball
    assert bpy.ops.rokeby.shadow_remove() == {"FINISHED"}
    assert lamp.light_linking.receiver_collection == own and lamp.light_linking.blocker_collection is None
    assert _twins() == [] and bpy.data.objects.get("Ball" + shadow.SHADOW_SUFFIX) is None
    np.testing.assert_allclose(ts.render(bpy_, sc, tmp_path / "removed.png"), plain, atol=1e-6)
    with pytest.raises(shadow.ShadowEditError, match="has no shadow edit"):
        api.remove_shadow_edit(ball)


# --- appearance painting ------------------------------------------------------------------------

def _painted(target):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
    ob = bpy.context.object
    ob.name = "Ball"
    mat = bpy.data.materials.new("Paint")
    mat.use_nodes = True
    ob.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    cam.location, cam.rotation_euler = (0.0, -4.0, 0.0), (np.pi / 2, 0.0, 0.0)
    bpy.context.view_layer.objects.active = ob
    appearance.setup(ob, target=target, resolution=32)
    appearance.paint(ob, "roughness", [(0.0, -1.0, 0.0)], 0.4, value=0.9)
    bpy.ops.ed.undo_push(message="painted")
    return ob


def _panel_log():
    from rokeby.appearance.ui import ROKEBY_PT_appearance  # noqa: PLC0415

    log = []
    ROKEBY_PT_appearance.draw(type("P", (), {"layout": Layout(log)})(), bpy.context)
    return log


def _draw_appearance_panel():
    return [t for kind, t in _panel_log() if kind == "label"]


APPEARANCE_ROLES = [("POINT", "attribute"), ("POINT", "material"), ("TEXTURE", "image"), ("TEXTURE", "uv map")]


@pytest.mark.parametrize("target,role", APPEARANCE_ROLES)
def test_delete_anything_appearance_painting_uses(target, role, registered, tmp_path):
    ob = _painted(target)
    values = appearance.point_values(ob, "roughness").copy()
    if role == "attribute":
        ob.data.attributes.remove(ob.data.attributes[appearance.PARAMS["roughness"][0]])
        words = "no attribute"
    elif role == "material":
        bpy.data.materials.remove(ob.active_material)
        words = None
    elif role == "image":
        img = next(im for im in bpy.data.images if im.name.endswith("roughness"))
        bpy.data.images.remove(img)
        words = "image of material 'Paint' is gone"
    else:
        ob.data.uv_layers.remove(ob.data.uv_layers[0])
        words = "no UV map"
    _settle(bpy.context.scene)
    bpy.context.view_layer.objects.active = ob
    labels = _draw_appearance_panel()
    if role == "image":
        assert any("image gone: roughness" in t for t in labels), labels
    if words is None:
        appearance.paint(ob, "roughness", [(0.0, -1.0, 0.0)], 0.4, value=0.1)  # the attributes still paint
    else:
        with pytest.raises(ValueError, match=words):
            appearance.paint(ob, "roughness", [(0.0, -1.0, 0.0)], 0.4, value=0.1)
        if role == "attribute":
            assert not bpy.ops.rokeby.appearance_paint.poll()  # greyed out; the panel offers Set Up
            assert any(kind == "operator" and t == "rokeby.appearance_setup" for kind, t in _panel_log())
        else:
            with pytest.raises(RuntimeError, match=words):
                bpy.ops.rokeby.appearance_paint(stroke=[{"name": "", "location": (0.0, -1.0, 0.0)}])
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.samples = 1
    sc.render.resolution_x = sc.render.resolution_y = 16
    sc.render.filepath = str(tmp_path / "after.png")
    bpy.ops.render.render(write_still=True)
    if role == "image":
        # "Make Missing Images" (setup again) makes it from the per-point values; painting works.
        appearance.setup(ob, target="TEXTURE", resolution=32)
        assert appearance.missing_images(ob) == []
        appearance.paint(ob, "roughness", [(0.0, -1.0, 0.0)], 0.4, value=0.1)
    bpy.ops.ed.undo_push(message="delete")
    bpy.ops.ed.undo()
    ob = bpy.data.objects["Ball"]
    np.testing.assert_allclose(appearance.point_values(ob, "roughness"), values, atol=1e-6)
    assert appearance.missing_images(ob) == []


# --- compositing ----------------------------------------------------------------------------------

@pytest.mark.parametrize("role", ["camera", "aov node", "view layer pass"])
def test_delete_anything_compositing_uses(role, registered, tmp_path):
    from rokeby import compositing as comp  # noqa: PLC0415
    from support.compositing import pass_scene

    sc = pass_scene()
    rokeby.register()
    assert bpy.ops.rokeby.composite_setup_passes() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="passes")
    if role == "camera":
        bpy.data.objects.remove(sc.camera, do_unlink=True)
        words = "camera"
    elif role == "aov node":
        for mat in bpy.data.materials:
            for node in [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputAOV"]:
                mat.node_tree.nodes.remove(node)
        words = None  # rendering the passes sets them up again, AOV outputs included
    else:
        sc.view_layers[0].use_pass_glossy_direct = False
        words = None  # rendering the passes enables them again
    path = str(tmp_path / "op.exr")
    if words is None:
        assert bpy.ops.rokeby.composite_render(edit="EMBOSS", filepath=path, image_name="after") == {"FINISHED"}
        assert np.isfinite(np.array(bpy.data.images["after"].pixels[:])).all()
        assert all(any(n.bl_idname == "ShaderNodeOutputAOV" for n in m.node_tree.nodes) for m in bpy.data.materials if m.users)
        assert sc.view_layers[0].use_pass_glossy_direct
    else:
        n_images = len(bpy.data.images)
        with pytest.raises(RuntimeError, match=words):
            bpy.ops.rokeby.composite_render(edit="EMBOSS", filepath=path, image_name="after")
        assert len(bpy.data.images) <= n_images + 1 and "after" not in bpy.data.images  # nothing half made
        with pytest.raises((comp.CompositingError, RuntimeError), match=words):
            comp.reconstruct(comp.render_passes(sc, path))
    bpy.ops.ed.undo_push(message="delete")
    bpy.ops.ed.undo()
    sc = bpy.context.scene
    assert bpy.ops.rokeby.composite_render(edit="EMBOSS", filepath=path, image_name="undone") == {"FINISHED"}
