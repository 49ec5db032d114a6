"""Type aliases shared by the stubs of rokeby_native's submodules (stubs only: no module of
this name exists at run time)."""

from collections.abc import Sequence
from typing import Literal

import numpy as np
import numpy.typing as npt

_F32 = npt.NDArray[np.float32]
_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_Array = npt.ArrayLike
_Polar = Literal["exact", "svd", "fast", "iterative"]
_GeodesicMethod = Literal["dense_graph", "graph", "heat", "dijkstra", "exact"]
# A surface point: (face index, (b0, b1, b2)) barycentric coordinates.
_SurfacePoint = tuple[int, Sequence[float]]
_Source = int | _SurfacePoint
_Sources = _Array | Sequence[_Source | Sequence[_Source]]
_Layout = Literal["latlong", "cube", "sphere", "paraboloid"] | str
