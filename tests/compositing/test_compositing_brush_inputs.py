"""Paint Normals' inputs (the modal part through ``StrokeDriver``, as in test_compositing_brush.py):
the release of the Esc that cancelled a stroke leaves the brush running; Ctrl+Z while it runs undoes
and redoes its own strokes only (refused before its first stroke, mid-stroke, and past what it
undid); a press outside the image's region (a sidebar button) is not taken; F3 finds Paint Normals
in the Image Editor (Image ▸ Rokeby: menu search reads menus)."""

import types

import pytest

bpy = pytest.importorskip("bpy")

from rokeby.compositing import brush as B  # noqa: E402
from support.ui import Layout  # noqa: E402

from test_compositing_brush import RADIUS, A, Bp, _pixels, _region, _to_pixel, frame, registered  # noqa: E402, F401


def _event(kind, value="NOTHING", x=0.0, y=0.0, **mods):
    e = types.SimpleNamespace(type=kind, value=value, mouse_x=x, mouse_y=y, ctrl=False, shift=False, alt=False, oskey=False)
    for k, v in mods.items():
        setattr(e, k, v)
    return e


def _stroke(d, a, b):
    assert d.handle(_event("LEFTMOUSE", "PRESS", *_region(*a))) == {"RUNNING_MODAL"}
    assert d.handle(_event("MOUSEMOVE", "NOTHING", *_region(*b))) == {"RUNNING_MODAL"}
    assert d.handle(_event("LEFTMOUSE", "RELEASE", *_region(*b))) == {"RUNNING_MODAL"}


def test_the_release_of_the_esc_that_cancelled_a_stroke_leaves_the_brush_running(registered, frame):
    from rokeby.compositing.brush_ui import StrokeDriver

    s = B.open_brush(str(frame), "Brushed")
    img0 = _pixels(bpy.data.images["Brushed"])
    d = StrokeDriver(s, RADIUS, 0.8, "emboss", _to_pixel)
    for key in ("ESC", "RIGHTMOUSE"):
        assert d.handle(_event("LEFTMOUSE", "PRESS", *_region(*A))) == {"RUNNING_MODAL"}
        d.handle(_event("MOUSEMOVE", "NOTHING", *_region(*Bp)))
        assert d.handle(_event(key, "PRESS")) == {"RUNNING_MODAL"}  # cancels the stroke
        assert _pixels(bpy.data.images["Brushed"]).tobytes() == img0.tobytes()
        assert d.handle(_event(key, "RELEASE")) == {"RUNNING_MODAL"}  # the brush stays
        d.handle(_event("LEFTMOUSE", "RELEASE", *_region(*Bp)))  # the button of the cancelled stroke
    _stroke(d, A, Bp)  # and still paints
    assert d.strokes == 1 and len(s.strokes) == 1
    assert d.handle(_event("ESC", "PRESS")) == {"FINISHED"}  # a press between strokes ends it


def test_ctrl_z_in_the_brush_undoes_its_own_strokes_only(registered, frame):
    from rokeby.compositing.brush_ui import StrokeDriver

    s = B.open_brush(str(frame), "Brushed")
    bpy.ops.ed.undo_push(message="opened")  # in the UI: Render and Recomposite's step
    img0 = _pixels(bpy.data.images["Brushed"])
    d = StrokeDriver(s, RADIUS, 0.8, "emboss", _to_pixel)
    z, shift_z = dict(ctrl=True), dict(ctrl=True, shift=True)
    assert d.handle(_event("Z", "PRESS", **z)) == {"RUNNING_MODAL"}  # before any stroke: refused
    assert d.refused and "no stroke of this brush" in d.refused
    _stroke(d, A, Bp)
    one = _pixels(bpy.data.images["Brushed"])
    _stroke(d, (10.0, 24.0), (38.0, 24.0))
    two = _pixels(bpy.data.images["Brushed"])
    assert one.tobytes() != img0.tobytes() and two.tobytes() != one.tobytes()
    # mid-stroke: held
    assert d.handle(_event("LEFTMOUSE", "PRESS", *_region(*A))) == {"RUNNING_MODAL"}
    assert d.handle(_event("Z", "PRESS", **z)) == {"RUNNING_MODAL"}
    assert d.handle(_event("ESC", "PRESS")) == {"RUNNING_MODAL"}
    d.handle(_event("LEFTMOUSE", "RELEASE", *_region(*A)))
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == two.tobytes()

    def key(mods, expect):
        assert d.handle(_event("Z", "PRESS", **mods)) == expect
        if expect == {"PASS_THROUGH"}:  # Blender's keymap runs the undo operator
            (bpy.ops.ed.redo if mods.get("shift") else bpy.ops.ed.undo)()

    key(z, {"PASS_THROUGH"})
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == one.tobytes()
    key(z, {"PASS_THROUGH"})
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == img0.tobytes()
    key(z, {"RUNNING_MODAL"})  # would undo the step before the brush
    key(shift_z, {"PASS_THROUGH"})
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == one.tobytes()
    key(shift_z, {"PASS_THROUGH"})
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == two.tobytes()
    key(shift_z, {"RUNNING_MODAL"})


def test_a_press_outside_the_image_region_is_not_taken(registered, frame):
    from rokeby.compositing.brush_ui import StrokeDriver

    s = B.open_brush(str(frame), "Brushed")
    img0 = _pixels(bpy.data.images["Brushed"])
    # The image's region spans x 0..300; the sidebar is to its right.
    d = StrokeDriver(s, RADIUS, 0.8, "emboss", _to_pixel, inside=lambda x, y: 0 <= x < 300 and 0 <= y < 300)
    assert d.handle(_event("LEFTMOUSE", "PRESS", 320.0, 60.0)) == {"PASS_THROUGH"}
    assert d.handle(_event("LEFTMOUSE", "RELEASE", 320.0, 60.0)) == {"PASS_THROUGH"}
    assert not s.painting and _pixels(bpy.data.images["Brushed"]).tobytes() == img0.tobytes()
    _stroke(d, A, Bp)
    assert d.strokes == 1


def test_f3_finds_paint_normals_in_the_image_editor(registered):
    """Blender's F3 searches the editor's menus: Image ▸ Rokeby names Paint Normals."""
    log = []
    menu = bpy.types.IMAGE_MT_image
    funcs = getattr(menu.draw, "_draw_funcs", [])
    ours = [f for f in funcs if getattr(f, "__module__", "").startswith("rokeby")]
    assert ours, "nothing of Rokeby in the Image Editor's Image menu"
    for f in ours:
        f(types.SimpleNamespace(layout=Layout(log)), bpy.context)
    submenus = [name for kind, name in log if kind == "menu"]
    for name in submenus:
        getattr(bpy.types, name).draw(types.SimpleNamespace(layout=Layout(log)), bpy.context)
    assert ("operator", "rokeby.composite_brush") in log


def test_paint_normals_starts_from_the_edited_result_shown(registered, frame):
    """Render and Recomposite (here Recomposite Render of the same frame) shows an edited frame;
    starting Paint Normals on it keeps that image bit for bit, and a stroke changes only the pixels
    under it, on top of the edit (not on the unedited recomposite)."""
    name = "Rokeby Recomposited"
    assert bpy.ops.rokeby.composite_edit(filepath=str(frame), edit="EMBOSS", amount=0.3, k_d=1.2, image_name=name) == {"FINISHED"}
    knob = _pixels(bpy.data.images[name])
    s = B.open_brush(str(frame), name)  # what the operator's invoke does
    assert _pixels(bpy.data.images[name]).tobytes() == knob.tobytes()
    B.paint_stroke(s, [A, Bp], RADIUS, 0.8, "emboss")
    after = _pixels(bpy.data.images[name])
    from test_compositing_brush import _segment_distance

    far = _segment_distance(knob.shape[:2], A, Bp) > RADIUS + 2
    assert (after != knob).any()
    assert after[far].tobytes() == knob[far].tobytes()
    # Through the operator (exec: a stroke given as pixels) on a freshly edited image: the same.
    assert bpy.ops.rokeby.composite_edit(filepath=str(frame), edit="SMOOTH", amount=2.0, image_name=name) == {"FINISHED"}
    smooth = _pixels(bpy.data.images[name])
    assert bpy.ops.rokeby.composite_brush(image_name=name, radius=RADIUS, stroke=[{"name": "", "pixel": A}]) == {"FINISHED"}
    got = _pixels(bpy.data.images[name])
    far = _segment_distance(knob.shape[:2], A, A) > RADIUS + 2
    assert (got != smooth).any() and got[far].tobytes() == smooth[far].tobytes()
