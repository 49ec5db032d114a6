//! Exact distances next to a geodesic source, by unfolding the faces around it into the plane.
//!
//! A shortest path on a triangle mesh is a straight line in the unfolding of the faces it crosses
//! (Mitchell, Mount, Papadimitriou 1987; Chen & Han 1990). Next to a source, the faces are laid out
//! one by one across their edges, keeping for each edge the *window*: the part of it that the
//! source sees through the faces crossed so far. A vertex inside the cone of a window gets its
//! straight-line distance in the unfolding, the length of a path that stays on the surface. This is
//! Chen and Han's window propagation cut at a fixed depth (edge crossings), without their pruning:
//! near the source every branch is cheap.
//!
//! What the result is, exactly:
//! * on the source's own triangle (every triangle around a vertex source) it is the chord, which
//!   is the geodesic distance (no path is shorter than the chord, and the segment lies in the face);
//! * elsewhere it is the length of a straight path on the surface: never shorter than the
//!   geodesic, and equal to it where the geodesic crosses at most [`NEAR_DEPTH`] edges and no
//!   vertex (it can only pass through a vertex where the angles around it sum to more than 2π, a
//!   saddle; there the unfolded value is an upper bound).

use crate::geometry::geodesic::{Mesh, Source};
use crate::geometry::mesh::Adjacency;
use glam::DVec2;

/// Edge crossings from the source's faces that the unfolding follows. 3 reaches the 2-ring of a
/// vertex source and two rings of faces around a surface point in a regular mesh.
pub const NEAR_DEPTH: usize = 3;

#[inline]
pub(crate) fn cross(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Face `f` laid out in the plane with its 3D edge lengths: corner 0 at the origin, corner 1 on +x.
pub(crate) fn layout(mesh: &Mesh, f: usize) -> [DVec2; 3] {
    let p = mesh.faces[f].map(|v| mesh.vertices[v]);
    let l = [0, 1, 2].map(|k| p[k].distance(p[(k + 1) % 3]));
    crate::geometry::intrinsic::layout(l)
}

/// The third corner of a triangle on edge A–B with 3D lengths `la` = |AC| and `lb` = |BC|, on the
/// other side of the line A–B from `q`.
pub(crate) fn unfold_corner(a: DVec2, b: DVec2, la: f64, lb: f64, q: DVec2) -> DVec2 {
    let e = b - a;
    let l = e.length();
    let x = (la * la - lb * lb + l * l) / (2.0 * l);
    let y = (la * la - x * x).max(0.0).sqrt();
    let t = e / l;
    let n = DVec2::new(-t.y, t.x);
    let side = if cross(e, q - a) > 0.0 { -1.0 } else { 1.0 };
    a + t * x + n * (y * side)
}

struct Walk<'a> {
    mesh: &'a Mesh,
    adj: &'a Adjacency,
    out: &'a mut [f64],
    touched: &'a mut Vec<usize>,
    s: DVec2,
    eps: f64,
}

impl Walk<'_> {
    fn set(&mut self, v: usize, d: f64) {
        if !d.is_finite() {
            return;
        }
        if self.out[v] == f64::INFINITY {
            self.touched.push(v);
        }
        if d < self.out[v] {
            self.out[v] = d;
        }
    }

    /// Crosses halfedge `h` (vertices at `pa`, `pb` in the plane, `q` a point on the near side)
    /// into every other face on that edge, through the window `w0`–`w1` (ordered so that
    /// cross(w0 − s, w1 − s) > 0).
    // An unfolding step: the halfedge, its ends in the plane, the near point and the window, each
    // its own argument; a struct would only repack them.
    #[allow(clippy::too_many_arguments)]
    fn cross_edge(
        &mut self,
        h: usize,
        pa: DVec2,
        pb: DVec2,
        q: DVec2,
        w0: DVec2,
        w1: DVec2,
        depth: usize,
    ) {
        let (d0, d1) = (w0 - self.s, w1 - self.s);
        let others: Vec<usize> = self.adj.across(h).collect();
        let (f, k) = (h / 3, h % 3);
        let (a, b) = (self.mesh.faces[f][k], self.mesh.faces[f][(k + 1) % 3]);
        for g in others {
            let gf = self.mesh.faces[g / 3];
            let c = gf[(g % 3 + 2) % 3];
            let (va, vb, vc) = (
                self.mesh.vertices[a],
                self.mesh.vertices[b],
                self.mesh.vertices[c],
            );
            let pc = unfold_corner(pa, pb, va.distance(vc), vb.distance(vc), q);
            let rc = pc - self.s;
            if cross(d0, rc) >= -self.eps && cross(rc, d1) >= -self.eps {
                self.set(c, rc.length());
            }
            if depth == 0 {
                continue;
            }
            // The halfedges of g on a–c and c–b.
            let he = |x: usize, y: usize| {
                (0..3)
                    .find(|&j| {
                        let (u, w) = (gf[j], gf[(j + 1) % 3]);
                        (u == x && w == y) || (u == y && w == x)
                    })
                    .map(|j| 3 * (g / 3) + j)
            };
            for (x, y, px, py, opp) in [(a, c, pa, pc, pb), (c, b, pc, pb, pa)] {
                if let (Some(hn), Some((n0, n1))) = (he(x, y), self.clip(px, py, d0, d1)) {
                    self.cross_edge(hn, px, py, opp, n0, n1, depth - 1);
                }
            }
        }
    }

    /// The part of segment X–Y inside the cone from `s` between directions d0 and d1, ordered.
    fn clip(&self, x: DVec2, y: DVec2, d0: DVec2, d1: DVec2) -> Option<(DVec2, DVec2)> {
        let e = y - x;
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        // f(t) = c0 + t·c1 >= 0 for both sides of the cone.
        for (c0, c1) in [
            (cross(d0, x - self.s), cross(d0, e)),
            (cross(x - self.s, d1), cross(e, d1)),
        ] {
            if c1.abs() < 1e-300 {
                if c0 < -self.eps {
                    return None;
                }
            } else {
                let r = -c0 / c1;
                if c1 > 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
            }
        }
        if (t1 - t0).is_nan() || t1 - t0 <= 1e-9 {
            return None;
        }
        let (p0, p1) = (x + e * t0, x + e * t1);
        if cross(p0 - self.s, p1 - self.s) >= 0.0 {
            Some((p0, p1))
        } else {
            Some((p1, p0))
        }
    }

    /// Starts from a face that contains the source at `s` (in the face's own layout `p`): its
    /// corners get their chords; every edge that does not pass through the source is a window.
    fn start_at_face(&mut self, f: usize, p: [DVec2; 3], depth: usize) {
        let fv = self.mesh.faces[f];
        for k in 0..3 {
            self.set(fv[k], p[k].distance(self.s));
        }
        for k in 0..3 {
            let (pa, pb, pc) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            let e = pb - pa;
            // Edges through the source (a vertex source's own edges, a point on an edge) are
            // crossed by other source faces, not as windows.
            if cross(e, self.s - pa).abs() <= 1e-9 * e.length_squared() {
                continue;
            }
            let (w0, w1) = if cross(pa - self.s, pb - self.s) >= 0.0 {
                (pa, pb)
            } else {
                (pb, pa)
            };
            self.cross_edge(3 * f + k, pa, pb, pc, w0, w1, depth);
        }
    }
}

/// Distances from the sources of one set to the vertices next to them: `out` (one entry per
/// vertex, +inf on entry) receives the smallest unfolded distance, `touched` the vertices set.
pub(crate) fn near_source(
    mesh: &Mesh,
    adj: &Adjacency,
    set: &[Source],
    out: &mut [f64],
    touched: &mut Vec<usize>,
) {
    for src in set {
        // A point on a vertex is that vertex; a point on an edge lies in the faces of that edge.
        let (faces, on_point): (Vec<usize>, bool) = match *src {
            Source::Vertex(v) => (adj.faces_around(v).to_vec(), false),
            Source::Point(sp) => {
                let fv = mesh.faces[sp.face];
                if let Some(k) = (0..3).find(|&k| sp.bary[k] >= 1.0 - 1e-12) {
                    (adj.faces_around(fv[k]).to_vec(), false)
                } else {
                    let mut fs = vec![sp.face];
                    if let Some(k) = (0..3).find(|&k| sp.bary[k] <= 1e-12) {
                        let h = 3 * sp.face + (k + 1) % 3;
                        fs.extend(adj.across(h).map(|g| g / 3));
                    }
                    (fs, true)
                }
            }
        };
        let vertex = match *src {
            Source::Vertex(v) => Some(v),
            Source::Point(sp) => (0..3)
                .find(|&k| sp.bary[k] >= 1.0 - 1e-12)
                .map(|k| mesh.faces[sp.face][k]),
        };
        if faces.is_empty() {
            // A vertex on no proper face: only itself.
            if let Some(v) = vertex {
                if out[v] == f64::INFINITY {
                    touched.push(v);
                }
                out[v] = 0.0;
            }
            continue;
        }
        for f in faces {
            let p = layout(mesh, f);
            let fv = mesh.faces[f];
            if !p.iter().all(|x| x.is_finite()) {
                // A face with coincident corners has no layout: its corners get their chords.
                let x = match *src {
                    Source::Vertex(v) => mesh.vertices[v],
                    Source::Point(sp) => mesh.point(&sp),
                };
                for v in fv {
                    let d = mesh.vertices[v].distance(x);
                    if out[v] == f64::INFINITY {
                        touched.push(v);
                    }
                    out[v] = out[v].min(d);
                }
                continue;
            }
            let s = match (vertex, on_point) {
                (Some(v), _) => p[fv.iter().position(|&x| x == v).unwrap_or(0)],
                (None, true) => {
                    // Barycentric coordinates of x in face f (its own face, or one across the
                    // edge that x lies on, where x is a combination of that edge's two ends).
                    match *src {
                        Source::Point(sp) if sp.face == f => {
                            p[0] * sp.bary[0] + p[1] * sp.bary[1] + p[2] * sp.bary[2]
                        }
                        Source::Point(sp) => {
                            // x lies on the shared edge: place it by its weights on that edge.
                            let sv = mesh.faces[sp.face];
                            let mut acc = DVec2::ZERO;
                            for (k, &v) in sv.iter().enumerate() {
                                if let Some(j) = fv.iter().position(|&y| y == v) {
                                    acc += p[j] * sp.bary[k];
                                }
                            }
                            acc
                        }
                        _ => unreachable!(),
                    }
                }
                (None, false) => unreachable!(),
            };
            let scale = p[1].length_squared().max(p[2].length_squared());
            let mut walk = Walk {
                mesh,
                adj,
                out,
                touched,
                s,
                eps: 1e-12 * scale,
            };
            walk.start_at_face(f, p, NEAR_DEPTH - 1);
        }
    }
}
