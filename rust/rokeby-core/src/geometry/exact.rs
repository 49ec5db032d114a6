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

use crate::error::{Result, RokebyError};
use crate::geodesic::{Mesh, Source};
use crate::mesh::Adjacency;
use crate::unfold::{layout, unfold_corner};
use glam::DVec2;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

#[derive(Clone, Copy)]
struct Window {
    /// Halfedge (3·face + corner) of the face behind: the window enters every other face on it.
    h: usize,
    a: usize,
    b: usize,
    len: f64,
    b0: f64,
    b1: f64,
    s: DVec2,
    sigma: f64,
}

#[derive(Clone, Copy)]
enum Item {
    Window(Window),
    /// A vertex whose distance was lowered, as a pseudo-source of that distance.
    Vertex(usize, f64),
}

/// A queue entry: the key and the item's slot in [`Queue::items`] (16 bytes, where an item is 80:
/// the heap moves entries, not items). Ordered by the key alone, as when the entry held the item,
/// so that the heap pops the same items in the same order.
struct Entry(f64, u32);
impl PartialEq for Entry {
    fn eq(&self, o: &Self) -> bool {
        self.0 == o.0
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0)
    }
}

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
        if !crate::mesh::is_proper(f) {
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

/// The priority queue of windows and vertices, in order of distance: a binary heap of (key, slot)
/// over the items in slots, reused between queries ([`direct_near`]).
#[derive(Default)]
pub(crate) struct Queue {
    heap: BinaryHeap<Entry>,
    items: Vec<Item>,
    /// Slots of popped items, for reuse.
    free: Vec<u32>,
}

impl Queue {
    fn push(&mut self, key: f64, item: Item) {
        let slot = match self.free.pop() {
            Some(i) => {
                self.items[i as usize] = item;
                i
            }
            None => {
                self.items.push(item);
                (self.items.len() - 1) as u32
            }
        };
        self.heap.push(Entry(key, slot));
    }

    fn pop(&mut self) -> Option<Item> {
        let Entry(_, slot) = self.heap.pop()?;
        self.free.push(slot);
        Some(self.items[slot as usize])
    }

    fn clear(&mut self) {
        self.heap.clear();
        self.items.clear();
        self.free.clear();
    }
}

struct Propagation<'a> {
    mesh: &'a Mesh,
    adj: &'a Adjacency,
    /// Vertices that become pseudo-sources; `None`: none do (paths stay straight, for the local
    /// direct geodesics of [`crate::svg`]).
    pseudo: Option<&'a [bool]>,
    dist: &'a mut [f64],
    /// Vertices whose distance went from +inf to finite, in that order.
    touched: Vec<usize>,
    heap: &'a mut Queue,
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

impl Propagation<'_> {
    fn relax(&mut self, v: usize, d: f64) {
        if d < self.dist[v] {
            if self.dist[v] == f64::INFINITY {
                self.touched.push(v);
            }
            self.dist[v] = d;
            if self.pseudo.is_some_and(|p| p[v]) {
                self.heap.push(d, Item::Vertex(v, d));
            }
        }
    }

    /// A source vertex: distance 0, expanded by the caller (not queued as a pseudo-source).
    fn set_source(&mut self, v: usize) {
        if self.dist[v] == f64::INFINITY {
            self.touched.push(v);
        }
        self.dist[v] = 0.0;
    }

    /// Xin & Wang's rules on the two ends of the window's edge.
    fn useless(&self, w: &Window) -> bool {
        let at = |x: f64| w.sigma + w.s.distance(DVec2::new(x, 0.0));
        let (f1, f0) = (at(w.b1), at(w.b0));
        self.dist[w.a] + w.b1 < f1 * (1.0 - 1e-12)
            || self.dist[w.b] + (w.len - w.b0) < f0 * (1.0 - 1e-12)
    }

    fn push(&mut self, w: Window) {
        if !(w.len > 0.0 && w.s.y < 0.0 && w.b1 > w.b0) {
            return;
        }
        let tol = 1e-9 * w.len;
        if w.b0 <= tol {
            self.relax(w.a, w.sigma + w.s.length());
        }
        if w.b1 >= w.len - tol {
            self.relax(w.b, w.sigma + w.s.distance(DVec2::new(w.len, 0.0)));
        }
        if self.useless(&w) {
            return;
        }
        let x = w.s.x.clamp(w.b0, w.b1);
        let key = w.sigma + w.s.distance(DVec2::new(x, 0.0));
        self.heap.push(key, Item::Window(w));
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
            h,
            a,
            b,
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
        for &f in self.adj.faces_around(v) {
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

    fn process(&mut self, w: Window) {
        if self.useless(&w) {
            return;
        }
        let (pa, pb) = (DVec2::ZERO, DVec2::new(w.len, 0.0));
        let k = w.s.y.abs().max(1e-300);
        // Where the ray from s through p (y > −s.y side) crosses the edge, as a numerator that is
        // ≥ 0 where the crossing is at or beyond x = bnd (the denominator p.y + k is positive).
        let num = |p: DVec2, bnd: f64| (p.x - w.s.x) * k - (bnd - w.s.x) * (p.y + k);
        let adj = self.adj;
        for g in adj.across(w.h) {
            let gf = self.mesh.faces[g / 3];
            let j = g % 3;
            let c = gf[(j + 2) % 3];
            if c == w.a || c == w.b {
                continue;
            }
            let vc = self.mesh.vertices[c];
            let (la, lb) = (
                self.mesh.vertices[w.a].distance(vc),
                self.mesh.vertices[w.b].distance(vc),
            );
            let pc = unfold_corner(pa, pb, la, lb, DVec2::new(0.0, -1.0));
            if !pc.is_finite() {
                continue;
            }
            let tol = 1e-9 * w.len;
            if pc.y > 0.0 && num(pc, w.b0 - tol) >= 0.0 && num(pc, w.b1 + tol) <= 0.0 {
                self.relax(c, w.sigma + w.s.distance(pc));
            }
            // Halfedges of g on a–c and c–b, whatever g's orientation.
            let he = |x: usize, y: usize| {
                (0..3)
                    .find(|&i| {
                        let (u, t) = (gf[i], gf[(i + 1) % 3]);
                        (u == x && t == y) || (u == y && t == x)
                    })
                    .map(|i| 3 * (g / 3) + i)
            };
            for (x, y, px, py, behind) in [(w.a, c, pa, pc, pb), (c, w.b, pc, pb, pa)] {
                let Some(hn) = he(x, y) else { continue };
                // The interval of u ∈ [0, 1] (px + u (py − px)) inside the cone.
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
                if u1 - u0 > 1e-12 {
                    self.window_on(hn, (x, y), (px, py, behind), (u0, u1), w.s, w.sigma);
                }
            }
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
    pseudo: &[bool],
    set: &[Source],
    max_items: usize,
) -> Result<Vec<f64>> {
    let mut dist = vec![f64::INFINITY; mesh.vertices.len()];
    let mut queue = Queue::default();
    let mut pr = Propagation {
        mesh,
        adj,
        pseudo: Some(pseudo),
        dist: &mut dist,
        touched: Vec::new(),
        heap: &mut queue,
    };
    start(&mut pr, set);
    let mut n = 0usize;
    while let Some(item) = pr.heap.pop() {
        n += 1;
        if n > max_items {
            return Err(RokebyError::numerical(
                "mesh",
                format!("exact geodesics: more than {max_items} windows (a degenerate mesh?)"),
            ));
        }
        match item {
            Item::Window(w) => pr.process(w),
            Item::Vertex(v, d) => {
                if d <= pr.dist[v] {
                    pr.expand_vertex(v, d);
                }
            }
        }
    }
    Ok(dist)
}

/// *Direct* geodesics from a set of sources (paths that bend at no vertex: straight lines in the
/// unfolding, Ying, Wang & He 2013, §3) to the vertices nearest to it: window propagation without
/// pseudo-sources, in order of distance, stopped once `k` vertices have a distance. Every value
/// is the length of a path on the surface (never shorter than the geodesic); values up to the
/// last window's distance are the direct geodesic distances. `dist` is all +inf and `touched`
/// empty on entry; on return `touched` holds the vertices reached (in the order they were first
/// reached) and `dist` their distances, which the caller resets to +inf. `queue`: the window
/// queue's buffers, kept by the caller between calls.
pub(crate) fn direct_near(
    mesh: &Mesh,
    adj: &Adjacency,
    set: &[Source],
    k: usize,
    dist: &mut [f64],
    touched: &mut Vec<usize>,
    queue: &mut Queue,
) {
    queue.clear();
    let mut pr = Propagation {
        mesh,
        adj,
        pseudo: None,
        dist,
        touched: std::mem::take(touched),
        heap: queue,
    };
    start(&mut pr, set);
    // A bound on the work for degenerate meshes (windows that split without end).
    let mut budget = 200 * k + 10_000;
    while let Some(item) = pr.heap.pop() {
        if pr.touched.len() >= k || budget == 0 {
            break;
        }
        budget -= 1;
        if let Item::Window(w) = item {
            pr.process(w);
        }
    }
    *touched = pr.touched;
}
