"""A stand-in for Blender's UILayout in background mode (no window to draw in): the add-on's
panels draw into :class:`Layout`, which records what they show and checks that every property,
operator and menu they name exists; :func:`draw_sidebar` draws the mirror sidebar as Blender would."""

from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")


class Layout:
    """Stands in for bpy.types.UILayout in background mode (no window to draw in): records the
    calls and checks that every property and operator the panel names exists."""

    def __init__(self, log):
        self.log = log
        self.alert = False

    def _sub(self, *a, **k):
        return Layout(self.log)

    row = column = box = _sub

    def label(self, text="", icon="NONE"):
        self.log.append(("label", text))

    def prop(self, data, name, **k):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **k):
        assert name in data.bl_rna.properties and search_name in search_data.bl_rna.properties
        self.log.append(("prop_search", name))

    def template_list(self, list_type, list_id, data, name, active_data, active_name, **k):
        assert hasattr(bpy.types, list_type)
        assert name in data.bl_rna.properties and active_name in active_data.bl_rna.properties
        self.log.append(("list", name))

    def operator(self, idname, **k):
        mod, op = idname.split(".")
        assert hasattr(getattr(bpy.ops, mod), op), idname
        self.log.append(("operator", idname))
        return OpProps(idname)

    def operator_menu_enum(self, idname, prop, **k):
        return self.operator(idname)

    def separator(self, **k):
        pass

    def menu(self, idname, **k):
        assert hasattr(bpy.types, idname), idname
        self.log.append(("menu", idname))


def draw_sidebar(panel_log):
    """Draws the sidebar's mirror panel and each sub-panel whose poll passes (as Blender does)
    into ``panel_log``."""
    from rokeby.reflection.ui import MIRROR_PANELS

    for cls in MIRROR_PANELS:
        if getattr(cls, "bl_parent_id", None) and not cls.poll(bpy.context):
            continue
        cls.draw(type("P", (), {"layout": Layout(panel_log)})(), bpy.context)


class OpProps:
    def __init__(self, idname):
        mod, op = idname.split(".")
        self.rna = getattr(getattr(bpy.ops, mod), op).get_rna_type()

    def __setattr__(self, key, value):
        if key != "rna":
            assert key in self.rna.properties, f"{self.rna.identifier} has no property {key!r}"
        object.__setattr__(self, key, value)
