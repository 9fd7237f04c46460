//! Measured end to end with the true sensor files: the paper bench (plane, cylinder, sphere) is
//! rendered by the simulator at its default noise over a sweep of mirror angles, the stripes are
//! extracted by omni-vision, triangulated with the true models, cleaned by statistical outlier
//! removal only (no voxel averaging or smoothing), and measured against the scene's true
//! surfaces and by a primitive fit. Each σ must be below half the paper's (0.25 / 0.47 / 0.62 mm).

use omni_cloud::eval::compare_with_scene;
use omni_cloud::filter::statistical_outlier_mask;
use omni_cloud::fit::{ErrorStats, FitOptions, ShapeKind, fit_shape, signed_errors};
use omni_cloud::triangulate::{DEFAULT_MIN_INCIDENCE_DEG, Triangulator};
use omni_formats::stream::Frame;
use omni_geom::Point3;
use omni_simulator::{
    BenchObject, Frame16, RenderOptions, Scene, Sensor, paper_bench, render_ambient_frame, render_laser_frame,
};
use omni_vision::image_io::GrayImage;
use omni_vision::stripe::{RidgeDetector, RidgeParams};
use rayon::prelude::*;

/// Mirror angles (degrees) of a sweep in `step` degree steps over the part of the facet whose
/// light plane crosses the object: where laser 0's plane passes x = 500 mm within `z_range`
/// (mm). Frames outside would hold no stripe on the object; leaving them out keeps the test fast.
fn sweep(sensor: &Sensor, z_range: (f64, f64), step: f64) -> Vec<f64> {
    (0..(30.0 / step) as usize)
        .map(|i| 0.5 * step + step * i as f64)
        .filter(|&a| {
            let lp = sensor.transmitter.light_plane(f64::to_radians(a), 0, 0).unwrap();
            let (slope, intercept) = lp.slope_intercept();
            let z = slope * 500.0 + intercept;
            z >= z_range.0 && z <= z_range.1
        })
        .collect()
}

fn to_gray(f: Frame16) -> GrayImage {
    GrayImage { width: f.width, height: f.height, bit_depth: f.bit_depth, data: f.data }
}

struct Measured {
    points: Vec<Point3<f64>>,
    truth: ErrorStats,
    fit_sigma: f64,
    radius_error: Option<f64>,
}

fn measure(object: BenchObject, kind: ShapeKind, z_range: (f64, f64), step: f64) -> Measured {
    let sensor = Sensor::paper();
    let scene_file = paper_bench(object);
    let scene = Scene::from_file(scene_file.clone()).unwrap();
    let (w, h) = sensor.camera.image_size();
    let detector = RidgeDetector::new(w, h, sensor.camera.mirror_circle(), RidgeParams::default());
    let tri = Triangulator::new(sensor.camera.as_ref(), &sensor.transmitter, DEFAULT_MIN_INCIDENCE_DEG).unwrap();
    let opts = RenderOptions { seed: 7, ..RenderOptions::ideal() };
    // The laser-off frame of the same view, subtracted as omni-ridge does with `ambient_path`.
    let ambient = to_gray(render_ambient_frame(&sensor, &scene, &RenderOptions { seed: 8, ..opts.clone() }));
    let frames: Vec<Vec<Point3<f64>>> = sweep(&sensor, z_range, step)
        .into_par_iter()
        .enumerate()
        .map(|(seq, alpha_deg)| {
            let rendered = render_laser_frame(&sensor, &scene, alpha_deg.to_radians(), 0, &[0, 1], &opts);
            let mut img = to_gray(rendered.image);
            img.subtract_saturating(&ambient).unwrap();
            let mut frame = Frame::new(seq as u64, "sim.png", alpha_deg, 0);
            frame.stripe = Some(detector.detect(&img));
            tri.triangulate_frame(&frame).unwrap().points.iter().map(|p| Point3::from(p.xyz)).collect()
        })
        .collect();
    let n_frames = frames.len();
    let raw: Vec<Point3<f64>> = frames.into_iter().flatten().collect();
    let coords: Vec<[f64; 3]> = raw.iter().map(|p| p.coords.into()).collect();
    let keep = statistical_outlier_mask(&coords, 20, 3.0).unwrap();
    let points: Vec<Point3<f64>> = raw.iter().zip(&keep).filter(|(_, k)| **k).map(|(p, _)| *p).collect();
    let comparison = compare_with_scene(&scene_file, &points, 10.0, &FitOptions::default()).unwrap();
    let (reports, stray) = (&comparison.objects, comparison.stray);
    assert_eq!(reports.len(), 1);
    assert!(comparison.unmeasured.is_empty());
    let fit = fit_shape(kind, &points, &FitOptions::default()).unwrap();
    let inliers: Vec<Point3<f64>> = points.iter().zip(&fit.inliers).filter(|(_, k)| **k).map(|(p, _)| *p).collect();
    let fit_stats = ErrorStats::from_errors(&signed_errors(&fit.shape, &inliers)).unwrap();
    eprintln!("{object:?} fit: {:?}", fit.shape);
    eprintln!(
        "{object:?}: {} frames, {} points triangulated, {} after outlier removal, {stray} farther than 10 mm; truth: mean {:+.3} mm, σ {:.3} mm, rms {:.3}, max {:.3}; fit σ {:.3} mm ({} inliers), radius error {:?}",
        n_frames,
        raw.len(),
        points.len(),
        reports[0].errors.mean,
        reports[0].errors.std_dev,
        reports[0].errors.rms,
        reports[0].errors.max_abs,
        fit_stats.std_dev,
        inliers.len(),
        reports[0].radius_error_mm,
    );
    Measured {
        points,
        truth: reports[0].errors,
        fit_sigma: fit_stats.std_dev,
        radius_error: reports[0].radius_error_mm,
    }
}

/// `step`: the sweep's mirror-angle step (degrees); the curved objects' radii need 4× the
/// plane's frames to tell a systematic error of 0.03 mm from the scatter of one scan (±0.011 mm
/// for the cylinder, ±0.015 mm for the sphere at 0.3°, measured over six noise seeds).
fn check(object: BenchObject, kind: ShapeKind, z_range: (f64, f64), paper_sigma: f64, step: f64) {
    let m = measure(object, kind, z_range, step);
    assert!(m.points.len() > 300, "{object:?}: only {} points", m.points.len());
    assert!(m.truth.std_dev < paper_sigma / 2.0, "{object:?}: σ {} ≥ {}", m.truth.std_dev, paper_sigma / 2.0);
    assert!(m.fit_sigma < paper_sigma / 2.0, "{object:?}: fit σ {}", m.fit_sigma);
    assert!(m.truth.mean.abs() < paper_sigma / 2.0, "{object:?}: mean {}", m.truth.mean);
    // The fitted radius of a patch seen from one side trades off against the axis position, so
    // it shows a flank-to-middle difference of a few thousandths of a px threefold (measured
    // here: cylinder +0.004 mm, sphere −0.023 mm; +0.065 / +0.009 mm while the blur's pull was
    // taken as σ²κ/2 everywhere, also on the flanks where the stripe bends faster and dims).
    // The target for ideal optics: 0.03 mm.
    if let Some(r) = m.radius_error {
        assert!(r.abs() <= 0.03, "{object:?}: radius error {r}");
    }
}

#[test]
fn paper_bench_plane() {
    check(BenchObject::Plane, ShapeKind::Plane, (-90.0, 90.0), 0.49, 0.3);
}

#[test]
fn paper_bench_cylinder() {
    check(BenchObject::Cylinder, ShapeKind::Cylinder, (-110.0, 110.0), 0.93, 0.075);
}

#[test]
fn paper_bench_sphere() {
    check(BenchObject::Sphere, ShapeKind::Sphere, (-60.0, 60.0), 1.24, 0.075);
}
