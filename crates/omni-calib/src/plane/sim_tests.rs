//! End to end on rendered images: the simulator's two-board rig, laser frames rendered with its
//! physical stripe model (beam profile, blur, shot and read noise, 8-bit), stripe centres found
//! by `omni_vision::stripe`, then the light-plane calibration.

use super::*;
use nalgebra::Point3;
use omni_formats::BoardFile;
use omni_formats::rig::RigBoard;
use omni_model::{CameraModel, TransmitterParams};
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
    let true_boards: Vec<PlacedBoard> = ["left", "right"]
        .iter()
        .zip(&rig.poses)
        .map(|(name, pose)| PlacedBoard::new(&rig_board(&board, name), *pose))
        .collect();
    let (frames, _, gray) = cached_rig();
    // Board poses found in the rendered pose image by the corner detector.
    let rig_file = omni_formats::rig::RigFile::new(true_boards.iter().map(|b| rig_board(&board, &b.name)).collect());
    let detected = inputs::boards_from_pose_image(sensor.camera.as_ref(), &rig_file, gray, 12).unwrap();
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
            calibrate_planes(sensor.camera.as_ref(), boards, frames, &initial, &PlaneCalibOptions::default()).unwrap();
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
    // The bar for the ideal build (0.01° in normal, 0.05 mm in offset), with the true
    // board poses (measured 0.0074°, 0.014 mm) and with the boards found in the mean of
    // POSE_IMAGES pose images (boards within 0.007°; planes 0.0084°, 0.011 mm; from one pose image
    // the boards were up to 0.017° off and the planes 0.013°).
    let (angle, off) = errors(&true_boards, "true board poses");
    assert!(angle < 0.01 && off < 0.05, "true poses: normal error {angle}°, offset {off} mm");
    let (angle, off) = errors(&boards, "boards from the pose image");
    assert!(angle < 0.01 && off < 0.05, "detected poses: normal error {angle}°, offset {off} mm");
}

type RenderedRig = (Vec<FrameStripes>, Vec<Vec<omni_simulator::TruthPoint>>, omni_vision::corners::GrayF32);

/// Ambient images of the unmoved rig averaged into its pose image (what `omni-calib-plane fit
/// --pose-image a.png b.png …` does). Measured with the receiver-calibrated camera (rendered
/// boards, annulus) on the 2° rig: 1 image → light planes 0.0141°/0.053 mm, boards 0.012–0.015°
/// and up to 0.057 mm; 4 → 0.0163°/0.037 mm; 8 → 0.0151°/0.034 mm (boards 0.011°, up to
/// 0.063 mm). With the true camera the boards go 0.013° → 0.007° (1 → 8 images): the pose
/// image's sensor noise is then the boards' main error; with the calibrated camera its ray
/// error (0.002° median, 0.005° max) tilts the boards by ~0.01° whatever the averaging.
const POSE_IMAGES: u64 = 8;

/// The paper sensor's rendered standard rig (6 × 9 boards of 40 mm), rendered once for all tests.
fn cached_rig() -> &'static RenderedRig {
    static RIG: std::sync::OnceLock<RenderedRig> = std::sync::OnceLock::new();
    RIG.get_or_init(|| rendered_rig(&Sensor::paper(), &Rig::standard(&BoardFile::new(6, 9, 40.0)), 2.0, POSE_IMAGES))
}

/// The rendered rig's laser frames (α = 8…24° every `step_deg`, ambient subtracted) with their
/// detected stripe pixels and the simulator's ground-truth stripe points, and the rig's pose image:
/// the pixel mean of `pose_images` ambient images of the static rig (independent sensor noise).
fn rendered_rig(sensor: &Sensor, rig: &Rig, step_deg: f64, pose_images: u64) -> RenderedRig {
    use rayon::prelude::*;
    let scene = Scene::from_file(rig.scene()).unwrap();
    let (w, h) = sensor.camera.image_size();
    let detector = RidgeDetector::new(w, h, sensor.camera.mirror_circle(), RidgeParams::default());
    let opts = RenderOptions::ideal();
    let ambient = render_ambient_frame(sensor, &scene, &RenderOptions { seed: 99, ..opts.clone() });
    let count = (16.0 / step_deg).round() as u64 + 1;
    let (frames, truths): (Vec<FrameStripes>, Vec<_>) = (0..count)
        .into_par_iter()
        .map(|i| {
            let a = 8.0 + step_deg * i as f64;
            let f =
                render_laser_frame(sensor, &scene, a.to_radians(), 0, &[0], &RenderOptions { seed: i, ..opts.clone() });
            let data: Vec<u16> = f.image.data.iter().zip(&ambient.data).map(|(l, a)| l.saturating_sub(*a)).collect();
            let frame = Frame { width: w, height: h, data: &data, max_value: f.image.max_value() as f64 };
            let pts = detector.detect_frame(&frame, &mut Scratch::default());
            let stripes = FrameStripes {
                seq: i,
                alpha_rad: a.to_radians(),
                facet: 0,
                placement: 0,
                lasers: vec![0],
                pixels: pts.iter().map(|p| [p.u, p.v]).collect(),
            };
            (stripes, f.truth)
        })
        .unzip();
    let images: Vec<omni_vision::corners::GrayF32> = (0..pose_images)
        .into_par_iter()
        .map(|k| {
            let opts = RenderOptions { seed: 1000 + k, ..RenderOptions::calibration() };
            let (image, _) = render_rig_pose_image(sensor, rig, &opts);
            let scale = 255.0 / image.max_value() as f32;
            let data = image.data.iter().map(|&v| v as f32 * scale).collect();
            omni_vision::corners::GrayF32 { width: w as usize, height: h as usize, data }
        })
        .collect();
    (frames, truths, inputs::mean_image(&images).unwrap())
}

/// A camera calibrated by `omni_calib::receiver` from the true corner pixels of `count` 9 × 6
/// boards (30 mm) placed as a careful user places them ([`omni_simulator::calibration_board_poses`]:
/// close boards spread over the whole mirror; the simulator's visibility) plus Gaussian noise of
/// `noise_px`: the rendered boards' detection error without the rendering cost.
fn projected_receiver_camera(sensor: &Sensor, count: usize, noise_px: f64, seed: u64) -> Box<dyn CameraModel> {
    use omni_simulator::{Scene, board_corners, board_object, calibration_board_poses, corner_pixels};
    let board = BoardFile::new(9, 6, 30.0);
    let poses = calibration_board_poses(sensor, &board, count, seed).unwrap();
    let mut rng = omni_simulator::rng::SplitMix64::new(seed);
    let grid = board_corners(board.inner_cols, board.inner_rows, board.square_mm);
    let obs: Vec<crate::receiver::Observation> = poses
        .iter()
        .enumerate()
        .filter_map(|(k, pose)| {
            let scene =
                Scene::from_file(omni_formats::scene::SceneFile::new(vec![board_object(&board, pose)])).unwrap();
            let (board_mm, pixels): (Vec<[f64; 2]>, Vec<[f64; 2]>) = corner_pixels(sensor, &scene, pose, &board)
                .iter()
                .zip(&grid)
                .filter_map(|(px, c)| px.map(|px| ([c.x, c.y], px)))
                .map(|(xy, px)| (xy, [px[0] + noise_px * rng.normal(), px[1] + noise_px * rng.normal()]))
                .unzip();
            // The detector needs a dozen corners to find a board.
            (pixels.len() >= 12).then(|| crate::receiver::Observation { name: format!("board{k}"), board_mm, pixels })
        })
        .collect();
    let (w, h) = sensor.camera.image_size();
    let c = sensor.camera.mirror_circle();
    let annulus = [c.centre.x, c.centre.y, c.inner_radius, c.outer_radius];
    let opts = crate::receiver::Options { annulus: Some(annulus), ..Default::default() };
    let cal = crate::receiver::calibrate(w, h, &obs, &opts).unwrap();
    eprintln!("receiver: {} boards ({noise_px} px noise), reprojection RMS {:.3} px", obs.len(), cal.rms_px);
    at_true_viewpoint(cal.spec, sensor)
}

/// Builds a fitted generic model with its viewpoint at the true camera's. Board images fix the
/// rays' directions, not their origin (the receiver calibration puts it at the world origin and
/// `omni-calib-receiver --viewpoint-mm` moves it): this is the translation part of the frame
/// gauge, chosen here so that the paper transmitter is a good initial model in both frames.
fn at_true_viewpoint(mut spec: omni_formats::CameraSpec, sensor: &Sensor) -> Box<dyn CameraModel> {
    let circle = sensor.camera.mirror_circle();
    let px = circle.centre + nalgebra::Vector2::new(0.5 * (circle.inner_radius + circle.outer_radius), 0.0);
    let viewpoint: [f64; 3] = sensor.camera.pixel_to_ray(&px).unwrap().origin.coords.into();
    spec.set_viewpoint_mm(viewpoint);
    spec.build().unwrap()
}

/// The gauge between a fitted central camera's world frame and the true one: the rotation that
/// best maps true pixel rays onto the fitted model's rays of the same pixels (Kabsch over the
/// mirror annulus), about the two viewpoints.
///
/// Board images cannot observe this rotation: turning every board pose and the model's rays by
/// the same rotation leaves every pixel where it was, and a small tilt is nearly a principal
/// point shift plus tangential distortion, so the fit picks one by its parametrisation. Every
/// later measurement inherits the fitted frame: the board poses, the stripe points and hence
/// the light planes are all expressed in it, and the scanner's point clouds come out rigidly
/// turned by it (a datum registration removes that). So the light planes are compared after
/// carrying them through this rotation; what remains is what the scanner's geometry gets wrong.
struct FrameAlignment {
    /// True ray directions → fitted ones.
    rot: nalgebra::Rotation3<f64>,
    o_true: Point3<f64>,
    o_fit: Point3<f64>,
    /// Median and largest angle between aligned rays over the annulus (degrees): the fitted
    /// model's own ray error.
    ray_median_deg: f64,
    ray_max_deg: f64,
}

impl FrameAlignment {
    fn new(truth: &dyn CameraModel, fitted: &dyn CameraModel) -> FrameAlignment {
        let circle = truth.mirror_circle();
        let mut pairs = vec![];
        let (mut o_true, mut o_fit) = (Point3::origin(), Point3::origin());
        for k in 0..360 {
            let az = (k as f64).to_radians();
            for r in [0.1, 0.3, 0.5, 0.7, 0.9] {
                let rad = circle.inner_radius + r * (circle.outer_radius - circle.inner_radius);
                let px = circle.centre + nalgebra::Vector2::new(az.cos(), az.sin()) * rad;
                if let (Some(t), Some(c)) = (truth.pixel_to_ray(&px), fitted.pixel_to_ray(&px)) {
                    pairs.push((t.dir.into_inner(), c.dir.into_inner()));
                    (o_true, o_fit) = (t.origin, c.origin);
                }
            }
        }
        let cross = pairs.iter().fold(nalgebra::Matrix3::zeros(), |a, (t, c)| a + c * t.transpose());
        let svd = cross.svd(true, true);
        let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
        let mut m = u * vt;
        if m.determinant() < 0.0 {
            m = u * nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, -1.0)) * vt;
        }
        let rot = nalgebra::Rotation3::from_matrix_unchecked(m);
        let mut errs: Vec<f64> = pairs.iter().map(|(t, c)| (rot * t).angle(c).to_degrees()).collect();
        errs.sort_by(f64::total_cmp);
        FrameAlignment { rot, o_true, o_fit, ray_median_deg: errs[errs.len() / 2], ray_max_deg: errs[errs.len() - 1] }
    }

    /// A true-frame point in the fitted frame.
    fn to_fitted(&self, p: &Point3<f64>) -> Point3<f64> {
        self.o_fit + self.rot * (p - self.o_true)
    }

    /// A fitted-frame plane in the true frame.
    fn plane_to_true(&self, plane: &omni_geom::Plane) -> omni_geom::Plane {
        let point = self.o_true + self.rot.inverse() * (plane.project(&self.o_fit) - self.o_fit);
        omni_geom::Plane::from_point_normal(&point, &(self.rot.inverse() * plane.normal.into_inner()))
    }
}

/// Triangulation error (mm) of the simulator's true stripe points, seen through `camera` and cut
/// with the calibrated light planes: (RMS, max) over the frames. A calibrated model has its own
/// world frame (turned by its calibration error), so the truth is first carried into it.
fn triangulation_error(
    align: &FrameAlignment,
    camera: &dyn CameraModel,
    tx: &Transmitter,
    frames: &[FrameStripes],
    truths: &[Vec<omni_simulator::TruthPoint>],
) -> (f64, f64) {
    let (mut ss, mut n, mut worst) = (0.0, 0usize, 0.0f64);
    for (f, truth) in frames.iter().zip(truths) {
        let lp = tx.light_plane(f.alpha_rad, f.facet, 0).unwrap();
        for t in truth.iter().step_by(10) {
            let Some(ray) = camera.pixel_to_ray(&nalgebra::Vector2::new(t.pixel[0], t.pixel[1])) else { continue };
            let Ok(hit) = omni_geom::intersect_ray_plane(&ray, &lp.plane, 0.01) else { continue };
            let e = (hit.point - align.to_fitted(&Point3::from(t.xyz))).norm();
            ss += e * e;
            n += 1;
            worst = worst.max(e);
        }
    }
    ((ss / n.max(1) as f64).sqrt(), worst)
}

/// Worst light-plane error over α = `from`…`to` (every 0.25°, facet 0, laser 0) of a calibrated
/// transmitter in the fitted camera's frame against the truth: (normal angle in degrees, offset
/// at 0.5 m in mm, largest distance over 0.5–2 m in mm), see [`synth::plane_error`].
fn light_plane_errors(
    align: &FrameAlignment,
    truth: &Transmitter,
    fitted: &Transmitter,
    range: (f64, f64),
) -> [f64; 3] {
    let mut worst = [0.0f64; 3];
    let steps = ((range.1 - range.0) / 0.25).round() as usize;
    for i in 0..=steps {
        let a = (range.0 + 0.25 * i as f64).to_radians();
        let t = truth.light_plane(a, 0, 0).unwrap();
        let m = align.plane_to_true(&fitted.light_plane(a, 0, 0).unwrap().plane);
        let (angle, off, far) = synth::plane_error(&t, &m);
        worst = [worst[0].max(angle), worst[1].max(off), worst[2].max(far)];
    }
    worst
}

/// Light-plane calibration of one camera on the rendered rig: board poses from the pose image
/// (or the true poses carried into the camera's frame), then the errors against the truth in a
/// common frame: (worst normal angle °, worst offset at 0.5 m mm, stripe re-triangulation RMS mm).
fn calibrate_with_camera(sensor: &Sensor, camera: &dyn CameraModel, what: &str, true_poses: bool) -> (f64, f64, f64) {
    calibrate_on_rig(cached_rig(), sensor, camera, what, true_poses)
}

fn calibrate_on_rig(
    rig: &RenderedRig,
    sensor: &Sensor,
    camera: &dyn CameraModel,
    what: &str,
    true_poses: bool,
) -> (f64, f64, f64) {
    let board = BoardFile::new(6, 9, 40.0);
    let (frames, truths, gray) = rig;
    let align = FrameAlignment::new(sensor.camera.as_ref(), camera);
    let boards: Vec<PlacedBoard> = if true_poses {
        let to_fitted = nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from(align.o_fit.coords - align.rot * align.o_true.coords),
            nalgebra::UnitQuaternion::from_rotation_matrix(&align.rot),
        );
        let rig = Rig::standard(&board);
        ["left", "right"]
            .iter()
            .zip(&rig.poses)
            .map(|(n, p)| PlacedBoard::new(&rig_board(&board, n), to_fitted * p))
            .collect()
    } else {
        let rig_file = omni_formats::rig::RigFile::new(vec![rig_board(&board, "left"), rig_board(&board, "right")]);
        inputs::boards_from_pose_image(camera, &rig_file, gray, 12).unwrap().into_iter().map(|(b, _)| b).collect()
    };
    // How far the boards are from the truth, in the true frame: the error the planes inherit.
    let board_errors: Vec<String> = boards
        .iter()
        .map(|b| {
            let plane = align.plane_to_true(&b.plane());
            // Detection order may swap the boards' names: compare with the nearer true board.
            let errors = Rig::standard(&board).poses.map(|truth| {
                let normal = (truth * nalgebra::Vector3::z()).angle(&plane.normal).to_degrees();
                let centre = truth * Point3::new(140.0, 80.0, 0.0);
                (normal.min(180.0 - normal), plane.signed_distance(&centre).abs())
            });
            let (normal, offset) = if errors[0].0 < errors[1].0 { errors[0] } else { errors[1] };
            format!("{normal:.4}°/{offset:.3} mm")
        })
        .collect();
    let cal =
        calibrate_planes(camera, &boards, frames, &TransmitterParams::paper(), &PlaneCalibOptions::default()).unwrap();
    let tx = Transmitter::new(cal.transmitter).unwrap();
    // The calibrated range: the rig's frames are at α = 8…24°.
    let [angle, off, far] = light_plane_errors(&align, &sensor.transmitter, &tx, (8.0, 24.0));
    let (rms, max) = triangulation_error(&align, camera, &tx, frames, truths);
    eprintln!(
        "{what} (rays {:.4}° median, {:.4}° max after turning by {:.4}°), {}: model rms {:.3} mm; light planes \
         worst normal {angle:.4}°, offset at 0.5 m {off:.4} mm, over 0.5–2 m {far:.3} mm; stripe points \
         re-triangulated RMS {rms:.3} mm, max {max:.3} mm; boards (normal, offset at their centre) {}",
        align.ray_median_deg,
        align.ray_max_deg,
        nalgebra::UnitQuaternion::from_rotation_matrix(&align.rot).angle().to_degrees(),
        if true_poses { "true board poses" } else { "boards from the pose image" },
        cal.report.model.residual_rms_mm,
        board_errors.join(", ")
    );
    (angle, off, rms)
}

/// The first accuracy target: the ideal build's light planes, calibrated with the camera
/// from `omni_calib::receiver::calibrate` (not the true one), against the true planes over the
/// calibrated range, compared in the true frame after the ray-alignment rotation
/// ([`FrameAlignment`]). The receiver is calibrated as a user does it ([`rendered_receiver_camera`]:
/// 20 rendered boards of the simulator's calibration set, corners detected inside the mirror
/// annulus, the annulus given to the fit), the light planes from the rendered rig (9 frames at
/// α = 8…24°, detected stripes, boards found in the mean of [`POSE_IMAGES`] pose images).
///
/// Measured today (release; worst normal, offset at 0.5 m; stripe points re-triangulated RMS):
/// * true camera: 0.0037°, 0.007 mm, 0.024 mm;
/// * receiver camera, seed 2 (this test): rays 0.0017° median / 0.0024° max after alignment,
///   reprojection 0.012 px; planes 0.0031°, 0.011 mm, 0.032 mm;
/// * receiver camera from projected corners with 0.005 px noise (rays 0.0003° median, 0.0012°
///   with the former farther boards): 0.0039°, 0.008 mm, 0.023 mm.
///
/// The receiver's ray error is what the light planes inherit (the offset is mostly the rays'
/// common elevation error, the mirror's "cone opening", times the distance: 0.005° is 0.044 mm
/// at 0.5 m). The causes found and removed were all in the corners the receiver is fitted to or
/// in their placement: (1) the corner refinement's pull on curved edges
/// (`omni_vision::corners`' curvature step: +0.030 px radial bias on every rendered corner, which
/// the fit cannot tell from a 0.005° elevation offset); (2) its pixel locking (bilinear window
/// samples drew corners towards pixel centres, 0.017 px·sin 2π·phase per axis; the window now
/// samples the pixel grid); (3) boards too far to pin the cone opening (a board seen under a
/// small angle absorbs it by turning its pose; the simulator's calibration set moved from
/// 0.7–1.25 to 0.45–0.75 board diagonals: predicted ray error for 0.02 px white noise 0.0055° →
/// 0.0032°); (4) the curvature step left the corners at a partial board's edge uncorrected or
/// corrected with the curvature one corner further in (those 5 % of the corners, 0.03 px off,
/// alone made a −0.004° cone error): now the parallel line stands in, and the curvature is
/// extrapolated to the border corner. Board seeds 2, 3, 5, 7, 9, 11 (rays median; normal;
/// offset at 0.5 m):
/// * before: 0.0051/0.0029/0.0054/0.0108/0.0076/0.0056°; 0.0084/0.0072/0.0100/0.0075/0.0087/
///   0.0094°; 0.032/0.044/0.073/0.087/0.080/0.078 mm;
/// * (1): 0.0066/0.0043/0.0071/0.0093/0.0063/0.0084°; 0.0082/0.0031/0.0065/0.0043/0.0039/
///   0.0047°; 0.096/0.033/0.094/0.068/0.062/0.049 mm;
/// * (1) + (3): 0.0046/0.0038/0.0071/0.0009/0.0072/0.0040°; 0.0037/0.0028/0.0045/0.0033/
///   0.0054/0.0033°; 0.040/0.035/0.066/0.012/0.094/0.041 mm;
/// * (1) + (2) + (3): 0.0027/0.0041/0.0050/0.0019/0.0069/0.0012°; 0.0034/0.0032/0.0054/0.0035/
///   0.0065/0.0040°; 0.016/0.022/0.054/0.003/0.074/0.018 mm;
/// * all four (today): 0.0017/0.0024/0.0044/0.0027/0.0044/0.0013°; 0.0031/0.0029/0.0053/
///   0.0039/0.0064/0.0033°; 0.011/0.012/0.047/0.011/0.053/0.009 mm.
///
/// So the normal holds on every set and the offset on five of six (seed 9 at 0.053 mm). What
/// remains is mostly sensor noise (0.010 px per corner; fitted alone, without the detector's
/// deterministic error, 0.0015–0.0019° on seeds 2, 5, 9) amplified by the weakly observed cone
/// opening, plus the detector's remaining deterministic error (0.008 px per axis on noiseless
/// renders; fitted alone 0.0008–0.0028°).
/// (`PLANE_BREAKDOWN=1` prints the rows with the true board poses carried into each frame.)
#[test]
fn camera_from_the_receiver_calibration_gives_the_true_light_planes() {
    let sensor = Sensor::paper();
    let (angle, off, rms) = calibrate_with_camera(&sensor, sensor.camera.as_ref(), "true camera", false);
    assert!(angle < 0.01 && off < 0.05 && rms < 0.1, "true camera: {angle}°, {off} mm, RMS {rms} mm");
    let receiver = rendered_receiver_camera(&sensor, 20, 2);
    let (angle, off, rms) = calibrate_with_camera(&sensor, receiver.as_ref(), "receiver camera", false);
    // The 0.01° and 0.05 mm (measured 0.0031°, 0.011 mm; other board seeds above). The
    // stripe points' RMS is the receiver camera's ray error more than the stripes' (true camera
    // 0.024 mm; measured here 0.032 mm).
    assert!(angle < 0.01 && off < 0.05 && rms < 0.1, "receiver camera: {angle}°, {off} mm, RMS {rms} mm");
    let accurate = projected_receiver_camera(&sensor, 20, 0.005, 21);
    let (angle, off, rms) =
        calibrate_with_camera(&sensor, accurate.as_ref(), "receiver camera, 0.005 px corners", false);
    assert!(angle < 0.01 && off < 0.05 && rms < 0.1, "accurate receiver camera: {angle}°, {off} mm, RMS {rms} mm");
    if std::env::var("PLANE_BREAKDOWN").is_ok() {
        calibrate_with_camera(&sensor, sensor.camera.as_ref(), "true camera", true);
        calibrate_with_camera(&sensor, receiver.as_ref(), "receiver camera", true);
        calibrate_with_camera(&sensor, accurate.as_ref(), "receiver camera, 0.005 px corners", true);
    }
}

/// The true camera with its world frame turned by `rot` about its viewpoint: what a fitted model
/// whose only error is the frame gauge looks like.
#[derive(Debug)]
struct TurnedCamera<'a> {
    inner: &'a dyn CameraModel,
    rot: nalgebra::Rotation3<f64>,
    viewpoint: Point3<f64>,
}

impl CameraModel for TurnedCamera<'_> {
    fn image_size(&self) -> (u32, u32) {
        self.inner.image_size()
    }
    fn pixel_to_ray(&self, px: &nalgebra::Vector2<f64>) -> Option<omni_geom::Ray> {
        let ray = self.inner.pixel_to_ray(px)?;
        Some(omni_geom::Ray::new(
            self.viewpoint + self.rot * (ray.origin - self.viewpoint),
            self.rot * ray.dir.into_inner(),
        ))
    }
    fn point_to_pixel(&self, p: &Point3<f64>) -> Option<nalgebra::Vector2<f64>> {
        self.inner.point_to_pixel(&(self.viewpoint + self.rot.inverse() * (p - self.viewpoint)))
    }
    fn mirror_circle(&self) -> omni_model::MirrorCircle {
        self.inner.mirror_circle()
    }
}

#[test]
fn frame_alignment_removes_a_turned_camera_frame_exactly() {
    // A camera whose world frame is turned by 0.5° calibrates light planes 0.5° off in absolute
    // terms; carried back by the ray alignment they must be the true camera's to rounding.
    let sensor = Sensor::paper();
    let truth = sensor.camera.as_ref();
    let circle = truth.mirror_circle();
    let px = circle.centre + nalgebra::Vector2::new(0.5 * (circle.inner_radius + circle.outer_radius), 0.0);
    let viewpoint = truth.pixel_to_ray(&px).unwrap().origin;
    let rot =
        nalgebra::Rotation3::from_scaled_axis(nalgebra::Vector3::new(0.3, -0.2, 0.4).normalize() * 0.5f64.to_radians());
    let turned = TurnedCamera { inner: truth, rot, viewpoint };
    let align = FrameAlignment::new(truth, &turned);
    let found = nalgebra::UnitQuaternion::from_rotation_matrix(&(align.rot * rot.inverse())).angle().to_degrees();
    assert!(found < 1e-9 && align.ray_max_deg < 1e-5, "alignment off by {found}°, rays {}°", align.ray_max_deg);
    let (angle, off, rms) = calibrate_with_camera(&sensor, truth, "true camera", false);
    let (angle_t, off_t, rms_t) = calibrate_with_camera(&sensor, &turned, "turned true camera", false);
    assert!(
        (angle - angle_t).abs() < 1e-4 && (off - off_t).abs() < 1e-3 && (rms - rms_t).abs() < 1e-3,
        "true camera {angle}°, {off} mm, {rms} mm; turned {angle_t}°, {off_t} mm, {rms_t} mm"
    );
}

/// A camera calibrated by `omni_calib::receiver::calibrate` as a user does it: `count` 9 × 6
/// boards (30 mm) of the simulator's calibration board set rendered, their corners detected
/// inside the mirror annulus, and the annulus given to the calibration (the rim circle a user
/// measures in an image of a lit scene; here the true camera's).
fn rendered_receiver_camera(sensor: &Sensor, count: usize, seed: u64) -> Box<dyn CameraModel> {
    use omni_simulator::{calibration_board_poses, render_board_image};
    use omni_vision::corners::{DetectorOptions, GrayF32, detect_board};
    use rayon::prelude::*;
    let board = BoardFile::new(9, 6, 30.0);
    let c = sensor.camera.mirror_circle();
    let annulus = [c.centre.x, c.centre.y, c.inner_radius, c.outer_radius];
    let detector = DetectorOptions { annulus: Some(annulus), ..Default::default() };
    let poses = calibration_board_poses(sensor, &board, count, seed).unwrap();
    let obs: Vec<crate::receiver::Observation> = poses
        .par_iter()
        .enumerate()
        .filter_map(|(k, pose)| {
            let opts = RenderOptions { seed: seed + k as u64, ..RenderOptions::calibration() };
            let (frame, _) = render_board_image(sensor, pose, &board, &opts);
            let scale = 255.0 / frame.max_value() as f32;
            let img = GrayF32 {
                width: frame.width as usize,
                height: frame.height as usize,
                data: frame.data.iter().map(|&v| v as f32 * scale).collect(),
            };
            let found = detect_board(&img, 9, 6, &detector).ok()?;
            Some(crate::receiver::Observation::from_corners(&format!("board{k}"), &found, board.square_mm))
        })
        .collect();
    let (w, h) = sensor.camera.image_size();
    let opts = crate::receiver::Options { annulus: Some(annulus), ..Default::default() };
    let cal = crate::receiver::calibrate(w, h, &obs, &opts).unwrap();
    eprintln!("receiver: {} rendered boards, reprojection RMS {:.3} px", obs.len(), cal.rms_px);
    at_true_viewpoint(cal.spec, sensor)
}
