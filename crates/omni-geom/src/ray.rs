use crate::Plane;
use nalgebra::{Point3, Unit, Vector3};

/// A half-line `origin + t·dir`, t ≥ 0 (mm; `dir` is unit length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: Point3<f64>,
    pub dir: Unit<Vector3<f64>>,
}

impl Ray {
    /// A ray from `origin` along `dir` (normalised here).
    pub fn new(origin: Point3<f64>, dir: Vector3<f64>) -> Self {
        Ray { origin, dir: Unit::new_normalize(dir) }
    }

    /// The point at distance `t` (mm) along the ray.
    pub fn at(&self, t: f64) -> Point3<f64> {
        self.origin + self.dir.into_inner() * t
    }

    /// Distance (mm) from `p` to the ray's supporting line.
    pub fn distance_to_line(&self, p: &Point3<f64>) -> f64 {
        let d = p - self.origin;
        (d - self.dir.into_inner() * self.dir.dot(&d)).norm()
    }
}

/// Why a ray does not give a usable intersection with a plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IntersectError {
    /// The ray meets the plane at a grazing angle: |cos(ray, normal)| below the threshold,
    /// where a tiny pixel error becomes a huge range error.
    Grazing { cos_incidence: f64 },
    /// The plane is behind the ray's origin (t ≤ 0).
    Behind { t: f64 },
}

impl std::fmt::Display for IntersectError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            IntersectError::Grazing { cos_incidence } => {
                write!(f, "grazing intersection (|cos| = {cos_incidence:.2e})")
            }
            IntersectError::Behind { t } => write!(f, "plane behind the viewpoint (t = {t:.3} mm)"),
        }
    }
}

impl std::error::Error for IntersectError {}

/// A successful ray–plane intersection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intersection {
    /// Distance along the ray (mm).
    pub t: f64,
    pub point: Point3<f64>,
    /// |cos| of the angle between the ray and the plane normal (1 = head-on, 0 = grazing).
    pub cos_incidence: f64,
}

/// Intersects `ray` with `plane`, refusing grazing rays (`|cos(dir, normal)| < min_cos`) and
/// planes behind the origin.
pub fn intersect_ray_plane(ray: &Ray, plane: &Plane, min_cos: f64) -> Result<Intersection, IntersectError> {
    let denom = plane.normal.dot(&ray.dir);
    let cos_incidence = denom.abs();
    if !(cos_incidence >= min_cos) || cos_incidence == 0.0 {
        return Err(IntersectError::Grazing { cos_incidence });
    }
    let t = -plane.signed_distance(&ray.origin) / denom;
    if !(t > 0.0) {
        return Err(IntersectError::Behind { t });
    }
    Ok(Intersection { t, point: ray.at(t), cos_incidence })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_grazing_and_behind() {
        let plane = Plane::from_point_normal(&Point3::new(0.0, 0.0, 5.0), &Vector3::z());
        let grazing = Ray::new(Point3::origin(), Vector3::new(1.0, 0.0, 1e-4));
        assert!(matches!(intersect_ray_plane(&grazing, &plane, 0.01), Err(IntersectError::Grazing { .. })));
        let behind = Ray::new(Point3::origin(), -Vector3::z());
        assert!(matches!(intersect_ray_plane(&behind, &plane, 0.01), Err(IntersectError::Behind { .. })));
    }
}
