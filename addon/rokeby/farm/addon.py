"""The render-farm feature registers itself: its operator (``ui``)."""

from __future__ import annotations

from . import ui


def register():
    ui.register()


def unregister():
    ui.unregister()
