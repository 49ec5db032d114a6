"""The shadow-editing feature registers itself: its operators, panel and overlay (``ui``), the
display of its meshes following the views' shading (``display``), and its steps in the add-on's
live updates (``rokeby.blender.hooks``): after each update deleted parts are repaired, each shadow
mesh's falloff follows its light and its display the views; after loading, old files migrate."""

from __future__ import annotations

from .. import shadow
from ..blender import hooks
from . import display, linking, ui

OWNER = "shadow"


def _scene_update(scene) -> int:
    """Deleted casters, lights, twins or shadow meshes leave no half set-up behind; the falloff of
    each shadow mesh follows its light (writes only changed values, so the update settles)."""
    if not any(linking._parts()):
        return 0
    for msg in shadow.repair(scene):
        print(f"Rokeby: {msg}")
    return shadow.sync_falloffs(scene)


def _migrate():
    """Shadow edits saved with names (before shadow data version 1) get pointers."""
    for msg in shadow.migrate():
        print(f"Rokeby: migrated {msg}")


def register():
    ui.register()
    display.register()
    hooks.add_step(OWNER, "scene_update", _scene_update)
    hooks.add_step(OWNER, "migrate", _migrate)


def unregister():
    hooks.remove(OWNER)
    display.unregister()
    ui.unregister()
