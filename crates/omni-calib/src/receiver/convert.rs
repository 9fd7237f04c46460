//! Conversion of a calibration into another model without a re-fit to board corners: the target
//! model is fitted (Levenberg–Marquardt, pixel residuals) to the source model's rays on a polar
//! grid of pixels over the source's mirror annulus, then both are compared on a finer grid.
//! A non-central source (a hyperbolic camera off the focus) gives its ray directions; a central
//! target keeps the source's viewpoint.

use super::{Model, Options};
use super::{ModelKind, Observation, describe, ocam_from_mei, ordinary_from_mei};
use nalgebra::{Vector2, Vector3};
use omni_formats::CameraSpec;
use omni_geom::lm;
use omni_model::{CameraModel, HyperbolicParams};

/// A converted camera and how far it is from the source over the annulus.
#[derive(Debug, Clone)]
pub struct Conversion {
    pub spec: CameraSpec,
    /// Largest angle between the source's and the target's ray of a pixel (deg).
    pub max_ray_deg: f64,
    /// Largest distance between the source's pixel of a ray and the target's (px).
    pub max_pixel_px: f64,
    /// Pixels compared.
    pub samples: usize,
}

/// Pixels of a polar grid over the source's annulus (`radii` × `angles`) that see a ray, with it.
fn sample_rays(cam: &dyn CameraModel, radii: usize, angles: usize) -> Vec<([f64; 2], Vector3<f64>)> {
    let circle = cam.mirror_circle();
    let (w, h) = cam.image_size();
    let outer = circle.outer_radius.min((w as f64).hypot(h as f64) / 2.0);
    let inner = circle.inner_radius;
    let mut out = Vec::new();
    for i in 0..radii {
        let r = inner + (outer - inner) * (i as f64 + 0.5) / radii as f64;
        for k in 0..angles {
            let a = std::f64::consts::TAU * (k as f64 + 0.37 * i as f64) / angles as f64;
            let px = Vector2::new(circle.centre.x + r * a.cos(), circle.centre.y + r * a.sin());
            if let Some(ray) = cam.pixel_to_ray(&px) {
                out.push(([px.x, px.y], ray.dir.into_inner()));
            }
        }
    }
    out
}

/// Pixel residuals of the target model against the sampled rays.
struct RayFit<'a> {
    model: &'a Model,
    samples: &'a [([f64; 2], Vector3<f64>)],
}

impl lm::Problem for RayFit<'_> {
    fn num_params(&self) -> usize {
        self.model.free.len()
    }
    fn num_residuals(&self) -> usize {
        2 * self.samples.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        let full = self.model.with_free(p);
        for (k, (px, d)) in self.samples.iter().enumerate() {
            let (dx, dy) = match self.model.project(&full, d) {
                Some(q) => (q.x - px[0], q.y - px[1]),
                None => (crate::pose::UNPROJECTABLE_PX, crate::pose::UNPROJECTABLE_PX),
            };
            out[2 * k] = dx;
            out[2 * k + 1] = dy;
        }
    }
}

fn fit(mut model: Model, samples: &[([f64; 2], Vector3<f64>)]) -> Model {
    let problem = RayFit { model: &model, samples };
    let opts = lm::Options { max_iterations: 200, ..Default::default() };
    let report = lm::minimize(&problem, &model.free_values(), &opts);
    model.full = model.with_free(&report.params);
    model
}

fn rms_px(model: &Model, samples: &[([f64; 2], Vector3<f64>)]) -> f64 {
    use lm::Problem as _;
    let problem = RayFit { model, samples };
    let mut r = vec![0.0; problem.num_residuals()];
    problem.residuals(&model.full, &mut r);
    super::rms(&r)
}

/// The Mei (or, with ξ fixed and no distortion, hyperbolic) model closest to the rays, from the
/// best focal length of a logarithmic grid.
fn fit_mei(centre: [f64; 2], scale_px: f64, xi: f64, fixed: bool, samples: &[([f64; 2], Vector3<f64>)]) -> Model {
    let start = (0..24)
        .map(|k| Model::mei(centre, xi, scale_px * 0.1 * 30f64.powf(k as f64 / 23.0), fixed))
        .min_by(|a, b| rms_px(a, samples).total_cmp(&rms_px(b, samples)))
        .expect("the grid is not empty");
    fit(start, samples)
}

/// Converts `source` into `target` (`mirror` gives a and b for the hyperbolic target); the
/// result keeps the source's size, annulus and viewpoint.
pub fn convert(source: &CameraSpec, target: ModelKind, mirror: &HyperbolicParams) -> Result<Conversion, String> {
    let cam = source.build().map_err(|e| e.to_string())?;
    let samples = sample_rays(cam.as_ref(), 24, 72);
    if samples.len() < 50 {
        return Err(format!("the source camera sees only {} of the sampled pixels", samples.len()));
    }
    let circle = cam.mirror_circle();
    let (width, height) = cam.image_size();
    let centre = [circle.centre.x, circle.centre.y];
    let outer = circle.outer_radius.min((width as f64).hypot(height as f64) / 2.0);
    let model = match target {
        ModelKind::Mei => fit_mei(centre, outer, 1.0, false, &samples),
        ModelKind::Hyperbolic => {
            let (a, b2) = (mirror.a_mm, mirror.b_mm * mirror.b_mm);
            let c = (a * a + b2).sqrt();
            fit_mei(centre, outer, 2.0 * a * c / (a * a + c * c), true, &samples)
        }
        ModelKind::Ocam => {
            let mei = fit_mei(centre, outer, 1.0, false, &samples);
            let pixels: Vec<[f64; 2]> = samples.iter().map(|s| s.0).collect();
            let obs = Observation { name: String::new(), board_mm: vec![[0.0; 2]; pixels.len()], pixels };
            let mut ocam = ocam_from_mei(&mei, &[obs], 4, width, height).ok_or("polynomial initialisation failed")?;
            // With the rays fixed, a turn of the image about the centre is no gauge: e is free.
            ocam.free = (0..ocam.full.len()).collect();
            fit(ocam, &samples)
        }
        ModelKind::Pinhole | ModelKind::PinholeRadtan | ModelKind::Fisheye => {
            let mei = fit_mei(centre, outer, 1.0, false, &samples);
            let pixels: Vec<[f64; 2]> = samples.iter().map(|s| s.0).collect();
            let obs = Observation { name: String::new(), board_mm: vec![[0.0; 2]; pixels.len()], pixels };
            let ordinary = ordinary_from_mei(&mei, &[obs], target).ok_or("pinhole/fisheye initialisation failed")?;
            fit(ordinary, &samples)
        }
    };
    let annulus = [centre[0], centre[1], circle.inner_radius, outer];
    let opts = Options { model: target, mirror: mirror.clone(), annulus: Some(annulus), ..Default::default() };
    let (_, _, _, mut spec) = describe(&model, &vec![f64::NAN; model.free.len()], width, height, &opts);
    keep_viewpoint(&mut spec, source);
    let (max_ray_deg, max_pixel_px, n) = compare(cam.as_ref(), &spec)?;
    Ok(Conversion { spec, max_ray_deg, max_pixel_px, samples: n })
}

/// A central target starts its rays where the source does.
fn keep_viewpoint(spec: &mut CameraSpec, source: &CameraSpec) {
    spec.set_viewpoint_mm(source.viewpoint_mm());
}

/// Largest ray angle (deg) and pixel distance (px) between two cameras over a grid finer than
/// the fit's, and the number of pixels compared.
pub fn compare(source: &dyn CameraModel, target: &CameraSpec) -> Result<(f64, f64, usize), String> {
    let other = target.build().map_err(|e| e.to_string())?;
    let (mut ray, mut pixel, mut n) = (0.0f64, 0.0f64, 0);
    for (px, d) in sample_rays(source, 61, 181) {
        let Some(r) = other.pixel_to_ray(&Vector2::new(px[0], px[1])) else { continue };
        ray = ray.max(r.dir.angle(&d).to_degrees());
        // The target's pixel of the source ray, seen from the target's own ray origin.
        let q = other.point_to_pixel(&(r.origin + 1e4 * d));
        let Some(q) = q else { continue };
        pixel = pixel.max((q - Vector2::new(px[0], px[1])).norm());
        n += 1;
    }
    if n == 0 {
        return Err("the converted camera sees none of the source's pixels".into());
    }
    Ok((ray, pixel, n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_model::{HyperbolicCamera, MeiParams};

    /// The exact hyperbolic camera is a Mei model (omni_model::mei docs): the conversion must
    /// find it, and convert back; the polynomial model approximates it.
    #[test]
    fn hyperbolic_mei_and_ocam_convert_into_each_other() {
        let h = HyperbolicParams::paper();
        let source = CameraSpec::Hyperbolic(h.clone());
        let mei = convert(&source, ModelKind::Mei, &h).unwrap();
        assert!(mei.max_ray_deg < 1e-4 && mei.max_pixel_px < 1e-3, "{mei:?}");
        // ξ and k1 trade off over the annulus (measured ξ 0.9979 for 0.9923 with k1 = 0.0028):
        // the rays, not the numbers, are compared.
        let CameraSpec::Mei(p) = &mei.spec else { panic!("{:?}", mei.spec) };
        assert_eq!(p.viewpoint_mm, MeiParams::from_hyperbolic(&h).viewpoint_mm);
        let back = convert(&mei.spec, ModelKind::Hyperbolic, &h).unwrap();
        assert!(back.max_ray_deg < 1e-4 && back.max_pixel_px < 1e-3, "{back:?}");
        let ocam = convert(&source, ModelKind::Ocam, &h).unwrap();
        eprintln!("hyperbolic → ocam: {:.5}° {:.5} px", ocam.max_ray_deg, ocam.max_pixel_px);
        assert!(ocam.max_ray_deg < 0.05 && ocam.max_pixel_px < 0.2, "{ocam:?}");
        // The comparison can fail: a camera 3 px off is reported as such.
        let mut moved = h.clone();
        moved.cx_px += 3.0;
        let cam = HyperbolicCamera::new(moved).unwrap();
        let (ray, pixel, _) = compare(&cam, &mei.spec).unwrap();
        assert!(pixel > 2.9 && ray > 0.1, "{ray}° {pixel} px");
    }

    /// The ordinary models convert into themselves exactly (the fit starts from a Mei fit of the
    /// rays), and a fisheye lens refuses to become a pinhole one at the image's corners.
    #[test]
    fn ordinary_models_convert_into_themselves() {
        let v = [725.95, 726.3, 673.5, 308.6, -0.0352, -0.0203, 0.0323, -0.0158];
        let fisheye = CameraSpec::Fisheye(omni_model::FisheyeParams::from_vector(&v, 1280, 720));
        let h = HyperbolicParams::paper();
        let same = convert(&fisheye, ModelKind::Fisheye, &h).unwrap();
        assert!(same.max_ray_deg < 1e-4 && same.max_pixel_px < 1e-3, "{same:?}");
        let v = [740.3, 740.9, 668.2, 313.6, -0.3275, 0.1156, -5.6e-4, 5.4e-4, -0.0192];
        let pinhole = CameraSpec::Pinhole(omni_model::PinholeParams::from_vector(&v, 1280, 720));
        let same = convert(&pinhole, ModelKind::Pinhole, &h).unwrap();
        assert!(same.max_ray_deg < 1e-3 && same.max_pixel_px < 1e-2, "{same:?}");
        let other = convert(&fisheye, ModelKind::Pinhole, &h).unwrap();
        eprintln!("fisheye → pinhole: {:.4}° {:.4} px", other.max_ray_deg, other.max_pixel_px);
        assert!(other.max_pixel_px > 1.0, "{other:?}");
    }
}
