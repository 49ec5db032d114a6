"""Shadow edits refer to their caster, light, twin light and linking collections by pointer
(problem 2): renaming the caster and the light keeps the edit (the render is the edited
one, pixel for pixel), objects made later under the old names take nothing over and lose nothing,
and a file saved when the links were names (as main wrote them before) loads with its shadow and
then survives renames too. Tiny Cycles renders of tests/shadow/test_shadow.py's top view (96 px, 4
samples, direct light only)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from support import shadow as ts  # noqa: E402
from rokeby import shadow  # noqa: E402
from rokeby.shadow import linking  # noqa: E402
from rokeby.core import schema  # noqa: E402


def _settle(sc):
    """What the UI does after an edit: a depsgraph update, which runs the add-on's handlers."""
    sc.view_layers[0].update()


def _shadow_pixels(img):
    """Pixels of the ground in shadow (below half of the lit ground's brightness)."""
    return int(np.count_nonzero(img < 0.5 * np.percentile(img, 95)))


def _edited(tmp_path):
    """The edited scene of tests/shadow/test_shadow.py, the ball hidden from the camera (the top view
    then sees its whole shadow), its render and the render of the same scene without the edit."""
    bpy_, sc, ball, lamp, ground, _s, ob, twin = ts.edited_scene()
    ball.visible_camera = False
    _settle(sc)
    edited = ts.render(bpy, sc, tmp_path / "edited.png")
    ob.visible_shadow = False
    plain = ts.render(bpy, sc, tmp_path / "plain.png")
    ob.visible_shadow = True
    _settle(sc)
    # The edit shows: hundreds of pixels more shadow than the unedited render.
    assert _shadow_pixels(edited) - _shadow_pixels(plain) > 150, (_shadow_pixels(edited), _shadow_pixels(plain))
    return sc, ball, lamp, ob, twin, edited


def _add_lamp(sc, name):
    ld = bpy.data.lights.new(name, "POINT")
    ld.energy, ld.shadow_soft_size = 300.0, 0.0
    lamp = bpy.data.objects.new(name, ld)
    sc.collection.objects.link(lamp)
    lamp.location = (-3.0, 2.0, 4.0)
    return lamp


def _add_ball(sc, name):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=0.3, location=(-1.2, 1.2, 0.3))
    ob = bpy.context.object
    ob.name = name
    return ob


def test_renaming_caster_and_light_keeps_the_edit_and_namesakes_take_nothing(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    # Reference: the scene with a second light and a second ball under other names.
    others = [_add_lamp(sc, "Other lamp"), _add_ball(sc, "Other ball")]
    _settle(sc)
    with_others = ts.render(bpy, sc, tmp_path / "others.png")
    for o in others:
        bpy.data.objects.remove(o, do_unlink=True)
    _settle(sc)

    ball.name, lamp.name = "Orb", "Key"
    _settle(sc)
    _settle(sc)
    renamed = ts.render(bpy, sc, tmp_path / "renamed.png")
    print(f"shadow pixels: edited {_shadow_pixels(edited)}, after renaming {_shadow_pixels(renamed)}")
    np.testing.assert_allclose(renamed, edited, atol=1e-6, err_msg="renaming the caster and the light changed the render")
    assert shadow.repair(sc) == []
    assert ob.rokeby_shadow.caster == ball and ob.rokeby_shadow.light == lamp and ob.visible_shadow
    assert lamp.rokeby_shadow.twin == twin and twin.parent == lamp

    # New objects under the old names: the same light and ball as the reference's.
    namesakes = [_add_lamp(sc, "Lamp"), _add_ball(sc, "Ball")]
    assert [o.name for o in namesakes] == ["Lamp", "Ball"]
    _settle(sc)
    _settle(sc)
    after = ts.render(bpy, sc, tmp_path / "namesakes.png")
    print(f"shadow pixels with the other lamp and ball: {_shadow_pixels(with_others)}, with namesakes {_shadow_pixels(after)}")
    np.testing.assert_allclose(after, with_others, atol=1e-6,
                               err_msg="a new light or ball under the old names changed the edited shadow")
    assert shadow.repair(sc) == []
    new_lamp, new_ball = namesakes
    assert new_lamp.light_linking.receiver_collection is None and new_lamp.light_linking.blocker_collection is None
    assert new_lamp.rokeby_shadow.twin is None and shadow.shadow_mesh_of(new_ball) is None
    assert shadow.shadow_mesh_of(ball) == ob and ob.rokeby_shadow.light == lamp

    # Saved and reloaded, renamed once more: still the edited render.
    path = str(tmp_path / "renamed.blend")
    for o in namesakes:
        bpy.data.objects.remove(o, do_unlink=True)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    sc = bpy.context.scene
    bpy.data.objects["Orb"].name = "Ball again"
    _settle(sc)
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "reloaded.png"), edited, atol=1e-6)


def _write_as_main_did(ob):
    """Rewrites the links of the edit of shadow mesh ``ob`` the way main stored them before
    pointers (addon/rokeby/shadow.py at 7f12774): names in custom properties on the shadow mesh
    (``rokeby_shadow_of``, ``rokeby_light``), the twin (``rokeby_twin_of``) and the light
    (``rokeby_linking_before``), linking collections found by the name '<light> · <role>', and no
    ``rokeby_shadow`` property group anywhere."""
    links = ob.rokeby_shadow
    caster, light = links.caster, links.light
    twin = light.rokeby_shadow.twin
    ll = light.rokeby_shadow
    ob["rokeby_shadow_of"], ob["rokeby_light"] = caster.name, light.name
    twin["rokeby_twin_of"] = light.name
    light["rokeby_linking_before"] = ["" if c is None else c.name for c in (ll.receivers_before, ll.blockers_before)]
    for attr, role in zip(linking._COLLECTION_ATTRS, linking._OURS):
        c = getattr(ll, attr)
        c.name = linking._collection_name(light.name, role)
        del c[schema.SHADOW_LINKING_TAG]
    for o in (ob, twin, light):
        o.property_unset("rokeby_shadow")
    assert all(o.rokeby_shadow.role == "NONE" and o.rokeby_shadow.twin is None for o in (ob, twin, light))


def test_a_file_saved_with_names_migrates_and_keeps_its_shadow(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    _write_as_main_did(ob)
    path = str(tmp_path / "names.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)  # load_post: handlers.migrate_file
    sc = bpy.context.scene
    ob, ball, lamp, twin = (bpy.data.objects[n] for n in ("Ball" + shadow.SHADOW_SUFFIX, "Ball", "Lamp", "Lamp" + shadow.TWIN_SUFFIX))
    assert not {"rokeby_shadow_of", "rokeby_light"} & set(ob.keys()) and "rokeby_twin_of" not in twin.keys()
    assert "rokeby_linking_before" not in lamp.keys()
    assert (ob.rokeby_shadow.role, ob.rokeby_shadow.caster, ob.rokeby_shadow.light) == ("SHADOW_MESH", ball, lamp)
    assert twin.rokeby_shadow.role == "TWIN" and twin.rokeby_shadow.light == lamp and lamp.rokeby_shadow.twin == twin
    assert lamp.rokeby_shadow.receivers_caster == lamp.light_linking.receiver_collection
    assert lamp.rokeby_shadow.linking_saved and lamp.rokeby_shadow.receivers_before is None
    _settle(sc)
    _settle(sc)
    assert shadow.repair(sc) == []
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "migrated.png"), edited, atol=1e-6)
    # Migrated links are pointers: renames keep the edit, and removing it restores the plain light.
    ball.name, lamp.name = "Orb", "Key"
    _settle(sc)
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "migrated_renamed.png"), edited, atol=1e-6)
    shadow.remove(ball)
    _settle(sc)
    assert lamp.light_linking.receiver_collection is None and lamp.light_linking.blocker_collection is None
    assert not [o for o in bpy.data.objects if o.rokeby_shadow.role != "NONE"]
    assert not [c for c in bpy.data.collections if " · " in c.name]


def test_a_caster_deleted_with_x_switches_the_edit_off(tmp_path):
    """Delete (X) keeps an object in bpy.data while something still uses it (here the linking
    collections hold the caster): an object in no scene is gone for the edit."""
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    for o in bpy.context.view_layer.objects:
        o.select_set(o == ball)
    bpy.context.view_layer.objects.active = ball
    with bpy.context.temp_override(selected_objects=[ball], active_object=ball):
        bpy.ops.object.delete()
    _settle(sc)
    _settle(sc)
    assert not ob.visible_shadow and lamp.rokeby_shadow.twin is None
    assert lamp.light_linking.receiver_collection is None and not [o for o in bpy.data.objects if o.rokeby_shadow.role == "TWIN"]
    assert shadow.repair(sc) == []
    # Nothing of ours keeps the deleted ball: Blender purges it like any object nothing uses.
    assert ob.rokeby_shadow.caster is None and ball.users == 0


def test_an_edit_whose_caster_left_the_scene_comes_back_with_it(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    props = bpy.data.collections.new("Props")
    props.objects.link(ball)
    sc.collection.objects.unlink(ball)
    sc.collection.children.link(props)
    _settle(sc)
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "moved.png"), edited, atol=1e-6)
    sc.collection.children.unlink(props)  # the caster is in no scene now, but not deleted
    _settle(sc)
    assert not ob.visible_shadow and ob.rokeby_shadow.caster == ball
    sc.collection.children.link(props)
    _settle(sc)
    _settle(sc)
    assert ob.visible_shadow and shadow.repair(sc) == []
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "back.png"), edited, atol=1e-6)


def test_start_refuses_a_twin_light_and_a_shadow_mesh(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    with pytest.raises(shadow.ShadowEditError, match="is the twin of 'Lamp'"):
        shadow.start(ball, twin)
    with pytest.raises(shadow.ShadowEditError, match="is the shadow mesh of 'Ball'"):
        shadow.start(ob, lamp)


def test_a_session_survives_renames_and_derived_parts_follow_the_names(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    s = shadow.start(ball, lamp, None, min_loop_vertices=10)
    ball.name, lamp.name = "Orb", "Key"  # during the session
    assert (s.caster, s.light) == ("Orb", "Key")
    h = s.handles(0)["points"].astype(np.float64)
    n, m = len(h), int(np.argmax(h[:, 0]))
    c = h.mean(axis=0)
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, c + (h[m] - c) * 1.35)
    s.commit()
    ob2, twin2 = shadow.apply(s)
    assert (ob2, twin2) == (ob, twin)  # the same parts, found by pointer, renamed after their owners
    assert ob.name == "Orb" + shadow.SHADOW_SUFFIX and twin.name == "Key" + shadow.TWIN_SUFFIX
    assert sorted(c.name for c in bpy.data.collections if schema.SHADOW_LINKING_TAG in c) == sorted(
        linking._collection_name("Key", r) for r in linking._OURS)
    assert {o.name for o in bpy.data.objects if o.rokeby_shadow.role != "NONE"} == {ob.name, twin.name}
    _settle(sc)
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "reapplied.png"), edited, atol=1e-6)


def test_a_copied_light_gets_its_own_linking_and_the_twin_stays(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    copy = lamp.copy()  # what Shift+D does to the object: custom properties and linking come along
    sc.collection.objects.link(copy)
    assert copy.rokeby_shadow.twin == twin and copy.light_linking.receiver_collection is not None
    _settle(sc)
    _settle(sc)
    assert shadow.repair(sc) == []
    assert copy.rokeby_shadow.twin is None and not copy.rokeby_shadow.linking_saved
    assert copy.light_linking.receiver_collection is None and copy.light_linking.blocker_collection is None
    assert lamp.rokeby_shadow.twin == twin and twin.rokeby_shadow.light == lamp
    bpy.data.objects.remove(copy, do_unlink=True)
    _settle(sc)
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "after_copy.png"), edited, atol=1e-6)


def test_a_twin_deleted_with_x_is_made_again(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    with bpy.context.temp_override(selected_objects=[twin], active_object=twin):
        bpy.ops.object.delete()
    _settle(sc)
    _settle(sc)
    assert shadow.repair(sc) == []
    new_twin = lamp.rokeby_shadow.twin
    assert new_twin is not None and new_twin.users_scene and new_twin.rokeby_shadow.light == lamp
    assert [o for o in bpy.data.objects if o.rokeby_shadow.role == "TWIN"] == [new_twin]
    np.testing.assert_allclose(ts.render(bpy, sc, tmp_path / "twin_again.png"), edited, atol=1e-6)


def test_an_edit_from_a_copied_light_leaves_the_original_whole(tmp_path):
    """A light copied with its links, then an edit from the copy: each light has its own twin and
    linking collections, and the original's still hold its caster and shadow mesh."""
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    copy = lamp.copy()
    sc.collection.objects.link(copy)
    copy.location.x += 0.5
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(-1.2, 1.2, 1.0))
    other = bpy.context.object
    s = shadow.start(other, copy, [bpy.data.objects["Ground"]], min_loop_vertices=6)
    h = s.handles(0)["points"].astype(np.float64)
    n, c = len(h), h.mean(axis=0)
    s.drag(0, ((n - n // 5) % n, n // 5), 0, c + (h[0] - c) * 1.3)
    s.commit()
    _ob2, twin2 = shadow.apply(s)
    assert twin2 != twin and lamp.rokeby_shadow.twin == twin and copy.rokeby_shadow.twin == twin2
    colls = {a: getattr(lamp.rokeby_shadow, a) for a in linking._COLLECTION_ATTRS}
    assert not {getattr(copy.rokeby_shadow, a) for a in linking._COLLECTION_ATTRS} & set(colls.values())
    assert ball.name in colls["receivers_caster"].objects and ob.name in colls["blockers_caster"].objects
    _settle(sc)
    assert shadow.repair(sc) == []


def test_edit_shadow_boundaries_picks_the_light_not_its_twin(tmp_path):
    sc, ball, lamp, ob, twin, edited = _edited(tmp_path)
    from rokeby.shadow import ui as shadow_ui

    for o in sc.objects:
        o.select_set(False)
    bpy.context.view_layer.objects.active = ball
    assert bpy.ops.rokeby.shadow_start(min_loop_vertices=10) == {"FINISHED"}  # two lights: the light and its twin
    sess = shadow_ui.session(sc)
    assert (sess.caster, sess.light) == ("Ball", "Lamp")
    sc.name = "Renamed scene"  # sessions belong to the scene, not to its name
    assert shadow_ui.session(sc) is sess
    assert bpy.ops.rokeby.shadow_stop() == {"FINISHED"} and shadow_ui.session(sc) is None
