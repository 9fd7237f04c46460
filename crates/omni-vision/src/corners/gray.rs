//! A small floating-point grey image with the few operations the corner detector needs:
//! separable Gaussian blur, clamped and bilinear sampling.

use std::path::Path;

/// A grey image as `f32` samples, row-major. 8-bit sources keep their 0–255 scale; 16-bit
/// sources are scaled to 0–255 so that thresholds mean the same thing for both.
#[derive(Debug, Clone, PartialEq)]
pub struct GrayF32 {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl GrayF32 {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        GrayF32 { width, height, data: vec![0.0; width * height] }
    }

    /// From 8-bit samples (row-major, `width * height` long).
    pub fn from_u8(width: usize, height: usize, pixels: &[u8]) -> Self {
        assert_eq!(pixels.len(), width * height, "pixel buffer size");
        GrayF32 { width, height, data: pixels.iter().map(|&p| p as f32).collect() }
    }

    /// From 16-bit samples, scaled to 0–255.
    pub fn from_u16(width: usize, height: usize, pixels: &[u16]) -> Self {
        assert_eq!(pixels.len(), width * height, "pixel buffer size");
        GrayF32 { width, height, data: pixels.iter().map(|&p| p as f32 * (255.0 / 65535.0)).collect() }
    }

    /// From any decoded image (converted to luma).
    pub fn from_dynamic(img: &image::DynamicImage) -> Self {
        match img {
            image::DynamicImage::ImageLuma16(g) => Self::from_u16(g.width() as usize, g.height() as usize, g.as_raw()),
            _ => {
                let g = img.to_luma8();
                Self::from_u8(g.width() as usize, g.height() as usize, g.as_raw())
            }
        }
    }

    /// Sample at integer coordinates, clamped to the border.
    #[inline]
    pub fn at(&self, x: isize, y: isize) -> f32 {
        let x = x.clamp(0, self.width as isize - 1) as usize;
        let y = y.clamp(0, self.height as isize - 1) as usize;
        self.data[y * self.width + x]
    }

    /// Bilinear sample at a sub-pixel position (pixel centres at integers), clamped.
    #[inline]
    pub fn bilinear(&self, x: f64, y: f64) -> f32 {
        let x0 = x.floor();
        let y0 = y.floor();
        let fx = (x - x0) as f32;
        let fy = (y - y0) as f32;
        let (xi, yi) = (x0 as isize, y0 as isize);
        let top = self.at(xi, yi) * (1.0 - fx) + self.at(xi + 1, yi) * fx;
        let bottom = self.at(xi, yi + 1) * (1.0 - fx) + self.at(xi + 1, yi + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Whether a position lies at least `margin` pixels inside the image.
    pub fn inside(&self, x: f64, y: f64, margin: f64) -> bool {
        x >= margin && y >= margin && x <= self.width as f64 - 1.0 - margin && y <= self.height as f64 - 1.0 - margin
    }
}

/// Loads an image file as grey; the error names the file.
pub fn load_gray(path: &Path) -> Result<GrayF32, String> {
    let img = crate::image_io::load_dynamic(path).map_err(|e| e.to_string())?;
    Ok(GrayF32::from_dynamic(&img))
}

/// Separable Gaussian blur with standard deviation `sigma` (px), border clamped.
pub fn gaussian_blur(img: &GrayF32, sigma: f64) -> GrayF32 {
    if sigma <= 0.0 {
        return img.clone();
    }
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-radius..=radius).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32).collect();
    let norm: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / norm).collect();
    let (w, h) = (img.width, img.height);
    let mut tmp = GrayF32::new(w, h);
    for y in 0..h {
        let row = &img.data[y * w..(y + 1) * w];
        for x in 0..w {
            let mut acc = 0.0;
            for (k, kv) in kernel.iter().enumerate() {
                let xx = (x as isize + k as isize - radius).clamp(0, w as isize - 1) as usize;
                acc += kv * row[xx];
            }
            tmp.data[y * w + x] = acc;
        }
    }
    let mut out = GrayF32::new(w, h);
    for y in 0..h {
        for (k, kv) in kernel.iter().enumerate() {
            let yy = (y as isize + k as isize - radius).clamp(0, h as isize - 1) as usize;
            let src = &tmp.data[yy * w..(yy + 1) * w];
            let dst = &mut out.data[y * w..(y + 1) * w];
            for x in 0..w {
                dst[x] += kv * src[x];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blur_preserves_constant_and_mean_of_step() {
        let mut img = GrayF32::new(20, 10);
        for y in 0..10 {
            for x in 10..20 {
                img.data[y * 20 + x] = 100.0;
            }
        }
        let b = gaussian_blur(&img, 1.5);
        assert!((b.at(0, 5) - 0.0).abs() < 1e-3);
        assert!((b.at(19, 5) - 100.0).abs() < 1e-3);
        // The edge lies between x = 9 and x = 10: their average stays at the midpoint.
        assert!(((b.at(9, 5) + b.at(10, 5)) / 2.0 - 50.0).abs() < 1e-3);
        assert!((img.bilinear(9.5, 3.0) - 50.0).abs() < 1e-4);
    }
}
