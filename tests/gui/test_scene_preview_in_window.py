"""The scene preview in a real window (tests/gui/scenarios/scene_preview.py): captured by the
window's own debounced timer, the red handle showing the object under the green handle as the
Cycles render does, no capture for a handle drag, one after a cube's transform is confirmed."""

import pytest

from harness import scenario_result


@pytest.fixture(scope="module")
def preview(dist_zip):
    return scenario_result("scene_preview", dist_zip, timeout=400)


def magenta(rgb) -> bool:
    """Magenta-dominant: red and blue well above green (sRGB screenshot or render values)."""
    r, g, b = rgb
    return r > g + 0.15 and b > g + 0.08


def test_the_window_captures_the_scene_by_itself(preview):
    assert preview["captures_after_first"] == preview["captures_before"] + 1, preview
    assert preview["capture"]["bytes"] > 0 and preview["capture"]["width"] == 256, preview


def test_the_red_handle_shows_the_object_under_the_green_handle(preview):
    # Without the preview the chrome ball is drawn flat grey; with it, the magenta cube sits under
    # the red handle, as in the Cycles render of the same view.
    assert not magenta(preview["red_handle_off"]), preview
    assert magenta(preview["red_handle_on"]), preview
    assert magenta(preview["red_handle_render"]), preview
    on, ren = preview["red_handle_on"], preview["red_handle_render"]
    assert max(abs(a - b) for a, b in zip(on, ren)) < 0.2, (on, ren)


def test_the_parallax_correction_puts_it_there(preview):
    # Drawn offscreen in the window with the same view: e(q) at the red handle is the constraint's
    # e_n; the corrected lookup finds the magenta cube along it, the centre-only lookup misses it.
    off = preview["offscreen"]
    assert max(abs(a - b) for a, b in zip(off["direction"], off["constraint_e"])) < 0.02, off
    assert magenta(off["corrected"]) and not magenta(off["centre"]), off


def test_a_handle_drag_captures_nothing(preview):
    assert preview["green_moved"] != preview["green_before"], preview  # the drag did move the handle
    assert preview["captures_handle_drag"] == 0, preview


def test_a_transform_captures_once_after_it_is_confirmed(preview):
    assert preview["captures_during_cube_drag"] and not any(preview["captures_during_cube_drag"]), preview
    assert preview["captures_after_cube_drag"] == 1, preview


def test_the_gpu_capture_draws_the_scene_as_the_view_does(preview):
    g = preview["gpu"]
    assert preview["gpu_capture_op"] == ["FINISHED"], preview
    assert g["route"] == "VIEWPORT" and g["captures"] == 1, g
    assert g["mirror_visible"] and g["overlays"], g  # the mirror shown again, the overlays back on
    assert magenta(g["red_handle"]), g  # the object under the green handle, drawn by the GPU capture
    assert g["refresh_again"] == 0, g
    assert g["captures_material"] == 1 and magenta(g["red_handle_material"]), g  # drawn in Material Preview too
    assert g["captures_after_flat"] == 2, g
