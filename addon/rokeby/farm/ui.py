"""*Export Farm Job…* (Render sub-panel of a mirror, and the Rokeby menu): writes a job bundle for the
saved file with the scene's frame range filled in, through ``rokeby.farm.api`` (docs/farm.md)."""

from __future__ import annotations

import bpy

from ..core.errors import RokebyError
from . import api


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
    zip_path: bpy.props.StringProperty(name="Extension Zip", subtype="FILE_PATH",
                                       description="The Rokeby extension zip to send with the job (empty: the installed add-on, packed)")

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
                                          zip_path=bpy.path.abspath(self.zip_path) if self.zip_path else None)
        except (RokebyError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if bpy.data.is_dirty:
            self.report({"WARNING"}, f"Farm job written to {bundle}; it renders the file as saved: save to include the unsaved changes")
        else:
            self.report({"INFO"}, f"Farm job written to {bundle} (docs/farm.md: openjd run, deadline bundle submit)")
        return {"FINISHED"}


CLASSES = (ROKEBY_OT_farm_export,)


def register():
    for cls in CLASSES:
        if not cls.is_registered:
            bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        if cls.is_registered:  # a second unregister (disabling, then unregistering) does nothing
            bpy.utils.unregister_class(cls)
