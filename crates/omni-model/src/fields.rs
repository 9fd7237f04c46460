//! Checks of named parameters, shared by the camera models' `validate`: the message names the
//! field at fault.

/// Each value must be a finite number above zero (focal lengths).
pub(crate) fn check_positive(fields: &[(&str, f64)]) -> Result<(), String> {
    match fields.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
        Some((name, v)) => Err(format!("{name} must be a positive number, got {v}")),
        None => Ok(()),
    }
}

/// Each value must be finite.
pub(crate) fn check_finite(fields: &[(&str, f64)]) -> Result<(), String> {
    match fields.iter().find(|(_, v)| !v.is_finite()) {
        Some((name, v)) => Err(format!("{name} must be finite, got {v}")),
        None => Ok(()),
    }
}
