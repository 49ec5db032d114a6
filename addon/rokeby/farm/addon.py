"""The render-farm feature registers itself: its operators (``ui``) and the save_pre handler that
records in a saved file which Rokeby saved it (``marker``)."""

from __future__ import annotations

from ..blender import hooks
from . import marker, ui


def register():
    ui.register()
    hooks.add("farm", "save_pre", marker.on_save_pre)


def unregister():
    hooks.remove("farm")
    ui.unregister()
