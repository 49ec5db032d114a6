"""An appearance stroke with the mouse in a real window (tests/gui/scenarios/stroke.py)."""

from harness import scenario_result


def test_appearance_stroke_and_undo(dist_zip):
    r = scenario_result("stroke", dist_zip)
    assert r["changed"] > 10, r
    # Every vertex within the brush radius of the stroke painted; none beyond the dabs' reach
    # (CUTOFF radii, where the Gaussian is below float32's resolution), 5 % for the chord.
    assert r["unchanged_within_radius"] == 0, r
    assert r["changed_max_dist"] <= r["cutoff"] * r["radius"] * 1.05, r
    assert r["max_after"] > 0.6, r  # toward the brush's value (0.95)
    assert r["undo_restores"], r
