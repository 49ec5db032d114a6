"""What one mirror's evaluation reads from the scene, and the checks on what it reads.

Which objects count (:func:`object_in_scene`: a handle or region centre that was deleted, even if
a pointer keeps it alive; :func:`mirrors_of`: the mirrors of a scene), whether an object can be a
mirror (:func:`check_mirror`, :func:`require_mirror`) and its IOR used (:func:`valid_ior`), and,
for one mirror, the eye renders see it from (:func:`render_eye`), one constraint row per usable
constraint (:func:`_constraint_inputs`) and the region specs (:func:`_region_inputs`).

A constraint row is [p, r, e] (paper §3): p the red handle projected onto the surface, r the
physical reflection of the ray from the constraint's generating eye, e towards the green handle.
A refraction constraint (paper §7.1) gives [p, t, e_t]: t = refract(view, N, 1/η) the physical
transmitted direction at p (η: the mirror's ``ior``), e_t towards the green handle. A constraint
or region that cannot be used is reported on the mirror's report and left out; the others are
still read.
"""

from __future__ import annotations

import numpy as np

from ..core import vecmath, words
from ..core.errors import RokebyError
from .duplicates import shrinkwrap_target
from .mirror_surface import _finite_matrix, project_to_surface

# A camera and a constraint's generating eye that see its target this far apart are reported.
EYE_MISMATCH_DEGREES = 3.0
# A red handle farther than this fraction of the mirror's size from its surface is reported.
OFF_SURFACE_TOLERANCE = 1e-3


# --- which objects count -------------------------------------------------------------------------


def object_in_scene(obj, scene) -> bool:
    """Whether ``obj`` (a handle or region centre) is still there: not removed, and linked into
    some collection. Deleting with X only unlinks an object that a constraint's pointer still
    uses, so an object whose only users are pointers counts as deleted. Costs no scan of
    ``scene.objects`` (rokeby.reflection.registry); ``scene`` is kept for callers."""
    if obj is None:
        return False
    try:
        users = obj.users - int(obj.use_fake_user)
    except ReferenceError:
        return False
    return users > _pointer_users(obj)


def _pointer_users(obj) -> int:
    """How many of the users of ``obj`` are the add-on's own pointers (constraints, regions, a
    map origin) of the mirrors in the file."""
    from . import pointers  # noqa: PLC0415

    return pointers.pointer_counts().get(obj.session_uid, 0)


def mirrors_of(scene) -> list:
    """The mirrors linked into ``scene``, from the add-on's registry (no scan of its objects)."""
    from . import pointers  # noqa: PLC0415

    return pointers.mirrors(scene)


def valid_ior(value) -> float:
    """The IOR as a float, or a RokebyError saying why it cannot be used."""
    ior = float(value)
    if not (np.isfinite(ior) and ior > 0.0):
        raise RokebyError(f"IOR must be finite and > 0, got {ior}")
    return ior


def check_mirror(obj):
    """A RokebyError unless ``obj`` is a local mesh object with faces (one a mirror can be)."""
    if obj is None:
        raise RokebyError("mirror: is None")
    try:
        name, kind = obj.name, obj.type
    except ReferenceError:
        raise RokebyError("mirror: the object was deleted") from None
    if kind != "MESH":
        raise RokebyError(f"mirror: '{name}' is {words.kind(kind)}, not a mesh")
    if len(obj.data.polygons) == 0:
        raise RokebyError(f"mirror: '{name}' has no faces")
    if obj.library is not None or obj.data.library is not None:
        raise RokebyError(f"mirror: '{name}' is linked from a library; make it local (or a library override with local mesh data)")
    return obj


def require_mirror(obj):
    """``obj`` if it is a Rokeby mirror (check_mirror and is_mirror), else a RokebyError."""
    check_mirror(obj)
    if not obj.rokeby.is_mirror:
        raise RokebyError(f"mirror: '{obj.name}' is not a Rokeby mirror: make it one with Add Mirror (Object ▸ Rokeby ▸ Add Mirror)")
    return obj


# --- one mirror's inputs -------------------------------------------------------------------------


def render_eye(obj, scene, depsgraph, size: float = 1.0):
    """The eye final renders see ``obj`` from, as (point or None, kind): the frozen eye of a
    frozen mirror ("frozen"), else the scene camera ("camera"; an orthographic camera's eye is
    placed far behind it along its view axis), else (None, "none")."""
    s = obj.rokeby
    if s.freeze:
        eye = np.array(s.freeze_eye, dtype=np.float64)
        if not np.all(np.isfinite(eye)):
            raise RokebyError(f"mirror '{obj.name}': its frozen eye is not finite")
        return eye, "frozen"
    cam = scene.camera
    if cam is None:
        return None, "none"
    m = _finite_matrix(cam.evaluated_get(depsgraph).matrix_world, f"camera '{cam.name}'")
    eye = m[:3, 3].copy()
    if cam.type == "CAMERA" and cam.data.type == "ORTHO":
        back = m[:3, 2] / max(np.linalg.norm(m[:3, 2]), 1e-300)  # a camera looks along its local −Z
        eye = eye + back * 1e4 * max(size, float(cam.data.ortho_scale), 1e-6)
    return eye, "camera"


def _angle_deg(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300), -1.0, 1.0))))


def _constraint_inputs(obj, scene, depsgraph, geo, mirror_matrix, report, kind="REFLECTION", ior=None, eye_now=None):
    """Constraint rows [p, r, e] (``kind`` REFLECTION) or [p, t, e_t] (REFRACTION, with the
    mirror's ``ior``) and their surface points; bad constraints are reported and skipped.

    r is the physical direction seen from ``eye_now`` (the render eye) when the mirror's
    generating eye is the scene camera, else from each constraint's stored eye; in that case a
    render eye that sees the target more than EYE_MISMATCH_DEGREES away is reported."""
    rows, points = [], []
    refraction = kind == "REFRACTION"
    from_camera = getattr(obj.rokeby, "eye_source", "CREATION") == "CAMERA" and eye_now is not None
    for k, c in enumerate(obj.rokeby.constraints):
        label = f"constraint {k + 1} ('{c.name}')" if c.name else f"constraint {k + 1}"
        if not c.enabled or getattr(c, "kind", "REFLECTION") != kind:
            continue
        try:
            red, green = c.surface_handle, c.target_handle
            if not object_in_scene(red, scene):
                raise RokebyError(f"{label}: its red (surface) handle was deleted")
            if not object_in_scene(green, scene):
                raise RokebyError(f"{label}: its green ({'transmitted' if refraction else 'reflected'}) handle was deleted")
            if getattr(c, "light_name", "") and green.parent is None:
                report.warn(f"{label}: the light '{c.light_name}' its green handle followed was deleted or unparented; the handle stays where it is")
            kept_on = shrinkwrap_target(red)
            if kept_on is not None and kept_on != obj:
                report.warn(f"{label}: red handle '{red.name}' is kept on '{kept_on.name}' (its Shrinkwrap), not on this mirror; "
                            "give this mirror its own constraint, or set the Shrinkwrap's target to it")
            red_m = _finite_matrix(red.evaluated_get(depsgraph).matrix_world, f"{label}: red handle '{red.name}'")
            green_m = _finite_matrix(green.evaluated_get(depsgraph).matrix_world, f"{label}: green handle '{green.name}'")
            eye = np.array(eye_now if from_camera else c.eye, dtype=np.float64)
            if not np.all(np.isfinite(eye)):
                raise RokebyError(f"{label}: its generating eye is not finite")
            sp = project_to_surface(obj, depsgraph, geo, red_m[:3, 3], mirror_matrix)
            if sp.offset > OFF_SURFACE_TOLERANCE * max(geo.size, 1e-12):
                parent = red.parent
                why = f" (it is parented to '{parent.name}')" if parent is not None and parent != obj else ""
                report.warn(f"{label}: red handle '{red.name}' is {sp.offset:.3g} off the surface{why}; the nearest surface point is used")
            view = sp.point - eye
            if not np.linalg.norm(view) > 1e-12 * max(geo.size, 1e-30):
                raise RokebyError(f"{label}: the generating eye lies on the surface point")
            if refraction:
                r = _transmitted(view / np.linalg.norm(view), sp.normal, ior, label)
            else:
                r = vecmath.reflect(view / np.linalg.norm(view), sp.normal)
            to_green = green_m[:3, 3] - sp.point
            if not np.linalg.norm(to_green) > 1e-9 * max(geo.size, 1e-30):
                raise RokebyError(f"{label}: the green handle sits on the surface point, so it gives no direction")
            e = to_green / np.linalg.norm(to_green)
            if not refraction and e @ sp.normal < 0.0:
                if getattr(c, "light_name", ""):
                    report.warn(f"{label}: no light reaches the red handle (the light is {np.degrees(np.arcsin(min(1.0, -e @ sp.normal))):.0f}° behind the surface there), so no highlight shows; move the red handle to the lit side")
                else:
                    report.warn(f"{label}: the green handle is {np.degrees(np.arcsin(min(1.0, -e @ sp.normal))):.0f}° behind the surface at the red handle; renders fold the reflection back above it, so it cannot show that point")
            if not from_camera and eye_now is not None and not refraction:
                view_now = sp.point - eye_now
                if np.linalg.norm(view_now) > 0.0:
                    off = _angle_deg(vecmath.reflect(view_now / np.linalg.norm(view_now), sp.normal), r)
                    if off > EYE_MISMATCH_DEGREES:
                        report.warn(f"{label}: from the render eye its reflection lands {off:.1f}° away from the green handle (it was made from another view); set Generating Eye to Scene Camera, or render from its view (Return to View)")
            rows.append(np.concatenate([sp.point, r / np.linalg.norm(r), e]))
            points.append(sp)
        except RokebyError as exc:
            report.warn(str(exc))
    return (np.array(rows, dtype=np.float32).reshape(-1, 9), points)


def _transmitted(incident, normal, ior, label):
    """Physical transmitted direction t at a refraction constraint, or a RokebyError saying why
    there is none."""
    if incident @ normal > 0.0:
        raise RokebyError(f"{label}: the generating eye sees the back of the surface at the red handle; refraction constraints edit where rays enter (the side the normals face)")
    if vecmath.total_internal_reflection(incident, normal, 1.0 / ior):
        raise RokebyError(f"{label}: total internal reflection at the red handle (IOR {ior:g} < 1 at this angle), so there is no transmitted ray to edit")
    return vecmath.refract(incident, normal, 1.0 / ior)


def _region_inputs(obj, scene, depsgraph, geo, mirror_matrix, report):
    """Region specs as plain tuples (for the fingerprint) — the weights are made later."""
    specs = []
    for k, rg in enumerate(obj.rokeby.regions):
        label = f"region {k + 1} ('{rg.name}')" if rg.name else f"region {k + 1}"
        if not rg.enabled:
            continue
        try:
            radius, border = float(rg.radius), float(rg.border)
            if not (np.isfinite(radius) and np.isfinite(border) and radius >= 0 and border >= 0):
                raise RokebyError(f"{label}: radius and border must be finite and >= 0")
            if rg.kind == "FREEFORM":
                if not rg.vertex_group:
                    raise RokebyError(f"{label}: no vertex group chosen (Regions ▸ Vertex group); the region is left out")
                if obj.vertex_groups.get(rg.vertex_group) is None:
                    raise RokebyError(f"{label}: vertex group '{rg.vertex_group}' was deleted; the region is left out until you choose a group")
                if rg.vertex_group not in geo.region_weights:
                    why = geo.region_problems.get(rg.vertex_group, f"vertex group '{rg.vertex_group}' could not be read")
                    raise RokebyError(f"{label}: {why}; the region is left out")
                specs.append(("FREEFORM", rg.vertex_group, border))
                continue
            if not object_in_scene(rg.center, scene):
                raise RokebyError(f"{label}: its centre empty was deleted")
            cm = _finite_matrix(rg.center.evaluated_get(depsgraph).matrix_world, f"{label}: centre '{rg.center.name}'")
            if rg.kind == "EUCLIDEAN":
                specs.append(("EUCLIDEAN", tuple(cm[:3, 3]), radius, border))
            else:
                sp = project_to_surface(obj, depsgraph, geo, cm[:3, 3], mirror_matrix)
                specs.append(("GEODESIC", sp.triangle, tuple(sp.bary), radius, border))
        except RokebyError as exc:
            report.warn(str(exc))
    return specs
