//! A fixed light plane (a line laser rigid with the camera) from stripe frames with a
//! checkerboard in view.
//!
//! Per frame: the board's corners give its pose through the calibrated camera
//! ([`crate::pose::estimate_board_pose`]); each stripe pixel's ray meets the board plane, and the
//! points inside the board's printed outline (the outer squares' edges, widened by
//! [`FixedPlaneOptions::margin_mm`]) are points of the light plane (mm, world frame). One plane
//! is fitted to the points of all frames robustly ([`omni_geom::robust_plane`]: least median of
//! squares, Tukey reweighting), then to the inliers by generalised least squares in which each
//! frame's points share its board's pose error and weigh by their own scatter about the frame's
//! line, so that a board posed less surely (a partial board, corners that fit worse), or a stripe
//! read less surely, pulls the plane less, however many points it carries. The
//! report gives per frame the residual RMS (mm) and the stripe's straightness (px and mm: the
//! RMS distance of its points from their own best line in 3-D, the px being that distance as
//! imaged), the plane with its uncertainty (from the fit, and from a jackknife over frames), and
//! a leave-one-frame-out check (each frame's inliers against the plane fitted to the other
//! frames).
//!
//! [`detect_frames`] reads the frames: corners by [`omni_vision::corners::detect_board`], stripe
//! centres by [`omni_vision::stripe::RidgeDetector::whole_frame`] on the colour reading given.

use crate::pose::{estimate_board_pose_with_covariance, params_to_pose, pose_to_params};
use crate::receiver::Observation;
use crate::receiver::corners_file::{CornersFile, ImageCorners};
use nalgebra::{Matrix6, Matrix6x3, Vector6};
use omni_geom::fit::orthonormal_basis;
use omni_geom::robust_plane::{RobustPlaneFit, fit_plane_robust_grouped};
use omni_geom::{Isometry3, Matrix3, Plane, Point3, Vector2, Vector3};
use omni_model::CameraModel;
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Settings of the fit.
#[derive(Debug, Clone, Copy)]
pub struct FixedPlaneOptions {
    /// Square side of the board (mm).
    pub square_mm: f64,
    /// Stripe points are kept up to this far outside the printed pattern's outline (mm;
    /// negative keeps them this far inside it).
    pub margin_mm: f64,
    /// Stripe points are dropped where they lie closer than this (px, as imaged there) to a
    /// square's edge on the board, or to the board's own edge (the pattern widened by
    /// `margin_mm`): there the stripe's profile falls on a white and a black square, or off the
    /// board, whose albedos make it lopsided and move its centre. 0 (the default) keeps every
    /// point, as exact stripe pixels need; `omni-calib-plane fixed` clears 3 px.
    pub edge_clearance_px: f64,
    /// Fewest stripe points on the board for a frame to be used.
    pub min_points: usize,
    /// Seed of the robust fit's random triples.
    pub seed: u64,
}

impl Default for FixedPlaneOptions {
    fn default() -> Self {
        FixedPlaneOptions { square_mm: 1.0, margin_mm: 0.0, edge_clearance_px: 0.0, min_points: 30, seed: 1 }
    }
}

/// One stripe frame's input.
#[derive(Debug, Clone)]
pub struct FrameInput {
    pub name: String,
    /// The board's corners, or why none were found.
    pub corners: Result<Observation, String>,
    /// Stripe centres (px).
    pub stripe: Vec<[f64; 2]>,
    /// Which of `stripe` the detector found saturated (its `SATURATED` quality flag); `None`
    /// where not known (centres from another detector).
    pub saturated: Option<Vec<bool>>,
    /// The frame's size (px), if known: it must be the camera model's.
    pub size: Option<(u32, u32)>,
}

/// A frame left out, and why.
#[derive(Debug, Clone, Serialize)]
pub struct Skipped {
    pub name: String,
    pub reason: String,
}

/// One used frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameReport {
    pub name: String,
    pub corners: usize,
    /// RMS reprojection error of the corners under the board pose (px).
    pub corner_rms_px: f64,
    /// Distance of the board's centre from the world origin (mm).
    pub board_distance_mm: f64,
    /// Stripe points found in the frame, and those on the board.
    pub stripe_points: usize,
    pub board_points: usize,
    /// How many of the board's points are saturated; `None` where not known. A clipped stripe
    /// is read at its plateau's middle, towards a lopsided laser's tail.
    pub saturated_points: Option<usize>,
    /// Board points within the robust fit's inlier band.
    pub inliers: usize,
    /// Of the board points, those on its white border (beyond the printed pattern, kept by
    /// `margin_mm`), how many of them are outliers, and those outliers' median distance from
    /// the plane (mm; `None` without any): mostly outliers, the border kept is wider than the
    /// board's (points tens of mm off, on what lies behind it), or print, a curl or a reflection
    /// of the stripe moves them.
    pub border_points: usize,
    pub border_outliers: usize,
    pub border_outlier_median_mm: Option<f64>,
    /// RMS and mean signed distance of the inliers from the plane (mm).
    pub residual_rms_mm: f64,
    pub residual_mean_mm: f64,
    /// RMS distance of the inliers from their own best 3-D line (mm) and that distance as
    /// imaged (px).
    pub straightness_mm: f64,
    pub straightness_px: f64,
    /// RMS distance of the inliers from the plane fitted without this frame (mm).
    pub leave_one_out_rms_mm: f64,
}

/// The fitted plane and its uncertainty.
#[derive(Debug, Clone, Serialize)]
pub struct PlaneReport {
    /// Unit normal (world frame) and distance from the world origin along it (mm), oriented so
    /// that the distance is ≥ 0.
    pub normal: [f64; 3],
    pub distance_mm: f64,
    /// σ of the normal's direction (degrees) and of the distance (mm) from the fit: the points'
    /// scatter and each board's pose error (from its corners), which its points share; not
    /// what differs between frames beyond that (the jackknife's below holds it).
    pub normal_sigma_deg: f64,
    pub distance_sigma_mm: f64,
    /// σ along the normal at the points' centroid (mm), from the fit.
    pub centroid_sigma_mm: f64,
    /// The same from a jackknife over the frames (the leave-one-out planes' spread).
    pub jackknife_normal_sigma_deg: f64,
    pub jackknife_distance_sigma_mm: f64,
    pub jackknife_centroid_sigma_mm: f64,
    /// The points' centroid (mm).
    pub centroid_mm: [f64; 3],
}

/// The whole report (`report` of scanner.json).
#[derive(Debug, Clone, Serialize)]
pub struct FixedPlaneReport {
    pub plane: PlaneReport,
    /// Points on the boards, and inliers of the fit.
    pub points: usize,
    pub inliers: usize,
    /// RMS of the inliers' distances from the plane (mm), and the robust σ (mm).
    pub rms_mm: f64,
    pub robust_sigma_mm: f64,
    /// RMS over all frames of the leave-one-frame-out distances (mm).
    pub leave_one_out_rms_mm: f64,
    pub frames_total: usize,
    pub frames: Vec<FrameReport>,
    pub skipped: Vec<Skipped>,
}

/// One used frame's 3-D points (mm, world frame), their pixels and whether each is an inlier.
#[derive(Debug, Clone)]
pub struct FramePoints {
    pub name: String,
    pub points: Vec<Point3<f64>>,
    pub pixels: Vec<[f64; 2]>,
    pub inliers: Vec<bool>,
}

/// The fit's result.
#[derive(Debug, Clone)]
pub struct FixedPlaneFit {
    /// The plane (unit normal, offset ≥ 0; mm, world frame).
    pub plane: Plane,
    pub report: FixedPlaneReport,
    pub frames: Vec<FramePoints>,
}

/// A frame's board points: the pose and the stripe points on the board.
struct OnBoard {
    name: String,
    corners: usize,
    corner_rms_px: f64,
    pose: Isometry3<f64>,
    stripe_points: usize,
    points: Vec<Point3<f64>>,
    pixels: Vec<[f64; 2]>,
    /// How many of `points` are saturated, where known ([`FrameInput::saturated`]).
    saturated: Option<usize>,
    /// Whether each of `points` lies on the board's white border, beyond the printed pattern.
    on_border: Vec<bool>,
    /// Each point's moves (mm) when the board's pose moves by one σ along each principal axis
    /// of its covariance (half the difference of the ± steps): their outer products summed give
    /// the covariance the pose's error adds to the points. `None` where the pose fit gave no
    /// covariance.
    pose_spread: Option<Vec<[Vector3<f64>; 6]>>,
}

fn board_points(camera: &dyn CameraModel, f: &FrameInput, opts: &FixedPlaneOptions) -> Result<OnBoard, String> {
    let obs = f.corners.as_ref().map_err(|r| r.clone())?;
    let (pose, pose_covariance) = estimate_board_pose_with_covariance(camera, &obs.board_mm, &obs.pixels)
        .ok_or_else(|| format!("board pose failed ({} corners)", obs.pixels.len()))?;
    let mut ss = 0.0;
    let mut n = 0usize;
    for (xy, px) in obs.board_mm.iter().zip(&obs.pixels) {
        if let Some(q) = camera.point_to_pixel(&(pose * Point3::new(xy[0], xy[1], 0.0))) {
            ss += (q.x - px[0]).powi(2) + (q.y - px[1]).powi(2);
            n += 1;
        }
    }
    let corner_rms_px = (ss / n.max(1) as f64).sqrt();
    // The printed pattern's outline: one square beyond the outer inner corners.
    let pad = opts.square_mm + opts.margin_mm;
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for xy in &obs.board_mm {
        x0 = x0.min(xy[0]);
        x1 = x1.max(xy[0]);
        y0 = y0.min(xy[1]);
        y1 = y1.max(xy[1]);
    }
    let square = opts.square_mm;
    let pattern = (x0 - square, x1 + square, y0 - square, y1 + square);
    let (x0, x1, y0, y1) = (x0 - pad, x1 + pad, y0 - pad, y1 + pad);
    let inverse = pose.inverse();
    let on_board = |u: f64, v: f64| board_hit(&pose, &camera.pixel_to_ray(&Vector2::new(u, v))?);
    // How far (mm) a board point lies beyond the printed pattern, along the farther axis; ≤ 0 on it.
    let beyond_pattern = |x: f64, y: f64| {
        let (px0, px1, py0, py1) = pattern;
        (px0 - x).max(x - px1).max(py0 - y).max(y - py1)
    };
    // Distance (mm) from a board point to the nearest edge: inside the pattern the lines through
    // the inner corners, which lie at multiples of the square; outside it, its outline or the
    // board's own edge, where its white border ends.
    let edge_distance = |x: f64, y: f64| {
        let (px0, px1, py0, py1) = pattern;
        let (dx, dy) = ((px0 - x).max(x - px1), (py0 - y).max(y - py1));
        if dx > 0.0 || dy > 0.0 {
            let board_edge = (x - x0).min(x1 - x).min(y - y0).min(y1 - y);
            return dx.max(0.0).hypot(dy.max(0.0)).min(board_edge);
        }
        let off = |c: f64| ((c / square) - (c / square).round()).abs() * square;
        off(x).min(off(y))
    };
    let mut points = Vec::new();
    let mut pixels = Vec::new();
    let flags = f.saturated.as_deref().filter(|s| s.len() == f.stripe.len());
    let mut saturated = 0;
    let mut beyond = Beyond::default();
    let mut on_border = Vec::new();
    for (k, px) in f.stripe.iter().enumerate() {
        let Some(p) = on_board(px[0], px[1]) else { continue };
        let local = inverse * p;
        if !(local.x >= x0 && local.x <= x1 && local.y >= y0 && local.y <= y1) {
            beyond.add(beyond_pattern(local.x, local.y), square);
            continue;
        }
        if opts.edge_clearance_px > 0.0 {
            // The board's footprint of one pixel here (mm), the larger of the two axes'.
            let footprint = [on_board(px[0] + 1.0, px[1]), on_board(px[0], px[1] + 1.0)]
                .iter()
                .map(|q| q.map_or(f64::INFINITY, |q| (q - p).norm()))
                .fold(0.0f64, f64::max);
            if edge_distance(local.x, local.y) < opts.edge_clearance_px * footprint {
                continue;
            }
        }
        on_border.push(beyond_pattern(local.x, local.y) > 0.0);
        points.push(p);
        pixels.push(*px);
        saturated += usize::from(flags.is_some_and(|s| s[k]));
    }
    let steps = pose_covariance.map(|c| one_sigma_poses(&pose, &c));
    let pose_spread = steps.map(|steps| {
        pixels
            .iter()
            .map(|px| {
                let ray = camera.pixel_to_ray(&Vector2::new(px[0], px[1]));
                let mut spread = [Vector3::zeros(); 6];
                for (s, (plus, minus)) in spread.iter_mut().zip(&steps) {
                    if let Some(ray) = &ray
                        && let (Some(a), Some(b)) = (board_hit(plus, ray), board_hit(minus, ray))
                    {
                        *s = (a - b) / 2.0;
                    }
                }
                spread
            })
            .collect()
    });
    if points.len() < opts.min_points {
        let mut why = format!(
            "the board does not carry the stripe: {} of {} stripe points on the board, fewer than {}",
            points.len(),
            f.stripe.len(),
            opts.min_points
        );
        if points.len() + beyond.outside_mm.len() >= opts.min_points {
            let (near, far) = beyond.quartiles_mm();
            let out = if far - near < 0.05 { format!("{near:.1}") } else { format!("{near:.1}-{far:.1}") };
            why += &format!(
                "; {} more lie on the board's plane beyond the border kept ({} mm past the printed pattern), the middle half {out} mm past it: if the board is flat there, give its white border as margin_mm (or --margin-mm)",
                beyond.outside_mm.len(),
                opts.margin_mm
            );
        }
        return Err(why);
    }
    Ok(OnBoard {
        name: f.name.clone(),
        corners: obs.pixels.len(),
        corner_rms_px,
        pose,
        stripe_points: f.stripe.len(),
        points,
        pixels,
        saturated: flags.map(|_| saturated),
        on_border,
        pose_spread,
    })
}

/// Stripe points on the board's plane beyond the border kept, and beyond the printed pattern by
/// at most [`BEYOND_SQUARES`] squares: a stripe that runs along the board's white border, named
/// when its frame is skipped.
#[derive(Default)]
struct Beyond {
    /// How far each lies outside the pattern (mm).
    outside_mm: Vec<f64>,
}

/// How far beyond the printed pattern (squares) a stripe point counts as on the board's border.
const BEYOND_SQUARES: f64 = 3.0;

impl Beyond {
    /// A point outside the kept outline, `outside_mm` beyond the pattern's (mm; ≤ 0 where a
    /// negative margin left it out inside the pattern: not on the border).
    fn add(&mut self, outside_mm: f64, square_mm: f64) {
        if outside_mm > 0.0 && outside_mm <= BEYOND_SQUARES * square_mm {
            self.outside_mm.push(outside_mm);
        }
    }

    /// How far outside the pattern the middle half of them lie (mm): the stripe's course along
    /// the border, without the ends that leave the board. (0, 0) for none.
    fn quartiles_mm(&self) -> (f64, f64) {
        let mut d = self.outside_mm.clone();
        d.sort_by(f64::total_cmp);
        let at = |q: f64| d.get((d.len().saturating_sub(1) as f64 * q).round() as usize).copied().unwrap_or(0.0);
        (at(0.25), at(0.75))
    }
}

/// Where `ray` meets the board at `pose` (its z = 0 plane), in front of the ray's origin.
fn board_hit(pose: &Isometry3<f64>, ray: &omni_geom::Ray) -> Option<Point3<f64>> {
    let normal = pose.rotation * Vector3::z();
    let denom = normal.dot(&ray.dir);
    let t = (normal.dot(&pose.translation.vector) - normal.dot(&ray.origin.coords)) / denom;
    (denom.abs() >= 1e-9 && t > 0.0).then(|| ray.origin + ray.dir.into_inner() * t)
}

/// The board's pose moved by ± one σ along each principal axis of its parameters' covariance
/// ([`pose_to_params`]).
fn one_sigma_poses(pose: &Isometry3<f64>, covariance: &Matrix6<f64>) -> Vec<(Isometry3<f64>, Isometry3<f64>)> {
    let params = Vector6::from(pose_to_params(pose));
    let eig = covariance.symmetric_eigen();
    (0..6)
        .map(|k| {
            let step = eig.eigenvectors.column(k) * eig.eigenvalues[k].max(0.0).sqrt();
            (params_to_pose((params + step).as_slice()), params_to_pose((params - step).as_slice()))
        })
        .collect()
}

/// The robust plane of `frames`' points, oriented with offset ≥ 0.
fn fit_frames(frames: &[&OnBoard], seed: u64) -> Option<RobustPlaneFit> {
    let pts: Vec<Point3<f64>> = frames.iter().flat_map(|f| f.points.iter().copied()).collect();
    // Each frame's points lie on one line of the plane: scored frame by frame, a plane through
    // the line of a frame that holds most of the points does not win over the plane of all.
    let group: Vec<usize> =
        frames.iter().enumerate().flat_map(|(k, f)| std::iter::repeat_n(k, f.points.len())).collect();
    let mut fit = fit_plane_robust_grouped(&pts, &group, seed)?;
    weigh_board_poses(frames, &mut fit);
    if fit.plane.offset < 0.0 {
        fit.plane = fit.plane.flipped();
        fit.basis = (-fit.basis.0, -fit.basis.1);
        // With the normal and the basis both negated, a and b keep their sign and c changes its
        // own: the covariance of c with a and b changes sign.
        for (i, j) in [(0, 2), (1, 2), (2, 0), (2, 1)] {
            fit.covariance[(i, j)] = -fit.covariance[(i, j)];
        }
    }
    Some(fit)
}

/// One frame's inlier points (mm) and their pose spreads ([`OnBoard::pose_spread`]).
type FrameInliers = (Vec<Point3<f64>>, Vec<[Vector3<f64>; 6]>);

/// Refits `fit`'s plane to its inliers by generalised least squares: each frame's points share
/// its board's pose error (`pose_spread`), which moves them together, so a frame whose board is
/// posed less surely weighs less however many points it has; beside it each point's own scatter
/// about its frame's line, the frame's own (a stripe read less surely, dimmer or wider, weighs
/// less). The covariance is the fit's, scaled up by its χ² per degree of freedom where that
/// exceeds 1 (with each frame's scatter taken from its own points it stays near 1). What differs
/// between frames beyond their boards' poses (a stripe read a little off in one frame) adds a
/// term or two a frame against thousands of points, so this σ leaves it out; the jackknife over
/// frames holds it. Where a board has no
/// pose covariance, or the system is singular, the robust fit stays.
fn weigh_board_poses(frames: &[&OnBoard], fit: &mut RobustPlaneFit) {
    // Each frame's inliers with their pose spreads.
    let mut groups: Vec<FrameInliers> = Vec::with_capacity(frames.len());
    let mut at = 0;
    for f in frames {
        let inliers = &fit.inliers[at..at + f.points.len()];
        at += f.points.len();
        let Some(spread) = &f.pose_spread else { return };
        let kept = || f.points.iter().zip(spread).zip(inliers).filter(|(_, k)| **k).map(|(p, _)| p);
        groups.push((kept().map(|(p, _)| *p).collect(), kept().map(|(_, s)| *s).collect()));
    }
    let Some(pooled) = scatter_about_lines(&groups, &fit.plane) else { return };
    // Each frame's own scatter where it has the points to tell it, else the frames' pooled one;
    // exact points (rendered truth) scatter by rounding alone: a floor keeps the weights finite.
    let noises: Vec<f64> = groups
        .iter()
        .map(|g| {
            let own = (g.0.len() >= MIN_POINTS_FOR_OWN_SCATTER)
                .then(|| scatter_about_lines(std::slice::from_ref(g), &fit.plane))
                .flatten();
            own.unwrap_or(pooled).max(MIN_SCATTER_MM2)
        })
        .collect();
    let (mut plane, mut basis, mut covariance) = (fit.plane, fit.basis, fit.covariance);
    for _ in 0..GLS_ITERATIONS {
        // The covariance is taken in the basis at the plane before the step, which the last,
        // tiny step moves by far less than the covariance resolves.
        basis = orthonormal_basis(&plane.normal);
        let Some((step, normal_inverse, chi2, dof)) = gls_step(&groups, &plane, basis, &noises) else { return };
        covariance = normal_inverse * (chi2 / dof).max(1.0);
        let n = plane.normal.into_inner() + basis.0 * step.x + basis.1 * step.y;
        let Some(next) = Plane::from_normal_offset(&n, plane.offset + step.z) else { return };
        plane = next;
        if step.norm() < 1e-12 {
            break;
        }
    }
    (fit.plane, fit.basis, fit.covariance) = (plane, basis, covariance);
}

/// The smallest point scatter (mm², about a frame's line) the weights assume: 0.1 µm.
const MIN_SCATTER_MM2: f64 = 1e-8;

/// Fewest inliers a frame needs for its own scatter to weigh its points (4 degrees of freedom
/// about its line: its σ then known to about ±35 %, its variance to ±70 %).
const MIN_POINTS_FOR_OWN_SCATTER: usize = 6;

/// Gauss–Newton steps of [`weigh_board_poses`]; each moves the plane by what is left of its
/// linearisation's error, which the second step already leaves far below the fit's σ.
const GLS_ITERATIONS: usize = 4;

/// The variance (mm²) of the points' distances from `plane` about each frame's own straight line
/// of them, pooled over the frames `groups`: the points' scatter without what their frame
/// shares.
fn scatter_about_lines(groups: &[FrameInliers], plane: &Plane) -> Option<f64> {
    let (mut ss, mut dof) = (0.0, 0.0);
    for (points, _) in groups.iter().filter(|(p, _)| p.len() >= 3) {
        let (c, along) = best_line(points);
        // The distances' least-squares line over the position along the frame's line.
        let at: Vec<(f64, f64)> = points.iter().map(|p| ((p - c).dot(&along), plane.signed_distance(p))).collect();
        let m = at.len() as f64;
        let (mean_s, mean_r) = (at.iter().map(|a| a.0).sum::<f64>() / m, at.iter().map(|a| a.1).sum::<f64>() / m);
        let (mut sss, mut ssr, mut srr) = (0.0, 0.0, 0.0);
        for (s, r) in &at {
            (sss, ssr, srr) =
                (sss + (s - mean_s).powi(2), ssr + (s - mean_s) * (r - mean_r), srr + (r - mean_r).powi(2));
        }
        ss += if sss > 0.0 { srr - ssr * ssr / sss } else { srr };
        dof += m - 2.0;
    }
    if !(dof > 0.0) {
        return None;
    }
    let variance = (ss / dof).max(0.0);
    variance.is_finite().then_some(variance)
}

/// One generalised least-squares step for the plane's change (a, b, c) in `basis`
/// ([`RobustPlaneFit`]'s parametrisation), its covariance, the χ² at `plane` and its degrees of
/// freedom. Per frame the points' covariance is σ²·I + U·Uᵀ, σ² the frame's scatter (`noises`,
/// one per group) and U their distances' pose spreads;
/// its inverse by Woodbury's identity, σ⁻²(I − U (σ²I + UᵀU)⁻¹ Uᵀ), needs only 6 × 6 systems.
fn gls_step(
    groups: &[FrameInliers],
    plane: &Plane,
    basis: (Vector3<f64>, Vector3<f64>),
    noises: &[f64],
) -> Option<(Vector3<f64>, Matrix3<f64>, f64, f64)> {
    let (mut normal_matrix, mut gradient, mut chi2, mut count) = (Matrix3::zeros(), Vector3::zeros(), 0.0, 0usize);
    let n = plane.normal.into_inner();
    for ((points, spreads), &noise) in groups.iter().zip(noises) {
        let (mut xx, mut xr, mut rr) = (Matrix3::zeros(), Vector3::zeros(), 0.0);
        let (mut ux, mut uu, mut ur) = (Matrix6x3::zeros(), Matrix6::zeros(), Vector6::zeros());
        for (p, spread) in points.iter().zip(spreads) {
            let x = Vector3::new(basis.0.dot(&p.coords), basis.1.dot(&p.coords), -1.0);
            let r = plane.signed_distance(p);
            let u = Vector6::from_fn(|k, _| spread[k].dot(&n));
            xx += x * x.transpose();
            xr += x * r;
            rr += r * r;
            ux += u * x.transpose();
            uu += u * u.transpose();
            ur += u * r;
        }
        let inner = (Matrix6::identity() * noise + uu).cholesky()?;
        let (solved_x, solved_r) = (inner.solve(&ux), inner.solve(&ur));
        normal_matrix += (xx - ux.transpose() * solved_x) / noise;
        gradient += (xr - ux.transpose() * solved_r) / noise;
        chi2 += (rr - ur.dot(&solved_r)) / noise;
        count += points.len();
    }
    let covariance = normal_matrix.try_inverse()?;
    let step = -(covariance * gradient);
    Some((step, covariance, chi2, (count as f64 - 3.0).max(1.0)))
}

/// The best 3-D line through `points` (mm): their centroid and the direction of their largest
/// spread.
fn best_line(points: &[Point3<f64>]) -> (Point3<f64>, Vector3<f64>) {
    let c = omni_geom::fit::centroid(points);
    let mut s = Matrix3::zeros();
    for p in points {
        s += (p - c) * (p - c).transpose();
    }
    let eig = s.symmetric_eigen();
    let i = (0..3).max_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b])).unwrap_or(0);
    (c, eig.eigenvectors.column(i).into_owned())
}

/// RMS distance of `points` from their own best 3-D line (mm), and that distance as imaged
/// (px; each point against its foot on the line, both projected).
fn straightness(camera: &dyn CameraModel, points: &[Point3<f64>]) -> (f64, f64) {
    if points.len() < 3 {
        return (f64::NAN, f64::NAN);
    }
    let (c, u) = best_line(points);
    let (mut ss_mm, mut ss_px, mut n_px) = (0.0, 0.0, 0usize);
    for p in points {
        let foot = c + u * (p - c).dot(&u);
        ss_mm += (p - foot).norm_squared();
        if let (Some(a), Some(b)) = (camera.point_to_pixel(p), camera.point_to_pixel(&foot)) {
            ss_px += (a - b).norm_squared();
            n_px += 1;
        }
    }
    ((ss_mm / points.len() as f64).sqrt(), (ss_px / n_px.max(1) as f64).sqrt())
}

/// Parameters (a, b, c) of `plane` relative to `fit`'s plane and basis (rad, rad, mm).
fn relative(fit: &RobustPlaneFit, plane: &Plane) -> Vector3<f64> {
    let (n0, d0) = (fit.plane.normal.into_inner(), fit.plane.offset);
    let sign = plane.normal.dot(&n0).signum();
    let (n, d) = (plane.normal.into_inner() * sign, plane.offset * sign);
    Vector3::new((n - n0).dot(&fit.basis.0), (n - n0).dot(&fit.basis.1), d - d0)
}

/// Fits the fixed plane to the frames (module docs). Frames without a usable board or without
/// enough stripe points on it are skipped and named in the report; fewer than two usable
/// frames is an error naming why the others were skipped.
pub fn fit_fixed_plane(
    camera: &dyn CameraModel,
    frames: &[FrameInput],
    opts: &FixedPlaneOptions,
) -> Result<FixedPlaneFit, String> {
    let mut used = Vec::new();
    let mut skipped = Vec::new();
    let (cw, ch) = camera.image_size();
    if let Some(f) = frames.iter().find(|f| f.size.is_some_and(|s| s != (cw, ch))) {
        let (w, h) = f.size.unwrap_or_default();
        return Err(format!("{}: the frame is {w} × {h} px but the camera model is {cw} × {ch} px", f.name));
    }
    for f in frames {
        match board_points(camera, f, opts) {
            Ok(b) => used.push(b),
            Err(reason) => skipped.push(Skipped { name: f.name.clone(), reason }),
        }
    }
    if used.len() < 2 {
        let why: Vec<String> = skipped.iter().map(|s| format!("{}: {}", s.name, s.reason)).collect();
        return Err(format!(
            "{} usable frame{} of {}, at least 2 needed{}{}",
            used.len(),
            if used.len() == 1 { "" } else { "s" },
            frames.len(),
            if why.is_empty() { "" } else { "; skipped: " },
            why.join("; ")
        ));
    }
    let all: Vec<&OnBoard> = used.iter().collect();
    let fit = fit_frames(&all, opts.seed).ok_or("no plane fits the stripe points (collinear?)")?;
    // Leave one frame out: the plane of the others, each frame's inliers against it.
    let loo: Vec<Option<RobustPlaneFit>> = (0..used.len())
        .into_par_iter()
        .map(|k| {
            let others: Vec<&OnBoard> = used.iter().enumerate().filter(|(i, _)| *i != k).map(|(_, f)| f).collect();
            fit_frames(&others, opts.seed)
        })
        .collect();
    let mut reports = Vec::new();
    let mut frame_points = Vec::new();
    let mut offset = 0;
    let (mut ss_in, mut n_in, mut ss_loo) = (0.0, 0usize, 0.0);
    for (k, f) in used.iter().enumerate() {
        let inl = fit.inliers[offset..offset + f.points.len()].to_vec();
        offset += f.points.len();
        let kept: Vec<Point3<f64>> = f.points.iter().zip(&inl).filter(|(_, k)| **k).map(|(p, _)| *p).collect();
        let r: Vec<f64> = kept.iter().map(|p| fit.plane.signed_distance(p)).collect();
        let n = r.len().max(1) as f64;
        let ss: f64 = r.iter().map(|x| x * x).sum();
        let loo_plane = loo[k].as_ref().map(|l| l.plane);
        let ss_k: f64 = match loo_plane {
            Some(pl) => kept.iter().map(|p| pl.signed_distance(p).powi(2)).sum(),
            None => f64::NAN,
        };
        ss_in += ss;
        ss_loo += ss_k;
        n_in += r.len();
        let (straight_mm, straight_px) = straightness(camera, &kept);
        let border_off: Vec<f64> = (f.points.iter().zip(&f.on_border).zip(&inl))
            .filter(|((_, b), i)| **b && !**i)
            .map(|((p, _), _)| fit.plane.signed_distance(p).abs())
            .collect();
        reports.push(FrameReport {
            name: f.name.clone(),
            corners: f.corners,
            corner_rms_px: f.corner_rms_px,
            board_distance_mm: (f.pose * Point3::origin()).coords.norm(),
            stripe_points: f.stripe_points,
            board_points: f.points.len(),
            saturated_points: f.saturated,
            inliers: r.len(),
            border_points: f.on_border.iter().filter(|b| **b).count(),
            border_outliers: border_off.len(),
            border_outlier_median_mm: omni_geom::stats::median(&border_off),
            residual_rms_mm: (ss / n).sqrt(),
            residual_mean_mm: r.iter().sum::<f64>() / n,
            straightness_mm: straight_mm,
            straightness_px: straight_px,
            leave_one_out_rms_mm: (ss_k / n).sqrt(),
        });
        frame_points.push(FramePoints {
            name: f.name.clone(),
            points: f.points.clone(),
            pixels: f.pixels.clone(),
            inliers: inl,
        });
    }
    // Jackknife over frames: (k − 1)/k Σ (θ_i − θ̄)² of the leave-one-out planes' parameters.
    let thetas: Vec<Vector3<f64>> = loo.iter().flatten().map(|l| relative(&fit, &l.plane)).collect();
    let k = thetas.len() as f64;
    let mean = thetas.iter().fold(Vector3::zeros(), |a, t| a + t) / k.max(1.0);
    let mut jack = omni_geom::Matrix3::zeros();
    for t in &thetas {
        let d = t - mean;
        jack += d * d.transpose();
    }
    jack *= (k - 1.0) / k.max(1.0);
    let inlier_points: Vec<Point3<f64>> = frame_points
        .iter()
        .flat_map(|f| f.points.iter().zip(&f.inliers).filter(|(_, k)| **k).map(|(p, _)| *p))
        .collect();
    let centroid = omni_geom::fit::centroid(&inlier_points);
    let at = |cov: &omni_geom::Matrix3<f64>, p: &Point3<f64>| {
        let j = Vector3::new(fit.basis.0.dot(&p.coords), fit.basis.1.dot(&p.coords), -1.0);
        (j.transpose() * cov * j)[(0, 0)].max(0.0).sqrt()
    };
    let n = fit.plane.normal;
    let plane_report = PlaneReport {
        normal: [n.x, n.y, n.z],
        distance_mm: fit.plane.offset,
        normal_sigma_deg: fit.normal_sigma().to_degrees(),
        distance_sigma_mm: fit.covariance[(2, 2)].max(0.0).sqrt(),
        centroid_sigma_mm: fit.sigma_at(&centroid),
        jackknife_normal_sigma_deg: (jack[(0, 0)] + jack[(1, 1)]).max(0.0).sqrt().to_degrees(),
        jackknife_distance_sigma_mm: jack[(2, 2)].max(0.0).sqrt(),
        jackknife_centroid_sigma_mm: at(&jack, &centroid),
        centroid_mm: [centroid.x, centroid.y, centroid.z],
    };
    let points_total: usize = used.iter().map(|f| f.points.len()).sum();
    let report = FixedPlaneReport {
        plane: plane_report,
        points: points_total,
        inliers: n_in,
        rms_mm: (ss_in / n_in.max(1) as f64).sqrt(),
        robust_sigma_mm: fit.robust_sigma,
        leave_one_out_rms_mm: (ss_loo / n_in.max(1) as f64).sqrt(),
        frames_total: frames.len(),
        frames: reports,
        skipped,
    };
    Ok(FixedPlaneFit { plane: fit.plane, report, frames: frame_points })
}

/// How [`detect_frames`] finds the board and the stripe.
#[derive(Debug, Clone)]
pub struct DetectOptions {
    pub inner_cols: u32,
    pub inner_rows: u32,
    pub square_mm: f64,
    /// Fewest corners for a (partial) board.
    pub min_corners: usize,
    /// What the stripe detector reads from the frame (a colour's laser contrast, a channel).
    pub colour: omni_vision::colour::ColourSpec,
    pub ridge: omni_vision::stripe::RidgeParams,
}

/// Detects the board's corners and the stripe in each frame (in parallel); `given` holds each
/// frame's stripe centres (px) from elsewhere (another detector), in which case the stripe
/// detector is not run. A frame that cannot
/// be read is an error naming it; a frame without a board is kept with the reason (skipped by
/// [`fit_fixed_plane`]). When most frames that show the whole board show another size than
/// the board file's, or most frames hold a corner grid larger than it, that is an error naming
/// the likely size.
pub fn detect_frames(
    paths: &[PathBuf],
    opts: &DetectOptions,
    given: Option<&[Vec<[f64; 2]>]>,
) -> Result<Vec<FrameInput>, String> {
    if let Some(g) = given {
        assert_eq!(g.len(), paths.len(), "one stripe per frame");
    }
    let detector = omni_vision::corners::DetectorOptions { min_corners: opts.min_corners, ..Default::default() };
    type Detected = (FrameInput, ImageCorners, Option<(u32, u32)>);
    let results: Vec<Result<Detected, String>> = paths
        .par_iter()
        .enumerate()
        .map(|(k, path)| {
            let name = path.display().to_string();
            let grey = omni_vision::corners::load_gray(path).map_err(|e| e.to_string())?;
            let found = omni_vision::corners::detect_board(&grey, opts.inner_cols, opts.inner_rows, &detector);
            let entry = ImageCorners::from_detection(name.clone(), found.clone());
            let larger = match &found {
                Err(omni_vision::corners::Rejection::LargerThanBoard { found }) => Some(*found),
                _ => None,
            };
            let corners = match found {
                Ok(b) => Ok(Observation::from_corners(&name, &b, opts.square_mm)),
                Err(why) => Err(format!("board not found: {why}")),
            };
            let (stripe, saturated) = match given {
                Some(g) => (g[k].clone(), None),
                None => detect_stripe(path, &opts.colour, &opts.ridge).map(|(stripe, flags)| (stripe, Some(flags)))?,
            };
            let size = Some((grey.width as u32, grey.height as u32));
            Ok((FrameInput { name, corners, stripe, saturated, size }, entry, larger))
        })
        .collect();
    let mut frames = Vec::new();
    let mut corners = CornersFile::new(1, 1, opts.inner_cols, opts.inner_rows);
    let mut larger = Vec::new();
    for r in results {
        let (f, entry, l) = r?;
        frames.push(f);
        corners.images.push(entry);
        larger.extend(l.map(|(a, b)| (a.max(b), a.min(b))));
    }
    if let Some(w) = corners.board_size_warning() {
        return Err(w);
    }
    if 2 * larger.len() > frames.len() {
        let (long, short) = *larger.iter().max_by_key(|s| larger.iter().filter(|t| t == s).count()).expect("not empty");
        let (cols, rows) = (opts.inner_cols, opts.inner_rows);
        let likely = if cols >= rows { (long, short) } else { (short, long) };
        return Err(format!(
            "the board file says {cols} × {rows} inner corners, but {} of the {} frames hold a larger corner grid (up to {} × {}): the board is probably at least {} × {}; fix inner_cols / inner_rows of the board file",
            larger.len(),
            frames.len(),
            likely.0,
            likely.1,
            likely.0,
            likely.1
        ));
    }
    Ok(frames)
}

/// The stripe centres of one frame (px), the whole frame searched, and which of them are
/// saturated.
pub fn detect_stripe(
    path: &Path,
    colour: &omni_vision::colour::ColourSpec,
    ridge: &omni_vision::stripe::RidgeParams,
) -> Result<(Vec<[f64; 2]>, Vec<bool>), String> {
    let img = omni_vision::image_io::load_frame_channel(path, colour).map_err(|e| e.to_string())?;
    let detector = omni_vision::stripe::RidgeDetector::whole_frame(img.width, img.height, *ridge);
    let points = detector.detect(&img);
    let saturated = points.iter().map(|p| p.quality & omni_vision::stripe::quality::SATURATED != 0).collect();
    Ok((points.iter().map(|p| [p.u, p.v]).collect(), saturated))
}
