"""Operators and a View Layer panel for compositing-stage shape editing (``rokeby.compositing``):
set up the render passes, and render → reconstruct → edit normals → show the recomposited frame
as a new image."""

from __future__ import annotations

import os
import tempfile

import bpy

from . import compositing as comp

EDITS = [
    ("EMBOSS", "Emboss", "n_z → β n_z (amount = β in (0, 1])"),
    ("RIPPLE", "Ripple", "fading 2D ripple decal (amount = strength)"),
    ("SMOOTH", "Smooth", "cross-bilateral smoothing with depth (amount = σ in pixels)"),
    ("NONE", "None", "no edit (material edits k_D, k_R only)"),
]

BACKENDS = [
    ("CPU", "CPU", "eqs. 3–5 in the Rust core"),
    ("GPU", "GPU (Blender)", "eqs. 3–5 by the GLSL shader, drawn through Blender's gpu module"),
]


class ROKEBY_OT_composite_setup_passes(bpy.types.Operator):
    """Enable the render passes and AOVs that compositing-stage shape editing needs"""

    bl_idname = "rokeby.composite_setup_passes"
    bl_label = "Set Up Compositing Passes"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        names = comp.setup_passes(context.scene, context.view_layer)
        self.report({"INFO"}, f"Rokeby: {len(names)} passes enabled on view layer '{context.view_layer.name}'")
        return {"FINISHED"}


class ROKEBY_OT_composite_render(bpy.types.Operator):
    """Render the passes, reconstruct the shading environments, edit the normals and show the
    recomposited frame as a new image"""

    bl_idname = "rokeby.composite_render"
    bl_label = "Render and Recomposite"
    bl_options = {"REGISTER", "UNDO"}

    edit: bpy.props.EnumProperty(name="Edit", items=EDITS, default="EMBOSS")
    amount: bpy.props.FloatProperty(name="Amount", default=0.5, min=0.0)
    k_d: bpy.props.FloatProperty(name="Diffuse k_D", default=1.0, min=0.0)
    k_r: bpy.props.FloatProperty(name="Reflection k_R", default=1.0, min=0.0)
    filepath: bpy.props.StringProperty(name="EXR", default="", subtype="FILE_PATH",
                                       description="Where the multilayer EXR goes (default: a temporary file)")
    image_name: bpy.props.StringProperty(name="Image", default="Rokeby Recomposited")
    backend: bpy.props.EnumProperty(name="Backend", items=BACKENDS, default="CPU")

    def execute(self, context):
        path = bpy.path.abspath(self.filepath) if self.filepath else os.path.join(tempfile.gettempdir(), "rokeby_composite.exr")
        try:
            p = comp.render_passes(context.scene, path)
            rec = comp.reconstruct(p, warn=False)
            n = rec.normals
            on = rec.ids >= 0
            if self.edit == "EMBOSS":
                n = comp.emboss(n, min(max(self.amount, 1e-3), 1.0), mask=on)
            elif self.edit == "RIPPLE":
                n = comp.bump(n, comp.ripple(p.shape), self.amount, mask=on)
            elif self.edit == "SMOOTH":
                n = comp.bilateral_smooth(n, p.depth, sigma_s=max(self.amount, 0.5), mask=on)
            out, stats = comp.recomposite(p, rec, n, k_d=self.k_d, k_r=self.k_r,
                                          backend="blender_gpu" if self.backend == "GPU" else "cpu")
        except (comp.CompositingError, ValueError, RuntimeError) as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        img = comp.show_image(self.image_name, out)
        for msg in rec.warnings():
            self.report({"WARNING"}, f"Rokeby: {msg}")
        self.report({"INFO"}, f"Rokeby: image '{img.name}': {stats['edited']} pixels recomposited")
        return {"FINISHED"}


class ROKEBY_PT_compositing(bpy.types.Panel):
    bl_label = "Rokeby Compositing"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "view_layer"

    def draw(self, context):
        col = self.layout.column()
        col.operator(ROKEBY_OT_composite_setup_passes.bl_idname, icon="RENDERLAYERS")
        col.operator(ROKEBY_OT_composite_render.bl_idname, icon="RENDER_STILL")


CLASSES = (ROKEBY_OT_composite_setup_passes, ROKEBY_OT_composite_render, ROKEBY_PT_compositing)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        if getattr(c, "is_registered", False):
            bpy.utils.unregister_class(c)
