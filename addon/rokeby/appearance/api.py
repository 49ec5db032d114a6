"""Appearance painting's entry points for scripts and operators (Fraser, §"Painting"): set a
material up for painting, paint a stroke, read the painted values, scale a parameter over the
whole object, remove the painting. ``rokeby.api`` re-exports the names of ``__all__``; the
parameters and brushes they take are ``rokeby.appearance.PARAMS`` and ``BRUSHES``.
"""

from __future__ import annotations

import numpy as np

from .brushes import paint
from .material_nodes import remove, set_global, setup
from .texture import point_values

__all__ = [
    "setup_appearance_painting", "paint_appearance", "appearance_values", "set_appearance_scale",
    "remove_appearance_painting",
]


def setup_appearance_painting(obj, *, material=None, target: str = "POINT", resolution: int = 1024,
                              uv_map: str | None = None, replace_links: bool = False):
    """Sets ``material`` (default: the object's active material; a new one if it has none) up for
    painting: the painted parameters become per-point attributes of the mesh (``target="POINT"``)
    or images on the UV map ``uv_map`` (``target="TEXTURE"``, ``resolution``² texels), filled
    with the material's current values and wired into its Principled BSDF. Idempotent. Inputs
    that other nodes drive (an Image Texture on Roughness, ...) are refused with a ValueError
    naming them unless ``replace_links``, which takes them over and keeps the links for
    :func:`remove_appearance_painting`. Returns the material."""
    return setup(obj, material, target=target, resolution=resolution, uv_map=uv_map,
                 linked="REPLACE" if replace_links else "REFUSE")


def paint_appearance(obj, brush: str, centres, radius: float, *, value=None, strength: float = 1.0,
                     mode: str | None = None) -> np.ndarray:
    """Paints one stroke of ``brush`` (a parameter of ``rokeby.appearance.PARAMS`` — "diffuse",
    "specular", "roughness", "metallic", "specular_tint", "anisotropic", ... — or one of Fraser's
    "sharpen", "blur", "stretch") through the world-space ``centres`` ((3,) or (K, 3) dabs, in
    order) with a Gaussian falloff of ``radius``. ``value``: the target value or colour (mode
    "MIX") or the amount ("ADD", "SUBTRACT"). Returns the parameter's new per-point values."""
    return paint(obj, brush, centres, radius, value=value, strength=strength, mode=mode)


def appearance_values(obj, param: str) -> np.ndarray:
    """The painted ``param`` per vertex, (V,) or (V, 4) float32, whatever the target (on a
    texture target, the images looked up at each vertex's UVs)."""
    return point_values(obj, param)


def set_appearance_scale(material, param: str, value) -> None:
    """Fraser's global sliders: scales ``param`` over the whole object (1 = as painted; an RGB(A)
    tint for the colours), without touching the painted values."""
    set_global(material, param, value)


def remove_appearance_painting(obj, *, material=None, delete_attributes: bool = False) -> None:
    """Undoes :func:`setup_appearance_painting` on ``material`` (default: the active one): the
    Rokeby nodes go and the links it replaced come back, so the material is as it was. The painted
    attributes stay on the mesh (a later set-up reuses them) unless ``delete_attributes``."""
    remove(obj, material, delete_attributes=delete_attributes)
