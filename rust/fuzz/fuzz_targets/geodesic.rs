//! Mesh::new, GeodesicSolver (Dijkstra and heat) and interpolate on arbitrary small meshes
//! (degenerate, non-manifold, NaN vertices, out-of-range faces): errors, never panics.
#![no_main]
use libfuzzer_sys::fuzz_target;
use rokeby_core::geometry::geodesic::{interpolate, GeodesicSolver, Mesh, Method, Source, SurfacePoint};

fuzz_target!(|data: &[u8]| {
    if data.len() < 8 {
        return;
    }
    let nv = 3 + (data[0] % 12) as usize;
    let nf = 1 + (data[1] % 16) as usize;
    let src = data[2] as usize;
    let body = &data[4..];
    let floats: Vec<f32> = body.chunks_exact(4).take(3 * nv).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    if floats.len() < 3 * nv {
        return;
    }
    let idx = &body[(12 * nv).min(body.len())..];
    let faces: Vec<i64> = idx.iter().take(3 * nf).map(|&b| b as i64 % (nv as i64 + 2) - 1).collect();
    if faces.len() % 3 != 0 || faces.is_empty() {
        return;
    }
    let Ok(mesh) = Mesh::new(&floats, &faces) else { return };
    let faces3 = mesh.faces.clone();
    let solver = GeodesicSolver::new(mesh);
    let sets = vec![vec![Source::Vertex(src % (nv + 1))], vec![Source::Point(SurfacePoint { face: src % (faces3.len() + 1), bary: [0.2, 0.3, 0.5] })]];
    for method in [Method::Dijkstra, Method::Heat] {
        if let Ok(d) = solver.distances(&sets, method) {
            assert!(d.iter().all(|x| !x.is_nan()), "NaN distance");
            let pts = [SurfacePoint { face: 0, bary: [1.0 / 3.0; 3] }];
            let _ = interpolate(&d[..nv.min(d.len())], nv, &faces3, &pts);
        }
    }
});
