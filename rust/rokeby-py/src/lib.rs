//! `rokeby_native`: the Python face of rokeby-core.
//!
//! This crate only converts: numpy arrays in (float32 or float64, any layout; float64 is stored
//! as float32 like Blender's mesh data), validated shapes with errors that name the argument,
//! the GIL released around the work, panics caught, core errors mapped by kind: bad input →
//! `ValueError`, memory → `MemoryError`, numerical failure → `NumericalError` (a `RuntimeError`),
//! cancelled → `KeyboardInterrupt`, internal bug or panic → `RuntimeError`.

//! One binding file per area of the core, named as the core names it, and one Python submodule
//! per area with the same name: [`reflection`], [`geometry`], [`envmaps`], [`shadows`],
//! [`compositing`] and [`exr_io`] (`rokeby_native.reflection.rotation_field`, ...). The top level
//! holds only what spans the areas: `__version__`, `NumericalError` and `cancel`. [`convert`] and
//! [`errors`] are shared.

use pyo3::prelude::*;

mod compositing;
mod convert;
mod envmaps;
mod errors;
mod exr_io;
mod geometry;
mod reflection;
mod shadows;

pub(crate) use convert::{f32_array, i64_array, parse_vec3, shape_str, F32Array};
pub(crate) use errors::{core_err, run_cancellable, run_detached, NumericalError};

/// cancel()
///
/// Stops the cancellable native calls in flight (blurs, filters, prefiltering, reconstruction) at
/// their next row: they raise KeyboardInterrupt. For a Blender operator's Esc or a watchdog
/// thread; Ctrl-C does the same for a call made from the main thread.
#[pyfunction]
fn cancel() {
    rokeby_core::cancel::request();
}

#[pymodule]
fn rokeby_native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // NumPy's C API is looked up (importing numpy's modules) on the first array made from Rust, and
    // rust-numpy panics if that import fails. Made here, at import, so that a KeyboardInterrupt
    // raised later by a Ctrl-C handler can never land inside that lookup: it would be a panic.
    let _ = numpy::PyArray1::<f32>::zeros(m.py(), 0, false);
    m.add("NumericalError", m.py().get_type::<NumericalError>())?;
    m.add_function(wrap_pyfunction!(cancel, m)?)?;
    add_area(m, "reflection", reflection::register)?;
    add_area(m, "geometry", geometry::register)?;
    add_area(m, "envmaps", envmaps::register)?;
    add_area(m, "shadows", shadows::register)?;
    add_area(m, "compositing", compositing::register)?;
    add_area(m, "exr_io", exr_io::register)?;
    Ok(())
}

/// The submodule `rokeby_native.<name>` filled by `register`, set as an attribute of the top
/// module and entered in `sys.modules`, so that `import rokeby_native.<name>` and
/// `from rokeby_native.<name> import ...` work as for a Python package.
fn add_area(
    top: &Bound<'_, PyModule>,
    name: &str,
    register: fn(&Bound<'_, PyModule>) -> PyResult<()>,
) -> PyResult<()> {
    let py = top.py();
    let qualified = format!("rokeby_native.{name}");
    let area = PyModule::new(py, &qualified)?;
    register(&area)?;
    top.add(name, &area)?;
    py.import("sys")?
        .getattr("modules")?
        .set_item(&qualified, &area)?;
    Ok(())
}
