//! Inputs the cargo-fuzz targets of rust/fuzz found: each test reproduces one and checks
//! the fix.
use glam::{DVec2, DVec3};
use rokeby_core::compositing::recomposite::{recomposite, Buffers, Params, Patch};
use rokeby_core::compositing::reconstruct::ParaboloidMap;
use rokeby_core::envmaps::prefilter::Lobe;
use rokeby_core::geometry::bvh::Bvh;
use rokeby_core::shadows::light_space::LightFrame;
use rokeby_core::shadows::mls2d::sinusoidal_noise;
use rokeby_core::shadows::silhouette::Light;

/// Fuzzer (bvh): NaN t_min/t_max returned a hit at t < 0 (`tt <= NaN` is false).
#[test]
fn bvh_nan_bounds_give_no_hit() {
    let tri = [
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(1.0, -1.0, 0.0),
        DVec3::new(0.0, 1.0, 0.0),
    ];
    let bvh = Bvh::new(vec![tri], "t").unwrap();
    let (o, d) = (DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.0, 0.0, 1.0)); // hit at t = −1
    assert!(bvh.intersect(o, d, f64::NAN, f64::NAN).is_none());
    assert!(bvh
        .intersect_brute_force(o, d, f64::NAN, f64::INFINITY)
        .is_none());
    assert!(bvh.intersect(o, -d, 0.0, f64::NAN).is_none());
    assert_eq!(
        bvh.intersect(o, -d, 0.0, f64::INFINITY).map(|h| h.t),
        Some(1.0)
    );
}

/// Fuzzer (mls2d): NaN boundary points went through the noise as NaN output.
#[test]
fn noise_rejects_non_finite_points() {
    let pts = [
        DVec2::new(0.0, 0.0),
        DVec2::new(f64::NAN, 1.0),
        DVec2::new(2.0, 0.0),
    ];
    let e = sinusoidal_noise(&pts, false, 0.1, 3.0).unwrap_err();
    assert!(e.to_string().contains("points"), "{e}");
    let ok = sinusoidal_noise(
        &[DVec2::ZERO, DVec2::X, DVec2::new(2.0, 0.0)],
        true,
        0.1,
        3.0,
    )
    .unwrap();
    assert!(ok.iter().all(|p| p.is_finite()));
}

/// Fuzzer (prefilter): a mirror lobe's kernel was 0/0 = NaN at c = 1 (TS σ = −0.0, and σ = 0,
/// GGX α = 0).
#[test]
fn mirror_lobe_kernel_is_finite() {
    for l in [
        Lobe::torrance_sparrow(-0.0).unwrap(),
        Lobe::torrance_sparrow(0.0).unwrap(),
        Lobe::ggx_roughness(0.0).unwrap(),
    ] {
        assert!(l.is_mirror());
        assert_eq!(l.kernel(1.0), 1.0, "{l:?}");
        assert_eq!(l.kernel(0.5), 0.0, "{l:?}");
    }
    assert!(Lobe::ggx_roughness(0.5).unwrap().kernel(1.0).is_finite());
}

/// Fuzzer (recomposite): a patch's reflection map of size 0 panicked in the lookup's clamp.
#[test]
fn recomposite_rejects_empty_reflection_map() {
    let ids = [0i32];
    let n = [0.0f32, 0.0, 1.0];
    let e = [0.0f32, 0.6, 0.8];
    let z = [0.5f32; 3];
    let b = Buffers {
        ids: &ids,
        normals: &n,
        edited: &e,
        view: &n,
        diffuse: &z,
        reflection: &z,
        alpha_d: &[],
        alpha_r: &[],
        alpha: &[],
        image: &z,
        diffuse_color: &[],
        reflection_color: &[],
    };
    for env in [
        ParaboloidMap::new(0, 3),
        ParaboloidMap {
            size: 2,
            channels: 3,
            data: vec![0.0; 5],
        },
    ] {
        let patches = [Patch {
            sh: None,
            env: Some(env),
        }];
        let err = recomposite(&b, &patches, &Params::default()).unwrap_err();
        assert!(err.to_string().contains("patches"), "{err}");
    }
    let patches = [Patch {
        sh: None,
        env: Some(ParaboloidMap::new(2, 3)),
    }];
    assert!(recomposite(&b, &patches, &Params::default()).is_ok());
}

/// Fuzzer (shadow_mesh): a directional light of |d| ≈ 1e300 (|d|² = inf) passed validation,
/// normalised to zero, and gave a NaN light frame.
#[test]
fn huge_light_direction_is_rejected_or_finite() {
    let verts = [DVec3::new(-1.0, -1.0, -1.0), DVec3::new(1.0, 1.0, 1.0)];
    let huge = Light::Directional(DVec3::new(1e300, -1e300, 0.0));
    assert!(huge.validate().is_err());
    assert!(LightFrame::new(huge, &verts).is_err());
    assert!(Light::Directional(DVec3::new(1e-300, 0.0, 0.0))
        .validate()
        .is_err());
    let ok = LightFrame::new(Light::Directional(DVec3::new(1e150, -1e150, 1.0)), &verts).unwrap();
    let p = ok.from_frustum(ok.to_frustum(verts[0]));
    assert!((p - verts[0]).length() < 1e-9, "{p:?}");
}

/// Fuzzer (bvh): a triangle with 1e30 coordinates that the triangle test hits (rounding at that
/// scale) just outside its box: the BVH's slab test rejected the box and disagreed with the brute
/// force.
#[test]
fn bvh_agrees_with_brute_force_on_huge_triangle() {
    let tri = [
        DVec3::new(1e30, 1e30, 0.9981994354161898),
        DVec3::new(-0.43529411764705883, 1e30, 1e30),
        DVec3::new(1e30, 0.9981994354161898, -0.43529411764705883),
    ];
    let bvh = Bvh::new(vec![tri; 3], "t").unwrap();
    let o = DVec3::new(
        -0.8667429617761502,
        -0.8705882352941177,
        -0.8705882352941177,
    );
    let d = DVec3::new(5.562684646268003e-309, 1e30, 1e30);
    let (a, b) = (
        bvh.intersect(o, d, 0.6774853131914245, 1e30),
        bvh.intersect_brute_force(o, d, 0.6774853131914245, 1e30),
    );
    assert_eq!(a.map(|h| h.t), b.map(|h| h.t));
}

/// Fuzzer (mls2d): boundary points 1e300 apart: |Δ|² overflowed, the arc length became inf and
/// sin(inf) = NaN.
#[test]
fn noise_of_huge_points_is_finite_or_an_error() {
    let pts = [DVec2::new(5.0, 5.0), DVec2::new(5.0, -1e300)];
    let out = sinusoidal_noise(&pts, false, -1e300, -46.40802624551766).unwrap();
    assert!(out.iter().all(|p| p.is_finite()), "{out:?}");
    let far = [DVec2::new(0.0, 1.7e308), DVec2::new(0.0, -1.7e308)];
    assert!(sinusoidal_noise(&far, false, 1.0, 1.0).is_err());
}

/// Fuzzer (prefilter): GGX α = 2.3e-10 gave k(1) = inf (α² − 1 = −1 in f64, so t = 0).
#[test]
fn sharp_ggx_kernel_is_finite() {
    let l = Lobe::Ggx {
        alpha: 2.328377492438592e-10,
    };
    assert!(!l.is_mirror());
    let k = l.kernel(1.0);
    assert!(k.is_finite() && k > 0.0, "{k}");
    assert!(Lobe::Ggx { alpha: 1e-200 }.is_mirror());
    // The stable form agrees with the textbook one where the latter is accurate.
    let (a2, c): (f64, f64) = (0.09, 0.7);
    let ch2 = 0.5 * (1.0 + c);
    let t = ch2 * (a2 - 1.0) + 1.0;
    let k0 = a2 / (std::f64::consts::PI * t * t) * c;
    assert!((Lobe::Ggx { alpha: 0.3 }.kernel(c) - k0).abs() < 1e-12 * k0);
}

/// Fuzzer (shadow_mesh): falloff factor of two nearly equal unit directions was 1 + 9e-16.
#[test]
fn falloff_stays_within_unit_interval() {
    use rokeby_core::shadows::shadow_mesh::falloff_factor;
    let a = DVec3::new(0.1, 0.7, 0.3);
    for k in 0..200 {
        let b = a * (1.0 + k as f64 * 1e-3);
        let x = falloff_factor(a, b, 0.5 + k as f64).unwrap();
        assert!((0.0..=1.0).contains(&x), "{x}");
    }
}

/// tests/native/test_properties_new.py (reflection_env): NaN parameters were accepted, and
/// blur_sigma = NaN gave a NaN map; each is now an error naming it.
#[test]
fn reflection_params_are_checked() {
    use rokeby_core::compositing::reconstruct::{reconstruct, ReflectionParams};
    let (w, h) = (4, 4);
    let mut refl = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let d = DVec3::new(x as f64 - 1.5, y as f64 - 1.5, 2.0).normalize();
            refl.extend([d.x as f32, d.y as f32, d.z as f32]);
        }
    }
    let vals = vec![1.0f32; w * h * 3];
    let mask = vec![1.0f32; w * h];
    let base = ReflectionParams {
        size: 8,
        min_coverage: 0.0,
        ..Default::default()
    };
    assert!(reconstruct(w, h, &refl, &vals, 3, &mask, &[], &base).is_ok());
    for (name, p) in [
        (
            "blur_sigma",
            ReflectionParams {
                blur_sigma: f64::NAN,
                ..base.clone()
            },
        ),
        (
            "blur_sigma",
            ReflectionParams {
                blur_sigma: -1.0,
                ..base.clone()
            },
        ),
        (
            "max_edge_angle",
            ReflectionParams {
                max_edge_angle: f64::NAN,
                ..base.clone()
            },
        ),
        (
            "max_depth_jump",
            ReflectionParams {
                max_depth_jump: f64::NAN,
                ..base.clone()
            },
        ),
        (
            "min_coverage",
            ReflectionParams {
                min_coverage: f64::NAN,
                ..base.clone()
            },
        ),
    ] {
        let e = reconstruct(w, h, &refl, &vals, 3, &mask, &[], &p).unwrap_err();
        assert!(e.to_string().contains(name), "{e}");
    }
}

/// Fuzzer (mls2d): a control point at −1e300 made the affine moment matrices inf · 0 = NaN.
#[test]
fn mls_rejects_overflowing_controls() {
    use rokeby_core::shadows::mls2d::{Mls2d, MlsStyle};
    let p = vec![
        DVec2::new(0.0, 1.28),
        DVec2::new(-1e300, 0.0),
        DVec2::new(0.0, -6.98),
        DVec2::new(3.0, 0.0),
    ];
    let e = Mls2d::new(p.clone(), p, MlsStyle::Affine, 5.562684646268003e-309).unwrap_err();
    assert!(e.to_string().contains("controls"), "{e}");
    let p = vec![
        DVec2::new(0.0, 1.28),
        DVec2::new(-1e100, 0.0),
        DVec2::new(0.0, -6.98),
    ];
    let m = Mls2d::new(p.clone(), p, MlsStyle::Affine, 1.0).unwrap();
    assert!(m.deform(DVec2::new(2.52, -12.36)).is_finite());
}

/// Fuzzer (mls2d): α = 1e30 made every weight 1/d^{2α} zero or infinite (NaN result);
/// the weights are now relative to the nearest control point's.
#[test]
fn mls_with_huge_alpha_is_finite_and_interpolates() {
    use rokeby_core::shadows::mls2d::{Mls2d, MlsStyle};
    let p = vec![
        DVec2::new(1.92, 3.0),
        DVec2::new(4.0, 1.0),
        DVec2::new(-2.0, 5.0),
        DVec2::new(0.0, -1.0),
    ];
    let q: Vec<DVec2> = p.iter().map(|x| *x * 1.5 + DVec2::new(0.3, -0.2)).collect();
    for style in [MlsStyle::Affine, MlsStyle::Similarity, MlsStyle::Rigid] {
        for alpha in [1e30, 1.0, 1e-300] {
            let m = Mls2d::new(p.clone(), q.clone(), style, alpha).unwrap();
            assert!(
                m.deform(DVec2::new(3.84, 3.84)).is_finite(),
                "{style:?} α = {alpha}"
            );
            assert!((m.deform(p[1]) - q[1]).length() < 1e-12);
        }
    }
    // Affine with α = 1 reproduces the affine map exactly.
    let m = Mls2d::new(p.clone(), q.clone(), MlsStyle::Affine, 1.0).unwrap();
    let v = DVec2::new(0.7, 2.2);
    assert!((m.deform(v) - (v * 1.5 + DVec2::new(0.3, -0.2))).length() < 1e-9);
}

/// Fuzzer (shadow_mesh): a caster vertex at 1e300 made the frame's radius inf and every frustum
/// coordinate NaN.
#[test]
fn light_frame_rejects_overflowing_caster() {
    let verts = [
        DVec3::new(1e30, 1e30, 8.19607843137255e299),
        DVec3::new(-1.0, 0.0, 0.0),
        DVec3::new(1.0, 1.0, 1.0),
    ];
    let e = LightFrame::new(Light::Point(DVec3::new(0.0, 0.0, -20.0)), &verts).unwrap_err();
    assert!(e.to_string().contains("vertices"), "{e}");
}

/// Fuzzer (mls2d): affine MLS at rest (q = p) with nearly collinear controls moved (20, 20) by
/// 6e-5 (A⁻¹A rounding); it is now the identity to rounding of the inputs.
#[test]
fn affine_mls_at_rest_is_the_identity() {
    use rokeby_core::shadows::mls2d::{Mls2d, MlsStyle};
    let p = vec![
        DVec2::new(0.0, 0.0),
        DVec2::new(1.0, 1e-5),
        DVec2::new(2.0, -1e-5),
        DVec2::new(3.0, 2e-5),
    ];
    for alpha in [0.5, 1.0, 2.0] {
        let m = Mls2d::new(p.clone(), p.clone(), MlsStyle::Affine, alpha).unwrap();
        for v in [
            DVec2::new(20.0, 20.0),
            DVec2::new(-7.0, 3.0),
            DVec2::new(1.5, 0.0),
        ] {
            assert!(
                (m.deform(v) - v).length() <= 1e-12 * (1.0 + v.length()),
                "α = {alpha}: {v:?} → {:?}",
                m.deform(v)
            );
        }
    }
}

/// Fuzzer (shadow_editor): w_z = constraint weight = 1e30 and a drag with 1e300 noise gave a
/// NaN shadow mesh; the solve now reports it.
#[test]
fn overflowing_shadow_solve_is_an_error() {
    use rokeby_core::shadows::shadow_mesh::{EdgePoint, ShadowMeshSolver};
    use rokeby_core::shadows::silhouette::ClosedMesh;
    let v: Vec<f32> = vec![
        1., 0., 0., -1., 0., 0., 0., 1., 0., 0., -1., 0., 0., 0., 1., 0., 0., -1.,
    ];
    let f: Vec<i64> = vec![
        0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5,
    ];
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    let frame = LightFrame::new(
        Light::Directional(DVec3::new(-1.28, -1.31, -1.95)),
        &mesh.vertices,
    )
    .unwrap();
    let cons = vec![
        EdgePoint {
            back: 0,
            front: 2,
            alpha: 0.5,
        },
        EdgePoint {
            back: 1,
            front: 3,
            alpha: 0.5,
        },
    ];
    let mut built = 0;
    for (wz, cw) in [(1e30, 1e30), (2.5, 1e30), (1e30, 10.0), (2.5, 10.0)] {
        let Ok(s) = ShadowMeshSolver::new(frame, &mesh.vertices, &mesh.faces, cons.clone(), wz, cw)
        else {
            continue;
        };
        built += 1;
        match s.solve(&[DVec2::new(1e300, -1e300), DVec2::new(-1e300, 1e300)]) {
            Ok(m) => assert!(
                m.iter().all(|p| p.is_finite()),
                "w_z {wz}, weight {cw}: NaN shadow mesh"
            ),
            Err(e) => assert!(e.to_string().contains("deltas"), "{e}"),
        }
    }
    assert!(built >= 1);
}

/// Fuzzer (prefilter): brute_force with a lobe far narrower than the texels (every weight 0)
/// returned 0/0 = NaN; it now returns the bilinear lookup, like a mirror lobe.
#[test]
fn brute_force_of_a_vanishing_lobe_is_the_lookup() {
    use rokeby_core::envmaps::envmap::{EnvMap, Layout};
    use rokeby_core::envmaps::prefilter::brute_force;
    let env = EnvMap::new(Layout::LatLong, 2, 4, 1, vec![-2.744_381; 8], "image").unwrap();
    for lobe in [
        Lobe::torrance_sparrow(1e-300).unwrap(),
        Lobe::phong(1e300).unwrap(),
    ] {
        let v = brute_force(&env, &lobe, &[0.3, 0.2, 0.9, 0.0, -1.0, 0.0]).unwrap();
        assert!(
            v.iter().all(|x| (x + 2.7443809509277344).abs() < 1e-6),
            "{lobe:?}: {v:?}"
        );
    }
}
