//! Lane vectors for the field kernels: one trait, three implementations (AVX-512: 16 × f32,
//! AVX2 + FMA: 8 × f32, portable: 8 × f32 in plain arrays). The kernels are written once against
//! [`L`] / [`Mk`] and instantiated inside `#[target_feature]` functions, so the intrinsics inline
//! into code compiled for those features.

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
}

// ---- portable -------------------------------------------------------------------------------

#[derive(Clone, Copy)]
pub(super) struct Portable;

impl Simd for Portable {
    const W: usize = 8;
    type V = [f32; 8];
    type M = [bool; 8];
    #[inline(always)]
    fn splat(x: f32) -> Self::V {
        [x; 8]
    }
    #[inline(always)]
    fn load(a: &[f32]) -> Self::V {
        a[..8].try_into().unwrap()
    }
    #[inline(always)]
    fn store(v: Self::V) -> [f32; 16] {
        let mut r = [0.0; 16];
        r[..8].copy_from_slice(&v);
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
        std::array::from_fn(|l| a[l] < b[l])
    }
    #[inline(always)]
    fn le(a: Self::V, b: Self::V) -> Self::M {
        std::array::from_fn(|l| a[l] <= b[l])
    }
    #[inline(always)]
    fn eq(a: Self::V, b: Self::V) -> Self::M {
        std::array::from_fn(|l| a[l] == b[l])
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
        std::array::from_fn(|l| if m[l] { a[l] } else { b[l] })
    }
    #[inline(always)]
    fn none() -> Self::M {
        [false; 8]
    }
    #[inline(always)]
    fn bits(m: Self::M) -> u32 {
        m.iter()
            .enumerate()
            .fold(0, |b, (l, &x)| b | ((x as u32) << l))
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
