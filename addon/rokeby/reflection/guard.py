"""Suspending the reflection feature's live update (``handlers``) while the add-on itself changes
the scene (a capture render, a committed edit): the handlers ignore what happens meanwhile.

Kept below ``handlers`` so that the modules the handlers call (the reflection-map capture) can
suspend them without importing them back.
"""

from __future__ import annotations

import contextlib

_suspend = 0


@contextlib.contextmanager
def suspended():
    """While inside, the live-update handlers do nothing (nesting allowed)."""
    global _suspend
    _suspend += 1
    try:
        yield
    finally:
        _suspend -= 1


def active() -> bool:
    """Whether the handlers are suspended now."""
    return _suspend > 0
