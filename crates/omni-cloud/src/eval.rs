//! Accuracy against ground truth: signed distances from measured points to a scene's true
//! surfaces (`scene.json`), per object, with fitted size and centre errors.
//!
//! Each point is assigned to the object whose surface is nearest to it. Signed distance is
//! positive outside the solid (for a rectangle or checkerboard: on the side its `normal` looks
//! to; for a room: inside the room, where the sensor is), so a positive mean error means the
//! surface was measured too far out / towards the sensor.
//!
//! Exactness: sphere, rectangle, checkerboard, box and room distances are exact; cylinder and
//! cone distances are exact near their curved surfaces and caps (the min/max combination is
//! approximate only within a few mm of a rim); the pyramid uses the largest face-plane distance
//! (exact next to a face).

use crate::fit::{ErrorStats, FitOptions, Measured, Shape as FitShape, ShapeKind, fit_and_measure};
use nalgebra::{Point3, Rotation3, Unit, Vector3};
use omni_formats::scene::{SceneFile, SceneObject, Shape};

/// Signed distance (mm) from `p` to one scene object's surface (module docs for the sign).
pub fn object_distance(shape: &Shape, p: &Point3<f64>) -> f64 {
    match shape {
        Shape::Sphere { centre_mm, radius_mm } => (p - Point3::from(*centre_mm)).norm() - radius_mm,
        Shape::Rectangle { centre_mm, normal, up, width_mm, height_mm } => {
            rectangle_distance(p, centre_mm, normal, up, *width_mm, *height_mm)
        }
        Shape::Checkerboard { centre_mm, normal, up, square_mm, inner_cols, inner_rows, margin_mm, .. } => {
            let w = (*inner_cols as f64 + 1.0) * square_mm + 2.0 * margin_mm;
            let h = (*inner_rows as f64 + 1.0) * square_mm + 2.0 * margin_mm;
            rectangle_distance(p, centre_mm, normal, up, w, h)
        }
        Shape::Box { centre_mm, size_mm, rotation_deg } => {
            let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), rotation_deg[2].to_radians())
                * Rotation3::from_axis_angle(&Vector3::y_axis(), rotation_deg[1].to_radians())
                * Rotation3::from_axis_angle(&Vector3::x_axis(), rotation_deg[0].to_radians());
            let local = rot.inverse() * (p - Point3::from(*centre_mm));
            box_sdf(&local, &(Vector3::from(*size_mm) * 0.5))
        }
        Shape::Room { centre_mm, size_mm } => {
            -box_sdf(&(p - Point3::from(*centre_mm)), &(Vector3::from(*size_mm) * 0.5))
        }
        Shape::Cylinder { base_mm, axis, radius_mm, height_mm } => {
            let a = Vector3::from(*axis).normalize();
            let w = p - Point3::from(*base_mm);
            let h = w.dot(&a);
            let radial = (w - a * h).norm() - radius_mm;
            let axial = (h - height_mm * 0.5).abs() - height_mm * 0.5;
            capped_sdf(radial, axial)
        }
        Shape::Cone { apex_mm, axis, radius_mm, height_mm } => {
            let a = Vector3::from(*axis).normalize();
            let half_angle = (radius_mm / height_mm).atan();
            let apex = Point3::from(*apex_mm);
            let lateral = FitShape::Cone { apex, axis: Unit::new_unchecked(a), half_angle }.signed_distance(p);
            let base = (p - apex).dot(&a) - height_mm;
            lateral.max(base)
        }
        Shape::Pyramid { vertices_mm } => {
            let v: Vec<Point3<f64>> = vertices_mm.iter().map(|x| Point3::from(*x)).collect();
            let centroid = Point3::from(v.iter().fold(Vector3::zeros(), |s, x| s + x.coords) / 4.0);
            let faces = [[0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3]];
            faces
                .iter()
                .map(|f| {
                    let mut n = (v[f[1]] - v[f[0]]).cross(&(v[f[2]] - v[f[0]])).normalize();
                    if n.dot(&(centroid - v[f[0]])) > 0.0 {
                        n = -n;
                    }
                    n.dot(&(p - v[f[0]]))
                })
                .fold(f64::NEG_INFINITY, f64::max)
        }
    }
}

/// Exact SDF of a cylinder-like solid from its radial and axial overshoots.
fn capped_sdf(radial: f64, axial: f64) -> f64 {
    if radial > 0.0 && axial > 0.0 { radial.hypot(axial) } else { radial.max(axial) }
}

/// Exact SDF of an axis-aligned box of half extents `half` centred at the origin.
fn box_sdf(p: &Vector3<f64>, half: &Vector3<f64>) -> f64 {
    let q = p.abs() - half;
    let outside = q.map(|x| x.max(0.0)).norm();
    outside + q.max().min(0.0)
}

/// Distance to a finite two-sided rectangle, signed by the side its normal looks to.
fn rectangle_distance(p: &Point3<f64>, centre: &[f64; 3], normal: &[f64; 3], up: &[f64; 3], w: f64, h: f64) -> f64 {
    let n = Vector3::from(*normal).normalize();
    let up = Vector3::from(*up);
    let y = (up - n * n.dot(&up)).normalize();
    let x = y.cross(&n);
    let d = p - Point3::from(*centre);
    let (u, v, z) = (d.dot(&x), d.dot(&y), d.dot(&n));
    let du = (u.abs() - 0.5 * w).max(0.0);
    let dv = (v.abs() - 0.5 * h).max(0.0);
    let dist = (du * du + dv * dv + z * z).sqrt();
    if z < 0.0 { -dist } else { dist }
}

/// What was measured for one scene object.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ObjectReport {
    pub name: String,
    pub kind: String,
    /// Signed errors of the points assigned to the object.
    pub errors: ErrorStats,
    /// Fitted radius − true radius (mm), spheres and cylinders, and its standard error (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius_error_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius_error_se_mm: Option<f64>,
    /// Distance between fitted and true sphere centre (mm), and its standard error (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub centre_error_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub centre_error_se_mm: Option<f64>,
}

/// A cloud compared with its scene.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// The objects that points were assigned to, in the scene's order.
    pub objects: Vec<ObjectReport>,
    /// The scene's objects no point was assigned to (by name): nothing of them was measured.
    pub unmeasured: Vec<String>,
    /// Points farther than the distance limit from every surface.
    pub stray: usize,
}

fn object_name(i: usize, o: &SceneObject) -> String {
    o.name.clone().unwrap_or_else(|| format!("object {i}"))
}

/// Blocks of the delete-a-block jackknife that gives the fitted radius's and centre's standard
/// errors: neighbouring points (the cloud's order) share a stripe and its errors, so a block is
/// every [`JACKKNIFE_BLOCKS`]-th point, each block spread over the whole object.
pub const JACKKNIFE_BLOCKS: usize = 10;

/// A fitted shape's size and place against nominal ones (mm), each with its jackknife standard
/// error (mm) where the leave-outs allow one.
#[derive(Debug, Clone, Copy, Default)]
pub struct ShapeErrors {
    /// Fitted − nominal radius.
    pub radius: Option<(f64, Option<f64>)>,
    /// Distance of a fitted sphere's centre from the nominal one.
    pub centre: Option<(f64, Option<f64>)>,
}

/// [`fit_and_measure`] of `kind` on `points`, and its errors against the nominal `radius` and,
/// for a sphere, `centre`, with standard errors from the same fit without each of
/// [`JACKKNIFE_BLOCKS`] interleaved blocks of the points (skipped when neither is given).
pub fn fit_with_errors(
    kind: ShapeKind,
    points: &[Point3<f64>],
    opts: &FitOptions,
    radius: Option<f64>,
    centre: Option<Point3<f64>>,
) -> Result<(Measured, ShapeErrors), String> {
    let errors_of = |shape: &FitShape| {
        let radius_error = radius.zip(shape.radius()).map(|(nominal, r)| r - nominal);
        let centre_error = match (centre, shape) {
            (Some(c), FitShape::Sphere { center, .. }) => Some((center - c).norm()),
            _ => None,
        };
        (radius_error, centre_error)
    };
    let measured = fit_and_measure(kind, points, opts)?;
    let (radius_error, centre_error) = errors_of(&measured.shape);
    if radius_error.is_none() && centre_error.is_none() {
        return Ok((measured, ShapeErrors::default()));
    }
    let leave_outs: Vec<(Option<f64>, Option<f64>)> = (0..JACKKNIFE_BLOCKS)
        .filter_map(|b| {
            let kept: Vec<Point3<f64>> =
                points.iter().enumerate().filter(|(k, _)| k % JACKKNIFE_BLOCKS != b).map(|(_, p)| *p).collect();
            fit_and_measure(kind, &kept, opts).ok()
        })
        .map(|f| errors_of(&f.shape))
        .collect();
    let sigma = |values: Vec<f64>| omni_geom::stats::jackknife_sigma(&values);
    let errors = ShapeErrors {
        radius: radius_error.map(|e| (e, sigma(leave_outs.iter().filter_map(|l| l.0).collect()))),
        centre: centre_error.map(|e| (e, sigma(leave_outs.iter().filter_map(|l| l.1).collect()))),
    };
    Ok((measured, errors))
}

/// Compares points with the scene. Points farther than `max_distance_mm` from every surface
/// are not assigned (stray points). Spheres with at least 10 points and cylinders with at least
/// 30 get their radius (and a sphere its centre) fitted, with standard errors
/// ([`fit_with_errors`]).
pub fn compare_with_scene(
    scene: &SceneFile,
    points: &[Point3<f64>],
    max_distance_mm: f64,
    fit: &FitOptions,
) -> Result<Comparison, String> {
    if scene.objects.is_empty() {
        return Err("the scene has no objects".into());
    }
    let mut per_object: Vec<(Vec<f64>, Vec<Point3<f64>>)> = vec![(Vec::new(), Vec::new()); scene.objects.len()];
    let mut stray = 0;
    for p in points {
        let (best, d) = scene
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| (i, object_distance(&o.shape, p)))
            .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .unwrap_or((0, f64::INFINITY));
        if d.abs() <= max_distance_mm {
            per_object[best].0.push(d);
            per_object[best].1.push(*p);
        } else {
            stray += 1;
        }
    }
    let mut out = Comparison { objects: Vec::new(), unmeasured: Vec::new(), stray };
    for (i, (o, (errs, pts))) in scene.objects.iter().zip(per_object).enumerate() {
        let Some(errors) = ErrorStats::from_errors(&errs) else {
            out.unmeasured.push(object_name(i, o));
            continue;
        };
        let fitted = match &o.shape {
            Shape::Sphere { centre_mm, radius_mm } if pts.len() >= 10 => {
                fit_with_errors(ShapeKind::Sphere, &pts, fit, Some(*radius_mm), Some(Point3::from(*centre_mm))).ok()
            }
            Shape::Cylinder { radius_mm, .. } if pts.len() >= 30 => {
                fit_with_errors(ShapeKind::Cylinder, &pts, fit, Some(*radius_mm), None).ok()
            }
            _ => None,
        };
        let e = fitted.map(|(_, e)| e).unwrap_or_default();
        out.objects.push(ObjectReport {
            name: object_name(i, o),
            kind: o.shape.kind().into(),
            errors,
            radius_error_mm: e.radius.map(|r| r.0),
            radius_error_se_mm: e.radius.and_then(|r| r.1),
            centre_error_mm: e.centre.map(|c| c.0),
            centre_error_se_mm: e.centre.and_then(|c| c.1),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_of_points_on_and_off_each_surface() {
        let s = Shape::Sphere { centre_mm: [500.0, 0.0, 0.0], radius_mm: 50.0 };
        assert!((object_distance(&s, &Point3::new(447.0, 0.0, 0.0)) - 3.0).abs() < 1e-12);
        let r = Shape::Rectangle {
            centre_mm: [500.0, 0.0, 0.0],
            normal: [-1.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            width_mm: 400.0,
            height_mm: 300.0,
        };
        assert!((object_distance(&r, &Point3::new(498.0, 150.0, 100.0)) - 2.0).abs() < 1e-12);
        assert!((object_distance(&r, &Point3::new(501.0, 0.0, 0.0)) + 1.0).abs() < 1e-12);
        assert!((object_distance(&r, &Point3::new(500.0, 203.0, 154.0)) - 5.0).abs() < 1e-12);
        let c =
            Shape::Cylinder { base_mm: [500.0, 0.0, -100.0], axis: [0.0, 0.0, 1.0], radius_mm: 50.0, height_mm: 200.0 };
        assert!((object_distance(&c, &Point3::new(448.0, 0.0, 30.0)) - 2.0).abs() < 1e-12);
        assert!((object_distance(&c, &Point3::new(500.0, 0.0, 103.0)) - 3.0).abs() < 1e-12);
        assert!((object_distance(&c, &Point3::new(500.0, 0.0, 0.0)) + 50.0).abs() < 1e-12);
        let k = Shape::Cone { apex_mm: [0.0, 0.0, 100.0], axis: [0.0, 0.0, -1.0], radius_mm: 100.0, height_mm: 100.0 };
        // 45° cone: the point (60, 0, 50) is 10/√2 outside the surface r = 100 − z.
        assert!((object_distance(&k, &Point3::new(60.0, 0.0, 50.0)) - 10.0 / 2f64.sqrt()).abs() < 1e-12);
        let room = Shape::Room { centre_mm: [0.0; 3], size_mm: [2000.0, 2000.0, 2000.0] };
        assert!((object_distance(&room, &Point3::new(990.0, 0.0, 0.0)) - 10.0).abs() < 1e-12);
        let b = Shape::Box { centre_mm: [0.0; 3], size_mm: [10.0, 20.0, 30.0], rotation_deg: [0.0, 0.0, 90.0] };
        // Rotated 90° about z: its 20 mm side now lies along x.
        assert!((object_distance(&b, &Point3::new(12.0, 0.0, 0.0)) - 2.0).abs() < 1e-9);
        let py =
            Shape::Pyramid { vertices_mm: [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]] };
        assert!((object_distance(&py, &Point3::new(2.0, 2.0, -1.5)) - 1.5).abs() < 1e-12);
    }
}
