//! The saddle vertex graph method (issue 21): under 0.5 % mean error against exact geodesics.

mod common;

use common::{load_obj, shared_meshes};
use rokeby_core::geodesic::{GeodesicSolver, Mesh, Method, Source};
use std::path::PathBuf;

/// Mean and max relative error outside the source's 1-ring, over the vertices exact reaches.
fn errors(got: &[f32], exact: &[f32], ring: &[bool]) -> (f64, f64) {
    let (mut sum, mut n, mut mx) = (0.0f64, 0usize, 0.0f64);
    for i in 0..exact.len() {
        let e = exact[i] as f64;
        if ring[i] || !(e > 0.0 && e.is_finite()) {
            continue;
        }
        let g = got[i] as f64;
        let r = if g.is_finite() {
            (g - e).abs() / e
        } else {
            1.0
        };
        sum += r;
        n += 1;
        mx = mx.max(r);
    }
    (sum / n.max(1) as f64, mx)
}

/// The shared meshes under 20k faces (fandisk, homer, spot, teapot): exact geodesics take seconds.
#[test]
fn graph_is_within_half_a_percent_of_exact_on_the_small_shared_meshes() {
    within_half_a_percent(|faces| faces < 20_000);
}

/// nefertiti and the bunny: the exact reference takes minutes per source on 2 cores
/// (`cargo test --release --test geodesic_graph -- --ignored`). Measured: nefertiti 0.35 %.
#[test]
#[ignore]
fn graph_is_within_half_a_percent_of_exact_on_the_large_shared_meshes() {
    within_half_a_percent(|faces| faces >= 20_000);
}

fn within_half_a_percent(take: impl Fn(usize) -> bool) {
    let mut report = Vec::new();
    let mut worst = 0.0f64;
    for path in shared_meshes() {
        let (v, f) = load_obj(&path);
        if !take(f.len() / 3) {
            continue;
        }
        let s = GeodesicSolver::new(Mesh::new(&v, &f).unwrap());
        let m = s.mesh();
        let nv = m.vertices.len();
        // The benchmark's sources: vertices of faces a quarter, half, three quarters through.
        let nf = m.faces.len();
        let sources: Vec<usize> = [1, 2, 3].map(|k| m.faces[nf * k / 4][0]).to_vec();
        let sets: Vec<Vec<Source>> = sources.iter().map(|&v| vec![Source::Vertex(v)]).collect();
        if std::env::var("ROKEBY_GRAPH_MESHES")
            .is_ok_and(|x| !x.split(',').any(|n| path.ends_with(n)))
        {
            continue;
        }
        let t = std::time::Instant::now();
        // ROKEBY_EXACT_CACHE=dir keeps the exact fields between runs (for tuning; off by default).
        let cache = std::env::var("ROKEBY_EXACT_CACHE").ok().map(|d| {
            PathBuf::from(d).join(format!(
                "{}.f32",
                path.file_name().unwrap().to_string_lossy()
            ))
        });
        let exact: Vec<f32> = match cache.as_ref().and_then(|c| std::fs::read(c).ok()) {
            Some(b) => b
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
            None => {
                let e = s.distances(&sets, Method::Exact).unwrap();
                if let Some(c) = &cache {
                    let b: Vec<u8> = e.iter().flat_map(|x| x.to_le_bytes()).collect();
                    std::fs::write(c, b).unwrap();
                }
                e
            }
        };
        let t_exact = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let _ = s.distances(&sets[..1], Method::Graph).unwrap();
        let t_first = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let graph = s.distances(&sets, Method::Graph).unwrap();
        let t_graph = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let heat = s.distances(&sets, Method::Heat).unwrap();
        let _ = t.elapsed();
        let t = std::time::Instant::now();
        let _ = s.distances(&sets, Method::Heat).unwrap();
        let t_heat = t.elapsed().as_secs_f64();
        let (mut gm, mut gx, mut hm) = (0.0, 0.0f64, 0.0);
        for (r, &src) in sources.iter().enumerate() {
            let mut ring = vec![false; nv];
            for fc in &m.faces {
                if fc.contains(&src) {
                    for &x in fc {
                        ring[x] = true;
                    }
                }
            }
            let e = &exact[r * nv..(r + 1) * nv];
            let (a, b) = errors(&graph[r * nv..(r + 1) * nv], e, &ring);
            let (c, _) = errors(&heat[r * nv..(r + 1) * nv], e, &ring);
            gm += a / 3.0;
            gx = gx.max(b);
            hm += c / 3.0;
        }
        worst = worst.max(gm);
        report.push(format!(
            "{:?}: graph mean {:.3} % max {:.2} % (heat {:.2} %); graph build {:.2} s, query {:.1} ms/source, heat {:.1} ms/source, exact {:.2} s/source",
            path.file_name().unwrap(),
            100.0 * gm,
            100.0 * gx,
            100.0 * hm,
            t_first,
            t_graph * 1e3 / 3.0,
            t_heat * 1e3 / 3.0,
            t_exact / 3.0,
        ));
        eprintln!("{}", report.last().unwrap());
    }
    println!("{}", report.join("\n"));
    assert!(worst < 0.005, "{}", report.join("\n"));
}
