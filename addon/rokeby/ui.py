"""Sidebar UI (3D View ▸ Rokeby): mirrors, their constraints and regions, settings and status.
Registered by ``rokeby.register``; no ``gpu`` use here."""

from __future__ import annotations

import bpy

from . import api, evaluate, native, viewport

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


class ROKEBY_PT_main(bpy.types.Panel):
    bl_idname = "ROKEBY_PT_main"
    bl_label = "Rokeby"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Rokeby"

    def draw(self, context):
        layout = self.layout
        if not native.available():
            col = layout.column()
            col.alert = True
            col.label(text="Native core missing", icon="ERROR")
            col.label(text="Run `make` in the Rokeby checkout")
            return
        mirrors = [ob for ob in context.scene.objects if ob.rokeby.is_mirror]
        box = layout.box()
        box.label(text=f"Mirrors ({len(mirrors)})", icon="MOD_MIRROR")
        box.prop(context.window_manager, "rokeby_viewport_preview", icon="SHADING_RENDERED")
        if viewport.last_error():
            box.label(text=f"Preview: {viewport.last_error()}"[:120], icon="ERROR")
        for m in mirrors:
            rep = evaluate.report_of(m)
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
            layout.operator("rokeby.update", icon="FILE_REFRESH")
            return
        s = mirror.rokeby
        layout.label(text=f"Mirror: {mirror.name}", icon="OBJECT_DATA")
        rep = evaluate.report_of(mirror)
        if rep is not None:
            col = layout.column(align=True)
            col.alert = rep.status == "ERROR"
            col.label(text=f"{rep.status.title()}: {rep.constraints_used} constraint(s), {rep.vertices:,} vertices", icon=_STATUS_ICON[rep.status])
            for msg in rep.messages[:6]:
                col.label(text=msg)
            if rep.render_note:
                row = col.row()
                row.alert = rep.renders is False
                row.label(text=rep.render_note[:120], icon={True: "RENDER_STILL", False: "ERROR", None: "INFO"}[rep.renders])
            if rep.interpolation_error is not None:
                p99, worst = rep.interpolation_error[:2]
                col.label(text=f"render vs preview: {p99:.2f}° (99th percentile), {worst:.2f}° max", icon="CHECKMARK" if p99 <= evaluate.AGREEMENT_DEGREES else "ERROR")
            if rep.recomputed or rep.python_ms:
                col.label(text=f"last update {rep.python_ms + rep.native_ms:.1f} ms (Python {rep.python_ms:.1f}, Rust {rep.native_ms:.1f})")
        col = layout.column()
        col.prop(s, "enabled")
        col.prop(s, "metric")
        if s.metric == "GEODESIC":
            col.prop(s, "geodesic_method")
        col.prop(s, "polar")
        col.prop(s, "eye_source")
        col.prop(s, "render_edits")
        col.prop(s, "show_preview")
        if viewport.status_of(mirror):
            col.label(text=viewport.status_of(mirror)[:120], icon="INFO")
        row = layout.row(align=True)
        row.prop(s, "freeze", toggle=True, icon="FREEZE")
        row.operator("rokeby.return_to_view", icon="HIDE_OFF")

        layout.label(text="Constraints")
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

        layout.label(text="Regions")
        row = layout.row()
        row.template_list("ROKEBY_UL_regions", "", s, "regions", s, "active_region", rows=2)
        col = row.column(align=True)
        op = col.operator_menu_enum("rokeby.region_add", "kind", icon="ADD", text="")
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
        layout.prop(s, "render_mode")
        if s.render_mode == "REFLECTION_MAP":
            _draw_reflection_map(layout, mirror, context.scene)
        row = layout.row(align=True)
        op = row.operator("rokeby.render_nodes", text="Reinstall Render Nodes", icon="NODE_MATERIAL")
        op.mirror, op.action = mirror.name, "INSTALL"
        op = row.operator("rokeby.render_nodes", text="", icon="X")
        op.mirror, op.action = mirror.name, "REMOVE"
        layout.operator("rokeby.update", icon="FILE_REFRESH")
        layout.operator("rokeby.mirror_remove", icon="TRASH")


def _draw_reflection_map(layout, mirror, scene):
    from . import reflmap  # noqa: PLC0415

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


_classes = (ROKEBY_UL_constraints, ROKEBY_UL_regions, ROKEBY_PT_main)


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(_classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
