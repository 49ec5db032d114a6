//! Local shape editing at the compositing stage (Zubiaga et al. 2016): properties of the SH fits
//! (eq. 1 and the QP of §3.1), the dual-paraboloid reflection map (eq. 2, hole filling) and
//! recompositing (eqs. 3–5).

use glam::DVec3;
use proptest::prelude::*;
use rokeby_core::compositing::recomposite::{self, Buffers, Params, Patch};
use rokeby_core::compositing::reconstruct::{
    self, dir_to_uv, uv_to_dir, ParaboloidMap, ReflectionParams,
};
use rokeby_core::compositing::sh::{self, Fit, SH_COEFFS};

fn fib_sphere(n: usize) -> Vec<[f64; 3]> {
    let g = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            [r * (g * i as f64).cos(), r * (g * i as f64).sin(), z]
        })
        .collect()
}

fn flat(ns: &[[f64; 3]]) -> Vec<f32> {
    ns.iter().flat_map(|n| n.map(|x| x as f32)).collect()
}

/// The normals as the fit sees them: rounded to f32, normalised in f64.
fn as_fit(ns: &[[f64; 3]]) -> Vec<[f64; 3]> {
    ns.iter()
        .map(|n| {
            let v = n.map(|x| x as f32 as f64);
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|x| x / l)
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Eq. 1: data that is exactly an order-2 SH function is recovered by both fits.
    #[test]
    fn sh_fit_recovers_order2(c in prop::array::uniform9(-1.0f64..1.0), hemi in any::<bool>()) {
        let mut ns = fib_sphere(600);
        if hemi {
            // Only the camera-facing hemisphere (what a convex object shows).
            ns.retain(|n| n[2] > 0.0);
        }
        let vals: Vec<f32> = ns.iter().map(|&n| sh::eval(&c, n) as f32).collect();
        for method in [Fit::LeastSquares, Fit::Constrained] {
            let f = sh::fit(&flat(&ns), &vals, 1, method).unwrap();
            for &n in &ns {
                let e = (sh::eval(&f.coeffs[0], n) - sh::eval(&c, n)).abs();
                prop_assert!(e < 1e-5, "{method:?}: error {e} at {n:?}");
            }
            if !hemi {
                for (fk, ck) in f.coeffs[0].iter().zip(&c) {
                    prop_assert!((fk - ck).abs() < 1e-5);
                }
            }
        }
    }

    /// The QP of §3.1: residuals D0 − D(n) are never positive, and it cannot fit better than LS.
    #[test]
    fn qp_residuals_non_negative(c in prop::array::uniform9(-1.0f64..1.0), seed in 0u64..1000, frac in 0.05f64..0.6) {
        let ns = fib_sphere(800);
        let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let mut rnd = || { state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (state >> 11) as f64 / (1u64 << 53) as f64 };
        // Occlusion darkens a random subset; plus noise of both signs.
        let vals: Vec<f32> = ns.iter().flat_map(|&n| {
            let base = sh::eval(&c, n);
            let occ = if rnd() < frac { 0.2 + 0.5 * rnd() } else { 0.0 };
            [(base - occ + 0.01 * (rnd() - 0.5)) as f32, (0.5 * base + 0.02 * (rnd() - 0.5)) as f32]
        }).collect();
        let ls = sh::fit(&flat(&ns), &vals, 2, Fit::LeastSquares).unwrap();
        let qp = sh::fit(&flat(&ns), &vals, 2, Fit::Constrained).unwrap();
        for ch in 0..2 {
            prop_assert!(ls.max_residual[ch] > 0.0, "LS has positive residuals on noisy data");
            prop_assert!(qp.max_residual[ch] <= 1e-9, "QP residual {}", qp.max_residual[ch]);
            prop_assert!(qp.rms_residual[ch] >= ls.rms_residual[ch] - 1e-12);
            // Recomputed independently of the fit's own report, in f64 from the f32 inputs.
            for (i, &n) in as_fit(&ns).iter().enumerate() {
                prop_assert!(vals[2 * i + ch] as f64 - sh::eval(&qp.coeffs[ch], n) <= 1e-9);
            }
        }
    }

    /// The dual-paraboloid parametrisation is a bijection of the sphere.
    #[test]
    fn paraboloid_roundtrip(x in -1.0f64..1.0, y in -1.0f64..1.0, z in -1.0f64..1.0) {
        let d = DVec3::new(x, y, z);
        prop_assume!(d.length() > 1e-3);
        let d = d.normalize();
        let (f, u, v) = dir_to_uv(d);
        prop_assert!(u * u + v * v <= 1.0 + 1e-12);
        let back = uv_to_dir(f, u, v);
        prop_assert!((back - d).length() < 1e-12);
    }
}

/// The QP is optimal, not just feasible: a finite-difference check that no feasible direction
/// decreases the objective (every coefficient nudged ± and made feasible by raising c₀₀).
#[test]
fn qp_is_a_local_minimum() {
    let ns = as_fit(&fib_sphere(400));
    let c = [0.8, 0.1, 0.3, -0.2, 0.05, 0.0, 0.1, -0.05, 0.02];
    let vals: Vec<f32> = ns
        .iter()
        .enumerate()
        .map(|(i, &n)| (sh::eval(&c, n) - if i % 7 == 0 { 0.3 } else { 0.0 }) as f32)
        .collect();
    let qp = sh::fit(&flat(&ns), &vals, 1, Fit::Constrained).unwrap();
    let obj = |co: &[f64; SH_COEFFS]| -> (f64, f64) {
        let mut s = 0.0;
        let mut worst = f64::NEG_INFINITY;
        for (i, &n) in ns.iter().enumerate() {
            let r = vals[i] as f64 - sh::eval(co, n);
            s += r * r;
            worst = worst.max(r);
        }
        (s, worst)
    };
    let (f0, w0) = obj(&qp.coeffs[0]);
    assert!(w0 <= 1e-9);
    for k in 0..SH_COEFFS {
        for sgn in [-1.0, 1.0] {
            let mut co = qp.coeffs[0];
            co[k] += sgn * 1e-3;
            let (_, w) = obj(&co);
            if w > 0.0 {
                co[0] += w / 0.282_094_791_773_878_14;
            }
            let (f, w) = obj(&co);
            assert!(w <= 1e-9);
            assert!(f >= f0 - 1e-9, "coefficient {k} {sgn}: {f} < {f0}");
        }
    }
}

#[test]
fn sh_bad_input_is_an_error() {
    assert!(sh::fit(&[0.0, 0.0, 1.0], &[1.0, 2.0], 1, Fit::LeastSquares).is_err());
    assert!(sh::fit(&[0.0, 0.0, 0.0], &[1.0], 1, Fit::Constrained).is_err());
    assert!(sh::fit(&[0.0, 0.0, 1.0], &[f32::NAN], 1, Fit::Constrained).is_err());
    assert!(sh::fit(&[], &[], 1, Fit::Constrained).is_err());
    // One pixel: still a (regularised) answer that matches it.
    let f = sh::fit(&[0.0, 0.0, 1.0], &[0.7], 1, Fit::Constrained).unwrap();
    assert!((sh::eval(&f.coeffs[0], [0.0, 0.0, 1.0]) - 0.7).abs() < 1e-6);
}

/// A smooth environment with some detail.
fn env(r: DVec3) -> [f64; 3] {
    [
        0.5 + 0.3 * r.x + 0.2 * r.y * r.z,
        0.4 + 0.1 * (3.0 * r.z).sin() + 0.1 * r.x * r.y,
        0.3 + 0.2 * r.y,
    ]
}

/// An orthographic image of a unit sphere: screen-space normals, reflected directions, R0.
fn sphere_image(w: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut normals = vec![0.0f32; w * w * 3];
    let mut mask = vec![0.0f32; w * w];
    let mut vals = vec![0.0f32; w * w * 3];
    for y in 0..w {
        for x in 0..w {
            let px = (x as f64 + 0.5) / w as f64 * 2.0 - 1.0;
            let py = (y as f64 + 0.5) / w as f64 * 2.0 - 1.0;
            let s = px * px + py * py;
            if s >= 1.0 {
                continue;
            }
            let n = DVec3::new(px, py, (1.0 - s).sqrt());
            let p = y * w + x;
            normals[3 * p..3 * p + 3].copy_from_slice(&[n.x as f32, n.y as f32, n.z as f32]);
            mask[p] = 1.0;
            let r = reconstruct::reflect(DVec3::Z, n);
            vals[3 * p..3 * p + 3].copy_from_slice(&env(r).map(|v| v as f32));
        }
    }
    let refl = reconstruct::reflect_dirs(&normals, &[0.0, 0.0, 1.0]).unwrap();
    (normals, refl, vals, mask)
}

/// Eq. 2 reproduces a known environment wherever the sphere's pixels cover it.
#[test]
fn partial_map_reproduces_known_environment() {
    let w = 200;
    let (_n, refl, vals, mask) = sphere_image(w);
    let params = ReflectionParams {
        size: 64,
        ..Default::default()
    };
    let pm = reconstruct::partial(w, w, &refl, &vals, 3, &mask, &[], &params).unwrap();
    assert!(pm.coverage > 0.8, "coverage {}", pm.coverage);
    let s = params.size;
    let mut worst = 0.0f64;
    let mut count = 0;
    for face in 0..2 {
        for i in 0..s {
            for j in 0..s {
                let t = (face * s + i) * s + j;
                if !pm.covered[t] {
                    continue;
                }
                let u = (j as f64 + 0.5) * 2.0 / s as f64 - 1.0;
                let v = (i as f64 + 0.5) * 2.0 / s as f64 - 1.0;
                let d = uv_to_dir(face, u, v);
                // Directions reflected near the silhouette are sampled by stretched polygons.
                if d.z < -0.9 {
                    continue;
                }
                let e = env(d);
                for (c, ec) in e.iter().enumerate() {
                    worst = worst.max((pm.map.data[t * 3 + c] as f64 - ec).abs());
                }
                count += 1;
            }
        }
    }
    assert!(count > 3000, "{count}");
    assert!(worst < 5e-3, "worst error {worst}");
}

/// A self-reflection mask (α_R) removes pixels: their polygons do not contribute.
#[test]
fn masked_pixels_do_not_contribute() {
    let w = 120;
    let (_n, refl, mut vals, mut mask) = sphere_image(w);
    // Left half: wrong values, masked out as occluded.
    for y in 0..w {
        for x in 0..w / 2 {
            let p = y * w + x;
            mask[p] = 0.0;
            vals[3 * p] = 100.0;
        }
    }
    let params = ReflectionParams {
        size: 48,
        ..Default::default()
    };
    let pm = reconstruct::partial(w, w, &refl, &vals, 3, &mask, &[], &params).unwrap();
    assert!(pm.coverage > 0.2);
    assert!(pm.map.data.iter().step_by(3).all(|&v| v < 2.0));
}

/// Hole filling reproduces a harmonic function: Re 1/(z − 2) on the front face (z = u + iv),
/// continued to the back face through the inversion uv/|uv|² (its pole at uv = (½, 0) of the back
/// face lies in the known region). Two holes, one across the equator.
#[test]
fn hole_filling_reproduces_harmonic_function() {
    let s = 128;
    let g = |u: f64, v: f64| {
        let (a, b) = (u - 2.0, v);
        a / (a * a + b * b)
    };
    let value = |face: usize, u: f64, v: f64| {
        if face == 0 {
            g(u, v)
        } else {
            let r2 = u * u + v * v;
            g(u / r2, v / r2)
        }
    };
    let mut map = ParaboloidMap::new(s, 1);
    let mut covered = vec![false; 2 * s * s];
    let in_hole = |face: usize, u: f64, v: f64| {
        let h1 = face == 0 && (u - 0.3).powi(2) + (v - 0.1).powi(2) < 0.35f64.powi(2);
        // Across the equator at direction (1, 0, 0): the same point set on both faces.
        let h2 = (u - 0.95).powi(2) + v * v < 0.25f64.powi(2);
        h1 || h2
    };
    let mut holes = vec![];
    for face in 0..2 {
        for i in 0..s {
            for j in 0..s {
                let u = (j as f64 + 0.5) * 2.0 / s as f64 - 1.0;
                let v = (i as f64 + 0.5) * 2.0 / s as f64 - 1.0;
                if u * u + v * v > 1.0 {
                    continue;
                }
                let t = (face * s + i) * s + j;
                if in_hole(face, u, v) {
                    holes.push((t, value(face, u, v)));
                } else {
                    covered[t] = true;
                    map.data[t] = value(face, u, v) as f32;
                }
            }
        }
    }
    let filled = reconstruct::fill_holes(&mut [&mut map], &covered).unwrap();
    assert_eq!(filled, holes.len());
    let worst = holes
        .iter()
        .map(|&(t, v)| (map.data[t] as f64 - v).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "hole filling: worst error {worst:.2e} over {} texels",
        holes.len()
    );
    // A non-harmonic fill (e.g. constant 0 or the mean) is off by ~0.1 here.
    assert!(worst < 1e-3, "worst {worst}");
    // Nothing known: an error, not a panic.
    let mut m2 = ParaboloidMap::new(16, 1);
    assert!(reconstruct::fill_holes(&mut [&mut m2], &vec![false; 2 * 16 * 16]).is_err());
}

/// The whole reconstruction of a sphere: filled, blurred and looked up, it matches the
/// environment in the directions the sphere shows; an object showing few directions is refused.
#[test]
fn reconstruct_sphere_and_refuse_small_coverage() {
    let w = 160;
    let (_n, refl, vals, mask) = sphere_image(w);
    let params = ReflectionParams {
        size: 64,
        ..Default::default()
    };
    let env_map = reconstruct::reconstruct(w, w, &refl, &vals, 3, &mask, &[], &params).unwrap();
    let mut out = [0.0; 3];
    let mut worst = 0.0f64;
    for d in fib_sphere(2000) {
        let d = DVec3::from(d);
        if d.z < -0.5 {
            continue;
        }
        env_map.map.lookup(d, &mut out);
        let e = env(d);
        for c in 0..3 {
            worst = worst.max((out[c] - e[c]).abs());
        }
    }
    assert!(worst < 0.02, "worst {worst}");
    assert!(out.iter().all(|v| v.is_finite()));
    // A 3×3-pixel patch: its reflections cover a tiny cone.
    let mut small = vec![0.0f32; w * w];
    for y in 78..81 {
        for x in 78..81 {
            small[y * w + x] = 1.0;
        }
    }
    let e = reconstruct::reconstruct(w, w, &refl, &vals, 3, &small, &[], &params).unwrap_err();
    assert!(e.to_string().contains("min_coverage"), "{e}");
}

/// A random recompositing scene's planes: (ids, normals, diffuse, reflection, α_D, α_R, image).
type Scene = (
    Vec<i32>,
    Vec<f32>,
    Vec<f32>,
    Vec<f32>,
    Vec<f32>,
    Vec<f32>,
    Vec<f32>,
);

fn random_scene(w: usize, h: usize, seed: u64) -> Scene {
    let mut state = seed | 1;
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let n = w * h;
    let ids: Vec<i32> = (0..n).map(|_| (rnd() * 3.0) as i32 - 1).collect();
    let normals: Vec<f32> = (0..n)
        .flat_map(|_| {
            let d = DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() + 0.1).normalize();
            [d.x as f32, d.y as f32, d.z as f32]
        })
        .collect();
    let mut v3 =
        |k: usize, s: f64, o: f64| -> Vec<f32> { (0..k).map(|_| (o + s * rnd()) as f32).collect() };
    let diffuse = v3(3 * n, 1.0, -0.05);
    let refl = v3(3 * n, 2.0, 0.0);
    let ad = v3(n, 1.0, 0.0);
    let ar = v3(n, 1.0, 0.0);
    let img = v3(3 * n, 3.0, 0.0);
    (ids, normals, diffuse, refl, ad, ar, img)
}

fn patches() -> Vec<Patch> {
    let mut env = ParaboloidMap::new(16, 3);
    for (k, v) in env.data.iter_mut().enumerate() {
        *v = ((k * 7919) % 97) as f32 / 50.0;
    }
    let sh1 = [[0.9, 0.1, 0.3, -0.2, 0.05, 0.0, 0.1, -0.05, 0.02]; 3];
    vec![
        Patch {
            sh: Some(sh1),
            env: Some(env.clone()),
        },
        Patch {
            sh: None,
            env: Some(env),
        },
    ]
}

/// Eqs. 3–5 with unmodified normals give I back bit for bit — also when ñ is a rescaled copy of n
/// (bitwise different, so the shortcut for identical normals is not taken and the formulas run),
/// for any k_D = k_R = 1, γ and α.
#[test]
fn identity_recompositing_is_exact() {
    let (w, h) = (37, 23);
    let (ids, normals, diffuse, refl, ad, ar, img) = random_scene(w, h, 7);
    let scaled: Vec<f32> = normals.iter().map(|x| 2.0 * x).collect();
    let alpha: Vec<f32> = (0..w * h).map(|i| (i % 5) as f32 / 4.0).collect();
    let col: Vec<f32> = (0..3 * w * h).map(|i| (i % 11) as f32 / 10.0).collect();
    for (edited, gamma, colours) in [
        (&normals, 1.0, false),
        (&scaled, 1.0, false),
        (&scaled, 2.2, true),
    ] {
        let b = Buffers {
            ids: &ids,
            normals: &normals,
            edited,
            view: &[0.0, 0.0, 1.0],
            diffuse: &diffuse,
            reflection: &refl,
            alpha_d: &ad,
            alpha_r: &ar,
            alpha: &alpha,
            image: &img,
            diffuse_color: if colours { &col } else { &[] },
            reflection_color: if colours { &col } else { &[] },
        };
        let (out, st) = recomposite::recomposite(
            &b,
            &patches(),
            &Params {
                gamma,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(st.masked, 0);
        assert!(
            out.iter()
                .zip(&img)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "not bit-exact (gamma {gamma})"
        );
    }
}

/// Edits change only edited pixels of patches; a tiny edit changes little (continuity of eq. 4's
/// v and eq. 3's residual); pixels outside patches never change; NaN inputs are masked.
#[test]
fn recompositing_edits_locally_and_continuously() {
    let (w, h) = (40, 30);
    let (ids, normals, diffuse, refl, ad, ar, img) = random_scene(w, h, 11);
    let mut edited = normals.clone();
    let mut tiny = normals.clone();
    for p in 0..w * h / 2 {
        edited[3 * p] += 0.4;
        tiny[3 * p] += 1e-6;
    }
    let mk = |e: &[f32]| {
        let b = Buffers {
            ids: &ids,
            normals: &normals,
            edited: e,
            view: &[0.0, 0.0, 1.0],
            diffuse: &diffuse,
            reflection: &refl,
            alpha_d: &ad,
            alpha_r: &ar,
            alpha: &[],
            image: &img,
            diffuse_color: &[],
            reflection_color: &[],
        };
        recomposite::recomposite(&b, &patches(), &Params::default())
            .unwrap()
            .0
    };
    let out = mk(&edited);
    let mut changed = 0;
    for p in 0..w * h {
        let same = (0..3).all(|c| out[3 * p + c].to_bits() == img[3 * p + c].to_bits());
        if p >= w * h / 2 || ids[p] < 0 {
            assert!(same, "pixel {p} changed");
        } else if !same {
            changed += 1;
        }
    }
    assert!(changed > w * h / 4, "{changed}");
    let out_tiny = mk(&tiny);
    let worst = out_tiny
        .iter()
        .zip(&img)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "tiny edit moved a pixel by {worst}");
    // NaN shading in one pixel: returned as I, counted.
    let mut d2 = diffuse.clone();
    let p = (0..w * h / 2).find(|&p| ids[p] == 0).unwrap();
    d2[3 * p] = f32::NAN;
    let b = Buffers {
        ids: &ids,
        normals: &normals,
        edited: &edited,
        view: &[0.0, 0.0, 1.0],
        diffuse: &d2,
        reflection: &refl,
        alpha_d: &ad,
        alpha_r: &ar,
        alpha: &[],
        image: &img,
        diffuse_color: &[],
        reflection_color: &[],
    };
    let (o2, st) = recomposite::recomposite(&b, &patches(), &Params::default()).unwrap();
    assert_eq!(st.masked, 1);
    assert_eq!(&o2[3 * p..3 * p + 3], &img[3 * p..3 * p + 3]);
    // Wrong sizes: errors naming the argument.
    let b = Buffers {
        ids: &ids,
        normals: &normals[3..],
        edited: &edited,
        view: &[0.0, 0.0, 1.0],
        diffuse: &diffuse,
        reflection: &refl,
        alpha_d: &ad,
        alpha_r: &ar,
        alpha: &[],
        image: &img,
        diffuse_color: &[],
        reflection_color: &[],
    };
    let e = recomposite::recomposite(&b, &patches(), &Params::default()).unwrap_err();
    assert!(e.to_string().starts_with("normals:"), "{e}");
}
