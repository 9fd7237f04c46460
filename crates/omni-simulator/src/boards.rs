//! Checkerboard images for receiver calibration and the two-perpendicular-boards rig for
//! transmitter calibration.
//!
//! Board frame (OpenCV convention, as in [`omni_formats::scene::Shape::Checkerboard`]): origin at
//! the top-left inner corner, x along the columns, y along the rows (down), z into the board
//! (the printed face looks to −z). Corner `i` is at column `i % inner_cols`, row
//! `i / inner_cols`, at (col · square, row · square, 0) mm. A pose maps board → world.

use crate::frame::Frame16;
use crate::render::{RenderOptions, render_ambient_frame};
use crate::rng::{SplitMix64, mix};
use crate::scene::{Scene, board_corners};
use crate::sensor::Sensor;
use nalgebra::Translation3;
use omni_formats::BoardFile;
use omni_formats::rig::{BoardCorners, BoardCornersFile, BoardPose as RigBoardPose, BoardPosesFile, RigBoard, RigFile};
use omni_formats::scene::{SceneFile, SceneObject, Shape};
use omni_geom::{Isometry3, Matrix3, Point3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// A board pose as written to JSON: world point = rotation · board point + translation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BoardPose {
    /// Rotation matrix, row-major (board → world).
    pub rotation: [[f64; 3]; 3],
    /// Board origin (top-left inner corner) in the world (mm).
    pub translation_mm: [f64; 3],
}

impl BoardPose {
    pub fn from_isometry(iso: &Isometry3<f64>) -> Self {
        let m = iso.rotation.to_rotation_matrix().into_inner();
        let t = iso.translation.vector;
        BoardPose { rotation: [0, 1, 2].map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]]), translation_mm: [t.x, t.y, t.z] }
    }

    pub fn isometry(&self) -> Isometry3<f64> {
        let m = Matrix3::from_fn(|r, c| self.rotation[r][c]);
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&m));
        Isometry3::from_parts(Translation3::from(Vector3::from(self.translation_mm)), rot)
    }
}

/// The scene object of a board at a pose (white albedo 0.85, black 0.05).
pub fn board_object(board: &BoardFile, pose: &Isometry3<f64>) -> SceneObject {
    let s = board.square_mm;
    let centre =
        pose * Point3::new((board.inner_cols as f64 - 1.0) * s / 2.0, (board.inner_rows as f64 - 1.0) * s / 2.0, 0.0);
    let normal = pose.transform_vector(&-Vector3::z());
    let up = pose.transform_vector(&-Vector3::y());
    SceneObject {
        name: Some("checkerboard".into()),
        albedo: 0.85,
        texture: None,
        shape: Shape::Checkerboard {
            centre_mm: centre.coords.into(),
            normal: normal.into(),
            up: up.into(),
            square_mm: s,
            inner_cols: board.inner_cols,
            inner_rows: board.inner_rows,
            margin_mm: board.margin_mm,
            dark_albedo: 0.05,
        },
    }
}

/// Ground-truth pixels of a board's inner corners (row-major), `None` where the corner is not
/// visible (outside the mirror or image, the board's back towards the camera, or hidden).
pub fn corner_pixels(
    sensor: &Sensor,
    scene: &Scene,
    pose: &Isometry3<f64>,
    board: &BoardFile,
) -> Vec<Option<[f64; 2]>> {
    let front = pose.transform_vector(&-Vector3::z());
    board_corners(board.inner_cols, board.inner_rows, board.square_mm)
        .iter()
        .map(|c| {
            let p = pose * c;
            let px = sensor.camera.point_to_pixel(&p)?;
            let ray = sensor.camera.pixel_to_ray(&px)?;
            if ray.dir.dot(&front) >= 0.0 {
                return None;
            }
            let hit = scene.cast(&ray.origin, &ray.dir, 1e-6, f64::INFINITY)?;
            ((hit.point - p).norm() < 1e-3).then_some([px.x, px.y])
        })
        .collect()
}

/// Renders one checkerboard (ambient light only) and its corners' true pixels. The noise stream
/// is derived from `opts.seed` and the pose, so a set of boards rendered with the same options
/// gets independent noise.
///
/// Panics if the board or the options are invalid (check them with `validate` first).
pub fn render_board_image(
    sensor: &Sensor,
    board_pose: &Isometry3<f64>,
    board: &BoardFile,
    opts: &RenderOptions,
) -> (Frame16, Vec<Option<[f64; 2]>>) {
    let scene = Scene::from_file(SceneFile::new(vec![board_object(board, board_pose)])).expect("valid board");
    let t = board_pose.translation.vector;
    let seed = [t.x, t.y, t.z, board_pose.rotation.w].iter().fold(opts.seed, |s, v| mix(s ^ mix(v.to_bits())));
    let image = render_ambient_frame(sensor, &scene, &RenderOptions { seed, ..opts.clone() });
    (image, corner_pixels(sensor, &scene, board_pose, board))
}

/// `count` random board poses around the sensor: azimuth uniform over 360°, 300–900 mm from the
/// camera axis, elevation (seen from the viewpoint) between −50° and +30°, facing the viewpoint
/// within ±45° of tilt and any roll. Poses whose board shows no corner are drawn again (up to
/// 1000 tries each; then an error). Some boards are partly out of view, by design.
pub fn random_board_poses(
    sensor: &Sensor,
    board: &BoardFile,
    count: usize,
    seed: u64,
) -> Result<Vec<Isometry3<f64>>, String> {
    board.validate()?;
    let mut rng = SplitMix64::stream(seed, 0xB0A2D);
    let mut poses = Vec::with_capacity(count);
    for i in 0..count {
        let pose = (0..1000)
            .map(|_| random_pose(&mut rng, board))
            .find(|pose| {
                let scene = Scene::from_file(SceneFile::new(vec![board_object(board, pose)])).expect("valid board");
                corner_pixels(sensor, &scene, pose, board).iter().any(Option::is_some)
            })
            .ok_or_else(|| format!("board {i}: no pose with a visible corner found in 1000 draws"))?;
        poses.push(pose);
    }
    Ok(poses)
}

/// `count` board poses as a careful user places a checkerboard to calibrate a catadioptric
/// camera (the calibration guides' advice, e.g. OCamCalib's and Mei's toolboxes): boards held
/// close, so that each fills a good part of the annulus and shows large, sharp squares; the set
/// covers all azimuths and the whole elevation range of the mirror, including boards cut by its
/// inner and outer rim; each board is turned towards the camera with a varied tilt (10°–45°,
/// any axis) and any roll.
///
/// Construction (deterministic per `seed`): board `i`'s centre direction, seen from the camera's
/// viewpoint, follows a 2-D low-discrepancy (R2) sequence over azimuth × elevation, with a
/// seed-dependent offset, so the boards spread evenly; the elevation range is the mirror's (the
/// rays at its inner and outer rim, from the sensor's model) widened by 5° on both sides. The
/// centre lies 0.45–0.75 board diagonals (of the inner corners) from the viewpoint: about
/// 130–210 mm for a 9 × 6 board of 30 mm squares, where it spans about 65°–105°. A pose showing
/// fewer than a third of the corners (at least 12) is drawn again with new jitter (up to 1000
/// tries; then an error).
///
/// Close boards fix the focal length / distance direction that small, far boards leave weakly
/// observed, and above all the mirror's "cone opening" (one elevation offset for all rays): a
/// board seen under a small angle absorbs it by a small turn of its own pose, a board spanning
/// a wide angle cannot (docs/DECISIONS.md has the ray errors against [`random_board_poses`]).
pub fn calibration_board_poses(
    sensor: &Sensor,
    board: &BoardFile,
    count: usize,
    seed: u64,
) -> Result<Vec<Isometry3<f64>>, String> {
    board.validate()?;
    let circle = sensor.camera.mirror_circle();
    // The first ray from `radius` px (along +x of the mirror centre) stepping by `step` px: a
    // camera off the mirror's focus images the blind centre slightly off the rim's centre.
    let rim_ray = |radius: f64, step: f64| {
        (0..20)
            .find_map(|k| {
                sensor.camera.pixel_to_ray(&(circle.centre + omni_geom::Vector2::new(radius + k as f64 * step, 0.0)))
            })
            .ok_or_else(|| {
                format!("the camera has no ray at {radius:.1} px from the mirror centre (is the mirror circle valid?)")
            })
    };
    let (inner, outer) = (rim_ray(circle.inner_radius + 0.5, 0.5)?, rim_ray(circle.outer_radius - 0.5, -0.5)?);
    let elevation = |d: &Vector3<f64>| d.z.atan2(d.x.hypot(d.y));
    let (e_inner, e_outer) = (elevation(&inner.dir), elevation(&outer.dir));
    let margin = 5f64.to_radians();
    let (e_lo, e_hi) = (e_inner.min(e_outer) - margin, e_inner.max(e_outer) + margin);
    let viewpoint = inner.origin;
    let s = board.square_mm;
    let diagonal = ((board.inner_cols as f64 - 1.0) * s).hypot((board.inner_rows as f64 - 1.0) * s);
    let needed = (board.inner_cols * board.inner_rows).div_ceil(3).max(12) as usize;
    let mut rng = SplitMix64::stream(seed, 0xCA11B);
    let offset = [rng.uniform(), rng.uniform()];
    // R2 sequence (Roberts): fractional parts of i/g and i/g² with g the plastic number.
    const G: f64 = 1.324_717_957_244_746;
    let mut poses = Vec::with_capacity(count);
    for i in 0..count {
        let base = [(offset[0] + i as f64 / G).fract(), (offset[1] + i as f64 / (G * G)).fract()];
        let pose = (0..1000)
            .map(|_| {
                // A little jitter (a tenth of a stratum) so that retries move the board.
                let u = (base[0] + 0.1 * (rng.uniform() - 0.5) / count as f64).rem_euclid(1.0);
                let v = (base[1] + 0.1 * (rng.uniform() - 0.5) / count as f64).clamp(0.0, 1.0);
                let azimuth = u * std::f64::consts::TAU;
                let elev = e_lo + (e_hi - e_lo) * v;
                let dir = Vector3::new(elev.cos() * azimuth.cos(), elev.cos() * azimuth.sin(), elev.sin());
                let centre = viewpoint + (0.45 + 0.3 * rng.uniform()) * diagonal * dir;
                let tilt = (10.0 + 35.0 * rng.uniform()).to_radians();
                facing_pose(rng.uniform(), tilt, rng.uniform(), viewpoint, centre, board)
            })
            .find(|pose| {
                let scene = Scene::from_file(SceneFile::new(vec![board_object(board, pose)])).expect("valid board");
                corner_pixels(sensor, &scene, pose, board).iter().flatten().count() >= needed
            })
            .ok_or_else(|| format!("board {i}: no pose showing {needed} corners found in 1000 draws"))?;
        poses.push(pose);
    }
    Ok(poses)
}

/// A board centred at `centre`, its printed face turned to `viewpoint`, then tilted by `tilt`
/// (radians) about an in-board axis at angle `axis_turn` · 2π and rolled by `roll_turn` · 2π.
fn facing_pose(
    axis_turn: f64,
    tilt: f64,
    roll_turn: f64,
    viewpoint: Point3<f64>,
    centre: Point3<f64>,
    board: &BoardFile,
) -> Isometry3<f64> {
    // Board z (into the board) points away from the viewpoint.
    let z = (centre - viewpoint).normalize();
    let facing = UnitQuaternion::rotation_between(&Vector3::z(), &z).unwrap_or_else(UnitQuaternion::identity);
    let a = axis_turn * std::f64::consts::TAU;
    let tilt = UnitQuaternion::from_scaled_axis(Vector3::new(a.cos(), a.sin(), 0.0) * tilt);
    let roll = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll_turn * std::f64::consts::TAU);
    let rot = facing * tilt * roll;
    let s = board.square_mm;
    let half = Vector3::new((board.inner_cols as f64 - 1.0) * s / 2.0, (board.inner_rows as f64 - 1.0) * s / 2.0, 0.0);
    // Place the board's centre (not its first corner) at `centre`.
    Isometry3::from_parts(Translation3::from(centre.coords - rot * half), rot)
}

fn random_pose(rng: &mut SplitMix64, board: &BoardFile) -> Isometry3<f64> {
    let azimuth = rng.uniform() * std::f64::consts::TAU;
    let dist = 300.0 + 600.0 * rng.uniform();
    let elevation = (-50.0 + 80.0 * rng.uniform()).to_radians();
    let viewpoint = Point3::new(0.0, 0.0, 80.0);
    let centre = Point3::new(dist * azimuth.cos(), dist * azimuth.sin(), viewpoint.z + dist * elevation.tan());
    // Board z (into the board) points away from the viewpoint, then tilted and rolled.
    let z = (centre - viewpoint).normalize();
    let facing = UnitQuaternion::rotation_between(&Vector3::z(), &z).unwrap_or_else(UnitQuaternion::identity);
    let roll = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.uniform() * std::f64::consts::TAU);
    let tilt_axis = Vector3::new(rng.uniform() - 0.5, rng.uniform() - 0.5, 0.0);
    let tilt = UnitQuaternion::from_scaled_axis(tilt_axis.normalize() * (45.0 * rng.uniform()).to_radians());
    let rot = facing * tilt * roll;
    let s = board.square_mm;
    let half = Vector3::new((board.inner_cols as f64 - 1.0) * s / 2.0, (board.inner_rows as f64 - 1.0) * s / 2.0, 0.0);
    // Place the board's centre (not its first corner) at `centre`.
    Isometry3::from_parts(Translation3::from(centre.coords - rot * half), rot)
}

/// The two-perpendicular-boards rig for transmitter calibration: two copies of a board standing
/// vertically on the +x side like an open book facing the sensor (a concave right angle), the
/// spine (their shared vertical edge, 2 mm gap) at (620, 0) mm, both centred at z = −50 mm, so
/// that laser 0's light planes of mid-range mirror angles (about 15°–24°) cross both boards. A
/// 9 × 6 board of 30 mm squares then spans x ≈ 365–620 mm. [`Rig::rig_file`],
/// [`Rig::board_poses_file`] and [`Rig::board_corners_file`] give the true rig in the formats
/// omni-calib-plane reads (boards named [`Rig::BOARD_NAMES`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    pub board: BoardFile,
    /// Board → world poses: [left board (y > 0), right board (y < 0)] seen from the sensor.
    pub poses: [Isometry3<f64>; 2],
}

impl Rig {
    /// The standard rig for a board (see the type's docs).
    pub fn standard(board: &BoardFile) -> Rig {
        let s = board.square_mm;
        let width = (board.inner_cols as f64 + 1.0) * s + 2.0 * board.margin_mm;
        let spine = Vector3::new(620.0, 0.0, -50.0);
        let r2 = std::f64::consts::FRAC_1_SQRT_2;
        let pose = |normal: Vector3<f64>, right: Vector3<f64>, centre: Vector3<f64>| {
            // Board axes: x = right, y = down, z = −normal.
            let rot = Rotation3::from_basis_unchecked(&[right, -Vector3::z(), -normal]);
            let rot = UnitQuaternion::from_rotation_matrix(&rot);
            let half =
                Vector3::new((board.inner_cols as f64 - 1.0) * s / 2.0, (board.inner_rows as f64 - 1.0) * s / 2.0, 0.0);
            Isometry3::from_parts(Translation3::from(centre - rot * half), rot)
        };
        let (na, ra) = (Vector3::new(-r2, -r2, 0.0), Vector3::new(r2, -r2, 0.0));
        let (nb, rb) = (Vector3::new(-r2, r2, 0.0), Vector3::new(-r2, -r2, 0.0));
        let gap = 1.0;
        let left = pose(na, ra, spine - ra * (width / 2.0 + gap));
        let right = pose(nb, rb, spine + rb * (width / 2.0 + gap));
        Rig { board: board.clone(), poses: [left, right] }
    }

    /// Names of the two boards in the omni-calib-plane files, in the order of [`Rig::poses`].
    pub const BOARD_NAMES: [&'static str; 2] = ["left", "right"];

    /// The rig's boards as omni-calib-plane reads them (`rig.json`, one placement). The
    /// simulator's board frame (origin at the first inner corner, x along the columns, y down the
    /// rows, z = x × y) is the rig format's, so the board parameters carry over unchanged.
    pub fn rig_file(&self) -> RigFile {
        let b = &self.board;
        let rig_board = |name: &str| RigBoard {
            name: name.into(),
            inner_cols: b.inner_cols,
            inner_rows: b.inner_rows,
            square_mm: b.square_mm,
            margin_mm: b.margin_mm,
            placement: 0,
        };
        RigFile::new(Self::BOARD_NAMES.map(rig_board).to_vec())
    }

    /// The TRUE board → world poses (`board_poses.json`).
    pub fn board_poses_file(&self) -> BoardPosesFile {
        let poses = Self::BOARD_NAMES
            .iter()
            .zip(&self.poses)
            .map(|(name, iso)| {
                let p = BoardPose::from_isometry(iso);
                RigBoardPose { board: (*name).into(), rotation: p.rotation, translation_mm: p.translation_mm }
            })
            .collect();
        BoardPosesFile::new(poses)
    }

    /// Corner pixels as [`render_rig_pose_image`] returns them (per board, row-major, `None` where
    /// hidden) in the `board_corners.json` form: `[i, j, u, v]` of the visible corners, corner `k`
    /// being column `k % inner_cols`, row `k / inner_cols`.
    pub fn board_corners_file(&self, corners: &[Vec<Option<[f64; 2]>>; 2]) -> BoardCornersFile {
        let cols = self.board.inner_cols as usize;
        let boards = Self::BOARD_NAMES
            .iter()
            .zip(corners)
            .map(|(name, px)| BoardCorners {
                board: (*name).into(),
                corners: px
                    .iter()
                    .enumerate()
                    .filter_map(|(k, p)| p.map(|[u, v]| [(k % cols) as f64, (k / cols) as f64, u, v]))
                    .collect(),
            })
            .collect();
        BoardCornersFile::new(boards)
    }

    /// The rig as a scene (two checkerboards).
    pub fn scene(&self) -> SceneFile {
        let objects = self.poses.iter().map(|p| board_object(&self.board, p)).collect();
        SceneFile {
            description: Some("two perpendicular checkerboards (transmitter calibration rig)".into()),
            ..SceneFile::new(objects)
        }
    }
}

/// Renders the rig's ambient "pose" image (lasers off) and both boards' true corner pixels.
pub fn render_rig_pose_image(
    sensor: &Sensor,
    rig: &Rig,
    opts: &RenderOptions,
) -> (Frame16, [Vec<Option<[f64; 2]>>; 2]) {
    let scene = Scene::from_file(rig.scene()).expect("valid rig");
    let image = render_ambient_frame(sensor, &scene, opts);
    let corners = [0, 1].map(|i| corner_pixels(sensor, &scene, &rig.poses[i], &rig.board));
    (image, corners)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibration_boards_are_close_cover_the_mirror_and_repeat_per_seed() {
        let sensor = Sensor::paper_scaled(256);
        let board = BoardFile::new(9, 6, 30.0);
        let poses = calibration_board_poses(&sensor, &board, 20, 3).unwrap();
        assert_eq!(calibration_board_poses(&sensor, &board, 20, 3).unwrap(), poses, "same seed, same poses");
        assert_ne!(calibration_board_poses(&sensor, &board, 20, 4).unwrap(), poses, "seed changes the set");
        let viewpoint = Point3::new(0.0, 0.0, 80.0);
        let circle = sensor.camera.mirror_circle();
        let (mut radii, mut azimuths) = (Vec::new(), Vec::new());
        for pose in &poses {
            let centre = pose * Point3::new(120.0, 75.0, 0.0);
            // 0.45–0.75 diagonals (283 mm) from the viewpoint.
            let dist = (centre - viewpoint).norm();
            assert!((125.0..=215.0).contains(&dist), "board centre {dist} mm away");
            let scene = Scene::from_file(SceneFile::new(vec![board_object(&board, pose)])).unwrap();
            let px: Vec<[f64; 2]> = corner_pixels(&sensor, &scene, pose, &board).into_iter().flatten().collect();
            assert!(px.len() >= 18, "{} corners visible", px.len());
            for p in px {
                let d = omni_geom::Vector2::new(p[0], p[1]) - circle.centre;
                radii.push((d.norm() - circle.inner_radius) / (circle.outer_radius - circle.inner_radius));
                azimuths.push(d.y.atan2(d.x));
            }
        }
        // Corners reach both rims (within 5 % of the annulus width) and every 30° sector.
        let (lo, hi) = radii.iter().fold((1.0f64, 0.0f64), |(lo, hi), &r| (lo.min(r), hi.max(r)));
        assert!(lo < 0.05 && hi > 0.95, "corners span {lo:.3}–{hi:.3} of the annulus");
        for sector in 0..12 {
            let a0 = -std::f64::consts::PI + sector as f64 * std::f64::consts::PI / 6.0;
            let n = azimuths.iter().filter(|&&a| a >= a0 && a < a0 + std::f64::consts::PI / 6.0).count();
            assert!(n >= 10, "sector {sector}: {n} corners");
        }
    }
}
