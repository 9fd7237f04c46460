//! The light-plane table: the plane of every (mirror angle, laser) for one facet, the correct
//! version of the paper's Table 1 (SENSOR.md erratum), computed from the transmitter model.

use omni_model::{Transmitter, TransmitterParams};
use serde::Serialize;

/// One row: laser `laser`'s light plane at mirror angle `alpha_deg` on facet `facet`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TableRow {
    pub alpha_deg: f64,
    pub facet: u32,
    pub laser: usize,
    /// Unit normal (world frame), oriented with non-negative z.
    pub normal: [f64; 3],
    /// The plane is normal · x = offset_mm.
    pub offset_mm: f64,
    /// The plane as z = slope·x + intercept_mm in the x–z plane (the paper's Eq. 14 form).
    pub slope: f64,
    pub intercept_mm: f64,
}

/// Parses `start:stop:step` (degrees, stop included when reached within 1e-9) or a single angle.
pub fn parse_alpha_range(text: &str) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = text.split(':').collect();
    let num = |s: &str| -> Result<f64, String> {
        let v: f64 = s.trim().parse().map_err(|_| format!("\"{s}\" is not a number"))?;
        if v.is_finite() { Ok(v) } else { Err(format!("\"{s}\" is not a finite number")) }
    };
    match parts.as_slice() {
        [one] => Ok(vec![num(one)?]),
        [a, b, s] => {
            let (start, stop, step) = (num(a)?, num(b)?, num(s)?);
            if !(step > 0.0) {
                return Err(format!("step must be positive, got {step}"));
            }
            if stop < start {
                return Err(format!("stop {stop} is below start {start}"));
            }
            let n = ((stop - start) / step + 1e-9).floor() as usize;
            if n > 1_000_000 {
                return Err("more than a million angles".into());
            }
            Ok((0..=n).map(|i| start + i as f64 * step).collect())
        }
        _ => Err(format!("expected START:STOP:STEP or one angle, got \"{text}\"")),
    }
}

/// The table for mirror angles `alphas_deg` (degrees) on `facet`, for one laser or all.
/// Fails if the model is invalid, the laser or facet does not exist, or an angle lies outside
/// one facet's range [0, 2θ].
pub fn light_plane_table(
    params: &TransmitterParams,
    alphas_deg: &[f64],
    facet: u32,
    laser: Option<usize>,
) -> Result<Vec<TableRow>, String> {
    let tx = Transmitter::new(params.clone())?;
    if facet >= tx.num_facets() {
        return Err(format!("facet {facet} is not in the model ({} facets)", tx.num_facets()));
    }
    let lasers: Vec<usize> = match laser {
        Some(l) if l >= tx.num_lasers() => {
            return Err(format!("laser {l} is not in the model ({} lasers)", tx.num_lasers()));
        }
        Some(l) => vec![l],
        None => (0..tx.num_lasers()).collect(),
    };
    let span = tx.facet_angle_deg();
    let mut rows = vec![];
    for &a in alphas_deg {
        if !(a >= -1e-9 && a <= span + 1e-9) {
            return Err(format!("alpha {a}° is outside one facet's range [0, {span}]°"));
        }
        for &l in &lasers {
            let lp = tx
                .light_plane(a.to_radians(), facet, l)
                .ok_or_else(|| format!("laser {l} runs parallel to facet {facet} at alpha {a}°"))?;
            let (slope, intercept_mm) = lp.slope_intercept();
            rows.push(TableRow {
                alpha_deg: a,
                facet,
                laser: l,
                normal: lp.plane.normal.into_inner().into(),
                offset_mm: lp.plane.offset,
                slope,
                intercept_mm,
            });
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_parse_inclusively_and_reject_nonsense() {
        assert_eq!(parse_alpha_range("0:30:1").unwrap().len(), 31);
        assert_eq!(parse_alpha_range("0:1:0.3").unwrap(), vec![0.0, 0.3, 0.6, 0.8999999999999999]);
        assert_eq!(parse_alpha_range("7.5").unwrap(), vec![7.5]);
        assert!(parse_alpha_range("0:30:0").is_err());
        assert!(parse_alpha_range("a:b:c").is_err());
        assert!(parse_alpha_range("5:1:1").is_err());
    }

    #[test]
    fn table_matches_the_paper_closed_form_for_the_ideal_build() {
        let rows = light_plane_table(&TransmitterParams::paper(), &[0.0, 15.0, 30.0], 0, Some(0)).unwrap();
        let (r, h) = (20.0, 120.0);
        // α = 15°: slope 0, and Eq. 5's b = 0.4830·R (SENSOR.md erratum), minus h.
        assert!(rows[1].slope.abs() < 1e-12);
        let b15 = r * 15f64.to_radians().cos() * 30f64.to_radians().sin();
        assert!((rows[1].intercept_mm - (b15 - h)).abs() < 1e-9, "{:?}", rows[1]);
        assert!((b15 / r - 0.4830).abs() < 1e-4);
        assert!((rows[0].slope - (-30f64).to_radians().tan()).abs() < 1e-12);
        assert!((rows[2].slope - 30f64.to_radians().tan()).abs() < 1e-12);
        assert!(light_plane_table(&TransmitterParams::paper(), &[31.0], 0, None).is_err());
        assert!(light_plane_table(&TransmitterParams::paper(), &[1.0], 12, None).is_err());
        assert!(light_plane_table(&TransmitterParams::paper(), &[1.0], 0, Some(2)).is_err());
    }
}
