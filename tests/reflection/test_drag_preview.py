"""Red-handle drags with geodesic distances: while the handle moves in a window, the
moved constraint's distances come from the fast drag method (a preview the report names); when
the drag ends, and before any render or save, the mirror's own method recomputes them, so what
renders and what is saved is always the accurate field."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from rokeby import api  # noqa: E402
from rokeby.core import schema  # noqa: E402
from rokeby.reflection import evaluate, geodesic_cache, handlers, mirror_state  # noqa: E402
from support.wysiwyg import new_scene, read_layers, sphere  # noqa: E402

FIELDS = (schema.ROTATION_ATTRIBUTE, schema.RENDER_ATTRIBUTE, schema.RENDER_ATTRIBUTE_WA)
# Red-handle positions of the drag (on the side of the ball the camera sees).
STEPS = [(0.25, -0.95, 0.1), (0.4, -0.9, 0.15), (0.55, -0.8, 0.2)]


@pytest.fixture
def window(monkeypatch):
    """Depsgraph updates as in a Blender window (a drag is a stream of interactive updates); the
    timers the add-on asks for are kept here instead of running."""
    timers = []
    monkeypatch.setattr(handlers, "WINDOW_UPDATES", True)
    monkeypatch.setattr(handlers, "_settle_pending", False)
    monkeypatch.setattr(evaluate, "_schedule", lambda fn, seconds: timers.append(fn))
    return timers


def _mirror():
    new_scene()
    ball = sphere(48, 24)
    api.add_mirror(ball)
    ball.rokeby.metric, ball.rokeby.geodesic_method = "GEODESIC", "GRAPH"
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.8, -3.0, 1.0))
    api.add_constraint(ball, (-0.6, -0.8, 0.0), (-1.5, -3.0, -0.6))
    rep = api.evaluate()["Ball"]
    assert rep.status != "ERROR" and not rep.drag_preview, rep.summary()
    return ball


def _drag_red(ball, to):
    ball.rokeby.constraints[0].surface_handle.location = to
    bpy.context.view_layer.update()  # the depsgraph handler, as in a window: interactive


def _read(me, name):
    attr = me.attributes[name]  # per vertex, or per face corner (rokeby.reflection.field_attributes)
    a = np.empty(3 * len(attr.data), np.float32)
    attr.data.foreach_get("vector", a)
    return a.reshape(-1, 3)


def _stored(ball):
    return {name: _read(ball.data, name) for name in FIELDS}


def _accurate(ball):
    """The field a direct, non-interactive evaluation stores for the same scene, its geodesic
    distances solved afresh (the mesh and its surface queries kept, so that the handles project
    to the very same surface points)."""
    st = mirror_state.state_of(ball)
    st.distance_cache.clear()
    st.distances_ready = None
    rep = api.evaluate(force=True)["Ball"]
    assert rep.status != "ERROR" and not rep.drag_preview, rep.summary()
    return _stored(ball)


def _differs(a, b):
    return max(float(np.abs(a[n] - b[n]).max()) for n in FIELDS)


@pytest.mark.parametrize("preview", ["update", "dijkstra"])
def test_a_drag_shows_a_preview_and_the_release_stores_the_accurate_field(window, monkeypatch, preview):
    """Either preview: the accurate distances updated from the drag's start (geodesic_cache.DRAG_UPDATE),
    or a Dijkstra solve (where the update is no fair guess, or with DRAG_UPDATE off)."""
    monkeypatch.setattr(geodesic_cache, "DRAG_UPDATE", preview == "update")
    ball = _mirror()
    for to in STEPS:
        _drag_red(ball, to)
        rep = api.report(ball)
        assert rep.recomputed and rep.drag_preview and rep.status != "ERROR", rep.summary()
        assert any(m.startswith("drag preview:") and "dijkstra" in m and "graph" in m for m in rep.messages)
    # Which preview ran: updates ("drag"; the last step is beyond DRAG_UPDATE_REACH of the start,
    # so Dijkstra solves there), or Dijkstra only.
    kinds = {key[0] for key in mirror_state.state_of(ball).distance_cache}
    assert kinds == ({"graph", "drag", "dijkstra"} if preview == "update" else {"graph", "dijkstra"}), kinds
    settle = [fn for fn in window if fn is handlers._settle_timer]
    assert len(settle) == 1, "the end of the drag was not scheduled (once)"
    preview = _stored(ball)
    # The updates go on: the timer waits.
    assert settle[0]() > 0 and mirror_state.state_of(ball).preview
    mirror_state.state_of(ball).interactive_time -= 10.0  # the pause: the artist let go
    assert settle[0]() is None
    rep = api.report(ball)
    assert not rep.drag_preview and not any(m.startswith("drag preview") for m in rep.messages), rep.summary()
    released = _stored(ball)
    accurate = _accurate(ball)
    for name in FIELDS:
        np.testing.assert_array_equal(released[name], accurate[name], err_msg=name)
    assert _differs(preview, accurate) > 1e-3  # the preview was a different field


def test_the_first_non_interactive_evaluation_replaces_the_preview(window):
    ball = _mirror()
    _drag_red(ball, STEPS[0])
    assert api.report(ball).drag_preview
    rep = api.evaluate()["Ball"]  # nothing moved since; not interactive
    assert rep.recomputed and not rep.drag_preview
    released = _stored(ball)
    accurate = _accurate(ball)
    for name in FIELDS:
        np.testing.assert_array_equal(released[name], accurate[name], err_msg=name)


def test_f12_right_after_a_drag_step_renders_the_accurate_field(window, tmp_path):
    ball = _mirror()
    _drag_red(ball, STEPS[1])
    assert api.report(ball).drag_preview
    preview = _stored(ball)
    sc = bpy.context.scene
    sc.render.filepath = str(tmp_path / "after_drag.exr")
    bpy.ops.render.render(write_still=True)  # render_pre: the accurate distances first
    dragged = read_layers(sc.render.filepath)["Combined"]
    assert not api.report(ball).drag_preview
    # What the render read: the evaluated mesh's field attributes.
    dg = bpy.context.evaluated_depsgraph_get()
    me = ball.evaluated_get(dg).data
    rendered = {name: _read(me, name) for name in FIELDS}
    accurate = _accurate(ball)
    for name in FIELDS:
        np.testing.assert_array_equal(rendered[name], accurate[name], err_msg=name)
    assert _differs(preview, accurate) > 1e-3
    sc.render.filepath = str(tmp_path / "accurate.exr")
    bpy.ops.render.render(write_still=True)
    np.testing.assert_array_equal(dragged, read_layers(sc.render.filepath)["Combined"])


def test_a_save_right_after_a_drag_step_holds_the_accurate_field(window, tmp_path):
    ball = _mirror()
    _drag_red(ball, STEPS[2])
    assert api.report(ball).drag_preview
    preview = _stored(ball)
    path = tmp_path / "dragged.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))  # save_pre: the accurate distances first
    held = _stored(ball)
    accurate = _accurate(ball)
    for name in FIELDS:
        np.testing.assert_array_equal(held[name], accurate[name], err_msg=name)
    assert _differs(preview, accurate) > 1e-3
    bpy.ops.wm.open_mainfile(filepath=str(path))
    saved = _stored(bpy.data.objects["Ball"])
    for name in FIELDS:
        np.testing.assert_array_equal(saved[name], held[name], err_msg=name)
