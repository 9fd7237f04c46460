//! The lens's blur measured on a checkerboard's edges.
//!
//! Between two neighbouring corners the board's edge is a step from a black square to a white
//! one, which the lens images as the step convolved with its PSF and each pixel's area. The
//! pixels near the middle of the edge (away from the corners' X-junctions), as a function of
//! their distance d from the line through the two corners, follow a + b·Φ((d − d₀)/s): an
//! error-function edge whose s² is the PSF's variance across the edge plus a pixel's (1/12 px²,
//! a unit square's variance along any direction). Fitting the pixels themselves, not an
//! interpolated profile, adds no interpolation blur. The result is the PSF's σ in px, as
//! `omni-ridge --optics-blur` takes it.

use super::{BoardCorners, GrayF32};
use crate::PIXEL_AREA_VARIANCE_PX2;
use omni_geom::lm::{self, Problem};
/// Shortest edge (px between its corners) measured: the next parallel edge must lie beyond the
/// pixels fitted, and the X-junctions at its ends away from them.
const MIN_EDGE_PX: f64 = 12.0;
/// The part of the edge measured, from its middle, as a fraction of its length either way.
const ALONG_FRACTION: f64 = 0.25;
/// Pixels up to this far (px) from the edge are fitted, at most a third of the edge's length.
const ACROSS_PX: f64 = 6.0;
/// Fewest pixels in a fit.
const MIN_PIXELS: usize = 24;

/// The blur of one image's board edges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeBlur {
    /// The lens's PSF σ (px), the pixel's area removed: the median over the edges.
    pub sigma_px: f64,
    /// Edges measured.
    pub edges: usize,
}

/// The lens's blur on the edges between `board`'s neighbouring corners in `img`; `None` if no
/// edge could be measured (too short, too little contrast, a fit that failed).
pub fn edge_blur(img: &GrayF32, board: &BoardCorners) -> Option<EdgeBlur> {
    let at: std::collections::HashMap<[u32; 2], [f64; 2]> = board.corners.iter().map(|c| (c.index, c.px)).collect();
    let brightest = img.data.iter().fold(0.0f32, |m, &v| m.max(v)) as f64;
    let mut sigmas: Vec<f64> = board
        .corners
        .iter()
        .flat_map(|c| [[c.index[0] + 1, c.index[1]], [c.index[0], c.index[1] + 1]].map(|n| (c.px, at.get(&n).copied())))
        .filter_map(|(a, b)| edge_sigma(img, brightest, a, b?))
        .collect();
    if sigmas.is_empty() {
        return None;
    }
    let mid = sigmas.len() / 2;
    let sigma_px = *sigmas.select_nth_unstable_by(mid, f64::total_cmp).1;
    Some(EdgeBlur { sigma_px, edges: sigmas.len() })
}

/// The PSF σ (px) on the edge between corners `a` and `b`, or `None`; `brightest` is the image's
/// largest sample.
fn edge_sigma(img: &GrayF32, brightest: f64, a: [f64; 2], b: [f64; 2]) -> Option<f64> {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let length = dx.hypot(dy);
    if length < MIN_EDGE_PX {
        return None;
    }
    let (tx, ty) = (dx / length, dy / length);
    let (nx, ny) = (-ty, tx);
    let (mx, my) = (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]));
    let along = ALONG_FRACTION * length;
    let across = ACROSS_PX.min(length / 3.0);
    let reach = along.hypot(across).ceil() as isize;
    let (x0, y0) = (mx.round() as isize, my.round() as isize);
    let mut samples = Vec::new();
    for y in y0 - reach..=y0 + reach {
        for x in x0 - reach..=x0 + reach {
            if x < 0 || y < 0 || x as usize >= img.width || y as usize >= img.height {
                continue;
            }
            let (ex, ey) = (x as f64 - mx, y as f64 - my);
            let (t, d) = (ex * tx + ey * ty, ex * nx + ey * ny);
            if t.abs() <= along && d.abs() <= across {
                samples.push((d, img.data[y as usize * img.width + x as usize] as f64));
            }
        }
    }
    if samples.len() < MIN_PIXELS {
        return None;
    }
    let mean_on = |side: f64| {
        let v: Vec<f64> = samples.iter().filter(|s| s.0 * side > 2.0).map(|s| s.1).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    let (dark, light) = (mean_on(-1.0)?, mean_on(1.0)?);
    let step = light - dark;
    // A faint step (a board seen edge-on, a shadow) or a clipped one (at 255, the full scale of
    // the detector's images) says nothing of the lens.
    if step.abs() < 0.1 * brightest || samples.iter().any(|s| s.1 >= 255.0) {
        return None;
    }
    let fit = lm::minimize(&EdgeFit { samples: &samples }, &[dark, step, 0.0, 1.0], &lm::Options::default());
    let [_, _, offset, s] = fit.params[..] else { return None };
    let s = s.abs();
    let variance = s * s - PIXEL_AREA_VARIANCE_PX2;
    (fit.converged && offset.abs() <= 1.5 && (0.3..=across / 2.0).contains(&s) && variance > 0.0)
        .then(|| variance.sqrt())
}

/// Pixels (distance from the edge, value) against a + b·Φ((d − d₀)/s), parameters [a, b, d₀, s].
struct EdgeFit<'a> {
    samples: &'a [(f64, f64)],
}

impl Problem for EdgeFit<'_> {
    fn num_params(&self) -> usize {
        4
    }

    fn num_residuals(&self) -> usize {
        self.samples.len()
    }

    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        let s = p[3].abs().max(1e-6);
        for (o, &(d, v)) in out.iter_mut().zip(self.samples) {
            let phi = 0.5 * (1.0 + omni_geom::erf((d - p[2]) / (s * std::f64::consts::SQRT_2)));
            *o = p[0] + p[1] * phi - v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corners::{BoardCorner, Orientation};

    /// A board of `square` px squares turned by `angle`, its edges blurred by a Gaussian of σ
    /// `sigma` and each pixel's area (a 16 × 16 supersampled box), 40 / 200 levels.
    fn board_image(square: f64, angle: f64, sigma: f64) -> (GrayF32, BoardCorners) {
        let (w, h) = (160usize, 160usize);
        let (c, s) = (angle.cos(), angle.sin());
        let origin = (80.3, 79.6);
        let phi = |x: f64| 0.5 * (1.0 + omni_geom::erf(x / (sigma * std::f64::consts::SQRT_2)));
        let mut img = GrayF32::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let mut sum = 0.0;
                for k in 0..256 {
                    let (sx, sy) = (
                        x as f64 + ((k % 16) as f64 + 0.5) / 16.0 - 0.5,
                        y as f64 + ((k / 16) as f64 + 0.5) / 16.0 - 0.5,
                    );
                    let (ex, ey) = (sx - origin.0, sy - origin.1);
                    let (u, v) = ((ex * c + ey * s) / square, (-ex * s + ey * c) / square);
                    // Distance (px) to the nearest grid line in u and in v, signed by the square's side.
                    let (fu, fv) = (u - u.round(), v - v.round());
                    let white_u = if (u.round() as i64).rem_euclid(2) == 0 { fu } else { -fu };
                    let white_v = if (v.round() as i64).rem_euclid(2) == 0 { fv } else { -fv };
                    // A checker is the product of the two steps' signs; blurred, each step is Φ.
                    let pu = 2.0 * phi(white_u * square) - 1.0;
                    let pv = 2.0 * phi(white_v * square) - 1.0;
                    sum += 120.0 + 80.0 * pu * pv;
                }
                img.data[y * w + x] = (sum / 256.0) as f32;
            }
        }
        let mut corners = Vec::new();
        for j in -2i32..=2 {
            for i in -2i32..=2 {
                let (u, v) = (i as f64 * square, j as f64 * square);
                let px = [origin.0 + u * c - v * s, origin.1 + u * s + v * c];
                corners.push(BoardCorner { index: [(i + 2) as u32, (j + 2) as u32], px });
            }
        }
        let board = BoardCorners { cols: 5, rows: 5, corners, orientation: Orientation::Unique, seen_size: None };
        (img, board)
    }

    /// Measured 0.7011 / 1.2001 / 0.4546 px.
    #[test]
    fn the_lens_blur_is_read_off_the_board_edges() {
        for (sigma, angle) in [(0.7, 0.3), (1.2, -0.5), (0.45, 0.1)] {
            let (img, board) = board_image(20.0, angle, sigma);
            let blur = edge_blur(&img, &board).unwrap();
            assert!(blur.edges >= 30, "{blur:?}");
            assert!((blur.sigma_px - sigma).abs() <= 0.03 * sigma, "σ {sigma}: {blur:?}");
        }
    }

    #[test]
    fn short_edges_and_flat_images_give_no_blur() {
        let (img, board) = board_image(10.0, 0.2, 0.7);
        assert_eq!(edge_blur(&img, &board), None);
        let (_, board) = board_image(20.0, 0.2, 0.7);
        let flat = GrayF32 { width: 160, height: 160, data: vec![100.0; 160 * 160] };
        assert_eq!(edge_blur(&flat, &board), None);
    }
}
