//! Freeform shadow boundary editing (Mattausch, Igarashi, Wimmer): the editing session.
//!
//! A [`ShadowEditor`] holds a closed caster, the receivers and a light. It computes the smooth
//! silhouette loops of the caster ([`crate::shadows::silhouette`], §4.1), the shadow handles — each
//! silhouette vertex a projected onto the receivers by a shadow ray in direction a − l through a
//! [`Bvh`] over receivers and caster, with a further ray from the hit point whenever the hit face is
//! back-facing (§4.2, Fig. 4 left) — and, per drag (§5.1, Fig. 2): the receiver point e under the
//! cursor → the modified silhouette point f at the depth of a (or e for contact shadows) → a 2D MLS
//! deformation ([`crate::shadows::mls2d`], §5.2) of the selected boundary segment (two fixed ends and the
//! dragged point as control points) in the light's frustum ([`crate::shadows::light_space`]), optional
//! sinusoidal noise (§5.3), and new handles g by shadow rays from the deformed silhouette. The
//! shadow mesh ([`crate::shadows::shadow_mesh`], §6.1) is solved from all edited loops; loops with fewer
//! than `min_loop_vertices` vertices are inactive (shown grey, not selectable, no constraints).
//!
//! A point light inside the caster's bounding box (a light under a hat's brim, inside a ring) has
//! no frustum around the whole caster; as the paper suggests (§5.2), each silhouette loop then
//! gets its own frustum ([`LightFrame::for_loop`]) in which it is deformed, and the shadow mesh is
//! solved in the spherical light space ([`LightSpace::Spherical`]). A light inside the caster's
//! volume (winding number ≥ ½) is an error: it lights only the caster's inside.
//!
//! While a drag is in progress ([`Self::shadow_mesh`] after [`Self::drag`]), the shadow mesh is
//! updated incrementally: with the affine or similarity style and no noise the deformed segment,
//! and so the shadow mesh (§6.1 is linear in the offsets), is an affine function of the dragged
//! point f's frustum (x, y) (Schaefer et al.'s affine and similarity MLS are linear in the
//! deformed control points). The first step of a drag takes the shadow mesh of the drag's base (f
//! at its committed position f₀: remembered from the last commit or solve, the rest pose for no
//! edits) and back-substitutes the responses to f₀ + h·eₓ and f₀ + h·e_y in one pass (four
//! columns: their x and y; a frustum offset has no depth part); every further step of it is a
//! combination of those, O(V).
//!
//! A silhouette vertex lies on a mesh edge, inside the smooth surface the normals describe, so
//! its grazing shadow ray would immediately re-enter the polygonal caster through the faces
//! around that edge; the faces incident to the edge's two vertices are skipped by its rays.

use crate::error::{Result, RokebyError};
use crate::geometry::bvh::{Bvh, Hit};
use crate::shadows::light_space::{LightFrame, LightSpace};
use crate::shadows::mls2d::{sinusoidal_noise, Mls2d, MlsStyle};
use crate::shadows::shadow_mesh::{EdgePoint, ShadowMeshSolver};
use crate::shadows::silhouette::{silhouettes, ClosedMesh, Light, SilhouetteLoop};
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Most rays a handle may take when every hit is a back face (the paper's "second ray", repeated
/// for casters that the ray crosses several times).
pub const MAX_BACK_FACE_RAYS: usize = 8;

/// A shadow handle: where a silhouette vertex's shadow ray lands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Handle {
    /// The landing point (the ray's last origin when it hit nothing).
    pub position: DVec3,
    /// Triangle hit: receivers first (0..num_receiver_faces), then the caster's faces; −1: none.
    pub triangle: i64,
    pub hit: bool,
    /// The handle lies on the caster itself (a self-shadow boundary).
    pub on_caster: bool,
    /// Hidden from the eye: by other geometry, or its surface faces away (only set when an eye
    /// is given; the paper's occlusion queries).
    pub occluded: bool,
}

/// Parameters of one drag (§5.1–5.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drag {
    pub loop_index: usize,
    /// The two fixed ends of the segment (indices into the loop).
    pub fixed: (usize, usize),
    /// The dragged silhouette vertex, strictly inside the segment.
    pub moved: usize,
    /// The receiver point e under the cursor.
    pub target: DVec3,
    pub style: MlsStyle,
    /// Schaefer's α of the MLS weights 1/d^{2α}.
    pub mls_alpha: f64,
    pub noise_amplitude: f64,
    pub noise_frequency: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct DragResult {
    /// The loop's (modified) silhouette vertices, all of them.
    pub silhouette: Vec<DVec3>,
    /// Their handles.
    pub handles: Vec<Handle>,
    /// The loop indices of the deformed segment, fixed ends included, in order.
    pub segment: Vec<usize>,
    /// The modified silhouette point f of the dragged vertex.
    pub moved_to: DVec3,
}

/// What identifies one drag (the same segment, dragged point and deformation) between steps.
#[derive(Debug, Clone, Copy, PartialEq)]
struct DragKey {
    loop_index: usize,
    fixed: (usize, usize),
    moved: usize,
    style: MlsStyle,
    mls_alpha: f64,
}

/// The incremental shadow mesh of one drag: x(f) = x₀ + Gₓ (f − f₀).x + G_y (f − f₀).y in the
/// solve space.
struct DragCache {
    key: DragKey,
    epoch: u64,
    f0: DVec2,
    x0: Vec<DVec3>,
    gx: Vec<DVec3>,
    gy: Vec<DVec3>,
}

impl DragCache {
    /// The solve-space shadow mesh for the dragged point at `f2`.
    fn at(&self, f2: DVec2) -> Vec<DVec3> {
        let (dx, dy) = (f2.x - self.f0.x, f2.y - self.f0.y);
        self.x0
            .iter()
            .zip(self.gx.iter().zip(&self.gy))
            .map(|(x0, (gx, gy))| *x0 + *gx * dx + *gy * dy)
            .collect()
    }
}

/// A solve-space shadow mesh and the constraint offsets it solves for: a drag's first step that
/// starts from these offsets (the state the last drag was committed or cancelled to) takes it
/// instead of back-substituting it again.
struct Solved {
    offsets: Vec<DVec3>,
    x: Vec<DVec3>,
}

/// Step (in frustum units) of the two extra right-hand sides of [`DragCache`]; the map is affine,
/// so any step gives the same result up to rounding.
const CACHE_STEP: f64 = 0.1;

pub struct ShadowEditor {
    caster: ClosedMesh,
    light: Light,
    /// The frustum around the whole caster (None: per-loop frusta).
    frame: Option<LightFrame>,
    /// Per loop: its frustum (the caster's, or its own with per-loop frusta; None: a loop no
    /// frustum holds, inactive).
    frames: Vec<Option<LightFrame>>,
    /// Why loops have no frustum (per-loop frusta), for the error when none is left.
    frame_error: Option<RokebyError>,
    space: LightSpace,
    bvh: Bvh,
    num_receiver_faces: usize,
    loops: Vec<SilhouetteLoop>,
    active: Vec<bool>,
    /// Per loop: rest (x, y, z) of each silhouette vertex in frustum coordinates.
    rest: Vec<Vec<DVec3>>,
    committed: Vec<Vec<DVec2>>,
    current: Vec<Vec<DVec2>>,
    t_min: f64,
    w_z: f64,
    constraint_weight: f64,
    solver: Option<ShadowMeshSolver>,
    /// The last drag step: its key and the dragged point's frustum (x, y); None when it is not
    /// affine in that point (rigid style, noise) or nothing is being dragged.
    last_drag: Option<(DragKey, DVec2)>,
    /// Bumped whenever the base of the drags changes (commit, cancel, reset, another drag).
    epoch: u64,
    /// Per loop: the handles of its committed silhouette (None until needed); a drag step casts
    /// only its segment's rays and takes the others from here.
    committed_handles: Vec<Option<Vec<Handle>>>,
    /// Per loop: the handles of its uncommitted drag (None: no drag since the last commit).
    current_handles: Vec<Option<Vec<Handle>>>,
    cache: Option<DragCache>,
    solved: Option<Solved>,
}

/// A point light farther than this many caster radii from the caster's bounds centre is treated
/// as a directional light along centre − light. The rays across the caster then differ from the
/// exact ones by less than radius/distance ≤ 1e-6 rad, below what the f32 meshes resolve, while the
/// exact perspective frustum would lose its depth range to rounding (1 − n/z ≈ r/D ≈ 0 in f64 for
/// a light at 1e30: every silhouette vertex at the same depth, a degenerate shadow-mesh solve).
pub const FAR_LIGHT_RATIO: f64 = 1e6;

/// `light`, or the directional light it is indistinguishable from (see [`FAR_LIGHT_RATIO`]).
pub fn far_point_as_directional(light: Light, vertices: &[DVec3]) -> Light {
    let Light::Point(l) = light else { return light };
    if vertices.is_empty() {
        return light;
    }
    let (mn, mx) = vertices.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(a, b), &p| (a.min(p), b.max(p)),
    );
    let centre = (mn + mx) * 0.5;
    let radius = ((mx - mn) * 0.5).length();
    // Componentwise first: |c − l| can overflow to inf for |l| near f64::MAX; the scaled
    // direction is still exact.
    let d = centre - l;
    let scale = d.abs().max_element();
    if !(radius.is_finite() && scale.is_finite()) || scale == 0.0 {
        return light;
    }
    let dist = (d / scale).length() * scale;
    if dist > FAR_LIGHT_RATIO * radius.max(1e-300) {
        Light::Directional(d / scale)
    } else {
        light
    }
}

impl ShadowEditor {
    /// A session for `caster` lit by `light` over receivers (`receiver_vertices` N×3 flat,
    /// `receiver_faces` F×3 flat; may be several objects merged). Errors: an open or non-manifold
    /// caster, a light inside the caster's volume, no receiver under the light (no handle of an
    /// active loop lands on a receiver).
    pub fn new(
        caster: ClosedMesh,
        receiver_vertices: &[f32],
        receiver_faces: &[i64],
        light: Light,
        min_loop_vertices: usize,
        w_z: f64,
        constraint_weight: f64,
    ) -> Result<Self> {
        light.validate()?;
        let light = far_point_as_directional(light, &caster.vertices);
        if !receiver_vertices.len().is_multiple_of(3) {
            return Err(RokebyError::invalid(
                "receiver_vertices",
                format!(
                    "expected N×3 coordinates, got {} values",
                    receiver_vertices.len()
                ),
            ));
        }
        if !receiver_faces.len().is_multiple_of(3) {
            return Err(RokebyError::invalid(
                "receiver_faces",
                format!("expected F×3 indices, got {} values", receiver_faces.len()),
            ));
        }
        // Bounds that keep the solve meaningful in f64: 1/w_z scales light-space depth, and the
        // constraint weight enters the normal equations squared (w² beside Laplacian entries ~1;
        // beyond 1e6 the Laplacian rows drown in rounding, below 1e-6 the handles are ignored).
        if !(w_z.is_finite() && (1e-6..=1e6).contains(&w_z)) {
            return Err(RokebyError::invalid(
                "w_z",
                format!("must be finite and in [1e-6, 1e6], got {w_z}"),
            ));
        }
        if !(constraint_weight.is_finite() && (1e-6..=1e6).contains(&constraint_weight)) {
            return Err(RokebyError::invalid(
                "constraint_weight",
                format!("must be finite and in [1e-6, 1e6], got {constraint_weight}"),
            ));
        }
        let nrv = receiver_vertices.len() / 3;
        if let Some(i) = receiver_vertices.iter().position(|x| !x.is_finite()) {
            return Err(RokebyError::invalid(
                "receiver_vertices",
                format!("vertex {} has a non-finite coordinate", i / 3),
            ));
        }
        let rv: Vec<DVec3> = receiver_vertices
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64))
            .collect();
        let mut tris = Vec::with_capacity(receiver_faces.len() / 3 + caster.faces.len());
        for (fi, c) in receiver_faces.chunks_exact(3).enumerate() {
            if let Some(&x) = c.iter().find(|&&x| x < 0 || x as usize >= nrv) {
                return Err(RokebyError::invalid(
                    "receiver_faces",
                    format!("face {fi} has vertex index {x} outside 0..{nrv}"),
                ));
            }
            tris.push([rv[c[0] as usize], rv[c[1] as usize], rv[c[2] as usize]]);
        }
        let num_receiver_faces = tris.len();
        for f in &caster.faces {
            tris.push(f.map(|i| caster.vertices[i]));
        }
        // §5.2: the frustum around the caster, or (a point light inside its bounds) one per loop.
        let (frame, space) = match (light, LightFrame::new(light, &caster.vertices)) {
            (_, Ok(f)) => (Some(f), LightSpace::Frustum(f)),
            (Light::Point(l), Err(_)) => {
                let w = caster.winding_number(l);
                if w.abs() >= 0.5 {
                    return Err(RokebyError::invalid(
                        "light",
                        format!("the light at ({:.4}, {:.4}, {:.4}) is inside the caster's volume (winding number {w:.2}): it lights only the caster's inside and no silhouette of it is visible; move the light out of the caster (it may stay inside the caster's bounding box, e.g. under a brim or inside a ring)", l.x, l.y, l.z),
                    ));
                }
                (None, LightSpace::spherical(l, &caster.vertices)?)
            }
            (_, Err(e)) => return Err(e),
        };
        let bvh = Bvh::new(tris, "receivers")?;
        let (mn, mx) = bvh.bounds();
        let t_min = 1e-7 * (mx - mn).length().max(1e-300);
        let loops = silhouettes(&caster, &light)?;
        let mut frame_error = None;
        let frames: Vec<Option<LightFrame>> = loops
            .iter()
            .map(|l| match frame {
                Some(f) => Some(f),
                None => match LightFrame::for_loop(light, &l.positions()) {
                    Ok(f) => Some(f),
                    Err(e) => {
                        frame_error.get_or_insert(e);
                        None
                    }
                },
            })
            .collect();
        let active: Vec<bool> = loops
            .iter()
            .zip(&frames)
            .map(|(l, f)| f.is_some() && l.len() >= min_loop_vertices.max(3))
            .collect();
        let rest: Vec<Vec<DVec3>> = loops
            .iter()
            .zip(&frames)
            .map(|(l, f)| match f {
                Some(f) => l
                    .vertices
                    .iter()
                    .map(|s| f.to_frustum(s.position))
                    .collect(),
                None => vec![DVec3::ZERO; l.len()],
            })
            .collect();
        let zeros: Vec<Vec<DVec2>> = loops.iter().map(|l| vec![DVec2::ZERO; l.len()]).collect();
        let nloops = loops.len();
        let ed = ShadowEditor {
            caster,
            light,
            frame,
            frames,
            frame_error,
            space,
            bvh,
            num_receiver_faces,
            loops,
            active,
            rest,
            committed: zeros.clone(),
            current: zeros,
            t_min,
            w_z,
            constraint_weight,
            solver: None,
            last_drag: None,
            epoch: 0,
            cache: None,
            solved: None,
            committed_handles: vec![None; nloops],
            current_handles: vec![None; nloops],
        };
        if ed.frame.is_none() && !ed.frames.iter().any(|f| f.is_some()) {
            let why = ed.frame_error.as_ref().map_or_else(
                || "the caster has no silhouette as seen from the light".to_string(),
                |e| e.to_string(),
            );
            return Err(RokebyError::invalid(
                "light",
                format!("no silhouette loop of the caster can be edited from this light inside its bounds ({why}); move the light"),
            ));
        }
        if !ed.active.iter().any(|&a| a) {
            return Err(RokebyError::invalid(
                "min_loop_vertices",
                format!("no silhouette loop has {} or more vertices (the longest has {}); lower the threshold", min_loop_vertices, ed.loops.first().map_or(0, |l| l.len())),
            ));
        }
        let mut any_receiver = false;
        for (k, l) in ed.loops.iter().enumerate() {
            if ed.active[k] {
                let hs = ed.cast_handles(&l.positions(), k, None);
                if hs.iter().any(|h| h.hit && !h.on_caster) {
                    any_receiver = true;
                    break;
                }
            }
        }
        if !any_receiver {
            return Err(RokebyError::invalid(
                "receivers",
                "no receiver under the light: no shadow ray from the caster's silhouette reaches a receiver; put a receiver (e.g. a ground plane) in the caster's shadow",
            ));
        }
        Ok(ed)
    }

    pub fn caster(&self) -> &ClosedMesh {
        &self.caster
    }
    /// The light's frustum around the whole caster (None: per-loop frusta, a point light inside
    /// the caster's bounds).
    pub fn frame(&self) -> Option<&LightFrame> {
        self.frame.as_ref()
    }
    /// Loop `k`'s frustum (None for a loop no frustum holds).
    pub fn loop_frame(&self, k: usize) -> Option<&LightFrame> {
        self.frames.get(k).and_then(|f| f.as_ref())
    }
    /// Whether each loop has its own frustum (§5.2).
    pub fn per_loop_frusta(&self) -> bool {
        self.frame.is_none()
    }
    /// The light (a far point light already turned into the directional one it equals).
    pub fn light(&self) -> Light {
        self.light
    }
    pub fn loops(&self) -> &[SilhouetteLoop] {
        &self.loops
    }
    pub fn active(&self) -> &[bool] {
        &self.active
    }
    pub fn num_receiver_faces(&self) -> usize {
        self.num_receiver_faces
    }

    fn check_loop(&self, k: usize) -> Result<()> {
        if k >= self.loops.len() {
            return Err(RokebyError::invalid(
                "loop",
                format!("loop {k} does not exist ({} loops)", self.loops.len()),
            ));
        }
        Ok(())
    }

    /// The current (edited, not necessarily committed) silhouette vertices of loop `k`.
    pub fn silhouette(&self, k: usize) -> Result<Vec<DVec3>> {
        self.check_loop(k)?;
        let Some(frame) = self.frames[k] else {
            return Ok(self.loops[k].positions());
        };
        Ok(self.rest[k]
            .iter()
            .zip(&self.current[k])
            .map(|(r, d)| frame.from_frustum(DVec3::new(r.x + d.x, r.y + d.y, r.z)))
            .collect())
    }

    /// One shadow ray (§4.2) from `from` for the silhouette vertex on caster edge (b, f).
    fn cast_one(&self, from: DVec3, b: u32, f: u32) -> Handle {
        let dir = self.light.ray_dir(from);
        let nr = self.num_receiver_faces;
        let near = |v: u32| self.caster.adjacency().faces_around(v as usize);
        let (nb, nf) = (near(b), near(f));
        let skip = |t: usize| {
            t >= nr && {
                let c = t - nr;
                nb.contains(&c) || nf.contains(&c)
            }
        };
        let mut origin = from;
        for _ in 0..MAX_BACK_FACE_RAYS {
            match self
                .bvh
                .intersect_filtered(origin, dir, self.t_min, f64::INFINITY, &skip)
            {
                None => break,
                Some(Hit {
                    t,
                    tri,
                    back_facing,
                    ..
                }) => {
                    let p = origin + dir * t;
                    if back_facing {
                        origin = p;
                        continue;
                    }
                    return Handle {
                        position: p,
                        triangle: tri as i64,
                        hit: true,
                        on_caster: tri >= nr,
                        occluded: false,
                    };
                }
            }
        }
        Handle {
            position: origin,
            triangle: -1,
            hit: false,
            on_caster: false,
            occluded: false,
        }
    }

    fn cast_handles(&self, points: &[DVec3], k: usize, eye: Option<DVec3>) -> Vec<Handle> {
        let l = &self.loops[k];
        points
            .par_iter()
            .zip(l.vertices.par_iter())
            .map(|(&p, s)| {
                let mut h = self.cast_one(p, s.back, s.front);
                if let (Some(e), true) = (eye, h.hit) {
                    // Hidden: seen from behind its surface, or something lies in between.
                    let d = h.position - e;
                    let t = self.bvh.triangle(h.triangle as usize);
                    let facing = (t[1] - t[0]).cross(t[2] - t[0]).dot(-d) > 0.0;
                    h.occluded = !facing || self.bvh.intersect(e, d, 0.0, 1.0 - 1e-5).is_some();
                }
                h
            })
            .collect()
    }

    /// Handles of loop `k` for its current silhouette; `eye` flags those hidden from it.
    pub fn handles(&self, k: usize, eye: Option<DVec3>) -> Result<Vec<Handle>> {
        if let Some(e) = eye {
            if !e.is_finite() {
                return Err(RokebyError::invalid("eye", "must be finite"));
            }
        }
        let s = self.silhouette(k)?;
        Ok(self.cast_handles(&s, k, eye))
    }

    /// The segment of loop `k` from `a` to `b` (cyclic) that contains `m`, ends included.
    fn segment(&self, k: usize, a: usize, b: usize, m: usize) -> Result<Vec<usize>> {
        let n = self.loops[k].len();
        for (name, i) in [("fixed", a), ("fixed", b), ("moved", m)] {
            if i >= n {
                return Err(RokebyError::invalid(
                    name,
                    format!("index {i} is outside loop {k} ({n} vertices)"),
                ));
            }
        }
        if a == b {
            return Err(RokebyError::invalid(
                "fixed",
                "the two fixed ends must differ",
            ));
        }
        if m == a || m == b {
            return Err(RokebyError::invalid(
                "moved",
                "the dragged vertex must lie strictly between the fixed ends",
            ));
        }
        let walk = |from: usize, to: usize| -> Vec<usize> {
            let mut v = vec![from];
            let mut i = from;
            while i != to {
                i = (i + 1) % n;
                v.push(i);
            }
            v
        };
        let fwd = walk(a, b);
        if fwd.contains(&m) {
            Ok(fwd)
        } else {
            Ok(walk(b, a))
        }
    }

    /// A loop that exists and is active (enough silhouette vertices to drag).
    fn check_editable(&self, k: usize) -> Result<()> {
        self.check_loop(k)?;
        if !self.active[k] {
            return Err(RokebyError::invalid(
                "loop",
                format!(
                    "loop {k} has {} vertices, fewer than the threshold: it is not editable",
                    self.loops[k].len()
                ),
            ));
        }
        Ok(())
    }

    /// One drag step (§5.1–5.3), relative to the last committed state; the result becomes the
    /// current state (see [`Self::commit`]).
    pub fn drag(&mut self, d: &Drag) -> Result<DragResult> {
        self.check_editable(d.loop_index)?;
        let k = d.loop_index;
        if !d.target.is_finite() {
            return Err(RokebyError::invalid("target", "must be finite"));
        }
        let seg = self.segment(k, d.fixed.0, d.fixed.1, d.moved)?;
        let frame = self.frames[k].expect("active loops have a frustum");
        let rest = &self.rest[k];
        let a3 = frame.from_frustum(DVec3::new(
            rest[d.moved].x + self.committed[k][d.moved].x,
            rest[d.moved].y + self.committed[k][d.moved].y,
            rest[d.moved].z,
        ));
        let f = frame.drag_target(a3, d.target);
        let f2 = frame.to_frustum(f).truncate();
        if !f2.is_finite() {
            return Err(RokebyError::invalid(
                "target",
                "the dragged point has no position in the light's frustum (behind the light?)",
            ));
        }
        let new = self.segment_offsets(k, &seg, d, f2)?;
        // The fuzzer found drags (1e30 targets, 1e300 noise, w_z = 1e30) whose silhouette left f64:
        // an error that changes nothing, not NaN points.
        let overflow = || {
            RokebyError::invalid(
                "drag",
                "the dragged boundary overflows f64 (target, noise amplitude or weights too large)",
            )
        };
        if !f.is_finite() || !new.iter().all(|p| p.is_finite()) {
            return Err(overflow());
        }
        let old = std::mem::replace(&mut self.current[k], new);
        let silhouette = match self.silhouette(k) {
            Ok(s) if s.iter().all(|p| p.is_finite()) => s,
            res => {
                self.current[k] = old;
                return Err(res.err().unwrap_or_else(overflow));
            }
        };
        // Outside the segment the silhouette is the committed one: only the segment's rays are cast.
        let mut handles = match self.committed_handles[k].take() {
            Some(h) => h,
            None => {
                let committed: Vec<DVec3> = self.rest[k]
                    .iter()
                    .zip(&self.committed[k])
                    .map(|(r, d)| frame.from_frustum(DVec3::new(r.x + d.x, r.y + d.y, r.z)))
                    .collect();
                self.cast_handles(&committed, k, None)
            }
        };
        self.committed_handles[k] = Some(handles.clone());
        let lp = &self.loops[k];
        let fresh: Vec<Handle> = seg
            .par_iter()
            .map(|&i| self.cast_one(silhouette[i], lp.vertices[i].back, lp.vertices[i].front))
            .collect();
        for (&i, h) in seg.iter().zip(fresh) {
            handles[i] = h;
        }
        self.current_handles[k] = Some(handles.clone());
        // The incremental shadow mesh (module documentation): valid while the same drag goes on.
        let key = DragKey {
            loop_index: k,
            fixed: (seg[0], *seg.last().expect("segment has ends")),
            moved: d.moved,
            style: d.style,
            mls_alpha: d.mls_alpha,
        };
        let affine = d.noise_amplitude == 0.0 && d.style != MlsStyle::Rigid;
        if self.last_drag.map(|(k0, _)| k0) != Some(key) {
            self.epoch += 1;
        }
        self.last_drag = affine.then_some((key, f2));
        Ok(DragResult {
            silhouette,
            handles,
            segment: seg,
            moved_to: f,
        })
    }

    /// Prepares the incremental shadow mesh of a drag before its first step, on the mouse press:
    /// the responses to the dragged point moving in x and y (the back-substitution that otherwise
    /// makes the first [`Self::shadow_mesh`] of a drag the slow one) do not depend on where the
    /// point goes, so the steps that follow with the same loop, ends, dragged vertex and style
    /// are all O(V). `Ok(false)`: nothing to prepare (an uncommitted drag is in progress, the
    /// style is rigid or noisy, or the loops have their own frusta: those steps solve in full).
    /// The shadow mesh is unchanged by it.
    pub fn prepare_drag(&mut self, d: &Drag) -> Result<bool> {
        self.check_editable(d.loop_index)?;
        let k = d.loop_index;
        let seg = self.segment(k, d.fixed.0, d.fixed.1, d.moved)?;
        if self.frame.is_none()
            || d.noise_amplitude != 0.0
            || d.style == MlsStyle::Rigid
            || self.current != self.committed
        {
            return Ok(false);
        }
        let key = DragKey {
            loop_index: k,
            fixed: (seg[0], *seg.last().expect("segment has ends")),
            moved: d.moved,
            style: d.style,
            mls_alpha: d.mls_alpha,
        };
        let r = self.rest[k][d.moved];
        let f0 = DVec2::new(r.x, r.y) + self.committed[k][d.moved];
        if self.last_drag.map(|(k0, _)| k0) != Some(key) {
            self.epoch += 1;
        }
        // The drag at its start (f at f₀: the committed state); shadow_mesh builds the cache.
        self.last_drag = Some((key, f0));
        if let Err(e) = self.shadow_mesh() {
            self.end_drag();
            return Err(e);
        }
        Ok(true)
    }

    /// Whether the current drag's next [`Self::shadow_mesh`] is incremental (O(V), from the map
    /// made by [`Self::prepare_drag`] or by this drag's first step).
    pub fn drag_is_incremental(&self) -> bool {
        match (self.last_drag, &self.cache) {
            (Some((key, _)), Some(c)) => {
                self.frame.is_some() && c.key == key && c.epoch == self.epoch
            }
            _ => false,
        }
    }

    /// Loop `k`'s offsets (frustum x, y per silhouette vertex) after deforming the segment `seg`
    /// of its committed state so that the dragged vertex goes to `f2` (§5.2, §5.3).
    fn segment_offsets(&self, k: usize, seg: &[usize], d: &Drag, f2: DVec2) -> Result<Vec<DVec2>> {
        let rest = &self.rest[k];
        let cur: Vec<DVec2> = rest
            .iter()
            .zip(&self.committed[k])
            .map(|(r, c)| DVec2::new(r.x + c.x, r.y + c.y))
            .collect();
        let (i0, i1) = (seg[0], *seg.last().expect("segment has ends"));
        let mls = Mls2d::new(
            vec![cur[i0], cur[i1], cur[d.moved]],
            vec![cur[i0], cur[i1], f2],
            d.style,
            d.mls_alpha,
        )?;
        let pts: Vec<DVec2> = seg.iter().map(|&i| cur[i]).collect();
        let mut moved = mls.deform_all(&pts);
        if d.noise_amplitude != 0.0 {
            moved = sinusoidal_noise(&moved, false, d.noise_amplitude, d.noise_frequency)?;
            // The ends stay where the user fixed them.
            moved[0] = cur[i0];
            let last = moved.len() - 1;
            moved[last] = cur[i1];
        }
        let mut new = self.committed[k].clone();
        for (&i, p) in seg.iter().zip(&moved) {
            new[i] = DVec2::new(p.x - rest[i].x, p.y - rest[i].y);
        }
        Ok(new)
    }

    /// Makes the current state the base of the next drag (mouse release).
    pub fn commit(&mut self) {
        self.committed = self.current.clone();
        // The committed shadow mesh, from the drag's incremental map (the next drag starts there).
        if let (Some((key, f2)), Some(c)) = (self.last_drag, &self.cache) {
            if c.key == key && c.epoch == self.epoch {
                let x = c.at(f2);
                self.solved = Some(Solved {
                    offsets: self.offsets(&self.current),
                    x,
                });
            }
        }
        for (c, h) in self
            .committed_handles
            .iter_mut()
            .zip(&mut self.current_handles)
        {
            if let Some(h) = h.take() {
                *c = Some(h);
            }
        }
        self.end_drag();
    }

    fn end_drag(&mut self) {
        self.last_drag = None;
        self.epoch += 1;
        self.cache = None;
    }

    /// Drops uncommitted changes.
    pub fn cancel(&mut self) {
        self.current = self.committed.clone();
        self.current_handles.iter_mut().for_each(|h| *h = None);
        self.end_drag();
    }

    /// Forgets every edit.
    pub fn reset(&mut self) {
        for (c, l) in self.committed.iter_mut().zip(&self.loops) {
            *c = vec![DVec2::ZERO; l.len()];
        }
        self.current = self.committed.clone();
        self.current_handles.iter_mut().for_each(|h| *h = None);
        self.committed_handles.iter_mut().for_each(|h| *h = None);
        self.end_drag();
    }

    /// Whether the shadow-mesh system has been factored (it is on the first [`Self::shadow_mesh`]).
    pub fn factored(&self) -> bool {
        self.solver.is_some()
    }

    /// Factors the shadow-mesh system (once per editor; the constraints are the vertices of the
    /// active loops).
    pub fn factor(&mut self) -> Result<()> {
        if self.solver.is_none() {
            let mut cons = Vec::new();
            for (l, &a) in self.loops.iter().zip(&self.active) {
                if a {
                    cons.extend(l.vertices.iter().map(|s| EdgePoint {
                        back: s.back,
                        front: s.front,
                        alpha: s.alpha,
                    }));
                }
            }
            self.solver = Some(ShadowMeshSolver::in_space(
                self.space,
                &self.caster.vertices,
                &self.caster.faces,
                cons,
                self.w_z,
                self.constraint_weight,
            )?);
        }
        Ok(())
    }

    /// The solve-space offsets of every active loop's constraints for the per-loop offsets
    /// `per_loop` (frustum (x, y) of each silhouette vertex): (Δx, Δy, 0) in the caster's frustum;
    /// with per-loop frusta the edited minus the rest silhouette point in the spherical space.
    fn offsets(&self, per_loop: &[Vec<DVec2>]) -> Vec<DVec3> {
        let solver = self.solver.as_ref().expect("factored");
        let mut out = Vec::new();
        for (k, d) in per_loop.iter().enumerate() {
            if !self.active[k] {
                continue;
            }
            match (self.frame, self.frames[k]) {
                (Some(_), _) => out.extend(d.iter().map(|d| d.extend(0.0))),
                (None, Some(f)) => {
                    out.extend(self.rest[k].iter().zip(d).zip(&self.loops[k].vertices).map(
                        |((r, d), s)| {
                            if *d == DVec2::ZERO {
                                return DVec3::ZERO;
                            }
                            let moved = f.from_frustum(DVec3::new(r.x + d.x, r.y + d.y, r.z));
                            solver.to_space(moved) - solver.to_space(s.position)
                        },
                    ))
                }
                (None, None) => unreachable!("active loops have a frustum"),
            }
        }
        out
    }

    /// The shadow mesh (§6.1) for the current edits: the caster's vertices moved so that its
    /// silhouettes follow the edited boundaries. During an affine drag in the caster's frustum
    /// every step after the first is incremental (module documentation).
    pub fn shadow_mesh(&mut self) -> Result<Vec<DVec3>> {
        self.factor()?;
        let Some((key, f2)) = self.last_drag.filter(|_| self.frame.is_some()) else {
            let off = self.offsets(&self.current);
            let x = self.solution(off)?;
            return self.solver.as_ref().expect("factored").to_world(&x);
        };
        if let Some(c) = &self.cache {
            if c.key == key && c.epoch == self.epoch {
                return self.solver.as_ref().expect("factored").to_world(&c.at(f2));
            }
        }
        // First step of this drag. Its base: the current offsets with the dragged loop's committed
        // (where the dragged point f is at f₀, its committed position, and the MLS is the identity).
        let k = key.loop_index;
        let mut base = self.current.clone();
        base[k] = self.committed[k].clone();
        let off_base = self.offsets(&base);
        let x0 = self.solution(off_base.clone())?;
        let r = self.rest[k][key.moved];
        let f0 = DVec2::new(r.x, r.y) + self.committed[k][key.moved];
        // The offsets' change for f moved by h in x and in y: their responses are Gₓ h and G_y h.
        let d = Drag {
            loop_index: k,
            fixed: key.fixed,
            moved: key.moved,
            target: DVec3::ZERO,
            style: key.style,
            mls_alpha: key.mls_alpha,
            noise_amplitude: 0.0,
            noise_frequency: 0.0,
        };
        let seg = self.segment(k, key.fixed.0, key.fixed.1, key.moved)?;
        let mut diffs = Vec::with_capacity(2);
        for h in [DVec2::new(CACHE_STEP, 0.0), DVec2::new(0.0, CACHE_STEP)] {
            let mut per_loop = base.clone();
            per_loop[k] = self.segment_offsets(k, &seg, &d, f0 + h)?;
            let off = self.offsets(&per_loop);
            diffs.push(
                off.iter()
                    .zip(&off_base)
                    .map(|(a, b)| *a - *b)
                    .collect::<Vec<_>>(),
            );
        }
        let solver = self.solver.as_ref().expect("factored");
        let mut g = solver.offset_response(&[&diffs[0], &diffs[1]])?;
        let inv = 1.0 / CACHE_STEP;
        let gy = g.pop().expect("two responses");
        let gx = g.pop().expect("two responses");
        let cache = DragCache {
            key,
            epoch: self.epoch,
            f0,
            x0,
            gx: gx.into_iter().map(|v| v * inv).collect(),
            gy: gy.into_iter().map(|v| v * inv).collect(),
        };
        let out = solver.to_world(&cache.at(f2))?;
        self.cache = Some(cache);
        Ok(out)
    }

    /// The solve-space shadow mesh for the constraint offsets `off`: the remembered one when it
    /// is for the same offsets, else solved (and remembered).
    fn solution(&mut self, off: Vec<DVec3>) -> Result<Vec<DVec3>> {
        if let Some(s) = self.solved.as_ref().filter(|s| s.offsets == off) {
            return Ok(s.x.clone());
        }
        let solver = self.solver.as_ref().expect("factored");
        let x = solver.solve_space(&[&off])?.pop().expect("one solution");
        self.solved = Some(Solved {
            offsets: off,
            x: x.clone(),
        });
        Ok(x)
    }
}
