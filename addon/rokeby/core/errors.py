"""The add-on's user-facing error (bpy-free): a clear problem with what an artist or a script
asked for, naming what is wrong. Features raise it (or a ValueError subclass of their own);
``rokeby.api.RokebyError`` is this class."""

from __future__ import annotations


class RokebyError(ValueError):
    """A clear, user-facing problem with a mirror, constraint or region, or with an argument."""
