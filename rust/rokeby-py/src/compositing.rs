//! Bindings of local shape editing at the compositing stage (Zubiaga et al. 2016): the SH diffuse
//! fit, the dual-paraboloid reflection environment and recompositing. Same house style as the
//! parent module: float arrays in (float32/float64), shapes checked with messages naming the
//! argument, the GIL released, core errors mapped by kind (`core_err`).

use super::{f32_array, run_cancellable, run_detached, shape_str, F32Array};
use crate::convert::{array_f32, array_f64};
use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rokeby_core::compositing::normals;
use rokeby_core::compositing::recomposite::{self as core_recomposite, Buffers, Params, Patch};
use rokeby_core::compositing::reconstruct::{self, ParaboloidMap, ReflectionParams};
use rokeby_core::compositing::sh::{self, Fit, SH_COEFFS};

/// A float array, or a boolean one read as 0/1 (masks).
fn mask_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<F32Array<'py>> {
    let kind: String = obj
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract())
        .unwrap_or_default();
    if kind == "b" {
        return f32_array(&obj.call_method1("astype", ("float32",))?, name);
    }
    f32_array(obj, name)
}

/// An (H, W, 3) array; `hw` fixes H, W when already known.
fn image3<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    hw: Option<(usize, usize)>,
) -> PyResult<(F32Array<'py>, usize, usize)> {
    let a = f32_array(obj, name)?;
    let s = a.shape();
    if s.len() != 3 || s[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected shape (H, W, 3), got {}",
            shape_str(&s)
        )));
    }
    if let Some((h, w)) = hw {
        if (s[0], s[1]) != (h, w) {
            return Err(PyValueError::new_err(format!(
                "{name}: expected shape ({h}, {w}, 3) like the other passes, got {}",
                shape_str(&s)
            )));
        }
    }
    Ok((a, s[0], s[1]))
}

/// An (H, W) array, or None when `obj` is None.
fn image1<'py>(
    obj: Option<&Bound<'py, PyAny>>,
    name: &str,
    h: usize,
    w: usize,
) -> PyResult<Option<F32Array<'py>>> {
    let Some(obj) = obj else { return Ok(None) };
    if obj.is_none() {
        return Ok(None);
    }
    let a = mask_array(obj, name)?;
    if a.shape() != [h, w] {
        return Err(PyValueError::new_err(format!(
            "{name}: expected shape ({h}, {w}) like the other passes, got {}",
            shape_str(&a.shape())
        )));
    }
    Ok(Some(a))
}

/// A required (H, W) array: None is refused by name (not a panic).
fn required1<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    h: usize,
    w: usize,
) -> PyResult<F32Array<'py>> {
    image1(Some(obj), name, h, w)?.ok_or_else(|| {
        PyValueError::new_err(format!("{name}: expected an ({h}, {w}) array, got None"))
    })
}

fn opt_image3<'py>(
    obj: Option<&Bound<'py, PyAny>>,
    name: &str,
    h: usize,
    w: usize,
) -> PyResult<Option<F32Array<'py>>> {
    match obj {
        Some(o) if !o.is_none() => Ok(Some(image3(o, name, Some((h, w)))?.0)),
        _ => Ok(None),
    }
}

fn parse_fit(method: &str) -> PyResult<Fit> {
    Fit::parse(method).ok_or_else(|| {
        PyValueError::new_err(format!(
            "method: unknown fit {method:?} (expected 'qp'/'constrained' or 'ls'/'least_squares')"
        ))
    })
}

/// Order-2 SH fit (eq. 1) of D0 over the pixels of one patch.
///
/// normals (N, 3), values (N, C). Rows with a non-finite or zero normal or a non-finite value are
/// left out and counted in "masked". method: 'qp' (D(n) >= D0, §3.1) or 'ls'. tolerance: the
/// QP's noise tolerance, D(n) >= D0 - tolerance, a number or one per channel (default 0: the
/// paper's QP). Returns {"coeffs": (C, 9) float64, "max_residual", "rms_residual",
/// "iterations": (C,), "pixels", "masked"}.
#[pyfunction]
#[pyo3(signature = (normals, values, method = "qp", tolerance = None))]
pub fn sh_fit<'py>(
    py: Python<'py>,
    normals: &Bound<'py, PyAny>,
    values: &Bound<'py, PyAny>,
    method: &str,
    tolerance: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let fit = parse_fit(method)?;
    let tolerance: Vec<f64> = match tolerance {
        None => Vec::new(),
        Some(t) => {
            let np = py.import("numpy")?;
            let a = np.call_method1("asarray", (t, "float64")).map_err(|e| {
                PyValueError::new_err(format!(
                    "tolerance: expected a number or one per channel ({e})"
                ))
            })?;
            let ndim: usize = a.getattr("ndim")?.extract()?;
            if ndim > 1 {
                return Err(PyValueError::new_err(format!("tolerance: expected a number or one per channel, got an array of {ndim} dimensions")));
            }
            a.call_method0("ravel")?.extract()?
        }
    };
    let n = f32_array(normals, "normals")?;
    let v = f32_array(values, "values")?;
    let ns = n.shape();
    if ns.len() != 2 || ns[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "normals: expected shape (N, 3), got {}",
            shape_str(&ns)
        )));
    }
    let vs = v.shape();
    let channels = match vs.len() {
        1 => 1,
        2 => vs[1],
        _ => 0,
    };
    if channels == 0 || vs[0] != ns[0] {
        return Err(PyValueError::new_err(format!(
            "values: expected shape ({}, C) (one row per normal), got {}",
            ns[0],
            shape_str(&vs)
        )));
    }
    let (nsl, vsl) = (n.slice(), v.slice());
    let p = run_detached(py, || sh::fit_patch(nsl, vsl, channels, fit, &tolerance))?;
    let r = p.fit;
    // The arrays are read in place (no copy): the caller must not write them while the call runs.
    // Validated rows that changed under the fit would surface here as non-finite coefficients.
    if r.coeffs.iter().flatten().any(|x| !x.is_finite()) {
        return Err(PyValueError::new_err("normals/values: the fit is not finite; were the arrays written by another thread during the call?"));
    }
    let d = PyDict::new(py);
    d.set_item(
        "coeffs",
        array_f64(
            py,
            &[channels, SH_COEFFS],
            r.coeffs.iter().flatten().copied().collect(),
        )?,
    )?;
    d.set_item("max_residual", array_f64(py, &[channels], r.max_residual)?)?;
    d.set_item("rms_residual", array_f64(py, &[channels], r.rms_residual)?)?;
    d.set_item("iterations", r.iterations)?;
    d.set_item("pixels", p.pixels)?;
    d.set_item("masked", p.masked)?;
    Ok(d)
}

/// D(n) for SH coefficients (C, 9) at normals (..., 3): (..., C).
#[pyfunction]
pub fn sh_eval<'py>(
    py: Python<'py>,
    coeffs: &Bound<'py, PyAny>,
    normals: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let c = f32_array(coeffs, "coeffs")?;
    let cs = c.shape();
    if cs.len() != 2 || cs[1] != SH_COEFFS {
        return Err(PyValueError::new_err(format!(
            "coeffs: expected shape (C, 9), got {}",
            shape_str(&cs)
        )));
    }
    let n = f32_array(normals, "normals")?;
    let ns = n.shape();
    if ns.last() != Some(&3) {
        return Err(PyValueError::new_err(format!(
            "normals: expected shape (..., 3), got {}",
            shape_str(&ns)
        )));
    }
    // Coefficients come in float64 from sh_fit; re-read them at full precision.
    let co: Vec<[f64; SH_COEFFS]> = {
        let np = py.import("numpy")?;
        let a64: Vec<f64> = np
            .call_method1("asarray", (coeffs, "float64"))?
            .call_method0("ravel")?
            .extract()?;
        a64.chunks_exact(SH_COEFFS)
            .map(|r| r.try_into().unwrap())
            .collect()
    };
    let nsl = n.slice();
    let out = run_detached(py, || sh::eval_many(&co, nsl))?;
    let mut shape = ns[..ns.len() - 1].to_vec();
    shape.push(cs[0]);
    array_f32(py, &shape, out)
}

/// r = 2(n·v)n − v for normals (H, W, 3) and view vectors (H, W, 3) or (3,) (surface → eye).
#[pyfunction]
pub fn reflect_dirs<'py>(
    py: Python<'py>,
    normals: &Bound<'py, PyAny>,
    view: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let (n, h, w) = image3(normals, "normals", None)?;
    let v = f32_array(view, "view")?;
    if v.shape() != [3] && v.shape() != [h, w, 3] {
        return Err(PyValueError::new_err(format!(
            "view: expected shape (3,) or ({h}, {w}, 3), got {}",
            shape_str(&v.shape())
        )));
    }
    let (ns, vs) = (n.slice(), v.slice());
    let out = run_detached(py, || reconstruct::reflect_dirs(ns, vs))?;
    array_f32(py, &[h, w, 3], out)
}

fn map_from(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<ParaboloidMap> {
    let a = f32_array(obj, name)?;
    let s = a.shape();
    if s.len() != 4 || s[0] != 2 || s[1] != s[2] || s[1] < 2 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected a dual-paraboloid map of shape (2, S, S, C), got {}",
            shape_str(&s)
        )));
    }
    if let Some(i) = a.slice().iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name}: value {i} is not finite"
        )));
    }
    Ok(ParaboloidMap {
        size: s[1],
        channels: s[3],
        data: a.slice().to_vec(),
    })
}

/// Reflection environment of one patch (§3.2): partial reconstruction (eq. 2), hole filling and
/// regularisation. reflected (H, W, 3) screen-space r, values (H, W, 3) R0, mask (H, W) > 0.5 for
/// the patch's unoccluded pixels (α_R), depth (H, W) or None. Non-finite pixels are left out.
/// stage='full' (default) or 'partial' (eq. 2 only: holes are 0, see "covered").
/// Returns {"map": (2, S, S, 3) float32, "covered": (2, S, S) bool, "coverage", "triangles",
/// "filled_texels", "blurred_texels"}. Raises ValueError when the reflections cover less than
/// min_coverage of the sphere.
#[pyfunction]
#[pyo3(signature = (reflected, values, mask, depth = None, size = 128, max_edge_angle = 0.5, max_depth_jump = 0.05, blur_sigma = 2.0, min_coverage = 0.01, stage = "full"))]
#[allow(clippy::too_many_arguments)]
pub fn reflection_env<'py>(
    py: Python<'py>,
    reflected: &Bound<'py, PyAny>,
    values: &Bound<'py, PyAny>,
    mask: &Bound<'py, PyAny>,
    depth: Option<&Bound<'py, PyAny>>,
    size: usize,
    max_edge_angle: f64,
    max_depth_jump: f64,
    blur_sigma: f64,
    min_coverage: f64,
    stage: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let (r, h, w) = image3(reflected, "reflected", None)?;
    let (v, _, _) = image3(values, "values", Some((h, w)))?;
    let m = required1(mask, "mask", h, w)?;
    let d = image1(depth, "depth", h, w)?;
    if stage != "full" && stage != "partial" {
        return Err(PyValueError::new_err(format!(
            "stage: expected 'full' or 'partial', got {stage:?}"
        )));
    }
    let params = ReflectionParams {
        size,
        max_edge_angle,
        max_depth_jump,
        blur_sigma,
        min_coverage,
    };
    let (rs, vs, ms) = (r.slice(), v.slice(), m.slice());
    let ds: &[f32] = d.as_ref().map(|a| a.slice()).unwrap_or(&[]);
    let partial_only = stage == "partial";
    let (map, covered, coverage, tris, filled, blurred) = run_cancellable(py, || {
        if partial_only {
            let p = reconstruct::partial(w, h, rs, vs, 3, ms, ds, &params)?;
            Ok((p.map, p.covered, p.coverage, p.triangles, 0, 0))
        } else {
            let e = reconstruct::reconstruct(w, h, rs, vs, 3, ms, ds, &params)?;
            Ok((
                e.map,
                e.covered,
                e.coverage,
                e.triangles,
                e.filled_texels,
                e.blurred_texels,
            ))
        }
    })?;
    let s = map.size;
    if map.data.iter().any(|x| !x.is_finite()) {
        return Err(PyValueError::new_err("reflected/values: the map is not finite; were the arrays written by another thread during the call?"));
    }
    let out = PyDict::new(py);
    out.set_item("map", array_f32(py, &[2, s, s, 3], map.data)?)?;
    let cov: Vec<f32> = covered.iter().map(|&c| if c { 1.0 } else { 0.0 }).collect();
    let np = py.import("numpy")?;
    out.set_item(
        "covered",
        array_f32(py, &[2, s, s], cov)?.call_method1("astype", (np.getattr("bool_")?,))?,
    )?;
    out.set_item("coverage", coverage)?;
    out.set_item("triangles", tris)?;
    out.set_item("filled_texels", filled)?;
    out.set_item("blurred_texels", blurred)?;
    Ok(out)
}

/// Harmonic hole filling of a dual-paraboloid map (2, S, S, C) where `covered` (2, S, S) is
/// false; covered texels are Dirichlet values. Returns the filled map.
#[pyfunction]
pub fn fill_holes<'py>(
    py: Python<'py>,
    map: &Bound<'py, PyAny>,
    covered: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let mut m = map_from(map, "map")?;
    let c = mask_array(covered, "covered")?;
    let s = m.size;
    if c.shape() != [2, s, s] {
        return Err(PyValueError::new_err(format!(
            "covered: expected shape (2, {s}, {s}) like map, got {}",
            shape_str(&c.shape())
        )));
    }
    let cov: Vec<bool> = c.slice().iter().map(|&x| x > 0.5).collect();
    let ch = m.channels;
    let data = run_detached(py, move || {
        reconstruct::fill_holes(&mut [&mut m], &cov)?;
        reconstruct::fill_beyond_equator(&mut m);
        Ok(m.data)
    })?;
    array_f32(py, &[2, s, s, ch], data)
}

/// Bilinear lookups of a dual-paraboloid map (2, S, S, C) in directions (..., 3): (..., C).
#[pyfunction]
pub fn envmap_lookup<'py>(
    py: Python<'py>,
    map: &Bound<'py, PyAny>,
    dirs: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let m = map_from(map, "map")?;
    let d = f32_array(dirs, "dirs")?;
    let ds = d.shape();
    if ds.last() != Some(&3) {
        return Err(PyValueError::new_err(format!(
            "dirs: expected shape (..., 3), got {}",
            shape_str(&ds)
        )));
    }
    let dsl = d.slice();
    let ch = m.channels;
    let out = py.detach(|| {
        let mut out = vec![0.0f32; dsl.len() / 3 * ch];
        let mut tmp = vec![0.0f64; ch];
        for (i, r) in dsl.chunks_exact(3).enumerate() {
            m.lookup(
                glam::DVec3::new(r[0] as f64, r[1] as f64, r[2] as f64),
                &mut tmp,
            );
            for c in 0..ch {
                out[i * ch + c] = tmp[c] as f32;
            }
        }
        out
    });
    let mut shape = ds[..ds.len() - 1].to_vec();
    shape.push(ch);
    array_f32(py, &shape, out)
}

fn parse_patches(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Patch>> {
    let list = obj.cast::<PyList>().map_err(|_| {
        PyTypeError::new_err(
            "patches: must be a list of dicts {'sh': (3, 9) or None, 'env': (2, S, S, 3) or None}",
        )
    })?;
    let np = obj.py().import("numpy")?;
    let mut out = Vec::with_capacity(list.len());
    for (k, item) in list.iter().enumerate() {
        let name = format!("patches[{k}]");
        if item.is_none() {
            out.push(Patch::default());
            continue;
        }
        let d = item
            .cast::<PyDict>()
            .map_err(|_| PyTypeError::new_err(format!("{name}: must be a dict or None")))?;
        let mut p = Patch::default();
        if let Some(s) = d.get_item("sh")? {
            if !s.is_none() {
                let a: Vec<f64> = np
                    .call_method1("asarray", (&s, "float64"))?
                    .call_method0("ravel")?
                    .extract()?;
                let shape: Vec<usize> = np.call_method1("shape", (&s,))?.extract()?;
                if shape != [3, SH_COEFFS] || a.iter().any(|x| !x.is_finite()) {
                    return Err(PyValueError::new_err(format!(
                        "{name}.sh: expected finite coefficients of shape (3, 9), got {}",
                        shape_str(&shape)
                    )));
                }
                let mut c = [[0.0; SH_COEFFS]; 3];
                for ch in 0..3 {
                    c[ch].copy_from_slice(&a[ch * SH_COEFFS..(ch + 1) * SH_COEFFS]);
                }
                p.sh = Some(c);
            }
        }
        if let Some(e) = d.get_item("env")? {
            if !e.is_none() {
                let m = map_from(&e, &format!("{name}.env"))?;
                if m.channels != 3 {
                    return Err(PyValueError::new_err(format!(
                        "{name}.env: expected 3 channels, got {}",
                        m.channels
                    )));
                }
                p.env = Some(m);
            }
        }
        out.push(p);
    }
    Ok(out)
}

/// Patch ids (H, W): int32 read directly (what rokeby.compositing makes), anything else through
/// floats; negative or non-finite → -1 (no patch).
fn ids_vec(ids: &Bound<'_, PyAny>, h: usize, w: usize) -> PyResult<Vec<i32>> {
    Ok(match ids.cast::<PyArrayDyn<i32>>() {
        Ok(a) if a.readonly().is_c_contiguous() => {
            let ro = a.readonly();
            if ro.shape() != [h, w] {
                return Err(PyValueError::new_err(format!(
                    "ids: expected shape ({h}, {w}) like normals, got {}",
                    shape_str(ro.shape())
                )));
            }
            ro.as_slice()
                .map_err(|e| PyRuntimeError::new_err(e.to_string()))?
                .iter()
                .map(|&x| x.max(-1))
                .collect()
        }
        _ => {
            let id_arr = f32_array(ids, "ids")?;
            if id_arr.shape() != [h, w] {
                return Err(PyValueError::new_err(format!(
                    "ids: expected shape ({h}, {w}) like normals, got {}",
                    shape_str(&id_arr.shape())
                )));
            }
            id_arr
                .slice()
                .iter()
                .map(|&x| {
                    if x.is_finite() && x >= 0.0 {
                        x as i32
                    } else {
                        -1
                    }
                })
                .collect()
        }
    })
}

/// The passes of one frame as `recomposite` and `Recompositor` take them, checked against each
/// other's (H, W) in the order of the Python signature: ids, normals, edited normals (absent for a
/// `Recompositor`, which takes them per run), view (H, W, 3) or (3,), diffuse, reflection and
/// image (H, W, 3), then the optional alpha_d, alpha_r, alpha (H, W) and diffuse_color,
/// reflection_color (H, W, 3). Borrowed where the arrays are float32 and contiguous.
struct Passes<'py> {
    h: usize,
    w: usize,
    ids: Vec<i32>,
    normals: F32Array<'py>,
    edited: Option<F32Array<'py>>,
    view: F32Array<'py>,
    /// diffuse, reflection, image.
    planes: [F32Array<'py>; 3],
    /// alpha_d, alpha_r, alpha, diffuse_color, reflection_color.
    optional: [Option<F32Array<'py>>; 5],
}

impl<'py> Passes<'py> {
    fn read(
        ids: &Bound<'py, PyAny>,
        normals: &Bound<'py, PyAny>,
        edited: Option<&Bound<'py, PyAny>>,
        view: &Bound<'py, PyAny>,
        planes: [&Bound<'py, PyAny>; 3],
        optional: [Option<&Bound<'py, PyAny>>; 5],
    ) -> PyResult<Self> {
        let (normals, h, w) = image3(normals, "normals", None)?;
        let ids = ids_vec(ids, h, w)?;
        let edited = match edited {
            Some(e) => Some(image3(e, "edited_normals", Some((h, w)))?.0),
            None => None,
        };
        let view = f32_array(view, "view")?;
        if view.shape() != [3] && view.shape() != [h, w, 3] {
            return Err(PyValueError::new_err(format!(
                "view: expected shape (3,) or ({h}, {w}, 3), got {}",
                shape_str(&view.shape())
            )));
        }
        let [d, r, i] = planes;
        let planes = [
            image3(d, "diffuse", Some((h, w)))?.0,
            image3(r, "reflection", Some((h, w)))?.0,
            image3(i, "image", Some((h, w)))?.0,
        ];
        let [ad, ar, al, dc, rc] = optional;
        let optional = [
            image1(ad, "alpha_d", h, w)?,
            image1(ar, "alpha_r", h, w)?,
            image1(al, "alpha", h, w)?,
            opt_image3(dc, "diffuse_color", h, w)?,
            opt_image3(rc, "reflection_color", h, w)?,
        ];
        Ok(Passes {
            h,
            w,
            ids,
            normals,
            edited,
            view,
            planes,
            optional,
        })
    }

    /// The core's view of the passes (absent optional ones as empty slices, no edited normals
    /// as the normals themselves), borrowed, not copied.
    fn buffers(&self) -> Buffers<'_> {
        let opt = |k: usize| self.optional[k].as_ref().map_or(&[][..], |x| x.slice());
        Buffers {
            ids: &self.ids,
            normals: self.normals.slice(),
            edited: self.edited.as_ref().unwrap_or(&self.normals).slice(),
            view: self.view.slice(),
            diffuse: self.planes[0].slice(),
            reflection: self.planes[1].slice(),
            alpha_d: opt(0),
            alpha_r: opt(1),
            alpha: opt(2),
            image: self.planes[2].slice(),
            diffuse_color: opt(3),
            reflection_color: opt(4),
        }
    }
}

/// Recompositing, eqs. 3–5. ids (H, W): patch index per pixel (< 0: none), normals and
/// edited_normals (H, W, 3) screen space, view (H, W, 3) or (3,), diffuse D0 and reflection R0
/// (H, W, 3) (illumination when diffuse_color/reflection_color are given), image I (H, W, 3);
/// alpha_d, alpha_r, alpha (H, W) default 1. patches: list of {'sh', 'env'} per id.
/// Returns (image (H, W, 3) float32, {"edited": pixels recomposited, "masked": pixels left as I
/// because an input was not finite or their patch has no reconstruction}).
#[pyfunction]
#[pyo3(signature = (ids, normals, edited_normals, view, diffuse, reflection, image, patches, alpha_d = None, alpha_r = None, alpha = None, diffuse_color = None, reflection_color = None, k_d = 1.0, k_r = 1.0, gamma = 1.0, epsilon = core_recomposite::EPSILON))]
#[allow(clippy::too_many_arguments)]
pub fn recomposite<'py>(
    py: Python<'py>,
    ids: &Bound<'py, PyAny>,
    normals: &Bound<'py, PyAny>,
    edited_normals: &Bound<'py, PyAny>,
    view: &Bound<'py, PyAny>,
    diffuse: &Bound<'py, PyAny>,
    reflection: &Bound<'py, PyAny>,
    image: &Bound<'py, PyAny>,
    patches: &Bound<'py, PyAny>,
    alpha_d: Option<&Bound<'py, PyAny>>,
    alpha_r: Option<&Bound<'py, PyAny>>,
    alpha: Option<&Bound<'py, PyAny>>,
    diffuse_color: Option<&Bound<'py, PyAny>>,
    reflection_color: Option<&Bound<'py, PyAny>>,
    k_d: f64,
    k_r: f64,
    gamma: f64,
    epsilon: f64,
) -> PyResult<(Bound<'py, PyArrayDyn<f32>>, Bound<'py, PyDict>)> {
    let p = Passes::read(
        ids,
        normals,
        Some(edited_normals),
        view,
        [diffuse, reflection, image],
        [alpha_d, alpha_r, alpha, diffuse_color, reflection_color],
    )?;
    let (h, w) = (p.h, p.w);
    let pts = parse_patches(patches)?;
    let bufs = p.buffers();
    let params = Params {
        k_d,
        k_r,
        gamma,
        epsilon,
    };
    let (out, st) = run_detached(py, || core_recomposite::recomposite(&bufs, &pts, &params))?;
    let stats = PyDict::new(py);
    stats.set_item("edited", st.edited)?;
    stats.set_item("masked", st.masked)?;
    Ok((array_f32(py, &[h, w, 3], out)?, stats))
}

/// A window bound (rows or cols): None (the whole extent), a slice with step 1, or (start, stop).
fn bound(
    obj: Option<&Bound<'_, PyAny>>,
    name: &str,
    len: usize,
) -> PyResult<std::ops::Range<usize>> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(0..len);
    };
    let bad = || {
        PyValueError::new_err(format!(
            "{name}: expected a slice with step 1 or (start, stop) inside 0..{len}, got {obj}"
        ))
    };
    let (a, b) = if let Ok(sl) = obj.cast::<pyo3::types::PySlice>() {
        let ind = sl.indices(len as isize)?;
        if ind.step != 1 {
            return Err(bad());
        }
        (ind.start, ind.stop)
    } else {
        obj.extract::<(isize, isize)>().map_err(|_| bad())?
    };
    if a < 0 || b > len as isize || a >= b {
        return Err(bad());
    }
    Ok(a as usize..b as usize)
}

/// Recompositor(ids, normals, view, diffuse, reflection, image, patches, *, alpha_d=None,
/// alpha_r=None, alpha=None, diffuse_color=None, reflection_color=None, gamma=1.0, epsilon=ε,
/// prepared=False)
///
/// One rendered frame held for many recompositings (eqs. 3–5; an artist's slider or brush): the
/// passes (as for `recomposite`, without edited_normals) are checked and copied into the core
/// once; each `run` takes only the edited normals (the whole frame, read in place, or a window)
/// and k_D, k_R, and writes I~ into the caller's float32 buffer, the GIL released. Gives
/// `recomposite`'s values bit for bit. `prepared`: keep, per pixel, what does not depend on the
/// edited normals (unit n and v, validity, eq. 5's subtracted term; 25–37 bytes a pixel,
/// `prepared_bytes`) instead of computing it in every run — the same values; 0.72× the instructions
/// of an edit but no faster on a quiet machine (docs/compositing.md), so off by default.
/// Methods: run(...), set_patches(patches); `shape` (H, W).
#[pyclass(frozen, name = "Recompositor", module = "rokeby_native.compositing")]
pub struct PyRecompositor {
    inner: std::sync::Mutex<core_recomposite::Recompositor>,
    shape: (usize, usize),
}

#[pymethods]
impl PyRecompositor {
    #[new]
    #[pyo3(signature = (ids, normals, view, diffuse, reflection, image, patches, *, alpha_d = None, alpha_r = None, alpha = None, diffuse_color = None, reflection_color = None, gamma = 1.0, epsilon = core_recomposite::EPSILON, prepared = false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        ids: &Bound<'_, PyAny>,
        normals: &Bound<'_, PyAny>,
        view: &Bound<'_, PyAny>,
        diffuse: &Bound<'_, PyAny>,
        reflection: &Bound<'_, PyAny>,
        image: &Bound<'_, PyAny>,
        patches: &Bound<'_, PyAny>,
        alpha_d: Option<&Bound<'_, PyAny>>,
        alpha_r: Option<&Bound<'_, PyAny>>,
        alpha: Option<&Bound<'_, PyAny>>,
        diffuse_color: Option<&Bound<'_, PyAny>>,
        reflection_color: Option<&Bound<'_, PyAny>>,
        gamma: f64,
        epsilon: f64,
        prepared: bool,
    ) -> PyResult<Self> {
        let p = Passes::read(
            ids,
            normals,
            None,
            view,
            [diffuse, reflection, image],
            [alpha_d, alpha_r, alpha, diffuse_color, reflection_color],
        )?;
        let (h, w) = (p.h, p.w);
        let pts = parse_patches(patches)?;
        let bufs = p.buffers();
        let inner = run_detached(py, || {
            let mut rc = core_recomposite::Recompositor::new(w, h, &bufs, pts, gamma, epsilon)?;
            rc.set_prepared(prepared);
            Ok(rc)
        })?;
        Ok(PyRecompositor {
            inner: std::sync::Mutex::new(inner),
            shape: (h, w),
        })
    }

    /// (H, W) of the frame.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        self.shape
    }

    /// Bytes held for the per-pixel terms that do not depend on the edited normals (0 when made
    /// with prepared=False).
    #[getter]
    fn prepared_bytes(&self) -> usize {
        let g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        g.prepared_bytes()
    }

    /// New reconstructions: a list of {'sh': (3, 9) or None, 'env': (2, S, S, 3) or None} per
    /// patch id (as for `recomposite`); the passes stay.
    fn set_patches(&self, py: Python<'_>, patches: &Bound<'_, PyAny>) -> PyResult<()> {
        let pts = parse_patches(patches)?;
        run_detached(py, || {
            let mut g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
            g.set_patches(pts)
        })
    }

    /// Eqs. 3–5 on the window rows × cols (None: the whole frame; a slice with step 1 or (start,
    /// stop)) into `out`: float32, C-contiguous, writable, (H, W, 3) — only the window's pixels
    /// are written — or the window's shape (rh, rw, 3). edited_normals: (H, W, 3) (the window's
    /// pixels are read; the whole frame is read in place), (rh, rw, 3) (the window's ñ), or None
    /// (the ñ last given for those pixels with a window; n before any). The ñ given with a window
    /// is kept for later calls. Returns {"edited", "masked"} as `recomposite`. A finite I giving a
    /// non-finite I~ (k_d, k_r or the edit too large for float32) raises ValueError naming the
    /// pixel; `out`'s window then holds no useful values.
    #[pyo3(signature = (out, edited_normals = None, rows = None, cols = None, k_d = 1.0, k_r = 1.0))]
    #[allow(clippy::too_many_arguments)]
    fn run<'py>(
        &self,
        py: Python<'py>,
        out: &Bound<'py, PyAny>,
        edited_normals: Option<&Bound<'py, PyAny>>,
        rows: Option<&Bound<'py, PyAny>>,
        cols: Option<&Bound<'py, PyAny>>,
        k_d: f64,
        k_r: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (h, w) = self.shape;
        let win = core_recomposite::Window {
            rows: bound(rows, "rows", h)?,
            cols: bound(cols, "cols", w)?,
        };
        let whole = win.rows.len() == h && win.cols.len() == w;
        let wshape = [win.rows.len(), win.cols.len(), 3];
        let e = match edited_normals.filter(|o| !o.is_none()) {
            Some(o) => {
                let a = f32_array(o, "edited_normals")?;
                let s = a.shape();
                if s != [h, w, 3] && s != wshape {
                    return Err(PyValueError::new_err(format!(
                        "edited_normals: expected shape ({h}, {w}, 3) or the window's {}, got {}",
                        shape_str(&wshape),
                        shape_str(&s)
                    )));
                }
                Some((s == [h, w, 3], a))
            }
            None => None,
        };
        let arr = out.cast::<PyArrayDyn<f32>>().map_err(|_| {
            PyTypeError::new_err(
                "out: must be a float32 numpy array (H, W, 3) or the window's shape",
            )
        })?;
        let mut rw = arr.try_readwrite().map_err(|e| {
            PyValueError::new_err(format!(
                "out: must be writable and not one of the inputs ({e})"
            ))
        })?;
        let os = rw.shape().to_vec();
        let out_full = os == [h, w, 3];
        if !out_full && os != wshape {
            return Err(PyValueError::new_err(format!(
                "out: expected shape ({h}, {w}, 3) or the window's {}, got {}",
                shape_str(&wshape),
                shape_str(&os)
            )));
        }
        if !rw.is_c_contiguous() {
            return Err(PyValueError::new_err("out: must be C-contiguous"));
        }
        let o = rw
            .as_slice_mut()
            .map_err(|e| PyValueError::new_err(format!("out: {e}")))?;
        let e: Option<(bool, &[f32])> = e.as_ref().map(|(full, a)| (*full, a.slice()));
        let st = run_detached(py, || {
            let mut g = self.inner.lock().unwrap_or_else(|p| p.into_inner());
            match e {
                // The whole frame given for the whole frame: read in place.
                Some((true, a)) if whole => g.run(&win, Some(a), k_d, k_r, o, out_full),
                Some((full, a)) => {
                    g.set_edited(&win, a, full)?;
                    g.run(&win, None, k_d, k_r, o, out_full)
                }
                None => g.run(&win, None, k_d, k_r, o, out_full),
            }
        })?;
        let stats = PyDict::new(py);
        stats.set_item("edited", st.edited)?;
        stats.set_item("masked", st.masked)?;
        Ok(stats)
    }
}

/// The edit mask of the normal tools: None, or (H, W) bool/float (> 0.5: may be edited).
fn edit_mask(mask: Option<&Bound<'_, PyAny>>, h: usize, w: usize) -> PyResult<Option<Vec<bool>>> {
    Ok(image1(mask, "mask", h, w)?.map(|m| m.slice().iter().map(|&v| v > 0.5).collect()))
}

/// Embossing of screen-space normals (H, W, 3): n_z → β n_z, renormalised, β in (0, 1]; background,
/// masked-out and unchanged pixels keep their input bits. Returns (H, W, 3) float32.
#[pyfunction]
#[pyo3(signature = (normals, beta, mask = None))]
pub fn normals_emboss<'py>(
    py: Python<'py>,
    normals: &Bound<'py, PyAny>,
    beta: f32,
    mask: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let (n, h, w) = image3(normals, "normals", None)?;
    let m = edit_mask(mask, h, w)?;
    let ns = n.slice();
    let out = run_detached(py, || {
        normals::emboss(
            ns,
            &normals::Frame {
                width: w,
                height: h,
                mask: m.as_deref(),
            },
            beta,
        )
    })?;
    array_f32(py, &[h, w, 3], out)
}

/// Bump mapping: ñ = normalize(n − strength ∇height), ∇h = (∂h/∂col, −∂h/∂row, 0); height (H, W).
#[pyfunction]
#[pyo3(signature = (normals, height, strength = 1.0, mask = None))]
pub fn normals_bump<'py>(
    py: Python<'py>,
    normals: &Bound<'py, PyAny>,
    height: &Bound<'py, PyAny>,
    strength: f32,
    mask: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let (n, h, w) = image3(normals, "normals", None)?;
    let hh = required1(height, "height", h, w)?;
    let m = edit_mask(mask, h, w)?;
    let (ns, hs) = (n.slice(), hh.slice());
    let out = run_detached(py, || {
        normals::bump(
            ns,
            &normals::Frame {
                width: w,
                height: h,
                mask: m.as_deref(),
            },
            hs,
            strength,
        )
    })?;
    array_f32(py, &[h, w, 3], out)
}

/// Cross-bilateral smoothing of the normals with depth (H, W): spatial σ_s pixels, range σ_d on
/// the relative depth difference; n_z = √(1 − |n̄|²).
#[pyfunction]
#[pyo3(signature = (normals, depth, sigma_s = 3.0, sigma_d = 0.02, mask = None))]
pub fn normals_bilateral<'py>(
    py: Python<'py>,
    normals: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    sigma_s: f64,
    sigma_d: f64,
    mask: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let (n, h, w) = image3(normals, "normals", None)?;
    let d = required1(depth, "depth", h, w)?;
    let m = edit_mask(mask, h, w)?;
    let (ns, ds) = (n.slice(), d.slice());
    let out = run_cancellable(py, || {
        normals::bilateral(
            ns,
            &normals::Frame {
                width: w,
                height: h,
                mask: m.as_deref(),
            },
            ds,
            sigma_s,
            sigma_d,
        )
    })?;
    array_f32(py, &[h, w, 3], out)
}

/// A procedural bump decal (fractal gradient noise faded by (1 − d/radius)₊² around `center`,
/// (x, y) pixels): heights (H, W) float32 in pixels, within about ±size/4.
#[pyfunction]
#[pyo3(signature = (height, width, size, octaves, seed, center, radius))]
#[allow(clippy::too_many_arguments)]
pub fn normals_noise_decal<'py>(
    py: Python<'py>,
    height: usize,
    width: usize,
    size: f64,
    octaves: u32,
    seed: u32,
    center: (f64, f64),
    radius: f64,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let out = run_detached(py, || {
        normals::noise_decal(width, height, size, octaves, seed, center, radius)
    })?;
    array_f32(py, &[height, width], out)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(normals_noise_decal, m)?)?;
    m.add_function(wrap_pyfunction!(normals_emboss, m)?)?;
    m.add_function(wrap_pyfunction!(normals_bump, m)?)?;
    m.add_function(wrap_pyfunction!(normals_bilateral, m)?)?;
    m.add_function(wrap_pyfunction!(sh_fit, m)?)?;
    m.add_function(wrap_pyfunction!(sh_eval, m)?)?;
    m.add_function(wrap_pyfunction!(reflect_dirs, m)?)?;
    m.add_function(wrap_pyfunction!(reflection_env, m)?)?;
    m.add_function(wrap_pyfunction!(fill_holes, m)?)?;
    m.add_function(wrap_pyfunction!(envmap_lookup, m)?)?;
    m.add_function(wrap_pyfunction!(recomposite, m)?)?;
    m.add_class::<PyRecompositor>()?;
    Ok(())
}
