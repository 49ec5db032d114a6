//! prefilter: lobes of arbitrary parameters, their kernels and radii, and prefiltering,
//! brute force, SH projection and irradiance of small random lat-long maps. Never a panic;
//! kernels are finite and ≥ 0, 0 ≤ core radius ≤ cut radius ≤ π/2; prefiltered levels and the
//! brute-force reference are weighted means (within the map's value range); a constant map's
//! irradiance is that constant.
#![no_main]
mod common;
use common::Input;
use libfuzzer_sys::fuzz_target;
use rokeby_core::envmaps::envmap::{EnvMap, Layout};
use rokeby_core::envmaps::prefilter::{brute_force, brute_force_irradiance, irradiance_map, prefilter, sh_irradiance, sh_project, Lobe, PrefilterParams};

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    let mut lobes = Vec::new();
    for _ in 0..1 + inp.below(3) {
        let p = if inp.bool() { inp.f64_in(50.0) } else { inp.f64_in(1.0) };
        let l = match inp.below(3) {
            0 => Lobe::phong(p.abs() * if inp.bool() { 1.0 } else { 1e3 }),
            1 => Lobe::ggx_roughness(p),
            _ => Lobe::torrance_sparrow(p),
        };
        if let Ok(l) = l {
            for c in [-1.0, -0.3, 0.0, 1e-300, 0.2, 0.9, 1.0, 1.5, f64::NAN] {
                let k = l.kernel(c);
                assert!(c.is_nan() || (k.is_finite() && k >= 0.0), "{l:?}.kernel({c}) = {k}");
            }
            let (r0, cut) = l.radii(1e-5);
            assert!(r0 >= 0.0 && r0 <= cut && cut <= std::f64::consts::FRAC_PI_2 + 1e-9, "{l:?}.radii = ({r0}, {cut})");
            lobes.push(l);
        }
    }
    let h = if inp.byte() % 4 == 0 { 16 } else { 2 + inp.below(10) };
    let w = 2 * h;
    let c = 1 + inp.below(3);
    let constant = inp.byte() % 4 == 0;
    let k = inp.finite(3.0) as f32;
    let data: Vec<f32> = if constant { vec![k; h * w * c] } else { inp.f32s_finite(h * w * c, 3.0) };
    let env = EnvMap::new(Layout::LatLong, h, w, c, data, "image").expect("finite lat-long map");
    let lo = env.data.iter().fold(f32::INFINITY, |a, &b| a.min(b)) as f64;
    let hi = env.data.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64;
    let tol = 1e-4 * (1.0 + hi.abs().max(lo.abs()));
    let params = if inp.bool() {
        PrefilterParams::default()
    } else {
        PrefilterParams { texels_per_radius: inp.f64_in(8.0), tail: inp.f64_in(0.5) }
    };
    if let Ok(levels) = prefilter(&env, &lobes, &params) {
        assert_eq!(levels.len(), lobes.len());
        for l in &levels {
            assert!(l.core_radius <= l.cut_radius + 1e-12);
            assert!(l.map.data.iter().all(|&x| x.is_finite() && (x as f64) >= lo - tol && (x as f64) <= hi + tol), "prefiltered value outside [{lo}, {hi}]");
        }
    }
    let nd = 3 * inp.below(4) + inp.below(2);
    let dirs = inp.f32s(nd, 2.0);
    if let Some(l) = lobes.first() {
        if let Ok(v) = brute_force(&env, l, &dirs) {
            assert!(v.iter().all(|&x| x.is_finite() && x >= lo - tol && x <= hi + tol), "brute_force {v:?} outside [{lo}, {hi}]");
        }
    }
    let co = sh_project(&env).expect("finite lat-long map");
    assert_eq!(co.len(), c);
    assert!(co.iter().flatten().all(|x| x.is_finite()));
    let mut out = vec![0.0f64; c];
    let n = inp.v3(2.0);
    sh_irradiance(&co, n, &mut out);
    if n.is_finite() && n.length() > 1e-6 && n.length() < 1e6 {
        assert!(out.iter().all(|x| x.is_finite()));
    }
    let (ih, iw) = (inp.below(9), inp.below(17));
    if let Ok((m, co2)) = irradiance_map(&env, ih, iw) {
        assert_eq!(co2.len(), c);
        assert!(m.data.iter().all(|x| x.is_finite()));
        // Texel-centre quadrature leaks a constant into the l = 2 terms on coarse maps (24% at
        // 2×4, 0.16% at 16×32): the property is checked where it holds to 2e-3.
        if constant && h >= 16 {
            assert!(m.data.iter().all(|&x| (x - k).abs() <= 2e-3 * (1.0 + k.abs())), "irradiance of constant {k} map: {:?}", &m.data[..c]);
        }
    }
    if let Ok(v) = brute_force_irradiance(&env, &dirs) {
        assert!(v.iter().all(|x| x.is_finite()));
    }
});
