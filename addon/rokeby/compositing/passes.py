"""The render passes the method needs (the short names Blender up to 4.5 writes into a multilayer
EXR, the long ones of 5.0 and later) and :class:`Passes`, one frame's passes as arrays."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import schema
from .errors import CompositingError


# Pass name in a Blender multilayer EXR → (field, number of channels).
PASSES = {
    "Combined": ("image", 4),
    "Normal": ("normal", 3),
    "DiffDir": ("diff_dir", 3),
    "DiffInd": ("diff_ind", 3),
    "DiffCol": ("diff_col", 3),
    "GlossDir": ("gloss_dir", 3),
    "GlossInd": ("gloss_ind", 3),
    "GlossCol": ("gloss_col", 3),
    "IndexOB": ("index_ob", 1),
    "IndexMA": ("index_ma", 1),
    "AO": ("ao", 3),
    "Depth": ("depth", 1),
    schema.AOV_REFLOCC: ("reflocc", 1),
    schema.AOV_CAMERA_X: ("camera_x", 3),
    schema.AOV_CAMERA_Y: ("camera_y", 3),
    schema.AOV_INCOMING_CAM: ("incoming_cam", 3),
}

# The names the passes have in a multilayer EXR: up to Blender 4.5 the short ones of PASSES, from
# 5.0 the long ones (the channel names then read "ViewLayer.Diffuse Direct", ".Object Index.X").
# The reader accepts either, so frames from any release load; errors name the short ones.
PASS_NAMES_LONG = {
    "DiffDir": "Diffuse Direct", "DiffInd": "Diffuse Indirect", "DiffCol": "Diffuse Color",
    "GlossDir": "Glossy Direct", "GlossInd": "Glossy Indirect", "GlossCol": "Glossy Color",
    "IndexOB": "Object Index", "IndexMA": "Material Index", "AO": "Ambient Occlusion",
}


def exr_pass_names(name: str) -> tuple:
    """The names pass ``name`` (a key of PASSES, or any render pass) may have in a multilayer EXR."""
    return (name, PASS_NAMES_LONG[name]) if name in PASS_NAMES_LONG else (name,)


@dataclass
class Passes:
    """Render passes of one frame, (H, W[, C]) float32 arrays, top row first."""
    image: np.ndarray
    normal: np.ndarray
    diff_dir: np.ndarray
    diff_ind: np.ndarray
    diff_col: np.ndarray
    gloss_dir: np.ndarray
    gloss_ind: np.ndarray
    gloss_col: np.ndarray
    index_ob: np.ndarray
    index_ma: np.ndarray
    ao: np.ndarray
    depth: np.ndarray
    reflocc: np.ndarray
    camera_x: np.ndarray
    camera_y: np.ndarray
    incoming_cam: np.ndarray
    alpha: np.ndarray | None = None
    header: dict = field(default_factory=dict)

    @property
    def shape(self):
        return self.image.shape[:2]

    def validate(self) -> None:
        h, w = self.shape
        for name, (attr, ch) in PASSES.items():
            a = getattr(self, attr)
            want = (h, w) if ch == 1 else (h, w, 3)
            if a.shape != want:
                raise CompositingError(f"pass {name}: expected shape {want} like Combined, got {a.shape}")
