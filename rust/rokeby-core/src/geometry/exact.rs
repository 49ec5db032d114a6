//! Exact polyhedral geodesic distances by window propagation: Chen & Han's algorithm (1990) run
//! in order of distance with a priority queue and the window filtering of Xin & Wang ("Improving
//! Chen and Han's algorithm on the discrete geodesic problem", ACM TOG 2009, "ICH").
//!
//! A *window* is an interval [b0, b1] of an edge that a source (or a pseudo-source: a saddle or
//! boundary vertex, where shortest paths may bend) sees straight through the faces crossed so
//! far. It is stored in the edge's own frame: the edge from vertex `a` at x = 0 to `b` at
//! x = `len`, the source image at `s` (y < 0), the face to enter on y > 0, and the distance
//! `sigma` of the (pseudo-)source. Popping a window unfolds the face across the edge: its third
//! vertex gets σ + |s − c| if the window sees it, and the parts of the two far edges inside the
//! window's cone become new windows. ICH's filter drops a window when a path through an end
//! vertex of its edge already reaches the far end of the window sooner (Xin & Wang §3.2, rules
//! on d(v1) and d(v2)): every path through that window could then be shortened, so nothing it
//! would reach is lost. Saddle vertices (total angle over 2π), reflex boundary vertices (over π)
//! and vertices on non-manifold edges become pseudo-sources when their distance is final.
//!
//! Two more prunings, both exact: a new window is trimmed where a window already queued on the
//! same edge (from either side) reaches its points sooner, as Mitchell, Mount & Papadimitriou's
//! algorithm (MMP) trims overlapping windows — only the new window's ends are cut, the one
//! already queued is left as it is; and every distance stored at a vertex is the length of a path
//! on the surface, so a filter can only drop windows that are beaten. That also makes the order
//! of the queue a matter of speed alone: windows are popped by their distance rounded to 1/128
//! relative (a radix heap), vertices whose distance falls after their expansion are expanded
//! again. The faces' unfoldings are looked up per halfedge ([`FaceUnfolding`]) and windows live
//! in a reused arena. Measured (docs/geodesics.md): on spot's three bench sources the trimming
//! takes 552M instructions to 337M (callgrind), the whole rework 1,266M to 327M.

use crate::error::{Result, RokebyError};
use crate::geometry::geodesic::{Mesh, Source};
use crate::geometry::mesh::Adjacency;
use crate::geometry::radix_heap::RadixHeap;
use crate::geometry::unfold::layout;
use glam::DVec2;

/// A window, stored in the frame of its edge (see the module documentation).
#[derive(Clone, Copy)]
struct Window {
    /// Halfedge (3·face + corner) of the face behind: the window enters every other face on it.
    h: u32,
    a: u32,
    b: u32,
    len: f64,
    b0: f64,
    b1: f64,
    s: DVec2,
    sigma: f64,
}

/// A queue key: the distance as f32 bits less the low `shift` bits of the mantissa (keys equal
/// within 2^(shift − 23) relative pop in no particular order).
fn queue_key(d: f64, shift: u32) -> u32 {
    (d as f32).max(0.0).to_bits() >> shift
}

/// The exact method's key shift: distances rounded to 1/128 relative, so that an entry moves
/// between the radix heap's buckets fewer times. Measured on spot (callgrind, three sources):
/// 702M instructions with f32 keys, 625M with 1/2048, 595M with 1/128, 683M with 1/16 (coarser:
/// the filter learns vertex distances later and more windows survive). The direct geodesics of
/// [`direct_near`] keep f32 keys: they stop after k vertices, so their order decides which.
const EXACT_KEY_SHIFT: u32 = 16;

/// A window as kept on its edge for trimming later ones: in the frame running from the edge's
/// lower vertex index to the higher, the source at (s.x, |s.y|).
struct Kept {
    s: DVec2,
    sigma: f64,
    b0: f64,
    b1: f64,
    next: u32,
}

/// Where σ_n + |s_n x| = σ_k + |s_k x| on the line y = 0 (x, of at most two; spurious roots of
/// the squaring may be among them): (Px + Q)² = 4α² |s_k x|² with α = σ_k − σ_n,
/// P = 2 (s_k.x − s_n.x), Q = |s_n|² − |s_k|² − α².
fn crossings(sn: DVec2, sigma_n: f64, sk: DVec2, sigma_k: f64) -> [f64; 2] {
    let al = sigma_k - sigma_n;
    let p = 2.0 * (sk.x - sn.x);
    let q = sn.length_squared() - sk.length_squared() - al * al;
    let a2 = 4.0 * al * al;
    let qa = a2 - p * p;
    let qb = -2.0 * a2 * sk.x - 2.0 * p * q;
    let qc = a2 * sk.length_squared() - q * q;
    if qa.abs() <= 1e-12 * (a2 + p * p) {
        return if qb != 0.0 {
            [-qc / qb, f64::NAN]
        } else {
            [f64::NAN; 2]
        };
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return [f64::NAN; 2];
    }
    let r = disc.sqrt();
    let (x0, x1) = ((-qb - r) / (2.0 * qa), (-qb + r) / (2.0 * qa));
    [x0.min(x1), x0.max(x1)]
}

/// Queue entries with this bit set are vertices (pseudo-sources); others index `Propagation::windows`.
const VERTEX: u32 = 1 << 31;

/// Which vertices may bend a shortest path: interior vertices whose total angle exceeds 2π
/// (saddles), boundary vertices whose angle exceeds π (reflex corners of a hole or an outline),
/// and vertices on non-manifold edges. Flat vertices are not among them: a straight line through
/// one is the common edge of the (closed) cones of the windows on either side.
pub(crate) fn pseudo_source_vertices(mesh: &Mesh, adj: &Adjacency) -> Vec<bool> {
    let nv = mesh.vertices.len();
    let mut angle = vec![0.0f64; nv];
    let mut boundary = vec![false; nv];
    let mut out = vec![false; nv];
    for (fi, f) in mesh.faces.iter().enumerate() {
        if !crate::geometry::mesh::is_proper(f) {
            continue;
        }
        let p = f.map(|v| mesh.vertices[v]);
        for k in 0..3 {
            let (e1, e2) = (p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]);
            let c = e1.cross(e2).length();
            angle[f[k]] += c.atan2(e1.dot(e2));
            let (a, b) = (f[k], f[(k + 1) % 3]);
            match adj.across(3 * fi + k).count() {
                1 => {}
                0 => {
                    boundary[a] = true;
                    boundary[b] = true;
                }
                _ => {
                    out[a] = true;
                    out[b] = true;
                }
            }
        }
    }
    let pi = std::f64::consts::PI;
    for v in 0..nv {
        let full = if boundary[v] { pi } else { 2.0 * pi };
        if angle[v] > full * (1.0 + 1e-9) {
            out[v] = true;
        }
    }
    out
}

/// What window propagation reads of each halfedge `3f + k` (corner k → k+1 of face f), made once
/// per mesh: its length and the third corner of f laid out in the edge's plane, with corner k at
/// the origin, corner k+1 at (length, 0) and the third corner on y ≥ 0 (NaN for a face with
/// coincident corners). Unfolding a face across an edge is then a lookup, not three 3D lengths
/// and a square root per window.
pub(crate) struct FaceUnfolding {
    len: Vec<f64>,
    apex: Vec<DVec2>,
    /// The one halfedge across each halfedge (the edge's other face), NO_FACE on the boundary,
    /// SEVERAL on a non-manifold edge (then [`Adjacency::across`] lists them).
    twin: Vec<u32>,
}

const NO_FACE: u32 = u32::MAX;
const SEVERAL: u32 = u32::MAX - 1;

impl FaceUnfolding {
    pub(crate) fn new(mesh: &Mesh, adj: &Adjacency) -> Self {
        let nh = 3 * mesh.faces.len();
        let twin = (0..nh)
            .map(|h| {
                let mut it = adj.across(h);
                match (it.next(), it.next()) {
                    (None, _) => NO_FACE,
                    (Some(g), None) if g < SEVERAL as usize => g as u32,
                    _ => SEVERAL,
                }
            })
            .collect();
        let (mut len, mut apex) = (Vec::with_capacity(nh), Vec::with_capacity(nh));
        for f in &mesh.faces {
            let p = f.map(|v| mesh.vertices[v]);
            let l = [0, 1, 2].map(|k| p[k].distance(p[(k + 1) % 3]));
            for k in 0..3 {
                let c =
                    crate::geometry::intrinsic::layout([l[k], l[(k + 1) % 3], l[(k + 2) % 3]])[2];
                len.push(l[k]);
                apex.push(if c.is_finite() { c } else { DVec2::NAN });
            }
        }
        FaceUnfolding { len, apex, twin }
    }

    /// Halfedge `g`'s length and third corner (see the type), from the table or, without one,
    /// from the mesh.
    #[inline]
    fn corner(table: Option<&Self>, mesh: &Mesh, g: usize) -> (f64, DVec2) {
        match table {
            Some(t) => (t.len[g], t.apex[g]),
            None => {
                let (f, k) = (mesh.faces[g / 3], g % 3);
                let p = [k, (k + 1) % 3, (k + 2) % 3].map(|i| mesh.vertices[f[i]]);
                let l = [
                    p[0].distance(p[1]),
                    p[1].distance(p[2]),
                    p[2].distance(p[0]),
                ];
                (l[0], crate::geometry::intrinsic::layout(l)[2])
            }
        }
    }
}

struct Propagation<'a> {
    mesh: &'a Mesh,
    adj: &'a Adjacency,
    /// The per-halfedge unfolding; `None`: computed from the mesh where needed (the local
    /// queries of [`crate::geometry::saddle_vertex_graph`], which touch a few faces each).
    table: Option<&'a FaceUnfolding>,
    /// Vertices that become pseudo-sources; `None`: none do (paths stay straight, for the local
    /// direct geodesics of [`crate::geometry::saddle_vertex_graph`]).
    pseudo: Option<&'a [bool]>,
    dist: &'a mut [f64],
    /// The distance each pseudo-source was last expanded with (+inf: never; empty without
    /// pseudo-sources).
    expanded: Vec<f64>,
    /// Vertices whose distance went from +inf to finite, in that order.
    touched: Vec<usize>,
    /// Windows waiting in the queue, and the free slots of popped ones (reused, so a query
    /// allocates only while its wavefront grows).
    windows: Vec<Window>,
    free: Vec<u32>,
    /// The windows queued so far on each edge (a list through `Kept::next` from the edge's
    /// lowest halfedge; empty without pseudo-sources): a new window is trimmed where one of them
    /// reaches its points sooner.
    edge_head: Vec<u32>,
    kept: Vec<Kept>,
    /// Windows and pseudo-sources by distance. Keys are f32 bits, shifted right by `key_shift`
    /// ([`queue_key`]): a window's children never come nearer the source than it, so the keys
    /// popped never decrease (as a radix heap needs); for exact distances the order only decides
    /// how soon the filter learns vertex distances, never the result.
    heap: RadixHeap,
    key_shift: u32,
}

/// The frame of edge X→Y with `behind` on y < 0: maps a point of the current frame into it.
fn edge_frame(x: DVec2, y: DVec2, behind: DVec2) -> impl Fn(DVec2) -> DVec2 {
    let t = (y - x).normalize();
    let n = DVec2::new(-t.y, t.x);
    let flip = if (behind - x).dot(n) > 0.0 { -1.0 } else { 1.0 };
    move |p: DVec2| {
        let d = p - x;
        DVec2::new(d.dot(t), flip * d.dot(n))
    }
}

impl<'a> Propagation<'a> {
    fn new(
        mesh: &'a Mesh,
        adj: &'a Adjacency,
        table: Option<&'a FaceUnfolding>,
        pseudo: Option<&'a [bool]>,
        dist: &'a mut [f64],
    ) -> Self {
        let expanded = if pseudo.is_some() {
            vec![f64::INFINITY; dist.len()]
        } else {
            Vec::new()
        };
        Propagation {
            mesh,
            adj,
            table,
            pseudo,
            dist,
            expanded,
            touched: Vec::new(),
            windows: Vec::new(),
            free: Vec::new(),
            edge_head: if pseudo.is_some() {
                vec![NO_FACE; 3 * mesh.faces.len()]
            } else {
                Vec::new()
            },
            kept: Vec::new(),
            heap: RadixHeap::new(),
            key_shift: if pseudo.is_some() { EXACT_KEY_SHIFT } else { 0 },
        }
    }

    fn relax(&mut self, v: usize, d: f64) {
        if d < self.dist[v] {
            if self.dist[v] == f64::INFINITY {
                self.touched.push(v);
            }
            self.dist[v] = d;
            if self.pseudo.is_some_and(|p| p[v]) {
                self.heap
                    .push_key(queue_key(d, self.key_shift), v as u32 | VERTEX);
            }
        }
    }

    /// A source vertex: distance 0, expanded by the caller (not queued as a pseudo-source).
    fn set_source(&mut self, v: usize) {
        if self.dist[v] == f64::INFINITY {
            self.touched.push(v);
        }
        self.dist[v] = 0.0;
        if let Some(e) = self.expanded.get_mut(v) {
            *e = 0.0;
        }
    }

    /// Xin & Wang's rules on the two ends of the window's edge: a path through end `a` reaches
    /// the far end b1 sooner (and so, by the triangle inequality along the edge, every point of
    /// the window), or one through `b` reaches b0 sooner.
    fn useless(&self, w: &Window) -> bool {
        let (da, db) = (self.dist[w.a as usize], self.dist[w.b as usize]);
        (da < f64::INFINITY
            && da + w.b1 < (w.sigma + w.s.distance(DVec2::new(w.b1, 0.0))) * (1.0 - 1e-12))
            || (db < f64::INFINITY
                && db + (w.len - w.b0)
                    < (w.sigma + w.s.distance(DVec2::new(w.b0, 0.0))) * (1.0 - 1e-12))
    }

    /// Queues a window after relaxing the edge ends it covers, unless the filter drops it or the
    /// windows already on its edge leave nothing of it.
    fn push(&mut self, w: Window) {
        if !(w.len > 0.0 && w.s.y < 0.0 && w.b1 > w.b0) {
            return;
        }
        let tol = 1e-9 * w.len;
        if w.b0 <= tol {
            self.relax(w.a as usize, w.sigma + w.s.length());
        }
        if w.b1 >= w.len - tol {
            self.relax(w.b as usize, w.sigma + w.s.distance(DVec2::new(w.len, 0.0)));
        }
        if self.useless(&w) {
            return;
        }
        let mut w = w;
        if !self.edge_head.is_empty() && !self.trim(&mut w) {
            return;
        }
        let x = w.s.x.clamp(w.b0, w.b1);
        let key = w.sigma + w.s.distance(DVec2::new(x, 0.0));
        let i = match self.free.pop() {
            Some(i) => {
                self.windows[i as usize] = w;
                i
            }
            None => {
                self.windows.push(w);
                (self.windows.len() - 1) as u32
            }
        };
        self.heap.push_key(queue_key(key, self.key_shift), i);
    }

    /// Trims the window's ends where a window kept on its edge reaches them sooner (as Mitchell,
    /// Mount & Papadimitriou's algorithm trims overlapping windows; the earlier window is left
    /// as it is), and keeps it on the edge. False when nothing is left.
    fn trim(&mut self, w: &mut Window) -> bool {
        let h = w.h as usize;
        let e = match self.table.map_or(SEVERAL, |t| t.twin[h]) {
            NO_FACE => h,
            SEVERAL => self.adj.across(h).fold(h, usize::min),
            g => h.min(g as usize),
        };
        // The canonical frame: x → len − x where a is the higher vertex.
        let flip = w.a > w.b;
        let to_c = |x: f64| if flip { w.len - x } else { x };
        let sn = DVec2::new(to_c(w.s.x), -w.s.y);
        let (mut lo, mut hi) = if flip {
            (w.len - w.b1, w.len - w.b0)
        } else {
            (w.b0, w.b1)
        };
        let tol = 1e-9 * w.len;
        let dn = |x: f64| w.sigma + sn.distance(DVec2::new(x, 0.0));
        let mut i = self.edge_head[e];
        while i != NO_FACE {
            let k = &self.kept[i as usize];
            i = k.next;
            let (ol, oh) = (lo.max(k.b0), hi.min(k.b1));
            if oh - ol <= tol {
                continue;
            }
            // Worse (by more than rounding) at x: the kept window's path there is shorter.
            let dk = |x: f64| k.sigma + k.s.distance(DVec2::new(x, 0.0));
            let worse = |x: f64| dk(x) < dn(x) * (1.0 - 1e-12);
            let better = |x: f64| dn(x) < dk(x) * (1.0 - 1e-9);
            // Beaten on a piece: at its middle, and not ahead (beyond rounding) at either end.
            let beaten =
                |p0: f64, p1: f64| p1 > p0 && worse(0.5 * (p0 + p1)) && !better(p0) && !better(p1);
            // Between consecutive crossings the sign of dn − dk does not change.
            let r = crossings(sn, w.sigma, k.s, k.sigma);
            let mut cuts = [ol, oh, oh, oh];
            for (c, x) in cuts[1..3].iter_mut().zip(r) {
                if x > ol && x < oh {
                    *c = x;
                }
            }
            cuts[1..3].sort_by(f64::total_cmp);
            if lo >= k.b0 {
                // From the left end: drop pieces the kept window beats.
                let mut n = lo;
                for p in cuts.windows(2) {
                    if beaten(p[0], p[1]) {
                        n = p[1];
                    } else if p[1] > p[0] {
                        break;
                    }
                }
                if n > lo {
                    lo = if n >= hi { hi } else { (n - tol).max(lo) };
                }
            }
            if hi <= k.b1 && hi > lo {
                let mut n = hi;
                for p in cuts.windows(2).rev() {
                    if beaten(p[0], p[1]) {
                        n = p[0];
                    } else if p[1] > p[0] {
                        break;
                    }
                }
                if n < hi {
                    hi = if n <= lo { lo } else { (n + tol).min(hi) };
                }
            }
            if hi - lo <= tol {
                return false;
            }
        }
        (w.b0, w.b1) = if flip {
            (w.len - hi, w.len - lo)
        } else {
            (lo, hi)
        };
        self.kept.push(Kept {
            s: sn,
            sigma: w.sigma,
            b0: lo,
            b1: hi,
            next: self.edge_head[e],
        });
        self.edge_head[e] = (self.kept.len() - 1) as u32;
        true
    }

    /// A window into the face across edge X→Y of a face laid out in the current frame.
    // A propagation step: the face, the edge ends and the window ends in the current frame, each
    // its own argument as in the window propagation of Chen & Han; a struct would only repack them.
    #[allow(clippy::too_many_arguments)]
    fn window_on(
        &mut self,
        h: usize,
        (a, b): (usize, usize),
        (px, py, behind): (DVec2, DVec2, DVec2),
        (u0, u1): (f64, f64),
        s: DVec2,
        sigma: f64,
    ) {
        let len = px.distance(py);
        if len.is_nan() || len <= 0.0 {
            return;
        }
        let to = edge_frame(px, py, behind);
        self.push(Window {
            h: h as u32,
            a: a as u32,
            b: b as u32,
            len,
            b0: u0 * len,
            b1: u1 * len,
            s: to(s),
            sigma,
        });
    }

    /// A (pseudo-)source at vertex `v` of distance `sigma`: its edges, and a window across the
    /// far edge of every face around it.
    fn expand_vertex(&mut self, v: usize, sigma: f64) {
        let adj = self.adj;
        for &f in adj.faces_around(v) {
            let fv = self.mesh.faces[f];
            let p = layout(self.mesh, f);
            if !p.iter().all(|x| x.is_finite()) {
                continue;
            }
            let k = fv.iter().position(|&x| x == v).unwrap_or(0);
            let (j, l) = ((k + 1) % 3, (k + 2) % 3);
            self.relax(fv[j], sigma + p[k].distance(p[j]));
            self.relax(fv[l], sigma + p[k].distance(p[l]));
            self.window_on(
                3 * f + j,
                (fv[j], fv[l]),
                (p[j], p[l], p[k]),
                (0.0, 1.0),
                p[k],
                sigma,
            );
        }
    }

    /// A source at `s` inside face `f` (laid out as `p`).
    fn expand_face(&mut self, f: usize, p: [DVec2; 3], s: DVec2) {
        let fv = self.mesh.faces[f];
        for k in 0..3 {
            self.relax(fv[k], s.distance(p[k]));
        }
        for k in 0..3 {
            let (j, l) = ((k + 1) % 3, (k + 2) % 3);
            self.window_on(
                3 * f + k,
                (fv[k], fv[j]),
                (p[k], p[j], p[l]),
                (0.0, 1.0),
                s,
                0.0,
            );
        }
    }

    /// Pops the next item: a window is unfolded into the faces across its edge, a pseudo-source
    /// expanded if its distance fell since it last was. `None` when the queue is empty.
    fn step(&mut self) -> Option<()> {
        let (_, i) = self.heap.pop_key()?;
        if i & VERTEX != 0 {
            let v = (i & !VERTEX) as usize;
            let d = self.dist[v];
            if d < self.expanded[v] {
                self.expanded[v] = d;
                self.expand_vertex(v, d);
            }
        } else {
            let w = self.windows[i as usize];
            self.free.push(i);
            self.process(w);
        }
        Some(())
    }

    fn process(&mut self, w: Window) {
        if self.useless(&w) {
            return;
        }
        let h = w.h as usize;
        match self.table.map_or(SEVERAL, |t| t.twin[h]) {
            NO_FACE => {}
            SEVERAL => {
                let adj = self.adj;
                for g in adj.across(h) {
                    self.enter(&w, g);
                }
            }
            g => self.enter(&w, g as usize),
        }
    }

    /// Unfolds the face of halfedge `g` (across the window's edge) and propagates the window
    /// into it: its third corner's distance, and the windows on its two far edges.
    fn enter(&mut self, w: &Window, g: usize) {
        let (mesh, table) = (self.mesh, self.table);
        let (a, b) = (w.a as usize, w.b as usize);
        let (pa, pb) = (DVec2::ZERO, DVec2::new(w.len, 0.0));
        let k = w.s.y.abs().max(1e-300);
        // Where the ray from s through p (y > −s.y side) crosses the edge, as a numerator that is
        // ≥ 0 where the crossing is at or beyond x = bnd (the denominator p.y + k is positive).
        let num = |p: DVec2, bnd: f64| (p.x - w.s.x) * k - (bnd - w.s.x) * (p.y + k);
        let tol = 1e-9 * w.len;
        let (gf, j) = (mesh.faces[g / 3], g % 3);
        let c = gf[(j + 2) % 3];
        if c == a || c == b {
            return;
        }
        // Halfedge g runs a→b or b→a; its third corner in the window's frame, and the
        // halfedges of the face on a–c and c–b.
        let (_, apex) = FaceUnfolding::corner(table, mesh, g);
        let (pc, h_ac, h_cb) = if gf[j] == a && gf[(j + 1) % 3] == b {
            (apex, 3 * (g / 3) + (j + 2) % 3, 3 * (g / 3) + (j + 1) % 3)
        } else if gf[j] == b && gf[(j + 1) % 3] == a {
            (
                DVec2::new(w.len - apex.x, apex.y),
                3 * (g / 3) + (j + 1) % 3,
                3 * (g / 3) + (j + 2) % 3,
            )
        } else {
            return;
        };
        if !pc.is_finite() {
            return;
        }
        if pc.y > 0.0 && num(pc, w.b0 - tol) >= 0.0 && num(pc, w.b1 + tol) <= 0.0 {
            self.relax(c, w.sigma + w.s.distance(pc));
        }
        // The children on a–c and c–b.
        for (x, y, px, py, hn) in [(a, c, pa, pc, h_ac), (c, b, pc, pb, h_cb)] {
            // The interval of t ∈ [0, 1] (px + t (py − px)) inside the cone.
            let (mut u0, mut u1) = (0.0f64, 1.0f64);
            for (bnd, sign) in [(w.b0, 1.0), (w.b1, -1.0)] {
                let (n0, n1) = (sign * num(px, bnd), sign * num(py, bnd));
                if n0 >= 0.0 && n1 >= 0.0 {
                    continue;
                }
                if n0 < 0.0 && n1 < 0.0 {
                    u1 = -1.0;
                    break;
                }
                let r = n0 / (n0 - n1);
                if n0 < 0.0 {
                    u0 = u0.max(r);
                } else {
                    u1 = u1.min(r);
                }
            }
            if u1 - u0 <= 1e-12 {
                continue;
            }
            // The child's frame: x along X→Y, the face behind (on the side of the third
            // corner, pc.y > 0) on y < 0.
            let (len, _) = FaceUnfolding::corner(table, mesh, hn);
            if len.is_nan() || len <= 0.0 {
                continue;
            }
            let t = (py - px) / len;
            let d = w.s - px;
            self.push(Window {
                h: hn as u32,
                a: x as u32,
                b: y as u32,
                len,
                b0: u0 * len,
                b1: u1 * len,
                s: DVec2::new(d.dot(t), d.y * t.x - d.x * t.y),
                sigma: w.sigma,
            });
        }
    }
}

/// Starts the propagation from a set of sources: their distances, and the first windows.
fn start(pr: &mut Propagation, set: &[Source]) {
    let (mesh, adj) = (pr.mesh, pr.adj);
    for src in set {
        match *src {
            Source::Vertex(v) => {
                pr.set_source(v);
                pr.expand_vertex(v, 0.0);
            }
            Source::Point(sp) => {
                let fv = mesh.faces[sp.face];
                if let Some(k) = (0..3).find(|&k| sp.bary[k] >= 1.0 - 1e-12) {
                    pr.set_source(fv[k]);
                    pr.expand_vertex(fv[k], 0.0);
                    continue;
                }
                let p = layout(mesh, sp.face);
                if !p.iter().all(|x| x.is_finite()) {
                    // A face with coincident corners: its corners at their chords.
                    let x = mesh.point(&sp);
                    for v in fv {
                        pr.relax(v, mesh.vertices[v].distance(x));
                    }
                    continue;
                }
                let s = p[0] * sp.bary[0] + p[1] * sp.bary[1] + p[2] * sp.bary[2];
                pr.expand_face(sp.face, p, s);
                // On an edge: the faces across it contain the point too.
                if let Some(k) = (0..3).find(|&k| sp.bary[k] <= 1e-12) {
                    let h = 3 * sp.face + (k + 1) % 3;
                    let (ea, eb) = (fv[(k + 1) % 3], fv[(k + 2) % 3]);
                    let t = sp.bary[(k + 2) % 3] / (sp.bary[(k + 1) % 3] + sp.bary[(k + 2) % 3]);
                    for g in adj.across(h).collect::<Vec<_>>() {
                        let f = g / 3;
                        let q = layout(mesh, f);
                        let gv = mesh.faces[f];
                        let (Some(ia), Some(ib)) = (
                            gv.iter().position(|&x| x == ea),
                            gv.iter().position(|&x| x == eb),
                        ) else {
                            continue;
                        };
                        if q.iter().all(|x| x.is_finite()) {
                            pr.expand_face(f, q, q[ia] * (1.0 - t) + q[ib] * t);
                        }
                    }
                }
            }
        }
    }
}

/// Exact geodesic distances from one set of sources to every vertex (+inf where none reaches).
/// `max_items` bounds the work (an error past it, never a wrong answer).
pub(crate) fn exact_distances(
    mesh: &Mesh,
    adj: &Adjacency,
    table: &FaceUnfolding,
    pseudo: &[bool],
    set: &[Source],
    max_items: usize,
) -> Result<Vec<f64>> {
    let mut dist = vec![f64::INFINITY; mesh.vertices.len()];
    let mut pr = Propagation::new(mesh, adj, Some(table), Some(pseudo), &mut dist);
    start(&mut pr, set);
    let mut n = 0usize;
    while pr.step().is_some() {
        n += 1;
        if n > max_items {
            return Err(RokebyError::numerical(
                "mesh",
                format!("exact geodesics: more than {max_items} windows (a degenerate mesh?)"),
            ));
        }
    }
    Ok(dist)
}

/// *Direct* geodesics from a set of sources (paths that bend at no vertex: straight lines in the
/// unfolding, Ying, Wang & He 2013, §3) to the vertices nearest to it: window propagation without
/// pseudo-sources, in order of distance, stopped once `k` vertices have a distance. Every value
/// is the length of a path on the surface (never shorter than the geodesic); values up to the
/// last window's distance are the direct geodesic distances. `dist` is all +inf on entry and is
/// left so (only the returned vertices are reset).
pub(crate) fn direct_near(
    mesh: &Mesh,
    adj: &Adjacency,
    set: &[Source],
    k: usize,
    dist: &mut [f64],
    touched: &mut Vec<usize>,
    queue: &mut Queue,
) {
    let mut pr = Propagation::new(mesh, adj, None, None, dist);
    // The buffers of the previous query (cleared), so that a query allocates only while its
    // wavefront outgrows them.
    queue.windows.clear();
    queue.free.clear();
    touched.clear();
    pr.windows = std::mem::take(&mut queue.windows);
    pr.free = std::mem::take(&mut queue.free);
    pr.touched = std::mem::take(touched);
    if let Some(heap) = queue.heap.take() {
        pr.heap = heap;
    }
    start(&mut pr, set);
    // A bound on the work for degenerate meshes (windows that split without end).
    let mut budget = 200 * k + 10_000;
    while pr.touched.len() < k && budget > 0 && pr.step().is_some() {
        budget -= 1;
    }
    *touched = std::mem::take(&mut pr.touched);
    queue.windows = std::mem::take(&mut pr.windows);
    queue.free = std::mem::take(&mut pr.free);
    let mut heap = std::mem::replace(&mut pr.heap, RadixHeap::new());
    heap.clear();
    queue.heap = Some(heap);
}

/// The buffers [`direct_near`] keeps between queries (the saddle vertex graph runs thousands of
/// them while it is built, and one per source at each query).
#[derive(Default)]
pub(crate) struct Queue {
    windows: Vec<Window>,
    free: Vec<u32>,
    heap: Option<RadixHeap>,
}
