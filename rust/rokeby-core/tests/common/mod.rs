//! Helpers shared by the integration tests (each test file is its own crate and includes this
//! module with `mod common;`): test meshes made in code and the shared meshes read from OBJ files.
#![allow(dead_code)] // each test crate uses its own subset

use glam::DVec3;
use std::path::PathBuf;

/// A grid of n×n vertices on [0,1]², triangulated with alternating diagonals (no directional bias).
pub fn grid(n: usize, map: impl Fn(f64, f64) -> DVec3) -> (Vec<f32>, Vec<i64>) {
    let mut v = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let p = map(i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
            v.extend_from_slice(&[p.x as f32, p.y as f32, p.z as f32]);
        }
    }
    let mut f = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as i64;
            let (b, c, d) = (a + 1, a + n as i64, a + n as i64 + 1);
            if (i + j) % 2 == 0 {
                f.extend_from_slice(&[a, b, d, a, d, c]);
            } else {
                f.extend_from_slice(&[a, b, c, b, d, c]);
            }
        }
    }
    (v, f)
}

/// The `.obj` files of the shared meshes folder ($ROKEBY_SHARED/meshes), sorted.
pub fn shared_meshes() -> Vec<PathBuf> {
    let root = std::env::var("ROKEBY_SHARED").map_or_else(
        |_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"),
        PathBuf::from,
    );
    let dir = root.join("meshes");
    let mut out: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("shared meshes at {dir:?}: {e} (set ROKEBY_SHARED)"))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "obj"))
        .collect();
    out.sort();
    assert!(!out.is_empty(), "no .obj in {dir:?}");
    out
}

/// The vertices and triangles of an OBJ file ([`rokeby_core::geometry::mesh::parse_obj`]).
pub fn load_obj(path: &PathBuf) -> (Vec<f32>, Vec<i64>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    rokeby_core::geometry::mesh::parse_obj(&text).unwrap_or_else(|e| panic!("{path:?}: {e}"))
}
