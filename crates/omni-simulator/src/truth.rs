//! Ground truth of the laser stripes: the exact 3D points and pixels of every visible stripe.
//!
//! The reflected fan of each laser is sampled in fan angle from the light plane's virtual source
//! (the laser apex mirrored in the facet); each fan ray starts where it leaves the facet, its
//! first scene hit is the lit point (so laser shadows are implied), which is kept only if it lies
//! on the lit half-plane, faces the laser and the camera, and the camera's ray through its pixel
//! sees that same point (camera occlusions). Samples are refined by bisection until neighbours
//! are at most 0.25 px apart, or a curve ends (shadow, occlusion, object edge).

use crate::render::{TruthPoint, facet_exit};
use crate::scene::Scene;
use crate::sensor::Sensor;
use omni_geom::{Point3, Vector2, Vector3};
use omni_model::LightPlane;

/// Initial fan-angle samples over the 180° fan.
const FAN_SAMPLES: usize = 2048;
/// Bisection depth limit (each level halves the fan-angle step, ~0.09° initially).
const MAX_DEPTH: u32 = 14;
/// Largest pixel distance between neighbouring samples of one curve.
const MAX_GAP_PX: f64 = 0.25;

/// Ground truth of the frame at mirror angle `alpha` (radians) on `facet` for the given lasers.
pub fn stripe_truth(sensor: &Sensor, scene: &Scene, alpha: f64, facet: u32, lasers: &[u32]) -> Vec<TruthPoint> {
    let mut out = Vec::new();
    for &laser in lasers {
        let Some(lp) = sensor.transmitter.light_plane(alpha, facet, laser as usize) else { continue };
        if !lp.on_facet {
            continue;
        }
        let fan = Fan { sensor, scene, lp, laser };
        let half = 89.5f64.to_radians();
        let phis: Vec<f64> = (0..=FAN_SAMPLES).map(|i| -half + 2.0 * half * i as f64 / FAN_SAMPLES as f64).collect();
        let samples: Vec<Option<TruthPoint>> = phis.iter().map(|&phi| fan.sample(phi)).collect();
        for i in 0..FAN_SAMPLES {
            if let Some(p) = samples[i] {
                out.push(p);
            }
            fan.refine(phis[i], samples[i], phis[i + 1], samples[i + 1], MAX_DEPTH, &mut out);
        }
        if let Some(p) = samples[FAN_SAMPLES] {
            out.push(p);
        }
    }
    out
}

struct Fan<'a> {
    sensor: &'a Sensor,
    scene: &'a Scene,
    lp: LightPlane,
    laser: u32,
}

impl Fan<'_> {
    /// The fan ray at angle `phi` (radians) from the central reflected ray, within the plane.
    fn direction(&self, phi: f64) -> Vector3<f64> {
        let out = self.lp.out_dir.into_inner();
        let side = self.lp.plane.normal.cross(&out).normalize();
        let d = out * phi.cos() + side * phi.sin();
        // Keep the direction exactly in the plane despite rounding.
        (d - self.lp.plane.normal.into_inner() * self.lp.plane.normal.dot(&d)).normalize()
    }

    fn sample(&self, phi: f64) -> Option<TruthPoint> {
        let u = self.direction(phi);
        let start = facet_exit(&self.lp, &u);
        let hit = self.scene.cast(&start, &u, 1e-6, f64::INFINITY)?;
        let p = self.lp.plane.project(&hit.point);
        if !self.lp.lights(&p) {
            return None;
        }
        let camera = self.sensor.camera.as_ref();
        let px = camera.point_to_pixel(&p)?;
        let ray = camera.pixel_to_ray(&px)?;
        // Lit side and seen side must be the same side of the surface.
        if u.dot(&hit.normal) * ray.dir.dot(&hit.normal) <= 0.0 {
            return None;
        }
        let seen = self.scene.cast(&ray.origin, &ray.dir, 1e-6, f64::INFINITY)?;
        if (seen.point - p).norm() > 1e-4 * (1.0 + (p - ray.origin).norm() * 1e-3) {
            return None;
        }
        Some(TruthPoint { xyz: p.coords.into(), pixel: [px.x, px.y], laser: self.laser })
    }

    /// Inserts samples between `a` (at `pa`) and `b` (at `pb`) until neighbours are close in the
    /// image or the depth limit is reached (a curve's end or a jump between surfaces).
    fn refine(
        &self,
        pa: f64,
        a: Option<TruthPoint>,
        pb: f64,
        b: Option<TruthPoint>,
        depth: u32,
        out: &mut Vec<TruthPoint>,
    ) {
        let needs = match (a, b) {
            (Some(a), Some(b)) => pixel_dist(&a, &b) > MAX_GAP_PX,
            (Some(_), None) | (None, Some(_)) => true,
            (None, None) => false,
        };
        if !needs || depth == 0 {
            return;
        }
        let pm = 0.5 * (pa + pb);
        let m = self.sample(pm);
        self.refine(pa, a, pm, m, depth - 1, out);
        if let Some(m) = m {
            out.push(m);
        }
        self.refine(pm, m, pb, b, depth - 1, out);
    }
}

fn pixel_dist(a: &TruthPoint, b: &TruthPoint) -> f64 {
    (Vector2::from(a.pixel) - Vector2::from(b.pixel)).norm()
}

/// Splits ground truth into curves: a new curve starts at a change of laser or where
/// neighbouring samples are more than 2 px apart.
pub fn truth_polylines(truth: &[TruthPoint]) -> Vec<Vec<TruthPoint>> {
    let mut lines: Vec<Vec<TruthPoint>> = Vec::new();
    for p in truth {
        match lines.last_mut() {
            Some(line) if line.last().is_some_and(|q| q.laser == p.laser && pixel_dist(q, p) <= 2.0) => line.push(*p),
            _ => lines.push(vec![*p]),
        }
    }
    lines
}

/// The world point of a truth sample.
pub fn truth_point(t: &TruthPoint) -> Point3<f64> {
    Point3::from(t.xyz)
}
