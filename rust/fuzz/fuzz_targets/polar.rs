//! ortho (eq. 5's polar decomposition) of arbitrary 3×3 matrices, both methods: a unit
//! quaternion for every finite matrix, never a panic.
#![no_main]
use glam::{DMat3, DQuat};
use libfuzzer_sys::fuzz_target;
use rokeby_core::reflection::polar::{ortho, rotation_vector, PolarMethod};

fuzz_target!(|data: &[u8]| {
    if data.len() < 72 {
        return;
    }
    let v: Vec<f64> = data.chunks_exact(8).take(9).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
    let m = DMat3::from_cols_array(&[v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]]);
    for method in [PolarMethod::Svd, PolarMethod::Iterative] {
        let mut warm = DQuat::IDENTITY;
        let q = ortho(&m, || None, method, &mut warm);
        if v.iter().all(|x| x.is_finite() && x.abs() < 1e150) {
            assert!((q.length() - 1.0).abs() < 1e-6, "non-unit quaternion {q:?} from {m:?}");
            let rv = rotation_vector(q);
            assert!(rv.is_finite() && rv.length() <= std::f64::consts::PI + 1e-9);
        }
    }
});
