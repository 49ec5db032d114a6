//! The shadow mesh (Mattausch et al. §6.1): the caster deformed so that its silhouettes follow
//! the edited shadow boundaries, by Laplacian editing (Sorkine 2006) with cotangent weights.
//!
//! The vertices are taken to post-perspective light space ([`LightFrame::to_frustum`]) and scaled
//! by (1, 1, 1/w_z) (w_z = 2.5 by default), so the deformation reaches far along the light
//! direction. With L the cotangent Laplacian (w_ij = (cot α_ij + cot β_ij)/2), δ = L P the
//! differential coordinates of the rest positions P, and one soft constraint per silhouette
//! vertex — (1 − α) P'_b + α P'_f = (1 − α) P_b + α P_f + (Δx, Δy, 0), Δ the boundary edit in the
//! frustum's (x, y) with its depth kept (§5.2) — the new positions minimise
//!
//! |L P' − δ|² + λ² Σ_k |C_k P' − t_k|² + ε² |P' − P|²,
//!
//! whose normal matrix LᵀL + λ² CᵀC + ε² I does not depend on the edit: it is factored once
//! (faer's sparse Cholesky). The rest pose P solves it for Δ = 0, so an edit's solution is P plus
//! M⁻¹ λ² Cᵀ Δ: two back-substitutions (x and y; Δ has no depth part in the frustum). The small ε anchors parts
//! of the caster without silhouette constraints. With every Δ = 0 the solution is P itself.
//! Afterwards the positions go back through the inverse scale and projection.
//!
//! For a point light inside the caster's bounds (per-loop frusta, §5.2) the space is
//! [`LightSpace::Spherical`] and a constraint's offset is the difference of its edited and rest
//! silhouette points there (a 3D offset; in the frustum it is (Δx, Δy, 0)). Every solution is
//! linear in the offsets, which [`ShadowMeshSolver::solve_space`] exposes for incremental updates
//! while dragging.

use crate::error::{Result, RokebyError};
use crate::geometry::laplacian::{self, edge_lengths};
use crate::numerical::{self, Triplet};
use crate::shadows::light_space::{LightFrame, LightSpace};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::Mat;
use glam::{DVec2, DVec3};

pub const DEFAULT_W_Z: f64 = 2.5;
/// λ relative to the mean diagonal of LᵀL: the constraints dominate, the shape follows.
pub const DEFAULT_CONSTRAINT_WEIGHT: f64 = 10.0;
/// ε relative to the mean diagonal of LᵀL.
const ANCHOR_WEIGHT: f64 = 1e-4;

/// A silhouette vertex as a constraint: s = (1 − α) v_back + α v_front.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgePoint {
    pub back: u32,
    pub front: u32,
    pub alpha: f64,
}

/// Cotangent weights per undirected edge (i < j), summed over the edge's faces
/// ([`crate::geometry::laplacian::cotangent_weights`] on the faces' edge lengths).
pub fn cotangent_weights(v: &[DVec3], faces: &[[usize; 3]]) -> Vec<(u32, u32, f64)> {
    let lengths: Vec<[f64; 3]> = faces.iter().map(|&f| edge_lengths(v, f)).collect();
    laplacian::cotangent_weights(faces, &lengths)
}

/// The factored shadow-mesh system for one set of silhouette constraints.
pub struct ShadowMeshSolver {
    space: LightSpace,
    w_z: f64,
    /// Rest positions in scaled post-perspective light space.
    rest: Vec<DVec3>,
    constraints: Vec<EdgePoint>,
    lambda2: f64,
    llt: Llt<u32, f64>,
}

impl ShadowMeshSolver {
    /// Factors the system for the caster (`vertices`, `faces`) and the silhouette vertices that
    /// constrain it. `w_z` > 0, `constraint_weight` > 0 (relative; see the constants).
    pub fn new(
        frame: LightFrame,
        vertices: &[DVec3],
        faces: &[[usize; 3]],
        constraints: Vec<EdgePoint>,
        w_z: f64,
        constraint_weight: f64,
    ) -> Result<Self> {
        Self::in_space(
            LightSpace::Frustum(frame),
            vertices,
            faces,
            constraints,
            w_z,
            constraint_weight,
        )
    }

    /// [`Self::new`] in any [`LightSpace`].
    pub fn in_space(
        space: LightSpace,
        vertices: &[DVec3],
        faces: &[[usize; 3]],
        constraints: Vec<EdgePoint>,
        w_z: f64,
        constraint_weight: f64,
    ) -> Result<Self> {
        if !(w_z.is_finite() && w_z > 0.0) {
            return Err(RokebyError::invalid(
                "w_z",
                format!("must be positive and finite, got {w_z}"),
            ));
        }
        if !(constraint_weight.is_finite() && constraint_weight > 0.0) {
            return Err(RokebyError::invalid(
                "constraint_weight",
                format!("must be positive and finite, got {constraint_weight}"),
            ));
        }
        let n = vertices.len();
        for (k, c) in constraints.iter().enumerate() {
            if c.back as usize >= n || c.front as usize >= n || !(0.0..=1.0).contains(&c.alpha) {
                return Err(RokebyError::invalid("constraints", format!("constraint {k} refers to edge ({}, {}) with α = {} outside the mesh or [0, 1]", c.back, c.front, c.alpha)));
            }
        }
        let rest: Vec<DVec3> = vertices.iter().map(|&p| space.to_space(p, w_z)).collect();
        if let Some(i) = rest.iter().position(|p| !p.is_finite()) {
            return Err(RokebyError::invalid(
                "vertices",
                format!("vertex {i} has no finite position in the light's frustum"),
            ));
        }
        // Cotangent weights on the light-space positions (the space the editing happens in).
        let edges = cotangent_weights(&rest, faces);
        let mut lap: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
        let mut diag = vec![0.0; n];
        for &(i, j, w) in &edges {
            lap[i as usize].push((j, -w));
            lap[j as usize].push((i, -w));
            diag[i as usize] += w;
            diag[j as usize] += w;
        }
        for i in 0..n {
            lap[i].push((i as u32, diag[i]));
        }
        // LᵀL = L² (L is symmetric): row i = Σ_k L_ik L_k·, lower triangle only.
        let mut acc = vec![0.0f64; n];
        let mut mark = vec![u32::MAX; n];
        let mut touched: Vec<u32> = Vec::new();
        let mut trip: Vec<Triplet<u32, u32, f64>> = Vec::new();
        let mut diag_sum = 0.0;
        for i in 0..n {
            touched.clear();
            for &(k, lik) in &lap[i] {
                for &(j, lkj) in &lap[k as usize] {
                    if j as usize > i {
                        continue;
                    }
                    if mark[j as usize] != i as u32 {
                        mark[j as usize] = i as u32;
                        acc[j as usize] = 0.0;
                        touched.push(j);
                    }
                    acc[j as usize] += lik * lkj;
                }
            }
            for &j in &touched {
                if j as usize == i {
                    diag_sum += acc[i];
                }
                trip.push(Triplet::new(i as u32, j, acc[j as usize]));
            }
        }
        let mean_diag = if n > 0 {
            (diag_sum / n as f64).max(1e-300)
        } else {
            1.0
        };
        let lambda2 = constraint_weight * constraint_weight * mean_diag;
        let eps2 = ANCHOR_WEIGHT * ANCHOR_WEIGHT * mean_diag;
        for c in &constraints {
            let (b, f, a) = (c.back, c.front, c.alpha);
            let (wb, wf) = (1.0 - a, a);
            trip.push(Triplet::new(b, b, lambda2 * wb * wb));
            trip.push(Triplet::new(f, f, lambda2 * wf * wf));
            let (hi, lo) = (b.max(f), b.min(f));
            trip.push(Triplet::new(hi, lo, lambda2 * wb * wf));
        }
        for i in 0..n as u32 {
            trip.push(Triplet::new(i, i, eps2));
        }
        let m = numerical::assemble(n, &trip, "shadow mesh")?;
        let llt = numerical::cholesky(&m, "shadow mesh")?;
        Ok(ShadowMeshSolver {
            space,
            w_z,
            rest,
            constraints,
            lambda2,
            llt,
        })
    }

    pub fn num_constraints(&self) -> usize {
        self.constraints.len()
    }

    /// The light's frustum around the caster (None in the spherical space).
    pub fn frame(&self) -> Option<&LightFrame> {
        match &self.space {
            LightSpace::Frustum(f) => Some(f),
            LightSpace::Spherical { .. } => None,
        }
    }

    pub fn space(&self) -> &LightSpace {
        &self.space
    }

    /// World point → the solve space (scaled by 1/w_z along the light).
    pub fn to_space(&self, p: DVec3) -> DVec3 {
        self.space.to_space(p, self.w_z)
    }

    /// Rest positions in the solve space: the solution for zero offsets (L P = δ, C P = t₀).
    pub fn rest_space(&self) -> &[DVec3] {
        &self.rest
    }

    /// The shadow mesh's world-space vertices for the silhouette offsets `deltas` (one per
    /// constraint, in frustum (x, y) units).
    pub fn solve(&self, deltas: &[DVec2]) -> Result<Vec<DVec3>> {
        let d3: Vec<DVec3> = deltas.iter().map(|d| d.extend(0.0)).collect();
        self.solve_offsets(&d3)
    }

    /// [`Self::solve`] for offsets in the solve space (3D; see the module documentation).
    pub fn solve_offsets(&self, offsets: &[DVec3]) -> Result<Vec<DVec3>> {
        let x = self.solve_space(&[offsets])?;
        self.to_world(&x[0])
    }

    /// The solutions in the solve space for several sets of offsets: the rest positions plus
    /// [`Self::offset_response`] (the normal equations' right-hand side is the rest pose's plus
    /// λ² Cᵀ d, and the rest pose solves the first part exactly).
    pub fn solve_space(&self, sets: &[&[DVec3]]) -> Result<Vec<Vec<DVec3>>> {
        let mut x = self.offset_response(sets)?;
        for xs in &mut x {
            for (p, r) in xs.iter_mut().zip(&self.rest) {
                *p += *r;
            }
        }
        Ok(x)
    }

    /// M⁻¹ λ² Cᵀ d for each set of offsets d (M = LᵀL + λ² CᵀC + ε² I): how far the solution
    /// moves from the rest positions, linear in d. The coordinates in which a set's offsets are
    /// all zero (z in the caster's frustum, where offsets are (Δx, Δy, 0)) move by exactly zero and
    /// are not back-substituted; the others are, together in one pass over the factor.
    pub fn offset_response(&self, sets: &[&[DVec3]]) -> Result<Vec<Vec<DVec3>>> {
        let n = self.rest.len();
        for d in sets {
            if d.len() != self.constraints.len() {
                return Err(RokebyError::invalid(
                    "deltas",
                    format!(
                        "expected {} offsets (one per silhouette constraint), got {}",
                        self.constraints.len(),
                        d.len()
                    ),
                ));
            }
            if !d.iter().all(|d| d.is_finite()) {
                return Err(RokebyError::invalid("deltas", "offsets must be finite"));
            }
        }
        let cols: Vec<(usize, usize)> = sets
            .iter()
            .enumerate()
            .flat_map(|(s, d)| {
                (0..3)
                    .filter(move |&c| d.iter().any(|o| o[c] != 0.0))
                    .map(move |c| (s, c))
            })
            .collect();
        let mut out = vec![vec![DVec3::ZERO; n]; sets.len()];
        if cols.is_empty() {
            return Ok(out);
        }
        let mut x = Mat::<f64>::zeros(n, cols.len());
        for (j, &(s, c)) in cols.iter().enumerate() {
            for (con, d) in self.constraints.iter().zip(sets[s]) {
                let v = d[c] * self.lambda2;
                x[(con.back as usize, j)] += v * (1.0 - con.alpha);
                x[(con.front as usize, j)] += v * con.alpha;
            }
        }
        self.llt.solve_in_place(x.as_mut());
        for (j, &(s, c)) in cols.iter().enumerate() {
            for (i, p) in out[s].iter_mut().enumerate() {
                p[c] = x[(i, j)];
            }
        }
        Ok(out)
    }

    /// Solve-space positions → the shadow mesh's world vertices. An error, not NaN vertices:
    /// the fuzzer found w_z = weight = 1e30 with a drag of 1e300 noise overflowing the solve.
    pub fn to_world(&self, x: &[DVec3]) -> Result<Vec<DVec3>> {
        let out: Vec<DVec3> = x
            .iter()
            .map(|&q| self.space.from_space(q, self.w_z))
            .collect();
        if let Some(i) = out.iter().position(|p| !p.is_finite()) {
            return Err(RokebyError::invalid("deltas", format!("the shadow mesh overflowed at vertex {i}: the silhouette offsets or the weights (w_z, constraint_weight) are too large")));
        }
        Ok(out)
    }
}

/// §6.2: the blend factor (l_initial · l_current)^β between shadow mesh (1) and original (0);
/// directions are normalised, opposite half-spaces give 0, β = 0 gives no falloff.
pub fn falloff_factor(l_initial: DVec3, l_current: DVec3, beta: f64) -> Result<f64> {
    if !(beta.is_finite() && beta >= 0.0) {
        return Err(RokebyError::invalid(
            "beta",
            format!("must be ≥ 0 and finite, got {beta}"),
        ));
    }
    let (a, b) = (l_initial.normalize_or_zero(), l_current.normalize_or_zero());
    if a == DVec3::ZERO || b == DVec3::ZERO {
        return Err(RokebyError::invalid(
            "light",
            "light directions must be non-zero and finite",
        ));
    }
    if beta == 0.0 {
        return Ok(1.0);
    }
    // Clamped: the fuzzer found a·b = 1 + 2⁻⁵² for unit a ≈ b, giving 1.0000000000000009.
    Ok(a.dot(b).clamp(0.0, 1.0).powf(beta))
}
