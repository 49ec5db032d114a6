"""The Blender scene of the compositing tests (tests/compositing), reused where other tests need
rendered passes."""


def pass_scene(tiny_object=False):
    """A red half-metal ball (and, with ``tiny_object``, a small ico sphere) under forest.exr, a
    camera, 64 × 48 Cycles renders at 16 samples: the scene whose passes the compositing tests
    render."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.samples, sc.cycles.device, sc.cycles.use_denoising = 16, "CPU", False
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 64, 48, 100
    from rokeby import envmaps

    envmaps.use_studio_world(sc, "forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    ob = bpy.context.object
    mat = bpy.data.materials.new("red")
    mat.use_nodes = True
    b = mat.node_tree.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (0.8, 0.3, 0.2, 1)
    b.inputs["Metallic"].default_value = 0.5
    b.inputs["Roughness"].default_value = 0.2
    ob.data.materials.append(mat)
    if tiny_object:
        bpy.ops.mesh.primitive_ico_sphere_add(radius=0.06, location=(1.4, 0, 0.9))
        bpy.context.object.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0.3, -4.5, 0.8), rotation=(1.4, 0, 0.06))
    sc.camera = bpy.context.object
    return sc
