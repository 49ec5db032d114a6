"""Scenes of the reflection tests that several files share."""

import numpy as np

from support import cycles

CHROME_BALL_SIZE = 48  # pixels of the chrome ball's square renders


def chrome_ball():
    """A smooth chrome ball (metallic 1, roughness 0) under forest.exr seen from 4 units in front,
    8-sample Cycles renders of CHROME_BALL_SIZE pixels, the add-on registered and its state reset.
    Returns ``(ball, material)``."""
    import bpy

    import rokeby
    from rokeby import envmaps
    from rokeby.reflection import mirror_state

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    mirror_state.reset()
    sc = bpy.context.scene
    cycles(sc, CHROME_BALL_SIZE, 8, seed=1)
    envmaps.use_studio_world(sc, "forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    ball.name = "Ball"
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.0
    ball.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    return ball, mat
