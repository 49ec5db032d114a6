//! The triangle mesh, one home: positions and faces in f64, their validation, the faces glued
//! along each edge and around each vertex ([`Adjacency`]), and what the shadow caster asks of a
//! mesh on top of that — closed, manifold and consistently oriented ([`Mesh::require_closed`]),
//! vertex normals, the generalised winding number.

use crate::error::{Result, RokebyError};
use glam::DVec3;

/// A place on the surface: a face and barycentric coordinates (normalised to sum 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    pub face: usize,
    pub bary: [f64; 3],
}

/// A validated triangle mesh in f64: finite vertices, face indices in range, at least one vertex
/// and one face, fewer than 2³² − 1 vertices (so that a vertex index fits a `u32`). Faces may
/// repeat a vertex (scanned meshes have such slivers); [`Mesh::require_closed`] refuses them.
#[derive(Debug, Clone)]
pub struct Mesh {
    pub vertices: Vec<DVec3>,
    pub faces: Vec<[usize; 3]>,
}

/// Reads the `v` and `f` lines of Wavefront OBJ text: flattened vertices (V×3) and triangles
/// (F×3, 0-based; polygons fanned from their first corner, `a/b/c` corners and negative, relative
/// indices read). Other lines are ignored. A number that does not parse is an error naming its
/// line. The one OBJ reader of the Rust side (tests, examples); the add-on reads OBJ in Python
/// (`rokeby.core.meshio`).
pub fn parse_obj(text: &str) -> Result<(Vec<f32>, Vec<i64>)> {
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for (n, line) in text.lines().enumerate() {
        let bad = |what: &str| RokebyError::invalid("obj", format!("line {}: {what}", n + 1));
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                for t in it.take(3) {
                    v.push(
                        t.parse::<f32>()
                            .map_err(|_| bad("a vertex coordinate is not a number"))?,
                    );
                }
            }
            Some("f") => {
                let nv = (v.len() / 3) as i64;
                let idx = it
                    .map(|t| {
                        let i: i64 = t
                            .split('/')
                            .next()
                            .unwrap_or("")
                            .parse()
                            .map_err(|_| bad("a face index is not an integer"))?;
                        Ok(if i < 0 { nv + i } else { i - 1 })
                    })
                    .collect::<Result<Vec<i64>>>()?;
                for k in 1..idx.len().saturating_sub(1) {
                    f.extend_from_slice(&[idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok((v, f))
}

impl Mesh {
    /// `vertices` (V×3 flattened), `faces` (F×3 flattened, any integer type converted to i64).
    pub fn new(vertices: &[f32], faces: &[i64]) -> Result<Self> {
        if !vertices.len().is_multiple_of(3) {
            return Err(RokebyError::invalid(
                "vertices",
                format!("expected N×3 coordinates, got {} values", vertices.len()),
            ));
        }
        if !faces.len().is_multiple_of(3) {
            return Err(RokebyError::invalid(
                "faces",
                format!("expected F×3 indices, got {} values", faces.len()),
            ));
        }
        if vertices.is_empty() {
            return Err(RokebyError::invalid("vertices", "the mesh has no vertices"));
        }
        if faces.is_empty() {
            return Err(RokebyError::invalid("faces", "the mesh has no faces"));
        }
        if let Some(i) = vertices.iter().position(|x| !x.is_finite()) {
            return Err(RokebyError::invalid(
                "vertices",
                format!("vertex {} is not finite", i / 3),
            ));
        }
        let nv = vertices.len() / 3;
        if nv >= u32::MAX as usize {
            return Err(RokebyError::invalid(
                "vertices",
                format!("{nv} vertices is more than supported (2^32 - 1)"),
            ));
        }
        if let Some(i) = faces.iter().position(|&x| x < 0 || x as u64 >= nv as u64) {
            return Err(RokebyError::invalid(
                "faces",
                format!(
                    "face {} refers to vertex {} but the mesh has vertices 0..{}",
                    i / 3,
                    faces[i],
                    nv - 1
                ),
            ));
        }
        let v = vertices
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64))
            .collect();
        let f = faces
            .chunks_exact(3)
            .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
            .collect();
        Ok(Mesh {
            vertices: v,
            faces: f,
        })
    }

    /// The position of a surface point.
    pub fn point(&self, p: &SurfacePoint) -> DVec3 {
        let [a, b, c] = self.faces[p.face];
        self.vertices[a] * p.bary[0] + self.vertices[b] * p.bary[1] + self.vertices[c] * p.bary[2]
    }

    /// Checks that the mesh is closed, manifold and consistently oriented: no face repeats a
    /// vertex and every edge is shared by exactly two faces, in opposite directions. Returns the
    /// adjacency it built for the check.
    pub fn require_closed(&self) -> Result<Adjacency> {
        for (fi, f) in self.faces.iter().enumerate() {
            if !is_proper(f) {
                return Err(RokebyError::invalid(
                    "faces",
                    format!("face {fi} repeats a vertex ({}, {}, {})", f[0], f[1], f[2]),
                ));
            }
        }
        let adj = Adjacency::new(self);
        let directed = |h: usize| {
            let f = self.faces[h / 3];
            (f[h % 3], f[(h % 3 + 1) % 3])
        };
        // Directed edges: each must appear once (the first repeat, in face order, is reported),
        // and its reverse once.
        let mut open = 0;
        let mut first_open = None;
        for h in 0..3 * self.faces.len() {
            let e = directed(h);
            if adj.across(h).any(|g| g < h && directed(g) == e) {
                return Err(RokebyError::invalid(
                    "faces",
                    format!("the mesh is not a consistently oriented manifold: edge ({}, {}) is used twice in the same direction (face {})", e.0, e.1, h / 3),
                ));
            }
            if !adj.across(h).any(|g| directed(g) == (e.1, e.0)) {
                open += 1;
                first_open.get_or_insert(e);
            }
        }
        if let Some((a, b)) = first_open {
            return Err(RokebyError::invalid(
                "faces",
                format!("the mesh must be a closed mesh: {open} boundary edges (e.g. ({a}, {b})); close the holes or use a solid mesh"),
            ));
        }
        Ok(adj)
    }

    /// Area-weighted averages of the face normals, normalised (zero for unreferenced vertices).
    pub fn vertex_normals(&self) -> Vec<DVec3> {
        let v = &self.vertices;
        let mut n = vec![DVec3::ZERO; v.len()];
        for t in &self.faces {
            let (a, b, c) = (v[t[0]], v[t[1]], v[t[2]]);
            let fnrm = (b - a).cross(c - a);
            for &i in t {
                n[i] += fnrm;
            }
        }
        n.into_iter().map(|x| x.normalize_or_zero()).collect()
    }

    /// The generalised winding number of the mesh around `p` (Σ of the faces' signed solid
    /// angles / 4π, Van Oosterom–Strackee): 1 inside an outward-oriented closed surface, 0
    /// outside (±½ on it).
    pub fn winding_number(&self, p: DVec3) -> f64 {
        let mut sum = 0.0;
        for f in &self.faces {
            let a = self.vertices[f[0]] - p;
            let b = self.vertices[f[1]] - p;
            let c = self.vertices[f[2]] - p;
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let num = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
            sum += 2.0 * num.atan2(den);
        }
        sum / (4.0 * std::f64::consts::PI)
    }

    /// Axis-aligned bounds of the vertices.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.vertices.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(a, b), &p| (a.min(p), b.max(p)),
        )
    }
}

/// Whether a face has three distinct vertices.
#[inline]
pub fn is_proper(f: &[usize; 3]) -> bool {
    f[0] != f[1] && f[1] != f[2] && f[0] != f[2]
}

const NONE: usize = usize::MAX;

/// Faces glued along edges (any number of faces per edge: non-manifold edges keep all of them) and
/// the faces around each vertex, in face order. Faces with a repeated vertex are left out.
/// Halfedge `3f + k` runs from corner k to corner k+1 of face f.
#[derive(Debug, Clone)]
pub struct Adjacency {
    /// Halfedges sorted by their undirected edge.
    sorted: Vec<(u32, u32, usize)>,
    /// Where halfedge h sits in `sorted` (NONE for faces with a repeated vertex).
    pos: Vec<usize>,
    vf_start: Vec<usize>,
    vf: Vec<usize>,
}

impl Adjacency {
    pub fn new(mesh: &Mesh) -> Self {
        let nf = mesh.faces.len();
        let nv = mesh.vertices.len();
        let mut sorted: Vec<(u32, u32, usize)> = Vec::with_capacity(3 * nf);
        let mut vf_start = vec![0usize; nv + 1];
        for (fi, f) in mesh.faces.iter().enumerate() {
            if !is_proper(f) {
                continue;
            }
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                sorted.push((a.min(b) as u32, a.max(b) as u32, 3 * fi + k));
                vf_start[f[k] + 1] += 1;
            }
        }
        sorted.sort_unstable();
        let mut pos = vec![NONE; 3 * nf];
        for (i, e) in sorted.iter().enumerate() {
            pos[e.2] = i;
        }
        for i in 0..nv {
            vf_start[i + 1] += vf_start[i];
        }
        let mut fill = vf_start.clone();
        let mut vf = vec![0usize; vf_start[nv]];
        for (fi, f) in mesh.faces.iter().enumerate() {
            if is_proper(f) {
                for &v in f {
                    vf[fill[v]] = fi;
                    fill[v] += 1;
                }
            }
        }
        Adjacency {
            sorted,
            pos,
            vf_start,
            vf,
        }
    }

    /// The other faces on the edge of halfedge `h`, each as a halfedge of that face.
    pub fn across(&self, h: usize) -> impl Iterator<Item = usize> + '_ {
        let p = self.pos[h];
        let (lo, hi) = if p == NONE {
            (0, 0)
        } else {
            let key = (self.sorted[p].0, self.sorted[p].1);
            let mut lo = p;
            while lo > 0 && (self.sorted[lo - 1].0, self.sorted[lo - 1].1) == key {
                lo -= 1;
            }
            let mut hi = p + 1;
            while hi < self.sorted.len() && (self.sorted[hi].0, self.sorted[hi].1) == key {
                hi += 1;
            }
            (lo, hi)
        };
        (lo..hi)
            .map(move |i| self.sorted[i].2)
            .filter(move |&g| g != h)
    }

    /// The faces around vertex `v`, in increasing order.
    pub fn faces_around(&self, v: usize) -> &[usize] {
        &self.vf[self.vf_start[v]..self.vf_start[v + 1]]
    }
}

/// One of the project's shared test meshes (`$ROKEBY_SHARED/meshes/<name>`, by default the
/// `shared/` folder beside the checkout), or None where it is absent.
#[cfg(test)]
pub(crate) fn shared_test_mesh(name: &str) -> Option<Mesh> {
    let root = std::env::var("ROKEBY_SHARED").map_or_else(
        |_| std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"),
        std::path::PathBuf::from,
    );
    let text = std::fs::read_to_string(root.join("meshes").join(name)).ok()?;
    let (v, f) = parse_obj(&text).unwrap();
    Some(Mesh::new(&v, &f).unwrap())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_obj_fans_polygons_and_reads_relative_indices() {
        let text = "# a quad and a triangle\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\n\
                    f 1/1/1 2/2/1 3/3/1 4/4/1\nf -4 -2 -1\n";
        let (v, f) = parse_obj(text).unwrap();
        assert_eq!(v.len(), 12);
        assert_eq!(f, vec![0, 1, 2, 0, 2, 3, 0, 2, 3]);
    }

    #[test]
    fn parse_obj_names_the_line_of_a_bad_number() {
        let err = parse_obj("v 0 0 0\nv 1 x 0\n").unwrap_err().to_string();
        assert!(
            err.contains("line 2") && err.contains("vertex coordinate"),
            "{err}"
        );
        let err = parse_obj("v 0 0 0\nf 1 a 1\n").unwrap_err().to_string();
        assert!(
            err.contains("line 2") && err.contains("face index"),
            "{err}"
        );
    }
}
