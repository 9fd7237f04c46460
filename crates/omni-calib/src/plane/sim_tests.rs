//! End to end on rendered images: the simulator's two-board rig, laser frames rendered with its
//! physical stripe model (beam profile, blur, shot and read noise, 8-bit), stripe centres found
//! by `omni_vision::stripe`, then the light-plane calibration.

use super::*;
use omni_formats::BoardFile;
use omni_formats::rig::RigBoard;
use omni_simulator::{
    RenderOptions, Rig, Scene, Sensor, render_ambient_frame, render_laser_frame, render_rig_pose_image,
};
use omni_vision::stripe::{Frame, RidgeDetector, RidgeParams, Scratch};

fn rig_board(board: &BoardFile, name: &str) -> RigBoard {
    RigBoard {
        name: name.to_string(),
        inner_cols: board.inner_cols,
        inner_rows: board.inner_rows,
        square_mm: board.square_mm,
        margin_mm: board.margin_mm,
        placement: 0,
    }
}

#[test]
fn rendered_rig_with_detected_stripes_gives_the_true_light_planes() {
    let sensor = Sensor::paper();
    let board = BoardFile::new(6, 9, 40.0);
    let rig = Rig::standard(&board);
    let scene = Scene::from_file(rig.scene()).unwrap();
    let true_boards: Vec<PlacedBoard> = ["left", "right"]
        .iter()
        .zip(&rig.poses)
        .map(|(name, pose)| PlacedBoard::new(&rig_board(&board, name), *pose))
        .collect();
    let (w, h) = sensor.camera.image_size();
    let detector = RidgeDetector::new(w, h, sensor.camera.mirror_circle(), RidgeParams::default());
    let opts = RenderOptions::default();
    let ambient = render_ambient_frame(&sensor, &scene, &RenderOptions { seed: 99, ..opts.clone() });
    let alphas: Vec<f64> = (0..9).map(|i| 8.0 + 2.0 * i as f64).collect();
    let t0 = std::time::Instant::now();
    let frames: Vec<FrameStripes> = alphas
        .iter()
        .enumerate()
        .map(|(i, &a)| {
            let f = render_laser_frame(&sensor, &scene, a.to_radians(), 0, &[0], &opts);
            // Ambient subtraction (the stream's `ambient_path`): the checkerboard squares would
            // otherwise make ridges of their own.
            let data: Vec<u16> = f.image.data.iter().zip(&ambient.data).map(|(l, a)| l.saturating_sub(*a)).collect();
            let frame = Frame { width: w, height: h, data: &data, max_value: f.image.max_value() as f64 };
            let pts = detector.detect_frame(&frame, &mut Scratch::default());
            FrameStripes {
                seq: i as u64,
                alpha_rad: a.to_radians(),
                facet: 0,
                placement: 0,
                lasers: vec![0],
                pixels: pts.iter().map(|p| [p.u, p.v]).collect(),
            }
        })
        .collect();
    eprintln!("rendered and detected {} frames in {:.1} s", frames.len(), t0.elapsed().as_secs_f64());
    // Board poses found in the rendered pose image by the corner detector.
    let (pose_image, _) = render_rig_pose_image(&sensor, &rig, &RenderOptions::calibration());
    let rig_file = omni_formats::rig::RigFile::new(true_boards.iter().map(|b| rig_board(&board, &b.name)).collect());
    let gray = omni_vision::corners::GrayF32::from_u8(
        w as usize,
        h as usize,
        &pose_image.data.iter().map(|&v| v.min(255) as u8).collect::<Vec<_>>(),
    );
    let detected = inputs::boards_from_pose_image(sensor.camera.as_ref(), &rig_file, &gray, 12).unwrap();
    for (placed, rep) in &detected {
        // Board planes (the labeling may flip the normal; the plane and outline stay).
        let err = rig
            .poses
            .iter()
            .map(|p| (p * nalgebra::Vector3::z()).dot(&(placed.pose * nalgebra::Vector3::z())).abs().min(1.0).acos())
            .fold(f64::INFINITY, f64::min)
            .to_degrees();
        eprintln!(
            "pose image: board {} from {:?} corners, corner rms {:.4}°, plane normal error {err:.4}°",
            rep.board,
            rep.corners_used,
            rep.corner_rms_deg.unwrap()
        );
        assert!(err < 0.05, "board {} normal error {err}°", rep.board);
    }
    let boards: Vec<PlacedBoard> = detected.into_iter().map(|(b, _)| b).collect();
    let mut initial = omni_model::TransmitterParams::paper();
    initial.polygon.encoder_zero_deg = 0.2;
    let errors = |boards: &[PlacedBoard], what: &str| {
        let cal =
            calibrate_planes(sensor.camera.as_ref(), boards, &frames, &initial, &PlaneCalibOptions::default()).unwrap();
        let fitted = Transmitter::new(cal.transmitter.clone()).unwrap();
        let (mut worst_angle, mut worst_off) = (0.0f64, 0.0f64);
        for f in cal.report.frames.iter().filter(|f| f.plane_normal.is_some()) {
            let t = sensor.transmitter.light_plane(f.alpha_deg.to_radians(), 0, 0).unwrap();
            let m = fitted.light_plane(f.alpha_deg.to_radians(), 0, 0).unwrap();
            let (angle, off, _) = synth::plane_error(&t, &m.plane);
            worst_angle = worst_angle.max(angle);
            worst_off = worst_off.max(off);
        }
        eprintln!(
            "rendered rig, {what}: {} frames with planes, {} rejected, frame rms {:.3} mm, model rms {:.3} mm; \
             worst normal {worst_angle:.4}°, offset at 0.5 m {worst_off:.4} mm",
            cal.report.frames.iter().filter(|f| f.plane_normal.is_some()).count(),
            cal.report.rejected.len(),
            cal.report.frame_plane_rms_mm,
            cal.report.model.residual_rms_mm,
        );
        (worst_angle, worst_off)
    };
    // The bar for the ideal build (0.01° in normal, 0.05 mm in offset) with the true board
    // poses; with poses from the detected corners the board error (here up to 0.02°) adds to it.
    let (angle, off) = errors(&true_boards, "true board poses");
    assert!(angle < 0.01 && off < 0.05, "true poses: normal error {angle}°, offset {off} mm");
    let (angle, off) = errors(&boards, "boards from the pose image");
    assert!(angle < 0.02 && off < 0.05, "detected poses: normal error {angle}°, offset {off} mm");
}
