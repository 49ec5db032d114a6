//! Bindings of the environment-map toolkit and its prefiltering (rokeby_core::envmaps::envmap,
//! rokeby_core::envmaps::prefilter). Same house style as the parent module: float arrays in
//! (float32/float64), shapes and values checked with messages naming the argument, the GIL
//! released around the work, core errors mapped by kind (`core_err`).
//!
//! Array shapes per layout (row 0 = the top row of the image file):
//! latlong (H, W, C) · cube (6, S, S, C) in the order +X, −X, +Y, −Y, +Z, −Z · sphere (S, S, C) ·
//! paraboloid (2, S, S, C), face 0 looking along +Z.

use super::{core_err, f32_array, run_cancellable, run_detached, shape_str};
use crate::convert::{array_f32, array_f64};
use numpy::PyArrayDyn;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use rokeby_core::compositing::sh::SH_COEFFS;
use rokeby_core::envmaps::envmap::{EnvMap, Layout};
use rokeby_core::envmaps::prefilter::{self as core_prefilter, Lobe, PrefilterParams, A_HAT};
use rokeby_core::RokebyError;

fn parse_layout(name: &str, arg: &str) -> PyResult<Layout> {
    Layout::parse(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "{arg}: unknown layout {name:?} (expected 'latlong', 'cube', 'sphere' or 'paraboloid')"
        ))
    })
}

/// The shape a map of `layout` has in numpy.
fn np_shape(m: &EnvMap) -> Vec<usize> {
    match m.layout {
        Layout::LatLong | Layout::Sphere => vec![m.height, m.width, m.channels],
        Layout::Cube | Layout::Paraboloid => vec![m.layout.faces(), m.height, m.width, m.channels],
    }
}

/// Reads an environment image of the given layout (shape and finiteness checked).
fn env_from(obj: &Bound<'_, PyAny>, layout: Layout, arg: &str) -> PyResult<EnvMap> {
    let a = f32_array(obj, arg)?;
    let s = a.shape();
    let (h, w, c) = match layout {
        Layout::LatLong | Layout::Sphere => {
            if s.len() != 3 {
                let want = if layout == Layout::LatLong {
                    "(H, W, C)"
                } else {
                    "(S, S, C)"
                };
                return Err(PyValueError::new_err(format!(
                    "{arg}: a {} map must have shape {want}, got {}",
                    layout.name(),
                    shape_str(&s)
                )));
            }
            (s[0], s[1], s[2])
        }
        Layout::Cube | Layout::Paraboloid => {
            let f = layout.faces();
            if s.len() != 4 || s[0] != f {
                return Err(PyValueError::new_err(format!(
                    "{arg}: a {} map must have shape ({f}, S, S, C), got {}",
                    layout.name(),
                    shape_str(&s)
                )));
            }
            (s[1], s[2], s[3])
        }
    };
    EnvMap::new(layout, h, w, c, a.slice().to_vec(), arg).map_err(core_err)
}

fn out_array<'py>(py: Python<'py>, m: EnvMap) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let shape = np_shape(&m);
    array_f32(py, &shape, m.data)
}

/// (..., 3) directions → flat N×3 and the leading shape.
fn directions(obj: &Bound<'_, PyAny>, arg: &str) -> PyResult<(Vec<f32>, Vec<usize>)> {
    let a = f32_array(obj, arg)?;
    let s = a.shape();
    if s.is_empty() || s[s.len() - 1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{arg}: expected shape (..., 3), got {}",
            shape_str(&s)
        )));
    }
    Ok((a.slice().to_vec(), s[..s.len() - 1].to_vec()))
}

/// The lobe of `kind` with parameter `p` (ValueError naming `arg` for bad values).
fn parse_lobe(kind: &str, p: f64, arg: &str) -> PyResult<Lobe> {
    let r = match kind.to_ascii_lowercase().as_str() {
        "phong" => Lobe::phong(p),
        "ggx" => Lobe::ggx_roughness(p),
        "torrance_sparrow" | "torrance-sparrow" | "ts" => Lobe::torrance_sparrow(p),
        "gaussian" => Lobe::gaussian(p),
        _ => {
            return Err(PyValueError::new_err(format!(
                "lobe: unknown lobe {kind:?} (expected 'phong', 'ggx', 'torrance_sparrow' or 'gaussian')"
            )))
        }
    };
    r.map_err(|e| match e {
        RokebyError::InvalidArgument { .. } => PyValueError::new_err(format!("{arg}: {e}")),
        e => core_err(e),
    })
}

/// The same environment on another layout. `size` is the output height (lat-long: width 2·size)
/// or face size; each texel averages `supersample`² bilinear lookups.
#[pyfunction]
#[pyo3(signature = (image, layout_in, layout_out, size, supersample = 1))]
pub fn convert<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    layout_in: &str,
    layout_out: &str,
    size: usize,
    supersample: usize,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let li = parse_layout(layout_in, "layout_in")?;
    let lo = parse_layout(layout_out, "layout_out")?;
    let env = env_from(image, li, "image")?;
    if size < 2 {
        return Err(PyValueError::new_err(format!(
            "size: must be ≥ 2, got {size}"
        )));
    }
    let (h, w) = if lo == Layout::LatLong {
        (size, size.saturating_mul(2))
    } else {
        (size, size)
    };
    let out = run_detached(py, || env.convert(lo, h, w, supersample))?;
    out_array(py, out)
}

/// Bilinear, seam-correct lookups: (..., 3) directions → (..., C).
#[pyfunction]
#[pyo3(signature = (image, layout, directions))]
pub fn sample<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    layout: &str,
    directions: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let env = env_from(image, parse_layout(layout, "layout")?, "image")?;
    let (d, lead) = self::directions(directions, "directions")?;
    let out = run_detached(py, || env.sample_many(&d))?;
    let mut shape = lead;
    shape.push(env.channels);
    array_f32(py, &shape, out)
}

/// Specular prefiltering of a lat-long (H, W, C) image: one (H_k, W_k, C) lat-long array per
/// value of `params` (Phong exponents σ, GGX roughness, Torrance–Sparrow σ, or the reflection
/// maps' separable Gaussian σ in radians), each at its own resolution (the input's for sharp
/// lobes, a coarser one for rough ones).
#[pyfunction]
#[pyo3(signature = (image, lobe, params, texels_per_radius = 6.0, tail = 1e-5))]
pub fn prefilter<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    lobe: &str,
    params: Vec<f64>,
    texels_per_radius: f64,
    tail: f64,
) -> PyResult<Bound<'py, PyList>> {
    let env = env_from(image, Layout::LatLong, "image")?;
    if params.is_empty() {
        return Err(PyValueError::new_err(
            "params: need at least one lobe parameter",
        ));
    }
    let lobes = params
        .iter()
        .enumerate()
        .map(|(i, &p)| parse_lobe(lobe, p, &format!("params[{i}]")))
        .collect::<PyResult<Vec<_>>>()?;
    let pp = PrefilterParams {
        texels_per_radius,
        tail,
    };
    let levels = run_cancellable(py, || core_prefilter::prefilter(&env, &lobes, &pp))?;
    let out = PyList::empty(py);
    for lv in levels {
        out.append(out_array(py, lv.map)?)?;
    }
    Ok(out)
}

/// Order-2 SH irradiance of a lat-long (H, W, C) image: {'coeffs': (C, 9) L_lm,
/// 'irradiance_coeffs': (C, 9) Â_l L_lm / π (evaluate with the SH basis for E(n)/π, e.g. sh_eval),
/// 'image': (size, 2·size, C) lat-long map of E(n)/π}.
#[pyfunction]
#[pyo3(signature = (image, size = 32))]
pub fn irradiance<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    size: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let env = env_from(image, Layout::LatLong, "image")?;
    if size < 2 {
        return Err(PyValueError::new_err(format!(
            "size: must be ≥ 2, got {size}"
        )));
    }
    let (map, coeffs) = run_cancellable(py, || {
        core_prefilter::irradiance_map(&env, size, size.saturating_mul(2))
    })?;
    let c = coeffs.len();
    let flat: Vec<f64> = coeffs.iter().flatten().copied().collect();
    let irr: Vec<f64> = coeffs
        .iter()
        .flat_map(|cf| (0..SH_COEFFS).map(move |k| cf[k] * A_HAT[k] / std::f64::consts::PI))
        .collect();
    let d = PyDict::new(py);
    d.set_item("coeffs", array_f64(py, &[c, SH_COEFFS], flat)?)?;
    d.set_item("irradiance_coeffs", array_f64(py, &[c, SH_COEFFS], irr)?)?;
    d.set_item("image", out_array(py, map)?)?;
    Ok(d)
}

/// The seed's brute-force sum over every texel of a lat-long image (Fraser eq. 2), the reference
/// for the prefiltered maps: lobe 'phong'/'ggx'/'torrance_sparrow' with parameter `param`
/// (normalised as the prefiltered maps are), or 'lambert' for E(n)/π. (..., 3) → (..., C) float64.
#[pyfunction]
#[pyo3(signature = (image, lobe, directions, param = 0.0))]
pub fn prefilter_reference<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    lobe: &str,
    directions: &Bound<'py, PyAny>,
    param: f64,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let env = env_from(image, Layout::LatLong, "image")?;
    let (d, lead) = self::directions(directions, "directions")?;
    // Checked here so that a zero or non-finite direction is reported as `directions` (the core's
    // irradiance reference calls them "normals").
    run_detached(py, || {
        rokeby_core::envmaps::envmap::finite_dirs(&d, "directions").map(|_| ())
    })?;
    let out = if lobe.eq_ignore_ascii_case("lambert") {
        run_detached(py, || core_prefilter::brute_force_irradiance(&env, &d))?
    } else {
        let l = parse_lobe(lobe, param, "param")?;
        run_detached(py, || core_prefilter::brute_force(&env, &l, &d))?
    };
    let mut shape = lead;
    shape.push(env.channels);
    array_f64(py, &shape, out)
}

/// The pixels of a Radiance RGBE (.hdr) file's bytes: (H, W, 3) float32, row 0 at the top.
/// Malformed or unsupported files raise ValueError saying what was found.
#[pyfunction]
pub fn rgbe_decode<'py>(py: Python<'py>, data: &[u8]) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let (h, w, px) = run_detached(py, || rokeby_core::envmaps::rgbe::decode(data))?;
    array_f32(py, &[h, w, 3], px)
}

/// The bytes of a Radiance RGBE (.hdr) file of (H, W, 3) float pixels (row 0 at the top;
/// run-length encoded scanlines). Negative values are written as 0; NaN/inf are refused.
#[pyfunction]
pub fn rgbe_encode<'py>(
    py: Python<'py>,
    pixels: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyBytes>> {
    let a = f32_array(pixels, "pixels")?;
    let shape = a.shape();
    if shape.len() != 3 || shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "pixels: expected shape (H, W, 3), got {}",
            shape_str(&shape)
        )));
    }
    let sl = a.slice();
    if let Some(i) = sl.iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "pixels: value {} at pixel {} is not finite",
            sl[i],
            i / 3
        )));
    }
    let bytes = run_detached(py, || {
        rokeby_core::envmaps::rgbe::encode(shape[0], shape[1], sl)
    })?;
    Ok(PyBytes::new(py, &bytes))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(convert, m)?)?;
    m.add_function(wrap_pyfunction!(rgbe_decode, m)?)?;
    m.add_function(wrap_pyfunction!(rgbe_encode, m)?)?;
    m.add_function(wrap_pyfunction!(sample, m)?)?;
    m.add_function(wrap_pyfunction!(prefilter, m)?)?;
    m.add_function(wrap_pyfunction!(irradiance, m)?)?;
    m.add_function(wrap_pyfunction!(prefilter_reference, m)?)?;
    Ok(())
}
