"""A shadow edit in Rendered shading in a real window (tests/gui/scenarios/shadow_rendered.py): the
shadow mesh's wire cage is not drawn over the caster in Rendered or Material Preview shading; Solid
shading shows it as a wire."""

import pytest

from harness import scenario_result


@pytest.fixture(scope="module")
def shown(dist_zip):
    return scenario_result("shadow_rendered", dist_zip)


def test_solid_shading_shows_the_shadow_mesh_as_a_wire(shown):
    assert shown["shadow_mesh"], shown
    assert shown["display_solid"] == "WIRE" and shown["display_solid_again"] == "WIRE", shown


def test_rendered_shading_draws_no_cage_over_the_caster(shown):
    assert shown["display_rendered"] == "SOLID" and shown["display_material"] == "SOLID", shown
    # Overlays on or off, the ball's pixels are the render's: no wire drawn over it.
    assert shown["ball_pixels"] > 500, shown
    assert shown["ball_pixels_changed_by_overlays"] <= 0.01 * shown["ball_pixels"], shown
