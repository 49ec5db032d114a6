"""Operators and a View Layer panel for compositing-stage shape editing (``rokeby.compositing``):
set up the render passes (reporting every render setting that changes), render → reconstruct →
edit normals → show the recomposited frame as a new image, and recomposite a whole EXR sequence
with one edit (the entry point for a user who installed only the extension: no checkout, no
``python -m rokeby.composite``; in background mode ``blender -b --python-expr``, see
docs/compositing.md)."""

from __future__ import annotations

import os
import tempfile

import bpy
import numpy as np

from .. import compositing as comp
from ..blender import prefs
from ..blender.progress import Progress
from ..core import schema
from ..core.errors import RokebyError

# What an operator reports when Esc / Ctrl-C / rokeby.core.native.cancel() stopped it (nothing changed).
CANCELLED = "Rokeby: Cancelled (nothing was changed)"

EDITS = [
    ("EMBOSS", "Emboss", "n_z → β n_z (amount = β in (0, 1])", 0),
    ("RIPPLE", "Ripple", "fading 2D ripple decal (amount = strength)", 1),
    ("NOISE", "Noise", "fading procedural noise bump decal (amount = strength)", 2),
    ("SMOOTH", "Smooth", "cross-bilateral smoothing with depth (amount = σ in pixels)", 3),
    ("NONE", "None", "no edit (material edits k_D, k_R only)", 4),
]

FITS = [
    ("QP", "QP", "the paper's fit, D(n) ≥ D0 at every pixel (occlusion-aware; rides a render's noise)", 0),
    ("QP_TOLERANT", "QP, noise-tolerant", "D(n) ≥ D0 − κσ, σ the diffuse pass's pixel noise (κ: Noise Tolerance)", 1),
    ("LS", "Least squares", "the fast fit; on noisy renders measured closest to the true environment", 2),
]

BACKENDS = [
    ("CPU", "CPU", "eqs. 3–5 in the Rust core", 0),
    ("GPU", "GPU (Blender)", "eqs. 3–5 by the GLSL shader, drawn through Blender's gpu module", 1),
]


def _fail(cls, message: str) -> bool:
    cls.poll_message_set(message)
    return False


def _settings_snapshot(scene, view_layer) -> dict:
    """The render settings Set Up Compositing Passes may change, as (label, value) by key."""
    st = scene.render.image_settings
    out = {}
    rna = st.bl_rna.properties["file_format"]
    out[("output", "file_format")] = next((item.name for item in rna.enum_items if item.identifier == st.file_format), st.file_format)
    out[("output", "color_depth")] = f"{st.color_depth}-bit"
    for prop in view_layer.bl_rna.properties:
        if prop.identifier.startswith("use_pass_"):
            out[("pass", prop.name)] = bool(getattr(view_layer, prop.identifier))
    out[("aovs",)] = tuple(a.name for a in view_layer.aovs)
    out[("object indices",)] = {o.name: o.pass_index for o in scene.objects if o.type == "MESH"}
    out[("material indices",)] = {m.name: (m.pass_index, m.use_nodes, len(m.node_tree.nodes) if m.node_tree else 0) for m in bpy.data.materials}
    return out


def describe_changes(before: dict, after: dict) -> list[str]:
    """Sentences naming each render setting that differs between two ``_settings_snapshot``s."""
    lines = []
    names = {"file_format": "Output file format", "color_depth": "Output colour depth"}
    for key in (("output", "file_format"), ("output", "color_depth")):
        if before[key] != after[key]:
            lines.append(f"{names[key[1]]} switched to {after[key]} (was {before[key]})")
    enabled = [key[1] for key in after if key[0] == "pass" and after[key] and not before.get(key)]
    if enabled:
        lines.append(f"Passes enabled on view layer: {', '.join(enabled)}")
    added = [a for a in after[("aovs",)] if a not in before[("aovs",)]]
    if added:
        lines.append(f"Shader AOVs added: {', '.join(added)}")
    obs = [n for n, i in after[("object indices",)].items() if before[("object indices",)].get(n) != i]
    if obs:
        lines.append(f"Pass index given to {len(obs)} object(s): {', '.join(obs[:6])}{' …' if len(obs) > 6 else ''}")
    mats = [n for n, v in after[("material indices",)].items() if before[("material indices",)].get(n) != v]
    if mats:
        lines.append(f"Material pass index and AOV output nodes set in {len(mats)} material(s): {', '.join(mats[:6])}{' …' if len(mats) > 6 else ''}")
    return lines


class ROKEBY_OT_composite_setup_passes(bpy.types.Operator):
    """Enable the render passes and AOVs that compositing-stage shape editing needs"""

    bl_idname = "rokeby.composite_setup_passes"
    bl_label = "Set Up Passes"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if context.scene is None or context.view_layer is None:
            return _fail(cls, "Needs a scene and a view layer to set the passes up on")
        return True

    def execute(self, context):
        before = _settings_snapshot(context.scene, context.view_layer)
        comp.setup_passes(context.scene, context.view_layer)
        changes = describe_changes(before, _settings_snapshot(context.scene, context.view_layer))
        for line in changes:  # every change in the Info log (Ctrl+Z undoes them all)
            self.report({"INFO"}, f"Rokeby: {line}")
        if changes:
            self.report({"INFO"}, f"Rokeby: {len(changes)} render setting change(s) on '{context.view_layer.name}' "
                                  "(listed in the Info editor; Ctrl+Z undoes them)")
        else:
            self.report({"INFO"}, f"Rokeby: the passes of '{context.view_layer.name}' were already set up; nothing changed")
        return {"FINISHED"}


MAX_SMOOTH_SIGMA = 50.0  # rokeby_core::compositing::normals::MAX_SIGMA_S: the smoothing's largest σ in pixels


def _edit_args(op, context=None) -> dict:
    """The operator's edit as ``rokeby.api`` takes it, with the knob clamped to what each edit
    accepts; the backend is the add-on preferences' default unless the operator was given one."""
    edit = op.edit.lower()
    amount = {"emboss": min(max(op.amount, 1e-3), 1.0),
              "smooth": min(max(op.amount, 0.5), MAX_SMOOTH_SIGMA)}.get(edit, op.amount)
    backend = op.backend if op.properties.is_property_set("backend") else prefs.get(context).compositing_backend
    return {"edit": edit, "amount": amount, "k_d": op.k_d, "k_r": op.k_r, "image_name": op.image_name,
            "backend": "blender_gpu" if backend == "GPU" else "cpu", "fit": "ls" if op.fit == "LS" else "qp",
            "noise_tolerance": op.noise_tolerance if op.fit == "QP_TOLERANT" else 0.0}


class _EditProps:
    edit: bpy.props.EnumProperty(name="Edit", items=EDITS, default="EMBOSS")
    amount: bpy.props.FloatProperty(name="Amount", default=0.5, min=0.0)
    k_d: bpy.props.FloatProperty(name="Diffuse k_D", default=1.0, min=0.0)
    k_r: bpy.props.FloatProperty(name="Reflection k_R", default=1.0, min=0.0)
    image_name: bpy.props.StringProperty(name="Image", default=schema.RECOMPOSITED_IMAGE)
    backend: bpy.props.EnumProperty(name="Backend", items=BACKENDS, default="CPU",
                                    description="Where eqs. 3–5 run (default: the add-on preferences' Default Compositing Backend)")
    fit: bpy.props.EnumProperty(name="Diffuse Fit", items=FITS, default="QP")
    noise_tolerance: bpy.props.FloatProperty(name="Noise Tolerance", default=3.0, min=0.0, soft_max=6.0,
                                             description="κ of the noise-tolerant QP, in standard deviations of the pixel noise")


class ROKEBY_OT_composite_render(_EditProps, bpy.types.Operator):
    """Render the passes, reconstruct the shading environments, edit the normals and show the
    recomposited frame as a new image"""

    bl_idname = "rokeby.composite_render"
    bl_label = "Render & Edit"
    bl_options = {"REGISTER", "UNDO"}

    filepath: bpy.props.StringProperty(name="EXR", default="", subtype="FILE_PATH",
                                       description="Where the multilayer EXR goes (default: a temporary file)")

    @classmethod
    def poll(cls, context):
        if context.scene is None or context.scene.camera is None:
            return _fail(cls, "The scene has no camera: Render and Recomposite renders from the scene camera")
        return True

    def execute(self, context):
        from . import api  # noqa: PLC0415

        path = bpy.path.abspath(self.filepath) if self.filepath else os.path.join(tempfile.gettempdir(), "rokeby_composite.exr")
        try:
            with Progress(context, 1) as progress:  # render, reconstruct, recomposite: seconds
                img, reports = api.recomposite_render(path, scene=context.scene, warn=False, **_edit_args(self, context))
                progress.step()
        except KeyboardInterrupt:
            self.report({"WARNING"}, CANCELLED)
            return {"CANCELLED"}
        except (comp.CompositingError, RokebyError, ValueError, RuntimeError) as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        context.scene[schema.COMPOSITE_LAST_EXR_KEY] = path
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

    @classmethod
    def poll(cls, context):
        if context.scene is None:
            return _fail(cls, "Needs a scene")
        return True

    def invoke(self, context, event):
        if not self.filepath and not context.scene.get(schema.COMPOSITE_LAST_EXR_KEY, ""):  # nothing rendered yet: pick an EXR
            context.window_manager.fileselect_add(self)
            return {"RUNNING_MODAL"}
        return self._start(context)

    def _path(self, context) -> str:
        return bpy.path.abspath(self.filepath) if self.filepath else context.scene.get(schema.COMPOSITE_LAST_EXR_KEY, "")

    def _start(self, context):
        """With a window and the CPU backend: read, reconstruct and recomposite on a worker thread
        while the operator waits modally, so that Esc stops it (rokeby.core.native.cancel()); the image
        is made on the main thread once the pixels are there. Otherwise: ``execute``."""
        import threading  # noqa: PLC0415

        from . import api  # noqa: PLC0415

        args = _edit_args(self, context)
        path = self._path(context)
        if not path or args["backend"] != "cpu" or context.window is None or bpy.app.background:
            return self.execute(context)
        image_name = args.pop("image_name")
        self._result = {}

        def work():
            try:
                self._result["ok"] = api.recomposite_exr_pixels(path, warn=False, **args)
            except BaseException as exc:  # noqa: BLE001 - handed to the main thread
                self._result["error"] = exc

        self._image_name = image_name
        self._args = args
        self._thread = threading.Thread(target=work, name="rokeby recomposite", daemon=True)
        self._thread.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        context.workspace.status_text_set("Rokeby: recompositing… (Esc: cancel)")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        from ..core import native  # noqa: PLC0415

        from . import api  # noqa: PLC0415

        if event.type == "ESC":
            native.cancel()  # the worker's native call stops at its next row
        if self._thread.is_alive():
            return {"RUNNING_MODAL"} if event.type == "ESC" else {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        context.workspace.status_text_set(None)
        exc = self._result.get("error")
        if exc is not None:
            return self._failed(exc)
        out, stats = self._result["ok"]
        img = comp.show_image(self._image_name, out)
        a = self._args
        api.record_edit(img, self._path(context), a["edit"], a["amount"], a["k_d"], a["k_r"], a["fit"], a["noise_tolerance"])
        return self._done(img, stats)

    def _failed(self, exc):
        if isinstance(exc, KeyboardInterrupt):
            self.report({"WARNING"}, CANCELLED)
            return {"CANCELLED"}
        if isinstance(exc, (comp.CompositingError, RokebyError, ValueError, RuntimeError, MemoryError)):
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        raise exc

    def execute(self, context):
        from . import api  # noqa: PLC0415

        path = self._path(context)
        if not path:
            self.report({"ERROR"}, "Rokeby: no rendered frame to edit: click Render and Recomposite first, or pick an EXR")
            return {"CANCELLED"}
        try:
            with Progress(context, 1) as progress:  # the first edit of a frame reads and reconstructs it
                img, stats = api.recomposite_exr(path, warn=False, **_edit_args(self, context))
                progress.step()
        except (KeyboardInterrupt, comp.CompositingError, RokebyError, ValueError, RuntimeError, MemoryError) as exc:
            return self._failed(exc)
        return self._done(img, stats)

    def _done(self, img, stats):
        for msg in stats["warnings"]:
            self.report({"WARNING"}, f"Rokeby: {msg}")
        ms = 1e3 * (stats["edit_s"] + stats["recomposite_s"] + stats["show_s"])
        self.report({"INFO"}, f"Rokeby: image '{img.name}': {stats['edited']} pixels recomposited in {ms:.0f} ms"
                              + ("" if stats["reused"] else f" (reading and reconstructing the frame: {stats['open_s']:.1f} s)"))
        return {"FINISHED"}


def sequence_frames(directory: str, pattern: str = "*.exr") -> list[str]:
    """:func:`rokeby.compositing.sequence_frames` of a Blender path ('//' relative to the .blend)."""
    return comp.sequence_frames(bpy.path.abspath(directory) if directory else directory, pattern)


def _image_rgb(img) -> np.ndarray:
    """(H, W, 3) float32 of a Blender float image, top row first (as ``compositing.write_exr`` takes it)."""
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1, :, :3]


class ROKEBY_OT_composite_sequence(_EditProps, bpy.types.Operator):
    """Recomposite every frame of an EXR sequence (rendered with the compositing passes) with the
    same edit and write each to the output folder. Frames whose output exists are skipped, so a
    run that stopped (a bad frame, a crash) resumes where it left off"""

    bl_idname = "rokeby.composite_sequence"
    bl_label = "Recomposite EXRs"
    bl_options = {"REGISTER"}

    directory: bpy.props.StringProperty(name="Folder", subtype="DIR_PATH",
                                        description="Folder of multilayer EXR frames rendered with the compositing passes")
    pattern: bpy.props.StringProperty(name="Frames", default="*.exr",
                                      description="Which files of the folder are frames: a glob (*.exr) or '#' per frame digit (shot_####.exr)")
    output_directory: bpy.props.StringProperty(name="Output Folder", subtype="DIR_PATH", default="",
                                               description="Where the recomposited frames go, under the input's file names "
                                                           "(default: a 'recomposited' folder inside the input folder)")
    skip_existing: bpy.props.BoolProperty(name="Skip Frames Done", default=True,
                                          description="Keep frames already written to the output folder (resume a stopped run)")
    filter_glob: bpy.props.StringProperty(default="*.exr", options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        if context.scene is None:
            return _fail(cls, "Needs a scene")
        return True

    def invoke(self, context, event):
        if not self.directory:
            context.window_manager.fileselect_add(self)  # pick the folder of frames
            return {"RUNNING_MODAL"}
        return self.execute(context)

    def execute(self, context):
        from . import api  # noqa: PLC0415

        try:
            frames = sequence_frames(self.directory, self.pattern)
        except comp.CompositingError as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        if not frames:
            self.report({"ERROR"}, f"Rokeby: no frames matching '{self.pattern}' in {self.directory}")
            return {"CANCELLED"}
        src = os.path.dirname(frames[0])
        out_dir = bpy.path.abspath(self.output_directory) if self.output_directory else os.path.join(src, "recomposited")
        if os.path.realpath(out_dir) == os.path.realpath(src):
            self.report({"ERROR"}, "Rokeby: the Output Folder must differ from the input folder (the frames would be overwritten)")
            return {"CANCELLED"}
        args = _edit_args(self, context)
        os.makedirs(out_dir, exist_ok=True)
        done, skipped, failed = [], [], []
        with Progress(context, len(frames)) as progress:
            for path in frames:
                out = os.path.join(out_dir, os.path.basename(path))
                if self.skip_existing and os.path.exists(out):
                    skipped.append(path)
                    progress.step()
                    continue
                try:
                    img, _stats = api.recomposite_exr(path, warn=False, **args)
                except KeyboardInterrupt:  # Ctrl-C / a cancel: the frames done stay, the rest is left
                    comp.close_render()
                    self.report({"WARNING"}, f"Rokeby: Cancelled after {len(done)} frame(s) recomposited into {out_dir} "
                                             "(the frame in progress was not written)")
                    return {"FINISHED"} if done else {"CANCELLED"}
                except (comp.CompositingError, RokebyError, ValueError, RuntimeError, OSError) as exc:
                    failed.append(f"{os.path.basename(path)}: {exc}")
                    progress.step()
                    continue
                try:
                    partial = out + ".partial.exr"  # written whole, then renamed: a crash leaves no half frame
                    comp.write_exr(partial, _image_rgb(img))
                    os.replace(partial, out)
                    done.append(path)
                except (comp.CompositingError, RokebyError, ValueError, RuntimeError, OSError) as exc:
                    failed.append(f"{os.path.basename(path)}: {exc}")
                finally:
                    if os.path.exists(partial):
                        os.remove(partial)
                progress.step()
        comp.close_render()  # the last frame's passes: let go of their memory
        summary = (f"Rokeby: {len(done)} frame(s) recomposited into {out_dir}"
                   + (f", {len(skipped)} already done (skipped)" if skipped else ""))
        if failed:
            self.report({"ERROR"}, f"{summary}; {len(failed)} failed (run again to retry them, frames done are skipped): "
                                   + "; ".join(failed[:3]) + (" …" if len(failed) > 3 else ""))
            return {"FINISHED"} if done else {"CANCELLED"}
        self.report({"INFO"}, summary)
        return {"FINISHED"}


class ROKEBY_OT_composite_to_compositor(bpy.types.Operator):
    """Feed the recomposited image into the scene's compositor (an Image node that every later
    recomposite keeps current, shown in the backdrop through a Viewer), to chain it with other
    compositor nodes"""

    bl_idname = "rokeby.composite_to_compositor"
    bl_label = "Use in Compositor"
    bl_options = {"REGISTER", "UNDO"}

    image_name: bpy.props.StringProperty(name="Image", default=schema.RECOMPOSITED_IMAGE)

    @classmethod
    def poll(cls, context):
        if context.scene is None:
            return _fail(cls, "Needs a scene")
        return True

    def execute(self, context):
        from . import api  # noqa: PLC0415

        try:
            node = api.use_in_compositor(self.image_name, scene=context.scene)
        except (comp.CompositingError, ValueError) as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Rokeby: the compositor's node '{node.name}' reads '{self.image_name}' and follows every recomposite of it")
        return {"FINISHED"}


class ROKEBY_PT_compositing(bpy.types.Panel):
    bl_label = "Rokeby Compositing"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "view_layer"

    def draw(self, context):
        col = self.layout.column()
        col.operator(ROKEBY_OT_composite_setup_passes.bl_idname, text="Set Up Compositing Passes", icon="RENDERLAYERS")
        col.operator(ROKEBY_OT_composite_render.bl_idname, text="Render and Recomposite", icon="RENDER_STILL")
        col.operator(ROKEBY_OT_composite_edit.bl_idname, icon="IMAGE")
        col.operator(ROKEBY_OT_composite_to_compositor.bl_idname, icon="NODE_COMPOSITING")
        col.separator()
        col.operator(ROKEBY_OT_composite_sequence.bl_idname, text="Recomposite EXR Sequence", icon="SEQUENCE")
        col.operator("rokeby.farm_export_recomposite", text="Export Recompositing Farm Job…", icon="NETWORK_DRIVE")


CLASSES = (ROKEBY_OT_composite_setup_passes, ROKEBY_OT_composite_render, ROKEBY_OT_composite_edit,
           ROKEBY_OT_composite_sequence, ROKEBY_OT_composite_to_compositor, ROKEBY_PT_compositing)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        if getattr(c, "is_registered", False):
            bpy.utils.unregister_class(c)
