"""Self-shadow edits (the paper's Fig. 1D / Fig. 6, the cap's shadow on the face) that
render in Cycles: one caster object holds a slab (the "face") and a sphere floating above it (the
"cap"); the sphere's shadow on the slab is a self-shadow. A loop whose handles lie on the caster,
dragged, changes the caster's pixels there and only there, and the installed set-up with the
edit at zero renders as the plain scene (no acne, no light leaks)."""

import os

import numpy as np
import pytest

from support import shadow as ts

SIZE = 64
ORTHO = 4.0
CAM = np.array([-0.8, 0.0])
LIGHT = (3.0, 0.0, 5.0)


def _caster_object(bpy, name="Mushroom", cap_z=1.5):
    """A flat ellipsoid 6 × 6 × 0.5 (the "face", top at z = 0.25) and a sphere (the "cap", r 0.5
    at z 1.5) in one closed mesh."""
    import bmesh

    b = bmesh.new()
    bmesh.ops.create_uvsphere(b, u_segments=64, v_segments=32, radius=1.0, matrix=_scale(3.0, 3.0, 0.25, (0.0, 0.0, 0.0)))
    nf = len(b.faces)
    bmesh.ops.create_uvsphere(b, u_segments=48, v_segments=24, radius=0.5, matrix=_scale(1, 1, 1, (0.0, 0.0, cap_z)))
    me = bpy.data.meshes.new(name)
    b.to_mesh(me)
    b.free()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    me.polygons.foreach_set("use_smooth", np.ones(len(me.polygons), bool))
    assert nf > 0
    me.update()
    return ob


def _scale(sx, sy, sz, t):
    from mathutils import Matrix

    m = Matrix.Diagonal((sx, sy, sz, 1.0))
    m.translation = t
    return m


def _scene(cap_z=1.5):
    bpy, sc = ts.dark_scene(SIZE)
    bpy.ops.mesh.primitive_plane_add(size=20, location=(0, 0, -1))
    ground = bpy.context.object
    caster = _caster_object(bpy, cap_z=cap_z)
    lamp = ts.add_light(sc, LIGHT)
    ts.add_top_camera(sc, CAM, ORTHO)
    sc.view_layers[0].update()
    return bpy, sc, caster, lamp, ground


def _render(bpy, sc, path):
    return ts.render(bpy, sc, path, SIZE)


def _pixel(p):
    """World (x, y) → (column, row) in the top view."""
    return np.array([((p[0] - CAM[0]) / ORTHO + 0.5) * SIZE, (0.5 - (p[1] - CAM[1]) / ORTHO) * SIZE])


def _self_loop(s):
    for k, lp in enumerate(s.loops()):
        h = s.handles(k)
        if lp["active"] and h["hit"].all() and h["on_caster"].mean() > 0.9:
            return k, h["points"].astype(np.float64)
    raise AssertionError("no self-shadow loop")


def _drag_self(s, scale=1.5):
    k, h = _self_loop(s)
    n = len(h)
    centre = h.mean(axis=0)
    m = int(np.argmin(h[:, 0]))  # the far (-x) side of the sphere's shadow on the slab
    target = centre + (h[m] - centre) * scale
    r = s.drag(k, ((m - n // 5) % n, (m + n // 5) % n), m, target)
    s.commit()
    return k, h, r["handles"]["points"].astype(np.float64), m, target


# EEVEE on a software GL (llvmpipe) compiles its shaders for minutes: opt in with ROKEBY_EEVEE_TESTS=1.
EEVEE = pytest.param(1.5, "BLENDER_EEVEE_NEXT", id="floating cap, EEVEE", marks=pytest.mark.skipif(
    os.environ.get("ROKEBY_EEVEE_TESTS") != "1", reason="EEVEE on llvmpipe takes minutes; set ROKEBY_EEVEE_TESTS=1"))


@pytest.mark.parametrize("cap_z, engine", [pytest.param(1.5, "CYCLES", id="floating cap"),
                                           pytest.param(0.6, "CYCLES", id="cap in contact"), EEVEE])
def test_a_self_shadow_loop_dragged_changes_the_caster_there_and_only_there(tmp_path, cap_z, engine):
    """The cap floating over the face, and the cap sunk into it (a contact shadow: the §7.1 case
    where the shadow mesh meets the surface it shadows)."""
    bpy, sc, caster, lamp, ground = _scene(cap_z)
    sc.render.engine = engine
    from rokeby import api, shadow
    from rokeby.core import schema

    plain = _render(bpy, sc, tmp_path / "plain.png")
    # "Within noise": 4 samples leave the anti-aliased edge pixels noisy, and another light set-up
    # draws other random numbers; the plain scene with another seed measures that noise.
    sc.cycles.seed = 2
    noise = np.abs(_render(bpy, sc, tmp_path / "plain2.png") - plain)
    sc.cycles.seed = 1
    s = api.start_shadow_edit(caster, lamp, [ground], min_loop_vertices=10)
    k, h0, h1, m, target = _drag_self(s)
    assert np.all(np.abs(h0[:, 2] - 0.2) < 0.06), "the loop's handles lie on the face (the caster)"
    assert s.has_self_edits()
    ob, twin = api.apply_shadow_edit(s)
    b = ob.rokeby_shadow.self_blocker
    assert b is not None and b.rokeby_shadow.role == "SELF_BLOCKER" and b.rokeby_shadow.caster == caster
    assert not b.visible_camera and b.visible_shadow and not b.visible_diffuse
    edited = _render(bpy, sc, tmp_path / "edited.png")
    changed = np.abs(edited - plain) > 0.1
    # The region the edit covers on screen: the old and new boundaries' bounds, 2 px around.
    pts = np.array([_pixel(p) for p in np.concatenate([h0, h1])])
    c0, r0 = np.floor(pts.min(axis=0)) - 2
    c1, r1 = np.ceil(pts.max(axis=0)) + 2
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    inside = (xx >= c0) & (xx <= c1) & (yy >= r0) & (yy <= r1)
    print(f"changed pixels: {changed.sum()} inside the edit's bounds, {(changed & ~inside).sum()} outside; "
          f"handle dragged {np.linalg.norm(target - h0[m]) / ORTHO * SIZE:.1f} px")
    assert changed.sum() >= 8, "dragging a self-shadow loop must change the caster's pixels"
    assert not (changed & ~inside).any(), "pixels changed outside the edited region"
    # Between the old and the new boundary the slab turned dark: the shadow grew there.
    mid = _pixel(0.5 * (h0[m] + target)).astype(int)
    assert plain[mid[1], mid[0]] > 0.2 and edited[mid[1], mid[0]] < 0.5 * plain[mid[1], mid[0]]
    # The unedited-but-installed state (every edit key at 0: self-shadow mesh = the caster a hair
    # inside itself) renders as the plain scene: no acne, no light leak at the contact.
    for o in (ob, b):
        o.data.shape_keys.key_blocks[schema.SHADOW_EDIT_KEY].value = 0.0
    sc.view_layers[0].update()
    zero = _render(bpy, sc, tmp_path / "zero.png")
    diff = np.abs(zero - plain)
    pad = np.pad(plain, 1, mode="edge")
    window = np.stack([pad[1 + dy:SIZE + 1 + dy, 1 + dx:SIZE + 1 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    flat = np.ptp(window, axis=0) < 0.05  # away from edges: lit or shadowed, no coverage noise
    print(f"installed at zero vs plain: sum {diff.sum():.2f} (plain with another seed: {noise.sum():.2f}), "
          f"edge pixels mean {diff[~flat].mean():.4f}, flat pixels max {diff[flat].max():.4f}")
    assert diff[flat].max() < 0.03, "acne or a light leak away from the shadow edges"
    if engine == "CYCLES":
        assert diff.sum() <= 1.5 * noise.sum() + 0.5, "the installed set-up changes the render beyond noise"
    else:  # EEVEE has no sampling noise here; its shadow maps move edge pixels a little
        assert diff[~flat].mean() < 0.1
    # Removing the edit takes the self-shadow mesh along and renders the plain scene again.
    api.remove_shadow_edit(caster)
    assert bpy.data.objects.get(caster.name + shadow.SELF_SUFFIX) is None
    again = _render(bpy, sc, tmp_path / "again.png")
    np.testing.assert_allclose(again, plain, atol=1e-4)


def test_live_self_shadow_drag_links_the_self_shadow_mesh_and_cancel_removes_it():
    bpy, sc, caster, lamp, ground = _scene()
    from rokeby import api, shadow

    s = api.start_shadow_edit(caster, lamp, [ground], min_loop_vertices=10)
    live = shadow.live_begin(s)
    k, h = _self_loop(s)
    n, m = len(h), int(np.argmin(h[:, 0]))
    c = h.mean(axis=0)
    s.drag(k, ((m - n // 5) % n, (m + n // 5) % n), m, c + (h[m] - c) * 1.3)
    shadow.live_step(live)
    b = live.shadow_object.rokeby_shadow.self_blocker
    twin = lamp.rokeby_shadow.twin
    assert b is not None and b.name in twin.light_linking.blocker_collection.objects  # not a blocker of the receivers
    assert caster.name in lamp.light_linking.blocker_collection.objects  # excluded: B shadows the caster instead
    s.cancel()
    shadow.live_end(live, keep=False)
    assert shadow.shadow_mesh_of(caster) is None
    assert not [o for o in bpy.data.objects if o.rokeby_shadow.role == "SELF_BLOCKER"]


def test_a_light_inside_the_casters_bounds_gives_an_editable_shadow_that_renders(tmp_path):
    """§5.2: a light inside the caster's bounding box (between its two parts) was refused; each
    silhouette loop now gets its own frustum. The nearer sphere's shadow on the ground, dragged, renders."""
    bpy = pytest.importorskip("bpy")
    bpy_, sc, ball, lamp, ground = ts.blender_scene()
    from rokeby import api

    # A second, smaller sphere in the same object, beyond the light: the light (0.8, 0, 3.5) lies
    # inside the bounds of the whole caster but outside each sphere's.
    import bmesh

    b = bmesh.new()
    b.from_mesh(ball.data)
    bmesh.ops.create_uvsphere(b, u_segments=24, v_segments=12, radius=0.3, matrix=_scale(1, 1, 1, (1.6, 0.0, 2.7)))
    b.to_mesh(ball.data)
    b.free()
    lamp.location = (0.8, 0.0, 3.5)
    sc.view_layers[0].update()
    corners = np.array(ball.bound_box) + np.array(ball.location)  # no rotation or scale
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    assert np.all(lo < lamp.location) and np.all(np.array(lamp.location) < hi)
    ball.visible_camera = False
    before = ts.render(bpy, sc, tmp_path / "before.png")
    s = api.start_shadow_edit(ball, lamp, [ground], min_loop_vertices=10)
    k = next(i for i, lp in enumerate(s.loops()) if lp["active"] and s.handles(i)["hit"].all()
             and np.linalg.norm(s.handles(i)["points"].mean(axis=0)[:2] - [-0.6, 0.0]) < 0.5)
    h = s.handles(k)["points"].astype(np.float64)
    n, c = len(h), h.mean(axis=0)
    m = int(np.argmin(h[:, 0]))  # the far (-x) side of the big sphere's shadow
    target = c + (h[m] - c) * 1.2
    s.drag(k, ((m - n // 5) % n, (m + n // 5) % n), m, target)
    s.commit()
    api.apply_shadow_edit(s)
    after = ts.render(bpy, sc, tmp_path / "after.png")
    d = (h[m] - c) / np.linalg.norm(h[m] - c)
    px = ts.SIZE / 4.0
    e0, e1 = ts.edge_along(before, c, d), ts.edge_along(after, c, d)
    want = np.linalg.norm(target - c)
    print(f"light inside the bounds: edge {e0 * px:.1f} px -> {e1 * px:.1f} px (target {want * px:.1f})")
    assert abs(e0 - np.linalg.norm(h[m] - c)) * px < 2.5
    assert abs(e1 - want) * px < 3.0
    f0, f1 = ts.edge_along(before, c, -d), ts.edge_along(after, c, -d)
    assert abs(f1 - f0) * px < 1.5


def test_a_light_inside_the_casters_volume_is_a_clear_error():
    bpy = pytest.importorskip("bpy")
    bpy_, sc, ball, lamp, ground = ts.blender_scene()
    from rokeby import shadow

    lamp.location = (0.0, 0.0, 1.6)  # inside the ball
    sc.view_layers[0].update()
    n = len(bpy.data.objects)
    with pytest.raises(shadow.ShadowEditError, match="inside the caster's volume"):
        shadow.start(ball, lamp, [ground])
    assert len(bpy.data.objects) == n


def test_self_shadow_edit_survives_save_and_reload_and_a_deleted_self_shadow_mesh_gives_the_caster_back(tmp_path):
    bpy, sc, caster, lamp, ground = _scene()
    from rokeby import api, shadow

    plain = _render(bpy, sc, tmp_path / "plain.png")
    s = api.start_shadow_edit(caster, lamp, [ground], min_loop_vertices=10)
    _drag_self(s)
    api.apply_shadow_edit(s)
    edited = _render(bpy, sc, tmp_path / "edited.png")
    path = str(tmp_path / "self.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    sc = bpy.context.scene
    caster = bpy.data.objects["Mushroom"]
    ob = shadow.shadow_mesh_of(caster)
    b = ob.rokeby_shadow.self_blocker
    assert b is not None and shadow.shadow_mesh_of(b) == ob
    np.testing.assert_allclose(_render(bpy, sc, tmp_path / "reloaded.png"), edited, atol=1e-4)
    # Deleted by hand: the caster shadows itself again (its original self-shadows), nothing breaks.
    bpy.data.objects.remove(b, do_unlink=True)
    assert shadow.repair(sc)
    np.testing.assert_allclose(_render(bpy, sc, tmp_path / "deleted.png"), plain, atol=0.02)
