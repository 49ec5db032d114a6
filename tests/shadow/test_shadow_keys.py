"""Keyed configurations (§6.2) and the live shadow while dragging (Fig. 3 B–D).

Keyed configurations: an edit made under two light positions is blended by the light's angle to
each; at the midpoint the rendered boundary lies between the two edits' boundaries. Live shadow:
every drag step writes the shadow mesh, so the viewport (EEVEE, solid with shadows) shows the edited
shadow during the drag; cancelling leaves the scene as before."""

import numpy as np
import pytest

from support import shadow as ts


def _rotated(deg):
    a = np.radians(deg)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    c = np.array([0.0, 0.0, 1.5])
    return rot @ (ts.LIGHT - c) + c


def _edit(api, ball, lamp, ground, scale):
    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n, m = len(h), int(np.argmax(h[:, 0]))
    c = h.mean(axis=0)
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, c + (h[m] - c) * scale)
    s.commit()
    return s


def _edge(img, lamp_pos):
    """The +x shadow edge (world units from the shadow's centre) under a light at ``lamp_pos``."""
    c = np.array([0.0, 0.0, 1.5])
    centre = lamp_pos + (c - lamp_pos) * (lamp_pos[2] / (lamp_pos[2] - c[2]))
    return ts.edge_along(img, centre, np.array([1.0, 0.0, 0.0]))


def test_two_keyed_configurations_blend_at_the_midpoint(tmp_path):
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    from rokeby import api, shadow
    from rokeby.core import schema

    ball.visible_camera = False
    l1, l2, mid = ts.LIGHT.astype(float), _rotated(30.0), _rotated(15.0)
    s1 = _edit(api, ball, lamp, ground, 1.4)  # made under l1: the +x edge pushed out
    ob, _ = api.apply_shadow_edit(s1)
    lamp.location = tuple(mid)
    sc.view_layers[0].update()
    only1 = _render(bpy, sc, tmp_path / "only1.png")
    lamp.location = tuple(l2)
    sc.view_layers[0].update()
    s2 = _edit(api, ball, lamp, ground, 0.75)  # made under l2: the +x edge pulled in
    ob2, _ = api.apply_shadow_edit(s2, add_configuration=True)
    assert ob2 == ob and s2.configuration == 1
    assert [k.name for k in ob.data.shape_keys.key_blocks] == ["Basis", schema.SHADOW_EDIT_KEY, shadow.configuration_key(1)]
    np.testing.assert_allclose(shadow.configuration_weights(ob, lamp), [0.0, 1.0], atol=1e-6)
    lamp.location = tuple(l1)
    sc.view_layers[0].update()
    np.testing.assert_allclose(shadow.configuration_weights(ob, lamp), [1.0, 0.0], atol=1e-6)
    lamp.location = tuple(mid)
    sc.view_layers[0].update()  # the handlers blend the keys by the light's angles
    w = [k.value for k in ob.data.shape_keys.key_blocks[1:]]
    np.testing.assert_allclose(w, [0.5, 0.5], atol=0.02)
    blended = _render(bpy, sc, tmp_path / "blended.png")
    # Configuration 2 alone under the midpoint light.
    api.remove_shadow_edit(ball)
    api.apply_shadow_edit(s2)
    lamp.location = tuple(mid)
    sc.view_layers[0].update()
    only2 = _render(bpy, sc, tmp_path / "only2.png")
    e1, e2, eb = (_edge(img, mid) for img in (only1, only2, blended))
    px = ts.SIZE / 4.0
    print(f"midpoint +x edge px: edit 1 {e1 * px:.1f}, edit 2 {e2 * px:.1f}, blended {eb * px:.1f}")
    assert (e1 - e2) * px > 4.0, "the two edits should differ clearly under the midpoint light"
    assert e2 * px + 1.0 < eb * px < e1 * px - 1.0, "the blended boundary must lie between the two edits"


def _render(bpy, sc, path):
    return ts.render(bpy, sc, path)


def test_a_file_with_two_configurations_reloads_them(tmp_path):
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    from rokeby import api, shadow
    from rokeby.core import schema

    s1 = _edit(api, ball, lamp, ground, 1.3)
    api.apply_shadow_edit(s1)
    lamp.location = tuple(_rotated(30.0))
    sc.view_layers[0].update()
    s2 = _edit(api, ball, lamp, ground, 0.8)
    ob, _ = api.apply_shadow_edit(s2, add_configuration=True)
    path = str(tmp_path / "keys.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    ob = bpy.data.objects["Ball" + shadow.SHADOW_SUFFIX]
    lamp = bpy.data.objects["Lamp"]
    assert shadow.configuration_vectors(ob).shape == (2, 3)
    np.testing.assert_allclose(shadow.configuration_weights(ob, lamp), [0.0, 1.0], atol=1e-6)
    # A new edit applied without add_configuration replaces the edit, every configuration of it.
    ball, ground = bpy.data.objects["Ball"], bpy.data.objects["Ground"]
    ob, _ = api.apply_shadow_edit(_edit(api, ball, lamp, ground, 1.2))
    assert shadow.configuration_vectors(ob).shape == (1, 3)
    assert [k.name for k in ob.data.shape_keys.key_blocks] == ["Basis", schema.SHADOW_EDIT_KEY]


def test_add_configuration_from_another_light_is_refused(tmp_path):
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    from rokeby import api, shadow

    api.apply_shadow_edit(_edit(api, ball, lamp, ground, 1.3))
    other = bpy.data.objects.new("Other", lamp.data.copy())
    sc.collection.objects.link(other)
    other.location = (-0.5, 0.3, 5.0)
    sc.view_layers[0].update()
    s = _edit(api, ball, other, ground, 1.2)
    keys_before = [k.name for k in shadow.shadow_mesh_of(ball).data.shape_keys.key_blocks]
    with pytest.raises(shadow.ShadowEditError, match="add_configuration"):
        api.apply_shadow_edit(s, add_configuration=True)
    assert [k.name for k in shadow.shadow_mesh_of(ball).data.shape_keys.key_blocks] == keys_before


def _key(ob, name=None):
    from rokeby.core import schema

    k = ob.data.shape_keys.key_blocks[name or schema.SHADOW_EDIT_KEY]
    co = np.empty(len(ob.data.vertices) * 3, np.float32)
    k.data.foreach_get("co", co)
    return co.reshape(-1, 3)


def test_live_shadow_mesh_changes_every_drag_step_and_cancel_restores(tmp_path):
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    from rokeby import api, shadow

    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n, m = len(h), int(np.argmax(h[:, 0]))
    c = h.mean(axis=0)
    fixed = ((m - n // 5) % n, (m + n // 5) % n)
    live = shadow.live_begin(s)  # no edit yet: the preview installs one
    ob = live.shadow_object
    assert live.created and shadow.shadow_mesh_of(ball) == ob
    rest = _key(ob)
    seen = [rest]
    for scale in (1.1, 1.2, 1.3):  # three steps of one drag (mouse moves)
        s.drag(0, fixed, m, c + (h[m] - c) * scale)
        shadow.live_step(live)
        seen.append(_key(ob))
    for a, b in zip(seen, seen[1:]):
        assert np.abs(b - a).max() > 1e-3, "each drag step must change the shadow mesh"
    # What a render (and the viewport) shows mid-drag: the edited edge, before any release.
    ball.visible_camera = False
    mid = ts.render(bpy, sc, tmp_path / "mid.png")
    want = np.linalg.norm(h[m] - c) * 1.3
    got = ts.edge_along(mid, c, (h[m] - c) / np.linalg.norm(h[m] - c))
    assert abs(got - want) * ts.SIZE / 4.0 < 3.0, f"mid-drag edge at {got:.3f}, cursor at {want:.3f}"
    # Esc: the drag is dropped and the preview's shadow mesh goes.
    s.cancel()
    shadow.live_end(live, keep=False)
    assert shadow.shadow_mesh_of(ball) is None
    assert lamp.light_linking.blocker_collection is None


def test_live_cancel_on_an_applied_edit_puts_its_keys_back():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    from rokeby import api, shadow

    s = _edit(api, ball, lamp, ground, 1.3)
    ob, _ = api.apply_shadow_edit(s)
    before = _key(ob)
    h = s.handles(0)["points"].astype(np.float64)
    n, m = len(h), int(np.argmin(h[:, 0]))
    c = h.mean(axis=0)
    live = shadow.live_begin(s)
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, c + (h[m] - c) * 1.4)
    shadow.live_step(live)
    assert np.abs(_key(ob) - before).max() > 1e-3
    s.cancel()
    shadow.live_end(live, keep=False)
    np.testing.assert_array_equal(_key(ob), before)
    # And a kept drag is applied: the key holds the committed edit.
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, c + (h[m] - c) * 1.4)
    live = shadow.live_begin(s)
    shadow.live_step(live)
    stepped = _key(ob)
    s.commit()
    shadow.live_end(live, keep=True)
    np.testing.assert_allclose(_key(ob), stepped, atol=1e-6)


def test_apply_operator_adds_a_key_configuration_and_the_panel_offers_it():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from rokeby import shadow
    from rokeby.shadow import ui as shadow_ui
    from support.ui import Layout

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        for location, scale in ((tuple(ts.LIGHT), 1.3), (tuple(_rotated(30.0)), 0.8)):
            lamp.location = location
            sc.view_layers[0].update()
            assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
            sess = shadow_ui.session(sc)
            h = sess.handles(0)["points"].astype(np.float64)
            n, c = len(h), h.mean(axis=0)
            assert bpy.ops.rokeby.shadow_drag(loop=0, fixed=(n - 8, 14), moved=3, target=tuple(c + (h[3] - c) * scale)) == {"FINISHED"}
            log = []
            shadow_ui.ROKEBY_PT_shadow.draw(type("P", (), {"layout": Layout(log)})(), bpy.context)
            assert bpy.ops.rokeby.shadow_apply(add_configuration=location != tuple(ts.LIGHT)) == {"FINISHED"}
        ob = shadow.shadow_mesh_of(ball)
        assert shadow.configuration_vectors(ob).shape == (2, 3)
        assert log.count(("operator", "rokeby.shadow_apply")) == 2  # Apply, and Add as Key Configuration
    finally:
        rokeby.unregister()
