//! Both field kernels on the per-vertex benchmark's scene (317 × 317 points of the curved mirror,
//! K = 8; about 7% of the points next to a constraint go to the f64 lanes with the fast polar
//! method, every point with the exact one): `field_lanes KERNEL fast|exact EVALS` times EVALS
//! evaluations (median) and prints a checksum of the output bits. EVALS = 0 builds the scene only
//! (the baseline to subtract from a callgrind count).

use rokeby_core::reflection::field::{fallback_lanes, Distances, Field, FieldOutput, Kernel};
use rokeby_core::reflection::polar::PolarMethod;
use std::time::Instant;

#[path = "common/field_scene.rs"]
mod field_scene;
use field_scene::{constraints, surface};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let kernel = Kernel::parse(&a[1]).unwrap();
    let polar = if a[2] == "exact" {
        PolarMethod::Svd
    } else {
        PolarMethod::Iterative
    };
    let evals: usize = a[3].parse().unwrap();
    let (pts, _) = surface(317, 317);
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
