"""Freeform shadow boundary editing: the native ShadowEditor on a sphere over a plane
(handles, drags, shadow mesh), bad inputs with clear errors, and in Blender a Cycles render whose
shadow edge follows a dragged handle while the far side stays."""

import os

import numpy as np
import pytest

from support.reference import uv_sphere
from support.shadow import LIGHT, SIZE, blender_scene, edge_along, edited_scene, render
from rokeby.core import native

rn = native.module()


PLANE_V = np.array([[-20, -20, 0], [20, -20, 0], [20, 20, 0], [-20, 20, 0]], np.float32)
PLANE_F = np.array([[0, 1, 2], [0, 2, 3]], np.int64)


@pytest.fixture
def editor():
    v, f = uv_sphere((0, 0, 1.5), 0.5)
    return rn.shadows.ShadowEditor(v, f, PLANE_V, PLANE_F, light_position=LIGHT, min_loop_vertices=10), v, f


def test_handles_lie_on_the_plane_along_light_rays(editor):
    ed, v, f = editor
    loops = ed.loops()
    assert len(loops) == ed.num_loops == 1 and loops[0]["active"]
    h = ed.handles(0)
    s = loops[0]["points"].astype(np.float64)
    assert h["hit"].all() and not h["on_caster"].any()
    want = LIGHT + (s - LIGHT) * (LIGHT[2] / (LIGHT[2] - s[:, 2]))[:, None]
    np.testing.assert_allclose(h["points"], want, atol=1e-5)
    sil = rn.shadows.silhouettes(v, f, light_position=LIGHT)
    np.testing.assert_allclose(sil[0]["points"], s, atol=1e-6)
    assert sil[0]["edges"].shape == (len(s), 2) and 0 < sil[0]["length"] < 2 * np.pi * 0.5


def test_drag_then_shadow_mesh_and_rest_identity(editor):
    ed, v, f = editor
    assert not ed.factored
    np.testing.assert_allclose(ed.shadow_mesh(), v, atol=1e-5)
    assert ed.factored
    h = ed.handles(0)["points"]
    n = len(h)
    centre = h.mean(axis=0)
    target = centre + (h[0] - centre) * 1.3
    r = ed.drag(0, (n - n // 6, n // 6), 0, target, style="similarity")
    np.testing.assert_allclose(r["handles"]["points"][0], target, atol=1e-4)
    assert r["segment"][0] == n - n // 6 and r["segment"][-1] == n // 6
    ed.commit()
    sm = ed.shadow_mesh()
    assert sm.shape == v.shape and np.abs(sm - v).max() > 1e-3
    # The edit is near the dragged vertex: the far side of the caster hardly moves.
    far = np.argmin(v @ (h[0] - centre))
    assert np.abs(sm[far] - v[far]).max() < 0.2 * np.abs(sm - v).max()
    ed.reset()
    np.testing.assert_allclose(ed.shadow_mesh(), v, atol=1e-5)


def test_falloff():
    assert rn.shadows.falloff_factor([0, 0, 1], [0, 0, 1], 3.0) == pytest.approx(1.0)
    a = np.radians(20)
    assert rn.shadows.falloff_factor([0, 0, 1], [0, np.sin(a), np.cos(a)], 2.0) == pytest.approx(np.cos(a) ** 2)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"faces": "open"}, "closed mesh"),
        ({"light_position": [0.0, 0.0, 1.6]}, "inside the caster's volume"),
        ({"light_position": [0.0, 0.0, 0.5]}, "no receiver under the light"),
        ({"receivers": "none"}, "no receiver under the light"),
        ({"light_position": None}, "exactly one of light_position"),
        ({"light_position": [0, 0, 5], "light_direction": [0, 0, -1]}, "exactly one of light_position"),
        ({"vertices": "2d"}, "vertices: expected shape (V, 3)"),
        ({"faces": "float"}, "faces: must be an array of integers"),
        ({"w_z": -1.0}, "w_z"),
        ({"min_loop_vertices": 10_000}, "no silhouette loop"),
    ],
)
def test_bad_inputs_are_clear_errors(kwargs, words):
    v, f = uv_sphere((0, 0, 1.5), 0.5, 8, 12)
    rv, rf = PLANE_V, PLANE_F
    kw = {"light_position": [0.0, 0.0, 5.0], "min_loop_vertices": 3}
    for k, val in kwargs.items():
        if k == "faces":
            f = f[1:] if val == "open" else f.astype(np.float64)
        elif k == "vertices":
            v = v[:, :2]
        elif k == "receivers":
            rv, rf = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int64)
        elif val is None:
            kw.pop(k)
        else:
            kw[k] = val
    with pytest.raises((ValueError, TypeError)) as e:
        rn.shadows.ShadowEditor(v, f, rv, rf, **kw)
    assert words in str(e.value)


def test_bad_drags_change_nothing(editor):
    ed, v, f = editor
    before = ed.loops()[0]["points"].copy()
    for args, kw, words in [
        ((0, (3, 3), 1, [0, 0, 0]), {}, "fixed ends must differ"),
        ((0, (0, 5), 5, [0, 0, 0]), {}, "strictly between"),
        ((4, (0, 5), 2, [0, 0, 0]), {}, "loop 4 does not exist"),
        ((0, (0, 5), 2, [0, 0]), {}, "target: expected shape (3,)"),
        ((0, (0, 5), 2, [0, 0, 0]), {"style": "wobbly"}, "unknown deformation style"),
    ]:
        with pytest.raises(ValueError, match=None) as e:
            ed.drag(*args, **kw)
        assert words in str(e.value)
    np.testing.assert_array_equal(ed.loops()[0]["points"], before)


# --- Blender: the shadow mesh object, linking, and a Cycles render ------------------------------

# EEVEE on a software GL (llvmpipe) spends about three minutes compiling its shaders: opt in with
# ROKEBY_EEVEE_TESTS=1 (measured there: edited edge 22.3 px for a 23.5 px target, far side unmoved).
EEVEE = pytest.param("EEVEE", "POINT", marks=pytest.mark.skipif(
    os.environ.get("ROKEBY_EEVEE_TESTS") != "1", reason="EEVEE on llvmpipe takes minutes; set ROKEBY_EEVEE_TESTS=1"))


@pytest.mark.parametrize("engine, light_type", [("CYCLES", "POINT"), ("CYCLES", "AREA"), EEVEE])
def test_render_shadow_edge_follows_the_dragged_handle(tmp_path, engine, light_type):
    """Cycles with hard (point) and soft (area light, the edge at half intensity) shadows, and EEVEE
    (which in 4.5 honours light and shadow linking and ray visibility)."""
    bpy, sc, ball, lamp, ground = blender_scene(light_type)
    from rokeby import api
    from rokeby.blender import compat

    sc.render.engine = compat.eevee_engine() if engine == "EEVEE" else engine

    ball_before = render(bpy, sc, tmp_path / "ball_before.png")
    # The top view would see the ball over most of its shadow: hide it from the camera only.
    ball.visible_camera = False
    before = render(bpy, sc, tmp_path / "before.png")
    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n = len(h)
    centre = h.mean(axis=0)
    m = int(np.argmax(h[:, 0]))  # the handle on the +x side
    d0 = (h[m] - centre) / np.linalg.norm(h[m] - centre)
    target = centre + (h[m] - centre) * 1.35
    r = s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, target)
    np.testing.assert_allclose(r["handles"]["points"][m], target, atol=1e-3)
    s.commit()
    ob, twin = api.apply_shadow_edit(s)
    assert not ob.visible_camera and ob.visible_shadow and not ob.visible_diffuse
    assert twin.light_linking.blocker_collection is not None
    after = render(bpy, sc, tmp_path / "after.png")
    px_per_unit = SIZE / 4.0
    e0 = edge_along(before, centre, d0)
    e1 = edge_along(after, centre, d0)
    want = np.linalg.norm(target - centre)
    # The shadow of the polygonal ball lies a pixel or so inside the handles of its smooth
    # silhouette (and a soft shadow's half-intensity line a little further in).
    assert abs(e0 - np.linalg.norm(h[m] - centre)) * px_per_unit < 2.5, "unedited render disagrees with the handles"
    assert abs(e1 - want) * px_per_unit < 3.0, f"edited edge at {e1:.3f}, dragged to {want:.3f}"
    moved, asked = (e1 - e0) * px_per_unit, (want - np.linalg.norm(h[m] - centre)) * px_per_unit
    assert abs(moved - asked) < 2.0, f"the edge moved {moved:.1f} px for a {asked:.1f} px drag"
    # The far side of the shadow does not move.
    f0 = edge_along(before, centre, -d0)
    f1 = edge_along(after, centre, -d0)
    assert abs(f1 - f0) * px_per_unit < 1.5, f"far side moved {abs(f1 - f0) * px_per_unit:.1f} px"
    print(f"{engine} {light_type} edge px: unedited {e0 * px_per_unit:.1f} (handle {np.linalg.norm(h[m] - centre) * px_per_unit:.1f}), "
          f"edited {e1 * px_per_unit:.1f} (target {want * px_per_unit:.1f}), far side {f0 * px_per_unit:.1f} -> {f1 * px_per_unit:.1f}")
    # The caster keeps its own shading and self-shadows: no shadow of the shadow mesh falls on it.
    ball.visible_camera = True
    ball_after = render(bpy, sc, tmp_path / "ball_after.png")
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    on_ball = np.hypot((xx + 0.5) / SIZE * 4 - 2, 2 - (yy + 0.5) / SIZE * 4) < 0.45
    assert ball_before[on_ball].mean() > 0.1, "the ball should be lit from above"
    assert np.abs(ball_after[on_ball] - ball_before[on_ball]).max() < 1e-2


def test_blender_bad_inputs_change_nothing():
    bpy, sc, ball, lamp, ground = blender_scene()
    from rokeby import shadow

    n_objects = len(bpy.data.objects)
    bm = ball.data
    # An open caster: delete one face through bmesh.
    import bmesh

    b = bmesh.new()
    b.from_mesh(bm)
    b.faces.ensure_lookup_table()
    bmesh.ops.delete(b, geom=[b.faces[0]], context="FACES_ONLY")
    b.to_mesh(bm)
    b.free()
    with pytest.raises(shadow.ShadowEditError, match="closed mesh"):
        shadow.start(ball, lamp, [ground])
    with pytest.raises(shadow.ShadowEditError, match="not a light"):
        shadow.start(ground, ground, [ball])
    assert len(bpy.data.objects) == n_objects


def _evaluated(bpy, ob):
    dg = bpy.context.evaluated_depsgraph_get()
    e = ob.evaluated_get(dg)
    me = e.to_mesh()
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    e.to_mesh_clear()
    mw = np.array(e.matrix_world)
    co = co.reshape(-1, 3)
    return co @ mw[:3, :3].T + mw[:3, 3]


def test_shadow_mesh_follows_an_armature_pose():
    bpy = pytest.importorskip("bpy")
    bpy_, sc, ball, lamp, ground = blender_scene()
    # Skin the ball to one bone before editing: the shadow mesh gets the same group and modifier.
    arm = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    sc.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    b = arm.data.edit_bones.new("Bone")
    b.head, b.tail = (0.0, 0.0, 1.0), (0.0, 0.0, 2.0)
    bpy.ops.object.mode_set(mode="OBJECT")
    g = ball.vertex_groups.new(name="Bone")
    g.add(list(range(len(ball.data.vertices))), 1.0, "REPLACE")
    mod = ball.modifiers.new("Armature", "ARMATURE")
    mod.object = arm
    from rokeby import api, shadow

    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n, m = len(h), int(np.argmax(h[:, 0]))
    c = h.mean(axis=0)
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, c + (h[m] - c) * 1.35)
    s.commit()
    ob, _twin = api.apply_shadow_edit(s)
    assert [vg.name for vg in ob.vertex_groups] == ["Bone"]
    assert [(md.type, md.object) for md in ob.modifiers] == [("ARMATURE", arm)]
    rest_shadow = _evaluated(bpy, ob)
    rest_ball = _evaluated(bpy, ball)
    assert np.abs(rest_shadow - rest_ball).max() > 1e-3  # the edit is there
    # Pose: rotate the bone 30° about x and lift it; both meshes move the same way.
    pb = arm.pose.bones["Bone"]
    pb.rotation_mode = "XYZ"
    pb.rotation_euler = (np.radians(30), 0.0, 0.0)
    pb.location = (0.0, 0.3, 0.0)
    sc.view_layers[0].update()
    posed_shadow = _evaluated(bpy, ob)
    posed_ball = _evaluated(bpy, ball)
    assert np.abs(posed_ball - rest_ball).max() > 0.1
    # A single rigid bone: the edit's offset rotates with the pose, its length is kept.
    np.testing.assert_allclose(np.linalg.norm(posed_shadow - posed_ball, axis=1),
                               np.linalg.norm(rest_shadow - rest_ball, axis=1), atol=1e-4)
    # And the falloff key scales it: β large and the light moved far → almost the original.
    lamp.location = (4.0, 0.0, 1.5)
    sc.view_layers[0].update()
    k = shadow.update_falloff(ob, lamp, 8.0)
    assert 0.0 <= k < 0.2
    sc.view_layers[0].update()
    blended = _evaluated(bpy, ob)
    np.testing.assert_allclose(blended - posed_ball, k * (posed_shadow - posed_ball), atol=1e-4)


def test_light_moved_20_degrees_puts_no_new_shadow_on_the_caster(tmp_path):
    bpy, sc, ball, lamp, ground, s, ob, twin = edited_scene()
    # Rotate the light 20° about the ball's centre (around the y axis); its twin follows.
    a = np.radians(20)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    c = np.array([0.0, 0.0, 1.5])
    new = rot @ (LIGHT - c) + c
    lamp.location = tuple(new)
    sc.view_layers[0].update()
    np.testing.assert_allclose(np.array(twin.matrix_world.translation), new, atol=1e-6)
    edited = render(bpy, sc, tmp_path / "edited.png")
    # The same light without the edit: hide the shadow mesh, drop the linking.
    ob.visible_shadow = False
    lamp.light_linking.receiver_collection = None
    lamp.light_linking.blocker_collection = None
    twin.hide_render = True
    sc.view_layers[0].update()
    plain = render(bpy, sc, tmp_path / "plain.png")
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    on_ball = np.hypot((xx + 0.5) / SIZE * 4 - 2, 2 - (yy + 0.5) / SIZE * 4) < 0.45
    assert plain[on_ball].mean() > 0.1
    np.testing.assert_allclose(edited[on_ball], plain[on_ball], atol=1e-3)
    # The edited shadow is still there on the ground (the two renders differ off the ball).
    assert np.abs(edited - plain)[~on_ball].max() > 0.1


def test_operators_start_drag_apply_and_the_overlay():
    bpy, sc, ball, lamp, ground = blender_scene()
    import rokeby
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        sess = shadow_ui.session(sc)
        geo = shadow_ui.overlay_geometry(sess)
        n = len(sess.loops()[0]["points"])
        assert geo["lines"].shape == (2 * n, 3) and geo["points"].shape == (n, 3)
        np.testing.assert_allclose(geo["line_colors"][0], shadow_ui.ACTIVE)
        # Seen from below the ground every handle is hidden: no boundary is drawn.
        hidden = shadow_ui.overlay_geometry(sess, eye=(0.0, 0.0, -5.0))
        assert len(hidden["lines"]) == 0 and len(hidden["points"]) == 0
        h = sess.handles(0)["points"].astype(np.float64)
        c = h.mean(axis=0)
        target = c + (h[3] - c) * 1.3
        assert bpy.ops.rokeby.shadow_drag(loop=0, fixed=(n - 8, 14), moved=3, target=tuple(target), style="rigid") == {"FINISHED"}
        np.testing.assert_allclose(sess.handles(0)["points"][3], target, atol=1e-3)
        # A bad drag is refused and changes nothing.
        before = sess.handles(0)["points"].copy()
        with pytest.raises(RuntimeError, match="strictly between"):
            bpy.ops.rokeby.shadow_drag(loop=0, fixed=(3, 14), moved=3, target=(0.0, 0.0, 0.0))
        np.testing.assert_array_equal(sess.handles(0)["points"], before)
        assert bpy.ops.rokeby.shadow_apply() == {"FINISHED"}
        assert bpy.data.objects.get("Ball" + "" + " Shadow Mesh") is not None
        # Errors are reported, not raised as tracebacks: a caster that is not a mesh.
        bpy.context.view_layer.objects.active = lamp
        with pytest.raises(RuntimeError, match="not a mesh"):
            bpy.ops.rokeby.shadow_start(light="Lamp")
        assert bpy.ops.rokeby.shadow_stop() == {"FINISHED"} and shadow_ui.session(sc) is None
    finally:
        rokeby.unregister()
