"""Operators, a sidebar panel and a viewport overlay for freeform shadow boundary editing
(``rokeby.shadow``).

Start a session on the active mesh (the caster) and a light; drag a shadow handle in the 3D view
(the nearest handle to the cursor, with the fixed ends a fraction of the loop away on either side)
or give the drag numerically (scripts, tests); apply makes the shadow-mesh object and the linking.
The overlay draws every loop's boundary through its handles (orange when editable, grey when the
loop is shorter than the threshold) and the handles; ``gpu`` is imported only inside the draw
callback, never at import or registration.
"""

from __future__ import annotations

import itertools
import time

import bpy
import numpy as np

from ..blender import compat, hooks
from ..blender.modal import undo_key, view3d_at as _view_at
from .. import shadow
from ..core import schema, words
from . import linking

_SESSIONS: dict = {}
_OVERLAY: dict = {}
_DRAW_HANDLE = [None]

# Undo: a session lives in memory, not in the file, so each operator that changes it (start,
# a confirmed drag, apply, stop) records the session's state under a new number and writes the
# number on the scene (``schema.SHADOW_SESSION_STEP_KEY``) before its undo step is pushed; after undo or redo the
# session is put back to the state the restored scene names (``sync_after_undo``).
_HISTORY: dict = {}  # number -> (session, committed drags, applied, configuration), or None: no session
_HISTORY_KEPT = 512  # numbers kept (Blender keeps 32 undo steps by default)
_STEP_IDS = itertools.count(int(time.time() * 1000) % (1 << 30) + 1)
PICK_RADIUS = 30  # pixels: how near a handle a press must be to drag it

ACTIVE = (1.0, 0.55, 0.0, 1.0)
INACTIVE = (0.5, 0.5, 0.5, 1.0)
STYLES = [("affine", "Affine", "", 0), ("similarity", "Similarity", "", 1), ("rigid", "Rigid", "", 2)]


def _key(scene):
    """Sessions and overlays belong to a scene by its session id, so renaming it keeps them."""
    return scene.session_uid


def session(scene):
    """The scene's current shadow-editing session (or None)."""
    return _SESSIONS.get(_key(scene))


def overlay_geometry(sess, eye=None) -> dict:
    """Line segments (pairs of points) and colours of the boundaries through the handles, and the
    handle points, for the overlay: handles that miss, or are hidden from ``eye``, break the line."""
    lines, line_colors, points, point_colors = [], [], [], []
    for k, lp in enumerate(sess.loops()):
        h = sess.handles(k, eye)
        ok = h["hit"] & ~h["occluded"]
        p = h["points"]
        nxt = np.roll(np.arange(len(p)), -1)
        seg = ok & ok[nxt]
        c = ACTIVE if lp["active"] else INACTIVE
        lines.append(np.stack([p[seg], p[nxt[seg]]], 1).reshape(-1, 3))
        line_colors.append(np.tile(c, (2 * int(seg.sum()), 1)))
        if lp["active"]:
            points.append(p[ok])
            point_colors.append(np.tile(c, (int(ok.sum()), 1)))
    cat = lambda a, w: np.concatenate(a).astype(np.float32) if a else np.zeros((0, w), np.float32)  # noqa: E731
    return {"lines": cat(lines, 3), "line_colors": cat(line_colors, 4), "points": cat(points, 3), "point_colors": cat(point_colors, 4)}


def _view_eye(rv3d):
    """The eye of a 3D view (perspective; None for orthographic views)."""
    if rv3d is None or not rv3d.is_perspective:
        return None
    return tuple(rv3d.view_matrix.inverted().translation)


def _refresh(scene, eye=None):
    """Recomputes the overlay; handles hidden from ``eye`` (default: the scene camera) are hidden."""
    if eye is None and scene.camera is not None:
        eye = tuple(scene.camera.matrix_world.translation)
    sess = session(scene)
    _OVERLAY[_key(scene)] = overlay_geometry(sess, eye) if sess is not None else None
    for area in getattr(bpy.context.screen, "areas", ()) if bpy.context.screen else ():
        if area.type == "VIEW_3D":
            area.tag_redraw()


def record(scene, sess=None) -> int:
    """Marks ``scene``'s next undo step with the session's state now (``sess`` None: no session);
    returns the number written on the scene."""
    step = next(_STEP_IDS)
    _HISTORY[step] = None if sess is None else (sess, list(sess.drags), sess.applied, sess.configuration)
    while len(_HISTORY) > _HISTORY_KEPT:
        _HISTORY.pop(next(iter(_HISTORY)))
    scene[schema.SHADOW_SESSION_STEP_KEY] = step
    return step


def sync_after_undo(*_args) -> int:
    """undo_post / redo_post: each scene's shadow-editing session becomes the one its restored
    undo step names (its drags replayed), or ends where the step is from before the session.
    Returns how many scenes changed."""
    changed = 0
    for sc in bpy.data.scenes:
        entry = _HISTORY.get(int(sc.get(schema.SHADOW_SESSION_STEP_KEY, 0) or 0))
        key, now = _key(sc), _SESSIONS.get(_key(sc))
        if entry is not None and (entry[0].caster_object() is None or entry[0].light_object() is None):
            entry = None  # its caster or light is gone in the restored scene
        if entry is None:
            if now is not None:
                _SESSIONS.pop(key, None)
                changed += 1
                _refresh(sc)
            continue
        sess, drags, applied, configuration = entry
        if sess.pending is not None:
            sess.cancel()
        if now is not sess or [id(d) for d in sess.drags] != [id(d) for d in drags]:
            sess.drags[:] = drags
            sess._replay(drags)
            changed += 1
        sess.applied, sess.configuration = applied, configuration
        _SESSIONS[key] = sess
        _refresh(sc)
    return changed


def _forget(*_args):
    """load_post: another file's undo steps name none of these sessions."""
    _HISTORY.clear()
    _SESSIONS.clear()
    _OVERLAY.clear()


def _draw():
    geo = _OVERLAY.get(_key(bpy.context.scene))
    if not geo or len(geo["lines"]) == 0:
        return
    import gpu  # noqa: PLC0415 - only while drawing
    from gpu_extras.batch import batch_for_shader  # noqa: PLC0415

    shader = compat.builtin_shader("FLAT_COLOR")
    gpu.state.line_width_set(2.0)
    gpu.state.point_size_set(6.0)
    batch_for_shader(shader, "LINES", {"pos": geo["lines"], "color": geo["line_colors"]}).draw(shader)
    if len(geo["points"]):
        batch_for_shader(shader, "POINTS", {"pos": geo["points"], "color": geo["point_colors"]}).draw(shader)
    gpu.state.line_width_set(1.0)
    gpu.state.point_size_set(1.0)


def _ensure_overlay():
    if _DRAW_HANDLE[0] is None:
        _DRAW_HANDLE[0] = bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW", "POST_VIEW")


def _light(context, name: str):
    if name:
        ob = bpy.data.objects.get(name)
        if ob is None or ob.type != "LIGHT":
            raise shadow.ShadowEditError(f"light: no light object named {name!r}")
        return ob
    # Twin lights made for edited shadows are never what the artist means.
    ok = lambda o: o.type == "LIGHT" and linking._role(o) != "TWIN"  # noqa: E731
    lights = [o for o in context.selected_objects if ok(o)] or [o for o in context.scene.objects if ok(o)]
    if len(lights) != 1:
        raise shadow.ShadowEditError(f"light: select one light (found {len(lights)}) or name it")
    return lights[0]


def _fail(cls, message: str) -> bool:
    cls.poll_message_set(message)
    return False


def _poll_session(cls, context) -> bool:
    if context.scene is None or session(context.scene) is None:
        return _fail(cls, "No shadow edit is running: click Edit Shadow Boundaries first (with the caster active)")
    return True


class ROKEBY_OT_shadow_start(bpy.types.Operator):
    """Start editing the shadow of the active mesh from a light: show its shadow boundaries"""

    bl_idname = "rokeby.shadow_start"
    bl_label = "Edit Shadow Boundaries"
    bl_options = {"REGISTER", "UNDO"}  # one undo step: Ctrl+Z ends the session it started

    light: bpy.props.StringProperty(name="Light", default="", description="Light object (default: the selected or only light)")
    min_loop_vertices: bpy.props.IntProperty(name="Shortest loop", default=20, min=3, description="Loops with fewer silhouette vertices are grey and not editable")
    w_z: bpy.props.FloatProperty(name="w_z", default=2.5, min=0.01, description="Reach of the shadow mesh's deformation along the light (paper §6.1)")

    @classmethod
    def poll(cls, context):
        ob = context.active_object
        if ob is None:
            return _fail(cls, "Select the mesh whose shadow you edit (the caster)")
        if ob.type != "MESH":
            return _fail(cls, f"'{ob.name}' is {words.kind(ob.type)}, not a mesh: select the mesh whose shadow you edit")
        if not any(o.type == "LIGHT" for o in context.scene.objects):
            return _fail(cls, "There is no light in this scene: a shadow edit needs the light that casts it")
        return True

    def execute(self, context):
        try:
            light = _light(context, self.light)
            sess = shadow.start(context.active_object, light, scene=context.scene, min_loop_vertices=self.min_loop_vertices, w_z=self.w_z)
        except shadow.ShadowEditError as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        _SESSIONS[_key(context.scene)] = sess
        record(context.scene, sess)
        _ensure_overlay()
        _refresh(context.scene)
        n = len(sess.loops())
        self.report({"INFO"}, f"Rokeby: {n} silhouette loop{'s' if n != 1 else ''} of '{sess.caster}' from '{sess.light}'")
        return {"FINISHED"}


class ROKEBY_OT_shadow_drag(bpy.types.Operator):
    """Drag a shadow boundary: press on a handle in the 3D view and drag, the segment between the
    fixed ends deforms (release to keep; right-click, Esc or Ctrl+Z cancel). From the sidebar
    button or a menu, the next press on a handle starts the drag"""

    bl_idname = "rokeby.shadow_drag"
    bl_label = "Drag Shadow Boundary"
    bl_options = {"REGISTER", "UNDO"}  # one undo step per confirmed drag (a cancelled drag pushes none)

    loop: bpy.props.IntProperty(name="Loop", default=0, min=0)
    fixed: bpy.props.IntVectorProperty(name="Fixed ends", size=2, default=(0, 0))
    moved: bpy.props.IntProperty(name="Dragged vertex", default=0, min=0)
    target: bpy.props.FloatVectorProperty(name="Target", size=3, subtype="XYZ", description="Receiver point the handle moves to")
    style: bpy.props.EnumProperty(name="Style", items=STYLES, default="affine")
    segment: bpy.props.FloatProperty(name="Segment", default=0.2, min=0.02, max=0.49, description="Fixed ends this fraction of the loop away on either side (interactive drags)")
    noise_amplitude: bpy.props.FloatProperty(name="Noise amplitude", default=0.0)
    noise_frequency: bpy.props.FloatProperty(name="Noise frequency", default=0.0)
    apply_edit: bpy.props.BoolProperty(
        name="Apply", default=False, options={"HIDDEN", "SKIP_SAVE"},
        description="Also make the shadow mesh show the edit (what a drag in the view does; the redo panel repeats it)")
    pass_through: bpy.props.BoolProperty(
        name="Pass Other Presses On", default=False, options={"HIDDEN", "SKIP_SAVE"},
        description="A press far from every handle goes on to the view (the shortcut: a click elsewhere still selects)")

    @classmethod
    def poll(cls, context):
        return _poll_session(cls, context)

    def _drag(self, sess):
        return sess.drag(self.loop, tuple(self.fixed), self.moved, tuple(self.target), style=self.style,
                         noise_amplitude=self.noise_amplitude, noise_frequency=self.noise_frequency)

    def execute(self, context):
        sess = session(context.scene)
        if sess is None:
            self.report({"ERROR"}, "Rokeby: start a shadow edit first")
            return {"CANCELLED"}
        try:
            self._drag(sess)
        except ValueError as exc:
            sess.cancel()
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        sess.commit()
        if self.apply_edit:
            try:
                shadow.apply(sess, scene=context.scene)
            except shadow.ShadowEditError as exc:
                self.report({"ERROR"}, f"Rokeby: {exc}")
                return {"CANCELLED"}
        record(context.scene, sess)
        _refresh(context.scene)
        return {"FINISHED"}

    def _nearest(self, sess, view):
        """(pixels, loop, handle) of the editable handle nearest the mouse in ``view``, or None."""
        from bpy_extras import view3d_utils  # noqa: PLC0415

        region, rv3d, co = view
        mouse = np.array(co, float)
        best = None
        for k, lp in enumerate(sess.loops()):
            if not lp["active"]:
                continue
            for i, p in enumerate(sess.handles(k)["points"]):
                s = view3d_utils.location_3d_to_region_2d(region, rv3d, p)
                if s is not None:
                    d = np.hypot(*(np.array(s) - mouse))
                    if best is None or d < best[0]:
                        best = (d, k, i)
        return best if best is not None and best[0] <= PICK_RADIUS else None

    def _status(self, context, text):
        ws = getattr(context, "workspace", None)
        if ws is not None:
            ws.status_text_set(text)

    def invoke(self, context, event):
        sess = session(context.scene)
        if sess is None:
            self.report({"ERROR"}, "Rokeby: start a shadow edit, then drag in a 3D view")
            return {"CANCELLED"}
        view = _view_at(context, event)
        picked = self._nearest(sess, view) if view is not None else None
        if picked is None:
            if self.pass_through:
                return {"PASS_THROUGH"}  # the shortcut's press was not on a handle
            if getattr(context.area, "type", None) != "VIEW_3D" and view is None:
                self.report({"ERROR"}, "Rokeby: drag shadow handles in a 3D view")
                return {"CANCELLED"}
            # The button in the sidebar (or a menu): wait for a press on a handle in the view.
            self._dragging = False
            context.window_manager.modal_handler_add(self)
            self._status(context, "Rokeby: press on a shadow handle in the 3D view and drag; Esc / right mouse: cancel")
            return {"RUNNING_MODAL"}
        return self._begin(context, sess, view, picked)

    def _begin(self, context, sess, view, picked):
        self._view = view[:2]
        _, self.loop, self.moved = picked
        n = len(sess.loops()[self.loop]["points"])
        w = max(1, int(self.segment * n))
        self.fixed = ((self.moved - w) % n, (self.moved + w) % n)
        # The edited shadow shows in the viewport during the drag (Fig. 3 B-D): each step writes
        # the shadow mesh (shadow.live_step); Esc puts back what was there.
        try:
            self._live = shadow.live_begin(sess, scene=context.scene)
        except (shadow.ShadowEditError, ValueError) as exc:
            self._live = None
            self.report({"WARNING"}, f"Rokeby: no live shadow: {exc}")
        else:
            # The shadow mesh is displayed as Wire: Solid and Material Preview shading skip such
            # objects (and Solid has no linked lights), so only Rendered shading shows the shadow.
            shading = getattr(getattr(context, "space_data", None), "shading", None)
            if shading is not None and shading.type != "RENDERED":
                self.report({"INFO"}, "Rokeby: the edited shadow shows while dragging in Rendered viewport shading (Z)")
        # On the press, before the mouse moves: the drag's responses to the dragged point, so that
        # every step, the first included, fits a frame (docs/shadow_editing.md).
        try:
            sess.prepare_drag(self.loop, tuple(self.fixed), self.moved, style=self.style,
                              noise_amplitude=self.noise_amplitude)
        except ValueError as exc:
            self.report({"WARNING"}, f"Rokeby: {exc}")
        if not getattr(self, "_waiting", False):
            context.window_manager.modal_handler_add(self)
        self._dragging = True
        self._status(context, "Rokeby: drag the shadow boundary; release: keep; Esc / right mouse / Ctrl+Z: cancel")
        return {"RUNNING_MODAL"}

    def _cancel(self, context, sess):
        self._status(context, None)
        if not getattr(self, "_dragging", False):
            return {"CANCELLED"}
        sess.cancel()
        if self._live is not None:
            shadow.live_end(self._live, keep=False, scene=context.scene)
        _refresh(context.scene)
        return {"CANCELLED"}

    def modal(self, context, event):
        from bpy_extras import view3d_utils  # noqa: PLC0415

        sess = session(context.scene)
        if sess is None:
            self._status(context, None)
            return {"CANCELLED"}
        if event.type in {"RIGHTMOUSE", "ESC"} or undo_key(event, context):
            return self._cancel(context, sess)  # Ctrl+Z takes back this drag, never a step before it
        if not getattr(self, "_dragging", True):  # waiting for the press on a handle
            if event.type == "LEFTMOUSE" and event.value == "PRESS":
                view = _view_at(context, event)
                picked = self._nearest(sess, view) if view is not None else None
                if picked is None:
                    if view is None:
                        return {"PASS_THROUGH"}  # a click elsewhere (the sidebar, a header) works as usual
                    self.report({"WARNING"}, "Rokeby: no shadow handle near the cursor: press on an orange handle")
                    return {"RUNNING_MODAL"}
                self._waiting = True
                return self._begin(context, sess, view, picked)
            return {"PASS_THROUGH"}  # hovering, zooming, orbiting: the view works while waiting
        if event.type == "MOUSEMOVE":
            region, rv3d = self._view
            view = _view_at(context, event)
            if view is not None and view[0] == region:
                co = view[2]
            elif hasattr(event, "mouse_x") and hasattr(region, "x"):
                co = (event.mouse_x - region.x, event.mouse_y - region.y)
            else:
                co = (event.mouse_region_x, event.mouse_region_y)
            o = view3d_utils.region_2d_to_origin_3d(region, rv3d, co)
            d = view3d_utils.region_2d_to_vector_3d(region, rv3d, co)
            hit, loc, *_ = context.scene.ray_cast(context.evaluated_depsgraph_get(), o, d)
            if hit:
                self.target = loc
                try:
                    self._drag(sess)
                    if self._live is not None:
                        shadow.live_step(self._live)
                except ValueError as exc:
                    self.report({"WARNING"}, f"Rokeby: {exc}")
                _refresh(context.scene, _view_eye(rv3d))
            return {"RUNNING_MODAL"}
        if event.type == "LEFTMOUSE" and event.value == "RELEASE":
            self._status(context, None)
            sess.commit()
            if self._live is not None:
                shadow.live_end(self._live, keep=True, scene=context.scene)
                self.apply_edit = True  # the redo panel's repeat applies it as this drag did
            record(context.scene, sess)
            _refresh(context.scene)
            return {"FINISHED"}
        return {"RUNNING_MODAL"}


class ROKEBY_OT_shadow_apply(bpy.types.Operator):
    """Make the shadow mesh of the edit and link the lights so receivers show the edited shadow"""

    bl_idname = "rokeby.shadow_apply"
    bl_label = "Apply Shadow Edit"
    bl_options = {"REGISTER", "UNDO"}

    add_configuration: bpy.props.BoolProperty(
        name="Add as Key Configuration",
        description="Keep the caster's edit and add this one for the light's current position (§6.2): the edits are "
                    "blended by the light's angle to each",
        default=False)

    @classmethod
    def poll(cls, context):
        return _poll_session(cls, context)

    def execute(self, context):
        sess = session(context.scene)
        if sess is None:
            self.report({"ERROR"}, "Rokeby: start a shadow edit first")
            return {"CANCELLED"}
        try:
            ob, twin = shadow.apply(sess, scene=context.scene, add_configuration=self.add_configuration)
        except shadow.ShadowEditError as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        record(context.scene, sess)
        self.report({"INFO"}, f"Rokeby: shadow mesh '{ob.name}', edited shadows lit by '{twin.name}'")
        return {"FINISHED"}


class ROKEBY_OT_shadow_stop(bpy.types.Operator):
    """Stop editing shadow boundaries (the shadow mesh stays)"""

    bl_idname = "rokeby.shadow_stop"
    bl_label = "Stop Shadow Editing"
    bl_options = {"REGISTER", "UNDO"}  # Ctrl+Z brings the session back

    @classmethod
    def poll(cls, context):
        return _poll_session(cls, context)

    def execute(self, context):
        _SESSIONS.pop(_key(context.scene), None)
        record(context.scene, None)
        _refresh(context.scene)
        return {"FINISHED"}


class ROKEBY_OT_shadow_remove(bpy.types.Operator):
    """Remove the shadow edit of the active object (a caster or its shadow mesh): the shadow mesh,
    the twin light and the linking go, and the light's own linking comes back"""

    bl_idname = "rokeby.shadow_remove"
    bl_label = "Remove Shadow Edit"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if shadow.shadow_mesh_of(context.active_object) is None:
            return _fail(cls, "The active object has no shadow edit: select its caster or its shadow mesh")
        return True

    def execute(self, context):
        try:
            shadow.remove(context.active_object)
        except shadow.ShadowEditError as exc:
            self.report({"ERROR"}, f"Rokeby: {exc}")
            return {"CANCELLED"}
        context.view_layer.update()
        return {"FINISHED"}


class ROKEBY_PT_shadow(bpy.types.Panel):
    bl_label = "Shadow Boundaries"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Rokeby"
    bl_options = {"DEFAULT_CLOSED"}
    bl_order = 10

    def draw(self, context):
        col = self.layout.column()
        sess = session(context.scene)
        if sess is None:
            col.operator(ROKEBY_OT_shadow_start.bl_idname, icon="LIGHT")
            if shadow.shadow_mesh_of(context.active_object) is not None:
                col.operator(ROKEBY_OT_shadow_remove.bl_idname, icon="TRASH")
            return
        loops = sess.loops()
        col.label(text=f"{sess.caster} from {sess.light}: {sum(lp['active'] for lp in loops)} of {len(loops)} loops editable")
        col.operator(ROKEBY_OT_shadow_drag.bl_idname, icon="MOUSE_LMB_DRAG")
        col.operator(ROKEBY_OT_shadow_apply.bl_idname, icon="CHECKMARK")
        caster = sess.caster_object()
        if caster is not None and shadow.shadow_mesh_of(caster) is not None:
            op = col.operator(ROKEBY_OT_shadow_apply.bl_idname, text="Add as Key Configuration", icon="KEYFRAME")
            op.add_configuration = True
        col.operator(ROKEBY_OT_shadow_stop.bl_idname, icon="X")


CLASSES = (ROKEBY_OT_shadow_start, ROKEBY_OT_shadow_drag, ROKEBY_OT_shadow_apply, ROKEBY_OT_shadow_stop, ROKEBY_OT_shadow_remove,
           ROKEBY_PT_shadow)


OWNER = "shadow.ui"
# The shortcut: a press on a shadow handle in the 3D view drags it (a press elsewhere passes on).
KEYMAP = (("rokeby.shadow_drag", "LEFTMOUSE", "PRESS", {}, {"pass_through": True}),)
_keymaps = []


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    hooks.add(OWNER, "undo_post", sync_after_undo)
    hooks.add(OWNER, "redo_post", sync_after_undo)
    hooks.add(OWNER, "load_post", _forget)
    kc = bpy.context.window_manager.keyconfigs.addon if bpy.context.window_manager else None
    if kc is not None:
        km = kc.keymaps.new(name="3D View", space_type="VIEW_3D")
        for idname, key, value, mods, props in KEYMAP:
            kmi = km.keymap_items.new(idname, key, value, **mods)
            for name, v in props.items():
                setattr(kmi.properties, name, v)
            _keymaps.append((km, kmi))


def unregister():
    for km, kmi in _keymaps:
        try:
            km.keymap_items.remove(kmi)
        except (ReferenceError, RuntimeError):
            pass
    _keymaps.clear()
    hooks.remove(OWNER)
    _HISTORY.clear()
    if _DRAW_HANDLE[0] is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_DRAW_HANDLE[0], "WINDOW")
        _DRAW_HANDLE[0] = None
    _SESSIONS.clear()
    _OVERLAY.clear()
    for c in reversed(CLASSES):
        if getattr(c, "is_registered", False):
            bpy.utils.unregister_class(c)
