"""The Rokeby Venus scene of `make demo`, built from code (bpy, background mode).

A figure (homer.obj from the shared meshes, imported with Blender's OBJ importer) stands in front
of a framed chrome mirror. The mirror is turned so that, physically, the camera sees the figure's
body in it. One constraint (red handle at the middle of the glass, green handle dragged from the
body to the face) and a Euclidean region around the glass make the mirror show the face instead:
Velázquez's mirror, and Fig. 9a of Ritschel et al. 2009 ("the mirror should reflect the face, not
the body").

    scene = build(shared_dir, width=640, height=360, samples=24)
    render(scene_path)                          # physical reflections
    edit(scene); render(...)                    # the edit, through the render node group

``bench/demo_render.py`` times the same scene with and without the node group.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

FIGURE_HEIGHT = 1.8  # metres, feet on the floor
# Points on the figure (fractions of its height, in front of its centre line): what the mirror
# shows physically (the belly) and what it should show (the face).
BODY_Z, FACE_Z = 0.49, 0.845
# Hits on the figure at or above this fraction of its height (the chin) count as the face.
FACE_FROM = 0.72


@dataclass
class DemoScene:
    mirror: object  # the glass: the Rokeby mirror
    figure: object
    camera: object
    body: np.ndarray  # the body point the glass's centre reflects physically
    face: np.ndarray  # where the green handle goes
    glass_centre: np.ndarray
    glass_size: tuple
    constraint: int | None = None
    region: int | None = None


def _material(name, color, *, metallic=0.0, roughness=0.5):
    import bpy

    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Roughness"].default_value = roughness
    return mat


def _clothes():
    """One material for the figure whose colour is chosen by position (metres; object space is
    world space): shoes, trousers, a short-sleeved shirt, stubble round the mouth, skin elsewhere.
    Masks in the shader give clean edges at any resolution."""
    mat = _material("Figure", (0.95, 0.72, 0.12), roughness=0.45)
    nt = mat.node_tree
    coords = nt.nodes.new("ShaderNodeTexCoord")
    xyz = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(coords.outputs["Object"], xyz.inputs["Vector"])
    h = FIGURE_HEIGHT

    def math(op, a, b=None):
        node = nt.nodes.new("ShaderNodeMath")
        node.operation = op
        for i, x in enumerate((a, b)):
            if isinstance(x, float):
                node.inputs[i].default_value = x
            elif x is not None:
                nt.links.new(x, node.inputs[i])
        return node.outputs[0]

    x, y, z = xyz.outputs["X"], xyz.outputs["Y"], xyz.outputs["Z"]

    def band(lo, hi):  # lo < z < hi, in fractions of the height
        return math("MULTIPLY", math("GREATER_THAN", z, lo * h), math("LESS_THAN", z, hi * h))

    layers = [  # later layers paint over earlier ones
        ((0.85, 0.85, 0.82), math("MULTIPLY", band(0.47, 0.715), math("LESS_THAN", math("ABSOLUTE", x), 0.17 * h))),
        ((0.08, 0.18, 0.55), band(0.07, 0.47)),
        ((0.12, 0.08, 0.05), math("LESS_THAN", z, 0.07 * h)),
        ((0.55, 0.42, 0.28), math("MULTIPLY", band(0.70, 0.80), math("LESS_THAN", y, -0.025 * h))),
    ]
    bsdf = nt.nodes["Principled BSDF"]
    colour = None
    for rgb, mask in layers:
        mix = nt.nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        if colour is None:
            mix.inputs["A"].default_value = tuple(bsdf.inputs["Base Color"].default_value)
        else:
            nt.links.new(colour, mix.inputs["A"])
        mix.inputs["B"].default_value = (*rgb, 1.0)
        nt.links.new(mask, mix.inputs["Factor"])
        colour = mix.outputs["Result"]
    nt.links.new(colour, bsdf.inputs["Base Color"])
    return mat


def _look_at(ob, target):
    from mathutils import Vector

    d = Vector(target) - ob.location
    ob.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()


def _figure(path: Path):
    """Import the figure, stand it on the floor at the origin facing -Y, FIGURE_HEIGHT tall, and
    dress it (skin, stubble, shirt, trousers, shoes, eyes) so that body and face read apart."""
    import bpy

    bpy.ops.wm.obj_import(filepath=str(path), forward_axis="NEGATIVE_Z", up_axis="Y")
    fig = bpy.context.selected_objects[0]
    fig.name = "Figure"
    me = fig.data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ np.array(fig.matrix_world)[:3, :3].T
    lo, hi = co.min(0), co.max(0)
    s = FIGURE_HEIGHT / float(hi[2] - lo[2])
    fig.matrix_world.identity()
    co = (co - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]) * s
    me.vertices.foreach_set("co", co.astype(np.float32).ravel())
    me.polygons.foreach_set("use_smooth", np.ones(len(me.polygons), bool))
    me.update()
    me.materials.append(_clothes())
    # The mesh has eye sockets only: white eyeballs with dark pupils make the face read.
    white = _material("Eye", (0.95, 0.95, 0.93), roughness=0.3)
    dark = _material("Pupil", (0.02, 0.02, 0.02), roughness=0.3)
    for side in (-1.0, 1.0):
        for radius, y, mat in ((0.045, -0.085, white), (0.011, -0.128, dark)):
            bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=(side * 0.045, y, 1.545), segments=24, ring_count=12)
            ball = bpy.context.object
            ball.name = f"Figure {mat.name.lower()}"
            ball.data.materials.append(mat)
            ball.data.polygons.foreach_set("use_smooth", np.ones(len(ball.data.polygons), bool))
            ball.parent = fig
    return fig, co


def _mirror(centre, normal, width, height, cuts=24):
    """A subdivided glass plane (the Rokeby mirror) and a gilded frame, facing ``normal``."""
    import bpy
    from mathutils import Vector

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=1.0)
    glass = bpy.context.object
    glass.name = "Mirror"
    glass.scale = (width, height, 1.0)
    rot = Vector(normal).to_track_quat("Z", "Y")
    glass.rotation_mode = "QUATERNION"
    glass.rotation_quaternion = rot
    glass.location = centre
    glass.data.materials.append(_material("Chrome", (0.9, 0.9, 0.9), metallic=1.0, roughness=0.0))
    border = 0.06
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    frame = bpy.context.object
    frame.name = "Mirror frame"
    frame.scale = (width + 2 * border, height + 2 * border, 0.04)
    frame.rotation_mode = "QUATERNION"
    frame.rotation_quaternion = rot
    frame.location = Vector(centre) - Vector(normal) * 0.021
    frame.data.materials.append(_material("Gilt", (0.8, 0.55, 0.2), metallic=1.0, roughness=0.35))
    bpy.context.view_layer.update()
    return glass


def build(shared: Path, *, width: int = 640, height: int = 360, samples: int = 24, seed: int = 9) -> DemoScene:
    """A fresh file with the demo scene, physically reflecting (no edit yet)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.seed = seed
    sc.cycles.use_denoising = True
    sc.cycles.denoiser = "OPENIMAGEDENOISE"
    sc.cycles.max_bounces = 4
    sc.render.resolution_x, sc.render.resolution_y = width, height
    sc.render.resolution_percentage = 100
    sc.render.image_settings.file_format = "PNG"
    sc.view_settings.view_transform = "Standard"

    from . import envmaps

    envmaps.use_studio_world(sc, "forest")

    bpy.ops.mesh.primitive_plane_add(size=12.0)
    floor = bpy.context.object
    floor.name = "Floor"
    floor.data.materials.append(_material("Floor", (0.35, 0.3, 0.26), roughness=0.8))

    fig, co = _figure(shared / "meshes" / "homer.obj")
    h = FIGURE_HEIGHT

    def front_point(z):
        band = co[np.abs(co[:, 2] - z * h) < 0.03 * h]
        band = band[np.abs(band[:, 0]) < 0.12 * h]
        return np.array([0.0, band[:, 1].min(), z * h])

    body, face = front_point(BODY_Z), front_point(FACE_Z)

    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.data.lens = 56.0
    eye = np.array([-4.8, -1.0, 1.45])
    glass_centre = np.array([0.1, -1.25, 1.0])
    # Physically, the glass's centre shows the body: its normal halves the angle between the
    # directions to the eye and to the body.
    to_eye = (eye - glass_centre) / np.linalg.norm(eye - glass_centre)
    to_body = (body - glass_centre) / np.linalg.norm(body - glass_centre)
    normal = (to_eye + to_body) / np.linalg.norm(to_eye + to_body)
    size = (0.5, 0.65)
    glass = _mirror(glass_centre, normal, *size)
    cam.location = eye
    _look_at(cam, (0.0, -0.62, 1.04))

    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 2.0
    sun.data.angle = np.radians(5.0)
    sc.collection.objects.link(sun)
    sun.rotation_euler = (np.radians(50.0), 0.0, np.radians(200.0))
    bpy.context.view_layer.update()
    return DemoScene(glass, fig, cam, body, face, glass_centre, size)


def edit(demo: DemoScene) -> dict:
    """Make the mirror show the face: a Rokeby mirror, one constraint at the glass's centre whose
    green handle is dragged from the body to the face, a Euclidean region around the glass, and
    the render node group. Returns the evaluation report of the mirror and what was moved."""
    import bpy

    from . import api

    api.add_mirror(demo.mirror)
    eye = np.array(demo.camera.matrix_world.translation)
    k = api.add_constraint(demo.mirror, demo.glass_centre, eye=eye, name="Face, not body")
    green = demo.mirror.rokeby.constraints[k].target_handle
    start = np.array(green.location)
    green.location = demo.face.tolist()  # the artist's drag
    radius = 0.5 * float(np.hypot(*demo.glass_size)) + 0.05
    r = api.add_region(demo.mirror, "EUCLIDEAN", center=demo.glass_centre, radius=radius, border=0.05, name="Glass")
    bpy.context.view_layer.update()
    rep = api.evaluate()[demo.mirror.name]
    wired = api.install_render_nodes(demo.mirror)
    demo.constraint, demo.region = k, r
    return {"report": rep, "green_from": start, "green_to": demo.face.copy(), "radius": radius, "wired": wired}


def render(path: Path) -> float:
    """Render the scene camera to ``path`` (PNG); returns the seconds the render took."""
    import time

    import bpy

    sc = bpy.context.scene
    sc.render.filepath = str(path)
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t


def glass_view(demo: DemoScene, *, edited: bool) -> dict:
    """What the glass shows, per glass vertex: the physically reflected ray from the camera
    (``edited=False``) or the edited one e = R r (``edited=True``, needs the Rokeby mirror) is cast
    into the scene and classified by what it hits: the figure's face (head height and above), its
    body, or anything else. Returns the fractions of glass vertices and the hit height at the
    glass's centre."""
    import bpy

    from . import api

    sc = bpy.context.scene
    dg = bpy.context.evaluated_depsgraph_get()
    eye = np.array(demo.camera.matrix_world.translation, np.float64)
    m = api.mesh_arrays(demo.mirror)
    p = m.vertices.astype(np.float64)
    if edited:
        d = api.edited_reflections(demo.mirror, eye).astype(np.float64)
    else:
        i = p - eye
        i /= np.linalg.norm(i, axis=1, keepdims=True)
        d = api.reflect(i, m.normals.astype(np.float64))
    figure = {demo.figure.name} | {ob.name for ob in demo.figure.children}
    kinds, heights = [], []
    for q, n, r in zip(p, m.normals, d):
        hit, loc, _n, _i, ob, _m = sc.ray_cast(dg, (q + 1e-4 * n).tolist(), r.tolist())
        if hit and ob.original.name in figure:
            kinds.append("face" if loc.z > FACE_FROM * FIGURE_HEIGHT else "body")
        else:
            kinds.append("other")
        heights.append(loc.z if hit else np.nan)
    kinds = np.array(kinds)
    centre = int(np.argmin(np.linalg.norm(p - demo.glass_centre, axis=1)))
    return {k: float(np.mean(kinds == k)) for k in ("face", "body", "other")} | {"centre_height": float(heights[centre]), "centre_sees": str(kinds[centre])}


def side_by_side(before: Path, after: Path, out: Path, labels=("", "")) -> tuple:
    """One picture: ``before`` and ``after`` next to each other with a caption band under each
    (composed with numpy, saved through a Blender image, captions drawn with blf into an ImBuf;
    where blf cannot draw into images, Blender 4.2, the bands stay empty and a note says so).
    Returns its (width, height)."""
    import bpy

    from .blender import compat

    pics = []
    for path in (before, after):
        img = bpy.data.images.load(str(path))
        w, h = img.size
        pics.append(np.array(img.pixels[:], np.float32).reshape(h, w, 4))
        bpy.data.images.remove(img)
    h = max(p.shape[0] for p in pics)
    gap, band = 8, 40
    width = sum(p.shape[1] for p in pics) + gap
    canvas = np.ones((h + band, width, 4), np.float32)
    canvas[..., :3] = 0.08
    x = 0
    lefts = []
    for p in pics:  # Blender images are stored bottom row first: the band goes below (rows 0..band)
        canvas[band + h - p.shape[0]: band + h, x: x + p.shape[1]] = p
        lefts.append(x)
        x += p.shape[1] + gap
    img = bpy.data.images.new("Rokeby side by side", width, h + band)
    img.pixels.foreach_set(canvas.ravel())
    out.parent.mkdir(parents=True, exist_ok=True)
    img.filepath_raw = str(out)
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)
    if not compat.blf_draws_into_images():
        print(f"  (no captions in {out.name}: this Blender's blf cannot draw into images; 4.3+ can)")
        return width, h + band
    import blf
    import imbuf

    buf = imbuf.load(str(out))
    with blf.bind_imbuf(0, buf):
        blf.size(0, 17)
        blf.color(0, 1.0, 1.0, 1.0, 1.0)
        for left, text in zip(lefts, labels):
            blf.position(0, left + 12, 14, 0)
            blf.draw_buffer(0, text)
    imbuf.write(buf, filepath=str(out))
    return width, h + band
