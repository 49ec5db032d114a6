"""A point light inside the caster's bounding box (the paper's §5.2 per-loop frusta):
a lamp at the centre of a ring lights the ground through the ring's hole, and the edge of that lit
disc is the shadow boundary of the ring's lower silhouette loop. Edited with the light inside the
bounds, it renders in Cycles where it was dragged, and only there; a light inside the ring's
volume is a clear error that changes nothing."""

import numpy as np
import pytest

from support import shadow as ts

LIGHT = (0.0, 0.0, 0.9)  # the ring's centre
MAJOR, MINOR = 1.0, 0.5


def _ring_scene():
    bpy, sc, ball, lamp, ground = ts.blender_scene()
    bpy.data.objects.remove(ball, do_unlink=True)
    bpy.ops.mesh.primitive_torus_add(major_radius=MAJOR, minor_radius=MINOR, major_segments=96, minor_segments=24,
                                     location=LIGHT)
    bpy.ops.object.shade_smooth()
    ring = bpy.context.object
    ring.name = "Ring"
    ring.visible_camera = False  # the top view sees the ground under it
    lamp.location = LIGHT
    lamp.data.energy = 300.0
    sc.view_layers[0].update()
    return bpy, sc, ring, lamp, ground


def _lit_edge(img, direction, r_max=1.95):
    """Distance (world units) from the centre along ``direction`` where the lit disc ends."""
    ts_ = np.linspace(0.0, r_max, 400)
    vals = []
    for t in ts_:
        c, r = ts.to_pixel(np.asarray(direction) * t)
        vals.append(img[int(np.clip(r, 0, ts.SIZE - 1)), int(np.clip(c, 0, ts.SIZE - 1))])
    vals = np.asarray(vals)
    thr = 0.5 * (vals.min() + vals.max())
    return ts_[1] * np.count_nonzero(vals > thr)


def test_a_light_inside_a_ring_edits_the_lit_disc_where_dragged_and_only_there(tmp_path):
    bpy, sc, ring, lamp, ground = _ring_scene()
    from rokeby import api

    corners = np.array(ring.bound_box) + np.array(ring.location)
    assert np.all(corners.min(axis=0) < LIGHT) and np.all(np.array(LIGHT) < corners.max(axis=0))
    before = ts.render(bpy, sc, tmp_path / "before.png")
    s = api.start_shadow_edit(ring, lamp, [ground], min_loop_vertices=20)
    k = next(i for i, lp in enumerate(s.loops()) if lp["active"] and s.handles(i)["hit"].all())
    h = s.handles(k)["points"].astype(np.float64)
    n = len(h)
    # The lit disc: radius h·cot(asin(r/R)) for the smooth ring (the polygonal one a little less).
    want0 = LIGHT[2] / np.tan(np.arcsin(MINOR / MAJOR))
    radii = np.linalg.norm(h[:, :2], axis=1)
    assert np.abs(radii - want0).max() < 0.03 * want0, (radii.min(), radii.max(), want0)
    m = int(np.argmax(h[:, 0]))  # the +x side
    d = h[m] / np.linalg.norm(h[m])
    target = h[m] * 1.15
    r = s.drag(k, ((m - n // 6) % n, (m + n // 6) % n), m, target)
    np.testing.assert_allclose(r["handles"]["points"][m], target, atol=1e-3)
    seg = np.asarray(r["segment"])
    s.commit()
    ob, _twin = api.apply_shadow_edit(s)
    # The light sits at the ring's origin (no direction to it): no NaN in what the edit stores.
    assert np.isfinite(np.asarray(ob["rokeby_light_initial"], np.float64)).all()
    after = ts.render(bpy, sc, tmp_path / "after.png")
    px = ts.SIZE / 4.0
    e0, e1 = _lit_edge(before, d[:2].tolist() + [0.0]), _lit_edge(after, d[:2].tolist() + [0.0])
    f0, f1 = _lit_edge(before, (-d[:2]).tolist() + [0.0]), _lit_edge(after, (-d[:2]).tolist() + [0.0])
    print(f"light inside a ring: lit edge {e0 * px:.1f} px -> {e1 * px:.1f} px (handle {np.linalg.norm(h[m]) * px:.1f}, "
          f"target {np.linalg.norm(target) * px:.1f}); far side {f0 * px:.1f} -> {f1 * px:.1f} px")
    assert abs(e0 - np.linalg.norm(h[m])) * px < 2.0, "the unedited render disagrees with the handles"
    assert abs(e1 - np.linalg.norm(target)) * px < 2.0, "the edited edge is not where it was dragged"
    assert abs(f1 - f0) * px < 1.0, "the far side moved"
    # Pixels change at the dragged boundary and nowhere else: between the old and the new edge,
    # within the dragged segment's angles.
    changed = np.abs(after - before) > 0.25 * (before.max() - before.min())
    rows, cols = np.nonzero(changed)
    xw = (cols + 0.5) / ts.SIZE * 4.0 - 2.0
    yw = 2.0 - (rows + 0.5) / ts.SIZE * 4.0
    rad, ang = np.hypot(xw, yw), np.arctan2(yw, xw)
    seg_ang = np.arctan2(h[seg, 1], h[seg, 0])
    lo, hi = seg_ang.min(), seg_ang.max()  # the +x segment does not cross ±π
    inside = (ang > lo - 2.0 / (px * want0)) & (ang < hi + 2.0 / (px * want0)) \
        & (rad > radii[seg].min() - 2.0 / px) & (rad < np.linalg.norm(target) + 2.0 / px)
    print(f"changed pixels: {changed.sum()}, outside the dragged segment's sector: {(~inside).sum()}")
    assert changed.sum() > 20
    assert (~inside).sum() == 0


def test_a_light_inside_the_rings_volume_is_a_clear_error_and_changes_nothing():
    bpy, sc, ring, lamp, ground = _ring_scene()
    from rokeby import shadow

    lamp.location = (MAJOR, 0.0, LIGHT[2] + 0.1)  # inside the tube
    sc.view_layers[0].update()
    n = len(bpy.data.objects)
    with pytest.raises(shadow.ShadowEditError, match="inside the caster's volume"):
        shadow.start(ring, lamp, [ground])
    assert len(bpy.data.objects) == n and shadow.shadow_mesh_of(ring) is None
