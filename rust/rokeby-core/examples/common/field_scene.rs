//! The field benchmarks' scene, shared by the examples `field_roofline` and `field_lanes`.

use glam::{DQuat, DVec3};

/// A curved mirror z = 0.3 (x² + y²) over [−1, 1]², sampled w × h, seen from `EYE`.
pub const EYE: [f64; 3] = [0.2, -2.5, 3.0];

pub fn surface(w: usize, h: usize) -> (Vec<f32>, Vec<f32>) {
    let mut p = Vec::with_capacity(3 * w * h);
    let mut n = Vec::with_capacity(3 * w * h);
    for j in 0..h {
        for i in 0..w {
            let x = -1.0 + 2.0 * (i as f64 + 0.5) / w as f64;
            let y = -1.0 + 2.0 * (j as f64 + 0.5) / h as f64;
            let z = 0.3 * (x * x + y * y);
            let nm = DVec3::new(-0.6 * x, -0.6 * y, 1.0).normalize();
            p.extend([x as f32, y as f32, z as f32]);
            n.extend([nm.x as f32, nm.y as f32, nm.z as f32]);
        }
    }
    (p, n)
}

/// K constraints at pseudo-random points of the surface, each edited by up to ~25°.
pub fn constraints(k: usize) -> Vec<f32> {
    let mut s = 0x9e3779b97f4a7c15u64;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let eye = DVec3::from_array(EYE);
    let mut rows = Vec::new();
    for _ in 0..k {
        let (x, y) = (rnd() * 1.8 - 0.9, rnd() * 1.8 - 0.9);
        let p = DVec3::new(x, y, 0.3 * (x * x + y * y));
        let n = DVec3::new(-0.6 * x, -0.6 * y, 1.0).normalize();
        let i = (p - eye).normalize();
        let r = i - 2.0 * i.dot(n) * n;
        let axis = DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
        let e = DQuat::from_axis_angle(axis, 0.45 * rnd()) * r;
        rows.extend([p.x, p.y, p.z, r.x, r.y, r.z, e.x, e.y, e.z].map(|v| v as f32));
    }
    rows
}
