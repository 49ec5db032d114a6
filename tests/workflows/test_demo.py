"""The `make demo` scene: physically the mirror shows the body, the edit makes it show the face
(checked by casting the reflected rays, no render), and the side-by-side composition."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import rokeby  # noqa: E402
from rokeby import api, demo_scene as ds  # noqa: E402
from rokeby.blender import compat  # noqa: E402
from rokeby.reflection import mirror_state  # noqa: E402

from support import SHARED, mesh_path  # noqa: E402


@pytest.fixture
def venus():
    mesh_path("homer.obj")
    demo = ds.build(SHARED, width=64, height=36, samples=1)
    rokeby.register()
    mirror_state.reset()
    return demo


def test_mirror_shows_the_body_then_the_face(venus):
    phys = ds.glass_view(venus, edited=False)
    assert phys["centre_sees"] == "body" and phys["face"] == 0.0 and phys["body"] > 0.5
    info = ds.edit(venus)
    assert info["report"].status == "OK" and info["wired"] == 1
    # The green handle started on the physical reflection (the body) and was dragged to the face.
    assert info["green_from"][2] < ds.FACE_FROM * ds.FIGURE_HEIGHT < info["green_to"][2]
    edited = ds.glass_view(venus, edited=True)
    assert edited["centre_sees"] == "face"
    assert abs(edited["centre_height"] - info["green_to"][2]) < 0.1
    assert edited["face"] > 0.15 and edited["body"] < phys["body"] / 2
    # Outside the region nothing turns: the frame and the figure carry no field, and the region
    # covers the glass, so every glass vertex turns by the same angle (one constraint).
    turns = api.quat_angle(api.field(venus.mirror))
    assert np.ptp(turns) < 1e-3 and turns.min() > np.radians(10)


def test_side_by_side_composes_and_labels(tmp_path):
    paths = []
    for name, value in (("a", 0.25), ("b", 0.75)):
        img = bpy.data.images.new(name, 40, 30)
        px = np.full((30, 40, 4), value, np.float32)
        px[..., 3] = 1.0
        img.pixels.foreach_set(px.ravel())
        img.filepath_raw = str(tmp_path / f"{name}.png")
        img.file_format = "PNG"
        img.save()
        bpy.data.images.remove(img)
        paths.append(tmp_path / f"{name}.png")
    w, h = ds.side_by_side(paths[0], paths[1], tmp_path / "sbs.png", ("before", "after"))
    img = bpy.data.images.load(str(tmp_path / "sbs.png"))
    px = np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], 4)
    assert (img.size[0], img.size[1]) == (w, h) and w > 80 and h > 30
    top = px[-30:]  # rows are bottom-up: the pictures are the top 30 rows
    np.testing.assert_allclose(top[:, :40, :3], 0.25, atol=0.01)
    np.testing.assert_allclose(top[:, -40:, :3], 0.75, atol=0.01)
    band = px[: h - 30, ..., :3]
    if not compat.blf_draws_into_images():
        assert band.max() < 0.1  # empty bands, no half-drawn text
        pytest.skip("captions: blf.bind_imbuf (Blender 4.3+) is missing, blf cannot draw into images here")
    assert band.max() > 0.5  # the captions were drawn (white on dark)
