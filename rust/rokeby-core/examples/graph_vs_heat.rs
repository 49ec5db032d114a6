//! The geodesic graphs' queries (`Method::DenseGraph`, the default, and `Method::Graph`) against
//! the heat method's (`Method::Heat`) on every shared mesh, in one process: the bench's query (one
//! source, the vertex of the face a quarter through the face list) after each method's
//! precomputation, the three methods alternating, and the median of each with their ratios.
//!
//! `cargo run --release -p rokeby-core --example graph_vs_heat [-- --runs N] [-- --mesh NAME]`;
//! `-- --once dense_graph|graph|heat --mesh NAME [--queries N]`: the precomputation and N queries (default 1)
//! only, for `valgrind --tool=callgrind`: the instructions of a query are the difference between
//! two such runs divided by the difference of their N (every thread counted, the precomputation
//! cancelled out).

use rokeby_core::geometry::geodesic::{GeodesicSolver, Mesh, Method, Source};
use std::path::PathBuf;
use std::time::Instant;

fn load_obj(path: &PathBuf) -> (Vec<f32>, Vec<i64>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    rokeby_core::geometry::mesh::parse_obj(&text).unwrap_or_else(|e| panic!("{path:?}: {e}"))
}

/// One query (a function of its own, so that callgrind can collect it alone).
#[inline(never)]
fn query_once(solver: &GeodesicSolver, set: &[Vec<Source>], method: Method) -> Vec<f32> {
    solver.distances(set, method).unwrap()
}

fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let runs: usize = arg("--runs").map_or(201, |x| x.parse().unwrap());
    let once =
        arg("--once").map(|m| Method::parse(&m).expect("--once dense_graph|graph|heat|dijkstra"));
    let only = arg("--mesh");
    let queries: usize = arg("--queries").map_or(1, |x| x.parse().unwrap());
    let root = std::env::var("ROKEBY_SHARED").map_or_else(
        |_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"),
        PathBuf::from,
    );
    let mut meshes: Vec<PathBuf> = std::fs::read_dir(root.join("meshes"))
        .expect("shared meshes (set ROKEBY_SHARED)")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "obj"))
        .filter(|p| only.as_ref().is_none_or(|n| p.ends_with(n)))
        .collect();
    meshes.sort_by_key(|p| std::fs::metadata(p).map_or(0, |m| m.len()));
    if once.is_none() {
        println!("| mesh | vertices | dense_graph query (ms) | graph query (ms) | heat query (ms) | dense_graph / heat | graph / heat |");
        println!("|---|---:|---:|---:|---:|---:|---:|");
    }
    for path in meshes {
        let (v, f) = load_obj(&path);
        let solver = GeodesicSolver::new(Mesh::new(&v, &f).unwrap());
        let m = solver.mesh();
        let nf = m.faces.len();
        let set = vec![vec![Source::Vertex(m.faces[nf / 4][0])]];
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if let Some(method) = once {
            solver.distances(&set, method).unwrap(); // the precomputation
            let mut d = Vec::new();
            for _ in 0..queries {
                d = query_once(&solver, &set, method);
            }
            println!(
                "{name}: {} distances, sum {}",
                d.len(),
                d.iter().map(|&x| x as f64).sum::<f64>()
            );
            continue;
        }
        let methods = [Method::DenseGraph, Method::Graph, Method::Heat];
        for &method in &methods {
            solver.distances(&set, method).unwrap();
        }
        let mut times = [
            Vec::with_capacity(runs),
            Vec::with_capacity(runs),
            Vec::with_capacity(runs),
        ];
        for _ in 0..runs {
            for (k, &method) in methods.iter().enumerate() {
                let t = Instant::now();
                std::hint::black_box(query_once(&solver, &set, method));
                times[k].push(t.elapsed().as_secs_f64());
            }
        }
        let [d, g, h] = times.map(median);
        println!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            m.vertices.len(),
            d * 1e3,
            g * 1e3,
            h * 1e3,
            d / h,
            g / h
        );
    }
}
