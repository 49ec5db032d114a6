"""Rokeby's scene model: PropertyGroups saved in the .blend.

Every mirror is a mesh object with ``obj.rokeby.is_mirror`` set. Its constraints and regions live in
collections on that object; the handles are ordinary empties, so they move, parent, constrain and
keyframe like any object. Every number here is animatable (Blender's default for properties of ID
data), so radii, borders and the freeze eye can be keyed on the timeline.

Property updates only mark the scene for re-evaluation; the work happens in ``rokeby.reflection.evaluate``.
"""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)
from bpy.types import PropertyGroup

from ..core import schema

METRICS = [
    ("EUCLIDEAN", "Euclidean", "Straight-line distance to each constraint (fast; works across several objects)", 0),
    ("GEODESIC", "Geodesic", "Distance over the surface: weights do not leak across gaps and folds", 1),
]
GEODESIC_METHODS = [
    # Blender stores the item number: HEAT and DIJKSTRA keep the numbers they had as positions.
    # The property's default stays HEAT (a file saved without the setting means heat); new mirrors
    # get DENSE_GRAPH from api.add_mirror. GRAPH stays for the files saved with it: its distances
    # are those it always gave.
    ("HEAT", "Smooth (heat)", "Heat method on an intrinsic Delaunay triangulation, exact next to each handle: about 1-2% error; factorised once per mesh. Not for meshes with open seams (unwelded duplicate vertices, as in the Utah teapot): its distances cross them, the Settings panel says so", "", 0),
    ("DIJKSTRA", "Fast (Dijkstra)", "Shortest paths along edges, as in the paper, exact next to each handle: fastest, over-estimates by 5-10%", "", 1),
    ("EXACT", "Exact", "Exact polyhedral geodesics (window propagation): no approximation error; seconds per handle on meshes of tens of thousands of faces", "", 2),
    ("GRAPH", "Graph (coarse)", "The coarser geodesic graph of earlier versions (each vertex linked to its 32 nearest): under 0.6% error; kept so that files saved with it render as they did", "", 3),
    ("DENSE_GRAPH", "Accurate (default)", "Dijkstra on a dense graph of exact local geodesics (saddle vertex graph, each vertex linked to its 96 nearest, redundant links pruned), exact next to each handle: under 0.25% error; built once per mesh (seconds), then queries about as fast as the heat method (faster on large meshes)", "", 4),
]
POLAR_METHODS = [
    ("EXACT", "Exact", "Rotational factor by an SVD in double precision", 0),
    ("FAST", "Fast", "Newton iteration on SO(3), warm-started and verified; about twice as fast", 1),
]
REGION_KINDS = [
    ("EUCLIDEAN", "Euclidean", "A sphere around an empty: radius and border in world units; may span several objects", "SPHERE", 0),
    ("GEODESIC", "Geodesic", "A disc on the surface around a surface point (an empty snapped to the mirror)", "MESH_CIRCLE", 1),
    ("FREEFORM", "Free-form", "A painted vertex group, with a smooth border measured over the surface", "GROUP_VERTEX", 2),
]


def _touch(self, context):
    """Property update: the evaluator compares fingerprints, so a tag is all that is needed."""
    from . import mirror_state

    mirror_state.mark_dirty(self.id_data)


def _region_radius_changed(self, context):
    if self.center is not None and self.center.type == "EMPTY" and self.kind == "EUCLIDEAN":
        # The sphere the artist sees is the region's outer edge.
        if abs(self.center.empty_display_size - self.radius) > 1e-9:
            self.center.empty_display_size = self.radius
    _touch(self, context)


def _is_mirror_changed(self, context):
    # A mirror made now (by the API, the operator or a script setting the flag) is current data;
    # only files saved before schema.DATA_VERSION existed load with 0 (handlers.on_load migrates them).
    if self.is_mirror and self.data_version < schema.DATA_VERSION:
        self.data_version = schema.DATA_VERSION
    from . import pointers

    pointers.invalidate()  # the add-on's registry of mirrors (no scan of scene.objects per update)
    _touch(self, context)


def _freeze_changed(self, context):
    """Freeze from any entry point (sidebar toggle, a script setting the property, the operator,
    the shortcut) stores the eye it freezes at, as ``api.freeze`` does: the active constraint's
    generating eye, else the scene camera's position. ``api.freeze(eye=...)`` sets its own after."""
    if self.freeze:
        scene = getattr(context, "scene", None) or bpy.context.scene
        cam = scene.camera if scene is not None else None
        if len(self.constraints):
            self.freeze_eye = tuple(self.constraints[min(self.active_constraint, len(self.constraints) - 1)].eye)
            self.freeze_eye_set = True
        elif cam is not None:
            self.freeze_eye = tuple(cam.matrix_world.translation)
            self.freeze_eye_set = True
    _touch(self, context)


def _freeze_eye_changed(self, context):
    self.freeze_eye_set = True
    _touch(self, context)


class RokebyMaterialRef(PropertyGroup):
    material: PointerProperty(type=bpy.types.Material, name="Material", update=_touch)


RENDER_MODES = [
    ("RAY_TRACED", "Ray traced", "Edited normals on the specular BSDFs: exact parallax, occlusion and self-reflection (slower, noisier when rough)", 0),
    ("REFLECTION_MAP", "Reflection map", "A panorama captured from the mirror's centre, looked up in the edited direction (paper §6.3): fast and noise-free, but no parallax or self-reflection", 1),
]
EYE_SOURCES = [
    ("CAMERA", "Scene Camera", "Constraints' reflected directions r are taken from the render eye (the scene camera, or the frozen eye), so renders hit every green handle from the camera", "CAMERA_DATA", 0),
    ("CREATION", "View at Creation", "Each constraint keeps the eye of the view it was made from (Return to View shows it); renders from elsewhere miss its green handle by the angle the status reports", "VIEW3D", 1),
]
# schema.DATA_VERSION is saved with each mirror: 0 = made before these settings existed (load_post
# migrates it), 1 = now.

MAP_RESOLUTIONS = [(str(w), f"{w} × {w // 2}", f"Capture a {w} × {w // 2} panorama", i) for i, w in enumerate((256, 512, 1024, 2048))]


class RokebyImageRef(PropertyGroup):
    image: PointerProperty(type=bpy.types.Image, name="Image")


CONSTRAINT_KINDS = [
    ("REFLECTION", "Reflection", "The green handle is what should be seen reflected at the red handle", "MOD_MIRROR", 0),
    ("REFRACTION", "Refraction", "The green handle gives the edited transmitted direction at the red handle (paper §7.1: a direction, no refracted position)", "LIGHT_SUN", 1),
]


class RokebyConstraint(PropertyGroup):
    """One constraint: the red handle on the mirror and the green handle at what should be seen
    reflected there (REFLECTION) or along the edited transmitted direction (REFRACTION), with the
    view it was made from."""

    enabled: BoolProperty(name="Enabled", default=True, update=_touch)
    kind: EnumProperty(name="Kind", items=CONSTRAINT_KINDS, default="REFLECTION", update=_touch)
    surface_handle: PointerProperty(
        type=bpy.types.Object,
        name="Surface handle",
        description="Red empty on the reflecting surface (the point p of the constraint)",
        update=_touch,
    )
    target_handle: PointerProperty(
        type=bpy.types.Object,
        name="Reflected handle",
        description="Green empty at the point that should appear reflected at the surface handle",
        update=_touch,
    )
    eye: FloatVectorProperty(
        name="Generating eye",
        description="Eye point of the view the constraint was made from; its reflected direction r is computed from here",
        size=3,
        subtype="TRANSLATION",
        update=_touch,
    )
    light_name: StringProperty(
        name="Light",
        description="Highlight constraints: the light the green handle follows (it is parented to it)",
        update=_touch,
    )
    view_location: FloatVectorProperty(name="View pivot", size=3, subtype="TRANSLATION")
    view_rotation: FloatVectorProperty(name="View rotation", size=4, subtype="QUATERNION", default=(1.0, 0.0, 0.0, 0.0))
    view_distance: FloatProperty(name="View distance", default=10.0, min=0.0)
    view_perspective: EnumProperty(
        name="View projection",
        items=[("PERSP", "Perspective", "", 0), ("ORTHO", "Orthographic", "", 1)],
        default="PERSP",
    )


class RokebyRegion(PropertyGroup):
    """A region of interest: only constraints inside act there (eq. 7), with a smooth border."""

    enabled: BoolProperty(name="Enabled", default=True, update=_touch)
    kind: EnumProperty(name="Kind", items=REGION_KINDS, default="EUCLIDEAN", update=_touch)
    center: PointerProperty(
        type=bpy.types.Object,
        name="Centre",
        description="Empty at the region's centre (Euclidean: anywhere; geodesic: snapped to the mirror's surface)",
        update=_region_radius_changed,
    )
    radius: FloatProperty(name="Radius", default=1.0, min=0.0, subtype="DISTANCE", update=_region_radius_changed)
    border: FloatProperty(
        name="Border",
        description="Width of the smooth step inside the radius, from full effect to none",
        default=0.25,
        min=0.0,
        subtype="DISTANCE",
        update=_touch,
    )
    vertex_group: StringProperty(name="Vertex group", description="Painted weights of a free-form region (followed when the group is renamed)", update=_touch)
    # Where the group was at the last update: with the mirror's vertex_group_names, how a rename
    # is told from a deletion (vertex groups have no pointer). -1: not known yet.
    vertex_group_index: IntProperty(name="Vertex group index", default=-1, options={"HIDDEN"})


class RokebyMirror(PropertyGroup):
    """Per-object settings: whether the object is an edited mirror, how distances are measured,
    which materials are edited, and its constraints and regions."""

    is_mirror: BoolProperty(name="Mirror", default=False, update=_is_mirror_changed)
    enabled: BoolProperty(name="Enabled", description="Apply this mirror's reflection edits", default=True, update=_touch)
    metric: EnumProperty(name="Distance", items=METRICS, default="EUCLIDEAN", update=_touch)
    geodesic_method: EnumProperty(name="Geodesic method", items=GEODESIC_METHODS, default="HEAT", update=_touch)
    polar: EnumProperty(name="Polar decomposition", items=POLAR_METHODS, default="FAST", update=_touch)
    freeze: BoolProperty(
        name="Freeze",
        description="Reflections stop following the camera: reflected directions are evaluated from the frozen eye",
        default=False,
        update=_freeze_changed,
    )
    freeze_eye: FloatVectorProperty(name="Frozen eye", size=3, subtype="TRANSLATION", update=_freeze_eye_changed)
    freeze_eye_set: BoolProperty(name="Frozen eye stored", default=False, options={"HIDDEN"})
    render_edits: BoolProperty(
        name="Edit Final Renders",
        description="Final renders (F12, Cycles and EEVEE) show this mirror's edits: the render nodes are installed and kept in sync with its materials automatically",
        default=True,
        update=_touch,
    )
    eye_source: EnumProperty(
        name="Generating Eye",
        description="Where each constraint's physical reflected direction is seen from",
        items=EYE_SOURCES,
        default="CAMERA",
        update=_touch,
    )
    data_version: IntProperty(name="Data version", default=0, options={"HIDDEN"})
    # The names of the object's vertex groups at the last update (JSON list), kept while it has
    # free-form regions: a rename shows as one name replaced at the same index.
    vertex_group_names: StringProperty(name="Vertex group names", options={"HIDDEN"})
    field_carrier: PointerProperty(
        type=bpy.types.Object,
        name="Field carrier",
        description="Mesh holding the field on the evaluated (e.g. subdivided) surface, read by the 'Rokeby field' modifier",
        options={"HIDDEN"},
    )
    show_preview: BoolProperty(
        name="Show in Viewport",
        description="Draw this mirror's edited reflections in the viewport preview (when the preview is on)",
        default=True,
    )
    ior: FloatProperty(
        name="IOR",
        description="Index of refraction of the mirror's material (outside → inside) used by refraction constraints and the render nodes; keep it equal to the Glass/Refraction BSDF's IOR",
        default=1.45,
        min=0.0,
        soft_min=1.0,
        soft_max=3.0,
        precision=3,
        update=_touch,
    )
    all_materials: BoolProperty(name="All materials", description="Edit the reflections of every material of the mirror", default=True, update=_touch)
    materials: CollectionProperty(type=RokebyMaterialRef, name="Edited materials")
    constraints: CollectionProperty(type=RokebyConstraint, name="Constraints")
    active_constraint: IntProperty(name="Active constraint", default=0, min=0)
    regions: CollectionProperty(type=RokebyRegion, name="Regions")
    active_region: IntProperty(name="Active region", default=0, min=0)
    # Reflection-map mode (rokeby.reflection.render.reflmap); captured on demand, not re-evaluated.
    render_mode: EnumProperty(name="Render mode", items=RENDER_MODES, default="RAY_TRACED")
    map_resolution: EnumProperty(name="Map resolution", description="Width of the captured panorama (height is half): sharper reflections against capture time", items=MAP_RESOLUTIONS, default="512")
    map_samples: IntProperty(name="Capture samples", description="Cycles samples of the capture", default=32, min=1, soft_max=1024)
    map_origin: PointerProperty(type=bpy.types.Object, name="Capture point", description="Capture the map from this object's location (default: the centre of the mirror's bounding box)")
    map_image: PointerProperty(type=bpy.types.Image, name="Reflection map", description="The captured lat-long panorama (Blender's equirectangular convention)")
    map_levels: CollectionProperty(type=RokebyImageRef, name="Blurred levels")
    map_fingerprint: StringProperty(name="Captured scene", options={"HIDDEN"})
    # Stable per-mirror id in the map's file names (rokeby.reflection.render.reflmap.map_stem): unique where names
    # are not (``Ball.L`` / ``Ball_L``); a copy that inherits it gets its own on its first capture.
    map_id: StringProperty(name="Map id", options={"HIDDEN"})
    map_capture_seconds: FloatProperty(name="Capture time", subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE", min=0.0)


# --- Shadow edits (rokeby.shadow): links between objects, by pointer -------------------------------
# Renaming a caster, a light or anything derived keeps every link; a new object under an old
# name takes nothing over. Files saved before this (names in custom properties) are migrated at
# load (shadow.migrate, called by handlers.migrate_file).
SHADOW_ROLES = [
    ("NONE", "None", "Not a part of a shadow edit (lights that have edits keep their links here too)", 0),
    ("SHADOW_MESH", "Shadow mesh", "The edited copy of a caster, seen by shadow rays only", 1),
    ("TWIN", "Twin light", "The light's twin that lights everything but the casters, blocked by the shadow meshes", 2),
    ("SELF_BLOCKER", "Self-shadow mesh", "The copy of a caster that shadows the caster itself: its edited self-shadow loops, "
     "elsewhere the caster a hair inside its surface", 3),
]


class RokebyShadowLinks(PropertyGroup):
    """What a shadow edit links (``obj.rokeby_shadow``). On a shadow mesh: its caster and light.
    On a twin light: the light it twins. On a light with edits: its twin, the four linking
    collections, and the light's own linking from before the first edit."""

    role: EnumProperty(name="Role", items=SHADOW_ROLES, default="NONE", options={"HIDDEN"})
    data_version: IntProperty(name="Shadow data version", default=0, options={"HIDDEN"})
    caster: PointerProperty(type=bpy.types.Object, name="Caster", description="The object whose shadow this shadow mesh edits")
    light: PointerProperty(type=bpy.types.Object, name="Light", description="The light the edit was made from (on a twin: the light it twins)")
    twin: PointerProperty(type=bpy.types.Object, name="Twin light", description="Lights everything but the casters, blocked by the shadow meshes")
    receivers_caster: PointerProperty(type=bpy.types.Collection, name="Receivers (caster)")
    blockers_caster: PointerProperty(type=bpy.types.Collection, name="Blockers (caster)")
    receivers_edited: PointerProperty(type=bpy.types.Collection, name="Receivers (edited)")
    blockers_edited: PointerProperty(type=bpy.types.Collection, name="Blockers (edited)")
    switched_off: BoolProperty(name="Switched off", description="Shadow mesh hidden from shadow rays while its caster or light is gone", default=False, options={"HIDDEN"})
    linking_saved: BoolProperty(name="Own linking stored", default=False, options={"HIDDEN"})
    receivers_before: PointerProperty(type=bpy.types.Collection, name="Own receivers", description="The light's receiver collection before its first shadow edit")
    blockers_before: PointerProperty(type=bpy.types.Collection, name="Own blockers", description="The light's blocker collection before its first shadow edit")
    self_blocker: PointerProperty(type=bpy.types.Object, name="Self-shadow mesh",
                                  description="On a shadow mesh with edited self-shadows: the copy that shadows the caster in its place")


classes = (RokebyMaterialRef, RokebyImageRef, RokebyConstraint, RokebyRegion, RokebyMirror, RokebyShadowLinks)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Object.rokeby = PointerProperty(type=RokebyMirror, name="Rokeby")
    bpy.types.Object.rokeby_shadow = PointerProperty(type=RokebyShadowLinks, name="Rokeby shadow edit")


def unregister():
    if hasattr(bpy.types.Object, schema.OBJECT_SHADOW_PROP):
        del bpy.types.Object.rokeby_shadow
    if hasattr(bpy.types.Object, schema.OBJECT_PROP):
        del bpy.types.Object.rokeby
    for cls in reversed(classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
