"""Rokeby — art-directed reflections for Blender.

Break the laws of optics on purpose: drag where a reflection lands on a surface and keep the
result smooth, animated and renderable (Ritschel et al. 2009, "Interactive Reflection Editing").

This package is a Blender extension (see blender_manifest.toml) and a plain Python package:
``rokeby.api`` works in background scripts, and its maths helpers work without Blender at all
(``bpy`` is imported only where Blender data is touched). Registering touches no ``gpu``
function, so the add-on loads in background mode (render farms, ``bpy`` as a module).
"""

from __future__ import annotations

__all__ = ["register", "unregister", "is_registered"]

__version__ = "0.1.0"  # as blender_manifest.toml says (tests/workflows/test_farm_jobs.py checks)

from . import _legacy

_legacy.install(__name__)  # old module paths (rokeby.evaluate, rokeby.shading, ...) name the moved modules


def __getattr__(name: str):
    """``rokeby.shading`` and the other old module names as attributes (they moved: rokeby._legacy)."""
    if name in _legacy.MOVED:
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

_registered = False


def is_registered() -> bool:
    return _registered


def _features():
    from .appearance import addon as appearance
    from .blender import prefs
    from .compositing import addon as compositing
    from .farm import addon as farm
    from .reflection import addon as reflection
    from .reflection import ui as reflection_ui
    from .shadow import addon as shadow

    # Each feature registers itself (props, operators, UI, hooks). The reflection sidebar's menus
    # name every feature's operators: it goes last.
    return (prefs, reflection, appearance, compositing, shadow, farm, reflection_ui)


def _modules():
    """The modules that declare the add-on's Blender classes (preferences, properties, operators,
    panels), in the order the features register them."""
    from .appearance import ui as appearance_ui
    from .blender import prefs
    from .compositing import brush_ui as compositing_brush_ui
    from .compositing import ui as compositing_ui
    from .farm import ui as farm_ui
    from .reflection import handlers, operators, props, ui
    from .reflection.viewport import draw as viewport
    from .shadow import ui as shadow_ui

    return (prefs, props, operators, handlers, viewport, appearance_ui, compositing_ui, compositing_brush_ui, shadow_ui, farm_ui, ui)


def register():
    """Register the add-on (idempotent: a second call does nothing)."""
    global _registered
    if _registered:
        return
    done = []
    try:
        for module in _features():
            module.register()
            done.append(module)
    except Exception:
        for module in reversed(done):
            module.unregister()
        raise
    _registered = True
    global _atexit_hooked
    if not _atexit_hooked:
        # With bpy as a Python module, classes whose properties have Python update callbacks
        # must be unregistered before the interpreter shuts down, or the process hangs at exit
        # (background scripts and render-farm jobs would never return).
        import atexit

        atexit.register(_unregister_at_exit)
        _atexit_hooked = True


_atexit_hooked = False


def _unregister_at_exit():
    if _registered:
        try:
            unregister()
        except Exception:  # noqa: BLE001 - shutting down
            pass


def unregister():
    global _registered
    for module in reversed(_features()):
        module.unregister()
    _registered = False
