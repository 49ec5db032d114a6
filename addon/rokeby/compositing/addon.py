"""The compositing feature registers itself: its operators and View Layer panel (``ui``), and the
normal brush's operator and Image Editor panel (``brush_ui``)."""

from __future__ import annotations

from . import brush_ui, ui


def register():
    ui.register()
    brush_ui.register()


def unregister():
    brush_ui.unregister()
    ui.unregister()
