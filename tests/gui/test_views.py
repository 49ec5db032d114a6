"""Return to View with its shortcut, and Add Region at a point clicked on the mirror
(tests/gui/scenarios/views.py)."""

import math

import pytest

from harness import scenario_result


@pytest.fixture(scope="module")
def views(dist_zip):
    return scenario_result("views", dist_zip)


def test_return_to_view(views):
    assert views["turned_deg"] > 5, views
    assert views["returned_deg"] < 0.06, views


def test_add_region_at_the_clicked_point(views):
    c = views["cursor"]
    assert abs(math.hypot(*c) - 1.0) < 0.02 and c[1] < -0.9, views  # Shift+right-click put the cursor on the sphere's front
    rg = views["region"]
    assert rg["kind"] == "EUCLIDEAN", rg
    assert math.dist(rg["center"], c) < 1e-4, rg  # at the clicked point
