//! Geodesic distances on triangle meshes (Ritschel et al. 2009, §6.2, and what scanned meshes need).
//!
//! * [`Method::Dijkstra`]: shortest paths along mesh edges, multi-source — the paper's baseline.
//!   Fast; always over-estimates (edge paths zig-zag), however fine the mesh.
//! * [`Method::Heat`]: the heat method (Crane, Weischedel, Wardetzky 2013/2017): one short heat
//!   flow (A + tL) u = δ, the normalised gradient X = −∇u/|∇u|, then the Poisson problem L φ = ∇·X.
//!   It runs on the intrinsic Delaunay triangulation of the mesh ([`crate::geometry::intrinsic`]), which
//!   keeps it accurate on scanned meshes with obtuse slivers. Paths cross faces, so it converges to the true geodesic distance as the mesh is refined. Both
//!   sparse matrices are factored once per mesh (faer's sparse Cholesky) and reused by every query:
//!   moving a handle costs two triangular solves, not a factorisation.
//!
//! * [`Method::Graph`]: Dijkstra on a saddle vertex graph of direct geodesics ([`crate::geometry::saddle_vertex_graph`],
//!   Ying, Wang & He 2013): under 0.5 % mean error on the shared meshes, after a graph built once.
//! * [`Method::DenseGraph`] (the default, [`Method::DEFAULT`]): the same on a denser graph whose
//!   redundant edges are pruned: under 0.25 % mean error at about the same query time.
//! * [`Method::Exact`]: exact polyhedral geodesics by window propagation ([`crate::geometry::exact`]).
//!
//! Sources are vertices or surface points (a face and barycentric coordinates), several per
//! distance field (the distance to the nearest). Inside the source's own triangle the distance is
//! the exact straight-line one, and so are the values on the 1-ring of a vertex source, where the
//! heat method is least accurate. Vertices that no source can reach (another connected component,
//! unreferenced vertices) get +inf.

use crate::error::{Result, RokebyError};
use crate::geometry::laplacian::{face_cotangents, FaceCotangents};
pub use crate::geometry::mesh::{Mesh, SurfacePoint};
use crate::numerical::{self, SparseMatrix, SymbolicCholesky, Triplet};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::Mat;
use glam::DVec3;
use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::{Mutex, OnceLock};

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Source {
    Vertex(usize),
    Point(SurfacePoint),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    Dijkstra,
    Heat,
    /// Exact polyhedral geodesics by window propagation ([`crate::geometry::exact`]).
    Exact,
    /// Dijkstra on a saddle vertex graph of direct geodesics ([`crate::geometry::saddle_vertex_graph`]): near-exact, with a
    /// query as fast as Dijkstra's after a precomputation.
    Graph,
    /// [`Method::Graph`] on a denser saddle vertex graph (each vertex linked to its
    /// [`crate::geometry::saddle_vertex_graph::DENSE_NEIGHBOURS`] nearest vertices), its redundant edges pruned
    /// ([`crate::geometry::saddle_vertex_graph::DENSE_PRUNE`]): about half the error at about the same query time.
    DenseGraph,
}

impl Method {
    /// The method of every entry point that does not name one (the binding's functions, new
    /// mirrors in the add-on).
    pub const DEFAULT: Method = Method::DenseGraph;

    /// Every method with its name, in the order they were added.
    pub const ALL: [(&'static str, Method); 5] = [
        ("heat", Method::Heat),
        ("dijkstra", Method::Dijkstra),
        ("exact", Method::Exact),
        ("graph", Method::Graph),
        ("dense_graph", Method::DenseGraph),
    ];

    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.iter().find(|m| m.0 == name).map(|m| m.1)
    }

    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|m| m.1 == self).map_or("", |m| m.0)
    }
}

/// A graph on the mesh vertices in compressed rows (CSR), built once per mesh, and its Dijkstra:
/// the edge graph of [`Method::Dijkstra`] and the saddle vertex graph of [`Method::Graph`]
/// ([`crate::geometry::saddle_vertex_graph`]). The rows are stored in *cache order*, the vertices sorted along a Morton
/// (Z-order) curve of their positions, so that a Dijkstra front, which moves across the surface,
/// reads and writes nearby memory; meshes come in any order (midpoint subdivision, for one, puts
/// neighbours hundreds of thousands of indices apart). `rank` and `order` map between mesh vertex
/// ids and cache positions.
pub(crate) struct Graph {
    /// Row of cache position p: `edges[start[p]..start[p + 1]]`.
    start: Vec<usize>,
    /// (neighbour's cache position, edge length): compact (u32 index, f32 length, relative rounding
    /// 6e-8; summed along paths in f64) and interleaved, so that a row is one read.
    edges: Vec<(u32, f32)>,
    /// order[p]: the mesh vertex at cache position p.
    order: Vec<u32>,
    /// rank[v]: the cache position of mesh vertex v.
    rank: Vec<u32>,
    /// Dijkstra's queue keys: distance × key_scale, rounded down (see [`Graph::key`]).
    key_scale: f64,
    /// The keys the longest edge spans, plus 2: the bucket queue's window.
    key_span: usize,
    /// Dijkstra's buffers, one per query running at once, reused by later queries.
    work: Mutex<Vec<DijkstraWork>>,
}

/// Queue keys per short edge: the quantum of Dijkstra's keys is a quarter of the 10th percentile
/// of the edge lengths. Vertices whose distances share a quantum pop in any order, which costs a
/// second settling only across an edge shorter than the quantum (rare by this choice), and an
/// edge spans a few keys, so that a bucket queue with a short window holds the whole front.
const KEYS_PER_SHORT_EDGE: f64 = 4.0;

/// Interleaves the low 21 bits of `x` with two zero bits between each (for a 63-bit Morton code).
fn spread3(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x001f_0000_0000_ffff;
    x = (x | x << 16) & 0x001f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Mesh vertices sorted along the Morton curve of their positions (ties by index).
fn morton_order(vertices: &[DVec3]) -> Vec<u32> {
    let lo = vertices.iter().fold(DVec3::INFINITY, |m, &x| m.min(x));
    let hi = vertices.iter().fold(DVec3::NEG_INFINITY, |m, &x| m.max(x));
    let scale = (((1u64 << 21) - 1) as f64) / (hi - lo).max_element().max(1e-300);
    let mut keyed: Vec<(u64, u32)> = vertices
        .par_iter()
        .enumerate()
        .map(|(i, &x)| {
            let q = ((x - lo) * scale).max(DVec3::ZERO);
            let code = spread3(q.x as u64) | spread3(q.y as u64) << 1 | spread3(q.z as u64) << 2;
            (code, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// The unique edges of the mesh's faces, both directions, sorted, and the mean edge length
/// (summed over them in this order).
fn mesh_edges(mesh: &Mesh) -> (Vec<(u32, u32)>, f64) {
    let mut edges: Vec<(u32, u32)> = Vec::with_capacity(mesh.faces.len() * 6);
    for f in &mesh.faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if a != b {
                edges.push((a as u32, b as u32));
                edges.push((b as u32, a as u32));
            }
        }
    }
    edges.par_sort_unstable();
    edges.dedup();
    let mean_edge = if edges.is_empty() {
        0.0
    } else {
        edges
            .iter()
            .map(|&(a, b)| edge_length(mesh, a, b) as f64)
            .sum::<f64>()
            / edges.len() as f64
    };
    (edges, mean_edge)
}

fn edge_length(mesh: &Mesh, a: u32, b: u32) -> f32 {
    mesh.vertices[a as usize].distance(mesh.vertices[b as usize]) as f32
}

impl Graph {
    /// The edge graph of the mesh (unique edges, their lengths) and the mean edge length.
    fn edge_graph(mesh: &Mesh) -> (Self, f64) {
        let nv = mesh.vertices.len();
        let (edges, mean_edge) = mesh_edges(mesh);
        // Rows of the mesh order (edges are sorted by their first vertex).
        let mut start = vec![0usize; nv + 1];
        for &(a, _) in &edges {
            start[a as usize + 1] += 1;
        }
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let rows: Vec<(u32, f32)> = edges
            .iter()
            .map(|&(a, b)| (b, edge_length(mesh, a, b)))
            .collect();
        (Graph::new(&mesh.vertices, &start, &rows), mean_edge)
    }

    /// The graph of the out-edges `rows[start[v]..start[v + 1]]` (mesh vertex, length) of each
    /// mesh vertex v, laid out in cache order.
    pub(crate) fn new(vertices: &[DVec3], start: &[usize], rows: &[(u32, f32)]) -> Self {
        let order = morton_order(vertices);
        let mut rank = vec![0u32; vertices.len()];
        for (p, &v) in order.iter().enumerate() {
            rank[v as usize] = p as u32;
        }
        let mut cache_start = Vec::with_capacity(vertices.len() + 1);
        cache_start.push(0);
        let mut out: Vec<(u32, f32)> = Vec::with_capacity(rows.len());
        for &v in &order {
            let row = out.len();
            let v = v as usize;
            out.extend(
                rows[start[v]..start[v + 1]]
                    .iter()
                    .map(|&(w, l)| (rank[w as usize], l)),
            );
            out[row..].sort_unstable_by_key(|e| e.0);
            cache_start.push(out.len());
        }
        let short_edge = if out.is_empty() {
            0.0
        } else {
            let mut l: Vec<f32> = out.iter().map(|e| e.1).collect();
            let k = l.len() / 10;
            *l.select_nth_unstable_by(k, f32::total_cmp).1 as f64
        };
        let quantum = if short_edge > 0.0 {
            short_edge / KEYS_PER_SHORT_EDGE
        } else if !out.is_empty() {
            let mean = out.iter().map(|e| e.1 as f64).sum::<f64>() / out.len() as f64;
            mean / (2.0 * KEYS_PER_SHORT_EDGE)
        } else {
            0.0
        };
        let key_scale = if quantum > 0.0 { 1.0 / quantum } else { 0.0 };
        let longest = out.iter().fold(0.0f32, |m, e| m.max(e.1)) as f64;
        Graph {
            start: cache_start,
            edges: out,
            order,
            rank,
            key_scale,
            // Beyond 2^16 buckets the longest edges go through the queue's overflow instead.
            key_span: ((longest * key_scale) as usize).min(1 << 16) + 2,
            work: Mutex::new(Vec::new()),
        }
    }

    /// Edges stored.
    pub(crate) fn edges(&self) -> usize {
        self.edges.len()
    }

    /// Dijkstra's queue key of distance `d`: non-decreasing in d (a rounded-down multiple of the
    /// quantum, saturating at u32::MAX), which is all the bucket queue and the label-correcting
    /// loop need; ties and keys that saturate only cost a vertex being settled again.
    #[inline]
    fn key(&self, d: f64) -> u32 {
        (d * self.key_scale) as u32
    }

    /// Asks the processor to bring the row of cache position `p` into its cache while the current
    /// row is relaxed: Dijkstra reads the rows in the order of distance, not of memory, so the
    /// hardware's own prefetching does not foresee them, and on the saddle vertex graph (32 edges,
    /// 256 bytes a row, the whole graph beyond the core's cache on meshes of a few thousand
    /// vertices) the wait for each row was most of a query's time.
    #[inline(always)]
    fn prefetch_row(&self, p: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let row = &self.edges[self.start[p]..self.start[p + 1]];
            let bytes = std::mem::size_of_val(row);
            let first = row.as_ptr().cast::<i8>();
            let mut off = 0;
            while off < bytes + 63 {
                // SAFETY: a prefetch is a hint that never faults nor changes memory, whatever the
                // address (here inside or one line past the row); SSE is part of x86_64.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(first.wrapping_add(off)) };
                off += 64;
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = p;
    }

    /// Neighbours of mesh vertex `v` and the edge lengths, as mesh vertex ids.
    fn neighbours(&self, v: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let p = self.rank[v] as usize;
        self.edges[self.start[p]..self.start[p + 1]]
            .iter()
            .map(move |&(q, l)| (self.order[q as usize] as usize, l as f64))
    }

    /// Multi-source Dijkstra with a bucket queue of quantised keys
    /// ([`crate::geometry::radix_heap::BucketQueue`]) and buffers kept between queries. `seed(near, touched)`
    /// writes the seeds' distances into `near` (mesh order, all +inf on entry) and the vertices it
    /// set into `touched` (empty on entry); `emit(v, d)` receives the distance of every mesh
    /// vertex v (+inf where no seed reaches).
    ///
    /// The result is, for every vertex, the smallest over the seeds u and graph paths from u of
    /// near(u) + the path's edge lengths, summed in f64 from u outward. Rounding is monotone, so
    /// that smallest value is the one fixed point of the relaxation whatever the order in which
    /// vertices are settled (the quantised keys can only make a vertex be settled again, never
    /// stop short of it): it depends neither on the vertex order nor on the queue, and for a set
    /// of sources it is the minimum of the fields of each source alone.
    pub(crate) fn dijkstra(
        &self,
        seed: impl FnOnce(&mut [f64], &mut Vec<usize>),
        mut emit: impl FnMut(usize, f64),
    ) {
        let mut w = {
            let mut pool = self.work.lock().unwrap_or_else(|e| e.into_inner());
            pool.pop()
        }
        .unwrap_or_else(|| {
            let nv = self.order.len();
            DijkstraWork {
                dist: vec![f64::INFINITY; nv],
                near: vec![f64::INFINITY; nv],
                settled: vec![false; nv],
                touched: Vec::new(),
                queue: crate::geometry::radix_heap::BucketQueue::new(self.key_span),
            }
        });
        let DijkstraWork {
            dist,
            near,
            settled,
            touched,
            queue,
        } = &mut w;
        seed(near, touched);
        queue.clear();
        for &v in touched.iter() {
            let (p, d) = (self.rank[v] as usize, near[v]);
            near[v] = f64::INFINITY;
            if d < dist[p] {
                dist[p] = d;
                queue.push(self.key(d), p as u32);
            }
        }
        touched.clear();
        while let Some((key, p)) = queue.pop() {
            let p = p as usize;
            let d = dist[p];
            if settled[p] || key > self.key(d) {
                // Settled with this very distance already (two entries of one key), or a stale
                // entry: p has a shorter distance, with its own entry.
                continue;
            }
            settled[p] = true;
            for &next in queue.peek(2) {
                self.prefetch_row(next as usize);
            }
            for &(q, l) in &self.edges[self.start[p]..self.start[p + 1]] {
                let nd = d + l as f64;
                let q = q as usize;
                if nd < dist[q] {
                    dist[q] = nd;
                    settled[q] = false;
                    queue.push(self.key(nd), q as u32);
                }
            }
        }
        for (p, d) in dist.iter_mut().enumerate() {
            emit(self.order[p] as usize, *d);
            *d = f64::INFINITY;
        }
        settled.fill(false);
        self.work.lock().unwrap_or_else(|e| e.into_inner()).push(w);
    }
}

/// Buffers of one Dijkstra query, kept by the graph between queries (no allocation per query).
/// Between queries every entry of `dist` and `near` is +inf, of `settled` false, and `touched` is
/// empty.
struct DijkstraWork {
    /// Distances in the graph's cache order.
    dist: Vec<f64>,
    /// The seeds' distances, in mesh order.
    near: Vec<f64>,
    /// Whether a vertex's outgoing edges were relaxed from its current distance (cache order).
    settled: Vec<bool>,
    touched: Vec<usize>,
    queue: crate::geometry::radix_heap::BucketQueue,
}

/// A heap entry: an f32 key (8-byte entries keep the heap in cache) and the vertex. The exact f64
/// distance lives in the distance array; a key rounded a little low or high can only make a vertex
/// be settled again later (label correcting), never give a wrong distance.
#[derive(PartialEq)]
struct HeapItem(f32, u32);
impl Eq for HeapItem {}
impl PartialOrd for HeapItem {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for HeapItem {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on distance.
        other
            .0
            .total_cmp(&self.0)
            .then_with(|| other.1.cmp(&self.1))
    }
}

/// The heat method's data for one mesh, computed once: the intrinsic Delaunay triangulation
/// (faces laid out in 2D), and the factorisations of both linear systems.
struct Heat {
    heat: Llt<u32, f64>,
    /// The heat flow with u = 0 on the boundary (meshes with boundary only): the final heat is the
    /// average of the Neumann and Dirichlet flows (Crane et al. 2013, §3.3), which removes most of
    /// the error the Neumann condition alone leaves near boundaries.
    heat_dirichlet: Option<Llt<u32, f64>>,
    poisson: Llt<u32, f64>,
    /// Intrinsic faces with positive area: vertices, 2D layout, cotangent at each corner, 1/(2·area).
    faces: Vec<HeatFace>,
    flips: usize,
}

struct HeatFace {
    v: [u32; 3],
    /// The 2D layout is corner 0 at the origin, corner 1 at (l01, 0), corner 2 at `p2`.
    l01: f64,
    p2: glam::DVec2,
    cot: [f64; 3],
}

impl HeatFace {
    #[inline]
    fn layout(&self) -> [glam::DVec2; 3] {
        [glam::DVec2::ZERO, glam::DVec2::new(self.l01, 0.0), self.p2]
    }
    #[inline]
    fn vertex(&self, k: usize) -> usize {
        self.v[k] as usize
    }
}

/// Near-field radii, in mean edge lengths: within NEAR_R1 of a source the heat method's direction
/// field is replaced by the gradient of the chord distance to the source (third-order accurate on
/// a smooth surface, where the heat gradient is least resolved), blended back by NEAR_R2.
/// Measured against exact geodesics (docs/benchmarks.md): spot's largest error 16.6 % → 11.2 %,
/// bunny's mean 0.92 % → 0.89 %; larger radii start to hurt on curved parts.
const NEAR_R1: f64 = 3.0;
const NEAR_R2: f64 = 6.0;

/// Keeps what does not change while handles move: the edge graph, the connected components and
/// (built on first use) the heat method's two Cholesky factorisations.
pub struct GeodesicSolver {
    mesh: Mesh,
    /// Average the Neumann and Dirichlet heat flows on meshes with boundary (more accurate near
    /// boundaries; one more factorisation's time and memory).
    average_boundary: bool,
    graph: Graph,
    component: Vec<usize>,
    heat: OnceLock<std::result::Result<Heat, RokebyError>>,
    mean_edge: f64,
    /// Faces across each edge and around each vertex, for the unfolding next to sources.
    adjacency: crate::geometry::mesh::Adjacency,
    /// Vertices where exact shortest paths may bend (saddles, boundary), made on first use.
    pseudo_sources: OnceLock<Vec<bool>>,
    /// Every face unfolded onto each of its edges, for the exact method, made on first use.
    face_unfolding: OnceLock<crate::geometry::exact::FaceUnfolding>,
    /// The saddle vertex graph, made on the first [`Method::Graph`] query.
    saddle_graph: OnceLock<crate::geometry::saddle_vertex_graph::SaddleGraph>,
    /// The dense, pruned saddle vertex graph, made on the first [`Method::DenseGraph`] query.
    dense_graph: OnceLock<crate::geometry::saddle_vertex_graph::SaddleGraph>,
}

/// The lower triangle (which is all a Cholesky factorisation with `Side::Lower` reads) of
/// `off_scale · W + diag`, where W holds one weight per unique edge (i > j) and `diag` the diagonal.
/// Built from compact per-edge sums rather than per-triangle triplets, to keep the peak memory of
/// large meshes low.
fn lower_matrix(
    n: usize,
    edges: &[(u32, u32, f64)],
    off_scale: f64,
    diag: &[f64],
) -> Result<SparseMatrix> {
    let mut t: Vec<Triplet<u32, u32, f64>> = Vec::with_capacity(edges.len() + n);
    t.extend(
        edges
            .iter()
            .map(|&(i, j, w)| Triplet::new(i, j, off_scale * w)),
    );
    t.extend(
        diag.iter()
            .enumerate()
            .map(|(i, &d)| Triplet::new(i as u32, i as u32, d)),
    );
    numerical::assemble(n, &t, "heat")
}

impl GeodesicSolver {
    pub fn new(mesh: Mesh) -> Self {
        Self::with_boundary_averaging(mesh, true)
    }

    /// `average_boundary = false` keeps only the Neumann heat flow: a third less memory and
    /// factorisation time on meshes with boundary, somewhat less accurate near the boundary.
    pub fn with_boundary_averaging(mesh: Mesh, average_boundary: bool) -> Self {
        let (graph, mean_edge) = Graph::edge_graph(&mesh);
        let nv = mesh.vertices.len();
        // Connected components by breadth-first search over the edge graph.
        let mut component = vec![usize::MAX; nv];
        let mut next = 0;
        let mut stack = Vec::new();
        for s in 0..nv {
            if component[s] != usize::MAX {
                continue;
            }
            component[s] = next;
            stack.push(s);
            while let Some(v) = stack.pop() {
                for (w, _) in graph.neighbours(v) {
                    if component[w] == usize::MAX {
                        component[w] = next;
                        stack.push(w);
                    }
                }
            }
            next += 1;
        }
        let adjacency = crate::geometry::mesh::Adjacency::new(&mesh);
        GeodesicSolver {
            adjacency,
            pseudo_sources: OnceLock::new(),
            face_unfolding: OnceLock::new(),
            saddle_graph: OnceLock::new(),
            dense_graph: OnceLock::new(),
            mesh,
            average_boundary,
            graph,
            component,
            heat: OnceLock::new(),
            mean_edge,
        }
    }

    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The saddle vertex graph ([`crate::geometry::saddle_vertex_graph`]), made on first use.
    pub fn saddle_graph(&self) -> &crate::geometry::saddle_vertex_graph::SaddleGraph {
        self.saddle_graph.get_or_init(|| {
            crate::geometry::saddle_vertex_graph::SaddleGraph::new(
                &self.mesh,
                &self.adjacency,
                crate::geometry::saddle_vertex_graph::NEIGHBOURS,
                None,
            )
        })
    }

    /// The dense, pruned saddle vertex graph of [`Method::DenseGraph`], made on first use.
    pub fn dense_graph(&self) -> &crate::geometry::saddle_vertex_graph::SaddleGraph {
        self.dense_graph.get_or_init(|| {
            crate::geometry::saddle_vertex_graph::SaddleGraph::new(
                &self.mesh,
                &self.adjacency,
                crate::geometry::saddle_vertex_graph::DENSE_NEIGHBOURS,
                Some(crate::geometry::saddle_vertex_graph::DENSE_PRUNE),
            )
        })
    }

    /// Whether the heat method's factorisations exist already (for callers that report reuse).
    pub fn is_factored(&self) -> bool {
        matches!(self.heat.get(), Some(Ok(_)))
    }

    /// Checks sources against the mesh and normalises barycentric coordinates.
    pub fn check_sources(&self, sets: &[Vec<Source>]) -> Result<Vec<Vec<Source>>> {
        let nv = self.mesh.vertices.len();
        let nf = self.mesh.faces.len();
        let mut out = Vec::with_capacity(sets.len());
        for (s, set) in sets.iter().enumerate() {
            if set.is_empty() {
                return Err(RokebyError::invalid(
                    "sources",
                    format!("source set {s} is empty"),
                ));
            }
            let mut fixed = Vec::with_capacity(set.len());
            for src in set {
                fixed.push(match *src {
                    Source::Vertex(v) if v < nv => Source::Vertex(v),
                    Source::Vertex(v) => {
                        return Err(RokebyError::invalid("sources", format!("source {s}: vertex {v} is out of range (0..{})", nv - 1)))
                    }
                    Source::Point(p) => {
                        if p.face >= nf {
                            return Err(RokebyError::invalid("sources", format!("source {s}: face {} is out of range (0..{})", p.face, nf - 1)));
                        }
                        let sum: f64 = p.bary.iter().sum();
                        if p.bary.iter().any(|b| !b.is_finite() || *b < -1e-6) || sum.is_nan() || sum <= 1e-12 {
                            return Err(RokebyError::invalid(
                                "sources",
                                format!("source {s}: barycentric coordinates {:?} must be finite, >= 0 and not all 0", p.bary),
                            ));
                        }
                        let b = p.bary.map(|b| b.max(0.0) / sum);
                        Source::Point(SurfacePoint { face: p.face, bary: b })
                    }
                });
            }
            out.push(fixed);
        }
        Ok(out)
    }

    /// Distance fields, one per source set (row-major S×V), by the chosen method.
    pub fn distances(&self, sets: &[Vec<Source>], method: Method) -> Result<Vec<f32>> {
        let sets = self.check_sources(sets)?;
        let rows: Vec<Vec<f64>> = match method {
            Method::Dijkstra | Method::Graph | Method::DenseGraph => {
                // Straight into the output: one row per set, the sets in parallel (one set on
                // the calling thread: handing it to a pool thread only adds the wake-up).
                let nv = self.mesh.vertices.len();
                let mut out = vec![0.0f32; sets.len() * nv];
                let graph = match method {
                    Method::Graph => Some((
                        self.saddle_graph(),
                        crate::geometry::saddle_vertex_graph::SOURCE_NEIGHBOURS,
                    )),
                    Method::DenseGraph => Some((
                        self.dense_graph(),
                        crate::geometry::saddle_vertex_graph::DENSE_SOURCE_NEIGHBOURS,
                    )),
                    _ => None,
                };
                let run = |row: &mut [f32], set: &[Source]| match graph {
                    None => self.dijkstra_with(set, |v, d| row[v] = d as f32),
                    Some((g, k_source)) => {
                        g.distances_with(&self.mesh, &self.adjacency, set, k_source, |v, d| {
                            row[v] = d as f32
                        })
                    }
                };
                if sets.len() == 1 {
                    run(&mut out, &sets[0]);
                } else {
                    out.par_chunks_mut(nv.max(1))
                        .zip(sets.par_iter())
                        .for_each(|(row, set)| run(row, set));
                }
                return Ok(out);
            }
            Method::Heat => self.heat_method(&sets)?,
            Method::Exact => {
                let pseudo = self.pseudo_sources.get_or_init(|| {
                    crate::geometry::exact::pseudo_source_vertices(&self.mesh, &self.adjacency)
                });
                let table = self.face_unfolding.get_or_init(|| {
                    crate::geometry::exact::FaceUnfolding::new(&self.mesh, &self.adjacency)
                });
                let cap = 5000 * (self.mesh.faces.len() + 1000);
                sets.par_iter()
                    .map(|s| {
                        crate::geometry::exact::exact_distances(
                            &self.mesh,
                            &self.adjacency,
                            table,
                            pseudo,
                            s,
                            cap,
                        )
                    })
                    .collect::<Result<Vec<_>>>()?
            }
        };
        Ok(rows
            .into_iter()
            .flat_map(|r| r.into_iter().map(|x| x as f32))
            .collect())
    }

    /// Distances next to the sources: the unfolded straight-line distances ([`crate::geometry::unfold`]),
    /// exact on the source's own faces and, wherever the geodesic is straight across a few
    /// edges, one to three rings out; then edge paths from those vertices one step further, which
    /// carry straight lines through flat vertices. Returns (vertex, distance, straight): every
    /// value is the length of a path on the surface, so never shorter than the geodesic.
    fn seeds(&self, set: &[Source]) -> Vec<(usize, f64, bool)> {
        let nv = self.mesh.vertices.len();
        let mut dist = vec![f64::INFINITY; nv];
        let mut touched = Vec::new();
        crate::geometry::unfold::near_source(
            &self.mesh,
            &self.adjacency,
            set,
            &mut dist,
            &mut touched,
        );
        let mut straight = vec![false; nv];
        let mut heap = BinaryHeap::with_capacity(touched.len());
        for &v in &touched {
            straight[v] = true;
            heap.push(HeapItem(dist[v] as f32, v as u32));
        }
        let mut reached = touched.clone();
        while let Some(HeapItem(key, v)) = heap.pop() {
            let v = v as usize;
            if key > dist[v] as f32 || !straight[v] {
                continue;
            }
            for (w, l) in self.graph.neighbours(v) {
                let nd = dist[v] + l;
                if nd < dist[w] {
                    if dist[w] == f64::INFINITY {
                        reached.push(w);
                    }
                    dist[w] = nd;
                    heap.push(HeapItem(nd as f32, w as u32));
                }
            }
        }
        reached
            .into_iter()
            .map(|v| (v, dist[v], straight[v]))
            .collect()
    }

    /// The 3D positions of a set's sources.
    fn source_points(&self, set: &[Source]) -> Vec<DVec3> {
        set.iter()
            .map(|src| match *src {
                Source::Vertex(v) => self.mesh.vertices[v],
                Source::Point(p) => self.mesh.point(&p),
            })
            .collect()
    }

    /// Multi-source Dijkstra along edges (the distance to the nearest source of the set, in mesh
    /// vertex order).
    pub fn dijkstra(&self, set: &[Source]) -> Vec<f64> {
        let mut out = vec![f64::INFINITY; self.mesh.vertices.len()];
        self.dijkstra_with(set, |v, d| out[v] = d);
        out
    }

    /// Multi-source Dijkstra along the edges ([`Graph::dijkstra`]); `emit(v, d)` receives the
    /// distance of every mesh vertex v (+inf where no source reaches).
    ///
    /// Seeds: the unfolded straight-line distances next to the sources ([`crate::geometry::unfold`]).
    fn dijkstra_with(&self, set: &[Source], emit: impl FnMut(usize, f64)) {
        self.graph.dijkstra(
            |near, touched| {
                crate::geometry::unfold::near_source(
                    &self.mesh,
                    &self.adjacency,
                    set,
                    near,
                    touched,
                )
            },
            emit,
        );
    }

    fn heat_factors(&self) -> Result<&Heat> {
        self.heat
            .get_or_init(|| self.build_heat())
            .as_ref()
            .map_err(|e| e.clone())
    }

    /// Cotangent Laplacian L of the intrinsic Delaunay triangulation (positive semi-definite, and
    /// with no negative weights on manifold parts), lumped mass A, and the factorisations of
    /// A + tL (t = h², h the mean edge length) and L + εA (ε regularises the constant null space of
    /// every component).
    fn build_heat(&self) -> Result<Heat> {
        let nv = self.mesh.vertices.len();
        let lengths: Vec<[f64; 3]> = self
            .mesh
            .faces
            .iter()
            .map(|f| {
                [0, 1, 2]
                    .map(|k| self.mesh.vertices[f[k]].distance(self.mesh.vertices[f[(k + 1) % 3]]))
            })
            .collect();
        let tri = crate::geometry::intrinsic::Intrinsic::delaunay(&self.mesh.faces, lengths);
        let flips = tri.flips;
        let mut faces = Vec::with_capacity(tri.faces.len());
        let mut mass = vec![0.0f64; nv];
        // Cotan weights: per unique edge (i > j) the sum of -½ cot of the opposite angles; the
        // diagonal of L is minus the row sum of the off-diagonal entries.
        let mut edges: Vec<(u32, u32, f64)> = Vec::with_capacity(tri.faces.len() * 3);
        let mut ldiag = vec![0.0f64; nv];
        let mut total_area = 0.0;
        for (f, l) in tri.faces.iter().zip(&tri.lengths) {
            // Faces without area (repeated vertices, collinear corners) have no stiffness: skip.
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                continue;
            }
            let Some(FaceCotangents { area, cot }) = face_cotangents(*l) else {
                continue;
            };
            total_area += area;
            for k in 0..3 {
                mass[f[k]] += area / 3.0;
                let (j, m) = (f[(k + 1) % 3], f[(k + 2) % 3]);
                let w = 0.5 * cot[k];
                edges.push((j.max(m) as u32, j.min(m) as u32, -w));
                ldiag[j] += w;
                ldiag[m] += w;
            }
            let p = crate::geometry::intrinsic::layout(*l);
            faces.push(HeatFace {
                v: f.map(|x| x as u32),
                l01: p[1].x,
                p2: p[2],
                cot,
            });
        }
        drop(tri);
        edges.par_sort_unstable_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)));
        edges.dedup_by(|next, kept| {
            if next.0 == kept.0 && next.1 == kept.1 {
                kept.2 += next.2;
                true
            } else {
                false
            }
        });
        edges.shrink_to_fit();
        let mean_mass = (total_area / nv as f64).max(1e-300);
        // Vertices without area (isolated, unreferenced, only on degenerate faces) get a tiny mass
        // so that both systems stay positive definite; no source reaches them through heat anyway.
        for m in &mut mass {
            if m.is_nan() || *m <= 1e-12 * mean_mass {
                *m = 1e-12 * mean_mass;
            }
        }
        let h = self.mean_edge.max(1e-300);
        let t = h * h;
        let eps = 1e-8;
        // A + tL and L + εA (ε A in the Laplacian's units, 1/h²).
        let heat_diag: Vec<f64> = (0..nv).map(|i| mass[i] + t * ldiag[i]).collect();
        let pois_diag: Vec<f64> = (0..nv).map(|i| ldiag[i] + eps * mass[i] / t).collect();
        // Boundary vertices: on an edge with exactly one face.
        let mut edge_faces: Vec<(usize, usize)> = self
            .mesh
            .faces
            .iter()
            .flat_map(|f| (0..3).map(move |k| (f[k].min(f[(k + 1) % 3]), f[k].max(f[(k + 1) % 3]))))
            .filter(|(a, b)| a != b)
            .collect();
        edge_faces.par_sort_unstable();
        let mut boundary = vec![false; nv];
        let mut i = 0;
        while i < edge_faces.len() {
            let mut j = i + 1;
            while j < edge_faces.len() && edge_faces[j] == edge_faces[i] {
                j += 1;
            }
            if j - i == 1 {
                boundary[edge_faces[i].0] = true;
                boundary[edge_faces[i].1] = true;
            }
            i = j;
        }
        // All three matrices share one sparsity pattern: one symbolic factorisation (ordering and
        // elimination tree) serves them all, which saves its memory and time twice over.
        let heat_m = lower_matrix(nv, &edges, t, &heat_diag)?;
        let symbolic = SymbolicCholesky::new(&heat_m, "heat")?;
        let factor = |m: SparseMatrix, what: &str| symbolic.factor(&m, what);
        let heat_dirichlet = if self.average_boundary && boundary.iter().any(|&b| b) {
            // u = 0 on the boundary by a penalty 1e8 times the largest diagonal entry.
            let big = 1e8 * heat_diag.iter().fold(0.0f64, |m, x| m.max(*x)).max(1e-300);
            let d: Vec<f64> = heat_diag
                .iter()
                .zip(&boundary)
                .map(|(&x, &b)| if b { x + big } else { x })
                .collect();
            Some(factor(lower_matrix(nv, &edges, t, &d)?, "heat")?)
        } else {
            None
        };
        let heat = factor(heat_m, "heat")?;
        let poisson = factor(lower_matrix(nv, &edges, 1.0, &pois_diag)?, "Poisson")?;
        Ok(Heat {
            heat,
            heat_dirichlet,
            poisson,
            faces,
            flips,
        })
    }

    /// Edge flips the intrinsic Delaunay triangulation needed (None before the first heat query).
    pub fn intrinsic_flips(&self) -> Option<usize> {
        self.heat
            .get()
            .and_then(|h| h.as_ref().ok())
            .map(|h| h.flips)
    }

    /// The normalised heat gradient direction X = −∇u/|∇u| of every face (in its 2D layout; zero
    /// where no heat reaches). A single heat step decays like e^(−d/√t), so some tens of edge
    /// lengths from the source u is too small to carry a reliable direction (and further out it
    /// underflows even in f64). Where that happens, a further heat flow is started from the front —
    /// the resolved vertices next to unresolved ones, a level set of distance — with the same
    /// factorisation: outside the front, distance from the front and distance from the source share
    /// their gradient. Only the directions are kept, not the heat values of each front.
    fn heat_directions(&self, hm: &Heat, u0: Vec<f64>) -> Vec<glam::DVec2> {
        let nv = self.mesh.vertices.len();
        // (Measured before the per-face rescaling: 1e-250 left the far half of a 1.6M-triangle
        // mesh 30 % short, 1e-30 gave 1.9 % there; 1e-150 has not been re-measured at that size.)
        // Heat values more than 150 orders of magnitude below the peak lose their direction; one
        // solve resolves every shared mesh (up to 100k faces) in one pass. Measured against exact
        // geodesics: with the earlier 1e-30, nefertiti needed several fronts (1.21 %
        // mean error, ~1.1 s for 3 sources); with 1e-150 one (1.20 %, ~0.6 s). Each further
        // front costs one more triangular solve.
        const RESOLVED: f64 = 1e-150;
        let mut dir = vec![glam::DVec2::ZERO; hm.faces.len()];
        let mut assigned = vec![false; hm.faces.len()];
        let mut resolved = vec![false; nv];
        let mut current = u0;
        // Each front reaches about ln(1e30) ≈ 69 √t (edge lengths) further: 250 cover ~17,000.
        for _level in 0..250 {
            let peak = current.iter().fold(0.0f64, |m, &x| m.max(x));
            if peak.is_nan() || peak <= 0.0 {
                break;
            }
            let ok: Vec<bool> = current.iter().map(|&x| x > RESOLVED * peak).collect();
            let mut progressed = false;
            for (fi, hf) in hm.faces.iter().enumerate() {
                if assigned[fi] || !(0..3).all(|k| ok[hf.vertex(k)]) {
                    continue;
                }
                assigned[fi] = true;
                progressed = true;
                let p = hf.layout();
                let mut g = glam::DVec2::ZERO;
                // Per-face rescaling: the direction does not depend on the scale, and values far
                // below 1 keep their full precision in the products.
                let m = 1.0 / (0..3).fold(0.0f64, |m, k| m.max(current[hf.vertex(k)]));
                for k in 0..3 {
                    // Edge opposite corner k, counter-clockwise, turned by +90° (N × e).
                    let e = p[(k + 2) % 3] - p[(k + 1) % 3];
                    g += glam::DVec2::new(-e.y, e.x) * (current[hf.vertex(k)] * m);
                }
                let gl = g.length();
                if gl > 0.0 {
                    dir[fi] = -g / gl;
                }
            }
            for i in 0..nv {
                resolved[i] |= ok[i];
            }
            if !progressed {
                break;
            }
            // The front: resolved vertices of faces that still have an unresolved vertex.
            let mut next = Mat::<f64>::zeros(nv, 1);
            let mut any = false;
            for hf in &hm.faces {
                let r = [0, 1, 2].map(|k| resolved[hf.vertex(k)]);
                if r.iter().any(|&x| x) && !r.iter().all(|&x| x) {
                    for k in 0..3 {
                        if r[k] {
                            next[(hf.vertex(k), 0)] = 1.0;
                            any = true;
                        }
                    }
                }
            }
            if !any {
                break;
            }
            hm.heat.solve_in_place(next.as_mut());
            current = (0..nv).map(|i| next[(i, 0)]).collect();
        }
        dir
    }

    fn heat_method(&self, sets: &[Vec<Source>]) -> Result<Vec<Vec<f64>>> {
        let hm = self.heat_factors()?;
        let nv = self.mesh.vertices.len();
        let ns = sets.len();
        // 1. Heat flow from all source sets at once (one column each).
        let mut u = Mat::<f64>::zeros(nv, ns);
        for (s, set) in sets.iter().enumerate() {
            for src in set {
                match *src {
                    Source::Vertex(v) => u[(v, s)] += 1.0,
                    Source::Point(p) => {
                        for (k, &v) in self.mesh.faces[p.face].iter().enumerate() {
                            u[(v, s)] += p.bary[k];
                        }
                    }
                }
            }
        }
        if let Some(hd) = &hm.heat_dirichlet {
            let mut ud = u.clone();
            hd.solve_in_place(ud.as_mut());
            hm.heat.solve_in_place(u.as_mut());
            u = (&u + &ud) * faer::Scale(0.5);
        } else {
            hm.heat.solve_in_place(u.as_mut());
        }
        // 2.–3. Normalised gradient per face and its integrated divergence per vertex.
        let cols: Vec<Vec<f64>> = (0..ns)
            .into_par_iter()
            .map(|s| {
                let mut div = vec![0.0f64; nv];
                let dirs = self.heat_directions(hm, (0..nv).map(|i| u[(i, s)]).collect());
                // Near-field: within r1 of a source the direction field is the gradient of the
                // chord distance to the nearest source point; blended into the heat gradient up to r2.
                let src_pts = self.source_points(&sets[s]);
                let chord_v: Vec<f64> = self
                    .mesh
                    .vertices
                    .iter()
                    .map(|&x| chord_to(&src_pts, x))
                    .collect();
                let chord = |v: usize| chord_v[v];
                let (r1, r2) = (NEAR_R1 * self.mean_edge, NEAR_R2 * self.mean_edge);
                for (fi, hf) in hm.faces.iter().enumerate() {
                    let p = hf.layout();
                    let cd = [
                        chord(hf.vertex(0)),
                        chord(hf.vertex(1)),
                        chord(hf.vertex(2)),
                    ];
                    let rmin = cd[0].min(cd[1]).min(cd[2]);
                    let w_near = if rmin < r2 && r2 > 0.0 {
                        1.0 - crate::reflection::region::smooth_step((rmin - r1) / (r2 - r1))
                    } else {
                        0.0
                    };
                    let mut x = dirs[fi];
                    if w_near > 0.0 {
                        let mut gc = glam::DVec2::ZERO;
                        for k in 0..3 {
                            let e = p[(k + 2) % 3] - p[(k + 1) % 3];
                            gc += glam::DVec2::new(-e.y, e.x) * cd[k];
                        }
                        let gcl = gc.length();
                        if gcl > 0.0 {
                            // X points away from the source: the gradient of distance (heat's −∇u).
                            x = (x * (1.0 - w_near) + gc / gcl * w_near).normalize_or_zero();
                        }
                    }
                    if x == glam::DVec2::ZERO {
                        continue;
                    }
                    for k in 0..3 {
                        let (j, l) = ((k + 1) % 3, (k + 2) % 3);
                        let e1 = p[j] - p[k];
                        let e2 = p[l] - p[k];
                        div[hf.vertex(k)] += 0.5 * (hf.cot[l] * e1.dot(x) + hf.cot[j] * e2.dot(x));
                    }
                }
                div
            })
            .collect();
        // 4. Poisson problem L φ = −div (L positive semi-definite), all columns at once.
        let mut phi = Mat::<f64>::zeros(nv, ns);
        for (s, col) in cols.iter().enumerate() {
            for (i, &d) in col.iter().enumerate() {
                phi[(i, s)] = -d;
            }
        }
        hm.poisson.solve_in_place(phi.as_mut());
        // 5. Shift each component to 0 at its sources; exact values near sources; +inf elsewhere.
        let rows = (0..ns)
            .into_par_iter()
            .map(|s| {
                let set = &sets[s];
                let mut row: Vec<f64> = (0..nv).map(|i| phi[(i, s)]).collect();
                let mut shift: std::collections::HashMap<usize, f64> =
                    std::collections::HashMap::new();
                for src in set {
                    let (c, val) = match *src {
                        Source::Vertex(v) => (self.component[v], row[v]),
                        Source::Point(p) => {
                            let f = self.mesh.faces[p.face];
                            (
                                self.component[f[0]],
                                (0..3).map(|k| p.bary[k] * row[f[k]]).sum(),
                            )
                        }
                    };
                    let e = shift.entry(c).or_insert(f64::INFINITY);
                    *e = e.min(val);
                }
                for (i, x) in row.iter_mut().enumerate() {
                    *x = match shift.get(&self.component[i]) {
                        Some(sh) => (*x - sh).max(0.0),
                        None => f64::INFINITY,
                    };
                }
                // No path is shorter than the chord to the nearest source (the heat method's
                // values can be, next to a source); next to the sources the unfolded distances
                // replace the heat values altogether.
                let pts = self.source_points(set);
                for (i, x) in row.iter_mut().enumerate() {
                    if x.is_finite() {
                        *x = x.max(chord_to(&pts, self.mesh.vertices[i]));
                    }
                }
                for (v, d, straight) in self.seeds(set) {
                    row[v] = if straight { d } else { d.min(row[v]) };
                }
                row
            })
            .collect();
        Ok(rows)
    }
}

/// The straight-line distance from `x` to the nearest of `pts`: a lower bound of every geodesic.
fn chord_to(pts: &[DVec3], x: DVec3) -> f64 {
    pts.iter()
        .map(|p| p.distance(x))
        .fold(f64::INFINITY, f64::min)
}

/// [`interpolate`] from flat arrays as the binding receives them, validated: `values` holds rows
/// of `n_vertices` (no NaN), `faces` F×3 vertex indices below `n_vertices`, `face_index` one face
/// per point and `bary` three finite barycentric coordinates per point. Errors name the argument
/// and the entry at fault.
pub fn interpolate_at(
    values: &[f32],
    n_vertices: usize,
    faces: &[i64],
    face_index: &[i64],
    bary: &[f32],
) -> Result<Vec<f32>> {
    if !values.len().is_multiple_of(n_vertices.max(1)) || (n_vertices == 0 && !values.is_empty()) {
        return Err(RokebyError::invalid(
            "values",
            format!("expected rows of {n_vertices} values, got {}", values.len()),
        ));
    }
    if values.iter().any(|x| x.is_nan()) {
        return Err(RokebyError::invalid("values", "contains NaN"));
    }
    if !faces.len().is_multiple_of(3) {
        return Err(RokebyError::invalid(
            "faces",
            format!("expected 3 indices per face, got {}", faces.len()),
        ));
    }
    if let Some(i) = faces
        .iter()
        .position(|&x| x < 0 || x as u64 >= n_vertices as u64)
    {
        return Err(RokebyError::invalid(
            "faces",
            format!(
                "face {} refers to vertex {} but values has {} vertices",
                i / 3,
                faces[i],
                n_vertices
            ),
        ));
    }
    if bary.len() != 3 * face_index.len() {
        return Err(RokebyError::invalid(
            "bary",
            format!(
                "expected 3 values for each of {} points, got {}",
                face_index.len(),
                bary.len()
            ),
        ));
    }
    let nf = faces.len() / 3;
    let faces3: Vec<[usize; 3]> = faces
        .chunks_exact(3)
        .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
        .collect();
    let mut pts = Vec::with_capacity(face_index.len());
    for (k, (&face, bc)) in face_index.iter().zip(bary.chunks_exact(3)).enumerate() {
        if face < 0 || face as u64 >= nf as u64 {
            return Err(RokebyError::invalid(
                "face_index",
                format!(
                    "entry {k} = {face} is out of range (0..{})",
                    nf.saturating_sub(1)
                ),
            ));
        }
        if bc.iter().any(|x| !x.is_finite()) {
            return Err(RokebyError::invalid(
                "bary",
                format!("row {k} is not finite"),
            ));
        }
        pts.push(SurfacePoint {
            face: face as usize,
            bary: [bc[0] as f64, bc[1] as f64, bc[2] as f64],
        });
    }
    interpolate(values, n_vertices, &faces3, &pts)
}

/// Values at surface points by barycentric interpolation of per-vertex values (paper §6.2: the
/// per-vertex distance field drawn with smooth shading). `values` holds `rows` rows of
/// `n_vertices`; the result is (rows, points). A vertex whose weight is exactly 0 does not
/// enter the sum (an unreachable +inf there does not turn the point into NaN); a result that
/// finite input cannot hold in float32 is an error, not an inf.
pub fn interpolate(
    values: &[f32],
    n_vertices: usize,
    faces: &[[usize; 3]],
    points: &[SurfacePoint],
) -> Result<Vec<f32>> {
    let rows = values.len() / n_vertices.max(1);
    let mut out = crate::alloc::with_capacity::<f32>(
        "interpolate output (rows × points)",
        &[rows, points.len()],
    )?;
    for r in 0..rows {
        let row = &values[r * n_vertices..(r + 1) * n_vertices];
        for (k, p) in points.iter().enumerate() {
            let f = faces[p.face];
            let mut v = 0.0f64;
            let mut finite_in = true;
            for c in 0..3 {
                if p.bary[c] != 0.0 {
                    let x = row[f[c]];
                    finite_in &= x.is_finite();
                    v += p.bary[c] * x as f64;
                }
            }
            if finite_in && v.is_finite() && v.abs() > f32::MAX as f64 {
                return Err(RokebyError::invalid(
                    "values",
                    format!("the value interpolated at point {k} ({v:e}) overflows float32"),
                ));
            }
            out.push(v as f32);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    //! A plain Dijkstra (a graph in mesh order, fresh buffers and a seeding
    //! pass per query) kept as the oracle: the rewrite must give the same bits.
    use super::*;
    use crate::geometry::mesh::shared_test_mesh;

    struct ReferenceGraph {
        start: Vec<usize>,
        nbr: Vec<u32>,
        len: Vec<f32>,
    }

    impl ReferenceGraph {
        fn new(mesh: &Mesh) -> Self {
            let nv = mesh.vertices.len();
            let mut edges: Vec<(usize, usize)> = Vec::new();
            for f in &mesh.faces {
                for k in 0..3 {
                    let (a, b) = (f[k], f[(k + 1) % 3]);
                    if a != b {
                        edges.push((a, b));
                        edges.push((b, a));
                    }
                }
            }
            edges.sort_unstable();
            edges.dedup();
            let mut start = vec![0usize; nv + 1];
            for &(a, _) in &edges {
                start[a + 1] += 1;
            }
            for i in 0..nv {
                start[i + 1] += start[i];
            }
            let nbr = edges.iter().map(|e| e.1 as u32).collect();
            let len = edges
                .iter()
                .map(|&(a, b)| mesh.vertices[a].distance(mesh.vertices[b]) as f32)
                .collect();
            ReferenceGraph { start, nbr, len }
        }

        fn neighbours(&self, v: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
            (self.start[v]..self.start[v + 1])
                .map(move |k| (self.nbr[k] as usize, self.len[k] as f64))
        }
    }

    /// A plain `seeds` and `dijkstra` (the oracle), reading the graph in mesh order.
    fn reference_dijkstra(s: &GeodesicSolver, g: &ReferenceGraph, set: &[Source]) -> Vec<f64> {
        let nv = s.mesh.vertices.len();
        let mut dist = vec![f64::INFINITY; nv];
        let mut touched = Vec::new();
        crate::geometry::unfold::near_source(&s.mesh, &s.adjacency, set, &mut dist, &mut touched);
        let mut straight = vec![false; nv];
        let mut heap = BinaryHeap::with_capacity(touched.len());
        for &v in &touched {
            straight[v] = true;
            heap.push(HeapItem(dist[v] as f32, v as u32));
        }
        let mut reached = touched.clone();
        while let Some(HeapItem(key, v)) = heap.pop() {
            let v = v as usize;
            if key > dist[v] as f32 || !straight[v] {
                continue;
            }
            for (w, l) in g.neighbours(v) {
                let nd = dist[v] + l;
                if nd < dist[w] {
                    if dist[w] == f64::INFINITY {
                        reached.push(w);
                    }
                    dist[w] = nd;
                    heap.push(HeapItem(nd as f32, w as u32));
                }
            }
        }
        let seeds: Vec<(usize, f64)> = reached.into_iter().map(|v| (v, dist[v])).collect();
        let mut dist = vec![f64::INFINITY; nv];
        let mut heap = crate::geometry::radix_heap::RadixHeap::new();
        for (v, d) in seeds {
            if d < dist[v] {
                dist[v] = d;
                heap.push(d as f32, v as u32);
            }
        }
        while let Some((key, v)) = heap.pop() {
            let v = v as usize;
            let d = dist[v];
            if key > d as f32 {
                continue;
            }
            for (w, l) in g.neighbours(v) {
                let nd = d + l;
                if nd < dist[w] {
                    dist[w] = nd;
                    heap.push(nd as f32, w as u32);
                }
            }
        }
        dist
    }

    /// A bumpy, jittered grid with a hole of unreferenced vertices and a second component.
    fn bumpy_grid(n: usize) -> Mesh {
        let mut v = Vec::new();
        let mut x = 987654321u64;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % 10_000) as f32 / 10_000.0 - 0.5
        };
        for j in 0..n {
            for i in 0..n {
                let (u, w) = (i as f32 + 0.3 * rnd(), j as f32 + 0.3 * rnd());
                v.extend([u, w, 0.4 * (0.7 * u).sin() * (0.5 * w).cos() + 0.05 * rnd()]);
            }
        }
        let mut f = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                if (n / 3..n / 2).contains(&i) && (n / 3..n / 2).contains(&j) {
                    continue;
                }
                let a = (j * n + i) as i64;
                let (b, c, d) = (a + 1, a + n as i64, a + n as i64 + 1);
                f.extend_from_slice(&[a, b, d, a, d, c]);
            }
        }
        // A separate triangle far away.
        let k = (v.len() / 3) as i64;
        v.extend([100.0, 0.0, 0.0, 101.0, 0.0, 0.0, 100.0, 1.0, 0.0]);
        f.extend([k, k + 1, k + 2]);
        Mesh::new(&v, &f).unwrap()
    }

    fn source_sets(mesh: &Mesh) -> Vec<Vec<Source>> {
        let (nv, nf) = (mesh.vertices.len(), mesh.faces.len());
        let p = |face: usize, bary: [f64; 3]| Source::Point(SurfacePoint { face, bary });
        vec![
            vec![Source::Vertex(0)],
            vec![Source::Vertex(nv / 2)],
            vec![p(nf / 3, [0.2, 0.3, 0.5])],
            vec![p(nf / 5, [0.0, 0.4, 0.6]), p(nf / 5, [1.0, 0.0, 0.0])],
            [0, nv / 4, nv / 2, 3 * nv / 4].map(Source::Vertex).to_vec(),
            vec![
                Source::Vertex(nv - 1),
                p(nf / 2, [0.1, 0.1, 0.8]),
                p(2 * nf / 3, [0.5, 0.5, 0.0]),
                Source::Vertex(nv / 7),
            ],
        ]
    }

    fn check_against_reference(mesh: Mesh, what: &str) {
        let solver = GeodesicSolver::new(mesh);
        let g = ReferenceGraph::new(&solver.mesh);
        let sets = solver.check_sources(&source_sets(&solver.mesh)).unwrap();
        let nv = solver.mesh.vertices.len();
        // Twice, so that the second round runs on reused buffers.
        for round in 0..2 {
            let all = solver.distances(&sets, Method::Dijkstra).unwrap();
            for (s, set) in sets.iter().enumerate() {
                let want = reference_dijkstra(&solver, &g, set);
                assert!(want.iter().any(|d| d.is_finite() && *d > 0.0));
                let got = solver.dijkstra(set);
                for v in 0..nv {
                    assert_eq!(
                        got[v].to_bits(),
                        want[v].to_bits(),
                        "{what}, set {s}, vertex {v}, round {round}: {} vs {}",
                        got[v],
                        want[v]
                    );
                    assert_eq!(all[s * nv + v].to_bits(), (want[v] as f32).to_bits());
                }
            }
        }
    }

    #[test]
    fn geodesic_dijkstra_matches_the_plain_implementation_bit_for_bit() {
        check_against_reference(bumpy_grid(60), "bumpy grid");
        let mut any = false;
        for name in ["spot.obj", "fandisk.obj", "homer.obj", "teapot.obj"] {
            if let Some(mesh) = shared_test_mesh(name) {
                check_against_reference(mesh, name);
                any = true;
            }
        }
        assert!(any, "no shared mesh found (set ROKEBY_SHARED)");
    }

    /// The distance field of a set of sources is the minimum of each source's own field, to the
    /// bit: the sources of a set may run as independent queries.
    #[test]
    fn geodesic_dijkstra_of_a_set_is_the_minimum_of_its_sources() {
        let solver = GeodesicSolver::new(bumpy_grid(50));
        for set in solver.check_sources(&source_sets(&solver.mesh)).unwrap() {
            let joint = solver.dijkstra(&set);
            let singles: Vec<Vec<f64>> = set.iter().map(|s| solver.dijkstra(&[*s])).collect();
            for (v, &d) in joint.iter().enumerate() {
                let m = singles.iter().map(|r| r[v]).fold(f64::INFINITY, f64::min);
                assert_eq!(d.to_bits(), m.to_bits(), "vertex {v}");
            }
        }
    }
}
