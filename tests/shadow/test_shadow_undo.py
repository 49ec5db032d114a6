"""Undo and redo of shadow editing: Edit Shadow Boundaries, each confirmed drag and Stop record one
undo step each, and Ctrl+Z / Ctrl+Shift+Z put the session (kept in memory, outside the file) back to
the state of the restored step, the shadow mesh of the drag with it.

Operators called from Python in background mode do not push their undo step: the test pushes it
after each, as Blender's UI does for an operator with the UNDO flag (checked here). The drag is the
operator's own modal code driven with synthetic events (tests/shadow/test_shadow_modal.py)."""

from types import SimpleNamespace

import numpy as np
import pytest

from support import shadow as ts

from test_shadow_modal import _event, _operator, _view

SESSION_OPERATORS = ("shadow_start", "shadow_drag", "shadow_apply", "shadow_stop")


def test_every_shadow_operator_that_changes_the_session_records_an_undo_step():
    bpy = pytest.importorskip("bpy")
    import rokeby

    rokeby.register()
    try:
        for name in SESSION_OPERATORS:
            assert "UNDO" in getattr(bpy.types, "ROKEBY_OT_" + name).bl_options, name
    finally:
        rokeby.unregister()


def test_undo_after_a_drag_takes_back_that_drag_only_and_the_session_follows():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import shadow
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        bpy.ops.ed.undo_push(message="scene set up")
        n_objects = len(bpy.data.objects)
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        bpy.ops.ed.undo_push(message="Edit Shadow Boundaries")
        sess = shadow_ui.session(sc)
        h0 = sess.handles(0)["points"].copy()

        region, rv3d = _view(bpy, sc)
        ctx = SimpleNamespace(scene=sc, region=region, region_data=rv3d, area=SimpleNamespace(type="VIEW_3D"),
                              window_manager=SimpleNamespace(modal_handler_add=lambda op: None),
                              evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
        screen = lambda p: np.array(view3d_utils.location_3d_to_region_2d(region, rv3d, p))  # noqa: E731
        m = int(np.argmax(h0[:, 0]))
        c = h0.mean(axis=0)

        def drag(f):
            op = _operator()
            assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", screen(sess.handles(0)["points"][m]))) == {"RUNNING_MODAL"}
            assert op.modal(ctx, _event("MOUSEMOVE", "NOTHING", screen(c + (h0[m] - c) * f))) == {"RUNNING_MODAL"}
            assert op.modal(ctx, _event("LEFTMOUSE", "RELEASE", (0, 0))) == {"FINISHED"}
            bpy.ops.ed.undo_push(message="Drag Shadow Boundary")
            return sess.handles(0)["points"].copy()

        h1 = drag(1.3)
        h2 = drag(1.5)
        assert not np.allclose(h1, h2) and not np.allclose(h0, h1)

        def state():
            s = shadow_ui.session(bpy.context.scene)
            caster = bpy.data.objects["Ball"]
            mesh = shadow.shadow_mesh_of(caster)
            key = None
            if mesh is not None:
                kb = mesh.data.shape_keys.key_blocks[shadow.configuration_key(0)]
                key = np.array([p.co[:] for p in kb.data])
            return (None if s is None else s.handles(0)["points"].copy()), key, len(bpy.data.objects)

        after2 = state()
        bpy.ops.ed.undo()  # the second drag only
        handles, key1, n = state()
        np.testing.assert_allclose(handles, h1, atol=1e-6)
        assert key1 is not None and not np.allclose(key1, after2[1])
        bpy.ops.ed.undo()  # the first drag: the session as started, no shadow mesh
        handles, key, n = state()
        np.testing.assert_allclose(handles, h0, atol=1e-6)
        assert key is None and n == n_objects
        bpy.ops.ed.undo()  # Edit Shadow Boundaries: no session, the scene as set up
        assert state() == (None, None, n_objects)
        assert shadow_ui._OVERLAY.get(shadow_ui._key(bpy.context.scene)) is None
        assert "Ball" in bpy.data.objects and "Ground" in bpy.data.objects
        bpy.ops.ed.redo()
        handles, key, n = state()
        np.testing.assert_allclose(handles, h0, atol=1e-6)
        bpy.ops.ed.redo()
        bpy.ops.ed.redo()
        handles, key, n = state()
        np.testing.assert_allclose(handles, h2, atol=1e-6)
        np.testing.assert_array_equal(key, after2[1])
        # A drag after undo continues from the restored state.
        bpy.ops.ed.undo()
        sess = shadow_ui.session(bpy.context.scene)
        ctx.scene = bpy.context.scene
        ctx.evaluated_depsgraph_get = bpy.context.evaluated_depsgraph_get
        h3 = drag(1.1)
        assert len(sess.drags) == 2 and not np.allclose(h3, h2)
    finally:
        rokeby.unregister()


def test_undo_of_stop_brings_the_session_back():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        bpy.ops.ed.undo_push(message="scene set up")
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        bpy.ops.ed.undo_push(message="Edit Shadow Boundaries")
        sess = shadow_ui.session(sc)
        h = sess.handles(0)["points"]
        n = len(h)
        assert bpy.ops.rokeby.shadow_drag(loop=0, fixed=((n - n // 5) % n, n // 5), moved=0,
                                          target=tuple(h.mean(0) + (h[0] - h.mean(0)) * 1.3)) == {"FINISHED"}
        bpy.ops.ed.undo_push(message="Drag Shadow Boundary")
        dragged = sess.handles(0)["points"].copy()
        assert bpy.ops.rokeby.shadow_stop() == {"FINISHED"}
        bpy.ops.ed.undo_push(message="Stop Shadow Editing")
        assert shadow_ui.session(bpy.context.scene) is None
        bpy.ops.ed.undo()
        back = shadow_ui.session(bpy.context.scene)
        assert back is sess and len(back.drags) == 1
        np.testing.assert_allclose(back.handles(0)["points"], dragged, atol=1e-6)
        bpy.ops.ed.redo()
        assert shadow_ui.session(bpy.context.scene) is None
    finally:
        rokeby.unregister()


def test_the_redo_panel_repeats_a_drag_with_its_shadow_mesh():
    """Adjust Last Operation after a drag in the view: Blender undoes the drag and runs execute()
    with the changed numbers; the session and the shadow mesh both show the repeated drag."""
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    import rokeby
    from bpy_extras import view3d_utils
    from rokeby import shadow
    from rokeby.shadow import ui as shadow_ui

    rokeby.register()
    try:
        bpy.context.view_layer.objects.active = ball
        bpy.ops.ed.undo_push(message="scene set up")
        assert bpy.ops.rokeby.shadow_start(light="Lamp", min_loop_vertices=10) == {"FINISHED"}
        bpy.ops.ed.undo_push(message="Edit Shadow Boundaries")
        sess = shadow_ui.session(sc)
        h0 = sess.handles(0)["points"].copy()
        region, rv3d = _view(bpy, sc)
        ctx = SimpleNamespace(scene=sc, region=region, region_data=rv3d, area=SimpleNamespace(type="VIEW_3D"),
                              window_manager=SimpleNamespace(modal_handler_add=lambda op: None),
                              evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
        screen = lambda p: np.array(view3d_utils.location_3d_to_region_2d(region, rv3d, p))  # noqa: E731
        m = int(np.argmax(h0[:, 0]))
        c = h0.mean(axis=0)
        op = _operator()
        assert op.invoke(ctx, _event("LEFTMOUSE", "PRESS", screen(h0[m]))) == {"RUNNING_MODAL"}
        assert op.modal(ctx, _event("MOUSEMOVE", "NOTHING", screen(c + (h0[m] - c) * 1.3))) == {"RUNNING_MODAL"}
        assert op.modal(ctx, _event("LEFTMOUSE", "RELEASE", (0, 0))) == {"FINISHED"}
        assert op.apply_edit
        bpy.ops.ed.undo_push(message="Drag Shadow Boundary")
        # The redo panel: undo, then execute with the operator's properties, the target changed.
        bpy.ops.ed.undo()
        assert shadow.shadow_mesh_of(bpy.data.objects["Ball"]) is None
        target = tuple(c + (h0[m] - c) * 1.5)
        assert bpy.ops.rokeby.shadow_drag(loop=op.loop, fixed=tuple(op.fixed), moved=op.moved, target=target,
                                          apply_edit=op.apply_edit) == {"FINISHED"}
        sess = shadow_ui.session(bpy.context.scene)
        np.testing.assert_allclose(sess.handles(0)["points"][m], target, atol=1e-3)
        mesh = shadow.shadow_mesh_of(bpy.data.objects["Ball"])
        assert mesh is not None
        kb = mesh.data.shape_keys.key_blocks[shadow.configuration_key(0)]
        assert not np.allclose(np.array([p.co[:] for p in kb.data]), np.array([p.co[:] for p in mesh.data.shape_keys.key_blocks[0].data]))
    finally:
        rokeby.unregister()
