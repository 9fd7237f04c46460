//! The error budget of one stripe point: what speckle, photon and read noise, and calibration
//! each leave in its range, for a matte wall facing the sensor at a given distance.
//!
//! The rule: every term is a stripe-centre uncertainty in pixels across the stripe, turned into
//! millimetres normal to the wall by the sensor's own geometry (how far the triangulated point
//! moves across the wall when the pixel moves by one across the stripe: the error a fit to the
//! wall or a comparison with its truth measures); terms add in quadrature. The point moves
//! within its light plane, not along its ray, so its range changes less than its distance from
//! the wall does.
//! * Speckle: Dorsch's limit C·λN/π for a resolved line; a line whose geometric image (width
//!   σ_g) is narrower than the speckle cannot move by more than about its width, so the two
//!   combine harmonically: C / √((π/λN)² + 1/(κσ_g)²).
//! * Photon and read noise: the centroid of a profile of width σ_w holding S e⁻ across the stripe
//!   over a background B per pixel: σ² = σ_w²/S + (B + σ_r² + Δ²/12)·W³/(12 S²), W = 6σ_w + 1 px.
//! * Calibration: the mean prediction error of a least-squares fit, rms·√(parameters /
//!   observations), for the camera (px) and the light planes (mm along the plane normal).

use crate::render::RenderOptions;
use crate::sensor::Sensor;
use omni_geom::{Point3, Vector2, Vector3, intersect_ray_plane};
use omni_model::{LightPlane, Optics};
use serde::Serialize;

/// The narrow-line factor κ of the speckle term: a line of geometric width σ_g moves by about
/// κσ_g under speckle. Fitted to the renderer (whose speckle matches Dorsch for resolved lines)
/// on the bench plane at 500 mm: 0.052 / 0.054 / 0.066 px at F/2.8 / F/4 / F/8 for σ_g =
/// 0.083 px give κ = 1.08–1.16.
const NARROW_LINE_KAPPA: f64 = 1.1;

/// Calibration uncertainties from the calibration reports.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct CalibrationUncertainty {
    /// The camera's ray error as a pixel error (px), if known.
    pub camera_px: Option<f64>,
    /// The light planes' position error along their normal (mm), if known.
    pub planes_mm: Option<f64>,
}

/// One range of the budget (σ, mm unless named).
#[derive(Debug, Clone, Serialize)]
pub struct BudgetLine {
    /// Horizontal distance of the wall from the camera axis (mm).
    pub range_mm: f64,
    /// The point's distance from the viewpoint (mm).
    pub distance_mm: f64,
    /// How far the point moves normal to the wall per pixel across the stripe (mm/px).
    pub mm_per_px: f64,
    /// The laser line's geometric width in the image (σ, px).
    pub line_sigma_px: f64,
    pub speckle_px: f64,
    pub noise_px: f64,
    pub speckle_mm: f64,
    pub noise_mm: f64,
    pub calibration_mm: Option<f64>,
    pub total_mm: f64,
}

/// The budget at each wall distance `ranges_mm`, for laser 0 at mirror angle `alpha_rad` on
/// facet 0, rendered with `opts` (its optics, or `optics` for the speckle term) on a wall of
/// albedo `albedo`. Ranges where the light plane misses the wall or the camera does not see
/// the point are left out.
pub fn error_budget(
    sensor: &Sensor,
    optics: &Optics,
    opts: &RenderOptions,
    calibration: &CalibrationUncertainty,
    albedo: f64,
    alpha_rad: f64,
    ranges_mm: &[f64],
) -> Vec<BudgetLine> {
    let Some(lp) = sensor.transmitter.light_plane(alpha_rad, 0, 0) else { return vec![] };
    ranges_mm.iter().filter_map(|&r| budget_at(sensor, optics, opts, calibration, albedo, &lp, r)).collect()
}

fn budget_at(
    sensor: &Sensor,
    optics: &Optics,
    opts: &RenderOptions,
    calibration: &CalibrationUncertainty,
    albedo: f64,
    lp: &LightPlane,
    range: f64,
) -> Option<BudgetLine> {
    let cam = sensor.camera.as_ref();
    let n = lp.plane.normal.into_inner();
    // The wall x = range; the point on it in the light plane at y = 0.
    if n.z.abs() < 1e-9 {
        return None;
    }
    let z = (lp.plane.offset - n.x * range) / n.z;
    let point = Point3::new(range, 0.0, z);
    let pixel = cam.point_to_pixel(&point)?;
    // The stripe on the wall runs along n × x; across it in the image is its perpendicular.
    let along = n.cross(&Vector3::x()).normalize();
    let tangent = (cam.point_to_pixel(&(point + along))? - pixel).normalize();
    let across = Vector2::new(-tangent.y, tangent.x);
    let on_plane = |p: Vector2<f64>| -> Option<(Point3<f64>, Point3<f64>)> {
        let ray = cam.pixel_to_ray(&p)?;
        let hit = intersect_ray_plane(&ray, &lp.plane, 1e-9).ok()?;
        Some((hit.point, ray.origin))
    };
    let on_wall = |p: Vector2<f64>| -> Option<Point3<f64>> {
        let ray = cam.pixel_to_ray(&p)?;
        let t = (range - ray.origin.x) / ray.dir.x;
        (t > 0.0).then(|| ray.origin + ray.dir.into_inner() * t)
    };
    let (h0, origin) = on_plane(pixel - across * 0.5)?;
    let (h1, _) = on_plane(pixel + across * 0.5)?;
    // The wall's normal is x.
    let mm_per_px = (h1.x - h0.x).abs();
    let distance = (point - origin).norm();
    // How fast the distance to the light plane changes across the stripe on the wall (mm/px).
    let (w0, w1) = (on_wall(pixel - across * 0.5)?, on_wall(pixel + across * 0.5)?);
    let plane_mm_per_px = (lp.plane.signed_distance(&w1) - lp.plane.signed_distance(&w0)).abs().max(1e-12);
    let line_sigma_px = opts.beam_sigma() / plane_mm_per_px;
    let speckle_px = speckle_sigma_px(optics, line_sigma_px);
    // Photometry as the renderer's: the stripe's signal summed across it, at one pixel along it.
    let to_p = point - lp.virtual_source;
    let cos_inc = (to_p.normalize().dot(&Vector3::x())).abs();
    let signal = albedo * opts.laser_strength * cos_inc / (std::f64::consts::PI * to_p.norm()) / plane_mm_per_px;
    let background = albedo * opts.ambient_e;
    let blur = opts.imaging.psf_sigma_at(cam, &pixel, distance);
    let width = (blur.powi(2) + 1.0 / 12.0 + line_sigma_px.powi(2)).sqrt();
    let noise_px = centroid_noise_px(signal, background, width, opts);
    let calibration_mm = calibration_range_mm(calibration, mm_per_px, &n, &(point - origin));
    let (speckle_mm, noise_mm) = (speckle_px * mm_per_px, noise_px * mm_per_px);
    let total_mm = (speckle_mm.powi(2) + noise_mm.powi(2) + calibration_mm.unwrap_or(0.0).powi(2)).sqrt();
    Some(BudgetLine {
        range_mm: range,
        distance_mm: distance,
        mm_per_px,
        line_sigma_px,
        speckle_px,
        noise_px,
        speckle_mm,
        noise_mm,
        calibration_mm,
        total_mm,
    })
}

/// The speckle term (px) for a line of geometric width `line_sigma_px`.
pub fn speckle_sigma_px(optics: &Optics, line_sigma_px: f64) -> f64 {
    let resolved = std::f64::consts::PI / optics.lambda_n_px();
    let narrow = 1.0 / (NARROW_LINE_KAPPA * line_sigma_px).max(1e-9);
    optics.speckle_contrast() / (resolved * resolved + narrow * narrow).sqrt()
}

/// Photon, read and quantisation noise of the intensity centroid (px) of a profile of width
/// `width_px` holding `signal` e⁻ over `background` e⁻ per pixel.
fn centroid_noise_px(signal: f64, background: f64, width_px: f64, opts: &RenderOptions) -> f64 {
    if !(signal > 0.0) {
        return f64::INFINITY;
    }
    let levels = if opts.bit_depth == 8 { 255.0 } else { 65535.0 };
    let step = opts.full_well_e / levels;
    let window = 6.0 * width_px + 1.0;
    let per_pixel = background + opts.read_noise_e.powi(2) + step * step / 12.0;
    (width_px * width_px / signal + per_pixel * window.powi(3) / (12.0 * signal * signal)).sqrt()
}

/// The calibration's share (mm normal to the wall): the camera's pixel error through the
/// geometry, and the light plane's offset through the viewing ray.
fn calibration_range_mm(
    c: &CalibrationUncertainty,
    mm_per_px: f64,
    plane_normal: &Vector3<f64>,
    view: &Vector3<f64>,
) -> Option<f64> {
    if c.camera_px.is_none() && c.planes_mm.is_none() {
        return None;
    }
    let camera = c.camera_px.unwrap_or(0.0) * mm_per_px;
    // A plane's offset moves the point along its ray, by offset / cos(normal, ray); normal to
    // the wall (x) by that times the ray's x component.
    let view = view.normalize();
    let cos = (plane_normal.dot(&view)).abs().max(1e-6);
    let planes = c.planes_mm.unwrap_or(0.0) / cos * view.x.abs();
    Some(camera.hypot(planes))
}

/// The calibration uncertainties that `camera.json`'s and `scanner.json`'s reports imply (the
/// reports of `omni-calib-receiver` and `omni-calib-plane`), where they have them.
pub fn calibration_from_reports(
    camera_report: Option<&serde_json::Value>,
    scanner_report: Option<&serde_json::Value>,
) -> CalibrationUncertainty {
    let camera_px = camera_report.and_then(|r| {
        let rms = r.get("rms_px")?.as_f64()?;
        let images = r.get("images")?.as_array()?;
        let used: Vec<&serde_json::Value> =
            images.iter().filter(|i| i.get("used").and_then(|u| u.as_bool()).unwrap_or(false)).collect();
        let corners: f64 = used.iter().filter_map(|i| i.get("corners")?.as_f64()).sum();
        let params = r.get("parameters")?.as_object()?.len() as f64 + 6.0 * used.len() as f64;
        (corners > 0.0).then(|| rms * (params / (2.0 * corners)).sqrt())
    });
    let planes_mm = scanner_report.and_then(|r| {
        let model = r.get("model")?;
        let rms = model.get("residual_rms_mm")?.as_f64()?;
        let points = model.get("points_used")?.as_f64()?;
        let params = model.get("parameters")?.as_array()?.len() as f64;
        (points > 0.0).then(|| rms * (params / points).sqrt())
    });
    CalibrationUncertainty { camera_px, planes_mm }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_bench_budget_is_dominated_by_speckle_and_grows_with_range() {
        let sensor = Sensor::paper();
        let opts = RenderOptions::default();
        let optics = Optics::paper();
        let ranges = [300.0, 500.0, 1000.0, 2000.0];
        let lines = error_budget(&sensor, &optics, &opts, &Default::default(), 0.8, 20f64.to_radians(), &ranges);
        assert_eq!(lines.len(), 4);
        for w in lines.windows(2) {
            assert!(w[1].total_mm > w[0].total_mm, "{:?}", lines);
        }
        let at500 = &lines[1];
        assert!(at500.speckle_mm > at500.noise_mm, "{at500:?}");
        // Speckle can never exceed Dorsch's limit for a resolved line.
        assert!(at500.speckle_px < optics.dorsch_sigma_px());
        assert!(at500.calibration_mm.is_none());
    }
}
