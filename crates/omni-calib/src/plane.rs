//! Transmitter calibration: the swept light planes, from laser stripes on boards of known pose.
//!
//! Pipeline ([`calibrate_planes`]), following SENSOR.md "Calibration" and "Beyond the paper":
//! 1. Board poses in the world frame, from the calibrated camera ([`estimate_board_pose`]: the
//!    receiver calibration's pose estimator, [`crate::pose`], on corner pixels;
//!    [`inputs::boards_from_pose_image`] finds the boards in the ambient pose image first, best in
//!    the [`inputs::mean_image`] of several images of the unmoved rig) or given.
//! 2. Each stripe pixel's ray meets the nearest board whose outline it crosses
//!    ([`locate_on_boards`]) → 3D points on two crossing lines per frame (mm, world frame).
//! 3. Points are split between the lasers with the initial model (a point belongs to the laser
//!    whose reflected fan lights it), and each (frame, laser) gets its own robust plane
//!    ([`fit_frame_plane`]: least-median-of-squares start, then least squares with outlier
//!    rejection); frames that cannot fix a plane (one board line, collinear points) are refused
//!    with the reason, but their points still enter the model fit.
//! 4. The physical transmitter (polygon axis, encoder zero, per-facet errors, each laser's fan
//!    plane) is fitted to all points at once ([`fit_transmitter`]); its gauge conventions are
//!    documented in [`model`]. The per-frame planes stay in the report as a check.
//!
//! Accuracy is bounded by the board poses: with this omnidirectional camera (~0.3°/px) a board
//! posed from 0.1 px corners is tilted by up to ~0.1°, which the light planes inherit. The board
//! poses are not refined with the stripes: a joint fit (transmitter and board poses together,
//! corner reprojection and stripe-point residuals each over their noise level, stripe points
//! recomputed from their rays) converged with unit normalised RMS but did not help. On the
//! synthetic two-board rig (0.1 px corners and stripes, 31 frames, 4 seeds) the worst light-plane
//! normal error went from 0.050/0.018/0.024/0.012° to 0.019/0.028/0.019/0.038° (mean 0.026° both
//! ways); on the rendered rig from 0.0131° to 0.0159° with the true camera. The stripes see the
//! board-pose components that the physical model cannot absorb, and those are not the ones that
//! tilt the light planes.
//!
//! ```no_run
//! # use omni_calib::plane::*;
//! # fn run(camera: &dyn omni_model::CameraModel, boards: &[PlacedBoard], frames: &[FrameStripes]) {
//! let initial = omni_model::TransmitterParams::paper();
//! let cal = calibrate_planes(camera, boards, frames, &initial, &PlaneCalibOptions::default()).unwrap();
//! let table = light_plane_table(&cal.transmitter, &[0.0, 1.0, 2.0], 0, None).unwrap();
//! # }
//! ```

pub mod inputs;
pub mod model;
mod observe;
#[cfg(test)]
mod sim_tests;
pub mod synth;
mod table;
#[cfg(test)]
mod tests;

pub use inputs::{BoardPoseFit, estimate_board_pose};
pub use model::{Estimate, ModelFit, ModelFitOptions, Observation, fit_transmitter};
pub use observe::{
    BoardPoint, FramePlane, FramePlaneOptions, FrameStripes, PlacedBoard, fit_frame_plane, locate_on_boards,
    robust_sigma,
};
pub use table::{TableRow, light_plane_table, parse_alpha_range};

use nalgebra::Point3;
use omni_model::{CameraModel, Transmitter, TransmitterParams};
use rayon::prelude::*;
use serde::Serialize;

/// Settings of the whole light-plane calibration.
#[derive(Debug, Clone, Copy)]
pub struct PlaneCalibOptions {
    pub frame: FramePlaneOptions,
    pub model: ModelFitOptions,
    /// Fewest board points a (frame, laser) needs to be used at all.
    pub min_points_per_frame: usize,
    /// Rays meeting a board at |cos incidence| below this are ignored (grazing).
    pub min_cos: f64,
    /// Board points farther than this (mm) from the initial model's light plane are dropped
    /// before any fit (bright structure that is not the stripe), then a second pass gates at a
    /// quarter of it (at least 2 mm) around the first pass's model; `None` keeps all points in
    /// one pass.
    pub gate_mm: Option<f64>,
}

impl Default for PlaneCalibOptions {
    fn default() -> Self {
        PlaneCalibOptions {
            frame: FramePlaneOptions::default(),
            model: ModelFitOptions::default(),
            min_points_per_frame: 20,
            min_cos: 0.05,
            gate_mm: None,
        }
    }
}

/// The per-frame check of one (frame, laser).
#[derive(Debug, Clone, Serialize)]
pub struct FrameReport {
    pub seq: u64,
    pub alpha_deg: f64,
    pub facet: u32,
    pub laser: usize,
    /// Board points assigned to this laser.
    pub points: usize,
    /// Stripe pixels of the frame that fell on no board (or gave no ray), all lasers together.
    pub off_board: usize,
    /// The frame's own plane `normal · x = offset_mm` (world frame), if the points fix one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plane_normal: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plane_offset_mm: Option<f64>,
    /// RMS distance of the inliers to the frame's own plane (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plane_rms_mm: Option<f64>,
    /// Why the frame has no plane of its own (its points still enter the model fit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plane_refused: Option<String>,
    /// RMS distance of its points to the fitted model's plane (mm).
    pub model_rms_mm: f64,
    /// Angle between the frame's own plane and the model's (degrees).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_angle_deg: Option<f64>,
}

/// A frame (or one laser of it) left out of the calibration.
#[derive(Debug, Clone, Serialize)]
pub struct Rejection {
    pub seq: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub laser: Option<usize>,
    pub reason: String,
}

/// The physical model fit, for the report.
#[derive(Debug, Clone, Serialize)]
pub struct ModelReport {
    pub residual_rms_mm: f64,
    pub points_used: usize,
    pub outliers_rejected: usize,
    pub iterations: usize,
    pub converged: bool,
    pub parameters: Vec<Estimate>,
    pub fixed: Vec<String>,
    pub gauge: Vec<String>,
    /// Steps of a board's pose (for the σ's share of the boards' poses) whose fit failed or
    /// changed the parameters' layout; their share is missing from the σ.
    #[serde(skip_serializing_if = "is_zero")]
    pub board_pose_steps_failed: usize,
}

/// What `scanner.json`'s `report` holds.
#[derive(Debug, Clone, Serialize)]
pub struct PlaneReport {
    pub frames_total: usize,
    /// (frame, laser) pairs used in the model fit.
    pub observations_used: usize,
    /// RMS over the frames' own planes of their inlier distances (mm).
    pub frame_plane_rms_mm: f64,
    pub model: ModelReport,
    pub frames: Vec<FrameReport>,
    pub rejected: Vec<Rejection>,
}

/// The calibrated transmitter and its report.
#[derive(Debug, Clone)]
pub struct PlaneCalibration {
    pub transmitter: TransmitterParams,
    pub report: PlaneReport,
}

/// The gauge conventions of the fit, as stated in the report.
pub const GAUGE_NOTES: [&str; 6] = [
    "facet pitch errors have zero mean over the observed facets; their common part is the encoder zero",
    "facet tilt and radius errors have zero mean over the observed facets (their common parts are \
     indistinguishable from the fan plane's tilt and offset)",
    "the first observed laser keeps its initial turn about the polygon axis (indistinguishable from the \
     encoder zero), so the encoder zero is relative to that laser's mounting",
    "zero_dir is the initial zero_dir projected perpendicular to the fitted axis",
    "the axis point moves only perpendicular to the initial axis",
    "laser apex and direction are the initial ones projected onto the fitted fan plane",
];

/// Checks every frame lies inside the model: facet index below n, α within one facet [0, 2θ],
/// a placement that has boards. The error names the frame.
pub fn check_frames(tx: &Transmitter, boards: &[PlacedBoard], frames: &[FrameStripes]) -> Result<(), String> {
    let span = tx.facet_angle();
    for f in frames {
        if f.facet >= tx.num_facets() {
            return Err(format!("frame {}: facet {} is not in the model ({} facets)", f.seq, f.facet, tx.num_facets()));
        }
        if !(f.alpha_rad >= -1e-9 && f.alpha_rad <= span + 1e-9) {
            return Err(format!(
                "frame {}: alpha_deg {} is outside the model's facet range [0, {}]",
                f.seq,
                f.alpha_rad.to_degrees(),
                span.to_degrees()
            ));
        }
        if !boards.iter().any(|b| b.placement == f.placement) {
            return Err(format!("frame {}: no rig board has placement {}", f.seq, f.placement));
        }
    }
    Ok(())
}

/// Fewest stripe points on a board for it to count as seen ([`one_board_plane`]).
const MIN_POINTS_ON_A_BOARD: usize = 10;

/// The board names, if every board with stripe points on it (`on_board[i]` of `boards[i]`,
/// [`MIN_POINTS_ON_A_BOARD`] or more) lies in one plane (normals within 1°, 5 mm apart at most):
/// then each frame gives lines on that plane alone, which any light plane through them fits as
/// well (a one-board rig, or boards placed side by side).
fn one_board_plane(boards: &[PlacedBoard], on_board: &[usize]) -> Option<String> {
    let seen: Vec<&PlacedBoard> =
        boards.iter().zip(on_board).filter(|&(_, &n)| n >= MIN_POINTS_ON_A_BOARD).map(|(b, _)| b).collect();
    let first = seen.first()?;
    let normal = |b: &PlacedBoard| b.pose.rotation * nalgebra::Vector3::z();
    let n0 = normal(first);
    let coplanar = seen.iter().all(|b| {
        let n = normal(b);
        n.dot(&n0).abs() >= 1f64.to_radians().cos()
            && n0.dot(&(b.pose.translation.vector - first.pose.translation.vector)).abs() <= 5.0
    });
    coplanar.then(|| seen.iter().map(|b| b.name.as_str()).collect::<Vec<_>>().join(", "))
}

/// The standard deviation of a fitted length (mm) and angle (°) beyond which a rig determines
/// it loosely: a facet's whole sweep on two boards gives hundredths to tenths (0.13 mm, 0.04°
/// with 0.1 px stripes); an 8° sweep with 0.5 px stripes 9 mm and 3°, its light planes good
/// within the sweep and extrapolated beyond it (the tool warns); a sweep of 1° gives 100 mm and
/// 4°, a model that fits its frames and no other angle.
pub const LOOSE_STD_MM: f64 = 5.0;
pub const LOOSE_STD_DEG: f64 = 1.0;
/// How many times [`LOOSE_STD_MM`] or [`LOOSE_STD_DEG`] a σ may reach before the fit is
/// refused as not determined.
const UNDETERMINED_FACTOR: f64 = 10.0;

/// The fitted parameters whose standard deviation exceeds `factor` × [`LOOSE_STD_MM`] or
/// [`LOOSE_STD_DEG`], named with their σ; `None` if there are none.
pub fn loosely_determined(estimates: &[Estimate], factor: f64) -> Option<String> {
    let loose: Vec<String> = estimates
        .iter()
        .filter_map(|e| {
            let std = e.std?;
            let limit = factor * if e.unit == "mm" { LOOSE_STD_MM } else { LOOSE_STD_DEG };
            (std > limit).then(|| format!("{} σ {std:.3} {}", e.name, e.unit))
        })
        .collect();
    (!loose.is_empty()).then(|| loose.join(", "))
}

/// Splits a frame's board points between its lit lasers using the initial model: a point goes to
/// the laser whose fan lights it (nearest plane if several or none do), if it lies within
/// `gate_mm` of that laser's initial plane.
fn assign_lasers(
    tx: &Transmitter,
    frame: &FrameStripes,
    points: &[observe::BoardPoint],
    gate_mm: Option<f64>,
) -> Vec<(usize, Vec<usize>)> {
    let lasers: Vec<usize> =
        frame.lasers.iter().map(|&l| l as usize).filter(|&l| l < tx.num_lasers()).collect::<Vec<_>>();
    let planes: Vec<_> = lasers.iter().map(|&l| tx.light_plane(frame.alpha_rad, frame.facet, l)).collect();
    let mut groups: Vec<(usize, Vec<usize>)> = lasers.iter().map(|&l| (l, vec![])).collect();
    for (i, p) in points.iter().enumerate() {
        let score = |k: usize| -> (bool, f64) {
            match &planes[k] {
                Some(lp) => (lp.lights(&p.point), lp.plane.signed_distance(&p.point).abs()),
                None => (false, f64::INFINITY),
            }
        };
        let best = (0..lasers.len()).min_by(|&a, &b| {
            let (la, da) = score(a);
            let (lb, db) = score(b);
            lb.cmp(&la).then(da.total_cmp(&db))
        });
        if let Some(k) = best
            && gate_mm.is_none_or(|g| score(k).1 <= g)
        {
            groups[k].1.push(i);
        }
    }
    groups
}

/// Calibrates the light planes from stripe frames on posed boards (see the module docs).
/// Fails, with a message naming the frame, for frames outside the model, and when no frame is
/// usable; individual unusable frames are listed in the report's `rejected`.
pub fn calibrate_planes(
    camera: &dyn CameraModel,
    boards: &[PlacedBoard],
    frames: &[FrameStripes],
    initial: &TransmitterParams,
    opts: &PlaneCalibOptions,
) -> Result<PlaneCalibration, String> {
    let first = calibrate_once(camera, boards, frames, initial, opts)?;
    let (mut cal, start, last) = match opts.gate_mm {
        None => (first, initial.clone(), *opts),
        Some(gate) => {
            // The first gate must cover the initial model's error, so it may still let in
            // bright lines near the stripe; a second pass gates tightly around the first pass's.
            let tight = PlaneCalibOptions { gate_mm: Some((gate / 4.0).max(2.0).min(gate)), ..*opts };
            let start = first.transmitter;
            (calibrate_once(camera, boards, frames, &start, &tight)?, start, tight)
        }
    };
    add_board_pose_spread(camera, boards, frames, &mut cal, &start, &last);
    Ok(cal)
}

/// Adds to each estimate's σ the spread the boards' pose errors give it: the fit's own σ takes
/// the stripe points' errors as independent, while one board's pose error moves every point on
/// that board alike. Each board with a pose covariance is moved by ± one standard deviation
/// along each principal axis of it and the last pass (`start`, `opts`) fitted again; half the
/// change between the two (central differences: a step's second-order part and much of a
/// change of inliers cancel) squared and summed over the axes is the variance. Steps whose fit
/// fails or changes the parameters' layout are counted in the report, not used.
fn add_board_pose_spread(
    camera: &dyn CameraModel,
    boards: &[PlacedBoard],
    frames: &[FrameStripes],
    cal: &mut PlaneCalibration,
    start: &TransmitterParams,
    opts: &PlaneCalibOptions,
) {
    let base = &cal.report.model.parameters;
    let refit = |b: usize, pose: &[f64]| -> Option<Vec<f64>> {
        let mut moved = boards.to_vec();
        moved[b].pose = crate::pose::params_to_pose(pose);
        let fit = calibrate_once(camera, &moved, frames, start, opts).ok()?;
        let values = &fit.report.model.parameters;
        let same = values.len() == base.len() && values.iter().zip(base).all(|(v, e)| v.name == e.name);
        same.then(|| values.iter().map(|v| v.value).collect())
    };
    // Every board's ± steps along its covariance's principal axes: (board, pose parameters).
    let mut steps: Vec<(usize, Vec<f64>)> = vec![];
    for (b, board) in boards.iter().enumerate() {
        let Some(covariance) = board.pose_covariance else { continue };
        let axes = nalgebra::SymmetricEigen::new(covariance);
        let p0 = crate::pose::pose_to_params(&board.pose);
        for k in 0..6 {
            let step = axes.eigenvectors.column(k) * axes.eigenvalues[k].max(0.0).sqrt();
            for sign in [1.0, -1.0] {
                steps.push((b, (0..6).map(|i| p0[i] + sign * step[i]).collect()));
            }
        }
    }
    let fits: Vec<Option<Vec<f64>>> = steps.par_iter().map(|(b, pose)| refit(*b, pose)).collect();
    let mut variance = vec![0.0; base.len()];
    let (mut used, mut failed) = (0usize, 0usize);
    for pair in fits.chunks_exact(2) {
        let (Some(up), Some(down)) = (&pair[0], &pair[1]) else {
            failed += 1;
            continue;
        };
        for (v, (u, d)) in variance.iter_mut().zip(up.iter().zip(down)) {
            *v += (0.5 * (u - d)).powi(2);
        }
        used += 1;
    }
    cal.report.model.board_pose_steps_failed = failed;
    if used == 0 {
        return;
    }
    for (e, v) in cal.report.model.parameters.iter_mut().zip(variance) {
        e.std_fit = e.std;
        e.std_board_poses = Some(v.sqrt());
        e.std = e.std.map(|s| (s * s + v).sqrt());
    }
}

/// One pass of [`calibrate_planes`]: laser assignment and gating with `initial`, frame planes,
/// model fit started from `initial`.
fn calibrate_once(
    camera: &dyn CameraModel,
    boards: &[PlacedBoard],
    frames: &[FrameStripes],
    initial: &TransmitterParams,
    opts: &PlaneCalibOptions,
) -> Result<PlaneCalibration, String> {
    let tx0 = Transmitter::new(initial.clone()).map_err(|e| format!("initial transmitter: {e}"))?;
    check_frames(&tx0, boards, frames)?;
    let mut rejected = vec![];
    let mut observations = vec![];
    let mut own_planes: Vec<(FrameReport, Option<FramePlane>)> = vec![];
    // Stripe points used on each board.
    let mut on_board = vec![0usize; boards.len()];
    for frame in frames {
        if frame.lasers.is_empty() {
            continue; // an ambient (laser-off) frame
        }
        let (points, off_board) = locate_on_boards(camera, boards, frame, opts.min_cos);
        for (laser, idx) in assign_lasers(&tx0, frame, &points, opts.gate_mm) {
            if idx.len() < opts.min_points_per_frame {
                // A laser whose stripe misses the boards entirely is normal (it lights the other side).
                if !idx.is_empty() || tx0.num_lasers() == 1 {
                    rejected.push(Rejection {
                        seq: frame.seq,
                        laser: Some(laser),
                        reason: format!(
                            "too few stripe points on the boards: {} (need {})",
                            idx.len(),
                            opts.min_points_per_frame
                        ),
                    });
                }
                continue;
            }
            let pts: Vec<observe::BoardPoint> = idx.iter().map(|&i| points[i]).collect();
            for p in &pts {
                on_board[p.board] += 1;
            }
            // Oriented like the model's planes (non-negative z) so the report reads consistently.
            let own = fit_frame_plane(&pts, boards.len(), &opts.frame).map(|mut fp| {
                if fp.plane.normal.z < 0.0 {
                    fp.plane = fp.plane.flipped();
                }
                fp
            });
            let used: Vec<Point3<f64>> = match &own {
                Ok(fp) => pts.iter().zip(&fp.inliers).filter(|(_, k)| **k).map(|(p, _)| p.point).collect(),
                Err(_) => pts.iter().map(|p| p.point).collect(),
            };
            let report = FrameReport {
                seq: frame.seq,
                alpha_deg: frame.alpha_rad.to_degrees(),
                facet: frame.facet,
                laser,
                points: pts.len(),
                off_board,
                plane_normal: own.as_ref().ok().map(|f| f.plane.normal.into_inner().into()),
                plane_offset_mm: own.as_ref().ok().map(|f| f.plane.offset),
                plane_rms_mm: own.as_ref().ok().map(|f| f.rms_mm),
                plane_refused: own.as_ref().err().cloned(),
                model_rms_mm: f64::NAN,
                model_angle_deg: None,
            };
            own_planes.push((report, own.ok()));
            observations.push(Observation { alpha_rad: frame.alpha_rad, facet: frame.facet, laser, points: used });
        }
    }
    if observations.is_empty() {
        let why = rejected.first().map(|r| format!(" (e.g. frame {}: {})", r.seq, r.reason)).unwrap_or_default();
        return Err(format!("no usable frame: no stripe fell on the boards{why}"));
    }
    if let Some(plane) = one_board_plane(boards, &on_board) {
        return Err(format!(
            "every stripe point lies on one board plane ({plane}): a light plane's turn about its line on a board is not seen, so the transmitter is not determined; the rig needs boards at an angle (two in view, or placements)"
        ));
    }
    let fit = fit_transmitter(initial, &observations, &opts.model)?;
    if let Some(loose) = loosely_determined(&fit.estimates, UNDETERMINED_FACTOR) {
        let (mm, deg) = (UNDETERMINED_FACTOR * LOOSE_STD_MM, UNDETERMINED_FACTOR * LOOSE_STD_DEG);
        return Err(format!(
            "the frames do not determine the transmitter: {loose} (σ above {mm} mm or {deg}°); take stripe frames over the whole sweep of each facet, on boards at an angle"
        ));
    }
    let tx = Transmitter::new(fit.params.clone())?;
    let mut frames_out = Vec::with_capacity(own_planes.len());
    let (mut ss, mut n) = (0.0, 0usize);
    for ((mut report, own), rms) in own_planes.into_iter().zip(&fit.observation_rms_mm) {
        report.model_rms_mm = *rms;
        if let Some(own) = own {
            ss += own.rms_mm.powi(2) * own.inliers.iter().filter(|k| **k).count() as f64;
            n += own.inliers.iter().filter(|k| **k).count();
            if let Some(lp) = tx.light_plane(report.alpha_deg.to_radians(), report.facet, report.laser) {
                report.model_angle_deg = Some(lp.plane.angle_to(&own.plane).to_degrees());
            }
        }
        frames_out.push(report);
    }
    let report = PlaneReport {
        frames_total: frames.len(),
        observations_used: observations.len(),
        frame_plane_rms_mm: (ss / n.max(1) as f64).sqrt(),
        model: ModelReport {
            residual_rms_mm: fit.rms_mm,
            points_used: fit.points_used,
            outliers_rejected: fit.outliers,
            iterations: fit.iterations,
            converged: fit.converged,
            parameters: fit.estimates,
            fixed: fit.fixed,
            gauge: GAUGE_NOTES.iter().map(|s| s.to_string()).collect(),
            board_pose_steps_failed: 0,
        },
        frames: frames_out,
        rejected,
    };
    Ok(PlaneCalibration { transmitter: fit.params, report })
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}
