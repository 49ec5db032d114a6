"""The live viewport preview of edited reflections (paper §6.1): ``glsl`` (the field shader's
interface and packing, no gpu) and ``draw`` (the draw handler)."""
