//! The simulated sensor: a camera model plus the transmitter.

use omni_formats::{CameraFile, ScannerFile};
use omni_model::{CameraModel, HyperbolicCamera, HyperbolicParams, Optics, Transmitter, TransmitterParams};
use std::path::Path;

/// The sensor being simulated: the receiver (any [`CameraModel`]) and the transmitter.
#[derive(Debug)]
pub struct Sensor {
    pub camera: Box<dyn CameraModel>,
    pub transmitter: Transmitter,
}

impl Sensor {
    /// The paper's prototype with our choice of lens and polygon ([`HyperbolicParams::paper`]:
    /// 1024 × 1024 px, f = 1950 px, mirror rim 25 mm; [`TransmitterParams::paper`]: 12 facets,
    /// R = 20 mm, polygon axis 120 mm below the camera centre).
    pub fn paper() -> Sensor {
        Sensor::from_params(HyperbolicParams::paper(), TransmitterParams::paper()).expect("paper preset is valid")
    }

    /// The paper's sensor with a `width` × `width` image: focal length and principal point are
    /// scaled by `width / 1024`, so the same scene fills the image the same way (for fast tests).
    pub fn paper_scaled(width: u32) -> Sensor {
        Sensor::from_params(paper_camera_scaled(width), TransmitterParams::paper()).expect("scaled preset is valid")
    }

    /// A sensor from model parameters; the error names the invalid field.
    pub fn from_params(camera: HyperbolicParams, transmitter: TransmitterParams) -> Result<Sensor, String> {
        Ok(Sensor { camera: Box::new(HyperbolicCamera::new(camera)?), transmitter: Transmitter::new(transmitter)? })
    }

    /// Reads `camera.json` and `scanner.json`.
    pub fn load(camera: &Path, scanner: &Path) -> omni_formats::Result<Sensor> {
        Ok(Sensor::load_with_optics(camera, scanner)?.0)
    }

    /// Reads `camera.json` and `scanner.json`, with the optics camera.json states, if any.
    pub fn load_with_optics(camera: &Path, scanner: &Path) -> omni_formats::Result<(Sensor, Option<Optics>)> {
        let (file, camera) = CameraFile::load(camera)?;
        let (_, transmitter) = ScannerFile::load_polygon(scanner)?;
        Ok((Sensor { camera, transmitter }, file.optics))
    }
}

/// [`HyperbolicParams::paper`] scaled to a `width` × `width` image (focal length and principal
/// point scale by `width / 1024`; the principal point stays at the image centre).
pub fn paper_camera_scaled(width: u32) -> HyperbolicParams {
    let mut p = HyperbolicParams::paper();
    let s = width as f64 / p.width as f64;
    p.fx_px *= s;
    p.fy_px *= s;
    p.cx_px = (width as f64 - 1.0) / 2.0;
    p.cy_px = (width as f64 - 1.0) / 2.0;
    p.width = width;
    p.height = width;
    p
}
