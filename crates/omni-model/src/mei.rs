//! Mei's unified (sphere) camera model with radial-tangential distortion.
//!
//! C. Mei and P. Rives, "Single View Point Omnidirectional Camera Calibration from Planar
//! Grids", ICRA 2007. Also Kalibr's `omni-radtan` and OpenCV's `omnidir`. Parameters, in order:
//! ξ (xi), fx, fy, cx, cy (px), k1, k2 (radial), p1, p2 (tangential).
//!
//! Convention in the omniscan world frame (+z up towards the mirror, pixel x right, y down,
//! the image centre sees straight **down** from the viewpoint): a world direction d = (x, y, z)
//! (unit, from the viewpoint) becomes sphere coordinates x_s = x, y_s = y, z_s = −z, then
//! m = (x_s, y_s)/(ξ + z_s), distorted by radial-tangential distortion, then u = fx·m'_x + cx,
//! v = fy·m'_y + cy. With this convention the exact hyperbolic camera of SENSOR.md *is* a Mei
//! model with ξ = 2ac/(a² + c²), fx = fx_hyp·b²/(a² + c²) (same for y) and no distortion
//! ([`MeiParams::from_hyperbolic`]), so the rays of a fitted Mei model compare directly with
//! those of [`crate::HyperbolicCamera`].
//!
//! The model has no metric scale: rays start at `viewpoint_mm` (default the world origin; the
//! exact hyperbolic camera's viewpoint is F = (0, 0, 2c)).

use crate::camera::{CentralCamera, CentralParams};
use crate::hyperbolic::HyperbolicParams;
use omni_geom::{Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Parameters of the Mei model (what `camera.json` stores for kind `mei`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeiParams {
    /// Mirror parameter ξ (0 = pinhole, 1 = parabolic mirror + orthographic camera).
    pub xi: f64,
    /// Generalised focal lengths (px).
    pub fx_px: f64,
    pub fy_px: f64,
    /// Principal point (px).
    pub cx_px: f64,
    pub cy_px: f64,
    /// Radial distortion coefficients.
    #[serde(default)]
    pub k1: f64,
    #[serde(default)]
    pub k2: f64,
    /// Tangential distortion coefficients.
    #[serde(default)]
    pub p1: f64,
    #[serde(default)]
    pub p2: f64,
    pub width: u32,
    pub height: u32,
    /// Radius (px) around the principal point below which the camera sees itself; 0 = none.
    #[serde(default)]
    pub inner_radius_px: f64,
    /// Radius (px) of the mirror rim around the principal point; 0 = the whole image.
    #[serde(default)]
    pub outer_radius_px: f64,
    /// Single viewpoint (mm, world frame) where all rays start.
    #[serde(default)]
    pub viewpoint_mm: [f64; 3],
}

impl MeiParams {
    /// Number of intrinsic parameters in [`MeiParams::to_vector`].
    pub const N: usize = 9;

    /// The Mei model equal to an ideal hyperbolic camera (see the module docs).
    pub fn from_hyperbolic(h: &HyperbolicParams) -> MeiParams {
        let a = h.a_mm;
        let b2 = h.b_mm * h.b_mm;
        let c = (a * a + b2).sqrt();
        let s = a * a + c * c;
        let r_img = |r: f64| {
            let z = c + a * (1.0 + r * r / b2).sqrt();
            0.5 * (h.fx_px + h.fy_px) * r / z
        };
        MeiParams {
            xi: 2.0 * a * c / s,
            fx_px: h.fx_px * b2 / s,
            fy_px: h.fy_px * b2 / s,
            cx_px: h.cx_px,
            cy_px: h.cy_px,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            width: h.width,
            height: h.height,
            inner_radius_px: r_img(h.inner_radius_mm),
            outer_radius_px: r_img(h.rim_radius_mm),
            viewpoint_mm: [0.0, 0.0, 2.0 * c],
        }
    }

    /// Intrinsics as a vector: ξ, fx, fy, cx, cy, k1, k2, p1, p2.
    pub fn to_vector(&self) -> [f64; 9] {
        [self.xi, self.fx_px, self.fy_px, self.cx_px, self.cy_px, self.k1, self.k2, self.p1, self.p2]
    }

    /// A camera of `width` × `height` px with the intrinsics `v` in [`MeiParams::to_vector`]
    /// order, no annulus and its viewpoint at the origin.
    pub fn from_vector(v: &[f64], width: u32, height: u32) -> MeiParams {
        let mut p = MeiParams {
            xi: 0.0,
            fx_px: 0.0,
            fy_px: 0.0,
            cx_px: 0.0,
            cy_px: 0.0,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            width,
            height,
            inner_radius_px: 0.0,
            outer_radius_px: 0.0,
            viewpoint_mm: [0.0; 3],
        };
        p.set_vector(v);
        p
    }

    /// Sets the intrinsics from [`MeiParams::to_vector`] order.
    pub fn set_vector(&mut self, v: &[f64]) {
        [self.xi, self.fx_px, self.fy_px, self.cx_px, self.cy_px, self.k1, self.k2, self.p1, self.p2] =
            [v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]];
    }

    /// Checks that the parameters are finite and meaningful; names the field at fault.
    pub fn validate(&self) -> Result<(), String> {
        crate::fields::check_positive(&[("fx_px", self.fx_px), ("fy_px", self.fy_px)])?;
        if !(self.xi.is_finite() && (0.0..=MAX_XI).contains(&self.xi)) {
            return Err(format!("xi must be a number from 0 to {MAX_XI}, got {}", crate::limits::shown(self.xi)));
        }
        crate::fields::check_finite(&[
            ("cx_px", self.cx_px),
            ("cy_px", self.cy_px),
            ("k1", self.k1),
            ("k2", self.k2),
            ("p1", self.p1),
            ("p2", self.p2),
            ("inner_radius_px", self.inner_radius_px),
            ("outer_radius_px", self.outer_radius_px),
            ("viewpoint_mm[0]", self.viewpoint_mm[0]),
            ("viewpoint_mm[1]", self.viewpoint_mm[1]),
            ("viewpoint_mm[2]", self.viewpoint_mm[2]),
        ])?;
        crate::limits::check_image_size(self.width, self.height)?;
        if self.inner_radius_px < 0.0 || self.outer_radius_px < 0.0 {
            return Err("inner_radius_px and outer_radius_px must be non-negative".into());
        }
        Ok(())
    }
}

/// The largest ξ read: a mirror's is below 1, a wide fisheye fitted as Mei's a few; beyond this
/// the number is a mistake, not a lens.
pub const MAX_XI: f64 = 100.0;

/// Projects a world direction (from the viewpoint, any length) with intrinsics `p`
/// ([`MeiParams::to_vector`] order). `None` where the sphere point is not imaged (ξ + z_s ≤ 0).
pub fn mei_project(p: &[f64], d: &Vector3<f64>) -> Option<Vector2<f64>> {
    let n = d.norm();
    if !(n > 0.0) {
        return None;
    }
    let (xs, ys, zs) = (d.x / n, d.y / n, -d.z / n);
    let den = p[0] + zs;
    if den <= 1e-9 {
        return None;
    }
    let (mx, my) = (xs / den, ys / den);
    let (dx, dy) = distort(p, mx, my);
    Some(Vector2::new(p[1] * dx + p[3], p[2] * dy + p[4]))
}

fn distort(p: &[f64], mx: f64, my: f64) -> (f64, f64) {
    let (k1, k2, p1, p2) = (p[5], p[6], p[7], p[8]);
    let r2 = mx * mx + my * my;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
    (
        mx * radial + 2.0 * p1 * mx * my + p2 * (r2 + 2.0 * mx * mx),
        my * radial + p1 * (r2 + 2.0 * my * my) + 2.0 * p2 * mx * my,
    )
}

/// Unit world direction seen by a pixel with intrinsics `p`; `None` if undistortion fails or
/// the pixel lies outside the model's image of the sphere.
pub fn mei_unproject(p: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>> {
    let (tx, ty) = ((px.x - p[3]) / p[1], (px.y - p[4]) / p[2]);
    // Undistort by Newton's method on the 2×2 distortion map.
    let (mut mx, mut my) = (tx, ty);
    for _ in 0..50 {
        let (dx, dy) = distort(p, mx, my);
        let (ex, ey) = (dx - tx, dy - ty);
        if ex.abs() < 1e-14 && ey.abs() < 1e-14 {
            break;
        }
        let h = 1e-7;
        let (ax, ay) = distort(p, mx + h, my);
        let (bx, by) = distort(p, mx, my + h);
        let (j11, j21, j12, j22) = ((ax - dx) / h, (ay - dy) / h, (bx - dx) / h, (by - dy) / h);
        let det = j11 * j22 - j12 * j21;
        if det.abs() < 1e-12 {
            return None;
        }
        mx -= (j22 * ex - j12 * ey) / det;
        my -= (-j21 * ex + j11 * ey) / det;
    }
    let (dx, dy) = distort(p, mx, my);
    if (dx - tx).abs() > 1e-9 || (dy - ty).abs() > 1e-9 {
        return None;
    }
    let xi = p[0];
    let r2 = mx * mx + my * my;
    let disc = 1.0 + (1.0 - xi * xi) * r2;
    if disc < 0.0 {
        return None;
    }
    let factor = (xi + disc.sqrt()) / (1.0 + r2);
    let (xs, ys, zs) = (factor * mx, factor * my, factor - xi);
    if xi + zs <= 0.0 {
        return None;
    }
    Some(Vector3::new(xs, ys, -zs).normalize())
}

/// The Mei camera, ready to use.
pub type MeiCamera = CentralCamera<MeiParams>;

impl CentralParams for MeiParams {
    fn check(&self) -> Result<(), String> {
        self.validate()
    }
    fn to_intrinsics(&self) -> Vec<f64> {
        self.to_vector().to_vec()
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
        mei_unproject(intrinsics, px)
    }
    fn pixel_of(&self, intrinsics: &[f64], dir: &Vector3<f64>) -> Option<Vector2<f64>> {
        mei_project(intrinsics, dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CameraModel, HyperbolicCamera};

    #[test]
    fn xi_is_bounded() {
        let mut p = MeiParams::from_hyperbolic(&HyperbolicParams::paper());
        assert!(p.validate().is_ok());
        p.xi = 1e308;
        assert_eq!(p.validate().unwrap_err(), "xi must be a number from 0 to 100, got 1e308");
        p.xi = -0.5;
        assert!(p.validate().is_err());
    }

    #[test]
    fn hyperbolic_camera_is_a_mei_model() {
        let h = HyperbolicParams::paper();
        let hyp = HyperbolicCamera::new(h.clone()).unwrap();
        let mei = MeiCamera::new(MeiParams::from_hyperbolic(&h)).unwrap();
        assert!((mei.params().viewpoint_mm[2] - 80.0).abs() < 1e-9);
        let mut n = 0;
        for k in 0..200 {
            let a = k as f64 * 0.7;
            let r = 60.0 + 4.3 * k as f64 % 420.0;
            let px = Vector2::new(511.5 + r * a.cos(), 511.5 + r * a.sin());
            let (Some(rh), Some(rm)) = (hyp.pixel_to_ray(&px), mei.pixel_to_ray(&px)) else { continue };
            n += 1;
            assert!(rh.dir.dot(&rm.dir) > 1.0 - 1e-14, "{px}: {:?} vs {:?}", rh.dir, rm.dir);
            assert!((rh.origin - rm.origin).norm() < 1e-9);
            let back = mei.point_to_pixel(&rm.at(700.0)).unwrap();
            assert!((back - px).norm() < 1e-8, "{px} -> {back}");
        }
        assert!(n > 150, "{n}");
    }

    #[test]
    fn distorted_model_round_trips() {
        let p = MeiParams {
            xi: 0.9,
            fx_px: 300.0,
            fy_px: 305.0,
            cx_px: 380.0,
            cy_px: 240.0,
            k1: -0.2,
            k2: 0.05,
            p1: 1e-3,
            p2: -2e-3,
            width: 752,
            height: 480,
            inner_radius_px: 30.0,
            outer_radius_px: 0.0,
            viewpoint_mm: [0.0; 3],
        };
        let cam = MeiCamera::new(p).unwrap();
        for &(x, y) in &[(100.0, 100.0), (500.0, 300.0), (380.0, 100.0), (650.0, 420.0)] {
            let px = Vector2::new(x, y);
            let ray = cam.pixel_to_ray(&px).unwrap();
            assert!(ray.dir.z < 0.5, "{:?}", ray.dir);
            let back = cam.point_to_pixel(&ray.at(500.0)).unwrap();
            assert!((back - px).norm() < 1e-8, "{px} -> {back}");
        }
        // The blind centre sees nothing.
        assert!(cam.pixel_to_ray(&Vector2::new(385.0, 240.0)).is_none());
    }
}
