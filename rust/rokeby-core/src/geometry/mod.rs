//! Surface geometry: the one triangle mesh and its adjacency ([`mesh`]), the one cotangent
//! Laplacian, geodesic distances (heat, Dijkstra, the saddle vertex graph, exact window
//! propagation, exact unfolding near the source, intrinsic Delaunay flips) and the
//! bounding-volume hierarchy for ray casts.

pub mod bvh;
pub mod exact;
pub mod geodesic;
pub mod intrinsic;
pub mod laplacian;
pub mod mesh;
pub(crate) mod radix_heap;
pub mod saddle_vertex_graph;
pub mod unfold;
