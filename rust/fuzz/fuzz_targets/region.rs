//! Region constructors and weights (influence, Euclidean, per-point, geodesic, free-form) on
//! arbitrary numbers: errors or weights in [0, 1], never a panic or NaN.
#![no_main]
use glam::DVec3;
use libfuzzer_sys::fuzz_target;
use rokeby_core::reflection::region::{influence, freeform_weights, geodesic_weights, Region};

fuzz_target!(|data: &[u8]| {
    let f: Vec<f32> = data.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    if f.len() < 8 {
        return;
    }
    let (r, b) = (f[0] as f64, f[1] as f64);
    let w = influence(f[2] as f64, r, b);
    if r.is_finite() && b.is_finite() && r >= 0.0 && b >= 0.0 && f[2].is_finite() {
        assert!((0.0..=1.0).contains(&w), "influence {w}");
    }
    if let Ok(reg) = Region::euclidean([f[3] as f64, f[4] as f64, f[5] as f64], r, b, "fuzz") {
        let a = reg.at_point(0, DVec3::new(f[6] as f64, f[7] as f64, 0.0));
        assert!(!a.is_nan() && (0.0..=1.0).contains(&a));
    }
    let half = f.len() / 2;
    if let Ok(ws) = geodesic_weights(&f[..half], r, b) {
        assert!(ws.iter().all(|x| (0.0..=1.0).contains(x)));
    }
    if let Ok(ws) = freeform_weights(&f[..half], &f[half..2 * half], b) {
        assert!(ws.iter().all(|x| (0.0..=1.0).contains(x)));
    }
});
