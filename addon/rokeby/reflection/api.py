"""Reflection editing's entry points, used by its operators and, through ``rokeby.api`` (which
re-exports the names of ``__all__``), by background scripts. The names starting with ``_`` are
this module's helpers, not part of the API.

Data moves as numpy arrays (``foreach_get``/``foreach_set``), never with Python loops over
vertices. Functions that need Blender import ``bpy`` lazily, so the maths helpers work in any
Python with numpy and rokeby_native.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict

import numpy as np

from ..core import native, schema, vecmath
from ..core.errors import RokebyError
from ..blender import meshes, transaction

__all__ = [
    "reflect",
    "constraint_row",
    "physical_reflected_point",
    "MeshArrays",
    "mesh_arrays",
    "rotation_field",
    "edited_directions",
    "rotate",
    "quat_angle",
    "geodesic_solver",
    "geodesic_distances",
    # scene model (Blender)
    "add_mirror",
    "remove_mirror",
    "mirror_of",
    "add_constraint",
    "remove_constraint",
    "add_region",
    "remove_region",
    "evaluate",
    "freeze",
    "edited_materials",
    "install_render_nodes",
    "remove_render_nodes",
    "capture_reflection_map",
    "reflection_map",
    "capture_preview_scene",
    "set_edited_materials",
    "constraint_view",
    "edited_reflections",
    "report",
    "field",
    "stored_field",
    "refract",
    "refraction_field",
    "stored_refraction",
    "set_ior",
    "ior_from_material",
    "physical_highlight",
    "add_highlight_constraint",
    "stats",
    "reset_stats",
    "RokebyError",
    "MirrorReport",
]


def _cancellable(fn):
    """``fn`` is an operation ``rokeby.core.native.cancel()`` can stop (KeyboardInterrupt; an
    operator's Esc, Ctrl-C): see ``native.cancellable``."""
    import functools  # noqa: PLC0415

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with native.cancellable():
            return fn(*args, **kwargs)
    return wrapper


def _vec3(value, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,):
        raise ValueError(f"{name}: expected 3 numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: is not finite ({a.tolist()})")
    return a


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not n > 1e-20:
        raise ValueError(f"{name}: has zero length")
    return v / n


reflect = vecmath.reflect  # one home: rokeby.core.vecmath
refract = vecmath.refract


def constraint_row(surface_point, normal, reflected_point, eye) -> np.ndarray:
    """One constraint row [p, r, e] (float32, 9 values) from the handles of the paper's UI:
    the red handle ``surface_point`` p on the mirror (with the surface ``normal`` there), the green
    handle ``reflected_point`` that should appear reflected at p, and the generating ``eye``.
    r is the physical reflection of the view ray at p; e points from p to the green handle.
    """
    p = _vec3(surface_point, "surface_point")
    n = _unit(_vec3(normal, "normal"), "normal")
    g = _vec3(reflected_point, "reflected_point")
    eye = _vec3(eye, "eye")
    i = _unit(p - eye, "surface_point - eye")
    r = _unit(reflect(i, n), "reflected direction")
    e = _unit(g - p, "reflected_point - surface_point")
    return np.concatenate([p, r, e]).astype(np.float32)


def physical_reflected_point(surface_point, normal, eye, distance: float) -> np.ndarray:
    """Where the physically correct reflected ray from ``surface_point`` is at ``distance``: the
    green handle of a fresh constraint (which therefore changes nothing until it moves)."""
    p = _vec3(surface_point, "surface_point")
    n = _unit(_vec3(normal, "normal"), "normal")
    i = _unit(p - _vec3(eye, "eye"), "surface_point - eye")
    if not (np.isfinite(distance) and distance > 0):
        raise ValueError(f"distance: must be finite and > 0, got {distance}")
    return p + distance * _unit(reflect(i, n), "reflected direction")


MeshArrays = meshes.MeshArrays  # the Blender layer's mesh arrays (rokeby.blender.meshes)


def mesh_arrays(obj, depsgraph=None, *, world: bool = True) -> MeshArrays:
    """Vertices, vertex normals and triangles of ``obj``'s evaluated mesh (modifiers, shape keys
    and armatures applied), read with foreach_get (rokeby.blender.meshes.mesh_arrays; a bad
    transform is a RokebyError)."""
    return meshes.mesh_arrays(obj, depsgraph, world=world, error=RokebyError)


def rotation_field(points, constraints, **kwargs) -> np.ndarray:
    """The MLS rotation field at ``points`` as (N, 4) quaternions (x, y, z, w); see
    ``rokeby_native.reflection.rotation_field`` for the keyword arguments (distances, regions, normals, eye,
    polar)."""
    return native.rotation_field(points, constraints, **kwargs)


def edited_directions(positions, normals, eye, constraints, **kwargs) -> np.ndarray:
    """Edited reflection directions per pixel/point; see ``rokeby_native.reflection.edited_directions``."""
    return native.edited_directions(positions, normals, eye, constraints, **kwargs)


def rotate(quats: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Apply unit quaternions (..., 4) as (x, y, z, w) to vectors (..., 3), vectorised."""
    q = np.asarray(quats, dtype=np.float64)
    v = np.asarray(vectors, dtype=np.float64)
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)



def quat_angle(quats: np.ndarray) -> np.ndarray:
    """Rotation angle in radians of each quaternion (..., 4), accurate for small angles."""
    q = np.asarray(quats, dtype=np.float64)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


# GeodesicSolvers by mesh: the factorisation is the expensive part and is reused for every handle
# move; a change of topology (faces) or of positions (which change the Laplacian) makes a new one.
_SOLVER_CACHE: "OrderedDict[tuple, object]" = OrderedDict()
_SOLVER_CACHE_SIZE = 8


def _digest(a: np.ndarray) -> str:
    a = np.ascontiguousarray(a)
    return hashlib.blake2b(a.tobytes(), digest_size=16).hexdigest() + str(a.shape) + str(a.dtype)


def geodesic_solver(vertices, faces, *, boundary: str = "average"):
    """A ``rokeby_native.geometry.GeodesicSolver`` for this mesh, reused while neither its faces (topology)
    nor its vertex positions change; otherwise a new one (keeps the 8 most recent meshes)."""
    v = np.asarray(vertices, dtype=np.float32)
    f = np.asarray(faces)
    key = (_digest(f), _digest(v), boundary)
    solver = _SOLVER_CACHE.get(key)
    if solver is None:
        solver = native.module().geometry.GeodesicSolver(v, f, boundary=boundary)
        _SOLVER_CACHE[key] = solver
        while len(_SOLVER_CACHE) > _SOLVER_CACHE_SIZE:
            _SOLVER_CACHE.popitem(last=False)
    else:
        _SOLVER_CACHE.move_to_end(key)
    return solver


# The geodesic method of every entry point that does not name one: rokeby_native's functions
# (their own default, checked equal by tests/reflection/test_geodesic_accuracy.py), this API and
# new mirrors (add_mirror's GEODESIC_METHODS item of the same name).
DEFAULT_GEODESIC_METHOD = "dense_graph"


def geodesic_distances(vertices, faces, sources, *, method: str = DEFAULT_GEODESIC_METHOD, boundary: str = "average") -> np.ndarray:
    """Geodesic distances (S, V) through the cached solver of this mesh; see
    ``rokeby_native.geometry.GeodesicSolver.distances`` for the forms ``sources`` may take."""
    return geodesic_solver(vertices, faces, boundary=boundary).distances(sources, method=method)


# --- the scene model: mirrors, constraints and regions as Blender data ---------------------------
# Everything below needs Blender. The operators in rokeby.reflection.operators are thin wrappers of these
# functions, and background scripts (render farms, pipelines) call them directly.

from . import evaluate as _ev  # noqa: E402 - aliased: api.evaluate is a function
from . import field_attributes as _attributes  # noqa: E402
from . import field_carriers as _carriers  # noqa: E402
from . import freeform_regions as _freeform  # noqa: E402
from . import mirror_state as _state  # noqa: E402
from . import mirror_surface as _surface  # noqa: E402
from . import scene_inputs as _inputs  # noqa: E402
from .mirror_state import MirrorReport  # noqa: E402
from .pointers import of_mirrors as _of_mirrors  # noqa: E402


def _scene(scene):
    import bpy  # noqa: PLC0415

    return scene if scene is not None else bpy.context.scene


def _view_layer(scene):
    import bpy  # noqa: PLC0415

    if scene == bpy.context.scene and bpy.context.view_layer is not None:
        return bpy.context.view_layer
    return scene.view_layers[0]


def _depsgraph(scene):
    vl = _view_layer(scene)
    vl.update()
    return vl.depsgraph


def _camera_eye(scene) -> tuple:
    """The scene camera's position, after bringing object matrices up to date (objects made or
    moved by a script have stale matrices until the depsgraph runs)."""
    if scene.camera is None:
        raise RokebyError("eye: not given and the scene has no camera")
    _depsgraph(scene)
    return tuple(scene.camera.matrix_world.translation)


def mirror_of(obj, scene=None):
    """The mirror ``obj`` belongs to: itself if it is a mirror, else the mirror whose constraint
    handle or region centre it is (None when it is neither)."""
    if obj is None:
        return None
    if obj.rokeby.is_mirror:
        return obj
    from . import registry  # noqa: PLC0415

    for m in registry.mirrors(_scene(scene)):
        if any(obj in (c.surface_handle, c.target_handle) for c in m.rokeby.constraints) or any(obj == rg.center for rg in m.rokeby.regions):
            return m
    return None


@transaction.atomic(materials=_of_mirrors)
def add_mirror(obj, *, metric: str = "EUCLIDEAN", geodesic_method: str = DEFAULT_GEODESIC_METHOD.upper(), polar: str = "FAST"):
    """Make the mesh object ``obj`` a Rokeby mirror (its reflections become editable). New mirrors
    measure geodesics on the dense geodesic graph (DENSE_GRAPH, rokeby_native's default method
    too); the property's own default, which files saved without the setting read back, stays HEAT."""
    _inputs.check_mirror(obj)
    s = obj.rokeby
    for prop, value in (("metric", metric), ("geodesic_method", geodesic_method), ("polar", polar)):
        allowed = [item.identifier for item in s.bl_rna.properties[prop].enum_items]
        if value not in allowed:
            raise RokebyError(f"{prop}: '{value}' is not one of {allowed}")
    s.metric, s.geodesic_method, s.polar = metric, geodesic_method, polar
    s.is_mirror = True
    s.enabled = True
    return obj


def _handle_collection(scene):
    import bpy  # noqa: PLC0415

    coll = bpy.data.collections.get(schema.HANDLE_COLLECTION)
    if coll is None or coll.library is not None:
        coll = bpy.data.collections.new(schema.HANDLE_COLLECTION)
    if scene.collection.children.get(coll.name) is None and coll not in scene.collection.children_recursive:
        scene.collection.children.link(coll)
    return coll


def _new_empty(scene, name, location, display, size, color):
    import bpy  # noqa: PLC0415

    ob = bpy.data.objects.new(name, None)
    ob.empty_display_type = display
    ob.empty_display_size = size
    ob.location = [float(x) for x in location]
    ob.color = color
    ob.show_name = False
    ob[schema.MADE_KEY] = True  # goes with the last mirror that uses it (rokeby.reflection.registry)
    _handle_collection(scene).objects.link(ob)
    return ob


def _remove_objects(objs):
    from . import registry  # noqa: PLC0415

    for ob in objs:
        try:
            transaction.remove(ob)
        except (ReferenceError, RuntimeError):
            pass
    # The collection made for the first handle goes with the last one.
    registry.drop_empty_handle_collection()


def _view_from_eye(eye, target):
    from mathutils import Vector  # noqa: PLC0415

    d = Vector(target) - Vector(eye)
    rot = d.to_track_quat("-Z", "Y")
    return {"location": tuple(target), "rotation": tuple(rot), "distance": float(d.length), "perspective": "PERSP"}


def _surface_of(mirror, scene, point):
    dg = _depsgraph(scene)
    m = _surface._finite_matrix(mirror.evaluated_get(dg).matrix_world, f"mirror '{mirror.name}'")
    geo = _surface.read_geometry(mirror, dg, m)
    return _surface.project_to_surface(mirror, dg, geo, _vec3(point, "surface_point"), m), geo, dg


@transaction.atomic(materials=_of_mirrors)
def add_constraint(mirror, surface_point, reflected_point=None, *, eye=None, view=None, name: str = "", kind: str = "REFLECTION", scene=None):
    """Add a reflection (or, ``kind='REFRACTION'``, refraction) constraint to ``mirror`` and
    return its index.

    ``surface_point`` (world space) is projected onto the mirror: the red handle goes there, kept
    on the surface by a Shrinkwrap constraint. The green handle goes to ``reflected_point``; when
    it is None, to where the physically reflected ray from ``eye`` hits the scene (or, when it hits
    nothing, as far along that ray as the eye is from the mirror), so that a fresh constraint
    changes nothing until a handle moves. ``eye`` is the generating eye point (default: the scene
    camera); ``view`` optionally gives the generating 3D view as a dict with location, rotation
    (w, x, y, z), distance and perspective ('PERSP' | 'ORTHO'), used by "return to view".

    A refraction constraint (paper §7.1) has a refracting position and a transmitted direction but
    no refracted position: ``reflected_point`` is then any point along the edited transmitted
    direction e_t. When it is None the green handle goes along the physical t = refract(view, N,
    1/η) (η: the mirror's ``ior``), as far as the eye is from the mirror, so a fresh refraction
    constraint is the identity too. Refused: an eye that sees the back of the surface at p, and
    total internal reflection there (η < 1).
    """
    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    from .props import CONSTRAINT_KINDS  # noqa: PLC0415 - Blender only

    kinds = [item[0] for item in CONSTRAINT_KINDS]
    if kind not in kinds:
        raise RokebyError(f"kind: '{kind}' is not one of {kinds}")
    ior = _inputs.valid_ior(mirror.rokeby.ior) if kind == "REFRACTION" else None
    if eye is None:
        eye = _camera_eye(scene)
    eye = _vec3(eye, "eye")
    sp, geo, dg = _surface_of(mirror, scene, surface_point)
    p = sp.point
    incident = p - eye
    if not np.linalg.norm(incident) > 1e-12 * max(geo.size, 1e-30):
        raise RokebyError("eye: lies on the surface point")
    if kind == "REFRACTION":
        r = _inputs._transmitted(incident / np.linalg.norm(incident), sp.normal, ior, "surface_point")
    else:
        r = reflect(incident / np.linalg.norm(incident), sp.normal)
    r /= np.linalg.norm(r)
    if reflected_point is None and kind == "REFRACTION":
        green = p + r * max(float(np.linalg.norm(incident)), geo.size, 1e-6)
    elif reflected_point is None:
        size = max(geo.size, 1e-6)
        origin = p + sp.normal * (1e-4 * size) * (1.0 if r @ sp.normal >= 0 else -1.0)
        hit, loc, _n, _i, _ob, _m = scene.ray_cast(dg, origin.tolist(), r.tolist())
        if hit:
            green = np.array(loc, dtype=np.float64)
        else:
            green = p + r * max(float(np.linalg.norm(incident)), size)
    else:
        green = _vec3(reflected_point, "reflected_point")
    if not np.linalg.norm(green - p) > 1e-9 * max(geo.size, 1e-30):
        raise RokebyError("reflected_point: coincides with the surface point")
    view = dict(view) if view is not None else _view_from_eye(eye, p)
    k = len(mirror.rokeby.constraints) + 1
    label = name or f"Constraint {k}"
    size = 0.02 * max(geo.size, 1e-6)
    created = []
    try:
        red = _new_empty(scene, f"{mirror.name} {label} surface", p, "SPHERE", size, (1.0, 0.1, 0.1, 1.0))
        created.append(red)
        shrink = red.constraints.new("SHRINKWRAP")
        shrink.name = schema.SHRINKWRAP_NAME
        shrink.target = mirror
        shrink.shrinkwrap_type = "NEAREST_SURFACE"
        role = "transmitted" if kind == "REFRACTION" else "reflected"
        green_ob = _new_empty(scene, f"{mirror.name} {label} {role}", green, "SPHERE", size, (0.1, 1.0, 0.1, 1.0))
        created.append(green_ob)
        item = mirror.rokeby.constraints.add()
        item.name = label
        item.kind = kind
        item.surface_handle = red
        item.target_handle = green_ob
        item.eye = eye.tolist()
        item.view_location = [float(x) for x in view["location"]]
        item.view_rotation = [float(x) for x in view["rotation"]]
        item.view_distance = float(view["distance"])
        item.view_perspective = view.get("perspective", "PERSP")
        mirror.rokeby.active_constraint = len(mirror.rokeby.constraints) - 1
    except Exception:
        _remove_objects(created)
        raise
    return len(mirror.rokeby.constraints) - 1


def _handle_users(scene, ob, skip=None):
    """How many constraints and regions (of any mirror in the file, ``skip`` aside) use ``ob``."""
    from . import registry  # noqa: PLC0415

    n = 0
    for m in registry.mirrors():
        for c in m.rokeby.constraints:
            if c != skip and ob in (c.surface_handle, c.target_handle):
                n += 1
        for rg in m.rokeby.regions:
            if rg != skip and rg.center == ob:
                n += 1
    return n


def _index(collection, index, what):
    if not isinstance(index, (int, np.integer)) or not 0 <= int(index) < len(collection):
        raise RokebyError(f"{what}: index {index!r} is out of range (there are {len(collection)})")
    return int(index)


def _made_here(ob) -> bool:
    from .registry import made_by_addon  # noqa: PLC0415

    try:
        return made_by_addon(ob)
    except ReferenceError:
        return False


@transaction.atomic(materials=_of_mirrors)
def remove_constraint(mirror, index: int, *, delete_handles: bool = True, scene=None):
    """Remove constraint ``index``; its handles are deleted unless another item uses them."""
    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    i = _index(mirror.rokeby.constraints, index, "constraint")
    c = mirror.rokeby.constraints[i]
    handles = [h for h in (c.surface_handle, c.target_handle) if h is not None]
    doomed = [h for h in handles if _handle_users(scene, h, skip=c) == 0 and _made_here(h)] if delete_handles else []
    mirror.rokeby.constraints.remove(i)
    mirror.rokeby.active_constraint = min(mirror.rokeby.active_constraint, max(len(mirror.rokeby.constraints) - 1, 0))
    _remove_objects(doomed)


# The reader modifier of free-form regions lives with the region code (freeform_regions.py), which
# keeps it live: remade when applied or removed, repointed when the vertex group is renamed.
_vertex_group_reader = _freeform.vertex_group_reader


def _ensure_reader(mirror, group):
    _freeform.ensure_reader(mirror, group)
    return _freeform.find_reader(mirror, group)


def _drop_unused_readers(mirror):
    _freeform.drop_unused_readers(mirror)


@transaction.atomic(materials=_of_mirrors)
def add_region(mirror, kind: str = "EUCLIDEAN", *, center=None, radius: float = 1.0, border: float = 0.25, vertex_group: str = "", name: str = "", scene=None):
    """Add a region of interest to ``mirror`` and return its index.

    kind 'EUCLIDEAN': a sphere around ``center`` (a point, or an existing empty, which several
    mirrors may share); 'GEODESIC': a disc over the surface around the surface point nearest
    ``center`` (its empty is kept on the surface); 'FREEFORM': the painted ``vertex_group`` of the
    mirror. ``radius`` and ``border`` are in world units; the border is the smooth step inside the
    radius.
    """
    import bpy  # noqa: PLC0415

    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    if kind not in ("EUCLIDEAN", "GEODESIC", "FREEFORM"):
        raise RokebyError(f"kind: '{kind}' is not one of EUCLIDEAN, GEODESIC, FREEFORM")
    for what, x in (("radius", radius), ("border", border)):
        if not (np.isfinite(x) and x >= 0):
            raise RokebyError(f"{what}: must be finite and >= 0, got {x}")
    created = []
    k = len(mirror.rokeby.regions) + 1
    label = name or f"Region {k}"
    try:
        centre_ob = None
        if kind == "FREEFORM":
            have = ", ".join(f"'{vg.name}'" for vg in mirror.vertex_groups)
            if not isinstance(vertex_group, str) or not vertex_group:
                raise RokebyError(
                    f"vertex_group: a free-form region needs the name of a vertex group of mirror '{mirror.name}' "
                    + (f"(it has {have})" if have else "(it has none: paint one first, e.g. in Weight Paint mode)"))
            if mirror.vertex_groups.get(vertex_group) is None:
                raise RokebyError(f"vertex_group: mirror '{mirror.name}' has no vertex group '{vertex_group}'" + (f" (it has {have})" if have else " (it has none)"))
        elif isinstance(center, bpy.types.Object):
            centre_ob = center
        else:
            if center is None:
                center = tuple(scene.cursor.location)
            point = _vec3(center, "center")
            if kind == "GEODESIC":
                point = _surface_of(mirror, scene, point)[0].point
            display = "SPHERE" if kind == "EUCLIDEAN" else "CIRCLE"
            centre_ob = _new_empty(scene, f"{mirror.name} {label} centre", point, display, max(radius, 1e-6), (0.3, 0.6, 1.0, 1.0))
            created.append(centre_ob)
            if kind == "GEODESIC":
                shrink = centre_ob.constraints.new("SHRINKWRAP")
                shrink.name = schema.SHRINKWRAP_NAME
                shrink.target = mirror
                shrink.shrinkwrap_type = "NEAREST_SURFACE"
        if kind == "FREEFORM":
            _ensure_reader(mirror, vertex_group)
        item = mirror.rokeby.regions.add()
        item.name = label
        item.kind = kind
        item.radius = float(radius)
        item.border = float(border)
        item.vertex_group = vertex_group
        if kind == "FREEFORM":
            item.vertex_group_index = mirror.vertex_groups.find(vertex_group)
            _freeform.remember_groups(mirror)
        item.center = centre_ob
        mirror.rokeby.active_region = len(mirror.rokeby.regions) - 1
    except Exception:
        _remove_objects(created)
        raise
    _state.mark_dirty(mirror)
    return len(mirror.rokeby.regions) - 1


@transaction.atomic(materials=_of_mirrors)
def remove_region(mirror, index: int, *, delete_center: bool = True, scene=None):
    """Remove region ``index`` (and its centre empty when the add-on made it and nothing else
    uses it; an object of the artist's own given as ``center`` stays)."""
    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    i = _index(mirror.rokeby.regions, index, "region")
    rg = mirror.rokeby.regions[i]
    doomed = [rg.center] if (delete_center and rg.center is not None and _handle_users(scene, rg.center, skip=rg) == 0
                             and _made_here(rg.center)) else []
    mirror.rokeby.regions.remove(i)
    mirror.rokeby.active_region = min(mirror.rokeby.active_region, max(len(mirror.rokeby.regions) - 1, 0))
    _drop_unused_readers(mirror)
    _remove_objects(doomed)
    _state.mark_dirty(mirror)


def _other_mirrors_of_mesh(mirror) -> list:
    """The other mirrors using ``mirror``'s mesh (Alt+D copies, Ctrl+L ▸ Link Object Data)."""
    import bpy  # noqa: PLC0415

    me = mirror.data
    if me is None or not _surface.shares_mesh(mirror):
        return []
    return [ob for ob in bpy.data.objects if ob != mirror and ob.data == me and ob.rokeby.is_mirror]


@transaction.atomic(materials=_of_mirrors)
def remove_mirror(mirror, *, scene=None):
    """Stop editing ``mirror``: its constraints, regions, handles and field go, and the file is
    left as it was before ``add_mirror``: its materials' node trees as they were (unless another
    mirror still edits them), the "Rokeby Handles" collection removed once empty, the add-on's
    node groups removed once nothing uses them. Handles, centres and data another mirror uses
    stay: a mesh shared with other mirrors keeps its attributes (it holds no field of this one:
    that lives in this mirror's own carrier, removed here)."""
    from . import registry  # noqa: PLC0415
    from .render import rendering  # noqa: PLC0415

    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    materials = rendering.edited_materials(mirror)
    while len(mirror.rokeby.constraints):
        remove_constraint(mirror, len(mirror.rokeby.constraints) - 1, scene=scene)
    while len(mirror.rokeby.regions):
        remove_region(mirror, len(mirror.rokeby.regions) - 1, scene=scene)
    if not _other_mirrors_of_mesh(mirror):
        _carriers.strip_field(mirror.data)
    _carriers.remove_carrier(mirror)
    mirror.rokeby.is_mirror = False
    # Its materials come back as they were (unless another mirror still edits them), also when
    # the render nodes were installed before the file was loaded (nothing synced them yet).
    registry.release(registry.mirrors(), materials=materials)
    rendering.sync_scene(scene)


# Re-entrance guard of evaluate(frame=...): set while its frame_set runs the frame handlers.
_SETTING_FRAME = False
# Blender's frame range (MAXFRAME).
_MAX_FRAME = 1048574


def evaluate(scene=None, frame=None, *, force: bool = False) -> "dict[str, MirrorReport]":
    """Bring every mirror of ``scene`` up to date (at ``frame`` when given, which may be
    fractional) and return a report per mirror. Only mirrors whose inputs changed are recomputed,
    unless ``force``. Never raises for a bad mirror: its report says what is wrong."""
    from . import guard  # noqa: PLC0415

    global _SETTING_FRAME
    scene = _scene(scene)
    with guard.suspended():
        if frame is not None:
            try:
                f = float(frame)
            except (TypeError, ValueError):
                raise TypeError(f"frame: expected a number, got {frame!r}") from None
            if not np.isfinite(f) or abs(f) > _MAX_FRAME:
                raise RokebyError(f"frame: must be finite and within ±{_MAX_FRAME}, got {frame}")
            whole = int(np.floor(f))
            if scene.frame_current == whole and abs(float(scene.frame_subframe) - (f - whole)) <= 1e-6:
                # Already there (e.g. a frame_change_post handler asking for the current frame):
                # no frame_set, which would run the frame-change handlers again and recurse.
                # Setting the frame re-applies its animation in the depsgraph update below.
                scene.frame_current = whole
            else:
                if _SETTING_FRAME:
                    raise RokebyError(f"frame: evaluate(frame={frame}) was called while evaluate is changing the frame "
                                      "(from a frame-change handler?); call evaluate() without a frame there")
                _SETTING_FRAME = True
                try:
                    scene.frame_set(whole, subframe=f - whole)
                finally:
                    _SETTING_FRAME = False
        # Meshes a script edited since the last look (foreach_set, bmesh.to_mesh) are re-read:
        # with the handlers suspended, nothing else tells the evaluator.
        edited = _ev.edited_meshes(scene)
        dg = _depsgraph(scene)
        reports = _ev.evaluate_scene(scene, dg, force=force, geometry_changed=edited, all_geometry=frame is not None)
        from .render import rendering  # noqa: PLC0415

        # Final renders follow: render nodes in every edited material (see rokeby.reflection.render.rendering).
        rendering.sync_scene(scene, reports, force=force)
        return reports


def report(mirror) -> "MirrorReport | None":
    """The last evaluation report of ``mirror`` (None before its first evaluation)."""
    return _state.report_of(mirror)


def field(mirror) -> "np.ndarray | None":
    """The last computed rotation field of ``mirror``: (V, 4) quaternions (x, y, z, w)."""
    return _state.rotations_of(mirror)


def stored_field(mirror) -> "np.ndarray | None":
    """The rotation vectors stored for ``mirror`` (the view-independent form, eq. 7 towards I): per
    vertex of its mesh, or of its evaluated mesh when a modifier changes the vertex count or the
    mesh is shared with other objects (then held by its own field carrier)."""
    carrier = _carriers.carrier_of(mirror)
    return _attributes.read_attribute(carrier if carrier is not None else mirror)


def refraction_field(mirror) -> "np.ndarray | None":
    """The last computed refraction field of ``mirror`` as (V, 4) quaternions (x, y, z, w), or
    None while it has no usable refraction constraint."""
    return _state.refractions_of(mirror)


def stored_refraction(mirror) -> "np.ndarray | None":
    """The rotation vectors (V, 3) of the refraction field stored in the mesh attribute
    ``rokeby_refraction``, or in the mirror's field carrier as for ``stored_field`` (None when
    the mirror has no refraction constraint)."""
    carrier = _carriers.carrier_of(mirror)
    return _attributes.read_attribute(carrier if carrier is not None else mirror, schema.REFRACTION_ATTRIBUTE)


def set_ior(mirror, ior: float):
    """Set the index of refraction refraction constraints and the render nodes use for ``mirror``
    (outside → inside; glass about 1.45–1.5). Must be finite and > 0."""
    _inputs.require_mirror(mirror)
    mirror.rokeby.ior = _inputs.valid_ior(ior)


def ior_from_material(mirror, material=None) -> float:
    """Take the mirror's IOR from its material: the IOR input of the first Glass, Refraction or
    Principled BSDF (with transmission) found in ``material`` (default: the edited materials in
    order). The IOR must be a plain value, not linked. Returns the IOR now set."""
    from .render import refraction  # noqa: PLC0415

    _inputs.require_mirror(mirror)
    materials = [material] if material is not None else edited_materials(mirror)
    problems = []
    for mat in materials:
        try:
            ior = refraction.material_ior(mat)
        except RokebyError as exc:
            problems.append(str(exc))
            continue
        if ior is not None:
            set_ior(mirror, ior)
            return mirror.rokeby.ior
    names = ", ".join(f"'{m.name}'" for m in materials if m is not None) or "none"
    raise RokebyError("material: no Glass, Refraction or transmissive Principled BSDF with an IOR value in " + names + ("; " + "; ".join(problems) if problems else ""))


def stats() -> dict:
    """How often mirrors were checked, recomputed or skipped (nothing had changed)."""
    return _state.stats()


def reset_stats():
    _state.reset_stats()


def edited_materials(mirror) -> list:
    """The materials whose reflections are edited: every material of the mirror unless a
    subset was chosen with ``set_edited_materials``."""
    from .render import rendering  # noqa: PLC0415

    _inputs.require_mirror(mirror)
    return rendering.edited_materials(mirror)


def set_edited_materials(mirror, materials=None):
    """Edit the reflections of ``materials`` only (None: all of the mirror's materials)."""
    _inputs.require_mirror(mirror)
    s = mirror.rokeby
    if materials is None:
        s.all_materials = True
        s.materials.clear()
        return
    own = {slot.material for slot in mirror.material_slots if slot.material is not None}
    chosen = []
    for mat in materials:
        if mat not in own:
            raise RokebyError(f"materials: '{getattr(mat, 'name', mat)}' is not a material of mirror '{mirror.name}'")
        if mat not in chosen:
            chosen.append(mat)
    s.materials.clear()
    for mat in chosen:
        s.materials.add().material = mat
    s.all_materials = False


@transaction.atomic(materials=_of_mirrors)
def install_render_nodes(mirror) -> int:
    """Make final renders (Cycles; EEVEE uses the same nodes) show the edit now. Evaluation does
    this by itself for every mirror with a constraint while its ``render_edits`` is on (the
    default; this call turns it on): see rokeby.reflection.render.rendering. In the mirror's
    ``render_mode``: RAY_TRACED — the node group "Rokeby Edited Normal" feeds the edited normal
    to the specular BSDFs of every edited material (see rokeby.reflection.render.shading); REFLECTION_MAP — their
    specular lobe becomes a lookup of the captured map in the edited direction (rokeby.reflection.render.reflmap;
    capture it first with ``capture_reflection_map``). The other mode's nodes are taken out.
    Returns how many BSDF inputs (ray traced) or BSDFs (reflection map) were rewired. In both
    modes "Rokeby Edited Refraction Normal" feeds Refraction BSDFs and split Glass BSDFs first
    (rokeby.reflection.render.refraction; counted too), so a split Glass's reflection part is edited as well."""
    from .render import rendering  # noqa: PLC0415

    _inputs.require_mirror(mirror)
    count = rendering.install(mirror)
    mirror.rokeby.render_edits = True
    return count


@transaction.atomic(materials=_of_mirrors)
def remove_render_nodes(mirror) -> int:
    """Take the render nodes out of the mirror's materials again and turn its ``render_edits``
    off (so evaluation does not put them back); returns from how many materials they went. On an
    object that is no longer a mirror (after Remove Mirror) it takes out whatever nodes are left in
    its materials that no other mirror keeps."""
    from .render import rendering  # noqa: PLC0415

    _inputs.check_mirror(mirror)
    mats = {slot.material for slot in mirror.material_slots if slot.material is not None}
    if not mirror.rokeby.is_mirror:
        # A former mirror (Remove Mirror): its materials lose nodes no remaining mirror keeps.
        from . import registry  # noqa: PLC0415

        kept = {mat for ob in registry.mirrors() if ob.type == "MESH" and rendering.kept(ob) for mat in rendering.edited_materials(ob)}
        return sum(rendering.uninstall_material(mat) for mat in mats if mat not in kept)
    # Each material is checked before anything changes (rokeby.reflection.render.shading refuses a split BSDF it
    # cannot rebuild); render_edits goes off once the nodes are out.
    count = sum(rendering.uninstall_material(mat) for mat in mats)
    mirror.rokeby.render_edits = False
    return count


@_cancellable
def capture_reflection_map(mirror, *, resolution=None, samples=None, storage: str = "AUTO", scene=None):
    """Capture (or refresh) the reflection map of ``mirror``: a Cycles equirectangular panorama
    from its bounding-box centre (or ``rokeby.map_origin``) with the mirror hidden, plus blurred
    levels for rough materials. ``resolution``: width, a power of two (height = width / 2;
    default: the mirror's ``map_resolution``); ``samples``: Cycles samples (default
    ``map_samples``); ``storage``: 'AUTO' (an OpenEXR cache in //rokeby_maps/ when the .blend is
    saved, else packed), 'FILE' or 'PACK'. Materials already in reflection-map mode show the new
    map at once. Returns the image. See rokeby.reflection.render.reflmap."""
    from .render import reflmap  # noqa: PLC0415

    return reflmap.capture(mirror, resolution=resolution, samples=samples, storage=storage, scene=scene)


def capture_preview_scene(mirror, *, width: int = 256, samples: int = 16, denoise: bool = False, scene=None):
    """Capture now the scene the viewport preview of ``mirror`` looks its edited reflection up in
    (the preview otherwise captures by itself when what it shows changes, never for handle moves):
    a Cycles equirectangular panorama from the mirror's centre with the mirror hidden from camera
    rays, and the distance per texel. ``width``: a power of two (height = width / 2). Returns the
    capture (``texels`` (H, W, 4): linear RGB and 1/distance, ``origin``, ``seconds``,
    ``nbytes``); it lives for the session, never in the .blend. See
    rokeby.reflection.viewport.scene_env."""
    from .viewport import scene_env  # noqa: PLC0415

    _inputs.require_mirror(mirror)
    return scene_env.capture(mirror, _scene(scene), width=width, samples=samples, denoise=denoise)


def reflection_map(mirror):
    """The captured lat-long image of ``mirror`` (Blender's equirectangular convention:
    ``rokeby.reflection.render.reflmap.direction_to_uv``), or None."""
    from .render import reflmap  # noqa: PLC0415

    _inputs.require_mirror(mirror)
    return reflmap.image_for(mirror)


def freeze(mirror, frozen: bool = True, *, eye=None):
    """Freeze (or unfreeze) ``mirror``: while frozen, reflected directions are evaluated from a
    fixed eye — ``eye`` if given, else the active constraint's generating eye — instead of
    following the camera."""
    _inputs.require_mirror(mirror)
    s = mirror.rokeby
    if frozen:
        if eye is None:
            if not len(s.constraints):
                raise RokebyError("eye: not given and the mirror has no constraint to take a generating eye from")
            eye = tuple(s.constraints[min(s.active_constraint, len(s.constraints) - 1)].eye)
        eye = _vec3(eye, "eye").tolist()
        s.freeze = True  # its update stores the camera's eye; the chosen one replaces it
        s.freeze_eye = eye
    else:
        s.freeze = False


def constraint_view(mirror, index: "int | None" = None) -> dict:
    """The generating view of a constraint (default: the active one): location, rotation
    (w, x, y, z), distance, perspective and eye, as stored when it was made."""
    _inputs.require_mirror(mirror)
    s = mirror.rokeby
    i = _index(s.constraints, s.active_constraint if index is None else index, "constraint")
    c = s.constraints[i]
    return {
        "location": tuple(c.view_location),
        "rotation": tuple(c.view_rotation),
        "distance": float(c.view_distance),
        "perspective": c.view_perspective,
        "eye": tuple(c.eye),
    }


def edited_reflections(mirror, eye=None, *, scene=None) -> np.ndarray:
    """Edited reflection directions e(q) = R(q) r(q) at the mirror's vertices (world space), with
    r(q) reflected from the frozen eye when the mirror is frozen, else from ``eye`` (default: the
    scene camera). This is what a renderer shows at each vertex."""
    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    s = mirror.rokeby
    if s.freeze:
        eye = tuple(s.freeze_eye)
    elif eye is None:
        eye = _camera_eye(scene)
    eye = _vec3(eye, "eye")
    evaluate(scene)
    st = _state._STATE.get(mirror.session_uid)
    if st is None or st.geometry is None or st.view_parts is None:
        rep = report(mirror)
        raise RokebyError(f"mirror '{mirror.name}' has no field: {rep.summary() if rep else 'not evaluated'}")
    geo = st.geometry
    incident = geo.vertices.astype(np.float64) - eye
    incident /= np.maximum(np.linalg.norm(incident, axis=1, keepdims=True), 1e-300)
    r = reflect(incident, geo.normals.astype(np.float64))
    # Eq. 7 per vertex for this eye, as the render nodes form it (rokeby_core's view_blend).
    parts, ramp = st.view_parts
    return native.view_blend(parts, r.astype(np.float32), ramp=ramp)


# --- highlights (paper §7.1, Figs. 6 and 7) --------------------------------------------------


def _light_point(light, p: np.ndarray, far: float) -> np.ndarray:
    """Where ``light`` is as seen from the points ``p`` (..., 3): its position, or for a sun the
    points ``far`` away against its direction of travel."""
    m = _surface._finite_matrix(light.matrix_world, f"light '{light.name}'")
    if light.data.type == "SUN":
        towards = m[:3, 2]  # a sun shines along its local −Z
        return p + towards / np.linalg.norm(towards) * far
    return np.broadcast_to(m[:3, 3], np.shape(p)).copy()


def physical_highlight(mirror, light, eye=None, *, scene=None) -> np.ndarray:
    """The point of ``mirror`` (world space) where ``light``'s highlight sits for a mirror-like
    BRDF seen from ``eye`` (default: the scene camera): the visible, lit vertex whose reflected view
    ray points most nearly at the light, refined to the surface point where it points at it."""
    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    if light is None or getattr(light, "type", None) != "LIGHT":
        raise RokebyError(f"light: '{getattr(light, 'name', light)}' is not a light object")
    if eye is None:
        eye = _camera_eye(scene)
    eye = _vec3(eye, "eye")
    geo = mesh_arrays(mirror, _depsgraph(scene))  # also brings the light's matrix up to date
    v = geo.vertices.astype(np.float64)
    n = geo.normals.astype(np.float64)
    to_light = _light_point(light, v, 1.0) - v
    to_light /= np.maximum(np.linalg.norm(to_light, axis=1, keepdims=True), 1e-300)
    incident = v - eye
    incident /= np.maximum(np.linalg.norm(incident, axis=1, keepdims=True), 1e-300)
    r = reflect(incident, n)
    ok = ((n * -incident).sum(1) > 0) & ((n * to_light).sum(1) > 0)
    if not ok.any():
        raise RokebyError(f"light '{light.name}': no part of mirror '{mirror.name}' both faces the eye and is lit")
    score = np.where(ok, (r * to_light).sum(1), -np.inf)
    best = int(np.argmax(score))
    return _refine_highlight(geo, light, eye, best)


def _refine_highlight(geo, light, eye, vertex: int) -> np.ndarray:
    """The surface point (inside the triangles around ``vertex`` and their neighbours) where the
    reflected view ray points at the light, with the smooth (interpolated) normal the renderers
    shade with: a zooming barycentric grid search per triangle, vectorised. A highlight
    constraint placed there is neutral (its r and e agree to well under 0.01°)."""
    tri = geo.triangles
    ring = np.flatnonzero((tri == vertex).any(1))
    near = np.unique(tri[ring])
    cand = tri[np.flatnonzero(np.isin(tri, near).any(1))].astype(np.int64)  # (T, 3)
    verts = geo.vertices.astype(np.float64)[cand]  # (T, 3, 3)
    nrms = geo.normals.astype(np.float64)[cand]

    def score(bary):  # bary (T, G, 3) → (T, G), and the points
        p = np.einsum("tgk,tkj->tgj", bary, verts)
        n = np.einsum("tgk,tkj->tgj", bary, nrms)
        n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
        i = p - eye
        i /= np.maximum(np.linalg.norm(i, axis=-1, keepdims=True), 1e-300)
        r = i - 2.0 * (i * n).sum(-1, keepdims=True) * n
        to_light = _light_point(light, p, 1.0) - p
        to_light /= np.maximum(np.linalg.norm(to_light, axis=-1, keepdims=True), 1e-300)
        lit = ((n * -i).sum(-1) > 0) & ((n * to_light).sum(-1) > 0)
        return np.where(lit, (r * to_light).sum(-1), -np.inf), p

    g = np.linspace(-1.0, 1.0, 9)
    du, dv = (x.ravel() for x in np.meshgrid(g, g))
    centre = np.full((len(cand), 2), 1.0 / 3.0)  # (b1, b2); b0 = 1 − b1 − b2
    step = 0.5
    for _ in range(24):
        b12 = centre[:, None, :] + step * np.stack([du, dv], -1)[None]
        b12 = np.clip(b12, 0.0, 1.0)
        b12 = b12 / np.maximum(b12.sum(-1, keepdims=True), 1.0)  # back into the triangle
        bary = np.concatenate([1.0 - b12.sum(-1, keepdims=True), b12], -1)
        sc, _p = score(bary)
        centre = b12[np.arange(len(cand)), np.argmax(sc, axis=1)]
        step *= 0.5
    bary = np.concatenate([1.0 - centre.sum(-1, keepdims=True), centre], -1)[:, None, :]
    sc, p = score(bary)
    t = int(np.argmax(sc[:, 0]))
    return p[t, 0]


def add_highlight_constraint(mirror, light, surface_point=None, *, eye=None, name: str = "", scene=None) -> int:
    """Highlight editing: a constraint whose green handle is ``light`` (parented to it, so it
    follows the light). Its red handle goes to ``surface_point``, by default to where the light's
    highlight physically is (``physical_highlight``), so a fresh one changes nothing; drag the red
    handle to move the highlight, add a second one to stretch it. Only the specular lobe changes:
    shadows stay where they are (the shading normal does not move shadow rays). Returns the index."""
    scene = _scene(scene)
    _inputs.require_mirror(mirror)
    if surface_point is None:
        surface_point = physical_highlight(mirror, light, eye, scene=scene)
    sp, geo, _dg = _surface_of(mirror, scene, surface_point)
    target = _light_point(light, sp.point, 1e3 * max(geo.size, 1e-6))
    index = add_constraint(mirror, sp.point, target, eye=eye, name=name or f"Highlight {light.name}", scene=scene)
    green = mirror.rokeby.constraints[index].target_handle
    green.parent = light  # keeps its world location: the light's current matrix is undone
    green.matrix_parent_inverse = light.matrix_world.inverted()
    mirror.rokeby.constraints[index].light_name = light.name
    green.empty_display_type = "SPHERE"
    return index
