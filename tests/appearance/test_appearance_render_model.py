"""The final-render model: renders use the Principled BSDF whatever the preview model;
the panel says so and shows by how much the render differs from a Phong or Torrance–Sparrow
preview, measured by an operator, never a claim of a match. bpy in background mode."""

import pytest

bpy = pytest.importorskip("bpy")

from rokeby import appearance, envmaps  # noqa: E402


class Layout:
    """Records what a panel's draw puts in a layout."""

    def __init__(self, out):
        self.out = out

    def column(self, align=False):
        return self

    row = column

    def label(self, text="", icon="NONE"):
        self.out.append(("label", text))

    def operator(self, idname, text="", icon="NONE", **_kw):
        self.out.append(("operator", idname))

    def prop(self, data, name, text="", **_kw):
        self.out.append(("prop", name))


@pytest.fixture
def painted():
    import rokeby

    bpy.ops.wm.read_factory_settings(use_empty=True)
    rokeby.register()
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
    ob = bpy.context.object
    mat = bpy.data.materials.new("Metal")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.6
    ob.data.materials.append(mat)
    appearance.setup(ob)
    envmaps.use_studio_world(bpy.context.scene, "forest")
    yield ob
    rokeby.unregister()


def _panel(context):
    from rokeby.appearance import ui as appearance_ui

    out = []
    appearance_ui.draw_render_model(Layout(out), context)
    return out


def _words(shown) -> str:
    """The panel's labels as one text (a long label is drawn as several wrapped lines)."""
    return " ".join(text for kind, text in shown if kind == "label")


def test_panel_states_the_render_model_and_the_measured_difference(painted):
    s = bpy.context.scene.rokeby_appearance_brush
    assert _panel(bpy.context) == [("label", "Renders use this model")]
    s.preview_model = "PHONG"
    shown = _panel(bpy.context)
    assert "Renders use Principled (GGX), not this model" in _words(shown)  # wrapped to the sidebar's width
    assert ("operator", "rokeby.appearance_render_difference") in shown  # not measured yet: no figure claimed
    assert bpy.ops.rokeby.appearance_render_difference() == {"FINISHED"}
    assert 0.1 < s.render_difference < 1.0, s.render_difference  # rough metal: the preview is far brighter than GGX
    shown = _panel(bpy.context)
    assert f"Render differs from this preview by {100 * s.render_difference:.1f} % (measured)" in _words(shown)
    appearance.paint(painted, "roughness", [0.0, 0.0, 1.0], radius=5.0, value=0.1)  # the figure no longer applies
    assert ("operator", "rokeby.appearance_render_difference") in _panel(bpy.context)


def test_measuring_without_an_environment_is_refused(painted):
    bpy.context.scene.world = None
    bpy.context.scene.rokeby_appearance_brush.preview_model = "TORRANCE_SPARROW"
    with pytest.raises(RuntimeError, match="no equirectangular Environment Texture"):
        bpy.ops.rokeby.appearance_render_difference()
    assert bpy.context.scene.rokeby_appearance_brush.render_difference == -1.0


def test_preview_settings_update_without_errors(painted, capfd):
    """Changing the preview model, light or light location runs their update (a viewport redraw);
    before, the update was a lambda that raised NameError inside Blender on every change."""
    s = bpy.context.scene.rokeby_appearance_brush
    capfd.readouterr()
    s.preview_model = "TORRANCE_SPARROW"
    s.preview_light = "BESIDE"
    s.light_location = (1.0, -2.0, 3.0)
    s.light_intensity = 5.0
    err = capfd.readouterr().err
    assert "Error" not in err and "Traceback" not in err, err
