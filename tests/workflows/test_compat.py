"""The compatibility module on the Blender this leg runs (`make test` on 4.5, `make
test-blender BPY=<version>` on the others): every answer of ``rokeby.blender.compat`` is checked by using
it — the engine id it picks renders, the multilayer EXR setting writes several layers, the
built-in point shader draws, the compositor tree it returns composites the render, modifier inputs
and node custom properties survive a save and reload, registered properties are found where this
Blender stores them."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
OpenEXR = pytest.importorskip("OpenEXR")

import rokeby  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from rokeby.reflection import freeform_regions  # noqa: E402

from support import cycles  # noqa: E402

ENGINES = ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE")


def _scene(size=8):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    cycles(sc, size, 1)
    world = bpy.data.worlds.new("grey")
    world.color = (0.2, 0.2, 0.2)
    sc.world = world
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    return sc


def _channels(path) -> dict:
    """Every channel of every part (Blender 5.0+ writes one part per pass)."""
    with OpenEXR.File(str(path)) as f:
        return {name: np.asarray(ch.pixels, np.float32) for part in f.parts for name, ch in part.channels.items()}


def test_eevee_engine_is_the_id_this_blender_declares_and_sets():
    sc = _scene()
    engine = compat.eevee_engine()
    assert engine in ENGINES and compat.is_eevee(engine)
    sc.render.engine = engine
    assert sc.render.engine == engine
    other = next(e for e in ENGINES if e != engine)
    with pytest.raises(TypeError):  # the other release's id is refused here: compat did not pick it
        sc.render.engine = other


def test_multilayer_exr_setting_writes_several_layers_and_single_layer_one(tmp_path):
    sc = _scene()
    vl = sc.view_layers[0]
    vl.use_pass_normal = vl.use_pass_z = True
    st = sc.render.image_settings
    compat.set_multilayer_exr(st, "32")
    assert compat.is_multilayer_exr(st) and st.color_depth == "32"
    sc.render.filepath = str(tmp_path / "multi.exr")
    bpy.ops.render.render(write_still=True)
    names = set(_channels(tmp_path / "multi.exr"))  # "ViewLayer.Combined" (RGBA grouped) or ".R", ...
    for layer in (f"{vl.name}.Combined", f"{vl.name}.Normal", f"{vl.name}.Depth"):
        assert any(n == layer or n.startswith(layer + ".") for n in names), (layer, sorted(names))

    compat.set_single_layer_exr(st)
    assert not compat.is_multilayer_exr(st) and st.file_format == "OPEN_EXR"
    sc.render.filepath = str(tmp_path / "single.exr")
    bpy.ops.render.render(write_still=True)
    ch = _channels(tmp_path / "single.exr")
    assert set(ch) <= {"R", "G", "B", "A", "RGB", "RGBA"}, sorted(ch)  # the combined image, no passes


def test_builtin_point_shader_draws_after_a_render_with_the_picked_engine():
    from support.bpy_process import run_check

    res = run_check("workflows/compat_gpu_check.py")
    assert compat.is_eevee(res["engine"]) and res["engine"] == compat.eevee_engine()
    assert res["picked"] == ("POINT_FLAT_COLOR" if res["has_point_flat_color"] else "FLAT_COLOR"), res
    assert res["lit"] >= 9, res  # a fat point, not a pixel or nothing
    np.testing.assert_allclose(res["colour"], (0.2, 0.9, 0.4), atol=0.02)


def test_compositor_tree_composites_the_render(tmp_path):
    sc = _scene()
    tree = compat.compositor_tree(sc, create=True)
    assert tree is not None and compat.compositor_tree(sc) == tree
    layers = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers")
    invert = tree.nodes.new("CompositorNodeInvert")
    tree.links.new(layers.outputs["Image"], invert.inputs["Color"])
    tree.links.new(invert.outputs["Color"], compat.compositor_output(tree))
    compat.set_single_layer_exr(sc.render.image_settings, "32")

    def render(name, composite):
        sc.render.use_compositing = composite
        sc.render.filepath = str(tmp_path / f"{name}.exr")
        bpy.ops.render.render(write_still=True)
        ch = _channels(tmp_path / f"{name}.exr")
        px = next((ch[k] for k in ("RGBA", "RGB") if k in ch), None)
        return (px if px is not None else np.stack([ch[c] for c in "RGB"], -1))[..., :3]

    plain, inverted = render("plain", False), render("inverted", True)
    assert 0.01 < plain.mean() < 0.9  # the world, neither black nor white
    # The compositor ran on what was rendered: the world inverted, everywhere.
    np.testing.assert_allclose(inverted, 1.0 - plain, atol=0.01)


def test_modifier_inputs_set_read_and_survive_reload(tmp_path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.object
    group = plane.vertex_groups.new(name="paint")
    group.add([0, 1], 0.75, "REPLACE")
    mod = plane.modifiers.new("reader", "NODES")
    mod.node_group = freeform_regions.vertex_group_reader()
    ids = freeform_regions._reader_ids(mod)
    compat.set_modifier_input(mod, ids["Vertex Group"], "paint")
    compat.set_modifier_input(mod, ids["Attribute"], "rk_read")
    assert compat.modifier_input(mod, ids["Vertex Group"]) == "paint"
    assert compat.modifier_input(mod, "no such input", "fallback") == "fallback"
    # The modifier evaluates with what was set: the weights arrive in the named attribute.
    dg = bpy.context.evaluated_depsgraph_get()
    me = plane.evaluated_get(dg).data
    attr = me.attributes.get("rk_read")
    assert attr is not None
    w = np.empty(len(me.vertices), np.float32)
    attr.data.foreach_get("value", w)
    np.testing.assert_allclose(np.sort(w), [0.0, 0.0, 0.75, 0.75])
    path, name = tmp_path / "inputs.blend", plane.name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    mod = bpy.data.objects[name].modifiers["reader"]
    assert compat.modifier_input(mod, ids["Attribute"]) == "rk_read"
    rokeby.unregister()


def test_registered_properties_are_found_where_this_blender_stores_them(tmp_path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
    ball = bpy.context.object
    bpy.ops.mesh.primitive_cube_add(location=(3.0, 0.0, 0.0))
    plain = bpy.context.object
    assert compat.stored_group(ball, "rokeby") is None  # nothing written yet
    api.add_mirror(ball)
    group = compat.stored_group(ball, "rokeby")
    assert group is not None and group.get("is_mirror")
    assert compat.stored_group(plain, "rokeby") is None
    if compat._system_properties():  # 5.0+: apart from the custom properties a user sees
        assert "rokeby" not in ball.keys()
    path, name = tmp_path / "stored.blend", ball.name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    assert compat.stored_group(bpy.data.objects[name], "rokeby").get("is_mirror")
    rokeby.unregister()


def test_node_custom_properties_survive_reload(tmp_path):
    """The add-on tags its shader nodes with custom properties (``node["rokeby_bsdf"]``): that
    works on every release this leg covers."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = bpy.data.materials.new("tagged")
    mat.use_fake_user = True
    if not mat.node_tree:
        mat.use_nodes = True
    node = mat.node_tree.nodes.new("ShaderNodeTexCoord")
    node["rokeby_tag"] = "kept"
    name = node.name  # `node` points into the old file's memory once another file is opened
    path = tmp_path / "nodes.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    node = bpy.data.materials["tagged"].node_tree.nodes[name]
    assert node.get("rokeby_tag") == "kept"


def test_depsgraph_id_types_are_those_the_depsgraph_accepts():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    dg = bpy.context.evaluated_depsgraph_get()
    asked = ("MESH", "NODETREE", "NO_SUCH_ID_TYPE")
    named = compat.depsgraph_id_types(asked)
    assert named == ("MESH", "NODETREE")
    for t in named:
        assert dg.id_type_updated(t) in (True, False)
    with pytest.raises(TypeError):  # what compat leaves out is what the depsgraph refuses
        dg.id_type_updated("NO_SUCH_ID_TYPE")
