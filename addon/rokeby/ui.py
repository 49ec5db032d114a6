"""Sidebar UI (3D View ▸ Rokeby). Registered by ``rokeby.register``; no ``gpu`` use here."""

from __future__ import annotations

import bpy

from . import native


class ROKEBY_PT_main(bpy.types.Panel):
    bl_idname = "ROKEBY_PT_main"
    bl_label = "Rokeby"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Rokeby"

    def draw(self, context):
        layout = self.layout
        if native.available():
            layout.label(text=f"Native core {native.version()}", icon="CHECKMARK")
        else:
            col = layout.column()
            col.alert = True
            col.label(text="Native core missing", icon="ERROR")
            col.label(text="Run `make` in the Rokeby checkout")


_classes = (ROKEBY_PT_main,)


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(_classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
