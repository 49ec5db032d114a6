"""GPU helpers of the Blender layer: compiling a shader from its declared interface through
Blender's ``gpu`` module. ``gpu`` is imported only when a shader is made (while drawing), never at
import or register time, so the add-on loads in background mode.
"""

from __future__ import annotations

from . import compat


def create_shader(interface: dict, interface_name: str, src: dict):
    """Compiles ``src`` (types, lib, vertex, fragment) through Blender's GPUShaderCreateInfo as
    ``interface`` declares it (call only while drawing: ``gpu`` is imported here)."""
    import gpu  # noqa: PLC0415

    info = gpu.types.GPUShaderCreateInfo()
    for slot, type_name, name in interface["vertex_in"]:
        info.vertex_in(slot, type_name, name)
    if interface["vertex_out"]:  # an empty interface block is a GLSL syntax error
        iface = gpu.types.GPUStageInterfaceInfo(interface_name)
        for interp, type_name, name in interface["vertex_out"]:
            getattr(iface, interp)(type_name, name)
        info.vertex_out(iface)
    for type_name, name in interface["push_constant"]:
        info.push_constant(type_name, name)
    for slot, type_name, name in interface["sampler"]:
        info.sampler(slot, type_name, name)
    if src["types"].strip():
        info.typedef_source(src["types"])
    for slot, type_name, name in interface["uniform_buf"]:
        info.uniform_buf(slot, type_name, name)
    for slot, type_name, name in interface["fragment_out"]:
        info.fragment_out(slot, type_name, name)
    if interface.get("depth_write"):
        compat.shader_depth_write(info, interface["depth_write"])
    info.vertex_source(src["vertex"])
    info.fragment_source(src["lib"] + "\n" + src["fragment"])
    return gpu.shader.create_from_info(info)
