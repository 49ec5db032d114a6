//! Bindings of the geometry: geodesic distances (rokeby_core::geometry::geodesic: heat method, Dijkstra,
//! exact), geodesic and free-form regions (rokeby_core::reflection::region) and barycentric interpolation.

use crate::convert::{f32_array, i64_array, shape_str, to_numpy};
use crate::errors::{core_err, run_detached};
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArray};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use rokeby_core::geometry::geodesic::{
    self, GeodesicSolver as CoreSolver, Mesh, Method, Source, SurfacePoint,
};
use rokeby_core::reflection::region;
use std::sync::Arc;

fn parse_mesh(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    let v = f32_array(vertices, "vertices")?;
    let vs = v.shape();
    if vs.len() != 2 || vs[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "vertices: expected shape (V, 3), got {}",
            shape_str(&vs)
        )));
    }
    let (f, fs) = i64_array(faces, "faces")?;
    if fs.len() != 2 || fs[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "faces: expected shape (F, 3) of vertex indices, got {}",
            shape_str(&fs)
        )));
    }
    Mesh::new(v.slice(), &f).map_err(core_err)
}

fn parse_point(item: &Bound<'_, PyAny>) -> Option<SurfacePoint> {
    let t: (i64, Vec<f64>) = item.extract().ok()?;
    if t.1.len() != 3 || t.0 < 0 {
        return None;
    }
    Some(SurfacePoint {
        face: t.0 as usize,
        bary: [t.1[0], t.1[1], t.1[2]],
    })
}

fn parse_one_source(item: &Bound<'_, PyAny>, k: usize) -> PyResult<Source> {
    if let Ok(v) = item.extract::<i64>() {
        if v < 0 {
            return Err(PyValueError::new_err(format!(
                "sources: source {k}: vertex index {v} is negative"
            )));
        }
        return Ok(Source::Vertex(v as usize));
    }
    if let Some(p) = parse_point(item) {
        return Ok(Source::Point(p));
    }
    Err(PyTypeError::new_err(format!(
        "sources: source {k} must be a vertex index or (face, (b0, b1, b2)), got {}",
        item.repr().map(|r| r.to_string()).unwrap_or_default()
    )))
}

/// sources: vertex indices (an int array or list: one distance field each), or a list whose items
/// are a vertex index, a surface point (face, (b0, b1, b2)), or a list of those (one field, the
/// distance to the nearest of the set).
fn parse_sources(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Vec<Source>>> {
    if obj.cast::<PyUntypedArray>().is_ok() {
        let (idx, shape) = i64_array(obj, "sources")?;
        if shape.len() > 1 {
            return Err(PyValueError::new_err(format!(
                "sources: an index array must be 1-D, got {}",
                shape_str(&shape)
            )));
        }
        return idx
            .into_iter()
            .enumerate()
            .map(|(k, v)| {
                if v < 0 {
                    Err(PyValueError::new_err(format!(
                        "sources: source {k}: vertex index {v} is negative"
                    )))
                } else {
                    Ok(vec![Source::Vertex(v as usize)])
                }
            })
            .collect();
    }
    if obj.extract::<i64>().is_ok() || parse_point(obj).is_some() {
        return Ok(vec![vec![parse_one_source(obj, 0)?]]);
    }
    let items: Vec<Bound<'_, PyAny>> = obj
        .try_iter()
        .map_err(|_| PyTypeError::new_err("sources: must be a list of sources"))?
        .collect::<PyResult<_>>()?;
    if items.is_empty() {
        return Err(PyValueError::new_err("sources: is empty"));
    }
    let mut sets = Vec::with_capacity(items.len());
    for (k, item) in items.iter().enumerate() {
        if item.extract::<i64>().is_ok() || parse_point(item).is_some() {
            sets.push(vec![parse_one_source(item, k)?]);
        } else if let Ok(inner) = item.try_iter() {
            let members: Vec<Bound<'_, PyAny>> = inner.collect::<PyResult<_>>()?;
            let set = members
                .iter()
                .map(|m| parse_one_source(m, k))
                .collect::<PyResult<Vec<_>>>()?;
            sets.push(set);
        } else {
            return Err(PyTypeError::new_err(format!("sources: source {k} must be a vertex index, (face, (b0, b1, b2)) or a list of those")));
        }
    }
    Ok(sets)
}

fn parse_method(name: &str) -> PyResult<Method> {
    Method::parse(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "method: unknown method {name:?} (expected 'dense_graph', 'graph', 'heat', 'dijkstra' or 'exact')"
        ))
    })
}

fn distances_array<'py>(
    py: Python<'py>,
    solver: &CoreSolver,
    sets: Vec<Vec<Source>>,
    method: Method,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let nv = solver.mesh().vertices.len();
    let ns = sets.len();
    let out = run_detached(py, || solver.distances(&sets, method))?;
    to_numpy(py, &[ns, nv], out)
}

/// geodesic_distances(vertices, faces, sources, *, method="dense_graph") -> (S, V) float32.
///
/// Distances over the surface from each source (or source set) to every vertex. +inf where no
/// source can reach (other connected components). For repeated queries on one mesh use
/// GeodesicSolver, which keeps what each method precomputes (the geodesic graph, the heat
/// method's factorisation). The default method is the add-on's default for new mirrors.
#[pyfunction]
#[pyo3(signature = (vertices, faces, sources, *, method="dense_graph"))]
fn geodesic_distances<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    sources: &Bound<'py, PyAny>,
    method: &str,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let method = parse_method(method)?;
    let mesh = parse_mesh(vertices, faces)?;
    let sets = parse_sources(sources)?;
    let solver = run_detached(py, || Ok(CoreSolver::new(mesh)))?;
    distances_array(py, &solver, sets, method)
}

/// GeodesicSolver(vertices, faces): geodesic distances on one mesh, keeping what does not change
/// between queries — the edge graph, the connected components and the heat method's two sparse
/// Cholesky factorisations (made on the first heat query). A moved handle costs one solve.
/// The mesh is fixed for a solver: make a new one when vertices or faces change.
/// boundary="average" (default) averages the Neumann and Dirichlet heat flows on meshes with
/// boundary (Crane et al. 2013 §3.3, more accurate there); "neumann" saves one factorisation.
#[pyclass(frozen, name = "GeodesicSolver", module = "rokeby_native.geometry")]
struct PyGeodesicSolver {
    inner: Arc<CoreSolver>,
}

#[pymethods]
impl PyGeodesicSolver {
    #[new]
    #[pyo3(signature = (vertices, faces, *, boundary="average"))]
    fn new(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        boundary: &str,
    ) -> PyResult<Self> {
        let average = match boundary {
            "average" => true,
            "neumann" => false,
            other => {
                return Err(PyValueError::new_err(format!(
                    "boundary: unknown condition {other:?} (expected 'average' or 'neumann')"
                )))
            }
        };
        let mesh = parse_mesh(vertices, faces)?;
        let inner = run_detached(py, move || {
            Ok(CoreSolver::with_boundary_averaging(mesh, average))
        })?;
        Ok(PyGeodesicSolver {
            inner: Arc::new(inner),
        })
    }

    /// distances(sources, method="dense_graph") -> (S, V) float32
    #[pyo3(signature = (sources, method="dense_graph"))]
    fn distances<'py>(
        &self,
        py: Python<'py>,
        sources: &Bound<'py, PyAny>,
        method: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let method = parse_method(method)?;
        let sets = parse_sources(sources)?;
        distances_array(py, &self.inner, sets, method)
    }

    /// geodesic_region(centre, radius, border=0.0, method="dense_graph") -> (V,) float32 a(q)
    ///
    /// A geodesic region of interest: 1 within `radius - border` of the surface `centre` (a vertex
    /// index or (face, (b0, b1, b2))) measured over the surface, a smooth step to 0 at `radius`,
    /// and 0 on other connected components. Pass it to rotation_field as a "weights" region.
    #[pyo3(signature = (centre, radius, border=0.0, method="dense_graph"))]
    fn geodesic_region<'py>(
        &self,
        py: Python<'py>,
        centre: &Bound<'py, PyAny>,
        radius: f64,
        border: f64,
        method: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let method = parse_method(method)?;
        let src = parse_one_source(centre, 0)?;
        let solver = self.inner.clone();
        let a = run_detached(py, move || {
            region::geodesic_region(&solver, src, radius, border, method)
        })?;
        Ok(numpy::PyArray1::from_vec(py, a).to_dyn().clone())
    }

    /// freeform_region(weights, border=0.0, method="dense_graph") -> (V,) float32 a(q)
    ///
    /// A free-form region from painted per-vertex weights in [0, 1] (a vertex group): unpainted
    /// vertices get 0; inside, the weight fades in over `border` (geodesic distance from the nearest
    /// unpainted vertex).
    #[pyo3(signature = (weights, border=0.0, method="dense_graph"))]
    fn freeform_region<'py>(
        &self,
        py: Python<'py>,
        weights: &Bound<'py, PyAny>,
        border: f64,
        method: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let method = parse_method(method)?;
        let w = f32_array(weights, "weights")?;
        let nv = self.inner.mesh().vertices.len();
        if w.shape() != [nv] {
            return Err(PyValueError::new_err(format!(
                "weights: expected shape ({nv},), one per vertex, got {}",
                shape_str(&w.shape())
            )));
        }
        let w = w.slice();
        let solver = &self.inner;
        let a = run_detached(py, || region::freeform_region(solver, w, border, method))?;
        Ok(numpy::PyArray1::from_vec(py, a).to_dyn().clone())
    }

    /// Whether the heat method's factorisation has been computed (and is being reused).
    #[getter]
    fn factored(&self) -> bool {
        self.inner.is_factored()
    }

    /// Edge flips made by the intrinsic Delaunay triangulation (None before the first heat query).
    #[getter]
    fn intrinsic_flips(&self) -> Option<usize> {
        self.inner.intrinsic_flips()
    }

    #[getter]
    fn num_vertices(&self) -> usize {
        self.inner.mesh().vertices.len()
    }

    #[getter]
    fn num_faces(&self) -> usize {
        self.inner.mesh().faces.len()
    }
}

/// interpolate(values, faces, face_index, bary) -> (S, P) float32
///
/// Per-vertex values (S, V) (e.g. distance fields) at surface points given by face indices (P,)
/// and barycentric coordinates (P, 3), by linear interpolation (paper §6.2).
#[pyfunction]
fn interpolate<'py>(
    py: Python<'py>,
    values: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    face_index: &Bound<'py, PyAny>,
    bary: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let vals = f32_array(values, "values")?;
    let vshape = vals.shape();
    let (rows, nv) = match vshape.len() {
        1 => (1, vshape[0]),
        2 => (vshape[0], vshape[1]),
        _ => {
            return Err(PyValueError::new_err(format!(
                "values: expected shape (V,) or (S, V), got {}",
                shape_str(&vshape)
            )))
        }
    };
    let (f, fs) = i64_array(faces, "faces")?;
    if fs.len() != 2 || fs[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "faces: expected shape (F, 3), got {}",
            shape_str(&fs)
        )));
    }
    let (fi, fis) = i64_array(face_index, "face_index")?;
    if fis.len() != 1 {
        return Err(PyValueError::new_err(format!(
            "face_index: expected shape (P,), got {}",
            shape_str(&fis)
        )));
    }
    let b = f32_array(bary, "bary")?;
    if b.shape() != [fi.len(), 3] {
        return Err(PyValueError::new_err(format!(
            "bary: expected shape ({}, 3), got {}",
            fi.len(),
            shape_str(&b.shape())
        )));
    }
    let (v, bs) = (vals.slice(), b.slice());
    let out = run_detached(py, || geodesic::interpolate_at(v, nv, &f, &fi, bs))?;
    to_numpy(py, &[rows, fi.len()], out)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(geodesic_distances, m)?)?;
    m.add_function(wrap_pyfunction!(interpolate, m)?)?;
    m.add_class::<PyGeodesicSolver>()?;
    Ok(())
}
