//! silhouette (§4.1): ClosedMesh::new of arbitrary vertex/face/normal arrays (soups,
//! open, non-manifold, out-of-range, NaN) and silhouettes of closed meshes (jittered octahedra,
//! UV spheres) under arbitrary lights. Never a panic; every silhouette vertex has α ∈ [0, 1], lies
//! at (1 − α) v_back + α v_front on an edge whose ends face the light oppositely, and each loop's
//! length is the sum of its closed polygon's sides.
#![no_main]
mod common;
use common::{octahedron, uv_sphere, Input};
use glam::DVec3;
use libfuzzer_sys::fuzz_target;
use rokeby_core::shadows::silhouette::{silhouette_alpha, silhouettes, ClosedMesh, Light};

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    let light = if inp.bool() { Light::Point(inp.v3(5.0)) } else { Light::Directional(inp.v3(1.0)) };
    let a = silhouette_alpha(&light, inp.v3(2.0), inp.v3(1.0), inp.v3(2.0), inp.v3(1.0));
    assert!(a.is_nan() || (0.0..=1.0).contains(&a), "alpha {a}");
    let (v, f) = match inp.below(4) {
        0 => {
            let nv = inp.below(10);
            let nf = inp.below(10);
            let extra = inp.below(2);
            let v = inp.f32s(3 * nv + extra, 3.0);
            let f: Vec<i64> = (0..3 * nf).map(|_| inp.below(nv + 2) as i64 - 1).collect();
            (v, f)
        }
        1 => octahedron(&mut inp, 1.0, DVec3::ZERO, 0.3),
        _ => {
            let (r, s) = (2 + inp.below(8), 3 + inp.below(10));
            uv_sphere(r, s, inp.range(1e-3, 10.0), inp.v3_finite(2.0))
        }
    };
    let normals = match inp.below(4) {
        0 => Some(inp.f32s(v.len(), 1.0)),
        1 => Some(v.clone()),
        _ => None,
    };
    let Ok(mesh) = ClosedMesh::new(&v, &f, normals.as_deref()) else { return };
    assert!(mesh.vertices.iter().all(|p| p.is_finite()));
    let (mn, mx) = mesh.bounds();
    assert!(mesh.vertices.iter().all(|p| p.cmpge(mn).all() && p.cmple(mx).all()));
    let Ok(loops) = silhouettes(&mesh, &light) else {
        assert!(light.validate().is_err(), "silhouettes refused a valid light");
        return;
    };
    let faces_light = |i: u32| mesh.normals[i as usize].dot(light.to_light(mesh.vertices[i as usize])) > 0.0;
    for l in &loops {
        assert!(!l.is_empty());
        let mut len = 0.0;
        for (k, s) in l.vertices.iter().enumerate() {
            assert!((0.0..=1.0).contains(&s.alpha), "alpha {}", s.alpha);
            assert!(!faces_light(s.back) && faces_light(s.front), "edge ({}, {}) does not change sign", s.back, s.front);
            let (vb, vf) = (mesh.vertices[s.back as usize], mesh.vertices[s.front as usize]);
            let p = vb * (1.0 - s.alpha) + vf * s.alpha;
            assert!(s.position.is_finite() && (s.position - p).length() <= 1e-9 * (1.0 + p.length()));
            len += (l.vertices[(k + 1) % l.len()].position - s.position).length();
        }
        assert!(l.length.is_finite() && (l.length - len).abs() <= 1e-9 * (1.0 + len), "length {} vs {len}", l.length);
        assert_eq!(l.positions().len(), l.len());
    }
});
