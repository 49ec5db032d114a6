//! Geodesic distances on a saddle vertex graph (Ying, Wang & He, "Saddle vertex graph (SVG): a
//! novel solution to the discrete geodesic problem", ACM TOG 32(6), 2013).
//!
//! A shortest path on a polyhedral surface is a chain of *direct* geodesics (straight in the
//! unfolding of the faces they cross) that bend only at saddle vertices (total angle over 2π) and
//! reflex boundary vertices (Mitchell, Mount & Papadimitriou 1987, Lemma 3.3). The SVG stores, for
//! every vertex, the direct geodesics to the `k` vertices nearest to it (window propagation without
//! pseudo-sources, [`crate::geometry::exact::direct_near`]); a query is one window propagation from the
//! sources to their own `k_source` nearest vertices, then Dijkstra on the graph. Distances are
//! exact where every straight piece of the geodesic lies within a vertex's `k`-neighbourhood
//! (Ying et al. §4); elsewhere the graph path bends at an ordinary vertex and is slightly long.
//!
//! Unlike the paper, every vertex (not only the saddles) has its out-edges: on convex parts, where
//! there are no saddles, the graph path then bends every few edges by small angles, which keeps the
//! error a fraction of a percent instead of growing with the distance. Every edge is the length of
//! a path on the surface, so no distance is ever shorter than the geodesic (or the chord).

use crate::geometry::exact::{direct_near, Queue};
use crate::geometry::geodesic::{Graph, Mesh, Source};
use crate::geometry::mesh::Adjacency;
use rayon::prelude::*;
use std::sync::Mutex;

/// Vertices each vertex is linked to. Measured against exact geodesics on the shared meshes
/// (docs/geodesics.md): the mean error falls like ~1/k while memory and precomputation grow like k.
pub const NEIGHBOURS: usize = 32;
/// Vertices the query's own propagation reaches from the sources: exact distances there.
pub const SOURCE_NEIGHBOURS: usize = 128;

/// The dense graph of [`crate::geometry::geodesic::Method::DenseGraph`]: vertices each vertex is linked to
/// before pruning. Measured against exact geodesics on the shared meshes and on generated meshes
/// with seams, holes, pieces, needles and slivers (docs/geodesics.md): the mean error falls like
/// ~1/k; pruning keeps the edges a vertex stores (and the query's time) near those of k = 32.
pub const DENSE_NEIGHBOURS: usize = 96;
/// The dense graph's pruning: an edge v→w is dropped where a two-edge path of the graph is at
/// most this much longer, relatively ([`prune_rows`]).
pub const DENSE_PRUNE: f64 = 0.004;
/// The dense graph's query: vertices its own propagation reaches from the sources.
pub const DENSE_SOURCE_NEIGHBOURS: usize = 48;

/// The graph: out-edges of each vertex to the vertices of its direct geodesic disk, with their
/// lengths (f32, summed in f64), in the cache-ordered rows that the edge graph's Dijkstra uses
/// ([`Graph`]: Morton order, bucket queue of quantised keys, buffers kept between queries).
pub struct SaddleGraph {
    graph: Graph,
    /// The window queues of the queries' propagations, one per query running at once.
    queues: Mutex<Vec<Queue>>,
}

impl SaddleGraph {
    /// Direct geodesics from every vertex to its `k` nearest vertices (in parallel); with
    /// `prune = Some(eps)`, the edges that a two-edge path replaces within `eps` dropped.
    pub(crate) fn new(mesh: &Mesh, adj: &Adjacency, k: usize, prune: Option<f64>) -> Self {
        let nv = mesh.vertices.len();
        const CHUNK: usize = 1024;
        let chunks: Vec<(Vec<u32>, Vec<_>)> = (0..nv.div_ceil(CHUNK))
            .into_par_iter()
            .map_init(
                || (vec![f64::INFINITY; nv], Vec::new(), Queue::default()),
                |(dist, touched, queue), c| {
                    let (lo, hi) = (c * CHUNK, ((c + 1) * CHUNK).min(nv));
                    let mut count = Vec::with_capacity(hi - lo);
                    let mut rows: Vec<(u32, f32)> = Vec::with_capacity((hi - lo) * k);
                    for v in lo..hi {
                        let before = rows.len();
                        direct_near(mesh, adj, &[Source::Vertex(v)], k, dist, touched, queue);
                        for w in touched.drain(..) {
                            let d = std::mem::replace(&mut dist[w], f64::INFINITY);
                            if w != v && d.is_finite() {
                                rows.push((w as u32, d as f32));
                            }
                        }
                        count.push((rows.len() - before) as u32);
                    }
                    rows.shrink_to_fit();
                    (count, rows)
                },
            )
            .collect();
        let total: usize = chunks.iter().map(|c| c.1.len()).sum();
        let mut start = Vec::with_capacity(nv + 1);
        let mut rows = Vec::with_capacity(total);
        start.push(0);
        for (count, r) in chunks {
            for c in count {
                start.push(start.last().unwrap() + c as usize);
            }
            rows.extend_from_slice(&r);
        }
        if let Some(eps) = prune {
            (start, rows) = prune_rows(nv, &start, &rows, eps);
        }
        SaddleGraph {
            graph: Graph::new(&mesh.vertices, &start, &rows),
            queues: Mutex::new(Vec::new()),
        }
    }

    /// Edges stored (for memory reports).
    pub fn edges(&self) -> usize {
        self.graph.edges()
    }

    /// Distances from one set of sources: their direct geodesics to `k_source` vertices, then
    /// multi-source Dijkstra on the graph; `emit(v, d)` receives the distance of every vertex.
    pub(crate) fn distances_with(
        &self,
        mesh: &Mesh,
        adj: &Adjacency,
        set: &[Source],
        k_source: usize,
        emit: impl FnMut(usize, f64),
    ) {
        let mut queue = {
            let mut pool = self.queues.lock().unwrap_or_else(|e| e.into_inner());
            pool.pop().unwrap_or_default()
        };
        self.graph.dijkstra(
            |near, touched| direct_near(mesh, adj, set, k_source, near, touched, &mut queue),
            emit,
        );
        self.queues
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(queue);
    }
}

/// Drops the out-edge v→w wherever a two-edge path v→u→w of the graph is at most `(1 + eps)`
/// times as long: Dijkstra then reaches w through u at nearly the same distance. Each replacement
/// uses strictly shorter edges, so chains of replacements end, and a dropped edge costs at most
/// a factor (1 + eps) per level of replacement.
fn prune_rows(
    nv: usize,
    start: &[usize],
    rows: &[(u32, f32)],
    eps: f64,
) -> (Vec<usize>, Vec<(u32, f32)>) {
    const CHUNK: usize = 1024;
    // Per chunk of vertices: the count of edges kept per vertex, and the kept edges.
    type Kept = (Vec<u32>, Vec<(u32, f32)>);
    let chunks: Vec<Kept> = (0..nv.div_ceil(CHUNK))
        .into_par_iter()
        .map_init(
            || (vec![f32::INFINITY; nv], Vec::new()),
            |(near, drop), c| {
                let (lo, hi) = (c * CHUNK, ((c + 1) * CHUNK).min(nv));
                let mut count = Vec::with_capacity(hi - lo);
                let mut out = Vec::new();
                for v in lo..hi {
                    let row = &rows[start[v]..start[v + 1]];
                    drop.clear();
                    drop.resize(row.len(), false);
                    for &(u, du) in row {
                        let ru = &rows[start[u as usize]..start[u as usize + 1]];
                        for &(x, dx) in ru {
                            near[x as usize] = dx;
                        }
                        for (i, &(w, dw)) in row.iter().enumerate() {
                            if dw > du
                                && (du as f64 + near[w as usize] as f64) <= (1.0 + eps) * dw as f64
                            {
                                drop[i] = true;
                            }
                        }
                        for &(x, _) in ru {
                            near[x as usize] = f32::INFINITY;
                        }
                    }
                    let before = out.len();
                    out.extend(row.iter().zip(drop.iter()).filter(|e| !*e.1).map(|e| *e.0));
                    count.push((out.len() - before) as u32);
                }
                (count, out)
            },
        )
        .collect();
    let mut start = Vec::with_capacity(nv + 1);
    let mut out = Vec::new();
    start.push(0);
    for (count, r) in chunks {
        for c in count {
            start.push(start.last().unwrap() + c as usize);
        }
        out.extend_from_slice(&r);
    }
    (start, out)
}

#[cfg(test)]
mod tests {
    //! A plain query (the graph's rows in mesh order, a radix heap on f32
    //! keys, fresh buffers per query) kept as the oracle: the rewrite must give the same bits.
    use super::*;
    use crate::geometry::mesh::shared_test_mesh;
    use crate::geometry::radix_heap::RadixHeap;

    /// The oracle graph: compressed rows in mesh vertex order.
    struct ReferenceGraph {
        start: Vec<usize>,
        nbr: Vec<u32>,
        len: Vec<f32>,
    }

    /// The direct geodesics of a set (vertex, distance), in the order they were reached.
    fn near(mesh: &Mesh, adj: &Adjacency, set: &[Source], k: usize) -> Vec<(usize, f64)> {
        let mut dist = vec![f64::INFINITY; mesh.vertices.len()];
        let mut touched = Vec::new();
        direct_near(
            mesh,
            adj,
            set,
            k,
            &mut dist,
            &mut touched,
            &mut Queue::default(),
        );
        touched.into_iter().map(|v| (v, dist[v])).collect()
    }

    impl ReferenceGraph {
        fn new(mesh: &Mesh, adj: &Adjacency, k: usize) -> Self {
            let (mut start, mut nbr, mut len) = (vec![0], Vec::new(), Vec::new());
            for v in 0..mesh.vertices.len() {
                for (w, d) in near(mesh, adj, &[Source::Vertex(v)], k) {
                    if w != v && d.is_finite() {
                        nbr.push(w as u32);
                        len.push(d as f32);
                    }
                }
                start.push(nbr.len());
            }
            ReferenceGraph { start, nbr, len }
        }

        /// A plain `SaddleGraph::distances` (the oracle).
        fn distances(&self, mesh: &Mesh, adj: &Adjacency, set: &[Source], k: usize) -> Vec<f64> {
            let mut dist = vec![f64::INFINITY; mesh.vertices.len()];
            let mut heap = RadixHeap::new();
            for (v, d) in near(mesh, adj, set, k) {
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

    #[test]
    fn saddle_graph_query_matches_the_plain_implementation_bit_for_bit() {
        use crate::geometry::geodesic::SurfacePoint;
        let mut any = false;
        for name in ["teapot.obj", "spot.obj", "homer.obj", "fandisk.obj"] {
            let Some(mesh) = shared_test_mesh(name) else {
                continue;
            };
            any = true;
            let adj = Adjacency::new(&mesh);
            let g = SaddleGraph::new(&mesh, &adj, NEIGHBOURS, None);
            let old = ReferenceGraph::new(&mesh, &adj, NEIGHBOURS);
            assert_eq!(g.edges(), old.nbr.len(), "{name}");
            let (nv, nf) = (mesh.vertices.len(), mesh.faces.len());
            let p = |face: usize, bary: [f64; 3]| Source::Point(SurfacePoint { face, bary });
            let sets = [
                vec![Source::Vertex(mesh.faces[nf / 4][0])],
                vec![Source::Vertex(nv / 3)],
                vec![p(nf / 2, [0.2, 0.3, 0.5])],
                vec![p(nf / 5, [0.0, 0.4, 0.6])],
                [0, nv / 4, nv / 2, 3 * nv / 4].map(Source::Vertex).to_vec(),
            ];
            // Twice, so that the second round runs on reused buffers.
            for round in 0..2 {
                for (s, set) in sets.iter().enumerate() {
                    let want = old.distances(&mesh, &adj, set, SOURCE_NEIGHBOURS);
                    assert!(want.iter().any(|d| d.is_finite() && *d > 0.0));
                    let mut got = vec![f64::NAN; nv];
                    g.distances_with(&mesh, &adj, set, SOURCE_NEIGHBOURS, |v, d| got[v] = d);
                    for v in 0..nv {
                        assert_eq!(
                            got[v].to_bits(),
                            want[v].to_bits(),
                            "{name}, set {s}, vertex {v}, round {round}: {} vs {}",
                            got[v],
                            want[v]
                        );
                    }
                }
            }
        }
        assert!(any, "no shared mesh found (set ROKEBY_SHARED)");
    }
}
