//! The light's frustum around a shadow caster: the 2D space in which shadow boundaries are
//! deformed (Mattausch et al. §5.2, "Choosing a deformation space") and the post-perspective light
//! space in which the shadow mesh is solved (§6.1).
//!
//! For a point light at l the frustum looks from l along the direction to the caster's bounds
//! centre; with light-view coordinates (X, Y, Z), Z > 0 the depth along that axis,
//!
//! x = X / (Z·t), y = Y / (Z·t), z = f/(f − n) · (1 − n/Z),
//!
//! where t is the half-opening (tangent) that just encloses the caster and [n, f] its depth range:
//! the caster maps into x, y ∈ [−1, 1], z ∈ [0, 1] (the usual perspective divide up to an affine
//! map). A directional light uses the orthographic frustum x = X/r, y = Y/r, z = (Z − n)/(f − n).
//! A point light inside the caster's bounding box has no frustum around the whole caster. The
//! paper's answer (§5.2: "if the light is allowed to enter the bounding volume of a shadow caster,
//! a more robust solution is to automatically calculate a shadow frustum for each silhouette loop
//! separately") is [`LightFrame::for_loop`]: a frustum around one loop's silhouette vertices, in
//! which that loop is deformed. The shadow mesh (§6.1) then needs one space for the whole caster:
//! [`LightSpace::Spherical`], the post-perspective depth laid along the rays from the light,
//!
//! Q(p) = u · (1 + z(r)/w_z),  u = (p − l)/r,  r = |p − l|,  z(r) = f/(f − n) · (1 − n/r),
//!
//! with [n, f] the caster's distance range from the light: like the frustum's space it maps every
//! ray from the light to a straight line (a radial one) with the same depth term z, but it covers
//! every direction around the light (one unit of Q across the rays is one radian).

use crate::error::{Result, RokebyError};
use crate::shadows::silhouette::Light;
use glam::{DMat3, DVec3};

/// The widest angle between a silhouette loop's vertices and its frustum's axis (§5.2, per-loop
/// frusta); beyond it the perspective divide x = X/Z runs away.
pub const MAX_LOOP_HALF_ANGLE_DEG: f64 = 80.0;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightFrame {
    pub light: Light,
    /// Frustum origin (the light position, or a point behind the caster for a directional light).
    pub origin: DVec3,
    /// Rows: the light-view axes (x, y, z = viewing direction).
    pub basis: DMat3,
    /// Half-opening tangent (point light) or half-width (directional light) of the frustum.
    pub half: f64,
    pub near: f64,
    pub far: f64,
}

fn orthonormal_basis(z: DVec3) -> DMat3 {
    let up = if z.z.abs() < 0.9 { DVec3::Z } else { DVec3::X };
    let x = up.cross(z).normalize();
    let y = z.cross(x);
    // Rows x, y, z: basis * p gives light-view coordinates.
    DMat3::from_cols(x, y, z).transpose()
}

impl LightFrame {
    /// The frustum of `light` enclosing the caster's `vertices`.
    pub fn new(light: Light, vertices: &[DVec3]) -> Result<Self> {
        light.validate()?;
        if vertices.is_empty() {
            return Err(RokebyError::invalid(
                "vertices",
                "the caster has no vertices",
            ));
        }
        let (mn, mx) = vertices.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(a, b), &p| (a.min(p), b.max(p)),
        );
        let centre = (mn + mx) * 0.5;
        let radius = ((mx - mn) * 0.5).length().max(1e-300);
        // The fuzzer found a vertex at 1e300 giving radius = inf and a NaN frame.
        if !radius.is_finite() {
            return Err(RokebyError::invalid("vertices", "the caster's vertices must be finite and its extent representable (|coordinates| well below 1e154)"));
        }
        match light {
            Light::Point(l) => {
                if l.cmpge(mn).all() && l.cmple(mx).all() {
                    return Err(RokebyError::invalid(
                        "light",
                        format!(
                            "the light at ({:.4}, {:.4}, {:.4}) is inside the caster's bounding box ({:.4}, {:.4}, {:.4})–({:.4}, {:.4}, {:.4}); move it outside the caster to edit its shadow",
                            l.x, l.y, l.z, mn.x, mn.y, mn.z, mx.x, mx.y, mx.z
                        ),
                    ));
                }
                let axis = (centre - l).normalize();
                let basis = orthonormal_basis(axis);
                let mut near = f64::INFINITY;
                let mut far: f64 = 0.0;
                let mut half: f64 = 0.0;
                for &p in vertices {
                    let q = basis * (p - l);
                    if q.z <= 1e-9 * radius {
                        return Err(RokebyError::invalid(
                            "light",
                            "the caster reaches beside or behind the light (it spans more than the light's forward half-space); move the light away from the caster",
                        ));
                    }
                    near = near.min(q.z);
                    far = far.max(q.z);
                    half = half.max(q.x.abs() / q.z).max(q.y.abs() / q.z);
                }
                if far - near < 1e-9 * far {
                    far = near * 2.0;
                }
                Ok(LightFrame {
                    light,
                    origin: l,
                    basis,
                    half: half.max(1e-12),
                    near,
                    far,
                })
            }
            Light::Directional(d) => {
                let axis = d.normalize();
                let basis = orthonormal_basis(axis);
                let origin = centre - axis * (2.0 * radius);
                let mut near = f64::INFINITY;
                let mut far: f64 = 0.0;
                let mut half: f64 = 0.0;
                for &p in vertices {
                    let q = basis * (p - origin);
                    near = near.min(q.z);
                    far = far.max(q.z);
                    half = half.max(q.x.abs()).max(q.y.abs());
                }
                if far - near < 1e-9 * radius {
                    far = near + radius;
                }
                Ok(LightFrame {
                    light,
                    origin,
                    basis,
                    half: half.max(1e-12 * radius),
                    near,
                    far,
                })
            }
        }
    }

    /// World point → frustum coordinates (x, y, z).
    pub fn to_frustum(&self, p: DVec3) -> DVec3 {
        let q = self.basis * (p - self.origin);
        match self.light {
            Light::Point(_) => DVec3::new(
                q.x / (q.z * self.half),
                q.y / (q.z * self.half),
                self.far / (self.far - self.near) * (1.0 - self.near / q.z),
            ),
            Light::Directional(_) => DVec3::new(
                q.x / self.half,
                q.y / self.half,
                (q.z - self.near) / (self.far - self.near),
            ),
        }
    }

    /// §5.2, per-loop frusta: the frustum of a point light around one silhouette loop's
    /// vertices `points` (its axis the mean of the directions to them), for a light inside the
    /// caster's bounds. A directional light's frustum is the caster's ([`Self::new`]). Error: a
    /// loop reaching more than [`MAX_LOOP_HALF_ANGLE_DEG`] from that axis (it wraps round the
    /// light; no perspective frustum holds it).
    pub fn for_loop(light: Light, points: &[DVec3]) -> Result<Self> {
        light.validate()?;
        let Light::Point(l) = light else {
            return Self::new(light, points);
        };
        if points.is_empty() {
            return Err(RokebyError::invalid(
                "loop",
                "the silhouette loop has no vertices",
            ));
        }
        let mut sum = DVec3::ZERO;
        for &p in points {
            let d = p - l;
            let len = d.length();
            if !(len.is_finite() && len > 0.0) {
                return Err(RokebyError::invalid(
                    "light",
                    "the light lies on the caster's silhouette; move it off the caster's surface",
                ));
            }
            sum += d / len;
        }
        let Some(axis) = sum.try_normalize() else {
            return Err(RokebyError::invalid(
                "light",
                "a silhouette loop surrounds the light on every side (its directions from the light cancel); no frustum holds it",
            ));
        };
        let basis = orthonormal_basis(axis);
        let cos_max = MAX_LOOP_HALF_ANGLE_DEG.to_radians().cos();
        let mut near = f64::INFINITY;
        let mut far: f64 = 0.0;
        let mut half: f64 = 0.0;
        for &p in points {
            let q = basis * (p - l);
            if q.z <= cos_max * q.length() {
                let deg = (q.z / q.length()).clamp(-1.0, 1.0).acos().to_degrees();
                return Err(RokebyError::invalid(
                    "light",
                    format!("a silhouette loop reaches {deg:.0}° from its mean direction as seen from the light (more than {MAX_LOOP_HALF_ANGLE_DEG}°): it wraps round the light and no frustum holds it"),
                ));
            }
            near = near.min(q.z);
            far = far.max(q.z);
            half = half.max(q.x.abs() / q.z).max(q.y.abs() / q.z);
        }
        if far - near < 1e-9 * far {
            // A loop at one depth (a circle round the axis): any depth range around it will do;
            // the loop's own depth is kept during a drag.
            near *= 0.5;
            far *= 2.0;
        }
        Ok(LightFrame {
            light,
            origin: l,
            basis,
            half: half.max(1e-12),
            near,
            far,
        })
    }

    /// Frustum coordinates → world point (the inverse of [`Self::to_frustum`]).
    pub fn from_frustum(&self, c: DVec3) -> DVec3 {
        let q = match self.light {
            Light::Point(_) => {
                let z = self.near / (1.0 - c.z * (self.far - self.near) / self.far);
                DVec3::new(c.x * z * self.half, c.y * z * self.half, z)
            }
            Light::Directional(_) => DVec3::new(
                c.x * self.half,
                c.y * self.half,
                self.near + c.z * (self.far - self.near),
            ),
        };
        self.basis.transpose() * q + self.origin
    }

    /// Depth along the frustum axis (light-view Z).
    pub fn depth(&self, p: DVec3) -> f64 {
        (self.basis * (p - self.origin)).z
    }

    /// §5.1: the modified silhouette point f on the light ray through the receiver point `e`, at
    /// the depth of the silhouette point `a` — or `e` itself when `e` is nearer the light than `a`
    /// (contact shadows, Fig. 4 right).
    pub fn drag_target(&self, a: DVec3, e: DVec3) -> DVec3 {
        let za = self.depth(a);
        let ze = self.depth(e);
        if ze <= za {
            return e;
        }
        match self.light {
            Light::Point(l) => l + (e - l) * (za / ze),
            Light::Directional(d) => e - d.normalize() * (ze - za),
        }
    }
}

/// The space the shadow mesh is solved in (§6.1: post-perspective light space scaled by
/// (1, 1, 1/w_z)): the light's frustum around the whole caster, or, for a point light inside the
/// caster's bounds (per-loop frusta, §5.2), the spherical post-perspective space of the module
/// documentation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LightSpace {
    Frustum(LightFrame),
    Spherical {
        light: DVec3,
        /// Nearest and farthest caster vertex from the light.
        near: f64,
        far: f64,
    },
}

impl LightSpace {
    /// The spherical space of a point light at `light` for the caster's `vertices`. Error: the
    /// light on a vertex (no direction to it).
    pub fn spherical(light: DVec3, vertices: &[DVec3]) -> Result<Self> {
        let mut near = f64::INFINITY;
        let mut far: f64 = 0.0;
        for &p in vertices {
            let r = (p - light).length();
            near = near.min(r);
            far = far.max(r);
        }
        if !(near.is_finite() && far.is_finite()) || near <= 1e-9 * far {
            return Err(RokebyError::invalid(
                "light",
                "the light lies on the caster's surface (a vertex is at the light); move it off the caster",
            ));
        }
        if far - near < 1e-9 * far {
            far = near * 2.0;
        }
        Ok(LightSpace::Spherical { light, near, far })
    }

    /// World point → solve space, the light direction scaled by 1/`w_z` (§6.1).
    pub fn to_space(&self, p: DVec3, w_z: f64) -> DVec3 {
        match *self {
            LightSpace::Frustum(fr) => fr.to_frustum(p) * DVec3::new(1.0, 1.0, 1.0 / w_z),
            LightSpace::Spherical { light, near, far } => {
                let d = p - light;
                let r = d.length();
                let z = far / (far - near) * (1.0 - near / r);
                d / r * (1.0 + z / w_z)
            }
        }
    }

    /// Solve space → world point (the inverse of [`Self::to_space`]; non-finite where the point
    /// has no world position, e.g. past the light).
    pub fn from_space(&self, q: DVec3, w_z: f64) -> DVec3 {
        match *self {
            LightSpace::Frustum(fr) => fr.from_frustum(q * DVec3::new(1.0, 1.0, w_z)),
            LightSpace::Spherical { light, near, far } => {
                let rho = q.length();
                let z = (rho - 1.0) * w_z;
                let den = 1.0 - z * (far - near) / far;
                if !(rho > 0.0 && den > 0.0) {
                    return DVec3::splat(f64::NAN);
                }
                light + q / rho * (near / den)
            }
        }
    }
}
