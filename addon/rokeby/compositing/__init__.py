"""Local shape editing at the compositing stage (Zubiaga, Guennebaud, Vergne, Barla, EGSR 2016).

The compositing artist edits the normal buffer; diffuse and reflection shading follow without
re-rendering (numerics in the Rust core). The pipeline, by the module that holds each step:

1. ``pass_setup.py``: :func:`setup_passes` (Cycles passes and AOV nodes), :func:`render_passes`;
2. ``exr_io.py``: :func:`read_exr` into :class:`Passes` (``passes.py``), :func:`write_exr`, :func:`sequence_frames`;
3. ``reconstruction.py``: :func:`reconstruct` the per-patch SH diffuse and dual-paraboloid
   reflection environments (``screen.py``: screen-space normals and view vectors);
4. ``recompositing.py``: :func:`recomposite` (eqs. 3–5), :class:`RecompositeSession` for many edits
   of one frame; ``gl.py`` (moderngl) and ``blender_gpu.py``: the GLSL backends, imported from there;
5. ``normal_tools.py``: :func:`emboss`, :func:`bump`, :func:`ripple`, :func:`noise_decal`,
   :func:`bilateral_smooth`, :func:`edit_normals` (the one-knob edits);
6. ``render_edit.py``: :func:`open_render` keeps the frame being edited; ``compositor_input.py``:
   :func:`show_image`, :func:`feed_compositor`; ``command_line.py``: ``python -m rokeby.composite``.

Scripts use ``rokeby.api`` (this feature's part: ``api.py``); ``brush.py`` is the normal brush, ``ui.py`` and
``brush_ui.py`` the operators and panels, ``errors.py`` the feature's errors, ``addon.py`` registers it. Tests: tests/compositing/ (test_compositing.py,
test_exr_io.py, test_recompositor.py, test_recomposite_glsl.py, test_compositing_brush.py, ...).
"""

from __future__ import annotations

from .command_line import command_parser, edit_options, one_knob_options
from .compositor_input import feed_compositor, show_image
from .errors import CompositingError, MissingPasses
from .exr_io import read_exr, sequence_frames, write_exr
from .normal_tools import EDITS, bilateral_smooth, bump, edit_normals, emboss, noise_decal, ripple
from .pass_setup import render_passes, setup_passes
from .passes import PASSES, Passes, exr_pass_names
from .reconstruction import PatchReport, Reconstruction, patch_ids, pixel_noise, reconstruct
from .recompositing import RECOMPOSITE_BACKENDS, RecompositeSession, recomposite
from .render_edit import RenderEdit, close_render, open_render
from .screen import camera_rotation, screen_space

__all__ = [
    "EDITS", "PASSES", "RECOMPOSITE_BACKENDS", "CompositingError", "MissingPasses", "Passes", "PatchReport", "Reconstruction", "RecompositeSession", "RenderEdit", "bilateral_smooth",
    "bump", "camera_rotation", "close_render", "command_parser", "edit_normals", "edit_options", "emboss",
    "exr_pass_names", "feed_compositor", "noise_decal", "one_knob_options", "open_render",
    "patch_ids", "pixel_noise", "read_exr", "recomposite", "reconstruct", "render_passes", "ripple", "screen_space", "sequence_frames", "setup_passes",
    "show_image", "write_exr",
]
