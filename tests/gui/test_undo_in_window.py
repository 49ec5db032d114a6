"""Undo around shadow drags in a real window (tests/gui/scenarios/shadow_undo.py): a press-drag-release
on a shadow handle with the mouse is one undo step; Ctrl+Z takes back that drag only (the scene set-up
and the session stay, the session's handles and shadow mesh as before the drag), Ctrl+Shift+Z brings
it back; Ctrl+Z while the button is held cancels that drag and nothing else."""

import numpy as np
import pytest

from harness import run_scenario


@pytest.fixture(scope="module")
def run(dist_zip):
    """One window for both tests (a start and the install cost about 10 s)."""
    return run_scenario("shadow_undo", dist_zip)


def test_ctrl_z_after_and_during_a_shadow_drag(run):
    assert run.error is None, run.describe()
    assert not run.tracebacks, run.describe()
    r = run.result
    started, dragged, undone, redone, mid = r["started"], r["dragged"], r["undone"], r["redone"], r["mid_drag_undo"]
    assert r["start"] == ["FINISHED"] and started["session"] and started["drags"] == 0, r
    # The press on the handle started a drag (the shortcut), the release kept it.
    assert r["shortcut_dragged"], r
    assert dragged["drags"] == 1 and dragged["shadow_mesh"], dragged
    assert not np.allclose(dragged["handles"], started["handles"])
    # Ctrl+Z: back to the session as started, the scene set-up intact.
    assert undone["session"] and undone["drags"] == 0 and not undone["shadow_mesh"], undone
    np.testing.assert_allclose(undone["handles"], started["handles"], atol=1e-6)
    assert undone["objects"] == started["objects"], (undone["objects"], started["objects"])
    # Ctrl+Shift+Z: the drag again.
    assert redone["drags"] == 1 and redone["shadow_mesh"], redone
    np.testing.assert_allclose(redone["handles"], dragged["handles"], atol=1e-6)
    # Ctrl+Z mid-drag: that drag cancelled, the first drag kept.
    assert mid["drags"] == 1 and mid["shadow_mesh"], mid
    np.testing.assert_allclose(mid["handles"], dragged["handles"], atol=1e-6)


def test_the_sidebar_drag_button_waits_for_a_press_on_a_handle(run):
    """Run from the sidebar (the mouse on the sidebar, as a click on Drag Shadow Boundary runs it), the
    operator waits; the next press on a handle in the view drags it."""
    assert run.error is None, run.describe()
    r = run.result
    assert r["button"] == ["RUNNING_MODAL"], r
    assert r["button_dragged"]["drags"] == r["mid_drag_undo"]["drags"] + 1, r["button_dragged"]
