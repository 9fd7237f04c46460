//! The ordinary-camera models (pinhole, fisheye): fitted to exact synthetic corners with noise,
//! and the model check against Mei on a lens they cannot follow.

use super::*;
use omni_geom::rng::SplitMix64;
use omni_model::{CameraModel, FisheyeCamera, PinholeCamera};

/// A wide-angle pinhole lens as OpenCV fits the hand-held laser set's camera (docs/DECISIONS.md).
pub(crate) fn pinhole_truth() -> PinholeParams {
    PinholeParams {
        fx_px: 740.3,
        fy_px: 740.9,
        cx_px: 668.2,
        cy_px: 313.6,
        k1: -0.3275,
        k2: 0.1156,
        k3: -0.0192,
        p1: -5.6e-4,
        p2: 5.4e-4,
        width: 1280,
        height: 720,
        viewpoint_mm: [0.0; 3],
    }
}

/// The same set's cv::fisheye fit.
pub(crate) fn fisheye_truth() -> FisheyeParams {
    FisheyeParams {
        fx_px: 725.95,
        fy_px: 726.3,
        cx_px: 673.5,
        cy_px: 308.6,
        k1: -0.0352,
        k2: -0.0203,
        k3: 0.0323,
        k4: -0.0158,
        width: 1280,
        height: 720,
        viewpoint_mm: [0.0; 3],
    }
}

/// `count` boards of 9 × 6 corners (5 mm) 40-90 mm in front of the camera (it looks along −z),
/// turned up to ±35°, spread over the image; only whole boards are kept. Gaussian noise `sigma`
/// px per coordinate.
fn boards_in_front(cam: &dyn CameraModel, count: usize, sigma: f64, seed: u64) -> Vec<Observation> {
    let mut rng = SplitMix64::new(seed);
    let mut out = Vec::new();
    while out.len() < count {
        let depth = 40.0 + 50.0 * rng.uniform();
        let centre = Vector3::new((rng.uniform() - 0.5) * 1.4 * depth, (rng.uniform() - 0.5) * 0.8 * depth, -depth);
        let tilt = nalgebra::UnitQuaternion::from_euler_angles(
            (rng.uniform() - 0.5) * 70f64.to_radians(),
            (rng.uniform() - 0.5) * 70f64.to_radians(),
            rng.uniform() * std::f64::consts::TAU,
        );
        let rot = tilt * nalgebra::UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0);
        let t = centre - rot * Vector3::new(20.0, 12.5, 0.0);
        let pose = Isometry3::from_parts(nalgebra::Translation3::from(t), rot);
        let mut obs = Observation { name: format!("board{}", out.len()), board_mm: vec![], pixels: vec![] };
        for j in 0..6 {
            for i in 0..9 {
                let xy = [i as f64 * 5.0, j as f64 * 5.0];
                if let Some(px) = cam.point_to_pixel(&(pose * Point3::new(xy[0], xy[1], 0.0))) {
                    obs.board_mm.push(xy);
                    obs.pixels.push([px.x + sigma * rng.normal(), px.y + sigma * rng.normal()]);
                }
            }
        }
        if obs.pixels.len() == 54 {
            out.push(obs);
        }
    }
    out
}

/// Largest angle (deg) between the rays of two cameras within 300 px of the image centre
/// (covered by the boards), after the best common rotation: a small turn of the camera is
/// nearly a shift of the principal point, which the board poses cannot tell apart.
fn worst_ray_deg(a: &dyn CameraModel, b: &dyn CameraModel) -> f64 {
    validate::ray_difference_deg(a, b, [639.5, 359.5], 0.0, 300.0).unwrap().1
}

#[test]
fn pinhole_and_fisheye_fits_recover_their_cameras() {
    let cases: [(ModelKind, Box<dyn CameraModel>); 2] = [
        (ModelKind::Pinhole, Box::new(PinholeCamera::new(pinhole_truth()).unwrap())),
        (ModelKind::Fisheye, Box::new(FisheyeCamera::new(fisheye_truth()).unwrap())),
    ];
    for (model, truth) in cases {
        let obs = boards_in_front(truth.as_ref(), 15, 0.1, 34);
        let cal = calibrate(1280, 720, &obs, &Options { model, ..Default::default() }).unwrap();
        let fitted = cal.spec.build().unwrap();
        let rays = worst_ray_deg(truth.as_ref(), fitted.as_ref());
        let check = cal.model_check.unwrap();
        eprintln!(
            "{model:?}: rms {:.4} px per corner, rays within {rays:.4}°, Mei {:.4} px; {:?}",
            cal.rms_per_corner_px(),
            check.mei_rms_px,
            cal.params
        );
        assert_eq!(cal.images.iter().filter(|i| i.used).count(), 15);
        // 0.1 px per coordinate: 0.141 per corner less what the fit absorbs.
        assert!(cal.rms_per_corner_px() > 0.11 && cal.rms_per_corner_px() < 0.15, "{}", cal.rms_per_corner_px());
        assert!(rays < 0.02, "{model:?}: rays off the truth by {rays}°");
        assert!((cal.params[0] / truth_focal(&cal.spec) - 1.0).abs() < 1e-9);
        assert!(validate::warnings(&cal, &Options { model, ..Default::default() }).is_empty());
    }
}

/// fx of the fitted spec (the check above only ties `params` to the spec).
fn truth_focal(spec: &CameraSpec) -> f64 {
    match spec {
        CameraSpec::Pinhole(p) => p.fx_px,
        CameraSpec::Fisheye(p) => p.fx_px,
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_lens_the_pinhole_cannot_follow_is_named_by_the_model_check() {
    // The wide-angle fisheye lens seen by boards out to its corners: Kalibr's 4-coefficient
    // radtan cannot follow it, the Mei fit can.
    let truth = FisheyeCamera::new(fisheye_truth()).unwrap();
    let obs = boards_in_front(&truth, 15, 0.1, 35);
    let opts = Options { model: ModelKind::PinholeRadtan, ..Default::default() };
    let cal = calibrate(1280, 720, &obs, &opts).unwrap();
    let check = cal.model_check.unwrap();
    eprintln!("pinhole-radtan on a fisheye lens: {:.3} px, Mei {:.3} px", check.model_rms_px, check.mei_rms_px);
    assert!(check.ratio() > validate::MODEL_CHECK_RATIO, "{check:?}");
    let w = validate::warnings(&cal, &opts);
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("the pinhole-radtan model leaves") && w[0].contains("use --model mei or --model fisheye"));
    assert!(cal.param_names.iter().all(|n| n != "k3"), "Kalibr's radtan has no k3: {:?}", cal.param_names);
}
