"""Compositing-stage editing in a real window (tests/gui/scenarios/composite_paint.py): Render and
Recomposite in Debian's Blender (its own OpenEXR library loaded: the process must survive the EXR
read), then Paint Normals from F3 in the Image Editor on the rendered frame: a stroke changes the
pixels along it only, Esc ends the brush, Ctrl+Z restores the frame."""

import pytest

from harness import scenario_result


@pytest.fixture(scope="module")
def painted(dist_zip):
    return scenario_result("composite_paint", dist_zip, timeout=400)


def test_render_and_recomposite_in_the_window(painted):
    assert painted["setup"] == ["FINISHED"] and painted["render"] == ["FINISHED"], painted
    assert painted["exr_written"] and painted["image"] == [160, 120], painted
    assert painted["image_finite"], painted


def test_paint_normals_on_the_rendered_frame(painted):
    assert painted["brush_running"], painted
    assert painted["changed"] > 100, painted
    lo, hi = painted["changed_rows"]
    row = painted["stroke_row"]
    assert row - 24 <= lo <= row <= hi <= row + 24, painted  # within the 20 px brush radius of the stroke
    assert painted["after_finite"], painted
    assert painted["brush_ended"], painted


def test_ctrl_z_undoes_the_stroke(painted):
    assert painted["undo_max_diff"] < 1e-6, painted
