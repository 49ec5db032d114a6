"""Blender UI of the normal brush (``rokeby.compositing.brush``): *Paint Normals* paints
emboss, bump or smooth strokes on the recomposited frame shown in an Image Editor, and the
result (the image, and the compositor's Image node reading it) updates at every mouse step.

Modal: left drag paints one stroke (one undo step, pushed when the button is released); Esc or
right mouse pressed during a stroke cancels that stroke (its release does nothing more), and
pressed when no stroke is in progress ends the brush; between strokes other events (zoom, pan,
clicks outside the image's region) pass through and Ctrl+Z / Ctrl+Shift+Z undo and redo this
brush's strokes only (refused where they would reach a step from before the brush); during a
stroke everything else is held. A circle of the brush radius follows the mouse (a
POST_PIXEL handler of the Image Editor, added and removed by the operator: ``gpu`` is touched
only there). Exec (scripts): one stroke given as (row, col) pixels. The settings are the
operator's (remembered between uses; shown in the Image Editor's sidebar, Rokeby tab)."""

from __future__ import annotations

import bpy
from bpy.props import CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty, StringProperty

from .. import compositing as comp
from ..blender import compat, hooks
from ..blender.modal import undo_key
from ..core import schema
from . import brush

# Explicit item numbers: the operator's remembered settings store the number.
MODES = [
    ("EMBOSS", "Emboss", "Bulge the surface under the stroke (n_z → β n_z, blended by strength and falloff)", 0),
    ("BUMP", "Bump", "Raise a ridge along the stroke (a bump of height strength × radius / 2)", 1),
    ("SMOOTH", "Smooth", "Smooth the normals under the stroke (cross-bilateral with depth, σ = radius / 4 up to 4 pixels)", 2),
]
UNDO_MESSAGE = "Rokeby: Normal Brush Stroke"


def _fail(cls, message: str) -> bool:
    cls.poll_message_set(message)
    return False


def _editor_image(context):
    space = getattr(context, "space_data", None)
    if space is not None and space.type == "IMAGE_EDITOR":
        return space.image
    return None


def _source(context, image_name: str, filepath: str = "") -> str:
    """The EXR the brush edits: the operator's, the one the image was painted from, or the
    scene's last Render and Recomposite."""
    if filepath:
        return bpy.path.abspath(filepath)
    img = bpy.data.images.get(image_name) if image_name else None
    if img is not None and img.get(schema.BRUSH_SOURCE_KEY):
        return img[schema.BRUSH_SOURCE_KEY]
    sc = getattr(context, "scene", None)
    return sc.get(schema.COMPOSITE_LAST_EXR_KEY, "") if sc is not None else ""


class RokebyBrushPoint(bpy.types.PropertyGroup):
    pixel: FloatVectorProperty(name="Pixel", size=2, description="(row, column) of the image, row 0 at the top")


class StrokeDriver:
    """The brush's modal logic, apart from Blender's event loop: ``handle(event)`` takes an event
    (``type``, ``value``, ``mouse_x``/``_y``: window coordinates) and returns the operator's modal
    result. ``to_pixel(x, y)`` maps window coordinates to (row, col) pixels (through the Image
    Editor's main region, whichever region the button was in); ``redraw()`` after each
    change of the image. Each step writes the image (``brush.show_step``); a stroke
    that reached the image ends with its record on the image and one undo step."""

    def __init__(self, session, radius: float, strength: float, mode: str, to_pixel, redraw=lambda: None,
                 inside=lambda x, y: True, context=None):
        brush.check_brush(radius, strength, mode)
        self.session, self.radius, self.strength, self.mode = session, radius, strength, mode
        self.to_pixel, self.redraw, self.inside, self.context = to_pixel, redraw, inside, context
        self.error = None
        self.refused = None  # what the last refused undo key was refused for (the operator reports it)
        self.strokes = 0  # strokes ended (undo steps pushed) and not undone
        self.undone = 0  # strokes of this brush undone (redo may bring them back)

    def _pixel(self, event):
        return self.to_pixel(event.mouse_x, event.mouse_y)

    def _show(self):
        brush.show_step(self.session)
        self.redraw()

    def handle(self, event) -> set:
        s = self.session
        t, v = event.type, event.value
        key = undo_key(event, self.context)
        self.refused = None
        if key is not None and not s.painting:
            if key == "UNDO" and self.strokes > 0:
                self.strokes, self.undone = self.strokes - 1, self.undone + 1
                return {"PASS_THROUGH"}  # Blender's undo takes back this brush's last stroke
            if key == "REDO" and self.undone > 0:
                self.strokes, self.undone = self.strokes + 1, self.undone - 1
                return {"PASS_THROUGH"}
            self.refused = ("no stroke of this brush to redo" if key == "REDO" else
                            "no stroke of this brush to undo (finish the brush with Esc / right mouse first)")
            return {"RUNNING_MODAL"}  # refused: it would reach a step from before the brush
        if t in ("ESC", "RIGHTMOUSE"):
            if v != "PRESS":
                return {"RUNNING_MODAL"}  # the release of the key that cancelled a stroke ends nothing
            if s.painting:  # this stroke only: the brush stays on
                s.cancel()
                self._show()
                return {"RUNNING_MODAL"}
            return {"FINISHED"}
        if t == "LEFTMOUSE" and v == "PRESS" and not s.painting:
            if not self.inside(event.mouse_x, event.mouse_y):
                return {"PASS_THROUGH"}  # a click in the sidebar, a header, another editor: theirs
            s.begin(self.radius, self.strength, self.mode)
            return self._step(event)
        if t == "LEFTMOUSE" and v == "RELEASE" and s.painting:
            if brush.finish_stroke(s) is not None:  # None: the stroke never reached the image
                _push_undo()
                self.strokes += 1
                self.undone = 0
            self.redraw()
            return {"RUNNING_MODAL"}
        if t in ("MOUSEMOVE", "INBETWEEN_MOUSEMOVE") and s.painting:
            return self._step(event)
        if s.painting:  # nothing else mid-stroke (an undo now would cut the stroke in two)
            return {"RUNNING_MODAL"}
        return {"PASS_THROUGH"}  # hovering, zooming, panning, undo between strokes

    def _step(self, event) -> set:
        try:
            if self.session.extend([self._pixel(event)]) is not None:
                self._show()
        except (comp.CompositingError, ValueError, RuntimeError) as exc:
            self.session.cancel()
            self._show()
            self.error = str(exc)
            return {"CANCELLED"}
        return {"RUNNING_MODAL"}


def _push_undo():
    """One undo step per stroke (the strokes are recorded on the image)."""
    try:
        bpy.ops.ed.undo_push(message=UNDO_MESSAGE)
    except RuntimeError:  # no undo stack (Blender started without one): the stroke stays, unundoable
        pass


class ROKEBY_OT_composite_brush(bpy.types.Operator):
    """Paint normal edits (emboss, bump, smooth) on the recomposited frame in the Image Editor:
    drag with the left mouse button, one undo step per stroke; Esc or right mouse cancels the
    stroke in progress, and ends the brush between strokes"""

    bl_idname = "rokeby.composite_brush"
    bl_label = "Paint Normals"
    bl_options = {"REGISTER"}  # each stroke pushes its own undo step

    mode: EnumProperty(name="Brush", items=MODES, default="EMBOSS")
    radius: FloatProperty(name="Radius", description="Brush radius in image pixels (the falloff reaches 0 there)",
                          default=20.0, min=0.5, max=brush.MAX_RADIUS, soft_max=200.0)
    strength: FloatProperty(name="Strength", default=0.5, min=0.01, max=1.0, subtype="FACTOR")
    image_name: StringProperty(name="Image", default="", options={"SKIP_SAVE"},
                               description="The image to paint on (default: the Image Editor's, else Rokeby Recomposited)")
    filepath: StringProperty(name="EXR", default="", subtype="FILE_PATH", options={"SKIP_SAVE"},
                             description="The multilayer EXR rendered with the compositing passes (default: the one the "
                                         "image was painted from, else the scene's last Render and Recomposite)")
    stroke: CollectionProperty(type=RokebyBrushPoint, name="Stroke", options={"HIDDEN", "SKIP_SAVE"},
                               description="exec only: the stroke's (row, column) pixels")

    @classmethod
    def poll(cls, context):
        if getattr(context, "scene", None) is None:
            return _fail(cls, "Needs a scene")
        space = getattr(context, "space_data", None)
        if space is not None and space.type == "IMAGE_EDITOR":
            img = space.image
            if img is None:
                return _fail(cls, "The Image Editor shows no image: open the recomposited frame (Render and Recomposite makes it)")
            if not (brush.has_session(img.name) or img.get(schema.BRUSH_SOURCE_KEY) or context.scene.get(schema.COMPOSITE_LAST_EXR_KEY)):
                return _fail(cls, f"'{img.name}' has no rendered passes to paint on: click Render and Recomposite first")
            return True
        if not (context.scene.get(schema.COMPOSITE_LAST_EXR_KEY) or any(brush.has_session(i.name) for i in bpy.data.images)):
            return _fail(cls, "No rendered frame to paint on: click Render and Recomposite, then open its image in an Image Editor")
        return True

    def _image_name(self, context) -> str:
        if self.image_name:
            return self.image_name
        img = _editor_image(context)
        return img.name if img is not None else schema.RECOMPOSITED_IMAGE

    def _open(self, context):
        name = self._image_name(context)
        path = _source(context, name, self.filepath)
        if not path:
            raise comp.CompositingError("no rendered frame to paint on: click Render and Recomposite first, or give an EXR")
        return brush.open_brush(path, name)

    def execute(self, context):
        if len(self.stroke) == 0:
            self.report({"ERROR"}, "stroke: give at least one {'name': '', 'pixel': (row, column)} (or paint in the Image Editor)")
            return {"CANCELLED"}
        try:
            session = self._open(context)
            got = brush.paint_stroke(session, [tuple(p.pixel) for p in self.stroke], self.radius, self.strength,
                                     self.mode.lower())
        except (comp.CompositingError, ValueError, RuntimeError, OSError) as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        _push_undo()
        self.report({"INFO"}, f"Rokeby: {got['changed_pixels']} pixels of '{session.image_name}' repainted")
        return {"FINISHED"}

    # --- interactive ------------------------------------------------------------------------
    def invoke(self, context, event):
        if context.area is None or context.area.type != "IMAGE_EDITOR" or context.region is None:
            if len(self.stroke):
                return self.execute(context)
            self.report({"ERROR"}, "Rokeby: Paint Normals paints in an Image Editor: open the recomposited image there "
                                   "and click Paint Normals in its sidebar (Rokeby tab)")
            return {"CANCELLED"}
        try:
            session = self._open(context)
        except (comp.CompositingError, ValueError, RuntimeError, OSError) as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        context.space_data.image = bpy.data.images[session.image_name]
        size = tuple(session.shape[::-1])
        # the image's region (the button sits in the sidebar, another region of the same area)
        region = next(r for r in context.area.regions if r.type == "WINDOW")
        self._region = region
        self._driver = StrokeDriver(session, self.radius, self.strength, self.mode.lower(),
                                    lambda x, y: brush.region_to_pixel(region, size, x - region.x, y - region.y),
                                    context.area.tag_redraw,
                                    inside=lambda x, y: region.x <= x < region.x + region.width and region.y <= y < region.y + region.height,
                                    context=context)
        context.window_manager.modal_handler_add(self)
        _cursor_show(context, region, event, self.radius, size)
        context.workspace.status_text_set("Rokeby Paint Normals: drag to paint (one undo step per stroke; Ctrl+Z undoes "
                                          "this brush's strokes); Esc / right mouse: cancel the stroke, or finish")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type in ("MOUSEMOVE", "INBETWEEN_MOUSEMOVE"):
            _cursor_show(context, self._region, event, self.radius, tuple(self._driver.session.shape[::-1]))
        result = self._driver.handle(event)
        if self._driver.refused:
            self.report({"INFO"}, f"Rokeby: {self._driver.refused}")
        if "FINISHED" in result or "CANCELLED" in result:
            _cursor_hide()
            context.workspace.status_text_set(None)
            if self._driver.error:
                self.report({"ERROR"}, f"Rokeby: {self._driver.error}")
            if context.area is not None:
                context.area.tag_redraw()
        return result


# --- the brush circle (POST_PIXEL of the Image Editor, only while the brush runs) -------------

_cursor = {"handle": None, "at": None}


def _cursor_show(context, region, event, radius: float, size) -> None:
    v2d = region.view2d
    x0, _y0 = v2d.view_to_region(0.0, 0.0, clip=False)
    x1, _y1 = v2d.view_to_region(1.0, 0.0, clip=False)
    _cursor["at"] = (event.mouse_x - region.x, event.mouse_y - region.y, radius * (x1 - x0) / max(size[0], 1))
    if _cursor["handle"] is None:
        _cursor["handle"] = bpy.types.SpaceImageEditor.draw_handler_add(_draw_cursor, (), "WINDOW", "POST_PIXEL")
    context.area.tag_redraw()


def _cursor_hide() -> None:
    _cursor["at"] = None
    if _cursor["handle"] is not None:
        bpy.types.SpaceImageEditor.draw_handler_remove(_cursor["handle"], "WINDOW")
        _cursor["handle"] = None


def _draw_cursor():
    at, region = _cursor["at"], bpy.context.region
    if at is None or region is None:
        return
    try:
        import gpu  # noqa: PLC0415
        import numpy as np  # noqa: PLC0415
        from gpu_extras.batch import batch_for_shader  # noqa: PLC0415

        t = np.linspace(0.0, 2.0 * np.pi, 65)
        pts = np.stack([at[0] + at[2] * np.cos(t), at[1] + at[2] * np.sin(t), np.zeros_like(t)], 1).astype(np.float32)
        lines = np.stack([pts[:-1], pts[1:]], 1).reshape(-1, 3)
        sh = compat.builtin_shader("POLYLINE_UNIFORM_COLOR")
        gpu.state.blend_set("ALPHA")
        sh.bind()
        sh.uniform_float("viewportSize", (region.width, region.height))
        sh.uniform_float("lineWidth", 1.5)
        sh.uniform_float("color", (1.0, 1.0, 1.0, 0.9))
        batch_for_shader(sh, "LINES", {"pos": lines}).draw(sh)
        gpu.state.blend_set("NONE")
    except Exception:  # noqa: BLE001 - a draw handler must not raise into Blender's redraw
        pass


class ROKEBY_PT_compositing_brush(bpy.types.Panel):
    bl_label = "Rokeby Normal Brush"
    bl_space_type = "IMAGE_EDITOR"
    bl_region_type = "UI"
    bl_category = "Rokeby"

    def draw(self, context):
        col = self.layout.column()
        props = context.window_manager.operator_properties_last(ROKEBY_OT_composite_brush.bl_idname)
        if props is not None:
            col.prop(props, "mode")
            col.prop(props, "radius")
            col.prop(props, "strength")
        col.operator(ROKEBY_OT_composite_brush.bl_idname, icon="BRUSH_DATA")
        img = _editor_image(context)
        if img is not None and brush.has_session(img.name):
            col.label(text=f"{len(brush.session_for(img.name).strokes)} stroke(s) on '{img.name}'")
        col.operator("rokeby.composite_to_compositor", icon="NODE_COMPOSITING").image_name = img.name if img is not None else schema.RECOMPOSITED_IMAGE


class IMAGE_MT_rokeby(bpy.types.Menu):
    """Rokeby's operators of the Image Editor (Image ▸ Rokeby): F3 menu search finds them here"""

    bl_idname = "IMAGE_MT_rokeby"
    bl_label = "Rokeby"

    def draw(self, context):
        layout = self.layout
        layout.operator_context = "INVOKE_REGION_WIN"  # the brush runs its modal part in the image's region
        layout.operator(ROKEBY_OT_composite_brush.bl_idname, icon="BRUSH_DATA")
        img = _editor_image(context)
        layout.operator("rokeby.composite_to_compositor", icon="NODE_COMPOSITING").image_name = \
            img.name if img is not None else schema.RECOMPOSITED_IMAGE


def draw_image_menu_entry(self, context):
    """Appended to the Image Editor's Image menu: the Rokeby submenu."""
    self.layout.separator()
    self.layout.menu(IMAGE_MT_rokeby.bl_idname, icon="MOD_MIRROR")


IMAGE_MENUS_EXTENDED = ("IMAGE_MT_image",)


def _on_undo_redo(*_args):
    try:
        brush.sync_after_undo()
    except (comp.CompositingError, ValueError, RuntimeError) as exc:  # a handler must not raise into Blender
        print(f"Rokeby: normal brush after undo: {exc}")


def _on_load(*_args):
    brush.close_all()  # another file: its images replay their strokes when painted again


OWNER = "compositing.brush"
_HANDLERS = (("undo_post", _on_undo_redo), ("redo_post", _on_undo_redo), ("load_post", _on_load))
CLASSES = (RokebyBrushPoint, ROKEBY_OT_composite_brush, ROKEBY_PT_compositing_brush, IMAGE_MT_rokeby)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    for name, fn in _HANDLERS:
        hooks.add(OWNER, name, fn)
    for name in IMAGE_MENUS_EXTENDED:
        getattr(bpy.types, name).append(draw_image_menu_entry)


def unregister():
    _cursor_hide()
    for name in IMAGE_MENUS_EXTENDED:
        menu = getattr(bpy.types, name, None)
        if menu is not None:
            menu.remove(draw_image_menu_entry)
    hooks.remove(OWNER)
    for c in reversed(CLASSES):
        if getattr(c, "is_registered", False):
            bpy.utils.unregister_class(c)
