//! Freeform shadow boundary editing (Mattausch, Igarashi, Wimmer): smooth silhouettes from the
//! light, light spaces (frusta per caster or per loop), 2D MLS boundary deformation, the Laplacian
//! shadow mesh and the editor that ties them together.

pub mod light_space;
pub mod mls2d;
pub mod shadow;
pub mod shadow_mesh;
pub mod silhouette;
