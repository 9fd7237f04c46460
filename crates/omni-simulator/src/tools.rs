//! What the `omni-sim` tool builds on: sensor presets with imperfections, angle lists, scene
//! checks against a sensor, and the ground-truth record format.

use crate::profile::SheetProfile;
use crate::render::TruthPoint;
use crate::rng::SplitMix64;
use crate::scene::Scene;
use crate::sensor::{Sensor, paper_camera_scaled};
use omni_model::{FacetError, HyperbolicParams, TransmitterParams};
use serde::{Deserialize, Serialize};

/// Build imperfections applied to the ideal preset (all zero = the ideal sensor).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Imperfections {
    /// Camera centre relative to the mirror's lower focus (mm).
    pub camera_offset_mm: [f64; 3],
    /// Camera tilt about x then y (degrees).
    pub camera_tilt_deg: [f64; 2],
    /// Principal point shift from the image centre (px).
    pub principal_point_offset_px: [f64; 2],
    /// Standard deviation of each facet's pyramidal tilt and pitch error (degrees); each
    /// facet's radius error has σ = R · sin(σ_deg) (mm), the displacement such a tilt gives at
    /// the facet's edge.
    pub facet_sigma_deg: f64,
    /// Encoder zero offset (degrees).
    pub encoder_offset_deg: f64,
    /// Seed of the random facet errors.
    pub seed: u64,
}

/// The paper preset at `width` × `width` pixels with imperfections applied.
pub fn paper_preset(width: u32, imp: &Imperfections) -> Result<(HyperbolicParams, TransmitterParams), String> {
    let all = imp
        .camera_offset_mm
        .iter()
        .chain(&imp.camera_tilt_deg)
        .chain(&imp.principal_point_offset_px)
        .chain([&imp.facet_sigma_deg, &imp.encoder_offset_deg]);
    if !all.into_iter().all(|v| v.is_finite()) {
        return Err("imperfections must be finite numbers".into());
    }
    if imp.facet_sigma_deg < 0.0 {
        return Err(format!("facet error sigma must be non-negative, got {}", imp.facet_sigma_deg));
    }
    let mut cam = paper_camera_scaled(width);
    cam.camera_offset_mm = imp.camera_offset_mm;
    cam.camera_tilt_deg = imp.camera_tilt_deg;
    cam.cx_px += imp.principal_point_offset_px[0];
    cam.cy_px += imp.principal_point_offset_px[1];
    let mut tx = TransmitterParams::paper();
    tx.polygon.encoder_zero_deg = imp.encoder_offset_deg;
    if imp.facet_sigma_deg > 0.0 {
        let mut rng = SplitMix64::stream(imp.seed, 0xFACE7);
        let sigma_mm = tx.polygon.circumradius_mm * imp.facet_sigma_deg.to_radians().sin();
        tx.polygon.facet_errors = (0..tx.polygon.facets)
            .map(|_| FacetError {
                tilt_deg: imp.facet_sigma_deg * rng.normal(),
                pitch_deg: imp.facet_sigma_deg * rng.normal(),
                radius_mm: sigma_mm * rng.normal(),
            })
            .collect();
    }
    cam.validate()?;
    tx.validate()?;
    Ok((cam, tx))
}

/// Parses mirror angles (degrees): `start:stop:step` (stop excluded, like a range; a stop that is
/// reached within 1e-9 of a step is excluded too) or a comma-separated list.
pub fn parse_angles(spec: &str) -> Result<Vec<f64>, String> {
    let num = |s: &str| -> Result<f64, String> {
        let v: f64 = s.trim().parse().map_err(|_| format!("\"{}\" is not a number", s.trim()))?;
        if v.is_finite() { Ok(v) } else { Err(format!("\"{}\" is not a finite number", s.trim())) }
    };
    let parts: Vec<&str> = spec.split(':').collect();
    match parts.len() {
        1 => spec
            .split(',')
            .map(num)
            .collect::<Result<Vec<_>, _>>()
            .and_then(|v| if v.is_empty() { Err("no angles given".into()) } else { Ok(v) }),
        3 => {
            let (start, stop, step) = (num(parts[0])?, num(parts[1])?, num(parts[2])?);
            if !(step > 0.0) {
                return Err(format!("step must be positive, got {step}"));
            }
            let count = ((stop - start) / step - 1e-9).ceil();
            if !(count >= 1.0) {
                return Err(format!("{start}:{stop}:{step} gives no angles (stop must exceed start)"));
            }
            if count > 1e6 {
                return Err(format!("{start}:{stop}:{step} gives {count} angles (at most 1 000 000)"));
            }
            Ok((0..count as usize).map(|i| start + step * i as f64).collect())
        }
        _ => Err(format!("\"{spec}\": expected start:stop:step or a comma-separated list")),
    }
}

/// Checks that every checkerboard of the scene shows at least one inner corner to the camera;
/// the error names the object.
pub fn check_boards_visible(sensor: &Sensor, scene: &Scene) -> Result<(), String> {
    for (index, pose, corners) in scene.checkerboards() {
        let front = pose.transform_vector(&-omni_geom::Vector3::z());
        let visible = corners.iter().any(|c| {
            let p = pose * c;
            sensor
                .camera
                .point_to_pixel(&p)
                .and_then(|px| sensor.camera.pixel_to_ray(&px))
                .is_some_and(|ray| ray.dir.dot(&front) < 0.0)
        });
        if !visible {
            let name = scene.file().objects[index].name.as_deref().unwrap_or("");
            return Err(format!(
                "objects[{index}] (checkerboard \"{name}\"): the board never enters the camera's field of view"
            ));
        }
    }
    Ok(())
}

/// One line of a ground-truth file (JSON Lines; format `omniscan.sim-truth`): the true stripe
/// points of one frame as `[x, y, z, u, v, laser]` (mm, px), each on its light plane: the peak
/// of the sheet's profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthRecord {
    pub seq: u64,
    pub path: String,
    pub alpha_deg: f64,
    pub facet: u32,
    pub points: Vec<[f64; 6]>,
    /// The sheet's profile, when it is not the default Gaussian or its width was set in px.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<SheetProfile>,
    /// The sheet's FWHM (mm) of each laser on, in the frame's `lasers` order (with `profile`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sheet_fwhm_mm: Option<Vec<f64>>,
}

impl TruthRecord {
    pub fn new(seq: u64, path: &str, alpha_deg: f64, facet: u32, truth: &[TruthPoint]) -> Self {
        let points =
            truth.iter().map(|t| [t.xyz[0], t.xyz[1], t.xyz[2], t.pixel[0], t.pixel[1], t.laser as f64]).collect();
        TruthRecord { seq, path: path.into(), alpha_deg, facet, points, profile: None, sheet_fwhm_mm: None }
    }

    /// The record with the sheet's profile and widths.
    pub fn with_sheet(self, profile: SheetProfile, sheet_fwhm_mm: &[f64]) -> Self {
        TruthRecord { profile: Some(profile), sheet_fwhm_mm: Some(sheet_fwhm_mm.to_vec()), ..self }
    }
}

/// First line of a ground-truth file.
pub fn truth_header(scene: &str) -> serde_json::Value {
    serde_json::json!({"format": "omniscan.sim-truth", "version": 1, "scene": scene,
        "points": "[x_mm, y_mm, z_mm, u_px, v_px, laser]"})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_specs() {
        assert_eq!(parse_angles("0:2:0.5").unwrap(), vec![0.0, 0.5, 1.0, 1.5]);
        assert_eq!(parse_angles("1, 2.5,4").unwrap(), vec![1.0, 2.5, 4.0]);
        assert!(parse_angles("0:30:0").unwrap_err().contains("step"));
        assert!(parse_angles("5:1:1").unwrap_err().contains("no angles"));
        assert!(parse_angles("a,b").unwrap_err().contains("\"a\""));
        assert!(parse_angles("nan").is_err());
    }

    #[test]
    fn imperfections_land_in_the_parameters() {
        let imp = Imperfections { facet_sigma_deg: 0.05, encoder_offset_deg: 0.1, seed: 3, ..Default::default() };
        let (cam, tx) = paper_preset(512, &imp).unwrap();
        assert_eq!(cam.width, 512);
        assert_eq!(tx.polygon.facet_errors.len(), 12);
        assert_eq!(tx.polygon.encoder_zero_deg, 0.1);
        let rms = (tx.polygon.facet_errors.iter().map(|e| e.tilt_deg.powi(2)).sum::<f64>() / 12.0).sqrt();
        assert!(rms > 0.01 && rms < 0.15, "{rms}");
        assert_eq!(paper_preset(512, &imp).unwrap().1, tx, "same seed, same errors");
    }
}
