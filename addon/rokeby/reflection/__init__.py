"""Reflection editing (Ritschel, Okabe, Thormählen, Seidel 2009, "Interactive Reflection Editing").

Scripts use ``rokeby.api`` (this feature's part: ``api.py``, whose ``__all__`` it re-exports; the
sidebar's operators call the same functions). The implementation, by the module that holds it:

* ``evaluate.py``: evaluating a mirror and the scene (scene → arrays → the Rust core → the
  rotation field, eq. 5 and 7), fingerprints and scheduling;
* ``mirror_state.py`` (each mirror's state, report and ``stats``), ``scene_inputs.py`` (the
  constraint rows [p, r, e] and region specs read from the scene), ``geodesic_cache.py`` (cached
  distances and the drag preview), ``interpolation_error.py`` (renders against the per-pixel
  preview), ``mirror_surface.py``, ``freeform_regions.py``, ``unreached_pieces.py``;
* ``field_attributes.py`` and ``field_carriers.py``: the field stored on the mesh, and on shared
  meshes through carriers;
* ``props.py`` (the saved scene model of mirrors), ``operators.py``, ``ui.py``, ``handlers.py``
  (live updates), ``registry.py``, ``pointers.py``, ``guard.py`` (suspending the live update),
  ``duplicates.py``, ``addon.py`` (registration);
* ``render/``: final renders (shader node groups, refraction, reflection maps); ``viewport/``: the
  live GPU preview and the scene it reflects.

Tests: tests/reflection/ (test_field.py, test_regions_workflow.py, test_wysiwyg.py,
test_scene_capture.py, test_refraction.py, test_highlight.py, test_reflmap.py, ...) and the
window leg's tests/gui/test_handles.py and test_scene_preview_in_window.py.
"""
