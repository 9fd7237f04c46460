//! X-junction (saddle point) candidates and their sub-pixel refinement.
//!
//! Response: the negative Hessian determinant of the Gaussian-smoothed image,
//! R = I_xy² − I_xx·I_yy, which is positive at saddle points (checkerboard corners), negative at
//! blobs and near zero along straight edges. Each local maximum is then checked on a circle
//! around it: an X-junction crosses exactly four dark/bright boundaries, two by two nearly
//! opposite; those crossings give the directions of its two edge lines.

use super::gray::{GrayF32, gaussian_blur};
use std::f64::consts::PI;

/// A corner candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// Position (px, image frame: x right, y down).
    pub px: [f64; 2],
    /// Saddle response (grey levels² / px⁴ at the detection scale).
    pub response: f32,
    /// Directions of the two edge lines through the corner (radians, in [0, π)).
    pub lines: [f64; 2],
    /// Grey-level contrast seen on the test circle.
    pub contrast: f32,
}

/// Tunables of the candidate search; the defaults work for 8-bit images with squares of 6–80 px.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SaddleOptions {
    /// Smoothing scale of the response (px).
    pub sigma: f64,
    /// Keep maxima above this fraction of the strongest response.
    pub relative_threshold: f32,
    /// Minimum grey-level contrast on the test circle (0–255 scale).
    pub min_contrast: f32,
    /// Radii (px) of the test circles; a candidate passes if any circle shows an X-junction.
    pub circle_radii: [f64; 2],
}

impl Default for SaddleOptions {
    fn default() -> Self {
        SaddleOptions { sigma: 1.5, relative_threshold: 0.003, min_contrast: 12.0, circle_radii: [4.0, 6.5] }
    }
}

/// Negative Hessian determinant of an already smoothed image (central differences).
pub fn saddle_response(smooth: &GrayF32) -> GrayF32 {
    let (w, h) = (smooth.width, smooth.height);
    let mut out = GrayF32::new(w, h);
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let (xi, yi) = (x as isize, y as isize);
            let c = smooth.at(xi, yi);
            let ixx = smooth.at(xi + 1, yi) - 2.0 * c + smooth.at(xi - 1, yi);
            let iyy = smooth.at(xi, yi + 1) - 2.0 * c + smooth.at(xi, yi - 1);
            let ixy = 0.25
                * (smooth.at(xi + 1, yi + 1) - smooth.at(xi + 1, yi - 1) - smooth.at(xi - 1, yi + 1)
                    + smooth.at(xi - 1, yi - 1));
            out.data[y * w + x] = ixy * ixy - ixx * iyy;
        }
    }
    out
}

/// Finds X-junction candidates in `img` (optionally only where `mask(x, y)` is true).
pub fn find_candidates(img: &GrayF32, opts: &SaddleOptions, mask: &dyn Fn(f64, f64) -> bool) -> Vec<Candidate> {
    let smooth = gaussian_blur(img, opts.sigma);
    let resp = saddle_response(&smooth);
    let max = resp.data.iter().cloned().fold(0.0f32, f32::max);
    if max <= 0.0 {
        return Vec::new();
    }
    let threshold = max * opts.relative_threshold;
    let (w, h) = (img.width, img.height);
    let nms = 2isize;
    let mut out = Vec::new();
    for y in 3..h.saturating_sub(3) {
        for x in 3..w.saturating_sub(3) {
            let r = resp.data[y * w + x];
            if r <= threshold || !mask(x as f64, y as f64) {
                continue;
            }
            if !is_local_max(&resp, x as isize, y as isize, nms) {
                continue;
            }
            let (dx, dy) = quadratic_peak_offset(&resp, x as isize, y as isize);
            let p = [x as f64 + dx, y as f64 + dy];
            let test = opts.circle_radii.iter().find_map(|&radius| circle_test(&smooth, p, radius, opts.min_contrast));
            if let Some((lines, contrast)) = test {
                out.push(Candidate { px: p, response: r, lines, contrast });
            }
        }
    }
    out
}

fn is_local_max(resp: &GrayF32, x: isize, y: isize, radius: isize) -> bool {
    let r = resp.at(x, y);
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            if dx == 0 && dy == 0 {
                continue;
            }
            let o = resp.at(x + dx, y + dy);
            // Ties are broken by scan order so that a plateau yields one maximum.
            if o > r || (o == r && (dy < 0 || (dy == 0 && dx < 0))) {
                return false;
            }
        }
    }
    true
}

/// Sub-pixel offset of a 3×3 peak from a separable parabola fit (clamped to ±0.5 px).
fn quadratic_peak_offset(resp: &GrayF32, x: isize, y: isize) -> (f64, f64) {
    let c = resp.at(x, y) as f64;
    let fit = |m: f64, p: f64| {
        let d = m - 2.0 * c + p;
        if d < 0.0 { (0.5 * (m - p) / d).clamp(-0.5, 0.5) } else { 0.0 }
    };
    (fit(resp.at(x - 1, y) as f64, resp.at(x + 1, y) as f64), fit(resp.at(x, y - 1) as f64, resp.at(x, y + 1) as f64))
}

/// Samples a circle around `p`; returns the two edge-line directions and the contrast if the
/// circle shows exactly four bright/dark transitions that pair up into two lines.
pub fn circle_test(smooth: &GrayF32, p: [f64; 2], radius: f64, min_contrast: f32) -> Option<([f64; 2], f32)> {
    const N: usize = 48;
    if !smooth.inside(p[0], p[1], radius + 1.0) {
        return None;
    }
    let samples: Vec<f32> = (0..N)
        .map(|k| {
            let a = 2.0 * PI * k as f64 / N as f64;
            smooth.bilinear(p[0] + radius * a.cos(), p[1] + radius * a.sin())
        })
        .collect();
    let lo = samples.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = samples.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    if hi - lo < min_contrast {
        return None;
    }
    let mid = 0.5 * (lo + hi);
    // Transition angles by linear interpolation of the crossing of `mid`.
    let mut crossings = Vec::with_capacity(4);
    for k in 0..N {
        let a = samples[k] - mid;
        let b = samples[(k + 1) % N] - mid;
        if (a >= 0.0) != (b >= 0.0) {
            let t = a / (a - b);
            crossings.push(2.0 * PI * (k as f64 + t as f64) / N as f64);
        }
    }
    if crossings.len() != 4 {
        return None;
    }
    // Each sector between crossings must span a few samples (not noise flicker).
    for k in 0..4 {
        let span = (crossings[(k + 1) % 4] - crossings[k]).rem_euclid(2.0 * PI);
        if span < 0.25 {
            return None;
        }
    }
    // Opposite crossings lie on one line through the corner.
    let mut lines = [0.0; 2];
    for k in 0..2 {
        let a = crossings[k];
        let b = crossings[k + 2];
        let gap = (b - a).rem_euclid(2.0 * PI);
        if (gap - PI).abs() > 0.7 {
            return None;
        }
        lines[k] = axial_mean(a, b - PI);
    }
    if axial_difference(lines[0], lines[1]) < 0.3 {
        return None;
    }
    Some((lines, hi - lo))
}

/// Mean of two directions given as angles, taken as lines (mod π), result in [0, π).
pub fn axial_mean(a: f64, b: f64) -> f64 {
    let (s, c) = ((2.0 * a).sin() + (2.0 * b).sin(), (2.0 * a).cos() + (2.0 * b).cos());
    (0.5 * s.atan2(c)).rem_euclid(PI)
}

/// Unsigned angle between two lines (radians, in [0, π/2]).
pub fn axial_difference(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(PI);
    d.min(PI - d)
}

/// Refines a corner to sub-pixel precision by gradient orthogonality (as OpenCV's
/// `cornerSubPix`): every gradient in a window around an X-junction is orthogonal to the vector
/// from the corner to its pixel, so the corner solves Σ w·g·gᵀ·(q − p) = 0 over the
/// `window_samples`. `half_window` in px (a circular window). Returns `None` if the system is
/// singular or the corner drifts more than `half_window`.
pub fn refine_corner(grad_img: &GrayF32, start: [f64; 2], half_window: f64) -> Option<[f64; 2]> {
    refine_corner_spread(grad_img, start, &Window::circle(half_window)).map(|(p, _)| p)
}

/// The refinement window: the offsets o (px, pixel − corner) with |S·o| ≤ 1, an ellipse (a
/// circle of radius r when S = I/r). Shaped by the local grid ([`Window::grid`]) it covers the
/// same fraction of each of the four squares around the corner however the image stretches and
/// skews them; a circle fitted to the shortest step covers only part of the longer squares and,
/// on a skewed grid, reaches the far edges of the squares in the acute angles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// Image offset → window coordinates (row-major 2 × 2).
    pub shape: [[f64; 2]; 2],
}

impl Window {
    /// A circle of radius `half_window` px (at least 1.5 px).
    pub fn circle(half_window: f64) -> Window {
        let r = half_window.max(1.5);
        Window { shape: [[1.0 / r, 0.0], [0.0, 1.0 / r]] }
    }

    /// The ellipse spanned by the two grid steps `e1`, `e2` (px vectors from the corner towards
    /// its neighbours along the two grid lines) times `fraction`: o = fraction·(u·e1 + v·e2) with
    /// u² + v² ≤ 1. `None` if the steps are (nearly) parallel.
    pub fn grid(e1: [f64; 2], e2: [f64; 2], fraction: f64) -> Option<Window> {
        let (a, b, c, d) = (fraction * e1[0], fraction * e2[0], fraction * e1[1], fraction * e2[1]);
        let det = a * d - b * c;
        let scale = (e1[0].hypot(e1[1]) * e2[0].hypot(e2[1])).max(1e-300) * fraction * fraction;
        if !(det.abs() > 0.2 * scale) {
            return None;
        }
        Some(Window { shape: [[d / det, -b / det], [-c / det, a / det]] })
    }

    /// The same window scaled by `k` about the corner.
    pub fn scaled(&self, k: f64) -> Window {
        let s = self.shape;
        Window { shape: [[s[0][0] / k, s[0][1] / k], [s[1][0] / k, s[1][1] / k]] }
    }

    /// The window's semi-axes (px): (shortest, longest).
    pub fn semi_axes(&self) -> (f64, f64) {
        // Singular values of S; the semi-axes are their inverses.
        let s = self.shape;
        let (p, q) = (s[0][0] * s[0][0] + s[1][0] * s[1][0], s[0][1] * s[0][1] + s[1][1] * s[1][1]);
        let r = s[0][0] * s[0][1] + s[1][0] * s[1][1];
        let mean = 0.5 * (p + q);
        let dev = (0.25 * (p - q) * (p - q) + r * r).sqrt();
        let (big, small) = (mean + dev, (mean - dev).max(1e-300));
        (1.0 / big.sqrt(), 1.0 / small.sqrt())
    }

    /// How far the window reaches along the unit direction `n` (px): |S⁻ᵀ·n|.
    pub fn reach(&self, n: [f64; 2]) -> f64 {
        let s = self.shape;
        let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
        // S⁻¹ = [[s11, −s01], [−s10, s00]] / det; its transpose applied to n.
        let x = (s[1][1] * n[0] - s[1][0] * n[1]) / det;
        let y = (-s[0][1] * n[0] + s[0][0] * n[1]) / det;
        x.hypot(y)
    }

    /// |S·o|: 1 on the window's boundary.
    pub fn radius(&self, o: [f64; 2]) -> f64 {
        let s = self.shape;
        (s[0][0] * o[0] + s[0][1] * o[1]).hypot(s[1][0] * o[0] + s[1][1] * o[1])
    }
}

/// [`refine_corner`] in `window`, and the spread of its solution (px²): the trace of the
/// sandwich covariance A⁻¹·(Σ w²·e²·g·gᵀ)·A⁻¹, where e = gᵀ(pixel − q) is each sample's misfit.
/// It grows with the image noise and with everything the model of two straight edges through the
/// corner does not explain (a neighbouring square's edge entering the window, curvature, an
/// uneven blur), so it compares windows of different sizes on the same corner.
pub fn refine_corner_spread(grad_img: &GrayF32, start: [f64; 2], window: &Window) -> Option<([f64; 2], f64)> {
    let mut p = start;
    for _ in 0..30 {
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for s in window_samples(grad_img, p, window) {
            let ([ox, oy], [gx, gy], w) = (s.offset, s.gradient, s.weight);
            let (gxx, gxy, gyy) = (w * gx * gx, w * gx * gy, w * gy * gy);
            a11 += gxx;
            a12 += gxy;
            a22 += gyy;
            // Offsets from p keep the sums small (p is added back below).
            b1 += gxx * ox + gxy * oy;
            b2 += gxy * ox + gyy * oy;
        }
        let det = a11 * a22 - a12 * a12;
        if !(det.abs() > 1e-9 * (a11 + a22).powi(2).max(1e-30)) {
            return None;
        }
        let dx = (a22 * b1 - a12 * b2) / det;
        let dy = (a11 * b2 - a12 * b1) / det;
        p = [p[0] + dx, p[1] + dy];
        if window.radius([p[0] - start[0], p[1] - start[1]]) > 1.0 {
            return None;
        }
        if dx.hypot(dy) < 1e-4 {
            break;
        }
    }
    Some((p, solution_spread(grad_img, p, window)?))
}

/// The sandwich covariance trace (px²) of the gradient-orthogonality solution at `p`.
fn solution_spread(img: &GrayF32, p: [f64; 2], window: &Window) -> Option<f64> {
    let (mut a, mut m) = (nalgebra::Matrix2::<f64>::zeros(), nalgebra::Matrix2::<f64>::zeros());
    for s in window_samples(img, p, window) {
        let g = nalgebra::Vector2::from(s.gradient);
        let e = g.dot(&nalgebra::Vector2::from(s.offset));
        a += s.weight * g * g.transpose();
        m += (s.weight * e).powi(2) * g * g.transpose();
    }
    let inv = a.try_inverse()?;
    Some((inv * m * inv).trace())
}

/// One gradient sample of the refinement window.
#[derive(Debug, Clone, Copy)]
pub(crate) struct WindowSample {
    /// Pixel centre − corner (px).
    pub offset: [f64; 2],
    /// Image gradient at the pixel (central differences, grey levels per px).
    pub gradient: [f64; 2],
    pub weight: f64,
}

/// The Gaussian weight's σ in the refinement window, as a fraction of the window's radius.
const WEIGHT_SIGMA: f64 = 0.6;

/// The refinement window around `p`: every pixel inside `window` (see [`Window`]), with its
/// gradient from the pixel values themselves and a Gaussian weight (σ = [`WEIGHT_SIGMA`] × the
/// window's radius in each direction) tapered to zero over the last pixel.
///
/// The samples sit on the pixel grid, not at `p` + integer offsets: interpolated samples share
/// `p`'s sub-pixel phase, and bilinear interpolation smooths the image by an amount that depends
/// on that phase, which gives every corner an error that follows its phase coherently. The taper
/// keeps the sums continuous in `p` as pixels enter and leave the window.
pub(crate) fn window_samples<'a>(
    img: &'a GrayF32,
    p: [f64; 2],
    window: &Window,
) -> impl Iterator<Item = WindowSample> + use<'a> {
    let window = *window;
    let r = window.semi_axes().1.ceil() as isize + 1;
    let (x0, y0) = (p[0].round() as isize, p[1].round() as isize);
    (-r..=r).flat_map(move |dy| (-r..=r).map(move |dx| (x0 + dx, y0 + dy))).filter_map(move |(x, y)| {
        let offset = [x as f64 - p[0], y as f64 - p[1]];
        let rho = window.radius(offset);
        // Distance (px) from the pixel to the window's boundary along the ray from the corner.
        let to_edge = if rho > 1e-12 { (1.0 / rho - 1.0) * offset[0].hypot(offset[1]) } else { f64::INFINITY };
        let taper = (to_edge + 0.5).clamp(0.0, 1.0);
        if taper <= 0.0 {
            return None;
        }
        let gx = 0.5 * (img.at(x + 1, y) - img.at(x - 1, y)) as f64;
        let gy = 0.5 * (img.at(x, y + 1) - img.at(x, y - 1)) as f64;
        let weight = taper * (-rho * rho / (2.0 * WEIGHT_SIGMA * WEIGHT_SIGMA)).exp();
        Some(WindowSample { offset, gradient: [gx, gy], weight })
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A `w`×`h` image whose pixel (x, y) is the mean of `value` over n × n points spread evenly
    /// inside it (a camera integrates over the pixel), `value` taking coordinates relative to
    /// (cx, cy) in px.
    pub(crate) fn supersampled(
        w: usize,
        h: usize,
        n: usize,
        (cx, cy): (f64, f64),
        value: impl Fn(f64, f64) -> f32,
    ) -> GrayF32 {
        let mut img = GrayF32::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for sy in 0..n {
                    for sx in 0..n {
                        let px = x as f64 - 0.5 + (sx as f64 + 0.5) / n as f64 - cx;
                        let py = y as f64 - 0.5 + (sy as f64 + 0.5) / n as f64 - cy;
                        acc += value(px, py);
                    }
                }
                img.data[y * w + x] = acc / (n * n) as f32;
            }
        }
        img
    }

    /// An anti-aliased checkerboard X-junction at (cx, cy) with edges at angles a1, a2 (rad),
    /// rendered by 16×16 supersampling: the ground truth for sub-pixel tests.
    pub(crate) fn synthetic_corner(w: usize, h: usize, cx: f64, cy: f64, a1: f64, a2: f64) -> GrayF32 {
        let (n1, n2) = ([-a1.sin(), a1.cos()], [-a2.sin(), a2.cos()]);
        supersampled(w, h, 16, (cx, cy), |px, py| {
            let s1 = px * n1[0] + py * n1[1] >= 0.0;
            let s2 = px * n2[0] + py * n2[1] >= 0.0;
            if s1 == s2 { 200.0 } else { 40.0 }
        })
    }

    #[test]
    fn finds_and_refines_a_rotated_skewed_corner_to_five_hundredths_of_a_pixel() {
        for &(cx, cy, a1, a2) in &[(20.3, 19.7, 0.3, 1.9), (21.45, 20.05, 1.0, 2.2), (19.9, 20.6, 0.05, 1.5)] {
            let img = gaussian_blur(&synthetic_corner(41, 41, cx, cy, a1, a2), 0.8);
            let cands = find_candidates(&img, &SaddleOptions::default(), &|_, _| true);
            assert_eq!(cands.len(), 1, "{cands:?}");
            let c = cands[0];
            assert!((c.px[0] - cx).abs() < 1.0 && (c.px[1] - cy).abs() < 1.0, "{c:?}");
            let found = [
                axial_difference(c.lines[0], a1).min(axial_difference(c.lines[1], a1)),
                axial_difference(c.lines[0], a2).min(axial_difference(c.lines[1], a2)),
            ];
            assert!(found[0] < 0.1 && found[1] < 0.1, "lines {:?} vs {a1} {a2}", c.lines);
            let p = refine_corner(&gaussian_blur(&img, 0.7), c.px, 5.0).unwrap();
            let err = ((p[0] - cx).powi(2) + (p[1] - cy).powi(2)).sqrt();
            assert!(err < 0.05, "refined {p:?} vs ({cx}, {cy}): {err} px");
        }
    }

    #[test]
    fn edges_and_blobs_are_not_corners() {
        let mut img = GrayF32::new(40, 40);
        for y in 0..40 {
            for x in 0..40 {
                let edge = if x > 20 { 200.0 } else { 30.0 };
                let blob = if (x as f64 - 8.0).powi(2) + (y as f64 - 30.0).powi(2) < 9.0 { 150.0 } else { 0.0 };
                img.data[y * 40 + x] = edge + blob;
            }
        }
        let found = find_candidates(&img, &SaddleOptions::default(), &|_, _| true);
        assert!(found.is_empty(), "{found:?}");
    }
}
