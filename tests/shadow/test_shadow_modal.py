"""The interactive Drag Shadow Boundary operator: its real invoke() and modal() driven
with synthetic mouse events.

Background Blender has no window, screen or 3D-view region, so no context override can give the
operator a real one; the context here is a stand-in holding the real scene and depsgraph and a
perspective view (region size, view and perspective matrices) made from a camera, which is all
the operator reads through ``bpy_extras.view3d_utils``. Everything else is the operator's own
code: picking the handle nearest the press, ray-casting each mouse move onto the receivers, the
native drag, the live shadow mesh per step, release keeps, Esc restores.
"""

from types import MethodType, SimpleNamespace

import numpy as np
import pytest

from support import shadow as ts

W, H = 400, 300
TOL = 0.02  # of the handle's distance from the shadow's centre: the shadow mesh's silhouette vs the cursor


def _view(bpy, sc):
    """A perspective 3D view looking down at the ball's shadow, as region + RegionView3D stand-ins."""
    from mathutils import Vector

    cam = bpy.data.objects.new("View", bpy.data.cameras.new("View"))
    sc.collection.objects.link(cam)
    cam.location = (0.5, -4.5, 7.0)
    cam.rotation_euler = (Vector((0.0, 0.0, 0.0)) - cam.location).to_track_quat("-Z", "Y").to_euler()
    sc.view_layers[0].update()
    view = cam.matrix_world.inverted()
    proj = cam.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=W, y=H)
    rv3d = SimpleNamespace(view_matrix=view, perspective_matrix=proj @ view, is_perspective=True, view_perspective="PERSP")
    return SimpleNamespace(width=W, height=H), rv3d


def _event(kind, value, xy, **mods):
    e = SimpleNamespace(type=kind, value=value, mouse_region_x=int(round(xy[0])), mouse_region_y=int(round(xy[1])),
                        ctrl=False, shift=False, alt=False, oskey=False)
    for k, v in mods.items():
        setattr(e, k, v)
    return e


def _operator():
    """The operator's own methods on a plain object holding its properties (background Blender
    cannot instantiate an Operator outside bpy.ops)."""
    from rokeby.shadow import ui as shadow_ui

    cls = shadow_ui.ROKEBY_OT_shadow_drag
    op = SimpleNamespace(loop=0, fixed=(0, 0), moved=0, target=(0.0, 0.0, 0.0), style="affine", segment=0.2,
                         noise_amplitude=0.0, noise_frequency=0.0, pass_through=False, apply_edit=False, reports=[])
    op.report = lambda kind, msg: op.reports.append((kind, msg))
    for name in ("_drag", "invoke", "modal", "_nearest", "_begin", "_cancel", "_status"):
        if hasattr(cls, name):
            setattr(op, name, MethodType(getattr(cls, name), op))
    return op


def _shadow_boundary_reach(rn, ob, lamp, centre, direction):
    """How far from ``centre`` along ``direction`` the shadow of ``ob`` (its evaluated mesh: the
    edit key applied) reaches on the ground z = 0: its silhouette from the lamp, projected."""
    import bpy

    ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    try:
        me.calc_loop_triangles()
        v = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", v)
        v = v.reshape(-1, 3)
        t = np.empty(len(me.loop_triangles) * 3, np.int64)
        me.loop_triangles.foreach_get("vertices", t)
    finally:
        ev.to_mesh_clear()
    m = np.array(ob.matrix_world)
    v = (v @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
    light = np.array(lamp.location, np.float64)
    loops = rn.shadows.silhouettes(v, t.reshape(-1, 3), light_position=light)
    s = max((lp["points"] for lp in loops), key=len).astype(np.float64)
    g = light + (s - light) * (light[2] / (light[2] - s[:, 2]))[:, None]
    return float(((g - centre) @ direction).max())


def test_modal_drag_with_synthetic_events_live_shadow_follows_release_keeps_esc_restores():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import shadow
    from rokeby.core import native
    from rokeby.shadow import ui as shadow_ui

    rn = native.module()
    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        sess = shadow_ui.session(sc)
        region, rv3d = _view(bpy, sc)
        added = []
        ctx = SimpleNamespace(scene=sc, region=region, region_data=rv3d, area=SimpleNamespace(type="VIEW_3D"),
                              window_manager=SimpleNamespace(modal_handler_add=added.append),
                              evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
        screen = lambda p: np.array(view3d_utils.location_3d_to_region_2d(region, rv3d, p))  # noqa: E731
        h0 = sess.handles(0)["points"].astype(np.float64)
        centre = h0.mean(axis=0)
        m = int(np.argmax(h0[:, 0]))  # the +x handle, in front of the view
        d = (h0[m] - centre) / np.linalg.norm(h0[m] - centre)
        r0 = np.linalg.norm(h0[m] - centre)

        def drag(factors, finish):
            op = _operator()
            press = sess.handles(0)["points"][m]  # where handle m is now
            assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", screen(press))) == {"RUNNING_MODAL"}, op.reports
            assert added[-1] is op and op.moved == m and op.loop == 0
            # Prepared on the press: the drag's first step is already an O(V) update of the shadow
            # mesh, not a back-substitution (the step that missed a frame).
            assert sess.editor.drag_is_incremental()
            reaches = []
            for f in factors:
                want = centre + d * r0 * f
                assert op.modal(ctx, _event("MOUSEMOVE", "NOTHING", screen(want))) == {"RUNNING_MODAL"}
                # The handle went under the cursor (the ray cast of the mouse position; pixel rounding).
                np.testing.assert_allclose(sess.handles(0)["points"][m], op.target, atol=1e-3)
                assert np.linalg.norm(np.asarray(op.target) - want) < 0.05
                # The live shadow: the shadow mesh in the scene now casts the dragged boundary.
                ob = shadow.shadow_mesh_of(ball)
                assert ob is not None
                reaches.append(_shadow_boundary_reach(rn, ob, lamp, centre, d) - np.dot(np.asarray(op.target) - centre, d))
            end = _event("LEFTMOUSE", "RELEASE", (0, 0)) if finish == "release" else _event("ESC", "PRESS", (0, 0))
            assert op.modal(ctx, end) == ({"FINISHED"} if finish == "release" else {"CANCELLED"})
            assert not op.reports, op.reports
            return reaches

        # 1. A drag released: the shadow mesh follows every step, and stays.
        reaches = drag([1.1, 1.25, 1.4], "release")
        print(f"live shadow boundary minus cursor, per step (units): {np.round(reaches, 4)}")
        assert max(abs(x) for x in reaches) < TOL * r0
        ob = shadow.shadow_mesh_of(ball)
        assert ob is not None
        kept = {k.name: (np.array([p.co[:] for p in k.data]), k.value) for k in ob.data.shape_keys.key_blocks}
        kept_handles = sess.handles(0)["points"].copy()
        assert abs(_shadow_boundary_reach(rn, ob, lamp, centre, d) - r0 * 1.4) < TOL * r0

        # 2. A second drag, cancelled with Esc: live during the drag, then exactly what was kept.
        reaches = drag([1.6, 1.8], "esc")
        assert max(abs(x) for x in reaches) < TOL * r0
        ob = shadow.shadow_mesh_of(ball)
        for k in ob.data.shape_keys.key_blocks:
            co, value = kept[k.name]
            np.testing.assert_array_equal(np.array([p.co[:] for p in k.data]), co)
            assert k.value == value
        np.testing.assert_array_equal(sess.handles(0)["points"], kept_handles)
        assert abs(_shadow_boundary_reach(rn, ob, lamp, centre, d) - r0 * 1.4) < TOL * r0

        # 3. Esc on the first drag of a fresh edit: nothing of the edit is left.
        shadow.remove(ball)
        sess.reset()
        n_objects = len(bpy.data.objects)
        drag([1.3], "esc")
        assert shadow.shadow_mesh_of(ball) is None
        assert len(bpy.data.objects) == n_objects
        np.testing.assert_allclose(sess.handles(0)["points"], h0, atol=1e-6)
    finally:
        rokeby.unregister()


def test_modal_drag_far_from_any_handle_waits_for_a_handle_and_changes_nothing():
    """A press far from every handle: the shortcut passes it on (a click elsewhere still selects);
    the button or menu waits for a press on a handle (one elsewhere in the view is refused with a
    warning), and Esc ends the wait with nothing changed."""
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from rokeby import shadow
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        region, rv3d = _view(bpy, sc)
        added = []
        ctx = SimpleNamespace(scene=sc, region=region, region_data=rv3d, area=SimpleNamespace(type="VIEW_3D"),
                              window_manager=SimpleNamespace(modal_handler_add=added.append),
                              evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
        op = _operator()
        op.pass_through = True
        assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", (2, 2))) == {"PASS_THROUGH"}
        assert not added and not op.reports
        op = _operator()
        assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", (2, 2))) == {"RUNNING_MODAL"}
        assert added == [op]
        assert op.modal(ctx, _event("LEFTMOUSE", "PRESS", (3, 3))) == {"RUNNING_MODAL"}
        assert op.reports and "no shadow handle near the cursor" in op.reports[-1][1]
        assert op.modal(ctx, _event("ESC", "PRESS", (0, 0))) == {"CANCELLED"}
        assert shadow.shadow_mesh_of(ball) is None and shadow_ui.session(sc) is not None
        # Outside a 3D view the operator refuses as well.
        ctx.area = SimpleNamespace(type="IMAGE_EDITOR")
        op = _operator()
        assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", (W / 2, H / 2))) == {"CANCELLED"}
    finally:
        rokeby.unregister()


def _ctx(bpy, sc, region, rv3d, added, **kw):
    return SimpleNamespace(scene=sc, region=region, region_data=rv3d, area=SimpleNamespace(type="VIEW_3D"),
                           window_manager=SimpleNamespace(modal_handler_add=added.append),
                           evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get, **kw)


def test_sidebar_button_waits_for_a_press_on_a_handle_in_the_view():
    """The sidebar's Drag Shadow Boundary button: the click is in the sidebar (another region of
    the 3D view's area), so the operator waits; the next press on a handle in the view's main
    region starts the drag, a click in the sidebar passes on, release keeps the drag."""
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import shadow
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        sess = shadow_ui.session(sc)
        region, rv3d = _view(bpy, sc)
        # The area: the main region at x = 0..W and the sidebar to its right (window coordinates).
        main = SimpleNamespace(type="WINDOW", x=0, y=0, width=W, height=H, data=rv3d)
        side = SimpleNamespace(type="UI", x=W, y=0, width=120, height=H, data=None)
        area = SimpleNamespace(type="VIEW_3D", regions=[side, main])
        added = []
        ctx = _ctx(bpy, sc, side, None, added)
        ctx.area = area

        def ev(kind, value, window_xy):
            e = _event(kind, value, (window_xy[0] - ctx.region.x, window_xy[1] - ctx.region.y))
            e.mouse_x, e.mouse_y = int(round(window_xy[0])), int(round(window_xy[1]))
            return e

        op = _operator()
        assert op.invoke(ctx, ev("LEFTMOUSE", "RELEASE", (W + 60, H / 2))) == {"RUNNING_MODAL"}, op.reports
        assert added == [op] and not op.reports
        # A click on another sidebar button goes to that button.
        assert op.modal(ctx, ev("LEFTMOUSE", "PRESS", (W + 60, 40))) == {"PASS_THROUGH"}
        h = sess.handles(0)["points"].astype(np.float64)
        m = int(np.argmax(h[:, 0]))
        press = view3d_utils.location_3d_to_region_2d(main, rv3d, h[m])
        assert op.modal(ctx, ev("LEFTMOUSE", "PRESS", press)) == {"RUNNING_MODAL"}, op.reports
        assert op.moved == m and op.loop == 0 and len(added) == 1
        c = h.mean(axis=0)
        want = c + (h[m] - c) * 1.3
        assert op.modal(ctx, ev("MOUSEMOVE", "NOTHING", view3d_utils.location_3d_to_region_2d(main, rv3d, want))) == {"RUNNING_MODAL"}
        assert np.linalg.norm(np.asarray(op.target) - want) < 0.05
        assert op.modal(ctx, ev("LEFTMOUSE", "RELEASE", (0, 0))) == {"FINISHED"}
        assert len(sess.drags) == 1 and shadow.shadow_mesh_of(ball) is not None
        np.testing.assert_allclose(sess.handles(0)["points"][m], op.target, atol=1e-3)
    finally:
        rokeby.unregister()


def test_ctrl_z_during_a_drag_cancels_that_drag_only():
    """Ctrl+Z while the mouse button is held: the drag is cancelled (the shape of the kept edit
    comes back bit for bit) and the event goes no further (it would undo a step before the drag)."""
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import shadow
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        sess = shadow_ui.session(sc)
        region, rv3d = _view(bpy, sc)
        added = []
        ctx = _ctx(bpy, sc, region, rv3d, added)
        screen = lambda p: np.array(view3d_utils.location_3d_to_region_2d(region, rv3d, p))  # noqa: E731
        h = sess.handles(0)["points"].astype(np.float64)
        m = int(np.argmax(h[:, 0]))
        c = h.mean(axis=0)
        op = _operator()
        assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", screen(h[m]))) == {"RUNNING_MODAL"}
        assert op.modal(ctx, _event("MOUSEMOVE", "NOTHING", screen(c + (h[m] - c) * 1.3))) == {"RUNNING_MODAL"}
        assert shadow.shadow_mesh_of(ball) is not None
        assert op.modal(ctx, _event("Z", "PRESS", (0, 0), ctrl=True)) == {"CANCELLED"}
        assert shadow.shadow_mesh_of(ball) is None and not sess.drags
        np.testing.assert_allclose(sess.handles(0)["points"], h, atol=1e-6)
    finally:
        rokeby.unregister()


def test_press_on_a_handle_is_a_3d_view_shortcut():
    """The add-on's keymap: a left press in the 3D View starts Drag Shadow Boundary, passing
    presses that are not on a handle on (so clicking still selects)."""
    bpy, *_ = ts.blender_scene()
    import rokeby
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        items = [(km.name, kmi) for km, kmi in shadow_ui._keymaps]
        if bpy.context.window_manager.keyconfigs.addon is None:
            pytest.skip("no add-on key configuration in this Blender (background mode without one)")
        (name, kmi), = [(n, k) for n, k in items if k.idname == "rokeby.shadow_drag"]
        assert name == "3D View" and (kmi.type, kmi.value) == ("LEFTMOUSE", "PRESS")
        assert not (kmi.ctrl or kmi.shift or kmi.alt) and kmi.properties.pass_through
    finally:
        rokeby.unregister()


def test_modal_drag_outside_rendered_shading_says_where_the_live_shadow_shows():
    """The shadow mesh is displayed as Wire, which Solid and Material Preview shading skip: the
    operator says the live shadow shows in Rendered shading, and says nothing there."""
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import shadow
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        sess = shadow_ui.session(sc)
        region, rv3d = _view(bpy, sc)
        press = view3d_utils.location_3d_to_region_2d(region, rv3d, sess.handles(0)["points"][0])
        for shading, said in (("MATERIAL", True), ("SOLID", True), ("RENDERED", False)):
            ctx = SimpleNamespace(scene=sc, region=region, region_data=rv3d, area=SimpleNamespace(type="VIEW_3D"),
                                  space_data=SimpleNamespace(shading=SimpleNamespace(type=shading)),
                                  window_manager=SimpleNamespace(modal_handler_add=lambda op: None),
                                  evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
            op = _operator()
            assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", press)) == {"RUNNING_MODAL"}
            told = [m for kind, m in op.reports if "Rendered viewport shading" in m]
            assert bool(told) == said, (shading, op.reports)
            assert op.modal(ctx, _event("ESC", "PRESS", (0, 0))) == {"CANCELLED"}
            assert shadow.shadow_mesh_of(ball) is None
    finally:
        rokeby.unregister()


if __name__ == "__main__":
    pytest.main([__file__, "-q"])
