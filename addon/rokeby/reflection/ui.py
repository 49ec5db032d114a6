"""Sidebar UI (3D View ▸ Sidebar ▸ Rokeby) and menus (Object ▸ Rokeby, the object context menu).

The sidebar's *Reflection Editing* panel lists the mirrors and shows the active mirror's status;
its sub-panels hold the rest: *Constraints*, *Regions*, *Settings* and *Render*. The Rokeby menu
names every operator of the add-on, so F3 search finds each one (Blender's menu search reads
menus). Registered by ``rokeby.register``; no ``gpu`` use here."""

from __future__ import annotations

import bpy

from . import api  # reflection editing's entry points (rokeby.api re-exports their __all__)
from . import interpolation_error, mirror_state, scene_inputs
from ..core import native, words
from .viewport import draw as viewport
from .viewport import scene_env
from .props import METRICS
from ..core import schema
from ..blender import ui_text

_STATUS_ICON = {"OK": "CHECKMARK", "WARNING": "ERROR", "ERROR": "CANCEL", "DISABLED": "HIDE_ON"}


def _active_mirror(context):
    return api.mirror_of(context.active_object, context.scene)


class ROKEBY_UL_constraints(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        broken = item.surface_handle is None or item.target_handle is None
        row.alert = broken
        row.prop(item, "enabled", text="")
        row.prop(item, "name", text="", emboss=False, icon="ERROR" if broken else "CON_TRACKTO")
        op = row.operator("rokeby.constraint_select", text="", icon="RESTRICT_SELECT_OFF", emboss=False)
        op.mirror, op.index = data.id_data.name, index


class ROKEBY_UL_regions(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        row.prop(item, "enabled", text="")
        icons = {"EUCLIDEAN": "SPHERE", "GEODESIC": "MESH_CIRCLE", "FREEFORM": "GROUP_VERTEX"}
        row.prop(item, "name", text="", emboss=False, icon=icons[item.kind])


def _sidebar(cls):
    cls.bl_space_type = "VIEW_3D"
    cls.bl_region_type = "UI"
    cls.bl_category = "Rokeby"
    return cls


@_sidebar
class ROKEBY_PT_main(bpy.types.Panel):
    """The mirrors of the scene, the viewport preview switch and the active mirror's status."""

    bl_idname = "ROKEBY_PT_main"
    bl_label = "Reflection Editing"
    bl_order = 0

    def draw(self, context):
        layout = self.layout
        if not native.available():
            col = layout.column()
            col.alert = True
            col.label(text="Rokeby's native core did not load", icon="ERROR")
            for line in _wrap(native.missing_hint(), 48):
                col.label(text=line)
            return
        mirrors = scene_inputs.mirrors_of(context.scene)
        box = layout.box()
        box.label(text=f"Mirrors ({len(mirrors)})", icon="MOD_MIRROR")
        box.prop(context.scene, schema.SCENE_VIEWPORT_PREVIEW_PROP, icon="SHADING_RENDERED")
        if getattr(context.scene, schema.SCENE_VIEWPORT_PREVIEW_PROP, False):
            row = box.row(align=True)
            row.prop(context.scene, schema.SCENE_PREVIEW_RENDERED_PROP)
            row.operator("rokeby.preview_capture", text="", icon="FILE_REFRESH")
        if viewport.last_error():
            ui_text.label(box, context, f"Preview: {viewport.last_error()}"[:240], icon="ERROR", boxed=True)
        for m in mirrors:
            rep = mirror_state.report_of(m)
            row = box.row(align=True)
            row.label(text=m.name, icon=_STATUS_ICON.get(rep.status, "QUESTION") if rep else "TIME")
            row.prop(m.rokeby, "enabled", text="")
        mirror = _active_mirror(context)
        ob = context.active_object
        if mirror is None:
            if ob is not None and ob.type == "MESH":
                layout.operator("rokeby.mirror_add", icon="ADD")
            else:
                layout.label(text="Select a mesh to make it a mirror")
            if mirrors:
                layout.operator("rokeby.update", icon="FILE_REFRESH")
            return
        row = layout.row(align=True)
        row.label(text=f"Mirror: {mirror.name}", icon="OBJECT_DATA")
        row.prop(mirror.rokeby, "enabled", text="")
        op = row.operator("rokeby.mirror_remove", text="", icon="TRASH")
        op.mirror = mirror.name
        rep = mirror_state.report_of(mirror)
        if rep is not None:
            col = layout.column(align=True)
            col.alert = rep.status == "ERROR"
            ui_text.label(col, context, f"{words.status(rep.status)}: {rep.constraints_used} constraint(s), {rep.vertices:,} vertices", icon=_STATUS_ICON[rep.status])
            for msg in rep.messages[:6]:
                ui_text.label(col, context, msg)
            if rep.render_note:
                row = col.row()
                row.alert = rep.renders is False
                ui_text.label(row, context, rep.render_note[:240], icon={True: "RENDER_STILL", False: "ERROR", None: "INFO"}[rep.renders])
            if rep.interpolation_error is not None:
                p99, worst = rep.interpolation_error[:2]
                ui_text.label(col, context, f"render vs preview: {p99:.2f}° (99th percentile), {worst:.2f}° max", icon="CHECKMARK" if p99 <= interpolation_error.AGREEMENT_DEGREES else "ERROR")
            cap = scene_env.current(mirror)
            if cap is not None:  # short: details in docs/addon.md, "Viewport preview"
                where = "GPU" if cap.route == "VIEWPORT" else "Cycles"
                col.label(text=f"Scene ({where}) {cap.seconds:.2f} s, {cap.nbytes / 2**20:.1f} MB", icon="WORLD")
            elif scene_env.error_of(mirror):
                col.label(text="Scene capture failed", icon="ERROR")
            if rep.recomputed or rep.python_ms:
                ui_text.label(col, context, f"last update {rep.python_ms + rep.native_ms:.1f} ms (Python {rep.python_ms:.1f}, Rust {rep.native_ms:.1f})")
        layout.operator("rokeby.update", icon="FILE_REFRESH")


def _wrap(text: str, width: int) -> list:
    """``text`` in lines of about ``width`` characters (a panel label does not wrap by itself)."""
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return lines + ([line] if line else [])


class _MirrorSubPanel:
    """A sub-panel of the active mirror (shown when there is one and the native core loaded)."""

    bl_parent_id = "ROKEBY_PT_main"

    @classmethod
    def poll(cls, context):
        return native.available() and _active_mirror(context) is not None


@_sidebar
class ROKEBY_PT_constraints(_MirrorSubPanel, bpy.types.Panel):
    bl_idname = "ROKEBY_PT_constraints"
    bl_label = "Constraints"
    bl_order = 0

    def draw(self, context):
        layout = self.layout
        mirror = _active_mirror(context)
        s = mirror.rokeby
        row = layout.row()
        row.template_list("ROKEBY_UL_constraints", "", s, "constraints", s, "active_constraint", rows=3)
        col = row.column(align=True)
        op = col.operator("rokeby.constraint_add", icon="ADD", text="")
        op.mirror = mirror.name
        op = col.operator("rokeby.constraint_add", icon="LIGHT_SUN", text="")  # a refraction constraint
        op.mirror, op.kind = mirror.name, "REFRACTION"
        op = col.operator("rokeby.highlight_add", icon="LIGHT_POINT", text="")  # from the selected light
        op.mirror = mirror.name
        op = col.operator("rokeby.constraint_remove", icon="REMOVE", text="")
        op.mirror = mirror.name
        if len(s.constraints) and s.active_constraint < len(s.constraints):
            c = s.constraints[s.active_constraint]
            sub = layout.column(align=True)
            sub.prop(c, "surface_handle", text="Red")
            sub.prop(c, "target_handle", text="Green")
            sub.prop(c, "eye")
            sub.prop(c, "kind")
        if any(c.kind == "REFRACTION" for c in s.constraints):
            row = layout.row(align=True)
            row.prop(s, "ior")
            op = row.operator("rokeby.ior_from_material", text="", icon="MATERIAL")
            op.mirror = mirror.name


@_sidebar
class ROKEBY_PT_regions(_MirrorSubPanel, bpy.types.Panel):
    bl_idname = "ROKEBY_PT_regions"
    bl_label = "Regions"
    bl_order = 1

    def draw(self, context):
        layout = self.layout
        mirror = _active_mirror(context)
        s = mirror.rokeby
        row = layout.row()
        row.template_list("ROKEBY_UL_regions", "", s, "regions", s, "active_region", rows=2)
        col = row.column(align=True)
        col.operator_menu_enum("rokeby.region_add", "kind", icon="ADD", text="")
        op = col.operator("rokeby.region_remove", icon="REMOVE", text="")
        op.mirror = mirror.name
        if len(s.regions) and s.active_region < len(s.regions):
            rg = s.regions[s.active_region]
            sub = layout.column(align=True)
            sub.prop(rg, "kind")
            if rg.kind == "FREEFORM":
                sub.prop_search(rg, "vertex_group", mirror, "vertex_groups")
            else:
                sub.prop(rg, "center")
                sub.prop(rg, "radius")
            sub.prop(rg, "border")


@_sidebar
class ROKEBY_PT_settings(_MirrorSubPanel, bpy.types.Panel):
    bl_idname = "ROKEBY_PT_settings"
    bl_label = "Settings"
    bl_order = 2

    def draw(self, context):
        layout = self.layout
        mirror = _active_mirror(context)
        s = mirror.rokeby
        col = layout.column()
        col.label(text="Distance")
        row = col.row(align=True)
        for ident, name, *_ in METRICS:  # an operator: geodesic distances take a while, with progress
            op = row.operator("rokeby.distance_set", text=name, depress=s.metric == ident)
            op.mirror, op.metric = mirror.name, ident
        if s.metric == "GEODESIC":
            col.prop(s, "geodesic_method")
            if mirror_state.heat_seams(mirror):
                # A short row; the method's tooltip (the enum item's description) has the details.
                row = col.row()
                row.alert = True
                row.label(text=mirror_state.HEAT_SEAMS_STATUS, icon="ERROR")
        # Short names: a field's name gets a quarter of the sidebar's width (the tooltip has the full one).
        col.prop(s, "polar", text="Polar")
        col.prop(s, "eye_source", text="Eye")
        col.prop(s, "render_edits")
        col.prop(s, "show_preview")
        if viewport.status_of(mirror):
            col.label(text=viewport.status_of(mirror)[:120], icon="INFO")
        row = layout.row(align=True)
        row.prop(s, "freeze", toggle=True, icon="FREEZE")
        op = row.operator("rokeby.return_to_view", icon="HIDE_OFF")
        op.mirror = mirror.name


@_sidebar
class ROKEBY_PT_render(_MirrorSubPanel, bpy.types.Panel):
    bl_idname = "ROKEBY_PT_render"
    bl_label = "Render"
    bl_order = 3

    def draw(self, context):
        layout = self.layout
        mirror = _active_mirror(context)
        s = mirror.rokeby
        layout.label(text="Edited materials")
        layout.prop(s, "all_materials")
        if not s.all_materials:
            edited = {item.material for item in s.materials}
            for slot in mirror.material_slots:
                if slot.material is None:
                    continue
                on = slot.material in edited
                op = layout.operator("rokeby.material_toggle", text=slot.material.name, icon="CHECKBOX_HLT" if on else "CHECKBOX_DEHLT", depress=on)
                op.mirror, op.material = mirror.name, slot.material.name
        layout.prop(s, "render_mode", text="Mode")
        if s.render_mode == "REFLECTION_MAP":
            _draw_reflection_map(layout, mirror, context.scene)
        row = layout.row(align=True)
        op = row.operator("rokeby.render_nodes", text="Reinstall Render Nodes", icon="NODE_MATERIAL")
        op.mirror, op.action = mirror.name, "INSTALL"
        op = row.operator("rokeby.render_nodes", text="", icon="X")
        op.mirror, op.action = mirror.name, "REMOVE"
        layout.operator("rokeby.farm_export", text="Export Farm Job…", icon="NETWORK_DRIVE")


def _draw_reflection_map(layout, mirror, scene):
    from .render import reflmap  # noqa: PLC0415

    s = mirror.rokeby
    box = layout.box()
    col = box.column(align=True)
    col.prop(s, "map_resolution")
    col.prop(s, "map_samples")
    col.prop(s, "map_origin")
    img = s.map_image
    if img is None:
        box.label(text="No map captured yet", icon="INFO")
    else:
        where = "packed" if img.packed_file else img.filepath
        box.label(text=f"{img.size[0]} × {img.size[1]}, {s.map_capture_seconds:.1f} s, {where}", icon="IMAGE_DATA")
        if reflmap.is_stale(mirror, scene):
            row = box.row()
            row.alert = True
            row.label(text="Stale: the scene changed since the capture", icon="ERROR")
    row = box.row(align=True)
    op = row.operator("rokeby.reflection_map", text="Capture Map" if img is None else "Refresh Map", icon="WORLD")
    op.mirror, op.action = mirror.name, "CAPTURE"
    if img is not None:
        op = row.operator("rokeby.reflection_map", text="", icon="X")
        op.mirror, op.action = mirror.name, "CLEAR"


# --- menus: Object ▸ Rokeby and the 3D View's object context menu ---------------------------------

# (operator, its label in the menu, properties, icon): every operator of the add-on, so that F3
# search (which reads menus) finds each one by its button's name.
MENU = (
    ("rokeby.mirror_add", None, {}, "ADD"),
    ("rokeby.mirror_remove", None, {}, "TRASH"),
    None,
    ("rokeby.constraint_add", "Add Reflection Constraint", {}, "CON_TRACKTO"),
    ("rokeby.constraint_add", "Add Refraction Constraint", {"kind": "REFRACTION"}, "LIGHT_SUN"),
    ("rokeby.highlight_add", None, {}, "LIGHT_POINT"),
    ("rokeby.constraint_remove", None, {}, "REMOVE"),
    ("rokeby.constraint_select", None, {}, "RESTRICT_SELECT_OFF"),
    ("rokeby.return_to_view", None, {}, "HIDE_OFF"),
    None,
    ("rokeby.region_add", "enum:kind", {}, "ADD"),
    ("rokeby.region_remove", None, {}, "REMOVE"),
    None,
    ("rokeby.distance_set", "Use Geodesic Distances", {"metric": "GEODESIC"}, "MESH_CIRCLE"),
    ("rokeby.distance_set", "Use Euclidean Distances", {"metric": "EUCLIDEAN"}, "SPHERE"),
    ("rokeby.freeze", None, {}, "FREEZE"),
    ("rokeby.material_toggle", "Toggle Active Material", {}, "MATERIAL"),
    ("rokeby.ior_from_material", None, {}, "MATERIAL"),
    ("rokeby.render_nodes", "Install Render Nodes", {"action": "INSTALL"}, "NODE_MATERIAL"),
    ("rokeby.render_nodes", "Remove Render Nodes", {"action": "REMOVE"}, "X"),
    ("rokeby.reflection_map", None, {}, "WORLD"),
    ("rokeby.reflection_map", "Clear Reflection Map", {"action": "CLEAR"}, "X"),
    ("rokeby.update", None, {}, "FILE_REFRESH"),
    ("rokeby.preview_capture", "Capture Scene for Preview", {}, "WORLD"),
    ("rokeby.farm_export", "Export Farm Job…", {}, "NETWORK_DRIVE"),
    None,
    ("rokeby.appearance_setup", "Set Up Appearance Painting", {}, "MATERIAL"),
    ("rokeby.appearance_paint", None, {}, "BRUSH_DATA"),
    ("rokeby.appearance_texture_remove", "Back to Per-Point Attributes", {}, "X"),
    ("rokeby.appearance_remove", "Remove Appearance Painting", {}, "TRASH"),
    ("rokeby.appearance_preview", None, {}, "SHADING_RENDERED"),
    ("rokeby.appearance_render_difference", None, {}, "VIEWZOOM"),
    None,
    ("rokeby.shadow_start", None, {}, "LIGHT"),
    ("rokeby.shadow_drag", None, {}, "MOUSE_LMB_DRAG"),
    ("rokeby.shadow_apply", None, {}, "CHECKMARK"),
    ("rokeby.shadow_stop", None, {}, "X"),
    ("rokeby.shadow_remove", None, {}, "TRASH"),
    None,
    ("rokeby.composite_setup_passes", None, {}, "RENDERLAYERS"),
    ("rokeby.composite_render", None, {}, "RENDER_STILL"),
    ("rokeby.composite_edit", None, {}, "IMAGE"),
    ("rokeby.composite_to_compositor", None, {}, "NODE_COMPOSITING"),
    ("rokeby.composite_brush", None, {}, "BRUSH_DATA"),
    ("rokeby.composite_sequence", None, {}, "SEQUENCE"),
    ("rokeby.farm_export_recomposite", "Export Recompositing Farm Job…", {}, "NETWORK_DRIVE"),
)


class VIEW3D_MT_rokeby(bpy.types.Menu):
    """Every Rokeby operator (greyed out, with the reason in its tooltip, where it cannot run)"""

    bl_idname = "VIEW3D_MT_rokeby"
    bl_label = "Rokeby"

    def draw(self, context):
        layout = self.layout
        layout.operator_context = "INVOKE_REGION_WIN"  # the click-to-place and drag operators run their modal part
        for entry in MENU:
            if entry is None:
                layout.separator()
                continue
            idname, text, props, icon = entry
            if text is not None and text.startswith("enum:"):
                layout.operator_menu_enum(idname, text[5:], icon=icon)
                continue
            op = layout.operator(idname, icon=icon) if text is None else layout.operator(idname, text=text, icon=icon)
            for key, value in props.items():
                setattr(op, key, value)


def draw_menu_entry(self, context):
    """Appended to Object and the object context menu: the Rokeby submenu."""
    self.layout.separator()
    self.layout.menu(VIEW3D_MT_rokeby.bl_idname, icon="MOD_MIRROR")


MENUS_EXTENDED = ("VIEW3D_MT_object", "VIEW3D_MT_object_context_menu")


# The sidebar's mirror panels, parent first (tests draw them in this order).
MIRROR_PANELS = (ROKEBY_PT_main, ROKEBY_PT_constraints, ROKEBY_PT_regions, ROKEBY_PT_settings, ROKEBY_PT_render)
_classes = (ROKEBY_UL_constraints, ROKEBY_UL_regions, *MIRROR_PANELS, VIEW3D_MT_rokeby)


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)
    for name in MENUS_EXTENDED:
        getattr(bpy.types, name).append(draw_menu_entry)


def unregister():
    for name in MENUS_EXTENDED:
        menu = getattr(bpy.types, name, None)
        if menu is not None:
            menu.remove(draw_menu_entry)
    for cls in reversed(_classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
