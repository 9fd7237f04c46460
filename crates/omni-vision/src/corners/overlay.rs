//! Drawing detected and reprojected corners over an image, for people to check a calibration.

use super::gray::GrayF32;
use image::{Rgb, RgbImage};

/// Green crosses: detected corners. Red circles: reprojected corners. Yellow line: from the
/// first detected corner to the second, showing the labeling's column direction.
pub fn draw_overlay(img: &GrayF32, detected: &[[f64; 2]], reprojected: &[[f64; 2]]) -> RgbImage {
    let mut out = RgbImage::from_fn(img.width as u32, img.height as u32, |x, y| {
        let v = img.data[y as usize * img.width + x as usize].clamp(0.0, 255.0) as u8;
        Rgb([v, v, v])
    });
    if detected.len() >= 2 {
        draw_line(&mut out, detected[0], detected[1], Rgb([255, 220, 0]));
    }
    for p in detected {
        for d in -3..=3 {
            put(&mut out, p[0] + d as f64, p[1], Rgb([0, 255, 0]));
            put(&mut out, p[0], p[1] + d as f64, Rgb([0, 255, 0]));
        }
    }
    for p in reprojected {
        for k in 0..16 {
            let a = k as f64 * std::f64::consts::PI / 8.0;
            put(&mut out, p[0] + 2.5 * a.cos(), p[1] + 2.5 * a.sin(), Rgb([255, 0, 0]));
        }
    }
    out
}

fn put(img: &mut RgbImage, x: f64, y: f64, c: Rgb<u8>) {
    let (xi, yi) = (x.round() as i64, y.round() as i64);
    if xi >= 0 && yi >= 0 && (xi as u32) < img.width() && (yi as u32) < img.height() {
        img.put_pixel(xi as u32, yi as u32, c);
    }
}

fn draw_line(img: &mut RgbImage, a: [f64; 2], b: [f64; 2], c: Rgb<u8>) {
    let n = ((b[0] - a[0]).hypot(b[1] - a[1]).ceil() as usize).max(1);
    for k in 0..=n {
        let t = k as f64 / n as f64;
        put(img, a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), c);
    }
}
