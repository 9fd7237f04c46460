//! Pure geometry for omniscan: rays, planes, ray–plane triangulation and least-squares fits
//! (plane, sphere, cylinder, cone), a small Levenberg–Marquardt solver, the roots of real
//! polynomials and the project's deterministic random generator ([`rng::SplitMix64`]).
//!
//! No I/O lives here. Lengths are millimetres, angles radians.
//!
//! ```
//! use omni_geom::{Plane, Ray, Point3, Vector3, intersect_ray_plane};
//! let plane = Plane::from_point_normal(&Point3::new(0.0, 0.0, 10.0), &Vector3::z());
//! let ray = Ray::new(Point3::origin(), Vector3::new(0.0, 0.0, 1.0));
//! let hit = intersect_ray_plane(&ray, &plane, 0.01).unwrap();
//! assert!((hit.point.z - 10.0).abs() < 1e-12);
//! ```

pub mod fit;
pub mod lm;
mod plane;
pub mod poly;
mod ray;
pub mod rng;
pub mod robust_plane;
pub mod stats;

pub use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Unit, UnitQuaternion, Vector2, Vector3};
pub use plane::Plane;
pub use ray::{IntersectError, Intersection, Ray, intersect_ray_plane};

/// The error function (Abramowitz & Stegun 7.1.26, |error| < 1.5e-7).
pub fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly =
        t * (0.254_829_592 + t * (-0.284_496_736 + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let y = 1.0 - poly * (-x * x).exp();
    if x >= 0.0 { y } else { -y }
}

/// Rotates `v` about the unit axis `axis` by `angle` (radians, right-hand rule).
pub fn rotate_about(axis: &Unit<Vector3<f64>>, angle: f64, v: &Vector3<f64>) -> Vector3<f64> {
    Rotation3::from_axis_angle(axis, angle) * v
}

/// Degrees → radians.
pub fn deg(d: f64) -> f64 {
    d.to_radians()
}
