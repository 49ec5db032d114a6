"""Saved-data fixtures: one small scene per feature, built through the add-on's public entry
points, saved as .blend files, with what the add-on showed for them (reports, stored fields,
tiny Cycles renders) in ``fixtures.json``.

    python feature_fixtures.py write OUTDIR   # build, save OUTDIR/<feature>.blend and OUTDIR/fixtures.json
    python feature_fixtures.py load OUTDIR    # open each OUTDIR/<feature>.blend, print RESULT {json} of the same figures

tests/workflows/test_saved_fixtures.py runs ``write`` with the previous release's add-on (a git worktree of
an earlier commit, its addon/ on PYTHONPATH) and ``load`` with the current one, and compares.
This script must use only entry points that exist at that commit and in the current code alike
(rokeby.api and rokeby.appearance): it is copied into the old tree when the old tree lacks it.
``scenes()`` is also how tests/workflows/test_saved_names.py builds its scenes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

SIZE = 32  # render side, pixels
SAMPLES = 4
SEED = 7


def _reset():
    import bpy

    import rokeby

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = SAMPLES
    sc.cycles.use_denoising = False
    sc.cycles.seed = SEED
    sc.render.resolution_x = sc.render.resolution_y = SIZE
    sc.render.resolution_percentage = 100
    w = bpy.data.worlds.new("World")
    w.use_nodes = True
    w.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.05, 0.08, 1.0)
    sc.world = w
    return sc


def _camera(sc, location=(0.0, -5.0, 1.2), target=(0.0, 0.0, 0.3)):
    import bpy
    from mathutils import Vector

    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    cam.location = location
    cam.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    sc.camera = cam
    sc.view_layers[0].update()  # matrix_world of objects made by bpy.data
    return cam


def _material(name, colour=(0.8, 0.8, 0.8), metallic=0.0, roughness=0.5, emission=0.0):
    import bpy

    m = bpy.data.materials.new(name)
    m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (*colour, 1.0)
    b.inputs["Metallic"].default_value = metallic
    b.inputs["Roughness"].default_value = roughness
    if emission:
        b.inputs["Emission Color"].default_value = (*colour, 1.0)
        b.inputs["Emission Strength"].default_value = emission
    return m


def _sphere(sc, name, location=(0.0, 0.0, 0.5), radius=0.5, material=None):
    import bpy

    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=radius, location=location)
    bpy.ops.object.shade_smooth()
    ob = bpy.context.object
    ob.name = ob.data.name = name
    if material is not None:
        ob.data.materials.append(material)
    return ob


def _plane(sc, name, size, location, rotation=(0.0, 0.0, 0.0), material=None):
    import bpy

    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    ob = bpy.context.object
    ob.name = ob.data.name = name
    if material is not None:
        ob.data.materials.append(material)
    return ob


def _lamp(sc, name="Lamp", location=(-2.0, -2.0, 3.0), energy=300.0):
    import bpy

    ld = bpy.data.lights.new(name, "POINT")
    ld.energy, ld.shadow_soft_size = energy, 0.0
    lamp = bpy.data.objects.new(name, ld)
    sc.collection.objects.link(lamp)
    lamp.location = location
    sc.view_layers[0].update()
    return lamp


def _surroundings(sc):
    """A red wall behind, a floor: something for the mirrors to reflect."""
    _plane(sc, "Floor", 8.0, (0.0, 0.0, 0.0), material=_material("Floor", (0.6, 0.6, 0.6)))
    _plane(sc, "Wall", 4.0, (0.0, 2.0, 1.0), rotation=(1.5708, 0.0, 0.0), material=_material("Wall", (0.9, 0.1, 0.05), emission=1.0))


# --- one scene per feature ---------------------------------------------------------------------

def build_reflection():
    """A chrome ball with a reflection constraint, one region of each kind, a highlight
    constraint, render edits installed; a glass ball with a refraction constraint."""
    from rokeby import api

    sc = _reset()
    cam = _camera(sc)
    _surroundings(sc)
    lamp = _lamp(sc)
    ball = _sphere(sc, "Ball", material=_material("Chrome", metallic=1.0, roughness=0.05))
    ball.modifiers.new("Subdivision", "SUBSURF").levels = 1  # the field lives on a carrier mesh
    api.add_mirror(ball)
    eye = tuple(cam.location)
    api.add_constraint(ball, (0.0, -0.45, 0.7), (1.5, -3.0, 2.5), eye=eye, name="Up")
    api.add_region(ball, "EUCLIDEAN", center=(0.0, -0.5, 0.6), radius=0.6, border=0.2)
    api.add_region(ball, "GEODESIC", center=(0.3, -0.4, 0.5), radius=0.4, border=0.1)
    g = ball.vertex_groups.new(name="Painted")
    g.add(list(range(0, len(ball.data.vertices), 2)), 1.0, "REPLACE")
    api.add_region(ball, "FREEFORM", vertex_group="Painted", border=0.1)
    api.add_highlight_constraint(ball, lamp, eye=eye)
    api.install_render_nodes(ball)
    glass_mat = _material("GlassMat", roughness=0.0)
    glass_mat.node_tree.nodes["Principled BSDF"].inputs["Transmission Weight"].default_value = 1.0
    glass = _sphere(sc, "Glass", location=(1.3, 0.0, 0.4), radius=0.35, material=glass_mat)
    api.add_mirror(glass)
    api.set_ior(glass, 1.45)
    api.add_constraint(glass, (1.3, -0.33, 0.45), (1.0, 3.0, 0.2), eye=eye, kind="REFRACTION", name="Bend")
    api.install_render_nodes(glass)
    api.evaluate(sc, force=True)
    return sc


def build_shadow():
    """A ball over a floor, its shadow from a point light edited (one loop dragged outwards)."""
    from rokeby import api

    sc = _reset()
    _camera(sc, (0.0, -0.5, 6.0), (0.0, 0.0, 0.0))
    floor = _plane(sc, "Ground", 6.0, (0.0, 0.0, 0.0), material=_material("Ground", (0.8, 0.8, 0.8)))
    ball = _sphere(sc, "Caster", location=(0.0, 0.0, 0.8), radius=0.4, material=_material("Clay", (0.3, 0.5, 0.8)))
    lamp = _lamp(sc, "Sun Lamp", (0.5, 0.3, 4.0), 500.0)
    s = api.start_shadow_edit(ball, lamp, [floor], min_loop_vertices=10)
    h = s.handles(0)["points"].astype(np.float64)
    n = len(h)
    centre = h.mean(axis=0)
    m = int(np.argmax(h[:, 0]))
    s.drag(0, ((m - n // 5) % n, (m + n // 5) % n), m, centre + (h[m] - centre) * 1.35)
    s.commit()
    api.apply_shadow_edit(s)
    sc.view_layers[0].update()
    return sc


def build_appearance():
    """Two objects set up for appearance painting: per-point attributes (painted once) and image
    textures."""
    from rokeby import appearance

    sc = _reset()
    _camera(sc)
    _surroundings(sc)
    _lamp(sc)
    a = _sphere(sc, "PaintedPoints", location=(-0.6, 0.0, 0.5), material=_material("PointsMat", (0.2, 0.6, 0.2), roughness=0.4))
    appearance.setup(a)
    appearance.paint(a, "diffuse", [(-0.6, -0.5, 0.5)], 0.4, value=(0.9, 0.1, 0.1), strength=1.0)
    appearance.paint(a, "sharpen", [(-0.6, -0.5, 0.5)], 0.4, value=0.5, strength=1.0)
    b = _sphere(sc, "PaintedTexture", location=(0.6, 0.0, 0.5), material=_material("TextureMat", (0.2, 0.2, 0.7), roughness=0.6))
    appearance.setup(b, target="TEXTURE", resolution=16)
    return sc


def build_compositing():
    """The compositing passes and AOVs set up on a scene with a shiny ball."""
    from rokeby import api

    sc = _reset()
    _camera(sc)
    _surroundings(sc)
    _lamp(sc)
    _sphere(sc, "Shiny", material=_material("ShinyMat", (0.5, 0.5, 0.5), metallic=0.6, roughness=0.2))
    api.setup_compositing_passes(sc)
    return sc


def build_reflmap():
    """A chrome ball in reflection-map mode, its map captured (tiny)."""
    from rokeby import api

    sc = _reset()
    cam = _camera(sc)
    _surroundings(sc)
    ball = _sphere(sc, "MapBall", material=_material("MapChrome", metallic=1.0, roughness=0.0))
    api.add_mirror(ball)
    api.add_constraint(ball, (0.0, -0.45, 0.7), (1.5, -3.0, 2.5), eye=tuple(cam.location), name="Up")
    ball.rokeby.render_mode = "REFLECTION_MAP"
    api.capture_reflection_map(ball, resolution=32, samples=1)
    api.install_render_nodes(ball)
    api.evaluate(sc, force=True)
    return sc


FEATURES = {
    "reflection": build_reflection,
    "shadow": build_shadow,
    "appearance": build_appearance,
    "compositing": build_compositing,
    "reflmap": build_reflmap,
}


def scenes():
    """Yields (feature, scene) with each feature's scene built (one at a time: each resets the file)."""
    for name, build in FEATURES.items():
        yield name, build()


# --- what a user sees of a scene ---------------------------------------------------------------

def _arr(a):
    return None if a is None else np.asarray(a, np.float64).round(7).tolist()


def figures(sc, render_dir: Path, tag: str) -> dict:
    """Reports, stored fields and a tiny Cycles render of ``sc``."""
    import bpy

    from rokeby import api, appearance

    out = {"reports": {}, "fields": {}}
    reports = api.evaluate(sc, force=True)
    for name, rep in sorted(reports.items()):
        out["reports"][name] = rep.status
    for ob in sorted(sc.objects, key=lambda o: o.name):
        if getattr(ob, "rokeby", None) is not None and ob.rokeby.is_mirror:
            out["fields"][f"{ob.name}/stored_field"] = _arr(api.stored_field(ob))
            if ob.rokeby.constraints and any(c.kind == "REFRACTION" for c in ob.rokeby.constraints):
                out["fields"][f"{ob.name}/stored_refraction"] = _arr(api.stored_refraction(ob))
        if ob.type == "MESH" and ob.name.startswith("Painted"):
            for param in ("base_color", "roughness"):
                try:
                    out["fields"][f"{ob.name}/{param}"] = _arr(appearance.read(ob, param))
                except Exception as exc:  # noqa: BLE001 - recorded, compared like a value
                    out["fields"][f"{ob.name}/{param}"] = f"error: {type(exc).__name__}"
        shadow = getattr(ob, "rokeby_shadow", None)
        if shadow is not None and shadow.role == "SHADOW_MESH":
            co = np.empty(len(ob.data.vertices) * 3, np.float32)
            ob.data.vertices.foreach_get("co", co)
            out["fields"][f"{ob.name}/shadow_mesh"] = _arr(co)
    path = render_dir / f"{tag}_render.exr"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True, scene=sc.name)
    img = bpy.data.images.load(str(path))
    px = np.array(img.pixels[:], np.float32).reshape(SIZE, SIZE, 4)[..., :3]
    bpy.data.images.remove(img)
    out["pixels"] = px.round(5).tolist()
    return out


def write(outdir: Path) -> dict:
    import bpy

    outdir.mkdir(parents=True, exist_ok=True)
    result = {}
    for name, sc in scenes():
        bpy.ops.wm.save_as_mainfile(filepath=str(outdir / f"{name}.blend"))
        result[name] = figures(sc, outdir, f"{name}_written")
    (outdir / "fixtures.json").write_text(json.dumps(result))
    return result


def load(outdir: Path) -> dict:
    import bpy

    import rokeby

    result = {}
    for name in FEATURES:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        rokeby.register()  # before opening: the add-on's load_post handlers migrate the file
        bpy.ops.wm.open_mainfile(filepath=str(outdir / f"{name}.blend"))
        rokeby.register()
        result[name] = figures(bpy.context.scene, outdir, f"{name}_loaded")
    return result


if __name__ == "__main__":
    mode, folder = sys.argv[1], Path(sys.argv[2])
    if mode == "write":
        write(folder)
        print("RESULT " + json.dumps({"written": sorted(FEATURES)}))
    elif mode == "load":
        print("RESULT " + json.dumps(load(folder)))
    else:
        raise SystemExit(f"unknown mode {mode!r}: expected write or load")
