"""The shadow-editing feature's error (bad input: ValueError)."""

from __future__ import annotations


class ShadowEditError(ValueError):
    """A shadow edit that cannot be made; nothing in the scene was changed."""
