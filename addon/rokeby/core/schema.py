"""Every name Rokeby writes into a .blend file or an EXR, in one place (bpy-free).

A saved file keeps what the add-on wrote under the names it used: mesh attributes, node-group
names, node names, labels and tags, custom-property keys, modifier, collection, object and image
names, AOV and EXR pass names, the properties registered on Blender's types. Renaming one of these
changes what saved scenes mean, so:

- every such name is a constant here, and the modules that write or read it use the constant;
- a name is never renamed or reused; a changed meaning bumps the data version of its owner
  (``DATA_VERSION``, ``SHADOW_DATA_VERSION``, the node groups' versions) and gets a load-time
  migration; :data:`SCHEMA_VERSION` counts the changes to this module's list;
- ``tests/workflows/test_saved_names.py`` compares what a scene of each feature writes with a checked-in
  snapshot (docs/saved-data.md), and ``tests/workflows/test_layers.py`` checks that no module outside this
  one spells a ``rokeby…`` name that is saved.

Enum item numbers (what Blender stores for an enum) are declared with the enums themselves
(explicit numbers, docs/saved-data.md §2).
"""

from __future__ import annotations

# Bumped whenever a name below is added, or a name's meaning changes (with a migration).
SCHEMA_VERSION = 3

# --- Properties registered on Blender's types ----------------------------------------------------
OBJECT_PROP = "rokeby"  # Object.rokeby: RokebyMirror (reflection editing, appearance roles)
OBJECT_SHADOW_PROP = "rokeby_shadow"  # Object.rokeby_shadow: RokebyShadowLinks
SCENE_VIEWPORT_PREVIEW_PROP = "rokeby_viewport_preview"  # Scene.rokeby_viewport_preview
SCENE_PREVIEW_RENDERED_PROP = "rokeby_preview_rendered"  # Scene.rokeby_preview_rendered: the preview over Rendered shading
SCENE_APPEARANCE_BRUSH_PROP = "rokeby_appearance_brush"  # Scene.rokeby_appearance_brush

# --- Data versions (stored in the properties above / on node groups) -----------------------------
DATA_VERSION = 1  # Object.rokeby.data_version of mirrors
SHADOW_DATA_VERSION = 1  # Object.rokeby_shadow.data_version

# --- Custom-property keys on IDs and nodes (shared) ----------------------------------------------
VERSION_KEY = "rokeby_version"  # node groups: the version of the group's layout
MADE_KEY = "rokeby_made"  # objects/collections the add-on made (removed with their owner)
DOOMED_KEY = "rokeby_doomed"  # IDs an undoable removal will delete at the end of the operation

# --- Reflection editing: mesh attributes ---------------------------------------------------------
ROTATION_ATTRIBUTE = "rokeby_rotation"  # per-vertex rotation vectors of the MLS field
RENDER_ATTRIBUTE = "rokeby_render_rotation"  # per face corner, view-independent part, for renders
RENDER_ATTRIBUTE_WA = "rokeby_render_rotation_wa"  # ... and its view-blend weight/angle part
REFRACTION_ATTRIBUTE = "rokeby_refraction"  # per-vertex rotation vectors of the refraction field
REGION_ATTRIBUTE_PREFIX = "rokeby_vg_"  # + vertex-group name: a free-form region's weights

# --- Reflection editing: objects, modifiers, node groups ------------------------------------------
HANDLE_COLLECTION = "Rokeby Handles"  # the collection holding the constraint/region handles
SHRINKWRAP_NAME = "Rokeby: stay on mirror"  # the constraint keeping a red handle on the mirror
VG_NODE_GROUP = "Rokeby Vertex Group Reader"  # Geometry Nodes group reading a vertex group
VG_MODIFIER_PREFIX = "Rokeby region: "  # + region: the modifier running VG_NODE_GROUP
CARRIER_PREFIX = "Rokeby field: "  # + mirror: the mesh carrying the field on the evaluated surface
TRANSFER_GROUP = "Rokeby Field Transfer"  # Geometry Nodes group copying the field onto the evaluated mesh
TRANSFER_MODIFIER = "Rokeby field"  # the modifier running TRANSFER_GROUP
NODE_GROUP_PREFIX = "Rokeby"  # every node group the add-on makes starts with this

# --- Reflection editing: final-render shader nodes (shading.py) ----------------------------------
DIRECTION_GROUP = "Rokeby Edited Direction"
NORMAL_GROUP = "Rokeby Edited Normal"
LINK_TAG = "rokeby_edited_normal"  # node key: a node of ours that feeds an edited normal
ROLE_KEY = "rokeby_role"  # on every node of ours in a material (with LINK_TAG; older files: True): its role
SOURCE_KEY = "rokeby_source"  # on split parts: the name of the Principled BSDF they stand in for
SPLIT_KEY = "rokeby_split"  # on a split Principled BSDF: its original outgoing links
SIGNATURE_KEY = "rokeby_signature"  # on a split Principled BSDF: its inputs when it was split
SPLIT_ID_KEY = "rokeby_split_id"  # on a split Principled BSDF: the key its parts carry in SOURCE_KEY
SOURCE_NAME_KEY = "rokeby_source_name"  # on split parts: the BSDF's name when split (to recreate it)
COPY_OF_KEY = "rokeby_copy_of"  # on a material-local copy of a node group: the group it copies
ORIGINAL_TREE_KEY = "rokeby_original_tree"  # on the material's group node: the group it used
FRAME_EDITED_REFLECTIONS = "Rokeby: edited reflections"  # frame labels in materials
FRAME_EDITED_COAT = "Rokeby: edited coat reflections"
FRAME_ALPHA = "Rokeby: alpha"
FRAME_NOTHING = "Rokeby: nothing"

# --- Reflection editing: refraction (refraction.py) ----------------------------------------------
REFRACTION_GROUP = "Rokeby Edited Refraction Normal"
REFRACTION_VERSION_KEY = "rokeby_refraction_version"
REFRACTION_TAG = "rokeby_refraction"  # on every node refraction.py adds: its role
REFRACTION_SOURCE_KEY = "rokeby_refraction_source"  # on the parts of a split Glass BSDF: the Glass's split id
REFRACTION_SPLIT_ID_KEY = "rokeby_refraction_split_id"  # on a split Glass BSDF
REFRACTION_SPLIT_KEY = "rokeby_refraction_split"  # on a split Glass BSDF: its original outgoing links
REFRACTION_SIGNATURE_KEY = "rokeby_refraction_signature"  # on a split Glass BSDF: its inputs when it was split
FRAME_EDITED_REFRACTION = "Rokeby: edited refraction"

# --- Reflection editing: reflection maps (reflmap.py) --------------------------------------------
REFLMAP_CACHE_DIR = "//rokeby_maps/"  # default folder of the captured maps, relative to the .blend
REFLMAP_SHARED_GROUP = "Rokeby Reflection Map"
REFLMAP_MIRROR_GROUP_PREFIX = "Rokeby Reflection Map: "  # + mirror
REFLMAP_IMAGE_PREFIX = "Rokeby Map "  # + map id
REFLMAP_TAG = "rokeby_reflection_map"
REFLMAP_VERSION_KEY = "rokeby_reflmap_version"
REFLMAP_BSDF_KEY = "rokeby_bsdf"  # on a map node: the BSDF it feeds
REFLMAP_SAVED_KEY = "rokeby_saved"  # on a map group node: the BSDF inputs it switched off (JSON)
# Roughness of each captured level (level 0 the capture itself): written into files as the level
# images' names (" r0.25") and cache file names ("_r0.25.exr") and as the shared group's blend
# factors (Map Range From Min/Max), and each level image holds the blur of its roughness. Never
# change it: files keep the levels they were captured with.
REFLMAP_ROUGHNESS_LEVELS = (0.0, 0.25, 0.5, 1.0)
FRAME_REFLECTION_MAP = "Rokeby: reflection map"

# --- Appearance painting (appearance/) -----------------------------------------------------------
# parameter -> mesh attribute (and attribute node name/label) holding its painted values
APPEARANCE_ATTRIBUTES = {
    "diffuse": "rokeby_base_color",
    "specular": "rokeby_specular",
    "roughness": "rokeby_roughness",
    "anisotropic": "rokeby_anisotropic",
    "anisotropic_rotation": "rokeby_anisotropic_rotation",
    "metallic": "rokeby_metallic",
    "specular_tint": "rokeby_specular_tint",
}
APPEARANCE_NODE_PREFIX = "rokeby_"  # + attribute / texture node names of ours
APPEARANCE_REPLACED_KEY = "rokeby_replaced_link"  # on a node: the link painting replaced
APPEARANCE_PAINTED_KEY = "rokeby_painted"  # on an image: painted by the add-on (packed on save)
APPEARANCE_IMAGE_FORMAT = "rokeby {material} {param}"  # painted texture image names


def appearance_image_name(material: str, param: str) -> str:
    return APPEARANCE_IMAGE_FORMAT.format(material=material, param=param)


# --- Shadow editing (shadow/) --------------------------------------------------------------------
SHADOW_EDIT_KEY = "Rokeby shadow edit"  # the collection/name stem of an edit's parts
SHADOW_LINKING_TAG = "rokeby_shadow_linking"  # on a light-linking collection: its role
SHADOW_LIGHT_INITIAL_KEY = "rokeby_light_initial"  # on a shadow mesh: the light position edited for
SHADOW_LIGHT_CONFIGURATIONS_KEY = "rokeby_light_configurations"  # ... further light positions (flat xyz)
SHADOW_FALLOFF_BETA_KEY = "rokeby_falloff_beta"  # ... the falloff exponent between them
SHADOW_SESSION_STEP_KEY = "rokeby_shadow_session_step"  # on a scene: which state of the shadow-editing
# session (kept in memory, not in the file) the scene's undo step holds; 0 or absent: none
# Keys of shadow edits saved before the pointer links (data version 0); read by the migration only.
SHADOW_LEGACY_SHADOW_OF_KEY = "rokeby_shadow_of"
SHADOW_LEGACY_LIGHT_KEY = "rokeby_light"
SHADOW_LEGACY_TWIN_OF_KEY = "rokeby_twin_of"
SHADOW_LEGACY_LINKING_BEFORE_KEY = "rokeby_linking_before"
SHADOW_LEGACY_KEYS = (SHADOW_LEGACY_SHADOW_OF_KEY, SHADOW_LEGACY_TWIN_OF_KEY)
# light-linking collection roles, named "<light> · <role>"
SHADOW_RECEIVERS_CASTER, SHADOW_BLOCKERS_CASTER = "receivers (caster)", "blockers (caster)"
SHADOW_RECEIVERS_EDITED, SHADOW_BLOCKERS_EDITED = "receivers (edited)", "blockers (edited)"


def shadow_collection_name(light_name: str, role: str) -> str:
    return f"{light_name} · {role}"


# --- Compositing (compositing/): AOVs, EXR passes, compositor nodes -------------------------------
AOV_REFLOCC = "rokeby_reflocc"
AOV_CAMERA_X = "rokeby_camera_x"
AOV_CAMERA_Y = "rokeby_camera_y"
AOV_INCOMING_CAM = "rokeby_incoming_cam"
COMPOSITING_NODE_TAG = "Rokeby Compositing"  # material nodes that write the AOVs
COMPOSITING_NODE_KEY = "rokeby_compositing"  # custom property marking those nodes
COMPOSITOR_NODE = "rokeby_recomposited"  # the compositor's image node of ours
COMPOSITOR_IMAGE_KEY = "rokeby_image_name"  # on it: the image it shows
RECOMPOSITED_IMAGE = "Rokeby Recomposited"  # default name of a recomposited image
COMPOSITE_LAST_EXR_KEY = "rokeby_composite_exr"  # on the scene: the last EXR the operators read/wrote
BRUSH_STROKES_KEY = "rokeby_brush_strokes"  # on a brushed image: list of {"id", "mode", "radius", "strength", "points"}
BRUSH_SOURCE_KEY = "rokeby_brush_exr"  # on a brushed image: the multilayer EXR its strokes edit
BRUSH_BASE_KEY = "rokeby_brush_base"  # on a recomposited image: the one-knob edit it shows, which strokes add to
# ({"edit", "amount", "k_d", "k_r", "fit", "noise_tolerance"})


# --- Render farms (farm/) ------------------------------------------------------------------------
# On each scene of a file that holds edits the add-on recomputes at render time (a reflection
# field, a shadow edit): the add-on version that saved it, e.g. "0.1.0". A farm job's tasks refuse
# to render the file in a Blender whose Rokeby is missing or another version.
SCENE_SAVED_WITH_KEY = "rokeby_saved_with"
