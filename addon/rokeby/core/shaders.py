"""Shader sources (bpy-free, no ``gpu``): where Rokeby's GLSL files are and how a plain OpenGL
context (moderngl) gets the ``#version`` header Blender's ``GPUShaderCreateInfo`` would declare.

The GLSL lives in ``shaders/`` only (see shaders/README.md); each feature declares its shader's
interface once, in GPUShaderCreateInfo's terms, and both Blender (``rokeby.blender.gpu``) and
standalone OpenGL build their declarations from it.
"""

from __future__ import annotations

from pathlib import Path

_ADDON = Path(__file__).resolve().parents[1]
_HERE = _ADDON  # where ``shaders/`` sits when the add-on is packaged


def shader_dir() -> Path:
    """``shaders/`` next to the add-on when packaged, else the checkout's top-level ``shaders/``."""
    for candidate in (_HERE / "shaders", _ADDON.parents[1] / "shaders"):
        if (candidate / "rokeby_field_lib.glsl").is_file():
            return candidate
    raise FileNotFoundError(f"Rokeby's GLSL files (rokeby_field_lib.glsl) were found neither in {_HERE / 'shaders'} nor in {_ADDON.parents[1] / 'shaders'}")


_GLSL_TYPE = {"VEC2": "vec2", "VEC3": "vec3", "VEC4": "vec4", "MAT4": "mat4", "FLOAT": "float", "INT": "int",
              "IVEC3": "ivec3", "FLOAT_2D": "sampler2D", "FLOAT_2D_ARRAY": "sampler2DArray"}


def standalone_header(interface: dict, types: str, version: str = "330 core") -> list[str]:
    """The declarations a plain OpenGL context needs for a shader described by ``interface`` (in
    GPUShaderCreateInfo's terms): version, the types file, uniform blocks, push constants as
    uniforms, samplers."""
    common = [f"#version {version}", types]
    for _slot, type_name, name in interface["uniform_buf"]:
        common.append(f"layout(std140) uniform {name}_block {{ {type_name} {name}; }};")
    for type_name, name in interface["push_constant"]:
        common.append(f"uniform {_GLSL_TYPE[type_name]} {name};")
    for _slot, type_name, name in interface["sampler"]:
        common.append(f"uniform {_GLSL_TYPE[type_name]} {name};")
    return common


def standalone_from(interface: dict, src: dict, version: str = "330 core") -> tuple[str, str]:
    """(vertex, fragment) for a plain OpenGL context (moderngl): a header generated from
    ``interface``, then the same files (``src``: types, lib, vertex, fragment) Blender compiles."""
    common = standalone_header(interface, src["types"], version)
    vert = list(common)
    for slot, type_name, name in interface["vertex_in"]:
        vert.append(f"layout(location = {slot}) in {_GLSL_TYPE[type_name]} {name};")
    for interp, type_name, name in interface["vertex_out"]:
        vert.append(f"{'flat ' if interp == 'flat' else ''}out {_GLSL_TYPE[type_name]} {name};")
    frag = list(common)
    for interp, type_name, name in interface["vertex_out"]:
        frag.append(f"{'flat ' if interp == 'flat' else ''}in {_GLSL_TYPE[type_name]} {name};")
    for slot, type_name, name in interface["fragment_out"]:
        frag.append(f"layout(location = {slot}) out {_GLSL_TYPE[type_name]} {name};")
    vert.append(src["vertex"])
    frag += [src["lib"], src["fragment"]]
    return "\n".join(vert) + "\n", "\n".join(frag) + "\n"
