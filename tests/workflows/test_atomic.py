"""Every operation that edits materials or writes files is all or nothing: with an
exception injected at each of its internal steps in turn (tests/support/atomic_harness.py: every call of
an add-on function the operation makes), it either completes as it would have without the fault
or leaves the scene (node trees, objects' properties, attributes, shape keys, modifiers, linking,
collections, images, passes) and the disk (the reflection-map folder, the output folder) exactly
as they were."""

import math
import os
import shutil

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from support.atomic_harness import each_fault  # noqa: E402
from support import cycles  # noqa: E402
from support.scenes import add_front_camera, add_point_lamp, empty_scene, plastic_material  # noqa: E402
from rokeby import api  # noqa: E402


def _sphere(name, segments=16, rings=8, radius=1.0):
    """A UV sphere made from arrays (Blender's primitive orders its edges differently from run to
    run, and the snapshots compare attributes), with a UV map, shaded smooth."""
    verts = [(0.0, 0.0, radius)]
    for i in range(1, rings):
        th = math.pi * i / rings
        for j in range(segments):
            ph = 2 * math.pi * j / segments
            verts.append((radius * math.sin(th) * math.cos(ph), radius * math.sin(th) * math.sin(ph), radius * math.cos(th)))
    verts.append((0.0, 0.0, -radius))
    south = len(verts) - 1
    ring = lambda i, j: 1 + (i - 1) * segments + j % segments  # noqa: E731
    faces = [(0, ring(1, j), ring(1, j + 1)) for j in range(segments)]
    for i in range(1, rings - 1):
        faces += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)) for j in range(segments)]
    faces += [(ring(rings - 1, j), south, ring(rings - 1, j + 1)) for j in range(segments)]
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], [tuple(reversed(f)) for f in faces])
    me.shade_smooth()
    uv = me.uv_layers.new(name="UVMap")
    co = np.array(verts)
    loops = np.array([v for f in me.polygons for v in f.vertices])
    u = (np.arctan2(co[loops, 1], co[loops, 0]) / (2 * math.pi)) % 1.0
    v = np.arccos(np.clip(co[loops, 2] / radius, -1, 1)) / math.pi
    uv.data.foreach_set("uv", np.stack([u, v], 1).astype(np.float32).ravel())
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _check(*args, **kwargs):
    r = each_fault(*args, **kwargs)
    assert r["raised"] >= 5, r  # the faults reached the operation's inner steps
    return r


def _base(metallic=0.0):
    """A plastic ball (its Principled BSDF gets split) with a textured Specular IOR Level, a camera
    and a light; the add-on's state reset."""
    sc = cycles(empty_scene(), 24, 1)
    ball = _sphere("Ball")
    mat = plastic_material(metallic=metallic)
    ball.data.materials.append(mat)
    add_front_camera(sc)
    lamp = add_point_lamp(sc)
    sc.view_layers[0].update()
    return {"scene": sc, "ball": ball, "mat": mat, "lamp": lamp}


def _mirror(render_edits=False, metallic=0.0):
    ctx = _base(metallic)
    ball = ctx["ball"]
    api.add_mirror(ball)
    ball.rokeby.render_edits = render_edits
    api.add_constraint(ball, (0.0, -1.0, 0.0), (1.0, -3.0, 2.0))
    api.evaluate()
    return ctx


def _installed():
    ctx = _mirror(render_edits=False)
    api.install_render_nodes(ctx["ball"])
    api.evaluate()
    return ctx


# --- mirrors and render edits ---------------------------------------------------------------------

def test_add_mirror():
    each_fault(_base, lambda ctx: api.add_mirror(ctx["ball"]))  # a few steps: property settings


def test_add_constraint():
    def make():
        ctx = _base()
        api.add_mirror(ctx["ball"])
        return ctx

    _check(make, lambda ctx: api.add_constraint(ctx["ball"], (0.0, -1.0, 0.0), (1.0, -3.0, 2.0)))


@pytest.mark.parametrize("metallic", [0.0, 1.0])
def test_install_render_nodes(metallic):
    def check(ctx):
        assert rokeby.reflection.render.rendering.installed(ctx["mat"])

    _check(lambda: _mirror(False, metallic), lambda ctx: api.install_render_nodes(ctx["ball"]), check=check)


def test_remove_render_nodes():
    _check(_installed, lambda ctx: api.remove_render_nodes(ctx["ball"]))


def test_remove_mirror():
    _check(_installed, lambda ctx: api.remove_mirror(ctx["ball"]))


def test_remove_constraint():
    _check(_installed, lambda ctx: api.remove_constraint(ctx["ball"], 0))


def test_reflection_map_mode_install():
    def make():
        ctx = _installed()
        ball = ctx["ball"]
        api.capture_reflection_map(ball, resolution=32, samples=1, storage="PACK")
        ball.rokeby.render_edits = False  # the switch alone installs nothing
        ball.rokeby.render_mode = "REFLECTION_MAP"
        return ctx

    _check(make, lambda ctx: api.install_render_nodes(ctx["ball"]))


def _glass():
    """The ball made of a Glass BSDF (split for refraction on install), a mirror with a constraint."""
    ctx = _base()
    mat = bpy.data.materials.new("Glass")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    glass = nt.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["Roughness"].default_value = 0.1
    nt.links.new(glass.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
    ctx["ball"].material_slots[0].material = mat
    api.add_mirror(ctx["ball"])
    ctx["ball"].rokeby.render_edits = False
    api.add_constraint(ctx["ball"], (0.0, -1.0, 0.0), (1.0, -3.0, 2.0))
    api.evaluate()
    return ctx


def test_glass_install_and_remove():
    _check(_glass, lambda ctx: api.install_render_nodes(ctx["ball"]))

    def installed():
        ctx = _glass()
        api.install_render_nodes(ctx["ball"])
        return ctx

    _check(installed, lambda ctx: api.remove_render_nodes(ctx["ball"]))


# --- reflection-map captures: the maps folder --------------------------------------------------

def _saved(tmp_path, captured):
    def make():
        shutil.rmtree(tmp_path / "rokeby_maps", ignore_errors=True)
        ctx = _mirror(render_edits=False, metallic=1.0)
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
        if captured:
            api.capture_reflection_map(ctx["ball"], resolution=32, samples=1, storage="FILE")
            # the maps on disk differ from what the next capture writes
            ctx["lamp"].location = (-1.5, -2.0, 2.5)
            ctx["scene"].world = bpy.data.worlds.new("Bright")
            ctx["scene"].world.color = (0.9, 0.8, 0.2)
        return ctx
    return make


@pytest.mark.parametrize("captured", [False, True], ids=["first", "again"])
def test_capture_reflection_map(tmp_path, captured):
    maps = tmp_path / "rokeby_maps"

    def check(ctx):
        assert ctx["ball"].rokeby.map_image is not None
        assert {p.suffix for p in maps.iterdir()} == {".exr"}

    r = each_fault(_saved(tmp_path, captured),
                   lambda ctx: api.capture_reflection_map(ctx["ball"], resolution=32, samples=1, storage="FILE"),
                   folders=(maps,), check=check)
    assert r["raised"] > 10


# --- appearance painting --------------------------------------------------------------------------

def _plain():
    """The ball without its textured input (painting would refuse to replace the link)."""
    ctx = _base()
    nt = ctx["mat"].node_tree
    nt.nodes.remove(nt.nodes["Noise Texture"])
    return ctx


def test_appearance_setup():
    from rokeby import appearance

    _check(_plain, lambda ctx: appearance.setup(ctx["ball"]))


def test_appearance_setup_replacing_links():
    from rokeby import appearance

    def make():
        ctx = _base()
        nt = ctx["mat"].node_tree
        tex = nt.nodes.new("ShaderNodeTexChecker")
        nt.links.new(tex.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
        return ctx

    _check(make, lambda ctx: appearance.setup(ctx["ball"], linked="REPLACE"))


def test_appearance_setup_texture():
    from rokeby import appearance

    _check(_plain, lambda ctx: appearance.setup(ctx["ball"], target="TEXTURE", resolution=16))


def test_appearance_remove():
    from rokeby import appearance

    def make():
        ctx = _base()
        appearance.setup(ctx["ball"], target="TEXTURE", resolution=16, linked="REPLACE")
        return ctx

    _check(make, lambda ctx: appearance.remove(ctx["ball"], delete_attributes=True))


def test_appearance_remove_texture():
    from rokeby import appearance

    def make():
        ctx = _base()
        appearance.setup(ctx["ball"], target="TEXTURE", resolution=16, linked="REPLACE")
        return ctx

    _check(make, lambda ctx: appearance.remove_texture(ctx["ball"]))


# --- shadow edits ---------------------------------------------------------------------------------

def _shadow_scene():
    ctx = _base()
    sc, ball, lamp = ctx["scene"], ctx["ball"], ctx["lamp"]
    ball.location = (0.0, 0.0, 1.5)
    ball.scale = (0.5, 0.5, 0.5)
    lamp.location = (0.0, 0.0, 5.0)
    me = bpy.data.meshes.new("Ground")
    me.from_pydata([(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)], [], [(0, 1, 2, 3)])
    ctx["ground"] = bpy.data.objects.new("Ground", me)
    sc.collection.objects.link(ctx["ground"])
    sc.view_layers[0].update()
    s = api.start_shadow_edit(ball, lamp, [ctx["ground"]], min_loop_vertices=6)
    h = s.handles(0)["points"].astype(np.float64)
    n = len(h)
    centre = h.mean(axis=0)
    m = int(np.argmax(h[:, 0]))
    s.drag(0, ((m - n // 4) % n, (m + n // 4) % n), m, centre + (h[m] - centre) * 1.3)
    s.commit()
    ctx["session"] = s
    return ctx


def test_shadow_apply():
    _check(_shadow_scene, lambda ctx: api.apply_shadow_edit(ctx["session"], falloff_beta=1.0))


def test_shadow_apply_again():
    """Updating an applied edit (another drag, another β): the shadow mesh's shape key and
    properties come back as they were."""
    def make():
        ctx = _shadow_scene()
        api.apply_shadow_edit(ctx["session"])
        s = ctx["session"]
        h = s.handles(0)["points"].astype(np.float64)
        n = len(h)
        m = int(np.argmin(h[:, 0]))
        s.drag(0, ((m - n // 4) % n, (m + n // 4) % n), m, h[m] + (h[m] - h.mean(axis=0)) * 0.2)
        s.commit()
        return ctx

    _check(make, lambda ctx: api.apply_shadow_edit(ctx["session"], falloff_beta=2.0))


def test_shadow_remove():
    def make():
        ctx = _shadow_scene()
        api.apply_shadow_edit(ctx["session"])
        return ctx

    _check(make, lambda ctx: api.remove_shadow_edit(ctx["ball"]))


# --- compositing ----------------------------------------------------------------------------------

def test_setup_compositing_passes():
    _check(_base, lambda ctx: api.setup_compositing_passes(ctx["scene"]))


# --- files written whole --------------------------------------------------------------------------

@pytest.mark.parametrize("writer", ["compositing", "envmaps"])
@pytest.mark.parametrize("fault", ["write", "rename"])
def test_exr_writes_are_whole_or_nothing(tmp_path, monkeypatch, writer, fault):
    """The recomposited frame (CLI, sequence) and environment maps are written under a temporary
    name and renamed: a failure while writing or renaming keeps the old file and leaves no partial
    one."""
    from rokeby import compositing, envmaps
    from rokeby.core import exr

    write = {"compositing": compositing.write_exr, "envmaps": envmaps.write_exr}[writer]
    out = tmp_path / "frame.exr"
    write(out, np.full((4, 6, 3), 0.25, np.float32))
    before = out.read_bytes()
    if fault == "rename":
        def boom(*_a):
            raise OSError("injected: disk full")
        monkeypatch.setattr(os, "replace", boom)
    else:
        def boom(path, data):
            with open(path, "wb") as f:
                f.write(data[:10])  # a partial file, then the failure
            raise OSError("injected: write failed")
        monkeypatch.setattr(exr, "save", boom)
    with pytest.raises((OSError, RuntimeError), match="injected"):
        write(out, np.full((4, 6, 3), 0.75, np.float32))
    monkeypatch.undo()
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frame.exr"]
