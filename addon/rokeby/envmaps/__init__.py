"""Environment maps for painting under environment light: HDR and LDR images, conversions between
lat-long, cube, sphere (mirror-ball) and dual-paraboloid maps, order-2 SH irradiance, and specular
prefiltering across roughness levels — the numerics in the Rust core (``rokeby_core::envmaps``)
through :mod:`rokeby.core.native`.

Arrays are float32 with row 0 the top row of the image file (as OpenEXR reads it); Blender's
``Image.pixels`` are bottom-up, :func:`flip_rows` converts. Formulas, algorithm and measured
errors: docs/envmaps.md.

Entry points, by the module that holds them:

* ``image_files.py``: :func:`read_image` (EXR, Radiance, PNG/JPEG), :func:`read_exr`,
  :func:`write_exr`, :func:`read_hdr`, :func:`write_hdr`, :func:`read_ldr`, :func:`flip_rows`;
* ``layouts.py``: the layouts (``LAYOUTS``), :func:`convert`, :func:`sample`;
* ``prefiltering.py``: :func:`prefilter` (``LOBES``, ``ROUGHNESS_LEVELS``), :func:`irradiance`,
  :func:`sh_irradiance`, :func:`reference`, :func:`lookup_levels`;
* ``studio_worlds.py``: :func:`studio_world`, :func:`use_studio_world`;
* ``api.py``: the names ``rokeby.api`` re-exports.

Tests: tests/envmaps/ (test_envmap.py, test_envmap_ldr.py), tests/native/test_properties_new.py.
"""

from __future__ import annotations

from .image_files import (LDR_SUFFIXES, flip_rows, read_exr, read_hdr, read_image, read_ldr, srgb_to_linear, write_exr,
                          write_hdr)
from .layouts import LAYOUTS, convert, sample
from .prefiltering import LOBES, ROUGHNESS_LEVELS, irradiance, lookup_levels, prefilter, reference, sh_irradiance
from .studio_worlds import studio_world, use_studio_world

__all__ = [
    "LAYOUTS", "LDR_SUFFIXES", "LOBES", "ROUGHNESS_LEVELS", "convert", "flip_rows", "irradiance", "lookup_levels",
    "prefilter", "read_exr", "read_hdr", "read_image", "read_ldr", "reference", "sample", "sh_irradiance",
    "srgb_to_linear", "studio_world", "use_studio_world", "write_exr", "write_hdr",
]
