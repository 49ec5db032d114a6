//! light_space and shadow_mesh (§5.1, §6): light frames of arbitrary lights around
//! closed meshes, frustum round trips and drag targets, cotangent weights, the shadow-mesh solver
//! and the §6.2 falloff factor. Never a panic; from_frustum(to_frustum(p)) = p; zero offsets give the
//! rest mesh back; non-zero offsets give finite vertices; falloff ∈ [0, 1].
#![no_main]
mod common;
use common::{octahedron, uv_sphere, Input};
use glam::DVec2;
use libfuzzer_sys::fuzz_target;
use rokeby_core::shadows::light_space::LightFrame;
use rokeby_core::shadows::shadow_mesh::{cotangent_weights, falloff_factor, EdgePoint, ShadowMeshSolver};
use rokeby_core::shadows::silhouette::{ClosedMesh, Light};

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    let fo = falloff_factor(inp.v3(1.0), inp.v3(1.0), inp.f64_in(4.0));
    if let Ok(x) = fo {
        assert!((0.0..=1.0).contains(&x), "falloff factor {x}");
    }
    let (s, c) = (inp.range(0.01, 5.0), inp.v3_finite(3.0));
    let (v, f) = if inp.bool() { octahedron(&mut inp, s, c, 0.2) } else { uv_sphere(2 + inp.below(6), 3 + inp.below(8), s, c) };
    let mesh = ClosedMesh::new(&v, &f, None).expect("closed test mesh");
    let light = if inp.bool() { Light::Point(inp.v3(20.0)) } else { Light::Directional(inp.v3(1.0)) };
    let weights = cotangent_weights(&mesh.vertices, &mesh.faces);
    assert!(weights.iter().all(|&(i, j, w)| i < j && w.is_finite()));
    let mut verts = mesh.vertices.clone();
    if inp.byte() % 16 == 0 {
        let k = inp.below(verts.len());
        verts[k] = inp.v3(1e300);
    }
    let Ok(frame) = LightFrame::new(light, &verts) else { return };
    let scale = verts.iter().fold(1.0f64, |s, p| s.max(p.length()));
    let finite_verts = verts.iter().all(|p| p.is_finite());
    // A light 1e30 away from a unit caster leaves no precision in the frustum (x, y ≈ X/Z): the
    // round trip and the rest solve are asserted for lights within 1e6 of the origin.
    let near_light = match light {
        Light::Point(l) => l.abs().max_element() <= 1e6,
        Light::Directional(_) => true,
    };
    for p in verts.iter().take(4) {
        let c = frame.to_frustum(*p);
        if finite_verts && near_light {
            let back = frame.from_frustum(c);
            assert!((back - *p).length() <= 1e-7 * scale, "frustum round trip {p:?} → {c:?} → {back:?}");
            let e = *p + inp.v3_finite(2.0);
            let t = frame.drag_target(*p, e);
            assert!(t.is_finite(), "drag_target({p:?}, {e:?}) = {t:?}");
        }
    }
    let nc = inp.below(6);
    let cons: Vec<EdgePoint> = (0..nc)
        .map(|_| {
            let fi = inp.below(mesh.faces.len());
            let k = inp.below(3);
            let adv = inp.byte() % 16 == 0;
            let fc = mesh.faces[fi];
            EdgePoint { back: if adv { inp.u16() as u32 } else { fc[k] as u32 }, front: fc[(k + 1) % 3] as u32, alpha: if adv { inp.f64_in(2.0) } else { inp.range(0.0, 1.0) } }
        })
        .collect();
    let (wz, cw) = if inp.byte() % 8 == 0 { (inp.f64_in(5.0), inp.f64_in(50.0)) } else { (inp.range(0.1, 10.0), inp.range(0.1, 100.0)) };
    let Ok(solver) = ShadowMeshSolver::new(frame, &verts, &mesh.faces, cons, wz, cw) else { return };
    assert!(finite_verts);
    assert_eq!(solver.num_constraints(), nc);
    let rest = solver.solve(&vec![DVec2::ZERO; nc]).expect("zero offsets");
    assert_eq!(rest.len(), verts.len());
    // The rest solve is exact up to the conditioning of the system: asserted for sane weights.
    let sane = near_light && scale <= 1e6 && (1e-3..=1e3).contains(&wz) && (1e-3..=1e4).contains(&cw);
    for (a, b) in rest.iter().zip(&verts).filter(|_| sane) {
        // To the conditioning of the squared-Laplacian system: observed up to 4e-4 relative (a
        // point light at (11.5, 11.5, 11.5), w_z 7.4, weight 73), so this bounds gross errors only.
        assert!((*a - *b).length() <= 1e-2 * scale, "zero offsets moved {b:?} to {a:?} ({light:?}, w_z {wz}, weight {cw}, frame {:?})", solver.frame());
    }
    let deltas: Vec<DVec2> = (0..nc).map(|_| inp.v2_finite(0.5)).collect();
    let moved = solver.solve(&deltas).expect("offsets");
    assert!(moved.iter().all(|p| p.is_finite()), "non-finite shadow mesh");
    assert!(solver.solve(&vec![DVec2::ZERO; nc + 1]).is_err());
});
