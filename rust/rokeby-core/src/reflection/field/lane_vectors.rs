//! Lane vectors for the field kernels: one trait, three implementations (AVX-512: 16 × f32,
//! AVX2 + FMA: 8 × f32, portable: 4 × f32 in plain arrays, which compilers keep in one 128-bit
//! register: SSE2 on x86-64, NEON on aarch64). The kernels are written once against
//! [`L`] / [`Mk`] and instantiated inside `#[target_feature]` functions, so the intrinsics inline
//! into code compiled for those features.

// Every unsafe fn here is a `#[target_feature]` kernel: safe to call exactly when the CPU has
// that feature, which the dispatcher checks first; the condition is not repeated on each fn.
#![allow(clippy::missing_safety_doc)]

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

pub(super) trait Simd: Copy {
    const W: usize;
    type V: Copy;
    type M: Copy;
    fn splat(x: f32) -> Self::V;
    /// W values from `a[..W]`.
    fn load(a: &[f32]) -> Self::V;
    /// The lanes, in the first W entries.
    fn store(v: Self::V) -> [f32; 16];
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
        Self::div(Self::splat(1.0), Self::sqrt(a))
    }
    /// W points of an (N, 3) array starting at `a[0]` (3W values) as x, y, z lanes.
    #[inline(always)]
    fn load3(a: &[f32]) -> [Self::V; 3] {
        let a = &a[..3 * Self::W];
        let mut r = [[0.0f32; 16]; 3];
        for l in 0..Self::W {
            r[0][l] = a[3 * l];
            r[1][l] = a[3 * l + 1];
            r[2][l] = a[3 * l + 2];
        }
        [Self::load(&r[0]), Self::load(&r[1]), Self::load(&r[2])]
    }
    /// x, y, z lanes into W points of an (N, 3) array at `o[0]` (3W values).
    #[inline(always)]
    fn store3(o: &mut [f32], v: [Self::V; 3]) {
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

#[derive(Clone, Copy)]
pub(super) struct Portable;

impl Simd for Portable {
    const W: usize = 4;
    type V = [f32; 4];
    type M = [u32; 4];
    #[inline(always)]
    fn splat(x: f32) -> Self::V {
        [x; 4]
    }
    #[inline(always)]
    fn load(a: &[f32]) -> Self::V {
        a[..4].try_into().unwrap()
    }
    #[inline(always)]
    fn store(v: Self::V) -> [f32; 16] {
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
        a.map(f32::sqrt)
    }
    #[inline(always)]
    fn abs(a: Self::V) -> Self::V {
        a.map(f32::abs)
    }
    #[inline(always)]
    fn min(a: Self::V, b: Self::V) -> Self::V {
        std::array::from_fn(|l| if b[l] < a[l] { b[l] } else { a[l] })
    }
    #[inline(always)]
    fn lt(a: Self::V, b: Self::V) -> Self::M {
        std::array::from_fn(|l| 0u32.wrapping_sub((a[l] < b[l]) as u32))
    }
    #[inline(always)]
    fn le(a: Self::V, b: Self::V) -> Self::M {
        std::array::from_fn(|l| 0u32.wrapping_sub((a[l] <= b[l]) as u32))
    }
    #[inline(always)]
    fn eq(a: Self::V, b: Self::V) -> Self::M {
        std::array::from_fn(|l| 0u32.wrapping_sub((a[l] == b[l]) as u32))
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
        std::array::from_fn(|l| f32::from_bits((m[l] & a[l].to_bits()) | (!m[l] & b[l].to_bits())))
    }
    #[inline(always)]
    fn none() -> Self::M {
        [0; 4]
    }
    #[inline(always)]
    fn bits(m: Self::M) -> u32 {
        m.iter()
            .enumerate()
            .fold(0, |b, (l, &x)| b | ((x & 1) << l))
    }
}

// ---- AVX2 + FMA -----------------------------------------------------------------------------
// SAFETY (both x86 implementations): these are only instantiated inside functions compiled with
// the matching `#[target_feature]`, which `Kernel::resolve` only calls on CPUs that have it.

#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx2 {
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

// ---- AVX-512F -------------------------------------------------------------------------------

#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Avx512;

#[cfg(target_arch = "x86_64")]
impl Simd for Avx512 {
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
        L(S::sub(S::splat(0.0), self.0))
    }
}

impl<S: Simd> L<S> {
    #[inline(always)]
    pub fn splat(x: f32) -> Self {
        L(S::splat(x))
    }
    #[inline(always)]
    pub fn from_array(a: &[f32; 16]) -> Self {
        L(S::load(a))
    }
    #[inline(always)]
    pub fn arr(self) -> [f32; 16] {
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
