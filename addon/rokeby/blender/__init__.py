"""The feature-agnostic Blender layer: what every feature uses to touch Blender data, knowing no
feature. ``compat`` (Blender-version differences), ``transaction`` (all or nothing), ``hooks``
(the one owner of ``bpy.app.handlers``), ``meshes`` (mesh arrays through foreach_get), ``nodes``
(node helpers), ``gpu`` (shaders through Blender's gpu module), ``registry`` (the index of the
objects features own), ``modal`` (the undo shortcut and the region under the mouse, for modal operators), ``ui_text`` (sidebar text that
fits), ``progress``, ``prefs``. Imports only ``rokeby.core`` (docs/architecture.md).
"""
