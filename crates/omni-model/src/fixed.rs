//! Fixed light planes: a transmitter without a scanning mirror (a line laser rigid with the
//! camera, or the polygon sensor with its motor stopped).
//!
//! Each plane is `normal · x = distance_mm` in the world (= camera) frame: `normal` a unit
//! vector, `distance_mm` the plane's signed distance from the world origin along it (mm). The
//! plane does not depend on a frame's mirror angle or facet; laser `laser` of a frame's
//! `lasers` list lights the plane with that id.

use omni_geom::{Plane, Vector3};
use serde::{Deserialize, Serialize};

/// One static light plane (world frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedPlaneParams {
    /// The laser's id, as frames list it in `lasers`.
    pub laser: u32,
    /// Unit normal of the plane (world frame); normalised when read, must not be zero.
    pub normal: [f64; 3],
    /// Signed distance of the plane from the world origin along `normal` (mm).
    pub distance_mm: f64,
}

/// The planes of a fixed-plane transmitter (what `scanner.json` stores for kind
/// `fixed_planes`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedPlanesParams {
    pub planes: Vec<FixedPlaneParams>,
}

impl FixedPlanesParams {
    /// One plane `normal · x = distance_mm` for laser 0.
    pub fn single(plane: &Plane) -> Self {
        FixedPlanesParams {
            planes: vec![FixedPlaneParams {
                laser: 0,
                normal: [plane.normal.x, plane.normal.y, plane.normal.z],
                distance_mm: plane.offset,
            }],
        }
    }

    /// Checks values; the message names the field at fault.
    pub fn validate(&self) -> Result<(), String> {
        if self.planes.is_empty() {
            return Err("planes must not be empty".into());
        }
        if self.planes.len() > crate::limits::MAX_FIXED_PLANES {
            return Err(format!(
                "planes: at most {} planes, got {}",
                crate::limits::MAX_FIXED_PLANES,
                self.planes.len()
            ));
        }
        for (i, p) in self.planes.iter().enumerate() {
            let n = Vector3::from(p.normal);
            if !(n.iter().all(|x| x.is_finite()) && n.norm() >= 1e-9 && n.norm().is_finite()) {
                return Err(format!("planes[{i}].normal must be finite and non-zero"));
            }
            if !p.distance_mm.is_finite() {
                return Err(format!("planes[{i}].distance_mm must be finite"));
            }
            if let Some(j) = self.planes[..i].iter().position(|q| q.laser == p.laser) {
                return Err(format!("planes[{i}].laser: laser {} already has a plane (planes[{j}])", p.laser));
            }
        }
        Ok(())
    }
}

/// The fixed-plane transmitter, validated, with unit normals.
#[derive(Debug, Clone)]
pub struct FixedPlanes {
    params: FixedPlanesParams,
    planes: Vec<(u32, Plane)>,
}

impl FixedPlanes {
    pub fn new(params: FixedPlanesParams) -> Result<Self, String> {
        params.validate()?;
        let planes = params
            .planes
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let n = Vector3::from(p.normal);
                // distance_mm is along the unit normal, whatever the length written.
                Plane::from_normal_offset(&(n / n.norm()), p.distance_mm).map(|plane| (p.laser, plane)).ok_or_else(
                    || format!("planes[{i}]: not a plane (normal {:?}, distance_mm {})", p.normal, p.distance_mm),
                )
            })
            .collect::<Result<_, _>>()?;
        Ok(FixedPlanes { params, planes })
    }

    pub fn params(&self) -> &FixedPlanesParams {
        &self.params
    }

    /// The plane of laser `laser` (world frame, unit normal), if the transmitter has one.
    pub fn plane(&self, laser: u32) -> Option<Plane> {
        self.planes.iter().find(|(l, _)| *l == laser).map(|(_, p)| *p)
    }

    /// The lasers' ids, in file order.
    pub fn lasers(&self) -> Vec<u32> {
        self.planes.iter().map(|(l, _)| *l).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planes_are_normalised_and_checked() {
        let p = FixedPlanesParams {
            planes: vec![FixedPlaneParams { laser: 3, normal: [0.0, 0.0, 2.0], distance_mm: 100.0 }],
        };
        let f = FixedPlanes::new(p.clone()).unwrap();
        let plane = f.plane(3).unwrap();
        assert!((plane.normal.z - 1.0).abs() < 1e-15 && (plane.offset - 100.0).abs() < 1e-12);
        assert!(f.plane(0).is_none());
        let mut bad = p.clone();
        bad.planes.push(bad.planes[0].clone());
        assert!(FixedPlanes::new(bad).unwrap_err().contains("planes[1].laser"));
        let mut bad = p.clone();
        bad.planes[0].normal = [0.0; 3];
        assert!(FixedPlanes::new(bad).unwrap_err().contains("planes[0].normal"));
        assert!(FixedPlanes::new(FixedPlanesParams { planes: vec![] }).is_err());
    }
}

/// A usable transmitter of either kind, as `scanner.json` holds it.
#[derive(Debug, Clone)]
pub enum TransmitterModel {
    /// The rotating polygon mirror and its line lasers.
    Polygon(crate::Transmitter),
    /// Static light planes.
    FixedPlanes(FixedPlanes),
}

impl TransmitterModel {
    /// The kind's name as `scanner.json` writes it (`polygon`, `fixed_planes`).
    pub fn kind(&self) -> &'static str {
        match self {
            TransmitterModel::Polygon(_) => crate::TRANSMITTER_KIND_POLYGON,
            TransmitterModel::FixedPlanes(_) => crate::TRANSMITTER_KIND_FIXED_PLANES,
        }
    }

    /// The polygon transmitter, if that is the kind.
    pub fn polygon(&self) -> Option<&crate::Transmitter> {
        match self {
            TransmitterModel::Polygon(t) => Some(t),
            TransmitterModel::FixedPlanes(_) => None,
        }
    }
}
