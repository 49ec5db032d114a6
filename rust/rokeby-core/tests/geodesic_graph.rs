//! The saddle vertex graph methods: the coarse graph under 0.5 % mean error against
//! exact geodesics, the dense graph (the default) under 0.25 %, on the shared meshes and
//! on generated ones with unwelded seams, holes, several pieces, needles and slivers.

mod common;

use common::{grid, load_obj, shared_meshes};
use glam::DVec3;
use rokeby_core::geometry::geodesic::{GeodesicSolver, Mesh, Method, Source};
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
    let (mut worst, mut worst_dense) = (0.0f64, 0.0f64);
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
        let dense = s.distances(&sets, Method::DenseGraph).unwrap();
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
        let (mut gm, mut gx, mut hm, mut dm) = (0.0, 0.0f64, 0.0, 0.0);
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
            dm += errors(&dense[r * nv..(r + 1) * nv], e, &ring).0 / 3.0;
            gm += a / 3.0;
            gx = gx.max(b);
            hm += c / 3.0;
        }
        worst = worst.max(gm);
        worst_dense = worst_dense.max(dm);
        report.push(format!(
            "{:?}: dense graph mean {:.3} %, graph mean {:.3} % max {:.2} % (heat {:.2} %); graph build {:.2} s, query {:.1} ms/source, heat {:.1} ms/source, exact {:.2} s/source",
            path.file_name().unwrap(),
            100.0 * dm,
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
    assert!(worst_dense <= 0.0025, "{}", report.join("\n"));
}

/// Mean relative error of `method` against exact over three sources (outside their 1-rings),
/// checking that no value is below the exact one and that the same vertices are reached.
fn mean_error(v: &[f32], f: &[i64], method: Method) -> f64 {
    let s = GeodesicSolver::new(Mesh::new(v, f).unwrap());
    let m = s.mesh();
    let (nv, nf) = (m.vertices.len(), m.faces.len());
    let sources: Vec<usize> = [1, 2, 3].map(|k| m.faces[nf * k / 4][0]).to_vec();
    let sets: Vec<Vec<Source>> = sources.iter().map(|&v| vec![Source::Vertex(v)]).collect();
    let exact = s.distances(&sets, Method::Exact).unwrap();
    let got = s.distances(&sets, method).unwrap();
    let mut mean = 0.0;
    for (r, &src) in sources.iter().enumerate() {
        let mut ring = vec![false; nv];
        for fc in &m.faces {
            if fc.contains(&src) {
                for &x in fc {
                    ring[x] = true;
                }
            }
        }
        let (e, g) = (&exact[r * nv..(r + 1) * nv], &got[r * nv..(r + 1) * nv]);
        for i in 0..nv {
            assert_eq!(e[i].is_finite(), g[i].is_finite(), "vertex {i}");
            assert!(
                !e[i].is_finite() || g[i] >= e[i] * (1.0 - 1e-5),
                "vertex {i}: {} < {}",
                g[i],
                e[i]
            );
        }
        mean += errors(g, e, &ring).0 / 3.0;
    }
    mean
}

/// A bumpy torus whose two seams are left unwelded (the grid's first and last rows and columns
/// meet at the same positions), several pieces of it side by side, a square hole cut out of one.
fn seam_tori(pieces: usize, hole: bool) -> (Vec<f32>, Vec<i64>) {
    let tau = std::f64::consts::TAU;
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for k in 0..pieces {
        let (pv, pf) = grid(48, |a, b| {
            let (u, w) = (a * tau, b * tau);
            let r = 0.35 + 0.03 * (5.0 * u).sin() * (3.0 * w).cos();
            DVec3::new(
                (1.0 + r * w.cos()) * u.cos() + 3.0 * k as f64,
                (1.0 + r * w.cos()) * u.sin(),
                r * w.sin(),
            )
        });
        let base = (v.len() / 3) as i64;
        for t in pf.chunks_exact(3) {
            let c: Vec<usize> = t.iter().map(|&i| i as usize).collect();
            let (i, j) = (c[0] % 48, c[0] / 48);
            if hole && k == 0 && (10..16).contains(&i) && (20..26).contains(&j) {
                continue;
            }
            f.extend(t.iter().map(|&i| i + base));
        }
        v.extend(pv);
    }
    (v, f)
}

/// An open wavy height field (saddles) whose columns are 20× thinner in places: needles, and
/// slivers where the grid's diagonals cross them.
fn needles() -> (Vec<f32>, Vec<i64>) {
    let n = 64;
    let mut xs = vec![0.0f64];
    for i in 1..n {
        let w = if i % 4 == 1 || i % 7 == 3 {
            0.002
        } else {
            0.04
        };
        xs.push(xs[i - 1] + w);
    }
    let span = xs[n - 1];
    grid(n, |a, b| {
        let i = ((a * (n - 1) as f64).round() as usize).min(n - 1);
        let x = 2.0 * xs[i] / span;
        let y = 2.0 * b;
        DVec3::new(x, y, 0.3 * (2.5 * x).sin() * (2.5 * y).cos() + 0.1 * x * y)
    })
}

/// The default method (the dense graph) is under 0.25 % mean error on generated meshes a user
/// might bring; the coarse graph was not on the needles (which shows these meshes are hard).
#[test]
fn dense_graph_is_within_a_quarter_percent_on_seams_holes_pieces_and_needles() {
    assert_eq!(Method::DEFAULT, Method::DenseGraph);
    assert_eq!(Method::parse(Method::DEFAULT.name()), Some(Method::DEFAULT));
    for (name, (v, f)) in [
        ("seam torus", seam_tori(1, false)),
        ("two seam tori, one holed", seam_tori(2, true)),
        ("needles", needles()),
    ] {
        let dense = mean_error(&v, &f, Method::DenseGraph);
        eprintln!("{name}: dense graph {:.3} %", 100.0 * dense);
        assert!(dense <= 0.0025, "{name}: {:.3} %", 100.0 * dense);
        if name == "needles" {
            let coarse = mean_error(&v, &f, Method::Graph);
            eprintln!("{name}: graph {:.3} %", 100.0 * coarse);
            assert!(coarse > dense * 1.5, "{name}: {coarse} vs {dense}");
        }
    }
}
