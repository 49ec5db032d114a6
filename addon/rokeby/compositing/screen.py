"""Screen space (Blender's camera space: x right, y up, z towards the viewer): the camera's
rotation from the camera-axis AOVs, and screen-space normals and view vectors of a frame."""

from __future__ import annotations

import numpy as np

from ..core import schema
from .errors import CompositingError
from .passes import Passes


# Blender's Vector Transform "Camera" space has z pointing forward; Blender's camera object (and
# our screen space) has z towards the viewer.
_CAM_FLIP = np.diag([1.0, 1.0, -1.0])


def _unit(a: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1e-12, a / n, 0.0).astype(np.float32)


def camera_rotation(camera_x: np.ndarray, camera_y: np.ndarray) -> np.ndarray:
    """World → screen-space rotation (3×3) from the AOVs holding the world X and Y axes in Blender's
    shader camera space (z forward) at every surface pixel: their mean over the pixels, flipped to
    z towards the viewer, completed by the cross product and re-orthonormalised (SVD)."""
    x = camera_x.reshape(-1, 3).astype(np.float64)
    y = camera_y.reshape(-1, 3).astype(np.float64)
    ok = (np.abs(np.linalg.norm(x, axis=1) - 1) < 1e-3) & (np.abs(np.linalg.norm(y, axis=1) - 1) < 1e-3)
    if not ok.any():
        raise CompositingError(f"passes {schema.AOV_CAMERA_X}/{schema.AOV_CAMERA_Y}: no surface pixel holds the camera rotation "
                               "(a material without the AOV outputs? Set Up Compositing Passes adds them again)")
    cx = _CAM_FLIP @ x[ok].mean(0)
    cy = _CAM_FLIP @ y[ok].mean(0)
    m = np.stack([cx, cy, np.cross(cx, cy)], 1)  # columns: world axes in screen space
    u, _s, vt = np.linalg.svd(m)
    return u @ vt


def screen_space(p: Passes) -> tuple[np.ndarray, np.ndarray]:
    """Screen-space normals and view vectors (H, W, 3) float32; zero where there is no surface."""
    rot = camera_rotation(p.camera_x, p.camera_y)
    n = _unit(p.normal @ rot.T.astype(np.float32))
    v = _unit(p.incoming_cam * _CAM_FLIP.diagonal().astype(np.float32))
    return n, v
