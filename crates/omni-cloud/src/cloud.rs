//! Turning triangulated stream frames into a [`PointCloud`] with the standard scalar fields.

use omni_formats::ply::{PointCloud, ScalarField};
use omni_formats::stream::Frame;
use omni_geom::{Isometry3, Point3};

/// The scalar fields written for triangulated points, in PLY order: stripe peak intensity,
/// frame sequence number, laser index, mirror angle (degrees), range from the viewpoint (mm),
/// pixel coordinates (px).
pub const POINT_SCALARS: [&str; 7] =
    ["intensity", "scalar_frame", "scalar_laser", "scalar_alpha_deg", "scalar_range", "scalar_u", "scalar_v"];

/// An empty cloud with the [`POINT_SCALARS`] fields.
pub fn empty_point_cloud() -> PointCloud {
    PointCloud {
        positions: Vec::new(),
        scalars: POINT_SCALARS.iter().map(|n| ScalarField::new(n.to_string(), Vec::new())).collect(),
    }
}

/// Appends the frame's `points` to `cloud` (which must have exactly the [`POINT_SCALARS`]
/// fields), mapping each through `pose` (sensor → world) if given and keeping only those
/// `keep` accepts (after the pose). Errors name the field at fault.
pub fn append_frame_points(
    cloud: &mut PointCloud,
    frame: &Frame,
    pose: Option<&Isometry3<f64>>,
    keep: &dyn Fn(&[f64; 3]) -> bool,
) -> Result<usize, String> {
    let points = frame.points.as_ref().ok_or("no `points` field (run omni-triangulate first)")?;
    let stripe = frame.stripe.as_deref().unwrap_or(&[]);
    let mut added = 0;
    for (i, p) in points.iter().enumerate() {
        if !(p.xyz.iter().all(|c| c.is_finite()) && p.range.is_finite()) {
            return Err(format!("field points[{i}]: not a finite number"));
        }
        let xyz = match pose {
            Some(iso) => (iso * Point3::from(p.xyz)).coords.into(),
            None => p.xyz,
        };
        if !keep(&xyz) {
            continue;
        }
        let sp = stripe.get(p.stripe_index as usize);
        let values = [
            sp.map_or(f32::NAN, |s| s.intensity as f32),
            frame.seq as f32,
            p.laser as f32,
            frame.alpha_deg as f32,
            p.range as f32,
            sp.map_or(f32::NAN, |s| s.u as f32),
            sp.map_or(f32::NAN, |s| s.v as f32),
        ];
        if sp.is_none() && !stripe.is_empty() {
            return Err(format!("field points[{i}]: stripe_index {} out of range", p.stripe_index));
        }
        cloud.positions.push(xyz);
        for (field, v) in cloud.scalars.iter_mut().zip(values) {
            field.values.push(if v.is_nan() { 0.0 } else { v });
        }
        added += 1;
    }
    Ok(added)
}
