//! The fixed light plane on the virtual sensor, rendered (issue 34's virtual target): the paper's
//! polygon sensor with its motor stopped is a sensor with one fixed light plane. Its frames are
//! rendered by the simulator with a real-shaped stripe (`SheetProfile::real`) over a checkerboard
//! in a lit room, written as colour PNG files and read back by the same code
//! `omni-calib-plane fixed` runs: the corners by omni-vision's detector, the stripe by
//! omni-ridge's on the red laser contrast, the plane by `omni_calib::fixed_plane`. The receiver
//! calibration is the true camera model.

use nalgebra::{Rotation3, Translation3};
use omni_calib::fixed_plane::{DetectOptions, FixedPlaneFit, FixedPlaneOptions, detect_frames, fit_fixed_plane};
use omni_formats::BoardFile;
use omni_formats::scene::SceneFile;
use omni_geom::rng::SplitMix64;
use omni_geom::{Isometry3, Plane, Point3, UnitQuaternion, Vector3};
use omni_simulator::{ColourOutput, RenderOptions, Scene, Sensor, board_object, render_laser_frame};
use std::path::PathBuf;

/// The mirror angle at which the polygon is stopped (radians), facet 0, laser 0: the central ray
/// leaves the facet about 16° upwards, so boards 200-400 mm out along it stay in the mirror's view.
const ALPHA: f64 = 0.4;

/// A board in front of the stopped sensor: `cols` × `rows` inner corners of `square` mm.
struct Setup {
    sensor: Sensor,
    board: BoardFile,
    /// The true light plane (world frame, offset ≥ 0).
    plane: Plane,
}

fn setup(width: u32, cols: u32, rows: u32, square: f64) -> Setup {
    let sensor = if width == 1024 { Sensor::paper() } else { Sensor::paper_scaled(width) };
    let lp = sensor.transmitter.light_plane(ALPHA, 0, 0).expect("laser 0");
    assert!(lp.on_facet);
    let plane = if lp.plane.offset < 0.0 { lp.plane.flipped() } else { lp.plane };
    Setup { sensor, board: BoardFile::new(cols, rows, square), plane }
}

/// `n` board poses 200-400 mm from the camera axis, at azimuths within ±25° of the laser's
/// direction (+x), each centred on the light plane give or take a quarter of its height, facing
/// the viewpoint within ±20° and turned by up to ±25° about its normal.
fn poses(s: &Setup, n: usize, rng: &mut SplitMix64) -> Vec<Isometry3<f64>> {
    let viewpoint = Point3::new(0.0, 0.0, 80.0);
    let (cols, rows, sq) = (s.board.inner_cols as f64, s.board.inner_rows as f64, s.board.square_mm);
    (0..n)
        .map(|k| {
            let d = 200.0 + 200.0 * k as f64 / (n - 1) as f64;
            let azimuth = (rng.uniform() - 0.5) * 50f64.to_radians();
            let (x, y) = (d * azimuth.cos(), d * azimuth.sin());
            let nrm = s.plane.normal;
            let z = (s.plane.offset - nrm.x * x - nrm.y * y) / nrm.z;
            // Board frame: z into the board (away from the viewpoint), x along the columns
            // (horizontal), y down the rows.
            let zb = (Point3::new(x, y, z) - viewpoint).normalize();
            let xb = Vector3::z().cross(&zb).normalize();
            let yb = zb.cross(&xb);
            let facing = Rotation3::from_basis_unchecked(&[xb, yb, zb]);
            let tilt = UnitQuaternion::from_euler_angles(
                (rng.uniform() - 0.5) * 40f64.to_radians(),
                (rng.uniform() - 0.5) * 40f64.to_radians(),
                (rng.uniform() - 0.5) * 50f64.to_radians(),
            );
            let rotation = UnitQuaternion::from_rotation_matrix(&facing) * tilt;
            let shift = (rng.uniform() - 0.5) * 0.5 * (rows - 1.0) * sq;
            let centre = Point3::new(x, y, z) + rotation * Vector3::new(0.0, shift, 0.0);
            let half = rotation * Vector3::new((cols - 1.0) * sq / 2.0, (rows - 1.0) * sq / 2.0, 0.0);
            Isometry3::from_parts(Translation3::from(centre.coords - half), rotation)
        })
        .collect()
}

/// The plane fitted from one detector's points, and from the same points moved onto the true
/// stripe: what the detector's errors cost, apart from which points it found.
struct Fits {
    detected: FixedPlaneFit,
    snapped: FixedPlaneFit,
}

/// Each stripe point within 1.5 px of the true stripe `truth` (its samples, about ¼ px apart)
/// moved onto the nearest of them.
fn snapped_onto(stripe: &mut [[f64; 2]], truth: &[[f64; 2]]) {
    let distance2 = |a: &[f64; 2], b: &[f64; 2]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    for p in stripe {
        if let Some(q) = truth.iter().min_by(|a, b| distance2(a, p).total_cmp(&distance2(b, p)))
            && distance2(q, p) <= 1.5 * 1.5
        {
            *p = *q;
        }
    }
}

/// Renders the frames (colour PNG in `dir`) and fits the plane from them as
/// `omni-calib-plane fixed --laser red` does, once per laser profile given, each also with its
/// points snapped onto the true stripe; also fits it with the same corners but the true stripe
/// pixels (every 4th truth sample, ≈ 1 px apart) in place of the detected ones.
fn render_and_fit(
    s: &Setup,
    opts: &RenderOptions,
    n: usize,
    seed: u64,
    dir: &std::path::Path,
    laser_profiles: &[Option<omni_model::LaserProfile>],
) -> (Vec<Fits>, FixedPlaneFit) {
    let mut rng = SplitMix64::new(seed);
    let t0 = std::time::Instant::now();
    let mut truth = Vec::new();
    let mut every_sample = Vec::new();
    let paths: Vec<PathBuf> = poses(s, n, &mut rng)
        .iter()
        .enumerate()
        .map(|(k, pose)| {
            let scene = Scene::from_file(SceneFile::new(vec![board_object(&s.board, pose)])).unwrap();
            let frame = render_laser_frame(&s.sensor, &scene, ALPHA, 0, &[0], opts);
            truth.push(frame.truth.iter().step_by(4).map(|t| t.pixel).collect::<Vec<_>>());
            every_sample.push(frame.truth.iter().map(|t| t.pixel).collect::<Vec<_>>());
            let rgb = frame.colour.expect("RGB frame");
            let path = dir.join(format!("f{k}.png"));
            std::fs::write(&path, rgb.encode(omni_simulator::FrameFormat::Png).unwrap()).unwrap();
            path
        })
        .collect();
    eprintln!("rendered {n} frames in {:.2} s", t0.elapsed().as_secs_f64());
    let t0 = std::time::Instant::now();
    let detect = |laser_profile| DetectOptions {
        inner_cols: s.board.inner_cols,
        inner_rows: s.board.inner_rows,
        square_mm: s.board.square_mm,
        min_corners: 12,
        colour: omni_vision::colour::ColourSpec {
            channel: omni_vision::colour::Channel::Laser(omni_vision::colour::Colour::Red),
            bayer: None,
            sites: false,
        },
        // The lens's blur known, as `omni-calib-plane fixed` takes it from the camera's optics.
        ridge: omni_vision::stripe::RidgeParams {
            optics_blur_px: Some(opts.imaging.psf_sigma_px()),
            laser_profile,
            ..Default::default()
        },
    };
    // As `omni-calib-plane fixed` does: points on the board's white border kept (the board file's
    // margin_mm, one square here), points within 3 px of a square's edge or the board's own edge
    // dropped. A board whose stripe runs along a row of squares keeps few points then: 10 make a
    // frame here.
    let opts = FixedPlaneOptions {
        square_mm: s.board.square_mm,
        margin_mm: s.board.margin_mm,
        edge_clearance_px: 3.0,
        min_points: 10,
        ..Default::default()
    };
    let mut fits = Vec::new();
    let mut frames = Vec::new();
    for &profile in laser_profiles {
        frames = detect_frames(&paths, &detect(profile), None).unwrap();
        let detected = fit_fixed_plane(s.sensor.camera.as_ref(), &frames, &opts).unwrap();
        let mut on_truth = frames.clone();
        for (f, t) in on_truth.iter_mut().zip(&every_sample) {
            snapped_onto(&mut f.stripe, t);
        }
        let snapped = fit_fixed_plane(s.sensor.camera.as_ref(), &on_truth, &opts).unwrap();
        fits.push(Fits { detected, snapped });
    }
    eprintln!("detected and fitted in {:.2} s", t0.elapsed().as_secs_f64());
    let mut true_stripe = frames;
    for (f, t) in true_stripe.iter_mut().zip(truth) {
        f.stripe = t;
    }
    (fits, fit_fixed_plane(s.sensor.camera.as_ref(), &true_stripe, &opts).unwrap())
}

/// The fitted plane against the true one: the normals' angle (degrees) and the largest distance
/// along the normal (mm) between the two planes at 300 mm from the camera axis, where the stripe
/// runs ahead of the laser and 50 mm to either side along it.
fn errors(s: &Setup, fit: &FixedPlaneFit) -> (f64, f64) {
    let angle = fit.plane.normal.angle(&s.plane.normal).to_degrees();
    let worst = [-50.0f64, 0.0, 50.0]
        .iter()
        .map(|y| {
            let x = (300.0f64 * 300.0 - y * y).sqrt();
            let n = s.plane.normal;
            let p = Point3::new(x, *y, (s.plane.offset - n.x * x - n.y * y) / n.z);
            fit.plane.signed_distance(&p).abs()
        })
        .fold(0.0f64, f64::max);
    (angle, worst)
}

fn report(label: &str, s: &Setup, fit: &FixedPlaneFit) -> (f64, f64) {
    let r = &fit.report;
    let (angle, worst) = errors(s, fit);
    eprintln!(
        "{label}: normal off by {angle:.4}°, plane off by {worst:.4} mm at 300 mm; {} frames, rms {:.4} mm, loo {:.4} mm, sigma {:.4}° (jackknife)",
        r.frames.len(),
        r.rms_mm,
        r.leave_one_out_rms_mm,
        r.plane.jackknife_normal_sigma_deg
    );
    for f in &r.frames {
        eprintln!(
            "  {}: {} corners {:.3} px, {:.0} mm, {} of {} stripe points on the board, {} inliers, mean {:.4} mm",
            f.name,
            f.corners,
            f.corner_rms_px,
            f.board_distance_mm,
            f.board_points,
            f.stripe_points,
            f.inliers,
            f.residual_mean_mm
        );
    }
    for k in &r.skipped {
        eprintln!("  skipped {}: {}", k.name, k.reason);
    }
    (angle, worst)
}

/// The idealised sensor (Gaussian PSF σ 0.7 px, photon and read noise) through a colour camera
/// (RGB, no mosaic) in a room lit for the board (white ≈ 105 of 255) whose light the camera is
/// white-balanced for: the default warm room makes every white square a faint red bar, which at
/// 12-25 px the stripe detector's coarse scales take for a stripe. The laser's real-shaped stripe
/// is 4 px wide (FWHM) and peaks at about 150 of 255 above the white squares in R − (G+B)/2.
fn options() -> RenderOptions {
    let mut o = RenderOptions { ambient_e: 6000.0, seed: 34, ..RenderOptions::ideal() }
        .with_real_stripe(4.0)
        .with_colour(None, ColourOutput::Rgb);
    o.laser_strength *= 0.4;
    let c = o.colour.as_mut().expect("colour camera");
    c.ambient_rgb = [c.ambient_rgb[1] / c.white_balance[0], c.ambient_rgb[1], c.ambient_rgb[1] / c.white_balance[2]];
    o
}

/// Issue 34's virtual target, 0.02° and 0.05 mm at 300 mm from 10 frames, over five scenes (seeds
/// 34, 1-4: board poses and photon noise; the idealised sensor has no speckle). The chain up to the
/// stripe meets it: with the detected corners and the true stripe pixels the plane comes back
/// within 0.012° and 0.011 mm (one scene 0.021° on one of six noise draws), and so it does from the
/// detector's own points moved onto the true stripe (asserted): which points it finds, and how
/// many, do not limit the plane. With omni-ridge's stripe points as found (the lens's blur known,
/// as from a camera file's optics) it does not: 0.007-0.025° and 0.065-0.084 mm. Their offset
/// towards the real profile's tail, about 0.05 px at 1.9 mm per px, moves the plane; how that
/// offset differs from frame to frame tilts it (a uniform shift of 0.05 px moves the snapped
/// points' plane by 0.07-0.08 mm and leaves its normal within 0.01°). The board's squares cut the
/// stripe into pieces too short for their top's shape to be told from noise, so only the profiles'
/// tops, not the light's peak under the blur, are found; and half the stripe points are clipped in
/// the red, where a plateau's centre lies towards the tail (docs/DECISIONS.md). Without the 3 px
/// clearance from the squares' edges (where the stripe's profile falls on white and black at once,
/// its centres scatter by 0.35-0.76 px) the seeds spread over 0.018-0.17° and 0.021-0.35 mm. With
/// the laser's cross-section known (`--laser-tail 0.17,4`) the unclipped pieces are led from their
/// tops to the sheet's peak by it, and the clipped ones from their plateau's centre by its edges'
/// distance against the width of the stripe's unclipped profiles on the black squares nearby:
/// 0.009-0.018° and 0.008-0.036 mm (0.006-0.019° and 0.013-0.043 mm when every piece was led from
/// its tops alone, before the windowed centroid's own offset was predicted). Over six draws of the
/// photon noise the five scenes' RMS ran 0.014-0.017° with the profile (0.008-0.016° without),
/// single scenes up to 0.023° (jackknife σ 0.011-0.025°): the target holds as the scenes' RMS, not
/// scene by scene. Asserted: each scene within 0.03° (0.045° without the profile, 0.03° from the
/// true stripe), the scenes' RMS within 0.02° (0.03°, 0.02°). The frames' mean offsets still differ
/// from frame to frame, and each frame weighs by its stripe's own scatter about its line
/// (docs/DECISIONS.md). The stripe on the board's white border (one square wide) counts, as
/// `omni-calib-plane fixed` takes it from the board file: without it the normals reached 0.028°.
/// Every frame's board is posed from its corners, and a partial board whose corners fit at 0.39 px
/// (the others 0.03-0.05) weighs little in the fit, so no frame pulls the plane: leave-one-out RMS
/// 1.01-1.08 × the in-sample one. The bounds guard these figures.
#[test]
fn rendered_fixed_plane_from_10_frames_through_the_detectors() {
    let s = setup(1024, 7, 5, 30.0);
    let profiles = [None, Some(omni_model::LaserProfile::tailed(0.17, 4.0))];
    // Per profile, each scene's (normal off (°), plane off (mm)).
    let mut per_profile: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
    let mut true_stripe_deg = Vec::new();
    for seed in [34, 1, 2, 3, 4] {
        let dir = tempfile::tempdir().unwrap();
        let opts = RenderOptions { seed, ..options() };
        let (fits, true_stripe) = render_and_fit(&s, &opts, 10, seed, dir.path(), &profiles);
        let (angle, worst) = report(&format!("seed {seed}, true stripe pixels, detected corners"), &s, &true_stripe);
        assert!(true_stripe.report.frames.len() >= 9, "{:?}", true_stripe.report.skipped);
        assert!(angle <= 0.03, "seed {seed}: normal off by {angle}° with the true stripe");
        true_stripe_deg.push(angle);
        assert!(worst <= 0.05, "seed {seed}: plane off by {worst} mm at 300 mm with the true stripe");
        for ((fits, profile), scenes) in fits.iter().zip(profiles).zip(&mut per_profile) {
            let label = if profile.is_some() { "laser profile known" } else { "rendered, real-shaped 4 px stripe" };
            let label = format!("seed {seed}, {label}");
            let (angle, worst) =
                report(&format!("{label}, its points snapped onto the true stripe"), &s, &fits.snapped);
            assert!(angle <= 0.02 && worst <= 0.05, "{label}, snapped: {angle}°, {worst} mm");
            let fit = &fits.detected;
            let (angle, worst) = report(&label, &s, fit);
            let r = &fit.report;
            assert!(r.frames.len() >= 9, "{label}: {} frames used", r.frames.len());
            let mut points: Vec<usize> = r.frames.iter().map(|f| f.board_points).collect();
            points.sort_unstable();
            assert!(points[points.len() / 2] >= 20, "{label}: stripe points per frame {points:?}");
            // Each scene's normal within 1.5 × the target (the fit's jackknife σ is 0.015-0.025°),
            // the scenes' RMS within it (below).
            let (max_angle, max_mm) = if profile.is_some() { (0.03, 0.05) } else { (0.045, 0.11) };
            assert!(angle <= max_angle, "{label}: normal off by {angle}°");
            assert!(worst <= max_mm, "{label}: plane off by {worst} mm at 300 mm");
            assert!(r.leave_one_out_rms_mm <= 1.3 * r.rms_mm, "{label}: {} vs {}", r.leave_one_out_rms_mm, r.rms_mm);
            scenes.push((angle, worst));
        }
    }
    // The profile takes most of the offset off: means over the seeds 0.076 → 0.020 mm.
    let mean = |v: &[(f64, f64)]| v.iter().map(|s| s.1).sum::<f64>() / v.len() as f64;
    let (without, with) = (mean(&per_profile[0]), mean(&per_profile[1]));
    assert!(with <= 0.5 * without, "mean over the seeds {without} mm without the profile, {with} mm with it");
    // The 0.02° as the scenes' RMS, with the profile known (0.03° without).
    let rms = |v: &mut dyn Iterator<Item = f64>| {
        let (sum, n) = v.fold((0.0, 0.0), |(sum, n), a| (sum + a * a, n + 1.0));
        (sum / n).sqrt()
    };
    let true_stripe = rms(&mut true_stripe_deg.into_iter());
    assert!(true_stripe <= 0.02, "normals' RMS over the seeds with the true stripe: {true_stripe}°");
    let [without, with] = per_profile.map(|scenes| rms(&mut scenes.into_iter().map(|s| s.0)));
    eprintln!(
        "normals over the seeds, RMS: {true_stripe:.4}° from the true stripe, {without:.4}° without the profile, \
         {with:.4}° with it"
    );
    assert!(
        with <= 0.02 && without <= 0.03,
        "normals' RMS over the seeds: {without}° without the profile, {with}° with it"
    );
}
