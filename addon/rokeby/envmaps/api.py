"""Environment maps' entry points for scripts: the HDR worlds bpy ships, and HDR image files read
and written by the Rust core. ``rokeby.api`` re-exports the names of ``__all__``; the maps
themselves (``convert``, ``sample``, ``prefilter``, ``irradiance``, ...) are ``rokeby.envmaps``'s,
documented in docs/envmaps.md.
"""

from __future__ import annotations

from .image_files import read_exr, read_hdr, write_exr, write_hdr
from .studio_worlds import studio_world, use_studio_world

__all__ = ["studio_world", "use_studio_world", "read_exr", "write_exr", "read_hdr", "write_hdr"]
