"""The appearance preview over Solid shading: no grey of the view's own drawing of the same surface
shows through the painted object (the two depths tie; the viewport samples its depth with a
sub-pixel jitter for anti-aliasing), while an object just in front still hides the preview."""

import pytest

pytest.importorskip("bpy")

from support.bpy_process import run_check  # noqa: E402


@pytest.mark.slow  # a fresh bpy process and its GPU context
def test_preview_shows_no_speckle_of_the_surface_under_it():
    res = run_check("appearance/appearance_depth_check.py")
    assert res["ball_pixels"] > 1000 and res["cube_pixels"] > 100, res
    for jitter, r in res["jitters"].items():
        assert r["speckle"] == 0, (jitter, r, res["ball_pixels"])
        assert r["cube_grey"] == res["cube_pixels"], (jitter, r)  # the cube in front stays in front
