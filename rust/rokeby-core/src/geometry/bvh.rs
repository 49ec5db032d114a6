//! A bounding-volume hierarchy over triangles for shadow rays (Mattausch et al., §4.2 and §5.1:
//! shadow handles are silhouette points projected onto the receivers by ray casting).
//!
//! Built top-down by median splits of the triangle centroids along the longest axis of their
//! bounds (leaves of at most [`LEAF_SIZE`] triangles); rays are tested with Möller–Trumbore in
//! f64 (with a 1e-9 barycentric slack, so shared edges are watertight), closest hit first. [`Bvh::intersect_many`] runs one ray per rayon task.

use crate::error::{Result, RokebyError};
use glam::DVec3;
use rayon::prelude::*;

pub const LEAF_SIZE: usize = 4;

/// The closest intersection of a ray with the triangles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter: the hit point is `origin + t * dir`.
    pub t: f64,
    /// Index of the triangle in the order the BVH was built from.
    pub tri: usize,
    /// Barycentric coordinates of the hit point on the triangle's second and third vertex.
    pub u: f64,
    pub v: f64,
    /// The ray arrives from behind the triangle: its geometric normal `(b − a) × (c − a)` points
    /// along the ray (a back face of an outward-oriented closed mesh).
    pub back_facing: bool,
}

#[derive(Debug, Clone, Copy)]
struct Node {
    min: DVec3,
    max: DVec3,
    /// Leaf: first index into `order`; inner node: index of the left child (right = left + 1).
    start: u32,
    /// Number of triangles of a leaf, 0 for inner nodes.
    count: u32,
}

/// A ray query that skips some triangles (for instance the caster's faces next to a silhouette
/// point, which a grazing ray from that point would otherwise hit at once).
pub trait TriFilter: Sync {
    fn skip(&self, tri: usize) -> bool;
}

impl<F: Fn(usize) -> bool + Sync> TriFilter for F {
    fn skip(&self, tri: usize) -> bool {
        self(tri)
    }
}

#[derive(Debug, Clone)]
pub struct Bvh {
    tris: Vec<[DVec3; 3]>,
    order: Vec<u32>,
    nodes: Vec<Node>,
}

fn tri_bounds(t: &[DVec3; 3]) -> (DVec3, DVec3) {
    (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))
}

impl Bvh {
    /// A BVH over `tris` (non-finite corners are an error naming `arg`).
    pub fn new(tris: Vec<[DVec3; 3]>, arg: &str) -> Result<Self> {
        if let Some(i) = tris.iter().position(|t| !t.iter().all(|p| p.is_finite())) {
            return Err(RokebyError::invalid(
                arg,
                format!("triangle {i} has a non-finite corner"),
            ));
        }
        if tris.len() >= u32::MAX as usize {
            return Err(RokebyError::invalid(
                arg,
                format!("{} triangles is more than the BVH supports", tris.len()),
            ));
        }
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let centroids: Vec<DVec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF_SIZE + 1);
        nodes.push(Node {
            min: DVec3::ZERO,
            max: DVec3::ZERO,
            start: 0,
            count: 0,
        });
        // Iterative build: (node index, range in `order`).
        let mut stack = vec![(0usize, 0usize, tris.len())];
        while let Some((ni, lo, hi)) = stack.pop() {
            let (mut mn, mut mx) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
            let (mut cmn, mut cmx) = (mn, mx);
            for &t in &order[lo..hi] {
                let (a, b) = tri_bounds(&tris[t as usize]);
                mn = mn.min(a);
                mx = mx.max(b);
                let c = centroids[t as usize];
                cmn = cmn.min(c);
                cmx = cmx.max(c);
            }
            nodes[ni].min = mn;
            nodes[ni].max = mx;
            let ext = cmx - cmn;
            if hi - lo <= LEAF_SIZE || ext.max_element() <= 0.0 {
                nodes[ni].start = lo as u32;
                nodes[ni].count = (hi - lo) as u32;
                continue;
            }
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = (lo + hi) / 2;
            order[lo..hi].select_nth_unstable_by(mid - lo, |&a, &b| {
                centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
            });
            let left = nodes.len();
            nodes.push(Node {
                min: DVec3::ZERO,
                max: DVec3::ZERO,
                start: 0,
                count: 0,
            });
            nodes.push(Node {
                min: DVec3::ZERO,
                max: DVec3::ZERO,
                start: 0,
                count: 0,
            });
            nodes[ni].start = left as u32;
            stack.push((left, lo, mid));
            stack.push((left + 1, mid, hi));
        }
        if tris.is_empty() {
            nodes[0].min = DVec3::ZERO;
            nodes[0].max = DVec3::ZERO;
        }
        Ok(Bvh { tris, order, nodes })
    }

    pub fn len(&self) -> usize {
        self.tris.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    pub fn triangle(&self, i: usize) -> &[DVec3; 3] {
        &self.tris[i]
    }

    /// Bounds of all triangles (zero for an empty BVH).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        (self.nodes[0].min, self.nodes[0].max)
    }

    /// The closest hit with `t_min < t < t_max` (`dir` need not be normalised), skipping the
    /// triangles `filter` rejects.
    pub fn intersect_filtered(
        &self,
        origin: DVec3,
        dir: DVec3,
        t_min: f64,
        t_max: f64,
        filter: &dyn TriFilter,
    ) -> Option<Hit> {
        if self.tris.is_empty() || !origin.is_finite() || !dir.is_finite() || dir == DVec3::ZERO {
            return None;
        }
        let inv = dir.recip();
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(ni) = stack.pop() {
            let n = &self.nodes[ni as usize];
            if !slab(n.min, n.max, origin, inv, t_min, t_best) {
                continue;
            }
            if n.count > 0 {
                for &t in &self.order[n.start as usize..(n.start + n.count) as usize] {
                    let ti = t as usize;
                    if filter.skip(ti) {
                        continue;
                    }
                    if let Some(h) = moller_trumbore(&self.tris[ti], origin, dir, t_min, t_best) {
                        t_best = h.t;
                        best = Some(Hit { tri: ti, ..h });
                    }
                }
            } else {
                stack.push(n.start);
                stack.push(n.start + 1);
            }
        }
        best
    }

    pub fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64, t_max: f64) -> Option<Hit> {
        self.intersect_filtered(origin, dir, t_min, t_max, &|_: usize| false)
    }

    /// One closest-hit query per (origin, dir), in parallel.
    pub fn intersect_many(
        &self,
        rays: &[(DVec3, DVec3)],
        t_min: f64,
        t_max: f64,
    ) -> Vec<Option<Hit>> {
        rays.par_iter()
            .map(|&(o, d)| self.intersect(o, d, t_min, t_max))
            .collect()
    }

    /// Reference: every triangle tested (for tests and validation).
    pub fn intersect_brute_force(
        &self,
        origin: DVec3,
        dir: DVec3,
        t_min: f64,
        t_max: f64,
    ) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        for (i, tri) in self.tris.iter().enumerate() {
            if let Some(h) = moller_trumbore(tri, origin, dir, t_min, t_best) {
                t_best = h.t;
                best = Some(Hit { tri: i, ..h });
            }
        }
        best
    }
}

fn slab(mn: DVec3, mx: DVec3, o: DVec3, inv: DVec3, t0: f64, t1: f64) -> bool {
    let a = (mn - o) * inv;
    let b = (mx - o) * inv;
    // NaN (0 · inf for a ray in a slab's plane) must not reject: min/max of glam drop NaN
    // operands the way f64::min/max do.
    let lo = a.min(b);
    let hi = a.max(b);
    let tmin = lo.x.max(lo.y).max(lo.z).max(t0);
    let tmax = hi.x.min(hi.y).min(hi.z).min(t1);
    // Conservative by a relative 1e-9: the fuzzer found a triangle with 1e30 coordinates that the
    // triangle test (rounding at that scale) hits just outside the box the slab test rejects, so
    // the BVH missed a hit the brute force found.
    tmin <= tmax + 1e-9 * tmax.abs().max(tmin.abs())
}

/// Barycentric slack of the triangle test. Plain Möller–Trumbore is not watertight: a ray through
/// the edge two triangles share can round to just outside both (a proptest aiming rays at the
/// edges and vertices of jittered grids found misses), and a shadow handle would fall through the
/// crack. 1e-9 is far above the f64 rounding of u and v and far below anything a mesh resolves.
const EDGE_TOLERANCE: f64 = 1e-9;

fn moller_trumbore(t: &[DVec3; 3], o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<Hit> {
    let e1 = t[1] - t[0];
    let e2 = t[2] - t[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    let scale = e1.length() * e2.length() * d.length();
    if det.abs() <= 1e-14 * scale || scale == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - t[0];
    let u = s.dot(p) * inv;
    if !(-EDGE_TOLERANCE..=1.0 + EDGE_TOLERANCE).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < -EDGE_TOLERANCE || u + v > 1.0 + EDGE_TOLERANCE {
        return None;
    }
    // Hits within the tolerance report the nearest point of the triangle.
    let u = u.clamp(0.0, 1.0);
    let v = v.clamp(0.0, 1.0 - u);
    let tt = e2.dot(q) * inv;
    // Negated so that NaN bounds reject every hit (the fuzzer found hits behind t_min = NaN).
    if !(tt > t_min && tt < t_max) {
        return None;
    }
    // det = e1 · (d × e2) = −d · (e1 × e2): positive when the ray meets the front side.
    Some(Hit {
        t: tt,
        tri: 0,
        u,
        v,
        back_facing: det < 0.0,
    })
}
