"""Evaluation of Rokeby mirrors: scene → arrays → rokeby_native → one mesh attribute.

For each mirror the evaluator gathers, as numpy arrays, the evaluated mesh in world space
(rokeby.reflection.mirror_surface), one constraint row [p, r, e] per constraint and the region
specs (rokeby.reflection.scene_inputs). It then computes the rotation field R(q) (paper eq. 5 and
7) per vertex and writes it as the rotation vector (axis × angle) point attribute
``rokeby_rotation`` of the mirror's mesh with a single ``foreach_set``, and the view-independent
parts the render nodes blend per shading point (rokeby.reflection.field_attributes; how close
renders come to the per-pixel preview: rokeby.reflection.interpolation_error).

Refraction constraints (``kind == 'REFRACTION'``, paper §7.1) give a second, independent field
from rows [p, t, e_t]. It uses the same distances, regions and caches and is written as
``rokeby_refraction``; the attribute is removed while the mirror has no usable refraction
constraint. Each field is recomputed only when its own rows change.

Dirty tracking: the inputs of a mirror are condensed into a fingerprint (handle positions, view
eyes, region settings, the mirror's transform and, when Blender reports that its geometry changed
or the frame changed, its evaluated vertex positions). When the fingerprint is unchanged nothing
is recomputed; ``mirror_state.stats()`` counts both cases. Geodesic distances and region weights
are cached (rokeby.reflection.geodesic_cache), so a handle move costs one solve for the handle
that moved, and a drag in a window shows a fast preview until it ends; during a drag the
render-vs-preview estimate runs at most every ``ESTIMATE_INTERVAL`` seconds and once more when the
updates pause (a timer, ``_schedule``). The runtime state of each mirror and its report live in
rokeby.reflection.mirror_state.

Shared meshes (Alt+D copies, Ctrl+L ▸ Link Object Data): a mesh used by more than one object
holds no field; each mirror using it writes its field to a carrier of its own
(rokeby.reflection.field_carriers). Copies of a mirror get handles of their own
(rokeby.reflection.duplicates).

Nothing here raises into Blender's handlers: a mirror that cannot be evaluated gets an ERROR
report (shown in the sidebar) and keeps its previous attribute values; every other mirror still
evaluates. Values are checked to be finite before they are written.
"""

from __future__ import annotations

import hashlib
import os
import time
from typing import NamedTuple

import numpy as np

from ..core import native, schema, words
from ..core.errors import RokebyError
from .field_attributes import _has_attribute, _has_render_attribute, remove_attribute, write_attribute, write_render_attribute
from .field_carriers import carrier_of, ensure_carrier, remove_carrier, strip_field
from .freeform_regions import sync_freeform_regions
from .geodesic_cache import _geodesic_distances, _preview_note, _regions_for_native
from .interpolation_error import _estimate, extend_rotations_outward, mesh_edges, ramp_form
from .mirror_state import _DIRTY, _STATE, _STATS, MirrorReport, _State
from .mirror_surface import _finite_matrix, read_geometry, shares_mesh
from .scene_inputs import _constraint_inputs, _region_inputs, mirrors_of, render_eye, valid_ior
from .unreached_pieces import _unreached_pieces, unreached_fallback

# While the artist drags, the estimate runs at most this often (seconds), and once after.
ESTIMATE_INTERVAL = 0.4


class _NativeTimer:
    def __init__(self):
        self.seconds = 0.0

    def __call__(self, fn, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - t0


def _fingerprint(obj, geo_version, mirror_matrix, rows, regions, extra=()) -> bytes:
    s = obj.rokeby
    h = hashlib.blake2b(digest_size=20)
    h.update(repr((s.enabled, s.metric, s.geodesic_method, s.polar, geo_version, regions, extra)).encode())
    h.update(np.ascontiguousarray(mirror_matrix).tobytes())
    h.update(np.ascontiguousarray(rows).tobytes())
    return h.digest()


def _defer_estimate(obj, state, args):
    """Estimate once the updates pause (``ESTIMATE_INTERVAL`` after the last one), then refresh
    the mirror's report; a render or an API evaluation estimates at once instead."""
    first = state.estimate_args is None
    state.estimate_args = args
    if not first:
        return
    uid = obj.session_uid

    def later():
        st = _STATE.get(uid)
        if st is None or st.estimate_args is None:
            return None
        if time.perf_counter() - st.estimate_time < ESTIMATE_INTERVAL:
            return ESTIMATE_INTERVAL  # still dragging: look again later
        est = _estimate(st, st.estimate_args)
        rep = st.report
        if rep is not None and rep.status != "ERROR":
            rep.interpolation_error = est
            base = [m for m in rep.messages if not (m.startswith("the mesh is too coarse") or " the edited reflection points below the surface" in m)]
            warned = [m for m in base if m not in rep.notes]
            rep.messages, rep.status = base, ("DISABLED" if rep.status == "DISABLED" else "OK" if not warned else rep.status)
            for msg in st.field_notes:
                rep.warn(msg)
        import bpy  # noqa: PLC0415

        for window in getattr(bpy.context.window_manager, "windows", ()):
            for area in window.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()
        return None

    _schedule(later, ESTIMATE_INTERVAL)


def _schedule(fn, seconds: float):
    """Run ``fn`` from Blender's event loop after ``seconds`` (again after what it returns)."""
    import bpy  # noqa: PLC0415

    bpy.app.timers.register(fn, first_interval=seconds)


class _Inputs(NamedTuple):
    """What one evaluation read from the scene (rokeby.reflection.scene_inputs)."""

    rows: np.ndarray  # reflection constraints [p, r, e], (K, 9)
    points: list  # their surface points
    specs: list  # region specs
    t_rows: np.ndarray  # refraction constraints [p, t, e_t], (T, 9)
    t_points: list
    ior: "float | None"  # the mirror's IOR, while it has refraction constraints


def evaluate_mirror(obj, scene, depsgraph, *, force=False, reread_geometry=False, interactive=False) -> MirrorReport:
    """Evaluate one mirror if its inputs changed (or ``force``); never raises. ``interactive``
    (the depsgraph handler, while the artist drags): the render-vs-preview estimate runs at most
    every ESTIMATE_INTERVAL seconds, and once more when the updates pause; a moved red handle's
    geodesic distances come from DRAG_METHOD (a drag preview, ``report.drag_preview``). Any
    evaluation that is not interactive recomputes a preview with the mirror's own method."""
    t0 = time.perf_counter()
    timer = _NativeTimer()
    _STATS["checks"] += 1
    name = getattr(obj, "name", "?")
    report = MirrorReport(name)
    uid = obj.session_uid
    state = _STATE.setdefault(uid, _State())
    try:
        _check_writable(obj, name)
        settings = obj.rokeby
        if _waits(obj, state, report):
            return report
        mirror_matrix = _finite_matrix(obj.evaluated_get(depsgraph).matrix_world, f"mirror '{name}'")
        geo = _current_geometry(obj, state, depsgraph, mirror_matrix, reread=reread_geometry or force)
        geo.uses += 1
        report.vertices = len(geo.vertices)
        report.field_mesh = geo.source
        eye_now, report.eye = render_eye(obj, scene, depsgraph, geo.size)
        if settings.freeze and not getattr(settings, "freeze_eye_set", True):
            report.warn("frozen, but no eye was stored (it had no constraint and the scene no camera): renders reflect from the frozen eye "
                        f"{tuple(round(float(x), 3) for x in settings.freeze_eye)}; unfreeze and freeze again, or set the frozen eye")
        inputs = _read_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, eye_now)
        # The stored field does not depend on the eye (renders blend eq. 7 per pixel); the rows
        # carry it when constraints are seen from the camera.
        fp_reflection = _fingerprint(obj, state.geometry_version, mirror_matrix, inputs.rows, inputs.specs)
        fp_refraction = _fingerprint(obj, state.geometry_version, mirror_matrix, inputs.t_rows, inputs.specs, (inputs.ior,))
        fp = fp_reflection + fp_refraction
        # The drag has ended (or a render, a save or the API asks): fields shown with drag-time
        # distances are recomputed with the mirror's own method, whatever else changed.
        settle = state.preview and not interactive
        if interactive:
            state.interactive_time = time.perf_counter()
        if fp == state.fingerprint and not force and not settle and state.report is not None and state.report.status != "ERROR":
            _STATS["skipped"] += 1
            return _kept_report(obj, state, geo, report)
        report.constraints_used = len(inputs.rows) + len(inputs.t_rows)
        method = {"HEAT": "heat", "DIJKSTRA": "dijkstra", "EXACT": "exact", "GRAPH": "graph", "DENSE_GRAPH": "dense_graph"}[settings.geodesic_method]
        polar = "exact" if settings.polar == "EXACT" else "fast"
        geodesic = bool(len(inputs.rows) + len(inputs.t_rows)) and settings.metric == "GEODESIC"
        distances, previewed = _distances(state, geo, report, inputs, method, timer, geodesic=geodesic, drag=interactive)
        _reflection_field(obj, depsgraph, state, geo, report, inputs, distances, method, polar, eye_now, timer,
                          again=force or settle, fingerprint=fp_reflection, interactive=interactive)
        _refraction_field(obj, depsgraph, state, geo, inputs, distances, method, polar, timer,
                          again=force or settle, fingerprint=fp_refraction)
        if geo.source == "transfer" and geo.shared:
            # Every object using a shared mesh carries its own field: none stays in the mesh,
            # where it would render on objects that are not (or no longer) this mirror.
            strip_field(obj.data)
        state.fingerprint = fp
        state.preview = report.drag_preview = previewed
        if previewed:
            report.note(_preview_note(obj))
        report.recomputed = True
        if not settings.enabled:
            report.status = "DISABLED"
        _STATS["recomputations"] += 1
    except RokebyError as exc:
        report.status = "ERROR"
        report.messages.append(str(exc))
        state.fingerprint = None
        _STATS["errors"] += 1
    except native.NativeUnavailable as exc:
        report.status = "ERROR"
        report.messages.append(str(exc))
        _STATS["errors"] += 1
    except (ValueError, TypeError, RuntimeError, ReferenceError) as exc:
        report.status = "ERROR"
        report.messages.append(f"{type(exc).__name__}: {exc}")
        state.fingerprint = None
        _STATS["errors"] += 1
    report.native_ms = timer.seconds * 1e3
    report.python_ms = (time.perf_counter() - t0) * 1e3 - report.native_ms
    state.report = report
    return report


def _check_writable(obj, name: str):
    """A RokebyError unless ``obj`` is a mesh object the field can be written to."""
    if obj.type != "MESH":
        raise RokebyError(f"mirror '{name}' is {words.kind(obj.type)}, not a mesh")
    if obj.library is not None:
        # Read-only: its field cannot follow this scene's camera or edits (no carrier, no
        # attribute can be written to it); a library override is a mirror of its own.
        raise RokebyError(f"mirror '{name}' is linked from library '{obj.library.filepath}' and cannot store the field: "
                          "make it local or a library override")


def _waits(obj, state, report) -> bool:
    """Whether the mirror's field waits for a later update (the previous one stays; ``report``,
    now the mirror's report, says why): in Edit Mode, or while a free-form region's reader is
    being (re)made."""
    uid = obj.session_uid
    if obj.mode == "EDIT":
        # Edit Mode writes its own mesh back on exit; the field follows when it does.
        report.warn("paused while the mirror is in Edit Mode")
        _DIRTY.add(uid)
        state.report = report
        return True
    changes = sync_freeform_regions(obj)
    if changes:
        # The reader's weights are in the next evaluation of the mesh; the ones at hand are
        # stale, so nothing is computed now and the previous field stays, as the status says.
        _DIRTY.add(uid)
        state.fingerprint = None
        for msg in changes:
            report.warn(f"{msg}; the field follows at the next update (until then renders show the previous one)")
        report.pending = True
        state.report = report
        return True
    return False


def _current_geometry(obj, state, depsgraph, mirror_matrix, *, reread: bool):
    """The mirror's geometry for this evaluation: the last one read, or read again (``reread``,
    the mirror marked dirty, its mesh newly shared or unshared, or moved). New positions start a
    new geometry version, which empties the distance and region caches."""
    uid = obj.session_uid
    groups = sorted({rg.vertex_group for rg in obj.rokeby.regions if rg.enabled and rg.kind == "FREEFORM" and rg.vertex_group})
    geo = state.geometry
    if (geo is None or reread or uid in _DIRTY or geo.shared != shares_mesh(obj)
            or not np.array_equal(getattr(geo, "matrix", None), mirror_matrix)):
        _DIRTY.discard(uid)
        try:
            new = read_geometry(obj, depsgraph, mirror_matrix, groups)
        except RokebyError:
            state.geometry = None
            raise
        new.matrix = mirror_matrix
        if not new.same_positions(geo):
            state.geometry_version += 1
            state.distance_cache.clear()
            state.region_cache.clear()
        else:
            new.bvh, new._poly_start, new.edges = geo.bvh, geo._poly_start, geo.edges
            new.uses, new.max_edge = geo.uses, geo.max_edge
        if new.bvh is None and geo is not None and geo.local is not None \
                and np.array_equal(geo.local, new.local) and np.array_equal(geo.triangles, new.triangles):
            # moved, not reshaped: the object-space BVH (or the count towards one) still holds
            new.bvh, new.uses, new.max_edge = geo.bvh, geo.uses, geo.max_edge
        state.geometry = geo = new
    return geo


def _read_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, eye_now) -> _Inputs:
    """The constraint rows of both kinds and the region specs of an enabled mirror (none while
    it is disabled); what cannot be used is reported."""
    settings = obj.rokeby
    t_rows, t_points, ior = np.zeros((0, 9), np.float32), [], None
    if not settings.enabled:
        return _Inputs(np.zeros((0, 9), np.float32), [], [], t_rows, t_points, ior)
    rows, points = _constraint_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, eye_now=eye_now)
    specs = _region_inputs(obj, scene, depsgraph, geo, mirror_matrix, report)
    if eye_now is None and len(settings.constraints):
        report.warn("the scene has no camera, so the render eye is unknown: constraints use the views they were made from and region borders blend view-independently; set a scene camera (or freeze the mirror)")
    if any(c.enabled and getattr(c, "kind", "REFLECTION") == "REFRACTION" for c in settings.constraints):
        try:
            ior = valid_ior(settings.ior)
        except RokebyError as exc:
            report.warn(f"mirror '{report.mirror}': {exc}; its refraction constraints are skipped")
        else:
            t_rows, t_points = _constraint_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, "REFRACTION", ior, eye_now=eye_now)
    return _Inputs(rows, points, specs, t_rows, t_points, ior)


def _kept_report(obj, state, geo, report) -> MirrorReport:
    """The mirror's last report, for an evaluation that found nothing changed: the same field,
    with the warnings of ``report``, which describe the scene as it is now (e.g. a deleted light
    whose highlight handle stayed where it was)."""
    if geo.shared:
        strip_field(obj.data)  # e.g. left by this mirror before its mesh was linked to another object
    kept = state.report
    kept.recomputed = False
    kept.messages, kept.status, kept.notes = list(report.messages), report.status, list(report.notes)
    if state.reach_note is not None:
        kept.note(state.reach_note)
    if state.preview:
        kept.note(_preview_note(obj))
    for msg in state.field_notes:
        kept.warn(msg)
    kept.eye = report.eye
    return kept


def _distances(state, geo, report, inputs, method, timer, *, geodesic: bool, drag: bool):
    """The (K + T, V) geodesic distances of both kinds of constraints (None unless ``geodesic``)
    and whether any row is a drag preview; pieces of the mesh no constraint reaches are noted on
    the report."""
    distances = None
    previewed = False
    if geodesic:
        # One query for both kinds: the per-point cache keeps every current constraint's solve.
        distances, previewed = _geodesic_distances(state, geo, inputs.points + inputs.t_points, method, timer, drag=drag)
        if np.all(np.isinf(distances)):
            report.warn("no constraint reaches this mesh over its surface; it takes the field of straight-line distances")
        report.unreached_pieces = _unreached_pieces(state, geo, distances)
    state.reach_note = None
    if report.unreached_pieces is not None:
        n, total = report.unreached_pieces
        state.reach_note = (
            f"{n} of {total} pieces of the mesh have no constraint on them: geodesic distances do not cross gaps, "
            "so there the constraints blend by straight-line distance")
        report.note(state.reach_note)
    return distances, previewed


def _reflection_field(obj, depsgraph, state, geo, report, inputs, distances, method, polar, eye_now, timer, *,
                      again: bool, fingerprint: bytes, interactive: bool):
    """Compute and write the reflection field when its inputs changed, its attributes are
    missing, or ``again`` (forced, or a drag preview to replace); then estimate how close renders
    come to the preview (deferred in the middle of a drag). Otherwise the last estimate stands."""
    rows, points, specs = inputs.rows, inputs.points, inputs.specs
    old = state.field_fingerprints
    transfer = geo.source == "transfer"
    target = carrier_of(obj) if transfer else obj
    stored = target is not None and _has_attribute(target, schema.ROTATION_ATTRIBUTE) and _has_render_attribute(target)
    if again or old.get(schema.ROTATION_ATTRIBUTE) != fingerprint or not stored:
        kwargs = {"polar": polar}
        if specs:
            kwargs["regions"] = _regions_for_native(state, geo, specs, points, method, timer)
        if distances is not None and len(rows):
            kwargs["distances"] = unreached_fallback(distances[: len(rows)], rows, geo.vertices, kwargs.get("regions"))
        # One field for the preview and the render: the parts of eq. 7 that do not depend on
        # the view, blended towards r rᵀ per shading point by the render nodes.
        parts = timer(native.rotation_field, geo.vertices, rows, output="view_blend", **kwargs)
        if specs:
            if geo.edges is None:
                geo.edges = mesh_edges(geo.triangles)
            parts = extend_rotations_outward(parts, geo.edges)
        # The view-independent form for scripts and tools (eq. 7 towards I).
        rv = timer(native.view_blend_rotation_vectors, parts)
        ramp = ramp_form(specs)
        if transfer:
            target = ensure_carrier(obj, depsgraph)
        else:
            remove_carrier(obj)
        write_attribute(target, rv, update=False)
        write_render_attribute(target, parts, state, ramp=ramp, timer=timer)
        state.view_parts = (parts, ramp)
        state.rotations = rv
        state.field_inputs = (rows, kwargs.get("distances"), kwargs.get("regions") or [])
        report.interpolation_error = None
        if eye_now is None or not len(rows):
            state.field_notes, state.estimate_args = [], None
        else:
            args = (geo, parts, eye_now, rows, kwargs, ramp)
            if interactive and time.perf_counter() - state.estimate_time < ESTIMATE_INTERVAL:
                # In the middle of a drag: the last estimate stands, a new one follows when
                # the updates pause (a timer), so each drag step pays only for the field.
                report.interpolation_error = state.report.interpolation_error if state.report is not None else None
                _defer_estimate(obj, state, args)
            else:
                report.interpolation_error = _estimate(state, args, timer)
        for msg in state.field_notes:
            report.warn(msg)
        old[schema.ROTATION_ATTRIBUTE] = fingerprint
    elif state.report is not None:
        report.interpolation_error = state.report.interpolation_error
        for msg in state.field_notes:
            report.warn(msg)


def _refraction_field(obj, depsgraph, state, geo, inputs, distances, method, polar, timer, *, again: bool, fingerprint: bytes):
    """Compute and write the refraction field when its inputs changed, its attribute is missing,
    or ``again``; remove it while the mirror has no usable refraction constraint."""
    rows, t_rows, t_points, specs = inputs.rows, inputs.t_rows, inputs.t_points, inputs.specs
    old = state.field_fingerprints
    # The refraction field goes where the reflection field went (the mirror's own carrier when
    # the mesh is shared or its vertex count changes).
    target = (carrier_of(obj) or ensure_carrier(obj, depsgraph)) if geo.source == "transfer" else obj
    if not len(t_rows):
        old.pop(schema.REFRACTION_ATTRIBUTE, None)
        state.refractions = None
        remove_attribute(target, schema.REFRACTION_ATTRIBUTE)
    elif again or old.get(schema.REFRACTION_ATTRIBUTE) != fingerprint or not _has_attribute(target, schema.REFRACTION_ATTRIBUTE):
        kwargs = {"polar": polar}
        if specs:
            kwargs["regions"] = _regions_for_native(state, geo, specs, t_points, method, timer)
        if distances is not None:
            kwargs["distances"] = unreached_fallback(distances[len(rows):], t_rows, geo.vertices, kwargs.get("regions"))
        tv = timer(native.rotation_field, geo.vertices, t_rows, output="rotation_vector", **kwargs)
        write_attribute(target, tv, schema.REFRACTION_ATTRIBUTE)
        state.refractions = tv
        old[schema.REFRACTION_ATTRIBUTE] = fingerprint


def mesh_fingerprint(obj) -> bytes:
    """A cheap digest of ``obj``'s own mesh data (positions, corners, polygons, shape keys): a
    script that edits them (``foreach_set``, ``bmesh.to_mesh``) tags nothing that the API sees."""
    me = obj.data
    h = hashlib.blake2b(digest_size=16)
    nv, nl, npoly = len(me.vertices), len(me.loops), len(me.polygons)
    h.update(repr((me.session_uid, nv, nl, npoly)).encode())
    co = np.empty(nv * 3, np.float32)
    me.vertices.foreach_get("co", co)
    h.update(co.tobytes())
    idx = np.empty(nl, np.int32)
    me.loops.foreach_get("vertex_index", idx)
    h.update(idx.tobytes())
    start = np.empty(npoly, np.int32)
    me.polygons.foreach_get("loop_start", start)
    h.update(start.tobytes())
    keys = me.shape_keys
    if keys is not None:
        for kb in keys.key_blocks:
            kco = np.empty(len(kb.data) * 3, np.float32)
            kb.data.foreach_get("co", kco)
            h.update(kb.name.encode() + kco.tobytes())
    return h.digest()


def edited_meshes(scene) -> set:
    """Mirrors of ``scene`` whose mesh data changed since the last call (or were never seen):
    their meshes are tagged so the next depsgraph update re-evaluates them from the edited data,
    and the caller re-reads their geometry. For ``rokeby.api.evaluate``, which runs with the
    handlers suspended and so never sees Blender's geometry updates."""
    out = set()
    for ob in mirrors_of(scene):
        try:
            if ob.type != "MESH" or ob.mode == "EDIT" or ob.library is not None or ob.data.library is not None:
                continue
            fp = mesh_fingerprint(ob)
        except (AttributeError, ReferenceError):
            continue
        state = _STATE.setdefault(ob.session_uid, _State())
        if state.mesh_fingerprint != fp:
            ob.data.update_tag()
            state.mesh_fingerprint = fp
            out.add(ob)
    return out


def evaluate_scene(scene, depsgraph, *, force=False, geometry_changed=None, all_geometry=False, interactive=False, settle=True) -> dict:
    """Evaluate every mirror of ``scene``; ``geometry_changed``: original IDs Blender reported
    with new geometry (their meshes are re-read), ``all_geometry``: re-read every mirror's mesh
    (a frame change can deform any of them); ``interactive``: see ``evaluate_mirror``;
    ``settle``: when a mirror is pending (a free-form region's reader modifier was remade or
    repointed), update ``depsgraph`` and evaluate it again at once, so the status never describes
    weights older than the painting. Blender would re-evaluate the tagged mesh after the
    depsgraph handler anyway, but without calling the handlers again, so the field would wait
    for the next edit."""
    out = {}
    changed = geometry_changed or set()
    mirrors = mirrors_of(scene)
    from . import duplicates  # noqa: PLC0415

    # Shift+D / Alt+D copies get handles of their own before anything reads them.
    if duplicates.separate_copies(mirrors):
        depsgraph.update()  # the new handles are evaluated (their Shrinkwrap, their parent)
    local_names = {ob.name for ob in mirrors if ob.library is None}
    for ob in mirrors:
        reread = all_geometry or ob in changed or (ob.type == "MESH" and ob.data in changed)
        rep = evaluate_mirror(ob, scene, depsgraph, force=force, reread_geometry=reread, interactive=interactive)
        # A mirror linked from a library shares its name with its library override, which keeps
        # the plain name; the linked one is listed with its library's file name.
        key = ob.name if ob.library is None or ob.name not in local_names else f"{ob.name} ({os.path.basename(ob.library.filepath)})"
        out[key] = rep
    pending = [name for name, rep in out.items() if rep.pending]
    if settle and pending:
        depsgraph.update()  # our own handlers are guarded against re-entrance (handlers._busy)
        by_name = {ob.name: ob for ob in mirrors}
        for name in pending:
            ob = by_name.get(name)
            if ob is not None:
                out[name] = evaluate_mirror(ob, scene, depsgraph, force=force, reread_geometry=True, interactive=interactive)
    # Forget objects that are no longer mirrors (deleted, or Remove Mirror).
    from . import pointers  # noqa: PLC0415

    live = {ob.session_uid for ob in pointers.mirrors()}
    for uid in [u for u in _STATE if u not in live]:
        del _STATE[uid]
    return out
