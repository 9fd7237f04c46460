//! Motion compensation: the sensor's pose at any time, interpolated from odometry samples, so
//! the slices of a moving sensor land in one world frame.
//!
//! Between two samples the rotation is interpolated by spherical linear interpolation (slerp)
//! and the translation linearly — the standard piecewise SE(3) interpolation for odometry at a
//! rate well above the motion's bandwidth. Times outside the samples, or inside a gap longer
//! than the allowed maximum, are errors: extrapolating or bridging a gap would silently warp
//! the cloud.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use omni_formats::odometry::PoseSample;

/// Interpolated trajectory over strictly increasing timestamps (µs).
#[derive(Debug, Clone)]
pub struct Trajectory {
    times: Vec<u64>,
    poses: Vec<Isometry3<f64>>,
    max_gap_us: u64,
}

impl Trajectory {
    /// From samples (sorted, strictly increasing; as [`omni_formats::odometry::read_odometry`]
    /// returns them) and the longest interval (µs) across which interpolation is allowed.
    pub fn new(samples: &[PoseSample], max_gap_us: u64) -> Result<Self, String> {
        if samples.is_empty() {
            return Err("odometry has no pose samples".into());
        }
        for w in samples.windows(2) {
            if w[1].t_us <= w[0].t_us {
                return Err(format!("odometry timestamps not strictly increasing at {} µs", w[1].t_us));
            }
        }
        let poses = samples
            .iter()
            .map(|s| {
                let [w, x, y, z] = s.quaternion_wxyz;
                let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
                Isometry3::from_parts(Translation3::from(Vector3::from(s.translation_mm)), q)
            })
            .collect();
        Ok(Trajectory { times: samples.iter().map(|s| s.t_us).collect(), poses, max_gap_us })
    }

    /// Time span covered (µs).
    pub fn span(&self) -> (u64, u64) {
        (self.times[0], *self.times.last().unwrap_or(&self.times[0]))
    }

    /// Pose (sensor → world) at time `t_us`.
    pub fn pose_at(&self, t_us: u64) -> Result<Isometry3<f64>, String> {
        let (t0, t1) = self.span();
        if t_us < t0 || t_us > t1 {
            return Err(format!("time {t_us} µs is outside the odometry ({t0}..{t1} µs)"));
        }
        let i = self.times.partition_point(|&t| t <= t_us);
        if i == self.times.len() {
            return Ok(self.poses[i - 1]);
        }
        let (ta, tb) = (self.times[i - 1], self.times[i]);
        if tb - ta > self.max_gap_us {
            return Err(format!(
                "time {t_us} µs falls in an odometry gap of {} µs ({ta}..{tb} µs; at most {} µs allowed)",
                tb - ta,
                self.max_gap_us
            ));
        }
        if t_us == ta {
            return Ok(self.poses[i - 1]);
        }
        let s = (t_us - ta) as f64 / (tb - ta) as f64;
        let (a, b) = (&self.poses[i - 1], &self.poses[i]);
        let rot = a.rotation.try_slerp(&b.rotation, s, 1e-12).unwrap_or(a.rotation);
        let tr = a.translation.vector.lerp(&b.translation.vector, s);
        Ok(Isometry3::from_parts(Translation3::from(tr), rot))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_geom::Point3;

    fn sample(t: u64, x: f64, yaw: f64) -> PoseSample {
        let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
        PoseSample { t_us: t, translation_mm: [x, 0.0, 0.0], quaternion_wxyz: [q.w, q.i, q.j, q.k] }
    }

    #[test]
    fn interpolates_constant_velocity_motion_exactly() {
        // Constant translation speed and yaw rate: slerp + lerp reproduce the motion exactly.
        let samples: Vec<_> = (0..5).map(|i| sample(i * 100_000, 10.0 * i as f64, 0.1 * i as f64)).collect();
        let traj = Trajectory::new(&samples, 200_000).unwrap();
        for t in [0u64, 50_000, 123_456, 399_999, 400_000] {
            let pose = traj.pose_at(t).unwrap();
            let s = t as f64 / 100_000.0;
            let expect = Isometry3::from_parts(
                Translation3::new(10.0 * s, 0.0, 0.0),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.1 * s),
            );
            let p = Point3::new(1000.0, -200.0, 50.0);
            assert!((pose * p - expect * p).norm() < 1e-9, "t = {t}");
        }
    }

    #[test]
    fn refuses_gaps_and_times_outside() {
        let samples = vec![sample(0, 0.0, 0.0), sample(100, 1.0, 0.0), sample(10_000, 2.0, 0.0)];
        let traj = Trajectory::new(&samples, 1000).unwrap();
        assert!(traj.pose_at(50).is_ok());
        assert!(traj.pose_at(5000).unwrap_err().contains("gap"));
        assert!(traj.pose_at(10_001).unwrap_err().contains("outside"));
        let unsorted = vec![sample(10, 0.0, 0.0), sample(5, 0.0, 0.0)];
        assert!(Trajectory::new(&unsorted, 1000).is_err());
    }
}
