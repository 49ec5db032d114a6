"""rokeby_native.compositing: local shape editing at the compositing stage (Zubiaga et al. 2016),
rust/rokeby-core/src/compositing: SH diffuse fits, reflection environments, recompositing
(eqs. 3–5) and the normal tools."""

from collections.abc import Sequence
from typing import Any, Literal

from ._types import _F32, _Array

def sh_fit(
    normals: _Array,
    values: _Array,
    method: Literal["qp", "ls"] | str = "qp",
    tolerance: float | _Array | None = None,
) -> dict[str, Any]: ...
def sh_eval(coeffs: _Array, normals: _Array) -> _F32: ...
def reflect_dirs(normals: _Array, view: _Array) -> _F32: ...
def reflection_env(
    reflected: _Array,
    values: _Array,
    mask: _Array,
    depth: _Array | None = None,
    size: int = 128,
    max_edge_angle: float = 0.5,
    max_depth_jump: float = 0.05,
    blur_sigma: float = 2.0,
    min_coverage: float = 0.01,
    stage: str = "full",
) -> dict[str, Any]: ...
def fill_holes(map: _Array, covered: _Array) -> _F32: ...
def envmap_lookup(map: _Array, dirs: _Array) -> _F32: ...
def recomposite(
    ids: _Array,
    normals: _Array,
    edited_normals: _Array,
    view: _Array,
    diffuse: _Array,
    reflection: _Array,
    image: _Array,
    patches: Sequence[dict[str, Any]],
    alpha_d: _Array | None = None,
    alpha_r: _Array | None = None,
    alpha: _Array | None = None,
    diffuse_color: _Array | None = None,
    reflection_color: _Array | None = None,
    k_d: float = 1.0,
    k_r: float = 1.0,
    gamma: float = 1.0,
    epsilon: float = ...,
) -> tuple[_F32, dict[str, Any]]: ...
def normals_emboss(normals: _Array, beta: float, mask: _Array | None = None) -> _F32: ...
def normals_bump(
    normals: _Array, height: _Array, strength: float = 1.0, mask: _Array | None = None
) -> _F32: ...
def normals_bilateral(
    normals: _Array,
    depth: _Array,
    sigma_s: float = 3.0,
    sigma_d: float = 0.02,
    mask: _Array | None = None,
) -> _F32: ...
def normals_noise_decal(
    height: int,
    width: int,
    size: float,
    octaves: int,
    seed: int,
    center: tuple[float, float] | Sequence[float],
    radius: float,
) -> _F32: ...


class Recompositor:
    def __new__(
        cls,
        ids: _Array,
        normals: _Array,
        view: _Array,
        diffuse: _Array,
        reflection: _Array,
        image: _Array,
        patches: Sequence[dict[str, Any] | None],
        *,
        alpha_d: _Array | None = None,
        alpha_r: _Array | None = None,
        alpha: _Array | None = None,
        diffuse_color: _Array | None = None,
        reflection_color: _Array | None = None,
        gamma: float = 1.0,
        epsilon: float = ...,
        prepared: bool = False,
    ) -> Recompositor: ...
    def run(
        self,
        out: _F32,
        edited_normals: _Array | None = None,
        rows: slice | tuple[int, int] | None = None,
        cols: slice | tuple[int, int] | None = None,
        k_d: float = 1.0,
        k_r: float = 1.0,
    ) -> dict[str, int]: ...
    def set_patches(self, patches: Sequence[dict[str, Any] | None]) -> None: ...
    @property
    def shape(self) -> tuple[int, int]: ...
    @property
    def prepared_bytes(self) -> int: ...
