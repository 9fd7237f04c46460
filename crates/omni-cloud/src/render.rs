//! A picture of a point cloud for people: points splatted into an RGB image seen obliquely
//! from the sensor's side (azimuth −30°, elevation 25°, orthographic), far points first, coloured
//! by height or range with a perceptually ordered colour map.

use omni_geom::{Point3, Vector3};

/// What the colour encodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ColorBy {
    /// z (mm).
    Height,
    /// Distance from the origin (mm).
    Range,
}

/// An 8-bit RGB picture, row-major.
pub struct Picture {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

/// Maps t ∈ [0, 1] to a blue → cyan → yellow → red ramp.
fn ramp(t: f64) -> [u8; 3] {
    let stops = [[48.0, 18.0, 160.0], [0.0, 170.0, 220.0], [240.0, 220.0, 40.0], [220.0, 40.0, 30.0]];
    let x = t.clamp(0.0, 1.0) * 3.0;
    let i = (x.floor() as usize).min(2);
    let f = x - i as f64;
    [0, 1, 2].map(|c| (stops[i][c] * (1.0 - f) + stops[i + 1][c] * f) as u8)
}

/// Renders the points into a picture `width` pixels wide (clamped to 16 to
/// [`omni_model::limits::MAX_IMAGE_SIDE_PX`]; white background). The height follows the
/// cloud's extent, within the same bounds and at most 4 × the width.
pub fn render(points: &[Point3<f64>], width: u32, color: ColorBy) -> Picture {
    let max = omni_model::limits::MAX_IMAGE_SIDE_PX;
    let width = width.clamp(16, max);
    let (az, el) = ((-30.0f64).to_radians(), 25.0f64.to_radians());
    // Camera basis: right, up, and the viewing direction (into the screen).
    let view = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin());
    let right = Vector3::z().cross(&-view).normalize();
    let up = (-view).cross(&right).normalize();
    let proj: Vec<(f64, f64, f64)> =
        points.iter().map(|p| (p.coords.dot(&right), p.coords.dot(&up), p.coords.dot(&view))).collect();
    let value = |p: &Point3<f64>| match color {
        ColorBy::Height => p.z,
        ColorBy::Range => p.coords.norm(),
    };
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for (p, q) in points.iter().zip(&proj) {
        lo = lo.min(value(p));
        hi = hi.max(value(p));
        x0 = x0.min(q.0);
        x1 = x1.max(q.0);
        y0 = y0.min(q.1);
        y1 = y1.max(q.1);
    }
    let span = (x1 - x0).max(y1 - y0).max(1e-9);
    let margin = 0.05 * span;
    let scale = width as f64 / (x1 - x0 + 2.0 * margin).max(1e-9);
    let height = (((y1 - y0 + 2.0 * margin) * scale).ceil() as u32).clamp(16, (4 * width).min(max));
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| proj[b].2.total_cmp(&proj[a].2)); // far first
    let dot = (width / 400).max(1) as i64;
    for i in order {
        let (x, y, _) = proj[i];
        let px = ((x - x0 + margin) * scale) as i64;
        let py = height as i64 - 1 - ((y - y0 + margin) * scale) as i64;
        let c = ramp((value(&points[i]) - lo) / (hi - lo).max(1e-9));
        for dy in 0..dot {
            for dx in 0..dot {
                let (u, v) = (px + dx, py + dy);
                if u >= 0 && v >= 0 && (u as u32) < width && (v as u32) < height {
                    let k = ((v as u32 * width + u as u32) * 3) as usize;
                    rgb[k..k + 3].copy_from_slice(&c);
                }
            }
        }
    }
    Picture { width, height, rgb }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_points_in_colour_on_white() {
        let pts: Vec<_> = (0..1000).map(|i| Point3::new(500.0, (i % 40) as f64 * 5.0, (i / 40) as f64 * 5.0)).collect();
        let pic = render(&pts, 200, ColorBy::Height);
        assert_eq!(pic.rgb.len(), (pic.width * pic.height * 3) as usize);
        let coloured = pic.rgb.chunks(3).filter(|c| c != &[255, 255, 255]).count();
        assert!(coloured > 500, "{coloured} coloured pixels");
    }
}
