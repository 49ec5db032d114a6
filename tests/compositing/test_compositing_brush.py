"""The normal brush ("a viewport/image-editor brush that paints normal edits (emboss,
bump, smooth) directly on the rendered image with the result updating per stroke"): strokes on a
Cycles render through the API, the operator and its modal event handling; pixels change under
the stroke and nowhere else, emboss and smooth move the shading's contrast in opposite
directions, one undo step per stroke, Esc cancels a stroke, bad inputs are named.

Background mode has no window, so no Image Editor area and no View2D: the modal part is driven
through ``StrokeDriver`` (the operator's modal() hands every event to it) with synthetic events,
and window coordinates are mapped to pixels by ``view_to_pixel`` after a fixed window → view
offset and scale (what ``View2D.region_to_view`` does for an unzoomed editor); ``region_to_pixel``
itself (one call of ``View2D.region_to_view``) does not run here."""

import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from support import cycles  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from rokeby import compositing as C  # noqa: E402
from rokeby.compositing import brush as B  # noqa: E402
from rokeby import envmaps  # noqa: E402
from rokeby.core import schema  # noqa: E402

SIZE = 48


def _render_frame(path):
    """A flat-shaded low-poly sphere (facets: the normals jump between them), 48 × 48 pixels."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = cycles(bpy.context.scene, SIZE, 4)
    envmaps.use_studio_world(sc, "forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=8)
    mat = bpy.data.materials.new("grey")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.4
    bpy.context.object.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0.0, -3.2, 0.0), rotation=(np.pi / 2, 0, 0))
    sc.camera = bpy.context.object
    C.render_passes(sc, str(path))
    sc[schema.COMPOSITE_LAST_EXR_KEY] = str(path)


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    path = tmp_path_factory.mktemp("brush") / "frame.exr"
    _render_frame(path)
    return path


@pytest.fixture
def registered(frame):
    """The scene that rendered ``frame`` (the file is re-read per test), the add-on registered."""
    _render_frame(frame)
    B.close_all()
    C.close_render()
    rokeby.register()
    yield bpy.context.scene
    rokeby.unregister()
    B.close_all()


def _pixels(img):
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1, :, :3].copy()  # top row first


def _segment_distance(shape, a, b):
    """Distance of every pixel (row, col) to the segment a–b."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    t = np.clip(((yy - a[0]) * d[0] + (xx - a[1]) * d[1]) / max(d @ d, 1e-12), 0, 1)
    return np.hypot(yy - (a[0] + t * d[0]), xx - (a[1] + t * d[1]))


def _grad(a):
    """Mean size of the differences between neighbouring pixels, per pixel (H-1, W-1)."""
    a = a if a.ndim == 3 else a[..., None]
    return np.linalg.norm(a[1:, :-1] - a[:-1, :-1], axis=-1) + np.linalg.norm(a[:-1, 1:] - a[:-1, :-1], axis=-1)


A, Bp = (24.0, 12.0), (24.0, 36.0)  # a stroke across the sphere, (row, col) pixels
RADIUS = 5.0


def test_a_stroke_changes_the_image_under_it_only_and_reaches_the_compositor(registered, frame, tmp_path):
    s = B.open_brush(str(frame), "Brushed")
    img = bpy.data.images["Brushed"]
    render = C.read_exr(str(frame)).image
    before = _pixels(img)
    assert before.tobytes() == render.tobytes()  # nothing painted yet: the render, bit for bit
    node = bpy.ops.rokeby.composite_to_compositor(image_name="Brushed")
    assert node == {"FINISHED"}
    tree = compat.compositor_tree(registered)
    tree.links.new(tree.nodes[schema.COMPOSITOR_NODE].outputs["Image"], compat.compositor_output(tree))
    got = B.paint_stroke(s, [A, Bp], RADIUS, 0.8, "emboss")
    after = _pixels(bpy.data.images["Brushed"])
    changed = (after != before).any(-1)
    dist = _segment_distance(changed.shape, A, Bp)
    assert got["changed_pixels"] == changed.sum() > 100
    assert dist[changed].max() < RADIUS  # the falloff reaches 0 at the radius
    inner = (dist < RADIUS - 1.5) & s.on
    assert changed[inner].mean() > 0.95  # and the sphere's pixels well inside it change
    assert np.isfinite(after).all()
    assert img[schema.BRUSH_SOURCE_KEY] == str(frame) and len(img[schema.BRUSH_STROKES_KEY]) == 1
    # the compositor's Image node reads the brushed image: a render through it outputs the stroke
    registered.render.use_compositing = True
    compat.set_single_layer_exr(registered.render.image_settings, "32")
    registered.render.filepath = str(tmp_path / "comp")
    bpy.ops.render.render(write_still=True)
    np.testing.assert_allclose(envmaps.read_exr(tmp_path / "comp.exr")[..., :3], after, rtol=1e-4, atol=1e-5)


def test_emboss_raises_and_smooth_lowers_the_shading_contrast_bump_differs(registered, frame):
    under = _segment_distance((SIZE, SIZE), A, Bp)[:-1, :-1] < RADIUS - 1
    base = None
    grads = {}
    for mode in B.MODES:
        s = B.open_brush(str(frame), f"Brushed {mode}")
        if base is None:
            base = (s.image.copy(), s.layer.copy())
            under &= s.on[:-1, :-1] & s.on[1:, :-1] & s.on[:-1, 1:]
        B.paint_stroke(s, [A, Bp], RADIUS, 1.0, mode)
        lum = _pixels(bpy.data.images[f"Brushed {mode}"]).mean(-1)
        grads[mode] = (_grad(s.layer)[under].mean(), _grad(lum)[under].mean())
    g0 = (_grad(base[1])[under].mean(), _grad(base[0].mean(-1))[under].mean())
    print("normal / image contrast under the stroke: render", g0, grads)
    # measured: normals 0.119 → 0.337 (emboss), 0.106 (smooth); image 0.662 → 0.682 (emboss), 0.628
    # (smooth) on Blender 4.5, 0.613 → 0.600, 0.580 on 5.0 (4 spp noise included: there the
    # recomposited frame is a little smoother than the render under every mode), so the shading is
    # compared between the modes: emboss leaves it clearly more contrasted than smooth (1.09x on
    # 4.5, 1.03x on 5.0), and smooth lowers the render's.
    assert grads["emboss"][0] > 2 * g0[0] and grads["smooth"][0] < 0.95 * g0[0]  # the normals' variation
    assert grads["emboss"][1] > 1.02 * grads["smooth"][1] and grads["smooth"][1] < 0.97 * g0[1]  # the shading follows
    assert abs(grads["bump"][0] - g0[0]) > 0.05 * g0[0]


def test_operator_stroke_is_one_undo_step_and_redo_brings_it_back(registered, frame):
    assert bpy.ops.rokeby.composite_brush.poll()  # Render and Recomposite's frame is there
    B.open_brush(str(frame), "Brushed")
    bpy.ops.ed.undo_push(message="opened")
    img0 = _pixels(bpy.data.images["Brushed"])
    pts = [{"name": "", "pixel": A}, {"name": "", "pixel": Bp}]
    assert bpy.ops.rokeby.composite_brush(image_name="Brushed", stroke=pts, radius=RADIUS, strength=0.7, mode="BUMP") == {"FINISHED"}
    img1 = _pixels(bpy.data.images["Brushed"])
    assert (img1 != img0).any(-1).sum() > 50
    pts2 = [{"name": "", "pixel": (12.0, 24.0)}, {"name": "", "pixel": (36.0, 24.0)}]
    assert bpy.ops.rokeby.composite_brush(image_name="Brushed", stroke=pts2, radius=RADIUS, strength=0.7, mode="SMOOTH") == {"FINISHED"}
    img2 = _pixels(bpy.data.images["Brushed"])
    assert (img2 != img1).any(-1).sum() > 50
    bpy.ops.ed.undo()
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == img1.tobytes()
    assert len(B.session_for("Brushed").strokes) == 1
    bpy.ops.ed.undo()
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == img0.tobytes()
    assert B.session_for("Brushed").layer.tobytes() == B.session_for("Brushed").base.tobytes()
    bpy.ops.ed.redo()
    bpy.ops.ed.redo()
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == img2.tobytes()


def _event(kind, value="NOTHING", x=0.0, y=0.0):
    return types.SimpleNamespace(type=kind, value=value, mouse_x=x, mouse_y=y)


def _to_pixel(x, y):
    """Window → pixel for an editor showing the 48-pixel image unzoomed with its corner at (100, 50)."""
    return B.view_to_pixel((x - 100.0) / SIZE, (y - 50.0) / SIZE, (SIZE, SIZE))


def _region(row, col):
    return 100.0 + col + 0.5, 50.0 + SIZE - row - 0.5


def test_modal_events_paint_a_stroke_and_esc_cancels_it(registered, frame):
    from rokeby.compositing.brush_ui import StrokeDriver

    s = B.open_brush(str(frame), "Brushed")
    bpy.ops.ed.undo_push(message="opened")  # the step before the brush (in the UI: Render and Recomposite's)
    img0 = _pixels(bpy.data.images["Brushed"])
    d = StrokeDriver(s, RADIUS, 0.8, "emboss", _to_pixel)  # as the operator's invoke makes it
    assert d.handle(_event("MOUSEMOVE", x=120, y=80)) == {"PASS_THROUGH"}  # hovering
    assert d.handle(_event("WHEELUPMOUSE")) == {"PASS_THROUGH"}  # zoom stays the editor's
    path = [A, (24.0, 20.0), (24.0, 28.0), Bp]
    assert d.handle(_event("LEFTMOUSE", "PRESS", *_region(*path[0]))) == {"RUNNING_MODAL"}
    steps = []
    for p in path[1:]:
        assert d.handle(_event("MOUSEMOVE", "NOTHING", *_region(*p))) == {"RUNNING_MODAL"}
        steps.append(_pixels(bpy.data.images["Brushed"]))  # the image follows each step
    assert all((b != a).any() for a, b in zip([img0, *steps[:-1]], steps))
    assert d.handle(_event("LEFTMOUSE", "RELEASE", *_region(*Bp))) == {"RUNNING_MODAL"}
    assert d.strokes == 1 and len(s.strokes) == 1
    stroked = _pixels(bpy.data.images["Brushed"])
    # the same stroke through the API, in one call: the same bits
    ref = B.BrushSession(s.opened)
    ref.paint(path, RADIUS, 0.8, "emboss")
    assert ref.image.tobytes() == stroked.tobytes()
    # Esc in the middle of the next stroke: the image as before it, the brush still running
    assert d.handle(_event("LEFTMOUSE", "PRESS", *_region(10.0, 10.0))) == {"RUNNING_MODAL"}
    d.handle(_event("MOUSEMOVE", "NOTHING", *_region(30.0, 30.0)))
    assert (_pixels(bpy.data.images["Brushed"]) != stroked).any()
    assert d.handle(_event("Z", "PRESS")) == {"RUNNING_MODAL"}  # held mid-stroke (Ctrl+Z would cut it)
    assert d.handle(_event("ESC", "PRESS")) == {"RUNNING_MODAL"}
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == stroked.tobytes() and d.strokes == 1
    # a drag outside the image changes nothing; Esc between strokes ends the brush
    d.handle(_event("LEFTMOUSE", "PRESS", *_region(-40.0, -40.0)))
    d.handle(_event("MOUSEMOVE", "NOTHING", *_region(-30.0, -60.0)))
    d.handle(_event("LEFTMOUSE", "RELEASE", *_region(-30.0, -60.0)))
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == stroked.tobytes() and len(s.strokes) == 1 and d.strokes == 1
    assert d.handle(_event("RIGHTMOUSE", "PRESS")) == {"FINISHED"}
    bpy.ops.ed.undo()  # the modal stroke was one undo step
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == img0.tobytes()


def test_region_to_pixel_mapping():
    # (u, v) of the view: 0..1 across the image, v up; pixels (row, col) top first, centres whole
    assert B.view_to_pixel(0.0, 1.0, (40, 20)) == (-0.5, -0.5)  # the top-left corner
    assert B.view_to_pixel(1.0, 0.0, (40, 20)) == (19.5, 39.5)  # the bottom-right corner
    assert B.view_to_pixel(0.5 / 40, 1 - 0.5 / 20, (40, 20)) == pytest.approx((0.0, 0.0), abs=1e-12)  # its centre
    assert _to_pixel(*_region(7.0, 30.0)) == pytest.approx((7.0, 30.0))


def test_strokes_survive_save_and_reload(registered, frame, tmp_path):
    from rokeby import api

    s = api.open_normal_brush(str(frame), "Brushed")  # the facade: the same session and stroke
    api.paint_normals(s, [A, Bp], radius=RADIUS, strength=0.6, mode="bump")
    B.paint_stroke(s, [(10.0, 24.0), (38.0, 24.0)], RADIUS, 0.6, "emboss")
    want = _pixels(bpy.data.images["Brushed"])
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "brushed.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "brushed.blend"))
    assert not B.has_session("Brushed")  # a new file: sessions closed
    B.open_brush(str(frame), "Brushed")  # replays the strokes the image records
    assert _pixels(bpy.data.images["Brushed"]).tobytes() == want.tobytes()


def test_bad_inputs_are_named(registered, frame):
    s = B.open_brush(str(frame), "Brushed")
    img0 = s.image.copy()
    for kw, msg in ((dict(radius=0.0), "radius: must be a number of pixels above 0"),
                    (dict(radius=-3.0), "radius: must be"), (dict(radius=float("nan")), "radius: must be"),
                    (dict(strength=0.0), r"strength: must be in \(0, 1\]"), (dict(strength=1.5), "strength: must be"),
                    (dict(mode="sharpen"), "mode: unknown 'sharpen'"),
                    (dict(points_px=[(500.0, 500.0), (600.0, 520.0)]), "every dab of radius 5 lies outside the 48×48 image"),
                    (dict(points_px=[]), "stroke: expected at least one"),
                    (dict(points_px=[(1.0, float("inf"))]), "must be finite")):
        args = {"points_px": [A, Bp], "radius": RADIUS, "strength": 0.5, "mode": "emboss", **kw}
        with pytest.raises(B.BrushError, match=msg):
            B.paint_stroke(s, **args)
    assert s.image.tobytes() == img0.tobytes() and not s.strokes and not s.painting
    with pytest.raises(B.BrushError, match="session: none given"):
        B.paint_stroke(None, [A], RADIUS, 0.5, "emboss")
    with pytest.raises(B.BrushError, match="no brush is open on it"):
        B.session_for("Nothing")
    with pytest.raises(RuntimeError, match="stroke: give at least one"):
        bpy.ops.rokeby.composite_brush(image_name="Brushed")
    with pytest.raises(RuntimeError, match="outside the 48×48 image"):
        bpy.ops.rokeby.composite_brush(image_name="Brushed", stroke=[{"name": "", "pixel": (-90.0, 5.0)}])
    del registered[schema.COMPOSITE_LAST_EXR_KEY]
    B.close_all()
    assert not bpy.ops.rokeby.composite_brush.poll()  # no frame rendered, no brush open: greyed out, saying why


def test_window_recompositing_and_steps_match_the_whole_frame_bit_for_bit():
    """No render: the synthetic frame of the GLSL tests (five kinds of patch, NaN pixels, view
    vectors per pixel). A stroke delivered in steps equals the stroke in one call; the windowed
    recompositing equals eqs. 3–5 on the whole frame; undo and replay (sync) restore the bits."""
    from support.recomposite_frames import frame as synthetic, passes_and_reconstruction

    p, rec = passes_and_reconstruction(*synthetic(h=64, w=96))
    p.depth = np.linspace(1.0, 2.0, 64 * 96, dtype=np.float32).reshape(64, 96)
    opened = C.RenderEdit(path="synthetic", passes=p, reconstruction=rec, session=C.RecompositeSession(p, rec))
    path = [(20.0, 5.0), (30.0, 40.0), (22.0, 80.0)]
    for mode in B.MODES:
        whole = B.BrushSession(opened)
        assert whole.image.tobytes() == p.image.tobytes()
        whole.paint(path, 7.0, 0.9, mode)
        steps = B.BrushSession(opened)
        steps.begin(7.0, 0.9, mode)
        for q in path:
            steps.extend([q])
        steps.end()
        assert steps.layer.tobytes() == whole.layer.tobytes() and steps.image.tobytes() == whole.image.tobytes(), mode
        full, _ = opened.session(whole.layer)
        assert full.tobytes() == whole.image.tobytes(), mode
        records = whole.records()
        whole.paint([(40.0, 50.0)], 9.0, 0.5, "bump")
        second = whole.image.copy()
        assert whole.sync(records) and whole.image.tobytes() == steps.image.tobytes()
        assert whole.sync([]) and whole.image.tobytes() == p.image.tobytes()
        again = B.BrushSession(opened)
        again.paint(path, 7.0, 0.9, mode)
        again.paint([(40.0, 50.0)], 9.0, 0.5, "bump")
        assert again.image.tobytes() == second.tobytes()


def test_an_unrelated_undo_leaves_another_edit_of_the_image_alone(registered, frame):
    """Recomposite Render into the painted image after a stroke, then an undo of something else:
    the image keeps the one-knob edit (undo keeps an image's pixels; the brush rewrites them only
    when the step changed its strokes)."""
    s = B.open_brush(str(frame), "Rokeby Recomposited")
    bpy.ops.ed.undo_push(message="opened")
    B.paint_stroke(s, [A, Bp], RADIUS, 0.8, "emboss")
    bpy.ops.ed.undo_push(message="stroke")
    assert bpy.ops.rokeby.composite_edit(filepath=str(frame), edit="EMBOSS", amount=0.3) == {"FINISHED"}
    knob = _pixels(bpy.data.images["Rokeby Recomposited"])
    bpy.ops.ed.undo_push(message="recomposite")
    bpy.ops.mesh.primitive_cube_add(location=(0.0, 5.0, 0.0))
    bpy.ops.ed.undo_push(message="cube")
    bpy.ops.ed.undo()
    assert _pixels(bpy.data.images["Rokeby Recomposited"]).tobytes() == knob.tobytes()
