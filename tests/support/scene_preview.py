"""A mirror scene for the scene preview's tests (tests/reflection/test_scene_capture.py and the
GPU check blender_scene_preview_check.py) and its pictures (tools/scene_preview_pictures.py):
a mirror ball of radius 1 at the origin, matte and emissive objects 1.5 to 6 radii from its
centre, an HDR world from Blender's bundled studio lights, a camera 7 radii away.

Objects (name, kind, location, size, colour); distances are from the ball's centre."""

from __future__ import annotations

import os

import numpy as np

from support import cycles

RADIUS = 1.0
OBJECTS = [
    # the magenta cube on the floor in front of and below the ball (2.2 radii: parallax matters most here)
    ("Magenta", "CUBE", (0.35, -1.75, -1.35), 0.5, (0.8, 0.05, 0.5), 0.0),  # on the floor
    ("Red", "CUBE", (1.9, -1.0, 0.3), 0.6, (0.8, 0.1, 0.05), 0.0),
    ("Blue", "SPHERE", (-2.2, -1.3, 0.4), 0.45, (0.05, 0.2, 0.8), 0.0),
    ("Lamp", "SPHERE", (-0.9, -2.4, 1.4), 0.3, (1.0, 0.75, 0.2), 4.0),  # emissive
    ("Yellow", "CUBE", (3.5, 2.0, -0.5), 1.0, (0.85, 0.7, 0.05), 0.0),
    ("Green", "CUBE", (-4.0, 3.5, 1.0), 1.4, (0.1, 0.6, 0.15), 0.0),
    ("Floor", "PLANE", (0.0, 0.0, -1.6), 12.0, (0.5, 0.5, 0.5), 0.0),
]
EYE = (1.2, -6.8, 1.4)
WORLD = "sunset.exr"
STRENGTH = 1.0


def world_path(name: str = WORLD) -> str:
    import bpy

    d = bpy.utils.system_resource("DATAFILES", path="studiolights/world")
    path = os.path.join(d, name)
    if not os.path.exists(path):
        raise FileNotFoundError(f"Blender's bundled studio light world {path} is missing")
    return path


def material(name, colour, emission=0.0):
    import bpy

    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    spec = bsdf.inputs.get("Specular IOR Level") or bsdf.inputs.get("Specular")
    spec.default_value = 0.0
    if emission:
        bsdf.inputs["Emission Color"].default_value = (*colour, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission
    mat.diffuse_color = (*colour, 1.0)
    return mat


def mirror_material():
    import bpy

    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Roughness"].default_value = 0.0
    glossy.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    nt.links.new(glossy.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
    return mat


def build(size: int = 96, samples: int = 64, world_name: str = WORLD, strength: float = STRENGTH):
    """The scene (a fresh file with the add-on registered): returns (scene, mirror, objects by name)."""
    import bpy

    import rokeby
    from rokeby import api

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    sc = bpy.context.scene
    cycles(sc, size, samples, seed=3)
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.max_bounces = 4
    sc.cycles.pixel_filter_type = "BOX"  # a pixel is the average over its square (the preview is drawn supersampled the same way)
    sc.cycles.filter_width = 1.0
    world = bpy.data.worlds.new("HDR")
    sc.world = world
    world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(world_path(world_name))
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = strength
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=RADIUS)
    mirror = bpy.context.object
    mirror.name = "Mirror"
    bpy.ops.object.shade_smooth()
    mirror.data.materials.append(mirror_material())
    objects = {}
    for name, kind, loc, s, colour, emission in OBJECTS:
        if kind == "CUBE":
            bpy.ops.mesh.primitive_cube_add(size=s, location=loc)
        elif kind == "SPHERE":
            bpy.ops.mesh.primitive_uv_sphere_add(radius=s, location=loc, segments=32, ring_count=16)
            bpy.ops.object.shade_smooth()
        else:
            bpy.ops.mesh.primitive_plane_add(size=s, location=loc)
        ob = bpy.context.object
        ob.name = name
        ob.data.materials.append(material(name, colour, emission))
        objects[name] = ob
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = EYE
    direction = -np.asarray(EYE, np.float64)
    cam.rotation_euler = _look_rotation(direction)
    cam.data.lens = 85.0
    api.add_mirror(mirror)
    bpy.context.view_layer.update()
    return sc, mirror, objects


def _look_rotation(direction):
    from mathutils import Vector

    return Vector(tuple(direction)).to_track_quat("-Z", "Y").to_euler()


def render(sc, path: str) -> np.ndarray:
    """A Cycles render of ``sc``'s camera, linear RGB (H, W, 3), row 0 at the bottom."""
    import bpy

    from rokeby.blender import compat

    sc.render.filepath = path
    sc.render.use_file_extension = False
    compat.set_single_layer_exr(sc.render.image_settings, "32")
    sc.render.image_settings.color_mode = "RGB"
    bpy.ops.render.render(write_still=True, scene=sc.name)
    from rokeby import envmaps

    return np.ascontiguousarray(envmaps.read_exr(path)[::-1, :, :3])  # the file's rows are top-down


def camera_view_projection(sc, w: int, h: int) -> np.ndarray:
    """World -> clip of the scene camera for a w × h image."""
    import bpy

    cam = sc.camera
    dg = bpy.context.evaluated_depsgraph_get()
    proj = np.array(cam.calc_matrix_camera(dg, x=w, y=h))
    return proj @ np.array(cam.matrix_world.inverted())
