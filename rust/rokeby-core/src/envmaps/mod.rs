//! Environment maps (lecture notes on environment/reflection mapping; Fraser's appearance
//! painting): lat-long, cube, sphere and dual-paraboloid maps, their prefiltering under
//! environment light, and Radiance `.hdr` files.

pub mod envmap;
pub mod prefilter;
pub mod rgbe;
