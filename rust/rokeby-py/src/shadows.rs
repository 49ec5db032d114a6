//! Bindings of freeform shadow boundary editing (rokeby_core::shadows::shadow and friends). Same
//! house style as the parent module: float arrays in (float32/float64), shapes checked with
//! messages naming the argument, the GIL released around the work, core errors as ValueError.

use super::{core_err, f32_array, i64_array, parse_vec3, run_detached, shape_str};
use glam::DVec3;
use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{IntoPyArray, PyArrayDyn};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rokeby_core::shadows::mls2d::MlsStyle;
use rokeby_core::shadows::shadow::{Drag, Handle, ShadowEditor as CoreEditor};
use rokeby_core::shadows::shadow_mesh;
use rokeby_core::shadows::silhouette::{self, ClosedMesh, Light, SilhouetteLoop};
use std::sync::Mutex;

fn arr<'py, T: numpy::Element>(
    py: Python<'py>,
    shape: &[usize],
    data: Vec<T>,
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    let a = ArrayD::from_shape_vec(IxDyn(shape), data)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

fn points<'py>(py: Python<'py>, p: &[DVec3]) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    arr(
        py,
        &[p.len(), 3],
        p.iter()
            .flat_map(|v| [v.x as f32, v.y as f32, v.z as f32])
            .collect(),
    )
}

/// A loop or vertex index: negative ones are a ValueError naming the argument (a usize parameter
/// would make them an OverflowError that names nothing).
fn index(i: i64, name: &str) -> PyResult<usize> {
    usize::try_from(i).map_err(|_| {
        PyValueError::new_err(format!("{name}: must be a non-negative index, got {i}"))
    })
}

/// (N, 3) float vertices and (F, 3) integer faces, flattened.
fn mesh_arrays(
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
    vname: &str,
    fname: &str,
) -> PyResult<(Vec<f32>, Vec<i64>)> {
    let v = f32_array(vertices, vname)?;
    let vs = v.shape();
    if vs.len() != 2 || vs[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{vname}: expected shape (V, 3), got {}",
            shape_str(&vs)
        )));
    }
    let (f, fs) = i64_array(faces, fname)?;
    if fs.len() != 2 || fs[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{fname}: expected shape (F, 3) of vertex indices (triangulate first), got {}",
            shape_str(&fs)
        )));
    }
    Ok((v.slice().to_vec(), f))
}

fn parse_light(
    position: Option<&Bound<'_, PyAny>>,
    direction: Option<&Bound<'_, PyAny>>,
) -> PyResult<Light> {
    match (position.filter(|o| !o.is_none()), direction.filter(|o| !o.is_none())) {
        (Some(p), None) => {
            let l = parse_vec3(p, "light_position")?;
            Ok(Light::Point(DVec3::from_array(l)))
        }
        (None, Some(d)) => {
            let l = parse_vec3(d, "light_direction")?;
            Ok(Light::Directional(DVec3::from_array(l)))
        }
        _ => Err(PyValueError::new_err("light: give exactly one of light_position (point, spot or area light) or light_direction (sun)")),
    }
}

fn caster(
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
    normals: Option<&Bound<'_, PyAny>>,
) -> PyResult<ClosedMesh> {
    let (v, f) = mesh_arrays(vertices, faces, "vertices", "faces")?;
    let n = match normals.filter(|o| !o.is_none()) {
        Some(o) => {
            let a = f32_array(o, "normals")?;
            if a.shape() != [v.len() / 3, 3] {
                return Err(PyValueError::new_err(format!(
                    "normals: expected shape ({}, 3) like vertices, got {}",
                    v.len() / 3,
                    shape_str(&a.shape())
                )));
            }
            Some(a.slice().to_vec())
        }
        None => None,
    };
    ClosedMesh::new(&v, &f, n.as_deref()).map_err(core_err)
}

fn loop_dict<'py>(
    py: Python<'py>,
    l: &SilhouetteLoop,
    current: Option<Vec<DVec3>>,
    active: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let pts = current.unwrap_or_else(|| l.positions());
    d.set_item("points", points(py, &pts)?)?;
    d.set_item(
        "edges",
        arr(
            py,
            &[l.len(), 2],
            l.vertices
                .iter()
                .flat_map(|s| [s.back as i64, s.front as i64])
                .collect(),
        )?,
    )?;
    d.set_item(
        "alpha",
        arr(py, &[l.len()], l.vertices.iter().map(|s| s.alpha).collect())?,
    )?;
    d.set_item("length", l.length)?;
    d.set_item("active", active)?;
    Ok(d)
}

fn handles_dict<'py>(py: Python<'py>, hs: &[Handle]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let n = hs.len();
    d.set_item(
        "points",
        points(py, &hs.iter().map(|h| h.position).collect::<Vec<_>>())?,
    )?;
    d.set_item(
        "triangle",
        arr(py, &[n], hs.iter().map(|h| h.triangle).collect())?,
    )?;
    d.set_item("hit", arr(py, &[n], hs.iter().map(|h| h.hit).collect())?)?;
    d.set_item(
        "on_caster",
        arr(py, &[n], hs.iter().map(|h| h.on_caster).collect())?,
    )?;
    d.set_item(
        "occluded",
        arr(py, &[n], hs.iter().map(|h| h.occluded).collect())?,
    )?;
    Ok(d)
}

/// silhouettes(vertices, faces, *, light_position=None, light_direction=None, normals=None)
/// → list of loops (longest first), each a dict: points (K, 3) float32, edges (K, 2) int64
/// (back-facing, front-facing vertex), alpha (K,) float64, length, active (always True here).
#[pyfunction]
#[pyo3(signature = (vertices, faces, *, light_position=None, light_direction=None, normals=None))]
pub fn silhouettes<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    light_position: Option<&Bound<'py, PyAny>>,
    light_direction: Option<&Bound<'py, PyAny>>,
    normals: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let light = parse_light(light_position, light_direction)?;
    let mesh = caster(vertices, faces, normals)?;
    let loops = run_detached(py, move || silhouette::silhouettes(&mesh, &light))?;
    let out = PyList::empty(py);
    for l in &loops {
        out.append(loop_dict(py, l, None, true)?)?;
    }
    Ok(out)
}

/// falloff_factor(l_initial, l_current, beta) → (l_initial · l_current)^β (§6.2), directions
/// normalised, 0 for opposite half-spaces.
#[pyfunction]
pub fn falloff_factor(
    l_initial: &Bound<'_, PyAny>,
    l_current: &Bound<'_, PyAny>,
    beta: f64,
) -> PyResult<f64> {
    let a = DVec3::from_array(parse_vec3(l_initial, "l_initial")?);
    let b = DVec3::from_array(parse_vec3(l_current, "l_current")?);
    shadow_mesh::falloff_factor(a, b, beta).map_err(core_err)
}

/// ShadowEditor(vertices, faces, receiver_vertices, receiver_faces, *, light_position=None,
/// light_direction=None, normals=None, min_loop_vertices=20, w_z=2.5, constraint_weight=10.0)
///
/// One editing session of a closed caster's shadow on the receivers (several objects merged into
/// one array; world space). Receiver triangles come first in `triangle` indices, then the
/// caster's. Methods: loops(), handles(loop, eye=None), drag(...), commit(), cancel(), reset(),
/// shadow_mesh().
#[pyclass(frozen, name = "ShadowEditor", module = "rokeby_native.shadows")]
pub struct PyShadowEditor {
    inner: Mutex<CoreEditor>,
}

impl PyShadowEditor {
    fn with<T: Send, F: FnOnce(&mut CoreEditor) -> rokeby_core::Result<T> + Send>(
        &self,
        py: Python<'_>,
        f: F,
    ) -> PyResult<T> {
        run_detached(py, || {
            let mut g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
            f(&mut g)
        })
    }
}

#[pymethods]
impl PyShadowEditor {
    #[new]
    #[pyo3(signature = (vertices, faces, receiver_vertices, receiver_faces, *, light_position=None, light_direction=None, normals=None, min_loop_vertices=20, w_z=2.5, constraint_weight=10.0))]
    // One argument per Python (keyword) argument of the pyo3 signature above.
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        receiver_vertices: &Bound<'_, PyAny>,
        receiver_faces: &Bound<'_, PyAny>,
        light_position: Option<&Bound<'_, PyAny>>,
        light_direction: Option<&Bound<'_, PyAny>>,
        normals: Option<&Bound<'_, PyAny>>,
        min_loop_vertices: usize,
        w_z: f64,
        constraint_weight: f64,
    ) -> PyResult<Self> {
        let light = parse_light(light_position, light_direction)?;
        let mesh = caster(vertices, faces, normals)?;
        let (rv, rf) = mesh_arrays(
            receiver_vertices,
            receiver_faces,
            "receiver_vertices",
            "receiver_faces",
        )?;
        let ed = run_detached(py, move || {
            CoreEditor::new(
                mesh,
                &rv,
                &rf,
                light,
                min_loop_vertices,
                w_z,
                constraint_weight,
            )
        })?;
        Ok(PyShadowEditor {
            inner: Mutex::new(ed),
        })
    }

    /// Number of silhouette loops.
    #[getter]
    fn num_loops(&self) -> usize {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .loops()
            .len()
    }

    /// Number of receiver triangles (caster triangles follow them in `triangle` indices).
    #[getter]
    fn num_receiver_faces(&self) -> usize {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .num_receiver_faces()
    }

    /// Whether the shadow-mesh system has been factored.
    #[getter]
    fn factored(&self) -> bool {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .factored()
    }

    /// The silhouette loops (longest first) with their current, edited points; `active` is False
    /// for loops below min_loop_vertices (shown grey, not editable).
    fn loops<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        let out = PyList::empty(py);
        for (k, l) in g.loops().iter().enumerate() {
            let cur = g.silhouette(k).map_err(core_err)?;
            out.append(loop_dict(py, l, Some(cur), g.active()[k])?)?;
        }
        Ok(out)
    }

    /// Shadow handles of loop `loop` (dict: points, triangle, hit, on_caster, occluded); `eye`
    /// (3,) flags the handles hidden from it.
    #[pyo3(signature = (r#loop, eye=None))]
    fn handles<'py>(
        &self,
        py: Python<'py>,
        r#loop: i64,
        eye: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let r#loop = index(r#loop, "loop")?;
        let eye = match eye.filter(|o| !o.is_none()) {
            Some(e) => Some(DVec3::from_array(parse_vec3(e, "eye")?)),
            None => None,
        };
        let hs = self.with(py, move |ed| ed.handles(r#loop, eye))?;
        handles_dict(py, &hs)
    }

    /// One drag step relative to the last commit: loop vertices `fixed` = (a, b) stay, `moved`
    /// follows the receiver point `target` (3,). style: "affine", "similarity" or "rigid".
    /// Returns dict: silhouette (K, 3), handles (dict), segment (S,) int64, moved_to (3,).
    #[pyo3(signature = (r#loop, fixed, moved, target, *, style="affine", mls_alpha=1.0, noise_amplitude=0.0, noise_frequency=0.0))]
    // One argument per Python (keyword) argument of the pyo3 signature above.
    #[allow(clippy::too_many_arguments)]
    fn drag<'py>(
        &self,
        py: Python<'py>,
        r#loop: i64,
        fixed: (i64, i64),
        moved: i64,
        target: &Bound<'py, PyAny>,
        style: &str,
        mls_alpha: f64,
        noise_amplitude: f64,
        noise_frequency: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (r#loop, moved) = (index(r#loop, "loop")?, index(moved, "moved")?);
        let fixed = (index(fixed.0, "fixed")?, index(fixed.1, "fixed")?);
        let style = MlsStyle::parse(style).ok_or_else(|| PyValueError::new_err(format!("style: unknown deformation style {style:?} (expected 'affine', 'similarity' or 'rigid')")))?;
        let target = DVec3::from_array(parse_vec3(target, "target")?);
        let d = Drag {
            loop_index: r#loop,
            fixed,
            moved,
            target,
            style,
            mls_alpha,
            noise_amplitude,
            noise_frequency,
        };
        let r = self.with(py, move |ed| ed.drag(&d))?;
        let out = PyDict::new(py);
        out.set_item("silhouette", points(py, &r.silhouette)?)?;
        out.set_item("handles", handles_dict(py, &r.handles)?)?;
        out.set_item(
            "segment",
            arr(
                py,
                &[r.segment.len()],
                r.segment.iter().map(|&i| i as i64).collect(),
            )?,
        )?;
        out.set_item(
            "moved_to",
            arr(
                py,
                &[3],
                vec![
                    r.moved_to.x as f32,
                    r.moved_to.y as f32,
                    r.moved_to.z as f32,
                ],
            )?,
        )?;
        Ok(out)
    }

    /// Mouse press: prepares the drag of `moved` between `fixed` (as `drag` takes them), so
    /// that its steps, the first included, update the shadow mesh in O(V). Returns whether it
    /// did (False: an uncommitted drag is in progress, a rigid or noisy style, or per-loop
    /// frusta — those steps solve in full). The shadow mesh is unchanged.
    #[pyo3(signature = (r#loop, fixed, moved, *, style="affine", mls_alpha=1.0, noise_amplitude=0.0))]
    // One argument per Python (keyword) argument of the pyo3 signature above.
    #[allow(clippy::too_many_arguments)]
    fn prepare_drag(
        &self,
        py: Python<'_>,
        r#loop: i64,
        fixed: (i64, i64),
        moved: i64,
        style: &str,
        mls_alpha: f64,
        noise_amplitude: f64,
    ) -> PyResult<bool> {
        let (r#loop, moved) = (index(r#loop, "loop")?, index(moved, "moved")?);
        let fixed = (index(fixed.0, "fixed")?, index(fixed.1, "fixed")?);
        let style = MlsStyle::parse(style).ok_or_else(|| PyValueError::new_err(format!("style: unknown deformation style {style:?} (expected 'affine', 'similarity' or 'rigid')")))?;
        let d = Drag {
            loop_index: r#loop,
            fixed,
            moved,
            target: DVec3::ZERO,
            style,
            mls_alpha,
            noise_amplitude,
            noise_frequency: 0.0,
        };
        self.with(py, move |ed| ed.prepare_drag(&d))
    }

    /// Whether the current drag's next shadow_mesh() is incremental (prepared on the press or
    /// by the drag's first step).
    fn drag_is_incremental(&self) -> bool {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .drag_is_incremental()
    }

    /// Mouse release: the current state becomes the base of the next drag.
    fn commit(&self) {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .commit();
    }

    /// Drops the uncommitted drag.
    fn cancel(&self) {
        self.inner
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .cancel();
    }

    /// Forgets every edit.
    fn reset(&self) {
        self.inner.lock().unwrap_or_else(|p| p.into_inner()).reset();
    }

    /// The shadow mesh's vertices (V, 3) float32 for the current edits (§6.1); the first call
    /// factors the system, later calls back-substitute.
    fn shadow_mesh<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let v = self.with(py, |ed| ed.shadow_mesh())?;
        points(py, &v)
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(silhouettes, m)?)?;
    m.add_function(wrap_pyfunction!(falloff_factor, m)?)?;
    m.add_class::<PyShadowEditor>()?;
    Ok(())
}
