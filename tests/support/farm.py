"""The shot the render-farm tests render: blend_fixtures' keyframed spot scene with a chrome mirror,
the forest world and tiny Cycles settings, render nodes installed (the add-on registered)."""

from __future__ import annotations


def keyframed_chrome_spot(*, file_format: str = "OPEN_EXR", size: int = 40, denoise: bool = True):
    """Builds the shot in the current bpy session; returns the mirror."""
    import bpy
    import make_fixtures

    import rokeby
    from rokeby import api, envmaps

    from . import SHARED, cycles

    mirror, _ = make_fixtures.keyframed_spot(SHARED)
    rokeby.register()
    sc = bpy.context.scene
    cycles(sc, size, 4, seed=3)
    if not denoise:
        sc.cycles.use_denoising = False  # Debian's Blender has no OpenImageDenoise
    sc.render.image_settings.file_format = file_format
    envmaps.use_studio_world(sc, "forest")
    mat = bpy.data.materials.new("Chrome")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.0
    mirror.data.materials.append(mat)
    api.evaluate()
    api.install_render_nodes(mirror)
    return mirror
