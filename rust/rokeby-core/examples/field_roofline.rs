//! The field kernels against this machine's roofline: the f32 FMA peak and the memory
//! bandwidth measured in the same run, then the per-pixel field (`edited_directions`, 1280×960, K =
//! 1 / 8 / 32) and the per-vertex field (`rotation_field`, 100k points, K = 8, the add-on's
//! view-blend output) per kernel, with the largest angle from the scalar f64 reference.
//!
//! `cargo run --release -p rokeby-core --example field_roofline [-- --quick] [-- --json]`
//! `--callgrind K KERNEL [--points] [--small] [--exact]`: one small evaluation only, ten rows of the
//! image (for instruction counts); `--exact`: the exact polar method.

use glam::{DQuat, DVec3};
use rokeby_core::reflection::field::{
    fallback_lanes, scalar_fallback_lanes, Distances, Field, FieldOutput, Kernel,
};
use rokeby_core::reflection::polar::PolarMethod;
use std::time::Instant;

#[path = "common/field_scene.rs"]
mod field_scene;
use field_scene::{constraints, surface, EYE};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// f32 peak without vector FMA (the portable fallback): 12 accumulators of 16 lanes per thread.
fn fma_loop(iters: usize) -> f32 {
    let mut acc = [[1.0f32; 16]; 12];
    let b = [0.999_999f32; 16];
    let c = [1e-7f32; 16];
    for _ in 0..iters {
        for a in acc.iter_mut() {
            for l in 0..16 {
                a[l] = a[l] * b[l] + c[l];
            }
        }
    }
    acc.iter().flatten().sum()
}

// The vector peaks are written with intrinsics: left to the auto-vectoriser, the 12 × 16 array
// above was vectorised across the accumulators with gathers and scatters (1 GFLOP/s on a Zen 4).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
unsafe fn fma_avx512(iters: usize) -> f32 {
    use std::arch::x86_64::*;
    let b = _mm512_set1_ps(0.999_999);
    let c = _mm512_set1_ps(1e-7);
    let mut acc = [_mm512_set1_ps(1.0); 12];
    for _ in 0..iters {
        for a in acc.iter_mut() {
            *a = _mm512_fmadd_ps(*a, b, c);
        }
    }
    let mut s = _mm512_setzero_ps();
    for a in acc {
        s = _mm512_add_ps(s, a);
    }
    _mm512_reduce_add_ps(s)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma_avx2(iters: usize) -> f32 {
    use std::arch::x86_64::*;
    let b = _mm256_set1_ps(0.999_999);
    let c = _mm256_set1_ps(1e-7);
    // 12 accumulators of 8 lanes, twice per iteration: the same 12 × 16 flops as the others.
    let mut acc = [_mm256_set1_ps(1.0); 12];
    for _ in 0..iters {
        for _ in 0..2 {
            for a in acc.iter_mut() {
                *a = _mm256_fmadd_ps(*a, b, c);
            }
        }
    }
    let mut s = _mm256_setzero_ps();
    for a in acc {
        s = _mm256_add_ps(s, a);
    }
    let mut lanes = [0f32; 8];
    _mm256_storeu_ps(lanes.as_mut_ptr(), s);
    lanes.iter().sum()
}

fn fma_any(iters: usize) -> f32 {
    #[cfg(target_arch = "x86_64")]
    {
        if Kernel::Avx512.available() {
            return unsafe { fma_avx512(iters) };
        }
        if Kernel::Avx2.available() {
            return unsafe { fma_avx2(iters) };
        }
    }
    fma_loop(iters)
}

/// GFLOP/s over all threads (2 flops per FMA).
fn peak_gflops(threads: usize) -> f64 {
    let iters = 2_000_000;
    let secs = time(5, || {
        let s: f32 = std::thread::scope(|sc| {
            let hs: Vec<_> = (0..threads).map(|_| sc.spawn(|| fma_any(iters))).collect();
            hs.into_iter().map(|h| h.join().unwrap()).sum()
        });
        std::hint::black_box(s);
    });
    (threads * iters * 12 * 16 * 2) as f64 / secs / 1e9
}

/// Stream triad a = b + s c over 3 × 64 MB, all threads: GB/s (12 bytes per element).
fn triad_gbs(threads: usize) -> f64 {
    let n = 16 << 20;
    let b = vec![1.0f32; n];
    let c = vec![2.0f32; n];
    let mut a = vec![0.0f32; n];
    let chunk = n.div_ceil(threads);
    let secs = time(5, || {
        std::thread::scope(|sc| {
            for ((a, b), c) in a
                .chunks_mut(chunk)
                .zip(b.chunks(chunk))
                .zip(c.chunks(chunk))
            {
                sc.spawn(move || {
                    for ((x, y), z) in a.iter_mut().zip(b).zip(c) {
                        *x = y + 3.0 * z;
                    }
                });
            }
        });
        std::hint::black_box(&a);
    });
    (12 * n) as f64 / secs / 1e9
}

/// Flops per pixel of the lanes' algorithm (the model the roofline shares use): 28 per constraint
/// (distance 8, weight 2, 9 FMAs for M), two Newton steps of about 160 (what a block takes on
/// average after its warm start, counted with callgrind), and 70 for r(q) and R r.
/// A single constraint (a constant rotation) costs only the last part.
fn flops_per_pixel(k: usize) -> f64 {
    if k == 1 {
        70.0
    } else {
        28.0 * k as f64 + 2.0 * 160.0 + 70.0
    }
}

fn angle_between(a: &[f32], b: &[f32]) -> f64 {
    a.chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(x, y)| {
            let x = DVec3::new(x[0] as f64, x[1] as f64, x[2] as f64);
            let y = DVec3::new(y[0] as f64, y[1] as f64, y[2] as f64);
            x.cross(y).length().atan2(x.dot(y))
        })
        .fold(0.0, f64::max)
}

fn quat_angle(a: &[f32], b: &[f32]) -> f64 {
    a.chunks_exact(6)
        .zip(b.chunks_exact(6))
        .map(|(x, y)| {
            let x = DQuat::from_xyzw(x[0] as f64, x[1] as f64, x[2] as f64, x[3] as f64);
            let y = DQuat::from_xyzw(y[0] as f64, y[1] as f64, y[2] as f64, y[3] as f64);
            let d = x.conjugate() * y;
            2.0 * d.xyz().length().atan2(d.w.abs())
        })
        .fold(0.0, f64::max)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--callgrind") {
        let k: usize = args[i + 1].parse().unwrap();
        let kernel = Kernel::parse(&args[i + 2]).unwrap();
        // Ten rows from the middle of the 1280×960 image (the warm start sees the real spacing), or
        // with `--small` the whole 128×96 image (the scene of the first instruction counts).
        let small = args.iter().any(|a| a == "--small");
        let (p, n) = if small {
            surface(128, 96)
        } else {
            let (p, n) = surface(1280, 960);
            let rows = 475 * 1280 * 3..485 * 1280 * 3;
            (p[rows.clone()].to_vec(), n[rows].to_vec())
        };
        let row_len = if small { 128 } else { 1280 };
        let polar = if args.iter().any(|a| a == "--exact") {
            PolarMethod::Svd
        } else {
            PolarMethod::Iterative
        };
        if args.iter().any(|a| a == "--points") {
            // 40 rows of the 317 × 317 vertex grid of the per-vertex benchmark (`--small`: the
            // 128×96 image's points).
            let (grid, _) = surface(317, 317);
            let p = if small {
                &p[..]
            } else {
                &grid[140 * 317 * 3..180 * 317 * 3]
            };
            let f = Field::new(&constraints(k), vec![])
                .unwrap()
                .with_kernel(kernel);
            let out = f
                .rotation_field_as(p, Distances::Euclidean, None, polar, FieldOutput::ViewBlend)
                .unwrap();
            println!("{} {}", f.kernel().name(), out[0]);
            return;
        }
        let f = Field::new(&constraints(k), vec![])
            .unwrap()
            .with_kernel(kernel);
        let out = f
            .edited_directions(&p, &n, EYE, Distances::Euclidean, polar, row_len)
            .unwrap();
        println!("{} {}", f.kernel().name(), out[0]);
        return;
    }
    let quick = args.iter().any(|a| a == "--quick");
    let reps = if quick { 3 } else { 7 };
    let threads = rayon::current_num_threads();
    let peak = peak_gflops(threads);
    let bw = triad_gbs(threads);
    println!("machine: {threads} threads, f32 FMA peak {peak:.0} GFLOP/s, triad {bw:.1} GB/s, best kernel {}",
        Kernel::best().name());
    let kernels: Vec<Kernel> = [
        Kernel::Scalar,
        Kernel::Portable,
        Kernel::Avx2,
        Kernel::Avx512,
    ]
    .into_iter()
    .filter(|k| k.available())
    .collect();
    let (w, h) = if quick { (640, 480) } else { (1280, 960) };
    let (p, n) = surface(w, h);
    let mp = (w * h) as f64 / 1e6;
    println!("\nper-pixel field, {w}x{h}, polar fast (goal at 1280x960 on 2 cores: 250 / 120 / 80 MP/s at K = 1 / 8 / 32; paper GTX 260: 18.5 MP/s at K = 32)");
    println!(
        "{:>4} {:>9} {:>9} {:>11} {:>12} {:>11} {:>10} {:>8}",
        "K", "kernel", "MP/s", "GFLOP/s", "% of peak", "max diff", "f64 lanes", "scalar"
    );
    let mut best_pixels = Vec::new();
    let mut exact_rate = 0.0;
    for k in [1usize, 8, 32] {
        let rows = constraints(k);
        let reference = Field::new(&rows, vec![])
            .unwrap()
            .with_kernel(Kernel::Scalar)
            .edited_directions(&p, &n, EYE, Distances::Euclidean, PolarMethod::Svd, w)
            .unwrap();
        for &kern in &kernels {
            let f = Field::new(&rows, vec![]).unwrap().with_kernel(kern);
            let mut out = Vec::new();
            let r = if kern == Kernel::Scalar {
                reps.min(3)
            } else {
                reps
            };
            let before = (fallback_lanes(), scalar_fallback_lanes());
            let secs = time(r, || {
                out = f
                    .edited_directions(&p, &n, EYE, Distances::Euclidean, PolarMethod::Iterative, w)
                    .unwrap();
            });
            // time() runs r + 1 evaluations.
            let fb = (fallback_lanes() - before.0) as f64 / ((r + 1) * w * h) as f64;
            let sc = (scalar_fallback_lanes() - before.1) as f64 / ((r + 1) * w * h) as f64;
            let rate = mp / secs;
            let gf = rate * 1e6 * flops_per_pixel(k) / 1e9;
            println!(
                "{k:>4} {:>9} {rate:>9.1} {gf:>11.1} {:>11.1}% {:>11.1e} {:>9.2}% {:>7.2}%",
                kern.name(),
                100.0 * gf / peak,
                angle_between(&out, &reference),
                100.0 * fb,
                100.0 * sc
            );
            if kern == Kernel::best() {
                best_pixels.push((k, rate, 100.0 * gf / peak, fb));
            }
        }
        // The exact polar method: f64 lanes of Newton's method, verified, the SVD where they
        // cannot vouch (best kernel); max diff against the scalar SVD.
        if k == 32 {
            let f = Field::new(&rows, vec![]).unwrap();
            let mut out = Vec::new();
            let secs = time(reps.min(3), || {
                out = f
                    .edited_directions(&p, &n, EYE, Distances::Euclidean, PolarMethod::Svd, w)
                    .unwrap();
            });
            println!(
                "{k:>4} {:>9} {:>9.1} {:>11} {:>12} {:>11.1e}   (polar exact, {})",
                "exact",
                mp / secs,
                "",
                "",
                angle_between(&out, &reference),
                f.kernel().name()
            );
            exact_rate = mp / secs;
        }
    }
    let side = if quick { 160 } else { 317 };
    let (pts, _) = surface(side, side);
    let npts = side * side;
    println!("\nper-vertex field, {npts} points, K = 8, view-blend output, polar fast (goal at 100k: <= 1.5 ms on 2 cores, <= 2.5 ms on 1)");
    let rows = constraints(8);
    let reference = Field::new(&rows, vec![])
        .unwrap()
        .with_kernel(Kernel::Scalar)
        .rotation_field_as(
            &pts,
            Distances::Euclidean,
            None,
            PolarMethod::Svd,
            FieldOutput::ViewBlend,
        )
        .unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    println!(
        "{:>9} {:>10} {:>10} {:>11} {:>11} {:>10} {:>8}",
        "kernel", "ms", "ms 1 core", "ns/point", "max diff", "f64 lanes", "scalar"
    );
    let mut best_points = (f64::NAN, f64::NAN, 0.0);
    for &kern in &kernels {
        let f = Field::new(&rows, vec![]).unwrap().with_kernel(kern);
        let mut out = Vec::new();
        let mut run = || {
            out = f
                .rotation_field_as(
                    &pts,
                    Distances::Euclidean,
                    None,
                    PolarMethod::Iterative,
                    FieldOutput::ViewBlend,
                )
                .unwrap();
        };
        let before = (fallback_lanes(), scalar_fallback_lanes());
        let secs = time(reps, &mut run);
        let fb = (fallback_lanes() - before.0) as f64 / ((reps + 1) * npts) as f64;
        let sc = (scalar_fallback_lanes() - before.1) as f64 / ((reps + 1) * npts) as f64;
        let secs1 = one.install(|| time(reps, &mut run));
        println!(
            "{:>9} {:>10.2} {:>10.2} {:>11.1} {:>11.1e} {:>9.2}% {:>7.2}%",
            kern.name(),
            secs * 1e3,
            secs1 * 1e3,
            secs * 1e9 / npts as f64,
            quat_angle(&out, &reference),
            100.0 * fb,
            100.0 * sc
        );
        if kern == Kernel::best() {
            best_points = (secs * 1e3, secs1 * 1e3, fb);
        }
    }
    {
        // The exact polar method, best kernel.
        let f = Field::new(&rows, vec![]).unwrap();
        let mut out = Vec::new();
        let secs = time(reps, || {
            out = f
                .rotation_field_as(
                    &pts,
                    Distances::Euclidean,
                    None,
                    PolarMethod::Svd,
                    FieldOutput::ViewBlend,
                )
                .unwrap();
        });
        println!(
            "{:>9} {:>10.2} {:>10} {:>11.1} {:>11.1e}   (polar exact, {}: {:.2}x the fast time)",
            "exact",
            secs * 1e3,
            "",
            secs * 1e9 / npts as f64,
            quat_angle(&out, &reference),
            f.kernel().name(),
            secs * 1e3 / best_points.0
        );
    }

    // The speed goals with what this run measured (absolute goals are for an idle AVX-512
    // machine; the memory floor is 36 bytes per pixel, 24 read and 12 written, at the triad rate).
    println!(
        "\ngoals, best kernel {}{}:",
        Kernel::best().name(),
        if quick {
            ", --quick: smaller scenes, per-vertex scaled to 100k"
        } else {
            ""
        }
    );
    println!(
        "{:<34} {:>10} {:>10} {:>9} {:>9} {:>10}  met",
        "goal", "measured", "paper", "% peak", "f64 lanes", "mem floor"
    );
    for &(k, rate, share, fb) in &best_pixels {
        let goal = match k {
            1 => 250.0,
            8 => 120.0,
            _ => 80.0,
        };
        let paper = if k == 32 { "18.5 MP/s" } else { "-" };
        println!(
            "{:<34} {:>6.1} MP/s {:>10} {:>8.1}% {:>8.2}% {:>5.0} MP/s  {}",
            format!("per-pixel K = {k}: >= {goal} MP/s"),
            rate,
            paper,
            share,
            100.0 * fb,
            bw * 1e3 / 36.0,
            if rate >= goal {
                "yes".to_string()
            } else {
                format!(
                    "no: missed by {:.1} MP/s ({:.0} % of the goal)",
                    goal - rate,
                    100.0 * (goal - rate) / goal
                )
            }
        );
    }
    if let Some(&(_, fast, _, _)) = best_pixels.iter().find(|b| b.0 == 32) {
        println!(
            "{:<34} {:>6.1} MP/s {:>10} {:>9} {:>9} {:>10}  {}  (exact {:.1}× slower)",
            "exact polar within 2x of fast",
            exact_rate,
            "-",
            "",
            "",
            "",
            if 2.0 * exact_rate >= fast {
                "yes".to_string()
            } else {
                format!(
                    "no: missed by {:.1}× (needs {:.1} MP/s more)",
                    fast / exact_rate / 2.0,
                    fast / 2.0 - exact_rate
                )
            },
            fast / exact_rate
        );
    }
    let per100k = 100_000.0 / npts as f64;
    let (ms2, ms1, fb) = best_points;
    println!(
        "{:<34} {:>8.2} ms {:>10} {:>9} {:>8.2}% {:>10}  {}",
        "per-vertex 100k, K = 8: <= 1.5 ms",
        ms2 * per100k,
        "-",
        "",
        100.0 * fb,
        "",
        if ms2 * per100k <= 1.5 { "yes" } else { "no" }
    );
    println!(
        "{:<34} {:>8.2} ms {:>10} {:>9} {:>9} {:>10}  {}",
        "  on one core: <= 2.5 ms",
        ms1 * per100k,
        "-",
        "",
        "",
        "",
        if ms1 * per100k <= 2.5 { "yes" } else { "no" }
    );
    println!(
        "(green/red handle moves: bench/addon_update.py; recompositing: the compositing section)"
    );
}
