//! `omniscan.Camera`: camera.json (omni_formats::CameraFile) and its model's pixel ↔ ray maps.

use crate::arrays::{Vectors, shaped};
use numpy::PyArrayDyn;
use omni_formats::CameraFile;
use omni_geom::{Point3, Vector2};
use omni_model::CameraModel;
use pyo3::prelude::*;
use std::path::PathBuf;

/// A float64 numpy array of any shape.
type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// A receiver model loaded from camera.json (kinds hyperbolic, mei, ocam, pinhole, fisheye): maps
/// pixels to world rays and world points to pixels, exactly as the omniscan tools do.
#[pyclass(frozen, module = "omniscan")]
pub struct Camera {
    pub(crate) file: CameraFile,
    pub(crate) model: Box<dyn CameraModel>,
}

#[pymethods]
impl Camera {
    /// Reads and validates camera.json; errors name the file and the field.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let (file, model) = CameraFile::load(&path).map_err(crate::format_error)?;
        Ok(Camera { file, model })
    }

    /// Parses camera.json's text (`name` is used in error messages).
    #[staticmethod]
    #[pyo3(signature = (text, name = "camera.json"))]
    fn from_json(text: &str, name: &str) -> PyResult<Self> {
        let (file, model) = CameraFile::parse(text.as_bytes(), name).map_err(crate::format_error)?;
        Ok(Camera { file, model })
    }

    /// The document as JSON text (what camera.json holds).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.file).map_err(|e| crate::value_error(e.to_string()))
    }

    /// The model kind: "hyperbolic", "mei", "ocam", "pinhole" or "fisheye".
    #[getter]
    fn kind(&self) -> &'static str {
        self.file.model.kind()
    }

    /// Image (width, height) in pixels.
    #[getter]
    fn image_size(&self) -> (u32, u32) {
        self.model.image_size()
    }

    /// The lens's blur (PSF σ, px) the stripe detector removes from curved stripes: camera.json's
    /// `lens_blur_px` (measured by omni-calib-receiver on its boards' edges), else what its
    /// `optics` imply, else None (also for optics focused at a distance, `focus_mm`, whose blur
    /// varies over the image).
    #[getter]
    fn lens_blur_px(&self) -> Option<f64> {
        self.file.lens_blur()
    }

    /// The mirror annulus (centre x, centre y, inner radius, outer radius), all in pixels.
    #[getter]
    fn mirror_circle(&self) -> (f64, f64, f64, f64) {
        let c = self.model.mirror_circle();
        (c.centre.x, c.centre.y, c.inner_radius, c.outer_radius)
    }

    /// World rays of pixels: `pixels` has shape (..., 2) (u, v in px); returns (origins,
    /// directions), each of shape (..., 3): ray origins in mm (the single viewpoint) and unit
    /// directions, world frame. Rows are NaN where a pixel does not see the scene through the
    /// mirror (outside the annulus or the image).
    fn pixel_to_ray<'py>(&self, py: Python<'py>, pixels: &Bound<'py, PyAny>) -> PyResult<(Array<'py>, Array<'py>)> {
        let px = Vectors::<2>::extract(pixels, "pixels")?;
        let (origins, dirs) = py.detach(|| {
            let (mut origins, mut dirs) = (Vec::with_capacity(px.len() * 3), Vec::with_capacity(px.len() * 3));
            for i in 0..px.len() {
                let [u, v] = px.get(i);
                match self.model.pixel_to_ray(&Vector2::new(u, v)) {
                    Some(ray) => {
                        origins.extend_from_slice(ray.origin.coords.as_slice());
                        dirs.extend_from_slice(ray.dir.as_slice());
                    }
                    None => {
                        origins.extend_from_slice(&[f64::NAN; 3]);
                        dirs.extend_from_slice(&[f64::NAN; 3]);
                    }
                }
            }
            (origins, dirs)
        });
        Ok((shaped(py, origins, &px.lead_shape, 3)?, shaped(py, dirs, &px.lead_shape, 3)?))
    }

    /// Pixels (u, v) of world points: `points` has shape (..., 3) (mm, world frame); returns
    /// shape (..., 2), NaN where a point is not visible through the mirror.
    fn point_to_pixel<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let pts = Vectors::<3>::extract(points, "points")?;
        let pixels = py.detach(|| {
            let mut out = Vec::with_capacity(pts.len() * 2);
            for i in 0..pts.len() {
                match self.model.point_to_pixel(&Point3::from(pts.get(i))) {
                    Some(px) => out.extend_from_slice(&[px.x, px.y]),
                    None => out.extend_from_slice(&[f64::NAN; 2]),
                }
            }
            out
        });
        shaped(py, pixels, &pts.lead_shape, 2)
    }

    fn __repr__(&self) -> String {
        let (w, h) = self.model.image_size();
        format!("Camera(kind={:?}, image_size=({w}, {h}))", self.kind())
    }
}
