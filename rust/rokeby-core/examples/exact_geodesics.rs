//! Exact polyhedral geodesics on the shared meshes: the sources of `make bench`'s
//! geodesic section (the first vertex of the faces a quarter, half and three quarters through the
//! face list), one source per query, run one after another on one thread; the median wall time
//! per query. `--dump DIR` writes each mesh's distances (3 × V little-endian f32) to
//! DIR/<mesh>.f32 for comparison with a reference.
//!
//! `cargo run --release -p rokeby-core --example exact_geodesics [-- --runs N] [-- --once]
//! [-- --dump DIR] [-- MESH.obj ...]` (`--once`: one pass, for `valgrind --tool=callgrind`).

use rokeby_core::geometry::geodesic::{GeodesicSolver, Mesh, Method, Source};
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let once = args.iter().any(|a| a == "--once");
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let runs: usize = value("--runs").map_or(5, |x| x.parse().unwrap());
    let dump = value("--dump").map(PathBuf::from);
    let mut names: Vec<String> = Vec::new();
    let mut skip = false;
    for a in &args {
        if skip {
            skip = false;
        } else if a == "--runs" || a == "--dump" {
            skip = true;
        } else if !a.starts_with("--") {
            names.push(a.clone());
        }
    }
    if names.is_empty() {
        names = ["teapot.obj", "spot.obj", "homer.obj", "fandisk.obj"]
            .map(String::from)
            .to_vec();
    }
    let root = std::env::var("ROKEBY_SHARED").map_or_else(
        |_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"),
        PathBuf::from,
    );
    for name in names {
        let path = root.join("meshes").join(&name);
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
        let (v, f) = rokeby_core::geometry::mesh::parse_obj(&text)
            .unwrap_or_else(|e| panic!("{path:?}: {e}"));
        let nf = f.len() / 3;
        let sources: Vec<usize> = [1, 2, 3].map(|k| f[3 * (nf * k / 4)] as usize).to_vec();
        let solver = GeodesicSolver::new(Mesh::new(&v, &f).unwrap());
        let query = |s: usize| {
            solver
                .distances(&[vec![Source::Vertex(s)]], Method::Exact)
                .unwrap()
        };
        let rows: Vec<Vec<f32>> = sources.iter().map(|&s| query(s)).collect();
        if let Some(dir) = &dump {
            let bytes: Vec<u8> = rows
                .iter()
                .flatten()
                .flat_map(|x| x.to_le_bytes())
                .collect();
            std::fs::write(dir.join(format!("{name}.f32")), bytes).unwrap();
        }
        if once {
            println!("{name}: {} faces, sources {sources:?}", nf);
            continue;
        }
        let mut times: Vec<f64> = (0..runs)
            .map(|_| {
                let t = Instant::now();
                for &s in &sources {
                    std::hint::black_box(query(s));
                }
                t.elapsed().as_secs_f64() / sources.len() as f64
            })
            .collect();
        times.sort_by(f64::total_cmp);
        println!(
            "{name}: {nf} faces, one source per query, median of {runs}: {:.1} ms (min {:.1})",
            times[runs / 2] * 1e3,
            times[0] * 1e3
        );
    }
}
