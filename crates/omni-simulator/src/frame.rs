//! Rendered images: 8- or 16-bit grey frames ([`Frame16`]: monochrome, a raw Bayer mosaic, or a
//! colour frame's luma) and colour frames ([`RgbFrame`]), and their files: PNG, binary PGM, and
//! JPEG with 4:2:0 chroma ([`FrameFormat`]).

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
        use image::ExtendedColorType::{L8, L16};
        omni_formats::png::write_samples_png(w, &self.data, self.bit_depth, (self.width, self.height), [L8, L16])
    }

    /// Writes the PNG atomically (temporary file, then rename; `-` = stdout).
    pub fn to_png(&self, path: &Path) -> omni_formats::Result<()> {
        omni_formats::io::write_atomic(path, |w| self.encode_png(w).map_err(std::io::Error::other))
    }

    /// The frame's bytes in `format` (JPEG keeps 8 bits: a 16-bit frame's top byte).
    pub fn encode(&self, format: FrameFormat) -> Result<Vec<u8>, String> {
        match format {
            FrameFormat::Png => self.to_png_bytes(),
            FrameFormat::Pgm => {
                let maxval = if self.bit_depth == 8 { 255 } else { 65535 };
                let mut out = format!("P5\n{} {}\n{maxval}\n", self.width, self.height).into_bytes();
                if self.bit_depth == 8 {
                    out.extend(self.data.iter().map(|v| (*v).min(255) as u8));
                } else {
                    out.extend(self.data.iter().flat_map(|v| v.to_be_bytes()));
                }
                Ok(out)
            }
            FrameFormat::Jpeg { quality } => {
                let bytes: Vec<u8> = self.data.iter().map(|v| to_8_bit(*v, self.bit_depth)).collect();
                encode_jpeg(&bytes, self.width, self.height, jpeg_encoder::ColorType::Luma, quality)
            }
        }
    }

    /// What a reader of this frame saved as JPEG of `quality` sees (8-bit grey).
    pub fn jpeg_round_trip(&self, quality: u8) -> Result<Frame16, String> {
        let bytes = self.encode(FrameFormat::Jpeg { quality })?;
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg).map_err(|e| e.to_string())?;
        let data = img.into_luma8().into_raw().into_iter().map(u16::from).collect();
        Ok(Frame16 { width: self.width, height: self.height, data, bit_depth: 8 })
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

/// A colour image: R, G, B interleaved, row-major, values in 0..=2^bit_depth − 1.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbFrame {
    pub width: u32,
    pub height: u32,
    /// R, G, B of each pixel in turn, row-major.
    pub data: Vec<u16>,
    /// 8 or 16.
    pub bit_depth: u8,
}

impl RgbFrame {
    /// R, G, B at column `x`, row `y`.
    pub fn get(&self, x: u32, y: u32) -> [u16; 3] {
        let i = 3 * (y * self.width + x) as usize;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// One channel (0 = R, 1 = G, 2 = B) as a grey frame.
    pub fn channel(&self, channel: usize) -> Frame16 {
        let data = self.data.iter().skip(channel).step_by(3).copied().collect();
        Frame16 { width: self.width, height: self.height, data, bit_depth: self.bit_depth }
    }

    /// Luma as the `image` crate computes it when it reads a colour file as grey
    /// (Rec. 709 weights 0.2126, 0.7152, 0.0722, rounded down).
    pub fn luma(&self) -> Frame16 {
        let data = self
            .data
            .chunks_exact(3)
            .map(|p| ((2126 * p[0] as u32 + 7152 * p[1] as u32 + 722 * p[2] as u32) / 10_000) as u16)
            .collect();
        Frame16 { width: self.width, height: self.height, data, bit_depth: self.bit_depth }
    }

    /// The frame's bytes in `format`: PNG (RGB, 8 or 16 bits) or JPEG (8 bits, 4:2:0 chroma); PGM
    /// holds grey frames only.
    pub fn encode(&self, format: FrameFormat) -> Result<Vec<u8>, String> {
        match format {
            FrameFormat::Png => {
                use image::ExtendedColorType::{Rgb8, Rgb16};
                let mut out = Vec::new();
                omni_formats::png::write_samples_png(
                    &mut out,
                    &self.data,
                    self.bit_depth,
                    (self.width, self.height),
                    [Rgb8, Rgb16],
                )
                .map_err(|e| e.to_string())?;
                Ok(out)
            }
            FrameFormat::Pgm => Err("PGM holds grey frames only: write a colour frame as PNG or JPEG".into()),
            FrameFormat::Jpeg { quality } => {
                let bytes: Vec<u8> = self.data.iter().map(|v| to_8_bit(*v, self.bit_depth)).collect();
                encode_jpeg(&bytes, self.width, self.height, jpeg_encoder::ColorType::Rgb, quality)
            }
        }
    }

    /// What a reader of this frame saved as JPEG of `quality` sees (8 bits, its chroma from
    /// 2 × 2 blocks as the decoder upsamples it).
    pub fn jpeg_round_trip(&self, quality: u8) -> Result<RgbFrame, String> {
        let bytes = self.encode(FrameFormat::Jpeg { quality })?;
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg).map_err(|e| e.to_string())?;
        let data = img.into_rgb8().into_raw().into_iter().map(u16::from).collect();
        Ok(RgbFrame { width: self.width, height: self.height, data, bit_depth: 8 })
    }

    /// Reads a colour PNG or JPEG (8 or 16 bits; grey files come back with R = G = B).
    pub fn open(path: &Path) -> Result<RgbFrame, String> {
        let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let (width, height) = (img.width(), img.height());
        Ok(match img {
            image::DynamicImage::ImageRgb16(b) => RgbFrame { width, height, data: b.into_raw(), bit_depth: 16 },
            image::DynamicImage::ImageLuma16(_) | image::DynamicImage::ImageRgba16(_) => {
                RgbFrame { width, height, data: img.into_rgb16().into_raw(), bit_depth: 16 }
            }
            other => {
                let data = other.into_rgb8().into_raw().into_iter().map(u16::from).collect();
                RgbFrame { width, height, data, bit_depth: 8 }
            }
        })
    }
}

/// How a frame is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameFormat {
    /// PNG: grey or RGB, 8 or 16 bits, lossless.
    Png,
    /// Binary PGM (P5): grey frames (a raw Bayer mosaic too), 8 or 16 bits.
    Pgm,
    /// Baseline JPEG of `quality` (1–100), 8 bits; colour frames with 4:2:0 chroma (each chroma
    /// sample the mean of a 2 × 2 block), as cameras write them.
    Jpeg { quality: u8 },
}

impl FrameFormat {
    /// The file name extension: `png`, `pgm` or `jpg`.
    pub fn extension(self) -> &'static str {
        match self {
            FrameFormat::Png => "png",
            FrameFormat::Pgm => "pgm",
            FrameFormat::Jpeg { .. } => "jpg",
        }
    }
}

/// The top 8 bits of a value of `bit_depth` bits.
fn to_8_bit(v: u16, bit_depth: u8) -> u8 {
    if bit_depth == 8 { v.min(255) as u8 } else { (v >> 8) as u8 }
}

/// Baseline JPEG, 4:2:0 chroma averaged over 2 × 2 blocks (libjpeg's way) for colour.
fn encode_jpeg(bytes: &[u8], w: u32, h: u32, colour: jpeg_encoder::ColorType, quality: u8) -> Result<Vec<u8>, String> {
    if !(1..=100).contains(&quality) {
        return Err(format!("JPEG quality must be within 1–100, got {quality}"));
    }
    let (w16, h16) = match (u16::try_from(w), u16::try_from(h)) {
        (Ok(a), Ok(b)) => (a, b),
        _ => return Err(format!("JPEG holds at most 65535 × 65535 pixels, got {w} × {h}")),
    };
    let mut out = Vec::new();
    let mut enc = jpeg_encoder::Encoder::new(&mut out, quality);
    enc.set_sampling_factor(jpeg_encoder::SamplingFactor::R_4_2_0);
    enc.set_chroma_subsampling_method(jpeg_encoder::ChromaSubsamplingMethod::Average);
    enc.encode(bytes, w16, h16, colour).map_err(|e| e.to_string())?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jpeg_frames_have_4_2_0_chroma() {
        // Columns alternating between two colours of different luma: 2 × 2 chroma blocks average
        // each pair of columns, so the decoded chroma no longer alternates while the luma does.
        let (w, h) = (32u32, 16u32);
        let data: Vec<u16> = (0..w * h).flat_map(|i| if i % 2 == 0 { [200, 40, 40] } else { [40, 40, 200] }).collect();
        let frame = RgbFrame { width: w, height: h, data, bit_depth: 8 };
        let bytes = frame.encode(FrameFormat::Jpeg { quality: 95 }).unwrap();
        // The frame header (SOF0): Y sampled 2 × 2, Cb and Cr 1 × 1 — 4:2:0.
        let sof = bytes.windows(2).position(|m| m == [0xFF, 0xC0]).unwrap();
        let components = &bytes[sof + 10..sof + 19];
        assert_eq!(bytes[sof + 9], 3);
        assert_eq!([components[1], components[4], components[7]], [0x22, 0x11, 0x11], "{components:?}");
        let back = frame.jpeg_round_trip(95).unwrap();
        let ycc = |p: [u16; 3]| {
            let (r, g, b) = (p[0] as f64, p[1] as f64, p[2] as f64);
            let y = 0.299 * r + 0.587 * g + 0.114 * b;
            (y, 0.564 * (b - y), 0.713 * (r - y))
        };
        let (mut dy, mut dc) = (0.0f64, 0.0f64);
        for y in 4..h - 4 {
            for x in (4..w - 4).step_by(2) {
                let (a, b) = (ycc(back.get(x, y)), ycc(back.get(x + 1, y)));
                dy = dy.max((a.0 - b.0).abs());
                dc = dc.max((a.1 - b.1).abs()).max((a.2 - b.2).abs());
            }
        }
        let (a, b) = (ycc(frame.get(0, 0)), ycc(frame.get(1, 0)));
        assert!(dy > 0.8 * (a.0 - b.0).abs(), "luma keeps its detail: {dy}");
        assert!(dc < 0.1 * (a.2 - b.2).abs(), "chroma is averaged over 2 × 2: {dc}");
        // Grey frames are plain 8-bit grey JPEG.
        let grey = frame.luma().jpeg_round_trip(90).unwrap();
        assert_eq!((grey.width, grey.height, grey.bit_depth), (w, h, 8));
        assert!(frame.encode(FrameFormat::Pgm).is_err());
    }

    #[test]
    fn pgm_holds_grey_frames_of_8_and_16_bits() {
        for bit_depth in [8u8, 16] {
            let max = if bit_depth == 8 { 255u32 } else { 65535 };
            let data = (0..12u32).map(|i| (i * max / 11) as u16).collect();
            let f = Frame16 { width: 4, height: 3, data, bit_depth };
            let bytes = f.encode(FrameFormat::Pgm).unwrap();
            let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Pnm).unwrap();
            let back: Vec<u16> = if bit_depth == 8 {
                img.into_luma8().into_raw().into_iter().map(u16::from).collect()
            } else {
                img.into_luma16().into_raw()
            };
            assert_eq!(back, f.data);
        }
    }

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
