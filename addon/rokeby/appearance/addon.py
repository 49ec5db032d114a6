"""The appearance-painting feature registers itself: its operators, brush settings, panels and
preview (``ui``), and its steps in the add-on's hooks (``rokeby.blender.hooks``): after loading,
files painted before the specular colour brush get its parameter; after undo/redo, painted images
reload the pixels of the packed data the step brought back. ``hooks.remove`` also takes away the
save handler that packs painted images (added by the first stroke)."""

from __future__ import annotations

from .. import appearance
from ..blender import hooks
from . import ui

OWNER = "appearance"


def _migrate():
    for msg in appearance.migrate():
        print(f"Rokeby: appearance painting: {msg}")


def register():
    ui.register()
    hooks.add_step(OWNER, "migrate", _migrate)
    hooks.add_step(OWNER, "undo_redo", appearance.reload_after_undo)


def unregister():
    hooks.remove(OWNER)
    ui.unregister()
