//! reconstruct (§3.2): paraboloid (u, v) ↔ direction, map lookups in any direction,
//! reflect_dirs, and the partial map / hole filling / regularisation / full reconstruction of
//! small random patches. Never a panic; finite maps give finite lookups; accepted patches give
//! finite maps with coverage in [0, 1].
#![no_main]
mod common;
use common::Input;
use glam::DVec3;
use libfuzzer_sys::fuzz_target;
use rokeby_core::compositing::reconstruct::{dir_to_uv, fill_beyond_equator, fill_holes, partial, reconstruct, reflect_dirs, regularize, uv_to_dir, ParaboloidMap, ReflectionParams};

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    // (u, v) ↔ direction on both faces.
    let d = inp.v3(2.0);
    if d.is_finite() && d.length() > 1e-6 && d.length() < 1e6 {
        let u = d.normalize();
        let (face, a, b) = dir_to_uv(u);
        assert!(face < 2 && a * a + b * b <= 1.0 + 1e-9, "dir_to_uv({u:?}) = ({face}, {a}, {b})");
        let back = uv_to_dir(face, a, b);
        assert!((back - u).length() < 1e-9, "round trip {u:?} → {back:?}");
    }

    // Lookups in a small map in every direction (non-unit, zero, NaN).
    let size = 1 + inp.below(6);
    let channels = 1 + inp.below(4);
    let mut m = ParaboloidMap::new(size, channels);
    let n = m.data.len();
    m.data = inp.f32s_finite(n, 10.0);
    let mut out = vec![0.0f64; channels];
    m.lookup(d, &mut out);
    assert!(out.iter().all(|x| x.is_finite()), "lookup({d:?}) = {out:?}");
    let lo = m.data.iter().fold(f64::INFINITY, |a, &b| a.min(b as f64));
    let hi = m.data.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b as f64));
    assert!(out.iter().all(|&x| x >= lo - 1e-6 && x <= hi + 1e-6), "bilinear lookup outside the data's range");

    // reflect_dirs: any values, wrong lengths are errors.
    let np = inp.below(8);
    let extra = inp.below(2);
    let normals = inp.f32s(np * 3 + extra, 2.0);
    let view = if inp.bool() { inp.f32s(3, 2.0) } else { inp.f32s(normals.len(), 2.0) };
    if let Ok(r) = reflect_dirs(&normals, &view) {
        assert_eq!(r.len(), normals.len());
        for c in r.chunks_exact(3) {
            let l = ((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) as f64).sqrt();
            assert!(c.iter().all(|x| x.is_nan()) || (l - 1.0).abs() < 1e-4, "reflected {c:?} is neither NaN nor unit");
        }
    }

    // A small image of a patch: reflected directions of a random smooth-ish field.
    let (w, h) = (1 + inp.below(7), 1 + inp.below(7));
    let adversarial = inp.bool();
    let refl: Vec<f32> = if adversarial {
        inp.f32s(w * h * 3, 1.5)
    } else {
        let mut r = Vec::new();
        let (c0, dx, dy) = (inp.v3_finite(1.0), inp.v3_finite(0.5), inp.v3_finite(0.5));
        for y in 0..h {
            for x in 0..w {
                let v = (c0 + dx * x as f64 + dy * y as f64).normalize_or(DVec3::Z);
                r.extend([v.x as f32, v.y as f32, v.z as f32]);
            }
        }
        r
    };
    let channels = 1 + inp.below(3);
    let values = if adversarial { inp.f32s(w * h * channels, 5.0) } else { inp.f32s_finite(w * h * channels, 5.0) };
    let mask: Vec<f32> = (0..w * h).map(|_| if inp.byte() % 4 == 0 { 0.0 } else { 1.0 }).collect();
    let depth = if inp.bool() { Vec::new() } else if adversarial { inp.f32s(w * h, 10.0) } else { (0..w * h).map(|_| inp.range(0.5, 2.0) as f32).collect() };
    let params = ReflectionParams {
        size: if adversarial { inp.below(20) } else { 8 + inp.below(9) },
        max_edge_angle: if adversarial { inp.f64_in(4.0) } else { inp.range(0.05, 3.0) },
        max_depth_jump: if adversarial { inp.f64_in(1.0) } else { inp.range(0.0, 1.0) },
        blur_sigma: if adversarial { inp.f64_in(8.0) } else { inp.range(0.0, 4.0) },
        min_coverage: if adversarial { inp.f64_in(1.0) } else { inp.range(0.0, 0.05) },
    };
    let trim = if adversarial { inp.below(2) } else { 0 };
    let refl = &refl[..refl.len() - trim.min(refl.len())];
    let check = |m: &ParaboloidMap| {
        assert_eq!(m.data.len(), 2 * m.size * m.size * m.channels);
        assert!(m.data.iter().all(|x| x.is_finite()), "non-finite map value from finite input");
    };
    let finite_in = refl.iter().chain(&values).chain(&depth).all(|x| x.is_finite());
    if let Ok(mut p) = partial(w, h, refl, &values, channels, &mask, &depth, &params) {
        assert!((0.0..=1.0 + 1e-9).contains(&p.coverage), "coverage {}", p.coverage);
        assert_eq!(p.covered.len(), 2 * p.map.size * p.map.size);
        if finite_in {
            check(&p.map);
        }
        if fill_holes(&mut [&mut p.map, &mut p.positions], &p.covered).is_ok() && finite_in {
            check(&p.map);
            let sigma = params.blur_sigma;
            regularize(&mut p.map, &p.positions, sigma);
            check(&p.map);
            fill_beyond_equator(&mut p.map);
            check(&p.map);
        }
    }
    if let Ok(env) = reconstruct(w, h, refl, &values, channels, &mask, &depth, &params) {
        assert!((0.0..=1.0 + 1e-9).contains(&env.coverage));
        if finite_in {
            check(&env.map);
        }
    }
});
