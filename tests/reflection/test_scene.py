"""The add-on's scene model in Blender (bpy, background mode): mirrors, constraints and regions
as scene data, live updates, keyframes, save/reload, view control and bad states."""


import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.reflection import mirror_state  # noqa: E402
from rokeby.core import schema  # noqa: E402

from support import SHARED  # noqa: E402
from support.reference import rotation_vectors  # noqa: E402
from support.ui import draw_sidebar  # noqa: E402

import make_fixtures  # noqa: E402

import rokeby_native  # noqa: E402


@pytest.fixture(autouse=True)
def registered():
    rokeby.register()
    mirror_state.reset()
    yield


def _rows_from_handles(mirror, eye, normal=None):
    """Constraint rows from the handle positions alone (the test's independent path)."""
    rows = []
    for c in mirror.rokeby.constraints:
        p = np.array(c.surface_handle.matrix_world.translation)
        g = np.array(c.target_handle.matrix_world.translation)
        rows.append(api.constraint_row(p, normal, g, eye))
    return np.array(rows)


def _world_vertices(ob):
    return api.mesh_arrays(ob).vertices


def test_fresh_constraint_changes_nothing_and_moving_its_handle_matches_native():
    mirror, eye = make_fixtures.plane_mirror()
    k = api.add_constraint(mirror, (0.4, 0.2, 0.5), eye=eye)  # projected onto the plane
    c = mirror.rokeby.constraints[k]
    red, green = c.surface_handle, c.target_handle
    bpy.context.view_layer.update()
    np.testing.assert_allclose(np.array(red.matrix_world.translation), [0.4, 0.2, 0.0], atol=1e-6)
    # The green handle lies on the physical reflection of the ray from the eye.
    d = np.array(green.location) - [0.4, 0.2, 0.0]
    r = api.reflect(np.array([0.4, 0.2, 0.0]) - eye, [0, 0, 1])
    assert np.degrees(np.arccos(np.clip(d @ r / np.linalg.norm(d) / np.linalg.norm(r), -1, 1))) < 1e-3
    reports = api.evaluate()
    assert reports["Plane"].status == "OK" and reports["Plane"].constraints_used == 1
    assert np.abs(api.stored_field(mirror)).max() < 1e-5
    green.location = (1.0, 2.0, 1.5)
    bpy.context.view_layer.update()  # the depsgraph handler recomputes
    got = api.stored_field(mirror)
    rows = _rows_from_handles(mirror, np.array(eye), normal=(0, 0, 1))
    q = rokeby_native.reflection.rotation_field(_world_vertices(mirror), rows, polar="fast")
    np.testing.assert_allclose(got, rotation_vectors(q), atol=2e-5)
    assert np.abs(got).max() > 0.1
    # At the red handle the edited reflection hits the green handle (the constraint holds).
    qp = rokeby_native.reflection.rotation_field(rows[:, :3], rows)
    e = api.rotate(qp, rows[:, 3:6])[0]
    assert np.degrees(np.arccos(np.clip(e @ rows[0, 6:9], -1, 1))) < 1e-2


def test_operators_make_the_same_field_as_the_api():
    mirror, eye = make_fixtures.plane_mirror()
    assert bpy.ops.rokeby.constraint_add(mirror="Plane", surface_point=(-0.5, 0.3, 0.0), eye=eye, use_eye=True, reflected_point=(0.0, 1.0, 2.0), use_reflected_point=True) == {"FINISHED"}
    by_op = api.evaluate(force=True)["Plane"]
    assert by_op.status == "OK"
    field_op = api.stored_field(mirror).copy()
    api.remove_constraint(mirror, 0)
    assert len(mirror.rokeby.constraints) == 0 and not [o for o in bpy.data.objects if o.type == "EMPTY"]
    api.add_constraint(mirror, (-0.5, 0.3, 0.0), (0.0, 1.0, 2.0), eye=eye)
    api.evaluate()
    np.testing.assert_array_equal(api.stored_field(mirror), field_op)
    # Operators for regions, freeze, selection and removal run in background mode too.
    assert bpy.ops.rokeby.region_add(mirror="Plane", kind="EUCLIDEAN", center=(-0.5, 0.3, 0.0), use_center=True, radius=1.0, border=0.3) == {"FINISHED"}
    assert bpy.ops.rokeby.freeze(mirror="Plane", action="FREEZE") == {"FINISHED"} and mirror.rokeby.freeze
    np.testing.assert_allclose(mirror.rokeby.freeze_eye, eye, atol=1e-6)
    assert bpy.ops.rokeby.constraint_select(mirror="Plane", index=0) == {"FINISHED"}
    assert bpy.context.view_layer.objects.active == mirror.rokeby.constraints[0].target_handle
    assert bpy.ops.rokeby.region_remove(mirror="Plane", index=0) == {"FINISHED"}
    assert bpy.ops.rokeby.constraint_remove(mirror="Plane", index=0) == {"FINISHED"}
    assert bpy.ops.rokeby.update() == {"FINISHED"}
    assert np.abs(api.stored_field(mirror)).max() == 0.0


def test_operator_refusals_leave_the_scene_unchanged():
    mirror, eye = make_fixtures.plane_mirror()
    n_objects = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="coincides with the surface point"):
        bpy.ops.rokeby.constraint_add(mirror="Plane", surface_point=(0, 0, 0), eye=eye, use_eye=True, reflected_point=(0, 0, 0), use_reflected_point=True)
    with pytest.raises(RuntimeError, match="no vertex group 'nope'"):
        bpy.ops.rokeby.region_add(mirror="Plane", kind="FREEFORM", vertex_group="nope")
    assert len(bpy.data.objects) == n_objects
    assert len(mirror.rokeby.constraints) == 0 and len(mirror.rokeby.regions) == 0


def test_keyframed_handles_give_different_fields_and_survive_save_and_reload(tmp_path):
    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    f1 = api.evaluate(frame=1)["Spot"]
    assert f1.status == "OK", f1.summary()
    a1 = api.stored_field(mirror).copy()
    api.evaluate(frame=20)
    a20 = api.stored_field(mirror).copy()
    assert np.all(np.isfinite(a1)) and np.all(np.isfinite(a20))
    assert np.abs(a1 - a20).max() > 0.05
    # Playback through frame_set (the frame-change handler) gives the same fields.
    bpy.context.scene.frame_set(1)
    np.testing.assert_allclose(api.stored_field(mirror), a1, atol=1e-6)
    path = tmp_path / "spot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    mirror = bpy.data.objects["Spot"]
    assert mirror.rokeby.is_mirror and len(mirror.rokeby.constraints) == 2
    assert mirror.rokeby.constraints[0].target_handle.animation_data.action is not None
    np.testing.assert_allclose(api.stored_field(mirror), a1, atol=1e-6)  # saved with the file
    api.evaluate(frame=20, force=True)
    np.testing.assert_allclose(api.stored_field(mirror), a20, atol=1e-5)
    api.evaluate(frame=1, force=True)
    np.testing.assert_allclose(api.stored_field(mirror), a1, atol=1e-5)


def test_unchanged_scene_is_not_recomputed():
    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    api.evaluate(frame=5)
    api.reset_stats()
    for _ in range(3):
        api.evaluate()
        bpy.context.view_layer.update()
    bpy.context.scene.frame_set(5)  # same frame: meshes re-read, nothing changed
    s = api.stats()
    assert s["recomputations"] == 0 and s["checks"] >= 4 and s["skipped"] == s["checks"]
    # Moving an unrelated object recomputes nothing either.
    bpy.data.objects["Floor"].location.x += 1.0
    bpy.context.view_layer.update()
    assert api.stats()["recomputations"] == 0
    # A handle move recomputes once.
    mirror.rokeby.constraints[0].target_handle.location.x += 0.3
    bpy.context.view_layer.update()
    assert api.stats()["recomputations"] == 1
    bpy.context.view_layer.update()  # the update caused by writing the field itself
    assert api.stats()["recomputations"] == 1


def test_deleted_handle_is_reported_and_the_rest_still_evaluates():
    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    other, eye = None, (0.0, -4.0, 0.6)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(3.0, 0.0, 0.0))
    other = bpy.context.object
    other.name = "Ball"
    other.data.materials.append(make_fixtures.chrome())
    api.add_mirror(other)
    api.add_constraint(other, (3.0, -1.0, 0.0), (2.0, -3.0, 1.0), eye=eye)
    api.evaluate(frame=20)
    bpy.data.objects.remove(mirror.rokeby.constraints[0].target_handle)
    reports = api.evaluate(frame=20)
    rep = reports["Spot"]
    assert rep.status == "WARNING" and rep.constraints_used == 1
    assert any("green (reflected) handle was deleted" in m for m in rep.messages)
    assert reports["Ball"].status != "ERROR", reports["Ball"].summary()  # a large edit: folds are warned
    assert np.abs(api.stored_field(other)).max() > 0.05
    # Deleting the red handle of the last constraint too: the field falls back to the identity.
    bpy.data.objects.remove(mirror.rokeby.constraints[1].surface_handle)
    rep = api.evaluate()["Spot"]
    assert rep.constraints_used == 0 and np.abs(api.stored_field(mirror)).max() == 0.0


def test_bad_states_are_reported_clearly():
    mirror, eye = make_fixtures.plane_mirror()
    api.add_constraint(mirror, (0.0, 0.0, 0.0), (0.5, 1.0, 1.0), eye=eye)
    c = mirror.rokeby.constraints[0]
    # A red handle pulled off the surface and parented to another object.
    c.surface_handle.constraints.clear()
    holder = bpy.data.objects.new("Holder", None)
    bpy.context.scene.collection.objects.link(holder)
    holder.location = (0.0, 0.0, 0.5)
    c.surface_handle.parent = holder
    c.surface_handle.location = (0.0, 0.0, 0.0)
    rep = api.evaluate()["Plane"]
    assert rep.status == "WARNING" and rep.constraints_used == 1
    assert any("off the surface" in m and "parented to 'Holder'" in m for m in rep.messages)
    # NaN transforms: reported, nothing non-finite written.
    c.target_handle.location = (float("nan"), 0.0, 0.0)
    rep = api.evaluate()["Plane"]
    assert any("non-finite transform" in m for m in rep.messages)
    assert np.all(np.isfinite(api.stored_field(mirror)))
    mirror.location = (float("nan"), 0.0, 0.0)
    rep = api.evaluate()["Plane"]
    assert rep.status == "ERROR" and "non-finite transform" in rep.messages[0]
    mirror.location = (0.0, 0.0, 0.0)
    # Not a mesh / no faces.
    curve = bpy.data.objects.new("Curve", bpy.data.curves.new("Curve", "CURVE"))
    bpy.context.scene.collection.objects.link(curve)
    with pytest.raises(api.RokebyError, match="'Curve' is a curve, not a mesh"):
        api.add_mirror(curve)
    curve.rokeby.is_mirror = True  # e.g. set by a script: reported, the rest evaluates
    me = bpy.data.meshes.new("Edges")
    me.from_pydata([(0, 0, 0), (1, 0, 0)], [(0, 1)], [])
    loose = bpy.data.objects.new("Edges", me)
    bpy.context.scene.collection.objects.link(loose)
    with pytest.raises(api.RokebyError, match="'Edges' has no faces"):
        api.add_mirror(loose)
    loose.rokeby.is_mirror = True
    reports = api.evaluate()
    assert reports["Curve"].status == "ERROR" and "not a mesh" in reports["Curve"].messages[0]
    assert reports["Edges"].status == "ERROR" and "has no faces" in reports["Edges"].messages[0]
    assert reports["Plane"].status in ("OK", "WARNING")


def test_linked_library_mirror_is_refused(tmp_path):
    make_fixtures.plane_mirror()
    lib = tmp_path / "lib.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(lib))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    with bpy.data.libraries.load(str(lib), link=True) as (src, dst):
        dst.objects = ["Plane"]
    ob = dst.objects[0]
    bpy.context.scene.collection.objects.link(ob)
    with pytest.raises(api.RokebyError, match="linked from a library"):
        api.add_mirror(ob)
    # It was a mirror in its library: evaluating reports that the field cannot be stored.
    rep = api.evaluate()["Plane"]
    assert rep.status == "ERROR" and "linked" in rep.messages[0]


def test_deforming_mirror_uses_the_evaluated_mesh():
    mirror, eye = make_fixtures.plane_mirror()
    make_fixtures.animate_shape_key(mirror, "Bump", lambda x, y: 0.4 * np.exp(-(x**2 + y**2)))
    api.add_constraint(mirror, (0.5, 0.0, 0.0), (0.5, 1.0, 2.0), eye=eye)
    api.evaluate(frame=1)
    a1 = api.stored_field(mirror).copy()
    rep = api.evaluate(frame=20)["Plane"]
    assert rep.field_mesh == "evaluated" and rep.recomputed
    a20 = api.stored_field(mirror)
    assert np.abs(a1 - a20).max() > 1e-3
    # The red handle follows the deformed surface (Shrinkwrap) and the field uses that surface.
    red = mirror.rokeby.constraints[0].surface_handle
    assert red.matrix_world.translation.z > 0.2
    st = mirror_state._STATE[mirror.session_uid]
    np.testing.assert_allclose(st.geometry.vertices, _world_vertices(mirror), atol=1e-6)


def test_geodesic_metric_and_one_solve_per_moved_handle():
    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    mirror.rokeby.metric = "GEODESIC"
    rep = api.evaluate(frame=20)["Spot"]
    assert rep.status != "ERROR", rep.summary()  # the fixture's frame-20 edit folds below the surface: warned
    st = mirror_state._STATE[mirror.session_uid]
    assert len(st.distance_cache) == 2
    geodesic = api.stored_field(mirror).copy()
    mirror.rokeby.metric = "EUCLIDEAN"
    euclid = api.evaluate()["Spot"]
    assert np.abs(api.stored_field(mirror) - geodesic).max() > 1e-3
    mirror.rokeby.metric = "GEODESIC"
    api.evaluate()
    np.testing.assert_allclose(api.stored_field(mirror), geodesic, atol=1e-6)  # cached distances
    assert len(st.distance_cache) == 2
    red = mirror.rokeby.constraints[0].surface_handle
    red.location.x += 0.05
    api.evaluate()
    assert len(st.distance_cache) == 3  # one new solve, the other constraint's distances reused
    assert euclid.status != "ERROR", euclid.summary()


def test_regions_limit_the_edit():
    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    api.evaluate(frame=20)
    q = api.field(mirror)
    v = api.mesh_arrays(mirror).vertices
    centre = np.array(mirror.rokeby.regions[0].center.matrix_world.translation)
    outside = np.linalg.norm(v - centre, axis=1) > 1.2
    assert outside.any() and np.abs(api.quat_angle(q[outside])).max() < 1e-6
    # A geodesic region around the first constraint: zero outside its radius over the surface.
    api.remove_region(mirror, 0)
    red = mirror.rokeby.constraints[0].surface_handle
    api.add_region(mirror, "GEODESIC", center=tuple(red.matrix_world.translation), radius=0.4, border=0.1)
    rep = api.evaluate()["Spot"]
    assert rep.status != "ERROR", rep.summary()  # the fixture's frame-20 edit folds below the surface: warned
    q = api.field(mirror)
    assert (api.quat_angle(q) > 1e-3).any()
    assert np.mean(api.quat_angle(q) < 1e-6) > 0.5  # most of the cow is outside the disc
    # A free-form region from a painted vertex group: unpainted vertices are untouched.
    api.remove_region(mirror, 0)
    vg = mirror.vertex_groups.new(name="Paint")
    painted = np.flatnonzero(np.linalg.norm(v - np.array(red.matrix_world.translation), axis=1) < 0.5)
    vg.add(painted.tolist(), 1.0, "REPLACE")
    api.add_region(mirror, "FREEFORM", vertex_group="Paint", border=0.05)
    rep = api.evaluate()["Spot"]
    assert rep.status != "ERROR", rep.summary()
    q = api.field(mirror)
    unpainted = np.ones(len(v), bool)
    unpainted[painted] = False
    assert np.abs(api.quat_angle(q[unpainted])).max() < 1e-6
    assert api.quat_angle(q[painted]).max() > 1e-3
    api.remove_region(mirror, 0)
    assert not [m for m in mirror.modifiers if m.name.startswith(schema.VG_MODIFIER_PREFIX)]


def test_freeze_stops_reflections_following_the_camera_and_return_to_view():
    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    api.evaluate(frame=20)
    a = api.edited_reflections(mirror, eye=(0.0, -4.0, 0.6))
    b = api.edited_reflections(mirror, eye=(2.0, -3.0, 1.5))
    assert np.abs(a - b).max() > 0.1  # unfrozen: follows the viewer
    api.freeze(mirror, True)
    np.testing.assert_allclose(mirror.rokeby.freeze_eye, mirror.rokeby.constraints[mirror.rokeby.active_constraint].eye)
    fa = api.edited_reflections(mirror, eye=(0.0, -4.0, 0.6))
    fb = api.edited_reflections(mirror, eye=(2.0, -3.0, 1.5))
    np.testing.assert_array_equal(fa, fb)
    np.testing.assert_allclose(fa, a, atol=1e-5)  # evaluated from the generating eye
    api.freeze(mirror, False)
    np.testing.assert_allclose(api.edited_reflections(mirror, eye=(2.0, -3.0, 1.5)), b, atol=1e-6)
    view = api.constraint_view(mirror, 0)
    eye = np.array(view["eye"])
    # The stored view looks from the eye at the red handle's original point.
    from mathutils import Quaternion, Vector

    back = np.array(view["location"]) + np.array(Quaternion(view["rotation"]) @ Vector((0.0, 0.0, view["distance"])))
    np.testing.assert_allclose(back, eye, atol=1e-5)
    with pytest.raises(api.RokebyError, match="out of range"):
        api.constraint_view(mirror, 7)


def test_edited_materials_choice():
    mirror, _ = make_fixtures.plane_mirror()
    mirror.data.materials.clear()
    m1, m2 = bpy.data.materials.new("Chrome"), bpy.data.materials.new("Paint")
    mirror.data.materials.append(m1)
    mirror.data.materials.append(m2)
    assert api.edited_materials(mirror) == [m1, m2]
    api.set_edited_materials(mirror, [m2])
    assert api.edited_materials(mirror) == [m2] and not mirror.rokeby.all_materials
    with pytest.raises(api.RokebyError, match="not a material of mirror"):
        api.set_edited_materials(mirror, [bpy.data.materials.new("Other")])
    assert api.edited_materials(mirror) == [m2]
    assert bpy.ops.rokeby.material_toggle(mirror="Plane", material="Chrome") == {"FINISHED"}
    assert set(api.edited_materials(mirror)) == {m1, m2}


def test_settings_are_animatable():
    mirror, eye = make_fixtures.plane_mirror()
    api.add_constraint(mirror, (0.0, 0.0, 0.0), (0.5, 1.0, 1.0), eye=eye)
    api.add_region(mirror, "EUCLIDEAN", center=(0.0, 0.0, 0.0), radius=0.5, border=0.1)
    rg = mirror.rokeby.regions[0]
    rg.keyframe_insert("radius", frame=1)
    rg.radius = 3.0
    rg.keyframe_insert("radius", frame=10)
    api.evaluate(frame=1)
    small = np.count_nonzero(np.abs(api.stored_field(mirror)).max(1) > 1e-6)
    api.evaluate(frame=10)
    large = np.count_nonzero(np.abs(api.stored_field(mirror)).max(1) > 1e-6)
    assert np.isclose(rg.radius, 3.0) and large > 2 * small > 0


def test_sidebar_panel_draws_every_state():
    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    mirror.rokeby.metric = "GEODESIC"
    mirror.rokeby.all_materials = False
    mirror.data.materials.append(bpy.data.materials.new("Chrome"))
    api.evaluate(frame=1)
    bpy.data.objects.remove(mirror.rokeby.constraints[0].target_handle)
    api.evaluate()
    ctx_states = []
    for active in (mirror, mirror.rokeby.constraints[1].surface_handle, bpy.data.objects["Floor"], None):
        bpy.context.view_layer.objects.active = active
        log = []
        draw_sidebar(log)
        ctx_states.append(log)
    texts = [t for kind, t in ctx_states[0] if kind == "label"]
    assert any("Mirror: Spot" in t for t in texts)
    assert "green (reflected) handle was deleted" in " ".join(texts)  # errors shown in the UI (wrapped to the sidebar)
    assert ("prop", "geodesic_method") in ctx_states[0] and ("list", "constraints") in ctx_states[0]
    assert ctx_states[1] == ctx_states[0]  # a selected handle shows its mirror
    assert ("operator", "rokeby.mirror_add") in ctx_states[2]


def test_vertex_parented_handle_follows_a_deforming_mirror():
    mirror, eye = make_fixtures.plane_mirror()
    co = make_fixtures.animate_shape_key(mirror, "Lift", lambda x, y: 0.3 * x)  # tilt the plane
    api.add_constraint(mirror, (1.0, 0.0, 0.0), (1.0, 1.0, 2.0), eye=eye)
    red = mirror.rokeby.constraints[0].surface_handle
    red.constraints.clear()
    vi = int(np.argmin(np.linalg.norm(co[:, :2] - [1.0, 0.0], axis=1)))
    red.parent = mirror
    red.parent_type = "VERTEX"
    red.parent_vertices[0] = vi
    red.location = (0.0, 0.0, 0.0)
    red.matrix_parent_inverse.identity()
    reports = [api.evaluate(frame=f)["Plane"] for f in (1, 20)]
    assert all(r.status == "OK" for r in reports), [r.summary() for r in reports]
    np.testing.assert_allclose(np.array(red.matrix_world.translation), co[vi], atol=1e-5)
