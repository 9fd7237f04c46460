//! PNG frames as every omniscan tool writes them.
//!
//! Rule: fast deflate and the Up filter. A frame is written once and read by every tool after
//! it, so its decoding is what a chain from PNG files pays for: undoing the Up filter is one
//! byte-wise addition per row, where the adaptive filter's Paeth rows are undone one pixel after
//! another, for files a few per cent larger (docs/DECISIONS.md).

use image::ImageEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};

/// Writes `pixels` (`width` × `height` samples of `colour`, 16-bit samples in native byte
/// order) as a PNG to `out`.
pub fn write_png<W: std::io::Write>(
    out: W,
    pixels: &[u8],
    width: u32,
    height: u32,
    colour: image::ExtendedColorType,
) -> image::ImageResult<()> {
    PngEncoder::new_with_quality(out, CompressionType::Fast, FilterType::Up).write_image(pixels, width, height, colour)
}

/// `samples` (row-major, of `bit_depth` bits: 8 or fewer written as 8-bit samples, more as
/// 16-bit ones) as a PNG of `width` × `height` px to `out`, of colour type `types[0]` for 8-bit
/// samples and `types[1]` for 16-bit ones (grey or RGB).
pub fn write_samples_png<W: std::io::Write>(
    out: W,
    samples: &[u16],
    bit_depth: u8,
    (width, height): (u32, u32),
    types: [image::ExtendedColorType; 2],
) -> image::ImageResult<()> {
    if bit_depth <= 8 {
        let bytes: Vec<u8> = samples.iter().map(|&v| v.min(255) as u8).collect();
        write_png(out, &bytes, width, height, types[0])
    } else {
        let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_ne_bytes()).collect();
        write_png(out, &bytes, width, height, types[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every sample type the tools write reads back as written (grey and RGB, 8 and 16 bits).
    #[test]
    fn frames_read_back_as_written() {
        use image::ExtendedColorType as C;
        let (width, height) = (37u32, 11u32);
        for (colour, channels, bytes_per_sample) in [(C::L8, 1, 1), (C::L16, 1, 2), (C::Rgb8, 3, 1), (C::Rgb16, 3, 2)] {
            let n = (width * height) as usize * channels * bytes_per_sample;
            let pixels: Vec<u8> = (0..n).map(|i| ((i * 7919) % 251) as u8).collect();
            let mut file = Vec::new();
            write_png(&mut file, &pixels, width, height, colour).unwrap();
            let read = image::load_from_memory_with_format(&file, image::ImageFormat::Png).unwrap();
            assert_eq!((read.width(), read.height()), (width, height));
            let back: Vec<u8> = match colour {
                C::L16 => read.to_luma16().into_raw().iter().flat_map(|v| v.to_ne_bytes()).collect(),
                C::Rgb16 => read.to_rgb16().into_raw().iter().flat_map(|v| v.to_ne_bytes()).collect(),
                _ => read.into_bytes(),
            };
            assert_eq!(back, pixels, "{colour:?}");
        }
    }
}
