"""rokeby_native.shadows: freeform shadow boundary editing (Mattausch et al.),
rust/rokeby-core/src/shadows."""

from collections.abc import Sequence
from typing import Any, Literal

from ._types import _F32, _Array

def falloff_factor(l_initial: _Array, l_current: _Array, beta: float) -> float: ...
def silhouettes(
    vertices: _Array,
    faces: _Array,
    *,
    light_position: _Array | None = None,
    light_direction: _Array | None = None,
    normals: _Array | None = None,
) -> list[dict[str, Any]]: ...


class ShadowEditor:
    def __new__(
        cls,
        vertices: _Array,
        faces: _Array,
        receiver_vertices: _Array,
        receiver_faces: _Array,
        *,
        light_position: _Array | None = None,
        light_direction: _Array | None = None,
        normals: _Array | None = None,
        min_loop_vertices: int = 20,
        w_z: float = 2.5,
        constraint_weight: float = 10.0,
    ) -> ShadowEditor: ...
    def loops(self) -> list[dict[str, Any]]: ...
    def handles(self, loop: int, eye: _Array | None = None) -> dict[str, Any]: ...
    def drag(
        self,
        loop: int,
        fixed: tuple[int, int] | Sequence[int],
        moved: int,
        target: _Array,
        *,
        style: Literal["affine", "similarity", "rigid"] = "affine",
        mls_alpha: float = 1.0,
        noise_amplitude: float = 0.0,
        noise_frequency: float = 0.0,
    ) -> dict[str, Any]: ...
    def prepare_drag(
        self,
        loop: int,
        fixed: tuple[int, int],
        moved: int,
        *,
        style: str = "affine",
        mls_alpha: float = 1.0,
        noise_amplitude: float = 0.0,
    ) -> bool: ...
    def drag_is_incremental(self) -> bool: ...
    def commit(self) -> None: ...
    def cancel(self) -> None: ...
    def reset(self) -> None: ...
    def shadow_mesh(self) -> _F32: ...
    @property
    def factored(self) -> bool: ...
    @property
    def num_loops(self) -> int: ...
    @property
    def num_receiver_faces(self) -> int: ...
