"""The bpy-free core of the add-on: what runs in any Python with numpy (no ``bpy``, no ``gpu``).

``schema`` (every name written into a .blend or an EXR), ``errors`` (RokebyError), ``vecmath`` (reflect, refract, total
internal reflection, the region border), ``latlong`` (directions ↔ equirectangular texture
coordinates), ``meshio`` (OBJ reading), ``shaders`` (GLSL sources), ``words`` (how messages name
things), ``exr`` (OpenEXR files through the Rust core) and ``native`` (the one import of the
Rust core ``rokeby_native``). Nothing here imports
from the rest of the add-on (docs/architecture.md).
"""
