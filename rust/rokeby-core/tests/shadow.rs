//! Freeform shadow boundary editing (Mattausch et al.): silhouettes against the closed-form
//! circle of a sphere, the BVH against brute force, MLS identities and exact affine maps, the
//! shadow mesh at rest and after a drag, handles on a ground plane, and every bad input.

use glam::{DVec2, DVec3};
use proptest::prelude::*;
use rokeby_core::geometry::bvh::Bvh;
use rokeby_core::shadows::light_space::LightFrame;
use rokeby_core::shadows::mls2d::{sinusoidal_noise, Mls2d, MlsStyle};
use rokeby_core::shadows::shadow::{Drag, ShadowEditor};
use rokeby_core::shadows::shadow_mesh::falloff_factor;
use rokeby_core::shadows::silhouette::{silhouettes, ClosedMesh, Light};

/// A UV sphere (poles + `lat`−1 rings of `lon` vertices), faces counter-clockwise from outside.
fn sphere(c: DVec3, r: f64, lat: usize, lon: usize) -> (Vec<f32>, Vec<i64>) {
    let mut v = vec![c + DVec3::Z * r];
    for i in 1..lat {
        let th = std::f64::consts::PI * i as f64 / lat as f64;
        for j in 0..lon {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / lon as f64;
            v.push(c + r * DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
        }
    }
    v.push(c - DVec3::Z * r);
    let south = (v.len() - 1) as i64;
    let ring = |i: usize, j: usize| (1 + (i - 1) * lon + j % lon) as i64;
    let mut f = Vec::new();
    for j in 0..lon {
        f.extend_from_slice(&[0, ring(1, j), ring(1, j + 1)]);
    }
    for i in 1..lat - 1 {
        for j in 0..lon {
            let (a, b, cc, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            f.extend_from_slice(&[a, cc, d, a, d, b]);
        }
    }
    for j in 0..lon {
        f.extend_from_slice(&[south, ring(lat - 1, j + 1), ring(lat - 1, j)]);
    }
    let vf = v
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    (vf, f)
}

/// A square ground plane z = `z` of half-size `h`, facing +z.
fn plane(z: f32, h: f32) -> (Vec<f32>, Vec<i64>) {
    (
        vec![-h, -h, z, h, -h, z, h, h, z, -h, h, z],
        vec![0, 1, 2, 0, 2, 3],
    )
}

fn signed_volume(v: &[f32], f: &[i64]) -> f64 {
    let p = |i: i64| {
        DVec3::new(
            v[3 * i as usize] as f64,
            v[3 * i as usize + 1] as f64,
            v[3 * i as usize + 2] as f64,
        )
    };
    f.chunks_exact(3)
        .map(|t| p(t[0]).dot(p(t[1]).cross(p(t[2]))) / 6.0)
        .sum()
}

#[test]
fn sphere_silhouette_is_the_tangent_circle() {
    let (c, r) = (DVec3::new(0.3, -0.2, 1.5), 0.5);
    let (v, f) = sphere(c, r, 64, 128);
    assert!(
        signed_volume(&v, &f) > 0.0,
        "test sphere must be outward oriented"
    );
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    let l = c + DVec3::new(0.4, 0.2, 3.0);
    let loops = silhouettes(&mesh, &Light::Point(l)).unwrap();
    assert_eq!(loops.len(), 1, "a sphere has one silhouette loop");
    // Tangent points p of rays from l: (p − c)·(p − l) = 0 → a circle around c + r²/D u.
    let dvec = l - c;
    let dd = dvec.length();
    let u = dvec / dd;
    let centre = c + u * (r * r / dd);
    let rho = r * (1.0 - r * r / (dd * dd)).sqrt();
    for s in &loops[0].vertices {
        let q = s.position - centre;
        let along = q.dot(u);
        let radial = (q - u * along).length();
        assert!(along.abs() < 2e-3 * r, "off the circle's plane by {along}");
        assert!((radial - rho).abs() < 2e-3 * r, "radius {radial} vs {rho}");
    }
    let want = 2.0 * std::f64::consts::PI * rho;
    assert!(
        (loops[0].length - want).abs() < 5e-3 * want,
        "length {} vs {want}",
        loops[0].length
    );
    // Ends of each edge face opposite ways.
    for s in &loops[0].vertices {
        let g = |i: u32| mesh.normals[i as usize].dot(l - mesh.vertices[i as usize]);
        assert!(g(s.back) <= 0.0 && g(s.front) > 0.0);
        assert!((0.0..=1.0).contains(&s.alpha));
    }
    // Directional light: the great circle orthogonal to the direction.
    let d = DVec3::new(0.2, -0.1, -1.0).normalize();
    let loops = silhouettes(&mesh, &Light::Directional(d)).unwrap();
    assert_eq!(loops.len(), 1);
    for s in &loops[0].vertices {
        let q = s.position - c;
        assert!(q.dot(d).abs() < 2e-3 * r);
        assert!(((q - d * q.dot(d)).length() - r).abs() < 2e-3 * r);
    }
}

#[test]
fn silhouette_loop_is_connected_and_oriented() {
    let (v, f) = sphere(DVec3::ZERO, 1.0, 16, 24);
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    let loops = silhouettes(&mesh, &Light::Point(DVec3::new(0.1, 0.2, 5.0))).unwrap();
    let l = &loops[0];
    // Consecutive silhouette vertices share a face: their edges have a common vertex.
    let n = l.len();
    for k in 0..n {
        let a = l.vertices[k];
        let b = l.vertices[(k + 1) % n];
        let ea = [a.back, a.front];
        assert!(
            ea.contains(&b.back) || ea.contains(&b.front),
            "vertices {k} and {} are not in one face",
            (k + 1) % n
        );
    }
}

fn lcg(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64) / ((1u64 << 53) as f64)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Watertightness: rays aimed exactly at shared edges and vertices of a randomly jittered,
    /// tilted, offset triangulated grid always hit it (BVH and brute force alike),
    /// so no shadow handle falls through a crack between receiver triangles.
    #[test]
    fn rays_through_shared_edges_and_vertices_hit(seed in any::<u64>(), scale_exp in -6i32..7, n in 2usize..12) {
        let mut s = seed;
        let mut rnd = || lcg(&mut s) * 2.0 - 1.0;
        let scale = 10f64.powi(scale_exp);
        let offset = DVec3::new(rnd(), rnd(), rnd()) * 1e3 * scale;
        let tilt = glam::DQuat::from_euler(glam::EulerRot::XYZ, rnd(), rnd(), rnd());
        let mut grid = vec![DVec3::ZERO; (n + 1) * (n + 1)];
        for j in 0..=n {
            for i in 0..=n {
                let jit = if i > 0 && i < n && j > 0 && j < n { DVec3::new(rnd(), rnd(), rnd()) * 0.3 } else { DVec3::ZERO };
                grid[j * (n + 1) + i] = offset + tilt * ((DVec3::new(i as f64, j as f64, 0.0) + jit) * scale);
            }
        }
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (a, b, c, d) = (j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i, (j + 1) * (n + 1) + i + 1);
                tris.push([grid[a], grid[b], grid[d]]);
                tris.push([grid[a], grid[d], grid[c]]);
            }
        }
        let normal = tilt * DVec3::Z;
        let bvh = Bvh::new(tris.clone(), "grid").unwrap();
        let mut targets = Vec::new();
        for t in &tris {
            for k in 0..3 {
                let w = rnd() * 0.5 + 0.5;
                targets.push(t[k] * w + t[(k + 1) % 3] * (1.0 - w)); // on an edge
            }
        }
        for j in 1..n {
            for i in 1..n {
                targets.push(grid[j * (n + 1) + i]); // interior vertices
            }
        }
        for p in targets {
            let d = (normal + DVec3::new(rnd(), rnd(), rnd()) * 0.5).normalize();
            let o = p + d * (5.0 * scale);
            for hit in [bvh.intersect(o, -d, 0.0, f64::INFINITY), bvh.intersect_brute_force(o, -d, 0.0, f64::INFINITY)] {
                prop_assert!(hit.is_some(), "ray at {:?} through an edge or vertex missed", p);
                // At the aimed point, or earlier where the jittered (non-planar) grid folds over it.
                prop_assert!(hit.unwrap().t < 5.0 * scale * (1.0 + 1e-9));
            }
        }
    }

    #[test]
    fn bvh_matches_brute_force(seed in any::<u64>(), ntri in 1usize..300) {
        let mut s = seed;
        let mut rnd = || lcg(&mut s) * 2.0 - 1.0;
        let tris: Vec<[DVec3; 3]> = (0..ntri).map(|_| {
            let c = DVec3::new(rnd(), rnd(), rnd()) * 3.0;
            [c + DVec3::new(rnd(), rnd(), rnd()) * 0.5, c + DVec3::new(rnd(), rnd(), rnd()) * 0.5, c + DVec3::new(rnd(), rnd(), rnd()) * 0.5]
        }).collect();
        let bvh = Bvh::new(tris, "tris").unwrap();
        let rays: Vec<(DVec3, DVec3)> = (0..64).map(|_| (DVec3::new(rnd(), rnd(), rnd()) * 4.0, DVec3::new(rnd(), rnd(), rnd()))).collect();
        let many = bvh.intersect_many(&rays, 0.0, f64::INFINITY);
        for (k, &(o, d)) in rays.iter().enumerate() {
            let a = bvh.intersect(o, d, 0.0, f64::INFINITY);
            let b = bvh.intersect_brute_force(o, d, 0.0, f64::INFINITY);
            prop_assert_eq!(a.is_some(), b.is_some());
            prop_assert_eq!(a, many[k]);
            if let (Some(a), Some(b)) = (a, b) {
                prop_assert!((a.t - b.t).abs() <= 1e-12 * a.t.max(1.0));
            }
        }
    }

    #[test]
    fn mls_at_rest_is_identity(seed in any::<u64>(), n in 1usize..8, style in 0usize..3) {
        let mut s = seed;
        let mut rnd = || lcg(&mut s) * 2.0 - 1.0;
        let p: Vec<DVec2> = (0..n).map(|_| DVec2::new(rnd(), rnd())).collect();
        let style = [MlsStyle::Affine, MlsStyle::Similarity, MlsStyle::Rigid][style];
        let m = Mls2d::new(p.clone(), p.clone(), style, 1.0).unwrap();
        for _ in 0..20 {
            let v = DVec2::new(rnd(), rnd()) * 2.0;
            prop_assert!((m.deform(v) - v).length() < 1e-9, "{:?} moved to {:?}", v, m.deform(v));
        }
        for &pi in &p {
            prop_assert!((m.deform(pi) - pi).length() < 1e-12);
        }
    }

    #[test]
    fn mls_affine_reproduces_affine_maps(seed in any::<u64>(), n in 3usize..8) {
        let mut s = seed;
        let mut rnd = || lcg(&mut s) * 2.0 - 1.0;
        let p: Vec<DVec2> = (0..n).map(|_| DVec2::new(rnd(), rnd())).collect();
        // Skip nearly collinear control sets (the affine fit is then ill-posed).
        let area = (p[1] - p[0]).perp_dot(p[2] - p[0]).abs();
        prop_assume!(area > 0.05);
        let a = glam::DMat2::from_cols(DVec2::new(rnd(), rnd()) + DVec2::X, DVec2::new(rnd(), rnd()) + DVec2::Y);
        let t = DVec2::new(rnd(), rnd());
        let q: Vec<DVec2> = p.iter().map(|&x| a * x + t).collect();
        let m = Mls2d::new(p, q, MlsStyle::Affine, 1.0).unwrap();
        for _ in 0..20 {
            let v = DVec2::new(rnd(), rnd()) * 2.0;
            let want = a * v + t;
            prop_assert!((m.deform(v) - want).length() < 1e-8 * (1.0 + want.length()));
        }
    }

    #[test]
    fn mls_similarity_and_rigid_reproduce_their_maps(seed in any::<u64>(), n in 2usize..8, angle in -3.0f64..3.0, scale in 0.3f64..3.0) {
        let mut s = seed;
        let mut rnd = || lcg(&mut s) * 2.0 - 1.0;
        let p: Vec<DVec2> = (0..n).map(|_| DVec2::new(rnd(), rnd())).collect();
        prop_assume!((p[1] - p[0]).length() > 0.05);
        let rot = DVec2::from_angle(angle);
        let t = DVec2::new(rnd(), rnd());
        for (style, k) in [(MlsStyle::Similarity, scale), (MlsStyle::Rigid, 1.0)] {
            let q: Vec<DVec2> = p.iter().map(|&x| rot.rotate(x) * k + t).collect();
            let m = Mls2d::new(p.clone(), q, style, 1.0).unwrap();
            for _ in 0..10 {
                let v = DVec2::new(rnd(), rnd()) * 2.0;
                let want = rot.rotate(v) * k + t;
                prop_assert!((m.deform(v) - want).length() < 1e-8 * (1.0 + want.length()), "{:?}", style);
            }
        }
    }

    #[test]
    fn light_frame_round_trips(x in -1.0f64..1.0, y in -1.0f64..1.0, z in 0.0f64..1.0, point in any::<bool>()) {
        let (v, _) = sphere(DVec3::new(0.0, 0.0, 1.0), 0.5, 8, 12);
        let verts: Vec<DVec3> = v.chunks_exact(3).map(|c| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64)).collect();
        let light = if point { Light::Point(DVec3::new(0.5, 0.3, 4.0)) } else { Light::Directional(DVec3::new(0.1, 0.2, -1.0)) };
        let fr = LightFrame::new(light, &verts).unwrap();
        let c = DVec3::new(x, y, z);
        prop_assert!((fr.to_frustum(fr.from_frustum(c)) - c).length() < 1e-9);
        for p in &verts {
            let q = fr.to_frustum(*p);
            prop_assert!(q.x.abs() <= 1.0 + 1e-9 && q.y.abs() <= 1.0 + 1e-9 && q.z >= -1e-9 && q.z <= 1.0 + 1e-9);
        }
    }
}

#[test]
fn sinusoidal_noise_offsets_along_the_normal() {
    let pts: Vec<DVec2> = (0..50).map(|i| DVec2::new(i as f64 * 0.1, 0.0)).collect();
    assert_eq!(sinusoidal_noise(&pts, false, 0.0, 3.0).unwrap(), pts);
    let out = sinusoidal_noise(&pts, false, 0.2, 3.0).unwrap();
    for (i, (a, b)) in pts.iter().zip(&out).enumerate() {
        let u = i as f64 * 0.1;
        // t = v_{i−1} − v_{i+1} = (−0.2, 0) → n = (0, −1).
        assert!((b.x - a.x).abs() < 1e-12);
        assert!(
            (b.y - (-0.2 * (3.0 * u).sin())).abs() < 1e-12,
            "{i}: {}",
            b.y
        );
    }
    assert!(sinusoidal_noise(&pts, false, f64::NAN, 1.0).is_err());
}

#[test]
fn falloff_follows_the_angle() {
    let a = DVec3::Z;
    let b = DVec3::new(0.0, (20f64).to_radians().sin(), (20f64).to_radians().cos());
    assert_eq!(falloff_factor(a, b, 0.0).unwrap(), 1.0);
    assert!(
        (falloff_factor(a, b, 4.0).unwrap() - (20f64).to_radians().cos().powi(4)).abs() < 1e-12
    );
    assert_eq!(falloff_factor(a, -a, 2.0).unwrap(), 0.0);
    assert!(falloff_factor(a, b, -1.0).is_err());
    assert!(falloff_factor(DVec3::ZERO, b, 1.0).is_err());
}

/// A sphere of radius 0.5 at height 1.5 over the plane z = 0, lit from above.
fn scene(lat: usize, lon: usize) -> (ShadowEditor, DVec3) {
    let (v, f) = sphere(DVec3::new(0.0, 0.0, 1.5), 0.5, lat, lon);
    let (pv, pf) = plane(0.0, 20.0);
    let l = DVec3::new(0.2, 0.1, 5.0);
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    (
        ShadowEditor::new(mesh, &pv, &pf, Light::Point(l), 20, 2.5, 10.0).unwrap(),
        l,
    )
}

#[test]
fn handles_are_the_projected_silhouette() {
    let (ed, l) = scene(32, 48);
    assert_eq!(ed.loops().len(), 1);
    let hs = ed.handles(0, None).unwrap();
    for (h, s) in hs.iter().zip(&ed.loops()[0].vertices) {
        assert!(h.hit && !h.on_caster && h.triangle < 2);
        // The ray l → a meets z = 0 at l + (a − l)·l.z/(l.z − a.z).
        let a = s.position;
        let want = l + (a - l) * (l.z / (l.z - a.z));
        assert!(
            (h.position - want).length() < 1e-9,
            "{:?} vs {want:?}",
            h.position
        );
    }
    // An eye below the plane sees none of them; one above sees those not behind the sphere.
    let hidden = ed.handles(0, Some(DVec3::new(0.0, 0.0, -3.0))).unwrap();
    assert!(hidden.iter().all(|h| h.occluded));
    let eye = DVec3::new(1.0, 0.0, 4.0);
    let seen = ed.handles(0, Some(eye)).unwrap();
    let occ = seen.iter().filter(|h| h.occluded).count();
    assert!(
        occ > 0 && occ < seen.len(),
        "{occ} of {} occluded",
        seen.len()
    );
    // Against the analytic sphere, away from grazing lines of sight.
    let c = DVec3::new(0.0, 0.0, 1.5);
    for h in &seen {
        let d = h.position - eye;
        let t = ((c - eye).dot(d) / d.length_squared()).clamp(0.0, 1.0);
        let dist = (eye + d * t - c).length();
        if (dist - 0.5).abs() > 0.02 {
            assert_eq!(
                h.occluded,
                dist < 0.5,
                "line of sight passes {dist} from the centre"
            );
        }
    }
}

#[test]
fn shadow_mesh_at_rest_is_the_input() {
    let (mut ed, _) = scene(24, 32);
    let out = ed.shadow_mesh().unwrap();
    for (a, b) in out.iter().zip(&ed.caster().vertices) {
        assert!((*a - *b).length() < 1e-9, "{a:?} vs {b:?}");
    }
}

/// Drag the handle at the loop's vertex `m` outwards (or inwards) on the plane.
fn drag_radially(ed: &mut ShadowEditor, l: DVec3, m: usize, factor: f64) -> (Drag, DVec3) {
    let n = ed.loops()[0].len();
    let h = ed.handles(0, None).unwrap()[m].position;
    let centre = DVec3::new(l.x, l.y, 0.0) + (DVec3::new(0.0, 0.0, 1.5) - l) * (l.z / (l.z - 1.5));
    let centre = DVec3::new(centre.x, centre.y, 0.0);
    let e = centre + (h - centre) * factor;
    let d = Drag {
        loop_index: 0,
        fixed: ((m + n - n / 6) % n, (m + n / 6) % n),
        moved: m,
        target: e,
        style: MlsStyle::Affine,
        mls_alpha: 1.0,
        noise_amplitude: 0.0,
        noise_frequency: 0.0,
    };
    (d, e)
}

#[test]
fn dragging_a_handle_moves_the_boundary_and_the_shadow_mesh_follows() {
    let (mut ed, l) = scene(48, 64);
    let n = ed.loops()[0].len();
    let before = ed.handles(0, None).unwrap();
    let (d, e) = drag_radially(&mut ed, l, 0, 1.3);
    let r = ed.drag(&d).unwrap();
    // The dragged handle lands where the cursor is (a plane receiver: exactly).
    assert!(
        (r.handles[0].position - e).length() < 1e-9,
        "{:?} vs {e:?}",
        r.handles[0].position
    );
    // Handles outside the segment do not move.
    for (k, b) in before.iter().enumerate().take(n) {
        if !r.segment.contains(&k) {
            assert!((r.handles[k].position - b.position).length() < 1e-12);
        }
    }
    ed.commit();
    // The shadow mesh's own silhouette from the same light casts its shadow edge through e.
    let sm = ed.shadow_mesh().unwrap();
    let c = ed.caster();
    let flat: Vec<f32> = sm
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let faces: Vec<i64> = c
        .faces
        .iter()
        .flat_map(|f| f.iter().map(|&x| x as i64))
        .collect();
    let smesh = ClosedMesh::new(&flat, &faces, None).unwrap();
    let loops = silhouettes(&smesh, &Light::Point(l)).unwrap();
    let shadow: Vec<DVec3> = loops[0]
        .positions()
        .iter()
        .map(|&a| l + (a - l) * (l.z / (l.z - a.z)))
        .collect();
    let dist = |p: DVec3| {
        shadow
            .iter()
            .map(|q| (*q - p).length())
            .fold(f64::INFINITY, f64::min)
    };
    let moved = (e - before[0].position).length();
    assert!(
        dist(e) < 0.15 * moved,
        "shadow-mesh boundary {} from the dragged point (moved {moved})",
        dist(e)
    );
    // The far side of the shadow stays.
    let far = before[n / 2].position;
    assert!(dist(far) < 0.05 * moved, "far side moved by {}", dist(far));
    // And the original handle position is no longer on the boundary.
    assert!(dist(before[0].position) > 0.5 * moved);
}

#[test]
fn shrinking_takes_the_second_ray_through_back_faces() {
    let (mut ed, l) = scene(32, 48);
    let (d, e) = drag_radially(&mut ed, l, 0, 0.6);
    let r = ed.drag(&d).unwrap();
    // f is inside the sphere: its first hit is a back face, the second ray reaches the plane.
    let h = r.handles[0];
    assert!(h.hit && !h.on_caster);
    assert!(
        (h.position - e).length() < 1e-9,
        "{:?} vs {e:?}",
        h.position
    );
    // cancel() restores the rest state.
    ed.cancel();
    let out = ed.shadow_mesh().unwrap();
    assert!(out
        .iter()
        .zip(&ed.caster().vertices)
        .all(|(a, b)| (*a - *b).length() < 1e-9));
}

#[test]
fn noise_and_styles_keep_the_fixed_ends() {
    let (mut ed, l) = scene(32, 48);
    let n = ed.loops()[0].len();
    let rest = ed.silhouette(0).unwrap();
    for style in [MlsStyle::Affine, MlsStyle::Similarity, MlsStyle::Rigid] {
        let (mut d, _) = drag_radially(&mut ed, l, 5, 1.2);
        d.style = style;
        d.noise_amplitude = 0.02;
        d.noise_frequency = 40.0;
        let r = ed.drag(&d).unwrap();
        for &k in [d.fixed.0, d.fixed.1].iter() {
            assert!((r.silhouette[k] - rest[k]).length() < 1e-9);
        }
        let changed = (0..n)
            .filter(|&k| (r.silhouette[k] - rest[k]).length() > 1e-6)
            .count();
        assert!(changed > 3 && changed < n, "{style:?}: {changed}");
    }
}

#[test]
fn bad_inputs_are_errors() {
    let (v, f) = sphere(DVec3::new(0.0, 0.0, 1.5), 0.5, 12, 16);
    let (pv, pf) = plane(0.0, 20.0);
    // Open mesh: one face removed.
    let e = ClosedMesh::new(&v, &f[3..], None).unwrap_err().to_string();
    assert!(e.contains("closed mesh"), "{e}");
    // Flipped face: inconsistent orientation.
    let mut g = f.clone();
    g.swap(0, 1);
    assert!(ClosedMesh::new(&v, &g, None)
        .unwrap_err()
        .to_string()
        .contains("oriented"));
    assert!(ClosedMesh::new(&v, &[0, 1, 999], None).is_err());
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    // A light inside the caster's bounds.
    let e = ShadowEditor::new(
        mesh.clone(),
        &pv,
        &pf,
        Light::Point(DVec3::new(0.0, 0.0, 1.6)),
        3,
        2.5,
        10.0,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("inside the caster's volume"), "{e}");
    // No receiver under the light (the plane is above the sphere, the light below it).
    let e = ShadowEditor::new(
        mesh.clone(),
        &pv,
        &pf,
        Light::Point(DVec3::new(0.0, 0.0, 0.5)),
        3,
        2.5,
        10.0,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("no receiver under the light"), "{e}");
    let e = ShadowEditor::new(
        mesh.clone(),
        &[],
        &[],
        Light::Point(DVec3::new(0.0, 0.0, 5.0)),
        3,
        2.5,
        10.0,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("no receiver under the light"), "{e}");
    assert!(ShadowEditor::new(
        mesh.clone(),
        &pv,
        &pf,
        Light::Point(DVec3::new(f64::NAN, 0.0, 5.0)),
        3,
        2.5,
        10.0
    )
    .is_err());
    assert!(ShadowEditor::new(
        mesh.clone(),
        &pv,
        &pf,
        Light::Point(DVec3::new(0.0, 0.0, 5.0)),
        3,
        -1.0,
        10.0
    )
    .is_err());
    let e = ShadowEditor::new(
        mesh.clone(),
        &pv,
        &pf,
        Light::Point(DVec3::new(0.0, 0.0, 5.0)),
        10_000,
        2.5,
        10.0,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("no silhouette loop"), "{e}");
    let mut ed = ShadowEditor::new(
        mesh,
        &pv,
        &pf,
        Light::Point(DVec3::new(0.0, 0.0, 5.0)),
        3,
        2.5,
        10.0,
    )
    .unwrap();
    let d = Drag {
        loop_index: 0,
        fixed: (0, 0),
        moved: 1,
        target: DVec3::ZERO,
        style: MlsStyle::Rigid,
        mls_alpha: 1.0,
        noise_amplitude: 0.0,
        noise_frequency: 0.0,
    };
    assert!(ed.drag(&d).is_err());
    assert!(ed
        .drag(&Drag {
            fixed: (0, 4),
            moved: 4,
            ..d
        })
        .is_err());
    assert!(ed
        .drag(&Drag {
            loop_index: 7,
            fixed: (0, 4),
            ..d
        })
        .is_err());
    assert!(ed
        .drag(&Drag {
            fixed: (0, 4),
            moved: 9999,
            ..d
        })
        .is_err());
    assert!(ed
        .drag(&Drag {
            fixed: (0, 4),
            target: DVec3::NAN,
            ..d
        })
        .is_err());
    assert!(ed.handles(9, None).is_err());
}

/// A point light at 1e30 (a sun placed as a far lamp) behaves as the directional light it is
/// indistinguishable from: same handles, a finite shadow mesh that follows a drag. Closer than
/// FAR_LIGHT_RATIO radii it stays a point light.
#[test]
fn far_point_lights_are_directional() {
    let (v, f) = sphere(DVec3::new(0.0, 0.0, 1.5), 0.5, 32, 48);
    let (pv, pf) = plane(0.0, 20.0);
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    let c = DVec3::new(0.0, 0.0, 1.5);
    let sun = ShadowEditor::new(
        mesh.clone(),
        &pv,
        &pf,
        Light::Directional(DVec3::new(0.0, 0.0, -1.0)),
        20,
        2.5,
        10.0,
    )
    .unwrap();
    for far in [1e12, 1e30, 1e300] {
        let mut ed = ShadowEditor::new(
            mesh.clone(),
            &pv,
            &pf,
            Light::Point(c + DVec3::new(0.0, 0.0, far)),
            20,
            2.5,
            10.0,
        )
        .unwrap();
        assert!(matches!(ed.light(), Light::Directional(_)), "{far}");
        let (a, b) = (ed.handles(0, None).unwrap(), sun.handles(0, None).unwrap());
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert!(
                (x.position - y.position).length() < 1e-9,
                "{far}: {:?} vs {:?}",
                x.position,
                y.position
            );
        }
        let n = a.len();
        let e = DVec3::new(a[0].position.x * 1.3, a[0].position.y * 1.3, 0.0);
        let d = Drag {
            loop_index: 0,
            fixed: ((n - n / 6) % n, n / 6),
            moved: 0,
            target: e,
            style: MlsStyle::Affine,
            mls_alpha: 1.0,
            noise_amplitude: 0.0,
            noise_frequency: 0.0,
        };
        let r = ed.drag(&d).unwrap();
        assert!((r.handles[0].position - e).length() < 1e-9);
        ed.commit();
        let sm = ed.shadow_mesh().unwrap();
        assert!(sm.iter().all(|p| p.is_finite()));
        let moved = sm
            .iter()
            .zip(&ed.caster().vertices)
            .map(|(p, q)| (*p - *q).length())
            .fold(0.0, f64::max);
        assert!(
            moved > 0.05 && moved < 1.0,
            "{far}: the shadow mesh moved by {moved}"
        );
    }
    let near = ShadowEditor::new(
        mesh.clone(),
        &pv,
        &pf,
        Light::Point(c + DVec3::new(0.0, 0.0, 1e5)),
        20,
        2.5,
        10.0,
    )
    .unwrap();
    assert!(matches!(near.light(), Light::Point(_)));
}

/// Solver weights outside [1e-6, 1e6] are refused by name (w² beside Laplacian entries ~1 would
/// drown one or the other in rounding); the ends of the range still give a finite shadow mesh.
#[test]
fn extreme_solver_weights_are_bounded() {
    let (v, f) = sphere(DVec3::new(0.0, 0.0, 1.5), 0.5, 24, 32);
    let (pv, pf) = plane(0.0, 20.0);
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    let l = Light::Point(DVec3::new(0.2, 0.1, 5.0));
    for (wz, cw, name) in [
        (2.5, 1e7, "constraint_weight"),
        (2.5, 1e-7, "constraint_weight"),
        (1e7, 10.0, "w_z"),
        (1e-300, 10.0, "w_z"),
    ] {
        let e = ShadowEditor::new(mesh.clone(), &pv, &pf, l, 20, wz, cw)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains(name) && e.contains("[1e-6, 1e6]"), "{e}");
    }
    for (wz, cw) in [(1e-6, 1e6), (1e6, 1e-6), (1e6, 1e6), (1e-6, 1e-6)] {
        let mut ed = ShadowEditor::new(mesh.clone(), &pv, &pf, l, 20, wz, cw).unwrap();
        let n = ed.loops()[0].len();
        let h = ed.handles(0, None).unwrap();
        let e = h[0].position + (h[0].position - DVec3::new(0.2, 0.1, 0.0)) * 0.3;
        let d = Drag {
            loop_index: 0,
            fixed: ((n - n / 6) % n, n / 6),
            moved: 0,
            target: DVec3::new(e.x, e.y, 0.0),
            style: MlsStyle::Affine,
            mls_alpha: 1.0,
            noise_amplitude: 0.0,
            noise_frequency: 0.0,
        };
        ed.drag(&d).unwrap();
        ed.commit();
        let sm = ed.shadow_mesh().unwrap();
        assert!(sm.iter().all(|p| p.is_finite()), "w_z {wz}, weight {cw}");
    }
}

/// A torus round the z axis (major radius `big`, tube radius `small`) centred at `c`, faces
/// counter-clockwise from outside.
fn torus(c: DVec3, big: f64, small: f64, nu: usize, nv: usize) -> (Vec<f32>, Vec<i64>) {
    let mut v = Vec::new();
    for i in 0..nu {
        let u = 2.0 * std::f64::consts::PI * i as f64 / nu as f64;
        for j in 0..nv {
            let w = 2.0 * std::f64::consts::PI * j as f64 / nv as f64;
            let r = big + small * w.cos();
            v.push(c + DVec3::new(r * u.cos(), r * u.sin(), small * w.sin()));
        }
    }
    let id = |i: usize, j: usize| ((i % nu) * nv + j % nv) as i64;
    let mut f = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, cc, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            f.extend_from_slice(&[a, b, cc, a, cc, d]);
        }
    }
    let vf = v
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    (vf, f)
}

/// §5.2 per-loop frusta: a point light at the centre of a ring (inside its bounding box, outside
/// its volume) lights the ground through the ring's hole. The lower silhouette loop (tangent
/// circle of the tube, 17.5° below the light) bounds the lit disc on the ground; its handles are
/// the analytic ones, a drag lands where the cursor is, the shadow mesh follows and rests at rest.
#[test]
fn a_light_inside_a_ring_gets_per_loop_frusta() {
    let c = DVec3::new(0.0, 0.0, 1.0);
    let (v, f) = torus(c, 1.0, 0.3, 96, 24);
    assert!(signed_volume(&v, &f) > 0.0);
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    assert!(mesh.winding_number(c).abs() < 1e-6);
    assert!((mesh.winding_number(DVec3::new(1.0, 0.0, 1.0)) - 1.0).abs() < 1e-6);
    assert!(LightFrame::new(Light::Point(c), &mesh.vertices).is_err());
    let (pv, pf) = plane(0.0, 20.0);
    let mut ed = ShadowEditor::new(mesh, &pv, &pf, Light::Point(c), 20, 2.5, 10.0).unwrap();
    assert!(ed.per_loop_frusta() && ed.frame().is_none());
    let k = (0..ed.loops().len())
        .find(|&k| ed.active()[k] && ed.handles(k, None).unwrap().iter().all(|h| h.hit))
        .expect("the lower loop reaches the ground");
    assert!(ed.loop_frame(k).unwrap().basis.row(2).z < -0.99);
    let hs = ed.handles(k, None).unwrap();
    // Tangent from the light to the tube: 17.46° below the horizon, so radius 1/tan on the ground
    // (the polygonal tube is a little smaller than the smooth one).
    let want = 1.0 / (0.3f64).asin().tan();
    for h in &hs {
        let r = h.position.truncate().length();
        assert!(
            !h.on_caster && (r - want).abs() < 0.03 * want,
            "{r} vs {want}"
        );
    }
    let n = hs.len();
    let m = 0;
    let e = hs[m].position * 1.15;
    let d = Drag {
        loop_index: k,
        fixed: ((n - n / 6) % n, n / 6),
        moved: m,
        target: DVec3::new(e.x, e.y, 0.0),
        style: MlsStyle::Affine,
        mls_alpha: 1.0,
        noise_amplitude: 0.0,
        noise_frequency: 0.0,
    };
    let r = ed.drag(&d).unwrap();
    assert!(
        (r.handles[m].position - d.target).length() < 1e-6,
        "{:?}",
        r.handles[m].position
    );
    for (i, h) in hs.iter().enumerate() {
        if !r.segment.contains(&i) {
            assert!((r.handles[i].position - h.position).length() < 1e-9);
        }
    }
    ed.commit();
    let sm = ed.shadow_mesh().unwrap();
    let rest = ed.caster().vertices.clone();
    let moved: Vec<f64> = sm
        .iter()
        .zip(&rest)
        .map(|(a, b)| (*a - *b).length())
        .collect();
    let most = moved.iter().cloned().fold(0.0, f64::max);
    assert!(most > 0.01 && most < 0.5, "the shadow mesh moved {most}");
    // The ring's far side (opposite the drag) hardly moves.
    let dir = hs[m].position.truncate().normalize();
    let far = (0..rest.len())
        .filter(|&i| (rest[i] - c).truncate().normalize().dot(dir) < -0.9)
        .map(|i| moved[i])
        .fold(0.0, f64::max);
    assert!(far < 0.05 * most, "far side moved {far} of {most}");
    // The shadow mesh's own silhouette casts the edit: its lower loop's handle near m moved out.
    let sm_f32: Vec<f32> = sm
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let mesh2 = ClosedMesh::new(&sm_f32, &f, None).unwrap();
    let ed2 = ShadowEditor::new(mesh2, &pv, &pf, Light::Point(c), 20, 2.5, 10.0).unwrap();
    let hs2 = (0..ed2.loops().len())
        .filter_map(|k| ed2.handles(k, None).ok())
        .find(|h| h.iter().all(|h| h.hit))
        .unwrap();
    let best = hs2
        .iter()
        .map(|h| h.position)
        .max_by(|a, b| a.truncate().dot(dir).total_cmp(&b.truncate().dot(dir)))
        .unwrap();
    let reach = best.truncate().dot(dir);
    assert!(
        (reach - d.target.truncate().length()).abs() < 0.25 * (d.target.truncate().length() - want),
        "the shadow mesh's boundary reaches {reach}, the drag {}",
        d.target.truncate().length()
    );
    ed.reset();
    for (a, b) in ed.shadow_mesh().unwrap().iter().zip(&rest) {
        assert!((*a - *b).length() < 1e-9);
    }
}

/// A light inside the caster's volume is refused by name, also when it is not at the centre.
#[test]
fn a_light_inside_the_casters_volume_is_a_clear_error() {
    let (v, f) = torus(DVec3::ZERO, 1.0, 0.3, 48, 16);
    let (pv, pf) = plane(-2.0, 20.0);
    let mesh = ClosedMesh::new(&v, &f, None).unwrap();
    for l in [DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, -1.1, 0.1)] {
        let e = ShadowEditor::new(mesh.clone(), &pv, &pf, Light::Point(l), 10, 2.5, 10.0)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("light") && e.contains("inside the caster's volume"),
            "{e}"
        );
    }
}

/// While one drag goes on, steps after the first are incremental (affine in the dragged point);
/// they give the shadow mesh a fresh editor solves directly, for the affine and similarity styles.
#[test]
fn incremental_drag_steps_equal_a_direct_solve() {
    for style in [MlsStyle::Affine, MlsStyle::Similarity] {
        let (mut ed, l) = scene(32, 48);
        let (mut fresh, _) = scene(32, 48);
        let mut last = Vec::new();
        for (i, factor) in [1.1, 1.2, 1.35, 0.9].into_iter().enumerate() {
            let (mut d, _) = drag_radially(&mut ed, l, 3, factor);
            d.style = style;
            let r = ed.drag(&d).unwrap();
            // Only the segment's rays are cast; the handles equal a full recast.
            assert_eq!(r.handles, ed.handles(0, None).unwrap());
            last = ed.shadow_mesh().unwrap();
            if i == 3 {
                fresh.drag(&d).unwrap();
            }
        }
        let want = fresh.shadow_mesh().unwrap();
        let most = want
            .iter()
            .zip(&ed.caster().vertices)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        assert!(most > 1e-3);
        for (a, b) in last.iter().zip(&want) {
            assert!(
                (*a - *b).length() < 1e-9 * (1.0 + most),
                "{style:?}: {a:?} vs {b:?}"
            );
        }
        // Committed, another drag: the base moved, still exact.
        ed.commit();
        fresh.commit();
        let (d, _) = drag_radially(&mut ed, l, 20, 1.2);
        ed.drag(&d).unwrap();
        ed.shadow_mesh().unwrap();
        let (d2, _) = drag_radially(&mut ed, l, 20, 1.25);
        let r = ed.drag(&d2).unwrap();
        assert_eq!(r.handles, ed.handles(0, None).unwrap());
        fresh.drag(&d2).unwrap();
        for (a, b) in ed
            .shadow_mesh()
            .unwrap()
            .iter()
            .zip(&fresh.shadow_mesh().unwrap())
        {
            assert!((*a - *b).length() < 1e-9 * (1.0 + most));
        }
        ed.cancel();
        fresh.cancel();
        for (a, b) in ed
            .shadow_mesh()
            .unwrap()
            .iter()
            .zip(&fresh.shadow_mesh().unwrap())
        {
            assert!((*a - *b).length() < 1e-9 * (1.0 + most));
        }
    }
}

/// A drag prepared on the mouse press (`prepare_drag`): its first step is already incremental,
/// and every step gives the shadow mesh an unprepared editor gives; the shadow mesh at the press
/// is the committed one; rigid drags and drags with an uncommitted step are not prepared.
#[test]
fn a_drag_prepared_on_the_press_is_incremental_from_its_first_step() {
    for style in [MlsStyle::Affine, MlsStyle::Similarity] {
        let (mut ed, l) = scene(32, 48);
        let (mut plain, _) = scene(32, 48);
        // A committed edit first, so that the press starts from a moved base.
        let (d, _) = drag_radially(&mut ed, l, 20, 1.2);
        for e in [&mut ed, &mut plain] {
            e.drag(&d).unwrap();
            e.shadow_mesh().unwrap();
            e.commit();
        }
        let at_press = plain.shadow_mesh().unwrap();
        let (mut d, _) = drag_radially(&mut ed, l, 3, 1.1);
        d.style = style;
        assert!(ed.prepare_drag(&d).unwrap());
        assert!(ed.drag_is_incremental());
        let same = ed.shadow_mesh().unwrap();
        let most = at_press
            .iter()
            .zip(&ed.caster().vertices)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        assert!(most > 1e-3);
        for (a, b) in same.iter().zip(&at_press) {
            assert!((*a - *b).length() < 1e-9 * (1.0 + most));
        }
        for factor in [1.1, 1.3, 0.9] {
            let (mut d, _) = drag_radially(&mut ed, l, 3, factor);
            d.style = style;
            ed.drag(&d).unwrap();
            // The first step too: no back-substitution left for it.
            assert!(ed.drag_is_incremental(), "{style:?} {factor}");
            plain.drag(&d).unwrap();
            let want = plain.shadow_mesh().unwrap();
            for (a, b) in ed.shadow_mesh().unwrap().iter().zip(&want) {
                assert!(
                    (*a - *b).length() < 1e-9 * (1.0 + most),
                    "{style:?}: {a:?} vs {b:?}"
                );
            }
        }
        // Mid-drag (an uncommitted step) nothing is prepared; nor for rigid drags.
        assert!(!ed.prepare_drag(&d).unwrap());
        ed.commit();
        plain.commit();
        let (mut r, _) = drag_radially(&mut ed, l, 3, 1.1);
        r.style = MlsStyle::Rigid;
        assert!(!ed.prepare_drag(&r).unwrap());
        // Without a press the first step of a drag is the one that solves.
        let (d2, _) = drag_radially(&mut plain, l, 20, 1.1);
        plain.drag(&d2).unwrap();
        assert!(!plain.drag_is_incremental());
        // Bad loops are refused by name.
        let mut bad = d2;
        bad.loop_index = 99;
        assert!(ed.prepare_drag(&bad).is_err());
    }
}
