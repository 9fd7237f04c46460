//! The exact hyperbolic catadioptric camera (SENSOR.md, paper §2.3.2).
//!
//! Mirror: (z − c)²/a² − (x² + y²)/b² = 1, c = √(a² + b²), sheet z ≥ c + a; foci O = (0,0,0)
//! (the camera centre when ideal) and F = (0,0,2c), the single effective viewpoint.
//! Pinhole camera at O looking up +z: u = fx·X/Z, v = fy·Y/Z around the principal point.
//!
//! With `camera_offset_mm`/`camera_tilt_deg` non-zero the camera sits off the focus: the model
//! becomes non-central, rays are traced exactly (refraction-free mirror reflection), and
//! projection is solved by Gauss–Newton on the pixel.

use crate::camera::{CameraModel, MirrorCircle};
use omni_geom::{Point3, Ray, Rotation3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Parameters of the hyperbolic camera (what `camera.json` stores for kind `hyperbolic`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HyperbolicParams {
    /// Mirror semi-axis a (mm).
    pub a_mm: f64,
    /// Mirror semi-axis b (mm).
    pub b_mm: f64,
    /// Focal length along x (px).
    pub fx_px: f64,
    /// Focal length along y (px).
    pub fy_px: f64,
    /// Principal point x (px).
    pub cx_px: f64,
    /// Principal point y (px).
    pub cy_px: f64,
    pub width: u32,
    pub height: u32,
    /// Mirror rim radius (mm): the largest mirror radius that reflects the scene.
    pub rim_radius_mm: f64,
    /// Mirror radius (mm) below which the camera sees itself (blind centre).
    #[serde(default)]
    pub inner_radius_mm: f64,
    /// Camera centre relative to the mirror's lower focus (mm, world frame); zero when ideal.
    #[serde(default)]
    pub camera_offset_mm: [f64; 3],
    /// Camera tilt about world x then y (degrees); zero when ideal.
    #[serde(default)]
    pub camera_tilt_deg: [f64; 2],
}

impl HyperbolicParams {
    /// The paper's mirror (a² = 1248.2060 mm², b² = 351.7940 mm², so c = 40 mm) with our
    /// choice of lens: 1024 × 1024 px, f = 1950 px (a 10.7 mm lens on 5.5 µm pixels), rim
    /// radius 25 mm so the rim fills the image (≈ 493 px), blind centre radius 4 mm.
    pub fn paper() -> Self {
        HyperbolicParams {
            a_mm: 1248.2060f64.sqrt(),
            b_mm: 351.7940f64.sqrt(),
            fx_px: 1950.0,
            fy_px: 1950.0,
            cx_px: 511.5,
            cy_px: 511.5,
            width: 1024,
            height: 1024,
            rim_radius_mm: 25.0,
            inner_radius_mm: 4.0,
            camera_offset_mm: [0.0; 3],
            camera_tilt_deg: [0.0; 2],
        }
    }

    /// Checks that every parameter is finite and physically meaningful; names the field at fault.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("a_mm", self.a_mm),
            ("b_mm", self.b_mm),
            ("fx_px", self.fx_px),
            ("fy_px", self.fy_px),
            ("rim_radius_mm", self.rim_radius_mm),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a positive number, got {v}"));
            }
        }
        let finite = [
            ("cx_px", self.cx_px),
            ("cy_px", self.cy_px),
            ("inner_radius_mm", self.inner_radius_mm),
            ("camera_offset_mm[0]", self.camera_offset_mm[0]),
            ("camera_offset_mm[1]", self.camera_offset_mm[1]),
            ("camera_offset_mm[2]", self.camera_offset_mm[2]),
            ("camera_tilt_deg[0]", self.camera_tilt_deg[0]),
            ("camera_tilt_deg[1]", self.camera_tilt_deg[1]),
        ];
        for (name, v) in finite {
            if !v.is_finite() {
                return Err(format!("{name} must be finite, got {v}"));
            }
        }
        crate::limits::check_image_size(self.width, self.height)?;
        if !(self.inner_radius_mm >= 0.0 && self.inner_radius_mm < self.rim_radius_mm) {
            return Err("inner_radius_mm must be in [0, rim_radius_mm)".into());
        }
        Ok(())
    }
}

/// The hyperbolic catadioptric camera, ready to use.
#[derive(Debug, Clone)]
pub struct HyperbolicCamera {
    params: HyperbolicParams,
    a: f64,
    b2: f64,
    c: f64,
    /// Camera centre (world) and rotation camera → world.
    centre: Point3<f64>,
    rot: Rotation3<f64>,
    ideal: bool,
}

impl HyperbolicCamera {
    /// Builds the camera; fails with the name of an invalid field.
    pub fn new(params: HyperbolicParams) -> Result<Self, String> {
        params.validate()?;
        let a = params.a_mm;
        let b2 = params.b_mm * params.b_mm;
        let c = (a * a + b2).sqrt();
        let [tx, ty] = params.camera_tilt_deg;
        let rot = Rotation3::from_axis_angle(&Vector3::y_axis(), ty.to_radians())
            * Rotation3::from_axis_angle(&Vector3::x_axis(), tx.to_radians());
        let centre = Point3::from(Vector3::from(params.camera_offset_mm));
        let ideal = params.camera_offset_mm == [0.0; 3] && params.camera_tilt_deg == [0.0; 2];
        Ok(HyperbolicCamera { params, a, b2, c, centre, rot, ideal })
    }

    pub fn params(&self) -> &HyperbolicParams {
        &self.params
    }

    /// The single effective viewpoint F = (0, 0, 2c) (mm). Exact only for the ideal build.
    pub fn viewpoint(&self) -> Point3<f64> {
        Point3::new(0.0, 0.0, 2.0 * self.c)
    }

    /// Mirror height z (mm) at radius r (mm) on the used sheet.
    pub fn mirror_z(&self, r: f64) -> f64 {
        self.c + self.a * (1.0 + r * r / self.b2).sqrt()
    }

    fn radius_ok(&self, m: &Point3<f64>) -> bool {
        let r = m.x.hypot(m.y);
        r <= self.params.rim_radius_mm && r >= self.params.inner_radius_mm
    }

    /// Camera-frame direction of a pixel (not normalised).
    fn pixel_dir(&self, px: &Vector2<f64>) -> Vector3<f64> {
        let p = &self.params;
        self.rot * Vector3::new((px.x - p.cx_px) / p.fx_px, (px.y - p.cy_px) / p.fy_px, 1.0)
    }

    /// Where the camera ray from `origin` along `d` first meets the used mirror sheet.
    fn hit_mirror(&self, origin: &Point3<f64>, d: &Vector3<f64>) -> Option<Point3<f64>> {
        // (z − c)²/a² − (x² + y²)/b² = 1 along origin + s·d.
        let a2 = self.a * self.a;
        let oz = origin.z - self.c;
        let qa = d.z * d.z / a2 - (d.x * d.x + d.y * d.y) / self.b2;
        let qb = 2.0 * (oz * d.z / a2 - (origin.x * d.x + origin.y * d.y) / self.b2);
        let qc = oz * oz / a2 - (origin.x * origin.x + origin.y * origin.y) / self.b2 - 1.0;
        let roots = solve_quadratic(qa, qb, qc)?;
        roots
            .into_iter()
            .filter(|s| *s > 0.0)
            .map(|s| origin + d * s)
            .filter(|m| m.z - self.c >= self.a * (1.0 - 1e-12))
            .min_by(|m1, m2| (m1 - origin).norm().total_cmp(&(m2 - origin).norm()))
    }

    /// Outward mirror normal (unit) at a mirror point.
    fn mirror_normal(&self, m: &Point3<f64>) -> Vector3<f64> {
        Vector3::new(-m.x / self.b2, -m.y / self.b2, (m.z - self.c) / (self.a * self.a)).normalize()
    }

    fn ideal_project(&self, p: &Point3<f64>) -> Option<Vector2<f64>> {
        self.ideal_project_any_radius(p).filter(|(_, m)| self.radius_ok(m)).map(|(px, _)| px)
    }

    /// The ideal camera's pixel of `p` and its mirror point, at any mirror radius.
    fn ideal_project_any_radius(&self, p: &Point3<f64>) -> Option<(Vector2<f64>, Point3<f64>)> {
        let f = self.viewpoint();
        let d = (p - f).try_normalize(1e-300)?;
        // Distance from F to the mirror along d (focal property): t = b²/(a − c·dz).
        let denom = self.a - self.c * d.z;
        if denom <= 0.0 {
            return None;
        }
        let t = self.b2 / denom;
        if (p - f).norm() <= t {
            return None; // the point is between the viewpoint and the mirror
        }
        let m = f + d * t;
        if m.z <= 0.0 {
            return None;
        }
        let q = &self.params;
        Some((Vector2::new(q.cx_px + q.fx_px * m.x / m.z, q.cy_px + q.fy_px * m.y / m.z), m))
    }

    /// Gauss–Newton on the pixel so that its traced ray passes through `p` (non-central case).
    fn general_project(&self, p: &Point3<f64>) -> Option<Vector2<f64>> {
        let start = self.ideal_project_any_radius(p).map(|(px, _)| px).or_else(|| {
            let c = self.mirror_circle();
            let d = Vector2::new(p.x, p.y).try_normalize(1e-300)?;
            Some(c.centre + d * 0.5 * (c.inner_radius + c.outer_radius))
        })?;
        self.project_from(p, &start)
    }

    /// The pixel whose traced ray passes through `p`, by Gauss–Newton on the pixel from `start`
    /// (px; a pixel near the answer, e.g. where `p` was observed): the exact projection of the
    /// non-central camera, to 1e-10 px. Unlike [`CameraModel::point_to_pixel`] it does not
    /// check the image bounds; `None` if the iteration leaves the mirror or does not converge.
    pub fn project_from(&self, p: &Point3<f64>, start: &Vector2<f64>) -> Option<Vector2<f64>> {
        let mut px = *start;
        // The angle between the pixel's ray and the direction to `p`, in a fixed basis; the
        // iteration may pass the rim or the blind centre, the answer may not.
        let first = self.reflect(&px)?;
        let (e1, e2) = omni_geom::fit::orthonormal_basis(&first.dir);
        let residual = |px: &Vector2<f64>| -> Option<Vector2<f64>> {
            let ray = self.reflect(px)?;
            let w = (p - ray.origin).try_normalize(1e-300)?;
            let d = ray.dir.into_inner() - w;
            Some(Vector2::new(d.dot(&e1), d.dot(&e2)))
        };
        let h = 1e-4;
        let mut converged = false;
        for _ in 0..30 {
            let r0 = residual(&px)?;
            let rx = residual(&(px + Vector2::new(h, 0.0)))?;
            let ry = residual(&(px + Vector2::new(0.0, h)))?;
            let j = nalgebra::Matrix2::from_columns(&[(rx - r0) / h, (ry - r0) / h]);
            let step = j.try_inverse()? * r0;
            px -= step;
            if step.norm() < 1e-10 {
                converged = true;
                break;
            }
        }
        let ray = self.trace(&px)?;
        let along = (p - ray.origin).dot(&ray.dir);
        (converged && along > 0.0 && ray.distance_to_line(p) < 1e-6 * along.max(1.0)).then_some(px)
    }

    /// Where the pixel's camera ray meets the mirror (mm, world frame), at any radius (the rim
    /// and the blind centre are not checked): e.g. to express an image radius on the mirror.
    pub fn mirror_point(&self, px: &Vector2<f64>) -> Option<Point3<f64>> {
        self.hit_mirror(&self.centre, &self.pixel_dir(px))
    }

    /// Exact reflection of the pixel's camera ray off the mirror, inside the rim and outside the
    /// blind centre.
    fn trace(&self, px: &Vector2<f64>) -> Option<Ray> {
        self.reflect(px).filter(|ray| self.radius_ok(&ray.origin))
    }

    /// Exact reflection of the pixel's camera ray off the mirror sheet, at any radius.
    fn reflect(&self, px: &Vector2<f64>) -> Option<Ray> {
        let d = self.pixel_dir(px);
        let m = self.hit_mirror(&self.centre, &d)?;
        let n = self.mirror_normal(&m);
        let dn = d.normalize();
        let r = dn - n * (2.0 * dn.dot(&n));
        Some(Ray::new(m, r))
    }
}

/// The geometric blur spot of a defocused lens: where the light of one scene point lands
/// relative to its chief ray's pixel (px), as the mean and covariance over the lens pupil.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DefocusSpot {
    /// The spot's centroid less the chief ray's pixel (px).
    pub mean: Vector2<f64>,
    /// The spot's covariance about its centroid (px²), image axes.
    pub covariance: nalgebra::Matrix2<f64>,
}

impl DefocusSpot {
    /// The spot's variance along the unit image direction `dir` (px²).
    pub fn variance_along(&self, dir: &Vector2<f64>) -> f64 {
        dir.dot(&(self.covariance * dir))
    }
}

/// Pupil samples: rings of equal area, each with equally spaced angles, so that the mean of any
/// quadratic function of the pupil position is exact.
const PUPIL_RINGS: usize = 8;
const PUPIL_ANGLES: usize = 16;

impl HyperbolicCamera {
    /// The blur spot of scene point `p` (mm, world frame) seen at pixel `px` through a thin
    /// lens at the camera centre with a pupil of radius `pupil_radius_mm`, focused on the plane
    /// `focus_mm` ahead of it along its axis (a scene point's virtual image in the mirror lies
    /// at a distance that changes over the field, so the catadioptric image is sharp only along
    /// one curve).
    ///
    /// Traced backwards: every ray from a pupil point towards the focus plane's point of `px`
    /// lands on that pixel, so its reflection off the mirror, where it passes `p`, names the
    /// pixel that point of the pupil blurs `p` onto (reversed). Exact rays, no paraxial
    /// approximation; `None` where a ray misses the mirror sheet or `p` is not in front of it.
    pub fn defocus_spot(
        &self,
        px: &Vector2<f64>,
        p: &Point3<f64>,
        focus_mm: f64,
        pupil_radius_mm: f64,
    ) -> Option<DefocusSpot> {
        let chief = self.reflect(px)?;
        let along = (p - chief.origin).dot(&chief.dir);
        if !(along > 0.0 && focus_mm > 0.0 && pupil_radius_mm >= 0.0) {
            return None;
        }
        let sharp = self.centre + self.pixel_dir(px) * focus_mm;
        let mut sum = Vector2::zeros();
        let mut sum_sq = nalgebra::Matrix2::zeros();
        let n = (PUPIL_RINGS * PUPIL_ANGLES) as f64;
        for ring in 0..PUPIL_RINGS {
            let radius = pupil_radius_mm * ((ring as f64 + 0.5) / PUPIL_RINGS as f64).sqrt();
            for k in 0..PUPIL_ANGLES {
                // Rings turned by half a step against each other, so no two share an angle.
                let angle = std::f64::consts::TAU * (k as f64 + 0.5 * (ring % 2) as f64) / PUPIL_ANGLES as f64;
                let pupil = self.centre + self.rot * Vector3::new(radius * angle.cos(), radius * angle.sin(), 0.0);
                let m = self.hit_mirror(&pupil, &(sharp - pupil))?;
                let d = (m - pupil).normalize();
                let normal = self.mirror_normal(&m);
                let out = d - normal * (2.0 * d.dot(&normal));
                // Where the ray crosses the plane through p across the chief ray.
                let t = (p - m).dot(&chief.dir) / out.dot(&chief.dir);
                if !(t > 0.0) {
                    return None;
                }
                let q = m + out * t;
                let offset = px - self.project_from(&q, px)?;
                sum += offset;
                sum_sq += offset * offset.transpose();
            }
        }
        let mean = sum / n;
        Some(DefocusSpot { mean, covariance: sum_sq / n - mean * mean.transpose() })
    }
}

fn solve_quadratic(a: f64, b: f64, c: f64) -> Option<[f64; 2]> {
    if a.abs() < 1e-300 {
        return (b.abs() > 1e-300).then(|| [-c / b, -c / b]);
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    // Numerically stable form.
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let r1 = q / a;
    let r2 = if q != 0.0 { c / q } else { r1 };
    Some([r1, r2])
}

impl CameraModel for HyperbolicCamera {
    fn image_size(&self) -> (u32, u32) {
        (self.params.width, self.params.height)
    }

    fn pixel_to_ray(&self, px: &Vector2<f64>) -> Option<Ray> {
        if !self.in_image(px) || !px.x.is_finite() || !px.y.is_finite() {
            return None;
        }
        if !self.ideal {
            return self.trace(px);
        }
        // Closed form (SENSOR.md): β = atan(l/f), |OM| = b²/(c·cosβ − a), ray from F through M.
        let p = &self.params;
        let u = (px.x - p.cx_px) / p.fx_px;
        let v = (px.y - p.cy_px) / p.fy_px;
        let l = u.hypot(v);
        let cos_b = 1.0 / (1.0 + l * l).sqrt();
        let sin_b = l * cos_b;
        let denom = self.c * cos_b - self.a;
        if denom <= 0.0 {
            return None;
        }
        let om = self.b2 / denom;
        let m = if l > 0.0 {
            Point3::new(om * sin_b * u / l, om * sin_b * v / l, om * cos_b)
        } else {
            Point3::new(0.0, 0.0, om)
        };
        if !self.radius_ok(&m) {
            return None;
        }
        let f = self.viewpoint();
        Some(Ray::new(f, m - f))
    }

    /// The mirror images each pencil of rays from a scene point through the lens's pupil
    /// without astigmatism (a conic's foci are a stigmatic pair, so its sagittal and tangential
    /// powers agree at every point, for any object distance), into a virtual image behind it:
    /// Coddington's mirror equation along the chief ray, 1/v = 1/|MF| − 1/|MO| + 1/D, with M
    /// the mirror point, O the lens, F the outer focus and D the scene point's distance from M.
    /// The thin lens focused on the plane at `focus_mm` blurs a point at axial distance z into a
    /// disc of diameter 2R·f·|1/focus − 1/z| (px). [`HyperbolicCamera::defocus_spot`] traces it
    /// exactly. Exact for the ideal build: with the camera off the focus the pencil is
    /// astigmatic and this lies between its two foci. A distance that does not reach past the
    /// mirror (0, say) gives the blur of the mirror's own surface, where its rim cuts the view.
    fn defocus_sigma_px(&self, px: &Vector2<f64>, distance_mm: f64, optics: &crate::Optics) -> Option<f64> {
        let focus = optics.focus_mm?;
        let f_px = 0.5 * (self.params.fx_px + self.params.fy_px);
        let ray = self.pixel_to_ray(px)?;
        let m = self.mirror_point(px)?;
        let to_mirror = m - self.centre;
        let (mo, mf) = (to_mirror.norm(), (m - self.viewpoint()).norm());
        let point = ray.at(distance_mm);
        let v =
            if (point - m).dot(&ray.dir) > 0.0 { 1.0 / (1.0 / mf - 1.0 / mo + 1.0 / (point - m).norm()) } else { 0.0 };
        let axial = (to_mirror * (1.0 + v / mo)).dot(&(self.rot * Vector3::z()));
        let diameter = 2.0 * optics.pupil_radius_mm(f_px) * f_px * (1.0 / focus - 1.0 / axial).abs();
        Some(diameter / 4.0)
    }

    fn point_to_pixel(&self, p: &Point3<f64>) -> Option<Vector2<f64>> {
        if !p.coords.iter().all(|x| x.is_finite()) {
            return None;
        }
        let px = if self.ideal { self.ideal_project(p) } else { self.general_project(p) }?;
        self.in_image(&px).then_some(px)
    }

    fn mirror_circle(&self) -> MirrorCircle {
        let p = &self.params;
        if self.ideal {
            let f = 0.5 * (p.fx_px + p.fy_px);
            let r_img = |r: f64| f * r / self.mirror_z(r);
            return MirrorCircle {
                centre: Vector2::new(p.cx_px, p.cy_px),
                inner_radius: r_img(p.inner_radius_mm),
                outer_radius: r_img(p.rim_radius_mm),
            };
        }
        // Off the focus: the rim and blind-centre circles projected through the (offset, tilted)
        // pinhole; centre of the rim's image, each circle's mean radius about its own centre.
        let circle = |r: f64| -> (Vector2<f64>, f64) {
            let z = self.mirror_z(r);
            let pts: Vec<Vector2<f64>> = (0..360)
                .map(|k| {
                    let a = (k as f64).to_radians();
                    let q = self.rot.inverse() * (Point3::new(r * a.cos(), r * a.sin(), z) - self.centre);
                    Vector2::new(p.cx_px + p.fx_px * q.x / q.z, p.cy_px + p.fy_px * q.y / q.z)
                })
                .collect();
            let c = pts.iter().sum::<Vector2<f64>>() / pts.len() as f64;
            (c, pts.iter().map(|q| (q - c).norm()).sum::<f64>() / pts.len() as f64)
        };
        let (centre, outer_radius) = circle(p.rim_radius_mm);
        MirrorCircle { centre, inner_radius: circle(p.inner_radius_mm).1, outer_radius }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_mirror_has_c_40() {
        let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        assert!((cam.c - 40.0).abs() < 1e-12);
        // Horizon maps to mirror radius b²/a ≈ 9.96 mm.
        let px = cam.point_to_pixel(&Point3::new(1000.0, 0.0, 80.0)).unwrap();
        let r_px = px.x - 511.5;
        let r_mm = 351.794 / 1248.206f64.sqrt();
        assert!((r_px - 1950.0 * r_mm / 80.0).abs() < 1e-9, "{r_px}");
    }

    #[test]
    fn ideal_closed_form_agrees_with_traced_reflection() {
        let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        for &(x, y) in &[(700.0, 511.5), (300.0, 222.0), (512.0, 900.0), (811.0, 640.0)] {
            let px = Vector2::new(x, y);
            let a = cam.pixel_to_ray(&px).unwrap();
            let b = cam.trace(&px).unwrap();
            assert!(a.dir.dot(&b.dir) > 1.0 - 1e-14);
            assert!(b.distance_to_line(&a.origin) < 1e-9);
        }
    }

    #[test]
    fn off_focus_camera_round_trips() {
        let mut p = HyperbolicParams::paper();
        p.camera_offset_mm = [0.3, -0.2, 0.5];
        p.camera_tilt_deg = [0.2, -0.1];
        let cam = HyperbolicCamera::new(p).unwrap();
        for &(x, y) in &[(700.0, 511.5), (300.0, 222.0), (512.0, 900.0)] {
            let px = Vector2::new(x, y);
            let ray = cam.pixel_to_ray(&px).unwrap();
            let back = cam.point_to_pixel(&ray.at(800.0)).unwrap();
            assert!((back - px).norm() < 1e-7, "{px} -> {back}");
        }
    }
}

#[cfg(test)]
mod defocus_tests {
    use super::*;
    use crate::Optics;

    fn focused(focus_mm: f64) -> Optics {
        Optics::paper().focused_at(focus_mm)
    }

    /// The closed form (Coddington's mirror equation and a thin lens) against the exact trace of
    /// 128 rays through the pupil, over the mirror's field, near and far, in and out of focus;
    /// and the traced spots are round (no astigmatism) and centred on the chief ray.
    #[test]
    fn the_closed_form_defocus_agrees_with_the_traced_pupil() {
        let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        for focus in [80.0, 85.0, 91.0, 100.0] {
            let optics = focused(focus);
            let pupil = optics.pupil_radius_mm(1950.0);
            for distance in [100.0, 300.0, 1000.0, 5000.0] {
                for (k, rho) in [130.0, 150.0, 203.0, 250.0, 270.0, 311.0, 359.0, 420.0, 470.0].into_iter().enumerate()
                {
                    let angle = 0.7 * k as f64;
                    let px = Vector2::new(511.5 + rho * angle.cos(), 511.5 + rho * angle.sin());
                    let ray = cam.pixel_to_ray(&px).unwrap();
                    let spot = cam.defocus_spot(&px, &ray.at(distance), focus, pupil).unwrap();
                    let sigma = cam.defocus_sigma_px(&px, distance, &optics).unwrap();
                    let radial = Vector2::new(angle.cos(), angle.sin());
                    let across = Vector2::new(-radial.y, radial.x);
                    let (sr, st) = (spot.variance_along(&radial).sqrt(), spot.variance_along(&across).sqrt());
                    let at = format!("focus {focus} mm, {distance} mm away, radius {rho} px");
                    assert!((sr - sigma).abs() <= 0.02 * sigma + 0.01, "{at}: traced {sr:.4}, closed form {sigma:.4}");
                    assert!((sr - st).abs() <= 0.01 * sr + 0.005, "{at}: radial {sr:.4}, tangential {st:.4}");
                    assert!(spot.mean.norm() <= 0.05, "{at}: centroid {:.4} px off", spot.mean.norm());
                }
            }
        }
    }

    /// Sharp along one ring, blurred on either side of it, the ring moving out as the lens is
    /// focused farther; no focus distance, no field-dependent blur.
    #[test]
    fn the_image_is_sharp_along_one_ring() {
        let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        let sharpest = |focus: f64| {
            let optics = focused(focus);
            (130..480)
                .map(|r| {
                    let s = cam.defocus_sigma_px(&Vector2::new(511.5 + r as f64, 511.5), 1000.0, &optics).unwrap();
                    (s, r)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap()
        };
        let (near, far) = (sharpest(85.0), sharpest(100.0));
        assert!(near.0 < 0.02 && far.0 < 0.02, "{near:?} {far:?}");
        assert!(near.1 < far.1, "{near:?} {far:?}");
        assert!(cam.defocus_sigma_px(&Vector2::new(800.0, 511.5), 1000.0, &Optics::paper()).is_none());
        // At distance 0 the mirror's own surface: a real object at the mirror point's height.
        let px = Vector2::new(511.5 + 480.0, 511.5);
        let optics = focused(91.0);
        let m = cam.mirror_point(&px).unwrap();
        let want = 2.0 * optics.pupil_radius_mm(1950.0) * 1950.0 * (1.0 / 91.0 - 1.0 / m.z).abs() / 4.0;
        let got = cam.defocus_sigma_px(&px, 0.0, &optics).unwrap();
        assert!(
            (got - want).abs() < 1e-9 && got < 0.5 * cam.defocus_sigma_px(&px, 1000.0, &optics).unwrap(),
            "{got} {want}"
        );
    }
}
