//! Conversions between Python objects and the core's flat arrays, shared by every binding file:
//! float arrays (float32 or float64, any layout) as float32, integer arrays as int64, shapes in
//! messages, and flat results back as numpy arrays.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;

/// A float array as float32: borrowed when it already is contiguous float32, else converted.
pub(crate) enum F32Array<'py> {
    Borrowed(PyReadonlyArrayDyn<'py, f32>),
    Owned(Vec<f32>, Vec<usize>),
}

impl F32Array<'_> {
    pub(crate) fn slice(&self) -> &[f32] {
        match self {
            F32Array::Borrowed(a) => a.as_slice().expect("checked contiguous"),
            F32Array::Owned(v, _) => v,
        }
    }
    pub(crate) fn shape(&self) -> Vec<usize> {
        match self {
            F32Array::Borrowed(a) => a.shape().to_vec(),
            F32Array::Owned(_, s) => s.clone(),
        }
    }
}

pub(crate) fn shape_str(s: &[usize]) -> String {
    let parts: Vec<String> = s.iter().map(|x| x.to_string()).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// Accepts a numpy array (or anything numpy.asarray takes) of float32/float64.
pub(crate) fn f32_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<F32Array<'py>> {
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

pub(crate) fn parse_vec3(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<[f64; 3]> {
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

/// An integer array (faces, indices) as i64; floats are refused (an index must be exact).
pub(crate) fn i64_array(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<i64>, Vec<usize>)> {
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

/// A flat result of the core as a numpy array of `shape`. The core returns exactly the product of
/// `shape` values; a mismatch is a bug, reported as such.
pub(crate) fn to_numpy<'py, T: numpy::Element>(
    py: Python<'py>,
    shape: &[usize],
    data: Vec<T>,
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    let n = data.len();
    let arr = ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| {
        PyRuntimeError::new_err(format!(
            "rokeby_native internal error (please report): {n} values for shape {} ({e})",
            shape_str(shape)
        ))
    })?;
    Ok(arr.into_pyarray(py))
}

pub(crate) fn array_f32<'py>(
    py: Python<'py>,
    shape: &[usize],
    data: Vec<f32>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    to_numpy(py, shape, data)
}

pub(crate) fn array_f64<'py>(
    py: Python<'py>,
    shape: &[usize],
    data: Vec<f64>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    to_numpy(py, shape, data)
}
