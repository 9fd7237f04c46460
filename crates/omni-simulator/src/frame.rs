//! Rendered images: 8- or 16-bit grey frames and their PNG encoding.

use image::ImageEncoder;
use std::path::Path;

/// A grey image as the camera delivers it: values in 0..=2^bit_depth − 1, row-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame16 {
    pub width: u32,
    pub height: u32,
    /// Row-major pixel values (0–255 for 8-bit frames, 0–65535 for 16-bit).
    pub data: Vec<u16>,
    /// 8 or 16.
    pub bit_depth: u8,
}

impl Frame16 {
    /// The value at column `x`, row `y`.
    pub fn get(&self, x: u32, y: u32) -> u16 {
        self.data[(y * self.width + x) as usize]
    }

    /// The largest value the bit depth can hold (255 or 65535).
    pub fn max_value(&self) -> u16 {
        if self.bit_depth == 8 { 255 } else { u16::MAX }
    }

    /// Bilinear interpolation at a sub-pixel position (pixel centres at integers); `None`
    /// outside the image.
    pub fn bilinear(&self, x: f64, y: f64) -> Option<f64> {
        if !(x >= 0.0 && y >= 0.0 && x <= (self.width - 1) as f64 && y <= (self.height - 1) as f64) {
            return None;
        }
        let (x0, y0) = (x.floor() as u32, y.floor() as u32);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let g = |x, y| self.get(x, y) as f64;
        Some((1.0 - fy) * ((1.0 - fx) * g(x0, y0) + fx * g(x1, y0)) + fy * ((1.0 - fx) * g(x0, y1) + fx * g(x1, y1)))
    }

    /// PNG bytes: 8-bit grey for 8-bit frames, 16-bit grey otherwise.
    pub fn to_png_bytes(&self) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        self.encode_png(&mut out).map_err(|e| e.to_string())?;
        Ok(out)
    }

    fn encode_png<W: std::io::Write>(&self, w: W) -> image::ImageResult<()> {
        let enc = image::codecs::png::PngEncoder::new(w);
        if self.bit_depth == 8 {
            let bytes: Vec<u8> = self.data.iter().map(|&v| v.min(255) as u8).collect();
            enc.write_image(&bytes, self.width, self.height, image::ExtendedColorType::L8)
        } else {
            // The encoder takes 16-bit samples in native byte order.
            let bytes: Vec<u8> = self.data.iter().flat_map(|v| v.to_ne_bytes()).collect();
            enc.write_image(&bytes, self.width, self.height, image::ExtendedColorType::L16)
        }
    }

    /// Writes the PNG atomically (temporary file, then rename; `-` = stdout).
    pub fn to_png(&self, path: &Path) -> omni_formats::Result<()> {
        omni_formats::io::write_atomic(path, |w| self.encode_png(w).map_err(std::io::Error::other))
    }

    /// Reads an 8- or 16-bit grey PNG (other colour types are converted to grey).
    pub fn from_png(path: &Path) -> Result<Frame16, String> {
        let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let (width, height) = (img.width(), img.height());
        Ok(match img {
            image::DynamicImage::ImageLuma16(b) => Frame16 { width, height, data: b.into_raw(), bit_depth: 16 },
            other => {
                let data = other.into_luma8().into_raw().into_iter().map(u16::from).collect();
                Frame16 { width, height, data, bit_depth: 8 }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips_8_and_16_bit() {
        let dir = tempfile::tempdir().unwrap();
        for bit_depth in [8u8, 16] {
            let max = if bit_depth == 8 { 255u32 } else { 65535 };
            let data = (0..12u32).map(|i| (i * max / 11) as u16).collect();
            let f = Frame16 { width: 4, height: 3, data, bit_depth };
            let p = dir.path().join(format!("f{bit_depth}.png"));
            f.to_png(&p).unwrap();
            assert_eq!(Frame16::from_png(&p).unwrap(), f);
        }
    }
}
