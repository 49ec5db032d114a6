"""Freeform shadow boundary editing (Mattausch, Igarashi, Wimmer) in Blender: an artist drags the
boundary of a caster's shadow; a shadow mesh that only the receivers see (light linking) renders
the edited shadow. The numerics run in Rust (``rokeby_native.shadows.ShadowEditor``).

Entry points, by the module that holds them:

* ``session.py``: :func:`start` a :class:`ShadowSession` (drag, commit, cancel, reset);
* ``shadow_mesh.py``: :func:`apply` the session's edit (shadow mesh, self-shadow mesh);
* ``linking.py``: :func:`shadow_mesh_of`, :func:`remove` (the twin light and linking collections);
* ``repair.py``: :func:`repair` after deletions, :func:`migrate` old files (the add-on's steps, ``addon.py``);
* ``configurations.py``: keyed configurations and the falloff (§6.2), :func:`sync_falloffs`;
* ``live_preview.py``: the shadow while dragging, :func:`live_begin` / :func:`live_step` / :func:`live_end`;
* ``light.py`` (the light's position or direction), ``errors.py`` (``ShadowEditError``), ``display.py``
  (how shadow meshes are drawn in each shading);
* ``ui.py``: operators, panel and overlay; ``addon.py`` registers them.

Scripts use ``rokeby.api`` (``api.py``: ``start_shadow_edit``, ``apply_shadow_edit``,
``remove_shadow_edit``). Tests:
tests/shadow/ (test_shadow.py, test_shadow_links.py, test_shadow_self.py, test_shadow_keys.py,
test_shadow_falloff.py, test_shadow_modal.py, test_shadow_undo.py, test_shadow_inside.py).
"""

from __future__ import annotations

from .configurations import (configuration_key, configuration_vectors, configuration_weights, falloff_factor,
                             sync_falloffs, update_falloff)
from .errors import ShadowEditError
from .light import light_arguments
from .linking import BLOCKERS_CASTER, BLOCKERS_EDITED, RECEIVERS_CASTER, RECEIVERS_EDITED, TWIN_SUFFIX, remove, shadow_mesh_of
from .live_preview import LivePreview, live_begin, live_end, live_step
from .repair import migrate, repair
from .session import MAX_DRAG_PARAMETER, ShadowSession, start
from .shadow_mesh import SELF_SUFFIX, SHADOW_SUFFIX, apply

__all__ = [
    "BLOCKERS_CASTER", "BLOCKERS_EDITED", "MAX_DRAG_PARAMETER", "RECEIVERS_CASTER",
    "RECEIVERS_EDITED", "SELF_SUFFIX", "SHADOW_SUFFIX", "TWIN_SUFFIX", "LivePreview", "ShadowEditError", "ShadowSession",
    "apply", "configuration_key", "configuration_vectors", "configuration_weights", "falloff_factor", "light_arguments",
    "live_begin", "live_end", "live_step", "migrate", "remove", "repair", "shadow_mesh_of", "start", "sync_falloffs",
    "update_falloff",
]
