"""The compositing feature registers itself: its operators and View Layer panel (``ui``)."""

from __future__ import annotations

from . import ui


def register():
    ui.register()


def unregister():
    ui.unregister()
