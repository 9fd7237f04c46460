//! Surface normals: the least-squares plane through each point's k nearest neighbours (the
//! eigenvector of their covariance with the smallest eigenvalue, as PCL's and Open3D's normal
//! estimation), flipped to face the viewpoint (the sensor), so that shading and meshing know
//! which side was seen. The viewpoint is one point for the whole cloud or one per point (a
//! moving sensor: where it was when it measured that point).

use crate::kdtree::KdTree;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use omni_formats::ply::{PointCloud, ScalarField};
use rayon::prelude::*;

/// The scalar fields normals are stored in (PLY's names; PCD and ROS call them `normal_x` …).
pub const NORMAL_FIELDS: [&str; 3] = ["nx", "ny", "nz"];

/// Where the sensor was when it measured the points (mm, the cloud's frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Viewpoints<'a> {
    /// One viewpoint for every point (a sensor that did not move, or the sensor frame).
    Fixed([f64; 3]),
    /// One viewpoint per point, in the cloud's order.
    PerPoint(&'a [[f64; 3]]),
}

impl Viewpoints<'_> {
    fn of(&self, i: usize) -> Vector3<f64> {
        match self {
            Viewpoints::Fixed(v) => Vector3::from(*v),
            Viewpoints::PerPoint(v) => Vector3::from(v[i]),
        }
    }
}

/// How thin a neighbourhood may be, across against along (the square root of its covariance's
/// middle eigenvalue over its largest), and still be taken for a patch of surface: thinner, it is
/// points along one curve (one stripe of one frame), whose noise alone would set the surface's
/// tilt about the curve. Adjacent slices of a scan give 0.3 or more.
pub const LINE_WIDTH_RATIO: f64 = 0.1;

/// Normals and how many of them came from a neighbourhood along a line.
#[derive(Debug, Clone, PartialEq)]
pub struct Normals {
    /// Unit normals (the cloud's order).
    pub normals: Vec<[f64; 3]>,
    /// Points whose neighbours lie along a line ([`LINE_WIDTH_RATIO`]): their normals are
    /// perpendicular to it and as near the viewpoint's direction as that allows, the surface's
    /// tilt about the line unmeasured.
    pub along_a_line: usize,
}

/// Unit normals of `points` (mm) from their `k` nearest neighbours (the point itself counted),
/// oriented so that `normal · (viewpoint − point) ≥ 0`. A point with fewer than 3 neighbours
/// gets the unit vector towards the viewpoint; one whose neighbours lie along a line, the
/// direction perpendicular to the line nearest to that.
pub fn estimate_normals(points: &[[f64; 3]], k: usize, viewpoint: [f64; 3]) -> Result<Vec<[f64; 3]>, String> {
    Ok(estimate_normals_seen_from(points, k, Viewpoints::Fixed(viewpoint))?.normals)
}

/// [`estimate_normals`] with each point turned towards its own viewpoint, and the count of
/// neighbourhoods along a line.
pub fn estimate_normals_seen_from(points: &[[f64; 3]], k: usize, viewpoints: Viewpoints) -> Result<Normals, String> {
    estimate_normals_of_stripes(points, k, viewpoints, None)
}

/// [`estimate_normals_seen_from`] knowing which stripe each point came from (`stripes`: one id
/// per point, e.g. its frame and laser): neighbours all from one stripe are a line whatever
/// their shape, since one frame's points lie in its light plane, which a plane fit would return
/// as the surface once the noise along the rays widens the stripe.
pub fn estimate_normals_of_stripes(
    points: &[[f64; 3]],
    k: usize,
    viewpoints: Viewpoints,
    stripes: Option<&[u64]>,
) -> Result<Normals, String> {
    if k < 3 {
        return Err(format!("normals need at least 3 neighbours, got {k}"));
    }
    if let Viewpoints::PerPoint(v) = viewpoints
        && v.len() != points.len()
    {
        return Err(format!("internal: {} viewpoints for {} points", v.len(), points.len()));
    }
    if let Some(ids) = stripes
        && ids.len() != points.len()
    {
        return Err(format!("internal: {} stripe ids for {} points", ids.len(), points.len()));
    }
    let tree = KdTree::build(points);
    let estimated: Vec<([f64; 3], bool)> = points
        .par_iter()
        .enumerate()
        .map_init(Vec::new, |nearest, (i, p)| {
            tree.knn(p, k, nearest);
            let to_view = (viewpoints.of(i) - Vector3::from(*p)).normalize();
            let one_stripe = stripes.is_some_and(|ids| nearest.iter().all(|&(_, j)| ids[j as usize] == ids[i]));
            let (n, line) = match neighbourhood_shape(points, nearest, one_stripe) {
                Some(Shape::Plane(n)) => (n, false),
                Some(Shape::Line { along, across }) => {
                    // The direction across the line nearest to the sensor's; any, if the
                    // sensor looks along the line.
                    let towards = to_view - along * to_view.dot(&along);
                    (if towards.norm() > 1e-6 { towards.normalize() } else { across }, true)
                }
                None => (to_view, false),
            };
            let n = if n.dot(&to_view) < 0.0 { -n } else { n };
            (if n.iter().all(|c| c.is_finite()) { n.into() } else { [0.0; 3] }, line)
        })
        .collect();
    let along_a_line = estimated.iter().filter(|e| e.1).count();
    Ok(Normals { normals: estimated.into_iter().map(|e| e.0).collect(), along_a_line })
}

/// A neighbourhood's shape: a patch of surface (its least-squares plane's normal) or points
/// along a line (the line's direction, and a unit vector across it).
enum Shape {
    Plane(Vector3<f64>),
    Line { along: Vector3<f64>, across: Vector3<f64> },
}

/// The shape of the neighbours (a line if `one_stripe`), if there are at least 3 and they are
/// not all one point.
fn neighbourhood_shape(points: &[[f64; 3]], nearest: &[(f64, u32)], one_stripe: bool) -> Option<Shape> {
    if nearest.len() < 3 {
        return None;
    }
    let n = nearest.len() as f64;
    let at = |i: u32| Vector3::from(points[i as usize]);
    let mean = nearest.iter().map(|&(_, i)| at(i)).sum::<Vector3<f64>>() / n;
    let cov = nearest.iter().fold(Matrix3::zeros(), |c, &(_, i)| {
        let d = at(i) - mean;
        c + d * d.transpose()
    });
    let eig = SymmetricEigen::new(cov);
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let (middle, largest) = (eig.eigenvalues[order[1]].max(0.0), eig.eigenvalues[order[2]]);
    // Neighbours within a nanometre of each other: no direction at all.
    if !(largest > 1e-12 * n) {
        return None;
    }
    let column = |k: usize| eig.eigenvectors.column(order[k]).normalize();
    if one_stripe || middle <= LINE_WIDTH_RATIO.powi(2) * largest {
        return Some(Shape::Line { along: column(2), across: column(0) });
    }
    Some(Shape::Plane(column(0)))
}

/// A point's stripe: its frame and laser where both are whole numbers of f32's exact range,
/// else an id of its own (bit 63 set, its index).
fn stripe_id(index: usize, frame: f32, laser: f32) -> u64 {
    let whole = |v: f32| v.is_finite() && v.fract() == 0.0 && (0.0..16_777_216.0).contains(&v);
    if whole(frame) && whole(laser) { (frame as u64) << 24 | laser as u64 } else { 1 << 63 | index as u64 }
}

/// Adds (or replaces) the `nx ny nz` float fields of `cloud` with [`estimate_normals`]; returns
/// how many came from a neighbourhood along a line ([`Normals::along_a_line`]).
pub fn add_normals(cloud: &mut PointCloud, k: usize, viewpoint: [f64; 3]) -> Result<usize, String> {
    add_normals_seen_from(cloud, k, Viewpoints::Fixed(viewpoint), false)
}

/// [`add_normals`] with each point turned towards its own viewpoint. With `frames_are_stripes`
/// (one stream's points, not averaged in voxels) and the cloud's `scalar_frame` and
/// `scalar_laser`, neighbours of one frame and laser are one stripe
/// ([`estimate_normals_of_stripes`]); a point whose numbers are not whole is no stripe's.
pub fn add_normals_seen_from(
    cloud: &mut PointCloud,
    k: usize,
    viewpoints: Viewpoints,
    frames_are_stripes: bool,
) -> Result<usize, String> {
    let stripes: Option<Vec<u64>> =
        cloud.scalar("scalar_frame").zip(cloud.scalar("scalar_laser")).filter(|_| frames_are_stripes).map(
            |(frames, lasers)| frames.iter().zip(lasers).enumerate().map(|(i, (f, l))| stripe_id(i, *f, *l)).collect(),
        );
    let Normals { normals, along_a_line } =
        estimate_normals_of_stripes(&cloud.positions, k, viewpoints, stripes.as_deref())?;
    cloud.scalars.retain(|s| !NORMAL_FIELDS.contains(&s.name.as_str()));
    for (axis, name) in NORMAL_FIELDS.iter().enumerate() {
        cloud.scalars.push(ScalarField::new(*name, normals.iter().map(|n| n[axis] as f32).collect()));
    }
    Ok(along_a_line)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
        Vector3::from(a).angle(&Vector3::from(b)).to_degrees()
    }

    #[test]
    fn a_noisy_plane_gets_its_normal_facing_the_sensor() {
        // The plane z = 0.3·x + 500 (mm) with 0.1 mm noise, seen from the origin below it.
        let mut rng = SplitMix64::new(3);
        let pts: Vec<[f64; 3]> = (0..4000)
            .map(|_| {
                let (x, y) = (rng.uniform() * 400.0 - 200.0, rng.uniform() * 400.0 - 200.0);
                [x, y, 0.3 * x + 500.0 + (rng.uniform() - 0.5) * 0.2]
            })
            .collect();
        let truth = Vector3::new(0.3, 0.0, -1.0).normalize();
        let normals = estimate_normals(&pts, 20, [0.0; 3]).unwrap();
        let worst = normals.iter().map(|n| angle_deg(*n, truth.into())).fold(0.0, f64::max);
        // 20 neighbours span ~ 7 mm; 0.1 mm uniform noise tilts the fit by well under 2°.
        assert!(worst < 2.0, "worst normal {worst}° from the truth");
    }

    #[test]
    fn a_sphere_seen_from_inside_and_outside() {
        // Points on a 300 mm sphere centred at c; the normal is ±(p − c)/r. 20000 points are
        // ~7.5 mm apart: 12 neighbours span ~15 mm, where an uneven neighbourhood on the curved
        // surface tilts the fit by a degree or two.
        let c = [1000.0, 0.0, 0.0];
        let mut rng = SplitMix64::new(5);
        let pts: Vec<[f64; 3]> = (0..20000)
            .map(|_| {
                let (z, t) = (rng.uniform() * 2.0 - 1.0, rng.uniform() * std::f64::consts::TAU);
                let r = (1.0 - z * z).sqrt();
                [c[0] + 300.0 * r * t.cos(), c[1] + 300.0 * r * t.sin(), c[2] + 300.0 * z]
            })
            .collect();
        for (view, outward) in [(c, false), ([0.0; 3], true)] {
            let normals = estimate_normals(&pts, 12, view).unwrap();
            for (p, n) in pts.iter().zip(&normals) {
                let radial = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                let to_view = Vector3::from(view) - Vector3::from(*p);
                // From the centre every normal points inwards; from outside, the points that
                // face the viewpoint point outwards and the far side points inwards.
                let cos = Vector3::from(radial).normalize().dot(&to_view.normalize());
                if cos.abs() < 0.2 {
                    // Near the silhouette the side seen is ill-defined; skip.
                    continue;
                }
                let faces = cos > 0.0;
                let want_out = outward && faces;
                let a = angle_deg(*n, if want_out { radial } else { radial.map(|v| -v) });
                assert!(a < 3.0, "view {view:?}: {a}° at {p:?}");
            }
        }
    }

    #[test]
    fn each_point_faces_its_own_viewpoint() {
        // The plane z = 0.2·y (mm), half of it measured from above (x < 0, sensor at z = +600)
        // and half from below (x ≥ 0, sensor at z = −600): one fixed viewpoint would turn half
        // the normals the wrong way.
        let mut rng = SplitMix64::new(9);
        let pts: Vec<[f64; 3]> = (0..3000)
            .map(|_| {
                let (x, y) = (rng.uniform() * 400.0 - 200.0, rng.uniform() * 400.0 - 200.0);
                [x, y, 0.2 * y + (rng.uniform() - 0.5) * 0.2]
            })
            .collect();
        let views: Vec<[f64; 3]> =
            pts.iter().map(|p| if p[0] < 0.0 { [-100.0, 0.0, 600.0] } else { [100.0, 50.0, -600.0] }).collect();
        let up = Vector3::new(0.0, -0.2, 1.0).normalize();
        let normals = estimate_normals_seen_from(&pts, 16, Viewpoints::PerPoint(&views)).unwrap();
        assert_eq!(normals.along_a_line, 0);
        let normals = normals.normals;
        for ((p, n), v) in pts.iter().zip(&normals).zip(&views) {
            let to_view = Vector3::from(*v) - Vector3::from(*p);
            assert!(Vector3::from(*n).dot(&to_view) > 0.0, "{p:?} faces away from {v:?}");
            let truth = if p[0] < 0.0 { up } else { -up };
            // 0.1 mm uniform noise over a neighbourhood ~ 8 mm wide: well under 2°.
            let a = angle_deg(*n, truth.into());
            assert!(a < 2.0, "{a}° at {p:?}");
        }
        let fixed = estimate_normals(&pts, 16, [0.0, 0.0, 600.0]).unwrap();
        assert!(fixed.iter().all(|n| n[2] > 0.0), "one viewpoint turns every normal up");
        assert!(estimate_normals_seen_from(&pts, 16, Viewpoints::PerPoint(&views[1..])).is_err());
    }

    #[test]
    fn add_normals_appends_three_float_fields_once() {
        let mut cloud = PointCloud {
            positions: vec![[0.0, 0.0, 10.0], [1.0, 0.0, 10.0], [0.0, 1.0, 10.0], [1.0, 1.0, 10.0]],
            scalars: vec![ScalarField::new("intensity", vec![1.0; 4])],
        };
        add_normals(&mut cloud, 4, [0.0; 3]).unwrap();
        add_normals(&mut cloud, 4, [0.0; 3]).unwrap();
        let names: Vec<&str> = cloud.scalars.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["intensity", "nx", "ny", "nz"]);
        assert_eq!(cloud.scalar("nz").unwrap(), &[-1.0; 4]);
        assert!(estimate_normals(&cloud.positions, 2, [0.0; 3]).is_err());
    }

    /// One stripe of one frame: points along the curve where a light plane meets the plane
    /// z = 0.3·x + 500, with 0.05 mm noise. Its neighbourhoods are lines, so each normal is
    /// perpendicular to the stripe and as near the direction to the sensor as that allows, and
    /// every point is counted; two stripes 4 mm apart give planes.
    #[test]
    fn a_lone_stripe_gets_normals_across_it_and_is_counted() {
        let mut rng = SplitMix64::new(13);
        let stripe = |offset: f64, rng: &mut SplitMix64| -> Vec<[f64; 3]> {
            (0..400)
                .map(|i| {
                    let x = -100.0 + 0.5 * i as f64;
                    let y = 0.1 * x + offset;
                    [x, y + 0.05 * rng.normal(), 0.3 * x + 500.0 + 0.05 * rng.normal()]
                })
                .collect()
        };
        let one = stripe(0.0, &mut rng);
        let found = estimate_normals_seen_from(&one, 16, Viewpoints::Fixed([0.0; 3])).unwrap();
        assert_eq!(found.along_a_line, one.len());
        let tangent = Vector3::new(1.0, 0.1, 0.3).normalize();
        for (p, n) in one.iter().zip(&found.normals) {
            let n = Vector3::from(*n);
            let to_view = -Vector3::from(*p).normalize();
            let nearest = (to_view - tangent * to_view.dot(&tangent)).normalize();
            assert!(n.dot(&tangent).abs() < 0.05 && n.angle(&nearest).to_degrees() < 3.0, "{n:?} at {p:?}");
        }
        let two: Vec<[f64; 3]> = one.iter().copied().chain(stripe(4.0, &mut rng)).collect();
        let found = estimate_normals_seen_from(&two, 16, Viewpoints::Fixed([0.0; 3])).unwrap();
        assert!(found.along_a_line < two.len() / 20, "{} of {}", found.along_a_line, two.len());
    }

    /// One frame's stripe lies in its light plane (here y = 0.1·x + 20; the surface is
    /// z = 0.3·x + 500), and its noise moves points along their rays, within that plane: with
    /// 0.8 mm of it the stripe is a band of the light plane, which a plane fit returns as the
    /// surface. Known to be one frame and laser, it is a line: its normals are across it,
    /// towards the sensor.
    #[test]
    fn one_frames_stripe_is_a_line_even_when_its_noise_widens_it() {
        let mut rng = SplitMix64::new(17);
        let light = Vector3::new(-0.1, 1.0, 0.0).normalize();
        let tangent = Vector3::new(1.0, 0.1, 0.3).normalize();
        let pts: Vec<[f64; 3]> = (0..400)
            .map(|i| {
                let x = -100.0 + 0.5 * i as f64;
                let on = Vector3::new(x, 0.1 * x + 20.0, 0.3 * x + 500.0);
                // Along the ray, then back into the light plane: noise within it.
                let moved = on * (1.0 + 0.8 * rng.normal() / on.norm());
                let back = moved - light * (light.dot(&moved) - light.dot(&on));
                back.into()
            })
            .collect();
        let plane_fit = estimate_normals_seen_from(&pts, 16, Viewpoints::Fixed([0.0; 3])).unwrap();
        let light_like = plane_fit.normals.iter().filter(|n| Vector3::from(**n).dot(&light).abs() > 0.9).count();
        assert!(light_like > pts.len() / 2, "the plane fit returns the light plane: {light_like} of {}", pts.len());
        let ids = vec![7u64; pts.len()];
        let found = estimate_normals_of_stripes(&pts, 16, Viewpoints::Fixed([0.0; 3]), Some(&ids)).unwrap();
        assert_eq!(found.along_a_line, pts.len());
        // The stripe's direction from 16 points 0.8 mm noisy over 8 mm tilts by a few degrees
        // (the light plane's normal lies 88° off).
        let angles: Vec<f64> = pts
            .iter()
            .zip(&found.normals)
            .map(|(p, n)| {
                let to_view = -Vector3::from(*p).normalize();
                let nearest = (to_view - tangent * to_view.dot(&tangent)).normalize();
                Vector3::from(*n).angle(&nearest).to_degrees()
            })
            .collect();
        let rms = (angles.iter().map(|a| a * a).sum::<f64>() / angles.len() as f64).sqrt();
        let worst = angles.iter().cloned().fold(0.0, f64::max);
        assert!(rms < 6.0 && worst < 15.0, "rms {rms}°, worst {worst}°");
    }

    /// Neighbours all at one point give no direction: the normal faces the sensor, uncounted. A
    /// line seen end-on gets a unit normal across it.
    #[test]
    fn coincident_points_and_a_line_seen_end_on() {
        let same = vec![[0.0, 0.0, 100.0]; 6];
        let found = estimate_normals_seen_from(&same, 4, Viewpoints::Fixed([0.0; 3])).unwrap();
        assert_eq!(found.along_a_line, 0);
        assert!(found.normals.iter().all(|n| (n[2] + 1.0).abs() < 1e-12), "{:?}", found.normals);
        let line: Vec<[f64; 3]> = (0..20).map(|i| [i as f64, 0.0, 0.0]).collect();
        let found = estimate_normals_seen_from(&line, 5, Viewpoints::Fixed([1000.0, 0.0, 0.0])).unwrap();
        assert_eq!(found.along_a_line, line.len());
        for n in &found.normals {
            assert!(n[0].abs() < 1e-9 && (Vector3::from(*n).norm() - 1.0).abs() < 1e-9, "{n:?}");
        }
    }

    /// A stripe is named only by whole frame and laser numbers: a voxel's mean or a NaN names
    /// none, so such points never make a neighbourhood one stripe.
    #[test]
    fn only_whole_frame_numbers_name_a_stripe() {
        assert_eq!(stripe_id(0, 5.0, 1.0), stripe_id(9, 5.0, 1.0));
        assert_ne!(stripe_id(0, 5.0, 1.0), stripe_id(0, 5.0, 0.0));
        assert_ne!(stripe_id(0, 5.0, 1.0), stripe_id(0, 6.0, 1.0));
        for (frame, laser) in [(5.5, 0.0), (f32::NAN, 0.0), (5.0, f32::INFINITY), (-1.0, 0.0), (3e7, 0.0)] {
            assert_ne!(stripe_id(1, frame, laser), stripe_id(2, frame, laser), "{frame} {laser}");
        }
    }
}
