"""The extension installed from disk in a real window, disabled and enabled again."""

from harness import scenario_result


def test_install_disable_enable(dist_zip):
    r = scenario_result("install", dist_zip)
    assert r["enabled"] and r["enabled_again"] and not r["enabled_after_disable"], r
    assert "ROKEBY_PT_main" in r["panels_installed"], r
    assert r["panels_disabled"] == [], r
    assert r["panels_enabled_again"] == r["panels_installed"], r
    assert r["tab"] == "Rokeby"
