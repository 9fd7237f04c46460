//! Turning the tool's input files into the calibration's inputs: the stripe stream into
//! [`FrameStripes`], and board poses (given, or from corner pixels) into [`PlacedBoard`]s.

use super::{FrameStripes, PlacedBoard, estimate_board_pose};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
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
            Ok((PlacedBoard::new(b, fit.pose), r))
        })
        .collect()
}
