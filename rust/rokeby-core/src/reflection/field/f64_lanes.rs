//! The field of eq. 5 over f64 lanes of 4 (AVX2 + FMA: one 256-bit register; elsewhere two SSE2
//! registers): for the points the f32 lanes cannot pin to 1e-5 rad (next to a constraint, where M is
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
    solve::<false>(ctx, idx, warm)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn solve4_avx2(ctx: &Ctx, idx: [usize; 4], warm: [DQuat; 4]) -> [Option<DQuat>; 4] {
    solve::<true>(ctx, idx, warm)
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

// ---- f64 lanes ---------------------------------------------------------------------------------

/// Four f64 lanes; `F`: fused multiply-add (compiled with FMA), else a · b + c.
#[derive(Clone, Copy)]
struct D<const F: bool>([f64; 4]);

macro_rules! op {
    ($tr:ident, $f:ident, $o:tt) => {
        impl<const F: bool> std::ops::$tr for D<F> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                D([
                    self.0[0] $o o.0[0],
                    self.0[1] $o o.0[1],
                    self.0[2] $o o.0[2],
                    self.0[3] $o o.0[3],
                ])
            }
        }
    };
}
op!(Add, add, +);
op!(Sub, sub, -);
op!(Mul, mul, *);
op!(Div, div, /);

impl<const F: bool> std::ops::Neg for D<F> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        D(self.0.map(|x| -x))
    }
}

impl<const F: bool> D<F> {
    #[inline(always)]
    fn splat(x: f64) -> Self {
        D([x; 4])
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        if F {
            D(std::array::from_fn(|l| self.0[l].mul_add(b.0[l], c.0[l])))
        } else {
            self * b + c
        }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        D(self.0.map(f64::sqrt))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        D(self.0.map(f64::abs))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        D(std::array::from_fn(|l| {
            if o.0[l] < self.0[l] {
                o.0[l]
            } else {
                self.0[l]
            }
        }))
    }
    /// Lanes where `m` holds take `a`, the others `b`.
    #[inline(always)]
    fn select(m: [bool; 4], a: Self, b: Self) -> Self {
        D(std::array::from_fn(|l| if m[l] { a.0[l] } else { b.0[l] }))
    }
}

#[inline(always)]
fn cross<const F: bool>(a: [D<F>; 3], b: [D<F>; 3]) -> [D<F>; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
fn dot3<const F: bool>(a: [D<F>; 3], b: [D<F>; 3]) -> D<F> {
    a[0].mul_add(b[0], a[1].mul_add(b[1], a[2] * b[2]))
}

/// Row-major rotation matrix of unit quaternion lanes (x, y, z, w).
#[inline(always)]
fn matrix<const F: bool>(q: [D<F>; 4]) -> [D<F>; 9] {
    let [x, y, z, w] = q;
    let one = D::splat(1.0);
    let two = D::splat(2.0);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (xw, yw, zw) = (x * w, y * w, z * w);
    [
        one - two * (yy + zz),
        two * (xy - zw),
        two * (xz + yw),
        two * (xy + zw),
        one - two * (xx + zz),
        two * (yz - xw),
        two * (xz - yw),
        two * (yz + xw),
        one - two * (xx + yy),
    ]
}

/// q · (v, 1), normalised (the step of `polar::ortho_iterative`, v = ω/2).
#[inline(always)]
fn step<const F: bool>(q: [D<F>; 4], v: [D<F>; 3]) -> [D<F>; 4] {
    let qv = [q[0], q[1], q[2]];
    let c = cross(qv, v);
    let nx = q[3].mul_add(v[0], q[0]) + c[0];
    let ny = q[3].mul_add(v[1], q[1]) + c[1];
    let nz = q[3].mul_add(v[2], q[2]) + c[2];
    let nw = q[3] - dot3(qv, v);
    let len = nx
        .mul_add(nx, ny.mul_add(ny, nz.mul_add(nz, nw * nw)))
        .sqrt();
    let il = D::splat(1.0) / len;
    [nx * il, ny * il, nz * il, nw * il]
}

#[inline(always)]
fn lane<const F: bool>(q: &[D<F>; 4], l: usize) -> DQuat {
    DQuat::from_xyzw(q[0].0[l], q[1].0[l], q[2].0[l], q[3].0[l])
}

#[inline(always)]
fn solve<const F: bool>(ctx: &Ctx, idx: [usize; 4], warm: [DQuat; 4]) -> [Option<DQuat>; 4] {
    let mut out = [None; 4];
    // M' = Σₙ eₙrₙᵀ / d²ₙ, as `Field::solve_group` sums it.
    let pt = |c: usize| D::<F>(idx.map(|i| ctx.points[3 * i + c] as f64));
    let q = [pt(0), pt(1), pt(2)];
    let mut m = [D::<F>::splat(0.0); 9];
    let mut dmin2 = D::<F>::splat(f64::INFINITY);
    for row in ctx.rows {
        let d2 = match ctx.dist {
            None => {
                let d = [
                    q[0] - D::splat(row.p[0]),
                    q[1] - D::splat(row.p[1]),
                    q[2] - D::splat(row.p[2]),
                ];
                dot3(d, d)
            }
            Some(dist) => {
                let v = D(idx.map(|i| dist[row.k * ctx.n + i] as f64));
                v * v
            }
        };
        dmin2 = dmin2.min(d2);
        let w = D::splat(1.0) / d2;
        for (e, &er) in m.iter_mut().zip(&row.er) {
            *e = w.mul_add(D::splat(er), *e);
        }
    }
    // On a constraint (interpolation) or unreachable: the scalar path.
    let usable: [bool; 4] = std::array::from_fn(|l| dmin2.0[l] > 0.0 && dmin2.0[l] < f64::INFINITY);
    let m = m.map(|e| e * D::select(usable, dmin2, D::splat(0.0)));
    let mut fro2 = D::<F>::splat(0.0);
    for e in &m {
        fro2 = e.mul_add(*e, fro2);
    }
    let scale = fro2.sqrt();
    // Lanes still iterating.
    let mut open: [bool; 4] =
        std::array::from_fn(|l| usable[l] && fro2.0[l] > 0.0 && fro2.0[l].is_finite());
    let mut qv = [0, 1, 2, 3].map(|c| D::<F>(warm.map(|w| w.to_array()[c])));
    let half = D::splat(0.5);
    let tol = scale * D::splat(1e-6);
    let (tol2, tol3) = (tol * tol, tol * tol * tol);
    for _ in 0..MAX_ITER {
        if !open.iter().any(|&o| o) {
            break;
        }
        let r = matrix(qv);
        // S = Rᵀ M: S_ij = Σ_k R_ki M_kj.
        let s: [D<F>; 9] = std::array::from_fn(|ij| {
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
        let newton: [bool; 4] = std::array::from_fn(|l| {
            h00.0[l] > tol.0[l] && a22.0[l] > tol2.0[l] && det.0[l] > tol3.0[l]
        });
        // Newton: ω = adj(H) g / det H; elsewhere the damped step g / (|tr| + ε).
        let inv = D::splat(1.0) / D::select(newton, det, tr.abs() + scale * D::splat(1e-12));
        let w = [
            D::select(
                newton,
                a00.mul_add(g[0], a01.mul_add(g[1], a02 * g[2])),
                g[0],
            ) * inv,
            D::select(
                newton,
                a01.mul_add(g[0], a11.mul_add(g[1], a12 * g[2])),
                g[1],
            ) * inv,
            D::select(
                newton,
                a02.mul_add(g[0], a12.mul_add(g[1], a22 * g[2])),
                g[2],
            ) * inv,
        ];
        let w2 = dot3(w, w);
        // At most a quarter turn per step.
        let qt = std::f64::consts::FRAC_PI_2;
        let hw: [f64; 4] = std::array::from_fn(|l| {
            if w2.0[l] > qt * qt {
                0.5 * qt / w2.0[l].sqrt()
            } else {
                0.5
            }
        });
        let next = step(qv, w.map(|c| c * D(hw)));
        for l in 0..4 {
            if !open[l] {
                continue;
            }
            let (nw, w2l, trl, f2) = (newton[l], w2.0[l], tr.0[l], fro2.0[l]);
            if !(w2l.is_finite() && trl.is_finite()) {
                open[l] = false;
                continue;
            }
            match ctx.exact {
                Exactness::Fast => {
                    if nw && w2l < 1e-8 {
                        open[l] = false;
                        // Numerically rank 1: the twist is chosen by the tie-break (scalar).
                        if trl * trl - f2 >= 1e-6 * f2 {
                            out[l] = Some(lane(&next, l));
                        }
                        continue;
                    }
                }
                Exactness::Exact => {
                    // λ_min(H) ≥ 4 det H / tr(H)², tr(H) = 2 tr S.
                    let four_det = 4.0 * det.0[l];
                    let s_trh2 = scale.0[l] * 4.0 * trl * trl;
                    if nw && w2l < 1e-8 {
                        if four_det < EXACT_COND * s_trh2 {
                            open[l] = false; // ill-conditioned: the SVD
                            continue;
                        }
                        if w2l * s_trh2 < EXACT_STEP_ERR * four_det {
                            open[l] = false;
                            out[l] = Some(lane(&next, l));
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
