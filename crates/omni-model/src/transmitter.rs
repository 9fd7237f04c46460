//! The laser transmitter: a rotating regular polygon mirror and line lasers (SENSOR.md,
//! "Beyond the paper").
//!
//! The reflected fan of laser j off facet k lies in the mirror image of the laser's fan plane
//! in the facet plane. Facet k's outward normal, in the polygon body frame (basis e1 = `zero_dir`,
//! e3 = axis × e1), is at angle ψ_k = θ − 2θ·k (+ pitch error) in the e1–e3 plane, tilted
//! towards the axis by the facet's tilt error; its distance from the axis is R·cos θ (+ radius
//! error). At mirror angle α within facet k (0 ≤ α < 2θ) the polygon has turned by
//! φ = α + 2θ·k + encoder zero offset about the axis (right hand), so facet k faces laser 0
//! with its normal at angle θ + α: the paper's chord from R(cos α, sin α) to R(cos(α+2θ), sin(α+2θ)).
//! Laser j uses facet (k + facet_offset_j) mod n.

use omni_geom::{Plane, Point3, Rotation3, Unit, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Manufacturing errors of one facet.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FacetError {
    /// Pyramidal tilt of the facet normal towards the polygon axis (degrees).
    #[serde(default)]
    pub tilt_deg: f64,
    /// Error of the facet's angle about the axis (degrees).
    #[serde(default)]
    pub pitch_deg: f64,
    /// Error of the facet's distance from the axis (mm).
    #[serde(default)]
    pub radius_mm: f64,
}

/// The polygon mirror (world frame, mm / degrees).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolygonParams {
    /// A point on the rotation axis (mm, world frame).
    pub axis_point_mm: [f64; 3],
    /// Rotation axis direction (right-hand rule gives the positive turning sense).
    pub axis_dir: [f64; 3],
    /// Body-frame direction e1 (⟂ axis) at which φ = 0 is measured.
    pub zero_dir: [f64; 3],
    /// Number of facets n.
    pub facets: u32,
    /// Circumradius R (mm).
    pub circumradius_mm: f64,
    /// Encoder zero offset (degrees): true turn = reported α + offset.
    #[serde(default)]
    pub encoder_zero_deg: f64,
    /// Per-facet errors: empty (ideal) or exactly n entries.
    #[serde(default)]
    pub facet_errors: Vec<FacetError>,
}

/// One line laser (world frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaserParams {
    /// Apex of the fan (mm).
    pub source_mm: [f64; 3],
    /// Central ray direction, towards the polygon.
    pub direction: [f64; 3],
    /// In-plane direction along which the 180° fan spreads (⟂ `direction`).
    pub fan_axis: [f64; 3],
    /// This laser hits facet (k + facet_offset) mod n when laser 0 hits facet k.
    pub facet_offset: u32,
}

/// The whole transmitter (what `scanner.json` stores).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransmitterParams {
    pub polygon: PolygonParams,
    pub lasers: Vec<LaserParams>,
}

impl TransmitterParams {
    /// The paper's ideal build, with our dimensions (the paper gives none): 12 facets,
    /// circumradius R = 20 mm, polygon axis along y at height −h with h = 120 mm (the
    /// transmitter frame of the paper shifted to (0, 0, −h)); laser 0 shines at 4θ = 60° through
    /// the facet midpoint M0 = R·cosθ·(cos 2θ, sin 2θ), its apex 30 mm back along that ray;
    /// laser 1 is its point mirror image through the axis (the two lasers are "aligned
    /// symmetrically around the rotation axis"), using the opposite facet.
    pub fn paper() -> Self {
        Self::ideal(12, 20.0, 120.0, 30.0)
    }

    /// An ideal two-laser build: `n` facets, circumradius `r` (mm), axis height −`h` (mm),
    /// laser apex `lever` mm from the facet midpoint.
    pub fn ideal(n: u32, r: f64, h: f64, lever: f64) -> Self {
        let theta = PI / n as f64;
        let m0 = [r * theta.cos() * (2.0 * theta).cos(), r * theta.cos() * (2.0 * theta).sin()];
        let inc = [(4.0 * theta).cos(), (4.0 * theta).sin()];
        let laser = |sign: f64| LaserParams {
            source_mm: [sign * (m0[0] + lever * inc[0]), 0.0, sign * (m0[1] + lever * inc[1]) - h],
            direction: [-sign * inc[0], 0.0, -sign * inc[1]],
            fan_axis: [0.0, 1.0, 0.0],
            facet_offset: if sign > 0.0 { 0 } else { n / 2 },
        };
        TransmitterParams {
            polygon: PolygonParams {
                axis_point_mm: [0.0, 0.0, -h],
                axis_dir: [0.0, -1.0, 0.0],
                zero_dir: [1.0, 0.0, 0.0],
                facets: n,
                circumradius_mm: r,
                encoder_zero_deg: 0.0,
                facet_errors: vec![],
            },
            lasers: vec![laser(1.0), laser(-1.0)],
        }
    }

    /// Checks values; the message names the field at fault.
    pub fn validate(&self) -> Result<(), String> {
        let p = &self.polygon;
        let finite3 = |name: &str, v: &[f64; 3]| {
            if v.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(format!("{name} must be finite")) }
        };
        // Positions (mm) within reach of a measurement: a wrong number, not a place.
        let max = crate::limits::MAX_COORDINATE_MM;
        let position = |name: &str, v: &[f64; 3]| match v.iter().all(|x| x.is_finite() && x.abs() <= max) {
            true => Ok(()),
            false => Err(format!("{name} must be finite and within ±{max:e} mm")),
        };
        position("polygon.axis_point_mm", &p.axis_point_mm)?;
        finite3("polygon.axis_dir", &p.axis_dir)?;
        finite3("polygon.zero_dir", &p.zero_dir)?;
        if !(3..=crate::limits::MAX_FACETS).contains(&p.facets) {
            return Err(format!("polygon.facets must be in 3..={}, got {}", crate::limits::MAX_FACETS, p.facets));
        }
        if !(p.circumradius_mm.is_finite() && p.circumradius_mm > 0.0 && p.circumradius_mm <= max) {
            return Err(format!("polygon.circumradius_mm must be positive, at most {max:e} mm"));
        }
        if !p.encoder_zero_deg.is_finite() {
            return Err("polygon.encoder_zero_deg must be finite".into());
        }
        let axis = Vector3::from(p.axis_dir);
        let zero = Vector3::from(p.zero_dir);
        if axis.norm() < 1e-9 || zero.norm() < 1e-9 || axis.normalize().dot(&zero.normalize()).abs() > 1e-6 {
            return Err("polygon.zero_dir must be non-zero and perpendicular to polygon.axis_dir".into());
        }
        if !(p.facet_errors.is_empty() || p.facet_errors.len() == p.facets as usize) {
            return Err(format!(
                "polygon.facet_errors must be empty or have {} entries, has {}",
                p.facets,
                p.facet_errors.len()
            ));
        }
        for (i, e) in p.facet_errors.iter().enumerate() {
            if !(e.tilt_deg.is_finite() && e.pitch_deg.is_finite() && e.radius_mm.is_finite()) {
                return Err(format!("polygon.facet_errors[{i}] must be finite"));
            }
        }
        if self.lasers.is_empty() {
            return Err("lasers must not be empty".into());
        }
        for (j, l) in self.lasers.iter().enumerate() {
            position(&format!("lasers[{j}].source_mm"), &l.source_mm)?;
            let d = Vector3::from(l.direction);
            let w = Vector3::from(l.fan_axis);
            if d.norm() < 1e-9 || w.norm() < 1e-9 || !d.iter().chain(w.iter()).all(|x| x.is_finite()) {
                return Err(format!("lasers[{j}]: direction and fan_axis must be finite and non-zero"));
            }
            if l.facet_offset >= p.facets {
                return Err(format!(
                    "lasers[{j}].facet_offset must be less than polygon.facets ({}), got {}",
                    p.facets, l.facet_offset
                ));
            }
            if d.normalize().dot(&w.normalize()).abs() > 1e-6 {
                return Err(format!("lasers[{j}].fan_axis must be perpendicular to lasers[{j}].direction"));
            }
        }
        Ok(())
    }
}

/// The light plane of one frame and laser, with what is needed to tell lit points from unlit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightPlane {
    /// The light plane (world frame), normal oriented with non-negative z (so that for the
    /// nominal build it reads z = slope·x + intercept).
    pub plane: Plane,
    /// The facet plane that reflected the fan.
    pub facet: Plane,
    /// Mirror image of the laser apex in the facet: the fan appears to come from here.
    pub virtual_source: Point3<f64>,
    /// Where the laser's central ray meets the facet (mm).
    pub facet_point: Point3<f64>,
    /// Reflected central ray direction (unit).
    pub out_dir: Unit<Vector3<f64>>,
    /// Whether the central ray meets the facet within its physical extent.
    pub on_facet: bool,
}

impl LightPlane {
    /// Whether `p` lies on the lit side: in the reflected fan's half-plane (in front of the
    /// virtual source along the outgoing direction) and beyond the facet.
    pub fn lights(&self, p: &Point3<f64>) -> bool {
        (p - self.facet_point).dot(&self.out_dir) > 0.0 && self.facet.signed_distance(p) > 0.0
    }

    /// Slope and intercept of the plane written as z = slope·x + intercept (mm) in the x–z
    /// plane (y ignored); meaningful for builds whose polygon axis is along y.
    pub fn slope_intercept(&self) -> (f64, f64) {
        let n = self.plane.normal;
        (-n.x / n.z, self.plane.offset / n.z)
    }
}

/// The transmitter model, precomputed from [`TransmitterParams`].
#[derive(Debug, Clone)]
pub struct Transmitter {
    params: TransmitterParams,
    axis_point: Point3<f64>,
    axis: Unit<Vector3<f64>>,
    e1: Vector3<f64>,
    e3: Vector3<f64>,
    theta: f64,
}

impl Transmitter {
    pub fn new(params: TransmitterParams) -> Result<Self, String> {
        params.validate()?;
        let axis = Unit::new_normalize(Vector3::from(params.polygon.axis_dir));
        let e1 = Vector3::from(params.polygon.zero_dir).normalize();
        let e3 = axis.cross(&e1);
        let theta = PI / params.polygon.facets as f64;
        Ok(Transmitter { axis_point: Point3::from(params.polygon.axis_point_mm), axis, e1, e3, theta, params })
    }

    pub fn params(&self) -> &TransmitterParams {
        &self.params
    }

    pub fn num_facets(&self) -> u32 {
        self.params.polygon.facets
    }

    pub fn num_lasers(&self) -> usize {
        self.params.lasers.len()
    }

    /// The scan range of one facet: α ∈ [0, 2θ) (radians).
    pub fn facet_angle(&self) -> f64 {
        2.0 * self.theta
    }

    /// [`Self::facet_angle`] in degrees as a person reads it (to 1e-9°: 30, not 29.999999999999996).
    pub fn facet_angle_deg(&self) -> f64 {
        (self.facet_angle().to_degrees() * 1e9).round() / 1e9
    }

    /// Checks a stream frame's `facet` and `alpha_deg` (as radians) against the polygon: the
    /// facet must exist (no wrapping modulo n), and α must lie within the facet's range
    /// [0, 2θ) give or take half of it (encoder offsets, rounding). The message names the field.
    pub fn check_frame(&self, alpha: f64, facet: u32) -> Result<(), String> {
        let n = self.num_facets();
        if facet >= n {
            return Err(format!("field facet: facet {facet} is not on the polygon ({n} facets, 0 to {})", n - 1));
        }
        self.check_alpha(alpha).map_err(|e| format!("field alpha_deg: {}° is {e}", alpha.to_degrees()))
    }

    /// Checks a mirror angle α (radians) against one facet's range [0, 2θ), give or take half
    /// of it (encoder offsets, rounding); the message, to follow the angle as its caller names
    /// it, says where the range is.
    pub fn check_alpha(&self, alpha: f64) -> Result<(), String> {
        let span = self.facet_angle();
        if alpha.is_finite() && alpha >= -0.5 * span && alpha <= 1.5 * span {
            Ok(())
        } else {
            Err(format!("far outside the facet's range [0, {}°)", self.facet_angle_deg()))
        }
    }

    /// Facet `k`'s plane (outward normal) when the polygon has turned by `phi` (radians).
    pub fn facet_plane(&self, k: u32, phi: f64) -> Plane {
        let p = &self.params.polygon;
        let err = p.facet_errors.get(k as usize).copied().unwrap_or_default();
        let psi = self.theta - 2.0 * self.theta * k as f64 + err.pitch_deg.to_radians();
        let tilt = err.tilt_deg.to_radians();
        let n_body = (self.e1 * psi.cos() + self.e3 * psi.sin()) * tilt.cos() + self.axis.into_inner() * tilt.sin();
        let n = Rotation3::from_axis_angle(&self.axis, phi) * n_body;
        let dist = p.circumradius_mm * self.theta.cos() + err.radius_mm;
        Plane::from_point_normal(&(self.axis_point + n * dist), &n)
    }

    /// The polygon's turn φ (radians) when the encoder reports angle `alpha` within facet `k`.
    pub fn polygon_turn(&self, alpha: f64, k: u32) -> f64 {
        alpha + 2.0 * self.theta * k as f64 + self.params.polygon.encoder_zero_deg.to_radians()
    }

    /// The light plane of laser `laser` when laser 0 faces facet `facet` at mirror angle
    /// `alpha` (radians, 0 ≤ α < 2θ nominally). `None` if the laser index is out of range or the
    /// laser runs parallel to the facet.
    pub fn light_plane(&self, alpha: f64, facet: u32, laser: usize) -> Option<LightPlane> {
        let l = self.params.lasers.get(laser)?;
        let n = self.params.polygon.facets;
        let k = (facet % n + l.facet_offset % n) % n;
        let phi = self.polygon_turn(alpha, facet % n);
        let facet_plane = self.facet_plane(k, phi);
        let src = Point3::from(l.source_mm);
        let dir = Vector3::from(l.direction).normalize();
        let fan_normal = dir.cross(&Vector3::from(l.fan_axis));
        let fan = Plane::from_point_normal(&src, &fan_normal);
        let mut plane = facet_plane.reflect_plane(&fan);
        if plane.normal.z < 0.0 {
            plane = plane.flipped();
        }
        let hit = omni_geom::intersect_ray_plane(&omni_geom::Ray::new(src, dir), &facet_plane.flipped(), 1e-9)
            .or_else(|_| omni_geom::intersect_ray_plane(&omni_geom::Ray::new(src, dir), &facet_plane, 1e-9))
            .ok()?;
        let out = facet_plane.reflect_vector(&dir);
        // The central ray hits the facet within its chord (half-length R·sin θ about the facet centre).
        let centre = facet_plane.project(&self.axis_point);
        let along_axis = (hit.point - centre).dot(&self.axis);
        let across = ((hit.point - centre) - self.axis.into_inner() * along_axis).norm();
        let on_facet = across <= self.params.polygon.circumradius_mm * self.theta.sin() + 1e-9;
        Some(LightPlane {
            plane,
            facet: facet_plane,
            virtual_source: facet_plane.reflect_point(&src),
            facet_point: hit.point,
            out_dir: Unit::new_normalize(out),
            on_facet,
        })
    }

    /// Splits an absolute polygon angle (radians, encoder reading) into (α within facet, facet).
    pub fn split_angle(&self, encoder_angle: f64) -> (f64, u32) {
        let step = 2.0 * self.theta;
        let turns = encoder_angle.rem_euclid(2.0 * PI);
        let k = ((turns / step).floor() as u32).min(self.params.polygon.facets - 1);
        (turns - k as f64 * step, k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Paper geometry in the transmitter frame: direct intersection of the laser's incident
    /// ray (slope tan 4θ through M0) with the chord P1→P2.
    fn direct_reflection_point(alpha: f64, r: f64, theta: f64) -> (f64, f64) {
        let p1 = (r * alpha.cos(), r * alpha.sin());
        let p2 = (r * (alpha + 2.0 * theta).cos(), r * (alpha + 2.0 * theta).sin());
        let m0 = (r * theta.cos() * (2.0 * theta).cos(), r * theta.cos() * (2.0 * theta).sin());
        let d = ((4.0 * theta).cos(), (4.0 * theta).sin());
        // m0 + s·d = p1 + t·(p2 − p1)
        let e = (p2.0 - p1.0, p2.1 - p1.1);
        let det = d.0 * (-e.1) - d.1 * (-e.0);
        let rhs = (p1.0 - m0.0, p1.1 - m0.1);
        let s = (rhs.0 * (-e.1) - rhs.1 * (-e.0)) / det;
        (m0.0 + s * d.0, m0.1 + s * d.1)
    }

    #[test]
    fn ideal_preset_matches_paper_closed_form() {
        let tx = Transmitter::new(TransmitterParams::paper()).unwrap();
        let (r, h, theta) = (20.0, 120.0, PI / 12.0);
        for i in 0..=60 {
            let alpha = (0.5 * i as f64).to_radians();
            let lp = tx.light_plane(alpha, 0, 0).unwrap();
            let (slope, intercept) = lp.slope_intercept();
            assert!((slope - (2.0 * alpha - 2.0 * theta).tan()).abs() < 1e-12, "slope at {i}");
            let (xa, za) = direct_reflection_point(alpha, r, theta);
            let b = za - (2.0 * alpha - 2.0 * theta).tan() * xa;
            assert!(
                (intercept - (b - h)).abs() < 1e-12 * r,
                "b at α = {}°: {} vs {}",
                0.5 * i as f64,
                intercept + h,
                b
            );
            assert!(lp.plane.normal.y.abs() < 1e-14);
        }
    }

    #[test]
    fn frames_outside_the_polygon_are_refused() {
        let tx = Transmitter::new(TransmitterParams::paper()).unwrap();
        assert!(tx.check_frame(15f64.to_radians(), 11).is_ok());
        assert!(tx.check_frame(-3f64.to_radians(), 0).is_ok(), "small excursions pass");
        let e = tx.check_frame(15f64.to_radians(), 12).unwrap_err();
        assert!(e.contains("field facet") && e.contains("12 facets"), "{e}");
        let e = tx.check_frame(95f64.to_radians(), 0).unwrap_err();
        assert!(e.contains("field alpha_deg") && e.contains("95"), "{e}");
        assert!(tx.check_frame(f64::NAN, 0).is_err());
    }

    #[test]
    fn facet_count_and_offsets_are_bounded() {
        let mut p = TransmitterParams::paper();
        p.polygon.facets = 1_000_000_000;
        let e = Transmitter::new(p).unwrap_err();
        assert!(e.contains("polygon.facets") && e.contains("360"), "{e}");
        let mut p = TransmitterParams::paper();
        p.lasers[1].facet_offset = 12;
        let e = Transmitter::new(p).unwrap_err();
        assert!(e.contains("lasers[1].facet_offset"), "{e}");
        // Places beyond any measurement are wrong numbers (a start for a fit once kept 1e308).
        let mut p = TransmitterParams::paper();
        p.polygon.axis_point_mm[0] = 1e308;
        assert!(Transmitter::new(p).unwrap_err().contains("polygon.axis_point_mm must be finite and within"));
        let mut p = TransmitterParams::paper();
        p.lasers[0].source_mm[2] = -2e9;
        assert!(Transmitter::new(p).unwrap_err().contains("lasers[0].source_mm"));
    }
}
