//! Local shape editing at the compositing stage (Zubiaga et al. 2016): SH diffuse environments
//! (eq. 1), dual-paraboloid reflection environments (eq. 2), recompositing (eqs. 3–5) and the
//! normal-editing tools.

pub mod normals;
pub mod recomposite;
pub mod reconstruct;
pub mod sh;
