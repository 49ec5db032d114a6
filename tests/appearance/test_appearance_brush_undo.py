"""The appearance brush (Paint Appearance, modal) and undo: one undo step per stroke, Ctrl+Z while
the brush runs takes back this brush's strokes only (refused before its first stroke, so it never
removes Set Up Appearance Painting or a stroke of an earlier brush), refused during a stroke; and a
click outside the 3D view's main region (a sidebar button) is not taken by the brush.

The operator's own modal() runs on a stand-in of its instance and of the context (a perspective
view made of matrices), as in tests/appearance/test_appearance.py; Blender's keymap is stood in by
calling ``bpy.ops.ed.undo()`` / ``redo()`` where the operator passes Ctrl+Z on."""

import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from rokeby import appearance  # noqa: E402

from test_appearance import brush_operator  # noqa: E402

SIZE, F, D = 200, 2.0, 5.0  # region pixels; focal length (NDC); eye at y = −5


class _Ctx:
    """The context a modal sees: the view's regions, and the active object fetched again at each
    use (undo replaces Blender's data)."""

    def __init__(self, region, rv3d, area):
        self.region, self.region_data, self.area = region, rv3d, area
        self.window_manager = bpy.context.window_manager
        self.workspace = types.SimpleNamespace(status_text_set=lambda _t: None)

    @property
    def scene(self):
        return bpy.context.scene

    @property
    def active_object(self):
        return bpy.context.view_layer.objects.active

    def evaluated_depsgraph_get(self):
        return bpy.context.evaluated_depsgraph_get()


def _view():
    from mathutils import Matrix

    view = Matrix(((1, 0, 0, 0), (0, 0, 1, 0), (0, -1, 0, -D), (0, 0, 0, 1)))  # looking along +Y, z up
    near, far = 0.1, 100.0
    proj = Matrix(((F, 0, 0, 0), (0, F, 0, 0), (0, 0, -(far + near) / (far - near), -2 * far * near / (far - near)), (0, 0, -1, 0)))
    return types.SimpleNamespace(view_matrix=view, perspective_matrix=proj @ view, is_perspective=True, view_perspective="PERSP")


def _event(kind, value, x, y, **mods):
    e = types.SimpleNamespace(type=kind, value=value, mouse_region_x=x, mouse_region_y=y, mouse_x=x, mouse_y=y,
                              ctrl=False, shift=False, alt=False, oskey=False)
    for k, v in mods.items():
        setattr(e, k, v)
    return e


@pytest.fixture
def painted():
    import rokeby

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=1.0)
    ob = bpy.context.object
    ob.name = "Ball"
    mat = bpy.data.materials.new("Paint")
    mat.use_nodes = True
    ob.data.materials.append(mat)
    rokeby.register()
    try:
        bpy.ops.ed.undo_push(message="scene")
        assert bpy.ops.rokeby.appearance_setup() == {"FINISHED"}
        bpy.ops.ed.undo_push(message="Set Up Appearance Painting")
        s = bpy.context.scene.rokeby_appearance_brush
        s.brush, s.radius, s.strength, s.value = "roughness", 0.3, 1.0, 0.9
        yield
    finally:
        rokeby.unregister()


def _roughness():
    ob = bpy.data.objects["Ball"]
    if appearance.PARAMS["roughness"][0] not in ob.data.attributes:
        return None
    return appearance.read(ob, "roughness").copy()


def test_ctrl_z_in_the_brush_undoes_its_strokes_only(painted):
    from rokeby.appearance import ui as appearance_ui

    modal = appearance_ui.ROKEBY_OT_appearance_paint.modal
    region = types.SimpleNamespace(width=SIZE, height=SIZE)
    ctx = _Ctx(region, _view(), types.SimpleNamespace(type="VIEW_3D", tag_redraw=lambda: None))
    reports = []
    op = brush_operator(reports)
    z, shift_z = dict(ctrl=True), dict(ctrl=True, shift=True)
    set_up = _roughness()

    # Before any stroke of this brush: Ctrl+Z is refused (it would undo Set Up Appearance Painting).
    assert modal(op, ctx, _event("Z", "PRESS", 100, 100, **z)) == {"RUNNING_MODAL"}
    assert reports and "no stroke of this brush" in reports[-1][1]

    def stroke(x0, y0, x1, y1):
        assert modal(op, ctx, _event("LEFTMOUSE", "PRESS", x0, y0)) == {"RUNNING_MODAL"}
        assert modal(op, ctx, _event("MOUSEMOVE", "NOTHING", x1, y1)) == {"RUNNING_MODAL"}
        # Mid-stroke Ctrl+Z is refused (it would cut the stroke in two).
        assert modal(op, ctx, _event("Z", "PRESS", x1, y1, **z)) == {"RUNNING_MODAL"}
        assert modal(op, ctx, _event("LEFTMOUSE", "RELEASE", x1, y1)) == {"RUNNING_MODAL"}
        return _roughness()

    first = stroke(100, 100, 110, 100)
    second = stroke(100, 130, 110, 130)
    assert np.abs(first - set_up).max() > 0.3 and np.abs(second - first).max() > 0.3

    def key(mods, expect):
        got = modal(op, ctx, _event("Z", "PRESS", 150, 150, **mods))
        assert got == expect
        if got == {"PASS_THROUGH"}:  # Blender's keymap runs the undo operator
            (bpy.ops.ed.undo if "shift" not in mods else bpy.ops.ed.redo)()

    key(z, {"PASS_THROUGH"})
    np.testing.assert_array_equal(_roughness(), first)
    key(z, {"PASS_THROUGH"})
    np.testing.assert_array_equal(_roughness(), set_up)
    key(z, {"RUNNING_MODAL"})  # refused: the set-up stays
    np.testing.assert_array_equal(_roughness(), set_up)
    key(shift_z, {"PASS_THROUGH"})
    np.testing.assert_array_equal(_roughness(), first)
    key(shift_z, {"PASS_THROUGH"})
    np.testing.assert_array_equal(_roughness(), second)
    key(shift_z, {"RUNNING_MODAL"})  # nothing of this brush left to redo
    # Ending the brush pushes no step of its own: one Ctrl+Z after it takes back the last stroke.
    assert modal(op, ctx, _event("ESC", "PRESS", 150, 150)) == {"CANCELLED"}
    bpy.ops.ed.undo()
    np.testing.assert_array_equal(_roughness(), first)


def test_a_click_outside_the_view_is_not_taken_by_the_brush(painted):
    """The brush started from the sidebar: its region is the sidebar's; a click on a sidebar button
    goes to the button (nothing painted), a drag over the view's main region paints."""
    from rokeby.appearance import ui as appearance_ui

    modal = appearance_ui.ROKEBY_OT_appearance_paint.modal
    main = types.SimpleNamespace(type="WINDOW", x=0, y=0, width=SIZE, height=SIZE, data=_view())
    side = types.SimpleNamespace(type="UI", x=SIZE, y=0, width=80, height=SIZE, data=None)
    area = types.SimpleNamespace(type="VIEW_3D", regions=[side, main], tag_redraw=lambda: None)
    ctx = _Ctx(side, None, area)
    op = brush_operator([])
    before = _roughness()

    def ev(kind, value, x, y):  # window coordinates; region coordinates relative to the sidebar
        e = _event(kind, value, x - SIZE, y)
        e.mouse_x, e.mouse_y = x, y
        return e

    assert modal(op, ctx, ev("LEFTMOUSE", "PRESS", SIZE + 40, 100)) == {"PASS_THROUGH"}
    assert modal(op, ctx, ev("LEFTMOUSE", "RELEASE", SIZE + 40, 100)) == {"PASS_THROUGH"}
    np.testing.assert_array_equal(_roughness(), before)
    assert modal(op, ctx, ev("LEFTMOUSE", "PRESS", 100, 100)) == {"RUNNING_MODAL"}
    assert modal(op, ctx, ev("MOUSEMOVE", "NOTHING", 110, 100)) == {"RUNNING_MODAL"}
    assert modal(op, ctx, ev("LEFTMOUSE", "RELEASE", 110, 100)) == {"RUNNING_MODAL"}
    assert np.abs(_roughness() - before).max() > 0.3


def test_a_click_on_a_sidebar_drawn_over_the_view_is_not_taken(painted):
    """Region Overlap (Blender's default): the sidebar is drawn over the main region, which spans
    the whole area; the brush runs in the main region. A press on the sidebar goes to the sidebar."""
    from rokeby.appearance import ui as appearance_ui

    modal = appearance_ui.ROKEBY_OT_appearance_paint.modal
    main = types.SimpleNamespace(type="WINDOW", x=0, y=0, width=SIZE, height=SIZE, data=_view())
    side = types.SimpleNamespace(type="UI", x=SIZE - 60, y=0, width=60, height=SIZE, data=None)
    area = types.SimpleNamespace(type="VIEW_3D", regions=[main, side], tag_redraw=lambda: None)
    ctx = _Ctx(main, main.data, area)
    op = brush_operator([])
    before = _roughness()
    assert modal(op, ctx, _event("LEFTMOUSE", "PRESS", SIZE - 30, 100)) == {"PASS_THROUGH"}
    assert modal(op, ctx, _event("LEFTMOUSE", "RELEASE", SIZE - 30, 100)) == {"PASS_THROUGH"}
    np.testing.assert_array_equal(_roughness(), before)
    assert modal(op, ctx, _event("LEFTMOUSE", "PRESS", 100, 100)) == {"RUNNING_MODAL"}
