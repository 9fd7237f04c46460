//! A picture for a person: the frame in grey with the detected centres drawn on it.

use super::{StripePoint, quality};
use crate::image_io::GrayImage;

/// RGB8 pixels (`3 · width · height`) of `img` (scaled to 8 bits) with each stripe point as a
/// coloured dot at its nearest pixel: red for good points, yellow for saturated, blue for weak.
pub fn draw_overlay(img: &GrayImage, points: &[StripePoint]) -> Vec<u8> {
    let grey = img.to_u8();
    let mut rgb: Vec<u8> = grey.iter().flat_map(|&g| [g / 2, g / 2, g / 2]).collect();
    let (w, h) = (img.width as i64, img.height as i64);
    for p in points {
        let (x, y) = (p.u.round() as i64, p.v.round() as i64);
        if x < 0 || y < 0 || x >= w || y >= h {
            continue;
        }
        let colour = if p.quality & quality::SATURATED != 0 {
            [255, 255, 0]
        } else if p.quality & quality::WEAK != 0 {
            [64, 128, 255]
        } else {
            [255, 0, 0]
        };
        let i = 3 * (y * w + x) as usize;
        rgb[i..i + 3].copy_from_slice(&colour);
    }
    rgb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_are_drawn_where_they_are() {
        let mut img = GrayImage::new(4, 3, 8);
        img.data.fill(100);
        let p = StripePoint { u: 2.2, v: 0.9, intensity: 200.0, width: 3.0, quality: quality::SATURATED };
        let rgb = draw_overlay(&img, &[p]);
        assert_eq!(rgb.len(), 36);
        assert_eq!(&rgb[3 * (4 + 2)..3 * (4 + 2) + 3], &[255, 255, 0]);
        assert_eq!(&rgb[0..3], &[50, 50, 50]);
    }
}
