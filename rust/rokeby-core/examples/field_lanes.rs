//! Both field kernels on the per-vertex benchmark's scene (317 × 317 points of the curved mirror,
//! K = 8; about 7% of the points next to a constraint go to the f64 lanes with the fast polar
//! method, every point with the exact one): `field_lanes KERNEL fast|exact EVALS` times EVALS
//! evaluations (median) and prints a checksum of the output bits. EVALS = 0 builds the scene only
//! (the baseline to subtract from a callgrind count).

use glam::{DQuat, DVec3};
use rokeby_core::reflection::field::{fallback_lanes, Distances, Field, FieldOutput, Kernel};
use rokeby_core::reflection::polar::PolarMethod;
use std::time::Instant;

const EYE: [f64; 3] = [0.2, -2.5, 3.0];

fn surface(w: usize, h: usize) -> Vec<f32> {
    let mut p = Vec::with_capacity(3 * w * h);
    for j in 0..h {
        for i in 0..w {
            let x = -1.0 + 2.0 * (i as f64 + 0.5) / w as f64;
            let y = -1.0 + 2.0 * (j as f64 + 0.5) / h as f64;
            let z = 0.3 * (x * x + y * y);
            p.extend([x as f32, y as f32, z as f32]);
        }
    }
    p
}

fn constraints(k: usize) -> Vec<f32> {
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

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let kernel = Kernel::parse(&a[1]).unwrap();
    let polar = if a[2] == "exact" {
        PolarMethod::Svd
    } else {
        PolarMethod::Iterative
    };
    let evals: usize = a[3].parse().unwrap();
    let pts = surface(317, 317);
    let f = Field::new(&constraints(8), vec![])
        .unwrap()
        .with_kernel(kernel);
    let mut times = Vec::new();
    let mut sum = 0xcbf29ce484222325u64;
    let before = fallback_lanes();
    for _ in 0..evals {
        let t = Instant::now();
        let out = f
            .rotation_field_as(
                &pts,
                Distances::Euclidean,
                None,
                polar,
                FieldOutput::ViewBlend,
            )
            .unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e3);
        sum = 0xcbf29ce484222325;
        for x in &out {
            sum = (sum ^ x.to_bits() as u64).wrapping_mul(0x100000001b3);
        }
    }
    if evals > 0 {
        let f64_share = (fallback_lanes() - before) as f64 / (evals * 317 * 317) as f64;
        times.sort_by(|x, y| x.partial_cmp(y).unwrap());
        println!(
            "{} {} median {:.3} ms min {:.3} ms over {evals}; f64 lanes {:.2}%; checksum {sum:016x}",
            f.kernel().name(),
            a[2],
            times[evals / 2],
            times[0],
            100.0 * f64_share
        );
    }
}
