"""Animating the shadow mesh (the paper's §6.2): each edit is a shape key of the shadow mesh
(a *keyed configuration*) with the light vector it was made under; the keys are blended by the
current light vector's angles to those, times the falloff (l_nearest · l_current)^β. The add-on's
update step keeps every shadow mesh's blend up to date (:func:`sync_falloffs`)."""

from __future__ import annotations

import numpy as np

from ..blender import registry as index
from ..core import native, schema
from .errors import ShadowEditError
from .light import _current_light_vector
from .linking import _parts, _role


def configuration_key(i: int) -> str:
    """Name of the shape key of keyed configuration ``i`` (§6.2; 0 is the first edit)."""
    return schema.SHADOW_EDIT_KEY if i == 0 else f"{schema.SHADOW_EDIT_KEY} {i + 1}"


def configuration_vectors(shadow_object) -> np.ndarray:
    """(K, 3) unit light vectors, in the caster's local frame, of the K keyed configurations of
    ``shadow_object`` (§6.2): where each of its edits was made."""
    vs = [np.asarray(shadow_object[schema.SHADOW_LIGHT_INITIAL_KEY], np.float64)]
    extra = np.asarray(shadow_object.get(schema.SHADOW_LIGHT_CONFIGURATIONS_KEY, []), np.float64).reshape(-1, 3)
    vs.extend(extra)
    out = np.asarray(vs).reshape(-1, 3)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _drop_configurations(ob) -> None:
    """Removes the keyed configurations after the first (keys and light vectors) from shadow mesh
    ``ob`` and its self-shadow mesh."""
    if schema.SHADOW_LIGHT_CONFIGURATIONS_KEY in ob:
        del ob[schema.SHADOW_LIGHT_CONFIGURATIONS_KEY]
    b = ob.rokeby_shadow.self_blocker
    for o in (ob, b):
        keys = None if o is None else o.data.shape_keys
        if keys is None:
            continue
        for k in [k for k in keys.key_blocks if k.name.startswith(schema.SHADOW_EDIT_KEY + " ")]:
            o.shape_key_remove(k)


def configuration_weights(shadow_object, light, beta: float = 0.0, *, caster=None) -> np.ndarray:
    """Shape-key values (K,) of the K keyed configurations of ``shadow_object`` (§6.2) for the
    light's current position: the configurations are blended by the angle θ_i between the current
    light vector and theirs (weights 1/θ_i normalised: along the arc between two configurations
    the blend is linear in the angle, at a configuration it is that one alone), times the falloff
    (l_nearest · l_current)^β. One configuration: just the falloff."""
    caster = caster if caster is not None else shadow_object.rokeby_shadow.caster
    if caster is None:
        raise ShadowEditError(f"the caster of '{shadow_object.name}' no longer exists")
    vs = configuration_vectors(shadow_object)
    cur = _current_light_vector(caster, light)
    c = np.clip(vs @ cur, -1.0, 1.0)
    theta = np.arccos(c)
    nearest = int(np.argmin(theta))
    fall = float(native.module().shadows.falloff_factor(vs[nearest], cur, float(beta))) if beta > 0 else 1.0
    if len(vs) == 1 or theta[nearest] < 1e-9:
        w = np.zeros(len(vs))
        w[nearest] = 1.0
    else:
        w = (1.0 / theta) / np.sum(1.0 / theta)
    return w * fall


def _set_key_values(ob, values) -> int:
    """Writes the configuration key values of shadow mesh ``ob`` and its self-shadow mesh (only
    those that changed); returns how many changed."""
    written = 0
    targets = [ob]
    b = ob.rokeby_shadow.self_blocker
    if b is not None and b.data.shape_keys is not None:
        targets.append(b)
    for t in targets:
        kb = t.data.shape_keys.key_blocks
        for i, v in enumerate(values):
            k = kb.get(configuration_key(i))
            if k is not None and abs(k.value - v) > 1e-6:
                k.value = float(v)
                written += t is ob
    return written


def falloff_factor(shadow_object, light, beta: float, *, caster=None) -> float:
    """(l_initial · l_current)^β (§6.2; β = 0: no falloff) for the light's current position
    relative to the caster, without writing anything (with keyed configurations, l_initial is the
    nearest configuration's)."""

    if _role(shadow_object) != "SHADOW_MESH":
        raise ShadowEditError(f"{getattr(shadow_object, 'name', shadow_object)!r} is not a Rokeby shadow mesh")
    caster = caster if caster is not None else shadow_object.rokeby_shadow.caster
    if caster is None:
        raise ShadowEditError(f"the caster of '{shadow_object.name}' no longer exists")
    cur = _current_light_vector(caster, light)
    vs = configuration_vectors(shadow_object)
    initial = vs[int(np.argmax(vs @ cur))]
    return float(native.module().shadows.falloff_factor(initial, cur, float(beta)))


def update_falloff(shadow_object, light, beta: float, *, caster=None) -> float:
    """Sets the shadow mesh's edit shape keys (and its self-shadow mesh's) to the falloff times the
    configuration weights (``configuration_weights``) and returns the falloff."""
    k = falloff_factor(shadow_object, light, beta, caster=caster)
    _set_key_values(shadow_object, configuration_weights(shadow_object, light, beta, caster=caster))
    return k


def sync_falloffs(scene) -> int:
    """Brings every shadow mesh's falloff and keyed-configuration blend (§6.2) up to date with its
    light's current position; called by the add-on's depsgraph and frame-change handlers. Writes
    only values that changed (so the write itself settles); returns how many it wrote. Shadow
    meshes whose light or caster is gone keep their values."""

    written = 0
    for ob in _parts()[0]:
        if not index.in_scene(ob, scene):
            continue
        light = ob.rokeby_shadow.light
        keys = ob.data.shape_keys
        if light is None or light.type != "LIGHT" or keys is None or schema.SHADOW_EDIT_KEY not in keys.key_blocks:
            continue
        beta = float(ob.get(schema.SHADOW_FALLOFF_BETA_KEY, 0.0))
        several = len(ob.get(schema.SHADOW_LIGHT_CONFIGURATIONS_KEY, [])) >= 3
        if not (np.isfinite(beta) and beta >= 0.0) or not (beta > 0.0 or several):
            continue  # β = 0 and one configuration: the key stays as apply or a script set it
        try:
            values = configuration_weights(ob, light, beta)
        except (ShadowEditError, ValueError, KeyError, np.linalg.LinAlgError):
            continue
        written += _set_key_values(ob, values)
    return written
