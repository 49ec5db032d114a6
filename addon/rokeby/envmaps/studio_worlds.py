"""The HDR worlds bpy ships (studiolights/world: city, courtyard, forest, interior, night, studio,
sunrise, sunset): their paths, and a world lit by one of them, for the tests, the demo and scripts
that need an environment without a file of their own."""

from __future__ import annotations

from pathlib import Path


def studio_world(name: str) -> Path:
    """Path of one of the HDR worlds bpy ships (city, courtyard, forest, interior, night, studio,
    sunrise, sunset)."""
    import bpy

    root = Path(bpy.utils.system_resource("DATAFILES")) / "studiolights" / "world"
    p = root / f"{name}.exr"
    if not p.exists():
        names = sorted(q.stem for q in root.glob("*.exr"))
        raise ValueError(f"name: no world {name!r} among the HDR worlds bpy ships (have {', '.join(names)})")
    return p


def use_studio_world(scene, name: str = "forest"):
    """Give ``scene`` a new world lit by one of the shipped HDRs (``studio_world``) through an
    Environment Texture node; returns the world."""
    import bpy

    world = bpy.data.worlds.new(name.capitalize())
    scene.world = world
    world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(studio_world(name)), check_existing=True)
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    return world
