"""Appearance painting under environment light (Fraser, "Interactive Real-Time BRDF Editing under
Environment Lighting", §"Painting"): per-point BRDF parameters stored as mesh attributes (or
images through the UV map) and wired into the material's Principled BSDF, brushes with a radius
and Gaussian falloff that write them, and global sliders that scale them for the whole object.

Scripts use ``rokeby.api`` (this feature's part: ``api.py``: :func:`setup_appearance_painting`,
:func:`paint_appearance`, :func:`appearance_values`, :func:`set_appearance_scale`,
:func:`remove_appearance_painting`). The implementation, by the module that holds it:

* ``material_nodes.py``: :func:`setup` a material for painting, :func:`set_global`, :func:`remove`,
  :func:`migrate` (old files, at load);
* ``brushes.py``: :func:`paint` one stroke, :func:`falloff` (a dab's Gaussian weights);
* ``attributes.py``: :func:`read` the per-point values;
* ``texture.py``: texture targets (:func:`setup_texture`, :func:`remove_texture`, :func:`target`,
  :func:`read_texture`, :func:`missing_images`), :func:`point_values` whatever the target;
* ``image_packing.py``: :func:`pack_painted`, :func:`reload_after_undo`;
* ``parameters.py``: the parameters (``PARAMS``, ``COLORS``), Fraser's brush names (``BRUSHES``);
* ``ui.py``, ``preview.py``, ``glsl.py``: operators, panels and the viewport preview; ``addon.py``
  registers them.

Tests: tests/appearance/ (test_appearance.py, test_appearance_texture.py, test_specular_colour.py,
test_appearance_brush_undo.py, test_appearance_light.py, ...).
"""

from __future__ import annotations

from .attributes import read
from .brushes import CUTOFF, falloff, paint
from .image_packing import pack, pack_painted, reload_after_undo
from .material_nodes import LINKED, migrate, remove, set_global, setup
from .parameters import BRUSHES, COLORS, MAX_COLOR, PARAMS
from .texture import TEXTURE_MARGIN, missing_images, point_values, read_texture, remove_texture, setup_texture, target

__all__ = [
    "BRUSHES", "COLORS", "CUTOFF", "LINKED", "MAX_COLOR", "PARAMS", "TEXTURE_MARGIN",
    "falloff", "migrate", "missing_images", "pack", "pack_painted", "paint", "point_values", "read", "read_texture",
    "reload_after_undo", "remove", "remove_texture", "set_global", "setup", "setup_texture", "target",
]
