//! Regions of interest (Ritschel et al. 2009, §4 "Regions" and eq. 7).
//!
//! A region gives every surface point q an influence a(q) ∈ [0, 1]: 1 in its core, falling to 0
//! across a border of user-set width with a smooth step, 0 outside. Euclidean regions are computed
//! here from a centre and a radius; geodesic and free-form regions arrive as per-point values
//! (computed from geodesic distances or painted as a vertex group), together with their value at
//! each constraint, which decides which constraints are *inside* the region (a(pₙ) > 0).

use crate::error::{Result, RokebyError};
use crate::geometry::geodesic::{GeodesicSolver, Method, Source};
use glam::DVec3;

/// Hermite smooth step: 0 for t ≤ 0, 1 for t ≥ 1, 3t² − 2t³ between (C¹ at both ends).
#[inline]
pub fn smooth_step(t: f64) -> f64 {
    if t.is_nan() || t <= 0.0 {
        return 0.0; // t ≤ 0, and NaN: a NaN distance must not give a NaN weight
    }
    let t = t.min(1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Influence at distance `d` from the centre of a region of outer `radius` whose border band,
/// `border` wide, lies inside the radius: a = 1 for d ≤ radius − border, 0 for d ≥ radius.
/// A border of 0 is a hard edge; a border larger than the radius is clamped to the radius.
#[inline]
pub fn influence(d: f64, radius: f64, border: f64) -> f64 {
    let border = border.min(radius);
    // A NaN distance (an unreachable point) goes to 0 too.
    if d.is_nan() || radius.is_nan() || d >= radius {
        return 0.0;
    }
    let inner = radius - border;
    if d <= inner {
        return 1.0;
    }
    1.0 - smooth_step((d - inner) / border)
}

/// A region as the field sees it.
#[derive(Debug, Clone)]
pub enum Region {
    /// Centre, outer radius and border width in scene units (may span several objects).
    Euclidean {
        center: DVec3,
        radius: f64,
        border: f64,
    },
    /// a(q) given per evaluated point (geodesic or free-form regions), and a(pₙ) per constraint.
    PerPoint {
        values: Vec<f32>,
        at_constraints: Vec<f32>,
    },
}

impl Region {
    pub fn euclidean(center: [f64; 3], radius: f64, border: f64, name: &str) -> Result<Self> {
        let c = DVec3::from_array(center);
        if !c.is_finite() {
            return Err(RokebyError::invalid(name, "center must be finite"));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(RokebyError::invalid(
                name,
                format!("radius must be finite and > 0, got {radius}"),
            ));
        }
        if !(border.is_finite() && border >= 0.0) {
            return Err(RokebyError::invalid(
                name,
                format!("border must be finite and >= 0, got {border}"),
            ));
        }
        Ok(Region::Euclidean {
            center: c,
            radius,
            border,
        })
    }

    /// `n_points`/`n_constraints` are the sizes the arrays must have.
    pub fn per_point(
        values: Vec<f32>,
        at_constraints: Vec<f32>,
        n_points: usize,
        n_constraints: usize,
        name: &str,
    ) -> Result<Self> {
        if values.len() != n_points {
            return Err(RokebyError::invalid(
                name,
                format!(
                    "values has {} entries but there are {} points",
                    values.len(),
                    n_points
                ),
            ));
        }
        if at_constraints.len() != n_constraints {
            return Err(RokebyError::invalid(
                name,
                format!(
                    "at_constraints has {} entries but there are {} constraints",
                    at_constraints.len(),
                    n_constraints
                ),
            ));
        }
        for (what, arr) in [("values", &values), ("at_constraints", &at_constraints)] {
            if let Some((i, v)) = arr
                .iter()
                .enumerate()
                .find(|(_, v)| !(v.is_finite() && (0.0..=1.0).contains(*v)))
            {
                return Err(RokebyError::invalid(
                    name,
                    format!("{what}[{i}] = {v} is not in [0, 1]"),
                ));
            }
        }
        Ok(Region::PerPoint {
            values,
            at_constraints,
        })
    }

    /// a(q) at evaluated point `index` with position `q`.
    #[inline]
    pub fn at_point(&self, index: usize, q: DVec3) -> f64 {
        match self {
            Region::Euclidean {
                center,
                radius,
                border,
            } => influence(q.distance(*center), *radius, *border),
            Region::PerPoint { values, .. } => values[index] as f64,
        }
    }

    /// a(pₙ) for constraint `k` at `p`.
    pub fn at_constraint(&self, k: usize, p: DVec3) -> f64 {
        match self {
            Region::Euclidean {
                center,
                radius,
                border,
            } => influence(p.distance(*center), *radius, *border),
            Region::PerPoint { at_constraints, .. } => at_constraints[k] as f64,
        }
    }
}

/// Geodesic region (paper §4): a(q) from geodesic distances to the region's surface centre, with
/// the same border convention as Euclidean regions. Unreachable points (+inf: other connected
/// components) get 0.
pub fn geodesic_weights(distances: &[f32], radius: f64, border: f64) -> Result<Vec<f32>> {
    check_radius_border(radius, border)?;
    Ok(distances
        .iter()
        .map(|&d| {
            if d.is_finite() {
                influence(d as f64, radius, border) as f32
            } else {
                0.0
            }
        })
        .collect())
}

/// Free-form region (paper §4, a vertex group in Blender): painted weights w ∈ [0, 1], with a
/// smooth border of `border` width inside the painted area: a(q) = w(q) · smoothstep(d(q)/border),
/// d(q) being the geodesic distance from q to the nearest unpainted vertex (+inf when every vertex
/// is painted). Unpainted vertices get 0; a border of 0 gives a = w.
pub fn freeform_weights(
    weights: &[f32],
    distance_to_outside: &[f32],
    border: f64,
) -> Result<Vec<f32>> {
    check_freeform(weights, border)?;
    if weights.len() != distance_to_outside.len() {
        return Err(RokebyError::invalid(
            "weights",
            "must have one entry per vertex",
        ));
    }
    Ok(weights
        .iter()
        .zip(distance_to_outside)
        .map(|(&w, &d)| {
            if w <= 0.0 {
                0.0
            } else if border == 0.0 || d.is_infinite() {
                w
            } else {
                (w as f64 * smooth_step(d as f64 / border)) as f32
            }
        })
        .collect())
}

fn check_freeform(weights: &[f32], border: f64) -> Result<()> {
    if !(border.is_finite() && border >= 0.0) {
        return Err(RokebyError::invalid(
            "border",
            format!("must be finite and >= 0, got {border}"),
        ));
    }
    if let Some((i, w)) = weights
        .iter()
        .enumerate()
        .find(|(_, w)| !(w.is_finite() && (0.0..=1.0).contains(*w)))
    {
        return Err(RokebyError::invalid(
            "weights",
            format!("weights[{i}] = {w} is not in [0, 1]"),
        ));
    }
    Ok(())
}

/// A geodesic region of interest on `solver`'s mesh (paper §4): 1 within `radius − border` of
/// the surface point `centre`, measured over the surface by `method`, a smooth step to 0 at
/// `radius`, and 0 on other connected components ([`geodesic_weights`]).
pub fn geodesic_region(
    solver: &GeodesicSolver,
    centre: Source,
    radius: f64,
    border: f64,
    method: Method,
) -> Result<Vec<f32>> {
    check_radius_border(radius, border)?;
    let d = solver.distances(&[vec![centre]], method)?;
    geodesic_weights(&d, radius, border)
}

/// A free-form region from painted per-vertex weights in [0, 1] (a vertex group, paper §4):
/// [`freeform_weights`] with the geodesic distance from the set of unpainted vertices (weight ≤ 0)
/// measured by `method`; without unpainted vertices, or with `border` 0, no distance is needed.
pub fn freeform_region(
    solver: &GeodesicSolver,
    weights: &[f32],
    border: f64,
    method: Method,
) -> Result<Vec<f32>> {
    let nv = solver.mesh().vertices.len();
    if weights.len() != nv {
        return Err(RokebyError::invalid(
            "weights",
            format!(
                "expected {nv} values, one per vertex, got {}",
                weights.len()
            ),
        ));
    }
    check_freeform(weights, border)?;
    let outside: Vec<Source> = weights
        .iter()
        .enumerate()
        .filter(|(_, &x)| x.is_nan() || x <= 0.0)
        .map(|(i, _)| Source::Vertex(i))
        .collect();
    let d = if outside.is_empty() || border == 0.0 {
        vec![f32::INFINITY; nv]
    } else {
        solver.distances(&[outside], method)?
    };
    freeform_weights(weights, &d, border)
}

fn check_radius_border(radius: f64, border: f64) -> Result<()> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(RokebyError::invalid(
            "radius",
            format!("must be finite and > 0, got {radius}"),
        ));
    }
    if !(border.is_finite() && border >= 0.0) {
        return Err(RokebyError::invalid(
            "border",
            format!("must be finite and >= 0, got {border}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> GeodesicSolver {
        // Two triangles of the unit square.
        let v = [
            0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0,
        ];
        let f = [0i64, 1, 2, 0, 2, 3];
        GeodesicSolver::new(crate::geometry::geodesic::Mesh::new(&v, &f).unwrap())
    }

    #[test]
    fn freeform_region_fades_in_from_the_unpainted_vertices() {
        let s = square();
        let a = freeform_region(&s, &[0.0, 1.0, 1.0, 1.0], 10.0, Method::Dijkstra).unwrap();
        assert_eq!(a[0], 0.0);
        // Vertex 1 is 1 away from vertex 0, vertex 2 is √2 away: a smooth step of d/10.
        assert!(a[1] > 0.0 && a[1] < a[2] && a[2] < 1.0, "{a:?}");
        // Every vertex painted: no border to fade over.
        let full = freeform_region(&s, &[0.5; 4], 10.0, Method::Dijkstra).unwrap();
        assert_eq!(full, vec![0.5; 4]);
        let e = freeform_region(&s, &[1.0; 3], 0.0, Method::Heat).unwrap_err();
        assert!(
            e.to_string().starts_with("weights: expected 4 values"),
            "{e}"
        );
        let e = freeform_region(&s, &[2.0; 4], 0.0, Method::Heat).unwrap_err();
        assert!(e.to_string().starts_with("weights: weights[0] = 2"), "{e}");
    }

    #[test]
    fn geodesic_region_validates_before_solving() {
        let s = square();
        let e = geodesic_region(&s, Source::Vertex(0), -1.0, 0.0, Method::Heat).unwrap_err();
        assert!(e.to_string().starts_with("radius"), "{e}");
        assert!(!s.is_factored());
        let a = geodesic_region(&s, Source::Vertex(0), 1.2, 0.0, Method::Dijkstra).unwrap();
        assert_eq!(a, vec![1.0, 1.0, 0.0, 1.0]);
    }

    #[test]
    fn influence_is_smooth_and_bounded() {
        assert_eq!(influence(0.0, 1.0, 0.2), 1.0);
        assert_eq!(influence(0.8, 1.0, 0.2), 1.0);
        assert!((influence(0.9, 1.0, 0.2) - 0.5).abs() < 1e-12);
        assert_eq!(influence(1.0, 1.0, 0.2), 0.0);
        assert_eq!(influence(0.99, 1.0, 0.0), 1.0);
        assert_eq!(influence(1.0, 1.0, 0.0), 0.0);
        // border wider than the radius is clamped: falls from the centre.
        assert!(influence(0.5, 1.0, 5.0) > 0.0 && influence(0.5, 1.0, 5.0) < 1.0);
    }
}
