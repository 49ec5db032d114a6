"""The light as the shadow editor and the keyed configurations (§6.2) read it: its position or
direction in world space, and its unit vector in the caster's local frame."""

from __future__ import annotations

import numpy as np

from .errors import ShadowEditError


def light_arguments(light) -> dict:
    """``light_position=`` (point, spot, area) or ``light_direction=`` (sun) of a Blender light
    object, in world space."""
    if light is None or getattr(light, "type", None) != "LIGHT":
        raise ShadowEditError(f"light: {getattr(light, 'name', light)!r} is not a light object")
    m = np.array(light.matrix_world, dtype=np.float64)
    if light.data.type == "SUN":
        d = -m[:3, 2]
        return {"light_direction": d / np.linalg.norm(d)}
    return {"light_position": m[:3, 3].copy()}


def _unit_light_vector(m: np.ndarray, kw: dict) -> np.ndarray:
    """The light direction in the caster's local frame (§6.2: relative changes of object and
    light), from the light to the caster's origin. A light at the origin itself (possible now that
    a light may be inside the caster's bounds, e.g. at a ring's centre) has no direction: the
    local -z axis is used, so no NaN reaches the stored light vectors."""
    lv = kw.get("light_direction")
    if lv is None:
        lv = m[:3, 3] - kw["light_position"]
    cur = np.linalg.solve(m[:3, :3], lv)
    n = np.linalg.norm(cur)
    if not (np.isfinite(n) and n > 1e-9 * max(1.0, float(np.abs(m[:3, 3]).max()))):
        return np.array([0.0, 0.0, -1.0])
    return cur / n


def _current_light_vector(caster, light) -> np.ndarray:
    return _unit_light_vector(np.array(caster.matrix_world, dtype=np.float64), light_arguments(light))
