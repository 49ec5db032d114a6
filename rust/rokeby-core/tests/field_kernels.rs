//! The f32 lane kernels (portable, AVX2, AVX-512: whichever this CPU runs) against the scalar f64
//! reference, the test oracle: every output within 1e-5 rad, the same errors for bad input, tails
//! and fallbacks (points on constraints, unreachable points, region borders) included.

use glam::{DQuat, DVec3};
use rokeby_core::reflection::field::{Distances, Field, FieldOutput, Kernel};
use rokeby_core::reflection::polar::PolarMethod;
use rokeby_core::reflection::region::Region;

const TOL: f64 = 1e-5;
const EYE: [f64; 3] = [0.25, -2.5, 3.0]; // exact in f32 (a point can sit on it)

fn lanes() -> Vec<Kernel> {
    // Forcing a kernel the CPU lacks runs the widest one below it; test each distinct one.
    let mut ks: Vec<Kernel> = [Kernel::Portable, Kernel::Avx2, Kernel::Avx512]
        .into_iter()
        .map(Kernel::resolve)
        .collect();
    ks.dedup();
    ks
}

struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A curved mirror z = 0.3 (x² + y²) sampled w × h: positions and normals.
fn surface(w: usize, h: usize) -> (Vec<f32>, Vec<f32>) {
    let (mut p, mut n) = (vec![], vec![]);
    for j in 0..h {
        for i in 0..w {
            let x = -1.0 + 2.0 * (i as f64 + 0.5) / w as f64;
            let y = -1.0 + 2.0 * (j as f64 + 0.5) / h as f64;
            let nm = DVec3::new(-0.6 * x, -0.6 * y, 1.0).normalize();
            p.extend([x as f32, y as f32, (0.3 * (x * x + y * y)) as f32]);
            n.extend([nm.x as f32, nm.y as f32, nm.z as f32]);
        }
    }
    (p, n)
}

/// K constraints on the surface (one of them exactly at surface point `on`), edits up to `max`.
fn constraints(k: usize, seed: u64, max: f64, on: Option<[f32; 3]>) -> Vec<f32> {
    let mut rng = Rng(seed);
    let eye = DVec3::from_array(EYE);
    let mut rows = vec![];
    for c in 0..k {
        let (x, y) = match (c, on) {
            (0, Some(p)) => (p[0] as f64, p[1] as f64),
            _ => (rng.f() * 1.8 - 0.9, rng.f() * 1.8 - 0.9),
        };
        let p = DVec3::new(x, y, (0.3 * (x * x + y * y)) as f32 as f64);
        let n = DVec3::new(-0.6 * x, -0.6 * y, 1.0).normalize();
        let i = (p - eye).normalize();
        let r = i - 2.0 * i.dot(n) * n;
        let axis = DVec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5).normalize();
        let e = DQuat::from_axis_angle(axis, max * rng.f()) * r;
        rows.extend([p.x, p.y, p.z, r.x, r.y, r.z, e.x, e.y, e.z].map(|v| v as f32));
    }
    rows
}

fn dir_angle(a: &[f32], b: &[f32]) -> f64 {
    let a = DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
    let b = DVec3::new(b[0] as f64, b[1] as f64, b[2] as f64);
    a.cross(b).length().atan2(a.dot(b))
}

fn quat_angle(a: &[f32], b: &[f32]) -> f64 {
    let a = DQuat::from_xyzw(a[0] as f64, a[1] as f64, a[2] as f64, a[3] as f64);
    let b = DQuat::from_xyzw(b[0] as f64, b[1] as f64, b[2] as f64, b[3] as f64);
    let d = a.conjugate() * b;
    2.0 * d.xyz().length().atan2(d.w.abs())
}

fn pixels(f: &Field, p: &[f32], n: &[f32], d: Distances, w: usize) -> Vec<f32> {
    f.edited_directions(p, n, EYE, d, PolarMethod::Iterative, w)
        .unwrap()
}

fn reference_pixels(
    rows: &[f32],
    regs: Vec<Region>,
    p: &[f32],
    n: &[f32],
    d: Distances,
    w: usize,
) -> Vec<f32> {
    Field::new(rows, regs)
        .unwrap()
        .with_kernel(Kernel::Scalar)
        .edited_directions(p, n, EYE, d, PolarMethod::Svd, w)
        .unwrap()
}

fn assert_dirs_close(got: &[f32], want: &[f32], what: &str) {
    let worst = got
        .chunks_exact(3)
        .zip(want.chunks_exact(3))
        .map(|(a, b)| dir_angle(a, b))
        .enumerate()
        .fold((0, 0.0), |m, (i, x)| if x > m.1 { (i, x) } else { m });
    assert!(
        worst.1 <= TOL,
        "{what}: pixel {} differs by {:e} rad",
        worst.0,
        worst.1
    );
}

#[test]
fn per_pixel_lanes_match_the_f64_reference() {
    // 67 × 41: rows that are not a multiple of 8 or 16 (tails), K from 2 to 32.
    let (w, h) = (67, 41);
    let (p, n) = surface(w, h);
    for (k, seed, max) in [(2, 1, 0.5), (8, 2, 0.45), (32, 3, 0.3), (8, 4, 2.8)] {
        let rows = constraints(
            k,
            seed,
            max,
            Some([p[3 * 700], p[3 * 700 + 1], p[3 * 700 + 2]]),
        );
        let want = reference_pixels(&rows, vec![], &p, &n, Distances::Euclidean, w);
        for kern in lanes() {
            let f = Field::new(&rows, vec![]).unwrap().with_kernel(kern);
            assert_eq!(f.kernel(), kern);
            let got = pixels(&f, &p, &n, Distances::Euclidean, w);
            assert_dirs_close(&got, &want, &format!("{} K={k} max={max}", kern.name()));
        }
    }
}

#[test]
fn per_pixel_lanes_with_given_distances_regions_and_one_constraint() {
    let (w, h) = (40, 30);
    let (p, n) = surface(w, h);
    let npx = w * h;
    let rows = constraints(6, 7, 0.4, None);
    // Given distances: Euclidean ×1.3 with every third pixel unreachable from constraint 2.
    let mut d = vec![0f32; 6 * npx];
    for c in 0..6 {
        for i in 0..npx {
            let q = DVec3::new(p[3 * i] as f64, p[3 * i + 1] as f64, p[3 * i + 2] as f64);
            let pc = DVec3::new(
                rows[9 * c] as f64,
                rows[9 * c + 1] as f64,
                rows[9 * c + 2] as f64,
            );
            d[c * npx + i] = if c == 2 && i % 3 == 0 {
                f32::INFINITY
            } else {
                (1.3 * q.distance(pc)) as f32
            };
        }
    }
    let region = || vec![Region::euclidean([0.1, 0.0, 0.0], 0.7, 0.3, "regions[0]").unwrap()];
    let cases: Vec<(&str, Vec<f32>, Vec<Region>, bool)> = vec![
        ("given", rows.clone(), vec![], true),
        ("region", rows.clone(), region(), false),
        ("given+region", rows.clone(), region(), true),
        (
            "one constraint",
            constraints(1, 9, 0.6, None),
            vec![],
            false,
        ),
    ];
    for (what, rows, regs, given) in cases {
        let dist = if given {
            Distances::Given(&d)
        } else {
            Distances::Euclidean
        };
        let want = reference_pixels(&rows, regs.clone(), &p, &n, dist, w);
        for kern in lanes() {
            let f = Field::new(&rows, regs.clone()).unwrap().with_kernel(kern);
            assert_dirs_close(
                &pixels(&f, &p, &n, dist, w),
                &want,
                &format!("{} {what}", kern.name()),
            );
        }
    }
}

#[test]
fn per_point_lanes_match_the_f64_reference_in_every_output_form() {
    let (pts, _) = surface(53, 37);
    let rows = constraints(
        8,
        11,
        0.5,
        Some([pts[3 * 99], pts[3 * 99 + 1], pts[3 * 99 + 2]]),
    );
    let regions = [
        vec![],
        vec![Region::euclidean([0.0, 0.2, 0.1], 0.8, 0.25, "regions[0]").unwrap()],
    ];
    for regs in regions {
        for output in [
            FieldOutput::Quaternion,
            FieldOutput::ViewBlend,
            FieldOutput::RotationVector,
        ] {
            let want = Field::new(&rows, regs.clone())
                .unwrap()
                .with_kernel(Kernel::Scalar)
                .rotation_field_as(&pts, Distances::Euclidean, None, PolarMethod::Svd, output)
                .unwrap();
            for kern in lanes() {
                let got = Field::new(&rows, regs.clone())
                    .unwrap()
                    .with_kernel(kern)
                    .rotation_field_as(
                        &pts,
                        Distances::Euclidean,
                        None,
                        PolarMethod::Iterative,
                        output,
                    )
                    .unwrap();
                let w = rokeby_core::reflection::field::output_width(output);
                for (i, (a, b)) in got.chunks_exact(w).zip(want.chunks_exact(w)).enumerate() {
                    let (err, what) = match output {
                        FieldOutput::RotationVector => (
                            (DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64)
                                - DVec3::new(b[0] as f64, b[1] as f64, b[2] as f64))
                            .length(),
                            "rotation vector",
                        ),
                        _ => (quat_angle(a, b), "rotation"),
                    };
                    assert!(
                        err <= TOL,
                        "{} {output:?} regions={}: point {i} {what} differs by {err:e}",
                        kern.name(),
                        regs.len()
                    );
                    if output == FieldOutput::ViewBlend {
                        assert!(
                            (a[4] - b[4]).abs() <= 1e-6 && (a[5] - b[5]).abs() <= 1e-6,
                            "a/u at {i}: {a:?} vs {b:?}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn lanes_refuse_bad_input_with_the_reference_errors() {
    let (w, h) = (20, 5);
    let (p, n) = surface(w, h);
    let rows = constraints(4, 5, 0.4, None);
    let msg = |kern: Kernel, p: &[f32], n: &[f32], d: Distances| {
        Field::new(&rows, vec![])
            .unwrap()
            .with_kernel(kern)
            .edited_directions(p, n, EYE, d, PolarMethod::Iterative, w)
            .err()
            .map(|e| e.to_string())
    };
    let mut bad_p = p.clone();
    bad_p[3 * 37 + 1] = f32::NAN;
    bad_p[3 * 80] = f32::INFINITY;
    let mut bad_n = n.clone();
    bad_n[3 * 51..3 * 51 + 3].copy_from_slice(&[0.0; 3]);
    let mut at_eye = p.clone();
    at_eye[3 * 13..3 * 13 + 3].copy_from_slice(&EYE.map(|x| x as f32));
    let mut d = vec![1.0f32; 4 * w * h];
    d[2 * w * h + 17] = -1.0;
    let mut d_nan = vec![1.0f32; 4 * w * h];
    d_nan[w * h + 3] = f32::NAN;
    // The test cases' (positions, normals, distances) triples, written out once.
    #[allow(clippy::type_complexity)]
    let cases: Vec<(Vec<f32>, Vec<f32>, Option<&[f32]>)> = vec![
        (bad_p, n.clone(), None),
        (p.clone(), bad_n, None),
        (at_eye, n.clone(), None),
        (p.clone(), n.clone(), Some(&d)),
        (p.clone(), n.clone(), Some(&d_nan)),
    ];
    for (pp, nn, dd) in cases {
        let dist = dd.map_or(Distances::Euclidean, Distances::Given);
        let want = msg(Kernel::Scalar, &pp, &nn, dist);
        assert!(want.is_some(), "the reference refuses this input");
        for kern in lanes() {
            assert_eq!(msg(kern, &pp, &nn, dist), want, "{}", kern.name());
        }
    }
    // Per point: a NaN point is refused by name, as by the reference.
    let mut bad = p.clone();
    bad[3 * 9 + 2] = f32::NAN;
    for kern in [Kernel::Scalar].into_iter().chain(lanes()) {
        let e = Field::new(&rows, vec![])
            .unwrap()
            .with_kernel(kern)
            .rotation_field_as(
                &bad,
                Distances::Euclidean,
                None,
                PolarMethod::Iterative,
                FieldOutput::ViewBlend,
            )
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("points") && e.contains("row 9"),
            "{}: {e}",
            kern.name()
        );
    }
}

#[test]
fn kernels_resolve_to_what_the_cpu_runs() {
    for name in ["scalar", "portable", "avx2", "avx512", "AVX-512"] {
        let k = Kernel::parse(name).unwrap();
        let r = Kernel::resolve(k);
        assert!(r.available() && r <= k, "{name} -> {r:?}");
    }
    assert_eq!(Kernel::parse("fastest"), None);
    assert!(Kernel::best().available());
    assert_eq!(Kernel::resolve(Kernel::Scalar), Kernel::Scalar);
    assert_eq!(Kernel::resolve(Kernel::Portable), Kernel::Portable);
}

/// The exact polar method by the f64 lanes (Newton's method verified to about 1e-13 rad of the SVD,
/// the SVD where they cannot vouch) against the scalar f64 SVD: the same f64 rotation rounded to
/// f32 twice, so within two f32 roundings: 3e-7 rad for a quaternion or a direction (each unit
/// component rounded by at most 6e-8 relative), and 3e-7 × |v| + 1e-7 for a rotation vector v.
/// Per pixel and per point, with given distances, a region, a point on a constraint, and tails.
#[test]
fn exact_polar_lanes_match_the_scalar_svd() {
    const EXACT_TOL: f64 = 3e-7;
    let (w, h) = (67, 41);
    let (p, n) = surface(w, h);
    let on = Some([p[3 * 700], p[3 * 700 + 1], p[3 * 700 + 2]]);
    let npx = w * h;
    let rows = constraints(8, 21, 0.6, on);
    let d: Vec<f32> = (0..8 * npx)
        .map(|j| {
            let (c, i) = (j / npx, j % npx);
            let q = DVec3::new(p[3 * i] as f64, p[3 * i + 1] as f64, p[3 * i + 2] as f64);
            let pc = DVec3::new(
                rows[9 * c] as f64,
                rows[9 * c + 1] as f64,
                rows[9 * c + 2] as f64,
            );
            (1.2 * q.distance(pc)) as f32
        })
        .collect();
    let region = || vec![Region::euclidean([0.1, 0.0, 0.0], 0.7, 0.3, "regions[0]").unwrap()];
    for (what, regs, given) in [
        ("plain", vec![], false),
        ("given", vec![], true),
        ("region", region(), false),
    ] {
        let dist = if given {
            Distances::Given(&d)
        } else {
            Distances::Euclidean
        };
        let want = reference_pixels(&rows, regs.clone(), &p, &n, dist, w);
        for kern in lanes() {
            let f = Field::new(&rows, regs.clone()).unwrap().with_kernel(kern);
            let got = f
                .edited_directions(&p, &n, EYE, dist, PolarMethod::Svd, w)
                .unwrap();
            for (i, (a, b)) in got.chunks_exact(3).zip(want.chunks_exact(3)).enumerate() {
                let err = dir_angle(a, b);
                assert!(
                    err <= EXACT_TOL,
                    "{} {what}: pixel {i} differs by {err:e}",
                    kern.name()
                );
            }
            for output in [
                FieldOutput::Quaternion,
                FieldOutput::ViewBlend,
                FieldOutput::RotationVector,
            ] {
                let field = |k: Kernel| {
                    Field::new(&rows, regs.clone())
                        .unwrap()
                        .with_kernel(k)
                        .rotation_field_as(&p, dist, None, PolarMethod::Svd, output)
                        .unwrap()
                };
                let (got, want) = (field(kern), field(Kernel::Scalar));
                let wd = rokeby_core::reflection::field::output_width(output);
                for (i, (a, b)) in got.chunks_exact(wd).zip(want.chunks_exact(wd)).enumerate() {
                    let (err, tol) = match output {
                        FieldOutput::RotationVector => {
                            let va = DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
                            let vb = DVec3::new(b[0] as f64, b[1] as f64, b[2] as f64);
                            ((va - vb).length(), EXACT_TOL * vb.length() + 1e-7)
                        }
                        _ => (quat_angle(a, b), EXACT_TOL),
                    };
                    assert!(
                        err <= tol,
                        "{} {what} {output:?}: point {i} differs by {err:e}",
                        kern.name()
                    );
                }
            }
        }
    }
}
