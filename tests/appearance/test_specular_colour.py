"""Specular colour brush (Fraser's proposed Step 6, "change the colour of specular
highlights using a brush"): Principled Specular Tint painted per point and in textures, rendered
by Cycles, undone by Ctrl-Z, kept by save/reload, added at load to files painted before it
existed. bpy in background mode."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from support import cycles  # noqa: E402
from rokeby import appearance, envmaps  # noqa: E402


@pytest.fixture
def lit_ball():
    """A black dielectric ball (specular 1, roughness 0.2) under one point light against a black
    world, seen by a camera: the only bright pixels are the light's highlight."""
    import rokeby

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    sc = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    ball.name = "Ball"
    mat = bpy.data.materials.new("Plastic")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.01, 0.01, 0.01, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.2
    bsdf.inputs["Specular IOR Level"].default_value = 1.0
    ball.data.materials.append(mat)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(cam)
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    cam.data.lens = 60
    sc.camera = cam
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    lamp.data.energy = 2000.0
    lamp.data.shadow_soft_size = 0.1
    lamp.location = (0.0, -4.0, 0.0)  # behind the camera: the highlight sits in the middle of the ball
    sc.collection.objects.link(lamp)
    world = bpy.data.worlds.new("Black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    sc.world = world
    bpy.context.view_layer.objects.active = ball
    yield ball
    rokeby.unregister()


def _render(tmp_path, name):
    sc = cycles(bpy.context.scene, 32, 8)
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.filepath = str(tmp_path / name)
    bpy.ops.render.render(write_still=True)
    return envmaps.read_exr(tmp_path / f"{name}.exr")[..., :3]


def _highlight(img):
    """Mean RGB of the brightest 2 % of the pixels (the highlight)."""
    lum = img.sum(axis=2).ravel()
    top = np.argsort(lum)[-max(4, lum.size // 50):]
    return img.reshape(-1, 3)[top].mean(axis=0)


def _paint_red():
    s = bpy.context.scene.rokeby_appearance_brush
    s.brush, s.color, s.radius, s.strength = "specular_tint", (1.0, 0.0, 0.0), 4.0, 1.0
    # one dab at the highlight (the ball's front), reaching the whole ball
    return bpy.ops.rokeby.appearance_paint(stroke=[{"name": "", "location": (0.0, -1.0, 0.0)}])


@pytest.mark.parametrize("target", ["POINT", "TEXTURE"])
def test_painted_specular_colour_tints_the_rendered_highlight_and_undo_restores_it(lit_ball, tmp_path, target):
    """A white highlight on black plastic; the specular colour brush with red makes the Cycles
    highlight red (green and blue fall to a fraction); Ctrl-Z brings the white highlight back."""
    bpy.context.scene.rokeby_appearance_brush.target = target
    bpy.context.scene.rokeby_appearance_brush.resolution = 64
    assert bpy.ops.rokeby.appearance_setup() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="set up")
    before = _highlight(_render(tmp_path, "before"))
    assert before.min() > 0.05 and before.max() / before.min() < 1.2, before  # a white highlight
    assert _paint_red() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="paint")
    ball = bpy.data.objects["Ball"]
    vals = appearance.point_values(ball, "specular_tint")
    co = np.empty(3 * len(ball.data.vertices), np.float32)
    ball.data.vertices.foreach_get("co", co)
    front = co.reshape(-1, 3)[:, 1] < -0.5  # the half the camera and the light face
    assert vals[front, 1].max() < 0.3 and vals[:, 0].min() > 0.99, vals[front, :3].max(axis=0)
    red = _highlight(_render(tmp_path, "red"))
    assert red[0] > 0.5 * before[0] and red[1] < 0.35 * red[0] and red[2] < 0.35 * red[0], (before, red)
    bpy.ops.ed.undo()
    ball = bpy.data.objects["Ball"]
    np.testing.assert_allclose(appearance.point_values(ball, "specular_tint"), 1.0, atol=1e-6)
    again = _highlight(_render(tmp_path, "undone"))
    np.testing.assert_allclose(again, before, rtol=0.05)


@pytest.mark.parametrize("target", ["POINT", "TEXTURE"])
def test_save_and_reload_keeps_the_painted_specular_colour(lit_ball, tmp_path, target):
    appearance.setup(lit_ball, target=target, resolution=32)
    appearance.paint(lit_ball, "specular_tint", [[0.0, -1.0, 0.0]], radius=0.6, value=(0.1, 0.9, 0.2))
    want = appearance.point_values(lit_ball, "specular_tint").copy()
    assert np.abs(want[:, 0] - 1.0).max() > 0.8  # painted
    path = str(tmp_path / "tint.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    ball = bpy.data.objects["Ball"]
    np.testing.assert_allclose(appearance.point_values(ball, "specular_tint"), want, atol=1e-6)
    bsdf = ball.active_material.node_tree.nodes["Principled BSDF"]
    assert bsdf.inputs["Specular Tint"].links[0].from_node.name == "rokeby_global_specular_tint"


def test_bad_specular_colours_are_refused_by_name(lit_ball):
    appearance.setup(lit_ball)
    before = appearance.read(lit_ball, "specular_tint").copy()
    for bad in ((1.0, 0.0), (1.0, float("nan"), 0.0), (-0.5, 0.0, 0.0)):
        with pytest.raises(ValueError, match="specular tint colour"):
            appearance.paint(lit_ball, "specular_tint", [0.0, -1.0, 0.0], 0.5, value=bad)
    np.testing.assert_array_equal(appearance.read(lit_ball, "specular_tint"), before)
    with pytest.raises(ValueError, match="tint"):
        appearance.set_global(lit_ball.active_material, "specular_tint", (1.0, 2.0))


def _strip_specular_tint(ball):
    """The material and mesh as Rokeby left them before the specular colour existed: no specular colour."""
    nodes = ball.active_material.node_tree.nodes
    for name in ("rokeby_specular_tint", "rokeby_global_specular_tint", "rokeby_tex_specular_tint"):
        if nodes.get(name) is not None:
            nodes.remove(nodes[name])
    img = bpy.data.images.get(f"rokeby {ball.active_material.name} specular_tint")
    if img is not None:
        bpy.data.images.remove(img)
    ball.data.attributes.remove(ball.data.attributes["rokeby_specular_tint"])


@pytest.mark.parametrize("target", ["POINT", "TEXTURE"])
def test_files_painted_before_the_specular_colour_get_it_at_load(lit_ball, tmp_path, target):
    """A file saved by the former version (no specular colour attribute, nodes or image) loads
    with them added (white: the render keeps its meaning) and the brush paints it; the other
    painted values are untouched."""
    appearance.setup(lit_ball, target=target, resolution=32)
    appearance.paint(lit_ball, "roughness", [[0.0, -1.0, 0.0]], radius=0.6, value=0.9)
    rough = appearance.point_values(lit_ball, "roughness").copy()
    _strip_specular_tint(lit_ball)
    assert not lit_ball.active_material.node_tree.nodes["Principled BSDF"].inputs["Specular Tint"].is_linked
    path = str(tmp_path / "old.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)  # load_post → handlers.migrate_file → appearance.migrate
    ball = bpy.data.objects["Ball"]
    assert appearance.target(ball) == target
    bsdf = ball.active_material.node_tree.nodes["Principled BSDF"]
    assert bsdf.inputs["Specular Tint"].links[0].from_node.name == "rokeby_global_specular_tint"
    np.testing.assert_allclose(appearance.point_values(ball, "specular_tint"), 1.0, atol=1e-6)
    np.testing.assert_allclose(appearance.point_values(ball, "roughness"), rough, atol=1e-6)
    appearance.paint(ball, "specular_tint", [[0.0, -1.0, 0.0]], radius=0.6, value=(1.0, 0.0, 0.0))
    assert appearance.point_values(ball, "specular_tint")[:, 1].min() < 0.5
