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
