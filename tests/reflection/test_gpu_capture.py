"""The GPU scene capture's geometry (rokeby.reflection.viewport.gpu_capture), without Blender: the
six face views cover every direction, and their resampling to the lat-long panorama the preview
looks up lands each texel on the face pixel that sees its direction. (The capture itself runs in a
real window: tests/gui/test_scene_preview_in_window.py.)"""

import numpy as np
import pytest

from rokeby.reflection.viewport import gpu_capture as G


def face_pixel_directions(s):
    """(6, S, S, 3): the world direction each face pixel centre sees (row 0 at the bottom)."""
    c = (np.arange(s) + 0.5) / s * 2.0 - 1.0
    x, y = np.meshgrid(c, c)  # x along the columns, y along the rows (bottom row first)
    out = np.empty((6, s, s, 3))
    for i, rot in enumerate(G.face_rotations()):
        view = np.stack([x, y, -np.ones_like(x)], axis=-1)  # OpenGL: the view looks down -z
        d = view @ rot  # view -> world: the transpose of the rotation
        out[i] = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return out


def test_faces_are_rotations_looking_along_their_axes():
    rot = G.face_rotations()
    for i, r in enumerate(rot):
        assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
        assert np.allclose(-r[2], G.FACES[i][0])  # the view looks along the face's forward


def test_projection_puts_a_point_ahead_at_the_face_centre():
    views, proj = G.face_matrices((1.0, 2.0, 3.0), 0.01, 100.0)
    for i, (f, _u) in enumerate(G.FACES):
        p = np.array([1.0, 2.0, 3.0, 1.0]) + np.r_[np.asarray(f) * 5.0, 0.0]
        clip = proj @ views[i] @ p
        ndc = clip[:3] / clip[3]
        assert np.allclose(ndc[:2], 0.0, atol=1e-12) and -1.0 < ndc[2] < 1.0


@pytest.mark.parametrize("size,width", [(32, 128), (64, 256)])
def test_resampling_sees_each_texels_direction(size, width):
    faces = face_pixel_directions(size)
    pano = G.cube_to_latlong(faces, width)
    want = G.latlong_directions(width)
    got = pano / np.linalg.norm(pano, axis=-1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip((got * want).sum(-1), -1, 1)))
    texel = 90.0 / size
    assert angle.max() < 0.75 * texel, angle.max()  # bilinear between the face pixels around it


def test_nearest_channels_are_not_blended_across_an_outline():
    s = 16
    faces = np.zeros((6, s, s, 2), np.float32)
    faces[..., 0] = 1.0
    faces[:, :, : s // 2, 1] = 0.5  # a step in channel 1 (1/distance) on every face
    pano = G.cube_to_latlong(faces, 64, nearest_channels=(1,))
    assert set(np.unique(pano[..., 1])) <= {0.0, 0.5}
    assert np.allclose(pano[..., 0], 1.0)


def test_bad_input_names_what_is_wrong():
    with pytest.raises(ValueError, match="faces"):
        G.cube_to_latlong(np.zeros((5, 4, 4, 3)), 16)
    with pytest.raises(ValueError, match="width"):
        G.cube_to_latlong(np.zeros((6, 4, 4, 3)), 15)
