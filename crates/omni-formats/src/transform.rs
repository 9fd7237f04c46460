//! `transform.json` (`omniscan.transform`, version 1): a rigid transform between two frames,
//! e.g. from a calibrated sensor's frame into a reference (ground-truth) frame.

use crate::Versioned;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// p_to = rotation · p_from + translation_mm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransformFile {
    pub format: String,
    pub version: u32,
    /// Rotation matrix, row by row.
    pub rotation: [[f64; 3]; 3],
    pub translation_mm: [f64; 3],
    /// RMS residual of the registration that produced it (mm), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rms_mm: Option<f64>,
    /// What the transform maps from and to.
    #[serde(default)]
    pub description: String,
}

impl Versioned for TransformFile {
    const FORMAT: &'static str = "omniscan.transform";
    const VERSION: u32 = 1;
}

impl TransformFile {
    pub fn from_isometry(iso: &Isometry3<f64>, rms_mm: Option<f64>, description: &str) -> Self {
        let m = iso.rotation.to_rotation_matrix().into_inner();
        let t = iso.translation.vector;
        TransformFile {
            format: Self::FORMAT.into(),
            version: Self::VERSION,
            rotation: [0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]),
            translation_mm: [t.x, t.y, t.z],
            rms_mm,
            description: description.into(),
        }
    }

    /// The transform, refusing a non-orthonormal rotation or non-finite numbers.
    pub fn isometry(&self) -> Result<Isometry3<f64>, String> {
        let r = &self.rotation;
        let m = Matrix3::new(r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]);
        if !m.iter().chain(self.translation_mm.iter()).all(|x| x.is_finite()) {
            return Err("field rotation/translation_mm: not a finite number".into());
        }
        if (m.transpose() * m - Matrix3::identity()).norm() > 1e-6 || (m.determinant() - 1.0).abs() > 1e-6 {
            return Err("field rotation: not a rotation matrix".into());
        }
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
        Ok(Isometry3::from_parts(Translation3::from(Vector3::from(self.translation_mm)), rot))
    }
}
