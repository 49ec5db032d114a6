"""Refraction constraints (paper §7.1, Fig. 8): the generalised half vector in numpy, the second
field ``rokeby_refraction`` in Blender, and Cycles renders of a glass ball in front of a
colour-coded backdrop."""


import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.reflection import mirror_state  # noqa: E402
from rokeby.reflection.render import refraction  # noqa: E402
from rokeby.core import schema  # noqa: E402

from support import cycles  # noqa: E402
from support.reference import rotation_vectors  # noqa: E402

import make_fixtures  # noqa: E402

import rokeby_native  # noqa: E402

SIZE = 48
EYE = (0.0, -4.0, 0.0)


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _angle(a, b):
    return np.arccos(np.clip(np.sum(_unit(a) * _unit(b), axis=-1), -1.0, 1.0))


def _views(rng, m, min_cos=0.02):
    """Random unit view vectors above the plane z = 0 (normal +Z)."""
    v = rng.normal(size=(m, 3))
    v[:, 2] = np.abs(v[:, 2])
    v = _unit(v)
    return v[v[:, 2] > min_cos]


# --- the maths ----------------------------------------------------------------------------------


@pytest.mark.parametrize("ior", [1.45, 2.4, 0.75])
def test_half_vector_refracts_the_view_into_the_edited_direction(rng, ior):
    v = _views(rng, 4000)
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    # Reachable directions: refract V about random normals tilted towards the viewer.
    tilt = _unit(n + 0.6 * rng.normal(size=n.shape) * [1, 1, 0])
    keep = np.sum(tilt * v, 1) > 0.05
    v, tilt = v[keep], tilt[keep]
    e = refraction._refract(-v, tilt, 1.0 / ior)
    ok = np.sum(e * e, 1) > 0.25
    h = refraction.half_vector(v[ok], e[ok], ior)
    np.testing.assert_allclose(h, tilt[ok], atol=1e-9)  # the one normal that does it
    np.testing.assert_allclose(refraction._refract(-v[ok], h, 1.0 / ior), e[ok], atol=1e-9)
    # Snell in vector form: η₁ (i × n) = η₂ (t × n).
    np.testing.assert_allclose(np.cross(-v[ok], h), ior * np.cross(e[ok], h), atol=1e-9)


@pytest.mark.parametrize("ior", [1.45, 1.01, 0.75])
def test_identity_field_gives_the_normal(rng, ior):
    v = _views(rng, 4000)
    n = _unit(np.tile([0.0, 0.0, 1.0], (len(v), 1)) + 0.2 * rng.normal(size=(len(v), 3)))
    t = refraction._refract(-v, n, 1.0 / ior)
    good = (np.sum(v * n, 1) > 1e-3) & (np.sum(t * t, 1) > 0.25)
    assert good.sum() > 1000
    out, _ = refraction.edited_normal(v[good], n[good], ior, np.zeros((good.sum(), 3)))
    np.testing.assert_allclose(out, n[good], atol=1e-9)


@pytest.mark.parametrize("ior", [1.45, 1.1, 0.75])
def test_unreachable_edits_are_clamped_into_the_cone(rng, ior):
    v = _views(rng, 20000, min_cos=1e-3)
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    rotvec = rng.normal(size=v.shape) * 2.0  # mostly far outside what refraction can reach
    out, e = refraction.edited_normal(v, n, ior, rotvec)
    assert np.all(np.isfinite(out)) and np.all(np.isfinite(e))
    t = refraction._refract(-v, n, 1.0 / ior)
    edited = np.sum(t * t, 1) > 0.25  # η < 1: no transmitted ray beyond the critical angle
    assert edited.sum() > 1000
    # n'_t faces the viewer and refracts V exactly into the clamped direction, which stays below
    # the surface and inside the reachable cone.
    assert np.sum(out * v, 1)[edited].min() > 0.0
    np.testing.assert_allclose(refraction._refract(-v, out, 1.0 / ior)[edited], e[edited], atol=1e-9)
    assert np.sum(e * n, 1)[edited].max() < 0.0
    c_max = refraction.reachable_cos(ior)
    assert np.sum(e * -v, 1)[edited].min() > c_max
    # The clamp is continuous: nearby edits give nearby normals (no switch to a constant).
    out2, _ = refraction.edited_normal(v, n, ior, rotvec + 1e-5 * rng.normal(size=v.shape))
    grazing = np.sum(v * n, 1) > 0.05
    assert np.abs(out2 - out)[edited & grazing].max() < 1e-3
    # Back faces, an unusable IOR and NaN IOR pass N through.
    out_b, _ = refraction.edited_normal(v, n, ior, rotvec, backfacing=np.ones(len(v), bool))
    np.testing.assert_array_equal(out_b, n)
    for bad in (0.0, -1.0, float("nan"), 1.0):
        out_x, _ = refraction.edited_normal(v, n, bad, rotvec)
        np.testing.assert_array_equal(out_x, n)


def test_generalised_half_vector_of_a_constant_edit_is_not_the_reflection_half_vector(rng):
    """Guard against reusing the reflection formula: normalize(e + V) does not refract V into e."""
    v = _views(rng, 500)
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    t = refraction._refract(-v, n, 1 / 1.45)
    wrong = _unit(t + v)
    assert np.abs(refraction._refract(-v, wrong, 1 / 1.45) - t).max() > 0.1


# --- the field in Blender -----------------------------------------------------------------------


@pytest.fixture
def registered():
    rokeby.register()
    mirror_state.reset()
    yield


def test_fresh_refraction_constraint_is_the_identity_and_matches_native(registered):
    mirror, eye = make_fixtures.plane_mirror()
    api.add_constraint(mirror, (0.3, -0.2, 0.4), eye=eye)  # a reflection edit, to check independence
    mirror.rokeby.constraints[0].target_handle.location = (0.5, 1.0, 2.0)
    k = api.add_constraint(mirror, (-0.4, 0.3, 0.0), eye=eye, kind="REFRACTION")
    c = mirror.rokeby.constraints[k]
    assert c.kind == "REFRACTION" and mirror.rokeby.constraints[0].kind == "REFLECTION"
    # The green handle lies along the physical transmitted ray from the eye (plane normal +Z).
    p = np.array([-0.4, 0.3, 0.0])
    t = api.refract(_unit(p - eye), [0.0, 0.0, 1.0], 1 / 1.45)
    assert np.degrees(_angle(np.array(c.target_handle.location) - p, t)) < 1e-4
    rep = api.evaluate()["Plane"]
    assert rep.status == "OK", rep.summary()
    assert rep.constraints_used == 2
    fresh = api.stored_refraction(mirror)
    assert fresh is not None and fresh.shape == (len(mirror.data.vertices), 3)
    assert np.abs(fresh).max() < 1e-5  # identity everywhere
    reflection = api.stored_field(mirror).copy()
    assert np.abs(reflection).max() > 0.1
    # Move the green handle: the stored field is rokeby_native's field of the rows [p, t, e_t].
    c.target_handle.location = (0.6, 0.9, -1.8)
    api.evaluate()
    got = api.stored_refraction(mirror)
    row = np.concatenate([p, t, _unit(np.array([0.6, 0.9, -1.8]) - p)])[None].astype(np.float32)
    q = rokeby_native.reflection.rotation_field(api.mesh_arrays(mirror).vertices, row, polar="fast")
    np.testing.assert_allclose(got, rotation_vectors(q), atol=2e-5)
    assert np.abs(got).max() > 0.3
    # The reflection field did not move, and is what its own constraint alone gives.
    np.testing.assert_array_equal(api.stored_field(mirror), reflection)
    refl_row = api.constraint_row(np.array(mirror.rokeby.constraints[0].surface_handle.matrix_world.translation), (0, 0, 1), (0.5, 1.0, 2.0), eye)
    q = rokeby_native.reflection.rotation_field(api.mesh_arrays(mirror).vertices, refl_row[None], polar="fast")
    np.testing.assert_allclose(reflection, rotation_vectors(q), atol=2e-5)
    # A reflection edit leaves the refraction field alone.
    mirror.rokeby.constraints[0].target_handle.location = (-1.0, 1.0, 2.0)
    api.evaluate()
    assert np.abs(api.stored_field(mirror) - reflection).max() > 0.05
    np.testing.assert_array_equal(api.stored_refraction(mirror), got)
    # Only the field whose rows changed is recomputed (the other is not rewritten).
    st = mirror_state._STATE[mirror.session_uid]
    before = st.rotations
    c.target_handle.location = (0.2, 0.9, -1.8)
    api.evaluate()
    assert st.rotations is before and np.abs(api.stored_refraction(mirror) - got).max() > 0.01
    # Removing the last refraction constraint removes the attribute.
    api.remove_constraint(mirror, k)
    api.evaluate()
    assert api.stored_refraction(mirror) is None and "rokeby_refraction" not in mirror.data.attributes


def test_refraction_regions_and_geodesic_distances(registered):
    mirror, eye = make_fixtures.plane_mirror()
    k = api.add_constraint(mirror, (0.5, 0.0, 0.0), eye=eye, kind="REFRACTION")
    mirror.rokeby.constraints[k].target_handle.location = (1.5, 0.5, -2.0)
    api.add_region(mirror, "EUCLIDEAN", center=(0.5, 0.0, 0.0), radius=0.6, border=0.2)
    mirror.rokeby.metric = "GEODESIC"
    rep = api.evaluate()["Plane"]
    assert rep.status == "OK", rep.summary()
    v = api.mesh_arrays(mirror).vertices
    got = api.stored_refraction(mirror)
    far = np.linalg.norm(v - [0.5, 0.0, 0.0], axis=1) > 0.6
    assert np.abs(got[far]).max() < 1e-6 and np.abs(got[~far]).max() > 0.1
    assert np.abs(api.stored_field(mirror)).max() == 0.0  # no reflection constraint
    assert len(mirror_state._STATE[mirror.session_uid].distance_cache) == 1


def test_bad_refraction_input_is_refused_clearly(registered):
    mirror, eye = make_fixtures.plane_mirror()
    for bad in (0.0, -1.5, float("nan"), float("inf")):
        with pytest.raises(api.RokebyError, match="IOR must be finite and > 0"):
            api.set_ior(mirror, bad)
    with pytest.raises(api.RokebyError, match="kind: 'REFRACT' is not one of"):
        api.add_constraint(mirror, (0.0, 0.0, 0.0), eye=eye, kind="REFRACT")
    with pytest.raises(api.RokebyError, match="sees the back of the surface"):
        api.add_constraint(mirror, (0.0, 0.0, 0.0), eye=(0.0, -1.0, -3.0), kind="REFRACTION")
    api.set_ior(mirror, 0.7)  # a bubble: total internal reflection at grazing views
    with pytest.raises(api.RokebyError, match="total internal reflection"):
        api.add_constraint(mirror, (1.5, 0.0, 0.0), eye=(-3.0, 0.0, 0.5), kind="REFRACTION")
    api.set_ior(mirror, 1.45)
    api.add_constraint(mirror, (0.0, 0.0, 0.0), eye=eye, kind="REFRACTION")
    mirror.rokeby.constraints[0].target_handle.location = (0.4, 0.4, -2.0)
    assert len([o for o in bpy.data.objects if o.type == "EMPTY"]) == 2  # refusals created nothing
    api.evaluate()
    good = api.stored_refraction(mirror).copy()
    mirror.rokeby.ior = float("nan")  # e.g. set by a script: reported, nothing non-finite written
    rep = api.evaluate()["Plane"]
    assert rep.status == "WARNING" and any("IOR must be finite and > 0" in m for m in rep.messages)
    assert api.stored_refraction(mirror) is None  # renders fall back to the unedited refraction
    assert np.all(np.isfinite(api.stored_field(mirror)))
    mirror.rokeby.ior = 1.45
    api.evaluate()
    np.testing.assert_allclose(api.stored_refraction(mirror), good, atol=1e-7)
    bpy.data.objects.remove(mirror.rokeby.constraints[0].target_handle)
    rep = api.evaluate()["Plane"]
    assert any("green (transmitted) handle was deleted" in m for m in rep.messages)
    assert api.stored_refraction(mirror) is None


def test_kind_and_ior_survive_save_and_reload(registered, tmp_path):
    mirror, eye = make_fixtures.plane_mirror()
    api.add_constraint(mirror, (0.2, 0.2, 0.0), eye=eye)
    api.add_constraint(mirror, (-0.2, 0.1, 0.0), eye=eye, kind="REFRACTION")
    api.set_ior(mirror, 1.52)
    mirror.rokeby.constraints[1].target_handle.location = (0.0, 1.0, -2.0)
    api.evaluate()
    stored = api.stored_refraction(mirror).copy()
    path = tmp_path / "refraction.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    mirror_state.reset()
    mirror = bpy.data.objects["Plane"]
    assert [c.kind for c in mirror.rokeby.constraints] == ["REFLECTION", "REFRACTION"]
    assert mirror.rokeby.ior == pytest.approx(1.52)
    np.testing.assert_array_equal(api.stored_refraction(mirror), stored)
    api.evaluate(force=True)
    np.testing.assert_allclose(api.stored_refraction(mirror), stored, atol=1e-6)


def test_operators_add_refraction_constraints_and_take_the_ior_from_the_material(registered):
    mirror, eye = make_fixtures.plane_mirror()
    assert bpy.ops.rokeby.constraint_add(mirror="Plane", surface_point=(0.1, 0.1, 0.0), eye=eye, use_eye=True, kind="REFRACTION") == {"FINISHED"}
    assert mirror.rokeby.constraints[0].kind == "REFRACTION"
    mat = bpy.data.materials.new("Glass")
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = 1.33
    mirror.data.materials.append(mat)
    assert bpy.ops.rokeby.ior_from_material(mirror="Plane") == {"FINISHED"}
    assert mirror.rokeby.ior == pytest.approx(1.33)
    glass.inputs["IOR"].default_value = 1.6
    assert api.ior_from_material(mirror, mat) == pytest.approx(1.6)
    tree.links.new(tree.nodes.new("ShaderNodeValue").outputs[0], glass.inputs["IOR"])
    with pytest.raises(RuntimeError, match="is linked"):
        bpy.ops.rokeby.ior_from_material(mirror="Plane")
    tree.nodes.remove(glass)
    with pytest.raises(api.RokebyError, match="no Glass, Refraction or transmissive Principled BSDF"):
        api.ior_from_material(mirror)


# --- Cycles renders -----------------------------------------------------------------------------


@pytest.fixture
def glass_ball():
    """A smooth unit glass ball seen from (0, −4, 0), 3 units before an emissive backdrop coloured
    by position (red along x, green along z), under a uniform grey world (every escaping ray is
    grey, so a black pixel can only be a killed path)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    mirror_state.reset()
    sc = bpy.context.scene
    cycles(sc, SIZE, 8, seed=1)
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    world = bpy.data.worlds.new("Grey")
    sc.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.25, 0.25, 0.25, 1.0)
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 3.0, 0.0), rotation=(np.pi / 2, 0.0, 0.0))
    backdrop = bpy.context.object
    back = bpy.data.materials.new("Backdrop")
    back.use_nodes = True
    nt = back.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    coords = nt.nodes.new("ShaderNodeTexCoord")
    split = nt.nodes.new("ShaderNodeSeparateXYZ")
    combine = nt.nodes.new("ShaderNodeCombineXYZ")
    combine.inputs["Z"].default_value = 0.3
    emit = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(coords.outputs["Generated"], split.inputs[0])
    nt.links.new(split.outputs["X"], combine.inputs["X"])
    nt.links.new(split.outputs["Y"], combine.inputs["Y"])
    nt.links.new(combine.outputs[0], emit.inputs["Color"])
    nt.links.new(emit.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    backdrop.data.materials.append(back)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    ball.name = "Ball"
    mat = bpy.data.materials.new("Glass")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    glass = nt.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = 1.45
    glass.inputs["Roughness"].default_value = 0.0
    nt.links.new(glass.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
    ball.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = EYE
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    api.add_mirror(ball)
    api.ior_from_material(ball)
    return ball, mat


def _render(tmp_path, name):
    sc = bpy.context.scene
    sc.render.filepath = str(tmp_path / f"{name}.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(sc.render.filepath)
    try:
        return np.array(img.pixels[:], dtype=np.float32).reshape(SIZE, SIZE, 4)[..., :3]
    finally:
        bpy.data.images.remove(img)


def _front_points(radius=1.0):
    """Per pixel (row 0 at the bottom, as Blender stores pixels): where the camera ray first meets
    the ball of ``radius`` (NaN where it misses)."""
    half = 18.0 / 50.0  # sensor half-width / focal length of the default camera
    ys, xs = np.mgrid[0:SIZE, 0:SIZE]
    d = np.stack([((xs + 0.5) / SIZE * 2 - 1) * half, np.ones(xs.shape), ((ys + 0.5) / SIZE * 2 - 1) * half], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array(EYE)
    b = d @ o
    disc = b * b - (o @ o - radius * radius)
    s = -b - np.sqrt(np.where(disc > 0, disc, np.nan))
    return o + s[..., None] * d


def test_node_group_computes_the_numpy_maths(glass_ball, tmp_path):
    """The group's Edited Normal, rendered as a colour (1 sample at pixel centres), equals
    ``refraction.edited_normal`` of the same V, N and field read back the same way."""
    ball, mat = glass_ball
    sc = bpy.context.scene
    sc.cycles.samples = 1
    sc.cycles.filter_width = 0.01
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=EYE, kind="REFRACTION")
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.9, border=0.2)
    ball.rokeby.constraints[0].target_handle.location = (0.0, -6.0, 0.5)  # far outside the cone
    api.evaluate()
    nt = mat.node_tree
    emit = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(emit.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    group = nt.nodes.new("ShaderNodeGroup")
    group.node_tree = refraction.node_group()
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "rokeby_refraction"

    def shot(socket):
        m = nt.nodes.new("ShaderNodeVectorMath")
        m.operation = "MULTIPLY_ADD"
        nt.links.new(socket, m.inputs[0])
        m.inputs[1].default_value = m.inputs[2].default_value = (0.5, 0.5, 0.5)
        nt.links.new(m.outputs[0], emit.inputs["Color"])
        return _render(tmp_path, "shot") * 2.0 - 1.0

    got = shot(group.outputs["Edited Normal"])
    n, v, rv = shot(geo.outputs["Normal"]), shot(geo.outputs["Incoming"]), shot(attr.outputs["Vector"])
    hit = np.isfinite(_front_points()[..., 0])
    want, _ = refraction.edited_normal(v[hit], n[hit], 1.45, rv[hit])
    assert (np.abs(want - n[hit]).max(1) > 1e-3).sum() > 500  # most of the ball is edited
    np.testing.assert_allclose(got[hit], want, atol=5e-6)


def test_cycles_refraction_edit_shows_inside_its_region_only(glass_ball, tmp_path):
    ball, mat = glass_ball
    nt = mat.node_tree
    refr = nt.nodes.new("ShaderNodeBsdfRefraction")  # deterministic: one closure, no Fresnel choice
    refr.distribution = "GGX"
    refr.inputs["IOR"].default_value = 1.45
    refr.inputs["Roughness"].default_value = 0.0
    nt.links.new(refr.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    nt.nodes.remove(nt.nodes["Glass BSDF"])
    api.ior_from_material(ball)
    plain = _render(tmp_path, "plain")
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=EYE, kind="REFRACTION")
    api.evaluate()
    assert api.install_render_nodes(ball) == 1
    fresh = _render(tmp_path, "fresh")
    # A fresh refraction constraint is the identity: n'_t = N, the same picture.
    assert np.abs(fresh - plain).max() < 1e-4
    ball.rokeby.constraints[0].target_handle.location.x += 1.2
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.6, border=0.2)
    api.evaluate()
    edited = _render(tmp_path, "edited")
    changed = np.abs(edited - fresh).max(-1) > 0.05
    dist = np.linalg.norm(_front_points() - [0.0, -1.0, 0.0], axis=-1)
    inside, outside = dist < 0.5, ~(dist < 0.7)  # background pixels (NaN) count as outside
    assert changed[inside].mean() > 0.8
    assert changed[outside].sum() == 0
    # The reflection field is untouched by the refraction edit.
    assert np.abs(api.stored_field(ball)).max() == 0.0
    assert api.remove_render_nodes(ball) == 1
    assert [n.bl_idname for n in nt.nodes if n.get(schema.REFRACTION_TAG)] == []
    np.testing.assert_array_equal(_render(tmp_path, "again"), plain)


def _tree_state(tree):
    links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier) for lk in tree.links)
    return sorted(n.name for n in tree.nodes), links


def test_glass_is_split_identity_holds_extreme_edits_stay_finite_and_removal_restores(glass_ball, tmp_path):
    ball, mat = glass_ball
    tree = mat.node_tree
    bump = tree.nodes.new("ShaderNodeBump")
    bump.inputs["Strength"].default_value = 0.0  # a bump map upstream, flat: same picture
    tree.links.new(bump.outputs["Normal"], tree.nodes["Glass BSDF"].inputs["Normal"])
    before = _tree_state(tree)
    plain = _render(tmp_path, "plain")
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=EYE, kind="REFRACTION")
    api.evaluate()
    # The Glass (refraction) and the Glossy part it was split into (rokeby.reflection.render.shading); idempotent.
    assert api.install_render_nodes(ball) == 2 and api.install_render_nodes(ball) == 2
    roles = sorted(n[schema.REFRACTION_TAG] for n in tree.nodes if n.get(schema.REFRACTION_TAG))
    assert roles == ["fresnel", "mix", "normal", "reflection", "refraction"]
    group = next(n for n in tree.nodes if n.get(schema.REFRACTION_TAG) == "normal")
    assert group.inputs["Normal"].links[0].from_node == bump  # the bump passes through
    # The split Glossy got the reflection group of rokeby.reflection.render.shading (reflection edits show too).
    glossy = next(n for n in tree.nodes if n.get(schema.REFRACTION_TAG) == "reflection")
    assert glossy.inputs["Normal"].links[0].from_node.node_tree.name == "Rokeby Edited Normal"
    fresh = _render(tmp_path, "fresh")
    # Same expectation, different sampling (Cycles picks reflection or refraction differently):
    # the mean colour of the ball agrees; pixels differ by noise only.
    hit = np.isfinite(_front_points()[..., 0])
    np.testing.assert_allclose(fresh[hit].mean(0), plain[hit].mean(0), atol=0.01)
    away = ~np.isfinite(_front_points(1.1)[..., 0])  # beyond the pixel filter's reach of the ball
    np.testing.assert_array_equal(fresh[away], plain[away])
    # An extreme edit, far outside what refraction can reach, over most of the ball.
    ball.rokeby.constraints[0].target_handle.location = (0.0, -6.0, 0.5)
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.9, border=0.2)
    api.evaluate()
    extreme = _render(tmp_path, "extreme")
    assert np.all(np.isfinite(extreme))
    assert extreme.max(-1).min() > 0.02  # no black pixel (the darkest possible is the grey world)
    # Visible (measured: 11% of the ball's pixels change by > 0.05; the clamps keep the rest close).
    assert (np.abs(extreme - fresh).max(-1) > 0.05)[hit].mean() > 0.08
    assert api.remove_render_nodes(ball) == 1
    assert _tree_state(tree) == before
    np.testing.assert_array_equal(_render(tmp_path, "again"), plain)
