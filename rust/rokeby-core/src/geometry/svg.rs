//! Geodesic distances on a saddle vertex graph (Ying, Wang & He, "Saddle vertex graph (SVG): a
//! novel solution to the discrete geodesic problem", ACM TOG 32(6), 2013).
//!
//! A shortest path on a polyhedral surface is a chain of *direct* geodesics (straight in the
//! unfolding of the faces they cross) that bend only at saddle vertices (total angle over 2π) and
//! reflex boundary vertices (Mitchell, Mount & Papadimitriou 1987, Lemma 3.3). The SVG stores, for
//! every vertex, the direct geodesics to the `k` vertices nearest to it (window propagation without
//! pseudo-sources, [`crate::exact::direct_near`]); a query is one window propagation from the
//! sources to their own `k_source` nearest vertices, then Dijkstra on the graph. Distances are
//! exact where every straight piece of the geodesic lies within a vertex's `k`-neighbourhood
//! (Ying et al. §4); elsewhere the graph path bends at an ordinary vertex and is slightly long.
//!
//! Unlike the paper, every vertex (not only the saddles) has its out-edges: on convex parts, where
//! there are no saddles, the graph path then bends every few edges by small angles, which keeps the
//! error a fraction of a percent instead of growing with the distance. Every edge is the length of
//! a path on the surface, so no distance is ever shorter than the geodesic (or the chord).

use crate::exact::direct_near;
use crate::geodesic::{Mesh, Source};
use crate::mesh::Adjacency;
use crate::radix_heap::RadixHeap;
use rayon::prelude::*;

/// Vertices each vertex is linked to. Measured against exact geodesics on the shared meshes
/// (docs/geodesics.md): the mean error falls like ~1/k while memory and precomputation grow like k.
pub const NEIGHBOURS: usize = 32;
/// Vertices the query's own propagation reaches from the sources: exact distances there.
pub const SOURCE_NEIGHBOURS: usize = 128;

/// The graph in compressed rows: out-edges of each vertex to the vertices of its direct
/// geodesic disk, with their lengths (f32, summed in f64).
pub struct SaddleGraph {
    start: Vec<usize>,
    nbr: Vec<u32>,
    len: Vec<f32>,
}

impl SaddleGraph {
    /// Direct geodesics from every vertex to its `k` nearest vertices (in parallel).
    pub(crate) fn new(mesh: &Mesh, adj: &Adjacency, k: usize) -> Self {
        let nv = mesh.vertices.len();
        const CHUNK: usize = 1024;
        let chunks: Vec<(Vec<u32>, Vec<u32>, Vec<f32>)> = (0..nv.div_ceil(CHUNK))
            .into_par_iter()
            .map_init(
                || vec![f64::INFINITY; nv],
                |dist, c| {
                    let (lo, hi) = (c * CHUNK, ((c + 1) * CHUNK).min(nv));
                    let mut count = Vec::with_capacity(hi - lo);
                    let mut nbr = Vec::with_capacity((hi - lo) * k);
                    let mut len = Vec::with_capacity((hi - lo) * k);
                    for v in lo..hi {
                        let before = nbr.len();
                        for (w, d) in direct_near(mesh, adj, &[Source::Vertex(v)], k, dist) {
                            if w != v && d.is_finite() {
                                nbr.push(w as u32);
                                len.push(d as f32);
                            }
                        }
                        count.push((nbr.len() - before) as u32);
                    }
                    nbr.shrink_to_fit();
                    len.shrink_to_fit();
                    (count, nbr, len)
                },
            )
            .collect();
        let total: usize = chunks.iter().map(|c| c.1.len()).sum();
        let mut start = Vec::with_capacity(nv + 1);
        let mut nbr = Vec::with_capacity(total);
        let mut len = Vec::with_capacity(total);
        start.push(0);
        for (count, n, l) in chunks {
            for c in count {
                start.push(start.last().unwrap() + c as usize);
            }
            nbr.extend_from_slice(&n);
            len.extend_from_slice(&l);
        }
        SaddleGraph { start, nbr, len }
    }

    /// Edges stored (for memory reports).
    pub fn edges(&self) -> usize {
        self.nbr.len()
    }

    /// Distances from one set of sources: their direct geodesics to `k_source` vertices, then
    /// multi-source Dijkstra on the graph.
    pub(crate) fn distances(
        &self,
        mesh: &Mesh,
        adj: &Adjacency,
        set: &[Source],
        k_source: usize,
    ) -> Vec<f64> {
        let nv = mesh.vertices.len();
        let mut dist = vec![f64::INFINITY; nv];
        let seeds = direct_near(mesh, adj, set, k_source, &mut dist);
        let mut heap = RadixHeap::new();
        for (v, d) in seeds {
            dist[v] = d;
            heap.push(d as f32, v as u32);
        }
        while let Some((key, v)) = heap.pop() {
            let v = v as usize;
            let d = dist[v];
            if key > d as f32 {
                continue;
            }
            for e in self.start[v]..self.start[v + 1] {
                let w = self.nbr[e] as usize;
                let nd = d + self.len[e] as f64;
                if nd < dist[w] {
                    dist[w] = nd;
                    heap.push(nd as f32, w as u32);
                }
            }
        }
        dist
    }
}
