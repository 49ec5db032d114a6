"""The farm operators, both thin over ``rokeby.farm.api`` (docs/farm.md):

- *Export Farm Job…* (a mirror's Render sub-panel, the Rokeby menu): a job bundle that renders the
  saved file, the scene's frame range filled in;
- *Export Recompositing Farm Job…* (View Layer ▸ Rokeby Compositing, the Rokeby menu): a job bundle
  that recomposites a folder of multilayer EXR frames, filled in from the recomposited image: the
  one-knob edit it shows, and the folder and frame pattern of the EXR it was made from.
"""

from __future__ import annotations

import os
import re

import bpy

from .. import compositing
from ..core import schema
from ..core.errors import RokebyError
from . import api, marker

ZIP_DESCRIPTION = ("The Rokeby extension zip to send with the job (empty: built from the add-on's checkout as `make dist` "
                   "builds it, or the installed add-on packed as installed)")


class ROKEBY_OT_farm_export(bpy.types.Operator):
    """Write an Open Job Description job bundle that renders this saved file's frames on a render farm
    (openjd run, Deadline Cloud), with the Rokeby extension travelling in the job"""

    bl_idname = "rokeby.farm_export"
    bl_label = "Export Farm Job"
    bl_options = {"REGISTER"}

    directory: bpy.props.StringProperty(name="Bundle Folder", subtype="DIR_PATH")
    frame_start: bpy.props.IntProperty(name="First Frame")
    frame_end: bpy.props.IntProperty(name="Last Frame")
    chunk: bpy.props.IntProperty(name="Frames per Task", default=1, min=1)
    zip_path: bpy.props.StringProperty(name="Extension Zip", subtype="FILE_PATH", description=ZIP_DESCRIPTION)

    @classmethod
    def poll(cls, context):
        if not bpy.data.filepath:
            cls.poll_message_set("Save the file first: a farm renders the saved .blend")
            return False
        return True

    def invoke(self, context, event):
        sc = context.scene
        self.frame_start, self.frame_end = sc.frame_start, sc.frame_end
        if not self.directory:
            self.directory = bpy.path.abspath("//farm_job")
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        try:
            bundle = api.write_render_job(bpy.data.filepath, bpy.path.abspath(self.directory),
                                          frames=(self.frame_start, self.frame_end), chunk=self.chunk,
                                          zip_path=bpy.path.abspath(self.zip_path) if self.zip_path else None,
                                          saved_with=marker.saved_with(context.scene))
        except (RokebyError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if bpy.data.is_dirty:
            self.report({"WARNING"}, f"Farm job written to {bundle}; it renders the file as saved: save to include the unsaved changes")
        else:
            self.report({"INFO"}, f"Farm job written to {bundle} (docs/farm.md: openjd run, deadline bundle submit)")
        return {"FINISHED"}


EDIT_ITEMS = [(e.upper(), e.capitalize(), f"the one-knob '{e}' edit, as Recomposite Render applies it", i)
              for i, e in enumerate(compositing.EDITS)]
FIT_ITEMS = [("QP", "QP", "the paper's fit (with Noise Tolerance above 0: the noise-tolerant QP)", 0),
             ("LS", "Least squares", "the fast fit", 1)]


def frame_pattern(filename: str) -> str:
    """A sequence's ``--pattern`` from one frame's file name: its last run of digits as '#'s
    (``shot_0007.exr`` → ``shot_####.exr``); ``*.exr`` when the name has no digits."""
    m = list(re.finditer(r"\d+", filename))
    if not m:
        return "*.exr"
    last = m[-1]
    return filename[: last.start()] + "#" * len(last.group()) + filename[last.end():]


class ROKEBY_OT_farm_export_recomposite(bpy.types.Operator):
    """Write an Open Job Description job bundle that recomposites a folder of multilayer EXR frames
    with one edit on a render farm (python -m rokeby.composite frame by frame), filled in from the
    recomposited image's edit"""

    bl_idname = "rokeby.farm_export_recomposite"
    bl_label = "Export EXR Farm Job"
    bl_options = {"REGISTER"}

    directory: bpy.props.StringProperty(name="Bundle Folder", subtype="DIR_PATH")
    input_directory: bpy.props.StringProperty(name="Frames Folder", subtype="DIR_PATH",
                                              description="The folder of multilayer EXR frames rendered with the compositing passes")
    pattern: bpy.props.StringProperty(name="Frames", default="*.exr",
                                      description="Which files of the folder are frames: a glob (*.exr) or '#' per frame digit (shot_####.exr)")
    output_directory: bpy.props.StringProperty(name="Output Folder", subtype="DIR_PATH",
                                               description="Where the recomposited frames go (default: 'recomposited' inside the frames folder)")
    image_name: bpy.props.StringProperty(name="Image", default=schema.RECOMPOSITED_IMAGE,
                                         description="The recomposited image whose edit and source frames fill this in")
    edit: bpy.props.EnumProperty(name="Edit", items=EDIT_ITEMS, default="EMBOSS")
    amount: bpy.props.FloatProperty(name="Amount", default=0.5, min=0.0)
    k_d: bpy.props.FloatProperty(name="Diffuse k_D", default=1.0, min=0.0)
    k_r: bpy.props.FloatProperty(name="Reflection k_R", default=1.0, min=0.0)
    fit: bpy.props.EnumProperty(name="Diffuse Fit", items=FIT_ITEMS, default="QP")
    noise_tolerance: bpy.props.FloatProperty(name="Noise Tolerance", default=0.0, min=0.0, soft_max=6.0)
    chunk: bpy.props.IntProperty(name="Frames per Task", default=1, min=1)
    zip_path: bpy.props.StringProperty(name="Extension Zip", subtype="FILE_PATH", description=ZIP_DESCRIPTION)

    @classmethod
    def poll(cls, context):
        if context.scene is None:
            cls.poll_message_set("Needs a scene")
            return False
        return True

    def fill_from_image(self) -> bool:
        """Sets what the caller left unset from the recomposited image: the one-knob edit it shows
        (Render and Recomposite, Recomposite Render record it) and the folder and frame pattern of
        the EXR it was made from. False when the image records no edit."""
        img = bpy.data.images.get(self.image_name)
        base = img.get(schema.BRUSH_BASE_KEY) if img is not None else None
        if base is None:
            return False
        base = base.to_dict() if hasattr(base, "to_dict") else dict(base)
        recorded = {"edit": str(base.get("edit", "emboss")).upper(), "amount": float(base.get("amount", 0.5)),
                    "k_d": float(base.get("k_d", 1.0)), "k_r": float(base.get("k_r", 1.0)),
                    "fit": "LS" if base.get("fit") == "ls" else "QP", "noise_tolerance": float(base.get("noise_tolerance", 0.0))}
        source = str(img.get(schema.BRUSH_SOURCE_KEY, ""))
        if source:
            recorded.update(input_directory=os.path.dirname(source), pattern=frame_pattern(os.path.basename(source)))
        for name, value in recorded.items():
            if not self.properties.is_property_set(name):
                setattr(self, name, value)
        return True

    def invoke(self, context, event):
        self.fill_from_image()
        if not self.directory:
            self.directory = bpy.path.abspath("//farm_recomposite_job") if bpy.data.filepath else ""
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        self.fill_from_image()
        if not self.input_directory:
            self.report({"ERROR"}, "Choose the Frames Folder: the multilayer EXR frames to recomposite")
            return {"CANCELLED"}
        src = bpy.path.abspath(self.input_directory)
        out = bpy.path.abspath(self.output_directory) if self.output_directory else os.path.join(src, "recomposited")
        try:
            options = compositing.one_knob_options(self.edit.lower(), self.amount, k_d=self.k_d, k_r=self.k_r,
                                                   fit=self.fit.lower(), noise_tolerance=self.noise_tolerance)
            bundle = api.write_recomposite_job(src, out, bpy.path.abspath(self.directory), pattern=self.pattern,
                                               edit_options=options, chunk=self.chunk,
                                               zip_path=bpy.path.abspath(self.zip_path) if self.zip_path else None)
        except (RokebyError, compositing.CompositingError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        img = bpy.data.images.get(self.image_name)
        strokes = img.get(schema.BRUSH_STROKES_KEY) if img is not None else None
        if strokes:
            self.report({"WARNING"}, f"Recompositing farm job written to {bundle}; the {len(strokes)} brush stroke(s) on "
                                     f"'{img.name}' are not in it (the job applies the one-knob edit to every frame)")
        else:
            self.report({"INFO"}, f"Recompositing farm job written to {bundle} (docs/farm.md: openjd run, deadline bundle submit)")
        return {"FINISHED"}


CLASSES = (ROKEBY_OT_farm_export, ROKEBY_OT_farm_export_recomposite)


def register():
    for cls in CLASSES:
        if not cls.is_registered:
            bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        if cls.is_registered:  # a second unregister (disabling, then unregistering) does nothing
            bpy.utils.unregister_class(cls)
