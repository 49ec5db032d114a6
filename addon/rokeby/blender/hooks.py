"""The one owner of ``bpy.app.handlers``: every feature adds its handlers here, under its name,
and ``remove(owner)`` takes away exactly what that owner added (nothing of other add-ons).

Two kinds of hook:

- **Blender handlers** (``add(owner, event, fn)``): ``fn`` is appended to
  ``bpy.app.handlers.<event>`` (``depsgraph_update_post``, ``load_post``, ``save_pre``, ...), made
  persistent so it survives loading another file. Adding the same function twice (or a function
  of the same module and name: a reloaded module) keeps one.
- **Steps** (``add_step(owner, point, fn)``): work a feature contributes to another's handler
  without the two importing each other. The reflection feature's live update runs the steps of
  ``"scene_update"`` after each evaluation (under its re-entrance guard; each returns how many
  things it moved, so the view is redrawn), ``"migrate"`` after loading a file and
  ``"undo_redo"`` after undo/redo. Steps run in the order they were added.
"""

from __future__ import annotations

_handlers: dict = {}  # owner -> [(event, fn)]
_steps: dict = {}  # point -> [(owner, fn)]


def _same(a, b) -> bool:
    return a is b or (getattr(a, "__module__", None), getattr(a, "__name__", None)) == (getattr(b, "__module__", None), getattr(b, "__name__", None))


def add(owner: str, event: str, fn) -> None:
    """Append ``fn`` (made persistent) to ``bpy.app.handlers.<event>`` once, recorded for ``owner``."""
    import bpy  # noqa: PLC0415
    from bpy.app.handlers import persistent  # noqa: PLC0415

    lst = getattr(bpy.app.handlers, event)
    fn = persistent(fn)
    for old in [f for f in lst if _same(f, fn)]:
        lst.remove(old)
    lst.append(fn)
    mine = _handlers.setdefault(owner, [])
    mine[:] = [(e, f) for e, f in mine if not (e == event and _same(f, fn))] + [(event, fn)]


def remove(owner: str) -> None:
    """Remove every handler and step ``owner`` added."""
    import bpy  # noqa: PLC0415

    for event, fn in _handlers.pop(owner, []):
        lst = getattr(bpy.app.handlers, event)
        while fn in lst:
            lst.remove(fn)
    for point in list(_steps):
        _steps[point] = [(o, f) for o, f in _steps[point] if o != owner]


def added(owner: "str | None" = None) -> list:
    """(owner, event, fn) of the handlers added and not removed."""
    return [(o, e, f) for o, pairs in _handlers.items() if owner in (None, o) for e, f in pairs]


def add_step(owner: str, point: str, fn) -> None:
    steps = _steps.setdefault(point, [])
    steps[:] = [(o, f) for o, f in steps if not (o == owner and _same(f, fn))] + [(owner, fn)]


def steps(point: str) -> list:
    """The functions added at ``point``, in the order they were added."""
    return [f for _o, f in _steps.get(point, [])]
