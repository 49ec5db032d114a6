"""The interactive Drag Shadow Boundary operator (issue 22): its real invoke() and modal() driven
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


def _event(kind, value, xy):
    return SimpleNamespace(type=kind, value=value, mouse_region_x=int(round(xy[0])), mouse_region_y=int(round(xy[1])))


def _operator():
    """The operator's own methods on a plain object holding its properties (background Blender
    cannot instantiate an Operator outside bpy.ops)."""
    from rokeby import shadow_ui

    cls = shadow_ui.ROKEBY_OT_shadow_drag
    op = SimpleNamespace(loop=0, fixed=(0, 0), moved=0, target=(0.0, 0.0, 0.0), style="affine", segment=0.2,
                         noise_amplitude=0.0, noise_frequency=0.0, reports=[])
    op.report = lambda kind, msg: op.reports.append((kind, msg))
    for name in ("_drag", "invoke", "modal"):
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
    loops = rn.shadow_silhouettes(v, t.reshape(-1, 3), light_position=light)
    s = max((lp["points"] for lp in loops), key=len).astype(np.float64)
    g = light + (s - light) * (light[2] / (light[2] - s[:, 2]))[:, None]
    return float(((g - centre) @ direction).max())


def test_modal_drag_with_synthetic_events_live_shadow_follows_release_keeps_esc_restores():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import native, shadow, shadow_ui

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


def test_modal_drag_far_from_any_handle_is_refused_and_changes_nothing():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from rokeby import shadow, shadow_ui

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
        assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", (2, 2))) == {"CANCELLED"}
        assert not added and op.reports and "no shadow handle near the cursor" in op.reports[0][1]
        assert shadow.shadow_mesh_of(ball) is None and shadow_ui.session(sc) is not None
        # Outside a 3D view the operator refuses as well.
        ctx.area = SimpleNamespace(type="IMAGE_EDITOR")
        op = _operator()
        assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", (W / 2, H / 2))) == {"CANCELLED"}
    finally:
        rokeby.unregister()


def test_modal_drag_outside_rendered_shading_says_where_the_live_shadow_shows():
    """The shadow mesh is displayed as Wire, which Solid and Material Preview shading skip: the
    operator says the live shadow shows in Rendered shading, and says nothing there."""
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import shadow, shadow_ui

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
