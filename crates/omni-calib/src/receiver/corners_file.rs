//! `corners.json`: checkerboard corners per image, so detection and fitting can be used apart
//! (`omni-calib-receiver --save-corners` writes it, `--corners` reads it; other detectors can
//! write it too).
//!
//! ```json
//! {"format": "omniscan.corners", "version": 1, "width": 752, "height": 480,
//!  "inner_cols": 7, "inner_rows": 11,
//!  "images": [{"name": "MiniOmni1.jpg", "corners": [[0, 0, 312.4, 101.9], ...]}]}
//! ```
//! Each corner is `[column, row, x_px, y_px]` (board indices, then the pixel; x right, y down,
//! (0, 0) = centre of the top-left pixel). Images without a board have an empty list and a
//! `reason`.

use super::Observation;
use omni_formats::Versioned;
use serde::{Deserialize, Serialize};

/// The corners of all images of a calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CornersFile {
    pub format: String,
    pub version: u32,
    /// Image size (px).
    pub width: u32,
    pub height: u32,
    /// Board size in inner corners.
    pub inner_cols: u32,
    pub inner_rows: u32,
    pub images: Vec<ImageCorners>,
}

/// The corners found in one image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageCorners {
    pub name: String,
    /// `[column, row, x_px, y_px]` per corner.
    pub corners: Vec<[f64; 4]>,
    /// Why no board was found (when `corners` is empty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

impl ImageCorners {
    /// The entry for one image from the detector's outcome (corners, or the reason none).
    pub fn from_detection(
        name: String,
        found: Result<omni_vision::corners::BoardCorners, omni_vision::corners::Rejection>,
    ) -> Self {
        match found {
            Ok(b) => ImageCorners {
                name,
                corners: b.corners.iter().map(|c| [c.index[0] as f64, c.index[1] as f64, c.px[0], c.px[1]]).collect(),
                reason: None,
            },
            Err(why) => ImageCorners { name, corners: Vec::new(), reason: Some(why.to_string()) },
        }
    }
}

impl Versioned for CornersFile {
    const FORMAT: &'static str = "omniscan.corners";
    const VERSION: u32 = 1;
}

impl CornersFile {
    pub fn new(width: u32, height: u32, inner_cols: u32, inner_rows: u32) -> Self {
        CornersFile {
            format: Self::FORMAT.into(),
            version: Self::VERSION,
            width,
            height,
            inner_cols,
            inner_rows,
            images: Vec::new(),
        }
    }

    /// Checks indices and pixels; the message names the image and corner at fault.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err("width and height must be positive".into());
        }
        for img in &self.images {
            for (k, c) in img.corners.iter().enumerate() {
                let ok_index = c[0] >= 0.0
                    && c[1] >= 0.0
                    && c[0] < self.inner_cols as f64
                    && c[1] < self.inner_rows as f64
                    && c[0].fract() == 0.0
                    && c[1].fract() == 0.0;
                if !ok_index {
                    return Err(format!(
                        "image {}: corner {k}: index ({}, {}) is not a corner of a {} × {} board",
                        img.name, c[0], c[1], self.inner_cols, self.inner_rows
                    ));
                }
                if !(c[2].is_finite() && c[3].is_finite()) {
                    return Err(format!("image {}: corner {k}: pixel must be finite", img.name));
                }
            }
        }
        Ok(())
    }

    /// Observations for [`super::calibrate`] with squares of `square_mm`.
    pub fn observations(&self, square_mm: f64) -> Vec<Observation> {
        self.images
            .iter()
            .map(|img| Observation {
                name: img.name.clone(),
                board_mm: img.corners.iter().map(|c| [c[0] * square_mm, c[1] * square_mm]).collect(),
                pixels: img.corners.iter().map(|c| [c[2], c[3]]).collect(),
            })
            .collect()
    }
}
