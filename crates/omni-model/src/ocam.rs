//! Scaramuzza's polynomial omnidirectional camera model (OCamCalib).
//!
//! D. Scaramuzza, A. Martinelli, R. Siegwart, "A Toolbox for Easily Calibrating Omnidirectional
//! Cameras", IROS 2006. Parameters: the polynomial f(ρ) = a0 + a1·ρ + a2·ρ² + … (OCamCalib
//! keeps a1 = 0), the distortion centre, and the affine matrix [c d; e 1].
//!
//! Convention in the omniscan world frame: OCamCalib works in (row, column) order; here the
//! centre is stored as `cx_px` (column, x right) and `cy_px` (row, y down), 0-based (the
//! `calib_results.txt` import/export adds or removes Matlab's +1). The affine relation keeps
//! OCamCalib's meaning: (row − cy, col − cx) = [c d; e 1]·(v′, u′), where (u′, v′) are the
//! ideal sensor coordinates along x and y. The world direction of a pixel is
//! (u′, v′, f(ρ)), ρ = √(u′² + v′²): with a0 < 0 the image centre looks straight down (−z),
//! as for [`crate::HyperbolicCamera`]. Projection solves f(ρ)/ρ = z/√(x² + y²) for ρ exactly
//! (bracketed Newton), so it is the true inverse; the inverse polynomial ρ(θ) that OCamCalib
//! stores is only used for import/export ([`OcamParams::fit_inverse_poly`]), fitted over the
//! valid radii only ([`OcamParams::valid_rho_range`]).

use crate::camera::{CentralCamera, CentralParams};
/// Evaluates Σ c_k·x^k (the polynomials' coefficients, lowest degree first).
pub use omni_geom::poly::eval as poly_eval;
use omni_geom::{Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Parameters of the polynomial model (what `camera.json` stores for kind `ocam`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcamParams {
    /// f(ρ) coefficients a0, a1, a2, … (ρ in px; a0 < 0).
    pub poly: Vec<f64>,
    /// Inverse polynomial ρ(θ) (θ = elevation of the direction above the sensor plane, rad),
    /// as OCamCalib's `invpol`; informative, may be empty.
    #[serde(default)]
    pub inv_poly: Vec<f64>,
    /// Distortion centre, column (px).
    pub cx_px: f64,
    /// Distortion centre, row (px).
    pub cy_px: f64,
    /// Affine coefficients [c d; e 1] (OCamCalib meaning, see the module docs).
    pub c: f64,
    pub d: f64,
    pub e: f64,
    pub width: u32,
    pub height: u32,
    /// Radius (px) around the centre below which the camera sees itself; 0 = none.
    #[serde(default)]
    pub inner_radius_px: f64,
    /// Radius (px) of the mirror rim; 0 = the whole image.
    #[serde(default)]
    pub outer_radius_px: f64,
    /// Single viewpoint (mm, world frame) where all rays start.
    #[serde(default)]
    pub viewpoint_mm: [f64; 3],
}

impl OcamParams {
    /// Checks that the parameters are finite and meaningful; names the field at fault.
    pub fn validate(&self) -> Result<(), String> {
        match self.poly.first() {
            None => return Err("poly: no coefficients (a0 first, negative)".to_string()),
            Some(&a0) if !(a0 < 0.0) => return Err(format!("poly[0] (a0) must be negative, got {a0}")),
            Some(_) => {}
        }
        for (k, v) in self.poly.iter().enumerate() {
            if !v.is_finite() {
                return Err(format!("poly[{k}] must be finite, got {v}"));
            }
        }
        for (k, v) in self.inv_poly.iter().enumerate() {
            if !v.is_finite() {
                return Err(format!("inv_poly[{k}] must be finite, got {v}"));
            }
        }
        crate::fields::check_finite(&[
            ("cx_px", self.cx_px),
            ("cy_px", self.cy_px),
            ("c", self.c),
            ("d", self.d),
            ("e", self.e),
            ("inner_radius_px", self.inner_radius_px),
            ("outer_radius_px", self.outer_radius_px),
        ])?;
        if (self.c - self.d * self.e).abs() < 1e-9 {
            return Err("affine matrix [c d; e 1] is singular".into());
        }
        crate::limits::check_image_size(self.width, self.height)?;
        Ok(())
    }

    /// Largest ρ (px) the model is used at: the rim radius, else the image half-diagonal.
    pub fn max_rho(&self) -> f64 {
        if self.outer_radius_px > 0.0 {
            self.outer_radius_px * 1.05
        } else {
            (self.width as f64).hypot(self.height as f64)
        }
    }

    /// Radii ρ (px, about the centre) over which the model is used: the mirror annulus, else
    /// out to the image edge nearest the centre (a mirror camera's rim lies inside the image;
    /// beyond it the fitted polynomial is unconstrained).
    pub fn valid_rho_range(&self) -> [f64; 2] {
        let inner = self.inner_radius_px.max(0.0);
        if self.outer_radius_px > 0.0 {
            return [inner, self.outer_radius_px];
        }
        // Pixel edges are at −0.5 and size − 0.5 (as `CameraModel::in_image`).
        let (w, h) = (self.width as f64 - 0.5, self.height as f64 - 0.5);
        let edge = (self.cx_px + 0.5).min(w - self.cx_px).min(self.cy_px + 0.5).min(h - self.cy_px);
        [inner, edge.max(inner + 1.0)]
    }

    /// Fits OCamCalib's inverse polynomial ρ(θ) over [`OcamParams::valid_rho_range`], raising
    /// the degree from 4 until the worst radial error is at most `tolerance_px` (or
    /// `max_degree` is reached); keeps the best fit and says how good it is.
    pub fn fit_inverse_poly(&mut self, tolerance_px: f64, max_degree: usize) -> InverseFit {
        let rho_range_px = self.valid_rho_range();
        let [lo, hi] = rho_range_px;
        // θ = elevation of the direction above the sensor plane, as OCamCalib's world2cam.
        let samples: Vec<(f64, f64)> = (0..=INVERSE_SAMPLES)
            .map(|k| {
                let rho = lo + (hi - lo) * k as f64 / INVERSE_SAMPLES as f64;
                (poly_eval(&self.poly, rho).atan2(rho), rho)
            })
            .collect();
        let mut best = InverseFit { degree: 0, max_error_px: f64::INFINITY, rho_range_px };
        for degree in 4..=max_degree.max(4) {
            let Some(coeffs) = least_squares_poly(&samples, degree) else { continue };
            let worst = samples.iter().map(|(t, r)| (poly_eval(&coeffs, *t) - r).abs()).fold(0.0, f64::max);
            if worst < best.max_error_px {
                best = InverseFit { degree, max_error_px: worst, rho_range_px };
                self.inv_poly = coeffs;
            }
            if worst <= tolerance_px {
                break;
            }
        }
        best
    }

    /// The worst radial error (px) of the stored inverse polynomial against the forward model
    /// over [`OcamParams::valid_rho_range`]; infinite if there is none.
    pub fn inverse_poly_error_px(&self) -> f64 {
        if self.inv_poly.is_empty() {
            return f64::INFINITY;
        }
        let [lo, hi] = self.valid_rho_range();
        (0..=INVERSE_SAMPLES)
            .map(|k| {
                let rho = lo + (hi - lo) * k as f64 / INVERSE_SAMPLES as f64;
                (poly_eval(&self.inv_poly, poly_eval(&self.poly, rho).atan2(rho)) - rho).abs()
            })
            .fold(0.0, f64::max)
    }
}

/// Radii sampled (plus one) when fitting and checking the inverse polynomial.
const INVERSE_SAMPLES: usize = 2000;

/// The worst error OCamCalib's inverse polynomial may have over the valid radii (px).
pub const INVERSE_TOLERANCE_PX: f64 = 0.01;

/// Highest degree tried for the inverse polynomial.
pub const INVERSE_MAX_DEGREE: usize = 24;

/// How well the inverse polynomial ρ(θ) matches the forward model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseFit {
    pub degree: usize,
    /// Worst |ρ_inv(θ(ρ)) − ρ| over the sampled radii (px).
    pub max_error_px: f64,
    /// The radii fitted (px, about the centre).
    pub rho_range_px: [f64; 2],
}

/// Least-squares coefficients c_0 … c_degree of ρ ≈ Σ c_k·θ^k (columns scaled for conditioning).
fn least_squares_poly(samples: &[(f64, f64)], degree: usize) -> Option<Vec<f64>> {
    let n = degree + 1;
    let scale = samples.iter().map(|s| s.0.abs()).fold(0.0, f64::max).max(1e-12);
    let a = nalgebra::DMatrix::from_fn(samples.len(), n, |r, k| (samples[r].0 / scale).powi(k as i32));
    let b = nalgebra::DVector::from_iterator(samples.len(), samples.iter().map(|s| s.1));
    let x = a.svd(true, true).solve(&b, 1e-14).ok()?;
    let coeffs: Vec<f64> = x.iter().enumerate().map(|(k, c)| c / scale.powi(k as i32)).collect();
    coeffs.iter().all(|c| c.is_finite()).then_some(coeffs)
}

fn poly_derivative(c: &[f64], x: f64) -> f64 {
    c.iter().enumerate().skip(1).rev().fold(0.0, |acc, (k, &v)| acc * x + k as f64 * v)
}

/// Intrinsics vector for calibration: cx, cy, c, d, e, then the polynomial coefficients.
pub fn ocam_vector(p: &OcamParams) -> Vec<f64> {
    let mut v = vec![p.cx_px, p.cy_px, p.c, p.d, p.e];
    v.extend_from_slice(&p.poly);
    v
}

/// Unit world direction of a pixel with intrinsics `v` ([`ocam_vector`] order).
pub fn ocam_unproject(v: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>> {
    let (cx, cy, c, d, e) = (v[0], v[1], v[2], v[3], v[4]);
    let (row, col) = (px.y - cy, px.x - cx);
    let det = c - d * e;
    // (row, col) = [c d; e 1]·(v′, u′)  ⇒  (v′, u′) = [1 −d; −e c]·(row, col) / det.
    let vp = (row - d * col) / det;
    let up = (-e * row + c * col) / det;
    let rho = up.hypot(vp);
    let z = poly_eval(&v[5..], rho);
    Vector3::new(up, vp, z).try_normalize(1e-300)
}

/// Projects a world direction with intrinsics `v` ([`ocam_vector`] order), solving
/// f(ρ)/ρ = z/√(x² + y²) for ρ in (0, `rho_max`].
pub fn ocam_project(v: &[f64], dir: &Vector3<f64>, rho_max: f64) -> Option<Vector2<f64>> {
    let (cx, cy, c, d, e) = (v[0], v[1], v[2], v[3], v[4]);
    let poly = &v[5..];
    let norm = dir.x.hypot(dir.y);
    let (up, vp) = if norm < 1e-12 * dir.z.abs() {
        if dir.z >= 0.0 || poly[0] >= 0.0 {
            return None;
        }
        (0.0, 0.0)
    } else {
        // g(ρ) = ρ·z − norm·f(ρ); at ρ = 0 it is −norm·a0 > 0.
        let g = |rho: f64| rho * dir.z - norm * poly_eval(poly, rho);
        let dg = |rho: f64| dir.z - norm * poly_derivative(poly, rho);
        // The first sign change of g on a coarse scan brackets the smallest root (the one seen).
        const SCAN: usize = 64;
        let (mut lo, mut hi) = (0.0, f64::NAN);
        for k in 1..=SCAN {
            let rho = rho_max * k as f64 / SCAN as f64;
            if g(rho) <= 0.0 {
                hi = rho;
                break;
            }
            lo = rho;
        }
        if hi.is_nan() {
            return None; // direction beyond the rim
        }
        let mut rho = 0.5 * (lo + hi);
        for _ in 0..100 {
            let gv = g(rho);
            if gv > 0.0 {
                lo = rho;
            } else {
                hi = rho;
            }
            let step = gv / dg(rho);
            if step.is_finite() && step.abs() < 1e-13 * (1.0 + rho) {
                break; // converged: rho is the root to rounding
            }
            let next = rho - step;
            rho = if step.is_finite() && next > lo && next < hi { next } else { 0.5 * (lo + hi) };
            if hi - lo < 1e-13 * (1.0 + rho) {
                break;
            }
        }
        (rho * dir.x / norm, rho * dir.y / norm)
    };
    let row = c * vp + d * up + cy;
    let col = e * vp + up + cx;
    Some(Vector2::new(col, row))
}

/// The polynomial camera, ready to use.
pub type OcamCamera = CentralCamera<OcamParams>;

impl CentralParams for OcamParams {
    fn check(&self) -> Result<(), String> {
        self.validate()
    }
    fn to_intrinsics(&self) -> Vec<f64> {
        ocam_vector(self)
    }
    fn size_px(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    fn viewpoint(&self) -> Point3<f64> {
        Point3::from(Vector3::from(self.viewpoint_mm))
    }
    fn annulus_px(&self) -> ([f64; 2], f64, f64) {
        ([self.cx_px, self.cy_px], self.inner_radius_px, self.outer_radius_px)
    }
    fn direction_of(&self, intrinsics: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>> {
        ocam_unproject(intrinsics, px)
    }
    fn pixel_of(&self, intrinsics: &[f64], dir: &Vector3<f64>) -> Option<Vector2<f64>> {
        ocam_project(intrinsics, dir, self.max_rho())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CameraModel;

    fn sample() -> OcamParams {
        // Coefficients of the size OCamCalib finds for a 752 × 480 mirror camera.
        OcamParams {
            poly: vec![-209.0, 0.0, 1.8e-3, -1.0e-6, 1.0e-9],
            inv_poly: vec![],
            cx_px: 375.0,
            cy_px: 240.0,
            c: 1.001,
            d: 2e-3,
            e: -1e-3,
            width: 752,
            height: 480,
            inner_radius_px: 20.0,
            outer_radius_px: 0.0,
            viewpoint_mm: [0.0; 3],
        }
    }

    #[test]
    fn round_trips_and_centre_looks_down() {
        let cam = OcamCamera::new(sample()).unwrap();
        let down = cam.pixel_to_ray(&Vector2::new(375.0 + 21.0, 240.0)).unwrap();
        assert!(down.dir.z < -0.99, "{:?}", down.dir);
        // x right in the image is +x in the world.
        assert!(down.dir.x > 0.0);
        for &(x, y) in &[(100.0, 100.0), (500.0, 300.0), (375.0, 100.0), (650.0, 420.0)] {
            let px = Vector2::new(x, y);
            let ray = cam.pixel_to_ray(&px).unwrap();
            let back = cam.point_to_pixel(&ray.at(500.0)).unwrap();
            assert!((back - px).norm() < 1e-8, "{px} -> {back}");
        }
    }

    #[test]
    fn inverse_polynomial_fits_to_a_hundredth_of_a_pixel() {
        let mut p = sample();
        p.outer_radius_px = 240.0;
        let fit = p.fit_inverse_poly(INVERSE_TOLERANCE_PX, INVERSE_MAX_DEGREE);
        assert!(fit.max_error_px <= 0.01, "{fit:?}");
        assert_eq!(fit.rho_range_px, [20.0, 240.0]);
        // Checked independently of the fit: round trips through world2cam's form.
        assert!(p.inverse_poly_error_px() <= 0.01);
    }
}
