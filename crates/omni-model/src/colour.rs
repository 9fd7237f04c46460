//! A colour camera's sensor and processing: the colour filter mosaic, the filters' response to
//! the laser and to the room light, white balance and the colour matrix (camera.json's optional
//! `colour` section).

use serde::{Deserialize, Serialize};

/// The order of a Bayer colour filter mosaic, named by row 0 then row 1 of each 2 × 2 cell:
/// `rggb` = row 0: R G, row 1: G B.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BayerPattern {
    Rggb,
    Bggr,
    Grbg,
    Gbrg,
}

impl BayerPattern {
    pub const ALL: [BayerPattern; 4] = [BayerPattern::Rggb, BayerPattern::Bggr, BayerPattern::Grbg, BayerPattern::Gbrg];

    /// The channel (0 = R, 1 = G, 2 = B) of pixel (x, y).
    pub fn channel(self, x: usize, y: usize) -> usize {
        let cell = match self {
            BayerPattern::Rggb => [0, 1, 1, 2],
            BayerPattern::Bggr => [2, 1, 1, 0],
            BayerPattern::Grbg => [1, 0, 2, 1],
            BayerPattern::Gbrg => [1, 2, 0, 1],
        };
        cell[(y % 2) * 2 + x % 2]
    }

    /// The lower-case name (`rggb`, …).
    pub fn name(self) -> &'static str {
        match self {
            BayerPattern::Rggb => "rggb",
            BayerPattern::Bggr => "bggr",
            BayerPattern::Grbg => "grbg",
            BayerPattern::Gbrg => "gbrg",
        }
    }

    /// Parses `rggb`, `bggr`, `grbg` or `gbrg` (any case).
    pub fn parse(s: &str) -> Result<BayerPattern, String> {
        BayerPattern::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| format!("unknown Bayer order \"{s}\" (known: rggb, bggr, grbg, gbrg)"))
    }
}

/// A colour camera (camera.json's `colour`): every field has a default, so `{}` is a plain RGB
/// camera without a mosaic.
///
/// The raw signal of channel c is `laser_rgb[c]` × the laser light and `ambient_rgb[c]` × the
/// room light a monochrome pixel would collect (so a response of 1 is the monochrome camera).
/// RGB output is `matrix · clip(white_balance ⊙ raw)`, each raw channel as a share of the full
/// well, clipped to 0–1 again after the matrix (a clipped highlight turns white, as cameras do).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraColour {
    /// Colour filter mosaic; absent: every pixel sees R, G and B (a three-chip camera, or a
    /// frame already demosaiced without loss).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bayer: Option<BayerPattern>,
    /// Raw R, G, B response to the laser (monochrome pixel = 1); absent: the built-in filter
    /// curves ([`filter_response`]) at the optics' wavelength.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub laser_rgb: Option<[f64; 3]>,
    /// Raw R, G, B response to the room light on a white surface (monochrome pixel = 1).
    #[serde(default = "default_ambient_rgb")]
    pub ambient_rgb: [f64; 3],
    /// White balance gains applied to the raw channels before the matrix.
    #[serde(default = "default_white_balance")]
    pub white_balance: [f64; 3],
    /// Colour matrix, rows = output R, G, B, columns = white-balanced raw R, G, B; each row
    /// sums to 1 so that white stays white.
    #[serde(default = "default_matrix")]
    pub matrix: [[f64; 3]; 3],
}

/// A reddish room (warm light): white paper reads about (1, 0.8, 0.7) in the output, as in the
/// real hand-held frames (docs/DECISIONS.md).
fn default_ambient_rgb() -> [f64; 3] {
    [0.47, 0.81, 0.46]
}

/// Daylight-like gains of a typical CMOS sensor (its green pixels are the most sensitive).
fn default_white_balance() -> [f64; 3] {
    [1.9, 1.0, 1.6]
}

/// A consumer CMOS sensor's colour matrix (raw → sRGB primaries, its saturation boost
/// included), rows summing to 1: a clipped red pulls green down, so that a red stripe on lit
/// paper comes out darker than the paper in luma, as in the real frames.
fn default_matrix() -> [[f64; 3]; 3] {
    [[1.80, -0.60, -0.20], [-0.45, 1.65, -0.20], [0.00, -0.55, 1.55]]
}

impl Default for CameraColour {
    fn default() -> Self {
        CameraColour {
            bayer: None,
            laser_rgb: None,
            ambient_rgb: default_ambient_rgb(),
            white_balance: default_white_balance(),
            matrix: default_matrix(),
        }
    }
}

impl CameraColour {
    /// Checks values; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        let fields: [(&str, &[f64]); 3] = [
            ("laser_rgb", self.laser_rgb.as_ref().map_or(&[][..], |v| &v[..])),
            ("ambient_rgb", &self.ambient_rgb),
            ("white_balance", &self.white_balance),
        ];
        for (name, v) in fields {
            if let Some(x) = v.iter().find(|x| !(x.is_finite() && (0.0..=100.0).contains(*x))) {
                return Err(format!("{name}: values must be within 0–100, got {x}"));
            }
        }
        if self.white_balance.contains(&0.0) {
            return Err("white_balance: gains must be positive".into());
        }
        for (i, row) in self.matrix.iter().enumerate() {
            if let Some(x) = row.iter().find(|x| !(x.is_finite() && x.abs() <= 100.0)) {
                return Err(format!("matrix row {i}: values must be within ±100, got {x}"));
            }
        }
        Ok(())
    }

    /// The raw R, G, B response to a laser of `wavelength_nm`: `laser_rgb`, else the built-in
    /// filter curves.
    pub fn laser_response(&self, wavelength_nm: f64) -> [f64; 3] {
        self.laser_rgb.unwrap_or_else(|| filter_response(wavelength_nm))
    }
}

/// Raw R, G, B response (monochrome pixel = 1) of a typical RGB CMOS sensor behind an IR-cut
/// filter (half transmission at 665 nm) to light of `wavelength_nm`: smooth approximations of
/// published filter curves (R rises at 585 nm; G peaks at 535 nm; B at 455 nm; the green and blue
/// dyes leak red light). At 650 nm: R 0.81, G 0.08, B 0.11.
pub fn filter_response(wavelength_nm: f64) -> [f64; 3] {
    let l = wavelength_nm;
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    let gauss = |mu: f64, s: f64| (-0.5 * ((l - mu) / s).powi(2)).exp();
    let ir_cut = logistic((665.0 - l) / 10.0);
    let r = logistic((l - 585.0) / 12.0) * ir_cut;
    let g = (0.95 * gauss(535.0, 38.0) + 0.10 * logistic((l - 620.0) / 12.0)) * ir_cut;
    let b = (0.90 * gauss(455.0, 30.0) + 0.14 * logistic((l - 625.0) / 10.0)) * ir_cut;
    [r, g, b]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bayer_orders_name_row_0_then_row_1() {
        let rows = |p: BayerPattern| {
            let c = |x, y| ['R', 'G', 'B'][p.channel(x, y)];
            format!("{}{}{}{}", c(0, 0), c(1, 0), c(0, 1), c(1, 1)).to_lowercase()
        };
        for p in BayerPattern::ALL {
            assert_eq!(rows(p), p.name());
            assert_eq!(BayerPattern::parse(&p.name().to_uppercase()).unwrap(), p);
            assert_eq!(p.channel(2, 4), p.channel(0, 0), "the cell repeats");
        }
        assert!(BayerPattern::parse("rgbg").unwrap_err().contains("rggb"));
    }

    #[test]
    fn the_defaults_load_from_an_empty_section_and_keep_white_white() {
        let c: CameraColour = serde_json::from_str("{}").unwrap();
        assert_eq!(c, CameraColour::default());
        c.validate().unwrap();
        for row in c.matrix {
            assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        let red = filter_response(650.0);
        assert!(red[0] > 0.8 && red[1] < 0.12 && red[2] < 0.14, "{red:?}");
        let green = filter_response(532.0);
        assert!(green[1] > 0.9 && green[0] < 0.05, "{green:?}");
        let json: CameraColour = serde_json::from_str(r#"{"bayer": "gbrg", "laser_rgb": [1, 0.1, 0.2]}"#).unwrap();
        assert_eq!((json.bayer, json.laser_response(650.0)), (Some(BayerPattern::Gbrg), [1.0, 0.1, 0.2]));
        assert!(serde_json::from_str::<CameraColour>(r#"{"bayer": "rgb"}"#).is_err());
    }
}
