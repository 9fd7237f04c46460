//! Turning the tool's input files into the calibration's inputs: the stripe stream into
//! [`FrameStripes`], and board poses (given, or from corner pixels) into [`PlacedBoard`]s.

use super::{FrameStripes, PlacedBoard};
use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Rotation3, Translation3, UnitQuaternion, Vector2};
use omni_formats::rig::{BoardCornersFile, BoardPose, BoardPosesFile, RigFile};
use omni_formats::stream::{Record, StreamReader};
use omni_formats::{Error, Result};
use omni_model::CameraModel;
use serde::Serialize;
use std::io::BufRead;

/// Reads the laser frames of an omni-ridge stream. Frames without lasers (ambient) are skipped;
/// a laser frame without a `stripe` field is an error naming the line. A frame's rig placement
/// is its optional integer field `placement` (default 0).
pub fn read_stripe_frames<R: BufRead>(reader: &mut StreamReader<R>) -> Result<Vec<FrameStripes>> {
    let mut frames = vec![];
    while let Some(record) = reader.next_record()? {
        let Record::Frame(f) = record else { continue };
        let loc = format!("line {} (frame {})", reader.line(), f.seq);
        if f.lasers.is_empty() {
            continue;
        }
        let Some(stripe) = &f.stripe else {
            return Err(Error::new(reader.name(), loc, "no stripe field: run omni-ridge on the frames first"));
        };
        let placement = match f.extra.get("placement") {
            None => 0,
            Some(v) => v.as_u64().and_then(|p| u32::try_from(p).ok()).ok_or_else(|| {
                Error::new(reader.name(), &loc, "field placement: expected a small non-negative integer")
            })?,
        };
        frames.push(FrameStripes {
            seq: f.seq,
            alpha_rad: f.alpha_deg.to_radians(),
            facet: f.facet,
            placement,
            lasers: f.lasers.clone(),
            pixels: stripe.iter().map(|p| [p.u, p.v]).collect(),
        });
    }
    Ok(frames)
}

/// A board pose estimated from corner pixels.
#[derive(Debug, Clone)]
pub struct BoardPoseFit {
    /// Board → world (mm).
    pub pose: Isometry3<f64>,
    /// RMS angle between the corners' camera rays and the directions to the posed corners (rad).
    pub rms_rad: f64,
    /// Corners whose pixels give a camera ray.
    pub corners_used: usize,
    /// Covariance of the pose's parameters (rotation vector rad, translation mm), the corners'
    /// errors independent; `None` if singular.
    pub covariance: Option<Matrix6<f64>>,
}

/// The pose of a planar board from its corners with any calibrated camera: the receiver
/// calibration's estimator ([`crate::pose::estimate_board_pose`]: linear pose from the rays, then
/// Levenberg–Marquardt on the reprojection error), with the figures the report states.
/// `board_mm` are the corners' board coordinates (mm, z = 0), `pixels` their image positions.
/// `None` if fewer than 4 corners give rays or the estimate degenerates.
pub fn estimate_board_pose(
    camera: &dyn CameraModel,
    board_mm: &[[f64; 2]],
    pixels: &[[f64; 2]],
) -> Option<BoardPoseFit> {
    let (pose, covariance) = crate::pose::estimate_board_pose_with_covariance(camera, board_mm, pixels)?;
    let (mut ss, mut n) = (0.0, 0usize);
    for (xy, px) in board_mm.iter().zip(pixels) {
        if let Some(ray) = camera.pixel_to_ray(&Vector2::new(px[0], px[1])) {
            let to_corner = pose * Point3::new(xy[0], xy[1], 0.0) - ray.origin;
            ss += ray.dir.angle(&to_corner).powi(2);
            n += 1;
        }
    }
    Some(BoardPoseFit { pose, rms_rad: (ss / n.max(1) as f64).sqrt(), corners_used: n, covariance })
}

/// A board's pose as used, for the report.
#[derive(Debug, Clone, Serialize)]
pub struct BoardPoseReport {
    pub board: String,
    pub placement: u32,
    pub rotation: [[f64; 3]; 3],
    pub translation_mm: [f64; 3],
    /// Where the pose came from: `given` or `corners`.
    pub source: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corners_used: Option<usize>,
    /// RMS angle between corner rays and the posed corners (degrees).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corner_rms_deg: Option<f64>,
}

fn isometry_from(pose: &BoardPose) -> Isometry3<f64> {
    let r = &pose.rotation;
    let m = Matrix3::new(r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]);
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
    Isometry3::from_parts(Translation3::from(nalgebra::Vector3::from(pose.translation_mm)), rot)
}

/// The pose file entry for an isometry (board → world).
pub fn board_pose_entry(board: &str, pose: &Isometry3<f64>) -> BoardPose {
    let m = pose.rotation.to_rotation_matrix().into_inner();
    BoardPose {
        board: board.into(),
        rotation: [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
        ],
        translation_mm: pose.translation.vector.into(),
    }
}

fn report(board: &omni_formats::rig::RigBoard, pose: &Isometry3<f64>, source: &'static str) -> BoardPoseReport {
    let e = board_pose_entry(&board.name, pose);
    BoardPoseReport {
        board: board.name.clone(),
        placement: board.placement,
        rotation: e.rotation,
        translation_mm: e.translation_mm,
        source,
        corners_used: None,
        corner_rms_deg: None,
    }
}

/// Boards at given poses. Every rig board needs exactly one pose; errors name the board.
pub fn boards_from_poses(
    rig: &RigFile,
    poses: &BoardPosesFile,
) -> std::result::Result<Vec<(PlacedBoard, BoardPoseReport)>, String> {
    poses.validate()?;
    if let Some(p) = poses.poses.iter().find(|p| !rig.boards.iter().any(|b| b.name == p.board)) {
        return Err(format!("pose for board \"{}\", which is not in the rig", p.board));
    }
    rig.boards
        .iter()
        .map(|b| {
            let mut found = poses.poses.iter().filter(|p| p.board == b.name);
            let pose = found.next().ok_or_else(|| format!("board \"{}\" not found: no pose given for it", b.name))?;
            if found.next().is_some() {
                return Err(format!("board \"{}\" has more than one pose", b.name));
            }
            let iso = isometry_from(pose);
            Ok((PlacedBoard::new(b, iso), report(b, &iso, "given")))
        })
        .collect()
}

/// Boards posed from their corner pixels with the calibrated camera. Every rig board needs at
/// least `min_corners` corners that the camera sees; errors name the board.
pub fn boards_from_corners(
    camera: &dyn CameraModel,
    rig: &RigFile,
    corners: &BoardCornersFile,
    min_corners: usize,
) -> std::result::Result<Vec<(PlacedBoard, BoardPoseReport)>, String> {
    if let Some(c) = corners.boards.iter().find(|c| !rig.boards.iter().any(|b| b.name == c.board)) {
        return Err(format!("corners for board \"{}\", which is not in the rig", c.board));
    }
    rig.boards
        .iter()
        .map(|b| {
            let c = corners
                .boards
                .iter()
                .find(|c| c.board == b.name)
                .ok_or_else(|| format!("board \"{}\" not found: no corners given for it", b.name))?;
            let mut pts = vec![];
            let mut px = vec![];
            for (k, &[i, j, u, v]) in c.corners.iter().enumerate() {
                let (ok_i, ok_j) = (i >= 0.0 && i < b.inner_cols as f64, j >= 0.0 && j < b.inner_rows as f64);
                if !(ok_i && ok_j && i.fract() == 0.0 && j.fract() == 0.0 && u.is_finite() && v.is_finite()) {
                    return Err(format!("board \"{}\" corner {k}: index ({i}, {j}) or pixel not valid", b.name));
                }
                pts.push([i * b.square_mm, j * b.square_mm]);
                px.push([u, v]);
            }
            let fit =
                estimate_board_pose(camera, &pts, &px).filter(|f| f.corners_used >= min_corners).ok_or_else(|| {
                    format!(
                        "board \"{}\" not found: fewer than {min_corners} of its {} corners give camera rays",
                        b.name,
                        pts.len()
                    )
                })?;
            let mut r = report(b, &fit.pose, "corners");
            r.corners_used = Some(fit.corners_used);
            r.corner_rms_deg = Some(fit.rms_rad.to_degrees());
            Ok((PlacedBoard::new(b, fit.pose).with_pose_covariance(fit.covariance), r))
        })
        .collect()
}

/// Boards found in the ambient pose image: each rig board is detected in turn
/// ([`omni_vision::corners::detect_board`]), posed with the camera, and blanked out of the image
/// so the next detection finds the next board. The corner labeling may come out mirrored or
/// turned by 180°; both leave the board's outline in place (it is symmetric), and the proper
/// labeling is the one whose pose explains the corners better. Boards of the same size are
/// matched to the rig's boards in detection order (their names may swap; the calibration only
/// uses their planes and outlines). Only rigs with one placement (one pose image) are supported.
pub fn boards_from_pose_image(
    camera: &dyn CameraModel,
    rig: &RigFile,
    image: &omni_vision::corners::GrayF32,
    min_corners: usize,
) -> std::result::Result<Vec<(PlacedBoard, BoardPoseReport)>, String> {
    use omni_vision::corners::{DetectorOptions, detect_board};
    let (w, h) = camera.image_size();
    if (image.width, image.height) != (w as usize, h as usize) {
        return Err(format!(
            "image is {} × {} px but the camera model (--camera) is for {w} × {h} px images (another camera or a resized picture?)",
            image.width, image.height
        ));
    }
    if rig.boards.iter().any(|b| b.placement != rig.boards[0].placement) {
        return Err("a pose image shows one placement; give --board-corners or --board-poses for several".into());
    }
    let circle = camera.mirror_circle();
    let opts = DetectorOptions {
        annulus: Some([circle.centre.x, circle.centre.y, circle.inner_radius, circle.outer_radius]),
        min_corners: min_corners.max(4),
        ..Default::default()
    };
    let mut img = image.clone();
    let mut out = vec![];
    for b in &rig.boards {
        let found = detect_board(&img, b.inner_cols, b.inner_rows, &opts)
            .map_err(|why| format!("board \"{}\" not found in the pose image: {why}", b.name))?;
        let fit = [found.clone(), found.mirrored()]
            .iter()
            .filter_map(|labels| {
                let pts: Vec<[f64; 2]> = labels
                    .corners
                    .iter()
                    .map(|c| [c.index[0] as f64 * b.square_mm, c.index[1] as f64 * b.square_mm])
                    .collect();
                let px: Vec<[f64; 2]> = labels.corners.iter().map(|c| c.px).collect();
                estimate_board_pose(camera, &pts, &px).map(|f| (f, pts, px))
            })
            .min_by(|a, b| a.0.rms_rad.total_cmp(&b.0.rms_rad))
            .filter(|(f, _, _)| f.corners_used >= min_corners)
            .ok_or_else(|| format!("board \"{}\" found in the pose image but could not be posed", b.name))?;
        let (fit, _, px) = fit;
        blank_board(&mut img, &px);
        let mut r = report(b, &fit.pose, "pose image");
        r.corners_used = Some(fit.corners_used);
        r.corner_rms_deg = Some(fit.rms_rad.to_degrees());
        out.push((PlacedBoard::new(b, fit.pose).with_pose_covariance(fit.covariance), r));
    }
    Ok(out)
}

/// The pixel mean of several images of the same static scene (e.g. ambient images of the rig):
/// the sensor noise falls as 1/√n, so corners found in it, and the boards posed from them, are
/// more accurate than from one image. Errors if the list is empty or the sizes differ.
pub fn mean_image(
    images: &[omni_vision::corners::GrayF32],
) -> std::result::Result<omni_vision::corners::GrayF32, String> {
    let first = images.first().ok_or("no image to average")?;
    let mut sum = vec![0.0f64; first.data.len()];
    for (k, img) in images.iter().enumerate() {
        if (img.width, img.height) != (first.width, first.height) {
            return Err(format!(
                "image {} is {}×{} px, the first is {}×{}: the images must show the same view",
                k + 1,
                img.width,
                img.height,
                first.width,
                first.height
            ));
        }
        for (s, v) in sum.iter_mut().zip(&img.data) {
            *s += *v as f64;
        }
    }
    let n = images.len() as f64;
    let data = sum.iter().map(|s| (s / n) as f32).collect();
    Ok(omni_vision::corners::GrayF32 { width: first.width, height: first.height, data })
}

/// Paints the board's corner region, grown by half its size about its centroid, with the image's
/// median grey, so that the detector cannot find the same board again.
fn blank_board(img: &mut omni_vision::corners::GrayF32, px: &[[f64; 2]]) {
    let hull = convex_hull(px);
    if hull.len() < 3 {
        return;
    }
    let n = hull.len() as f64;
    let c = hull.iter().fold([0.0, 0.0], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n]);
    let grown: Vec<[f64; 2]> = hull.iter().map(|p| [c[0] + 1.5 * (p[0] - c[0]), c[1] + 1.5 * (p[1] - c[1])]).collect();
    let mut sorted = img.data.clone();
    sorted.sort_by(f32::total_cmp);
    let grey = sorted[sorted.len() / 2];
    let (x0, x1) = grown.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| (a.0.min(p[0]), a.1.max(p[0])));
    let (y0, y1) = grown.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| (a.0.min(p[1]), a.1.max(p[1])));
    for y in (y0.floor().max(0.0) as usize)..=(y1.ceil().min(img.height as f64 - 1.0) as usize) {
        for x in (x0.floor().max(0.0) as usize)..=(x1.ceil().min(img.width as f64 - 1.0) as usize) {
            if inside_convex(&grown, [x as f64, y as f64]) {
                img.data[y * img.width + x] = grey;
            }
        }
    }
}

/// Convex hull (Andrew's monotone chain), counter-clockwise in (x, y).
fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> =
            if pass == 0 { Box::new(p.iter()) } else { Box::new(p.iter().rev()) };
        for &q in iter {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

fn inside_convex(hull: &[[f64; 2]], q: [f64; 2]) -> bool {
    let n = hull.len();
    (0..n).all(|i| {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) >= 0.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::synth::paper_camera;
    use omni_simulator::rng::SplitMix64;

    #[test]
    fn mean_image_averages_pixels_and_refuses_other_sizes() {
        use omni_vision::corners::GrayF32;
        let img = |w: usize, h: usize, f: &dyn Fn(usize) -> f32| GrayF32 {
            width: w,
            height: h,
            data: (0..w * h).map(f).collect(),
        };
        let a = img(4, 3, &|i| i as f32);
        let b = img(4, 3, &|i| 100.0 - i as f32);
        let c = img(4, 3, &|_| 20.0);
        let mean = mean_image(&[a.clone(), b, c]).unwrap();
        assert_eq!((mean.width, mean.height), (4, 3));
        assert!(mean.data.iter().all(|v| (v - 40.0).abs() < 1e-5), "{:?}", mean.data);
        assert_eq!(mean_image(std::slice::from_ref(&a)).unwrap().data, a.data);
        let err = mean_image(&[a.clone(), img(3, 4, &|_| 0.0)]).unwrap_err();
        assert!(err.contains("image 2") && err.contains("3×4"), "{err}");
        assert!(mean_image(&[]).is_err());
    }

    #[test]
    fn board_pose_from_noisy_corners_with_its_report_figures() {
        let camera = paper_camera();
        let truth = Isometry3::from_parts(
            Translation3::new(450.0, -120.0, -150.0),
            UnitQuaternion::from_euler_angles(1.9, 0.3, -0.8),
        );
        let board: Vec<[f64; 2]> =
            (0..6).flat_map(|j| (0..8).map(move |i| [i as f64 * 30.0, j as f64 * 30.0])).collect();
        let mut rng = SplitMix64::new(7);
        let mut used = vec![];
        let mut pixels = vec![];
        for b in &board {
            if let Some(px) = camera.point_to_pixel(&(truth * Point3::new(b[0], b[1], 0.0))) {
                used.push(*b);
                pixels.push([px.x + 0.1 * rng.normal(), px.y + 0.1 * rng.normal()]);
            }
        }
        assert!(used.len() >= 40, "board mostly visible: {}", used.len());
        let fit = estimate_board_pose(&camera, &used, &pixels).unwrap();
        let dt = (fit.pose.translation.vector - truth.translation.vector).norm();
        let dr = fit.pose.rotation.angle_to(&truth.rotation).to_degrees();
        // 0.1 px noise on ~48 corners at ~0.5 m: sub-millimetre, hundredths of a degree.
        assert!(dt < 1.0 && dr < 0.1, "translation error {dt} mm, rotation error {dr}°");
        assert_eq!(fit.corners_used, used.len());
        // The camera sees ~0.3°/px here: 0.1 px of noise is ~0.03° of ray angle.
        let rms_deg = fit.rms_rad.to_degrees();
        assert!(rms_deg > 0.005 && rms_deg < 0.06, "corner rms {rms_deg}°");
        // Too few corners: no pose.
        assert!(estimate_board_pose(&camera, &used[..3], &pixels[..3]).is_none());
    }
}
