//! Exact synthetic geometry for testing and benchmarking the light-plane calibration without
//! rendering: the paper camera, a rig of two perpendicular boards, corner pixels and stripe
//! pixels (light plane ∩ board, projected through the true camera) with Gaussian pixel noise
//! from a seeded generator. (The rendered equivalent is `omni_simulator`'s rig.)

use super::{FrameStripes, PlacedBoard};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use omni_formats::rig::RigBoard;
use omni_geom::Plane;
use omni_geom::rng::SplitMix64;
use omni_model::{CameraModel, HyperbolicCamera, HyperbolicParams, LightPlane, Transmitter};

pub fn paper_camera() -> HyperbolicCamera {
    HyperbolicCamera::new(HyperbolicParams::paper()).unwrap()
}

/// Two 7 × 9 boards (40 mm squares, 20 mm margin), long side vertical, meeting at a right angle
/// along a vertical spine at x = `spine_mm` on the +x side, opened towards the sensor; they span
/// z ≈ −340…100 mm so laser 0's planes cross both over most of a facet's sweep.
pub fn two_board_rig(spine_mm: f64) -> Vec<(RigBoard, Isometry3<f64>)> {
    let board = |name: &str| RigBoard {
        name: name.into(),
        inner_cols: 7,
        inner_rows: 9,
        square_mm: 40.0,
        margin_mm: 20.0,
        placement: 0,
    };
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let down = Vector3::new(0.0, 0.0, -1.0);
    [("left", s), ("right", -s)]
        .into_iter()
        .map(|(name, side)| {
            let bx = Vector3::new(-s, side, 0.0);
            let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[bx, down, bx.cross(&down)]));
            // The board's far edge (x_b = −60 mm) on the spine, its top edge (y_b = −60 mm) at z = 100.
            let origin = Vector3::new(spine_mm, 0.0, 40.0) + bx * 60.0;
            (board(name), Isometry3::from_parts(Translation3::from(origin), UnitQuaternion::from_rotation_matrix(&rot)))
        })
        .collect()
}

/// Corner pixels of a posed board seen by `camera`, with Gaussian noise (σ = `noise_px`):
/// (board coordinates, pixels) of the visible corners.
pub fn corner_pixels(
    camera: &dyn CameraModel,
    board: &RigBoard,
    pose: &Isometry3<f64>,
    noise_px: f64,
    rng: &mut SplitMix64,
) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let mut used = vec![];
    let mut px = vec![];
    for c in board.corners_mm() {
        if let Some(p) = camera.point_to_pixel(&(pose * Point3::new(c[0], c[1], 0.0))) {
            used.push(c);
            px.push([p.x + noise_px * rng.normal(), p.y + noise_px * rng.normal()]);
        }
    }
    (used, px)
}

/// The stripe pixels of one frame: where each lit laser's true light plane crosses each board
/// (sampled every `spacing_mm` along the line), projected through the true camera, plus noise.
pub fn stripe_frame(
    camera: &dyn CameraModel,
    truth: &Transmitter,
    boards: &[PlacedBoard],
    seq: u64,
    alpha_deg: f64,
    facet: u32,
    noise_px: f64,
    spacing_mm: f64,
    rng: &mut SplitMix64,
) -> FrameStripes {
    let mut pixels = vec![];
    for laser in 0..truth.num_lasers() {
        let Some(lp) = truth.light_plane(alpha_deg.to_radians(), facet, laser) else { continue };
        for b in boards {
            for p in plane_board_line(&lp.plane, b, spacing_mm) {
                if !lp.lights(&p) {
                    continue;
                }
                if let Some(px) = camera.point_to_pixel(&p) {
                    pixels.push([px.x + noise_px * rng.normal(), px.y + noise_px * rng.normal()]);
                }
            }
        }
    }
    FrameStripes {
        seq,
        alpha_rad: alpha_deg.to_radians(),
        facet,
        placement: 0,
        lasers: (0..truth.num_lasers() as u32).collect(),
        pixels,
    }
}

/// Points (world, mm) every `spacing_mm` along the line where `plane` crosses the board outline.
pub fn plane_board_line(plane: &Plane, board: &PlacedBoard, spacing_mm: f64) -> Vec<Point3<f64>> {
    let o = board.pose * Point3::origin();
    let (bx, by) = (board.pose * Vector3::x(), board.pose * Vector3::y());
    // In board coordinates the line is a·X + b·Y = c.
    let (a, b) = (plane.normal.dot(&bx), plane.normal.dot(&by));
    let c = plane.offset - plane.normal.dot(&o.coords);
    let norm2 = a * a + b * b;
    if norm2 < 1e-12 {
        return vec![];
    }
    let foot = (a * c / norm2, b * c / norm2);
    let dir = (-b / norm2.sqrt(), a / norm2.sqrt());
    let (x0, x1, y0, y1) = board.extent_mm;
    let reach = (x1 - x0).hypot(y1 - y0) + foot.0.hypot(foot.1);
    let n = (2.0 * reach / spacing_mm) as i64;
    (-n / 2..=n / 2)
        .map(|i| (foot.0 + dir.0 * i as f64 * spacing_mm, foot.1 + dir.1 * i as f64 * spacing_mm))
        .filter(|&(x, y)| x >= x0 && x <= x1 && y >= y0 && y <= y1)
        .map(|(x, y)| o + bx * x + by * y)
        .collect()
}

/// How far `fitted` is from the true light plane where it meets the scene: the angle between the
/// normals (degrees), and the distance of `fitted` from the true plane's central ray points at
/// 0.5 m and the largest over 0.5–2 m (mm, measured from the facet point).
pub fn plane_error(truth: &LightPlane, fitted: &Plane) -> (f64, f64, f64) {
    let angle = truth.plane.angle_to(fitted).to_degrees();
    let at = |r: f64| fitted.signed_distance(&(truth.facet_point + truth.out_dir.into_inner() * r)).abs();
    let worst = [500.0, 1000.0, 1500.0, 2000.0].into_iter().map(at).fold(0.0, f64::max);
    (angle, at(500.0), worst)
}
