//! Smooth silhouettes of a closed mesh as seen from a light (Mattausch et al., §4.1, after
//! Hertzmann and Zorin 2000).
//!
//! A vertex v faces the light when g(v) = n(v)·(l − v) > 0 (point light at l) or n(v)·(−d) > 0
//! (directional light travelling along d), with n(v) the vertex normal. On every edge whose ends
//! face opposite ways — v_b back-facing, v_f front-facing — the silhouette vertex is
//! s = (1 − α) v_b + α v_f with α solving the paper's equation
//!
//! (1 − α) n(v_b)·(l − v_f) + α n(v_f)·(l − v_b) = 0.
//!
//! For a directional light both terms reduce to g(v_b) and g(v_f) and α = g_b / (g_b − g_f). For a
//! point light the cross terms can put the root outside [0, 1] (or make it undefined) on long edges
//! of strongly curved meshes; there the Hertzmann–Zorin root α = g_b / (g_b − g_f) is used, which
//! always lies in [0, 1]. Every face with mixed signs holds exactly one silhouette segment between
//! its two sign-changing edges, so on a closed, consistently oriented mesh the segments chain into
//! closed loops; each loop is oriented so that the back-facing side lies to its left when seen
//! from outside the surface.

use crate::error::{Result, RokebyError};
use crate::geometry::mesh::{Adjacency, Mesh};
use glam::DVec3;

/// A light as the shadow editing sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// A point (or spot, or area-light centre) at this position.
    Point(DVec3),
    /// A directional (sun) light travelling along this direction (normalised on use).
    Directional(DVec3),
}

impl Light {
    /// The direction light travels to reach `p` (unit length).
    pub fn ray_dir(&self, p: DVec3) -> DVec3 {
        match *self {
            Light::Point(l) => (p - l).normalize_or_zero(),
            Light::Directional(d) => d.normalize_or_zero(),
        }
    }

    /// l − v for a point light, −d for a directional light: the "towards the light" vector.
    pub fn to_light(&self, v: DVec3) -> DVec3 {
        match *self {
            Light::Point(l) => l - v,
            Light::Directional(d) => -d.normalize_or_zero(),
        }
    }

    pub fn validate(&self) -> Result<()> {
        match *self {
            Light::Point(l) if !l.is_finite() => Err(RokebyError::invalid("light", "the light position must be finite")),
            // try_normalize: the fuzzer found |d| ≈ 1e300 (length² = inf) normalising to zero and
            // giving a NaN light frame.
            Light::Directional(d) if d.try_normalize().is_none() => {
                Err(RokebyError::invalid("light", "the light direction must be finite and non-zero (and of a length whose square is a finite, non-zero f64)"))
            }
            _ => Ok(()),
        }
    }
}

/// A validated closed, consistently oriented triangle mesh (the shadow caster): a [`Mesh`] that
/// passed [`Mesh::require_closed`], with its vertex normals. It dereferences to the [`Mesh`].
#[derive(Debug, Clone)]
pub struct ClosedMesh {
    mesh: Mesh,
    adjacency: Adjacency,
    pub normals: Vec<DVec3>,
}

impl ClosedMesh {
    /// Checks the caster: a valid [`Mesh`] (finite vertices, indices in range) that is closed,
    /// manifold and oriented ([`Mesh::require_closed`]: no face repeats a vertex, every edge is
    /// shared by exactly two faces in opposite directions). `normals`, when given, are the vertex
    /// normals (normalised here); otherwise area-weighted face normals are averaged.
    pub fn new(vertices: &[f32], faces: &[i64], normals: Option<&[f32]>) -> Result<Self> {
        let mesh = Mesh::new(vertices, faces)?;
        let adjacency = mesh.require_closed()?;
        let nv = mesh.vertices.len();
        let normals = match normals {
            Some(n) => {
                if n.len() != vertices.len() {
                    return Err(RokebyError::invalid(
                        "normals",
                        format!(
                            "expected {nv}×3 values (one normal per vertex), got {}",
                            n.len()
                        ),
                    ));
                }
                let mut out = Vec::with_capacity(nv);
                for (i, c) in n.chunks_exact(3).enumerate() {
                    let v = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
                    if !v.is_finite() || v.length_squared() == 0.0 {
                        return Err(RokebyError::invalid(
                            "normals",
                            format!("normal {i} is zero or not finite"),
                        ));
                    }
                    out.push(v.normalize());
                }
                out
            }
            None => mesh.vertex_normals(),
        };
        Ok(ClosedMesh {
            mesh,
            adjacency,
            normals,
        })
    }

    /// The mesh (also reached by dereferencing).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The faces glued along each edge and around each vertex.
    pub fn adjacency(&self) -> &Adjacency {
        &self.adjacency
    }
}

impl std::ops::Deref for ClosedMesh {
    type Target = Mesh;
    fn deref(&self) -> &Mesh {
        &self.mesh
    }
}

/// One silhouette vertex: on edge (`back`, `front`) at s = (1 − α) v_back + α v_front.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SilhouetteVertex {
    pub back: u32,
    pub front: u32,
    pub alpha: f64,
    pub position: DVec3,
}

/// A closed silhouette loop: its vertices in order and its length Σ |s_{i+1} − s_i|.
#[derive(Debug, Clone, PartialEq)]
pub struct SilhouetteLoop {
    pub vertices: Vec<SilhouetteVertex>,
    pub length: f64,
}

impl SilhouetteLoop {
    pub fn len(&self) -> usize {
        self.vertices.len()
    }
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }
    pub fn positions(&self) -> Vec<DVec3> {
        self.vertices.iter().map(|s| s.position).collect()
    }
}

/// α of §4.1 on the edge (v_b, v_f); see the module comment for the fall-back.
pub fn silhouette_alpha(light: &Light, vb: DVec3, nb: DVec3, vf: DVec3, nf: DVec3) -> f64 {
    let a = nb.dot(light.to_light(vf));
    let b = nf.dot(light.to_light(vb));
    let den = a - b;
    if den != 0.0 {
        let alpha = a / den;
        if (0.0..=1.0).contains(&alpha) {
            return alpha;
        }
    }
    let gb = nb.dot(light.to_light(vb));
    let gf = nf.dot(light.to_light(vf));
    if gb == gf {
        0.5
    } else {
        (gb / (gb - gf)).clamp(0.0, 1.0)
    }
}

/// The smooth silhouette loops of `mesh` from `light` (§4.1).
pub fn silhouettes(mesh: &ClosedMesh, light: &Light) -> Result<Vec<SilhouetteLoop>> {
    light.validate()?;
    let v = &mesh.vertices;
    let n = &mesh.normals;
    let front: Vec<bool> = v
        .iter()
        .zip(n)
        .map(|(&p, &nn)| nn.dot(light.to_light(p)) > 0.0)
        .collect();
    // Silhouette vertex per sign-changing edge, stored at the lower of the edge's two halfedges
    // (3f + k: corner k → k+1 of face f; on a closed mesh each has exactly one across).
    let adj = mesh.adjacency();
    let mut index = vec![u32::MAX; 3 * mesh.faces.len()];
    let mut pts: Vec<SilhouetteVertex> = Vec::new();
    let mut next: Vec<u32> = Vec::new();
    let mut point_of = |h: usize,
                        (a, b): (usize, usize),
                        pts: &mut Vec<SilhouetteVertex>,
                        next: &mut Vec<u32>|
     -> u32 {
        let key = adj.across(h).fold(h, usize::min);
        if index[key] == u32::MAX {
            let (vb, vf) = if front[a] { (b, a) } else { (a, b) };
            let alpha = silhouette_alpha(light, v[vb], n[vb], v[vf], n[vf]);
            let position = v[vb] * (1.0 - alpha) + v[vf] * alpha;
            pts.push(SilhouetteVertex {
                back: vb as u32,
                front: vf as u32,
                alpha,
                position,
            });
            next.push(u32::MAX);
            index[key] = (pts.len() - 1) as u32;
        }
        index[key]
    };
    for (fi, f) in mesh.faces.iter().enumerate() {
        let s = f.map(|i| front[i]);
        if s[0] == s[1] && s[1] == s[2] {
            continue;
        }
        // Going round the face: the back→front edge starts the segment, front→back ends it, so
        // the back-facing side is on the segment's left (faces are counter-clockwise from outside)
        // and neighbouring faces, which share the edge in opposite directions, agree.
        let mut start = u32::MAX;
        let mut end = u32::MAX;
        for k in 0..3 {
            let e = (f[k], f[(k + 1) % 3]);
            let (sa, sb) = (s[k], s[(k + 1) % 3]);
            if !sa && sb {
                start = point_of(3 * fi + k, e, &mut pts, &mut next);
            } else if sa && !sb {
                end = point_of(3 * fi + k, e, &mut pts, &mut next);
            }
        }
        next[start as usize] = end;
    }
    // Chain: every point has exactly one successor on a closed oriented manifold.
    let mut seen = vec![false; pts.len()];
    let mut loops = Vec::new();
    for s0 in 0..pts.len() {
        if seen[s0] {
            continue;
        }
        let mut verts = Vec::new();
        let mut i = s0;
        loop {
            if seen[i] {
                if i != s0 {
                    return Err(RokebyError::invalid(
                        "faces",
                        "silhouette chaining failed: the caster is not a closed oriented manifold",
                    ));
                }
                break;
            }
            seen[i] = true;
            verts.push(pts[i]);
            let nx = next[i];
            if nx == u32::MAX {
                return Err(RokebyError::invalid(
                    "faces",
                    "silhouette chaining failed: the caster is not a closed oriented manifold",
                ));
            }
            i = nx as usize;
        }
        let m = verts.len();
        let length = (0..m)
            .map(|k| (verts[(k + 1) % m].position - verts[k].position).length())
            .sum();
        loops.push(SilhouetteLoop {
            vertices: verts,
            length,
        });
    }
    // Longest first: the loops an artist edits.
    loops.sort_by(|a, b| {
        b.vertices
            .len()
            .cmp(&a.vertices.len())
            .then(b.length.total_cmp(&a.length))
    });
    Ok(loops)
}
