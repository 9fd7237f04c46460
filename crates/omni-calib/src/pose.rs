//! Board poses from a calibrated (or trial) camera: linear estimate from rays, then
//! Levenberg–Marquardt on the pixel reprojection error.
//!
//! A board point (x, y) in mm (board frame, z = 0) maps to the world as R·(x, y, 0) + t.
//! Poses are parametrised for optimisation as (rotation vector, translation) — 6 numbers.

use nalgebra::{
    DMatrix, Isometry3, Matrix3, Matrix6, Point3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3,
};
use omni_geom::lm;
use omni_model::CameraModel;

/// Pose → 6 parameters (rotation vector in rad, translation in mm).
pub fn pose_to_params(pose: &Isometry3<f64>) -> [f64; 6] {
    let r = pose.rotation.scaled_axis();
    let t = pose.translation.vector;
    [r.x, r.y, r.z, t.x, t.y, t.z]
}

/// 6 parameters → pose.
pub fn params_to_pose(p: &[f64]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p[3], p[4], p[5]),
        UnitQuaternion::from_scaled_axis(Vector3::new(p[0], p[1], p[2])),
    )
}

/// World position of a board point under a pose given as 6 parameters.
#[inline]
pub fn board_to_world(p: &[f64], xy: [f64; 2]) -> Point3<f64> {
    let rot = Rotation3::new(Vector3::new(p[0], p[1], p[2]));
    Point3::from(rot * Vector3::new(xy[0], xy[1], 0.0) + Vector3::new(p[3], p[4], p[5]))
}

/// Linear pose of a planar board from the viewing rays of its points (central camera with
/// viewpoint `origin`): the direct linear transform of the homography H = [r1 r2 t] between
/// the board plane and the ray directions, then the closest rotation. Needs ≥ 4 points in
/// general position; `None` if degenerate.
pub fn pose_from_rays(origin: &Point3<f64>, dirs: &[Vector3<f64>], board_mm: &[[f64; 2]]) -> Option<Isometry3<f64>> {
    let n = dirs.len().min(board_mm.len());
    if n < 4 {
        return None;
    }
    // Normalise board coordinates for conditioning.
    let (mx, my) = board_mm[..n].iter().fold((0.0, 0.0), |a, p| (a.0 + p[0], a.1 + p[1]));
    let (mx, my) = (mx / n as f64, my / n as f64);
    let scale = (board_mm[..n].iter().map(|p| (p[0] - mx).hypot(p[1] - my)).sum::<f64>() / n as f64).max(1e-9);
    let mut a = DMatrix::<f64>::zeros(3 * n, 9);
    for k in 0..n {
        let b = dirs[k].normalize();
        let x = [(board_mm[k][0] - mx) / scale, (board_mm[k][1] - my) / scale, 1.0];
        // b × (H x) = 0: rows of the skew matrix [b]× times H x.
        let skew = Matrix3::new(0.0, -b.z, b.y, b.z, 0.0, -b.x, -b.y, b.x, 0.0);
        for r in 0..3 {
            for hr in 0..3 {
                for hc in 0..3 {
                    a[(3 * k + r, 3 * hr + hc)] = skew[(r, hr)] * x[hc];
                }
            }
        }
    }
    let svd = (a.transpose() * &a).symmetric_eigen();
    let (imin, _) = svd.eigenvalues.iter().enumerate().min_by(|x, y| x.1.total_cmp(y.1))?;
    let h = svd.eigenvectors.column(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    // Undo the normalisation: x_norm = T·x.
    let t_norm = Matrix3::new(1.0 / scale, 0.0, -mx / scale, 0.0, 1.0 / scale, -my / scale, 0.0, 0.0, 1.0);
    let mut hm = hn * t_norm;
    let lambda = 2.0 / (hm.column(0).norm() + hm.column(1).norm());
    hm *= lambda;
    // Points must lie in front of the viewpoint along their rays.
    let front: f64 =
        (0..n).map(|k| (hm * Vector3::new(board_mm[k][0], board_mm[k][1], 1.0)).dot(&dirs[k]).signum()).sum();
    if front < 0.0 {
        hm = -hm;
    }
    let r1 = hm.column(0).into_owned();
    let r2 = hm.column(1).into_owned();
    let r3 = r1.cross(&r2);
    let approx = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = approx.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut rot = u * vt;
    if rot.determinant() < 0.0 {
        return None;
    }
    rot = Rotation3::from_matrix_unchecked(rot).into_inner();
    let t = hm.column(2).into_owned() + origin.coords;
    let pose = Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot)),
    );
    pose.translation.vector.iter().all(|v| v.is_finite()).then_some(pose)
}

struct PoseProblem<'a> {
    project: &'a dyn Fn(&Point3<f64>) -> Option<Vector2<f64>>,
    board: &'a [[f64; 2]],
    pixels: &'a [[f64; 2]],
}

/// Residual (px) used when a point does not project at all: large, so the solver moves away.
pub const UNPROJECTABLE_PX: f64 = 50.0;

impl lm::Problem for PoseProblem<'_> {
    fn num_params(&self) -> usize {
        6
    }
    fn num_residuals(&self) -> usize {
        2 * self.board.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        for (k, (xy, px)) in self.board.iter().zip(self.pixels).enumerate() {
            match (self.project)(&board_to_world(p, *xy)) {
                Some(q) => {
                    out[2 * k] = q.x - px[0];
                    out[2 * k + 1] = q.y - px[1];
                }
                None => {
                    out[2 * k] = UNPROJECTABLE_PX;
                    out[2 * k + 1] = UNPROJECTABLE_PX;
                }
            }
        }
    }
}

/// Refines a board pose by minimising the pixel reprojection error; returns the pose, the RMS
/// error (px) and the covariance of the pose's parameters as [`pose_to_params`] gives them
/// (rotation vector in rad, its angle at most π; translation in mm), the corners' errors taken
/// as independent (`None` if singular).
pub fn refine_pose(
    project: &dyn Fn(&Point3<f64>) -> Option<Vector2<f64>>,
    board_mm: &[[f64; 2]],
    pixels: &[[f64; 2]],
    initial: &Isometry3<f64>,
    iterations: usize,
) -> (Isometry3<f64>, f64, Option<Matrix6<f64>>) {
    let problem = PoseProblem { project, board: board_mm, pixels };
    let opts = lm::Options { max_iterations: iterations, huber: Some(3.0), ..Default::default() };
    let report = lm::minimize(&problem, &pose_to_params(initial), &opts);
    let covariance = report.covariance.as_ref().map(|c| Matrix6::from_fn(|i, j| c[(i, j)]));
    let pose = params_to_pose(&report.params);
    let rotation = Vector3::new(report.params[0], report.params[1], report.params[2]);
    (pose, report.rms, covariance.map(|c| in_shortest_rotation(&rotation, &c)))
}

/// A pose covariance taken at rotation vector `r` re-expressed for the same rotation's shortest
/// vector (angle at most π, as [`pose_to_params`] gives it). The solver may end past π, where
/// r' = r·(1 − 2πk/|r|) and the sideways components change sign: Jacobian
/// (1 − 2πk/|r|)·I + 2πk·r·rᵀ/|r|³ on the rotation's rows.
fn in_shortest_rotation(r: &Vector3<f64>, covariance: &Matrix6<f64>) -> Matrix6<f64> {
    let angle = r.norm();
    let turns = ((angle + std::f64::consts::PI) / std::f64::consts::TAU).floor();
    if turns == 0.0 {
        return *covariance;
    }
    let k = std::f64::consts::TAU * turns;
    let mut jacobian = Matrix6::identity();
    let rotation = Matrix3::identity() * (1.0 - k / angle) + r * r.transpose() * (k / angle.powi(3));
    jacobian.fixed_view_mut::<3, 3>(0, 0).copy_from(&rotation);
    jacobian * covariance * jacobian.transpose()
}

/// The pose (board → world) of a planar board from its detected corners: `board_points_mm` are
/// the corners' board coordinates (mm, board frame z = 0), `pixels` their image positions.
/// Linear estimate from the camera's rays, then LM on the reprojection error. `None` if fewer
/// than 4 corners see the scene or the estimate degenerates.
pub fn estimate_board_pose(
    camera: &dyn CameraModel,
    board_points_mm: &[[f64; 2]],
    pixels: &[[f64; 2]],
) -> Option<Isometry3<f64>> {
    estimate_board_pose_with_covariance(camera, board_points_mm, pixels).map(|(pose, _)| pose)
}

/// [`estimate_board_pose`] with the covariance of the pose's parameters ([`refine_pose`]).
pub fn estimate_board_pose_with_covariance(
    camera: &dyn CameraModel,
    board_points_mm: &[[f64; 2]],
    pixels: &[[f64; 2]],
) -> Option<(Isometry3<f64>, Option<Matrix6<f64>>)> {
    let mut dirs = Vec::new();
    let mut board = Vec::new();
    let mut px_used = Vec::new();
    let mut origin = Vector3::zeros();
    for (xy, px) in board_points_mm.iter().zip(pixels) {
        if let Some(ray) = camera.pixel_to_ray(&Vector2::new(px[0], px[1])) {
            origin += ray.origin.coords;
            dirs.push(ray.dir.into_inner());
            board.push(*xy);
            px_used.push(*px);
        }
    }
    if dirs.len() < 4 {
        return None;
    }
    let origin = Point3::from(origin / dirs.len() as f64);
    let initial = pose_from_rays(&origin, &dirs, &board)?;
    let project = |p: &Point3<f64>| camera.point_to_pixel(p);
    let (pose, _, covariance) = refine_pose(&project, &board, &px_used, &initial, 50);
    Some((pose, covariance))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The covariance moved to the shortest rotation vector is the solver's carried through the
    /// chart change r → pose_to_params(params_to_pose(r)), differentiated numerically.
    #[test]
    fn a_covariance_past_half_a_turn_is_carried_to_the_shortest_rotation() {
        for angle in [1.0, 3.3, 9.5] {
            let p = [0.6 * angle, -0.48 * angle, 0.64 * angle, 10.0, -20.0, 300.0];
            let r = Vector3::new(p[0], p[1], p[2]);
            let a = Matrix6::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 * 0.1 + if i == j { 1.0 } else { 0.0 });
            let covariance = a * a.transpose() * 1e-4;
            let h = 1e-6;
            let jacobian = Matrix6::from_fn(|i, j| {
                let (mut up, mut down) = (p, p);
                up[j] += h;
                down[j] -= h;
                let (u, d) = (pose_to_params(&params_to_pose(&up)), pose_to_params(&params_to_pose(&down)));
                (u[i] - d[i]) / (2.0 * h)
            });
            let expected = jacobian * covariance * jacobian.transpose();
            let got = in_shortest_rotation(&r, &covariance);
            assert!((got - expected).abs().max() < 1e-8, "angle {angle}: {got} vs {expected}");
        }
    }
    use omni_model::{HyperbolicCamera, HyperbolicParams};

    #[test]
    fn recovers_a_board_pose_through_the_mirror() {
        let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        let truth = Isometry3::from_parts(
            Translation3::new(420.0, -150.0, -60.0),
            UnitQuaternion::from_euler_angles(1.2, 0.3, -1.9),
        );
        let mut board = Vec::new();
        let mut pixels = Vec::new();
        for j in 0..6 {
            for i in 0..9 {
                let xy = [i as f64 * 25.0, j as f64 * 25.0];
                let p = truth * Point3::new(xy[0], xy[1], 0.0);
                if let Some(px) = cam.point_to_pixel(&p) {
                    board.push(xy);
                    pixels.push([px.x, px.y]);
                }
            }
        }
        assert!(board.len() > 40, "{}", board.len());
        let pose = estimate_board_pose(&cam, &board, &pixels).unwrap();
        let dt = (pose.translation.vector - truth.translation.vector).norm();
        let da = pose.rotation.angle_to(&truth.rotation);
        assert!(dt < 1e-6 && da < 1e-9, "translation error {dt} mm, rotation error {da} rad");
    }
}
