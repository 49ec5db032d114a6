"""Fixtures the reflection tests share."""

import pytest

import support.reflection


@pytest.fixture
def chrome_ball():
    """The chrome ball under forest.exr (support.reflection.chrome_ball): ``(ball, material)``."""
    pytest.importorskip("bpy")
    return support.reflection.chrome_ball()
