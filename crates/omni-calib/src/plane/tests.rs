//! End-to-end tests of the light-plane calibration on exact synthetic geometry (true camera,
//! board poses estimated from noisy corners, stripe pixels with noise).

use super::synth::*;
use super::*;
use omni_geom::rng::SplitMix64;
use omni_model::{FacetError, TransmitterParams};

/// Corner noise (px) for the pose image and stripe-centre noise (px) for the laser frames.
const CORNER_NOISE_PX: f64 = 0.1;
/// 0.1 px: the omni-vision stripe detector's measured precision bound on simulated stripes.
const STRIPE_NOISE_PX: f64 = 0.1;

/// The rig's boards posed from noisy corners with the camera (as the CLI does).
fn posed_rig(camera: &dyn CameraModel, rng: &mut SplitMix64) -> Vec<PlacedBoard> {
    two_board_rig(550.0)
        .iter()
        .map(|(board, truth)| {
            let (pts, px) = corner_pixels(camera, board, truth, CORNER_NOISE_PX, rng);
            let fit = estimate_board_pose(camera, &pts, &px).expect("board pose");
            PlacedBoard::new(board, fit.pose).with_pose_covariance(fit.covariance)
        })
        .collect()
}

fn true_rig() -> Vec<PlacedBoard> {
    two_board_rig(550.0).iter().map(|(b, p)| PlacedBoard::new(b, *p)).collect()
}

fn frames(
    camera: &dyn CameraModel,
    truth: &Transmitter,
    facets: &[u32],
    alphas_deg: &[f64],
    rng: &mut SplitMix64,
) -> Vec<FrameStripes> {
    let rig = true_rig();
    let mut out = vec![];
    for &k in facets {
        for &a in alphas_deg {
            let seq = out.len() as u64;
            out.push(stripe_frame(camera, truth, &rig, seq, a, k, STRIPE_NOISE_PX, 2.0, rng));
        }
    }
    out
}

/// Calibrates an ideal build over one facet's sweep (α every 0.5°: 61 frames) and returns the
/// worst (normal angle °, offset at 0.5 m mm, distance over 0.5–2 m mm) over the calibrated range.
fn ideal_build_errors(true_poses: bool, seed: u64) -> (f64, f64, f64, usize) {
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let mut rng = SplitMix64::new(seed);
    let boards = if true_poses { true_rig() } else { posed_rig(&camera, &mut rng) };
    let alphas: Vec<f64> = (0..=60).map(|i| i as f64 * 0.5).collect();
    let frames = frames(&camera, &truth, &[0], &alphas, &mut rng);
    // Start from a build that is off by a few tenths of a degree and a millimetre.
    let mut initial = TransmitterParams::paper();
    initial.polygon.encoder_zero_deg = 0.3;
    initial.polygon.axis_point_mm[2] += 1.0;
    let cal = calibrate_planes(&camera, &boards, &frames, &initial, &PlaneCalibOptions::default()).unwrap();
    let fitted = Transmitter::new(cal.transmitter.clone()).unwrap();
    let used: Vec<&FrameReport> = cal.report.frames.iter().filter(|f| f.plane_normal.is_some()).collect();
    let (mut worst_angle, mut worst_off, mut worst_far) = (0.0f64, 0.0f64, 0.0f64);
    for f in &used {
        let t = truth.light_plane(f.alpha_deg.to_radians(), f.facet, f.laser).unwrap();
        let m = fitted.light_plane(f.alpha_deg.to_radians(), f.facet, f.laser).unwrap();
        let (angle, off, far) = plane_error(&t, &m.plane);
        worst_angle = worst_angle.max(angle);
        worst_off = worst_off.max(off);
        worst_far = worst_far.max(far);
    }
    eprintln!(
        "ideal build, {} poses: {} frames, model rms {:.4} mm, frame rms {:.4} mm; worst normal {:.5}°, \
         offset at 0.5 m {:.4} mm, worst over 0.5–2 m {:.4} mm",
        if true_poses { "true" } else { "estimated" },
        used.len(),
        cal.report.model.residual_rms_mm,
        cal.report.frame_plane_rms_mm,
        worst_angle,
        worst_off,
        worst_far
    );
    (worst_angle, worst_off, worst_far, used.len())
}

#[test]
fn ideal_build_light_planes_match_the_truth_with_exact_board_poses() {
    // The fit itself: stripe noise only (board poses exact).
    for seed in [1, 2] {
        let (angle, off, far, frames) = ideal_build_errors(true, seed);
        assert!(frames >= 45, "calibrated range: {frames} frames");
        assert!(angle < 0.01, "seed {seed}: normal error {angle}°");
        assert!(off < 0.05, "seed {seed}: offset error at 0.5 m {off} mm");
        assert!(far < 0.4, "seed {seed}: distance over 0.5–2 m {far} mm");
    }
}

#[test]
fn ideal_build_light_planes_with_board_poses_from_corners() {
    // Boards posed from 0.1 px corners: each board normal is off by ~0.03–0.1° (the camera sees
    // ~0.3°/px), which bounds the light planes' accuracy.
    let (angle, off, _, frames) = ideal_build_errors(false, 1);
    assert!(frames >= 45, "calibrated range: {frames} frames");
    assert!(angle < 0.1, "normal error {angle}°");
    assert!(off < 0.2, "offset error at 0.5 m {off} mm");
}

/// A build with per-facet errors, an encoder offset and a slightly tilted polygon axis.
fn imperfect_build() -> TransmitterParams {
    let mut p = TransmitterParams::paper();
    p.polygon.encoder_zero_deg = 0.4;
    p.polygon.axis_dir = [0.002, -1.0, 0.001];
    p.polygon.zero_dir = [1.0, 0.002, 0.0];
    p.polygon.facet_errors = (0..12)
        .map(|k| {
            let k = k as f64;
            FacetError {
                tilt_deg: 0.05 * (1.3 * k).sin(),
                pitch_deg: 0.08 * (0.7 * k + 0.4).cos(),
                radius_mm: 0.05 * (2.1 * k).sin(),
            }
        })
        .collect();
    p
}

/// Linear interpolation of two frame planes (normal and offset) at fraction `t`.
fn interpolate(a: &FrameReport, b: &FrameReport, t: f64) -> omni_geom::Plane {
    let na = nalgebra::Vector3::from(a.plane_normal.unwrap());
    let mut nb = nalgebra::Vector3::from(b.plane_normal.unwrap());
    let mut ob = b.plane_offset_mm.unwrap();
    if na.dot(&nb) < 0.0 {
        nb = -nb;
        ob = -ob;
    }
    let n = na * (1.0 - t) + nb * t;
    omni_geom::Plane::from_normal_offset(&n, a.plane_offset_mm.unwrap() * (1.0 - t) + ob * t).unwrap()
}

/// Calibrates the imperfect build from all 12 facets, α every 3° (132 frames), starting from
/// the ideal build.
fn calibrate_imperfect(true_poses: bool, step_deg: f64) -> (PlaneCalibration, Transmitter) {
    let camera = paper_camera();
    let truth = Transmitter::new(imperfect_build()).unwrap();
    let mut rng = SplitMix64::new(5);
    let boards = if true_poses { true_rig() } else { posed_rig(&camera, &mut rng) };
    let alphas: Vec<f64> = (0..=(30.0 / step_deg).round() as usize).map(|i| i as f64 * step_deg).collect();
    let facets: Vec<u32> = (0..12).collect();
    let frames = frames(&camera, &truth, &facets, &alphas, &mut rng);
    let cal = calibrate_planes(&camera, &boards, &frames, &TransmitterParams::paper(), &PlaneCalibOptions::default())
        .unwrap();
    (cal, truth)
}

fn estimate<'a>(cal: &'a PlaneCalibration, name: &str) -> &'a Estimate {
    cal.report.model.parameters.iter().find(|e| e.name == name).unwrap()
}

#[test]
fn facet_errors_and_encoder_offset_are_recovered() {
    let (cal, _) = calibrate_imperfect(false, 3.0);
    let truth_params = imperfect_build();
    // Compare in the fit's gauge: pitch, tilt and radius errors with zero mean over the facets,
    // the mean pitch in the encoder zero.
    let true_errs = &truth_params.polygon.facet_errors;
    let mean = |f: fn(&FacetError) -> f64| true_errs.iter().map(f).sum::<f64>() / 12.0;
    let (mean_pitch, mean_tilt, mean_radius) = (mean(|e| e.pitch_deg), mean(|e| e.tilt_deg), mean(|e| e.radius_mm));
    let fit_errs = &cal.transmitter.polygon.facet_errors;
    let enc_err = cal.transmitter.polygon.encoder_zero_deg - (truth_params.polygon.encoder_zero_deg + mean_pitch);
    let (mut pitch_err, mut tilt_err, mut radius_err) = (0.0f64, 0.0f64, 0.0f64);
    for (t, f) in true_errs.iter().zip(fit_errs) {
        pitch_err = pitch_err.max((f.pitch_deg - (t.pitch_deg - mean_pitch)).abs());
        tilt_err = tilt_err.max((f.tilt_deg - (t.tilt_deg - mean_tilt)).abs());
        radius_err = radius_err.max((f.radius_mm - (t.radius_mm - mean_radius)).abs());
    }
    let radius_std = estimate(&cal, "facet_errors[3].radius_mm").std.unwrap();
    let enc_std = estimate(&cal, "polygon.encoder_zero_deg").std.unwrap();
    eprintln!(
        "imperfect build, estimated board poses: model rms {:.4} mm; encoder zero error {enc_err:.5}° (σ {enc_std:.5}°), \
         worst facet pitch error {pitch_err:.5}°, tilt {tilt_err:.5}°, radius {radius_err:.5} mm (σ {radius_std:.4} mm); \
         true errors up to 0.08°, 0.05°, 0.05 mm, encoder 0.4°",
        cal.report.model.residual_rms_mm
    );
    // Pitch and tilt: well inside the true errors (0.08°, 0.05°). The encoder zero carries the
    // board-pose error (boards posed from 0.1 px corners tilt by ~0.1°), far above its σ.
    assert!(pitch_err < 0.01, "pitch error {pitch_err}°");
    assert!(tilt_err < 0.015, "tilt error {tilt_err}°");
    assert!(enc_err.abs() < 0.05, "encoder zero error {enc_err}°");
    // Radius errors of 0.05 mm are near this rig's resolution (σ ≈ 0.025 mm): 4σ.
    assert!(radius_err < 4.0 * radius_std && radius_std < 0.05, "radius error {radius_err} mm, σ {radius_std}");
}

#[test]
fn physical_model_beats_interpolated_frame_planes_on_held_out_angles() {
    // True board poses: their error would bias both methods alike; this isolates the fits.
    let step = 3.0;
    let (cal, truth) = calibrate_imperfect(true, step);
    let fitted = Transmitter::new(cal.transmitter.clone()).unwrap();
    // Held-out angles halfway between calibrated ones.
    let (mut model_angle, mut model_off, mut interp_angle, mut interp_off, mut n) = (0.0, 0.0, 0.0, 0.0, 0);
    for k in 0..12 {
        let own: Vec<&FrameReport> =
            cal.report.frames.iter().filter(|f| f.facet == k && f.laser == 0 && f.plane_normal.is_some()).collect();
        for pair in own.windows(2) {
            if (pair[1].alpha_deg - pair[0].alpha_deg - step).abs() > 1e-9 {
                continue;
            }
            let a = 0.5 * (pair[0].alpha_deg + pair[1].alpha_deg);
            let t = truth.light_plane(a.to_radians(), k, 0).unwrap();
            let (ma, mo, _) = plane_error(&t, &fitted.light_plane(a.to_radians(), k, 0).unwrap().plane);
            let (ia, io, _) = plane_error(&t, &interpolate(pair[0], pair[1], 0.5));
            model_angle += ma;
            model_off += mo;
            interp_angle += ia;
            interp_off += io;
            n += 1;
        }
    }
    let n_f = n as f64;
    eprintln!(
        "held-out ({n} angles): physical model mean normal error {:.5}°, offset at 0.5 m {:.4} mm; \
         interpolated frame planes {:.5}°, {:.4} mm",
        model_angle / n_f,
        model_off / n_f,
        interp_angle / n_f,
        interp_off / n_f
    );
    assert!(n >= 60, "held-out angles: {n}");
    assert!(model_angle < 0.5 * interp_angle, "normal: model {model_angle}, interpolation {interp_angle}");
    assert!(model_off < 0.5 * interp_off, "offset: model {model_off}, interpolation {interp_off}");
}

#[test]
fn single_board_placements_calibrate_from_lines_alone() {
    // The same two boards, but in two placements (one board in view at a time): every frame's
    // stripe is one line, so no frame has a plane of its own, yet the physical model fits.
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let mut rng = SplitMix64::new(8);
    let mut boards = true_rig();
    boards[1].placement = 1;
    let mut frames = vec![];
    for (placement, board) in boards.iter().enumerate() {
        for i in 0..=30 {
            let seq = frames.len() as u64;
            let mut f = stripe_frame(
                &camera,
                &truth,
                std::slice::from_ref(board),
                seq,
                i as f64,
                0,
                STRIPE_NOISE_PX,
                2.0,
                &mut rng,
            );
            f.placement = placement as u32;
            frames.push(f);
        }
    }
    let mut initial = TransmitterParams::paper();
    initial.polygon.encoder_zero_deg = 0.3;
    let cal = calibrate_planes(&camera, &boards, &frames, &initial, &PlaneCalibOptions::default()).unwrap();
    assert!(cal.report.frames.iter().all(|f| f.plane_refused.as_deref().is_some_and(|r| r.contains("one line"))));
    let fitted = Transmitter::new(cal.transmitter.clone()).unwrap();
    let mut worst = (0.0f64, 0.0f64);
    for f in &cal.report.frames {
        let t = truth.light_plane(f.alpha_deg.to_radians(), 0, 0).unwrap();
        let (a, o, _) = plane_error(&t, &fitted.light_plane(f.alpha_deg.to_radians(), 0, 0).unwrap().plane);
        worst = (worst.0.max(a), worst.1.max(o));
    }
    eprintln!(
        "single-board placements: {} line frames, model rms {:.3} mm; worst normal {:.5}°, offset at 0.5 m {:.4} mm",
        cal.report.frames.len(),
        cal.report.model.residual_rms_mm,
        worst.0,
        worst.1
    );
    assert!(cal.report.frames.len() >= 50);
    assert!(worst.0 < 0.01 && worst.1 < 0.05, "normal {}°, offset {} mm", worst.0, worst.1);
}

/// One board alone (one placement): every frame's stripe is a line on the same plane, which the
/// reviewer's one-board rig fitted with a small residual while the axis moved 160–200 mm.
#[test]
fn one_board_alone_is_refused() {
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let mut rng = SplitMix64::new(8);
    let board = true_rig().swap_remove(0);
    let frames: Vec<FrameStripes> = (0..=30)
        .map(|i| {
            let b = std::slice::from_ref(&board);
            stripe_frame(&camera, &truth, b, i as u64, i as f64, 0, STRIPE_NOISE_PX, 2.0, &mut rng)
        })
        .collect();
    let err = calibrate_planes(&camera, &[board], &frames, &TransmitterParams::paper(), &PlaneCalibOptions::default())
        .unwrap_err();
    assert!(err.contains("one board plane") && err.contains("boards at an angle"), "{err}");
}

#[test]
fn both_lasers_are_calibrated_from_boards_on_both_sides() {
    // The rig and its copy turned by 180° about z (on the −x side, lit by laser 1): each frame
    // holds two stripes that must be split between the lasers.
    let camera = paper_camera();
    let truth = Transmitter::new(imperfect_build()).unwrap();
    let turn = nalgebra::Isometry3::rotation(nalgebra::Vector3::z() * std::f64::consts::PI);
    let mut boards = true_rig();
    for b in true_rig() {
        boards.push(PlacedBoard { name: format!("{}-back", b.name), pose: turn * b.pose, ..b });
    }
    let mut rng = SplitMix64::new(9);
    // α every 1° on two facets: each facet's own errors (pitch, tilt, radius) are fitted from its
    // 31 frames. With 2° steps (16 frames a facet) the stripe noise alone reached 0.0108° on two of
    // four seeds; with 1° the worst over seeds 1, 2, 3, 9 is 0.0077° and 0.031 mm.
    let alphas: Vec<f64> = (0..=30).map(|i| i as f64).collect();
    let mut frames = vec![];
    for k in [0, 3] {
        for &a in &alphas {
            let seq = frames.len() as u64;
            frames.push(stripe_frame(&camera, &truth, &boards, seq, a, k, STRIPE_NOISE_PX, 2.0, &mut rng));
        }
    }
    let cal = calibrate_planes(&camera, &boards, &frames, &TransmitterParams::paper(), &PlaneCalibOptions::default())
        .unwrap();
    let fitted = Transmitter::new(cal.transmitter.clone()).unwrap();
    for laser in 0..2 {
        let own: Vec<&FrameReport> =
            cal.report.frames.iter().filter(|f| f.laser == laser && f.plane_normal.is_some()).collect();
        let mut worst = (0.0f64, 0.0f64);
        for f in &own {
            let t = truth.light_plane(f.alpha_deg.to_radians(), f.facet, laser).unwrap();
            let (a, o, _) =
                plane_error(&t, &fitted.light_plane(f.alpha_deg.to_radians(), f.facet, laser).unwrap().plane);
            worst = (worst.0.max(a), worst.1.max(o));
        }
        eprintln!(
            "laser {laser}: {} frames with planes; worst normal {:.5}°, offset at 0.5 m {:.4} mm",
            own.len(),
            worst.0,
            worst.1
        );
        assert!(own.len() >= 50, "laser {laser}: {} frames", own.len());
        assert!(worst.0 < 0.01 && worst.1 < 0.05, "laser {laser}: normal {}°, offset {} mm", worst.0, worst.1);
    }
    assert!(cal.report.model.parameters.iter().any(|e| e.name.contains("lasers[1] fan normal turn")));
}

#[test]
fn gate_around_the_initial_model_removes_checkerboard_lines() {
    // Without ambient subtraction the ridge detector also finds the checkerboard's horizontal
    // edges: on both boards, at every 40 mm of height, denser than the stripe and coplanar, so
    // no robust fit can tell them from the stripe. The initial model can.
    let camera = paper_camera();
    let truth = Transmitter::new(imperfect_build()).unwrap();
    let boards = true_rig();
    let mut rng = SplitMix64::new(12);
    let mut frames = vec![];
    for i in 0..=30 {
        let a = i as f64;
        let mut f = stripe_frame(&camera, &truth, &boards, i, a, 0, STRIPE_NOISE_PX, 2.0, &mut rng);
        for k in -6..=3 {
            let edge = omni_geom::Plane::from_point_normal(
                &nalgebra::Point3::new(0.0, 0.0, 20.0 + 40.0 * k as f64),
                &nalgebra::Vector3::z(),
            );
            for b in &boards {
                for p in plane_board_line(&edge, b, 1.5) {
                    if let Some(px) = camera.point_to_pixel(&p) {
                        f.pixels.push([px.x + 0.1 * rng.normal(), px.y + 0.1 * rng.normal()]);
                    }
                }
            }
        }
        frames.push(f);
    }
    let initial = TransmitterParams::paper();
    let plain = calibrate_planes(&camera, &boards, &frames, &initial, &PlaneCalibOptions::default());
    // The gate must exceed the initial model's error (the 0.4° encoder offset moves the planes by
    // up to ~9 mm at the boards); the second pass then gates at a quarter of it around the first
    // pass's model, which drops the edge 10 mm from the level plane near α = 15°.
    let gated = PlaneCalibOptions { gate_mm: Some(20.0), ..Default::default() };
    let cal = calibrate_planes(&camera, &boards, &frames, &initial, &gated).unwrap();
    let fitted = Transmitter::new(cal.transmitter.clone()).unwrap();
    let worst = |tx: &Transmitter| {
        (0..=30)
            .map(|a| {
                let a = (a as f64).to_radians();
                truth.light_plane(a, 0, 0).unwrap().plane.angle_to(&tx.light_plane(a, 0, 0).unwrap().plane).to_degrees()
            })
            .fold(0.0, f64::max)
    };
    let plain_err = plain.map(|c| worst(&Transmitter::new(c.transmitter).unwrap())).unwrap_or(f64::INFINITY);
    let gated_err = worst(&fitted);
    eprintln!("checkerboard lines: worst normal error {plain_err:.4}° ungated, {gated_err:.5}° with a 20 mm gate");
    assert!(gated_err < 0.01, "gated: {gated_err}°");
    assert!(plain_err > 0.1, "without the gate the edges win: {plain_err}°");
}

/// Three frames 0.5° apart on the two-board rig: each frame's plane is fine, but the polygon's
/// axis is not determined by so short a sweep (its offset's σ about 100 mm, where 11 frames over
/// the facet give 0.13 mm): refused, naming the parameter. (An 8° sweep with 0.5 px stripe noise
/// gives 9 mm and 3°: warned of by the tool, not refused.)
#[test]
fn a_sweep_too_short_to_fix_the_axis_is_refused() {
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let mut rng = SplitMix64::new(3);
    let boards = posed_rig(&camera, &mut rng);
    let frames = frames(&camera, &truth, &[0], &[20.0, 20.5, 21.0], &mut rng);
    let err = calibrate_planes(&camera, &boards, &frames, &TransmitterParams::paper(), &PlaneCalibOptions::default())
        .unwrap_err();
    assert!(err.contains("do not determine") && err.contains("polygon.axis_point offset u σ"), "{err}");
}

/// The reported σ are honest about the boards' poses: over 8 seeds of boards posed from 0.1 px
/// corners (one facet's sweep, α every 1°), each parameter's scatter against its mean reported
/// σ, pooled over the parameters (RMS of the ratios), lies within 0.5–1.5. (The fit's own σ
/// alone, which takes the stripe points' errors as independent, gave 1.6–11 × over 16 seeds at
/// α every 0.5°.)
#[test]
fn reported_sigmas_include_the_board_poses() {
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let alphas: Vec<f64> = (0..=30).map(f64::from).collect();
    let runs: Vec<Vec<Estimate>> = (1..=8)
        .map(|seed| {
            let mut rng = SplitMix64::new(seed);
            let boards = posed_rig(&camera, &mut rng);
            let frames = frames(&camera, &truth, &[0], &alphas, &mut rng);
            let mut initial = TransmitterParams::paper();
            initial.polygon.encoder_zero_deg = 0.3;
            let cal = calibrate_planes(&camera, &boards, &frames, &initial, &PlaneCalibOptions::default()).unwrap();
            cal.report.model.parameters
        })
        .collect();
    let mut ratios = vec![];
    for (k, e) in runs[0].iter().enumerate() {
        let values: Vec<f64> = runs.iter().map(|r| r[k].value).collect();
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let scatter = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (values.len() - 1) as f64).sqrt();
        let reported = runs.iter().map(|r| r[k].std.unwrap()).sum::<f64>() / runs.len() as f64;
        let fit_only = runs.iter().map(|r| r[k].std_fit.unwrap()).sum::<f64>() / runs.len() as f64;
        eprintln!(
            "{}: scatter {scatter:.5}, reported σ {reported:.5} (the fit's own {fit_only:.5}) {}",
            e.name, e.unit
        );
        ratios.push(scatter / reported);
    }
    let pooled = (ratios.iter().map(|r| r * r).sum::<f64>() / ratios.len() as f64).sqrt();
    assert!((0.5..=1.5).contains(&pooled), "scatter / reported σ, pooled: {pooled:.2} ({ratios:.2?})");
}
