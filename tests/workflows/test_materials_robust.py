"""Materials come back as they were ("half-done operations and materials left
changed"): Remove Render Edits after Remove Mirror, after the original Principled BSDF was
deleted as "unused", after the Material Output or the split BSDF was renamed; a material swapped
out of a mirror's slot; installs interrupted by an exception half way."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from support import cycles  # noqa: E402
from support.scenes import add_front_camera, add_point_lamp, empty_scene, plastic_material  # noqa: E402
from rokeby import api  # noqa: E402
from rokeby.reflection.render import refraction, rendering, shading  # noqa: E402
from rokeby.core import schema  # noqa: E402


def _tree_state(tree):
    nodes = sorted((n.name, n.bl_idname, n.label, n.node_tree.name if getattr(n, "node_tree", None) else "",
                    getattr(n, "distribution", ""), tuple(sorted(k for k in n.keys())))
                   for n in tree.nodes)
    links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier) for lk in tree.links)
    values = sorted((n.name, s.identifier, repr(tuple(s.default_value) if hasattr(s.default_value, "__len__") else s.default_value))
                    for n in tree.nodes for s in n.inputs if hasattr(s, "default_value"))
    return nodes, links, values


def _scene(metallic=0.0, alpha=1.0):
    """A plastic ball (its Principled BSDF gets split) with a textured roughness, a camera and a light."""
    sc = cycles(empty_scene(reset_state=False), 24, 4)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    ball = bpy.context.object
    ball.name = "Ball"
    mat = plastic_material(metallic=metallic, alpha=alpha)
    ball.data.materials.append(mat)
    add_front_camera(sc)
    add_point_lamp(sc, energy=800.0)
    sc.view_layers[0].update()
    return sc, ball, mat


def _edit(ball):
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -1.0, 0.0), (1.0, -3.0, 2.0))
    reps = api.evaluate()
    assert reps["Ball"].renders, reps["Ball"].summary()
    assert rendering.installed(ball.data.materials[0])


def _render(tmp_path, name):
    sc = bpy.context.scene
    sc.render.filepath = str(tmp_path / f"{name}.png")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(sc.render.filepath)
    px = np.array(img.pixels[:], np.float32)
    bpy.data.images.remove(img)
    return px


def test_remove_render_edits_works_after_remove_mirror():
    sc, ball, mat = _scene()
    before = _tree_state(mat.node_tree)
    _edit(ball)
    api.remove_mirror(ball)
    assert _tree_state(mat.node_tree) == before
    assert api.remove_render_nodes(ball) == 0  # a former mirror: accepted, nothing left to remove
    assert _tree_state(mat.node_tree) == before


@pytest.mark.parametrize("metallic,alpha", [(0.0, 1.0), (0.4, 0.7)], ids=["plastic", "partly metallic, alpha"])
def test_deleted_original_bsdf_is_rebuilt_on_removal(metallic, alpha, tmp_path):
    sc, ball, mat = _scene(metallic, alpha)
    plain = _render(tmp_path, "plain")
    before = _tree_state(mat.node_tree)
    _edit(ball)
    nt = mat.node_tree
    # "Delete Unused Nodes": a node with no linked output that feeds nothing goes.
    unused = [n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled" and not shading._ours(n) and not any(o.is_linked for o in n.outputs)]
    assert len(unused) == 1
    nt.nodes.remove(unused[0])
    api.remove_render_nodes(ball)
    assert not rendering.installed(mat)
    assert _tree_state(nt) == before
    removed = _render(tmp_path, "removed")
    assert removed.reshape(-1, 4)[:, :3].max() > 0.1  # not black
    np.testing.assert_array_equal(removed, plain)


def test_removal_finds_a_renamed_material_output():
    sc, ball, mat = _scene()
    _edit(ball)
    nt = mat.node_tree
    nt.nodes["Material Output"].name = "Final Output"
    api.remove_render_nodes(ball)
    out = nt.nodes["Final Output"]
    assert out.inputs["Surface"].is_linked
    assert out.inputs["Surface"].links[0].from_node.bl_idname == "ShaderNodeBsdfPrincipled"
    assert not rendering.installed(mat)


def test_renamed_split_bsdf_leaks_no_parts():
    """Parts are found by their tag, not by the BSDF's name: after a rename, an edit of the BSDF
    rebuilds its parts in place (no orphan copies) and removal restores the tree exactly."""
    sc, ball, mat = _scene()
    nt = mat.node_tree
    _edit(ball)
    ours = len([n for n in nt.nodes if shading._ours(n)])
    split = next(n for n in nt.nodes if schema.SPLIT_KEY in n)
    split.name = "My Plastic"
    split.inputs["Roughness"].default_value = 0.35  # an edit: the parts are rebuilt
    assert shading.sync(mat)
    assert len([n for n in nt.nodes if shading._ours(n)]) == ours
    api.remove_render_nodes(ball)
    assert not [n.name for n in nt.nodes if shading._ours(n)]
    got = _tree_state(nt)
    # Exactly the artist's tree with the rename and the edit.
    sc, ball2, ref = _scene()
    ref.node_tree.nodes["Principled BSDF"].name = "My Plastic"
    ref.node_tree.nodes["My Plastic"].inputs["Roughness"].default_value = 0.35
    assert got == _tree_state(ref.node_tree)


@pytest.mark.parametrize("how", ["slot", "mesh data", "object link"])
def test_material_swapped_out_of_the_slot_loses_its_nodes(how):
    sc, ball, mat = _scene()
    before = _tree_state(mat.node_tree)
    _edit(ball)
    other = bpy.data.materials.new("Other")
    other.use_nodes = True
    if how == "slot":
        ball.material_slots[0].material = other
    elif how == "mesh data":
        ball.data.materials[0] = other
    else:
        ball.material_slots[0].link = "OBJECT"
        ball.material_slots[0].material = other
    sc.view_layers[0].update()  # the depsgraph handler syncs (no explicit evaluate)
    assert not rendering.installed(mat)
    assert _tree_state(mat.node_tree) == before
    assert rendering.installed(other)


@pytest.mark.parametrize("victim", ["scalar_math", "_feed_edited_normal", "_value_socket"])
def test_install_is_atomic_under_an_injected_fault(victim, monkeypatch):
    sc, ball, mat = _scene(0.4, 0.7)
    before = _tree_state(mat.node_tree)
    groups = sorted(g.name for g in bpy.data.node_groups)
    real = getattr(shading, victim)
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:  # half way: some nodes and links are already made
            raise RuntimeError("injected fault")
        return real(*args, **kwargs)

    monkeypatch.setattr(shading, victim, failing)
    with pytest.raises(RuntimeError, match="injected fault"):
        shading.install(mat)
    assert _tree_state(mat.node_tree) == before
    assert not rendering.installed(mat)
    monkeypatch.setattr(shading, victim, real)
    assert shading.install(mat) == 1  # and it installs cleanly afterwards
    assert shading.uninstall(mat)
    assert _tree_state(mat.node_tree) == before
    assert sorted(g.name for g in bpy.data.node_groups if not g.name.startswith("Rokeby")) == [g for g in groups if not g.startswith("Rokeby")]


def _glass_material():
    mat = bpy.data.materials.new("Glass")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    glass = nt.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["Roughness"].default_value = 0.1
    nt.links.new(glass.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
    return mat


def test_glass_removal_finds_a_renamed_material_output():
    _scene()
    mat = _glass_material()
    nt = mat.node_tree
    assert refraction.install(mat) == 1
    nt.nodes["Material Output"].name = "Final Output"
    refraction.uninstall(mat)
    surface = nt.nodes["Final Output"].inputs["Surface"]
    assert surface.is_linked and surface.links[0].from_node.bl_idname == "ShaderNodeBsdfGlass"


@pytest.mark.parametrize("victim", ["_copy_input", "_feed"])
def test_glass_install_is_atomic_under_an_injected_fault(victim, monkeypatch):
    _scene()
    mat = _glass_material()
    before = _tree_state(mat.node_tree)
    real = getattr(refraction, victim)
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2 or victim == "_feed":  # half way: some parts are already made and linked
            raise RuntimeError("injected fault")
        return real(*args, **kwargs)

    monkeypatch.setattr(refraction, victim, failing)
    with pytest.raises(RuntimeError, match="injected fault"):
        refraction.install(mat)
    assert _tree_state(mat.node_tree) == before
    assert not refraction.installed(mat)


def test_removal_refuses_when_the_bsdf_and_its_parts_are_gone():
    """With the original BSDF and its diffuse part deleted, nothing holds the artist's values:
    removal refuses by name and changes nothing (no black material, no half-removed nodes)."""
    sc, ball, mat = _scene()
    _edit(ball)
    nt = mat.node_tree
    nt.nodes.remove(next(n for n in nt.nodes if schema.SPLIT_KEY in n))
    nt.nodes.remove(next(n for n in nt.nodes if n.get(schema.ROLE_KEY) == "diffuse"))
    state = _tree_state(nt)
    with pytest.raises(api.RokebyError, match="Principled BSDF that Rokeby split was deleted"):
        api.remove_render_nodes(ball)
    assert _tree_state(nt) == state
    assert ball.rokeby.render_edits  # the mirror is as it was too


def test_old_file_parts_found_after_renaming_the_split_bsdf():
    """Files from before split ids: the parts carry the BSDF's name; renamed since, the BSDF still
    finds them (one unclaimed set) and removal restores the tree, with no second BSDF."""
    sc, ball, mat = _scene()
    nt = mat.node_tree
    before = _tree_state(nt)
    _edit(ball)
    split = next(n for n in nt.nodes if schema.SPLIT_KEY in n)
    for n in nt.nodes:  # as an older version stored it
        if shading._ours(n) and schema.SOURCE_KEY in n:
            n[schema.SOURCE_KEY] = split.name
            del n[schema.SOURCE_NAME_KEY]
    del split[schema.SPLIT_ID_KEY]
    split.name = "My Plastic"
    api.remove_render_nodes(ball)
    nt.nodes["My Plastic"].name = "Principled BSDF"
    assert _tree_state(nt) == before
