"""The appearance brush in a real window (tests/gui/scenarios/appearance_brush.py): Ctrl+Z while it
runs never reaches past it (before its first stroke it is refused, so Set Up Appearance Painting
stays), a stroke is one undo step, and a click on the sidebar while it runs goes to the sidebar."""

from harness import scenario_result


def test_ctrl_z_and_sidebar_clicks_while_the_brush_runs(dist_zip):
    r = scenario_result("appearance_brush", dist_zip)
    assert r["setup"] == ["FINISHED"] and r["set_up"] and r["brush"] == ["RUNNING_MODAL"], r
    assert r["undo_before_stroke_kept_setup"], r
    assert r["stroke_changed"] and r["stroke_changed"] > 5, r
    assert r["undo_stroke_back_to_setup"], r
    assert r["second_undo_kept_setup"], r
    assert r["tab_clicked"] == "Rokeby", r
