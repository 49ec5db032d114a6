//! mls2d (§5.2–5.3): MLS deformations of arbitrary control points and styles, and
//! sinusoidal noise along arbitrary polylines. Never a panic; accepted control points give finite
//! deformations of finite points; the deformation interpolates (f(p_i) = q_i) and is the
//! identity when q = p; noise keeps the point count and moves points by at most |amplitude|.
#![no_main]
mod common;
use common::Input;
use glam::DVec2;
use libfuzzer_sys::fuzz_target;
use rokeby_core::shadows::mls2d::{sinusoidal_noise, Mls2d, MlsStyle};

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    let style = [MlsStyle::Affine, MlsStyle::Similarity, MlsStyle::Rigid][inp.below(3)];
    let _ = MlsStyle::parse(["affine", "similarity", "rigid", "", "Rigid"][inp.below(5)]);
    let np = inp.below(8);
    let adversarial = inp.byte() % 6 == 0;
    let p: Vec<DVec2> = (0..np).map(|_| if adversarial { inp.v2(10.0) } else { inp.v2_finite(10.0) }).collect();
    let identity = inp.bool();
    let q: Vec<DVec2> = if identity { p.clone() } else { (0..np + if adversarial { inp.below(2) } else { 0 }).map(|_| if adversarial { inp.v2(10.0) } else { inp.v2_finite(10.0) }).collect() };
    let alpha = if adversarial { inp.f64_in(3.0) } else { inp.range(0.5, 2.0) };
    if let Ok(m) = Mls2d::new(p.clone(), q.clone(), style, alpha) {
        let v = inp.v2_finite(20.0);
        let f = m.deform(v);
        assert!(f.is_finite(), "{style:?} alpha {alpha}: deform({v:?}) = {f:?} for {p:?} → {q:?}");
        // Distinct control points (at least 1e-3 apart) are interpolated.
        let distinct = p.iter().enumerate().all(|(i, a)| p.iter().skip(i + 1).all(|b| (*a - *b).length() > 1e-3));
        // Exactness is asserted for the tame inputs: 1e30 control points leave no precision for
        // a query at O(1) (x − p* cancels), which is rounding, not a broken invariant.
        if distinct && !adversarial {
            let scale = 1.0 + q.iter().fold(0.0f64, |s, x| s.max(x.length()));
            for (a, b) in p.iter().zip(&q) {
                let fa = m.deform(*a);
                assert!((fa - *b).length() <= 1e-6 * scale, "{style:?}: f({a:?}) = {fa:?}, expected {b:?}");
            }
        }
        if identity && !adversarial {
            let scale = 1.0 + v.length();
            assert!((f - v).length() <= 1e-6 * scale, "{style:?} at rest moved {v:?} to {f:?}");
        }
        let all = m.deform_all(&[v]);
        assert_eq!(all[0], f);
    }
    let n = inp.below(10);
    let pts: Vec<DVec2> = (0..n).map(|_| if adversarial { inp.v2(5.0) } else { inp.v2_finite(5.0) }).collect();
    let closed = inp.bool();
    let (amp, freq) = if adversarial { (inp.f64_in(2.0), inp.f64_in(50.0)) } else { (inp.finite(2.0), inp.finite(50.0)) };
    if let Ok(out) = sinusoidal_noise(&pts, closed, amp, freq) {
        assert_eq!(out.len(), pts.len());
        for (a, b) in pts.iter().zip(&out) {
            assert!(b.is_finite(), "noise gave {b:?} from {pts:?}, closed {closed}, amplitude {amp}, frequency {freq}");
            // Scaled before the length: offsets near 1e300 would square to inf.
            let s = amp.abs().max(1e-300);
            assert!(((*a - *b) / s).length() <= 1.0 + 1e-9, "noise moved {a:?} to {b:?} (amplitude {amp})");
        }
    }
});
