//! Steger's line detector (C. Steger, "An unbiased detector of curvilinear structures", PAMI
//! 1998), used only in a band around each ray's coarse stripe centre: the image smoothed by a
//! Gaussian of scale σ is evaluated at sub-pixel positions (weights tabulated every 1/1024 px,
//! so no pixel rounding enters), its
//! Hessian gives the stripe normal `n`, and Newton steps along `n` converge to the ridge, the
//! maximum across the stripe. The ridge's tangent is then intersected with the sampling ray, so
//! the result is comparable with the 1-D estimators.

use super::{Frame, Pixel};

/// Newton steps at most; the start (a windowed centroid) is within a few hundredths of a pixel.
const MAX_STEPS: usize = 4;
/// Converged when a step is shorter than this (px).
const CONVERGED_PX: f64 = 1e-3;

/// Sub-pixel phases of the weight table (position quantised to 1/1024 px).
const LEVELS: usize = 1024;

/// The smoothing scale, the window it needs and its weights at every sub-pixel phase.
#[derive(Debug, Clone)]
pub struct Kernels {
    /// Taps on either side of floor(x): −half..=half+1.
    half: i64,
    /// Taps per axis (2·half + 2).
    taps: usize,
    /// `table[phase · 3 · taps + kind · taps + tap]`: value (kind 0), first (1) and second (2)
    /// derivative weights of the continuous Gaussian at the tap's offset from the position.
    table: Vec<f64>,
    /// `centred[k]`: the value, first and second derivative weights at offset +k px (k ≤ half)
    /// from a pixel centre; at −k the first is negated.
    centred: Vec<[f64; 3]>,
}

impl Kernels {
    /// Gaussian derivatives of scale `sigma` (px).
    pub fn new(sigma: f64) -> Self {
        Self::with_half((3.0 * sigma).ceil() as i64, sigma)
    }

    /// Gaussian derivatives of scale `sigma` (px) truncated `half` taps either side of the
    /// position.
    pub fn with_half(half: i64, sigma: f64) -> Self {
        let taps = 2 * half as usize + 2;
        let s2 = sigma * sigma;
        let norm = 1.0 / ((std::f64::consts::TAU).sqrt() * sigma);
        let mut table = vec![0.0; LEVELS * 3 * taps];
        for phase in 0..LEVELS {
            let f = phase as f64 / LEVELS as f64;
            for k in 0..taps {
                let d = (k as i64 - half) as f64 - f;
                let g = norm * (-d * d / (2.0 * s2)).exp();
                let base = phase * 3 * taps;
                table[base + k] = g;
                table[base + taps + k] = d / s2 * g;
                table[base + 2 * taps + k] = (d * d - s2) / (s2 * s2) * g;
            }
        }
        let centred =
            (0..=half as usize).map(|k| [0, 1, 2].map(|kind| table[kind * taps + half as usize + k])).collect();
        Kernels { half, taps, table, centred }
    }

    /// The first tap's coordinate and the value, first and second derivative weights of the
    /// taps around `x` (≥ 0).
    fn weights(&self, x: f64) -> (i64, &[f64], &[f64], &[f64]) {
        let xi = x as i64;
        let phase = (((x - xi as f64) * LEVELS as f64) as usize).min(LEVELS - 1);
        let w = &self.table[phase * 3 * self.taps..(phase + 1) * 3 * self.taps];
        let (w0, rest) = w.split_at(self.taps);
        let (w1, w2) = rest.split_at(self.taps);
        (xi - self.half, w0, w1, w2)
    }

    /// Gradient and Hessian `[rx, ry, rxx, rxy, ryy]` of the smoothed image at (x, y) px, or
    /// `None` if the window leaves the image.
    pub(super) fn derivatives<P: Pixel>(&self, f: &Frame<'_, P>, x: f64, y: f64) -> Option<[f64; 5]> {
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (x0, wx0, wx1, wx2) = self.weights(x);
        let (y0, wy0, wy1, wy2) = self.weights(y);
        let n = self.taps as i64;
        if x0 < 0 || y0 < 0 || x0 + n > f.width as i64 || y0 + n > f.height as i64 {
            return None;
        }
        let mut acc = [0.0; 5];
        let w = f.width as usize;
        for j in 0..self.taps {
            let row = &f.data[(y0 as usize + j) * w + x0 as usize..][..self.taps];
            let (mut h0, mut h1, mut h2) = (0.0, 0.0, 0.0);
            for (i, p) in row.iter().enumerate() {
                let v = p.to_f32() as f64;
                h0 += v * wx0[i];
                h1 += v * wx1[i];
                h2 += v * wx2[i];
            }
            acc[0] += wy0[j] * h1;
            acc[1] += wy1[j] * h0;
            acc[2] += wy0[j] * h2;
            acc[3] += wy1[j] * h1;
            acc[4] += wy2[j] * h0;
        }
        Some(acc)
    }

    /// [`Self::derivatives`] at the centre of pixel (x, y), over the ±half pixels around it (the
    /// kernel's symmetry halves the work), or `None` if they leave the image.
    pub(super) fn derivatives_at_pixel<P: Pixel>(&self, f: &Frame<'_, P>, x: usize, y: usize) -> Option<[f64; 5]> {
        let h = self.half as usize;
        let w = f.width as usize;
        if x < h || y < h || x + h >= w || y + h >= f.height as usize {
            return None;
        }
        let c = &self.centred;
        let mut acc = [0.0; 5];
        for j in 0..=2 * h {
            let row = &f.data[(y + j - h) * w + x - h..][..=2 * h];
            let v = |i: usize| row[i].to_f32() as f64;
            let centre = v(h);
            let (mut h0, mut h1, mut h2) = (c[0][0] * centre, 0.0, c[0][2] * centre);
            for (k, ck) in c.iter().enumerate().skip(1) {
                let (after, before) = (v(h + k), v(h - k));
                h0 += ck[0] * (after + before);
                h1 += ck[1] * (after - before);
                h2 += ck[2] * (after + before);
            }
            let cj = c[j.abs_diff(h)];
            let g1 = if j < h { -cj[1] } else { cj[1] };
            acc[0] += cj[0] * h1;
            acc[1] += g1 * h0;
            acc[2] += cj[0] * h2;
            acc[3] += g1 * h1;
            acc[4] += cj[2] * h0;
        }
        Some(acc)
    }

    /// The unit normal of a bright line (eigenvector of the Hessian's most negative eigenvalue)
    /// and that eigenvalue, or `None` where the image is not ridge-shaped.
    pub(super) fn normal(h: &[f64; 5]) -> Option<((f64, f64), f64)> {
        let [_, _, rxx, rxy, ryy] = *h;
        let half_trace = 0.5 * (rxx + ryy);
        let disc = (0.25 * (rxx - ryy).powi(2) + rxy * rxy).sqrt();
        let lambda = half_trace - disc;
        if lambda >= 0.0 {
            return None;
        }
        let (nx, ny) = if rxy.abs() > 1e-12 * (rxx.abs() + ryy.abs()) {
            (lambda - ryy, rxy)
        } else if rxx < ryy {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        // (Not `hypot`: a library call, and a Hessian's entries cannot overflow a square.)
        let norm = (nx * nx + ny * ny).sqrt();
        Some(((nx / norm, ny / norm), lambda))
    }

    /// Refines the coarse centre at radius `r` (px) on the ray from `centre` along unit `dir`:
    /// the ray's intersection with the tangent of the ridge of the smoothed image, or `None` if
    /// there is no ridge, the stripe runs nearly along the ray, or the fit moves > 1.5 px.
    pub fn refine_along_ray<P: Pixel>(
        &self,
        f: &Frame<'_, P>,
        centre: (f64, f64),
        dir: (f64, f64),
        r: f64,
    ) -> Option<f64> {
        let (mut x, mut y) = (centre.0 + r * dir.0, centre.1 + r * dir.1);
        let mut n = (0.0, 0.0);
        for _ in 0..MAX_STEPS {
            let h = self.derivatives(f, x, y)?;
            let (normal, lambda) = Self::normal(&h)?;
            n = normal;
            let t = -(h[0] * n.0 + h[1] * n.1) / lambda;
            x += t * n.0;
            y += t * n.1;
            if t.abs() < CONVERGED_PX {
                break;
            }
        }
        let along = n.0 * dir.0 + n.1 * dir.1;
        if along.abs() < 0.3 {
            return None;
        }
        let s = (n.0 * (x - centre.0) + n.1 * (y - centre.1)) / along;
        ((s - r).abs() <= 1.5).then_some(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivatives_at_a_pixel_centre_match_the_sub_pixel_ones() {
        let (w, h) = (24u32, 20u32);
        let img: Vec<u16> = (0..w * h).map(|i| (i.wrapping_mul(2_654_435_761) % 4001) as u16).collect();
        let f = Frame { width: w, height: h, data: &img, max_value: 65535.0 };
        let k = Kernels::with_half(3, 1.0);
        for (x, y) in [(3, 3), (10, 7), (16, 12)] {
            let centred = k.derivatives_at_pixel(&f, x, y).unwrap();
            let general = k.derivatives(&f, x as f64, y as f64).unwrap();
            // The general kernel has one more tap, 4σ away on the + side: its second-derivative
            // weight is 15·e⁻⁸/√(2π) ≈ 0.002 of the pixels' values (≤ 4000); a wrong sign or tap
            // would be off by hundreds.
            for (a, b) in centred.iter().zip(&general) {
                assert!((a - b).abs() < 2.5e-3 * 4000.0, "({x}, {y}): {centred:?} against {general:?}");
            }
        }
        assert!(k.derivatives_at_pixel(&f, 2, 10).is_none() && k.derivatives_at_pixel(&f, 10, 17).is_none());
    }

    #[test]
    fn converges_to_a_straight_lines_centre_from_a_pixel_away() {
        // A line at 30° to the columns: centre x = 15.37 + (y − 15)·tan 30°, σ = 0.8 px.
        let (w, h) = (32u32, 32u32);
        let tan = 30f64.to_radians().tan();
        let cos = 30f64.to_radians().cos();
        let img: Vec<u16> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let d = (x - 15.37 - (y - 15.0) * tan) * cos;
                (40000.0 * (-d * d / (2.0 * 0.64)).exp()) as u16
            })
            .collect();
        let f = Frame { width: w, height: h, data: &img, max_value: 65535.0 };
        let k = Kernels::new(1.0);
        // Ray along +x through (0, 15): the line crosses it at x = 15.37.
        for start in [14.6, 15.0, 15.9] {
            let s = k.refine_along_ray(&f, (0.0, 15.0), (1.0, 0.0), start).unwrap();
            assert!((s - 15.37).abs() < 0.003, "from {start}: {s}");
        }
    }
}
