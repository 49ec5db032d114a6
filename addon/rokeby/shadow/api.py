"""Shadow editing's entry points for scripts and operators (Mattausch, Igarashi, Wimmer): start an
edit, apply it as a shadow mesh with light and shadow linking, remove it. ``rokeby.api``
re-exports the names of ``__all__``; the session they hand out is ``rokeby.shadow.ShadowSession``.
"""

from __future__ import annotations

from .. import shadow

__all__ = ["start_shadow_edit", "apply_shadow_edit", "remove_shadow_edit"]


def start_shadow_edit(caster, light, receivers=None, *, scene=None, min_loop_vertices: int = 20, w_z: float = 2.5):
    """Starts editing the shadow that the closed mesh ``caster`` casts from ``light`` onto
    ``receivers`` (default: the scene's other visible meshes); returns a ``rokeby.shadow.ShadowSession``
    (loops(), handles(), drag(), commit()). Clear errors for open casters, a light inside the
    caster's bounds or nothing under the light; nothing in the scene changes."""
    return shadow.start(caster, light, receivers, scene=scene, min_loop_vertices=min_loop_vertices, w_z=w_z)


def apply_shadow_edit(session, *, scene=None, falloff_beta: float = 0.0, add_configuration: bool = False):
    """Creates or updates the shadow-mesh object of ``session`` (shadow rays only, same vertex
    groups and armature as the caster) and the light/shadow linking that makes the receivers show
    the edited shadow; drags whose handles lie on the caster edit its self-shadows too (a
    self-shadow mesh shadows the caster in its place). ``falloff_beta`` > 0 blends the edit out as
    the light moves away, (l_initial · l_current)^β (§6.2), kept up to date by the add-on's
    handlers. ``add_configuration=True`` keeps the existing edit and adds this one as a keyed
    configuration (§6.2): the handlers blend them by the light's angle to each. Returns (shadow
    object, twin light)."""
    return shadow.apply(session, scene=scene, falloff_beta=falloff_beta, add_configuration=add_configuration)


def remove_shadow_edit(obj) -> None:
    """Removes the shadow edit of ``obj`` (a caster or its shadow mesh): the shadow mesh, the twin
    light and the linking go, and the light's own linking from before the edit comes back."""
    shadow.remove(obj)
