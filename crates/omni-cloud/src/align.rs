//! Registration of a calibrated sensor's frame to a reference frame through the calibration rig.
//!
//! A calibrated sensor measures in its own frame (the receiver calibration fixes it: image axes
//! and the single viewpoint). To compare its clouds with ground truth given in another frame, the
//! rig boards serve as the datum: their corners, placed with the poses used during light-plane
//! calibration, are registered rigidly (Kabsch) onto the same corners placed with the boards'
//! known poses. Boards of the same size may have been matched to rig names in either order, so
//! every assignment of used poses to reference poses among same-size boards is tried, and so is
//! each board's symmetric labelling (a detector may number a board's corners from the opposite
//! end); the combination with the smallest residual is kept. A symmetric rig (two equal boards
//! at a right angle) also fits itself turned half a turn, so the two frames are assumed to differ
//! by less than 90° — true for any calibration that follows SENSOR.md's frame conventions.

use omni_formats::rig::{BoardPose, RigFile};
use omni_geom::{Isometry3, Matrix3, Point3, Vector3};

/// The board's inner corners in the world, in row-major order of the board's labels; `flip`
/// (bit 0: columns, bit 1: rows) relabels them as a detector that resolved the board's symmetric
/// orientation the other way would have.
fn corners_world(rig: &RigFile, pose: &BoardPose, flip: u8) -> Option<Vec<Point3<f64>>> {
    let board = rig.boards.iter().find(|b| b.name == pose.board)?;
    let r = &pose.rotation;
    let m = Matrix3::new(r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]);
    let t = Vector3::from(pose.translation_mm);
    let (cols, rows, s) = (board.inner_cols, board.inner_rows, board.square_mm);
    let mut out = Vec::with_capacity((cols * rows) as usize);
    for j in 0..rows {
        for i in 0..cols {
            let fi = if flip & 1 != 0 { cols - 1 - i } else { i };
            let fj = if flip & 2 != 0 { rows - 1 - j } else { j };
            out.push(Point3::from(m * Vector3::new(fi as f64 * s, fj as f64 * s, 0.0) + t));
        }
    }
    Some(out)
}

/// All permutations of `0..n` (n is the number of rig boards: small).
fn permutations(n: usize) -> Vec<Vec<usize>> {
    if n == 0 {
        return vec![vec![]];
    }
    let mut out = Vec::new();
    for p in permutations(n - 1) {
        for i in 0..=p.len() {
            let mut q = p.clone();
            q.insert(i, n - 1);
            out.push(q);
        }
    }
    out
}

/// The transform calibrated → reference and its RMS corner residual (mm).
pub fn register_rig(
    rig: &RigFile,
    used: &[BoardPose],
    reference: &[BoardPose],
) -> Result<(Isometry3<f64>, f64), String> {
    if used.is_empty() || reference.len() < used.len() || reference.len() > 6 {
        return Err(format!("cannot pair {} used board poses with {} reference poses", used.len(), reference.len()));
    }
    let size = |name: &str| rig.boards.iter().find(|b| b.name == name).map(|b| (b.inner_cols, b.inner_rows));
    let mut best: Option<(Isometry3<f64>, f64)> = None;
    let n = used.len();
    for perm in permutations(reference.len()) {
        if used.iter().zip(&perm).any(|(u, &r)| size(&u.board).is_none() || size(&u.board) != size(&reference[r].board))
        {
            continue;
        }
        // Every combination of per-board relabellings (4 per board).
        for flips in 0..4usize.pow(n as u32) {
            let (mut src, mut dst) = (Vec::new(), Vec::new());
            for (k, (u, &r)) in used.iter().zip(&perm).enumerate() {
                let flip = ((flips >> (2 * k)) & 3) as u8;
                let (Some(a), Some(b)) = (corners_world(rig, u, flip), corners_world(rig, &reference[r], 0)) else {
                    continue;
                };
                src.extend(a);
                dst.extend(b);
            }
            if let Some((iso, rms)) = omni_geom::fit::kabsch(&src, &dst)
                && iso.rotation.angle() < std::f64::consts::FRAC_PI_2
                && best.is_none_or(|(_, b)| rms < b)
            {
                best = Some((iso, rms));
            }
        }
    }
    best.ok_or_else(|| "no board of the calibration matches a reference board by name and size".into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_formats::rig::RigBoard;

    fn pose(name: &str, iso: &Isometry3<f64>) -> BoardPose {
        let m = iso.rotation.to_rotation_matrix().into_inner();
        let t = iso.translation.vector;
        BoardPose {
            board: name.into(),
            rotation: [0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]),
            translation_mm: [t.x, t.y, t.z],
        }
    }

    #[test]
    fn recovers_the_frame_change_even_with_swapped_names() {
        let board = |name: &str| RigBoard {
            name: name.into(),
            inner_cols: 9,
            inner_rows: 6,
            square_mm: 30.0,
            margin_mm: 30.0,
            placement: 0,
        };
        let rig = RigFile::new(vec![board("upper"), board("lower")]);
        let upper = Isometry3::new(Vector3::new(600.0, -120.0, 0.0), Vector3::new(0.0, 0.8, 0.0));
        let lower = Isometry3::new(Vector3::new(600.0, -120.0, -10.0), Vector3::new(0.0, -0.8, 0.3));
        let change = Isometry3::new(Vector3::new(0.2, -0.1, 80.0), Vector3::new(0.001, 0.002, -0.003));
        let reference = vec![pose("upper", &upper), pose("lower", &lower)];
        // The calibrated frame sees the boards through `change⁻¹`, with the names swapped.
        // The second board is also labelled from its opposite corner (a 180° turn in its plane).
        let turn = Isometry3::new(Vector3::new(240.0, 150.0, 0.0), Vector3::new(0.0, 0.0, std::f64::consts::PI));
        let used = vec![pose("upper", &(change.inverse() * lower)), pose("lower", &(change.inverse() * upper * turn))];
        let (iso, rms) = register_rig(&rig, &used, &reference).unwrap();
        assert!(rms < 1e-9, "{rms}");
        assert!((iso.translation.vector - change.translation.vector).norm() < 1e-9);
    }
}
