//! The field of eq. 5 over lanes of points: structure-of-arrays blocks of W points in f32, W = 16
//! (AVX-512), 8 (AVX2 + FMA) or 4 without target features (the portable path), chosen at run time.
//!
//! Per block: M = Σₙ wₙ eₙrₙᵀ with scale-free weights wₙ = d²_min / d²ₙ ∈ (0, 1] (the nearest
//! constraint weighs 1; ortho is scale-invariant, so this is eq. 3's 1/d² up to a per-point factor,
//! and M stays well inside f32's range for any scene scale the lanes accept), then Newton's method on
//! SO(3) for ortho(M) (as `polar::ortho_iterative`), warm-started per lane from the point W places
//! earlier, with a group-wide early exit. A lane's result is accepted only when its last step was a
//! Newton step with H positive definite and small, and when M is well enough conditioned that f32
//! rounding cannot move the rotation by more than about 1e-6 rad: λ_min(H) ≥ `COND` ‖M‖_F, H having
//! eigenvalues σ₂+σ₃, σ₁+σ₃, σ₁+σ₂ at the optimum, so this bounds δR ≈ δM / λ_min. Every other
//! lane (near a constraint, rank-deficient M, unreachable points, a region border, non-finite or
//! suspicious input) is recomputed in f64: by the f64 lanes of `f64_lanes` in blocks of 4, and by the
//! scalar f64 path where those cannot vouch. The scalar path stays the reference (the oracle of the
//! tests; `ROKEBY_SIMD=scalar` uses it everywhere).

use super::lane_vectors::{dot3, Mk, Portable, Simd, L, Q};
#[cfg(target_arch = "x86_64")]
use super::lane_vectors::{Avx2, Avx512};
use super::{Field, FieldOutput};
use crate::reflection::region::Region;
use glam::{DQuat, DVec3};

/// Which implementation evaluates the field.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Kernel {
    /// The scalar f64 reference, point by point.
    Scalar,
    /// f32 lanes of 4 without target features (SSE2 on x86-64, NEON on aarch64).
    Portable,
    /// f32 lanes of 8 with AVX2 and FMA.
    Avx2,
    /// f32 lanes of 16 with AVX-512F.
    Avx512,
}

impl Kernel {
    pub fn parse(name: &str) -> Option<Self> {
        match name.trim().to_ascii_lowercase().as_str() {
            "scalar" | "reference" => Some(Kernel::Scalar),
            "portable" | "lanes" => Some(Kernel::Portable),
            "avx2" => Some(Kernel::Avx2),
            "avx512" | "avx-512" => Some(Kernel::Avx512),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Kernel::Scalar => "scalar",
            Kernel::Portable => "portable",
            Kernel::Avx2 => "avx2",
            Kernel::Avx512 => "avx512",
        }
    }

    /// Whether this CPU can run the kernel.
    pub fn available(self) -> bool {
        match self {
            Kernel::Scalar | Kernel::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => is_x86_feature_detected!("avx512f"),
            #[cfg(not(target_arch = "x86_64"))]
            Kernel::Avx2 | Kernel::Avx512 => false,
        }
    }

    /// The widest kernel this CPU runs.
    pub fn best() -> Self {
        [Kernel::Avx512, Kernel::Avx2]
            .into_iter()
            .find(|k| k.available())
            .unwrap_or(Kernel::Portable)
    }

    /// `requested`, or the widest available kernel below it when the CPU lacks it (so forcing
    /// `avx512` on an AVX2 machine runs AVX2, never an illegal instruction).
    pub fn resolve(requested: Self) -> Self {
        [
            Kernel::Avx512,
            Kernel::Avx2,
            Kernel::Portable,
            Kernel::Scalar,
        ]
        .into_iter()
        .find(|k| *k <= requested && k.available())
        .unwrap_or(Kernel::Scalar)
    }

    /// The kernel fields use by default: `ROKEBY_SIMD` = scalar | portable | avx2 | avx512 | auto
    /// (unset or unknown: auto, the widest available), resolved against this CPU.
    pub fn from_env() -> Self {
        match std::env::var("ROKEBY_SIMD")
            .ok()
            .as_deref()
            .and_then(Kernel::parse)
        {
            Some(k) => Kernel::resolve(k),
            None => Kernel::best(),
        }
    }
}

/// Conditioning a lane needs to be accepted: λ_min(H) ≥ cond ‖M‖_F (see the module docs), per
/// point for the whole rotation, per pixel for e = R r. Where M is nearly rank 1 (next to a
/// constraint) the uncertain part of R is the twist about that constraint's eₙ ≈ e(q), which
/// leaves e(q) nearly unmoved, so pixels accept a smaller margin. Measured largest differences
/// from the f64 reference on the bench scenes: 3.7e-6 rad (points), 1.5e-6 rad (pixels).
const COND_POINTS: f32 = 0.02;
const COND_PIXELS: f32 = 0.002;
/// Newton steps per block before the remaining lanes go to the scalar path.
const MAX_ITER: usize = 10;
/// Error (rad) the last Newton step may leave, estimated as (‖M‖ / λ_min) |ω|².
const STEP_ERR: f32 = 1e-7;

/// A constraint row as the lanes read it: p and eₙrₙᵀ (row-major), broadcast to every lane.
#[derive(Clone, Copy)]
pub(super) struct Row {
    p: [f32; 3],
    er: [f32; 9],
    /// Index of the constraint (its row of a (K, N) distance array).
    k: usize,
}

/// What the lanes know of a field: one group (all constraints, or those of the one region).
pub(super) struct Plan {
    rows: Vec<Row>,
    /// The group's rotation when it is the same everywhere (one constraint).
    pub(super) constant: Option<[f32; 4]>,
}

impl Plan {
    /// The group's constraints, in the order the scalar path sums them.
    pub(super) fn members(&self) -> impl Iterator<Item = usize> + '_ {
        self.rows.iter().map(|r| r.k)
    }
}

impl Field {
    /// The lanes' view of this field, or None where only the scalar path applies (no group, or
    /// several regions).
    pub(super) fn plan(&self) -> Option<Plan> {
        if self.groups.len() != 1 || self.regions.len() > 1 {
            return None;
        }
        let g = &self.groups[0];
        let constant = g
            .constant
            .map(|q| [q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
        let rows = g
            .members
            .iter()
            .map(|&n| {
                let c = &self.constraints[n];
                let m = self.er[n].transpose().to_cols_array(); // row-major of eₙrₙᵀ
                Row {
                    p: c.p.as_vec3().to_array(),
                    er: m.map(|x| x as f32),
                    k: n,
                }
            })
            .collect();
        Some(Plan { rows, constant })
    }
}

/// What one call computes.
pub(super) enum Job<'a> {
    /// Per pixel: e(q) = R_a(q) r(q), (N, 3).
    Pixels { normals: &'a [f32], eye: [f32; 3] },
    /// Per point, in the given output form (`view`: eq. 7 blends towards r rᵀ at region borders,
    /// which those lanes leave to the scalar path).
    Points {
        output: FieldOutput,
        view: bool,
        /// u of `FieldOutput::ViewBlend` for one Euclidean region with a border.
        ramp: Option<(DVec3, f64, f64)>,
    },
}

pub(super) struct Inputs<'a> {
    pub field: &'a Field,
    pub plan: &'a Plan,
    pub points: &'a [f32],
    pub dist: Option<&'a [f32]>,
    pub n: usize,
    pub job: Job<'a>,
}

/// What a chunk left for the scalar path.
#[derive(Default)]
pub(super) struct Leftover {
    /// Points whose lane was not accepted, in order, with the lane's rotation (a warm start for
    /// the scalar Newton iteration).
    pub points: Vec<(usize, [f32; 4])>,
    /// A lane saw input the checks would refuse (non-finite, zero normal, q = eye, bad distance).
    pub suspect: bool,
}

/// Evaluates points [start, start + out.len() / width) into `out` with `kernel` (not Scalar);
/// returns what the scalar path must redo.
pub(super) fn run(kernel: Kernel, inp: &Inputs, start: usize, out: &mut [f32]) -> Leftover {
    match kernel {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::resolve` only hands out kernels whose features this CPU has.
        Kernel::Avx512 if Kernel::Avx512.available() => unsafe { run_avx512(inp, start, out) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above.
        Kernel::Avx2 | Kernel::Avx512 if Kernel::Avx2.available() => unsafe {
            run_avx2(inp, start, out)
        },
        _ => run_lanes::<Portable>(inp, start, out),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
unsafe fn run_avx512(inp: &Inputs, start: usize, out: &mut [f32]) -> Leftover {
    run_lanes::<Avx512>(inp, start, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn run_avx2(inp: &Inputs, start: usize, out: &mut [f32]) -> Leftover {
    run_lanes::<Avx2>(inp, start, out)
}

// ---- the kernel ----------------------------------------------------------------------------

/// Loads lanes of an (N, 3) array at points base..base + count (padding repeats the last point).
#[inline(always)]
// Gathers three lane arrays from one (N, 3) row index per lane: one subscript, three arrays.
#[allow(clippy::needless_range_loop)]
fn load3<S: Simd<E = f32>>(a: &[f32], base: usize, count: usize) -> [L<S>; 3] {
    if count == S::W {
        return S::load3(&a[3 * base..3 * (base + S::W)]).map(L);
    }
    let mut r = [[0.0f32; 16]; 3];
    for l in 0..S::W {
        let i = base + l.min(count - 1);
        r[0][l] = a[3 * i];
        r[1][l] = a[3 * i + 1];
        r[2][l] = a[3 * i + 2];
    }
    [
        L::from_array(&r[0]),
        L::from_array(&r[1]),
        L::from_array(&r[2]),
    ]
}

/// Stores lanes 0..count of a 3-vector into an (N, 3) block.
#[inline(always)]
fn store3<S: Simd<E = f32>>(o: &mut [f32], v: &[L<S>; 3], count: usize) {
    if count == S::W {
        S::store3(o, [v[0].0, v[1].0, v[2].0]);
        return;
    }
    let (x, y, z) = (v[0].arr(), v[1].arr(), v[2].arr());
    let o = &mut o[..3 * count];
    for l in 0..count {
        o[3 * l] = x[l];
        o[3 * l + 1] = y[l];
        o[3 * l + 2] = z[l];
    }
}

/// Lanes whose values are all finite.
#[inline(always)]
// `x − x` is deliberate: 0 for finite lanes, NaN for ±∞ and NaN (the finiteness test).
#[allow(clippy::eq_op)]
fn finite<S: Simd<E = f32>>(v: &[L<S>]) -> Mk<S> {
    // x − x is 0 for finite x and NaN otherwise.
    let mut acc = L::<S>::splat(0.0);
    for x in v {
        acc = acc + (*x - *x);
    }
    acc.eq(L::splat(0.0))
}

/// Newton's method on SO(3) for ortho(M), M row-major, from `q`; returns the result and the
/// lanes it accepts (see the module docs).
#[inline(always)]
fn ortho_lanes<S: Simd<E = f32>>(m: &[L<S>; 9], mut q: Q<S>, cond_min: f32) -> (Q<S>, Mk<S>) {
    let mut fro2 = L::splat(0.0);
    for e in m {
        fro2 = e.mul_add(*e, fro2);
    }
    let scale = fro2.sqrt();
    let tol = scale * L::splat(1e-5);
    let tol2 = tol * tol;
    let tol3 = tol2 * tol;
    let half = L::splat(0.5);
    let mut done = Mk::<S>::none();
    let mut good = Mk::<S>::none();
    for _ in 0..MAX_ITER {
        // The step's algebra is the f64 kernel's, line for line (written out in both: see
        // lane_vectors.rs for what sharing it costs).
        let r = q.matrix();
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
        let newton = h00.gt(tol).and(a22.gt(tol2)).and(det.gt(tol3));
        // Newton: ω = H⁻¹ g = adj(H) g / det H; elsewhere a damped gradient step g / (|tr| + ε).
        // One division for both.
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
        // λ_min(H) ≥ 4 det H / tr(H)² (the other two eigenvalues' product is at most tr²/4).
        let trh = tr + tr;
        let four_det = L::splat(4.0) * det;
        let s_trh2 = scale * trh * trh;
        let cond = four_det.ge(L::splat(cond_min) * s_trh2);
        // Newton converges quadratically: the step taken now leaves an error of about
        // (‖M‖ / λ_min) |ω|², so a lane is done once that is below `STEP_ERR` (and the step is
        // inside the quadratic regime), usually one step after a warm start.
        let small = newton
            .and(w2.lt(L::splat(1e-4)))
            .and((w2 * s_trh2).lt(L::splat(STEP_ERR) * four_det));
        // A lane's verdict is taken at its first small Newton step.
        good = good.or(done.andnot(small.and(cond)));
        done = done.or(small);
        // At most a quarter turn per step (rare after the first block: a branch, not a division
        // per step).
        let qt = std::f32::consts::FRAC_PI_2;
        let big = w2.gt(L::splat(qt * qt));
        let hw = if big.bits() != 0 {
            L::select(big, L::splat(qt) * w2.rsqrt(), L::splat(1.0)) * half
        } else {
            half
        };
        let w = w.map(|c| c * hw);
        // q ← q · (ω/2, 1), normalised.
        let [nx, ny, nz, nw] = q.times(w);
        let len2 = nx.mul_add(nx, ny.mul_add(ny, nz.mul_add(nz, nw * nw)));
        let il = len2.rsqrt();
        q = Q {
            x: nx * il,
            y: ny * il,
            z: nz * il,
            w: nw * il,
        };
        if done.all() {
            break;
        }
    }
    let ok = good.and(finite(&[q.x, q.y, q.z, q.w]));
    (q, ok)
}

/// The lanes over points [start, start + out.len() / width).
#[inline(always)]
fn run_lanes<S: Simd<E = f32>>(inp: &Inputs, start: usize, out: &mut [f32]) -> Leftover {
    let width = match inp.job {
        Job::Pixels { .. } => 3,
        Job::Points { output, .. } => super::output_width(output),
    };
    let count_all = out.len() / width;
    let mut left = Leftover::default();
    let plan = inp.plan;
    let region = inp.field.regions.first();
    let cond = match inp.job {
        Job::Pixels { .. } => COND_PIXELS,
        Job::Points { .. } => COND_POINTS,
    };
    let zero = L::<S>::splat(0.0);
    let one = L::<S>::splat(1.0);
    let mut warm = Q::<S>::splat([0.0, 0.0, 0.0, 1.0]);
    let mut b = 0;
    while b < count_all {
        let base = start + b;
        let count = S::W.min(count_all - b);
        let lanes = (1u32 << count) - 1;
        let qp = load3::<S>(inp.points, base, count);
        let mut ok = finite(&qp);
        let mut suspect = !ok.bits();
        // The group's rotation.
        let q = if let Some(c) = plan.constant {
            Q::splat(c)
        } else {
            // One pass over the rows: M' = Σₙ eₙrₙᵀ / d²ₙ, then M = d²_min M' (the scale-free
            // weights d²_min / d²ₙ; the lanes accept only 1e-30 < d²_min < 1e30, where 1/d²ₙ and
            // K/d²_min stay inside f32's range).
            let mut dmin2 = L::splat(f32::INFINITY);
            let mut m = [zero; 9];
            for row in plan.rows.iter() {
                let d2 = match inp.dist {
                    None => {
                        let dx = qp[0] - L::splat(row.p[0]);
                        let dy = qp[1] - L::splat(row.p[1]);
                        let dz = qp[2] - L::splat(row.p[2]);
                        dot3([dx, dy, dz], [dx, dy, dz])
                    }
                    Some(d) => {
                        let off = row.k * inp.n + base;
                        let v = if count == S::W {
                            L(S::load(&d[off..off + S::W]))
                        } else {
                            let mut v = [0.0f32; 16];
                            for (l, x) in v.iter_mut().enumerate().take(S::W) {
                                *x = d[off + l.min(count - 1)];
                            }
                            L::from_array(&v)
                        };
                        // NaN or negative: the distance check refuses it.
                        suspect |= !v.ge(zero).bits();
                        v * v
                    }
                };
                dmin2 = dmin2.min(d2);
                let w = one / d2;
                for (e, &er) in m.iter_mut().zip(&row.er) {
                    *e = w.mul_add(L::splat(er), *e);
                }
            }
            // Zero (on a constraint: interpolation), unreachable, or outside the range where
            // f32 weights are exact enough: the scalar path.
            ok = ok
                .and(dmin2.gt(L::splat(1e-30)))
                .and(dmin2.lt(L::splat(1e30)));
            let m = m.map(|e| e * dmin2);
            let (q, good) = ortho_lanes(&m, warm, cond);
            ok = ok.and(good);
            // Warm start: accepted lanes carry on, the others restart from the identity.
            warm = Q {
                x: L::select(ok, q.x, zero),
                y: L::select(ok, q.y, zero),
                z: L::select(ok, q.z, zero),
                w: L::select(ok, q.w, one),
            };
            q
        };
        // Canonical sign, w ≥ 0.
        let neg = q.w.lt(zero);
        let q = Q {
            x: L::select(neg, -q.x, q.x),
            y: L::select(neg, -q.y, q.y),
            z: L::select(neg, -q.z, q.z),
            w: L::select(neg, -q.w, q.w),
        };
        // The region's weight a per point (scalar: one distance or one table lookup).
        let mut a = [1.0f64; 16];
        if let Some(reg) = region {
            for (l, al) in a.iter_mut().enumerate().take(count) {
                let i = base + l;
                let p = &inp.points[3 * i..3 * i + 3];
                *al = reg.at_point(i, DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            }
        }
        let ok_bits = ok.bits();
        match &inp.job {
            Job::Pixels { normals, eye } => {
                let nv = load3::<S>(normals, base, count);
                let n2 = dot3(nv, nv);
                let iv = [
                    qp[0] - L::splat(eye[0]),
                    qp[1] - L::splat(eye[1]),
                    qp[2] - L::splat(eye[2]),
                ];
                let i2 = dot3(iv, iv);
                // Normals too short for f32, or q at the eye: the scalar checks decide.
                let fine = finite(&nv)
                    .and(n2.gt(L::splat(1e-30)))
                    .and(i2.gt(L::splat(1e-30)));
                suspect |= !fine.bits();
                let inl = n2.rsqrt();
                let nv = nv.map(|c| c * inl);
                let iil = i2.rsqrt();
                let iv = iv.map(|c| c * iil);
                let k = dot3(iv, nv);
                let k2 = -(k + k);
                let r = [
                    k2.mul_add(nv[0], iv[0]),
                    k2.mul_add(nv[1], iv[1]),
                    k2.mul_add(nv[2], iv[2]),
                ];
                // |r| = 1 up to rounding (i, n unit); e is normalised once, below.
                let e = q.rotate(r);
                let el = dot3(e, e).rsqrt();
                let e = e.map(|c| c * el);
                let accepted = ok_bits & finite(&e).bits() & fine.bits();
                let blk = &mut out[3 * b..3 * (b + count)];
                let mut need = suspect & lanes;
                if region.is_none() {
                    store3(blk, &e, count);
                    need |= !accepted & lanes;
                } else {
                    // Region: a ≥ 1 takes R r, a ≤ 0 leaves r, the border blends (scalar).
                    let (mut v, ra) = (
                        [e[0].arr(), e[1].arr(), e[2].arr()],
                        [r[0].arr(), r[1].arr(), r[2].arr()],
                    );
                    for l in 0..count {
                        if a[l] < 1.0 {
                            for c in 0..3 {
                                v[c][l] = ra[c][l];
                            }
                        }
                        if a[l] > 0.0 && !(a[l] >= 1.0 && accepted & (1 << l) != 0) {
                            need |= 1 << l;
                        }
                    }
                    store3::<S>(blk, &v.map(|x| L::from_array(&x)), count);
                }
                while need != 0 {
                    let l = need.trailing_zeros() as usize;
                    need &= need - 1;
                    left.points.push((base + l, q.lane(l)));
                }
            }
            Job::Points { output, .. }
                if region.is_none() && *output != FieldOutput::RotationVector =>
            {
                // No region: a = u = 1 everywhere, every lane takes R; one plain copy per point.
                let (qx, qy, qz, qw) = (q.x.arr(), q.y.arr(), q.z.arr(), q.w.arr());
                let blk = &mut out[width * b..width * (b + count)];
                if width == 6 {
                    for (l, o) in blk.chunks_exact_mut(6).enumerate() {
                        o.copy_from_slice(&[qx[l], qy[l], qz[l], qw[l], 1.0, 1.0]);
                    }
                } else {
                    for (l, o) in blk.chunks_exact_mut(4).enumerate() {
                        o.copy_from_slice(&[qx[l], qy[l], qz[l], qw[l]]);
                    }
                }
                let mut need = (!ok_bits | suspect) & lanes;
                while need != 0 {
                    let l = need.trailing_zeros() as usize;
                    need &= need - 1;
                    left.points.push((base + l, [qx[l], qy[l], qz[l], qw[l]]));
                }
            }
            Job::Points { output, view, ramp } => {
                let (qx, qy, qz, qw) = (q.x.arr(), q.y.arr(), q.z.arr(), q.w.arr());
                for l in 0..count {
                    let i = base + l;
                    let w = width;
                    let o = &mut out[w * (b + l)..w * (b + l) + w];
                    let inside = a[l] > 0.0;
                    let quat = if inside {
                        [qx[l], qy[l], qz[l], qw[l]]
                    } else {
                        [0.0, 0.0, 0.0, 1.0]
                    };
                    let mut lane_ok = ok_bits & (1 << l) != 0 || !inside;
                    match output {
                        FieldOutput::ViewBlend => {
                            let av = if inside { a[l].min(1.0) } else { 0.0 };
                            let u = match ramp {
                                Some((c, radius, border)) => {
                                    let p = &inp.points[3 * i..3 * i + 3];
                                    let d = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
                                        .distance(*c);
                                    (radius - d) / border.min(*radius)
                                }
                                None => av,
                            };
                            o.copy_from_slice(&[
                                quat[0], quat[1], quat[2], quat[3], av as f32, u as f32,
                            ]);
                        }
                        FieldOutput::Quaternion => {
                            // Inside the border the blend towards I (or r rᵀ) is scalar.
                            lane_ok &= a[l] >= 1.0 || !inside;
                            o.copy_from_slice(&quat);
                        }
                        FieldOutput::RotationVector => {
                            lane_ok &= a[l] >= 1.0 || !inside;
                            let v = crate::reflection::polar::rotation_vector(DQuat::from_xyzw(
                                quat[0] as f64,
                                quat[1] as f64,
                                quat[2] as f64,
                                quat[3] as f64,
                            ));
                            o.copy_from_slice(&[v.x as f32, v.y as f32, v.z as f32]);
                        }
                    }
                    // A border lane with a view blends towards r rᵀ: scalar.
                    if *view && inside && a[l] < 1.0 {
                        lane_ok = false;
                    }
                    if !lane_ok || suspect & (1 << l) != 0 {
                        left.points.push((i, quat));
                    }
                }
            }
        }
        left.suspect |= suspect & lanes != 0;
        b += count;
    }
    left
}

/// u of `FieldOutput::ViewBlend` for a field with exactly one Euclidean region with a border.
pub(super) fn ramp_of(regions: &[Region]) -> Option<(DVec3, f64, f64)> {
    match regions {
        [Region::Euclidean {
            center,
            radius,
            border,
        }] if *border > 0.0 => Some((*center, *radius, *border)),
        _ => None,
    }
}
