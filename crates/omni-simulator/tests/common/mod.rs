//! Helpers shared by the simulator's integration tests.

use omni_geom::Vector2;
use omni_simulator::TruthPoint;

/// Bilinear intensity centroid of the stripe profile along `dir` (unit) through the truth pixel:
/// its offset (px) from the truth pixel, from samples within ±4 px.
pub fn centroid_along(img: &[f64], w: u32, h: u32, t: &TruthPoint, dir: Vector2<f64>) -> Option<f64> {
    centroid_within(img, w, h, t, dir, 4.0)
}

/// As [`centroid_along`], from samples within ±`reach_px` (0.1 px apart): wide or defocused
/// stripes need more than ±4 px.
#[allow(dead_code)] // used by some of the test binaries that include this module
pub fn centroid_within(img: &[f64], w: u32, h: u32, t: &TruthPoint, dir: Vector2<f64>, reach_px: f64) -> Option<f64> {
    let p = Vector2::from(t.pixel);
    let at = |q: Vector2<f64>| bilinear(img, w, h, q);
    let steps = (10.0 * reach_px).round() as i32;
    let offsets: Vec<f64> = (-steps..=steps).map(|i| i as f64 * 0.1).collect();
    let values: Vec<f64> = offsets.iter().map(|s| at(p + dir * *s)).collect::<Option<_>>()?;
    let peak = values.iter().cloned().fold(0.0, f64::max);
    if peak < 20.0 {
        return None;
    }
    // Only the connected run around the peak above 5 % of it (another stripe may be near).
    let thr = 0.05 * peak;
    let k = values.iter().position(|v| *v == peak)?;
    let (mut a, mut b) = (k, k);
    while a > 0 && values[a - 1] > thr {
        a -= 1;
    }
    while b + 1 < values.len() && values[b + 1] > thr {
        b += 1;
    }
    if a == 0 || b + 1 == values.len() {
        return None; // profile cut by the sampling window
    }
    let (sw, swx) =
        (a..=b).fold((0.0, 0.0), |(sw, swx), i| (sw + values[i] - thr, swx + (values[i] - thr) * offsets[i]));
    Some(swx / sw)
}

/// Rms width (px) of the intensity profile along `dir` (unit) within ±5 px of the truth pixel;
/// `None` near the image border or on a dark profile.
#[allow(dead_code)] // used by some of the test binaries that include this module
pub fn width_along(img: &[f64], w: u32, h: u32, t: &TruthPoint, dir: Vector2<f64>) -> Option<f64> {
    let p = Vector2::from(t.pixel);
    let (mut s0, mut s1, mut s2) = (0.0, 0.0, 0.0);
    for i in -100..=100 {
        let s = i as f64 * 0.05;
        let v = bilinear(img, w, h, p + dir * s)?;
        (s0, s1, s2) = (s0 + v, s1 + v * s, s2 + v * s * s);
    }
    if s0 <= 0.0 {
        return None;
    }
    let mean = s1 / s0;
    Some((s2 / s0 - mean * mean).sqrt())
}

/// Bilinear interpolation of `img` at `q`; `None` outside the image.
fn bilinear(img: &[f64], w: u32, h: u32, q: Vector2<f64>) -> Option<f64> {
    if !(q.x >= 0.0 && q.y >= 0.0 && q.x <= (w - 1) as f64 && q.y <= (h - 1) as f64) {
        return None;
    }
    let (x0, y0) = (q.x.floor() as usize, q.y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w as usize - 1), (y0 + 1).min(h as usize - 1));
    let (fx, fy) = (q.x - x0 as f64, q.y - y0 as f64);
    let g = |x: usize, y: usize| img[y * w as usize + x];
    Some((1.0 - fy) * ((1.0 - fx) * g(x0, y0) + fx * g(x1, y0)) + fy * ((1.0 - fx) * g(x0, y1) + fx * g(x1, y1)))
}
