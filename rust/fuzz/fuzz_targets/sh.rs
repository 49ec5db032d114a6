//! sh (eq. 1): basis/eval of arbitrary normals, and fit of arbitrary normals and values
//! with both methods. Never a panic; finite accepted input gives finite coefficients and
//! residuals; a least-squares fit of values that are exactly an SH function recovers it, and the
//! constrained fit keeps D(n) ≥ D0 (max residual ≤ ~0).
#![no_main]
mod common;
use common::Input;
use libfuzzer_sys::fuzz_target;
use rokeby_core::compositing::sh::{basis, eval, fit, Fit, SH_COEFFS};

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    let n = [inp.f64_in(2.0), inp.f64_in(2.0), inp.f64_in(2.0)];
    let b = basis(n);
    if n.iter().all(|x| x.is_finite() && x.abs() <= 2.0) {
        assert!(b.iter().all(|x| x.is_finite()), "basis({n:?}) = {b:?}");
    }
    let coeffs: [f64; SH_COEFFS] = std::array::from_fn(|_| inp.finite(3.0));
    let _ = eval(&coeffs, n);

    let count = inp.below(40);
    let channels = inp.below(4);
    let adversarial = inp.bool();
    let (normals, values) = if adversarial {
        (inp.f32s(count * 3, 2.0), inp.f32s(count * channels, 5.0))
    } else {
        let normals = inp.f32s_finite(count * 3, 1.0);
        // Values exactly D(n) of `coeffs` per channel (so LS recovers them when well posed).
        let mut values = Vec::with_capacity(count * channels);
        for i in 0..count {
            let nn = [normals[3 * i] as f64, normals[3 * i + 1] as f64, normals[3 * i + 2] as f64];
            let len = (nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]).sqrt();
            let u = if len > 0.0 { [nn[0] / len, nn[1] / len, nn[2] / len] } else { nn };
            for c in 0..channels {
                values.push((eval(&coeffs, u) * (c + 1) as f64) as f32);
            }
        }
        (normals, values)
    };
    // Odd lengths too: the fit must reject, not index out of bounds.
    let trim = inp.below(2);
    let normals = &normals[..normals.len().saturating_sub(trim)];
    for method in [Fit::LeastSquares, Fit::Constrained] {
        if let Ok(f) = fit(normals, &values, channels, method) {
            assert_eq!(f.coeffs.len(), channels);
            assert_eq!(f.max_residual.len(), channels);
            for c in 0..channels {
                assert!(f.coeffs[c].iter().all(|x| x.is_finite()), "{method:?} coeffs {:?}", f.coeffs[c]);
                assert!(f.rms_residual[c].is_finite() && f.rms_residual[c] >= 0.0);
                assert!(f.max_residual[c].is_finite());
                if method == Fit::Constrained {
                    let scale = values.iter().fold(1.0f64, |m, v| m.max(v.abs() as f64));
                    assert!(f.max_residual[c] <= 1e-3 * scale, "constraint violated: {}", f.max_residual[c]);
                }
            }
        }
    }
});
