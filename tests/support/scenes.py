"""Pieces of the small Blender scenes many tests build: an empty file with the add-on registered,
the camera 4 units in front of the origin looking at it, the point light up and to its right, and
the plastic material whose Principled BSDF the add-on splits (a textured Specular IOR Level and a
coat)."""

from __future__ import annotations

import math

import pytest


def empty_scene(reset_state: bool = True):
    """Blender's empty factory file with the add-on registered (and, with ``reset_state``, the
    evaluator's per-session state dropped). Returns the scene."""
    bpy = pytest.importorskip("bpy")
    import rokeby
    from rokeby.reflection import mirror_state

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    if reset_state:
        mirror_state.reset()
    return bpy.context.scene


def add_front_camera(sc):
    """The scene's camera, named Camera, at (0, -4, 0) looking along +y at the origin."""
    import bpy

    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    return cam


def add_point_lamp(sc, energy: float | None = None):
    """A point light named Lamp at (1.5, -2, 2.5) (Blender's default power unless ``energy``)."""
    import bpy

    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    if energy is not None:
        lamp.data.energy = energy
    lamp.location = (1.5, -2.0, 2.5)
    sc.collection.objects.link(lamp)
    return lamp


def plastic_material(name: str = "Plastic", metallic: float = 0.0, alpha: float | None = None):
    """A red Principled plastic (roughness 0.2, coat 0.3) with a noise texture on its Specular IOR
    Level: a BSDF the add-on splits so that only its specular lobes see an edit."""
    import bpy

    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    p = nt.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.8, 0.2, 0.1, 1.0)
    p.inputs["Roughness"].default_value = 0.2
    p.inputs["Metallic"].default_value = metallic
    if alpha is not None:
        p.inputs["Alpha"].default_value = alpha
    p.inputs["Coat Weight"].default_value = 0.3
    noise = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(noise.outputs["Fac"], p.inputs["Specular IOR Level"])
    return mat
