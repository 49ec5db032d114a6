"""rokeby_native.geometry: geodesic distances, geodesic and free-form regions and surface
interpolation, rust/rokeby-core/src/geometry."""

from ._types import _F32, _Array, _GeodesicMethod, _Source, _Sources
from typing import Literal

def geodesic_distances(
    vertices: _Array, faces: _Array, sources: _Sources, *, method: _GeodesicMethod = "dense_graph"
) -> _F32: ...
def interpolate(values: _Array, faces: _Array, face_index: _Array, bary: _Array) -> _F32: ...

class GeodesicSolver:
    def __new__(
        cls,
        vertices: _Array,
        faces: _Array,
        *,
        boundary: Literal["average", "neumann"] = "average",
    ) -> GeodesicSolver: ...
    def distances(self, sources: _Sources, method: _GeodesicMethod = "dense_graph") -> _F32: ...
    def geodesic_region(
        self,
        centre: _Source,
        radius: float,
        border: float = 0.0,
        method: _GeodesicMethod = "dense_graph",
    ) -> _F32: ...
    def freeform_region(
        self, weights: _Array, border: float = 0.0, method: _GeodesicMethod = "dense_graph"
    ) -> _F32: ...
    @property
    def factored(self) -> bool: ...
    @property
    def intrinsic_flips(self) -> int | None: ...
    @property
    def num_vertices(self) -> int: ...
    @property
    def num_faces(self) -> int: ...
