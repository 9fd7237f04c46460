//! `omniscan.read_stream` and `omniscan.read_ply`: omni_formats' readers, results as numpy.

use crate::arrays::rows;
use numpy::IntoPyArray;
use omni_formats::stream::{Record, Status, StreamReader};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

/// A serialisable record as a Python object (through the `json` module: the record's own
/// field names and values, as in the file).
pub(crate) fn to_python<'py>(py: Python<'py>, value: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| crate::value_error(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// Reads an omniscan stream (JSON Lines: manifest, stripes or points; `-` = stdin) with the
/// tools' reader: the header's format and version are checked, every record validated, and a
/// relative `frames_dir` resolved beside the file. Returns a dict: `header` (dict), `frames`
/// (list of dicts with the record's fields; `stripe` an (n, 5) array of u, v, intensity, width,
/// quality and `points` an (m, 6) array of x, y, z (mm), laser, range (mm), stripe_index where
/// present, else None; `image_path` the frame's image and `ambient_image_path` its laser-off
/// frame (None without one) resolved against `frames_dir`), `errors`
/// (per-frame error records) and `status` (the final record; for a stream cut short, the
/// `complete: false` status the tools pass on).
#[pyfunction]
pub fn read_stream<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let mut reader = StreamReader::open(&path).map_err(crate::format_error)?;
    let (frames, errors) = (PyList::empty(py), PyList::empty(py));
    let (mut header, mut status, mut frames_dir) = (None, None, None::<String>);
    while let Some(record) = reader.next_record().map_err(crate::format_error)? {
        match record {
            Record::Header(h) => {
                frames_dir = h.frames_dir.clone();
                header = Some(to_python(py, &h)?);
            }
            Record::Frame(mut frame) => {
                let stripe = frame.stripe.take();
                let points = frame.points.take();
                let image_path = frame.resolve_path(frames_dir.as_deref(), &frame.path);
                let ambient_image_path =
                    frame.ambient_path.as_ref().map(|a| frame.resolve_path(frames_dir.as_deref(), a));
                let d = to_python(py, &frame)?.cast_into::<PyDict>()?;
                let stripe = match stripe {
                    Some(s) => Some(rows(py, &s.into_iter().map(<[f64; 5]>::from).collect::<Vec<_>>())?),
                    None => None,
                };
                let points = match points {
                    Some(p) => Some(rows(py, &p.into_iter().map(<[f64; 6]>::from).collect::<Vec<_>>())?),
                    None => None,
                };
                d.set_item("stripe", stripe)?;
                d.set_item("points", points)?;
                d.set_item("image_path", image_path)?;
                d.set_item("ambient_image_path", ambient_image_path)?;
                frames.append(d)?;
            }
            Record::Error(e) => errors.append(to_python(py, &e)?)?,
            Record::Status(s) => status = Some(to_python(py, &s)?),
        }
    }
    if status.is_none() && reader.cut_short() {
        let frames_read = frames.len() as u64;
        status = Some(to_python(py, &Status::cut_short(frames_read, reader.cut_short_message()))?);
    }
    let out = PyDict::new(py);
    out.set_item("header", header)?;
    out.set_item("frames", frames)?;
    out.set_item("errors", errors)?;
    out.set_item("status", status)?;
    Ok(out)
}

/// Reads a PLY point cloud (binary or ASCII; `-` = stdin) with the tools' reader. Returns a
/// dict: `xyz` an (n, 3) float64 array (mm), and one (n,) float32 array per scalar property,
/// under its name.
#[pyfunction]
pub fn read_ply<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let cloud = py.detach(|| omni_formats::ply::read_ply(&path)).map_err(crate::format_error)?;
    let out = PyDict::new(py);
    out.set_item("xyz", rows(py, &cloud.positions)?)?;
    for field in cloud.scalars {
        out.set_item(field.name, field.values.into_pyarray(py))?;
    }
    Ok(out)
}
