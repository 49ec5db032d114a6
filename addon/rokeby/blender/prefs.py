"""Add-on preferences: the choices that belong to a machine, not to a .blend file.

Edit ▸ Preferences ▸ Add-ons ▸ Rokeby: the default compositing backend, the GPU opt-ins and the
folder reflection maps are cached in. They are saved with Blender's preferences (userpref.blend),
never in a .blend; settings that belong to a file (brush settings, the viewport preview switch)
live on the Scene (see ``appearance.ui`` and ``reflection.viewport.draw``).

The class's ``bl_idname`` is the add-on's package name: ``rokeby`` as a legacy add-on,
``bl_ext.<repository>.rokeby`` as an extension; this module sits in the package's ``blender``
folder, so its ``__package__`` less the last part is that name in both cases. Code reads the preferences through :func:`get`,
which also answers (with the defaults) where the add-on is registered without Blender knowing it
as an add-on (``import rokeby; rokeby.register()`` with bpy as a Python module, render farms).
"""

from __future__ import annotations

from types import SimpleNamespace

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty

PACKAGE = __package__.rpartition(".")[0]  # the add-on's package: this module is in its blender/ folder

COMPOSITING_BACKENDS = [
    ("CPU", "CPU", "Eqs. 3–5 in the Rust core: works everywhere, including background mode", 0),
    ("GPU", "GPU (Blender)", "Eqs. 3–5 by the GLSL shader through Blender's gpu module (needs a GPU context)", 1),
]

SCENE_CAPTURES = [
    ("CYCLES", "Cycles (as F12 renders)", "The preview's scene is rendered with Cycles from each mirror: the render's "
                                          "materials and lights, per-pixel agreement with F12; tenths of seconds to "
                                          "seconds per capture", 0),
    ("VIEWPORT", "Viewport (GPU)", "The preview's scene is drawn on the GPU as the 3D view's Solid shading draws it "
                                   "(materials in their Viewport Display colour): milliseconds per capture; Cycles "
                                   "where no 3D view is open", 1),
]


class RokebyPreferences(bpy.types.AddonPreferences):
    bl_idname = PACKAGE

    compositing_backend: EnumProperty(
        name="Default Compositing Backend",
        description="Backend of Render and Recomposite, Recomposite Render and Recomposite EXR Sequence when the "
                    "operator is not given one",
        items=COMPOSITING_BACKENDS,
        default="CPU",
    )
    gpu_viewport_preview: BoolProperty(
        name="GPU Viewport Previews",
        description="Allow the viewport previews (edited reflections, painted appearance) to draw with Rokeby's "
                    "own GPU shaders; switch off on a machine whose graphics driver cannot run them",
        default=True,
    )
    preview_parallax: BoolProperty(
        name="Parallax-Corrected Reflections",
        description="The reflection preview corrects its lookup in the captured scene for where each point of the "
                    "mirror is (near objects in the right place); off: the lookup from the mirror's centre, about "
                    "a fifth of the cost per pixel on a software renderer",
        default=True,
    )
    scene_capture: EnumProperty(
        name="Scene Capture",
        description="How the reflection preview captures the scene around each mirror",
        items=SCENE_CAPTURES,
        default="CYCLES",
    )
    cache_folder: StringProperty(
        name="Reflection Map Cache",
        description="Folder captured reflection maps are written to when they are stored as files (empty: "
                    "rokeby_maps/ next to the .blend). A folder outside the .blend's own directory is not sent "
                    "with the file to another machine",
        default="",
        subtype="DIR_PATH",
    )

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(heading="Compositing")
        col.prop(self, "compositing_backend")
        col = layout.column(heading="GPU")
        col.prop(self, "gpu_viewport_preview")
        col.prop(self, "preview_parallax")
        col.prop(self, "scene_capture")
        col = layout.column(heading="Reflection Maps")
        col.prop(self, "cache_folder")


# What ``get`` answers where Blender does not list the add-on (the class's defaults; a test keeps them equal).
DEFAULTS = {"compositing_backend": "CPU", "gpu_viewport_preview": True, "preview_parallax": True, "scene_capture": "CYCLES",
            "cache_folder": ""}


def get(context=None):
    """The add-on's preferences (``RokebyPreferences``), or an object answering their defaults where
    Blender does not list the add-on (registered by ``rokeby.register()`` from a script)."""
    context = context if context is not None else bpy.context
    prefs = getattr(context, "preferences", None)
    addon = prefs.addons.get(PACKAGE) if prefs is not None else None
    got = getattr(addon, "preferences", None) if addon is not None else None
    return got if got is not None else SimpleNamespace(**DEFAULTS)


def register():
    bpy.utils.register_class(RokebyPreferences)


def unregister():
    if getattr(RokebyPreferences, "is_registered", False):
        bpy.utils.unregister_class(RokebyPreferences)
