//! `omniscan.Scanner` (scanner.json, the transmitter model), its light planes, and
//! `omniscan.triangulate` (omni_cloud's triangulator on numpy pixels).

use crate::arrays::{Vectors, rows, shaped};
use crate::camera::Camera;
use numpy::{IntoPyArray, PyArrayDyn};
use omni_cloud::triangulate::{DEFAULT_MIN_INCIDENCE_DEG, Triangulator};
use omni_formats::ScannerFile;
use omni_formats::stream::{Frame, StripePoint};
use omni_model::{LightPlane, Transmitter, TransmitterModel};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// The transmitter model loaded from scanner.json: the polygon mirror and the line lasers, or
/// fixed light planes (`kind` "fixed_planes").
#[pyclass(frozen, module = "omniscan")]
pub struct Scanner {
    file: ScannerFile,
    model: TransmitterModel,
}

/// A light plane as the Python API gives it: the polygon's (with its facet and fan), or a
/// fixed plane (normal, offset).
enum PlaneAt {
    Polygon(LightPlane),
    Fixed(omni_geom::Plane),
}

impl PlaneAt {
    fn plane(&self) -> omni_geom::Plane {
        match self {
            PlaneAt::Polygon(lp) => lp.plane,
            PlaneAt::Fixed(p) => *p,
        }
    }
}

impl Scanner {
    /// The polygon transmitter, or a ValueError naming the kind for `what`.
    fn polygon(&self, what: &str) -> PyResult<&Transmitter> {
        self.model.polygon().ok_or_else(|| {
            crate::value_error(format!("{what}: transmitter kind \"{}\" has no polygon mirror", self.model.kind()))
        })
    }

    /// The light plane of laser `laser` when laser 0 faces `facet` at mirror angle
    /// `alpha_deg` (degrees), after the same checks as the triangulator's. A fixed plane does
    /// not depend on the angle or facet.
    fn plane_at(&self, alpha_deg: f64, facet: u32, laser: usize) -> PyResult<PlaneAt> {
        let model = match &self.model {
            TransmitterModel::Polygon(t) => t,
            TransmitterModel::FixedPlanes(f) => {
                return u32::try_from(laser).ok().and_then(|l| f.plane(l)).map(PlaneAt::Fixed).ok_or_else(|| {
                    crate::value_error(format!(
                        "laser {laser} has no plane in the scanner model (lasers {:?})",
                        f.lasers()
                    ))
                });
            }
        };
        let alpha = alpha_deg.to_radians();
        model.check_frame(alpha, facet).map_err(crate::value_error)?;
        if laser >= model.num_lasers() {
            return Err(crate::value_error(format!(
                "laser {laser} is not in the scanner model ({} lasers)",
                model.num_lasers()
            )));
        }
        model.light_plane(alpha, facet, laser).map(PlaneAt::Polygon).ok_or_else(|| {
            crate::value_error(format!("laser {laser}: no light plane at alpha {alpha_deg}° facet {facet}"))
        })
    }

    fn num_lasers_any(&self) -> usize {
        match &self.model {
            TransmitterModel::Polygon(t) => t.num_lasers(),
            TransmitterModel::FixedPlanes(f) => f.lasers().len(),
        }
    }
}

#[pymethods]
impl Scanner {
    /// Reads and validates scanner.json; errors name the file and the field.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let (file, model) = ScannerFile::load(&path).map_err(crate::format_error)?;
        Ok(Scanner { file, model })
    }

    /// Parses scanner.json's text (`name` is used in error messages).
    #[staticmethod]
    #[pyo3(signature = (text, name = "scanner.json"))]
    fn from_json(text: &str, name: &str) -> PyResult<Self> {
        let (file, model) = ScannerFile::parse(text.as_bytes(), name).map_err(crate::format_error)?;
        Ok(Scanner { file, model })
    }

    /// The document as JSON text (what scanner.json holds).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.file).map_err(|e| crate::value_error(e.to_string()))
    }

    /// The transmitter's kind: "polygon" or "fixed_planes".
    #[getter]
    fn kind(&self) -> &'static str {
        self.model.kind()
    }

    /// The polygon's facets (a ValueError for fixed planes).
    #[getter]
    fn num_facets(&self) -> PyResult<u32> {
        Ok(self.polygon("num_facets")?.num_facets())
    }

    #[getter]
    fn num_lasers(&self) -> usize {
        self.num_lasers_any()
    }

    /// The scan range of one facet, α ∈ [0, facet_angle_deg) (degrees; a ValueError for fixed
    /// planes).
    #[getter]
    fn facet_angle_deg(&self) -> PyResult<f64> {
        Ok(self.polygon("facet_angle_deg")?.facet_angle().to_degrees())
    }

    /// The light plane of `laser` when laser 0 faces `facet` at mirror angle `alpha_deg`
    /// (degrees), as a dict (mm, world frame): `normal` (unit, z ≥ 0) and `offset` of the plane
    /// normal·x = offset; the reflecting facet's plane (`facet_normal`, `facet_offset`, outward);
    /// `virtual_source` (the laser apex mirrored in the facet), `facet_point` and `out_dir` (the
    /// central ray's hit on the facet and its reflected direction), `on_facet`. For fixed planes
    /// (`kind` "fixed_planes") the dict holds `normal` and `offset` only, whatever the angle.
    #[pyo3(signature = (alpha_deg, facet = 0, laser = 0))]
    fn light_plane<'py>(
        &self,
        py: Python<'py>,
        alpha_deg: f64,
        facet: i64,
        laser: i64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let at = self.plane_at(alpha_deg, crate::index_arg("facet", facet)?, crate::index_arg("laser", laser)?)?;
        let d = PyDict::new(py);
        let vec3 = |v: &[f64]| v.to_vec().into_pyarray(py);
        let plane = at.plane();
        d.set_item("normal", vec3(plane.normal.as_slice()))?;
        d.set_item("offset", plane.offset)?;
        let PlaneAt::Polygon(lp) = at else { return Ok(d) };
        d.set_item("facet_normal", vec3(lp.facet.normal.as_slice()))?;
        d.set_item("facet_offset", lp.facet.offset)?;
        d.set_item("virtual_source", vec3(lp.virtual_source.coords.as_slice()))?;
        d.set_item("facet_point", vec3(lp.facet_point.coords.as_slice()))?;
        d.set_item("out_dir", vec3(lp.out_dir.as_slice()))?;
        d.set_item("on_facet", lp.on_facet)?;
        Ok(d)
    }

    /// The light planes of `laser` at many mirror angles: `alpha_deg` of any shape (degrees);
    /// returns shape (..., 4): (nx, ny, nz, offset) of normal·x = offset (mm, world frame).
    #[pyo3(signature = (alpha_deg, facet = 0, laser = 0))]
    fn light_planes<'py>(
        &self,
        py: Python<'py>,
        alpha_deg: &Bound<'py, PyAny>,
        facet: i64,
        laser: i64,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let (facet, laser): (u32, usize) = (crate::index_arg("facet", facet)?, crate::index_arg("laser", laser)?);
        let np = py.import("numpy")?;
        let angles = np.call_method1("asarray", (alpha_deg, "float64"))?.call_method1("reshape", ((-1, 1),))?;
        let lead_shape: Vec<usize> = np.call_method1("shape", (alpha_deg,))?.extract()?;
        let angles = Vectors::<1>::extract(&angles, "alpha_deg")?;
        let mut out = Vec::with_capacity(angles.len() * 4);
        for i in 0..angles.len() {
            let plane = self.plane_at(angles.get(i)[0], facet, laser)?.plane();
            out.extend_from_slice(plane.normal.as_slice());
            out.push(plane.offset);
        }
        shaped(py, out, &lead_shape, 4)
    }

    fn __repr__(&self) -> String {
        match &self.model {
            TransmitterModel::Polygon(t) => {
                format!("Scanner(num_facets={}, num_lasers={})", t.num_facets(), t.num_lasers())
            }
            TransmitterModel::FixedPlanes(f) => format!("Scanner(kind=\"fixed_planes\", lasers={:?})", f.lasers()),
        }
    }
}

/// Triangulates stripe pixels of one frame, as omni-triangulate does: each pixel's ray meets
/// the light plane of every laser in `lasers` at mirror angle `alpha_deg` (degrees) with laser
/// 0 facing `facet` (a fixed-plane scanner ignores `alpha_deg` and `facet`); grazing (below `min_incidence_deg`) and unlit intersections are refused.
/// `pixels` has shape (n, 2). Returns a dict: `xyz` (m, 3) mm world frame, `laser` (m,),
/// `range` (m,) mm from the viewpoint, `index` (m,) the row of `pixels` each point came from, and
/// `rejected` (counts: no_ray, grazing, unlit, ambiguous).
#[pyfunction]
#[pyo3(signature = (camera, scanner, pixels, alpha_deg, facet = 0, lasers = vec![0, 1], min_incidence_deg = DEFAULT_MIN_INCIDENCE_DEG))]
pub fn triangulate<'py>(
    py: Python<'py>,
    camera: &Camera,
    scanner: &Scanner,
    pixels: &Bound<'py, PyAny>,
    alpha_deg: f64,
    facet: i64,
    lasers: Vec<i64>,
    min_incidence_deg: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let facet: u32 = crate::index_arg("facet", facet)?;
    let lasers = lasers.into_iter().map(|l| crate::index_arg("lasers", l)).collect::<PyResult<Vec<u32>>>()?;
    let px = Vectors::<2>::extract(pixels, "pixels")?;
    if px.lead_shape.len() != 1 {
        return Err(crate::value_error(format!("pixels: expected shape (n, 2), got {:?} + (2,)", px.lead_shape)));
    }
    if let Some(i) = (0..px.len()).find(|&i| px.get(i).iter().any(|c| !c.is_finite())) {
        return Err(crate::value_error(format!("pixels[{i}]: not a finite number")));
    }
    let triangulator =
        Triangulator::new(camera.model.as_ref(), &scanner.model, min_incidence_deg).map_err(crate::value_error)?;
    let mut frame = Frame::new(0, "", alpha_deg, facet);
    frame.lasers = lasers;
    frame.stripe = Some(
        (0..px.len())
            .map(|i| {
                let [u, v] = px.get(i);
                StripePoint { u, v, intensity: 0.0, width: 0.0, quality: 0 }
            })
            .collect(),
    );
    let result = py.detach(|| triangulator.triangulate_frame(&frame)).map_err(crate::value_error)?;
    let d = PyDict::new(py);
    let xyz: Vec<[f64; 3]> = result.points.iter().map(|p| p.xyz).collect();
    d.set_item("xyz", rows(py, &xyz)?)?;
    d.set_item("laser", result.points.iter().map(|p| p.laser).collect::<Vec<_>>().into_pyarray(py))?;
    d.set_item("range", result.points.iter().map(|p| p.range).collect::<Vec<_>>().into_pyarray(py))?;
    d.set_item("index", result.points.iter().map(|p| p.stripe_index as i64).collect::<Vec<_>>().into_pyarray(py))?;
    let r = result.rejections;
    let rejected = PyDict::new(py);
    rejected.set_item("no_ray", r.no_ray)?;
    rejected.set_item("grazing", r.grazing)?;
    rejected.set_item("unlit", r.unlit)?;
    rejected.set_item("ambiguous", r.ambiguous)?;
    d.set_item("rejected", rejected)?;
    Ok(d)
}
