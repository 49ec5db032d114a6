//! Properties of the MLS rotation field (Ritschel et al. 2009, eqs. 2–7) that a user would notice:
//! rotations are rotations, constraints are met exactly, the field is smooth, it does not care
//! where the scene is, how it is oriented or how large it is, and the extremes stay finite.

use glam::{DMat3, DQuat, DVec3};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rokeby_core::reflection::field::{Distances, Field};
use rokeby_core::reflection::polar::PolarMethod;
use rokeby_core::reflection::region::Region;

fn quats(out: &[f32]) -> Vec<DQuat> {
    out.chunks_exact(4)
        .map(|c| DQuat::from_xyzw(c[0] as f64, c[1] as f64, c[2] as f64, c[3] as f64))
        .collect()
}

/// Angle of the rotation between a and b, accurate for tiny angles (acos near 1 is not).
fn angle(a: DQuat, b: DQuat) -> f64 {
    let d = a.conjugate() * b;
    2.0 * d.xyz().length().atan2(d.w.abs())
}

fn dir_angle(a: DVec3, b: DVec3) -> f64 {
    a.normalize()
        .cross(b.normalize())
        .length()
        .atan2(a.normalize().dot(b.normalize()))
}

fn rows(cs: &[(DVec3, DVec3, DVec3)]) -> Vec<f32> {
    cs.iter()
        .flat_map(|(p, r, e)| [p.x, p.y, p.z, r.x, r.y, r.z, e.x, e.y, e.z].map(|x| x as f32))
        .collect()
}

fn field_at(cs: &[(DVec3, DVec3, DVec3)], pts: &[DVec3], polar: PolarMethod) -> Vec<DQuat> {
    let f = Field::new(&rows(cs), vec![]).unwrap();
    let flat: Vec<f32> = pts
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    quats(
        &f.rotation_field(&flat, Distances::Euclidean, None, polar)
            .unwrap(),
    )
}

fn unit_vec() -> impl Strategy<Value = DVec3> {
    (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0)
        .prop_filter("non-degenerate", |(x, y, z)| x * x + y * y + z * z > 0.05)
        .prop_map(|(x, y, z)| DVec3::new(x, y, z).normalize())
}

fn point() -> impl Strategy<Value = DVec3> {
    (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

/// Constraints with well-separated points (the paper's use; coincident ones are tested apart).
fn constraints(max: usize) -> impl Strategy<Value = Vec<(DVec3, DVec3, DVec3)>> {
    prop::collection::vec((point(), unit_vec(), unit_vec()), 1..=max).prop_filter(
        "separated points",
        |cs| {
            cs.iter()
                .enumerate()
                .all(|(i, a)| cs.iter().skip(i + 1).all(|b| a.0.distance(b.0) > 0.05))
        },
    )
}

proptest! {
    // Seeded and bounded: the same cases on every run (CI is reproducible).
    #![proptest_config(ProptestConfig { cases: 2000, rng_seed: RngSeed::Fixed(0x2009_7E0B), failure_persistence: None, .. ProptestConfig::default() })]

    #[test]
    fn rotations_are_proper(cs in constraints(8), qs in prop::collection::vec(point(), 1..16)) {
        for polar in [PolarMethod::Svd, PolarMethod::Iterative] {
            for q in field_at(&cs, &qs, polar) {
                let r = DMat3::from_quat(q);
                let rtr = r.transpose() * r - DMat3::IDENTITY;
                prop_assert!(rtr.to_cols_array().iter().all(|x| x.abs() < 1e-5));
                prop_assert!((r.determinant() - 1.0).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn constraints_are_interpolated(cs in constraints(8)) {
        let pts: Vec<DVec3> = cs.iter().map(|c| c.0).collect();
        for polar in [PolarMethod::Svd, PolarMethod::Iterative] {
            let qs = field_at(&cs, &pts, polar);
            for (q, (_, r, e)) in qs.iter().zip(&cs) {
                prop_assert!(dir_angle(*q * *r, *e) < 1e-4, "e(p_n) misses e_n by {}", dir_angle(*q * *r, *e));
            }
        }
    }

    #[test]
    fn field_is_continuous(cs in constraints(6), q in point(), dir in unit_vec()) {
        // Continuity, not a Lipschitz bound (ill-conditioned configurations are steep but not
        // broken): the change shrinks with the step, and is small for a small step.
        prop_assume!(cs.iter().all(|c| c.0.distance(q) > 0.05));
        let qs = field_at(&cs, &[q, q + dir * 1e-3, q + dir * 1e-5], PolarMethod::Svd);
        let (big, small) = (angle(qs[0], qs[1]), angle(qs[0], qs[2]));
        prop_assert!(small < 1e-5 || small < 0.1 * big, "no convergence: {big} then {small} rad");
        prop_assert!(small < 1e-2, "jump of {small} rad for a step of 1e-5");
    }

    #[test]
    fn field_is_continuous_into_a_constraint(cs in constraints(6), dir in unit_vec()) {
        // R(q) → R(pₙ) as q → pₙ: the twist at pₙ is the limit chosen by the other constraints.
        let p = cs[0].0;
        let qs = field_at(&cs, &[p, p + dir * 1e-3, p + dir * 1e-5], PolarMethod::Svd);
        let (big, small) = (angle(qs[0], qs[1]), angle(qs[0], qs[2]));
        prop_assert!(small < 1e-5 || small < 0.1 * big, "no convergence at a constraint: {big} then {small} rad");
    }

    #[test]
    fn field_is_equivariant(cs in constraints(6), qs in prop::collection::vec(point(), 1..8),
                            axis in unit_vec(), ang in -3.0f64..3.0, shift in point()) {
        let rot = DQuat::from_axis_angle(axis, ang);
        let moved: Vec<_> = cs.iter().map(|(p, r, e)| (rot * *p + shift, rot * *r, rot * *e)).collect();
        let qs2: Vec<DVec3> = qs.iter().map(|q| rot * *q + shift).collect();
        let a = field_at(&cs, &qs, PolarMethod::Svd);
        let b = field_at(&moved, &qs2, PolarMethod::Svd);
        for (qa, qb) in a.iter().zip(&b) {
            let expect = rot * *qa * rot.conjugate();
            prop_assert!(angle(expect, *qb) < 2e-4, "not equivariant: {}", angle(expect, *qb));
        }
    }

    #[test]
    fn field_is_scale_invariant(cs in constraints(6), qs in prop::collection::vec(point(), 1..8)) {
        let a = field_at(&cs, &qs, PolarMethod::Svd);
        for s in [1e-4, 1e4, 1e-6, 1e6] {
            let scaled: Vec<_> = cs.iter().map(|(p, r, e)| (*p * s, *r, *e)).collect();
            let qs2: Vec<DVec3> = qs.iter().map(|q| *q * s).collect();
            let b = field_at(&scaled, &qs2, PolarMethod::Svd);
            for (qa, qb) in a.iter().zip(&b) {
                prop_assert!(angle(*qa, *qb) < 1e-4, "scale {s}: differs by {}", angle(*qa, *qb));
            }
        }
    }
}

#[test]
fn no_constraints_is_identity() {
    let f = Field::new(&[], vec![]).unwrap();
    let out = f
        .rotation_field(
            &[0.0, 1.0, 2.0],
            Distances::Euclidean,
            None,
            PolarMethod::Svd,
        )
        .unwrap();
    assert_eq!(out, vec![0.0, 0.0, 0.0, 1.0]);
}

#[test]
fn antiparallel_edit_is_a_half_turn_everywhere() {
    let r = DVec3::new(0.0, 0.6, 0.8);
    let cs = [(DVec3::ZERO, r, -r)];
    for q in field_at(
        &cs,
        &[DVec3::ZERO, DVec3::ONE, DVec3::new(5.0, -3.0, 1.0)],
        PolarMethod::Svd,
    ) {
        assert!((q * r + r).length() < 1e-6);
        assert!((q.w).abs() < 1e-6, "a half turn has w = 0");
    }
}

#[test]
fn single_constraint_is_the_smallest_rotation() {
    let r = DVec3::Z;
    let e = DVec3::new(0.0, 1.0, 1.0).normalize();
    let qs = field_at(
        &[(DVec3::ZERO, r, e)],
        &[DVec3::new(3.0, 1.0, 0.0)],
        PolarMethod::Iterative,
    );
    let expect = DQuat::from_rotation_arc(r, e);
    assert!(angle(qs[0], expect) < 1e-6);
}

#[test]
fn coincident_constraints_are_averaged() {
    let p = DVec3::new(0.2, 0.1, 0.0);
    let r = DVec3::Z;
    let e1 = DVec3::new(0.5, 0.0, 1.0).normalize();
    let e2 = DVec3::new(-0.5, 0.0, 1.0).normalize();
    let cs = [(p, r, e1), (p, r, e2)];
    let qs = field_at(&cs, &[p, p + DVec3::X], PolarMethod::Svd);
    for q in qs {
        // e1 and e2 are symmetric about r: their average is r itself.
        assert!(dir_angle(q * r, r) < 1e-6);
    }
}

#[test]
fn thousand_constraints_and_all_at_one_point() {
    let mut cs = Vec::new();
    for i in 0..1000 {
        let t = i as f64 * 0.01;
        let p = DVec3::new(t.cos() * (1.0 + t), t.sin(), 0.1 * t);
        let r = DVec3::new(t.sin(), 0.3, 1.0).normalize();
        let e = DVec3::new(0.2, t.cos(), 1.0).normalize();
        cs.push((p, r, e));
    }
    let pts: Vec<DVec3> = cs
        .iter()
        .step_by(97)
        .map(|c| c.0)
        .chain([DVec3::new(0.3, 0.3, 0.3)])
        .collect();
    let qs = field_at(&cs, &pts, PolarMethod::Svd);
    for (q, c) in qs.iter().zip(cs.iter().step_by(97)) {
        assert!(dir_angle(*q * c.1, c.2) < 1e-4);
    }
    assert!(qs.iter().all(|q| q.is_finite()));
    // All constraints at one point: the field is ortho of their plain sum, everywhere.
    let same: Vec<_> = cs.iter().map(|c| (DVec3::ONE, c.1, c.2)).collect();
    let qs = field_at(
        &same,
        &[DVec3::ONE, DVec3::ZERO, DVec3::splat(-7.0)],
        PolarMethod::Svd,
    );
    assert!(angle(qs[0], qs[1]) < 1e-5 && angle(qs[1], qs[2]) < 1e-5);
}

#[test]
fn regions_localise_the_edit() {
    let r = DVec3::Z;
    let e = DVec3::new(0.0, 0.5, 1.0).normalize();
    let c = rows(&[(DVec3::ZERO, r, e), (DVec3::new(10.0, 0.0, 0.0), r, -r)]);
    let region = Region::euclidean([0.0, 0.0, 0.0], 1.0, 0.5, "regions[0]").unwrap();
    let f = Field::new(&c, vec![region]).unwrap();
    let pts = [
        0.0f32, 0.0, 0.0, 0.75, 0.0, 0.0, 2.0, 0.0, 0.0, 10.0, 0.0, 0.0,
    ];
    let qs = quats(
        &f.rotation_field(&pts, Distances::Euclidean, None, PolarMethod::Svd)
            .unwrap(),
    );
    // Inside: only the first constraint (the second is outside every region and acts nowhere).
    assert!(angle(qs[0], DQuat::from_rotation_arc(r, e)) < 1e-6);
    // In the border: part of the way.
    let part = angle(qs[1], DQuat::IDENTITY);
    assert!(part > 0.01 && part < angle(qs[0], DQuat::IDENTITY) - 0.01);
    // Outside the region, and at the outside constraint itself: unchanged.
    assert!(angle(qs[2], DQuat::IDENTITY) < 1e-7);
    assert!(angle(qs[3], DQuat::IDENTITY) < 1e-7);
}

#[test]
fn empty_region_changes_nothing_and_overlaps_blend() {
    let r = DVec3::Z;
    let e1 = DVec3::new(0.0, 0.5, 1.0).normalize();
    let e2 = DVec3::new(0.5, 0.0, 1.0).normalize();
    let c = rows(&[
        (DVec3::new(-0.5, 0.0, 0.0), r, e1),
        (DVec3::new(0.5, 0.0, 0.0), r, e2),
    ]);
    let regions = vec![
        Region::euclidean([-0.5, 0.0, 0.0], 0.8, 0.0, "a").unwrap(), // holds constraint 0 only
        Region::euclidean([0.5, 0.0, 0.0], 0.8, 0.0, "b").unwrap(),  // holds constraint 1 only
        Region::euclidean([0.0, 5.0, 0.0], 1.0, 0.2, "c").unwrap(),  // holds none
    ];
    let f = Field::new(&c, regions).unwrap();
    let pts = [0.0f32, 0.0, 0.0, 0.0, 5.0, 0.0, -0.9, 0.0, 0.0];
    let qs = quats(
        &f.rotation_field(&pts, Distances::Euclidean, None, PolarMethod::Svd)
            .unwrap(),
    );
    let (q1, q2) = (
        DQuat::from_rotation_arc(r, e1),
        DQuat::from_rotation_arc(r, e2),
    );
    // At the overlap both regions have a = 1: the edit is between the two.
    assert!(angle(qs[0], q1) > 0.05 && angle(qs[0], q2) > 0.05);
    assert!((angle(qs[0], q1) - angle(qs[0], q2)).abs() < 1e-6);
    // The constraint-less region leaves its area unchanged.
    assert!(angle(qs[1], DQuat::IDENTITY) < 1e-7);
    // Only region a: exactly constraint 0's rotation.
    assert!(angle(qs[2], q1) < 1e-6);
}

#[test]
fn geodesic_distances_infinite_means_unreachable() {
    let r = DVec3::Z;
    let e = DVec3::new(0.0, 0.5, 1.0).normalize();
    let e2 = DVec3::new(0.5, 0.0, 1.0).normalize();
    let c = rows(&[(DVec3::ZERO, r, e), (DVec3::X, r, e2)]);
    let f = Field::new(&c, vec![]).unwrap();
    // two points; the first constraint cannot reach point 1, neither reaches... nothing.
    let d = [0.5f32, f32::INFINITY, 0.5, 0.25];
    let qs = quats(
        &f.rotation_field(
            &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
            Distances::Given(&d),
            None,
            PolarMethod::Svd,
        )
        .unwrap(),
    );
    assert!(angle(qs[1], DQuat::from_rotation_arc(r, e2)) < 1e-6);
    let bad = [f32::NAN, 1.0, 1.0, 1.0];
    assert!(f
        .rotation_field(
            &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
            Distances::Given(&bad),
            None,
            PolarMethod::Svd
        )
        .is_err());
}

#[test]
fn per_pixel_matches_per_point() {
    let cs = [
        (
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(0.0, 0.3, 1.0).normalize(),
            DVec3::new(0.2, 0.3, 1.0).normalize(),
        ),
        (
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.1, -0.3, 1.0).normalize(),
            DVec3::new(-0.4, 0.0, 1.0).normalize(),
        ),
    ];
    let f = Field::new(&rows(&cs), vec![]).unwrap();
    let eye = [0.5, -3.0, 2.0];
    let mut pos = Vec::new();
    let mut nrm = Vec::new();
    for i in 0..50 {
        let x = i as f32 * 0.03 - 0.2;
        pos.extend_from_slice(&[x, 0.1 * x, 0.0]);
        nrm.extend_from_slice(&[0.0, 0.1, 1.0]);
    }
    for polar in [PolarMethod::Svd, PolarMethod::Iterative] {
        let dirs = f
            .edited_directions(&pos, &nrm, eye, Distances::Euclidean, polar, 10)
            .unwrap();
        let rots = quats(
            &f.rotation_field(&pos, Distances::Euclidean, None, PolarMethod::Svd)
                .unwrap(),
        );
        for i in 0..50 {
            let q = DVec3::new(
                pos[3 * i] as f64,
                pos[3 * i + 1] as f64,
                pos[3 * i + 2] as f64,
            );
            let n = DVec3::new(0.0, 0.1, 1.0);
            let r =
                rokeby_core::reflection::field::reflect_dir(q, n, DVec3::from_array(eye)).unwrap();
            let e = DVec3::new(
                dirs[3 * i] as f64,
                dirs[3 * i + 1] as f64,
                dirs[3 * i + 2] as f64,
            );
            assert!(dir_angle(rots[i] * r, e) < 1e-5);
        }
    }
}

#[test]
fn bad_constraints_are_errors_not_panics() {
    let zero_r = [0.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    assert!(Field::new(&zero_r, vec![]).is_err());
    let nan_p = [f32::NAN, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0];
    assert!(Field::new(&nan_p, vec![]).is_err());
    let f = Field::new(&[0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0], vec![]).unwrap();
    assert!(f
        .rotation_field(
            &[f32::INFINITY, 0.0, 0.0],
            Distances::Euclidean,
            None,
            PolarMethod::Svd
        )
        .is_err());
    assert!(f
        .rotation_field(&[], Distances::Euclidean, None, PolarMethod::Svd)
        .is_err());
    assert!(f
        .edited_directions(
            &[0.0, 0.0, 0.0],
            &[0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            Distances::Euclidean,
            PolarMethod::Svd,
            1
        )
        .is_err());
    assert!(f
        .edited_directions(
            &[0.0, 0.0, 1.0],
            &[0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0],
            Distances::Euclidean,
            PolarMethod::Svd,
            1
        )
        .is_err());
}

// --- eq. 7 in closed form for renderers (FieldOutput::ViewBlend + view_blend) -------------------

fn rotation() -> impl Strategy<Value = DQuat> {
    (unit_vec(), 0.0f64..std::f64::consts::PI)
        .prop_map(|(axis, angle)| DQuat::from_axis_angle(axis, angle))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, rng_seed: RngSeed::Fixed(0x2009_7E0C), failure_persistence: None, .. ProptestConfig::default() })]

    /// view_blend(R, a, r) = ortho(a R + (1 − a) r rᵀ) r wherever the in-plane factor is a proper
    /// rotation (a + (1 − a) cos φ > 0), which is eq. 7's domain of continuity.
    #[test]
    fn view_blend_is_eq7_in_closed_form(rot in rotation(), a in 0.0f64..=1.0, r in unit_vec()) {
        let s = rot.inverse() * r;
        prop_assume!(a + (1.0 - a) * r.dot(s) > 0.05);
        let m = DMat3::from_quat(rot) * a + DMat3::from_cols(r * r.x, r * r.y, r * r.z) * (1.0 - a);
        let want = rokeby_core::reflection::polar::ortho_svd(&m) * r;
        let got = rokeby_core::reflection::field::view_blend(rot, a, r);
        prop_assert!((got.length() - 1.0).abs() < 1e-9);
        prop_assert!(dir_angle(got, want) < 1e-6, "{} rad", dir_angle(got, want));
    }

    /// The stored parts (R, a) blended per point give the per-pixel path's edited directions,
    /// with one region (exact) for any constraints, points, normals and eye.
    #[test]
    fn view_blend_parts_reproduce_the_per_pixel_field(cs in constraints(6), qs in prop::collection::vec((point(), unit_vec()), 1..24), eye in point()) {
        let c = rows(&cs);
        let region = Region::euclidean([0.1, -0.2, 0.0], 0.9, 0.6, "regions[0]").unwrap();
        let f = Field::new(&c, vec![region]).unwrap();
        let eye = eye * 5.0 + DVec3::new(0.0, 0.0, 6.0);
        let pts: Vec<f32> = qs.iter().flat_map(|(p, _)| [p.x as f32, p.y as f32, p.z as f32]).collect();
        let nrm: Vec<f32> = qs.iter().flat_map(|(_, n)| [n.x as f32, n.y as f32, n.z as f32]).collect();
        let want = f.edited_directions(&pts, &nrm, eye.to_array(), Distances::Euclidean, PolarMethod::Svd, 8).unwrap();
        let parts = f.rotation_field_as(&pts, Distances::Euclidean, None, PolarMethod::Svd, rokeby_core::reflection::field::FieldOutput::ViewBlend).unwrap();
        let r: Vec<f32> = qs.iter().flat_map(|(p, n)| {
            let d = rokeby_core::reflection::field::reflect_dir(*p, *n, eye).unwrap();
            [d.x as f32, d.y as f32, d.z as f32]
        }).collect();
        let got = rokeby_core::reflection::field::view_blend_directions(&parts, &r, false).unwrap();
        let by_ramp = rokeby_core::reflection::field::view_blend_directions(&parts, &r, true).unwrap();
        prop_assert!(got.iter().zip(&by_ramp).all(|(a, b)| (a - b).abs() < 1e-5), "smooth_step(u) is a for one Euclidean region");
        for i in 0..qs.len() {
            let p = &parts[6 * i..6 * i + 6];
            let rot = DQuat::from_xyzw(p[0] as f64, p[1] as f64, p[2] as f64, p[3] as f64).normalize();
            let rr = DVec3::new(r[3 * i] as f64, r[3 * i + 1] as f64, r[3 * i + 2] as f64);
            // Outside eq. 7's continuous domain both answers are legitimate closest rotations.
            prop_assume!(p[4] as f64 + (1.0 - p[4] as f64) * rr.dot(rot.inverse() * rr) > 0.05);
            let g = DVec3::new(got[3 * i] as f64, got[3 * i + 1] as f64, got[3 * i + 2] as f64);
            let w = DVec3::new(want[3 * i] as f64, want[3 * i + 1] as f64, want[3 * i + 2] as f64);
            prop_assert!(dir_angle(g, w) < 2e-5, "point {i}: {} rad", dir_angle(g, w));
        }
    }
}

#[test]
fn view_blend_ends_and_bad_input() {
    let rot = DQuat::from_axis_angle(DVec3::X, 1.0);
    let r = DVec3::new(0.0, 0.6, 0.8);
    assert!(
        dir_angle(
            rokeby_core::reflection::field::view_blend(rot, 1.0, r),
            rot * r
        ) < 1e-12
    );
    assert!(dir_angle(rokeby_core::reflection::field::view_blend(rot, 0.0, r), r) < 1e-12);
    assert!(
        dir_angle(
            rokeby_core::reflection::field::view_blend(DQuat::IDENTITY, 0.5, r),
            r
        ) < 1e-12
    );
    assert!(
        rokeby_core::reflection::field::view_blend_directions(&[0.0; 6], &[0.0; 6], false).is_err()
    );
    assert!(rokeby_core::reflection::field::view_blend_directions(
        &[0.0, 0.0, 0.0, 1.0, f32::NAN, 0.0],
        &[0.0, 0.0, 1.0],
        false
    )
    .is_err());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, rng_seed: RngSeed::Fixed(0x2009_7E0D), failure_persistence: None, .. ProptestConfig::default() })]

    /// The per-point rotation vectors made from the parts are the view-independent field
    /// (eq. 7 towards I) that rotation_field returns without a view, for one region.
    #[test]
    fn view_blend_rotation_vectors_are_the_view_independent_field(cs in constraints(6), qs in prop::collection::vec(point(), 1..24)) {
        let region = Region::euclidean([0.1, -0.2, 0.0], 0.9, 0.6, "regions[0]").unwrap();
        let f = Field::new(&rows(&cs), vec![region]).unwrap();
        let pts: Vec<f32> = qs.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
        let parts = f.rotation_field_as(&pts, Distances::Euclidean, None, PolarMethod::Svd, rokeby_core::reflection::field::FieldOutput::ViewBlend).unwrap();
        let want = f.rotation_field_as(&pts, Distances::Euclidean, None, PolarMethod::Svd, rokeby_core::reflection::field::FieldOutput::RotationVector).unwrap();
        let got = rokeby_core::reflection::field::view_blend_rotation_vectors(&parts).unwrap();
        for (g, w) in got.chunks_exact(3).zip(want.chunks_exact(3)) {
            let (g, w) = (DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64), DVec3::new(w[0] as f64, w[1] as f64, w[2] as f64));
            let (qg, qw) = (DQuat::from_scaled_axis(g), DQuat::from_scaled_axis(w));
            prop_assert!(angle(qg, qw) < 2e-5, "{} rad", angle(qg, qw));
        }
    }
}

#[test]
fn view_blend_render_rows_keep_each_polygon_in_one_hemisphere() {
    use rokeby_core::reflection::field::view_blend_render_rows as rows_of;
    let q = DQuat::from_axis_angle(DVec3::Z, 3.0);
    let parts: Vec<f32> = [q, -DQuat::from_axis_angle(DVec3::Z, 3.1)]
        .iter()
        .enumerate()
        .flat_map(|(i, q)| {
            [
                q.x as f32,
                q.y as f32,
                q.z as f32,
                q.w as f32,
                0.5,
                0.25 + i as f32,
            ]
        })
        .collect();
    // One triangle (0, 1, 1) whose first corner is vertex 0: the quaternions straddle the seam.
    let r = rows_of(&parts, &[0, 1, 1], &[0, 0, 0], false).unwrap();
    assert!(r.per_corner && r.xyz.len() == 9);
    for c in 0..3 {
        let v = r.xyz[3 * c] * r.xyz[0]
            + r.xyz[3 * c + 1] * r.xyz[1]
            + r.xyz[3 * c + 2] * r.xyz[2]
            + r.wa[3 * c] * r.wa[0];
        assert!(v > 0.0, "corner {c} in the other hemisphere");
        assert_eq!(r.wa[3 * c + 1], 0.5);
    }
    let ramp = rows_of(&parts, &[0, 1], &[0, 0], true).unwrap();
    assert_eq!(
        (ramp.wa[1], ramp.wa[2], ramp.wa[4], ramp.wa[5]),
        (-1.0, 0.25, -1.0, 1.25)
    );
    // Without a seam the rows are per vertex.
    let same: Vec<f32> = parts[..6]
        .iter()
        .chain(parts[..6].iter())
        .copied()
        .collect();
    let r = rows_of(&same, &[0, 1, 1], &[0, 0, 0], false).unwrap();
    assert!(!r.per_corner && r.xyz.len() == 6);
    assert!(rows_of(&parts, &[0, 2], &[0, 0], false).is_err());
    assert!(rows_of(&parts, &[0, -1], &[0, 0], false).is_err());
    assert!(rows_of(&parts, &[0], &[0, 0], false).is_err());
    assert!(rokeby_core::reflection::field::view_blend_rotation_vectors(&parts[..5]).is_err());
}
