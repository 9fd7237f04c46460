//! `omniscan._native`: the Python bindings (PyO3). Every function here converts numpy arrays to
//! the workspace crates' types, calls the crate, and converts back; the geometry, the detector
//! and the readers are the crates' own (README.md "Python", docs/DECISIONS.md).
//!
//! Units as everywhere in omniscan: millimetres, world frame (receiver frame, +z up towards the
//! mirror); degrees in the Python API, radians in the crates; pixels x right, y down, (0, 0) at
//! the centre of the top-left pixel.

mod arrays;
mod camera;
mod readers;
mod scanner;
mod stripe;

use pyo3::prelude::*;

pyo3::create_exception!(
    omniscan,
    FormatError,
    pyo3::exceptions::PyValueError,
    "A file or record omniscan refuses: the message names the file and the field, record or line."
);

/// An omniscan reader's error as a Python exception: a missing or unreadable file is an
/// `OSError`, anything else a [`FormatError`] (a `ValueError`); both keep the message, which
/// names the file and the field or line.
pub(crate) fn format_error(e: omni_formats::Error) -> PyErr {
    // `Error::io` keeps the operating system's message, which ends in "(os error N)".
    if e.location.is_empty() && e.message.contains("(os error") {
        pyo3::exceptions::PyOSError::new_err(e.to_string())
    } else {
        FormatError::new_err(e.to_string())
    }
}

/// A value error with `message` (bad arguments: shapes, ranges, names).
pub(crate) fn value_error(message: impl Into<String>) -> PyErr {
    pyo3::exceptions::PyValueError::new_err(message.into())
}

/// A count or index argument (`facet`, `laser`) taken as a Python int: a ValueError naming the
/// argument for a negative or too large one, where pyo3's own conversion says OverflowError
/// and names nothing.
pub(crate) fn index_arg<T: TryFrom<i64>>(name: &str, value: i64) -> PyResult<T> {
    T::try_from(value).map_err(|_| value_error(format!("{name}: expected a whole number from 0, got {value}")))
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FormatError", m.py().get_type::<FormatError>())?;
    m.add_class::<camera::Camera>()?;
    m.add_class::<scanner::Scanner>()?;
    m.add_function(wrap_pyfunction!(scanner::triangulate, m)?)?;
    m.add_function(wrap_pyfunction!(stripe::detect_stripe, m)?)?;
    m.add_function(wrap_pyfunction!(stripe::measure_laser_tail, m)?)?;
    m.add_function(wrap_pyfunction!(readers::read_stream, m)?)?;
    m.add_function(wrap_pyfunction!(readers::read_ply, m)?)?;
    m.add("DEFAULT_MIN_INCIDENCE_DEG", omni_cloud::triangulate::DEFAULT_MIN_INCIDENCE_DEG)?;
    Ok(())
}
