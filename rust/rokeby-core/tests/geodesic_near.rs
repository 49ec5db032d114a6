//! Next to the source: no method may return a distance shorter than the straight chord
//! to the nearest source, which no path on the surface can beat; on developable meshes the values
//! around a vertex or surface-point source are the exact unfolded distances.

mod common;

use common::{grid, load_obj, shared_meshes};
use glam::DVec3;
use rokeby_core::geometry::geodesic::{GeodesicSolver, Mesh, Method, Source, SurfacePoint};

/// A small deterministic generator (no dependency): xorshift64*.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        ((self.next() * n as f64) as usize).min(n - 1)
    }
}

fn source_point(m: &Mesh, s: &Source) -> DVec3 {
    match *s {
        Source::Vertex(v) => m.vertices[v],
        Source::Point(p) => m.point(&p),
    }
}

#[test]
fn no_distance_is_shorter_than_the_chord_on_any_shared_mesh() {
    let mut rng = Rng(0x9E3779B97F4A7C15);
    let mut report = Vec::new();
    for path in shared_meshes() {
        let (v, f) = load_obj(&path);
        let s = GeodesicSolver::new(Mesh::new(&v, &f).unwrap());
        let m = s.mesh();
        let (nv, nf) = (m.vertices.len(), m.faces.len());
        // Random surface points (some on edges and corners, as snapped handles are), and vertices.
        let mut sets: Vec<Vec<Source>> = Vec::new();
        for k in 0..6 {
            let (a, b) = (rng.next(), rng.next());
            let (a, b) = if a + b > 1.0 {
                (1.0 - a, 1.0 - b)
            } else {
                (a, b)
            };
            let bary = match k {
                4 => [0.0, a.max(0.05), 1.0 - a.max(0.05)],
                5 => [1.0, 0.0, 0.0],
                _ => [a, b, 1.0 - a - b],
            };
            sets.push(vec![Source::Point(SurfacePoint {
                face: rng.below(nf),
                bary,
            })]);
        }
        for _ in 0..3 {
            sets.push(vec![Source::Vertex(rng.below(nv))]);
        }
        // A set of two: the chord to the nearer one bounds every value.
        sets.push(vec![
            Source::Vertex(rng.below(nv)),
            Source::Point(SurfacePoint {
                face: rng.below(nf),
                bary: [0.3, 0.3, 0.4],
            }),
        ]);
        let scale = m
            .vertices
            .iter()
            .fold(0.0f64, |a, x| a.max(x.abs().max_element()));
        for method in [Method::Dijkstra, Method::Heat, Method::Graph] {
            let d = s.distances(&sets, method).unwrap();
            let (mut worst, mut bad, mut checked) = (0.0f64, 0usize, 0usize);
            for (r, set) in sets.iter().enumerate() {
                let pts: Vec<DVec3> = set.iter().map(|x| source_point(m, x)).collect();
                for i in 0..nv {
                    let got = d[r * nv + i] as f64;
                    assert!(!got.is_nan(), "{path:?} {method:?}: NaN at vertex {i}");
                    if !got.is_finite() {
                        continue;
                    }
                    let chord = pts
                        .iter()
                        .map(|p| p.distance(m.vertices[i]))
                        .fold(f64::INFINITY, f64::min);
                    checked += 1;
                    // float32 output: a relative rounding of 6e-8 and an absolute one near 0.
                    if got < chord * (1.0 - 1e-6) - 1e-6 * scale {
                        bad += 1;
                        worst = worst.max((chord - got) / chord);
                    }
                }
            }
            report.push(format!(
                "{:?} {method:?}: {bad} of {checked} below the chord (worst {:.1} %)",
                path.file_name().unwrap(),
                100.0 * worst
            ));
        }
    }
    println!("{}", report.join("\n"));
    assert!(
        report.iter().all(|r| r.contains(": 0 of")),
        "{}",
        report.join("\n")
    );
}

#[test]
fn next_to_the_source_the_unfolded_distances_are_exact_on_developable_meshes() {
    // A plane and a half cylinder (unrolls isometrically onto the unit square): around a vertex
    // source (1- and 2-ring) and around surface points (their triangle and the next ring), every
    // method returns the unrolled straight-line distance.
    let n = 41;
    let h = 1.0 / (n - 1) as f64;
    let r = 1.0 / std::f64::consts::PI;
    for (name, map) in [
        (
            "plane",
            Box::new(|x: f64, y: f64| DVec3::new(x, y, 0.0)) as Box<dyn Fn(f64, f64) -> DVec3>,
        ),
        (
            "cylinder",
            Box::new(move |x: f64, y: f64| {
                let a = x * std::f64::consts::PI;
                DVec3::new(r * a.cos(), r * a.sin(), y)
            }),
        ),
    ] {
        let (v, f) = grid(n, map);
        let s = GeodesicSolver::new(Mesh::new(&v, &f).unwrap());
        let m = s.mesh();
        // The polyhedral half cylinder unrolls onto columns one chord (not one arc) wide.
        let w = if name == "plane" {
            h
        } else {
            2.0 * r * (std::f64::consts::PI * h / 2.0).sin()
        };
        let uv = |i: usize| DVec3::new((i % n) as f64 * w, (i / n) as f64 * h, 0.0);
        // The face containing vertex 20·n+20 as its first corner, and a point inside it.
        let centre = 20 * n + 20;
        let face = m.faces.iter().position(|t| t[0] == centre).unwrap();
        let bary = [0.2, 0.5, 0.3];
        let fp = m.faces[face];
        let p_uv = uv(fp[0]) * bary[0] + uv(fp[1]) * bary[1] + uv(fp[2]) * bary[2];
        let edge_bary = [0.0, 0.35, 0.65];
        let e_uv = uv(fp[1]) * edge_bary[1] + uv(fp[2]) * edge_bary[2];
        let cases = [
            (Source::Vertex(centre), uv(centre), 2.0 * h),
            (Source::Point(SurfacePoint { face, bary }), p_uv, 1.4 * h),
            (
                Source::Point(SurfacePoint {
                    face,
                    bary: edge_bary,
                }),
                e_uv,
                1.2 * h,
            ),
        ];
        // The exact method everywhere (the unrolled straight line never leaves the strip).
        for (src, at, _) in cases {
            let d = s.distances(&[vec![src]], Method::Exact).unwrap();
            for (i, &di) in d.iter().enumerate().take(n * n) {
                let want = uv(i).distance(at);
                assert!(
                    (di as f64 - want).abs() < 2e-6,
                    "{name} exact {src:?}: vertex {i} at {} should be {want}",
                    di
                );
            }
        }
        for method in [Method::Heat, Method::Dijkstra] {
            for (src, at, radius) in cases {
                let d = s.distances(&[vec![src]], method).unwrap();
                let mut checked = 0;
                for (i, &di) in d.iter().enumerate().take(n * n) {
                    let want = uv(i).distance(at);
                    if want <= radius {
                        checked += 1;
                        assert!(
                            (di as f64 - want).abs() < 2e-6,
                            "{name} {method:?} {src:?}: vertex {i} at {} should be {want}",
                            di
                        );
                    }
                }
                assert!(
                    checked >= 6,
                    "{name}: only {checked} vertices near the source"
                );
            }
        }
    }
}
