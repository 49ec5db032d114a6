"""Every Rokeby panel and redo panel reads whole at the default sidebar width (nothing cut): one
window (tests/gui/scenarios/panels.py) with a mirror's status rows and the appearance preview's
rows drawn, every panel open, and Set Up Appearance run from F3 search for its redo panel."""

import pytest

from harness import scenario_result


@pytest.fixture(scope="module")
def panels(dist_zip):
    return scenario_result("panels", dist_zip)


def test_every_panel_reads_whole(panels):
    r = panels
    assert any(d.startswith("mirror:ROKEBY_PT_main") for d in r["drawn"]), r["drawn"]
    assert any(d.startswith("appearance:ROKEBY_PT_appearance_brush") for d in r["drawn"]), r["drawn"]
    assert r.get("cut", {}) == {}, "texts cut at the default sidebar width (text, needed px, room px):\n" + "\n".join(
        f"  {panel}: {c}" for panel, cuts in r["cut"].items() for c in cuts)


def test_redo_panel_title_reads_whole(panels):
    hud = panels["hud"]
    assert hud["need"] <= hud["room"], f"redo panel title {hud['title']!r} needs {hud['need']} px, has {hud['room']}"
    appearance = {t: n for t, n in panels["redo_titles_cut"].items() if "Appearance" in t or "Attributes" in t}
    assert appearance == {}, f"appearance redo titles cut at {hud['room']} px: {appearance}"


def test_every_redo_title_reads_whole(panels):
    """Every Rokeby operator's redo title fits the collapsed redo panel (the sidebar buttons and menus
    keep the long names: Set Up Compositing Passes, Render and Recomposite, Recomposite EXR Sequence,
    Add Reflection Constraint)."""
    assert panels["redo_titles_cut"] == {}, panels["redo_titles_cut"]
