//! From stripe pixels to 3D points on the rig boards, and one robust plane per frame.

use nalgebra::{Isometry3, Matrix6, Point3, Vector2, Vector3};
use omni_formats::rig::RigBoard;
use omni_geom::fit::fit_plane;
use omni_geom::rng::SplitMix64;
use omni_geom::{Intersection, Plane, Ray, intersect_ray_plane};
use omni_model::CameraModel;

/// A rig board at its pose in the world frame.
#[derive(Debug, Clone)]
pub struct PlacedBoard {
    pub name: String,
    /// Frames with this placement number see this board.
    pub placement: u32,
    /// Board → world (mm).
    pub pose: Isometry3<f64>,
    /// Physical outline in board coordinates (mm): (x_min, x_max, y_min, y_max).
    pub extent_mm: (f64, f64, f64, f64),
    /// Covariance of the pose's parameters ([`crate::pose::pose_to_params`]: rotation vector in
    /// rad, translation in mm) where it was estimated from corners; `None` for a given pose.
    pub pose_covariance: Option<Matrix6<f64>>,
}

impl PlacedBoard {
    pub fn new(board: &RigBoard, pose: Isometry3<f64>) -> Self {
        PlacedBoard {
            name: board.name.clone(),
            placement: board.placement,
            pose,
            extent_mm: board.extent_mm(),
            pose_covariance: None,
        }
    }

    /// The board with the covariance of its estimated pose.
    pub fn with_pose_covariance(self, covariance: Option<Matrix6<f64>>) -> Self {
        PlacedBoard { pose_covariance: covariance, ..self }
    }

    /// The board's plane in the world frame (normal = board z axis).
    pub fn plane(&self) -> Plane {
        Plane::from_point_normal(&(self.pose * Point3::origin()), &(self.pose * Vector3::z()))
    }

    /// Where `ray` meets the board inside its outline; `None` if it misses, is behind, or grazes
    /// the board (|cos incidence| < `min_cos`).
    pub fn hit(&self, ray: &Ray, min_cos: f64) -> Option<Intersection> {
        let hit = intersect_ray_plane(ray, &self.plane(), min_cos).ok()?;
        let local = self.pose.inverse_transform_point(&hit.point);
        let (x0, x1, y0, y1) = self.extent_mm;
        (local.x >= x0 && local.x <= x1 && local.y >= y0 && local.y <= y1).then_some(hit)
    }
}

/// The stripe of one laser frame: what the calibration needs from a stream record.
#[derive(Debug, Clone)]
pub struct FrameStripes {
    /// Frame sequence number (for messages and the report).
    pub seq: u64,
    /// Mirror angle within the facet (radians).
    pub alpha_rad: f64,
    /// Facet facing laser 0.
    pub facet: u32,
    /// Rig placement the frame was taken in.
    pub placement: u32,
    /// Lasers that were on.
    pub lasers: Vec<u32>,
    /// Stripe centre pixels (x right, y down).
    pub pixels: Vec<[f64; 2]>,
}

/// A stripe point back-projected onto a board (world frame, mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardPoint {
    /// Index into the placed boards.
    pub board: usize,
    pub point: Point3<f64>,
}

/// Back-projects each stripe pixel onto the nearest board of the frame's placement whose outline
/// its ray meets. Returns the points and the number of pixels that fell on no board.
pub fn locate_on_boards(
    camera: &dyn CameraModel,
    boards: &[PlacedBoard],
    frame: &FrameStripes,
    min_cos: f64,
) -> (Vec<BoardPoint>, usize) {
    let mut points = Vec::with_capacity(frame.pixels.len());
    let mut missed = 0;
    for px in &frame.pixels {
        let Some(ray) = camera.pixel_to_ray(&Vector2::new(px[0], px[1])) else {
            missed += 1;
            continue;
        };
        let nearest = boards
            .iter()
            .enumerate()
            .filter(|(_, b)| b.placement == frame.placement)
            .filter_map(|(i, b)| b.hit(&ray, min_cos).map(|h| (i, h)))
            .min_by(|a, b| a.1.t.total_cmp(&b.1.t));
        match nearest {
            Some((board, hit)) => points.push(BoardPoint { board, point: hit.point }),
            None => missed += 1,
        }
    }
    (points, missed)
}

/// Settings of the per-frame plane fit.
#[derive(Debug, Clone, Copy)]
pub struct FramePlaneOptions {
    /// Fewest points a board must hold to count as crossed by the stripe.
    pub min_points_per_board: usize,
    /// Outliers: |distance| > max(`outlier_sigmas`·σ_MAD, `outlier_floor_mm`).
    pub outlier_sigmas: f64,
    pub outlier_floor_mm: f64,
    /// Below this ratio of the two largest point spreads the points are a line, not a plane.
    pub min_planarity: f64,
}

impl Default for FramePlaneOptions {
    fn default() -> Self {
        FramePlaneOptions { min_points_per_board: 8, outlier_sigmas: 4.0, outlier_floor_mm: 0.2, min_planarity: 0.05 }
    }
}

/// A frame's own least-squares light plane.
#[derive(Debug, Clone)]
pub struct FramePlane {
    pub plane: Plane,
    /// RMS point-to-plane distance of the inliers (mm).
    pub rms_mm: f64,
    /// Per input point: kept by the outlier rejection.
    pub inliers: Vec<bool>,
    /// Boards holding at least the minimum number of inliers.
    pub boards_crossed: usize,
}

/// Fits a plane to one frame's board points, rejecting outliers; refuses a frame whose points
/// cannot fix a plane (fewer than two boards crossed, or the points nearly collinear), with the
/// reason as the error.
pub fn fit_frame_plane(points: &[BoardPoint], n_boards: usize, opts: &FramePlaneOptions) -> Result<FramePlane, String> {
    let crossed = |mask: &[bool]| {
        let mut count = vec![0usize; n_boards];
        for (p, &keep) in points.iter().zip(mask) {
            if keep {
                count[p.board] += 1;
            }
        }
        count.iter().filter(|&&c| c >= opts.min_points_per_board).count()
    };
    let mut inliers = vec![true; points.len()];
    if crossed(&inliers) < 2 {
        return Err(format!(
            "stripe crosses fewer than two boards with {} points each: its points lie on one line",
            opts.min_points_per_board
        ));
    }
    // Start from the least-median-of-squares plane: up to half the points may be spurious
    // (glints, ambient structure) without pulling the least-squares rounds below away.
    if let Some(start) = lmeds_inliers(points, opts) {
        inliers = start;
    }
    let mut fit = None;
    for _round in 0..4 {
        let kept: Vec<Point3<f64>> = points.iter().zip(&inliers).filter(|(_, k)| **k).map(|(p, _)| p.point).collect();
        let f = fit_plane(&kept).ok_or("plane fit failed (non-finite points)")?;
        if f.planarity_ratio < opts.min_planarity {
            return Err(format!("points nearly collinear (planarity {:.3})", f.planarity_ratio));
        }
        let dist: Vec<f64> = points.iter().map(|p| f.plane.signed_distance(&p.point)).collect();
        let limit = (opts.outlier_sigmas * robust_sigma(&dist)).max(opts.outlier_floor_mm);
        let next: Vec<bool> = dist.iter().map(|d| d.abs() <= limit).collect();
        let changed = next != inliers;
        inliers = next;
        fit = Some(f);
        if !changed {
            break;
        }
    }
    let kept: Vec<Point3<f64>> = points.iter().zip(&inliers).filter(|(_, k)| **k).map(|(p, _)| p.point).collect();
    let boards_crossed = crossed(&inliers);
    if boards_crossed < 2 {
        return Err("after outlier rejection the stripe crosses fewer than two boards".into());
    }
    let f = fit_plane(&kept).or(fit).ok_or("plane fit failed")?;
    Ok(FramePlane { plane: f.plane, rms_mm: f.rms, inliers, boards_crossed })
}

/// Inliers of a least-median-of-squares plane over deterministic random triples. The score of a
/// plane is the worst, over the boards crossed, of the median squared distance of that board's
/// points, so a plane must explain the stripe line on every board (a plain median would accept
/// any plane through the line of the board that holds most points). Inliers lie within
/// max(`outlier_sigmas`·σ, floor), σ = 1.4826·(1 + 5/(n − 3))·√score (Rousseeuw's scale).
/// `None` if no triple spans a plane.
fn lmeds_inliers(points: &[BoardPoint], opts: &FramePlaneOptions) -> Option<Vec<bool>> {
    let n = points.len();
    if n < 4 {
        return None;
    }
    let mut groups: Vec<Vec<usize>> = vec![];
    for b in 0..=points.iter().map(|p| p.board).max()? {
        let idx: Vec<usize> = (0..n).filter(|&i| points[i].board == b).collect();
        if idx.len() >= opts.min_points_per_board {
            groups.push(idx);
        }
    }
    // Seeded by the point count: deterministic for the same input.
    let mut rng = SplitMix64::new(0x9E37_79B9_7F4A_7C15u64 ^ n as u64);
    let mut next = || rng.below(n);
    let mut best: Option<(f64, Plane)> = None;
    let mut dist = vec![];
    for _ in 0..300 {
        let (a, b, c) = (points[next()].point, points[next()].point, points[next()].point);
        let normal = (b - a).cross(&(c - a));
        // Skip triples that are (nearly) collinear: they come from one board line.
        if normal.norm() < 1e-3 * (b - a).norm() * (c - a).norm() || normal.norm() == 0.0 {
            continue;
        }
        let plane = Plane::from_point_normal(&a, &normal);
        let mut score = 0.0f64;
        for g in &groups {
            dist.clear();
            dist.extend(g.iter().map(|&i| plane.signed_distance(&points[i].point).powi(2)));
            let k = dist.len() / 2;
            score = score.max(*dist.select_nth_unstable_by(k, f64::total_cmp).1);
        }
        if best.is_none_or(|(m, _)| score < m) {
            best = Some((score, plane));
        }
    }
    let (score, plane) = best?;
    let sigma = 1.4826 * (1.0 + 5.0 / (n as f64 - 3.0)) * score.sqrt();
    let limit = (opts.outlier_sigmas * sigma).max(opts.outlier_floor_mm);
    Some(points.iter().map(|p| plane.signed_distance(&p.point).abs() <= limit).collect())
}

/// 1.4826 × median absolute deviation from the median: σ of the bulk, blind to outliers.
pub fn robust_sigma(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let med = median(values.to_vec());
    1.4826 * median(values.iter().map(|v| (v - med).abs()).collect())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_geom::rng::SplitMix64;

    /// Points on two perpendicular lines of the plane z = 0.1·x − 100 (mm), on boards 0 and 1,
    /// with 0.1 mm noise.
    fn two_lines(rng: &mut SplitMix64) -> (Plane, Vec<BoardPoint>) {
        let plane = Plane::from_point_normal(&Point3::new(0.0, 0.0, -100.0), &Vector3::new(-0.1, 0.0, 1.0));
        let mut pts = vec![];
        for i in 0..100 {
            let s = i as f64 * 3.0;
            for (board, p) in [(0, Point3::new(400.0 + s, s, 0.0)), (1, Point3::new(400.0 + s, -s, 0.0))] {
                let mut q = plane.project(&p);
                q.z += 0.1 * rng.normal();
                pts.push(BoardPoint { board, point: q });
            }
        }
        (plane, pts)
    }

    #[test]
    fn frame_plane_survives_forty_percent_spurious_points() {
        let mut rng = SplitMix64::new(4);
        let (truth, mut pts) = two_lines(&mut rng);
        let good = pts.len();
        // Spurious points: 40 % of the total, up to ±80 mm off the plane (e.g. checkerboard edges).
        for i in 0..(good * 2 / 3) {
            let mut p = pts[i].point;
            p.z += 20.0 + 60.0 * rng.uniform();
            pts.push(BoardPoint { point: p, ..pts[i] });
        }
        let fit = fit_frame_plane(&pts, 2, &FramePlaneOptions::default()).unwrap();
        // The spurious points must not move the plane: it is the least-squares plane of the good
        // points alone (up to the two noisiest of them, which the rejection may drop).
        let clean: Vec<Point3<f64>> = pts[..good].iter().map(|p| p.point).collect();
        let oracle = fit_plane(&clean).unwrap().plane;
        let to_oracle = fit.plane.angle_to(&oracle).to_degrees();
        assert!(to_oracle < 0.001, "normal {to_oracle}° from the good points' own plane");
        // And that plane is as close to the truth as the noise allows: 200 points with 0.1 mm
        // noise spread ±170 mm and ±86 mm about their centroid give σ ≈ 0.0053° for the normal
        // (0.0058° measured); the bound is 4σ.
        let angle = fit.plane.angle_to(&truth).to_degrees();
        assert!(angle < 0.02, "normal error {angle}°");
        assert!(
            (fit.plane.signed_distance(&Point3::new(500.0, 0.0, -50.0))
                - truth.signed_distance(&Point3::new(500.0, 0.0, -50.0)))
            .abs()
                < 0.05
        );
        assert!(fit.inliers[..good].iter().filter(|k| **k).count() >= good - 2, "good points kept");
        assert!(fit.inliers[good..].iter().all(|k| !k), "spurious points rejected");
        assert!(fit.rms_mm < 0.12, "rms {}", fit.rms_mm);
    }

    #[test]
    fn points_on_one_board_line_are_refused_with_the_reason() {
        let mut rng = SplitMix64::new(5);
        let (_, pts) = two_lines(&mut rng);
        let one_board: Vec<BoardPoint> = pts.iter().filter(|p| p.board == 0).copied().collect();
        let e = fit_frame_plane(&one_board, 2, &FramePlaneOptions::default()).unwrap_err();
        assert!(e.contains("one line"), "{e}");
        // Two boards but all points on a single straight line: collinear.
        let line: Vec<BoardPoint> =
            (0..40).map(|i| BoardPoint { board: i % 2, point: Point3::new(i as f64, 0.0, 0.0) }).collect();
        let e = fit_frame_plane(&line, 2, &FramePlaneOptions::default()).unwrap_err();
        assert!(e.contains("collinear"), "{e}");
    }
}
