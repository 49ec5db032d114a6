//! Intrinsic Delaunay triangulation by edge flips (Fisher, Springborn, Schröder, Bobenko 2007;
//! Sharp & Crane 2020 for its use as a robust Laplacian on scanned meshes).
//!
//! The triangulation keeps the mesh's vertices and its metric (edge lengths) but flips non-Delaunay
//! edges *intrinsically*: the new edge runs across the two triangles on the surface, its length
//! found by laying them out in the plane. The cotan Laplacian of an intrinsic Delaunay triangulation
//! has no negative weights, which is what keeps the heat method accurate on meshes with obtuse
//! slivers. Only manifold, consistently oriented interior edges are flipped; boundary and
//! non-manifold edges stay as they are (the result is then Delaunay everywhere else).

use glam::DVec2;

const NONE: usize = usize::MAX;

/// An intrinsic triangulation: per face its vertices (counter-clockwise) and the length of the
/// edge from corner k to corner k+1.
pub struct Intrinsic {
    pub faces: Vec<[usize; 3]>,
    pub lengths: Vec<[f64; 3]>,
    /// Number of flips made (for reports and tests).
    pub flips: usize,
}

/// Area of a triangle from its edge lengths (Kahan's stable Heron formula).
pub fn area_from_lengths(a: f64, b: f64, c: f64) -> f64 {
    let mut s = [a, b, c];
    s.sort_by(|x, y| y.total_cmp(x));
    let [a, b, c] = s;
    let p = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c));
    0.25 * p.max(0.0).sqrt()
}

/// Cotangent of the angle opposite the edge of length `opp`, between edges `a` and `b`.
pub fn cot_opposite(opp: f64, a: f64, b: f64, area: f64) -> f64 {
    (a * a + b * b - opp * opp) / (4.0 * area)
}

/// The 2D layout of a triangle with lengths l01, l12, l20: corner 0 at the origin, corner 1 on +x,
/// corner 2 above.
pub fn layout(l: [f64; 3]) -> [DVec2; 3] {
    let (l01, l12, l20) = (l[0], l[1], l[2]);
    let x = (l01 * l01 + l20 * l20 - l12 * l12) / (2.0 * l01);
    let y = (l20 * l20 - x * x).max(0.0).sqrt();
    [DVec2::ZERO, DVec2::new(l01, 0.0), DVec2::new(x, y)]
}

impl Intrinsic {
    /// Flip to intrinsic Delaunay. Faces with zero area (or broken triangle inequality) are kept
    /// but never flipped across.
    pub fn delaunay(faces: &[[usize; 3]], lengths: Vec<[f64; 3]>) -> Self {
        let nf = faces.len();
        let mut faces = faces.to_vec();
        let mut lengths = lengths;
        // twin[3f + k] = 3g + j: halfedge k of face f (corner k → k+1) is glued to halfedge j of g.
        let mut twin = vec![NONE; 3 * nf];
        {
            let mut keyed: Vec<(usize, usize, usize)> = Vec::with_capacity(3 * nf);
            for (f, t) in faces.iter().enumerate() {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    if a != b {
                        keyed.push((a.min(b), a.max(b), 3 * f + k));
                    }
                }
            }
            keyed.sort_unstable();
            let mut i = 0;
            while i < keyed.len() {
                let mut j = i + 1;
                while j < keyed.len() && keyed[j].0 == keyed[i].0 && keyed[j].1 == keyed[i].1 {
                    j += 1;
                }
                if j - i == 2 {
                    let (h1, h2) = (keyed[i].2, keyed[i + 1].2);
                    let (f1, k1, f2, k2) = (h1 / 3, h1 % 3, h2 / 3, h2 % 3);
                    // Consistent orientation: the two halfedges run in opposite directions.
                    if faces[f1][k1] == faces[f2][(k2 + 1) % 3]
                        && faces[f1][(k1 + 1) % 3] == faces[f2][k2]
                    {
                        twin[h1] = h2;
                        twin[h2] = h1;
                    }
                }
                i = j;
            }
        }
        let good = |l: &[f64; 3]| {
            let a = area_from_lengths(l[0], l[1], l[2]);
            a > 1e-12 * l.iter().fold(0.0f64, |m, x| m.max(*x)).powi(2)
        };
        let mut stack: Vec<usize> = (0..3 * nf)
            .filter(|&h| twin[h] != NONE && h < twin[h])
            .collect();
        let mut in_stack = vec![false; 3 * nf];
        for &h in &stack {
            in_stack[h] = true;
        }
        let mut flips = 0;
        let max_flips = 50 * nf + 1000;
        while let Some(h) = stack.pop() {
            in_stack[h] = false;
            let t = twin[h];
            if t == NONE || flips >= max_flips {
                continue;
            }
            let (f, k, g, j) = (h / 3, h % 3, t / 3, t % 3);
            let (lf, lg) = (lengths[f], lengths[g]);
            if !good(&lf) || !good(&lg) {
                continue;
            }
            // Face f = (a, b, c) with edge a→b at k; face g = (b, a, d) with edge b→a at j.
            let (a, b, c) = (faces[f][k], faces[f][(k + 1) % 3], faces[f][(k + 2) % 3]);
            let d = faces[g][(j + 2) % 3];
            if c == d {
                continue;
            }
            let (l_ab, l_bc, l_ca) = (lf[k], lf[(k + 1) % 3], lf[(k + 2) % 3]);
            let (l_ad, l_db) = (lg[(j + 1) % 3], lg[(j + 2) % 3]);
            let af = area_from_lengths(l_ab, l_bc, l_ca);
            let ag = area_from_lengths(l_ab, l_ad, l_db);
            let cot_c = cot_opposite(l_ab, l_bc, l_ca, af);
            let cot_d = cot_opposite(l_ab, l_ad, l_db, ag);
            if cot_c + cot_d >= -1e-12 {
                continue; // Delaunay
            }
            // Lay out: a at the origin, b on +x, c above, d below; the new edge is c–d.
            let x_c = (l_ab * l_ab + l_ca * l_ca - l_bc * l_bc) / (2.0 * l_ab);
            let y_c = (l_ca * l_ca - x_c * x_c).max(0.0).sqrt();
            let x_d = (l_ab * l_ab + l_ad * l_ad - l_db * l_db) / (2.0 * l_ab);
            let y_d = -(l_ad * l_ad - x_d * x_d).max(0.0).sqrt();
            let l_cd = ((x_c - x_d).powi(2) + (y_c - y_d).powi(2)).sqrt();
            // Outer halfedges and their twins before the flip.
            let (h_bc, h_ca) = (3 * f + (k + 1) % 3, 3 * f + (k + 2) % 3);
            let (h_ad, h_db) = (3 * g + (j + 1) % 3, 3 * g + (j + 2) % 3);
            let (t_bc, t_ca, t_ad, t_db) = (twin[h_bc], twin[h_ca], twin[h_ad], twin[h_db]);
            // New faces: f = (c, a, d), g = (d, b, c); the shared edge is d→c in f, c→d in g.
            faces[f] = [c, a, d];
            lengths[f] = [l_ca, l_ad, l_cd];
            faces[g] = [d, b, c];
            lengths[g] = [l_db, l_bc, l_cd];
            let set = |tw: &mut Vec<usize>, x: usize, y: usize| {
                tw[x] = y;
                if y != NONE {
                    tw[y] = x;
                }
            };
            set(&mut twin, 3 * f, t_ca); // c→a
            set(&mut twin, 3 * f + 1, t_ad); // a→d
            set(&mut twin, 3 * g, t_db); // d→b
            set(&mut twin, 3 * g + 1, t_bc); // b→c
            set(&mut twin, 3 * f + 2, 3 * g + 2); // d→c with c→d
            flips += 1;
            for x in [3 * f, 3 * f + 1, 3 * g, 3 * g + 1] {
                let y = twin[x];
                if y != NONE {
                    let key = x.min(y);
                    if !in_stack[key] {
                        in_stack[key] = true;
                        stack.push(key);
                    }
                }
            }
            let _ = (h_bc, h_ca, h_ad, h_db);
        }
        Intrinsic {
            faces,
            lengths,
            flips,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flips_the_long_diagonal_of_a_thin_rhombus() {
        // Square-ish quad a(0,0) b(2,0) split along a–b with apexes c(1, 0.2) and d(1, -0.2):
        // the edge a–b sees two obtuse angles and must flip to c–d.
        let pts = [
            DVec2::new(0.0, 0.0),
            DVec2::new(2.0, 0.0),
            DVec2::new(1.0, 0.2),
            DVec2::new(1.0, -0.2),
        ];
        let faces = vec![[0, 1, 2], [1, 0, 3]];
        let len = |f: &[usize; 3]| [0, 1, 2].map(|k| pts[f[k]].distance(pts[f[(k + 1) % 3]]));
        let lengths = faces.iter().map(len).collect();
        let t = Intrinsic::delaunay(&faces, lengths);
        assert_eq!(t.flips, 1);
        let diag = t.lengths[0][2];
        assert!((diag - 0.4).abs() < 1e-12, "new edge c–d has length {diag}");
        let total: f64 = t
            .lengths
            .iter()
            .map(|l| area_from_lengths(l[0], l[1], l[2]))
            .sum();
        assert!((total - 0.4).abs() < 1e-12, "area is kept: {total}");
    }
}
