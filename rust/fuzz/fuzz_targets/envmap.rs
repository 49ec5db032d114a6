//! envmap: EnvMap::new/zeros of arbitrary shapes and values, directions ↔ map
//! coordinates of every layout, sample/sample_many in arbitrary directions, convert between
//! layouts. Never a panic; coords lie within the image; direction(coords(d)) = d; lookups and
//! conversions of a finite map are finite and within the map's value range (bilinear weights
//! are a partition of unity ≥ 0).
#![no_main]
mod common;
use common::Input;
use libfuzzer_sys::fuzz_target;
use rokeby_core::envmaps::envmap::{cube_dir, cube_face_st, finite_dirs, latlong_dir, latlong_texel_solid_angle, latlong_uv, paraboloid_dir, paraboloid_uv, sphere_dir, sphere_st, EnvMap, Layout};

const LAYOUTS: [Layout; 4] = [Layout::LatLong, Layout::Cube, Layout::Sphere, Layout::Paraboloid];

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    let d = inp.v3(2.0);
    // Free functions never panic; unit finite directions round-trip.
    let _ = (latlong_uv(d), cube_face_st(d), sphere_st(d), paraboloid_uv(d));
    let (a, b) = (inp.f64_in(2.0), inp.f64_in(2.0));
    let face = inp.below(8);
    let _ = (latlong_dir(a, b), cube_dir(face, a, b), sphere_dir(a, b), paraboloid_dir(face, a, b));
    let (hh, i) = (inp.below(64), inp.below(64));
    if hh > 0 && i < hh {
        let w = latlong_texel_solid_angle(hh, 2 * hh, i);
        assert!(w.is_finite() && w >= 0.0);
    }
    let unit = if d.is_finite() && d.length() > 1e-3 && d.length() < 1e3 { Some(d.normalize()) } else { None };
    if let Some(u) = unit {
        let (s, t) = (latlong_uv(u), cube_face_st(u));
        assert!((0.0..=1.0).contains(&s.0) && (0.0..=1.0).contains(&s.1), "latlong_uv({u:?}) = {s:?}");
        assert!(t.0 < 6 && (0.0..=1.0).contains(&t.1) && (0.0..=1.0).contains(&t.2), "cube_face_st({u:?}) = {t:?}");
        assert!((latlong_dir(s.0, s.1) - u).length() < 1e-9);
        assert!((cube_dir(t.0, t.1, t.2) - u).length() < 1e-9);
        let (f, pu, pv) = paraboloid_uv(u);
        assert!(f < 2 && pu * pu + pv * pv <= 1.0 + 1e-9);
        assert!((paraboloid_dir(f, pu, pv) - u).length() < 1e-9);
    }

    let layout = LAYOUTS[inp.below(4)];
    let (h, w, c) = if inp.byte() % 8 == 0 {
        (inp.below(usize::MAX), inp.below(usize::MAX), inp.below(5))
    } else {
        let h = inp.below(9);
        (h, if layout == Layout::LatLong { 2 * h + inp.below(2) } else { h }, inp.below(4))
    };
    let n = layout.faces().saturating_mul(h).saturating_mul(w).saturating_mul(c).min(4096);
    let adversarial = inp.bool();
    let values = if adversarial { inp.f32s(n, 5.0) } else { inp.f32s_finite(n, 5.0) };
    let _ = EnvMap::zeros(layout, h, w, c);
    let Ok(env) = EnvMap::new(layout, h, w, c, values, "image") else { return };
    assert!(env.data.iter().all(|x| x.is_finite()), "EnvMap::new accepted a non-finite value");
    let lo = env.data.iter().fold(f32::INFINITY, |a, &b| a.min(b));
    let hi = env.data.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
    let tol = 1e-4 * (1.0 + hi.abs().max(lo.abs()));
    let in_range = |v: &[f32]| v.iter().all(|&x| x.is_finite() && x >= lo - tol && x <= hi + tol);

    let (f, x, y) = env.coords(d);
    assert!(f < env.faces(), "face {f} of {}", env.faces());
    assert!((0.0..=env.width as f64).contains(&x) && (0.0..=env.height as f64).contains(&y), "coords({d:?}) = ({f}, {x}, {y}) outside {}×{}", env.height, env.width);
    if let Some(u) = unit {
        let back = env.direction(f, x, y);
        // The sphere map's rim is one direction (−Z) spread over a circle: skip near it.
        if env.layout != Layout::Sphere || u.z > -0.99 {
            assert!((back - u).length() < 1e-6, "{:?}: direction(coords({u:?})) = {back:?}", env.layout);
        }
    }
    let mut out = vec![0.0f32; c];
    env.sample(d, &mut out);
    assert!(in_range(&out), "sample({d:?}) = {out:?} outside [{lo}, {hi}]");
    let (fx, fy) = (inp.f64_in(40.0), inp.f64_in(40.0));
    if fx.is_finite() && fy.is_finite() {
        env.sample_at(inp.below(env.faces()), fx, fy, &mut out);
        assert!(in_range(&out), "sample_at({fx}, {fy}) = {out:?}");
    }
    let nd = 3 * inp.below(6) + inp.below(2);
    let dirs = inp.f32s(nd, 2.0);
    if let Ok(s) = env.sample_many(&dirs) {
        assert_eq!(s.len() * 3, dirs.len() / 3 * 3 * c);
        assert!(in_range(&s));
        assert!(finite_dirs(&dirs, "d").is_ok());
    }
    let to = LAYOUTS[inp.below(4)];
    let th = inp.below(7);
    let tw = if to == Layout::LatLong { 2 * th } else { th };
    let ss = inp.below(4);
    if let Ok(m) = env.convert(to, th, tw, ss) {
        assert_eq!(m.data.len(), to.faces() * th * tw * c);
        assert!(in_range(&m.data), "convert {:?} → {to:?} left the value range", env.layout);
    }
});
