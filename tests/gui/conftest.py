"""The window leg: fixtures shared by tests/gui/ (run by ``make test-gui``; ``make test`` never collects
this folder, see tests/conftest.py's pytest_ignore_collect)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from harness import REPO, unavailable_reason


def pytest_collection_modifyitems(items):
    for item in items:
        if Path(str(item.fspath)).resolve().is_relative_to(Path(__file__).resolve().parent):
            item.add_marker(pytest.mark.gui)


@pytest.fixture(scope="session")
def gui_machine():
    """Skips with the reason when this machine cannot run a real Blender window."""
    reason = unavailable_reason()
    if reason:
        pytest.skip(reason)


@pytest.fixture(scope="session")
def dist_zip(gui_machine):
    """The extension zip ``make dist`` built (ROKEBY_GUI_ZIP names another)."""
    if os.environ.get("ROKEBY_GUI_ZIP"):
        return Path(os.environ["ROKEBY_GUI_ZIP"])
    zips = sorted((REPO / "dist").glob("rokeby-*.zip"), key=lambda p: p.stat().st_mtime)
    if not zips:
        pytest.fail("no dist/rokeby-*.zip: run `make dist` (make test-gui does)")
    return zips[-1]
