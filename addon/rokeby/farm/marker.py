"""The scene marker: which Rokeby saved the file, for a farm job's tasks to check.

A file holding edits that the add-on recomputes at render time (a reflection or refraction field:
its mesh attributes, on mirrors and carriers; a shadow edit: its shadow meshes, twin lights and
linked lights) renders without error in a Blender that lacks the add-on, but shows those edits as
they were at the frame it was saved on, at every frame. So, when such a file is saved, each of its
scenes records the add-on version under ``schema.SCENE_SAVED_WITH_KEY`` (a save_pre handler), and
the job's tasks (``worker.py``) refuse to render a marked scene unless that same version is enabled.
A file without such edits carries no marker (one saved earlier loses it).
"""

from __future__ import annotations

from ..core import schema

_FIELD_ATTRIBUTES = (schema.ROTATION_ATTRIBUTE, schema.RENDER_ATTRIBUTE, schema.RENDER_ATTRIBUTE_WA,
                     schema.REFRACTION_ATTRIBUTE)


def holds_render_time_edits() -> bool:
    """Whether the open file holds a reflection/refraction field or a shadow edit."""
    import bpy  # noqa: PLC0415

    from ..blender import compat  # noqa: PLC0415

    for mesh in bpy.data.meshes:
        attrs = mesh.attributes
        if any(attrs.get(name) is not None for name in _FIELD_ATTRIBUTES):
            return True
    return any(compat.stored_group(ob, schema.OBJECT_SHADOW_PROP) is not None for ob in bpy.data.objects)


def mark(version: str) -> bool:
    """Writes (or, without render-time edits, removes) the marker on every scene of the file;
    returns whether the file is marked."""
    import bpy  # noqa: PLC0415

    marked = holds_render_time_edits()
    for scene in bpy.data.scenes:
        if scene.library is not None:
            continue  # a linked scene belongs to its own file
        if marked:
            if scene.get(schema.SCENE_SAVED_WITH_KEY) != version:
                scene[schema.SCENE_SAVED_WITH_KEY] = version
        elif schema.SCENE_SAVED_WITH_KEY in scene:
            del scene[schema.SCENE_SAVED_WITH_KEY]
    return marked


def saved_with(scene) -> "str | None":
    """The Rokeby version that saved ``scene``'s file (None: not marked)."""
    value = scene.get(schema.SCENE_SAVED_WITH_KEY)
    return str(value) if value is not None else None


def on_save_pre(*_args):
    """save_pre: the marker, before Blender writes the file."""
    from .api import addon_version  # noqa: PLC0415

    mark(addon_version())
