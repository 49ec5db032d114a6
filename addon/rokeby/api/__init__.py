"""rokeby.api — the scripting API of Rokeby, used by background scripts (render farms, pipelines)
and by the reflection feature's operators: the entry points of every feature in one place.

This is the facade of the layered add-on (docs/architecture.md): it implements nothing of its own
but thin wrappers, and no feature imports it. Reflection editing's entry points (maths helpers,
mirrors, constraints, regions, render nodes, reflection maps, highlights, refraction) are
``rokeby.reflection.edit``; compositing's are ``rokeby.compositing.workflow``; shadow editing's are
``rokeby.shadow``. Data moves as numpy arrays (``foreach_get``/``foreach_set``), never with
Python loops over vertices. Functions that need Blender import ``bpy`` lazily, so the maths
helpers work in any Python with numpy and rokeby_native.
"""

from __future__ import annotations

from .. import shadow
from ..reflection import edit as _edit

# Every name of reflection editing's entry-point module, private ones too (scripts and tests reach
# api._require_mirror, api._index): rokeby.api.<name> is what it was before the layering.
globals().update({_k: _v for _k, _v in vars(_edit).items() if not _k.startswith("__")})
_scene = _edit._scene


# --- Local shape editing at the compositing stage (Zubiaga et al. 2016; rokeby.compositing) ------

from ..compositing.workflow import (  # noqa: E402 - the compositing feature's entry points
    _check_fit,
    _recomposite_opened,
    open_normal_brush,
    paint_normals,
    recomposite_exr,
    recomposite_exr_pixels,
    recomposite_render,
    setup_compositing_passes,
    use_in_compositor,
)


# --- Freeform shadow boundary editing (Mattausch et al.; rokeby.shadow) ---------------------------

def start_shadow_edit(caster, light, receivers=None, *, scene=None, min_loop_vertices: int = 20, w_z: float = 2.5):
    """Starts editing the shadow that the closed mesh ``caster`` casts from ``light`` onto
    ``receivers`` (default: the scene's other visible meshes); returns a ``rokeby.shadow.ShadowSession``
    (loops(), handles(), drag(), commit()). Clear errors for open casters, a light inside the
    caster's bounds or nothing under the light; nothing in the scene changes."""
    return shadow.start(caster, light, receivers, scene=_scene(scene), min_loop_vertices=min_loop_vertices, w_z=w_z)


def apply_shadow_edit(session, *, scene=None, falloff_beta: float = 0.0, add_configuration: bool = False):
    """Creates or updates the shadow-mesh object of ``session`` (shadow rays only, same vertex
    groups and armature as the caster) and the light/shadow linking that makes the receivers show
    the edited shadow; drags whose handles lie on the caster edit its self-shadows too (a
    self-shadow mesh shadows the caster in its place). ``falloff_beta`` > 0 blends the edit out as
    the light moves away, (l_initial · l_current)^β (§6.2), kept up to date by the add-on's
    handlers. ``add_configuration=True`` keeps the existing edit and adds this one as a keyed
    configuration (§6.2): the handlers blend them by the light's angle to each. Returns (shadow
    object, twin light)."""
    return shadow.apply(session, scene=_scene(scene), falloff_beta=falloff_beta, add_configuration=add_configuration)


def remove_shadow_edit(obj) -> None:
    """Removes the shadow edit of ``obj`` (a caster or its shadow mesh): the shadow mesh, the twin
    light and the linking go, and the light's own linking from before the edit comes back."""
    shadow.remove(obj)


# --- Render farms (Open Job Description; rokeby.farm) -------------------------------------------

from ..farm.api import write_recomposite_job, write_render_job  # noqa: E402 - the farm feature's entry points


__all__ = [*_edit.__all__, "write_render_job", "write_recomposite_job", "setup_compositing_passes", "recomposite_render", "recomposite_exr", "recomposite_exr_pixels",
           "use_in_compositor", "open_normal_brush", "paint_normals", "start_shadow_edit", "apply_shadow_edit", "remove_shadow_edit"]
