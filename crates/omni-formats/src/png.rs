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
