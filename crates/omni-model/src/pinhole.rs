//! The pinhole camera with radial-tangential distortion: OpenCV's `calibrateCamera` model
//! (distortion k1 k2 p1 p2 k3) and Kalibr's `pinhole-radtan` (k3 = 0).
//!
//! Convention in the omniscan world frame (as [`crate::mei`]): the image centre looks straight
//! **down** (−z), pixel x right, y down. A world direction d = (x, y, z) from the viewpoint is the
//! OpenCV camera-frame direction (x, y, −z); it is in front of the camera when z < 0. Then
//! a = x/(−z), b = y/(−z), r² = a² + b²,
//! a' = a·(1 + k1·r² + k2·r⁴ + k3·r⁶) + 2·p1·a·b + p2·(r² + 2a²),
//! b' = b·(1 + k1·r² + k2·r⁴ + k3·r⁶) + p1·(r² + 2b²) + 2·p2·a·b,
//! u = fx·a' + cx, v = fy·b' + cy: the same numbers as OpenCV's.
//!
//! The model's domain: a disc about the axis inside which the distortion is one-to-one, ending
//! before the radial map r ↦ r·(1 + k1·r² + k2·r⁴ + k3·r⁶) turns back (where a fitted
//! polynomial folds back into the image) and before the tangential terms can fold it; beyond it
//! neither projection nor unprojection is defined ([`radtan_max_radius`]). Unprojection
//! inverts the distortion by damped Newton iterations on the 2 × 2 map, started from the
//! distorted point, and accepts only a solution inside the domain that reproduces the pixel.

use crate::camera::{CentralCamera, CentralParams};
use omni_geom::{Point3, Vector2, Vector3, poly};
use serde::{Deserialize, Serialize};

/// Parameters of the radial-tangential pinhole model (what `camera.json` stores for kind
/// `pinhole`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PinholeParams {
    /// Focal lengths (px).
    pub fx_px: f64,
    pub fy_px: f64,
    /// Principal point (px).
    pub cx_px: f64,
    pub cy_px: f64,
    /// Radial distortion coefficients (OpenCV's k1, k2, k3).
    #[serde(default)]
    pub k1: f64,
    #[serde(default)]
    pub k2: f64,
    #[serde(default)]
    pub k3: f64,
    /// Tangential distortion coefficients (OpenCV's p1, p2).
    #[serde(default)]
    pub p1: f64,
    #[serde(default)]
    pub p2: f64,
    pub width: u32,
    pub height: u32,
    /// Single viewpoint (mm, world frame) where all rays start.
    #[serde(default)]
    pub viewpoint_mm: [f64; 3],
}

impl PinholeParams {
    /// Number of intrinsic parameters in [`PinholeParams::to_vector`].
    pub const N: usize = 9;

    /// Intrinsics as a vector: fx, fy, cx, cy, k1, k2, p1, p2, k3 (OpenCV's order of the
    /// distortion coefficients).
    pub fn to_vector(&self) -> [f64; 9] {
        [self.fx_px, self.fy_px, self.cx_px, self.cy_px, self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    /// A camera of `width` × `height` px with the intrinsics `v` in [`PinholeParams::to_vector`]
    /// order and its viewpoint at the origin.
    pub fn from_vector(v: &[f64], width: u32, height: u32) -> PinholeParams {
        PinholeParams {
            fx_px: v[0],
            fy_px: v[1],
            cx_px: v[2],
            cy_px: v[3],
            k1: v[4],
            k2: v[5],
            p1: v[6],
            p2: v[7],
            k3: v[8],
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
            ("p1", self.p1),
            ("p2", self.p2),
            ("viewpoint_mm[0]", self.viewpoint_mm[0]),
            ("viewpoint_mm[1]", self.viewpoint_mm[1]),
            ("viewpoint_mm[2]", self.viewpoint_mm[2]),
        ])?;
        crate::limits::check_image_size(self.width, self.height)
    }
}

/// Largest undistorted radius r = √(a² + b²) considered (r = 100 is 89.4° off the axis).
const MAX_RADIUS: f64 = 100.0;

/// The model's domain: the largest undistorted radius r (at most 100) inside which the
/// distortion is one-to-one, the least of the radial map's two local scales ρ = 1 + k1·r² +
/// k2·r⁴ + k3·r⁶ (across the radius) and ρ + 2r²·dρ/d(r²) = 1 + 3k1·r² + 5k2·r⁴ + 7k3·r⁶ (along
/// it) staying above 6·√(p1² + p2²)·r. Both Jacobians are symmetric: the radial one has those
/// two eigenvalues, the tangential one eigenvalues of at most 6·√(p1² + p2²)·r in magnitude, so
/// inside that disc (F(x) − F(y))·(x − y) > 0 for any two points and no pixel has two rays.
/// `v` in [`PinholeParams::to_vector`] order.
pub fn radtan_max_radius(v: &[f64]) -> f64 {
    let tangential = 6.0 * v[6].hypot(v[7]);
    let mut across = [1.0, 0.0, v[4], 0.0, v[5], 0.0, v[8]];
    let mut along = radial_slope_coefficients(v);
    (across[1], along[1]) = (-tangential, -tangential);
    [across, along].iter().filter_map(|c| poly::first_non_positive(c, 0.0, MAX_RADIUS)).fold(MAX_RADIUS, f64::min)
}

/// The radial map's slope d(r·ρ)/dr = 1 + 3k1·r² + 5k2·r⁴ + 7k3·r⁶: its coefficients in r,
/// lowest degree first (`v` in [`PinholeParams::to_vector`] order).
fn radial_slope_coefficients(v: &[f64]) -> [f64; 7] {
    [1.0, 0.0, 3.0 * v[4], 0.0, 5.0 * v[5], 0.0, 7.0 * v[8]]
}

/// The intrinsics with the domain appended ([`PinholeParams::to_vector`], then
/// [`radtan_max_radius`]): what [`radtan_project`] and [`radtan_unproject`] take.
pub fn radtan_intrinsics(v: &[f64]) -> Vec<f64> {
    let mut p = v[..PinholeParams::N].to_vec();
    p.push(radtan_max_radius(v));
    p
}

fn distort(p: &[f64], a: f64, b: f64) -> (f64, f64) {
    let (k1, k2, p1, p2, k3) = (p[4], p[5], p[6], p[7], p[8]);
    let r2 = a * a + b * b;
    let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    (a * radial + 2.0 * p1 * a * b + p2 * (r2 + 2.0 * a * a), b * radial + p1 * (r2 + 2.0 * b * b) + 2.0 * p2 * a * b)
}

/// Jacobian [[∂a'/∂a, ∂a'/∂b], [∂b'/∂a, ∂b'/∂b]] of the distortion.
fn distort_jacobian(p: &[f64], a: f64, b: f64) -> [[f64; 2]; 2] {
    let (k1, k2, p1, p2, k3) = (p[4], p[5], p[6], p[7], p[8]);
    let r2 = a * a + b * b;
    let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    // d(radial)/d(r²)
    let dr = k1 + r2 * (2.0 * k2 + r2 * 3.0 * k3);
    [
        [radial + 2.0 * a * a * dr + 2.0 * p1 * b + 6.0 * p2 * a, 2.0 * a * b * dr + 2.0 * p1 * a + 2.0 * p2 * b],
        [2.0 * a * b * dr + 2.0 * p1 * a + 2.0 * p2 * b, radial + 2.0 * b * b * dr + 6.0 * p1 * b + 2.0 * p2 * a],
    ]
}

/// Pixel of a world direction (from the viewpoint, any length) with intrinsics `p`
/// ([`radtan_intrinsics`]); `None` behind the camera or beyond the model's domain.
pub fn radtan_project(p: &[f64], d: &Vector3<f64>) -> Option<Vector2<f64>> {
    let depth = -d.z;
    if !(depth > 0.0) {
        return None;
    }
    let (a, b) = (d.x / depth, d.y / depth);
    if a.hypot(b) > p[9] {
        return None;
    }
    let (x, y) = distort(p, a, b);
    Some(Vector2::new(p[0] * x + p[2], p[1] * y + p[3]))
}

/// Unit world direction of a pixel with intrinsics `p` ([`radtan_intrinsics`]); `None` where
/// the inverse of the distortion does not converge inside the model's domain.
pub fn radtan_unproject(p: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>> {
    let (tx, ty) = ((px.x - p[2]) / p[0], (px.y - p[3]) / p[1]);
    let (a, b) = invert_distortion(p, tx, ty)?;
    Vector3::new(a, b, -1.0).try_normalize(1e-300)
}

/// Solves distort(a, b) = (tx, ty) inside the domain r ≤ p[9]: started from the inverse of the
/// radial part alone (an increasing function of r there, bracketed), then Newton steps on the
/// whole map, halved while they do not reduce the error or leave the domain.
fn invert_distortion(p: &[f64], tx: f64, ty: f64) -> Option<(f64, f64)> {
    let r_max = p[9];
    let rd = tx.hypot(ty);
    let r = radial_inverse(p, rd);
    let (mut a, mut b) = if rd > 0.0 { (tx * r / rd, ty * r / rd) } else { (0.0, 0.0) };
    let err = |a: f64, b: f64| {
        let (x, y) = distort(p, a, b);
        (x - tx, y - ty)
    };
    let (mut ex, mut ey) = err(a, b);
    for _ in 0..100 {
        let e = ex.hypot(ey);
        if e < 1e-15 * (1.0 + tx.hypot(ty)) {
            break;
        }
        let j = distort_jacobian(p, a, b);
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if !(det.abs() > 1e-300) {
            return None;
        }
        let da = (j[1][1] * ex - j[0][1] * ey) / det;
        let db = (-j[1][0] * ex + j[0][0] * ey) / det;
        let mut step = 1.0;
        loop {
            let (na, nb) = (a - step * da, b - step * db);
            if na.hypot(nb) <= r_max {
                let (nx, ny) = err(na, nb);
                if nx.hypot(ny) < e {
                    (a, b, ex, ey) = (na, nb, nx, ny);
                    break;
                }
            }
            step *= 0.5;
            if step < 1e-12 {
                return None;
            }
        }
    }
    let j = distort_jacobian(p, a, b);
    let folded = j[0][0] * j[1][1] - j[0][1] * j[1][0] <= 0.0;
    (ex.hypot(ey) <= 1e-9 * (1.0 + tx.hypot(ty)) && !folded).then_some((a, b))
}

/// The r in [0, p[9]] where r·(1 + k1·r² + k2·r⁴ + k3·r⁶) is nearest `rd` (bracketed Newton).
fn radial_inverse(p: &[f64], rd: f64) -> f64 {
    let g = |r: f64| {
        let s = r * r;
        r * (1.0 + s * (p[4] + s * (p[5] + s * p[8])))
    };
    let slope = radial_slope_coefficients(p);
    let dg = |r: f64| poly::eval(&slope, r);
    let (mut lo, mut hi) = (0.0, p[9]);
    if g(hi) <= rd {
        return hi;
    }
    let mut r = rd.min(hi);
    for _ in 0..100 {
        let e = g(r) - rd;
        if e > 0.0 {
            hi = r;
        } else {
            lo = r;
        }
        let step = e / dg(r);
        let next = r - step;
        r = if step.is_finite() && next > lo && next < hi { next } else { 0.5 * (lo + hi) };
        if !(step.abs() > 1e-16 * (1.0 + r)) || hi - lo < 1e-16 {
            break;
        }
    }
    r
}

/// The radial-tangential pinhole camera, ready to use.
pub type PinholeCamera = CentralCamera<PinholeParams>;

impl CentralParams for PinholeParams {
    fn check(&self) -> Result<(), String> {
        self.validate()
    }
    fn to_intrinsics(&self) -> Vec<f64> {
        radtan_intrinsics(&self.to_vector())
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
        radtan_unproject(intrinsics, px)
    }
    fn pixel_of(&self, intrinsics: &[f64], dir: &Vector3<f64>) -> Option<Vector2<f64>> {
        radtan_project(intrinsics, dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CameraModel;
    use proptest::prelude::*;

    /// A wide-angle lens as OpenCV fits the hand-held laser set's camera (barrel distortion).
    fn sample() -> PinholeParams {
        PinholeParams {
            fx_px: 880.0,
            fy_px: 878.0,
            cx_px: 641.0,
            cy_px: 362.0,
            k1: -0.38,
            k2: 0.21,
            k3: -0.07,
            p1: 1.1e-3,
            p2: -6e-4,
            width: 1280,
            height: 720,
            viewpoint_mm: [0.0; 3],
        }
    }

    #[test]
    fn matches_opencv_formula_and_looks_down() {
        let cam = PinholeCamera::new(sample()).unwrap();
        let centre = cam.pixel_to_ray(&Vector2::new(641.0, 362.0)).unwrap();
        assert!(centre.dir.z < -0.999999, "{:?}", centre.dir);
        // A point 0.2 right, 0.1 down of the axis at depth 1 (OpenCV frame), by hand.
        let (a, b) = (0.2, 0.1);
        let r2: f64 = a * a + b * b;
        let radial = 1.0 - 0.38 * r2 + 0.21 * r2 * r2 - 0.07 * r2 * r2 * r2;
        let u = 880.0 * (a * radial + 2.0 * 1.1e-3 * a * b + -6e-4 * (r2 + 2.0 * a * a)) + 641.0;
        let v = 878.0 * (b * radial + 1.1e-3 * (r2 + 2.0 * b * b) + 2.0 * -6e-4 * a * b) + 362.0;
        let px = cam.point_to_pixel(&Point3::new(a, b, -1.0)).unwrap();
        assert!((px - Vector2::new(u, v)).norm() < 1e-9, "{px} vs {u} {v}");
        assert!(cam.point_to_pixel(&Point3::new(0.1, 0.0, 1.0)).is_none(), "behind the camera");
    }

    #[test]
    fn the_domain_ends_where_the_distortion_turns_back() {
        // Radial distortion alone: where r·ρ(r) turns back.
        let mut radial = sample().to_vector();
        (radial[6], radial[7]) = (0.0, 0.0);
        let r = radtan_max_radius(&radial);
        let g = |r: f64| r * (1.0 + radial[4] * r * r + radial[5] * r.powi(4) + radial[8] * r.powi(6));
        assert!(g(r - 1e-6) < g(r) && g(r + 1e-3) < g(r), "r_max {r}");
        // With tangential terms a little earlier: where the scale along the radius meets
        // 6·√(p1² + p2²)·r.
        let v = sample().to_vector();
        let rt = radtan_max_radius(&v);
        let along = |r: f64| 1.0 + 3.0 * v[4] * r * r + 5.0 * v[5] * r.powi(4) + 7.0 * v[8] * r.powi(6);
        assert!(rt < r && rt > 0.98 * r, "{rt} vs {r}");
        assert!((along(rt) - 6.0 * v[6].hypot(v[7]) * rt).abs() < 1e-12, "r_max {rt}");
        let p = radtan_intrinsics(&v);
        assert!(radtan_project(&p, &Vector3::new(rt * 1.01, 0.0, -1.0)).is_none());
        assert!(radtan_project(&p, &Vector3::new(rt * 0.99, 0.0, -1.0)).is_some());
        // A pixel beyond the image of the domain's edge has no ray.
        let edge = radtan_project(&p, &Vector3::new(rt * 0.999, 0.0, -1.0)).unwrap();
        assert!(radtan_unproject(&p, &Vector2::new(edge.x + 50.0, edge.y)).is_none());
        // No turning point: the whole half-space up to r = 100.
        let mut open = v;
        open[4] = 0.1;
        open[5] = 0.0;
        open[8] = 0.0;
        assert_eq!(radtan_max_radius(&open), MAX_RADIUS);
    }

    /// A lens whose radial map never turns back, though its slope dips to 0.0006 at r = 1.33:
    /// there p2 folds the image, and two directions 0.14 apart in r met at one pixel (a draw of
    /// `project_unproject_round_trips` that once unprojected the pixel to the other one).
    #[test]
    fn no_pixel_has_two_rays_where_the_tangential_terms_fold_the_image() {
        let (k1, k2, k3, p2) = (-0.40933955980705117, 0.0862398733074494, -0.004552920036781069, 0.0018382984981100664);
        let v = [300.0, 294.0, 500.0, 300.0, k1, k2, 0.0, p2, k3];
        let p = radtan_intrinsics(&v);
        let near = (-0.6226380285678131, -1.1459081436256384);
        let far = (-0.393188389406403 / 0.5692226554572428, -0.7220723363695661 / 0.5692226554572428);
        let (dn, df) = (distort(&p, near.0, near.1), distort(&p, far.0, far.1));
        assert!((dn.0 - df.0).hypot(dn.1 - df.1) < 1e-9, "{dn:?} vs {df:?}");
        let r_max = radtan_max_radius(&v);
        assert!(r_max < near.0.hypot(near.1) && r_max > 1.2, "r_max {r_max}");
        for (a, b) in [near, far] {
            assert!(radtan_project(&p, &Vector3::new(a, b, -1.0)).is_none());
        }
    }

    proptest! {
        #[test]
        fn project_unproject_round_trips(
            fx in 300.0..1500.0f64, aspect in 0.98..1.02f64, cx in 500.0..780.0f64, cy in 300.0..420.0f64,
            k1 in -0.45..0.2f64, k2 in -0.1..0.3f64, k3 in -0.1..0.1f64, p1 in -2e-3..2e-3f64, p2 in -2e-3..2e-3f64,
            fa in -1.0..1.0f64, fb in -1.0..1.0f64,
        ) {
            let p = PinholeParams { fx_px: fx, fy_px: fx * aspect, cx_px: cx, cy_px: cy, k1, k2, k3, p1, p2,
                width: 1280, height: 720, viewpoint_mm: [1.0, -2.0, 3.0] };
            let cam = PinholeCamera::new(p).unwrap();
            let v = cam.params().to_vector();
            // A direction inside 90 % of the domain (and of 60° off the axis).
            let r_max = (0.9 * radtan_max_radius(&v)).min(60f64.to_radians().tan());
            let (a, b) = (fa * r_max / std::f64::consts::SQRT_2, fb * r_max / std::f64::consts::SQRT_2);
            let p = radtan_intrinsics(&v);
            let d = Vector3::new(a, b, -1.0);
            let px = radtan_project(&p, &d).unwrap();
            let back = radtan_unproject(&p, &px);
            prop_assert!(back.is_some(), "{px}: no ray");
            let back = back.unwrap();
            prop_assert!((back - d.normalize()).norm() < 1e-10, "{px}: {back} vs {d}");
            // Pixels → rays → pixels over the image.
            let q = Vector2::new(cx + 600.0 * fa, cy + 340.0 * fb);
            if let Some(ray) = cam.pixel_to_ray(&q) {
                let again = cam.point_to_pixel(&ray.at(500.0)).unwrap();
                prop_assert!((again - q).norm() < 1e-8, "{q} -> {again}");
            }
        }
    }
}
