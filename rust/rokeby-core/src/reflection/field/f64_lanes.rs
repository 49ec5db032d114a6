//! The field of eq. 5 over f64 lanes of 4 (`lane_vectors`' `Avx2F64`, one 256-bit register, on
//! CPUs with AVX2 + FMA; `PortableF64` elsewhere): for the points the f32 lanes cannot pin to 1e-5 rad (next to a constraint, where M is
//! nearly rank 1), gathered into blocks of 4, and for every point of the exact polar method.
//!
//! Per lane: M = Σₙ eₙrₙᵀ / d²ₙ in f64 as `Field::solve_group` forms it (then scaled by d²_min:
//! ortho is scale-invariant), and Newton's method on SO(3) for ortho(M) (`polar::ortho_iterative`)
//! from the lane's warm start. A lane returns a rotation only where the scalar path's answer is the
//! same optimum:
//! * fast (`Exactness::Fast`): `ortho_iterative`'s own acceptance (a Newton step below 1e-4 rad with
//!   H positive definite, and M not numerically rank 1), so the result is the scalar fast path's up
//!   to rounding;
//! * exact (`Exactness::Exact`): H positive definite with λ_min(H) ≥ `EXACT_COND` ‖M‖_F (so f64
//!   rounding moves R by at most about 1e-13 rad) and a last Newton step leaving an error
//!   (‖M‖ / λ_min)|ω|² below `EXACT_STEP_ERR`: the SVD's rotation to about 1e-12 rad.
//!
//! Every other lane (a point on a constraint, unreachable, rank 1, ill-conditioned, not converged)
//! returns None and is computed by the scalar path (the SVD with its rank-1 tie-break).

use super::f32_lanes::Plan;
#[cfg(target_arch = "x86_64")]
use super::lane_vectors::Avx2F64;
use super::lane_vectors::{dot3, Mk, PortableF64, Simd, L, Q};
use glam::DQuat;

/// Conditioning the exact lanes need: λ_min(H) ≥ EXACT_COND ‖M‖_F, so the rounding of S = RᵀM
/// (about 1e-16 ‖M‖) moves the rotation by at most about 1e-16 / EXACT_COND rad.
const EXACT_COND: f64 = 1e-3;
/// Error (rad) the last Newton step of an exact lane may leave, estimated as (‖M‖ / λ_min)|ω|².
const EXACT_STEP_ERR: f64 = 1e-14;
/// Newton steps before a lane goes to the scalar path (as `polar::ortho`'s 10, plus the steps the
/// exact tolerance takes beyond the fast one).
const MAX_ITER: usize = 12;

/// Which answer the lanes must reproduce.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Exactness {
    /// `PolarMethod::Iterative`'s.
    Fast,
    /// `PolarMethod::Svd`'s.
    Exact,
}

/// A constraint row in f64: p and eₙrₙᵀ row-major (the f64 values the scalar path uses).
#[derive(Clone, Copy)]
pub(super) struct Row64 {
    pub p: [f64; 3],
    pub er: [f64; 9],
    pub k: usize,
}

/// Where the distances come from, and the rows.
pub(super) struct Ctx<'a> {
    pub rows: &'a [Row64],
    pub points: &'a [f32],
    pub dist: Option<&'a [f32]>,
    pub n: usize,
    pub exact: Exactness,
}

/// Solves the group's rotation at points `idx` from `warm`, with the widest f64 lanes this CPU runs
/// for `kernel` (the f32 kernel's choice: AVX2 + FMA, or portable).
pub(super) fn solve4(
    kernel: super::Kernel,
    ctx: &Ctx,
    idx: [usize; 4],
    warm: [DQuat; 4],
) -> [Option<DQuat>; 4] {
    #[cfg(target_arch = "x86_64")]
    if kernel >= super::Kernel::Avx2 && super::Kernel::Avx2.available() {
        // SAFETY: AVX2 and FMA are present (checked just above).
        return unsafe { solve4_avx2(ctx, idx, warm) };
    }
    let _ = kernel;
    solve::<PortableF64>(ctx, idx, warm)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn solve4_avx2(ctx: &Ctx, idx: [usize; 4], warm: [DQuat; 4]) -> [Option<DQuat>; 4] {
    solve::<Avx2F64>(ctx, idx, warm)
}

/// Plan rows in f64.
pub(super) fn rows64(field: &super::Field, plan: &Plan) -> Vec<Row64> {
    plan.members()
        .map(|k| {
            let p = field.constraints[k].p;
            Row64 {
                p: p.to_array(),
                er: field.er[k].transpose().to_cols_array(),
                k,
            }
        })
        .collect()
}

// ---- the kernel --------------------------------------------------------------------------------

/// The lane of each of 4 values.
#[inline(always)]
fn lanes<S: Simd<E = f64>>(a: [f64; 4]) -> L<S> {
    L::from_array(&a)
}

/// Lane l of a mask.
#[inline(always)]
fn lane_set<S: Simd>(m: Mk<S>, l: usize) -> bool {
    m.bits() >> l & 1 != 0
}

#[inline(always)]
fn solve<S: Simd<E = f64>>(ctx: &Ctx, idx: [usize; 4], warm: [DQuat; 4]) -> [Option<DQuat>; 4] {
    const { assert!(S::W == 4) };
    let mut out = [None; 4];
    let zero = L::<S>::splat(0.0);
    let inf = L::<S>::splat(f64::INFINITY);
    // M' = Σₙ eₙrₙᵀ / d²ₙ, as `Field::solve_group` sums it.
    let pt = |c: usize| lanes::<S>(idx.map(|i| ctx.points[3 * i + c] as f64));
    let q = [pt(0), pt(1), pt(2)];
    let mut m = [zero; 9];
    let mut dmin2 = inf;
    for row in ctx.rows {
        let d2 = match ctx.dist {
            None => {
                let d = [
                    q[0] - L::splat(row.p[0]),
                    q[1] - L::splat(row.p[1]),
                    q[2] - L::splat(row.p[2]),
                ];
                dot3(d, d)
            }
            Some(dist) => {
                let v = lanes::<S>(idx.map(|i| dist[row.k * ctx.n + i] as f64));
                v * v
            }
        };
        dmin2 = dmin2.min(d2);
        let w = L::splat(1.0) / d2;
        for (e, &er) in m.iter_mut().zip(&row.er) {
            *e = w.mul_add(L::splat(er), *e);
        }
    }
    // On a constraint (interpolation) or unreachable: the scalar path.
    let usable = dmin2.gt(zero).and(dmin2.lt(inf));
    let m = m.map(|e| e * L::select(usable, dmin2, zero));
    let mut fro2 = zero;
    for e in &m {
        fro2 = e.mul_add(*e, fro2);
    }
    let scale = fro2.sqrt();
    // Lanes still iterating.
    let open = usable.and(fro2.gt(zero)).and(fro2.lt(inf));
    let mut open: [bool; 4] = std::array::from_fn(|l| lane_set(open, l));
    let mut qv = Q::<S> {
        x: lanes(warm.map(|w| w.x)),
        y: lanes(warm.map(|w| w.y)),
        z: lanes(warm.map(|w| w.z)),
        w: lanes(warm.map(|w| w.w)),
    };
    let tol = scale * L::splat(1e-6);
    let (tol2, tol3) = (tol * tol, tol * tol * tol);
    let half = L::splat(0.5);
    for _ in 0..MAX_ITER {
        if !open.iter().any(|&o| o) {
            break;
        }
        // The step's algebra is the f32 kernel's, line for line (written out in both: see
        // lane_vectors.rs for what sharing it costs).
        let r = qv.matrix();
        // S = Rᵀ M: S_ij = Σ_k R_ki M_kj.
        let s: [L<S>; 9] = std::array::from_fn(|ij| {
            let (i, j) = (ij / 3, ij % 3);
            r[i].mul_add(m[j], r[3 + i].mul_add(m[3 + j], r[6 + i] * m[6 + j]))
        });
        let g = [s[7] - s[5], s[2] - s[6], s[3] - s[1]];
        let tr = s[0] + s[4] + s[8];
        let h00 = tr - s[0];
        let h11 = tr - s[4];
        let h22 = tr - s[8];
        let h01 = -(s[1] + s[3]) * half;
        let h02 = -(s[2] + s[6]) * half;
        let h12 = -(s[5] + s[7]) * half;
        let a00 = h11 * h22 - h12 * h12;
        let a11 = h00 * h22 - h02 * h02;
        let a22 = h00 * h11 - h01 * h01;
        let a01 = h02 * h12 - h01 * h22;
        let a02 = h01 * h12 - h02 * h11;
        let a12 = h01 * h02 - h00 * h12;
        let det = h00.mul_add(a00, h01.mul_add(a01, h02 * a02));
        // H positive definite (`polar::positive_definite` with tolerance 1e-6 ‖M‖).
        let newton = h00.gt(tol).and(a22.gt(tol2)).and(det.gt(tol3));
        // Newton: ω = adj(H) g / det H; elsewhere the damped step g / (|tr| + ε).
        let inv = L::splat(1.0) / L::select(newton, det, tr.abs() + scale * L::splat(1e-12));
        let w = [
            L::select(
                newton,
                a00.mul_add(g[0], a01.mul_add(g[1], a02 * g[2])),
                g[0],
            ) * inv,
            L::select(
                newton,
                a01.mul_add(g[0], a11.mul_add(g[1], a12 * g[2])),
                g[1],
            ) * inv,
            L::select(
                newton,
                a02.mul_add(g[0], a12.mul_add(g[1], a22 * g[2])),
                g[2],
            ) * inv,
        ];
        let w2 = dot3(w, w);
        // At most a quarter turn per step (a branch: rarely taken).
        let qt = std::f64::consts::FRAC_PI_2;
        let big = w2.gt(L::splat(qt * qt));
        let hw = if big.bits() != 0 {
            L::select(big, L::splat(0.5 * qt) / w2.sqrt(), half)
        } else {
            half
        };
        // q ← q · (ω/2, 1), normalised.
        let [nx, ny, nz, nw] = qv.times(w.map(|c| c * hw));
        let il = L::splat(1.0)
            / nx.mul_add(nx, ny.mul_add(ny, nz.mul_add(nz, nw * nw)))
                .sqrt();
        let next = Q {
            x: nx * il,
            y: ny * il,
            z: nz * il,
            w: nw * il,
        };
        let (w2, tr, fro2, det, scale) = (w2.arr(), tr.arr(), fro2.arr(), det.arr(), scale.arr());
        for l in 0..4 {
            if !open[l] {
                continue;
            }
            let (nw, w2l, trl, f2) = (lane_set(newton, l), w2[l], tr[l], fro2[l]);
            if !(w2l.is_finite() && trl.is_finite()) {
                open[l] = false;
                continue;
            }
            let accept = || {
                let [x, y, z, w] = next.lane(l);
                Some(DQuat::from_xyzw(x, y, z, w))
            };
            match ctx.exact {
                Exactness::Fast => {
                    if nw && w2l < 1e-8 {
                        open[l] = false;
                        // Numerically rank 1: the twist is chosen by the tie-break (scalar).
                        if trl * trl - f2 >= 1e-6 * f2 {
                            out[l] = accept();
                        }
                        continue;
                    }
                }
                Exactness::Exact => {
                    // λ_min(H) ≥ 4 det H / tr(H)², tr(H) = 2 tr S.
                    let four_det = 4.0 * det[l];
                    let s_trh2 = scale[l] * 4.0 * trl * trl;
                    if nw && w2l < 1e-8 {
                        if four_det < EXACT_COND * s_trh2 {
                            open[l] = false; // ill-conditioned: the SVD
                            continue;
                        }
                        if w2l * s_trh2 < EXACT_STEP_ERR * four_det {
                            open[l] = false;
                            out[l] = accept();
                            continue;
                        }
                    }
                }
            }
            if !nw && w2l < 1e-24 {
                open[l] = false; // a saddle or a rank-deficient optimum
            }
        }
        qv = next;
    }
    out.map(|q| {
        q.filter(|q| q.is_finite())
            .map(crate::reflection::polar::canonical)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat3, DVec3};

    struct Rng(u64);
    impl Rng {
        fn f(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
        fn unit(&mut self) -> DVec3 {
            DVec3::new(self.f(), self.f(), self.f()).normalize()
        }
    }

    fn angle(a: DQuat, b: DQuat) -> f64 {
        let d = a.conjugate() * b;
        2.0 * d.xyz().length().atan2(d.w.abs())
    }

    /// The exact lanes against the f64 SVD on random fields, from near-rank-1 (a point next to a
    /// constraint) to well spread, warm-started far (identity) and near: every accepted lane within
    /// 1e-12 rad of `polar::ortho_svd` (the module's bounds give about 1e-13, the SVD rounds too;
    /// measured 1.1e-13), and at least 80% of the lanes away from the constraints accepted from
    /// the identity (measured 96%; next to a constraint M is nearly rank 1 and the SVD decides).
    #[test]
    fn exact_lanes_match_the_svd_to_1e_12() {
        let mut rng = Rng(0x1234_5678_9abc_def1);
        // Lanes far from every constraint (odd lanes): total, accepted.
        let (mut accepted, mut total, mut worst) = (0, 0, 0.0f64);
        for kernel in [super::super::Kernel::Portable, super::super::Kernel::Avx2] {
            for case in 0..400 {
                let k = 2 + case % 7;
                let rows: Vec<Row64> = (0..k)
                    .map(|n| {
                        let r = rng.unit();
                        let e = DQuat::from_axis_angle(rng.unit(), 2.5 * (rng.f() + 0.5)) * r;
                        let er = DMat3::from_cols(e * r.x, e * r.y, e * r.z);
                        Row64 {
                            p: (rng.unit() * (1.0 + rng.f())).to_array(),
                            er: er.transpose().to_cols_array(),
                            k: n,
                        }
                    })
                    .collect();
                // Points near the first constraint (down to 1e-4 of the spacing) and far.
                let near = 10f64.powf(-4.0 * (rng.f() + 0.5));
                let pts: Vec<f32> = (0..4)
                    .flat_map(|l| {
                        let p = DVec3::from_array(rows[0].p)
                            + rng.unit() * if l % 2 == 0 { near } else { 1.0 };
                        p.as_vec3().to_array()
                    })
                    .collect();
                let ctx = Ctx {
                    rows: &rows,
                    points: &pts,
                    dist: None,
                    n: 4,
                    exact: Exactness::Exact,
                };
                let warm = [DQuat::IDENTITY; 4];
                let got = solve4(kernel, &ctx, [0, 1, 2, 3], warm);
                for (l, g) in got.iter().enumerate() {
                    let q = DVec3::new(
                        pts[3 * l] as f64,
                        pts[3 * l + 1] as f64,
                        pts[3 * l + 2] as f64,
                    );
                    let mut m = DMat3::ZERO;
                    for row in &rows {
                        let d2 = (q - DVec3::from_array(row.p)).length_squared();
                        m += DMat3::from_cols_array(&row.er).transpose() * d2.recip();
                    }
                    let want = crate::reflection::polar::ortho_svd(&m);
                    total += l % 2;
                    if let Some(g) = g {
                        accepted += l % 2;
                        worst = worst.max(angle(*g, want));
                        // From the answer itself, one more solve agrees too.
                        let again = solve4(kernel, &ctx, [0, 1, 2, 3], [*g; 4])[l];
                        if let Some(a) = again {
                            worst = worst.max(angle(a, want));
                        }
                    }
                }
            }
        }
        assert!(worst <= 1e-12, "worst {worst:e} rad");
        assert!(
            accepted * 10 >= total * 8,
            "{accepted} of {total} far lanes accepted"
        );
    }
}
