use nalgebra::{Point3, Unit, Vector3};

/// An oriented plane `normal · x = offset` (normal is unit length, offset in mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub normal: Unit<Vector3<f64>>,
    pub offset: f64,
}

impl Plane {
    /// The plane through `point` with the given normal (need not be unit length).
    pub fn from_point_normal(point: &Point3<f64>, normal: &Vector3<f64>) -> Self {
        let normal = Unit::new_normalize(*normal);
        Plane { normal, offset: normal.dot(&point.coords) }
    }

    /// From `normal · x = offset` with an arbitrary-length normal; `None` if the normal is ~zero.
    pub fn from_normal_offset(normal: &Vector3<f64>, offset: f64) -> Option<Self> {
        let n = normal.norm();
        if !(n > 1e-300) || !offset.is_finite() {
            return None;
        }
        Some(Plane { normal: Unit::new_unchecked(normal / n), offset: offset / n })
    }

    /// Signed distance (mm), positive on the side the normal points to.
    pub fn signed_distance(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&p.coords) - self.offset
    }

    /// Orthogonal projection of `p` onto the plane.
    pub fn project(&self, p: &Point3<f64>) -> Point3<f64> {
        p - self.normal.into_inner() * self.signed_distance(p)
    }

    /// Mirror image of a point in this plane.
    pub fn reflect_point(&self, p: &Point3<f64>) -> Point3<f64> {
        p - self.normal.into_inner() * (2.0 * self.signed_distance(p))
    }

    /// Mirror image of a direction (free vector) in this plane.
    pub fn reflect_vector(&self, v: &Vector3<f64>) -> Vector3<f64> {
        v - self.normal.into_inner() * (2.0 * self.normal.dot(v))
    }

    /// Mirror image of another plane in this plane: reflection is an isometry, so a plane maps
    /// to a plane (the light plane of a facet is the laser's fan plane mirrored in the facet).
    pub fn reflect_plane(&self, other: &Plane) -> Plane {
        let n = self.reflect_vector(&other.normal);
        let p = self.reflect_point(&Point3::from(other.normal.into_inner() * other.offset));
        Plane::from_point_normal(&p, &n)
    }

    /// The same plane with the opposite orientation.
    pub fn flipped(&self) -> Plane {
        Plane { normal: -self.normal, offset: -self.offset }
    }

    /// A point on the plane (the foot of the perpendicular from the origin).
    pub fn point(&self) -> Point3<f64> {
        Point3::from(self.normal.into_inner() * self.offset)
    }

    /// Angle (radians, 0..π/2) between the two planes' normals, ignoring orientation.
    pub fn angle_to(&self, other: &Plane) -> f64 {
        self.normal.dot(&other.normal).abs().min(1.0).acos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_plane_maps_points_on_plane_to_points_on_image() {
        let mirror = Plane::from_point_normal(&Point3::new(1.0, 2.0, 3.0), &Vector3::new(0.3, -0.5, 0.8));
        let p = Plane::from_point_normal(&Point3::new(-4.0, 0.5, 2.0), &Vector3::new(1.0, 0.2, -0.1));
        let img = mirror.reflect_plane(&p);
        let e1 = p.normal.cross(&Vector3::x()).normalize();
        let e2 = p.normal.cross(&e1);
        for (s, t) in [(0.0, 0.0), (10.0, -3.0), (-7.5, 22.0)] {
            let q = p.point() + e1 * s + e2 * t;
            assert!(p.signed_distance(&q).abs() < 1e-12);
            assert!(img.signed_distance(&mirror.reflect_point(&q)).abs() < 1e-12);
        }
    }
}
