//! `rokeby_native`: the Python face of rokeby-core.
//!
//! This crate only converts: numpy arrays in (float32 or float64, any layout; float64 is stored
//! as float32 like Blender's mesh data), validated shapes with errors that name the argument,
//! the GIL released around the work, panics caught, core errors mapped by kind: bad input →
//! `ValueError`, memory → `MemoryError`, numerical failure → `NumericalError` (a `RuntimeError`),
//! cancelled → `KeyboardInterrupt`, internal bug or panic → `RuntimeError`.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{
    PyKeyboardInterrupt, PyMemoryError, PyRuntimeError, PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use rokeby_core::field::{output_width, Distances, Field, FieldOutput};
use rokeby_core::geodesic::{
    self, GeodesicSolver as CoreSolver, Mesh, Method, Source, SurfacePoint,
};
use rokeby_core::polar::{self, PolarMethod};
use rokeby_core::region::Region;
use rokeby_core::RokebyError;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

mod compositing;
mod environment;
mod shadow;

/// A float array as float32: borrowed when it already is contiguous float32, else converted.
enum F32Array<'py> {
    Borrowed(PyReadonlyArrayDyn<'py, f32>),
    Owned(Vec<f32>, Vec<usize>),
}

impl F32Array<'_> {
    fn slice(&self) -> &[f32] {
        match self {
            F32Array::Borrowed(a) => a.as_slice().expect("checked contiguous"),
            F32Array::Owned(v, _) => v,
        }
    }
    fn shape(&self) -> Vec<usize> {
        match self {
            F32Array::Borrowed(a) => a.shape().to_vec(),
            F32Array::Owned(_, s) => s.clone(),
        }
    }
}

fn shape_str(s: &[usize]) -> String {
    let parts: Vec<String> = s.iter().map(|x| x.to_string()).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// Accepts a numpy array (or anything numpy.asarray takes) of float32/float64.
fn f32_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<F32Array<'py>> {
    let py = obj.py();
    let arr: Bound<'py, PyAny> = if obj.cast::<PyUntypedArray>().is_ok() {
        obj.clone()
    } else {
        let np = py.import("numpy")?;
        np.call_method1("asarray", (obj,)).map_err(|e| {
            PyTypeError::new_err(format!("{name}: cannot be read as an array ({e})"))
        })?
    };
    // Integers are exact coordinates (`center=[0, 0, 1]`); bool, complex and objects are not.
    let kind: String = arr
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract())
        .unwrap_or_default();
    let arr = if kind == "i" || kind == "u" {
        arr.call_method1("astype", ("float64",))?
    } else {
        arr
    };
    if let Ok(a) = arr.cast::<PyArrayDyn<f32>>() {
        let ro = a.readonly();
        // Borrow only C-ordered data: `as_slice` also accepts Fortran order, whose flat layout
        // is not the logical row-major order the core reads.
        if ro.is_c_contiguous() && ro.as_slice().is_ok() {
            return Ok(F32Array::Borrowed(ro));
        }
        let shape = ro.shape().to_vec();
        return Ok(F32Array::Owned(
            ro.as_array().iter().copied().collect(),
            shape,
        ));
    }
    if let Ok(a) = arr.cast::<PyArrayDyn<f64>>() {
        let ro = a.readonly();
        let shape = ro.shape().to_vec();
        let view = ro.as_array();
        // Finite float64 beyond float32's range would turn into inf here: refused, naming the value.
        if let Some((i, x)) = view
            .iter()
            .enumerate()
            .find(|(_, x)| x.is_finite() && x.abs() > f32::MAX as f64)
        {
            return Err(PyValueError::new_err(format!(
                "{name}: value {i} ({x:e}) is beyond float32's range (±3.4e38)"
            )));
        }
        return Ok(F32Array::Owned(
            view.iter().map(|&x| x as f32).collect(),
            shape,
        ));
    }
    let dtype = match arr.cast::<PyUntypedArray>() {
        Ok(u) => u.dtype().str()?.to_string(),
        Err(_) => arr.get_type().name()?.to_string(),
    };
    Err(PyTypeError::new_err(format!("{name}: must be an array of floats (float32 or float64; integers are converted), got dtype {dtype}")))
}

pyo3::create_exception!(
    rokeby_native,
    NumericalError,
    PyRuntimeError,
    "A numerical method of the core failed on input that passed validation (a factorisation broke down, an iteration did not converge)."
);

fn core_err(e: RokebyError) -> PyErr {
    let text = e.to_string();
    match e {
        RokebyError::InvalidArgument { .. } => PyValueError::new_err(text),
        RokebyError::OutOfMemory { .. } => PyMemoryError::new_err(text),
        RokebyError::Numerical { .. } => NumericalError::new_err(text),
        RokebyError::Cancelled => PyKeyboardInterrupt::new_err("rokeby_native: cancelled"),
        RokebyError::Internal(_) => PyRuntimeError::new_err(format!("rokeby_native {text}")),
    }
}

fn panic_err(p: Box<dyn std::any::Any + Send>) -> PyErr {
    let msg = p
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown".into());
    PyRuntimeError::new_err(format!(
        "rokeby_native internal error (please report): {msg}"
    ))
}

/// Runs `f` without the GIL; a panic (a bug) becomes RuntimeError instead of crossing into Python.
fn run_detached<T: Send, F: FnOnce() -> Result<T, RokebyError> + Send>(
    py: Python<'_>,
    f: F,
) -> PyResult<T> {
    let res = py.detach(|| catch_unwind(AssertUnwindSafe(f)));
    match res {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(core_err(e)),
        Err(p) => Err(panic_err(p)),
    }
}

/// Like [`run_detached`] for long work that checks [`rokeby_core::cancel`] between rows: the work
/// runs on a worker thread while this thread, every 50 ms, takes the GIL back to let Python run
/// its signal handlers; Ctrl-C (KeyboardInterrupt) or `rokeby_native.cancel()` from another
/// thread stops the work at its next row and the call raises.
pub(crate) fn run_cancellable<T: Send, F: FnOnce() -> Result<T, RokebyError> + Send>(
    py: Python<'_>,
    f: F,
) -> PyResult<T> {
    use std::sync::mpsc;
    use std::time::Duration;
    rokeby_core::cancel::reset();
    std::thread::scope(|scope| {
        let (tx, rx) = mpsc::channel();
        scope.spawn(move || {
            let _ = tx.send(catch_unwind(AssertUnwindSafe(f)));
        });
        let mut interrupted: Option<PyErr> = None;
        let mut rx = rx;
        loop {
            let (got, back) = py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
            rx = back;
            match got {
                Ok(res) => {
                    if let Some(err) = interrupted {
                        return Err(err);
                    }
                    return match res {
                        Ok(Ok(v)) => Ok(v),
                        Ok(Err(e)) => Err(core_err(e)),
                        Err(p) => Err(panic_err(p)),
                    };
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    if interrupted.is_none() {
                        if let Err(e) = py.check_signals() {
                            rokeby_core::cancel::request();
                            interrupted = Some(e);
                        }
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err("rokeby_native internal error (please report): the worker thread ended without a result"));
                }
            }
        }
    })
}

/// field_kernel() -> str: the kernel the field functions use now: "scalar" (the f64 reference),
/// "portable", "avx2" or "avx512" — ROKEBY_SIMD (read at each call) resolved against this CPU.
#[pyfunction]
fn field_kernel() -> &'static str {
    rokeby_core::field::Kernel::from_env().name()
}

/// cancel()
///
/// Stops the cancellable native calls in flight (blurs, filters, prefiltering, reconstruction) at
/// their next row: they raise KeyboardInterrupt. For a Blender operator's Esc or a watchdog
/// thread; Ctrl-C does the same for a call made from the main thread.
#[pyfunction]
fn cancel() {
    rokeby_core::cancel::request();
}

fn parse_polar(name: &str) -> PyResult<PolarMethod> {
    PolarMethod::parse(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "polar: unknown method {name:?} (expected 'exact'/'svd' or 'fast'/'iterative')"
        ))
    })
}

fn parse_vec3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 3]> {
    let a = f32_array(obj, name)?;
    if a.shape() != [3] {
        return Err(PyValueError::new_err(format!(
            "{name}: expected shape (3,), got {}",
            shape_str(&a.shape())
        )));
    }
    let s = a.slice();
    Ok([s[0] as f64, s[1] as f64, s[2] as f64])
}

fn parse_constraints(obj: &Bound<'_, PyAny>) -> PyResult<Vec<f32>> {
    let a = f32_array(obj, "constraints")?;
    let shape = a.shape();
    if shape.len() != 2 || shape[1] != 9 {
        return Err(PyValueError::new_err(format!(
            "constraints: expected shape (K, 9) with rows [p, r, e], got {}",
            shape_str(&shape)
        )));
    }
    Ok(a.slice().to_vec())
}

fn dict_get<'py>(d: &Bound<'py, PyDict>, key: &str, name: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?
        .ok_or_else(|| PyValueError::new_err(format!("{name}: missing key {key:?}")))
}

fn dict_f64(d: &Bound<'_, PyDict>, key: &str, name: &str, default: Option<f64>) -> PyResult<f64> {
    match d.get_item(key)? {
        Some(v) => v
            .extract::<f64>()
            .map_err(|_| PyTypeError::new_err(format!("{name}: {key} must be a number"))),
        None => {
            default.ok_or_else(|| PyValueError::new_err(format!("{name}: missing key {key:?}")))
        }
    }
}

/// regions: a list of dicts, {"kind": "euclidean", "center", "radius", "border"} or
/// {"kind": "weights", "values" (one per point), "at_constraints" (one per constraint)}.
fn parse_regions(
    obj: Option<&Bound<'_, PyAny>>,
    n_points: usize,
    n_constraints: usize,
) -> PyResult<Vec<Region>> {
    let Some(obj) = obj else {
        return Ok(Vec::new());
    };
    if obj.is_none() {
        return Ok(Vec::new());
    }
    let items: Vec<Bound<'_, PyAny>> = if let Ok(l) = obj.cast::<PyList>() {
        l.iter().collect()
    } else if let Ok(t) = obj.cast::<PyTuple>() {
        t.iter().collect()
    } else {
        return Err(PyTypeError::new_err("regions: must be a list of dicts"));
    };
    let mut out = Vec::with_capacity(items.len());
    for (j, item) in items.iter().enumerate() {
        let name = format!("regions[{j}]");
        let d = item
            .cast::<PyDict>()
            .map_err(|_| PyTypeError::new_err(format!("{name}: must be a dict")))?;
        let kind: String = dict_get(d, "kind", &name)?
            .extract()
            .map_err(|_| PyTypeError::new_err(format!("{name}: kind must be a string")))?;
        match kind.as_str() {
            "euclidean" => {
                let center = parse_vec3(&dict_get(d, "center", &name)?, &format!("{name}.center"))?;
                let radius = dict_f64(d, "radius", &name, None)?;
                let border = dict_f64(d, "border", &name, Some(0.0))?;
                out.push(Region::euclidean(center, radius, border, &name).map_err(core_err)?);
            }
            "weights" => {
                let values = f32_array(&dict_get(d, "values", &name)?, &format!("{name}.values"))?;
                let at_c = f32_array(
                    &dict_get(d, "at_constraints", &name)?,
                    &format!("{name}.at_constraints"),
                )?;
                out.push(
                    Region::per_point(
                        values.slice().to_vec(),
                        at_c.slice().to_vec(),
                        n_points,
                        n_constraints,
                        &name,
                    )
                    .map_err(core_err)?,
                );
            }
            other => {
                return Err(PyValueError::new_err(format!(
                    "{name}: unknown kind {other:?} (expected 'euclidean' or 'weights')"
                )));
            }
        }
    }
    Ok(out)
}

/// distances: (K, *lead) where lead is the shape of the points without the last axis.
fn parse_distances<'py>(
    obj: Option<&Bound<'py, PyAny>>,
    k: usize,
    lead: &[usize],
) -> PyResult<Option<F32Array<'py>>> {
    let Some(obj) = obj else { return Ok(None) };
    if obj.is_none() {
        return Ok(None);
    }
    let a = f32_array(obj, "distances")?;
    let mut want = vec![k];
    want.extend_from_slice(lead);
    if a.shape() != want {
        return Err(PyValueError::new_err(format!(
            "distances: expected shape {} (constraints × points), got {}",
            shape_str(&want),
            shape_str(&a.shape())
        )));
    }
    Ok(Some(a))
}

/// rotation_field(points, constraints, *, distances=None, regions=None, normals=None, eye=None,
/// polar="exact") -> (N, 4) float32 unit quaternions (x, y, z, w), w >= 0.
///
/// The MLS rotation field R(q) = ortho(Σ wₙ eₙ rₙᵀ), wₙ = 1/d(pₙ, q)² (Ritschel et al. 2009,
/// eq. 5) at every point. constraints: (K, 9) rows [p, r, e]; K = 0 gives identities.
/// distances: optional (K, N) precomputed (e.g. geodesic) distances, +inf = unreachable.
/// regions: list of dicts (see README). normals + eye: make eq. 7 blend towards r rᵀ exactly.
/// output="quaternion" (N, 4), "rotation_vector" (N, 3): axis × angle, angle in [0, π], or
/// "view_blend" (N, 6): eq. 7's view-independent parts (x, y, z, w, a, u) for `view_blend`.
#[pyfunction]
#[pyo3(signature = (points, constraints, *, distances=None, regions=None, normals=None, eye=None, polar="exact", output="quaternion"))]
#[allow(clippy::too_many_arguments)]
fn rotation_field<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    constraints: &Bound<'py, PyAny>,
    distances: Option<&Bound<'py, PyAny>>,
    regions: Option<&Bound<'py, PyAny>>,
    normals: Option<&Bound<'py, PyAny>>,
    eye: Option<&Bound<'py, PyAny>>,
    polar: &str,
    output: &str,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let method = parse_polar(polar)?;
    let output = match output {
        "quaternion" => FieldOutput::Quaternion,
        "rotation_vector" => FieldOutput::RotationVector,
        "view_blend" => FieldOutput::ViewBlend,
        other => {
            return Err(PyValueError::new_err(format!(
            "output: expected \"quaternion\", \"rotation_vector\" or \"view_blend\", got {other:?}"
        )))
        }
    };
    let width = output_width(output);
    let pts = f32_array(points, "points")?;
    let shape = pts.shape();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "points: expected shape (N, 3), got {}",
            shape_str(&shape)
        )));
    }
    let n = shape[0];
    if n == 0 {
        return Err(PyValueError::new_err("points: is empty (N = 0)"));
    }
    let rows = parse_constraints(constraints)?;
    let k = rows.len() / 9;
    let dist = parse_distances(distances, k, &shape[..1])?;
    let regs = parse_regions(regions, n, k)?;
    let nrm = match (
        normals.filter(|o| !o.is_none()),
        eye.filter(|o| !o.is_none()),
    ) {
        (Some(nm), Some(ey)) => {
            let a = f32_array(nm, "normals")?;
            if a.shape() != shape {
                return Err(PyValueError::new_err(format!(
                    "normals: expected shape {}, got {}",
                    shape_str(&shape),
                    shape_str(&a.shape())
                )));
            }
            Some((a, parse_vec3(ey, "eye")?))
        }
        (None, None) => None,
        (Some(_), None) => {
            return Err(PyValueError::new_err(
                "eye: required when normals are given",
            ))
        }
        (None, Some(_)) => {
            return Err(PyValueError::new_err("normals: required when eye is given"))
        }
    };
    let field = Field::new(&rows, regs).map_err(core_err)?;
    let p = pts.slice();
    let d = match &dist {
        Some(a) => Distances::Given(a.slice()),
        None => Distances::Euclidean,
    };
    let view = nrm.as_ref().map(|(a, e)| (a.slice(), *e));
    let out = run_detached(py, || field.rotation_field_as(p, d, view, method, output))?;
    let arr = ArrayD::from_shape_vec(IxDyn(&[n, width]), out)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

/// view_blend(parts, directions, *, ramp=False) -> (N, 3) float32 unit vectors.
///
/// Eq. 7 in closed form per point, R_a r = ortho(a R + (1 − a) r rᵀ) r, from the parts
/// (N, 6) = (x, y, z, w, a, u) of rotation_field(..., output="view_blend") (or an interpolation
/// of them) and unit directions r (N, 3): what the render nodes compute per shading point. The
/// weight is a, or smooth_step(u) with ramp=True (a field with one Euclidean region).
#[pyfunction]
#[pyo3(signature = (parts, directions, *, ramp=false))]
fn view_blend<'py>(
    py: Python<'py>,
    parts: &Bound<'py, PyAny>,
    directions: &Bound<'py, PyAny>,
    ramp: bool,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let pa = parts_array(parts)?;
    let da = f32_array(directions, "directions")?;
    let (ps, ds) = (pa.shape(), da.shape());
    if ds.len() != 2 || ds[1] != 3 || ds[0] != ps[0] {
        return Err(PyValueError::new_err(format!(
            "directions: expected shape ({}, 3), got {}",
            ps[0],
            shape_str(&ds)
        )));
    }
    let (p, d) = (pa.slice(), da.slice());
    let out = run_detached(py, || rokeby_core::field::view_blend_directions(p, d, ramp))?;
    let arr = ArrayD::from_shape_vec(IxDyn(&[ps[0], 3]), out)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

fn parts_array<'py>(parts: &Bound<'py, PyAny>) -> PyResult<F32Array<'py>> {
    let pa = f32_array(parts, "parts")?;
    let ps = pa.shape();
    if ps.len() != 2 || ps[1] != 6 {
        return Err(PyValueError::new_err(format!(
            "parts: expected shape (N, 6), got {}",
            shape_str(&ps)
        )));
    }
    Ok(pa)
}

/// view_blend_render_rows(parts, corner_vert, first_vert, *, ramp=False) -> (per_corner, (R, 3), (R, 3)).
///
/// The parts as the add-on stores them for renders: (x, y, z) and (w, a, 0), or (w, −1, u) with
/// ramp=True; per vertex (R = N) when every polygon's quaternions share a hemisphere, else per
/// corner (R = C), each corner's quaternion in the hemisphere of its polygon's first corner
/// (first_vert[c]: that corner's vertex).
#[pyfunction]
#[pyo3(signature = (parts, corner_vert, first_vert, *, ramp=false))]
#[allow(clippy::type_complexity)]
fn view_blend_render_rows<'py>(
    py: Python<'py>,
    parts: &Bound<'py, PyAny>,
    corner_vert: &Bound<'py, PyAny>,
    first_vert: &Bound<'py, PyAny>,
    ramp: bool,
) -> PyResult<(
    bool,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
)> {
    let pa = parts_array(parts)?;
    // Contiguous int64 index arrays (what the add-on keeps per mesh) are read in place; others
    // are converted.
    let borrowed = |a: &Bound<'py, PyAny>| {
        a.cast::<PyArrayDyn<i64>>()
            .ok()
            .map(|x| x.readonly())
            .filter(|r| r.is_c_contiguous() && r.ndim() == 1)
    };
    let (cb, fb) = (borrowed(corner_vert), borrowed(first_vert));
    let owned_c = if cb.is_none() {
        Some(i64_array(corner_vert, "corner_vert")?)
    } else {
        None
    };
    let owned_f = if fb.is_none() {
        Some(i64_array(first_vert, "first_vert")?)
    } else {
        None
    };
    for (what, shape) in [
        ("corner_vert", owned_c.as_ref().map(|o| o.1.clone())),
        ("first_vert", owned_f.as_ref().map(|o| o.1.clone())),
    ] {
        if let Some(sh) = shape {
            if sh.len() != 1 {
                return Err(PyValueError::new_err(format!(
                    "{what}: expected shape (C,), got {}",
                    shape_str(&sh)
                )));
            }
        }
    }
    let cv: &[i64] = match (&cb, &owned_c) {
        (Some(r), _) => r
            .as_slice()
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?,
        (None, Some(o)) => &o.0,
        _ => return Err(PyRuntimeError::new_err("internal: corner_vert unread")),
    };
    let fv: &[i64] = match (&fb, &owned_f) {
        (Some(r), _) => r
            .as_slice()
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?,
        (None, Some(o)) => &o.0,
        _ => return Err(PyRuntimeError::new_err("internal: first_vert unread")),
    };
    let p = pa.slice();
    let r = run_detached(py, || {
        rokeby_core::field::view_blend_render_rows(p, cv, fv, ramp)
    })?;
    let rows = r.xyz.len() / 3;
    let a = ArrayD::from_shape_vec(IxDyn(&[rows, 3]), r.xyz)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let b = ArrayD::from_shape_vec(IxDyn(&[rows, 3]), r.wa)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok((r.per_corner, a.into_pyarray(py), b.into_pyarray(py)))
}

/// view_blend_rotation_vectors(parts) -> (N, 3) float32: the view-independent field
/// ortho(a R + (1 − a) I) of each point's parts as rotation vectors (axis × angle).
#[pyfunction]
fn view_blend_rotation_vectors<'py>(
    py: Python<'py>,
    parts: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let pa = parts_array(parts)?;
    let n = pa.shape()[0];
    let p = pa.slice();
    let out = run_detached(py, || rokeby_core::field::view_blend_rotation_vectors(p))?;
    let arr = ArrayD::from_shape_vec(IxDyn(&[n, 3]), out)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

/// edited_directions(positions, normals, eye, constraints, *, distances=None, regions=None,
/// polar="fast") -> (..., 3) float32 unit vectors.
///
/// The per-pixel path (paper §6.1): r(q) = reflect(q − eye, n) and e(q) = R_a(q) r(q) for a
/// G-buffer of positions and normals of any leading shape, e.g. (H, W, 3) (rows of W pixels are
/// the unit of parallel work). K = 0 returns the unedited reflections r(q).
#[pyfunction]
#[pyo3(signature = (positions, normals, eye, constraints, *, distances=None, regions=None, polar="fast"))]
#[allow(clippy::too_many_arguments)]
fn edited_directions<'py>(
    py: Python<'py>,
    positions: &Bound<'py, PyAny>,
    normals: &Bound<'py, PyAny>,
    eye: &Bound<'py, PyAny>,
    constraints: &Bound<'py, PyAny>,
    distances: Option<&Bound<'py, PyAny>>,
    regions: Option<&Bound<'py, PyAny>>,
    polar: &str,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let method = parse_polar(polar)?;
    let pos = f32_array(positions, "positions")?;
    let shape = pos.shape();
    if shape.is_empty() || shape[shape.len() - 1] != 3 {
        return Err(PyValueError::new_err(format!(
            "positions: expected shape (..., 3), got {}",
            shape_str(&shape)
        )));
    }
    let lead = &shape[..shape.len() - 1];
    let n: usize = lead.iter().product();
    if n == 0 {
        return Err(PyValueError::new_err(format!(
            "positions: is empty (shape {})",
            shape_str(&shape)
        )));
    }
    let nrm = f32_array(normals, "normals")?;
    if nrm.shape() != shape {
        return Err(PyValueError::new_err(format!(
            "normals: expected shape {} like positions, got {}",
            shape_str(&shape),
            shape_str(&nrm.shape())
        )));
    }
    let eye = parse_vec3(eye, "eye")?;
    let rows = parse_constraints(constraints)?;
    let k = rows.len() / 9;
    let dist = parse_distances(distances, k, lead)?;
    let regs = parse_regions(regions, n, k)?;
    let field = Field::new(&rows, regs).map_err(core_err)?;
    let row_len = if lead.len() >= 2 {
        lead[lead.len() - 1]
    } else {
        4096
    };
    let (p, nm) = (pos.slice(), nrm.slice());
    let d = match &dist {
        Some(a) => Distances::Given(a.slice()),
        None => Distances::Euclidean,
    };
    let out = run_detached(py, || {
        field.edited_directions(p, nm, eye, d, method, row_len)
    })?;
    let arr = ArrayD::from_shape_vec(IxDyn(&shape), out)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

/// ortho(matrices, method="exact") -> (..., 4) float32 quaternions (x, y, z, w), w >= 0.
/// The rotational factor of the polar decomposition of each 3×3 matrix (eq. 5's "ortho"), exposed
/// for tests and benchmarks of the polar methods.
#[pyfunction]
#[pyo3(signature = (matrices, method="exact"))]
fn ortho<'py>(
    py: Python<'py>,
    matrices: &Bound<'py, PyAny>,
    method: &str,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let method = parse_polar(method)?;
    let m = f32_array(matrices, "matrices")?;
    let shape = m.shape();
    if shape.len() < 2 || shape[shape.len() - 1] != 3 || shape[shape.len() - 2] != 3 {
        return Err(PyValueError::new_err(format!(
            "matrices: expected shape (..., 3, 3), got {}",
            shape_str(&shape)
        )));
    }
    let s = m.slice();
    if let Some(i) = s.iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "matrices: matrix {} has a non-finite entry",
            i / 9
        )));
    }
    let out = run_detached(py, || {
        let mut warm = glam::DQuat::IDENTITY;
        let mut out = Vec::with_capacity(s.len() / 9 * 4);
        for c in s.chunks_exact(9) {
            // Row-major numpy (i, j) → column-major glam.
            let mat = glam::DMat3::from_cols_array(&[
                c[0] as f64,
                c[3] as f64,
                c[6] as f64,
                c[1] as f64,
                c[4] as f64,
                c[7] as f64,
                c[2] as f64,
                c[5] as f64,
                c[8] as f64,
            ]);
            let q = polar::canonical(polar::ortho(&mat, || None, method, &mut warm));
            out.extend_from_slice(&[q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
        }
        Ok(out)
    })?;
    let mut oshape = shape[..shape.len() - 2].to_vec();
    oshape.push(4);
    let arr = ArrayD::from_shape_vec(IxDyn(&oshape), out)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

/// An integer array (faces, indices) as i64; floats are refused (an index must be exact).
fn i64_array(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<i64>, Vec<usize>)> {
    let py = obj.py();
    let arr: Bound<'_, PyAny> = if obj.cast::<PyUntypedArray>().is_ok() {
        obj.clone()
    } else {
        py.import("numpy")?
            .call_method1("asarray", (obj,))
            .map_err(|e| {
                PyTypeError::new_err(format!("{name}: cannot be read as an array ({e})"))
            })?
    };
    let kind: String = arr
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract())
        .unwrap_or_default();
    if kind != "i" && kind != "u" {
        let dtype = arr
            .getattr("dtype")
            .map(|d| d.to_string())
            .unwrap_or_else(|_| "?".into());
        return Err(PyTypeError::new_err(format!(
            "{name}: must be an array of integers, got dtype {dtype}"
        )));
    }
    let arr = arr.call_method1("astype", ("int64",))?;
    let a = arr
        .cast::<PyArrayDyn<i64>>()
        .map_err(|_| PyTypeError::new_err(format!("{name}: must be an integer array")))?;
    let ro = a.readonly();
    // The contiguous copy astype made is read as one slice (iterating a dynamic-dimension view
    // element by element cost ~40 ns per index: 16 ms for the corners of a 100k-vertex mirror).
    let values = match ro.as_slice() {
        Ok(sl) => sl.to_vec(),
        Err(_) => ro.as_array().iter().copied().collect(),
    };
    Ok((values, ro.shape().to_vec()))
}

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
            "method: unknown method {name:?} (expected 'heat', 'dijkstra', 'exact' or 'graph')"
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
    let arr = ArrayD::from_shape_vec(IxDyn(&[ns, nv]), out)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

/// geodesic_distances(vertices, faces, sources, *, method="heat") -> (S, V) float32.
///
/// Distances over the surface from each source (or source set) to every vertex. +inf where no
/// source can reach (other connected components). For repeated queries on one mesh use
/// GeodesicSolver, which keeps the heat method's factorisation.
#[pyfunction]
#[pyo3(signature = (vertices, faces, sources, *, method="heat"))]
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
#[pyclass(frozen, name = "GeodesicSolver", module = "rokeby_native")]
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

    /// distances(sources, method="heat") -> (S, V) float32
    #[pyo3(signature = (sources, method="heat"))]
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

    /// geodesic_region(centre, radius, border=0.0, method="heat") -> (V,) float32 a(q)
    ///
    /// A geodesic region of interest: 1 within `radius - border` of the surface `centre` (a vertex
    /// index or (face, (b0, b1, b2))) measured over the surface, a smooth step to 0 at `radius`,
    /// and 0 on other connected components. Pass it to rotation_field as a "weights" region.
    #[pyo3(signature = (centre, radius, border=0.0, method="heat"))]
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
            let d = solver.distances(&[vec![src]], method)?;
            rokeby_core::region::geodesic_weights(&d, radius, border)
        })?;
        Ok(numpy::PyArray1::from_vec(py, a).to_dyn().clone())
    }

    /// freeform_region(weights, border=0.0, method="heat") -> (V,) float32 a(q)
    ///
    /// A free-form region from painted per-vertex weights in [0, 1] (a vertex group): unpainted
    /// vertices get 0; inside, the weight fades in over `border` (geodesic distance from the nearest
    /// unpainted vertex).
    #[pyo3(signature = (weights, border=0.0, method="heat"))]
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
        let w = w.slice().to_vec();
        let solver = self.inner.clone();
        let a = run_detached(py, move || {
            let outside: Vec<Source> = w
                .iter()
                .enumerate()
                .filter(|(_, &x)| !(x > 0.0))
                .map(|(i, _)| Source::Vertex(i))
                .collect();
            let d = if outside.is_empty() || border == 0.0 {
                vec![f32::INFINITY; w.len()]
            } else {
                solver.distances(&[outside], method)?
            };
            rokeby_core::region::freeform_weights(&w, &d, border)
        })?;
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
    if vals.slice().iter().any(|x| x.is_nan()) {
        return Err(PyValueError::new_err("values: contains NaN"));
    }
    let (f, fs) = i64_array(faces, "faces")?;
    if fs.len() != 2 || fs[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "faces: expected shape (F, 3), got {}",
            shape_str(&fs)
        )));
    }
    if let Some(i) = f.iter().position(|&x| x < 0 || x as u64 >= nv as u64) {
        return Err(PyValueError::new_err(format!(
            "faces: face {} refers to vertex {} but values has {} vertices",
            i / 3,
            f[i],
            nv
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
    let nf = fs[0];
    let faces3: Vec<[usize; 3]> = f
        .chunks_exact(3)
        .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
        .collect();
    let mut pts = Vec::with_capacity(fi.len());
    for (k, (&face, bc)) in fi.iter().zip(b.slice().chunks_exact(3)).enumerate() {
        if face < 0 || face as usize >= nf {
            return Err(PyValueError::new_err(format!(
                "face_index: entry {k} = {face} is out of range (0..{})",
                nf.saturating_sub(1)
            )));
        }
        if bc.iter().any(|x| !x.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "bary: row {k} is not finite"
            )));
        }
        pts.push(SurfacePoint {
            face: face as usize,
            bary: [bc[0] as f64, bc[1] as f64, bc[2] as f64],
        });
    }
    let v = vals.slice();
    let out = run_detached(py, || geodesic::interpolate(v, nv, &faces3, &pts))?;
    let arr = ArrayD::from_shape_vec(IxDyn(&[rows, pts.len()]), out)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

#[pymodule]
fn rokeby_native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("NumericalError", m.py().get_type::<NumericalError>())?;
    m.add_function(wrap_pyfunction!(cancel, m)?)?;
    m.add_function(wrap_pyfunction!(field_kernel, m)?)?;
    m.add_function(wrap_pyfunction!(rotation_field, m)?)?;
    m.add_function(wrap_pyfunction!(edited_directions, m)?)?;
    m.add_function(wrap_pyfunction!(view_blend, m)?)?;
    m.add_function(wrap_pyfunction!(view_blend_render_rows, m)?)?;
    m.add_function(wrap_pyfunction!(view_blend_rotation_vectors, m)?)?;
    m.add_function(wrap_pyfunction!(ortho, m)?)?;
    m.add_function(wrap_pyfunction!(geodesic_distances, m)?)?;
    m.add_function(wrap_pyfunction!(interpolate, m)?)?;
    m.add_class::<PyGeodesicSolver>()?;
    compositing::register(m)?;
    environment::register(m)?;
    shadow::register(m)?;
    Ok(())
}
