"""Progress in Blender's status bar for work an artist waits on (over about 0.3 s): switching a
mirror to geodesic distances, capturing a reflection map, reconstructing a render, recompositing
an EXR sequence.

``with Progress(context, steps) as p: ... p.step()`` calls ``window_manager.progress_begin``,
``progress_update`` and ``progress_end`` (the end also on error). In background mode (render
farms, bpy as a module) there is no status bar and nothing is called."""

from __future__ import annotations

import bpy


def window_manager(context=None):
    """The window manager whose status bar shows progress, or None (background mode)."""
    if bpy.app.background:
        return None
    context = context if context is not None else bpy.context
    return getattr(context, "window_manager", None)


class Progress:
    """A context manager for ``steps`` units of work: ``step(n)`` reports ``n`` more done."""

    def __init__(self, context, steps: int):
        self.steps = max(int(steps), 1)
        self.done = 0
        self.wm = window_manager(context)

    def __enter__(self):
        if self.wm is not None:
            self.wm.progress_begin(0, self.steps)
            self.wm.progress_update(0)
        return self

    def step(self, n: int = 1) -> None:
        self.done = min(self.done + n, self.steps)
        if self.wm is not None:
            self.wm.progress_update(self.done)

    def __exit__(self, *exc):
        if self.wm is not None:
            self.wm.progress_end()
        return False
