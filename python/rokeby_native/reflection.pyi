"""rokeby_native.reflection: reflection editing (Ritschel et al. 2009), rust/rokeby-core/src/reflection:
the MLS rotation field R(q) (eqs. 2–7), its view-dependent blend (eq. 7) and ortho (eq. 5)."""

from collections.abc import Sequence
from typing import Any, Literal

from ._types import _F32, _Array, _Polar

def field_kernel() -> str: ...
def rotation_field(
    points: _Array,
    constraints: _Array,
    *,
    distances: _Array | None = None,
    regions: Sequence[dict[str, Any]] | None = None,
    normals: _Array | None = None,
    eye: _Array | None = None,
    polar: _Polar = "exact",
    output: Literal["quaternion", "rotation_vector", "view_blend"] = "quaternion",
) -> _F32: ...
def edited_directions(
    positions: _Array,
    normals: _Array,
    eye: _Array,
    constraints: _Array,
    *,
    distances: _Array | None = None,
    regions: Sequence[dict[str, Any]] | None = None,
    polar: _Polar = "fast",
) -> _F32: ...
def view_blend(parts: _Array, directions: _Array, *, ramp: bool = False) -> _F32: ...
def view_blend_render_rows(
    parts: _Array, corner_vert: _Array, first_vert: _Array, *, ramp: bool = False
) -> tuple[bool, _F32, _F32]: ...
def view_blend_rotation_vectors(parts: _Array) -> _F32: ...
def ortho(matrices: _Array, method: _Polar = "exact") -> _F32: ...
