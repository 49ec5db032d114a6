//! Geodesic distances against closed forms: a flat grid (Euclidean), a cylinder (unrolled), a
//! sphere (great circles); surface-point sources; and every bad input.

mod common;

use common::grid;
use glam::DVec3;
use rokeby_core::geometry::geodesic::{GeodesicSolver, Mesh, Method, Source, SurfacePoint};

fn solver(v: &[f32], f: &[i64]) -> GeodesicSolver {
    GeodesicSolver::new(Mesh::new(v, f).unwrap())
}

/// Mean and max relative error over vertices farther than `skip` from the source.
fn rel_err(got: &[f32], want: &[f64], skip: f64) -> (f64, f64) {
    let mut sum = 0.0;
    let mut max: f64 = 0.0;
    let mut n = 0;
    for (g, w) in got.iter().zip(want) {
        if *w > skip {
            let e = (*g as f64 - w).abs() / w;
            sum += e;
            max = max.max(e);
            n += 1;
        }
    }
    (sum / n as f64, max)
}

#[test]
fn flat_grid_is_euclidean() {
    let n = 81;
    let (v, f) = grid(n, |x, y| DVec3::new(x, y, 0.0));
    let s = solver(&v, &f);
    let src = 40 * n + 40; // centre
    let want: Vec<f64> = v
        .chunks(3)
        .map(|c| ((c[0] as f64 - 0.5).powi(2) + (c[1] as f64 - 0.5).powi(2)).sqrt())
        .collect();
    let heat = s
        .distances(&[vec![Source::Vertex(src)]], Method::Heat)
        .unwrap();
    let dij = s
        .distances(&[vec![Source::Vertex(src)]], Method::Dijkstra)
        .unwrap();
    let (hm, hx) = rel_err(&heat, &want, 2.0 / (n - 1) as f64);
    let (dm, _) = rel_err(&dij, &want, 2.0 / (n - 1) as f64);
    println!("flat: heat mean {hm:.4} max {hx:.4}; dijkstra mean {dm:.4}");
    assert!(hm < 0.01, "heat mean relative error {hm}");
    assert!(
        dm > hm,
        "edge paths over-estimate: {dm} should exceed the heat method's {hm}"
    );
    // Dijkstra never under-estimates.
    assert!(dij.iter().zip(&want).all(|(g, w)| *g as f64 >= w - 1e-6));
}

#[test]
fn cylinder_unrolls() {
    // Circumference 2π·r with r = 1/(2π)·2 → unrolled width 2; height 1; open along a seam? No:
    // use a half cylinder (an open strip), whose unrolling is exact.
    let n = 81;
    let r = 1.0 / std::f64::consts::PI; // half circumference = 1
    let (v, f) = grid(n, |x, y| {
        let a = x * std::f64::consts::PI;
        DVec3::new(r * a.cos(), r * a.sin(), y)
    });
    let s = solver(&v, &f);
    let src = 40 * n + 40;
    let want: Vec<f64> = (0..n * n)
        .map(|k| {
            let (i, j) = (k % n, k / n);
            let (x, y) = (i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
            ((x - 0.5).powi(2) + (y - 0.5).powi(2)).sqrt()
        })
        .collect();
    let heat = s
        .distances(&[vec![Source::Vertex(src)]], Method::Heat)
        .unwrap();
    let (hm, hx) = rel_err(&heat, &want, 2.0 / (n - 1) as f64);
    println!("cylinder: heat mean {hm:.4} max {hx:.4}");
    assert!(hm < 0.01);
}

#[test]
fn sphere_great_circles() {
    // UV sphere without duplicated poles: latitude rings, 1 pole vertex each end.
    let (rings, segs) = (60usize, 120usize);
    let mut v: Vec<f32> = vec![0.0, 0.0, 1.0];
    for i in 1..rings {
        let th = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..segs {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / segs as f64;
            v.extend_from_slice(&[
                (th.sin() * ph.cos()) as f32,
                (th.sin() * ph.sin()) as f32,
                th.cos() as f32,
            ]);
        }
    }
    v.extend_from_slice(&[0.0, 0.0, -1.0]);
    let south = (v.len() / 3 - 1) as i64;
    let idx = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as i64;
    let mut f = Vec::new();
    for j in 0..segs {
        f.extend_from_slice(&[0, idx(1, j), idx(1, j + 1)]);
        f.extend_from_slice(&[south, idx(rings - 1, j + 1), idx(rings - 1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
            f.extend_from_slice(&[
                idx(i, j),
                idx(i + 1, j),
                idx(i + 1, j + 1),
                idx(i, j),
                idx(i + 1, j + 1),
                idx(i, j + 1),
            ]);
        }
    }
    let s = solver(&v, &f);
    let want: Vec<f64> = v
        .chunks(3)
        .map(|c| (c[2] as f64).clamp(-1.0, 1.0).acos())
        .collect();
    for method in [Method::Heat, Method::Dijkstra] {
        let d = s.distances(&[vec![Source::Vertex(0)]], method).unwrap();
        let (m, x) = rel_err(&d, &want, 0.1);
        println!("sphere {method:?}: mean {m:.4} max {x:.4}");
        if method == Method::Heat {
            assert!(m < 0.01);
        }
    }
}

#[test]
fn surface_point_source_mid_triangle() {
    let n = 41;
    let (v, f) = grid(n, |x, y| DVec3::new(x, y, 0.0));
    let s = solver(&v, &f);
    // A point inside face 0 (corners (0,0), (1/40,0), (1/40,1/40) by the grid's first diagonal).
    let bary = [0.2, 0.5, 0.3];
    let m = s.mesh();
    let p = m.point(&SurfacePoint { face: 0, bary });
    for method in [Method::Heat, Method::Dijkstra] {
        let d = s
            .distances(
                &[vec![Source::Point(SurfacePoint { face: 0, bary })]],
                method,
            )
            .unwrap();
        for &vi in &m.faces[0] {
            assert!(
                (d[vi] as f64 - p.distance(m.vertices[vi])).abs() < 1e-6,
                "exact inside the source triangle"
            );
        }
        let far = n * n - 1;
        let want = p.distance(m.vertices[far]);
        let tol = if method == Method::Heat { 0.02 } else { 0.1 };
        assert!(
            ((d[far] as f64) - want).abs() / want < tol,
            "{method:?}: {} vs {want}",
            d[far]
        );
        // Interpolated at the source itself: close to 0.
        let at = rokeby_core::geometry::geodesic::interpolate(
            &d,
            m.vertices.len(),
            &m.faces,
            &[SurfacePoint { face: 0, bary }],
        )
        .unwrap();
        assert!(at[0] < 0.02);
    }
}

#[test]
fn several_sources_give_the_nearest() {
    let n = 21;
    let (v, f) = grid(n, |x, y| DVec3::new(x, y, 0.0));
    let s = solver(&v, &f);
    let a = s
        .distances(&[vec![Source::Vertex(0)]], Method::Dijkstra)
        .unwrap();
    let b = s
        .distances(&[vec![Source::Vertex(n * n - 1)]], Method::Dijkstra)
        .unwrap();
    let both = s
        .distances(
            &[vec![Source::Vertex(0), Source::Vertex(n * n - 1)]],
            Method::Dijkstra,
        )
        .unwrap();
    for i in 0..n * n {
        assert_eq!(both[i], a[i].min(b[i]));
    }
    let hb = s
        .distances(
            &[vec![Source::Vertex(0), Source::Vertex(n * n - 1)]],
            Method::Heat,
        )
        .unwrap();
    assert!(hb[0] == 0.0 && hb[n * n - 1] == 0.0);
    assert!(s.is_factored());
}

#[test]
fn disconnected_and_unreferenced_vertices_are_unreachable() {
    // Two separate triangles plus an unreferenced vertex.
    let v = [
        0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 5.0, 0.0, 0.0, 6.0, 0.0, 0.0, 5.0, 1.0,
        0.0, 9.0, 9.0, 9.0,
    ];
    let f = [0i64, 1, 2, 3, 4, 5];
    let s = solver(&v, &f);
    for method in [Method::Heat, Method::Dijkstra] {
        let d = s.distances(&[vec![Source::Vertex(0)]], method).unwrap();
        assert!(d[..3].iter().all(|x| x.is_finite()));
        assert!(
            d[3..].iter().all(|x| *x == f32::INFINITY),
            "{method:?}: {d:?}"
        );
        assert!(d.iter().all(|x| !x.is_nan()));
    }
}

#[test]
fn degenerate_faces_duplicates_and_nonmanifold_edges_stay_finite() {
    let n = 11;
    let (mut v, mut f) = grid(n, |x, y| DVec3::new(x, y, 0.1 * (x * 3.0).sin()));
    let nv = (v.len() / 3) as i64;
    // A duplicate vertex of vertex 5 with a zero-area face, a sliver, and a fin on edge (0, 1)
    // making it non-manifold (three faces).
    v.extend_from_slice(&[v[15], v[16], v[17]]);
    v.extend_from_slice(&[0.05, 0.0, 0.5]);
    f.extend_from_slice(&[5, nv, 6, 0, 1, nv + 1, 3, 3, 4]);
    let s = solver(&v, &f);
    for method in [Method::Heat, Method::Dijkstra] {
        let d = s.distances(&[vec![Source::Vertex(60)]], method).unwrap();
        assert!(d.iter().all(|x| x.is_finite() && *x >= 0.0), "{method:?}");
    }
}

/// the exact method's window trimming and per-halfedge tables on a mesh with a
/// non-manifold edge, a zero-area face and a sliver: every distance is finite, at least the
/// straight chord and at most the edge path (Dijkstra), and it agrees with the flat parts'
/// straight lines where the surface is flat (the fin and the sliver are off the grid's plane).
#[test]
fn exact_on_nonmanifold_and_degenerate_faces_lies_between_chord_and_edge_path() {
    let n = 11;
    let (mut v, mut f) = grid(n, |x, y| DVec3::new(x, y, 0.0));
    let nv = (v.len() / 3) as i64;
    // A duplicate of vertex 5 with a zero-area face on it, a face with a repeated vertex, and a
    // fin on the interior edge (60, 61): three faces there.
    v.extend_from_slice(&[v[15], v[16], v[17]]);
    v.extend_from_slice(&[0.55, 0.5, 0.3]);
    f.extend_from_slice(&[5, nv, 6, 3, 3, 4, 60, 61, nv + 1]);
    let s = solver(&v, &f);
    let src = 12;
    let set = [vec![Source::Vertex(src)]];
    let exact = s.distances(&set, Method::Exact).unwrap();
    let edge = s.distances(&set, Method::Dijkstra).unwrap();
    let p = |i: usize| DVec3::new(v[3 * i] as f64, v[3 * i + 1] as f64, v[3 * i + 2] as f64);
    for (i, (&d, &e)) in exact.iter().zip(&edge).enumerate() {
        let chord = p(i).distance(p(src)) as f32;
        assert!(d.is_finite(), "vertex {i}");
        assert!(
            d >= chord * (1.0 - 1e-6) && d <= e * (1.0 + 1e-6),
            "vertex {i}: {d} not in [{chord}, {e}]"
        );
        if i < n * n {
            // The grid is flat and convex: the straight line is on it.
            assert!(
                (d - chord).abs() <= 1e-6 * chord.max(1.0),
                "vertex {i}: {d} vs {chord}"
            );
        }
    }
}

#[test]
fn bad_input_is_an_error() {
    assert!(Mesh::new(&[], &[]).is_err());
    assert!(Mesh::new(&[0.0, 0.0, 0.0], &[]).is_err());
    assert!(Mesh::new(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], &[0, 1, 3]).is_err());
    assert!(Mesh::new(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], &[0, -1, 2]).is_err());
    assert!(Mesh::new(
        &[f32::NAN, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        &[0, 1, 2]
    )
    .is_err());
    let s = solver(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], &[0, 1, 2]);
    assert!(s
        .distances(&[vec![Source::Vertex(3)]], Method::Dijkstra)
        .is_err());
    assert!(s.distances(&[vec![]], Method::Dijkstra).is_err());
    let bad = SurfacePoint {
        face: 1,
        bary: [1.0, 0.0, 0.0],
    };
    assert!(s
        .distances(&[vec![Source::Point(bad)]], Method::Heat)
        .is_err());
    let nan = SurfacePoint {
        face: 0,
        bary: [f64::NAN, 0.0, 0.0],
    };
    assert!(s
        .distances(&[vec![Source::Point(nan)]], Method::Heat)
        .is_err());
}

#[test]
fn long_strip_far_end_is_right() {
    // 1500 edge lengths long: one heat flow from the source decays below any usable value long
    // before the far end; the fronts must carry the direction all the way.
    let (nx, ny) = (1501usize, 4usize);
    let mut v = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            v.extend_from_slice(&[i as f32, j as f32, 0.0]);
        }
    }
    let mut f = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let a = (j * nx + i) as i64;
            let (b, c, d) = (a + 1, a + nx as i64, a + nx as i64 + 1);
            f.extend_from_slice(&[a, b, d, a, d, c]);
        }
    }
    let s = solver(&v, &f);
    let d = s
        .distances(&[vec![Source::Vertex(0)]], Method::Heat)
        .unwrap();
    for i in [100usize, 500, 1000, 1500] {
        let got = d[i] as f64;
        assert!((got - i as f64).abs() / (i as f64) < 0.02, "at {i}: {got}");
    }
}
