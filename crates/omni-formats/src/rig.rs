//! `rig.json` and `board_poses.json`: the checkerboards used to calibrate the light planes
//! (omni-calib-plane), and their poses in the world frame.
//!
//! A rig is a list of boards. Boards that share a `placement` number stand still together
//! (the paper's two perpendicular boards are two boards of placement 0); a calibration may also
//! move one board through several placements. A frame record of the stream belongs to the
//! placement named by its optional `placement` field (default 0).
//!
//! Board frame (the same as a `board.json` board): origin at the first inner corner, x along
//! the columns (inner corner (i, j) at (i·s, j·s, 0) mm), y along the rows, z = x × y. The
//! physical board (squares plus white margin m) spans x ∈ [−s − m, cols·s + m] and
//! y ∈ [−s − m, rows·s + m].

use crate::Versioned;
use serde::{Deserialize, Serialize};

/// `rig.json`: the boards of a light-plane calibration rig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigFile {
    pub format: String,
    pub version: u32,
    pub boards: Vec<RigBoard>,
}

/// One checkerboard of a rig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigBoard {
    /// Unique name, e.g. `left`; poses refer to boards by this name.
    pub name: String,
    /// Inner corners along the board's x (columns).
    pub inner_cols: u32,
    /// Inner corners along the board's y (rows).
    pub inner_rows: u32,
    /// Square side (mm).
    pub square_mm: f64,
    /// White margin around the outer squares (mm).
    #[serde(default)]
    pub margin_mm: f64,
    /// Which placement (set of frames) the board belongs to.
    #[serde(default)]
    pub placement: u32,
}

impl Versioned for RigFile {
    const FORMAT: &'static str = "omniscan.rig";
    const VERSION: u32 = 1;

    fn check(&self) -> Result<(), String> {
        self.validate()
    }
}

impl RigBoard {
    /// The physical board outline in board coordinates (mm): (x_min, x_max, y_min, y_max).
    pub fn extent_mm(&self) -> (f64, f64, f64, f64) {
        let (s, m) = (self.square_mm, self.margin_mm);
        (-s - m, self.inner_cols as f64 * s + m, -s - m, self.inner_rows as f64 * s + m)
    }

    /// Inner corner positions in board coordinates (mm), row by row (index = j·cols + i).
    pub fn corners_mm(&self) -> Vec<[f64; 2]> {
        let s = self.square_mm;
        (0..self.inner_rows).flat_map(|j| (0..self.inner_cols).map(move |i| [i as f64 * s, j as f64 * s])).collect()
    }
}

impl RigFile {
    pub fn new(boards: Vec<RigBoard>) -> Self {
        RigFile { format: Self::FORMAT.into(), version: Self::VERSION, boards }
    }

    /// Checks values; the message names the field at fault.
    pub fn validate(&self) -> Result<(), String> {
        if self.boards.is_empty() {
            return Err("field boards: the rig has no boards".into());
        }
        for (i, b) in self.boards.iter().enumerate() {
            if b.name.is_empty() {
                return Err(format!("field boards[{i}].name: must not be empty"));
            }
            if self.boards[..i].iter().any(|o| o.name == b.name) {
                return Err(format!("field boards[{i}].name: duplicate board name \"{}\"", b.name));
            }
            crate::docs::check_board_corners(&format!("boards[{i}]."), b.inner_cols, b.inner_rows)?;
            if !(b.square_mm.is_finite() && b.square_mm > 0.0) {
                return Err(format!("field boards[{i}].square_mm: must be positive, got {}", b.square_mm));
            }
            if !(b.margin_mm.is_finite() && b.margin_mm >= 0.0) {
                return Err(format!("field boards[{i}].margin_mm: must be non-negative, got {}", b.margin_mm));
            }
        }
        Ok(())
    }
}

/// A rigid pose board → world: p_world = rotation · p_board + translation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardPose {
    /// Name of the rig board.
    pub board: String,
    /// Rotation matrix, row by row; its columns are the board's x, y, z axes in the world frame.
    pub rotation: [[f64; 3]; 3],
    /// Board origin (first inner corner) in the world frame (mm).
    pub translation_mm: [f64; 3],
}

impl BoardPose {
    /// Checks the rotation is finite and orthonormal with determinant +1 (to 1e-6).
    pub fn validate(&self) -> Result<(), String> {
        let r = &self.rotation;
        if !r.iter().flatten().chain(self.translation_mm.iter()).all(|x| x.is_finite()) {
            return Err("rotation and translation_mm must be finite".into());
        }
        for a in 0..3 {
            for b in 0..3 {
                let dot: f64 = (0..3).map(|k| r[k][a] * r[k][b]).sum();
                let want = if a == b { 1.0 } else { 0.0 };
                if (dot - want).abs() > 1e-6 {
                    return Err("rotation is not orthonormal".into());
                }
            }
        }
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        if det < 0.0 {
            return Err("rotation is a reflection (determinant −1)".into());
        }
        Ok(())
    }
}

/// `board_poses.json`: known board poses (e.g. measured, or the simulator's ground truth),
/// an alternative to finding them in a pose image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardPosesFile {
    pub format: String,
    pub version: u32,
    pub poses: Vec<BoardPose>,
}

impl Versioned for BoardPosesFile {
    const FORMAT: &'static str = "omniscan.board_poses";
    const VERSION: u32 = 1;

    fn check(&self) -> Result<(), String> {
        self.validate()
    }
}

impl BoardPosesFile {
    pub fn new(poses: Vec<BoardPose>) -> Self {
        BoardPosesFile { format: Self::FORMAT.into(), version: Self::VERSION, poses }
    }

    /// Checks every pose, and that no board has two; the message names the entry at fault.
    pub fn validate(&self) -> Result<(), String> {
        for (i, p) in self.poses.iter().enumerate() {
            p.validate().map_err(|m| format!("field poses[{i}] (board \"{}\"): {m}", p.board))?;
            if self.poses[..i].iter().any(|q| q.board == p.board) {
                return Err(format!("field poses[{i}]: board \"{}\" has a pose already", p.board));
            }
        }
        Ok(())
    }
}

/// Detected (or given) inner-corner pixels of one rig board in the pose image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardCorners {
    /// Name of the rig board.
    pub board: String,
    /// `[i, j, u, v]`: inner corner (column i, row j) seen at pixel (u, v).
    pub corners: Vec<[f64; 4]>,
}

/// `board_corners.json`: corner pixels of the rig boards in the pose image, from which
/// omni-calib-plane estimates the board poses with the calibrated camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardCornersFile {
    pub format: String,
    pub version: u32,
    pub boards: Vec<BoardCorners>,
}

impl Versioned for BoardCornersFile {
    const FORMAT: &'static str = "omniscan.board_corners";
    const VERSION: u32 = 1;
}

impl BoardCornersFile {
    pub fn new(boards: Vec<BoardCorners>) -> Self {
        BoardCornersFile { format: Self::FORMAT.into(), version: Self::VERSION, boards }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every reader of board poses refuses a rotation that is not one and a board posed twice,
    /// naming the entry.
    #[test]
    fn board_poses_are_rotations_one_per_board() {
        let pose = |board: &str, r00: f64| BoardPose {
            board: board.into(),
            rotation: [[r00, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation_mm: [0.0, 0.0, 500.0],
        };
        let parse = |poses: Vec<BoardPose>| {
            let text = serde_json::to_vec(&BoardPosesFile::new(poses)).unwrap();
            crate::parse_doc::<BoardPosesFile>(&text, "poses.json").map_err(|e| e.to_string())
        };
        assert!(parse(vec![pose("a", 1.0), pose("b", 1.0)]).is_ok());
        let err = parse(vec![pose("a", 1.0), pose("b", 2.0)]).unwrap_err();
        assert!(
            err.contains("poses.json") && err.contains("poses[1] (board \"b\"): rotation is not orthonormal"),
            "{err}"
        );
        let err = parse(vec![pose("a", 1.0), pose("a", 1.0)]).unwrap_err();
        assert!(err.contains("poses[1]: board \"a\" has a pose already"), "{err}");
    }

    fn rig() -> RigFile {
        let b = |name: &str| RigBoard {
            name: name.into(),
            inner_cols: 7,
            inner_rows: 5,
            square_mm: 40.0,
            margin_mm: 20.0,
            placement: 0,
        };
        RigFile::new(vec![b("left"), b("right")])
    }

    #[test]
    fn rig_round_trips_and_names_bad_fields() {
        let r = rig();
        let text = serde_json::to_vec(&r).unwrap();
        let back: RigFile = crate::docs::parse_doc(&text, "rig.json").unwrap();
        assert_eq!(back, r);
        assert_eq!(r.boards[0].extent_mm(), (-60.0, 300.0, -60.0, 220.0));
        assert_eq!(r.boards[0].corners_mm()[8], [40.0, 40.0]);
        let mut bad = rig();
        bad.boards[1].name = "left".into();
        assert!(bad.validate().unwrap_err().contains("boards[1].name"));
        let mut bad = rig();
        bad.boards[0].square_mm = f64::NAN;
        assert!(bad.validate().unwrap_err().contains("boards[0].square_mm"));
    }

    #[test]
    fn pose_validation_rejects_non_rotations() {
        let mut p = BoardPose {
            board: "a".into(),
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation_mm: [0.0; 3],
        };
        assert!(p.validate().is_ok());
        p.rotation[2][2] = -1.0;
        assert!(p.validate().unwrap_err().contains("reflection"));
        p.rotation[2][2] = 2.0;
        assert!(p.validate().unwrap_err().contains("orthonormal"));
    }
}
