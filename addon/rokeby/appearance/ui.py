"""Blender UI of appearance painting: an operator that sets an object up, a brush
operator that paints strokes on it in the viewport (modal: the mouse is ray-cast onto the object
and each step is one dab of :func:`rokeby.appearance.paint`; exec: a stroke given as points, for
scripts and tests), the brush settings, and a sidebar panel with Fraser's global sliders (the
material's ``rokeby_global_*`` node values), split into sub-panels (Brush, Global Sliders). The
brush settings are the scene's (``scene.rokeby_appearance_brush``: saved in the .blend). While the brush runs, a circle of its radius follows
the mouse on the surface (a POST_VIEW handler, added and removed by the operator). ``gpu`` is
touched only inside that draw handler, so it registers in background mode."""

from __future__ import annotations

import bpy
from bpy.props import CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty, StringProperty

from .. import appearance
from . import api, parameters
from ..blender import compat, ui_text
from ..core import words
from ..core import schema

# Explicit item numbers: Blender stores the number, so new brushes are appended with new numbers
# (files saved before the enum had explicit numbers stored 0-6, which are these).
_BRUSH_ITEMS = [
    ("diffuse", "Diffuse", "Paint the diffuse colour", 0),
    ("specular", "Specular", "Paint the specular intensity k_s toward the value", 1),
    ("sharpen", "Sharpen", "Lower the roughness (sharper highlights)", 2),
    ("blur", "Blur", "Raise the roughness (blurrier highlights)", 3),
    ("stretch", "Stretch", "Raise the anisotropy and turn it along the stroke", 4),
    ("metallic", "Metallic", "Move energy between diffuse and specular (Metallic) toward the value", 5),
    ("roughness", "Roughness", "Paint the roughness toward the value", 6),
    ("specular_tint", "Specular Colour", "Paint the colour of the highlights (Principled Specular Tint) toward the colour", 7),
]
_MODES = {"diffuse": "MIX", "specular": "MIX", "metallic": "MIX", "roughness": "MIX", "specular_tint": "MIX"}


def _redraw_views(context):
    for area in context.screen.areas if getattr(context, "screen", None) else ():
        if area.type == "VIEW_3D":
            area.tag_redraw()


def _redraw_update(_self, context):
    """The settings' update callback (a named function: a lambda in these annotations would not
    see this module's names when Blender evaluates them)."""
    _redraw_views(context)


class RokebyStrokePoint(bpy.types.PropertyGroup):
    location: FloatVectorProperty(name="Location", size=3, subtype="XYZ")


class RokebyAppearanceBrush(bpy.types.PropertyGroup):
    brush: EnumProperty(name="Brush", items=_BRUSH_ITEMS, default="blur")
    radius: FloatProperty(name="Radius", description="Brush radius in world units (the Gaussian falls to e⁻² there)", default=0.2, min=1e-4, soft_max=2.0, subtype="DISTANCE")
    strength: FloatProperty(name="Strength", default=0.5, min=0.0, max=1.0, subtype="FACTOR")
    value: FloatProperty(name="Value", description="Target (specular, metallic, roughness) or amount per dab (sharpen, blur, stretch)", default=0.25, min=0.0, max=1.0)
    color: FloatVectorProperty(name="Colour", subtype="COLOR", size=3, default=(0.8, 0.2, 0.1), min=0.0, soft_max=1.0)
    target: EnumProperty(
        name="Target",
        items=[
            ("POINT", "Per-Point Attribute", "Paint per-point attributes of the mesh", 0),
            ("TEXTURE", "Image Texture", "Paint one float image per parameter on the active UV map (packed into the .blend on save)", 1),
        ],
        default="POINT",
    )
    preview_model: EnumProperty(
        name="Preview Model",
        description="The BRDF the viewport preview shades with (the final render always uses Blender's Principled BSDF)",
        items=[
            ("PRINCIPLED", "Principled (GGX)", "Blender's BSDF as a split sum: GGX prefiltered radiance and the GGX albedo table", 0),
            ("PHONG", "Phong", "The seed's normalised Phong lobe, exponent from the roughness", 1),
            ("TORRANCE_SPARROW", "Torrance–Sparrow", "Fraser's simplified Torrance–Sparrow lobe with Schlick's Fresnel", 2),
        ],
        default="PRINCIPLED",
        update=_redraw_update,
    )
    resolution: IntProperty(name="Resolution", description="Side of the painted images in texels (texture target)", default=1024, min=8, max=16384)
    # Fraser's interface: the painted object under the environment and under a point light, side by side.
    preview_light: EnumProperty(
        name="Preview Light",
        description="What lights the viewport preview",
        items=[
            ("ENVIRONMENT", "Environment", "The world's environment image, prefiltered for the preview model", 0),
            ("POINT", "Point Light", "One movable point light (Light Location, Intensity) instead of the world", 1),
            ("BESIDE", "Both, Side by Side", "Fraser's interface: the object under the world and, beside it on screen, "
             "a copy under the point light (placed relative to the copy as Light Location is to the object)", 2),
        ],
        default="ENVIRONMENT",
        update=_redraw_update,
    )
    light_location: FloatVectorProperty(name="Light Location", description="The preview's point light, world space", size=3,
                                        subtype="TRANSLATION", default=(3.0, -3.0, 4.0), update=_redraw_update)
    # The final-render model: renders use Principled (GGX); Measure Difference to Render
    # stores how far they are from the Phong / Torrance–Sparrow preview (−1: not measured).
    render_difference: FloatProperty(name="Render Difference", default=-1.0)
    render_difference_key: StringProperty(name="Measured For", default="")
    light_intensity: FloatProperty(name="Light Intensity", description="The preview's point light in W/sr (radiance falls off as 1/d²)",
                                   default=10.0, min=0.0, soft_max=1000.0, update=_redraw_update)


def _settings(context):
    """The brush settings: the scene's, saved with the .blend."""
    return context.scene.rokeby_appearance_brush


def _fail(cls, message: str) -> bool:
    cls.poll_message_set(message)
    return False


def _poll_mesh(cls, context) -> bool:
    ob = context.active_object
    if ob is None:
        return _fail(cls, "Select the mesh to paint")
    if ob.type != "MESH":
        return _fail(cls, f"'{ob.name}' is {words.kind(ob.type)}: select the mesh to paint")
    return True


def _poll_painted(cls, context) -> bool:
    if not _poll_mesh(cls, context):
        return False
    ob = context.active_object
    if appearance.PARAMS["roughness"][0] not in ob.data.attributes:
        return _fail(cls, f"'{ob.name}' is not set up for painting: click Set Up Appearance Painting first")
    return True


def _dab(settings, obj, points, previous=None, pack=True):
    brush = settings.brush
    value = tuple(settings.color) if brush in appearance.COLORS else settings.value
    appearance.paint(obj, brush, points, settings.radius, value=value, strength=settings.strength, mode=_MODES.get(brush),
                     previous=previous, pack=pack)


class ROKEBY_OT_appearance_setup(bpy.types.Operator):
    """Create the painted-appearance attributes on the active mesh and wire them into its
    material's Principled BSDF"""

    bl_idname = "rokeby.appearance_setup"
    # Short: the redo panel's title has about 135 px at UI scale 1 (the sidebar button says more).
    bl_label = "Set Up Appearance"
    bl_options = {"REGISTER", "UNDO"}

    replace_links: bpy.props.BoolProperty(
        name="Replace Texture Links",
        description="Paint over Principled inputs that other nodes (textures) drive: the links are kept aside, "
        "and Remove Appearance Painting puts them back",
        default=False,
    )

    @classmethod
    def poll(cls, context):
        return _poll_mesh(cls, context)

    def execute(self, context):
        s = _settings(context)
        try:
            api.setup_appearance_painting(context.active_object, target=s.target, resolution=s.resolution,
                                          replace_links=self.replace_links)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class ROKEBY_OT_appearance_remove(bpy.types.Operator):
    """Remove appearance painting from the active material: its Rokeby nodes go and the texture
    links Set Up replaced come back, so the material is as it was before (the painted
    attributes stay on the mesh for a later Set Up)"""

    bl_idname = "rokeby.appearance_remove"
    bl_label = "Remove Appearance"  # short for the redo panel's title (the menu says more)
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if not _poll_mesh(cls, context):
            return False
        mat = context.active_object.active_material
        nodes = mat.node_tree.nodes if mat is not None and mat.node_tree is not None else None
        if nodes is None or not any(nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + p) is not None for p in appearance.PARAMS):
            return _fail(cls, f"'{context.active_object.name}' has no appearance painting in its active material")
        return True

    def execute(self, context):
        try:
            api.remove_appearance_painting(context.active_object)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class ROKEBY_OT_appearance_texture_remove(bpy.types.Operator):
    """Go back to per-point attributes: remove the painted images and their nodes from the
    active material (restoring it exactly as the per-point setup left it)"""

    bl_idname = "rokeby.appearance_texture_remove"
    bl_label = "Back to Attributes"  # short for the redo panel's title (the button says more)
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if not _poll_mesh(cls, context):
            return False
        if appearance.target(context.active_object) != "TEXTURE":
            return _fail(cls, f"'{context.active_object.name}' is painted per point already (no image textures to remove)")
        return True

    def execute(self, context):
        try:
            appearance.remove_texture(context.active_object)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class ROKEBY_OT_appearance_paint(bpy.types.Operator):
    """Paint the active object's appearance with the current brush: drag with the left mouse
    button in the 3D view, one undo step per stroke; right mouse or Esc ends the brush"""

    bl_idname = "rokeby.appearance_paint"
    bl_label = "Paint Appearance"
    bl_options = {"REGISTER", "UNDO"}

    stroke: CollectionProperty(type=RokebyStrokePoint, name="Stroke", description="exec only: the world-space dab positions", options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        return _poll_painted(cls, context)

    def execute(self, context):
        if len(self.stroke) == 0:
            self.report({"ERROR"}, "stroke: give at least one {'name': '', 'location': (x, y, z)} (or run the operator from the viewport)")
            return {"CANCELLED"}
        pts = [tuple(e.location) for e in self.stroke]
        try:
            _dab(_settings(context), context.active_object, pts)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}

    # --- interactive ------------------------------------------------------------------------
    # One undo step per stroke (press ... release), pushed at the release; the brush's end pushes
    # none (it returns CANCELLED: its strokes are already steps). Ctrl+Z between strokes undoes
    # this brush's strokes only (never a step from before the brush: it is refused there, and so
    # is redo past what it undid); during a stroke it is refused.
    UNDO_MESSAGE = "Paint Appearance Stroke"

    def _hit(self, view, ob, depsgraph):
        """(world point, world normal) where the mouse ray meets ``ob``, or None."""
        from bpy_extras import view3d_utils

        region, rv3d, co = view
        origin = view3d_utils.region_2d_to_origin_3d(region, rv3d, co)
        direction = view3d_utils.region_2d_to_vector_3d(region, rv3d, co)
        inv = ob.matrix_world.inverted()
        ok, loc, nrm, _i = ob.ray_cast(inv @ origin, (inv.to_3x3() @ direction).normalized(), depsgraph=depsgraph)
        if not ok:
            return None
        return ob.matrix_world @ loc, (inv.transposed().to_3x3() @ nrm).normalized()

    def _status(self, context, text):
        ws = getattr(context, "workspace", None)
        if ws is not None:
            ws.status_text_set(text)

    def _redraw(self, context):
        area = getattr(context, "area", None)
        if area is not None:
            area.tag_redraw()
        _redraw_views(context)

    def _end(self, context):
        self._status(context, None)
        show_cursor(None)
        self._redraw(context)

    def _end_stroke(self, context):
        """The release: the stroke becomes one undo step (texture strokes packed first, so the
        step holds them)."""
        self._painting = False
        self._last = None
        if not self._dabbed:
            return
        self._dabbed = False
        ob = context.active_object
        if ob is not None:
            appearance.pack_painted(ob)
        try:
            bpy.ops.ed.undo_push(message=self.UNDO_MESSAGE)
        except RuntimeError:  # no undo stack (Blender started without one): the stroke stays
            return
        self._strokes += 1
        self._undone = 0

    def invoke(self, context, event):
        from ..blender.modal import view3d_at  # noqa: PLC0415

        if context.area is None or (context.area.type != "VIEW_3D" and view3d_at(context, event) is None):
            return self.execute(context)
        self._last = None
        self._painting = False
        self._dabbed = False
        self._strokes = 0  # strokes of this brush pushed as undo steps and not undone
        self._undone = 0  # strokes of this brush undone (redo may bring them back)
        context.window_manager.modal_handler_add(self)
        self._status(context, "Rokeby: drag to paint (one undo step per stroke); right mouse / Esc: finish")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        from ..blender.modal import undo_key, view3d_at  # noqa: PLC0415

        key = undo_key(event, context)
        if key is not None:
            if self._painting:
                return {"RUNNING_MODAL"}  # mid-stroke: refused (it would cut the stroke in two)
            if key == "UNDO" and self._strokes > 0:
                self._strokes -= 1
                self._undone += 1
                return {"PASS_THROUGH"}  # Blender's Ctrl+Z takes back this brush's last stroke
            if key == "REDO" and self._undone > 0:
                self._strokes += 1
                self._undone -= 1
                return {"PASS_THROUGH"}
            self.report({"INFO"}, "Rokeby: no stroke of this brush to undo (finish the brush with right mouse / Esc first)"
                        if key != "REDO" else "Rokeby: no stroke of this brush to redo")
            return {"RUNNING_MODAL"}  # refused: it would reach past the brush
        if event.type in {"RIGHTMOUSE", "ESC"} and event.value == "PRESS":
            if self._painting:
                self._end_stroke(context)
            self._end(context)
            return {"CANCELLED"}  # every stroke is its own undo step already
        view = view3d_at(context, event) if event.type in {"LEFTMOUSE", "MOUSEMOVE"} else None
        if event.type == "LEFTMOUSE":
            if event.value == "RELEASE":
                if not self._painting:
                    return {"PASS_THROUGH"}  # the release of a click outside the view (a button)
                self._end_stroke(context)
                return {"RUNNING_MODAL"}  # the release ends this drag; passed on it could click-select
            if event.value != "PRESS":
                return {"RUNNING_MODAL"} if self._painting else {"PASS_THROUGH"}
            if view is None:
                return {"PASS_THROUGH"}  # a click in the sidebar, a header, another editor: theirs
            self._painting, self._last, self._dabbed = True, None, False
        elif event.type != "MOUSEMOVE":
            return {"RUNNING_MODAL"} if self._painting else {"PASS_THROUGH"}
        ob = context.active_object
        hit = self._hit(view, ob, context.evaluated_depsgraph_get()) if view is not None and ob is not None else None
        settings = _settings(context)
        # the brush cursor: a circle of the brush radius on the surface under the mouse
        show_cursor(None if hit is None else (tuple(hit[0]), tuple(hit[1]), settings.radius))
        self._redraw(context)
        if not self._painting:
            return {"PASS_THROUGH"}  # hovering: the view keeps its own mouse handling
        if hit is not None:
            try:
                _dab(settings, ob, [tuple(hit[0])], previous=self._last, pack=False)
            except ValueError as e:
                self.report({"ERROR"}, str(e))
                self._end_stroke(context)
                self._end(context)
                return {"CANCELLED"}
            self._last = tuple(hit[0])
            self._dabbed = True
        return {"RUNNING_MODAL"}


# --- the brush cursor (POST_VIEW, only while the brush operator runs) -------------------------

CURSOR_COLOUR = (1.0, 1.0, 1.0, 0.9)
_cursor = {"handle": None, "circle": None}


def brush_circle(centre, normal, radius: float, segments: int = 64):
    """(segments, 3) points of the circle of ``radius`` about ``centre`` in the plane normal to
    ``normal`` (the brush's reach on the surface: the Gaussian falls to e⁻² there)."""
    import numpy as np

    n = np.asarray(normal, np.float64)
    n = n / max(np.linalg.norm(n), 1e-30)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    t = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    return (np.asarray(centre, np.float64) + radius * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * v)).astype(np.float32)


def draw_cursor(circle, viewport_size, colour=CURSOR_COLOUR) -> None:
    """Draws a closed loop of points (from :func:`brush_circle`) with Blender's polyline shader
    (matrices from the gpu.matrix stack: the view's, in a draw handler)."""
    import gpu
    import numpy as np
    from gpu_extras.batch import batch_for_shader

    pts = np.asarray(circle, np.float32)
    lines = np.stack([pts, np.roll(pts, -1, axis=0)], axis=1).reshape(-1, 3)
    sh = compat.builtin_shader("POLYLINE_UNIFORM_COLOR")
    gpu.state.blend_set("ALPHA")
    sh.bind()
    sh.uniform_float("viewportSize", viewport_size)
    sh.uniform_float("lineWidth", 1.5)
    sh.uniform_float("color", colour)
    batch_for_shader(sh, "LINES", {"pos": lines}).draw(sh)
    gpu.state.blend_set("NONE")


def _draw_cursor_handler():
    circle = _cursor["circle"]
    region = bpy.context.region
    if circle is None or region is None:
        return
    try:
        draw_cursor(circle, (region.width, region.height))
    except Exception:  # noqa: BLE001 - a draw handler must not raise into Blender's redraw
        pass


def show_cursor(state) -> None:
    """``state`` = (centre, normal, radius): show the brush circle there (adding the POST_VIEW
    handler on first use); None hides it and removes the handler."""
    if state is None:
        _cursor["circle"] = None
        if _cursor["handle"] is not None:
            bpy.types.SpaceView3D.draw_handler_remove(_cursor["handle"], "WINDOW")
            _cursor["handle"] = None
        return
    _cursor["circle"] = brush_circle(*state)
    if _cursor["handle"] is None:
        _cursor["handle"] = bpy.types.SpaceView3D.draw_handler_add(_draw_cursor_handler, (), "WINDOW", "POST_VIEW")


class ROKEBY_OT_appearance_preview(bpy.types.Operator):
    """Show (or hide) the painted objects under the world HDR, prefiltered, in the viewport"""

    bl_idname = "rokeby.appearance_preview"
    bl_label = "Preview Under the World"

    @classmethod
    def poll(cls, context):
        from . import preview as appearance_preview
        from ..blender import prefs

        if not appearance_preview.enabled() and not prefs.get(context).gpu_viewport_preview:
            return _fail(cls, "GPU viewport previews are switched off in Rokeby's add-on preferences")
        return True

    def execute(self, context):
        from . import preview as appearance_preview

        appearance_preview.enable(not appearance_preview.enabled())
        for area in context.screen.areas if context.screen else ():
            if area.type == "VIEW_3D":
                area.tag_redraw()
        return {"FINISHED"}


def _difference_key(context) -> str:
    """What a render-difference figure was measured for: the preview model, the object, its
    painted values and the world image (a change shows the figure as stale)."""
    ob = context.active_object
    s = _settings(context)
    world = context.scene.world
    img = next((n.image for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT" and n.image is not None), None) \
        if world is not None and world.use_nodes else None
    means = tuple(round(float(x), 3) for x in _painted_means(ob)) if ob is not None and ob.type == "MESH" else ()
    return f"{s.preview_model}|{ob.name if ob else ''}|{img.name if img else ''}|{means}"


def _painted_means(ob):
    """The object's painted values averaged: base (rgb), specular, roughness, metallic, tint (rgb)."""
    import numpy as np

    base = appearance.point_values(ob, "diffuse")[:, :3].mean(axis=0)
    rest = [float(appearance.point_values(ob, p).mean()) for p in ("specular", "roughness", "metallic")]
    tint = appearance.point_values(ob, "specular_tint")[:, :3].mean(axis=0) if appearance.PARAMS["specular_tint"][0] in ob.data.attributes \
        else np.ones(3)
    return (*base, *rest, *tint)


class ROKEBY_OT_appearance_render_difference(bpy.types.Operator):
    """Measure how much the final render (always Blender's Principled BSDF) differs from the
    preview model's shading of this object's painted values under the world"""

    bl_idname = "rokeby.appearance_render_difference"
    bl_label = "Measure Difference to Render"

    @classmethod
    def poll(cls, context):
        return _poll_painted(cls, context)

    def execute(self, context):
        from . import glsl as appearance_glsl, preview as appearance_preview

        s = _settings(context)
        px = appearance_preview.world_pixels(context.scene)
        if px is None:
            self.report({"ERROR"}, "the world has no equirectangular Environment Texture to measure under")
            return {"CANCELLED"}
        try:
            v = _painted_means(context.active_object)
            d = appearance_glsl.render_difference(px, s.preview_model, base=v[0:3], specular=v[3], roughness=v[4], metallic=v[5],
                                                  spec_tint=v[6:9])
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        s.render_difference = d
        s.render_difference_key = _difference_key(context)
        name = s.bl_rna.properties["preview_model"].enum_items[s.preview_model].name
        self.report({"INFO"}, f"Renders (Principled) differ from the {name} preview by {100 * d:.1f} %")
        return {"FINISHED"}


def draw_render_model(layout, context) -> None:
    """What the panel says about the final render: always Principled (GGX); for another preview
    model, by how much the render differs (measured), or the button that measures it."""
    s = _settings(context)
    if s.preview_model == "PRINCIPLED":
        layout.label(text="Renders use this model", icon="CHECKMARK")  # the model menu above names it
        return
    col = layout.column(align=True)
    ui_text.label(col, context, "Renders use Principled (GGX), not this model", icon="INFO")
    if s.render_difference >= 0 and s.render_difference_key == _difference_key(context):
        ui_text.label(col, context, f"Render differs from this preview by {100 * s.render_difference:.1f} % (measured)", icon="ERROR")
    else:
        col.operator(ROKEBY_OT_appearance_render_difference.bl_idname, icon="VIEWZOOM")


class ROKEBY_PT_appearance(bpy.types.Panel):
    """Set up painting on the active mesh (target: per-point attributes or image textures)."""

    bl_label = "Appearance Painting"
    bl_idname = "ROKEBY_PT_appearance"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Rokeby"
    bl_options = {"DEFAULT_CLOSED"}
    bl_order = 20

    def draw(self, context):
        layout = self.layout
        ob = context.active_object
        if ob is None or ob.type != "MESH":
            layout.label(text="Select a mesh")
            return
        s = _settings(context)
        if appearance.PARAMS["roughness"][0] not in ob.data.attributes or appearance.target(ob) == "POINT":
            col = layout.column(align=True)
            col.prop(s, "target")
            if s.target == "TEXTURE":
                col.prop(s, "resolution")
                if len(ob.data.uv_layers) == 0:
                    col.label(text="This mesh has no UV map", icon="ERROR")
            if appearance.PARAMS["roughness"][0] not in ob.data.attributes or s.target == "TEXTURE":
                row = layout.row(align=True)
                row.operator(ROKEBY_OT_appearance_setup.bl_idname, text="Set Up Appearance Painting")
                row.operator(ROKEBY_OT_appearance_setup.bl_idname, text="", icon="LINKED").replace_links = True
        else:
            img = parameters._texture_image(ob, "roughness")
            ui_text.label(layout, context, f"Target: images {img.size[0]}² on UV map '{ob.active_material.node_tree.nodes[schema.APPEARANCE_NODE_PREFIX + 'uv'].uv_map}'" if img else "Target: images", icon="IMAGE_DATA")
            layout.operator(ROKEBY_OT_appearance_texture_remove.bl_idname, text="Back to Per-Point Attributes")
            missing = appearance.missing_images(ob)
            if missing:
                ui_text.label(layout, context, f"Painted image gone: {', '.join(missing)}", icon="ERROR")
                col = layout.column(align=True)
                col.prop(s, "target")
                col.prop(s, "resolution")
                col.operator(ROKEBY_OT_appearance_setup.bl_idname, text="Make Missing Images")


class _PaintedSubPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Rokeby"
    bl_parent_id = "ROKEBY_PT_appearance"

    @classmethod
    def poll(cls, context):
        ob = context.active_object
        return ob is not None and ob.type == "MESH" and appearance.PARAMS["roughness"][0] in ob.data.attributes


class ROKEBY_PT_appearance_brush(_PaintedSubPanel, bpy.types.Panel):
    """The brush and the viewport preview."""

    bl_label = "Brush"
    bl_idname = "ROKEBY_PT_appearance_brush"
    bl_order = 0

    def draw(self, context):
        layout = self.layout
        s = _settings(context)
        col = layout.column(align=True)
        col.prop(s, "brush")
        col.prop(s, "radius")
        col.prop(s, "strength")
        col.prop(s, "color" if s.brush in appearance.COLORS else "value")
        layout.operator(ROKEBY_OT_appearance_paint.bl_idname, icon="BRUSH_DATA")
        from . import preview as appearance_preview

        on = appearance_preview.enabled()
        layout.operator(ROKEBY_OT_appearance_preview.bl_idname, text="Hide Preview" if on else "Preview Under the World", icon="SHADING_RENDERED", depress=on)
        if on:
            # Short names: a field's name gets a quarter of the sidebar's width (the tooltip has the full one).
            layout.prop(s, "preview_model", text="Model")
            draw_render_model(layout, context)
            layout.prop(s, "preview_light", text="Light")
            if s.preview_light != "ENVIRONMENT":
                col = layout.column(align=True)
                col.prop(s, "light_location")
                col.prop(s, "light_intensity")
        if on and appearance_preview.last_error:
            ui_text.label(layout, context, appearance_preview.last_error, icon="ERROR")


class ROKEBY_PT_appearance_sliders(_PaintedSubPanel, bpy.types.Panel):
    """Fraser's global sliders: the material's ``rokeby_global_*`` node values."""

    bl_label = "Global Sliders"
    bl_idname = "ROKEBY_PT_appearance_sliders"
    bl_options = {"DEFAULT_CLOSED"}
    bl_order = 1

    def draw(self, context):
        layout = self.layout
        mat = context.active_object.active_material
        nodes = mat.node_tree.nodes if mat is not None and mat.use_nodes else {}
        col = layout.column()
        for param in appearance.PARAMS:
            node = nodes.get(schema.APPEARANCE_NODE_PREFIX + "global_" + param)
            if node is not None:
                col.prop(node.inputs[7 if param in appearance.COLORS else 1], "default_value", text=_SLIDER_NAMES.get(param, param))


# Slider labels as words (the parameter names title-cased would read "Anisotropic_Rotation").
_SLIDER_NAMES = {"diffuse": "Diffuse", "specular": "Specular", "roughness": "Roughness", "metallic": "Metallic",
                 "anisotropic": "Anisotropy", "anisotropic_rotation": "Anisotropic Rotation", "specular_tint": "Specular Colour"}

# The painting panels, parent first.
PANELS = (ROKEBY_PT_appearance, ROKEBY_PT_appearance_brush, ROKEBY_PT_appearance_sliders)


_CLASSES = (RokebyStrokePoint, RokebyAppearanceBrush, ROKEBY_OT_appearance_setup, ROKEBY_OT_appearance_remove, ROKEBY_OT_appearance_texture_remove, ROKEBY_OT_appearance_paint, ROKEBY_OT_appearance_preview,
            ROKEBY_OT_appearance_render_difference, *PANELS)


def register():
    for c in _CLASSES:
        bpy.utils.register_class(c)
    # On the Scene, so the brush is saved with the .blend (a WindowManager property is not).
    bpy.types.Scene.rokeby_appearance_brush = PointerProperty(type=RokebyAppearanceBrush, name="Rokeby Appearance Brush")


def unregister():
    from . import preview as appearance_preview

    appearance_preview.enable(False)
    show_cursor(None)
    if hasattr(bpy.types.Scene, schema.SCENE_APPEARANCE_BRUSH_PROP):
        del bpy.types.Scene.rokeby_appearance_brush
    for c in reversed(_CLASSES):
        if getattr(c, "is_registered", False):
            bpy.utils.unregister_class(c)
