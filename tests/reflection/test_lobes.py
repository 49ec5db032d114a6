"""Only the specular lobes see the edit (paper §6): dielectric and coated Principled BSDFs are split
so their diffuse shading keeps the original normal. Cycles render passes (multilayer OpenEXR) of a
red plastic ball under bpy's forest.exr and a sun."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
OpenEXR = pytest.importorskip("OpenEXR")

from rokeby import api  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from rokeby.reflection.render import shading  # noqa: E402
from rokeby.core import schema  # noqa: E402
from rokeby.compositing import exr_pass_names  # noqa: E402
from support.reflection import CHROME_BALL_SIZE as SIZE  # noqa: E402  (chrome_ball: tests/reflection/conftest.py)

PASSES = ("Combined", "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "rokeby_n")


@pytest.fixture
def plastic_ball(chrome_ball):
    ball, mat = chrome_ball
    sc = bpy.context.scene
    sc.cycles.samples = 16
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 0.0
    bsdf.inputs["Roughness"].default_value = 0.15
    bsdf.inputs["Base Color"].default_value = (0.6, 0.05, 0.03, 1.0)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(50), 0.0, math.radians(-40))
    sc.collection.objects.link(sun)
    vl = sc.view_layers[0]
    for name in ("diffuse_direct", "diffuse_indirect", "diffuse_color", "glossy_direct", "glossy_indirect"):
        setattr(vl, f"use_pass_{name}", True)
    aov = vl.aovs.add()
    aov.name, aov.type = "rokeby_n", "COLOR"
    api.add_mirror(ball)
    ball.rokeby.render_edits = False  # these tests install and remove the render nodes themselves
    api.add_constraint(ball, (0.0, -1.0, 0.0), eye=(0.0, -4.0, 0.0))
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.6, border=0.3)
    api.evaluate()
    return ball, mat, bsdf


def _passes(tmp_path, name):
    sc = bpy.context.scene
    compat.set_multilayer_exr(sc.render.image_settings, None)
    sc.render.filepath = str(tmp_path / f"{name}.exr")
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(sc.render.filepath) as f:
        ch = {k: v for part in f.parts for k, v in part.channels.items()}  # one part per pass from 5.0
        out = {}
        for p in PASSES:  # "DiffDir" up to 4.5, "Diffuse Direct" from 5.0
            key = next((f"ViewLayer.{n}" for n in exr_pass_names(p) if f"ViewLayer.{n}" in ch), None)
            if key is not None:
                out[p] = np.asarray(ch[key].pixels, np.float32)[..., :3]
    assert all(np.isfinite(v).all() for v in out.values())
    return out


def _tree_state(tree):
    nodes = sorted((n.name, n.bl_idname, n.label) for n in tree.nodes)
    links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier) for lk in tree.links)
    return nodes, links


def _show_normal(mat, source=None):
    """Write the normal the specular lobe uses (n' once installed, else N) to the AOV rokeby_n."""
    tree = mat.node_tree
    aov = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputAOV"), None)
    if aov is None:
        aov = tree.nodes.new("ShaderNodeOutputAOV")
        aov.aov_name = "rokeby_n"
    if source is None:
        spec = next((n for n in tree.nodes if n.get(schema.ROLE_KEY) == "specular"), None)
        if spec is not None:
            source = spec.inputs["Normal"].links[0].from_socket
        else:
            geo = tree.nodes.new("ShaderNodeNewGeometry")
            source = geo.outputs["Normal"]
    tree.links.new(source, aov.inputs["Color"])
    return aov


def _edit(ball):
    green = ball.rokeby.constraints[0].target_handle
    green.location = (2.5, -1.5, 3.0)
    api.evaluate()


def _diffuse(p):
    return p["DiffDir"] + p["DiffInd"]


def _gloss(p):
    return p["GlossDir"] + p["GlossInd"]


def test_split_keeps_diffuse_and_moves_specular(plastic_ball, tmp_path):
    ball, mat, bsdf = plastic_ball
    before = _tree_state(mat.node_tree)
    plain = _passes(tmp_path, "plain")
    assert api.install_render_nodes(ball) == 1
    roles = sorted(n.get(schema.ROLE_KEY) for n in mat.node_tree.nodes if n.get(schema.LINK_TAG))
    assert {"diffuse", "specular", "normal", "sum"} <= set(roles) and "metal" not in roles
    assert not bsdf.outputs["BSDF"].is_linked  # the split stands in for it
    aov = _show_normal(mat)
    identity = _passes(tmp_path, "identity")
    # The identity field: the split renders like the plain Principled (its diffuse attenuation
    # is approximated by the Fresnel factor) to within the sampling noise, measured as the
    # difference between two plain renders with different seeds.
    bpy.context.scene.cycles.seed = 2
    reseeded = _passes(tmp_path, "identity_seed2")
    bpy.context.scene.cycles.seed = 1
    noise = np.abs(reseeded["Combined"] - identity["Combined"]).mean()
    err = np.abs(identity["Combined"] - plain["Combined"]).mean()
    assert err < 1.3 * noise, (err, noise)
    bias = abs(identity["Combined"].mean() - plain["Combined"].mean()) / plain["Combined"].mean()
    assert bias < 0.01, bias
    _edit(ball)
    edited = _passes(tmp_path, "edited")
    inside = np.linalg.norm(edited["rokeby_n"] - identity["rokeby_n"], axis=-1) > 0.05
    assert inside.mean() > 0.05  # the edit reaches the render
    # Specular moves where the field changed; diffuse stays (up to sampling noise).
    gloss_change = np.abs(_gloss(edited) - _gloss(identity)).mean(-1)[inside].mean()
    diff_change = np.abs(_diffuse(edited) - _diffuse(identity)).mean(-1)[inside].mean()
    assert gloss_change > 5 * diff_change, (gloss_change, diff_change)
    # Feeding n' to the whole Principled BSDF (no split) would move the diffuse shading too.
    mat.node_tree.nodes.remove(aov)
    api.remove_render_nodes(ball)
    assert _tree_state(mat.node_tree) == before  # removal leaves the material as it was
    group = mat.node_tree.nodes.new("ShaderNodeGroup")
    group.node_tree = shading.node_group()
    mat.node_tree.links.new(group.outputs[0], bsdf.inputs["Normal"])
    unsplit = _passes(tmp_path, "unsplit")
    wrong = np.abs(_diffuse(unsplit) - _diffuse(identity)).mean(-1)[inside].mean()
    assert wrong > 3 * diff_change, (wrong, diff_change)


def _normal_angles(ball, mat, tmp_path, name):
    """Angle (rad) between n' and N per pixel at 128 px, one sample (the AOV needs no more)."""
    sc = bpy.context.scene
    sc.cycles.samples = 1
    sc.render.resolution_x = sc.render.resolution_y = 128
    api.install_render_nodes(ball)
    _show_normal(mat)
    edited = _passes(tmp_path, f"{name}_edited")["rokeby_n"]
    geo = mat.node_tree.nodes.new("ShaderNodeNewGeometry")
    _show_normal(mat, geo.outputs["Normal"])
    normal = _passes(tmp_path, f"{name}_normal")["rokeby_n"]
    on_ball = np.linalg.norm(normal, axis=-1) > 0.9
    cos = (edited * normal).sum(-1) / np.maximum(np.linalg.norm(edited, axis=-1), 1e-9)
    return np.arccos(np.clip(cos, -1, 1)), on_ball


def _max_step(angle, mask):
    both_x = mask[:, 1:] & mask[:, :-1]
    both_y = mask[1:, :] & mask[:-1, :]
    return max(np.abs(np.diff(angle, axis=1))[both_x].max(), np.abs(np.diff(angle, axis=0))[both_y].max())


@pytest.mark.parametrize("border", [0.3, 0.0])
def test_edited_normal_is_continuous_across_the_region_border(plastic_ball, tmp_path, border):
    ball, mat, _ = plastic_ball
    ball.rokeby.regions[0].border = border
    _edit(ball)
    angle, on_ball = _normal_angles(ball, mat, tmp_path, "border")
    peak = angle[on_ball].max()
    assert peak > 0.3  # a strong edit inside the region
    assert np.percentile(angle[on_ball], 25) < 0.01  # far outside the region n' = N
    step = _max_step(angle, on_ball)
    if border > 0:
        # A smooth border: no neighbouring-pixel step comes near the size of the edit.
        assert step < 0.25 * peak, (step, peak)
    else:
        # Control: a hard region edge (border 0) is exactly the jump the measure catches.
        assert step > 0.25 * peak, (step, peak)


def test_artist_edits_reach_the_split_parts(plastic_ball, tmp_path):
    ball, mat, bsdf = plastic_ball
    api.install_render_nodes(ball)
    bsdf.inputs["Base Color"].default_value = (0.05, 0.05, 0.6, 1.0)  # red → blue, after install
    bpy.context.view_layer.update()  # the depsgraph handler syncs the parts
    diffuse = next(n for n in mat.node_tree.nodes if n.get(schema.ROLE_KEY) == "diffuse")
    assert tuple(diffuse.inputs["Base Color"].default_value) == pytest.approx((0.05, 0.05, 0.6, 1.0))
    col = _passes(tmp_path, "blue")["DiffCol"]
    on_ball = col.sum(-1) > 0.05
    assert on_ball.mean() > 0.2 and (col[..., 2] > 5 * col[..., 0])[on_ball].mean() > 0.95
    # Metallic turned to 1: the split goes away, the BSDF gets n' directly.
    bsdf.inputs["Metallic"].default_value = 1.0
    assert shading.sync(mat)
    assert not [n for n in mat.node_tree.nodes if n.get(schema.ROLE_KEY) in ("diffuse", "specular")]
    assert bsdf.inputs["Normal"].links[0].from_node.get(schema.ROLE_KEY) == "normal"


def test_coat_and_partly_metallic(plastic_ball, tmp_path):
    ball, mat, bsdf = plastic_ball
    bsdf.inputs["Coat Weight"].default_value = 1.0
    bsdf.inputs["Metallic"].default_value = 0.5
    before = _tree_state(mat.node_tree)
    api.install_render_nodes(ball)
    roles = [n.get(schema.ROLE_KEY) for n in mat.node_tree.nodes if n.get(schema.LINK_TAG)]
    assert "metal" in roles and "metallic" in roles
    for role in ("specular", "metal"):
        part = next(n for n in mat.node_tree.nodes if n.get(schema.ROLE_KEY) == role)
        for name in ("Normal", "Coat Normal"):
            assert part.inputs[name].links[0].from_node.get(schema.ROLE_KEY) == "normal", (role, name)
    diffuse = next(n for n in mat.node_tree.nodes if n.get(schema.ROLE_KEY) == "diffuse")
    assert not diffuse.inputs["Normal"].is_linked and diffuse.inputs["Coat Weight"].default_value == 0.0
    identity = _passes(tmp_path, "identity")
    _edit(ball)
    edited = _passes(tmp_path, "edited")
    assert np.abs(_gloss(edited) - _gloss(identity)).mean() > 0.01
    api.remove_render_nodes(ball)
    assert _tree_state(mat.node_tree) == before


def test_split_survives_save_and_reload(plastic_ball, tmp_path):
    ball, mat, _ = plastic_ball
    api.install_render_nodes(ball)
    _edit(ball)
    first = _passes(tmp_path, "first")["Combined"]
    path = str(tmp_path / "split.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    mat = bpy.data.materials["Chrome"]
    assert shading.installed(mat)
    again = _passes(tmp_path, "again")["Combined"]
    np.testing.assert_allclose(again, first, atol=1e-5)
    assert api.remove_render_nodes(bpy.data.objects["Ball"]) == 1
    assert not shading.installed(mat)
    assert mat.node_tree.nodes["Principled BSDF"].outputs["BSDF"].links[0].to_node.bl_idname == "ShaderNodeOutputMaterial"


def test_extreme_edit_below_the_surface_gives_no_black_or_nan(chrome_ball, tmp_path):
    """Green handle behind the ball: e points below the surface over much of the region. The
    group folds it back above the tangent plane, so no pixel is black or NaN and the image
    stays continuous; without the fold, Cycles would clamp every such pixel to one grazing
    direction."""
    ball, mat = chrome_ball
    sc = bpy.context.scene
    sc.render.image_settings.file_format = "OPEN_EXR"
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (0.0, 6.0, 0.3), eye=(0.0, -4.0, 0.0))  # behind
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -1.0, 0.0), radius=0.7, border=0.3)
    api.evaluate()
    api.install_render_nodes(ball)
    sc.render.filepath = str(tmp_path / "extreme.exr")
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(sc.render.filepath) as f:
        ch = f.channels()
        img = np.asarray(ch["RGBA"].pixels if "RGBA" in ch else ch["RGB"].pixels, np.float32)[..., :3]
    assert np.isfinite(img).all()
    ys, xs = np.mgrid[0:SIZE, 0:SIZE]
    half = 4.0 * 18.0 / 50.0
    r = np.hypot((xs + 0.5) / SIZE * 2 - 1, 1 - (ys + 0.5) / SIZE * 2) * half
    on_ball = r < 0.9
    assert (img[on_ball].max(-1) < 1e-3).sum() == 0  # no black pixel on the ball
    # The edit really is extreme: at many vertices facing the camera, e points below the surface.
    geo = api.mesh_arrays(ball)
    e = api.edited_reflections(ball, eye=(0.0, -4.0, 0.0)).astype(np.float64)
    facing = geo.normals[:, 1] < -0.2
    below = (e * geo.normals).sum(-1) < 0
    assert below[facing].mean() > 0.05, below[facing].mean()
    # Continuous: no neighbouring-pixel jump on the ball larger than on the plain render's
    # brightest edge (the environment's own contrast), within the noise of 8 samples.
    api.remove_render_nodes(ball)
    sc.render.filepath = str(tmp_path / "plain.exr")
    bpy.ops.render.render(write_still=True)
    with OpenEXR.File(sc.render.filepath) as f:
        ch = f.channels()
        plain = np.asarray(ch["RGBA"].pixels if "RGBA" in ch else ch["RGB"].pixels, np.float32)[..., :3]

    def max_step(im):
        lum = im.mean(-1)
        both_x = on_ball[:, 1:] & on_ball[:, :-1]
        both_y = on_ball[1:, :] & on_ball[:-1, :]
        return max(np.abs(np.diff(lum, axis=1))[both_x].max(), np.abs(np.diff(lum, axis=0))[both_y].max())

    assert max_step(img) < 1.5 * max_step(plain) + 0.05, (max_step(img), max_step(plain))
