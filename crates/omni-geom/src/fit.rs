//! Least-squares fits of primitives to 3D points (mm): plane (SVD), sphere and cylinder
//! (algebraic initialisation, then geometric refinement by Levenberg–Marquardt).

use crate::Plane;
use crate::lm::{self, Problem};
use nalgebra::{Matrix3, Point3, Unit, Vector3};

/// Result of a plane fit.
#[derive(Debug, Clone, Copy)]
pub struct PlaneFit {
    pub plane: Plane,
    /// RMS of point-to-plane distances (mm).
    pub rms: f64,
    /// Largest |distance| (mm).
    pub max_abs: f64,
    /// Ratio of the two largest spreads: near 0 means the points are (nearly) collinear.
    pub planarity_ratio: f64,
}

/// Mean of the points (the origin for none).
pub fn centroid(points: &[Point3<f64>]) -> Point3<f64> {
    let n = points.len().max(1) as f64;
    Point3::from(points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n)
}

/// Centroid and scatter matrix of points.
fn centroid_scatter(points: &[Point3<f64>]) -> (Point3<f64>, Matrix3<f64>) {
    let c = centroid(points);
    let mut s = Matrix3::zeros();
    for p in points {
        let d = p - c;
        s += d * d.transpose();
    }
    (c, s)
}

/// Total least-squares plane through ≥ 3 points (normal = smallest eigenvector of the scatter).
/// `None` for fewer than 3 points or non-finite input.
pub fn fit_plane(points: &[Point3<f64>]) -> Option<PlaneFit> {
    if points.len() < 3 || points.iter().any(|p| !p.coords.iter().all(|x| x.is_finite())) {
        return None;
    }
    let (c, s) = centroid_scatter(points);
    let eig = s.symmetric_eigen();
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let normal = eig.eigenvectors.column(idx[0]).into_owned();
    let plane = Plane::from_point_normal(&c, &normal);
    let (rms, max_abs) = distance_stats(points.iter().map(|p| plane.signed_distance(p)));
    let planarity_ratio = (eig.eigenvalues[idx[1]].max(0.0) / eig.eigenvalues[idx[2]].max(1e-300)).sqrt();
    Some(PlaneFit { plane, rms, max_abs, planarity_ratio })
}

fn distance_stats(d: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut ss, mut mx, mut n) = (0.0, 0.0f64, 0usize);
    for x in d {
        ss += x * x;
        mx = mx.max(x.abs());
        n += 1;
    }
    ((ss / n.max(1) as f64).sqrt(), mx)
}

/// Result of a sphere fit.
#[derive(Debug, Clone, Copy)]
pub struct SphereFit {
    pub center: Point3<f64>,
    pub radius: f64,
    /// RMS of |p − c| − r (mm).
    pub rms: f64,
}

struct SphereProblem<'a>(&'a [Point3<f64>]);

impl Problem for SphereProblem<'_> {
    fn num_params(&self) -> usize {
        4
    }
    fn num_residuals(&self) -> usize {
        self.0.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        let c = Vector3::new(p[0], p[1], p[2]);
        for (o, q) in out.iter_mut().zip(self.0) {
            *o = (q.coords - c).norm() - p[3];
        }
    }
    fn jacobian(&self, p: &[f64], jac: &mut nalgebra::DMatrix<f64>) {
        let c = Vector3::new(p[0], p[1], p[2]);
        for (i, q) in self.0.iter().enumerate() {
            let d = q.coords - c;
            let n = d.norm().max(1e-300);
            for k in 0..3 {
                jac[(i, k)] = -d[k] / n;
            }
            jac[(i, 3)] = -1.0;
        }
    }
}

/// Geometric least-squares sphere through ≥ 4 points.
pub fn fit_sphere(points: &[Point3<f64>]) -> Option<SphereFit> {
    if points.len() < 4 {
        return None;
    }
    // Algebraic: |p|² = 2 c·p + k, linear in (c, k).
    let mut a = nalgebra::DMatrix::zeros(points.len(), 4);
    let mut b = nalgebra::DVector::zeros(points.len());
    for (i, p) in points.iter().enumerate() {
        a[(i, 0)] = 2.0 * p.x;
        a[(i, 1)] = 2.0 * p.y;
        a[(i, 2)] = 2.0 * p.z;
        a[(i, 3)] = 1.0;
        b[i] = p.coords.norm_squared();
    }
    let sol = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let c = Vector3::new(sol[0], sol[1], sol[2]);
    let r0 = (sol[3] + c.norm_squared()).max(0.0).sqrt();
    let rep = lm::minimize(&SphereProblem(points), &[c.x, c.y, c.z, r0], &lm::Options::default());
    let p = &rep.params;
    if !p.iter().all(|x| x.is_finite()) {
        return None;
    }
    Some(SphereFit { center: Point3::new(p[0], p[1], p[2]), radius: p[3].abs(), rms: rep.rms })
}

/// Result of a cylinder fit.
#[derive(Debug, Clone, Copy)]
pub struct CylinderFit {
    /// The point of the axis closest to the points' centroid.
    pub axis_point: Point3<f64>,
    pub axis: Unit<Vector3<f64>>,
    pub radius: f64,
    /// RMS of (distance to axis − r) (mm).
    pub rms: f64,
}

/// Two unit vectors completing `a` to an orthonormal basis.
pub fn orthonormal_basis(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if a.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = a.cross(&helper).normalize();
    let v = a.cross(&u).normalize();
    (u, v)
}

/// Coordinates of `points` relative to `origin` in the plane spanned by the unit vectors `u`, `v`
/// (their projection along the third axis).
pub fn project_2d(points: &[Point3<f64>], origin: &Point3<f64>, u: &Vector3<f64>, v: &Vector3<f64>) -> Vec<(f64, f64)> {
    points.iter().map(|p| ((p - origin).dot(u), (p - origin).dot(v))).collect()
}

/// Unit directions covering the upper hemisphere (z ≥ 0, azimuth in [0, π): each axis once up to
/// sign) on `n_el + 1` elevation rings, about 90°/`n_el` apart: the candidates of a coarse search
/// for an axis direction.
pub fn hemisphere_directions(n_el: usize) -> Vec<Vector3<f64>> {
    let mut out = Vec::new();
    for i in 0..=n_el {
        let el = std::f64::consts::FRAC_PI_2 * i as f64 / n_el.max(1) as f64;
        let n_az = ((4.0 * n_el as f64 * el.cos()).ceil() as usize).max(1);
        for j in 0..n_az {
            let az = std::f64::consts::PI * j as f64 / n_az as f64;
            out.push(Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()));
        }
    }
    out
}

/// The axis direction `a0` tilted by `tu`, `tv` along its orthonormal complement `u`, `v`
/// (normalised): the two-parameter axis of the cylinder and cone least-squares problems, free
/// of the sign and pole singularities of angles.
pub fn tilted_axis(a0: &Vector3<f64>, u: &Vector3<f64>, v: &Vector3<f64>, tu: f64, tv: f64) -> Vector3<f64> {
    (a0 + u * tu + v * tv).normalize()
}

/// Kåsa algebraic circle fit in 2D; returns (centre, radius, rms of radial residuals).
pub fn fit_circle_2d(pts: &[(f64, f64)]) -> Option<((f64, f64), f64, f64)> {
    if pts.len() < 3 {
        return None;
    }
    let mut a = nalgebra::DMatrix::zeros(pts.len(), 3);
    let mut b = nalgebra::DVector::zeros(pts.len());
    for (i, &(x, y)) in pts.iter().enumerate() {
        a[(i, 0)] = 2.0 * x;
        a[(i, 1)] = 2.0 * y;
        a[(i, 2)] = 1.0;
        b[i] = x * x + y * y;
    }
    let s = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let r = (s[2] + s[0] * s[0] + s[1] * s[1]).max(0.0).sqrt();
    let rms =
        (pts.iter().map(|&(x, y)| ((x - s[0]).hypot(y - s[1]) - r).powi(2)).sum::<f64>() / pts.len() as f64).sqrt();
    Some(((s[0], s[1]), r, rms))
}

struct CylinderProblem<'a> {
    points: &'a [Point3<f64>],
    /// Reference frame of the parametrisation: origin, axis guess and its orthonormal basis.
    origin: Vector3<f64>,
    a0: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
}

impl CylinderProblem<'_> {
    /// Params: (tilt_u, tilt_v, offset_u, offset_v, radius): axis = normalize(a0 + tu·u + tv·v),
    /// through origin + ou·u + ov·v.
    fn axis(&self, p: &[f64]) -> (Vector3<f64>, Vector3<f64>) {
        let dir = tilted_axis(&self.a0, &self.u, &self.v, p[0], p[1]);
        (self.origin + self.u * p[2] + self.v * p[3], dir)
    }
}

impl Problem for CylinderProblem<'_> {
    fn num_params(&self) -> usize {
        5
    }
    fn num_residuals(&self) -> usize {
        self.points.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        let (c, d) = self.axis(p);
        for (o, q) in out.iter_mut().zip(self.points) {
            let w = q.coords - c;
            *o = (w - d * d.dot(&w)).norm() - p[4];
        }
    }
}

/// Geometric least-squares cylinder. `axis_hint` is an approximate axis direction; without it
/// the direction is found by a coarse search over the hemisphere (circle fits of the points
/// projected along each candidate), which copes with patches seen from one side only.
pub fn fit_cylinder(points: &[Point3<f64>], axis_hint: Option<Vector3<f64>>) -> Option<CylinderFit> {
    if points.len() < 6 {
        return None;
    }
    let a0 = match axis_hint {
        Some(a) if a.norm() > 0.0 => a.normalize(),
        _ => search_cylinder_axis(points)?,
    };
    let (u, v) = orthonormal_basis(&a0);
    let c = centroid(points);
    let ((cu, cv), r0, _) = fit_circle_2d(&project_2d(points, &c, &u, &v))?;
    let problem = CylinderProblem { points, origin: c.coords, a0, u, v };
    let rep = lm::minimize(&problem, &[0.0, 0.0, cu, cv, r0], &lm::Options::default());
    if !rep.params.iter().all(|x| x.is_finite()) {
        return None;
    }
    let (axis_pt, dir) = problem.axis(&rep.params);
    let w = c.coords - axis_pt;
    let foot = axis_pt + dir * dir.dot(&w);
    Some(CylinderFit {
        axis_point: Point3::from(foot),
        axis: Unit::new_normalize(dir),
        radius: rep.params[4].abs(),
        rms: rep.rms,
    })
}

fn search_cylinder_axis(points: &[Point3<f64>]) -> Option<Vector3<f64>> {
    let step = (points.len() / 2000).max(1);
    let sample: Vec<Point3<f64>> = points.iter().step_by(step).copied().collect();
    let c = centroid(&sample);
    let mut best: Option<(f64, Vector3<f64>)> = None;
    for a in hemisphere_directions(20) {
        let (u, v) = orthonormal_basis(&a);
        if let Some((_, _, rms)) = fit_circle_2d(&project_2d(&sample, &c, &u, &v))
            && best.is_none_or(|(b, _)| rms < b)
        {
            best = Some((rms, a));
        }
    }
    best.map(|(_, a)| a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_fit_recovers_plane() {
        let n = Vector3::new(0.2, -0.3, 0.9).normalize();
        let (u, v) = orthonormal_basis(&n);
        let o = Point3::new(10.0, 20.0, -5.0);
        let pts: Vec<_> = (0..50).map(|i| o + u * (i as f64 * 1.7 % 13.0) + v * (i as f64 * 0.37)).collect();
        let f = fit_plane(&pts).unwrap();
        assert!(f.plane.normal.dot(&n).abs() > 1.0 - 1e-12);
        assert!(f.rms < 1e-9);
    }

    #[test]
    fn sphere_fit_recovers_sphere_from_a_cap() {
        let c = Point3::new(500.0, 10.0, -20.0);
        let mut pts = vec![];
        for i in 0..20 {
            for j in 0..20 {
                let th = 2.0 + 0.05 * i as f64;
                let ph = -0.5 + 0.05 * j as f64;
                pts.push(c + Vector3::new(th.cos() * ph.cos(), th.sin() * ph.cos(), ph.sin()) * 50.0);
            }
        }
        let f = fit_sphere(&pts).unwrap();
        assert!((f.radius - 50.0).abs() < 1e-8 && (f.center - c).norm() < 1e-8, "{f:?}");
    }

    #[test]
    fn cylinder_fit_recovers_axis_and_radius_from_a_one_sided_patch() {
        let axis = Vector3::new(0.05, 0.02, 1.0).normalize();
        let (u, v) = orthonormal_basis(&axis);
        let c = Point3::new(500.0, 0.0, 0.0);
        let mut pts = vec![];
        for i in 0..30 {
            for j in 0..20 {
                let th = 2.3 + 0.05 * i as f64; // ~85° of arc, facing one way
                pts.push(c + (u * th.cos() + v * th.sin()) * 50.0 + axis * (j as f64 * 10.0 - 100.0));
            }
        }
        let f = fit_cylinder(&pts, None).unwrap();
        assert!((f.radius - 50.0).abs() < 1e-6, "{f:?}");
        assert!(f.axis.dot(&axis).abs() > 1.0 - 1e-10);
    }
}

/// The rigid transform `T` minimising Σ|T·src_i − dst_i|² (Kabsch/Umeyama without scale) and
/// the RMS of the remaining residuals (mm). `None` for fewer than 3 pairs, mismatched lengths or
/// (near-)collinear points.
pub fn kabsch(src: &[Point3<f64>], dst: &[Point3<f64>]) -> Option<(nalgebra::Isometry3<f64>, f64)> {
    if src.len() != dst.len() || src.len() < 3 {
        return None;
    }
    let n = src.len() as f64;
    let cs = src.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cd = dst.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mut h = Matrix3::zeros();
    for (s, d) in src.iter().zip(dst) {
        h += (s.coords - cs) * (d.coords - cd).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut sv = svd.singular_values;
    sv.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    if sv[1] <= 1e-9 * sv[0].max(1e-300) {
        return None;
    }
    let mut d = Matrix3::identity();
    if (v_t.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = v_t.transpose() * d * u.transpose();
    let rot = nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
    let t = cd - rot * cs;
    let iso = nalgebra::Isometry3::from_parts(nalgebra::Translation3::from(t), rot);
    let rms = (src.iter().zip(dst).map(|(s, d)| (iso * s - d).norm_squared()).sum::<f64>() / n).sqrt();
    Some((iso, rms))
}

#[cfg(test)]
mod kabsch_tests {
    use super::*;

    #[test]
    fn kabsch_recovers_a_rigid_motion() {
        let rot = nalgebra::UnitQuaternion::from_euler_angles(0.1, -0.3, 1.2);
        let iso = nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(5.0, -80.0, 3.0), rot);
        let src: Vec<_> =
            (0..20).map(|i| Point3::new(i as f64 * 3.0, (i * i % 7) as f64, (i % 3) as f64 * 10.0)).collect();
        let dst: Vec<_> = src.iter().map(|p| iso * p).collect();
        let (fit, rms) = kabsch(&src, &dst).unwrap();
        assert!(rms < 1e-9);
        assert!((fit.translation.vector - iso.translation.vector).norm() < 1e-9);
        assert!(fit.rotation.angle_to(&rot) < 1e-12);
    }
}
