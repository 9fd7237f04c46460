//! From stripe pixels to 3D points on the rig boards, and one robust plane per frame.

use nalgebra::{Isometry3, Point3, Vector2, Vector3};
use omni_formats::rig::RigBoard;
use omni_geom::fit::fit_plane;
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
}

impl PlacedBoard {
    pub fn new(board: &RigBoard, pose: Isometry3<f64>) -> Self {
        PlacedBoard { name: board.name.clone(), placement: board.placement, pose, extent_mm: board.extent_mm() }
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
    let mut fit = None;
    for _round in 0..3 {
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
