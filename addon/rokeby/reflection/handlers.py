"""Live updates: Blender's depsgraph and frame-change handlers keep every mirror's field current.

- ``depsgraph_update_post``: after any edit (a handle dragged, a property changed, a mesh edited);
  meshes are re-read only for objects Blender reports with new geometry.
  Edited materials with split Principled BSDFs bring their parts up to date (``shading.sync``).
- ``frame_change_post``: on every frame change (playback, scrubbing, final renders); every mirror's
  mesh is re-read because animation can deform it.
- ``render_pre``: before every final render the mirrors are evaluated for the render camera.
- Drag previews: while a red handle is dragged in a window, the moved constraint's geodesic
  distances come from a fast method (``geodesic_cache.DRAG_METHOD``); when the updates pause for
  ``geodesic_cache.SETTLE_INTERVAL`` (the drag ended) a timer recomputes them with the mirror's own
  method. ``render_pre``, ``save_pre`` and every non-interactive evaluation (API, frame change) do
  the same at once, so renders and saved files never hold the drag-time field.
- After each evaluation, ``rendering.sync_scene`` keeps the render nodes in the mirrors'
  materials (new and swapped materials included), so F12 shows the edit with no extra step.
- ``load_post`` / ``undo_post`` / ``redo_post``: runtime state is rebuilt from the file's data
  (files from before data version 1 are migrated so that they keep their meaning);
  after undo/redo, painted images reload the pixels of the packed data the step brought back.

The evaluator's dirty tracking decides what to recompute. A re-entrance guard makes the handlers
ignore the updates that writing the field itself causes while it runs; ``suspended()`` lets the
API drive evaluation itself (for example around ``frame_set``).

Heavy scenes: the handlers never scan ``scene.objects``. ``rokeby.reflection.registry`` keeps what the add-on
owns (mirrors, shadow-edit objects, each mirror's handles, carrier and materials) and is rebuilt
on load/undo/redo, when the number of objects or a collection changes, and when Rokeby data is
added or removed; with no Rokeby data an update costs a length and a flag test. Each run first
tidies up after deletions (``registry.tidy``): a handle deleted with X is released (pointer
cleared, row flagged, object freed) and what only a deleted mirror used goes with it.
"""

from __future__ import annotations

import time

import bpy
from bpy.app.handlers import persistent

from ..blender import compat, hooks
from ..blender import registry as index
from ..core import schema
from . import evaluate, field_carriers, geodesic_cache, guard, mirror_state, registry
from .render import rendering, shading

_busy = False


def _run(scene, depsgraph, materials=(), **kwargs):
    global _busy
    if _busy or guard.active() or scene is None:
        return
    _busy = True
    try:
        # Deletions first: handles deleted with X are released, a deleted mirror's leftovers go.
        found = registry.mirrors()
        tidied = registry.tidy(found)
        for msg in tidied:
            print(f"Rokeby: {msg}")
        if tidied:
            # Objects were removed: the evaluated state must follow before it is read (the
            # update this causes finds the handlers busy).
            depsgraph.view_layer.update()
        reports = evaluate.evaluate_scene(scene, depsgraph, **kwargs)
        registry.refresh()
        # F12 shows the edit with no extra step: render nodes follow mirrors and materials.
        rendering.sync_scene(scene, reports, changed_materials=materials)
        moved = 0
        # Other features' work after each update (shadow edits: repair and falloffs follow their
        # lights), added through rokeby.blender.hooks so that no feature imports another.
        for step in hooks.steps("scene_update"):
            moved += step(scene) or 0
        if moved or any(r.recomputed for r in reports.values()):
            _redraw()
        if kwargs.get("interactive") and any(r.drag_preview for r in reports.values()):
            _settle_later()
    except Exception as exc:  # noqa: BLE001 - a handler must never take Blender down
        print(f"Rokeby: update failed: {type(exc).__name__}: {exc}")
    finally:
        _busy = False


def _redraw():
    wm = getattr(bpy.context, "window_manager", None)
    if wm is None:
        return
    for window in wm.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


@persistent
def on_depsgraph_update(scene, depsgraph):
    index.note_depsgraph(depsgraph)
    if _busy or guard.active():
        return
    with index.pinned():  # objects counted once per update
        if registry.has_data():  # else nothing is looked at: heavy scenes pay nothing
            _on_depsgraph_update(scene, depsgraph)


# ID types whose updates can change a mirror's geometry or an edited material by themselves.
_DATA_TYPES = ("MESH", "KEY", "MATERIAL", "NODETREE", "CURVE", "LATTICE", "ARMATURE")


def _updates_needed(depsgraph) -> bool:
    """Whether ``depsgraph.updates`` (a walk over every ID of the graph: 0.6 ms at 10,000
    objects) can hold anything for the add-on: data that was edited, or a mirror whose geometry
    other objects drive (modifiers, shape keys). Moving unrelated objects needs no walk."""
    types = compat.depsgraph_id_types(_DATA_TYPES)
    if len(types) < len(_DATA_TYPES):  # an ID type this Blender does not name: walk
        return True
    if any(depsgraph.id_type_updated(t) for t in types):
        return True
    for ob in registry.mirrors():
        if ob.type != "MESH" or (ob.data is not None and ob.data.shape_keys is not None):
            return True
        # The readers of free-form regions read the mirror's own data (a MESH update).
        if any(not (m.type == "NODES" and m.name.startswith(schema.VG_MODIFIER_PREFIX)) for m in ob.modifiers):
            return True
    return False


def _on_depsgraph_update(scene, depsgraph):
    changed = set()
    materials = set()
    for update in (depsgraph.updates if _updates_needed(depsgraph) else ()):
        if update.is_updated_geometry:
            changed.add(update.id.original)
        if isinstance(update.id, (bpy.types.Material, bpy.types.ShaderNodeTree)):
            materials.add(update.id.original)
    if materials:
        _sync_materials(materials)
    _run(scene, depsgraph, materials=materials, geometry_changed=changed, interactive=in_a_window())


# None: decided by bpy.app.background. The benchmark sets True to measure a window's drag loop
# in background mode (with the deferred estimate's timer replaced).
WINDOW_UPDATES: "bool | None" = None


def in_a_window() -> bool:
    """Whether depsgraph updates come from an artist working in a Blender window: a drag is then
    a stream of them and the render-vs-preview estimate waits for a pause. In background mode
    (scripts, farms, tests) there is no event loop to finish a deferred estimate, so each update
    is final."""
    return (not bpy.app.background) if WINDOW_UPDATES is None else WINDOW_UPDATES


def _sync_materials(ids):
    """An artist edited a material: split Principled BSDFs follow their original (shading.sync)."""
    global _busy
    _busy = True
    try:
        # Only the mirrors' edited materials can hold split BSDFs (rendering keeps the others clean).
        mats = {mat for m in registry.mirrors() for mat in rendering.edited_materials(m)}
        for mat in mats:
            if mat in ids or (mat.node_tree is not None and mat.node_tree in ids):
                shading.sync(mat)
    except Exception as exc:  # noqa: BLE001 - a handler must never take Blender down
        print(f"Rokeby: material update failed: {type(exc).__name__}: {exc}")
    finally:
        _busy = False


@persistent
def on_frame_change(scene, depsgraph):
    with index.pinned():
        if registry.has_data():
            _run(scene, depsgraph, all_geometry=True)


def _depsgraph_of(scene):
    try:
        view_layer = scene.view_layers[0] if bpy.context.scene != scene or bpy.context.view_layer is None else bpy.context.view_layer
        return view_layer.depsgraph
    except (AttributeError, IndexError, ReferenceError):
        return None


@persistent
def on_render_pre(scene, *_args):
    """Before a final render (F12, an animation frame, a farm job): every mirror is brought up
    to date for the render camera, so a render never shows a field from an older state (nor a
    drag preview: this evaluation is not interactive)."""
    if _busy or guard.active() or scene is None:
        return
    depsgraph = _depsgraph_of(scene)
    if depsgraph is None:
        return
    with index.pinned():
        if registry.has_data():
            _run(scene, depsgraph, all_geometry=True)


# --- drag previews: the accurate distances follow when the drag ends ---------------------------

_settle_pending = False


def _settle_later():
    """Once per drag: a timer that settles the previews when the updates pause."""
    global _settle_pending
    if not _settle_pending:
        _settle_pending = True
        evaluate._schedule(_settle_timer, geodesic_cache.SETTLE_INTERVAL)


def _settle_timer():
    global _settle_pending
    wait = geodesic_cache.SETTLE_INTERVAL - (time.perf_counter() - mirror_state.last_interactive_update())
    if wait > 0 or _busy or guard.active():
        return max(wait, 0.05)  # still dragging (or the API is at work): look again later
    _settle_pending = False
    settle_previews()
    return None


def settle_previews(scene=None) -> int:
    """Recompute every mirror (of ``scene``, or of every scene) whose stored field is a drag
    preview with its own geodesic method, as when the drag ends; returns how many were."""
    done = 0
    for sc in [scene] if scene is not None else list(bpy.data.scenes):
        mirrors = mirror_state.previews(sc)
        depsgraph = _depsgraph_of(sc) if mirrors else None
        if depsgraph is None:
            continue
        with index.pinned():
            _run(sc, depsgraph)
        done += len(mirrors) - len(mirror_state.previews(sc))
    return done


@persistent
def on_save_pre(*_args):
    """A saved file holds the accurate field, never a drag preview."""
    if not _busy and not guard.active():
        settle_previews()


@persistent
def on_load(*_args):
    global _settle_pending
    _settle_pending = False  # loading a file drops the timers (and the previews go with the state)
    registry.reset()
    migrate_file()
    mirror_state.reset()
    rendering.reset()


def migrate_file():
    """Mirrors saved before their data version 1 keep their meaning: constraints stay seen
    from the views they were made from, and final renders show the edit only where the artist
    had installed the render nodes (then they stay in sync). Shadow edits that named their
    caster, light and twin get pointers (``shadow.migrate``)."""
    field_carriers.claim_carriers()  # carriers saved before they had an owner (Shift+D copies shared one)
    for ob in registry.mirrors():
        s = getattr(ob, "rokeby", None)
        if s is None or not s.is_mirror or s.data_version >= schema.DATA_VERSION or ob.library is not None:
            continue
        s.eye_source = "CREATION"
        mats = [slot.material for slot in ob.material_slots if slot.material is not None]
        s.render_edits = any(rendering.installed(m) for m in mats)
        s.freeze_eye_set = True
        s.data_version = schema.DATA_VERSION
    # Shadow edits saved with names get pointers; appearance painting saved before the specular
    # colour brush gets its parameter (each feature's "migrate" step, rokeby.blender.hooks).
    for step in hooks.steps("migrate"):
        step()


@persistent
def on_undo_redo(*_args):
    registry.reset()
    mirror_state.reset()
    rendering.reset()
    # Painted images: pixels in memory follow the packed data the step brought back
    # (each feature's "undo_redo" step, rokeby.blender.hooks).
    for step in hooks.steps("undo_redo"):
        step()


_HANDLERS = (
    ("depsgraph_update_post", on_depsgraph_update),
    ("frame_change_post", on_frame_change),
    ("load_post", on_load),
    ("render_pre", on_render_pre),
    ("save_pre", on_save_pre),
    ("undo_post", on_undo_redo),
    ("redo_post", on_undo_redo),
)


def register():
    registry.reset()
    for name, fn in _HANDLERS:
        hooks.add("reflection", name, fn)


def unregister():
    hooks.remove("reflection")
    mirror_state.reset()
