//! Triangulation against exact synthetic data: truth points on the light planes of the paper
//! build are projected with the true camera, then triangulated back.

use omni_cloud::rng::SplitMix64;
use omni_cloud::triangulate::{DEFAULT_MIN_INCIDENCE_DEG, Triangulator};
use omni_formats::stream::{Frame, StripePoint};
use omni_geom::{Point3, Vector2};
use omni_model::{CameraModel, HyperbolicCamera, HyperbolicParams, Transmitter, TransmitterParams};

struct Truth {
    point: Point3<f64>,
    laser: u32,
    /// sin of the angle between the viewing ray and the light plane.
    sin_incidence: f64,
}

fn sensor() -> (HyperbolicCamera, Transmitter) {
    (HyperbolicCamera::new(HyperbolicParams::paper()).unwrap(), Transmitter::new(TransmitterParams::paper()).unwrap())
}

/// Visible, lit points on both lasers' light planes of one frame, with their exact pixels.
fn truth_frame(
    cam: &HyperbolicCamera,
    tx: &Transmitter,
    alpha_deg: f64,
    facet: u32,
    far_mm: f64,
) -> (Frame, Vec<Truth>) {
    let mut frame = Frame::new(0, "f.png", alpha_deg, facet);
    let mut stripe = Vec::new();
    let mut truth = Vec::new();
    let f = cam.viewpoint();
    for laser in 0..2u32 {
        let lp = tx.light_plane(alpha_deg.to_radians(), facet, laser as usize).unwrap();
        let across = lp.plane.normal.cross(&lp.out_dir).normalize();
        for i in 0..40 {
            for k in 0..25 {
                let s = 150.0 + (far_mm - 150.0) * i as f64 / 39.0;
                let w = -1500.0 + 3000.0 * k as f64 / 24.0;
                let p = lp.facet_point + lp.out_dir.into_inner() * s + across * w;
                if !lp.lights(&p) {
                    continue;
                }
                let Some(px) = cam.point_to_pixel(&p) else { continue };
                let dir = (p - f).normalize();
                stripe.push(StripePoint { u: px.x, v: px.y, intensity: 200.0, width: 3.0, quality: 0 });
                truth.push(Truth { point: p, laser, sin_incidence: lp.plane.normal.dot(&dir).abs() });
            }
        }
    }
    frame.stripe = Some(stripe);
    (frame, truth)
}

#[test]
fn exact_pixels_triangulate_to_the_truth_within_1e9_mm_with_the_right_laser() {
    let (cam, tx) = sensor();
    let tri = Triangulator::new(&cam, &tx, DEFAULT_MIN_INCIDENCE_DEG).unwrap();
    let min_sin = DEFAULT_MIN_INCIDENCE_DEG.to_radians().sin();
    let (mut checked, mut worst) = (0, 0.0f64);
    for (alpha_deg, facet) in [(1.0, 0), (7.5, 3), (15.0, 6), (22.25, 11), (29.5, 1)] {
        let (frame, truth) = truth_frame(&cam, &tx, alpha_deg, facet, 3000.0);
        let out = tri.triangulate_frame(&frame).unwrap();
        let expected: Vec<usize> = (0..truth.len()).filter(|&i| truth[i].sin_incidence >= min_sin).collect();
        assert_eq!(out.points.len(), expected.len(), "α = {alpha_deg}: {:?}", out.rejections);
        assert_eq!(out.rejections.ambiguous, 0);
        for p in &out.points {
            let t = &truth[p.stripe_index as usize];
            let err = (Point3::from(p.xyz) - t.point).norm();
            worst = worst.max(err);
            assert!(err < 1e-9, "α = {alpha_deg}: error {err} mm at {:?}", t.point);
            assert_eq!(p.laser, t.laser);
            let range = (t.point - cam.viewpoint()).norm();
            assert!((p.range - range).abs() < 1e-9);
            checked += 1;
        }
    }
    assert!(checked > 2000, "only {checked} points checked");
    eprintln!("exact triangulation: {checked} points, worst error {worst:.2e} mm");
}

#[test]
fn grazing_rays_are_refused_at_the_documented_threshold() {
    let (cam, tx) = sensor();
    let (frame, truth) = truth_frame(&cam, &tx, 10.0, 2, 12_000.0);
    for min_deg in [2.0, 5.0, 10.0] {
        let tri = Triangulator::new(&cam, &tx, min_deg).unwrap();
        let out = tri.triangulate_frame(&frame).unwrap();
        let min_sin = min_deg.to_radians().sin();
        let grazing = truth.iter().filter(|t| t.sin_incidence < min_sin).count();
        assert!(grazing > 10, "test needs grazing rays at {min_deg}°");
        assert_eq!(out.rejections.grazing as usize, grazing, "at {min_deg}°");
        assert_eq!(out.points.len(), truth.len() - grazing);
    }
    assert!(Triangulator::new(&cam, &tx, 0.0).is_err());
    assert!(Triangulator::new(&cam, &tx, f64::NAN).is_err());
}

#[test]
fn pixel_noise_propagates_as_linear_theory_predicts() {
    // σ = 0.25 px of centre noise: the normalised range errors (error / predicted σ, with the
    // prediction from the pixel→range derivative) must have mean ≈ 0 and std ≈ 1.
    let (cam, tx) = sensor();
    let tri = Triangulator::new(&cam, &tx, DEFAULT_MIN_INCIDENCE_DEG).unwrap();
    let (frame, truth) = truth_frame(&cam, &tx, 18.0, 4, 2500.0);
    let clean = tri.triangulate_frame(&frame).unwrap().points;
    let stripe = frame.stripe.clone().unwrap();
    let sigma_px = 0.25;
    let range_of = |u: f64, v: f64, laser: u32| -> Option<f64> {
        let ray = cam.pixel_to_ray(&Vector2::new(u, v))?;
        let lp = tx.light_plane(18f64.to_radians(), 4, laser as usize)?;
        let t = (lp.plane.offset - lp.plane.normal.dot(&ray.origin.coords)) / lp.plane.normal.dot(&ray.dir);
        Some(t)
    };
    let mut rng = SplitMix64::new(42);
    let mut z = Vec::new();
    for p in &clean {
        let sp = stripe[p.stripe_index as usize];
        let h = 1e-3;
        let (Some(up), Some(um), Some(vp), Some(vm)) = (
            range_of(sp.u + h, sp.v, p.laser),
            range_of(sp.u - h, sp.v, p.laser),
            range_of(sp.u, sp.v + h, p.laser),
            range_of(sp.u, sp.v - h, p.laser),
        ) else {
            continue;
        };
        let sigma_range = sigma_px * (((up - um) / (2.0 * h)).powi(2) + ((vp - vm) / (2.0 * h)).powi(2)).sqrt();
        for _ in 0..20 {
            let mut f = frame.clone();
            let noisy = StripePoint { u: sp.u + rng.normal() * sigma_px, v: sp.v + rng.normal() * sigma_px, ..sp };
            f.stripe = Some(vec![noisy]);
            if let Some(q) = tri.triangulate_frame(&f).unwrap().points.first() {
                z.push((q.range - p.range) / sigma_range);
            }
        }
    }
    assert!(z.len() > 5000, "{}", z.len());
    let n = z.len() as f64;
    let mean = z.iter().sum::<f64>() / n;
    let std = (z.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    eprintln!("normalised range error over {} samples: mean {mean:.4}, std {std:.4}", z.len());
    assert!(mean.abs() < 0.05 && (std - 1.0).abs() < 0.05, "mean {mean}, std {std}");
    assert_eq!(truth.len(), stripe.len());
}

#[test]
fn bad_frames_are_errors_naming_the_field() {
    let (cam, tx) = sensor();
    let tri = Triangulator::new(&cam, &tx, DEFAULT_MIN_INCIDENCE_DEG).unwrap();
    let frame = Frame::new(3, "f.png", 10.0, 0);
    assert!(tri.triangulate_frame(&frame).unwrap_err().contains("stripe"));
    let mut f = frame.clone();
    f.stripe = Some(vec![StripePoint { u: f64::NAN, v: 1.0, intensity: 1.0, width: 1.0, quality: 0 }]);
    assert!(tri.triangulate_frame(&f).unwrap_err().contains("stripe[0]"));
    let mut f = frame.clone();
    f.stripe = Some(vec![]);
    f.lasers = vec![0, 5];
    assert!(tri.triangulate_frame(&f).unwrap_err().contains("lasers"));
    // Laser-off frame and a pixel outside the mirror: no points, no error.
    let mut f = frame.clone();
    f.stripe = Some(vec![StripePoint { u: 1.0, v: 1.0, intensity: 1.0, width: 1.0, quality: 0 }]);
    let out = tri.triangulate_frame(&f).unwrap();
    assert_eq!((out.points.len(), out.rejections.no_ray), (0, 1));
    f.lasers = vec![];
    assert!(tri.triangulate_frame(&f).unwrap().points.is_empty());
}

/// A fixed light plane: exact pixels of points on it triangulate back to them whatever the
/// frame's mirror angle and facet; a laser without a plane is an error naming it.
#[test]
fn fixed_plane_pixels_triangulate_to_the_truth() {
    use omni_model::{FixedPlaneParams, FixedPlanes, FixedPlanesParams, TransmitterModel};
    let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
    // A plane tilted 30° from vertical, 300 mm out along +x.
    let normal = omni_geom::Vector3::new(30f64.to_radians().cos(), 0.0, 30f64.to_radians().sin());
    let params = FixedPlanesParams {
        planes: vec![FixedPlaneParams { laser: 2, normal: [normal.x, normal.y, normal.z], distance_mm: 300.0 }],
    };
    let model = TransmitterModel::FixedPlanes(FixedPlanes::new(params).unwrap());
    let tri = Triangulator::new(&cam, &model, DEFAULT_MIN_INCIDENCE_DEG).unwrap();
    let (e1, e2) = omni_geom::fit::orthonormal_basis(&normal);
    let mut frame = Frame::new(0, "f.png", 123.0, 77);
    frame.lasers = vec![2];
    let mut truth = Vec::new();
    let mut stripe = Vec::new();
    for i in -10..=10 {
        for k in -3..=3 {
            let p = Point3::from(normal * 300.0 + e1 * (20.0 * i as f64) + e2 * (20.0 * k as f64));
            let Some(px) = cam.point_to_pixel(&p) else { continue };
            stripe.push(StripePoint { u: px.x, v: px.y, intensity: 200.0, width: 3.0, quality: 0 });
            truth.push(p);
        }
    }
    assert!(truth.len() > 100, "{}", truth.len());
    frame.stripe = Some(stripe);
    let out = tri.triangulate_frame(&frame).unwrap();
    assert_eq!(out.points.len(), truth.len(), "{:?}", out.rejections);
    for p in &out.points {
        let t = truth[p.stripe_index as usize];
        let err = (Point3::from(p.xyz) - t).norm();
        assert!(err < 1e-6 && p.laser == 2, "point {} off by {err} mm", p.stripe_index);
    }
    frame.lasers = vec![0];
    let e = tri.triangulate_frame(&frame).unwrap_err();
    assert!(e.contains("field lasers: laser 0 has no plane"), "{e}");
}
