"""Operators: thin, undoable wrappers of ``rokeby.api``. No ``gpu`` use here.

Every operator reports problems in Blender's status bar/info log (``self.report``) and cancels
without changing the scene when the API refuses (the API validates before it creates anything).
Every operator has a ``poll`` that greys its button and menu entry out where it cannot run and
says why (``poll_message_set``, in the words of the buttons). Operators that act on a mirror take
it from the active object (a handle or region centre stands for its mirror); from a script,
``mirror=`` names it, and they are then available whenever the scene has a mirror.
"""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, StringProperty

from . import api  # reflection editing's entry points (rokeby.api re-exports their __all__)
from . import scene_inputs
from ..core import words
from ..core.errors import RokebyError
from ..blender.progress import Progress
from .props import CONSTRAINT_KINDS, METRICS, REGION_KINDS

UNDO = {"REGISTER", "UNDO"}


def _mirror(context, name: str = ""):
    if name:
        ob = bpy.data.objects.get(name)
        if ob is None:
            raise RokebyError(f"mirror: no object named '{name}'")
        return ob
    ob = context.active_object
    if ob is None:
        raise RokebyError("no active object: select a mirror")
    # A selected handle or region centre stands for its mirror.
    return api.mirror_of(ob, context.scene) or ob


def _fail(cls, message: str) -> bool:
    """A poll's refusal: ``message`` is what the greyed-out button's tooltip says."""
    cls.poll_message_set(message)
    return False


def poll_mirror(cls, context):
    """The mirror an operator acts on, for its ``poll``: the active object's mirror; True where
    none is active but the scene has a mirror (a script names it with ``mirror=``); False, with
    the reason set, where there is no mirror to act on."""
    scene = context.scene
    ob = context.active_object
    m = api.mirror_of(ob, scene) if ob is not None and scene is not None else None
    if m is not None:
        return m
    if scene is not None and scene_inputs.mirrors_of(scene):
        return True
    if ob is not None and ob.type == "MESH":
        return _fail(cls, f"'{ob.name}' is not a Rokeby mirror: click Add Mirror first")
    return _fail(cls, "There is no Rokeby mirror in this scene: select a mesh and click Add Mirror")


class _Op:
    """An operator on one mirror (its ``mirror`` property, else the active object's mirror):
    ``run`` does the work; a refusal from the API is reported and cancels, changing nothing."""

    def execute(self, context):
        try:
            self.run(context, _mirror(context, self.mirror))
        except RokebyError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        return {"FINISHED"}

    def index_or(self, active: int):
        """The ``index`` property, or ``active`` when it is left at -1."""
        return self.index if self.index >= 0 else active

    @classmethod
    def poll(cls, context):
        return bool(poll_mirror(cls, context))


def _poll_constraints(cls, context, what: str) -> bool:
    m = poll_mirror(cls, context)
    if m is True or not m:
        return bool(m)
    if not len(m.rokeby.constraints):
        return _fail(cls, f"'{m.name}' has no constraints {what}: add one with Add Reflection Constraint")
    return True


class ROKEBY_OT_mirror_add(_Op, bpy.types.Operator):
    """Make the active mesh a Rokeby mirror whose reflections can be edited"""

    bl_idname = "rokeby.mirror_add"
    bl_label = "Add Mirror"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror", description="Object name (default: the active object)")

    @classmethod
    def poll(cls, context):
        ob = context.active_object
        if ob is None:
            return _fail(cls, "Select a mesh to make it a mirror")
        if ob.type != "MESH":
            return _fail(cls, f"'{ob.name}' is {words.kind(ob.type)}: select a mesh to make it a mirror")
        if ob.rokeby.is_mirror:
            return _fail(cls, f"'{ob.name}' is already a Rokeby mirror")
        if ob.library is not None or ob.data.library is not None:
            return _fail(cls, f"'{ob.name}' is linked from a library: make it local first (Object ▸ Relations ▸ Make Local)")
        if len(ob.data.polygons) == 0:
            return _fail(cls, f"'{ob.name}' has no faces to reflect in")
        return True

    def run(self, context, mirror):
        api.add_mirror(mirror)


class ROKEBY_OT_mirror_remove(_Op, bpy.types.Operator):
    """Stop editing this mirror: remove its constraints, regions, handles and field"""

    bl_idname = "rokeby.mirror_remove"
    bl_label = "Remove Mirror"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")

    def run(self, context, mirror):
        api.remove_mirror(mirror, scene=context.scene)


def _view_of(context):
    """Eye and view dict of the 3D view the operator runs in (None outside a 3D view)."""
    rv3d = getattr(context, "region_data", None)
    if rv3d is None or not hasattr(rv3d, "view_matrix"):
        return None, None
    inv = rv3d.view_matrix.inverted()
    eye = np.array(inv.translation)
    if not rv3d.is_perspective:
        # An orthographic view has no eye point: use a point far back along the view direction.
        eye = np.array(rv3d.view_location) + np.array(inv.to_3x3().col[2]) * max(rv3d.view_distance, 1.0) * 10.0
    view = {
        "location": tuple(rv3d.view_location),
        "rotation": tuple(rv3d.view_rotation),
        "distance": float(rv3d.view_distance),
        "perspective": "PERSP" if rv3d.is_perspective else "ORTHO",
    }
    return eye, view


class ROKEBY_OT_constraint_add(_Op, bpy.types.Operator):
    """Click on a mirror: the red handle goes where you click, the green handle where the reflected ray lands, so nothing changes until you move one"""

    bl_idname = "rokeby.constraint_add"
    bl_label = "Add Constraint"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror", description="Object name (default: the mirror under the click, or the active one)")
    surface_point: FloatVectorProperty(name="Surface point", size=3, subtype="TRANSLATION")
    eye: FloatVectorProperty(name="Eye", size=3, subtype="TRANSLATION", description="Generating eye (default: the view's, else the scene camera)")
    use_eye: BoolProperty(name="Use eye", default=False, options={"HIDDEN"})
    reflected_point: FloatVectorProperty(name="Reflected point", size=3, subtype="TRANSLATION")
    use_reflected_point: BoolProperty(name="Set reflected point", default=False, description="Place the green handle here instead of on the physical reflection (refraction: on the physical transmitted ray)")
    kind: EnumProperty(name="Kind", items=CONSTRAINT_KINDS, default="REFLECTION")

    def run(self, context, mirror):
        eye, view = _view_of(context)
        if self.use_eye:
            eye, view = np.array(self.eye), None
        api.add_constraint(
            mirror,
            tuple(self.surface_point),
            tuple(self.reflected_point) if self.use_reflected_point else None,
            eye=None if eye is None else tuple(eye),
            view=view,
            kind=self.kind,
            scene=context.scene,
        )

    def invoke(self, context, event):
        if context.area is None or context.area.type != "VIEW_3D":
            return self.execute(context)
        context.window_manager.modal_handler_add(self)
        context.area.header_text_set("Rokeby: click on a mirror to add a constraint (Esc/right-click: cancel)")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type in {"ESC", "RIGHTMOUSE"}:
            context.area.header_text_set(None)
            return {"CANCELLED"}
        if event.type == "LEFTMOUSE" and event.value == "PRESS":
            context.area.header_text_set(None)
            region, rv3d = context.region, context.region_data
            if region is None or rv3d is None or region.type != "WINDOW":
                return {"CANCELLED"}
            from bpy_extras import view3d_utils  # noqa: PLC0415

            coord = (event.mouse_region_x, event.mouse_region_y)
            origin = view3d_utils.region_2d_to_origin_3d(region, rv3d, coord)
            direction = view3d_utils.region_2d_to_vector_3d(region, rv3d, coord)
            dg = context.evaluated_depsgraph_get()
            hit, loc, _n, _i, ob, _m = context.scene.ray_cast(dg, origin, direction)
            if not hit:
                self.report({"WARNING"}, "Rokeby: the click hit nothing; click on a mirror")
                return {"CANCELLED"}
            ob = ob.original
            if not ob.rokeby.is_mirror:
                self.report({"WARNING"}, f"Rokeby: '{ob.name}' is not a mirror (Add Mirror first)")
                return {"CANCELLED"}
            self.mirror = ob.name
            self.surface_point = loc
            return self.execute(context)
        return {"RUNNING_MODAL"}


class ROKEBY_OT_highlight_add(_Op, bpy.types.Operator):
    """Highlight editing: a constraint whose green handle is a light (it follows the light) and whose red handle starts where the light's highlight is; drag the red handle to move the highlight, add another to stretch it. Shadows stay where they are"""

    bl_idname = "rokeby.highlight_add"
    bl_label = "Add Highlight Constraint"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror", description="Object name (default: the active object's mirror)")
    light: StringProperty(name="Light", description="Light object (default: the selected light)")

    @classmethod
    def poll(cls, context):
        if not poll_mirror(cls, context):
            return False
        if not any(ob.type == "LIGHT" for ob in context.scene.objects):
            return _fail(cls, "There is no light in this scene: a highlight constraint follows a light")
        return True

    def run(self, context, mirror):
        light = bpy.data.objects.get(self.light) if self.light else None
        if light is None:
            lights = [ob for ob in context.selected_objects if ob.type == "LIGHT"]
            if self.light or len(lights) != 1:
                raise RokebyError(f"light: '{self.light}' is not an object" if self.light else "select one light (and the mirror), or name the light")
            light = lights[0]
        api.add_highlight_constraint(mirror, light, scene=context.scene)


class ROKEBY_OT_constraint_remove(_Op, bpy.types.Operator):
    """Remove the constraint and its handles"""

    bl_idname = "rokeby.constraint_remove"
    bl_label = "Remove Constraint"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    index: IntProperty(name="Index", default=-1, description="Constraint index (default: the active one)")

    @classmethod
    def poll(cls, context):
        return _poll_constraints(cls, context, "to remove")

    def run(self, context, mirror):
        api.remove_constraint(mirror, self.index_or(mirror.rokeby.active_constraint), scene=context.scene)


class ROKEBY_OT_constraint_select(_Op, bpy.types.Operator):
    """Select the constraint's handles (the green one active, ready to move)"""

    bl_idname = "rokeby.constraint_select"
    bl_label = "Select Handles"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    index: IntProperty(name="Index", default=-1)

    @classmethod
    def poll(cls, context):
        return _poll_constraints(cls, context, "whose handles to select")

    def run(self, context, mirror):
        s = mirror.rokeby
        i = api._index(s.constraints, self.index_or(s.active_constraint), "constraint")
        c = s.constraints[i]
        handles = [h for h in (c.surface_handle, c.target_handle) if h is not None and context.view_layer.objects.get(h.name) == h]
        if not handles:
            raise RokebyError("the constraint's handles were deleted")
        for ob in context.view_layer.objects:
            ob.select_set(False)
        for h in handles:
            h.select_set(True)
        context.view_layer.objects.active = handles[-1]
        s.active_constraint = i


class ROKEBY_OT_region_add(_Op, bpy.types.Operator):
    """Add a region of interest: only constraints inside it act there, with a smooth border"""

    bl_idname = "rokeby.region_add"
    bl_label = "Add Region"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    kind: EnumProperty(name="Kind", items=REGION_KINDS, default="EUCLIDEAN")
    radius: FloatProperty(name="Radius", default=1.0, min=0.0, subtype="DISTANCE")
    border: FloatProperty(name="Border", default=0.25, min=0.0, subtype="DISTANCE")
    vertex_group: StringProperty(name="Vertex group", description="Free-form: the painted vertex group (default: the active one)")
    center: FloatVectorProperty(name="Centre", size=3, subtype="TRANSLATION")
    use_center: BoolProperty(name="Use centre", default=False, description="Centre here (default: the 3D cursor)")

    def run(self, context, mirror):
        group = self.vertex_group
        if self.kind == "FREEFORM" and not group and mirror.vertex_groups.active is not None:
            group = mirror.vertex_groups.active.name
        centre = tuple(self.center) if self.use_center else tuple(context.scene.cursor.location)
        api.add_region(mirror, self.kind, center=centre, radius=self.radius, border=self.border, vertex_group=group, scene=context.scene)


class ROKEBY_OT_region_remove(_Op, bpy.types.Operator):
    """Remove the region (and its centre empty)"""

    bl_idname = "rokeby.region_remove"
    bl_label = "Remove Region"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    index: IntProperty(name="Index", default=-1)

    @classmethod
    def poll(cls, context):
        m = poll_mirror(cls, context)
        if m is True or not m:
            return bool(m)
        if not len(m.rokeby.regions):
            return _fail(cls, f"'{m.name}' has no regions to remove")
        return True

    def run(self, context, mirror):
        api.remove_region(mirror, self.index_or(mirror.rokeby.active_region), scene=context.scene)


class ROKEBY_OT_return_to_view(_Op, bpy.types.Operator):
    """Jump the 3D view back to the view the active constraint was made from"""

    bl_idname = "rokeby.return_to_view"
    bl_label = "Return to View"
    bl_options = {"REGISTER"}

    mirror: StringProperty(name="Mirror")
    index: IntProperty(name="Index", default=-1)

    @classmethod
    def poll(cls, context):
        if getattr(context, "region_data", None) is None or not hasattr(context.region_data, "view_rotation"):
            return _fail(cls, "Only in a 3D View: it moves the view to where the constraint was made from")
        return _poll_constraints(cls, context, "to return to")

    def run(self, context, mirror):
        v = api.constraint_view(mirror, self.index_or(mirror.rokeby.active_constraint))
        rv3d = context.region_data
        rv3d.view_perspective = v["perspective"]
        rv3d.view_location = v["location"]
        rv3d.view_rotation = v["rotation"]
        rv3d.view_distance = v["distance"]


class ROKEBY_OT_freeze(_Op, bpy.types.Operator):
    """Freeze reflections: they stop following the camera (evaluated from the active constraint's generating eye) until unfrozen"""

    bl_idname = "rokeby.freeze"
    bl_label = "Freeze Reflections"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    action: EnumProperty(name="Action", items=[("TOGGLE", "Toggle", "", 0), ("FREEZE", "Freeze", "", 1), ("UNFREEZE", "Unfreeze", "", 2)], default="TOGGLE")

    def run(self, context, mirror):
        scene_inputs.require_mirror(mirror)
        frozen = {"TOGGLE": not mirror.rokeby.freeze, "FREEZE": True, "UNFREEZE": False}[self.action]
        eye = None
        if frozen and not len(mirror.rokeby.constraints):
            eye, _view = _view_of(context)
            if eye is None and context.scene.camera is not None:
                eye = np.array(context.scene.camera.matrix_world.translation)
        api.freeze(mirror, frozen, eye=None if eye is None else tuple(eye))


class ROKEBY_OT_distance_set(_Op, bpy.types.Operator):
    """Measure the mirror's weights by straight-line (Euclidean) or over-the-surface (geodesic) distance, and recompute its field now, with progress in the status bar (geodesic distances take a second on large meshes)"""

    bl_idname = "rokeby.distance_set"
    bl_label = "Set Distance"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    metric: EnumProperty(name="Distance", items=[(m[0], m[1], m[2], i) for i, m in enumerate(METRICS)], default="GEODESIC")

    def run(self, context, mirror):
        scene_inputs.require_mirror(mirror)
        with Progress(context, 2) as progress:
            mirror.rokeby.metric = self.metric
            progress.step()
            rep = api.evaluate(context.scene).get(mirror.name)
            progress.step()
        if rep is not None and rep.status == "ERROR":
            self.report({"WARNING"}, f"Rokeby: {rep.summary()}")


class ROKEBY_OT_material_toggle(_Op, bpy.types.Operator):
    """Edit or stop editing the reflections of this material of the mirror"""

    bl_idname = "rokeby.material_toggle"
    bl_label = "Toggle Edited Material"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    material: StringProperty(name="Material", description="Material name (default: the mirror's active material)")

    @classmethod
    def poll(cls, context):
        m = poll_mirror(cls, context)
        if m is True or not m:
            return bool(m)
        if not any(slot.material for slot in m.material_slots):
            return _fail(cls, f"'{m.name}' has no materials")
        return True

    def run(self, context, mirror):
        edited = api.edited_materials(mirror)
        mat = bpy.data.materials.get(self.material) if self.material else mirror.active_material
        if mat is None:
            raise RokebyError(f"material: no material named '{self.material}'" if self.material else f"'{mirror.name}' has no active material")
        edited = [x for x in edited if x != mat] if mat in edited else edited + [mat]
        api.set_edited_materials(mirror, edited)


class ROKEBY_OT_render_nodes(_Op, bpy.types.Operator):
    """Insert (or remove) the node group that makes Cycles and EEVEE renders show the edited reflections"""

    bl_idname = "rokeby.render_nodes"
    bl_label = "Render Edits"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    action: EnumProperty(name="Action", items=[("INSTALL", "Install", "", 0), ("REMOVE", "Remove", "", 1)], default="INSTALL")

    def run(self, context, mirror):
        if self.action == "REMOVE":
            api.remove_render_nodes(mirror)
        elif api.install_render_nodes(mirror) == 0:
            self.report({"WARNING"}, f"Rokeby: no Glossy or Principled BSDF in the edited materials of '{mirror.name}'")


class ROKEBY_OT_reflection_map(_Op, bpy.types.Operator):
    """Capture (or refresh) the mirror's reflection map: a Cycles panorama from its centre, with the mirror hidden"""

    bl_idname = "rokeby.reflection_map"
    bl_label = "Capture Reflection Map"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    action: EnumProperty(name="Action", items=[("CAPTURE", "Capture", "", 0), ("CLEAR", "Clear", "Remove the map's images", 1)], default="CAPTURE")

    def run(self, context, mirror):
        from .render import reflmap  # noqa: PLC0415

        scene_inputs.require_mirror(mirror)
        if self.action == "CLEAR":
            reflmap.clear(mirror)
            return
        with Progress(context, 1) as progress:
            img = api.capture_reflection_map(mirror, scene=context.scene)
            progress.step()
        where = "packed in the .blend" if img.packed_file else img.filepath
        self.report({"INFO"}, f"Rokeby: {img.size[0]}×{img.size[1]} map of '{mirror.name}' in {mirror.rokeby.map_capture_seconds:.1f} s ({where})")


class ROKEBY_OT_ior_from_material(_Op, bpy.types.Operator):
    """Take the mirror's IOR (used by refraction constraints and renders) from its Glass, Refraction or transmissive Principled BSDF"""

    bl_idname = "rokeby.ior_from_material"
    bl_label = "IOR from Material"
    bl_options = UNDO

    mirror: StringProperty(name="Mirror")
    material: StringProperty(name="Material", description="Material name (default: the mirror's edited materials, in order)")

    @classmethod
    def poll(cls, context):
        m = poll_mirror(cls, context)
        if m is True or not m:
            return bool(m)
        if not any(slot.material for slot in m.material_slots):
            return _fail(cls, f"'{m.name}' has no material to take the IOR from")
        return True

    def run(self, context, mirror):
        mat = None
        if self.material:
            mat = bpy.data.materials.get(self.material)
            if mat is None:
                raise RokebyError(f"material: no material named '{self.material}'")
        ior = api.ior_from_material(mirror, mat)
        self.report({"INFO"}, f"Rokeby: IOR of '{mirror.name}' set to {ior:.4g}")


class ROKEBY_OT_update(bpy.types.Operator):
    """Recompute every mirror's field now"""

    bl_idname = "rokeby.update"
    bl_label = "Update Fields"
    bl_options = {"REGISTER"}

    force: BoolProperty(name="Force", default=True, description="Recompute even if nothing changed")

    @classmethod
    def poll(cls, context):
        if context.scene is None or not scene_inputs.mirrors_of(context.scene):
            return _fail(cls, "There is no Rokeby mirror in this scene to update")
        return True

    def execute(self, context):
        reports = api.evaluate(context.scene, force=self.force)
        bad = [r for r in reports.values() if r.status == "ERROR"]
        if bad:
            self.report({"WARNING"}, "; ".join(r.summary() for r in bad))
        else:
            self.report({"INFO"}, f"Rokeby: {len(reports)} mirror(s) up to date")
        return {"FINISHED"}


class ROKEBY_OT_preview_capture(bpy.types.Operator):
    """Capture again the scene that the viewport preview reflects, for every previewed mirror (it is captured by itself when objects, materials, lights or the world change)"""

    bl_idname = "rokeby.preview_capture"
    bl_label = "Capture Scene"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        from .viewport import scene_env  # noqa: PLC0415

        if context.scene is None or not scene_env.previewed(context.scene):
            return _fail(cls, "Switch on Viewport Preview for a mirror first")
        return True

    def execute(self, context):
        from .viewport import scene_env  # noqa: PLC0415

        done = 0
        for ob in scene_env.previewed(context.scene):
            cap = scene_env.current(ob)
            try:
                api.capture_preview_scene(ob, width=cap.width if cap else scene_env.DEFAULT_WIDTH,
                                          samples=cap.samples if cap else scene_env.DEFAULT_SAMPLES, scene=context.scene)
            except RokebyError as exc:
                self.report({"ERROR"}, str(exc))
                return {"CANCELLED"}
            done += 1
        for area in context.screen.areas if context.screen else ():
            if area.type == "VIEW_3D":
                area.tag_redraw()
        self.report({"INFO"}, f"Rokeby: captured the scene around {done} mirror(s)")
        return {"FINISHED"}


classes = (
    ROKEBY_OT_preview_capture,
    ROKEBY_OT_mirror_add,
    ROKEBY_OT_mirror_remove,
    ROKEBY_OT_constraint_add,
    ROKEBY_OT_highlight_add,
    ROKEBY_OT_constraint_remove,
    ROKEBY_OT_constraint_select,
    ROKEBY_OT_region_add,
    ROKEBY_OT_region_remove,
    ROKEBY_OT_return_to_view,
    ROKEBY_OT_freeze,
    ROKEBY_OT_distance_set,
    ROKEBY_OT_material_toggle,
    ROKEBY_OT_render_nodes,
    ROKEBY_OT_reflection_map,
    ROKEBY_OT_ior_from_material,
    ROKEBY_OT_update,
)

# Shortcuts in the 3D View (addon keymap: shown and editable in Preferences > Keymap).
KEYMAP = (
    ("rokeby.return_to_view", "V", {"shift": True, "alt": True}),
    ("rokeby.freeze", "F", {"shift": True, "alt": True}),
    ("rokeby.constraint_add", "C", {"shift": True, "alt": True}),
)
_keymaps = []


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    kc = bpy.context.window_manager.keyconfigs.addon if bpy.context.window_manager else None
    if kc is not None:
        km = kc.keymaps.new(name="3D View", space_type="VIEW_3D")
        for idname, key, mods in KEYMAP:
            kmi = km.keymap_items.new(idname, key, "PRESS", **mods)
            _keymaps.append((km, kmi))


def unregister():
    for km, kmi in _keymaps:
        try:
            km.keymap_items.remove(kmi)
        except (ReferenceError, RuntimeError):
            pass
    _keymaps.clear()
    for cls in reversed(classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
