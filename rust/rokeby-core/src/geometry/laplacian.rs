//! The cotangent Laplacian, one home (Pinkall & Polthier 1993; Crane et al. 2013 eq. 5; Sorkine
//! 2006 §2): the weight of edge (i, j) is w_ij = ½ (cot α_ij + cot β_ij), α and β the angles
//! opposite the edge in its faces, computed from edge lengths alone ([`crate::geometry::intrinsic`]'s
//! stable Heron area and law of cosines) so that it serves both intrinsic triangulations (the
//! geodesic heat method) and meshes with positions (the shadow mesh). Faces without area
//! (collinear or repeated corners) have no stiffness and are left out.

use crate::geometry::intrinsic::{area_from_lengths, cot_opposite};
use glam::DVec3;

/// Area and corner cotangents of one face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceCotangents {
    pub area: f64,
    /// cot[k]: the cotangent of the angle at corner k (opposite the edge from k+1 to k+2).
    pub cot: [f64; 3],
}

/// The corner cotangents of a triangle with edge lengths `l` (l[k]: from corner k to k+1); `None`
/// for a face without area (area ≤ 10⁻¹² · longest², or not finite).
pub fn face_cotangents(l: [f64; 3]) -> Option<FaceCotangents> {
    let area = area_from_lengths(l[0], l[1], l[2]);
    let longest = l.iter().fold(0.0f64, |m, x| m.max(*x));
    // `longest` is never NaN (f64::max skips NaN); a NaN area has no area.
    if area.is_nan() || area <= 1e-12 * longest * longest {
        return None;
    }
    // The edge opposite corner k is l[(k+1)%3], between l[k] and l[(k+2)%3].
    let cot = [0, 1, 2].map(|k| cot_opposite(l[(k + 1) % 3], l[k], l[(k + 2) % 3], area));
    Some(FaceCotangents { area, cot })
}

/// The edge lengths of face `f` of a mesh with positions `v`: [|v1 − v0|, |v2 − v1|, |v0 − v2|].
pub fn edge_lengths(v: &[DVec3], f: [usize; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| v[f[k]].distance(v[f[(k + 1) % 3]]))
}

/// Cotangent weights w_ij per undirected edge (i < j), summed over the edge's faces, sorted by
/// (i, j). Faces with repeated vertices or without area contribute nothing.
pub fn cotangent_weights(faces: &[[usize; 3]], lengths: &[[f64; 3]]) -> Vec<(u32, u32, f64)> {
    let mut e: Vec<(u32, u32, f64)> = Vec::with_capacity(faces.len() * 3);
    for (f, l) in faces.iter().zip(lengths) {
        if !crate::geometry::mesh::is_proper(f) {
            continue;
        }
        let Some(fc) = face_cotangents(*l) else {
            continue;
        };
        for k in 0..3 {
            let (i, j) = (f[(k + 1) % 3] as u32, f[(k + 2) % 3] as u32);
            e.push((i.min(j), i.max(j), 0.5 * fc.cot[k]));
        }
    }
    e.sort_unstable_by_key(|a| (a.0, a.1));
    let mut out: Vec<(u32, u32, f64)> = Vec::with_capacity(e.len() / 2 + 1);
    for (i, j, w) in e {
        match out.last_mut() {
            Some(l) if l.0 == i && l.1 == j => l.2 += w,
            _ => out.push((i, j, w)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn right_isoceles_triangle() {
        // Corners (0,0), (1,0), (0,1): 90° at corner 0, 45° at the others.
        let v = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let fc = face_cotangents(edge_lengths(&v, [0, 1, 2])).unwrap();
        assert!((fc.area - 0.5).abs() < 1e-15);
        assert!(fc.cot[0].abs() < 1e-15);
        assert!((fc.cot[1] - 1.0).abs() < 1e-15 && (fc.cot[2] - 1.0).abs() < 1e-15);
        let w = cotangent_weights(&[[0, 1, 2]], &[edge_lengths(&v, [0, 1, 2])]);
        // Edge (1, 2) is opposite the right angle: weight 0; the legs ½ cot 45° = ½.
        assert_eq!(w.len(), 3);
        assert!((w[0].2 - 0.5).abs() < 1e-15 && (w[1].2 - 0.5).abs() < 1e-15);
        assert!(w[2].2.abs() < 1e-15 && (w[2].0, w[2].1) == (1, 2));
    }

    #[test]
    fn matches_the_dot_over_cross_formula_and_sums_shared_edges() {
        let v = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.1, 0.2),
            DVec3::new(0.3, 1.2, -0.1),
            DVec3::new(1.4, 1.1, 0.5),
        ];
        let faces = [[0usize, 1, 2], [1, 3, 2]];
        let lengths: Vec<[f64; 3]> = faces.iter().map(|&f| edge_lengths(&v, f)).collect();
        let w = cotangent_weights(&faces, &lengths);
        let cot = |o: usize, a: usize, b: usize| {
            let (x, y) = (v[a] - v[o], v[b] - v[o]);
            x.dot(y) / x.cross(y).length()
        };
        let shared = w.iter().find(|e| (e.0, e.1) == (1, 2)).unwrap().2;
        assert!((shared - 0.5 * (cot(0, 1, 2) + cot(3, 1, 2))).abs() < 1e-12);
        assert_eq!(w.len(), 5);
    }

    #[test]
    fn faces_without_area_have_no_stiffness() {
        let v = [DVec3::ZERO, DVec3::X, 2.0 * DVec3::X];
        assert!(face_cotangents(edge_lengths(&v, [0, 1, 2])).is_none());
        assert!(
            cotangent_weights(&[[0, 1, 2], [0, 0, 1]], &[edge_lengths(&v, [0, 1, 2]); 2])
                .is_empty()
        );
    }
}
