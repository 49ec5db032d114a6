//! Environment-map parametrisations: exact direction formulas both ways (round trips), the
//! lecture notes' sphere-map identity, bilinear seam-correct lookups and conversions.

use glam::DVec3;
use proptest::prelude::*;
use rokeby_core::envmaps::envmap::{self, EnvMap, Layout};

const LAYOUTS: [Layout; 4] = [
    Layout::LatLong,
    Layout::Cube,
    Layout::Sphere,
    Layout::Paraboloid,
];

fn dims(layout: Layout, n: usize) -> (usize, usize) {
    match layout {
        Layout::LatLong => (n, 2 * n),
        _ => (n, n),
    }
}

/// A smooth test environment (not band-limited to order 1, positive).
fn smooth(d: DVec3) -> [f32; 3] {
    let a = 1.0 + 0.5 * d.x + 0.3 * d.y - 0.2 * d.z + 0.2 * d.x * d.y;
    let b = 1.0 + 0.4 * (3.0 * d.z).sin() * d.x;
    let c = 2.0 + d.y * d.z;
    [a as f32, b as f32, c as f32]
}

fn filled(layout: Layout, n: usize, f: impl Fn(DVec3) -> [f32; 3]) -> EnvMap {
    let (h, w) = dims(layout, n);
    let mut m = EnvMap::zeros(layout, h, w, 3).unwrap();
    let probe = m.clone();
    for face in 0..layout.faces() {
        for i in 0..h {
            for j in 0..w {
                let v = f(probe.texel_direction(face, i, j));
                let k = ((face * h + i) * w + j) * 3;
                m.data[k..k + 3].copy_from_slice(&v);
            }
        }
    }
    m
}

fn unit() -> impl Strategy<Value = DVec3> {
    (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0).prop_filter_map("non-zero", |(x, y, z)| {
        let d = DVec3::new(x, y, z);
        (d.length() > 1e-3).then(|| d.normalize())
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// direction → map coordinates → direction, for every layout (the sphere map away from its
    /// singular antipode r = (0, 0, −1), where the whole rim maps to one direction).
    #[test]
    fn direction_map_direction(d in unit(), n in 4usize..300) {
        for layout in LAYOUTS {
            if layout == Layout::Sphere && d.z < -0.999 {
                continue;
            }
            let (h, w) = dims(layout, n);
            let m = EnvMap::zeros(layout, h, w, 1).unwrap();
            let (f, x, y) = m.coords(d);
            prop_assert!(f < layout.faces());
            prop_assert!((0.0..=w as f64).contains(&x) && (0.0..=h as f64).contains(&y), "{layout:?} {x} {y}");
            let back = m.direction(f, x, y);
            prop_assert!((back - d).length() < 1e-9, "{layout:?}: {d} -> ({f}, {x}, {y}) -> {back}");
        }
    }

    /// map coordinates → direction → map coordinates inside each face.
    #[test]
    fn map_direction_map(fx in 0.001f64..0.999, fy in 0.001f64..0.999, face in 0usize..6, n in 4usize..300) {
        for layout in LAYOUTS {
            let (h, w) = dims(layout, n);
            let m = EnvMap::zeros(layout, h, w, 1).unwrap();
            let face = face % layout.faces();
            let (x, y) = (fx * w as f64, fy * h as f64);
            match layout {
                Layout::Sphere | Layout::Paraboloid => {
                    let (u, v) = (2.0 * fx - 1.0, 2.0 * fy - 1.0);
                    if u * u + v * v > 0.98 {
                        continue;
                    }
                }
                _ => {}
            }
            let (f2, x2, y2) = m.coords(m.direction(face, x, y));
            prop_assert_eq!(f2, face);
            prop_assert!((x2 - x).abs() < 1e-7 * n as f64 && (y2 - y).abs() < 1e-7 * n as f64, "{layout:?} ({x}, {y}) -> ({x2}, {y2})");
        }
    }

    /// The notes' derivation: (s, t) are the x, y of the mirror ball's normal n = (r + v)/|r + v|.
    #[test]
    fn sphere_map_is_the_mirror_ball_normal(d in unit()) {
        prop_assume!(d.z > -0.999);
        let (s, t) = envmap::sphere_st(d);
        let n = (d + DVec3::Z).normalize();
        prop_assert!((s - n.x).abs() < 1e-12 && (t - n.y).abs() < 1e-12);
        // and r = 2(n·v)n − v
        let r = envmap::sphere_dir(s, t);
        prop_assert!((r - (2.0 * n.z * n - DVec3::Z)).length() < 1e-9);
    }

    /// The cube map meets the ray at r / max|r_i| on the face of the major axis.
    #[test]
    fn cube_face_is_the_major_axis(d in unit()) {
        let (f, s, t) = envmap::cube_face_st(d);
        let m = d.abs().max_element();
        let p = d / m;
        let axis = f / 2;
        prop_assert!((p[axis].abs() - 1.0).abs() < 1e-12);
        prop_assert_eq!(p[axis] > 0.0, f % 2 == 0);
        prop_assert!((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t));
    }

    /// Bilinear lookups of a smooth environment are second-order accurate everywhere, seams
    /// included (lat-long u = 0 ≡ 1 and poles, cube edges and corners, the paraboloid equator).
    #[test]
    fn bilinear_lookup_is_smooth_across_seams(d in unit()) {
        for layout in [Layout::LatLong, Layout::Cube, Layout::Paraboloid] {
            let m = filled(layout, 96, smooth);
            let mut out = [0.0f32; 3];
            m.sample(d, &mut out);
            let want = smooth(d);
            for c in 0..3 {
                prop_assert!((out[c] - want[c]).abs() < 2.5e-3, "{layout:?} at {d}: {out:?} vs {want:?}");
            }
        }
    }
}

/// Directions exactly on seams: first-order (clamped) lookups would be off by ~gradient × texel.
#[test]
fn seam_directions() {
    let mut dirs = vec![];
    for k in 0..200 {
        let a = k as f64 / 200.0 * std::f64::consts::TAU;
        dirs.push(DVec3::new(-a.cos(), 1e-9, a.sin()).normalize()); // lat-long seam (−X half-plane)
        dirs.push(DVec3::new(1.0, 1.0, 2.0 * (k as f64 / 200.0) - 1.0).normalize()); // cube edge
        dirs.push(DVec3::new(a.cos() * 0.02, a.sin() * 0.02, 1.0).normalize()); // near the pole
        dirs.push(DVec3::new(a.cos(), a.sin(), 1e-6).normalize()); // paraboloid equator
    }
    dirs.push(DVec3::new(1.0, 1.0, 1.0).normalize()); // cube corner
    dirs.push(DVec3::new(-1.0, 1.0, -1.0).normalize());
    for layout in [Layout::LatLong, Layout::Cube, Layout::Paraboloid] {
        let m = filled(layout, 96, smooth);
        let mut worst = 0.0f32;
        for d in &dirs {
            let mut out = [0.0f32; 3];
            m.sample(*d, &mut out);
            let want = smooth(*d);
            for c in 0..3 {
                worst = worst.max((out[c] - want[c]).abs());
            }
        }
        assert!(worst < 2.5e-3, "{layout:?}: worst seam error {worst}");
    }
}

#[test]
fn blender_latlong_convention() {
    // +X at the image centre, +Y at u = ¼, up at v = 1 (row 0 of the file).
    let (u, v) = envmap::latlong_uv(DVec3::X);
    assert!((u - 0.5).abs() < 1e-12 && (v - 0.5).abs() < 1e-12);
    let (u, _) = envmap::latlong_uv(DVec3::Y);
    assert!((u - 0.25).abs() < 1e-12);
    let (_, v) = envmap::latlong_uv(DVec3::Z);
    assert!((v - 1.0).abs() < 1e-12);
    let m = EnvMap::zeros(Layout::LatLong, 8, 16, 1).unwrap();
    let (_, _, y) = m.coords(DVec3::new(0.0, 0.0, 1.0));
    assert!(y.abs() < 1e-12);
}

/// Conversions between every pair of layouts keep a smooth environment (sup error).
#[test]
fn conversions_round_trip() {
    let src = filled(Layout::LatLong, 128, smooth);
    for layout in [Layout::Cube, Layout::Sphere, Layout::Paraboloid] {
        let n = 128;
        let mid = src.convert(layout, n, n, 2).unwrap();
        let back = mid.convert(Layout::LatLong, 128, 256, 1).unwrap();
        let mut worst = 0.0f32;
        for i in 0..128 {
            for j in 0..256 {
                let d = back.texel_direction(0, i, j);
                if layout == Layout::Sphere && d.z < -0.5 {
                    continue; // the disk's rim squeezes the back hemisphere: see docs/envmaps.md
                }
                let want = smooth(d);
                for (c, w) in want.iter().enumerate() {
                    worst = worst.max((back.texel(0, i, j)[c] - w).abs());
                }
            }
        }
        assert!(
            worst < 6e-3,
            "latlong → {layout:?} → latlong: worst error {worst}"
        );
    }
}

#[test]
fn bad_input_is_an_error() {
    let e = EnvMap::new(Layout::LatLong, 4, 8, 3, vec![0.0; 95], "image").unwrap_err();
    assert!(e.to_string().contains("expected 96 values"), "{e}");
    let mut d = vec![0.5f32; 96];
    d[3 * (8 + 2) + 1] = f32::NAN;
    let e = EnvMap::new(Layout::LatLong, 4, 8, 3, d, "image").unwrap_err();
    assert!(e.to_string().contains("row 1, column 2, channel 1"), "{e}");
    let e = EnvMap::zeros(Layout::Cube, 4, 5, 3).unwrap_err();
    assert!(e.to_string().contains("square"), "{e}");
    let m = EnvMap::zeros(Layout::LatLong, 4, 8, 1).unwrap();
    assert!(m.sample_many(&[0.0, 0.0, 0.0]).is_err());
    assert!(m.sample_many(&[1.0, f32::INFINITY, 0.0]).is_err());
    assert!(m.convert(Layout::Cube, 8, 8, 0).is_err());
    let e = m
        .convert(Layout::Cube, 1_000_000, 1_000_000, 1)
        .unwrap_err();
    assert!(e.to_string().contains("4 GiB"), "{e}");
    assert!(EnvMap::zeros(Layout::LatLong, usize::MAX / 2, 4, 3).is_err());
}
