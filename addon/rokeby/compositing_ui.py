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
    ("NOISE", "Noise", "fading procedural noise bump decal (amount = strength)"),
    ("SMOOTH", "Smooth", "cross-bilateral smoothing with depth (amount = σ in pixels)"),
    ("NONE", "None", "no edit (material edits k_D, k_R only)"),
]

FITS = [
    ("QP", "QP", "the paper's fit, D(n) ≥ D0 at every pixel (occlusion-aware; rides a render's noise)"),
    ("QP_TOLERANT", "QP, noise-tolerant", "D(n) ≥ D0 − κσ, σ the diffuse pass's pixel noise (κ: Noise Tolerance)"),
    ("LS", "Least squares", "the fast fit; on noisy renders measured closest to the true environment"),
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


MAX_SMOOTH_SIGMA = 50.0  # rokeby_core::normals::MAX_SIGMA_S: the smoothing's largest σ in pixels
LAST_EXR = "rokeby_composite_exr"  # scene custom property: the EXR the last Render and Recomposite wrote


def _edit_args(op) -> dict:
    """The operator's edit as ``rokeby.api`` takes it, with the knob clamped to what each edit accepts."""
    edit = op.edit.lower()
    amount = {"emboss": min(max(op.amount, 1e-3), 1.0),
              "smooth": min(max(op.amount, 0.5), MAX_SMOOTH_SIGMA)}.get(edit, op.amount)
    return {"edit": edit, "amount": amount, "k_d": op.k_d, "k_r": op.k_r, "image_name": op.image_name,
            "backend": "blender_gpu" if op.backend == "GPU" else "cpu", "fit": "ls" if op.fit == "LS" else "qp",
            "noise_tolerance": op.noise_tolerance if op.fit == "QP_TOLERANT" else 0.0}


class _EditProps:
    edit: bpy.props.EnumProperty(name="Edit", items=EDITS, default="EMBOSS")
    amount: bpy.props.FloatProperty(name="Amount", default=0.5, min=0.0)
    k_d: bpy.props.FloatProperty(name="Diffuse k_D", default=1.0, min=0.0)
    k_r: bpy.props.FloatProperty(name="Reflection k_R", default=1.0, min=0.0)
    image_name: bpy.props.StringProperty(name="Image", default="Rokeby Recomposited")
    backend: bpy.props.EnumProperty(name="Backend", items=BACKENDS, default="CPU")
    fit: bpy.props.EnumProperty(name="Diffuse Fit", items=FITS, default="QP")
    noise_tolerance: bpy.props.FloatProperty(name="Noise Tolerance", default=3.0, min=0.0, soft_max=6.0,
                                             description="κ of the noise-tolerant QP, in standard deviations of the pixel noise")


class ROKEBY_OT_composite_render(_EditProps, bpy.types.Operator):
    """Render the passes, reconstruct the shading environments, edit the normals and show the
    recomposited frame as a new image"""

    bl_idname = "rokeby.composite_render"
    bl_label = "Render and Recomposite"
    bl_options = {"REGISTER", "UNDO"}

    filepath: bpy.props.StringProperty(name="EXR", default="", subtype="FILE_PATH",
                                       description="Where the multilayer EXR goes (default: a temporary file)")

    def execute(self, context):
        from . import api  # noqa: PLC0415

        path = bpy.path.abspath(self.filepath) if self.filepath else os.path.join(tempfile.gettempdir(), "rokeby_composite.exr")
        try:
            img, reports = api.recomposite_render(path, scene=context.scene, warn=False, **_edit_args(self))
        except (comp.CompositingError, api.RokebyError, ValueError, RuntimeError) as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        context.scene[LAST_EXR] = path
        for msg in comp.Reconstruction.warnings_of(reports):
            self.report({"WARNING"}, f"Rokeby: {msg}")
        self.report({"INFO"}, f"Rokeby: image '{img.name}' recomposited; edit it again without rendering: "
                              "Recomposite Render")
        return {"FINISHED"}


class ROKEBY_OT_composite_edit(_EditProps, bpy.types.Operator):
    """Edit the normals of the frame already rendered (the last Render and Recomposite, or an EXR)
    and show it recomposited, without rendering again: adjust the edit in the redo panel"""

    bl_idname = "rokeby.composite_edit"
    bl_label = "Recomposite Render"
    bl_options = {"REGISTER", "UNDO"}

    filepath: bpy.props.StringProperty(name="EXR", default="", subtype="FILE_PATH",
                                       description="A multilayer EXR rendered with the compositing passes "
                                                   "(default: the last Render and Recomposite of this scene)")

    def execute(self, context):
        from . import api  # noqa: PLC0415

        path = bpy.path.abspath(self.filepath) if self.filepath else context.scene.get(LAST_EXR, "")
        if not path:
            self.report({"ERROR"}, "Rokeby: no rendered frame to edit: run Render and Recomposite first, or pick an EXR")
            return {"CANCELLED"}
        try:
            img, stats = api.recomposite_exr(path, warn=False, **_edit_args(self))
        except (comp.CompositingError, api.RokebyError, ValueError, RuntimeError) as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        for msg in stats["warnings"]:
            self.report({"WARNING"}, f"Rokeby: {msg}")
        ms = 1e3 * (stats["edit_s"] + stats["recomposite_s"] + stats["show_s"])
        self.report({"INFO"}, f"Rokeby: image '{img.name}': {stats['edited']} pixels recomposited in {ms:.0f} ms"
                              + ("" if stats["reused"] else f" (reading and reconstructing the frame: {stats['open_s']:.1f} s)"))
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
        col.operator(ROKEBY_OT_composite_edit.bl_idname, icon="IMAGE")


CLASSES = (ROKEBY_OT_composite_setup_passes, ROKEBY_OT_composite_render, ROKEBY_OT_composite_edit, ROKEBY_PT_compositing)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        if getattr(c, "is_registered", False):
            bpy.utils.unregister_class(c)
