//! The Kannala–Brandt fisheye camera: OpenCV's `cv::fisheye` model (distortion k1..k4 on the
//! angle θ off the axis) and Kalibr's `pinhole-equi`.
//!
//! J. Kannala and S. S. Brandt, "A Generic Camera Model and Calibration Method for Conventional,
//! Wide-Angle, and Fish-Eye Lenses", PAMI 2006 (its radially symmetric part).
//!
//! Convention in the omniscan world frame (as [`crate::pinhole`]): the image centre looks
//! straight **down** (−z); a world direction d = (x, y, z) is the OpenCV camera-frame direction
//! (x, y, −z). θ = atan2(√(x² + y²), −z), θ_d = θ·(1 + k1·θ² + k2·θ⁴ + k3·θ⁶ + k4·θ⁸),
//! a' = θ_d·x/√(x² + y²), b' = θ_d·y/√(x² + y²), u = fx·a' + cx, v = fy·b' + cy: OpenCV's numbers
//! for every direction in front of the camera (OpenCV computes θ = atan(r) of the normalised
//! point, which is the same for −z > 0). This model also images directions beyond 90° if the
//! polynomial stays increasing there.
//!
//! The model's domain: θ from 0 up to the first turning point of θ_d(θ), at most 180°
//! ([`kb_max_theta`]); unprojection solves θ_d(θ) = ρ there (bracketed Newton), so it is the
//! exact inverse of the projection.

use crate::camera::{CentralCamera, CentralParams};
use omni_geom::{Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Parameters of the Kannala–Brandt model (what `camera.json` stores for kind `fisheye`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FisheyeParams {
    /// Focal lengths (px).
    pub fx_px: f64,
    pub fy_px: f64,
    /// Principal point (px).
    pub cx_px: f64,
    pub cy_px: f64,
    /// Coefficients of θ³, θ⁵, θ⁷, θ⁹ in θ_d (OpenCV's D = k1..k4).
    #[serde(default)]
    pub k1: f64,
    #[serde(default)]
    pub k2: f64,
    #[serde(default)]
    pub k3: f64,
    #[serde(default)]
    pub k4: f64,
    pub width: u32,
    pub height: u32,
    /// Single viewpoint (mm, world frame) where all rays start.
    #[serde(default)]
    pub viewpoint_mm: [f64; 3],
}

impl FisheyeParams {
    /// Number of intrinsic parameters in [`FisheyeParams::to_vector`].
    pub const N: usize = 8;

    /// Intrinsics as a vector: fx, fy, cx, cy, k1, k2, k3, k4.
    pub fn to_vector(&self) -> [f64; 8] {
        [self.fx_px, self.fy_px, self.cx_px, self.cy_px, self.k1, self.k2, self.k3, self.k4]
    }

    /// A camera of `width` × `height` px with the intrinsics `v` in [`FisheyeParams::to_vector`]
    /// order and its viewpoint at the origin.
    pub fn from_vector(v: &[f64], width: u32, height: u32) -> FisheyeParams {
        FisheyeParams {
            fx_px: v[0],
            fy_px: v[1],
            cx_px: v[2],
            cy_px: v[3],
            k1: v[4],
            k2: v[5],
            k3: v[6],
            k4: v[7],
            width,
            height,
            viewpoint_mm: [0.0; 3],
        }
    }

    /// Checks that the parameters are finite and meaningful; names the field at fault.
    pub fn validate(&self) -> Result<(), String> {
        crate::fields::check_positive(&[("fx_px", self.fx_px), ("fy_px", self.fy_px)])?;
        crate::fields::check_finite(&[
            ("cx_px", self.cx_px),
            ("cy_px", self.cy_px),
            ("k1", self.k1),
            ("k2", self.k2),
            ("k3", self.k3),
            ("k4", self.k4),
            ("viewpoint_mm[0]", self.viewpoint_mm[0]),
            ("viewpoint_mm[1]", self.viewpoint_mm[1]),
            ("viewpoint_mm[2]", self.viewpoint_mm[2]),
        ])?;
        crate::limits::check_image_size(self.width, self.height)
    }
}

fn theta_d(p: &[f64], t: f64) -> f64 {
    let t2 = t * t;
    t * (1.0 + t2 * (p[4] + t2 * (p[5] + t2 * (p[6] + t2 * p[7]))))
}

/// dθ_d/dθ's coefficients in θ, lowest degree first.
fn theta_d_slope_coefficients(p: &[f64]) -> [f64; 9] {
    [1.0, 0.0, 3.0 * p[4], 0.0, 5.0 * p[5], 0.0, 7.0 * p[6], 0.0, 9.0 * p[7]]
}

fn theta_d_slope(p: &[f64], t: f64) -> f64 {
    omni_geom::poly::eval(&theta_d_slope_coefficients(p), t)
}

/// The model's domain: the largest θ (rad) up to which θ_d(θ) increases, at most π.
/// `v` in [`FisheyeParams::to_vector`] order.
pub fn kb_max_theta(v: &[f64]) -> f64 {
    let pi = std::f64::consts::PI;
    omni_geom::poly::first_non_positive(&theta_d_slope_coefficients(v), 0.0, pi).unwrap_or(pi)
}

/// The intrinsics with the domain appended ([`FisheyeParams::to_vector`], then
/// [`kb_max_theta`]): what [`kb_project`] and [`kb_unproject`] take.
pub fn kb_intrinsics(v: &[f64]) -> Vec<f64> {
    let mut p = v[..FisheyeParams::N].to_vec();
    p.push(kb_max_theta(v));
    p
}

/// Pixel of a world direction (from the viewpoint, any length) with intrinsics `p`
/// ([`kb_intrinsics`]); `None` beyond the model's domain.
pub fn kb_project(p: &[f64], d: &Vector3<f64>) -> Option<Vector2<f64>> {
    let lateral = d.x.hypot(d.y);
    if !(lateral > 0.0 || d.z < 0.0) {
        return None;
    }
    let t = lateral.atan2(-d.z);
    if t > p[8] || t >= std::f64::consts::PI {
        return None;
    }
    let (ca, sa) = if lateral > 0.0 { (d.x / lateral, d.y / lateral) } else { (0.0, 0.0) };
    let td = theta_d(p, t);
    Some(Vector2::new(p[0] * td * ca + p[2], p[1] * td * sa + p[3]))
}

/// Unit world direction of a pixel with intrinsics `p` ([`kb_intrinsics`]); `None` beyond the
/// image of the model's domain.
pub fn kb_unproject(p: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>> {
    let (a, b) = ((px.x - p[2]) / p[0], (px.y - p[3]) / p[1]);
    let rho = a.hypot(b);
    if !rho.is_finite() {
        return None;
    }
    if rho == 0.0 {
        return Some(Vector3::new(0.0, 0.0, -1.0));
    }
    let (mut lo, mut hi) = (0.0, p[8]);
    if theta_d(p, hi) < rho {
        return None;
    }
    // θ_d is increasing on [lo, hi]: Newton steps kept inside the bracket, else bisection.
    let mut t = rho.min(hi);
    for _ in 0..100 {
        let g = theta_d(p, t) - rho;
        if g > 0.0 {
            hi = t;
        } else {
            lo = t;
        }
        let step = g / theta_d_slope(p, t);
        if step.is_finite() && step.abs() < 1e-15 * (1.0 + t) {
            break;
        }
        let next = t - step;
        t = if step.is_finite() && next > lo && next < hi { next } else { 0.5 * (lo + hi) };
        if hi - lo < 1e-15 {
            break;
        }
    }
    let s = t.sin();
    Some(Vector3::new(s * a / rho, s * b / rho, -t.cos()))
}

/// The Kannala–Brandt camera, ready to use.
pub type FisheyeCamera = CentralCamera<FisheyeParams>;

impl CentralParams for FisheyeParams {
    fn check(&self) -> Result<(), String> {
        self.validate()
    }
    fn to_intrinsics(&self) -> Vec<f64> {
        kb_intrinsics(&self.to_vector())
    }
    fn size_px(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    fn viewpoint(&self) -> Point3<f64> {
        Point3::from(Vector3::from(self.viewpoint_mm))
    }
    fn annulus_px(&self) -> ([f64; 2], f64, f64) {
        ([self.cx_px, self.cy_px], 0.0, 0.0)
    }
    fn direction_of(&self, intrinsics: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>> {
        kb_unproject(intrinsics, px)
    }
    fn pixel_of(&self, intrinsics: &[f64], dir: &Vector3<f64>) -> Option<Vector2<f64>> {
        kb_project(intrinsics, dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CameraModel;
    use proptest::prelude::*;

    fn sample() -> FisheyeParams {
        FisheyeParams {
            fx_px: 520.0,
            fy_px: 519.0,
            cx_px: 641.0,
            cy_px: 362.0,
            k1: -0.02,
            k2: 0.01,
            k3: -0.004,
            k4: 0.0005,
            width: 1280,
            height: 720,
            viewpoint_mm: [0.0; 3],
        }
    }

    #[test]
    fn matches_opencv_formula_and_looks_down() {
        let cam = FisheyeCamera::new(sample()).unwrap();
        let centre = cam.pixel_to_ray(&Vector2::new(641.0, 362.0)).unwrap();
        assert!((centre.dir.z + 1.0).abs() < 1e-15, "{:?}", centre.dir);
        // OpenCV: x = X/Z, r = |x|, θ = atan(r), θ_d, then x·θ_d/r; by hand for (0.3, −0.2, 1).
        let (a, b): (f64, f64) = (0.3, -0.2);
        let r = a.hypot(b);
        let t = r.atan();
        let td = t * (1.0 - 0.02 * t.powi(2) + 0.01 * t.powi(4) - 0.004 * t.powi(6) + 0.0005 * t.powi(8));
        let (u, v) = (520.0 * a * td / r + 641.0, 519.0 * b * td / r + 362.0);
        let px = cam.point_to_pixel(&Point3::new(a, b, -1.0)).unwrap();
        assert!((px - Vector2::new(u, v)).norm() < 1e-9, "{px} vs {u} {v}");
    }

    #[test]
    fn the_domain_ends_where_theta_d_turns_back() {
        let mut v = sample().to_vector();
        v[4] = -0.3;
        let t = kb_max_theta(&v);
        assert!(theta_d(&v, t - 1e-6) < theta_d(&v, t) && theta_d(&v, t + 1e-3) < theta_d(&v, t), "{t}");
        let p = kb_intrinsics(&v);
        let dir = |t: f64| Vector3::new(t.sin(), 0.0, -t.cos());
        assert!(kb_project(&p, &dir(t * 1.01)).is_none());
        let edge = kb_project(&p, &dir(t * 0.999)).unwrap();
        assert!(kb_unproject(&p, &Vector2::new(edge.x + 20.0, edge.y)).is_none());
        assert!(kb_unproject(&p, &Vector2::new(edge.x - 1.0, edge.y)).is_some());
        // Increasing all the way: 180°.
        assert_eq!(kb_max_theta(&sample().to_vector()), std::f64::consts::PI);
    }

    proptest! {
        #[test]
        fn project_unproject_round_trips(
            fx in 200.0..900.0f64, aspect in 0.98..1.02f64, cx in 500.0..780.0f64, cy in 300.0..420.0f64,
            k1 in -0.1..0.1f64, k2 in -0.05..0.05f64, k3 in -0.02..0.02f64, k4 in -0.005..0.005f64,
            frac in 0.0..0.98f64, phi in 0.0..std::f64::consts::TAU, fa in -1.0..1.0f64, fb in -1.0..1.0f64,
        ) {
            let p = FisheyeParams { fx_px: fx, fy_px: fx * aspect, cx_px: cx, cy_px: cy, k1, k2, k3, k4,
                width: 1280, height: 720, viewpoint_mm: [0.0; 3] };
            let v = p.to_vector();
            let q = kb_intrinsics(&v);
            let t = frac * q[8];
            let d = Vector3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), -t.cos());
            let px = kb_project(&q, &d).unwrap();
            let back = kb_unproject(&q, &px);
            prop_assert!(back.is_some(), "{px}: no ray");
            prop_assert!((back.unwrap() - d).norm() < 1e-10, "{px}: {:?} vs {d}", back);
            // Pixels → rays → pixels over the image.
            let cam = FisheyeCamera::new(p).unwrap();
            let px = Vector2::new(cx + 600.0 * fa, cy + 340.0 * fb);
            if let Some(ray) = cam.pixel_to_ray(&px) {
                let again = cam.point_to_pixel(&ray.at(500.0)).unwrap();
                prop_assert!((again - px).norm() < 1e-8, "{px} -> {again}");
            }
        }
    }
}
