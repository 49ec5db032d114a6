//! The Moving Least Squares rotation field of Ritschel et al. 2009, §5.
//!
//! A constraint n has a point pₙ on the reflecting surface, its original reflected direction rₙ and
//! its edited direction eₙ. At a surface point q the field is the rotation
//!
//! ```text
//!   R(q) = ortho( Σₙ wₙ eₙ rₙᵀ ),   wₙ = 1 / d(pₙ, q)²              (eqs. 3 and 5)
//!   e(q) = R(q) r(q)                                                 (eq. 6)
//!   R_a(q) = ortho( a(q) R(q) + (1 − a(q)) r(q) r(q)ᵀ )               (eq. 7, one region)
//! ```
//!
//! Implementation notes (each is a documented choice, tested in `tests/field_props.rs`):
//! * Weights wₙ = 1/d²ₙ are accumulated in f64, whose range holds them for every distance float32
//!   coordinates produce; ortho is scale-invariant, so the field is the same for scenes scaled by
//!   1e-6 or 1e6 (tested), with no normalisation pass.
//! * Interpolation: where q coincides with constraints (d = 0) only those act, with equal weights
//!   (coincident constraints are averaged). When they leave the twist about eₙ free (rank 1), the
//!   other constraints choose it, which is the limit of the field as q → pₙ, so R is continuous.
//! * Regions: only constraints with a(pₙ) > 0 act in a region; a region without constraints
//!   changes nothing. Overlapping regions j combine as ortho(Σⱼ aⱼ Rⱼ + (1 − min(1, Σⱼ aⱼ)) X),
//!   which is eq. 7 exactly for one region. X = r rᵀ where the view is known (per pixel, or per
//!   point when normals and an eye are given), else X = I (the view-independent form, which acts
//!   on r(q) the same way: a R r + (1 − a) r). Points outside every region are unchanged, and
//!   constraints outside every region act nowhere. Without any region, all constraints act
//!   everywhere (the paper's default before a region is drawn).
//! * One constraint in a group gives the same rotation everywhere (the smallest rotation rₙ → eₙ),
//!   computed once.

use crate::error::{Result, RokebyError};
use crate::reflection::polar::{self, min_rotation, PolarMethod};
use crate::reflection::region::Region;
use crate::unit_vector::unit_longer_than;
use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

mod f32_lanes;
mod f64_lanes;
mod lane_vectors;
pub use f32_lanes::Kernel;

/// Row length of a constraint: [p (3), r (3), e (3)].
pub const CONSTRAINT_STRIDE: usize = 9;

#[derive(Debug, Clone, Copy)]
pub struct Constraint {
    /// pₙ, the red handle's point on the reflecting surface.
    pub p: DVec3,
    /// rₙ, the original (physical) reflected direction at pₙ, unit.
    pub r: DVec3,
    /// eₙ, the edited direction (towards the green handle), unit.
    pub e: DVec3,
}

/// Where wₙ's distances come from.
#[derive(Debug, Clone, Copy)]
pub enum Distances<'a> {
    /// |q − pₙ|, computed on the fly.
    Euclidean,
    /// Precomputed d(pₙ, q) as a row-major (K, N) array (e.g. geodesic). +inf = unreachable.
    Given(&'a [f32]),
}

struct Group {
    region: Option<usize>,
    members: Vec<usize>,
    /// The field of a single constraint: the same rotation everywhere.
    constant: Option<DQuat>,
}

/// A prepared field: validated, normalised constraints, their region membership, and constant
/// parts computed once. Evaluate it per point or per pixel.
pub struct Field {
    constraints: Vec<Constraint>,
    /// eₙ rₙᵀ, the rank-1 term of eq. 5, formed once.
    er: Vec<DMat3>,
    regions: Vec<Region>,
    groups: Vec<Group>,
    /// Which implementation evaluates it (`Kernel::from_env()` unless chosen).
    kernel: Kernel,
}

/// Per-chunk working memory: no allocation per point or pixel.
struct Scratch {
    warm: Vec<DQuat>,
    blend_warm: DQuat,
    d2: Vec<f64>,
    /// The (one) group's rotation at the next point, solved by the f64 lanes (`wide`).
    given: Option<DQuat>,
}

impl Scratch {
    /// Warm-starts the (one) group's Newton iteration from a lane's f32 rotation.
    fn warm_from(&mut self, q: [f32; 4]) {
        if let Some(w) = self.warm.first_mut() {
            *w = warm_quat(q);
        }
    }
}

/// A lane's f32 rotation as an f64 warm start (the identity if it is not one).
fn warm_quat(q: [f32; 4]) -> DQuat {
    let q = DQuat::from_xyzw(q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64);
    let len = q.length();
    if len.is_finite() && len > 0.5 {
        q / len
    } else {
        DQuat::IDENTITY
    }
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// The unit vector of a constraint's direction (finite; any length above 1e-20 is a direction).
fn unit(v: DVec3, arg: &str, what: &str) -> Result<DVec3> {
    if !v.is_finite() {
        return Err(RokebyError::invalid(arg, format!("{what} is not finite")));
    }
    unit_longer_than(v, 1e-20)
        .ok_or_else(|| RokebyError::invalid(arg, format!("{what} has zero length")))
}

/// The form in which the per-point field is returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldOutput {
    /// Unit quaternions (x, y, z, w), w ≥ 0.
    Quaternion,
    /// Rotation vectors axis × angle, angle in [0, π].
    RotationVector,
    /// The view-independent parts of eq. 7, (x, y, z, w, a, u) per point: the rotation R of the
    /// region(s) acting there (w ≥ 0) and the region weight a ∈ [0, 1]. A renderer forms
    /// R_a r = `view_blend(R, a, r)` per shading point for its own r (see there), so the blend
    /// towards r rᵀ is exact per pixel and the stored field does not depend on the eye. Where
    /// several regions overlap with Σa < 1, R = ortho(Σⱼ aⱼ Rⱼ) and a = Σⱼ aⱼ (exact when the
    /// overlapping rotations agree, and wherever Σa ≥ 1 or one region acts).
    /// u: when the field has exactly one region and it is Euclidean with a border > 0, its
    /// unclamped border ramp (radius − |q − c|) / border, so that a = `smooth_step(u)`; a
    /// renderer interpolating u instead of a across a face follows the border per pixel, as the
    /// preview does (a distance interpolates far better than its smooth step). Otherwise u = a.
    ViewBlend,
}

/// Width of one point's output for `output`.
pub fn output_width(output: FieldOutput) -> usize {
    match output {
        FieldOutput::Quaternion => 4,
        FieldOutput::RotationVector => 3,
        FieldOutput::ViewBlend => 6,
    }
}

/// Eq. 7 for one region in closed form: R_a r with R_a = ortho(a R + (1 − a) r rᵀ), r unit.
///
/// Write aR + (1 − a) r rᵀ = R N with N = a I + (1 − a) s rᵀ, s = Rᵀ r. N keeps the plane P
/// spanned by r and s and is a·I on P⊥, so its polar factor is a rotation in P (when
/// a + (1 − a) cos φ > 0, φ = ∠(r, s); otherwise the closest rotation in P, the continuous
/// choice a shader can make), by θ = atan2((1 − a) sin φ, 2a + (1 − a) cos φ) from r towards s.
/// Hence R_a r = R (cos θ r + sin θ t), t the unit part of s orthogonal to r. a = 1 gives R r,
/// a = 0 gives r. The render nodes (rokeby.reflection.render.shading) implement the same lines.
pub fn view_blend(rot: DQuat, a: f64, r: DVec3) -> DVec3 {
    let a = a.clamp(0.0, 1.0);
    let b = 1.0 - a;
    let s = rot.inverse() * r;
    let cos_phi = r.dot(s);
    let perp = s - r * cos_phi;
    let sin_phi = perp.length();
    let theta = (b * sin_phi).atan2(2.0 * a + b * cos_phi);
    let t = if sin_phi > 1e-300 {
        perp / sin_phi
    } else {
        DVec3::ZERO
    };
    rot * (r * theta.cos() + t * theta.sin())
}

/// `view_blend` for N points: `parts` (N×6, `FieldOutput::ViewBlend`, possibly interpolated)
/// and unit directions r (N×3), both flattened; the weight is a, or `smooth_step(u)` when
/// `ramp` (the single-Euclidean-region form). Returns the edited directions (N×3).
pub fn view_blend_directions(parts: &[f32], r: &[f32], ramp: bool) -> Result<Vec<f32>> {
    if !parts.len().is_multiple_of(6)
        || !r.len().is_multiple_of(3)
        || parts.len() / 6 != r.len() / 3
    {
        return Err(RokebyError::invalid(
            "parts",
            format!(
                "expected (N, 6) parts for (N, 3) directions, got {} and {} values",
                parts.len(),
                r.len()
            ),
        ));
    }
    check_finite(r, "directions")?;
    check_parts(parts)?;
    let mut out = vec![0f32; r.len()];
    out.par_chunks_mut(3 * 4096)
        .enumerate()
        .for_each(|(ci, chunk)| {
            for (j, o) in chunk.chunks_exact_mut(3).enumerate() {
                let i = ci * 4096 + j;
                let p = &parts[6 * i..6 * i + 6];
                let q = DQuat::from_xyzw(p[0] as f64, p[1] as f64, p[2] as f64, p[3] as f64);
                let len = q.length();
                let q = if len > 1e-30 {
                    q / len
                } else {
                    DQuat::IDENTITY
                };
                let d = vec3_at(r, i).normalize_or_zero();
                let a = if ramp {
                    crate::reflection::region::smooth_step(p[5] as f64)
                } else {
                    p[4] as f64
                };
                let e = view_blend(q, a, d);
                o.copy_from_slice(&[e.x as f32, e.y as f32, e.z as f32]);
            }
        });
    check_output(&out)?;
    Ok(out)
}

fn check_parts(parts: &[f32]) -> Result<usize> {
    if !parts.len().is_multiple_of(6) {
        return Err(RokebyError::invalid(
            "parts",
            format!("expected (N, 6) rows, got {} values", parts.len()),
        ));
    }
    if let Some(i) = first_index(parts, |x| !x.is_finite()) {
        return Err(RokebyError::invalid(
            "parts",
            format!("row {} has a non-finite value", i / 6),
        ));
    }
    Ok(parts.len() / 6)
}

/// Eq. 7's view-independent parts as a renderer reads them (the add-on's render attributes):
/// (x, y, z) and (w, a, 0) per row, or (w, −1, u) with `ramp` (one Euclidean region: a =
/// `smooth_step(u)` per shading point). Corner c belongs to vertex `corner_vert[c]` and to the
/// polygon whose first corner's vertex is `first_vert[c]`. When every polygon's quaternions lie
/// in one hemisphere already (no vertex of a polygon has q·q_first < 0, the common case), the rows
/// are per vertex (`per_corner` false): the renderer's interpolation is then right as it is, at a
/// quarter of the data. Otherwise they are per corner, each quaternion's sign chosen in the
/// hemisphere of its polygon's first corner, so interpolation never crosses the antipodal seam
/// (edits near a half turn).
pub struct RenderRows {
    pub per_corner: bool,
    pub xyz: Vec<f32>,
    pub wa: Vec<f32>,
}

pub fn view_blend_render_rows(
    parts: &[f32],
    corner_vert: &[i64],
    first_vert: &[i64],
    ramp: bool,
) -> Result<RenderRows> {
    let n = check_parts(parts)?;
    if corner_vert.len() != first_vert.len() {
        return Err(RokebyError::invalid(
            "first_vert",
            format!(
                "has {} entries for {} corners",
                first_vert.len(),
                corner_vert.len()
            ),
        ));
    }
    for (arg, idx) in [("corner_vert", corner_vert), ("first_vert", first_vert)] {
        if let Some(c) = first_index(idx, |&v| v < 0 || v as u64 >= n as u64) {
            return Err(RokebyError::invalid(
                arg,
                format!(
                    "corner {c} refers to vertex {} but there are {n} vertices",
                    idx[c]
                ),
            ));
        }
    }
    let q = |v: i64| &parts[6 * v as usize..6 * v as usize + 4];
    let dot = |a: &[f32], b: &[f32]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    let flips = (0..corner_vert.len())
        .into_par_iter()
        .with_min_len(8192)
        .any(|c| dot(q(corner_vert[c]), q(first_vert[c])) < 0.0);
    let rows = if flips { corner_vert.len() } else { n };
    let mut xyz = vec![0f32; 3 * rows];
    let mut wa = vec![0f32; 3 * rows];
    const CHUNK: usize = 8192;
    xyz.par_chunks_mut(3 * CHUNK)
        .zip(wa.par_chunks_mut(3 * CHUNK))
        .enumerate()
        .for_each(|(ci, (xs, ws))| {
            for (j, (x, w)) in xs
                .chunks_exact_mut(3)
                .zip(ws.chunks_exact_mut(3))
                .enumerate()
            {
                let k = ci * CHUNK + j;
                let (v, sign) = if flips {
                    let v = corner_vert[k];
                    (
                        v as usize,
                        if dot(q(v), q(first_vert[k])) < 0.0 {
                            -1.0
                        } else {
                            1.0
                        },
                    )
                } else {
                    (k, 1.0)
                };
                let p = &parts[6 * v..6 * v + 6];
                x.copy_from_slice(&[sign * p[0], sign * p[1], sign * p[2]]);
                if ramp {
                    w.copy_from_slice(&[sign * p[3], -1.0, p[5]]);
                } else {
                    w.copy_from_slice(&[sign * p[3], p[4], 0.0]);
                }
            }
        });
    Ok(RenderRows {
        per_corner: flips,
        xyz,
        wa,
    })
}

/// The view-independent form of each point's field, ortho(a R + (1 − a) I), as rotation vectors
/// (axis × angle, angle in [0, π]): a rotation about R's axis by ψ = atan2(a sin α, a cos α + 1 − a),
/// α being R's angle (a R + (1 − a) I is a scaled rotation in the plane orthogonal to the axis and
/// 1 along it). What the add-on stores per point for scripts.
pub fn view_blend_rotation_vectors(parts: &[f32]) -> Result<Vec<f32>> {
    let n = check_parts(parts)?;
    let mut out = vec![0f32; 3 * n];
    out.par_chunks_mut(3 * 8192)
        .enumerate()
        .for_each(|(ci, chunk)| {
            for (j, o) in chunk.chunks_exact_mut(3).enumerate() {
                let p = &parts[6 * (ci * 8192 + j)..6 * (ci * 8192 + j) + 6];
                let q = polar::canonical(DQuat::from_xyzw(
                    p[0] as f64,
                    p[1] as f64,
                    p[2] as f64,
                    p[3] as f64,
                ));
                let a = (p[4] as f64).clamp(0.0, 1.0);
                let u = DVec3::new(q.x, q.y, q.z);
                let s = u.length();
                let v = if s > 1e-12 {
                    // |u| = sin(α/2), w = cos(α/2): sin α = 2 s w, cos α = w² − s² (one atan2).
                    u / s * (a * 2.0 * s * q.w).atan2(a * (q.w * q.w - s * s) + 1.0 - a)
                } else {
                    u * (2.0 * a) // ψ ≈ a α for small angles; the rotation vector of R is ≈ 2u
                };
                o.copy_from_slice(&[v.x as f32, v.y as f32, v.z as f32]);
            }
        });
    Ok(out)
}

/// The original reflected direction r(q) = reflect(i, n), i = (q − eye)/|q − eye| (eq. 6's r(q)).
pub fn reflect_dir(q: DVec3, n: DVec3, eye: DVec3) -> Option<DVec3> {
    let i = (q - eye).try_normalize()?;
    let n = n.try_normalize()?;
    (i - 2.0 * i.dot(n) * n).try_normalize()
}

impl Field {
    /// `rows` is the (K, 9) constraint array flattened; `regions` may be empty (all constraints act
    /// everywhere).
    pub fn new(rows: &[f32], regions: Vec<Region>) -> Result<Self> {
        if !rows.len().is_multiple_of(CONSTRAINT_STRIDE) {
            return Err(RokebyError::invalid(
                "constraints",
                "must have 9 columns [p, r, e]",
            ));
        }
        let k = rows.len() / CONSTRAINT_STRIDE;
        let mut constraints = Vec::with_capacity(k);
        for (n, row) in rows.chunks_exact(CONSTRAINT_STRIDE).enumerate() {
            let v = |o: usize| DVec3::new(row[o] as f64, row[o + 1] as f64, row[o + 2] as f64);
            let arg = "constraints";
            let p = v(0);
            if !p.is_finite() {
                return Err(RokebyError::invalid(
                    arg,
                    format!("row {n}: p (columns 0-2) is not finite"),
                ));
            }
            let r = unit(v(3), arg, &format!("row {n}: r (columns 3-5)"))?;
            let e = unit(v(6), arg, &format!("row {n}: e (columns 6-8)"))?;
            constraints.push(Constraint { p, r, e });
        }
        let mut groups = Vec::new();
        if regions.is_empty() {
            if k > 0 {
                groups.push(Group {
                    region: None,
                    members: (0..k).collect(),
                    constant: None,
                });
            }
        } else {
            for (j, reg) in regions.iter().enumerate() {
                let members: Vec<usize> = (0..k)
                    .filter(|&n| reg.at_constraint(n, constraints[n].p) > 0.0)
                    .collect();
                if !members.is_empty() {
                    groups.push(Group {
                        region: Some(j),
                        members,
                        constant: None,
                    });
                }
            }
        }
        for g in &mut groups {
            if g.members.len() == 1 {
                let c = constraints[g.members[0]];
                g.constant = Some(polar::canonical(min_rotation(c.r, c.e)));
            }
        }
        let er = constraints.iter().map(|c| outer(c.e, c.r)).collect();
        Ok(Field {
            constraints,
            er,
            regions,
            groups,
            kernel: Kernel::from_env(),
        })
    }

    /// The kernel that evaluates this field: `kernel`, or the widest one below it this CPU runs.
    pub fn with_kernel(mut self, kernel: Kernel) -> Self {
        self.kernel = Kernel::resolve(kernel);
        self
    }

    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    pub fn num_constraints(&self) -> usize {
        self.constraints.len()
    }

    fn scratch(&self) -> Scratch {
        let max_members = self
            .groups
            .iter()
            .map(|g| g.members.len())
            .max()
            .unwrap_or(0);
        Scratch {
            warm: vec![DQuat::IDENTITY; self.groups.len()],
            blend_warm: DQuat::IDENTITY,
            d2: vec![0.0; max_members],
            given: None,
        }
    }

    /// Eq. 5 for one group (all constraints of one region) at point `idx` / position `q`.
    ///
    /// One pass accumulates M = Σ wₙ eₙrₙᵀ with wₙ = 1/d²ₙ in f64: ortho is scale-invariant and
    /// f64's range holds 1/d² for any distance that float32 coordinates can produce (down to
    /// ~1e-90), so no normalisation pass is needed. A zero distance (q on a constraint) switches
    /// to the interpolation branch.
    // A kernel of eqs. 2–7: the point, its constraints, distances, regions and scratch, each its own
    // argument as the paper's terms; a struct would only repack them.
    #[allow(clippy::too_many_arguments)]
    fn solve_group(
        &self,
        gi: usize,
        idx: usize,
        n_points: usize,
        q: DVec3,
        dist: Distances,
        polar: PolarMethod,
        s: &mut Scratch,
    ) -> DQuat {
        let g = &self.groups[gi];
        if let Some(c) = g.constant {
            return c;
        }
        if let Some(q) = s.given.take() {
            // Solved by the f64 lanes for this point (only fields of one group use them).
            s.warm[gi] = q;
            return q;
        }
        let d2 = &mut s.d2[..g.members.len()];
        let mut m = DMat3::ZERO;
        let mut dmin2 = f64::INFINITY;
        for (slot, &n) in d2.iter_mut().zip(&g.members) {
            let x = match dist {
                Distances::Euclidean => (q - self.constraints[n].p).length_squared(),
                Distances::Given(d) => {
                    let x = d[n * n_points + idx] as f64;
                    x * x
                }
            };
            *slot = x;
            dmin2 = dmin2.min(x);
            // x = 0 gives +inf here; that M is discarded by the interpolation branch below.
            m += self.er[n] * x.recip();
        }
        if dmin2 == f64::INFINITY {
            // No constraint of this region can reach q (another connected component).
            return DQuat::IDENTITY;
        }
        if dmin2 == 0.0 {
            // q is on constraint(s): interpolation. Equal weights among the coincident ones; the
            // others only break a rank-1 tie (the limit q → pₙ), so R is continuous there.
            let mut m0 = DMat3::ZERO;
            let mut b = DMat3::ZERO;
            for (&x, &n) in d2.iter().zip(&g.members) {
                if x == 0.0 {
                    m0 += self.er[n];
                } else if x.is_finite() {
                    b += self.er[n] * x.recip();
                }
            }
            let q = polar::ortho_tiebreak(&m0, Some(&b));
            s.warm[gi] = q;
            return q;
        }
        // Where the nearest constraint dominates (M numerically rank 1), the others decide the
        // twist about eₙ — the limit the rank-2 solution tends to, so the field has no seam at
        // the rank threshold. Summed apart (not M minus the nearest term, which cancels).
        let tiebreak = || {
            let mut rest = DMat3::ZERO;
            let mut skipped = false;
            for (&x, &n) in d2.iter().zip(&g.members) {
                if !skipped && x == dmin2 {
                    skipped = true;
                } else if x.is_finite() {
                    rest += self.er[n] * x.recip();
                }
            }
            Some(rest)
        };
        polar::ortho(&m, tiebreak, polar, &mut s.warm[gi])
    }

    /// Σⱼ aⱼ(q) Rⱼ(q) over the regions acting at q (eq. 7's sum), with Σⱼ aⱼ, how many act and
    /// the last one's (Rⱼ, aⱼ). Needs regions.
    // A kernel of eqs. 2–7: the point, its constraints, distances, regions and scratch, each its own
    // argument as the paper's terms; a struct would only repack them.
    #[allow(clippy::too_many_arguments)]
    fn region_sum_at(
        &self,
        idx: usize,
        n_points: usize,
        q: DVec3,
        dist: Distances,
        polar: PolarMethod,
        s: &mut Scratch,
    ) -> (DMat3, f64, usize, (DQuat, f64)) {
        let mut acc = DMat3::ZERO;
        let mut asum = 0.0;
        let mut count = 0;
        let mut last = (DQuat::IDENTITY, 0.0);
        for gi in 0..self.groups.len() {
            let Some(region) = self.groups[gi].region else {
                continue;
            };
            let a = self.regions[region].at_point(idx, q);
            if a <= 0.0 {
                continue;
            }
            let rg = self.solve_group(gi, idx, n_points, q, dist, polar, s);
            acc += DMat3::from_quat(rg) * a;
            asum += a;
            count += 1;
            last = (rg, a);
        }
        (acc, asum, count, last)
    }

    /// R(q) (or R_a(q) inside regions) at one point. `r_view` is r(q) when the view is known.
    // A kernel of eqs. 2–7: the point, its constraints, distances, regions and scratch, each its own
    // argument as the paper's terms; a struct would only repack them.
    #[allow(clippy::too_many_arguments)]
    fn rotation_at(
        &self,
        idx: usize,
        n_points: usize,
        q: DVec3,
        r_view: Option<DVec3>,
        dist: Distances,
        polar: PolarMethod,
        s: &mut Scratch,
    ) -> DQuat {
        if self.groups.is_empty() {
            return DQuat::IDENTITY;
        }
        if self.regions.is_empty() {
            return self.solve_group(0, idx, n_points, q, dist, polar, s);
        }
        let (mut acc, asum, count, last) = self.region_sum_at(idx, n_points, q, dist, polar, s);
        if count == 0 {
            return DQuat::IDENTITY;
        }
        if count == 1 && asum >= 1.0 {
            return last.0;
        }
        let rest = 1.0 - asum.min(1.0);
        if rest > 0.0 {
            acc += match r_view {
                Some(r) => outer(r, r),
                None => DMat3::IDENTITY,
            } * rest;
        }
        polar::ortho(&acc, || None, polar, &mut s.blend_warm)
    }

    /// The view-independent parts of R_a(q) (see `FieldOutput::ViewBlend`): (R, a).
    fn view_blend_parts_at(
        &self,
        idx: usize,
        n_points: usize,
        q: DVec3,
        dist: Distances,
        polar: PolarMethod,
        s: &mut Scratch,
    ) -> (DQuat, f64) {
        if self.groups.is_empty() {
            return (DQuat::IDENTITY, 0.0);
        }
        if self.regions.is_empty() {
            return (self.solve_group(0, idx, n_points, q, dist, polar, s), 1.0);
        }
        let (acc, asum, count, last) = self.region_sum_at(idx, n_points, q, dist, polar, s);
        match count {
            0 => (DQuat::IDENTITY, 0.0),
            1 => (last.0, last.1.min(1.0)),
            _ => (
                polar::ortho(&acc, || None, polar, &mut s.blend_warm),
                asum.min(1.0),
            ),
        }
    }

    fn check_distance_shape(&self, dist: Distances, n_points: usize) -> Result<()> {
        if let Distances::Given(d) = dist {
            let k = self.constraints.len();
            if d.len() != k * n_points {
                return Err(RokebyError::invalid(
                    "distances",
                    format!("expected shape ({k}, {n_points}) for {k} constraints and {n_points} points, got {} values", d.len()),
                ));
            }
        }
        Ok(())
    }

    fn check_distance_values(&self, dist: Distances, n_points: usize) -> Result<()> {
        if let Distances::Given(d) = dist {
            if let Some(i) = first_index(d, |x| x.is_nan() || *x < 0.0) {
                return Err(RokebyError::invalid(
                    "distances",
                    format!("entry ({}, {}) = {} is not a distance (NaN or negative; unreachable is +inf)", i / n_points.max(1), i % n_points.max(1), d[i]),
                ));
            }
        }
        Ok(())
    }

    fn check_per_point_regions(&self, n_points: usize) -> Result<()> {
        for (j, reg) in self.regions.iter().enumerate() {
            if let Region::PerPoint { values, .. } = reg {
                if values.len() != n_points {
                    return Err(RokebyError::invalid(
                        format!("regions[{j}]"),
                        format!(
                            "values has {} entries but there are {} points",
                            values.len(),
                            n_points
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Per-point path: rotations at `points` (N×3 flattened) as unit quaternions (x, y, z, w),
    /// w ≥ 0, flattened N×4. `view`: optional per-point normals and an eye, so that eq. 7 blends
    /// towards r rᵀ exactly; without it the view-independent form (towards I) is used.
    pub fn rotation_field(
        &self,
        points: &[f32],
        dist: Distances,
        view: Option<(&[f32], [f64; 3])>,
        polar: PolarMethod,
    ) -> Result<Vec<f32>> {
        self.rotation_field_as(points, dist, view, polar, FieldOutput::Quaternion)
    }

    /// `rotation_field` with the output form chosen: quaternions (N×4) or rotation vectors
    /// axis × angle (N×3, what the add-on writes as a mesh attribute), converted in the same pass.
    pub fn rotation_field_as(
        &self,
        points: &[f32],
        dist: Distances,
        view: Option<(&[f32], [f64; 3])>,
        polar: PolarMethod,
        output: FieldOutput,
    ) -> Result<Vec<f32>> {
        let n = points.len() / 3;
        if points.is_empty() {
            return Err(RokebyError::invalid("points", "is empty"));
        }
        self.check_distance_shape(dist, n)?;
        self.check_per_point_regions(n)?;
        let eye = match view {
            Some((normals, eye)) => {
                if normals.len() != points.len() {
                    return Err(RokebyError::invalid(
                        "normals",
                        "must have the same shape as points",
                    ));
                }
                check_finite(points, "points")?;
                check_nonzero_dirs(normals, "normals")?;
                let eye = DVec3::from_array(eye);
                if !eye.is_finite() {
                    return Err(RokebyError::invalid("eye", "is not finite"));
                }
                check_eye(points, eye)?;
                Some((normals, eye))
            }
            None => None,
        };
        let width = output_width(output);
        let mut out = vec![0f32; n * width];
        let given = match dist {
            Distances::Given(d) => Some(d),
            Distances::Euclidean => None,
        };
        let plan = self.lanes_plan(polar, dist);
        let Some(plan) = plan else {
            check_finite(points, "points")?;
            self.check_distance_values(dist, n)?;
            // The exact method: the f64 lanes, the scalar path where they cannot vouch.
            let rows = self.wide_rows(self.exact_plan(polar).as_ref());
            let ctx = rows.as_deref().map(|rows| f64_lanes::Ctx {
                rows,
                points,
                dist: given,
                n,
                exact: f64_lanes::Exactness::Exact,
            });
            const CHUNK: usize = 2048;
            par_chunks_if_large(&mut out, CHUNK * width, n, |ci, chunk| {
                let mut s = self.scratch();
                let count = chunk.len() / width;
                let at = |j: usize| (ci * CHUNK + j, None::<[f32; 4]>);
                self.with_wide(ctx.as_ref(), count, at, &mut s, |i, s| {
                    let o = &mut chunk[(i - ci * CHUNK) * width..(i - ci * CHUNK + 1) * width];
                    self.point_scalar(i, n, points, dist, eye, polar, output, o, s);
                });
                (false, false)
            });
            check_output(&out)?;
            return Ok(out);
        };
        let rows = self.wide_rows(Some(&plan));
        let ctx = rows.as_deref().map(|rows| f64_lanes::Ctx {
            rows,
            points,
            dist: given,
            n,
            exact: f64_lanes::Exactness::Fast,
        });
        let inputs = f32_lanes::Inputs {
            field: self,
            plan: &plan,
            points,
            dist: given,
            n,
            job: f32_lanes::Job::Points {
                output,
                view: eye.is_some(),
                ramp: f32_lanes::ramp_of(&self.regions),
            },
        };
        const CHUNK: usize = 4096;
        let (suspect, nonfinite) = par_chunks_if_large(&mut out, CHUNK * width, n, |ci, chunk| {
            let start = ci * CHUNK;
            let left = f32_lanes::run(self.kernel, &inputs, start, chunk);
            let mut s = self.scratch();
            let mut nonfinite = false;
            FALLBACK_LANES.fetch_add(left.points.len() as u64, Ordering::Relaxed);
            let pts = &left.points;
            let at = |j: usize| (pts[j].0, Some(pts[j].1));
            self.with_wide(ctx.as_ref(), pts.len(), at, &mut s, |i, s| {
                let o = &mut chunk[(i - start) * width..(i - start + 1) * width];
                self.point_scalar(i, n, points, dist, eye, polar, output, o, s);
                nonfinite |= !o.iter().all(|x| x.is_finite());
            });
            (left.suspect, nonfinite)
        });
        if suspect {
            // The same errors, in the same order, as the checks the scalar path runs first.
            check_finite(points, "points")?;
            self.check_distance_values(dist, n)?;
        }
        if nonfinite {
            check_output(&out)?;
        }
        Ok(out)
    }

    /// The f32 lanes' plan when this call can use them: a vector kernel, Newton's polar method (the
    /// exact one runs the f64 lanes alone, `exact_plan`), and one group.
    fn lanes_plan(&self, polar: PolarMethod, dist: Distances) -> Option<f32_lanes::Plan> {
        if self.kernel == Kernel::Scalar || polar != PolarMethod::Iterative {
            return None;
        }
        let plan = self.plan()?;
        // A constant group never reads its distances; the scan below still refuses bad ones.
        if plan.constant.is_some() && matches!(dist, Distances::Given(_)) {
            return None;
        }
        Some(plan)
    }

    /// The plan of the exact polar method's f64 lanes: a vector kernel and one group.
    fn exact_plan(&self, polar: PolarMethod) -> Option<f32_lanes::Plan> {
        if self.kernel == Kernel::Scalar || polar != PolarMethod::Svd {
            return None;
        }
        self.plan()
    }

    /// The f64 lanes' rows for `plan`, unless its group is one constraint (a constant rotation).
    fn wide_rows(&self, plan: Option<&f32_lanes::Plan>) -> Option<Vec<f64_lanes::Row64>> {
        let plan = plan?;
        (self.kernel != Kernel::Scalar && plan.constant.is_none())
            .then(|| f64_lanes::rows64(self, plan))
    }

    /// `each(i, s)` (the scalar path of point i) for the points `at(0..count)` in order. With
    /// `ctx`, the group's rotation at each point is first solved by the f64 lanes in blocks of 4
    /// and handed to the scalar path in `s.given` (None: the scalar path solves it). Warm starts:
    /// the f32 lane's rotation `at(j).1`, else the lane's previous result (the point 4 before).
    fn with_wide(
        &self,
        ctx: Option<&f64_lanes::Ctx>,
        count: usize,
        at: impl Fn(usize) -> (usize, Option<[f32; 4]>),
        s: &mut Scratch,
        mut each: impl FnMut(usize, &mut Scratch),
    ) {
        let Some(ctx) = ctx else {
            for j in 0..count {
                let (i, q) = at(j);
                if let Some(q) = q {
                    s.warm_from(q);
                    SCALAR_LANES.fetch_add(1, Ordering::Relaxed);
                }
                each(i, s);
            }
            return;
        };
        let mut chain = [DQuat::IDENTITY; 4];
        let mut scalar = 0;
        for b in (0..count).step_by(4) {
            let len = 4.min(count - b);
            let lanes: [(usize, Option<[f32; 4]>); 4] =
                std::array::from_fn(|l| at(b + l.min(len - 1)));
            let warm = std::array::from_fn(|l| lanes[l].1.map_or(chain[l], warm_quat));
            let got = f64_lanes::solve4(self.kernel, ctx, lanes.map(|x| x.0), warm);
            for l in 0..len {
                let (i, q) = lanes[l];
                match got[l] {
                    Some(g) => chain[l] = g,
                    None => {
                        if let Some(q) = q {
                            s.warm_from(q);
                        }
                        scalar += q.is_some() as u64;
                    }
                }
                s.given = got[l];
                each(i, s);
                s.given = None;
            }
        }
        SCALAR_LANES.fetch_add(scalar, Ordering::Relaxed);
    }

    /// One point of `rotation_field_as` by the scalar f64 path (the reference).
    // A kernel of eqs. 2–7: the point, its constraints, distances, regions and scratch, each its own
    // argument as the paper's terms; a struct would only repack them.
    #[allow(clippy::too_many_arguments)]
    fn point_scalar(
        &self,
        i: usize,
        n: usize,
        points: &[f32],
        dist: Distances,
        eye: Option<(&[f32], DVec3)>,
        polar: PolarMethod,
        output: FieldOutput,
        o: &mut [f32],
        s: &mut Scratch,
    ) {
        let q = vec3_at(points, i);
        if output == FieldOutput::ViewBlend {
            let (rot, a) = self.view_blend_parts_at(i, n, q, dist, polar, s);
            let rot = polar::canonical(rot);
            let u = match f32_lanes::ramp_of(&self.regions) {
                Some((center, radius, border)) => {
                    (radius - q.distance(center)) / border.min(radius)
                }
                None => a,
            };
            o.copy_from_slice(&[
                rot.x as f32,
                rot.y as f32,
                rot.z as f32,
                rot.w as f32,
                a as f32,
                u as f32,
            ]);
            return;
        }
        let r_view = eye.and_then(|(normals, eye)| reflect_dir(q, vec3_at(normals, i), eye));
        let rot = polar::canonical(self.rotation_at(i, n, q, r_view, dist, polar, s));
        match output {
            FieldOutput::ViewBlend => {} // written above
            FieldOutput::Quaternion => {
                o.copy_from_slice(&[rot.x as f32, rot.y as f32, rot.z as f32, rot.w as f32])
            }
            FieldOutput::RotationVector => {
                let v = polar::rotation_vector(rot);
                o.copy_from_slice(&[v.x as f32, v.y as f32, v.z as f32]);
            }
        }
    }

    /// One pixel of `edited_directions` by the scalar f64 path (the reference).
    // A kernel of eqs. 2–7: the point, its constraints, distances, regions and scratch, each its own
    // argument as the paper's terms; a struct would only repack them.
    #[allow(clippy::too_many_arguments)]
    fn pixel_scalar(
        &self,
        i: usize,
        n: usize,
        positions: &[f32],
        normals: &[f32],
        eye: DVec3,
        dist: Distances,
        polar: PolarMethod,
        o: &mut [f32],
        s: &mut Scratch,
    ) {
        let q = vec3_at(positions, i);
        // Checked: q ≠ eye and n ≠ 0, so r exists; the fallback is unreachable for valid input.
        let r = reflect_dir(q, vec3_at(normals, i), eye).unwrap_or(DVec3::Z);
        let rot = self.rotation_at(i, n, q, Some(r), dist, polar, s);
        let e = (rot * r).normalize();
        o.copy_from_slice(&[e.x as f32, e.y as f32, e.z as f32]);
    }

    /// Per-pixel path (paper §6.1): for a G-buffer of positions and normals (N×3 flattened) seen
    /// from `eye`, the edited reflection directions e(q) = R_a(q) r(q) as unit vectors (N×3).
    /// Work is split into rows of `row_len` pixels (tiles of coherent pixels: the iterative polar
    /// method warm-starts from the previous pixel of the row, the lanes from the pixel W before).
    pub fn edited_directions(
        &self,
        positions: &[f32],
        normals: &[f32],
        eye: [f64; 3],
        dist: Distances,
        polar: PolarMethod,
        row_len: usize,
    ) -> Result<Vec<f32>> {
        let n = positions.len() / 3;
        if normals.len() != positions.len() {
            return Err(RokebyError::invalid(
                "normals",
                "must have the same shape as positions",
            ));
        }
        if positions.is_empty() {
            return Err(RokebyError::invalid("positions", "is empty"));
        }
        let eye = DVec3::from_array(eye);
        if !eye.is_finite() {
            return Err(RokebyError::invalid("eye", "is not finite"));
        }
        self.check_distance_shape(dist, n)?;
        self.check_per_point_regions(n)?;
        let checks = || -> Result<()> {
            check_finite(positions, "positions")?;
            check_nonzero_dirs(normals, "normals")?;
            check_eye(positions, eye)?;
            self.check_distance_values(dist, n)
        };
        let row_len = row_len.clamp(1, 1 << 16);
        let mut out = vec![0f32; n * 3];
        let given = match dist {
            Distances::Given(d) => Some(d),
            Distances::Euclidean => None,
        };
        let Some(plan) = self.lanes_plan(polar, dist) else {
            checks()?;
            // The exact method: the f64 lanes, the scalar path where they cannot vouch.
            let rows = self.wide_rows(self.exact_plan(polar).as_ref());
            let ctx = rows.as_deref().map(|rows| f64_lanes::Ctx {
                rows,
                points: positions,
                dist: given,
                n,
                exact: f64_lanes::Exactness::Exact,
            });
            par_chunks_if_large(&mut out, row_len * 3, n, |ci, chunk| {
                let mut s = self.scratch();
                let at = |j: usize| (ci * row_len + j, None::<[f32; 4]>);
                self.with_wide(ctx.as_ref(), chunk.len() / 3, at, &mut s, |i, s| {
                    let o = &mut chunk[(i - ci * row_len) * 3..(i - ci * row_len + 1) * 3];
                    self.pixel_scalar(i, n, positions, normals, eye, dist, polar, o, s);
                });
                (false, false)
            });
            check_output(&out)?;
            return Ok(out);
        };
        let rows = self.wide_rows(Some(&plan));
        let ctx = rows.as_deref().map(|rows| f64_lanes::Ctx {
            rows,
            points: positions,
            dist: given,
            n,
            exact: f64_lanes::Exactness::Fast,
        });
        let inputs = f32_lanes::Inputs {
            field: self,
            plan: &plan,
            points: positions,
            dist: given,
            n,
            job: f32_lanes::Job::Pixels {
                normals,
                eye: eye.as_vec3().to_array(),
            },
        };
        let (suspect, nonfinite) = par_chunks_if_large(&mut out, row_len * 3, n, |ci, chunk| {
            let start = ci * row_len;
            let left = f32_lanes::run(self.kernel, &inputs, start, chunk);
            let mut s = self.scratch();
            let mut nonfinite = false;
            FALLBACK_LANES.fetch_add(left.points.len() as u64, Ordering::Relaxed);
            let pts = &left.points;
            let at = |j: usize| (pts[j].0, Some(pts[j].1));
            self.with_wide(ctx.as_ref(), pts.len(), at, &mut s, |i, s| {
                let o = &mut chunk[(i - start) * 3..(i - start + 1) * 3];
                self.pixel_scalar(i, n, positions, normals, eye, dist, polar, o, s);
                nonfinite |= !o.iter().all(|x| x.is_finite());
            });
            (left.suspect, nonfinite)
        });
        if suspect {
            checks()?;
        }
        if nonfinite {
            check_output(&out)?;
        }
        Ok(out)
    }
}

/// Points or pixels the lanes handed to the scalar f64 path since the process started (what
/// `make bench` reports as the fallback share).
static FALLBACK_LANES: AtomicU64 = AtomicU64::new(0);

/// How many points or pixels the f32 lanes have handed to f64 so far (those next to a constraint,
/// at region borders, or too ill-conditioned for f32; see `lanes`): to the f64 lanes (`wide`) and,
/// where those cannot vouch either, to the scalar path.
pub fn fallback_lanes() -> u64 {
    FALLBACK_LANES.load(Ordering::Relaxed)
}

/// Of `fallback_lanes`, those the f64 lanes left to the scalar f64 path (points on a constraint,
/// M numerically rank 1, region borders).
static SCALAR_LANES: AtomicU64 = AtomicU64::new(0);

pub fn scalar_fallback_lanes() -> u64 {
    SCALAR_LANES.load(Ordering::Relaxed)
}

/// Points up to which a call runs on the calling thread: waking the pool costs more than it
/// saves for a few thousand points, and on two cores shared with Blender it competes with the UI.
const SMALL_JOB: usize = 16384;

/// `f(chunk index, chunk)` over `out` in chunks of `chunk_len` values, in parallel unless the job
/// (`n` points) is small; returns the OR of the flags the chunks report.
fn par_chunks_if_large(
    out: &mut [f32],
    chunk_len: usize,
    n: usize,
    f: impl Fn(usize, &mut [f32]) -> (bool, bool) + Sync,
) -> (bool, bool) {
    let or = |a: (bool, bool), b: (bool, bool)| (a.0 | b.0, a.1 | b.1);
    if n <= SMALL_JOB {
        out.chunks_mut(chunk_len)
            .enumerate()
            .map(|(ci, c)| f(ci, c))
            .fold((false, false), or)
    } else {
        out.par_chunks_mut(chunk_len)
            .enumerate()
            .map(|(ci, c)| f(ci, c))
            .reduce(|| (false, false), or)
    }
}

#[inline]
fn vec3_at(a: &[f32], i: usize) -> DVec3 {
    DVec3::new(a[3 * i] as f64, a[3 * i + 1] as f64, a[3 * i + 2] as f64)
}

/// The first index (in order, whatever the thread count) of `a` for which `bad` holds, checked
/// in parallel chunks with a plain loop inside each (rayon's `position_first` pays an atomic per
/// element: 9 ms for the 600k values of a 100k-point field, against well under 1 ms this way).
fn first_index<T: Sync>(a: &[T], bad: impl Fn(&T) -> bool + Sync) -> Option<usize> {
    const CHUNK: usize = 16384;
    a.par_chunks(CHUNK)
        .enumerate()
        .find_map_first(|(ci, chunk)| chunk.iter().position(&bad).map(|j| ci * CHUNK + j))
}

/// Rows per parallel validation task.
const CHECK_ROWS: usize = 8192;

/// The first row (in order, whatever the thread count) for which `bad` holds.
fn first_bad_row(a: &[f32], bad: impl Fn(&[f32]) -> bool + Sync) -> Option<usize> {
    a.par_chunks(3 * CHECK_ROWS)
        .enumerate()
        .find_map_first(|(ci, chunk)| {
            chunk
                .chunks_exact(3)
                .position(&bad)
                .map(|j| ci * CHECK_ROWS + j)
        })
}

fn check_finite(a: &[f32], arg: &str) -> Result<()> {
    if a.is_empty() {
        return Err(RokebyError::invalid(arg, "is empty"));
    }
    if let Some(i) = first_bad_row(a, |r| {
        !(r[0].is_finite() && r[1].is_finite() && r[2].is_finite())
    }) {
        return Err(RokebyError::invalid(
            arg,
            format!(
                "row {i} has a non-finite value ({:?})",
                &a[3 * i..3 * i + 3]
            ),
        ));
    }
    Ok(())
}

fn check_nonzero_dirs(a: &[f32], arg: &str) -> Result<()> {
    check_finite(a, arg)?;
    if let Some(i) = first_bad_row(a, |r| {
        let l2 = DVec3::new(r[0] as f64, r[1] as f64, r[2] as f64).length_squared();
        l2.is_nan() || l2 <= 1e-40
    }) {
        return Err(RokebyError::invalid(
            arg,
            format!("row {i} has zero length"),
        ));
    }
    Ok(())
}

fn check_eye(points: &[f32], eye: DVec3) -> Result<()> {
    if let Some(i) = first_bad_row(points, |r| {
        DVec3::new(r[0] as f64, r[1] as f64, r[2] as f64) == eye
    }) {
        return Err(RokebyError::invalid(
            "eye",
            format!("coincides with point {i}: no view direction there"),
        ));
    }
    Ok(())
}

/// The kernel never produces a non-finite value by construction; this is the last guard so that a
/// bug becomes an error message, not NaN in Blender data.
fn check_output(out: &[f32]) -> Result<()> {
    if let Some(i) = first_index(out, |x| !x.is_finite()) {
        return Err(RokebyError::internal(format!(
            "the rotation field has a non-finite result at flat index {i}"
        )));
    }
    Ok(())
}
