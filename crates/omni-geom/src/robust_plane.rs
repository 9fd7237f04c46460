//! A plane fitted robustly to 3-D points (mm) with false points among them: least median of
//! squares from random triples (deterministic seed), Tukey-biweight reweighting, then total least
//! squares on the inliers, with the fit's covariance.

use crate::Plane;
use crate::fit::{fit_plane, orthonormal_basis};
use crate::rng::SplitMix64;
use nalgebra::{Matrix3, Point3, Vector3};

/// Tukey's biweight constant (95 % efficiency under Gaussian noise), in units of the robust σ.
pub const TUKEY_C: f64 = 4.685;
/// Random triples tried for the least-median start.
const TRIPLES: usize = 400;
/// Points the least-median score is taken over (an even subsample of larger sets).
const SCORE_POINTS: usize = 4000;

/// A robust plane fit.
#[derive(Debug, Clone)]
pub struct RobustPlaneFit {
    /// The plane, total least squares on the inliers; its normal is the smallest-spread
    /// direction, sign as the scatter's eigenvector gives it (callers orient it).
    pub plane: Plane,
    /// Whether each point is an inlier: |distance| < [`TUKEY_C`] × the robust σ.
    pub inliers: Vec<bool>,
    /// The robust σ (mm): 1.4826 × the median |distance| of the reweighted plane.
    pub robust_sigma: f64,
    /// RMS of the inliers' distances (mm).
    pub rms: f64,
    /// Covariance of (a, b, c), the plane's small changes n → n + a·e1 + b·e2 (rad) and
    /// offset → offset + c (mm), with (e1, e2) = [`RobustPlaneFit::basis`], from the inliers'
    /// residuals taken as independent (σ² (JᵀJ)⁻¹, σ² = Σr² / (n − 3)).
    pub covariance: Matrix3<f64>,
    /// The tangent directions of the covariance's a and b.
    pub basis: (Vector3<f64>, Vector3<f64>),
}

impl RobustPlaneFit {
    /// σ of the normal's direction (rad): √(var a + var b).
    pub fn normal_sigma(&self) -> f64 {
        (self.covariance[(0, 0)] + self.covariance[(1, 1)]).max(0.0).sqrt()
    }

    /// σ (mm) of the plane's position along its normal at `p`.
    pub fn sigma_at(&self, p: &Point3<f64>) -> f64 {
        let j = Vector3::new(self.basis.0.dot(&p.coords), self.basis.1.dot(&p.coords), -1.0);
        (j.transpose() * self.covariance * j)[(0, 0)].max(0.0).sqrt()
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// The robust plane through `points` (at least 3, not all collinear); `seed` fixes the random
/// triples. `None` if no plane fits (too few points, collinear, non-finite).
pub fn fit_plane_robust(points: &[Point3<f64>], seed: u64) -> Option<RobustPlaneFit> {
    fit_plane_robust_grouped(points, &vec![0; points.len()], seed)
}

/// [`fit_plane_robust`] for points that come in groups (`group[i]` is point i's, e.g. the
/// frame it was measured in), each of which may lie on a line of the plane: a candidate plane
/// is scored by the median over the groups of each group's median distance, so that a plane
/// through one group's line alone, however many points that group holds, scores as badly as
/// its distance from the other groups. With one group this is [`fit_plane_robust`].
pub fn fit_plane_robust_grouped(points: &[Point3<f64>], group: &[usize], seed: u64) -> Option<RobustPlaneFit> {
    let n = points.len();
    assert_eq!(group.len(), n, "one group per point");
    if n < 3 || points.iter().any(|p| !p.coords.iter().all(|x| x.is_finite())) {
        return None;
    }
    let step = n.div_ceil(SCORE_POINTS).max(1);
    let groups = group.iter().max().map_or(0, |g| g + 1);
    let mut sample: Vec<Vec<&Point3<f64>>> = vec![Vec::new(); groups];
    for (p, g) in points.iter().zip(group).step_by(step) {
        sample[*g].push(p);
    }
    sample.retain(|s| !s.is_empty());
    let score = |pl: &Plane| {
        let per_group = sample.iter().map(|s| median(s.iter().map(|p| pl.signed_distance(p).abs()).collect()));
        median(per_group.collect())
    };
    let mut best: Option<(f64, Plane)> = fit_plane(points).map(|f| (score(&f.plane), f.plane));
    let mut rng = SplitMix64::new(seed);
    for _ in 0..TRIPLES {
        let (a, b, c) = (points[rng.below(n)], points[rng.below(n)], points[rng.below(n)]);
        let normal = (b - a).cross(&(c - a));
        if normal.norm() < 1e-9 * (b - a).norm().max(1e-300) * (c - a).norm().max(1e-300) {
            continue;
        }
        let pl = Plane::from_point_normal(&a, &normal);
        let s = score(&pl);
        if best.as_ref().is_none_or(|(bs, _)| s < *bs) {
            best = Some((s, pl));
        }
    }
    let (_, mut plane) = best?;
    // Tukey reweighting (weighted total least squares), σ from the median absolute distance.
    let mut sigma = 0.0;
    for _ in 0..30 {
        let r: Vec<f64> = points.iter().map(|p| plane.signed_distance(p)).collect();
        sigma = 1.4826 * median(r.iter().map(|x| x.abs()).collect());
        if !(sigma > 0.0) {
            break;
        }
        let c = TUKEY_C * sigma;
        let w: Vec<f64> = r.iter().map(|x| if x.abs() < c { (1.0 - (x / c).powi(2)).powi(2) } else { 0.0 }).collect();
        let next = weighted_plane(points, &w)?;
        let moved = (next.normal.into_inner() - plane.normal.into_inner() * next.normal.dot(&plane.normal).signum())
            .norm()
            + (next.offset - plane.offset * next.normal.dot(&plane.normal).signum()).abs() / 1e3;
        plane = next;
        if moved < 1e-12 {
            break;
        }
    }
    let cut = TUKEY_C * sigma;
    let inliers: Vec<bool> = points.iter().map(|p| plane.signed_distance(p).abs() <= cut).collect();
    let kept: Vec<Point3<f64>> = points.iter().zip(&inliers).filter(|(_, k)| **k).map(|(p, _)| *p).collect();
    let final_fit = fit_plane(&kept)?;
    let plane = final_fit.plane;
    let basis = orthonormal_basis(&plane.normal);
    let mut jtj = Matrix3::zeros();
    let mut ss = 0.0;
    for p in &kept {
        let j = Vector3::new(basis.0.dot(&p.coords), basis.1.dot(&p.coords), -1.0);
        jtj += j * j.transpose();
        ss += plane.signed_distance(p).powi(2);
    }
    let dof = (kept.len() as f64 - 3.0).max(1.0);
    let covariance = jtj.try_inverse()? * (ss / dof);
    Some(RobustPlaneFit { plane, inliers, robust_sigma: sigma, rms: final_fit.rms, covariance, basis })
}

/// Weighted total least squares plane (weights ≥ 0); `None` if the weights vanish.
pub fn weighted_plane(points: &[Point3<f64>], weights: &[f64]) -> Option<Plane> {
    let sw: f64 = weights.iter().sum();
    if !(sw > 0.0) {
        return None;
    }
    let c = points.iter().zip(weights).fold(Vector3::zeros(), |a, (p, w)| a + p.coords * *w) / sw;
    let mut s = Matrix3::zeros();
    for (p, w) in points.iter().zip(weights) {
        let d = p.coords - c;
        s += d * d.transpose() * *w;
    }
    let eig = s.symmetric_eigen();
    let i = (0..3).min_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]))?;
    Some(Plane::from_point_normal(&Point3::from(c), &eig.eigenvectors.column(i).into_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_lines_of_a_plane_give_the_plane_when_one_holds_most_points() {
        // Two stripes of one plane, each measured on its own board: 0.02 mm of noise across
        // the line within the board's plane, so that each stripe's points lie exactly in that
        // plane. The first holds 70 % of the points: its board's plane has median distance 0.
        let mut rng = SplitMix64::new(3);
        let truth = Plane::from_point_normal(&Point3::new(0.0, 0.0, 50.0), &Vector3::new(0.1, 0.9, -0.4));
        let (e1, e2) = orthonormal_basis(&truth.normal);
        let base = Point3::from(truth.normal.into_inner() * truth.offset);
        let mut pts = Vec::new();
        let mut group = Vec::new();
        for (k, (count, along, at)) in [(700, e1, 0.0), (300, e1 + e2 * 0.3, 40.0)].into_iter().enumerate() {
            let across = (truth.normal.into_inner() + e2).normalize();
            for _ in 0..count {
                let noise = across * (0.02 * rng.normal());
                pts.push(base + e2 * at + along * (rng.uniform() * 100.0 - 50.0) + noise);
                group.push(k);
            }
        }
        let fit = fit_plane_robust_grouped(&pts, &group, 1).unwrap();
        let sign = fit.plane.normal.dot(&truth.normal).signum();
        let angle = (fit.plane.normal.into_inner() * sign).angle(&truth.normal).to_degrees();
        assert!(angle < 0.05, "normal off by {angle}°");
        assert!(fit.inliers.iter().filter(|k| **k).count() > 950);
    }

    #[test]
    fn finds_the_plane_through_a_third_of_outliers() {
        let mut rng = SplitMix64::new(7);
        let truth = Plane::from_point_normal(&Point3::new(0.0, 0.0, 300.0), &Vector3::new(0.2, -0.1, 1.0));
        let (e1, e2) = orthonormal_basis(&truth.normal);
        let mut pts = Vec::new();
        for i in 0..3000 {
            let q = Point3::from(truth.normal.into_inner() * truth.offset)
                + e1 * (rng.uniform() * 200.0 - 100.0)
                + e2 * (rng.uniform() * 200.0 - 100.0);
            let off = if i % 3 == 0 { rng.uniform() * 40.0 - 20.0 } else { 0.05 * rng.normal() };
            pts.push(q + truth.normal.into_inner() * off);
        }
        let fit = fit_plane_robust(&pts, 1).unwrap();
        let sign = fit.plane.normal.dot(&truth.normal).signum();
        let angle = (fit.plane.normal.into_inner() * sign).angle(&truth.normal);
        assert!(angle.to_degrees() < 0.01, "normal off by {}°", angle.to_degrees());
        assert!((fit.plane.offset * sign - truth.offset).abs() < 0.05, "{}", fit.plane.offset);
        assert!((fit.rms - 0.05).abs() < 0.01, "rms {}", fit.rms);
        // The stated σ of the normal matches the scatter of the inliers' fit (200 mm square,
        // 0.05 mm noise, 2000 points: σ ≈ 0.05 / (57.7 · √2000) rad).
        let expect = (2.0f64).sqrt() * 0.05 / (200.0 / 12f64.sqrt() * 2000f64.sqrt());
        assert!((fit.normal_sigma() / expect - 1.0).abs() < 0.2, "{} vs {expect}", fit.normal_sigma());
    }
}
