//! rokeby-core: the numerics of Rokeby, free of Python.
//!
//! * [`reflection::polar`]  — the rotational factor of the polar decomposition (`ortho` of Ritschel et al. 2009,
//!   eq. 5), exact (Jacobi SVD, f64) and fast (warm-started iteration with an exactness check).
//! * [`reflection::region`] — regions of interest a(q) with smooth-step borders (paper §4 "Regions", eq. 7).
//! * [`reflection::field`]  — the Moving Least Squares rotation field R(q) = ortho(Σ wₙ eₙ rₙᵀ), wₙ = 1/d²
//!   (eqs. 2–7), evaluated per point (mesh vertices) or per pixel (a G-buffer), in parallel.
//! * [`compositing::sh`], [`compositing::reconstruct`], [`compositing::recomposite`] — local shape editing at the compositing stage
//!   (Zubiaga et al. 2016): SH diffuse environments (eq. 1, LS and the QP), dual-paraboloid
//!   reflection environments (eq. 2, hole filling, regularisation) and recompositing (eqs. 3–5).
//! * [`envmaps::envmap`], [`envmaps::prefilter`] — environment maps (lat-long, cube, sphere, dual-paraboloid; exact
//!   direction formulas, seam-correct bilinear lookups, conversions) and their prefiltering under
//!   environment light (Fraser): order-2 SH irradiance, Phong/GGX/Torrance–Sparrow lobes;
//!   [`envmaps::rgbe`] reads and writes Radiance `.hdr` files.
//! * [`unit_vector`] — unit vectors (v/‖v‖, or no direction), the one normalisation of the core.
//! * [`exr_io`] — OpenEXR files (Blender's multilayer renders, recomposited frames, environment
//!   maps) in pure Rust, so no second OpenEXR library enters Blender's process.
//! * [`shadows::silhouette`], [`geometry::bvh`], [`shadows::light_space`], [`shadows::mls2d`], [`shadows::shadow_mesh`], [`shadows::shadow`] — freeform
//!   shadow boundary editing (Mattausch, Igarashi, Wimmer): smooth silhouettes from the light,
//!   shadow handles by ray casting, 2D MLS boundary deformation, the Laplacian shadow mesh.

// One folder per area; every module is named through its area (`rokeby_core::geometry::geodesic`).
pub mod alloc;
pub mod cancel;
pub mod compositing;
pub mod envmaps;
pub mod error;
pub mod exr_io;
pub mod geometry;
pub mod numerical;
pub mod reflection;
pub mod shadows;
pub mod unit_vector;

pub use error::{Result, RokebyError};
