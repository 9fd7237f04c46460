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
//! `reason`. An image that shows the board whole (all four sides end at its outer squares) may
//! add `"seen_board_size": [long, short]`, the inner corners the image shows along the board's
//! longer and shorter side, whatever `inner_cols × inner_rows` says; when most such images
//! disagree with it, [`CornersFile::board_size_warning`] names the likely size.

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
    /// The board's inner corners (longer, shorter side) if the image shows it whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seen_board_size: Option<[u32; 2]>,
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
                seen_board_size: b.seen_size,
            },
            Err(why) => {
                ImageCorners { name, corners: Vec::new(), reason: Some(why.to_string()), seen_board_size: None }
            }
        }
    }
}

/// Fewest images showing the board whole with one other size before
/// [`CornersFile::board_size_warning`] warns.
pub const BOARD_SIZE_IMAGES: usize = 2;

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

    /// A warning when the board file's size looks off by some rows or columns: at least
    /// [`BOARD_SIZE_IMAGES`] images, and more than half of those showing the board whole, show it
    /// with one other size. Names that size in the file's order (columns × rows).
    pub fn board_size_warning(&self) -> Option<String> {
        let (cols, rows) = (self.inner_cols, self.inner_rows);
        let seen: Vec<[u32; 2]> = self.images.iter().filter_map(|i| i.seen_board_size).collect();
        let (size, count) =
            seen.iter().map(|s| (*s, seen.iter().filter(|t| *t == s).count())).max_by_key(|(_, n)| *n)?;
        if size == [cols.max(rows), cols.min(rows)] || count < BOARD_SIZE_IMAGES || 2 * count <= seen.len() {
            return None;
        }
        let [long, short] = size;
        // The order of the seen size that keeps most of the file's numbers (else its shape).
        let keeps = |(c, r): (u32, u32)| (c == cols) as u8 + (r == rows) as u8;
        let (a, b) = ((long, short), (short, long));
        let likely = match keeps(a).cmp(&keeps(b)) {
            std::cmp::Ordering::Greater => a,
            std::cmp::Ordering::Less => b,
            std::cmp::Ordering::Equal if cols >= rows => a,
            std::cmp::Ordering::Equal => b,
        };
        Some(format!(
            "the board file says {cols} × {rows} inner corners, but {count} of the {} images that show the board whole show {} × {}: the board is probably {} × {}; fix inner_cols / inner_rows of the board file",
            seen.len(),
            likely.0,
            likely.1,
            likely.0,
            likely.1
        ))
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

#[cfg(test)]
mod tests {
    use super::*;
    use omni_vision::corners::{DetectorOptions, detect_board, load_gray};

    fn file(cols: u32, rows: u32, seen: &[Option<[u32; 2]>]) -> CornersFile {
        let mut f = CornersFile::new(100, 100, cols, rows);
        for (k, s) in seen.iter().enumerate() {
            f.images.push(ImageCorners { name: format!("b{k}"), corners: vec![], reason: None, seen_board_size: *s });
        }
        f
    }

    #[test]
    fn a_board_file_off_by_one_is_named_with_the_likely_size() {
        let nine_six = Some([9, 6]);
        for (cols, rows, likely) in
            [(8, 6, "9 × 6"), (10, 6, "9 × 6"), (6, 8, "6 × 9"), (9, 7, "9 × 6"), (8, 5, "9 × 6")]
        {
            let w = file(cols, rows, &[nine_six, None, nine_six, nine_six]).board_size_warning().unwrap();
            eprintln!("{w}");
            assert!(w.contains(&format!("probably {likely}")) && w.contains("3 of the 3 images"), "{w}");
        }
        // The right size, one image alone, or no majority: silent.
        assert_eq!(file(9, 6, &[nine_six, nine_six]).board_size_warning(), None);
        assert_eq!(file(6, 9, &[nine_six, nine_six]).board_size_warning(), None);
        assert_eq!(file(8, 6, &[nine_six, None]).board_size_warning(), None);
        assert_eq!(file(8, 6, &[nine_six, nine_six, Some([8, 6]), Some([8, 6])]).board_size_warning(), None);
    }

    /// The real MiniOmni board (7 × 11 inner corners) given as 7 × 10 or 8 × 11.
    #[test]
    fn the_real_board_given_off_by_one_is_named() {
        let dir =
            std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/real-omni-miniomni"));
        let images: Vec<_> = (1..=6).map(|k| load_gray(&dir.join(format!("MiniOmni{k}.jpg"))).unwrap()).collect();
        for (cols, rows) in [(7, 11), (7, 10), (8, 11)] {
            let mut f = CornersFile::new(752, 480, cols, rows);
            for (k, img) in images.iter().enumerate() {
                let found = detect_board(img, cols, rows, &DetectorOptions::default());
                f.images.push(ImageCorners::from_detection(format!("MiniOmni{}", k + 1), found));
            }
            let w = f.board_size_warning();
            eprintln!("{cols} × {rows}: {w:?}");
            match (cols, rows) {
                (7, 11) => assert_eq!(w, None),
                _ => assert!(
                    w.as_deref().is_some_and(|w| w.contains("probably 7 × 11") && w.contains("4 of the 4")),
                    "{w:?}"
                ),
            }
        }
    }
}
