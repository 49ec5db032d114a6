"""Type stubs of `rokeby_native`, the pyo3 binding of rokeby-core (rust/rokeby-py).

Maintained by hand; tests/test_native_stubs.py checks that every public name of the built module
has a stub here and that each function's parameters (names, kinds, defaults) match the module's
`__text_signature__`. Array arguments accept anything `numpy.asarray` reads (float32/float64;
float64 is stored as float32), index arrays integers. Errors: bad input → ValueError/TypeError
naming the argument, memory → MemoryError, a numerical failure → NumericalError (a RuntimeError),
cancelled → KeyboardInterrupt, a bug in the core → RuntimeError. See docs/errors.md.
"""

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

__version__: str

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

class NumericalError(RuntimeError):
    """A numerical method of the core failed on input that passed validation (a factorisation
    broke down, an iteration did not converge)."""

# --- control ---------------------------------------------------------------------------------

def cancel() -> None: ...
def field_kernel() -> str: ...

# --- reflection: the MLS rotation field (Ritschel et al. 2009) -------------------------------

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

# --- geometry: geodesic distances and regions ------------------------------------------------

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

# --- compositing: local shape editing (Zubiaga et al. 2016) ----------------------------------

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

# --- envmap: environment maps and their prefiltering -----------------------------------------

_Layout = Literal["latlong", "cube", "sphere", "paraboloid"] | str

def env_convert(
    image: _Array, layout_in: _Layout, layout_out: _Layout, size: int, supersample: int = 1
) -> _F32: ...
def env_sample(image: _Array, layout: _Layout, directions: _Array) -> _F32: ...
def env_prefilter(
    image: _Array,
    lobe: str,
    params: Sequence[float] | _Array,
    texels_per_radius: float = 6.0,
    tail: float = 1e-5,
) -> list[_F32]: ...
def env_irradiance(image: _Array, size: int = 32) -> dict[str, Any]: ...
def env_reference(image: _Array, lobe: str, directions: _Array, param: float = 0.0) -> _F64: ...
def rgbe_decode(data: bytes) -> _F32: ...
def rgbe_encode(pixels: _Array) -> bytes: ...

# --- OpenEXR files (pure Rust: no OpenEXR C library in the process) ---------------------------

def exr_read(data: bytes, dwa: bool = False) -> list[dict[str, Any]]: ...
def exr_write(
    channels: dict[str, _Array],
    header: dict[str, str] | None = None,
    compression: str = "zip",
    half: Sequence[str] | None = None,
) -> bytes: ...

# --- shadow: freeform shadow boundary editing (Mattausch et al.) -----------------------------

def shadow_falloff(l_initial: _Array, l_current: _Array, beta: float) -> float: ...
def shadow_silhouettes(
    vertices: _Array,
    faces: _Array,
    *,
    light_position: _Array | None = None,
    light_direction: _Array | None = None,
    normals: _Array | None = None,
) -> list[dict[str, Any]]: ...

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
