"""The live viewport preview of edited reflections (paper §6.1): ``glsl`` (the field shader's
interface and packing, no gpu), ``draw`` (the draw handler), ``scene_env`` (the scene captured from
each previewed mirror, kept current) and ``gpu_capture`` (the capture drawn by Blender's viewport)."""
