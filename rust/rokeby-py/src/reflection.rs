//! Bindings of reflection editing (Ritschel et al. 2009): the MLS rotation field
//! (rokeby_core::reflection::field), its view-dependent blend (eq. 7), regions (rokeby_core::reflection::region) and the
//! polar decomposition (rokeby_core::reflection::polar).

use crate::convert::{f32_array, i64_array, parse_vec3, shape_str, to_numpy, F32Array};
use crate::errors::{core_err, run_detached};
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use rokeby_core::reflection::field::{output_width, Distances, Field, FieldOutput};
use rokeby_core::reflection::polar::{self, PolarMethod};
use rokeby_core::reflection::region::Region;

/// field_kernel() -> str: the kernel the field functions use now: "scalar" (the f64 reference),
/// "portable", "avx2" or "avx512" — ROKEBY_SIMD (read at each call) resolved against this CPU.
#[pyfunction]
fn field_kernel() -> &'static str {
    rokeby_core::reflection::field::Kernel::from_env().name()
}

fn parse_polar(name: &str) -> PyResult<PolarMethod> {
    PolarMethod::parse(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "polar: unknown method {name:?} (expected 'exact'/'svd' or 'fast'/'iterative')"
        ))
    })
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
// One argument per Python (keyword) argument of the pyo3 signature above.
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
    to_numpy(py, &[n, width], out)
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
    let out = run_detached(py, || {
        rokeby_core::reflection::field::view_blend_directions(p, d, ramp)
    })?;
    to_numpy(py, &[ps[0], 3], out)
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
// Returns the Python tuple of arrays the docstring lists.
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
        rokeby_core::reflection::field::view_blend_render_rows(p, cv, fv, ramp)
    })?;
    let rows = r.xyz.len() / 3;
    Ok((
        r.per_corner,
        to_numpy(py, &[rows, 3], r.xyz)?,
        to_numpy(py, &[rows, 3], r.wa)?,
    ))
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
    let out = run_detached(py, || {
        rokeby_core::reflection::field::view_blend_rotation_vectors(p)
    })?;
    to_numpy(py, &[n, 3], out)
}

/// edited_directions(positions, normals, eye, constraints, *, distances=None, regions=None,
/// polar="fast") -> (..., 3) float32 unit vectors.
///
/// The per-pixel path (paper §6.1): r(q) = reflect(q − eye, n) and e(q) = R_a(q) r(q) for a
/// G-buffer of positions and normals of any leading shape, e.g. (H, W, 3) (rows of W pixels are
/// the unit of parallel work). K = 0 returns the unedited reflections r(q).
#[pyfunction]
#[pyo3(signature = (positions, normals, eye, constraints, *, distances=None, regions=None, polar="fast"))]
// One argument per Python (keyword) argument of the pyo3 signature above.
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
    to_numpy(py, &shape, out)
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
    let out = run_detached(py, || polar::ortho_batch(s, method))?;
    let mut oshape = shape[..shape.len() - 2].to_vec();
    oshape.push(4);
    to_numpy(py, &oshape, out)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(field_kernel, m)?)?;
    m.add_function(wrap_pyfunction!(rotation_field, m)?)?;
    m.add_function(wrap_pyfunction!(edited_directions, m)?)?;
    m.add_function(wrap_pyfunction!(view_blend, m)?)?;
    m.add_function(wrap_pyfunction!(view_blend_render_rows, m)?)?;
    m.add_function(wrap_pyfunction!(view_blend_rotation_vectors, m)?)?;
    m.add_function(wrap_pyfunction!(ortho, m)?)?;
    Ok(())
}
