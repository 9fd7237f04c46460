//! Stripe pixels → 3D points: each pixel's ray meets the light plane of its frame and laser.
//!
//! For every stripe point the camera model gives the world ray (from the single viewpoint). The
//! ray is intersected with the light plane of every laser listed in the frame's `lasers`; an
//! intersection counts only if
//! * it lies in front of the viewpoint (t > 0),
//! * the ray is not grazing: the angle between the ray and the light plane is at least
//!   `min_incidence` ([`DEFAULT_MIN_INCIDENCE_DEG`] = 5° by default). The range error caused by
//!   an angular pixel error grows as 1 / sin(incidence): ×11.5 at 5°, so points beyond that are
//!   refused rather than kept as noise;
//! * the point is lit by that laser ([`LightPlane::lights`]): in the reflected fan's half-plane,
//!   beyond the facet. A fixed light plane ([`FixedPlanes`]) has no fan or facet recorded: every
//!   point in front of the viewpoint counts as lit.
//!
//! Each laser covers its own half-space, so normally exactly one laser qualifies. If several
//! qualify (a point near the seam of a miscalibrated or unusual build), the laser whose fan
//! points most directly at the point wins: the largest cosine between the reflected central
//! ray and the direction from the fan's virtual source to the point. That is the laser for which
//! the point lies deepest inside its fan, away from the fan's edge where a real line laser is dim
//! and a point is least likely to have been lit. Ties (equal to 1e-12) go to the lower laser index.
//! Fixed planes have no fan to score: the first qualifying laser of the frame's `lasers` wins.
//!
//! A fixed plane does not depend on the frame's mirror angle or facet; those fields are not
//! checked for it.

use omni_formats::stream::{Frame, Point};
use omni_geom::{Point3, Ray, Vector2, Vector3};
use omni_model::{CameraModel, FixedPlanes, LightPlane, Transmitter, TransmitterModel};

/// Default grazing threshold (degrees): smallest accepted angle between ray and light plane.
pub const DEFAULT_MIN_INCIDENCE_DEG: f64 = 5.0;

/// The light plane of one laser in one frame, reduced to what the per-point kernel needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserPlane {
    /// Laser index (as listed in the frame's `lasers`).
    pub laser: u32,
    /// Light plane `normal · x = offset` (unit normal, mm).
    pub normal: Vector3<f64>,
    pub offset: f64,
    /// Facet plane (outward unit normal, mm): lit points are on its positive side.
    pub facet_normal: Vector3<f64>,
    pub facet_offset: f64,
    /// Where the central ray meets the facet, and the reflected central ray (unit).
    pub facet_point: Point3<f64>,
    pub out_dir: Vector3<f64>,
    /// Mirror image of the laser apex in the facet (mm).
    pub virtual_source: Point3<f64>,
    /// A fixed light plane: no facet or fan limits, every point counts as lit (the facet and
    /// fan fields are unused).
    pub unbounded: bool,
}

impl LaserPlane {
    /// From the transmitter model's light plane.
    pub fn new(laser: u32, lp: &LightPlane) -> Self {
        LaserPlane {
            laser,
            normal: lp.plane.normal.into_inner(),
            offset: lp.plane.offset,
            facet_normal: lp.facet.normal.into_inner(),
            facet_offset: lp.facet.offset,
            facet_point: lp.facet_point,
            out_dir: lp.out_dir.into_inner(),
            virtual_source: lp.virtual_source,
            unbounded: false,
        }
    }

    /// A fixed light plane `plane` (world frame, unit normal) of laser `laser`.
    pub fn fixed(laser: u32, plane: &omni_geom::Plane) -> Self {
        LaserPlane {
            laser,
            normal: plane.normal.into_inner(),
            offset: plane.offset,
            facet_normal: Vector3::zeros(),
            facet_offset: 0.0,
            facet_point: Point3::origin(),
            out_dir: Vector3::zeros(),
            virtual_source: Point3::origin(),
            unbounded: true,
        }
    }

    /// Whether `p` is lit by this laser (same test as [`LightPlane::lights`]).
    #[inline]
    pub fn lights(&self, p: &Point3<f64>) -> bool {
        self.unbounded
            || (p - self.facet_point).dot(&self.out_dir) > 0.0
                && self.facet_normal.dot(&p.coords) - self.facet_offset > 0.0
    }

    /// Cosine between the fan's central ray and the direction from the virtual source to `p`.
    #[inline]
    fn fan_centrality(&self, p: &Point3<f64>) -> f64 {
        if self.unbounded {
            return 0.0;
        }
        let d = p - self.virtual_source;
        d.dot(&self.out_dir) / d.norm().max(1e-300)
    }
}

/// Why a stripe point gave no 3D point (counted per frame).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rejections {
    /// The pixel does not see the scene through the mirror (no ray).
    pub no_ray: u64,
    /// Every candidate intersection was grazing.
    pub grazing: u64,
    /// Every candidate light plane was behind the viewpoint or the point was not lit.
    pub unlit: u64,
    /// Points for which more than one laser qualified (kept, resolved by the documented rule).
    pub ambiguous: u64,
}

impl Rejections {
    pub fn add(&mut self, o: &Rejections) {
        self.no_ray += o.no_ray;
        self.grazing += o.grazing;
        self.unlit += o.unlit;
        self.ambiguous += o.ambiguous;
    }

    /// Points that were refused (ambiguous ones are kept, not counted here).
    pub fn refused(&self) -> u64 {
        self.no_ray + self.grazing + self.unlit
    }
}

/// One accepted intersection: the point, its distance from the viewpoint and the laser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub point: Point3<f64>,
    /// Distance from the ray origin (mm).
    pub range: f64,
    pub laser: u32,
}

/// Outcome of intersecting one ray with a frame's light planes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RayOutcome {
    Hit { hit: Hit, ambiguous: bool },
    Grazing,
    Unlit,
}

/// The per-point kernel: intersects one ray with the frame's light planes and picks the laser
/// (module docs). `min_sin` = sin(minimum incidence angle). `dir` must be unit length.
#[inline]
pub fn intersect_ray(origin: &Point3<f64>, dir: &Vector3<f64>, planes: &[LaserPlane], min_sin: f64) -> RayOutcome {
    let mut best: Option<(Hit, f64)> = None;
    let mut qualified = 0u32;
    let mut any_grazing = false;
    for lp in planes {
        let denom = lp.normal.dot(dir);
        if !(denom.abs() >= min_sin) || denom == 0.0 {
            any_grazing = true;
            continue;
        }
        let t = (lp.offset - lp.normal.dot(&origin.coords)) / denom;
        if !(t > 0.0) {
            continue;
        }
        let p = origin + dir * t;
        if !lp.lights(&p) {
            continue;
        }
        qualified += 1;
        let score = if planes.len() > 1 { lp.fan_centrality(&p) } else { 0.0 };
        if best.is_none_or(|(_, s)| score > s + 1e-12) {
            best = Some((Hit { point: p, range: t, laser: lp.laser }, score));
        }
    }
    match best {
        Some((hit, _)) => RayOutcome::Hit { hit, ambiguous: qualified > 1 },
        None if any_grazing => RayOutcome::Grazing,
        None => RayOutcome::Unlit,
    }
}

/// The light planes a triangulator intersects: the polygon's swept planes or fixed ones.
#[derive(Debug, Clone, Copy)]
pub enum LightSource<'a> {
    Polygon(&'a Transmitter),
    Fixed(&'a FixedPlanes),
}

impl<'a> From<&'a Transmitter> for LightSource<'a> {
    fn from(t: &'a Transmitter) -> Self {
        LightSource::Polygon(t)
    }
}

impl<'a> From<&'a FixedPlanes> for LightSource<'a> {
    fn from(t: &'a FixedPlanes) -> Self {
        LightSource::Fixed(t)
    }
}

impl<'a> From<&'a TransmitterModel> for LightSource<'a> {
    fn from(t: &'a TransmitterModel) -> Self {
        match t {
            TransmitterModel::Polygon(p) => LightSource::Polygon(p),
            TransmitterModel::FixedPlanes(f) => LightSource::Fixed(f),
        }
    }
}

/// Triangulation of whole frames with one camera and transmitter model.
pub struct Triangulator<'a> {
    camera: &'a dyn CameraModel,
    transmitter: LightSource<'a>,
    min_sin: f64,
}

/// Points of one frame and what was refused.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FramePoints {
    pub points: Vec<Point>,
    pub rejections: Rejections,
}

impl<'a> Triangulator<'a> {
    /// `min_incidence_deg`: grazing threshold in degrees (0 < D < 90).
    pub fn new(
        camera: &'a dyn CameraModel,
        transmitter: impl Into<LightSource<'a>>,
        min_incidence_deg: f64,
    ) -> Result<Self, String> {
        if !(min_incidence_deg > 0.0 && min_incidence_deg < 90.0) {
            return Err(format!("minimum incidence must be in (0, 90) degrees, got {min_incidence_deg}"));
        }
        Ok(Triangulator { camera, transmitter: transmitter.into(), min_sin: min_incidence_deg.to_radians().sin() })
    }

    /// The light planes of the frame's listed lasers. Errors name the field at fault.
    pub fn frame_planes(&self, frame: &Frame) -> Result<Vec<LaserPlane>, String> {
        let transmitter = match self.transmitter {
            LightSource::Polygon(t) => t,
            LightSource::Fixed(f) => {
                return frame
                    .lasers
                    .iter()
                    .map(|&j| {
                        f.plane(j).map(|p| LaserPlane::fixed(j, &p)).ok_or_else(|| {
                            format!(
                                "field lasers: laser {j} has no plane in the scanner model (lasers {:?})",
                                f.lasers()
                            )
                        })
                    })
                    .collect();
            }
        };
        if !frame.alpha_deg.is_finite() {
            return Err("field alpha_deg: not a finite number".into());
        }
        let alpha = frame.alpha_deg.to_radians();
        transmitter.check_frame(alpha, frame.facet)?;
        frame
            .lasers
            .iter()
            .map(|&j| {
                if j as usize >= transmitter.num_lasers() {
                    return Err(format!(
                        "field lasers: laser {j} is not in the scanner model ({} lasers)",
                        transmitter.num_lasers()
                    ));
                }
                let lp = transmitter.light_plane(alpha, frame.facet, j as usize).ok_or_else(|| {
                    format!("laser {j}: no light plane at alpha {}° facet {}", frame.alpha_deg, frame.facet)
                })?;
                Ok(LaserPlane::new(j, &lp))
            })
            .collect()
    }

    /// Triangulates every stripe point of `frame`. A frame without a `stripe` field is an error
    /// (the stream has not been through omni-ridge); an empty stripe gives no points.
    pub fn triangulate_frame(&self, frame: &Frame) -> Result<FramePoints, String> {
        let stripe = frame.stripe.as_ref().ok_or("no `stripe` field (run omni-ridge first)")?;
        let planes = self.frame_planes(frame)?;
        let mut out = FramePoints { points: Vec::with_capacity(stripe.len()), rejections: Rejections::default() };
        if planes.is_empty() {
            return Ok(out);
        }
        for (i, sp) in stripe.iter().enumerate() {
            if !(sp.u.is_finite() && sp.v.is_finite()) {
                return Err(format!("field stripe[{i}]: not a finite number"));
            }
            let Some(ray) = self.camera.pixel_to_ray(&Vector2::new(sp.u, sp.v)) else {
                out.rejections.no_ray += 1;
                continue;
            };
            match intersect_ray(&ray.origin, &ray.dir, &planes, self.min_sin) {
                RayOutcome::Hit { hit, ambiguous } => {
                    out.rejections.ambiguous += ambiguous as u64;
                    out.points.push(Point {
                        xyz: hit.point.coords.into(),
                        laser: hit.laser,
                        range: hit.range,
                        stripe_index: i as u32,
                    });
                }
                RayOutcome::Grazing => out.rejections.grazing += 1,
                RayOutcome::Unlit => out.rejections.unlit += 1,
            }
        }
        Ok(out)
    }

    /// Triangulates a batch of precomputed rays against one frame's planes (the benchmarked
    /// kernel); appends hits to `out` and returns how many rays hit.
    pub fn triangulate_rays(&self, rays: &[Ray], planes: &[LaserPlane], out: &mut Vec<Hit>) -> usize {
        let before = out.len();
        for ray in rays {
            if let RayOutcome::Hit { hit, .. } = intersect_ray(&ray.origin, &ray.dir, planes, self.min_sin) {
                out.push(hit);
            }
        }
        out.len() - before
    }
}
