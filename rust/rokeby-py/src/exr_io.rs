//! Bindings of the pure-Rust OpenEXR reader and writer (rokeby_core::exr_io): bytes in and out,
//! so that the add-on reads and writes EXRs without loading a second OpenEXR C library into
//! Blender's process. A bad file is ValueError saying what is wrong; the GIL is released around
//! decoding and encoding.

use super::{f32_array, run_detached, shape_str};
use crate::convert::to_numpy;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple};
use rokeby_core::exr_io::{self, AttrValue, Samples, WriteChannel};

/// read(data, dwa=False) -> list[dict]
///
/// Every part of the OpenEXR file `data` (bytes), as dicts: ``name`` (str or None),
/// ``data_window`` and ``display_window`` ((xmin, ymin, xmax, ymax), inclusive), ``compression``
/// (OpenEXR's name: "zip", "piz", …), ``tiled``, ``header`` (the string, integer and float
/// attributes by name) and ``channels``: name → (H, W) array over the data window, row 0 at its
/// top, float32 for half (widened exactly) and float channels, uint32 for uint ones, in the file's
/// order, with ``types``: name → "half" | "float" | "uint". Malformed, truncated or unsupported
/// files (deep data, subsampled channels) raise ValueError saying what is wrong, and so do DWAA/
/// DWAB files unless ``dwa`` is true (their decoding differs from OpenEXR's in a few pixels).
#[pyfunction]
#[pyo3(signature = (data, dwa=false))]
pub fn read<'py>(py: Python<'py>, data: &[u8], dwa: bool) -> PyResult<Bound<'py, PyList>> {
    let parts = run_detached(py, || exr_io::read(data, dwa))?;
    let out = PyList::empty(py);
    for p in parts {
        let d = PyDict::new(py);
        d.set_item("name", p.name)?;
        d.set_item("data_window", PyTuple::new(py, p.data_window)?)?;
        d.set_item("display_window", PyTuple::new(py, p.display_window)?)?;
        d.set_item("compression", p.compression)?;
        d.set_item("tiled", p.tiled)?;
        let header = PyDict::new(py);
        for (k, v) in p.attributes {
            match v {
                AttrValue::Text(s) => header.set_item(k, s)?,
                AttrValue::Int(i) => header.set_item(k, i)?,
                AttrValue::Float(f) => header.set_item(k, f)?,
            }
        }
        d.set_item("header", header)?;
        let channels = PyDict::new(py);
        let types = PyDict::new(py);
        let shape = [p.height, p.width];
        for c in p.channels {
            types.set_item(&c.name, c.sample_type.name())?;
            match c.samples {
                Samples::F32(v) => channels.set_item(&c.name, to_numpy(py, &shape, v)?)?,
                Samples::U32(v) => channels.set_item(&c.name, to_numpy(py, &shape, v)?)?,
            }
        }
        d.set_item("channels", channels)?;
        d.set_item("types", types)?;
        out.append(d)?;
    }
    Ok(out)
}

/// write(channels, header=None, compression="zip", half=()) -> bytes
///
/// The bytes of a one-part scanline OpenEXR file: ``channels`` maps names to (H, W) float arrays
/// of one shape (row 0 at the top; stored as float, or as half for the names in ``half``),
/// ``header`` maps attribute names to strings, ``compression`` is one of "none", "rle", "zips",
/// "zip", "piz", "pxr24", "b44", "b44a". Data and display windows are (0, 0)–(W−1, H−1).
#[pyfunction]
#[pyo3(signature = (channels, header=None, compression="zip", half=None))]
pub fn write<'py>(
    py: Python<'py>,
    channels: &Bound<'py, PyDict>,
    header: Option<&Bound<'py, PyDict>>,
    compression: &str,
    half: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyBytes>> {
    let comp = exr_io::compression_from_name(compression).map_err(super::core_err)?;
    let half = half.unwrap_or_default();
    let mut arrays = Vec::with_capacity(channels.len());
    let mut size: Option<Vec<usize>> = None;
    for (k, v) in channels.iter() {
        let name: String = k
            .extract()
            .map_err(|_| PyTypeError::new_err("channels: keys must be channel names (str)"))?;
        let a = f32_array(&v, &format!("channels[{name:?}]"))?;
        let shape = a.shape();
        if shape.len() != 2 {
            return Err(PyValueError::new_err(format!(
                "channels[{name:?}]: expected shape (H, W), got {}",
                shape_str(&shape)
            )));
        }
        match &size {
            None => size = Some(shape.clone()),
            Some(s) if *s != shape => {
                return Err(PyValueError::new_err(format!(
                    "channels[{name:?}]: shape {} differs from the first channel's {}",
                    shape_str(&shape),
                    shape_str(s)
                )))
            }
            _ => {}
        }
        arrays.push((name, a));
    }
    if let Some(h) = half.iter().find(|h| !arrays.iter().any(|(n, _)| n == *h)) {
        return Err(PyValueError::new_err(format!(
            "half: {h:?} is not one of the channels"
        )));
    }
    let Some(size) = size else {
        return Err(PyValueError::new_err("channels: no channels to write"));
    };
    let mut attrs: Vec<(String, String)> = Vec::new();
    if let Some(hd) = header {
        for (k, v) in hd.iter() {
            let k: String = k
                .extract()
                .map_err(|_| PyTypeError::new_err("header: keys must be attribute names (str)"))?;
            let v: String = v.extract().map_err(|_| {
                PyTypeError::new_err(format!("header[{k:?}]: only string attributes are written"))
            })?;
            attrs.push((k, v));
        }
    }
    let chans: Vec<WriteChannel<'_>> = arrays
        .iter()
        .map(|(n, a)| WriteChannel {
            name: n,
            samples: a.slice(),
            half: half.contains(n),
        })
        .collect();
    let attr_refs: Vec<(&str, &str)> = attrs
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    let bytes = run_detached(py, || {
        exr_io::write(size[1], size[0], &chans, &attr_refs, comp)
    })?;
    Ok(PyBytes::new(py, &bytes))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(write, m)?)?;
    Ok(())
}
