//! Lane vectors for both field kernels: one trait, [`Simd`], generic over its element type
//! (`Simd::E`), with five implementations:
//! * f32 (the kernel of `f32_lanes`): AVX-512 16 × f32, AVX2 + FMA 8 × f32, and portable 4 × f32
//!   in plain arrays, which compilers keep in one 128-bit register (SSE2 on x86-64, NEON on
//!   aarch64);
//! * f64 (the kernel of `f64_lanes`): AVX2 + FMA 4 × f64 in one 256-bit register, and portable
//!   4 × f64 in plain arrays (two SSE2 registers on x86-64; `mul_add` unfused there).
//!
//! Each kernel is written once against [`L`] (lanes, with the arithmetic operators) and [`Mk`]
//! (lane masks), and instantiated inside `#[target_feature]` functions, so the intrinsics inline
//! into code compiled for those features. What both kernels compute the same way lives here too:
//! unit quaternion lanes [`Q`] (R(q), R v, q · (v, 1)), `cross` and `dot3`. Newton's method on
//! SO(3) itself stays in each kernel: they differ in normalisation (f32: `rsqrt` refined once;
//! f64: √ and a division) and acceptance (f32: block-wide masks; f64: per lane, as the scalar
//! path's tests), and the step shared as one function cost the f32 lanes 1.2% more instructions
//! (callgrind, AVX2 and portable) where inlined in `ortho_lanes` it costs nothing; sharing only
//! the step's algebra (S, g, H, adj H, ω; an `#[inline(always)]` generic function, the tolerances
//! computed once) still cost 0.8% (AVX2) and 1.0% (portable) per evaluation of the field_lanes
//! example, bit-identical output. So that algebra is written out in both kernels, the same lines.

// Every unsafe fn here is a `#[target_feature]` kernel: safe to call exactly when the CPU has
// that feature, which the dispatcher checks first; the condition is not repeated on each fn.
#![allow(clippy::missing_safety_doc)]

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// A lane's element type.
pub(super) trait Elem: Copy + Default {
    /// `x` rounded to this type (constants: exact for the small ones the kernels use, and the
    /// same value as the literal written in this type for the others).
    fn of(x: f64) -> Self;
}

impl Elem for f32 {
    #[inline(always)]
    fn of(x: f64) -> Self {
        x as f32
    }
}

impl Elem for f64 {
    #[inline(always)]
    fn of(x: f64) -> Self {
        x
    }
}

pub(super) trait Simd: Copy {
    /// The element: f32 or f64.
    type E: Elem;
    const W: usize;
    type V: Copy;
    type M: Copy;
    fn splat(x: Self::E) -> Self::V;
    /// W values from `a[..W]`.
    fn load(a: &[Self::E]) -> Self::V;
    /// The lanes, in the first W entries.
    fn store(v: Self::V) -> [Self::E; 16];
    fn add(a: Self::V, b: Self::V) -> Self::V;
    fn sub(a: Self::V, b: Self::V) -> Self::V;
    fn mul(a: Self::V, b: Self::V) -> Self::V;
    fn div(a: Self::V, b: Self::V) -> Self::V;
    /// a · b + c (fused where the target has FMA).
    fn mul_add(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    fn sqrt(a: Self::V) -> Self::V;
    fn abs(a: Self::V) -> Self::V;
    /// b where b < a, else a (NaN in b keeps a).
    fn min(a: Self::V, b: Self::V) -> Self::V;
    fn lt(a: Self::V, b: Self::V) -> Self::M;
    fn le(a: Self::V, b: Self::V) -> Self::M;
    fn eq(a: Self::V, b: Self::V) -> Self::M;
    fn and(a: Self::M, b: Self::M) -> Self::M;
    fn or(a: Self::M, b: Self::M) -> Self::M;
    fn andnot(a: Self::M, b: Self::M) -> Self::M; // !a & b
    fn select(m: Self::M, a: Self::V, b: Self::V) -> Self::V;
    fn none() -> Self::M;
    /// Bit l = lane l.
    fn bits(m: Self::M) -> u32;
    /// 1 / √a to about 1e-7 relative (an estimate refined by one Newton step where the target
    /// has one; exact otherwise). Only for a > 0 and finite.
    #[inline(always)]
    fn rsqrt(a: Self::V) -> Self::V {
        Self::div(Self::splat(Self::E::of(1.0)), Self::sqrt(a))
    }
    /// W points of an (N, 3) array starting at `a[0]` (3W values) as x, y, z lanes.
    #[inline(always)]
    fn load3(a: &[Self::E]) -> [Self::V; 3] {
        let a = &a[..3 * Self::W];
        let mut r = [[Self::E::default(); 16]; 3];
        for l in 0..Self::W {
            r[0][l] = a[3 * l];
            r[1][l] = a[3 * l + 1];
            r[2][l] = a[3 * l + 2];
        }
        [Self::load(&r[0]), Self::load(&r[1]), Self::load(&r[2])]
    }
    /// x, y, z lanes into W points of an (N, 3) array at `o[0]` (3W values).
    #[inline(always)]
    fn store3(o: &mut [Self::E], v: [Self::V; 3]) {
        let o = &mut o[..3 * Self::W];
        let (x, y, z) = (Self::store(v[0]), Self::store(v[1]), Self::store(v[2]));
        for l in 0..Self::W {
            o[3 * l] = x[l];
            o[3 * l + 1] = y[l];
            o[3 * l + 2] = z[l];
        }
    }
}

// ---- portable -------------------------------------------------------------------------------

/// 4 × f32 in plain arrays.
#[derive(Clone, Copy)]
pub(super) struct Portable;

/// 4 × f64 in plain arrays (two SSE2 registers on x86-64).
#[derive(Clone, Copy)]
pub(super) struct PortableF64;

/// The portable implementation for element `$e` with mask lanes `$b` (its bits' width).
macro_rules! portable {
    ($s:ident, $e:ty, $b:ty) => {
        impl Simd for $s {
            type E = $e;
            const W: usize = 4;
            type V = [$e; 4];
            type M = [$b; 4];
            #[inline(always)]
            fn splat(x: $e) -> Self::V {
                [x; 4]
            }
            #[inline(always)]
            fn load(a: &[$e]) -> Self::V {
                a[..4].try_into().unwrap()
            }
            #[inline(always)]
            fn store(v: Self::V) -> [$e; 16] {
                let mut r = [0.0; 16];
                r[..4].copy_from_slice(&v);
                r
            }
            #[inline(always)]
            fn add(a: Self::V, b: Self::V) -> Self::V {
                std::array::from_fn(|l| a[l] + b[l])
            }
            #[inline(always)]
            fn sub(a: Self::V, b: Self::V) -> Self::V {
                std::array::from_fn(|l| a[l] - b[l])
            }
            #[inline(always)]
            fn mul(a: Self::V, b: Self::V) -> Self::V {
                std::array::from_fn(|l| a[l] * b[l])
            }
            #[inline(always)]
            fn div(a: Self::V, b: Self::V) -> Self::V {
                std::array::from_fn(|l| a[l] / b[l])
            }
            #[inline(always)]
            fn mul_add(a: Self::V, b: Self::V, c: Self::V) -> Self::V {
                std::array::from_fn(|l| a[l] * b[l] + c[l])
            }
            #[inline(always)]
            fn sqrt(a: Self::V) -> Self::V {
                a.map(<$e>::sqrt)
            }
            #[inline(always)]
            fn abs(a: Self::V) -> Self::V {
                a.map(<$e>::abs)
            }
            #[inline(always)]
            fn min(a: Self::V, b: Self::V) -> Self::V {
                std::array::from_fn(|l| if b[l] < a[l] { b[l] } else { a[l] })
            }
            #[inline(always)]
            fn lt(a: Self::V, b: Self::V) -> Self::M {
                std::array::from_fn(|l| <$b>::wrapping_sub(0, (a[l] < b[l]) as $b))
            }
            #[inline(always)]
            fn le(a: Self::V, b: Self::V) -> Self::M {
                std::array::from_fn(|l| <$b>::wrapping_sub(0, (a[l] <= b[l]) as $b))
            }
            #[inline(always)]
            fn eq(a: Self::V, b: Self::V) -> Self::M {
                std::array::from_fn(|l| <$b>::wrapping_sub(0, (a[l] == b[l]) as $b))
            }
            #[inline(always)]
            fn and(a: Self::M, b: Self::M) -> Self::M {
                std::array::from_fn(|l| a[l] & b[l])
            }
            #[inline(always)]
            fn or(a: Self::M, b: Self::M) -> Self::M {
                std::array::from_fn(|l| a[l] | b[l])
            }
            #[inline(always)]
            fn andnot(a: Self::M, b: Self::M) -> Self::M {
                std::array::from_fn(|l| !a[l] & b[l])
            }
            #[inline(always)]
            fn select(m: Self::M, a: Self::V, b: Self::V) -> Self::V {
                std::array::from_fn(|l| {
                    <$e>::from_bits((m[l] & a[l].to_bits()) | (!m[l] & b[l].to_bits()))
                })
            }
            #[inline(always)]
            fn none() -> Self::M {
                [0; 4]
            }
            #[inline(always)]
            fn bits(m: Self::M) -> u32 {
                m.iter()
                    .enumerate()
                    .fold(0, |b, (l, &x)| b | (((x & 1) as u32) << l))
            }
        }
    };
}
portable!(Portable, f32, u32);
portable!(PortableF64, f64, u64);

// ---- AVX2 + FMA -----------------------------------------------------------------------------
// SAFETY (both x86 implementations): these are only instantiated inside functions compiled with
// the matching `#[target_feature]`, which `Kernel::resolve` only calls on CPUs that have it.

#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx2 {
    type E = f32;
    const W: usize = 8;
    type V = __m256;
    type M = __m256;
    #[inline(always)]
    fn splat(x: f32) -> Self::V {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    fn load(a: &[f32]) -> Self::V {
        assert!(a.len() >= 8);
        unsafe { _mm256_loadu_ps(a.as_ptr()) }
    }
    #[inline(always)]
    fn store(v: Self::V) -> [f32; 16] {
        let mut r = [0.0; 16];
        unsafe { _mm256_storeu_ps(r.as_mut_ptr(), v) };
        r
    }
    #[inline(always)]
    fn add(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_add_ps(a, b) }
    }
    #[inline(always)]
    fn sub(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    fn div(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_div_ps(a, b) }
    }
    #[inline(always)]
    fn mul_add(a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        unsafe { _mm256_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn sqrt(a: Self::V) -> Self::V {
        unsafe { _mm256_sqrt_ps(a) }
    }
    #[inline(always)]
    fn abs(a: Self::V) -> Self::V {
        unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), a) }
    }
    #[inline(always)]
    fn min(a: Self::V, b: Self::V) -> Self::V {
        // minps(b, a) = b < a ? b : a
        unsafe { _mm256_min_ps(b, a) }
    }
    #[inline(always)]
    fn lt(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    fn le(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    fn eq(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(a, b) }
    }
    #[inline(always)]
    fn and(a: Self::M, b: Self::M) -> Self::M {
        unsafe { _mm256_and_ps(a, b) }
    }
    #[inline(always)]
    fn or(a: Self::M, b: Self::M) -> Self::M {
        unsafe { _mm256_or_ps(a, b) }
    }
    #[inline(always)]
    fn andnot(a: Self::M, b: Self::M) -> Self::M {
        unsafe { _mm256_andnot_ps(a, b) }
    }
    #[inline(always)]
    fn select(m: Self::M, a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_blendv_ps(b, a, m) }
    }
    #[inline(always)]
    fn none() -> Self::M {
        unsafe { _mm256_setzero_ps() }
    }
    #[inline(always)]
    fn bits(m: Self::M) -> u32 {
        unsafe { _mm256_movemask_ps(m) as u32 }
    }
    #[inline(always)]
    fn rsqrt(a: Self::V) -> Self::V {
        // y₀ ≈ 1/√a to 12 bits, then y₁ = y₀ (1.5 − 0.5 a y₀²): about 23 bits.
        unsafe {
            let y = _mm256_rsqrt_ps(a);
            let hay = _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(0.5), a), y);
            _mm256_mul_ps(y, _mm256_fnmadd_ps(hay, y, _mm256_set1_ps(1.5)))
        }
    }
    #[inline(always)]
    fn load3(a: &[f32]) -> [Self::V; 3] {
        // Three loads of x0 y0 z0 x1 | x4 y4 z4 x5, y1 z1 x2 y2 | y5 z5 x6 y6,
        // z2 x3 y3 z3 | z6 x7 y7 z7, then five shuffles per 128-bit half.
        let a = &a[..24];
        unsafe {
            let p = a.as_ptr();
            let m03 = _mm256_insertf128_ps::<1>(
                _mm256_castps128_ps256(_mm_loadu_ps(p)),
                _mm_loadu_ps(p.add(12)),
            );
            let m14 = _mm256_insertf128_ps::<1>(
                _mm256_castps128_ps256(_mm_loadu_ps(p.add(4))),
                _mm_loadu_ps(p.add(16)),
            );
            let m25 = _mm256_insertf128_ps::<1>(
                _mm256_castps128_ps256(_mm_loadu_ps(p.add(8))),
                _mm_loadu_ps(p.add(20)),
            );
            let xy = _mm256_shuffle_ps::<0b10_01_11_10>(m14, m25); // x2 y2 x3 y3
            let yz = _mm256_shuffle_ps::<0b01_00_10_01>(m03, m14); // y0 z0 y1 z1
            let x = _mm256_shuffle_ps::<0b10_00_11_00>(m03, xy); // x0 x1 x2 x3
            let y = _mm256_shuffle_ps::<0b11_01_10_00>(yz, xy); // y0 y1 y2 y3
            let z = _mm256_shuffle_ps::<0b11_00_11_01>(yz, m25); // z0 z1 z2 z3
            [x, y, z]
        }
    }
    #[inline(always)]
    fn store3(o: &mut [f32], v: [Self::V; 3]) {
        let o = &mut o[..24];
        let [x, y, z] = v;
        unsafe {
            let rxy = _mm256_shuffle_ps::<0b10_00_10_00>(x, y); // x0 x2 y0 y2
            let ryz = _mm256_shuffle_ps::<0b11_01_11_01>(y, z); // y1 y3 z1 z3
            let rzx = _mm256_shuffle_ps::<0b11_01_10_00>(z, x); // z0 z2 x1 x3
            let r03 = _mm256_shuffle_ps::<0b10_00_10_00>(rxy, rzx); // x0 y0 z0 x1
            let r14 = _mm256_shuffle_ps::<0b11_01_10_00>(ryz, rxy); // y1 z1 x2 y2
            let r25 = _mm256_shuffle_ps::<0b11_01_11_01>(rzx, ryz); // z2 x3 y3 z3
            let p = o.as_mut_ptr();
            _mm256_storeu_ps(p, _mm256_permute2f128_ps::<0x20>(r03, r14));
            _mm256_storeu_ps(p.add(8), _mm256_permute2f128_ps::<0x30>(r25, r03));
            _mm256_storeu_ps(p.add(16), _mm256_permute2f128_ps::<0x31>(r14, r25));
        }
    }
}

/// 4 × f64 in one 256-bit register, AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx2F64;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx2F64 {
    type E = f64;
    const W: usize = 4;
    type V = __m256d;
    type M = __m256d;
    #[inline(always)]
    fn splat(x: f64) -> Self::V {
        unsafe { _mm256_set1_pd(x) }
    }
    #[inline(always)]
    fn load(a: &[f64]) -> Self::V {
        assert!(a.len() >= 4);
        unsafe { _mm256_loadu_pd(a.as_ptr()) }
    }
    #[inline(always)]
    fn store(v: Self::V) -> [f64; 16] {
        let mut r = [0.0; 16];
        unsafe { _mm256_storeu_pd(r.as_mut_ptr(), v) };
        r
    }
    #[inline(always)]
    fn add(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_add_pd(a, b) }
    }
    #[inline(always)]
    fn sub(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_sub_pd(a, b) }
    }
    #[inline(always)]
    fn mul(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_mul_pd(a, b) }
    }
    #[inline(always)]
    fn div(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_div_pd(a, b) }
    }
    #[inline(always)]
    fn mul_add(a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        unsafe { _mm256_fmadd_pd(a, b, c) }
    }
    #[inline(always)]
    fn sqrt(a: Self::V) -> Self::V {
        unsafe { _mm256_sqrt_pd(a) }
    }
    #[inline(always)]
    fn abs(a: Self::V) -> Self::V {
        unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), a) }
    }
    #[inline(always)]
    fn min(a: Self::V, b: Self::V) -> Self::V {
        // minpd(b, a) = b < a ? b : a
        unsafe { _mm256_min_pd(b, a) }
    }
    #[inline(always)]
    fn lt(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm256_cmp_pd::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    fn le(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm256_cmp_pd::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    fn eq(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm256_cmp_pd::<_CMP_EQ_OQ>(a, b) }
    }
    #[inline(always)]
    fn and(a: Self::M, b: Self::M) -> Self::M {
        unsafe { _mm256_and_pd(a, b) }
    }
    #[inline(always)]
    fn or(a: Self::M, b: Self::M) -> Self::M {
        unsafe { _mm256_or_pd(a, b) }
    }
    #[inline(always)]
    fn andnot(a: Self::M, b: Self::M) -> Self::M {
        unsafe { _mm256_andnot_pd(a, b) }
    }
    #[inline(always)]
    fn select(m: Self::M, a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm256_blendv_pd(b, a, m) }
    }
    #[inline(always)]
    fn none() -> Self::M {
        unsafe { _mm256_setzero_pd() }
    }
    #[inline(always)]
    fn bits(m: Self::M) -> u32 {
        unsafe { _mm256_movemask_pd(m) as u32 }
    }
}

// ---- AVX-512F -------------------------------------------------------------------------------

#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx512;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx512 {
    type E = f32;
    const W: usize = 16;
    type V = __m512;
    type M = __mmask16;
    #[inline(always)]
    fn splat(x: f32) -> Self::V {
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    fn load(a: &[f32]) -> Self::V {
        assert!(a.len() >= 16);
        unsafe { _mm512_loadu_ps(a.as_ptr()) }
    }
    #[inline(always)]
    fn store(v: Self::V) -> [f32; 16] {
        let mut r = [0.0; 16];
        unsafe { _mm512_storeu_ps(r.as_mut_ptr(), v) };
        r
    }
    #[inline(always)]
    fn add(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm512_add_ps(a, b) }
    }
    #[inline(always)]
    fn sub(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    fn div(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm512_div_ps(a, b) }
    }
    #[inline(always)]
    fn mul_add(a: Self::V, b: Self::V, c: Self::V) -> Self::V {
        unsafe { _mm512_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    fn sqrt(a: Self::V) -> Self::V {
        unsafe { _mm512_sqrt_ps(a) }
    }
    #[inline(always)]
    fn abs(a: Self::V) -> Self::V {
        unsafe { _mm512_abs_ps(a) }
    }
    #[inline(always)]
    fn min(a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm512_min_ps(b, a) }
    }
    #[inline(always)]
    fn lt(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    fn le(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm512_cmp_ps_mask::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    fn eq(a: Self::V, b: Self::V) -> Self::M {
        unsafe { _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(a, b) }
    }
    #[inline(always)]
    fn and(a: Self::M, b: Self::M) -> Self::M {
        a & b
    }
    #[inline(always)]
    fn or(a: Self::M, b: Self::M) -> Self::M {
        a | b
    }
    #[inline(always)]
    fn andnot(a: Self::M, b: Self::M) -> Self::M {
        !a & b
    }
    #[inline(always)]
    fn select(m: Self::M, a: Self::V, b: Self::V) -> Self::V {
        unsafe { _mm512_mask_blend_ps(m, b, a) }
    }
    #[inline(always)]
    fn none() -> Self::M {
        0
    }
    #[inline(always)]
    fn bits(m: Self::M) -> u32 {
        m as u32
    }
    #[inline(always)]
    fn rsqrt(a: Self::V) -> Self::V {
        // 14-bit estimate, one Newton step: about 24 bits.
        unsafe {
            let y = _mm512_rsqrt14_ps(a);
            let hay = _mm512_mul_ps(_mm512_mul_ps(_mm512_set1_ps(0.5), a), y);
            _mm512_mul_ps(y, _mm512_fnmadd_ps(hay, y, _mm512_set1_ps(1.5)))
        }
    }
}

// ---- operators ------------------------------------------------------------------------------

/// Lanes of f32 for the kernel's arithmetic.
#[derive(Clone, Copy)]
pub(super) struct L<S: Simd>(pub S::V);

/// A lane mask.
#[derive(Clone, Copy)]
pub(super) struct Mk<S: Simd>(pub S::M);

macro_rules! op {
    ($tr:ident, $f:ident) => {
        impl<S: Simd> std::ops::$tr for L<S> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                L(S::$f(self.0, o.0))
            }
        }
    };
}
op!(Add, add);
op!(Sub, sub);
op!(Mul, mul);
op!(Div, div);

impl<S: Simd> std::ops::Neg for L<S> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        L(S::sub(S::splat(S::E::default()), self.0))
    }
}

impl<S: Simd> L<S> {
    #[inline(always)]
    pub fn splat(x: S::E) -> Self {
        L(S::splat(x))
    }
    /// A constant in every lane (rounded to the element type).
    #[inline(always)]
    pub fn constant(x: f64) -> Self {
        L(S::splat(S::E::of(x)))
    }
    /// The first W values of `a`.
    #[inline(always)]
    pub fn from_array(a: &[S::E]) -> Self {
        L(S::load(a))
    }
    #[inline(always)]
    pub fn arr(self) -> [S::E; 16] {
        S::store(self.0)
    }
    #[inline(always)]
    pub fn mul_add(self, b: Self, c: Self) -> Self {
        L(S::mul_add(self.0, b.0, c.0))
    }
    #[inline(always)]
    pub fn sqrt(self) -> Self {
        L(S::sqrt(self.0))
    }
    /// 1 / √self (see `Simd::rsqrt`).
    #[inline(always)]
    pub fn rsqrt(self) -> Self {
        L(S::rsqrt(self.0))
    }
    #[inline(always)]
    pub fn abs(self) -> Self {
        L(S::abs(self.0))
    }
    #[inline(always)]
    pub fn min(self, o: Self) -> Self {
        L(S::min(self.0, o.0))
    }
    #[inline(always)]
    pub fn lt(self, o: Self) -> Mk<S> {
        Mk(S::lt(self.0, o.0))
    }
    #[inline(always)]
    pub fn gt(self, o: Self) -> Mk<S> {
        Mk(S::lt(o.0, self.0))
    }
    #[inline(always)]
    pub fn ge(self, o: Self) -> Mk<S> {
        Mk(S::le(o.0, self.0))
    }
    #[inline(always)]
    pub fn eq(self, o: Self) -> Mk<S> {
        Mk(S::eq(self.0, o.0))
    }
    #[inline(always)]
    pub fn select(m: Mk<S>, a: Self, b: Self) -> Self {
        L(S::select(m.0, a.0, b.0))
    }
}

impl<S: Simd> Mk<S> {
    #[inline(always)]
    pub fn none() -> Self {
        Mk(S::none())
    }
    #[inline(always)]
    pub fn and(self, o: Self) -> Self {
        Mk(S::and(self.0, o.0))
    }
    #[inline(always)]
    pub fn or(self, o: Self) -> Self {
        Mk(S::or(self.0, o.0))
    }
    /// !self & o
    #[inline(always)]
    pub fn andnot(self, o: Self) -> Self {
        Mk(S::andnot(self.0, o.0))
    }
    #[inline(always)]
    pub fn bits(self) -> u32 {
        S::bits(self.0)
    }
    #[inline(always)]
    pub fn all(self) -> bool {
        S::bits(self.0) == (1u32 << S::W) - 1
    }
}

// ---- quaternion lanes and the Newton step, shared by both kernels ---------------------------

/// Unit quaternion lanes (x, y, z, w).
#[derive(Clone, Copy)]
pub(super) struct Q<S: Simd> {
    pub x: L<S>,
    pub y: L<S>,
    pub z: L<S>,
    pub w: L<S>,
}

impl<S: Simd> Q<S> {
    #[inline(always)]
    pub fn splat(q: [S::E; 4]) -> Self {
        Q {
            x: L::splat(q[0]),
            y: L::splat(q[1]),
            z: L::splat(q[2]),
            w: L::splat(q[3]),
        }
    }
    /// Row-major rotation matrix.
    #[inline(always)]
    pub fn matrix(&self) -> [L<S>; 9] {
        let (x, y, z, w) = (self.x, self.y, self.z, self.w);
        let one = L::constant(1.0);
        let two = L::constant(2.0);
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
    /// v rotated: v + 2w (u × v) + 2 u × (u × v).
    #[inline(always)]
    pub fn rotate(&self, v: [L<S>; 3]) -> [L<S>; 3] {
        let u = [self.x, self.y, self.z];
        let t = cross(u, v).map(|c| c + c);
        let ut = cross(u, t);
        [
            self.w.mul_add(t[0], v[0]) + ut[0],
            self.w.mul_add(t[1], v[1]) + ut[1],
            self.w.mul_add(t[2], v[2]) + ut[2],
        ]
    }
    /// q · (v, 1), not normalised (x, y, z, w): the update of a Newton step, v = ω/2.
    #[inline(always)]
    pub fn times(&self, v: [L<S>; 3]) -> [L<S>; 4] {
        let qv = [self.x, self.y, self.z];
        let c = cross(qv, v);
        [
            self.w.mul_add(v[0], self.x) + c[0],
            self.w.mul_add(v[1], self.y) + c[1],
            self.w.mul_add(v[2], self.z) + c[2],
            self.w - dot3(qv, v),
        ]
    }
    /// Lane l as (x, y, z, w).
    #[inline(always)]
    pub fn lane(&self, l: usize) -> [S::E; 4] {
        [
            self.x.arr()[l],
            self.y.arr()[l],
            self.z.arr()[l],
            self.w.arr()[l],
        ]
    }
}

#[inline(always)]
pub(super) fn cross<S: Simd>(a: [L<S>; 3], b: [L<S>; 3]) -> [L<S>; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
pub(super) fn dot3<S: Simd>(a: [L<S>; 3], b: [L<S>; 3]) -> L<S> {
    a[0].mul_add(b[0], a[1].mul_add(b[1], a[2] * b[2]))
}
