//! Steger's line detector (C. Steger, "An unbiased detector of curvilinear structures", PAMI
//! 1998), used only at the coarse stripe centre of each ray: the Hessian of the
//! Gaussian-smoothed image gives the stripe normal `n`, and a second-order Taylor expansion
//! along `n` gives the sub-pixel centreline point; its tangent line is then intersected with
//! the sampling ray, so the result is comparable with the 1-D estimators.

use super::{Frame, Pixel};

/// Sampled Gaussian derivative kernels (correlation weights) of one scale.
#[derive(Debug, Clone)]
pub struct Kernels {
    /// Half-size m: the kernels cover offsets −m..=m px.
    half: usize,
    g0: Vec<f64>,
    g1: Vec<f64>,
    g2: Vec<f64>,
}

impl Kernels {
    /// Kernels of scale `sigma` (px), normalised so that they measure the value, first and
    /// second derivative of a polynomial exactly.
    pub fn new(sigma: f64) -> Self {
        let half = (3.0 * sigma).ceil().max(1.0) as usize;
        let offs: Vec<f64> = (0..=2 * half).map(|i| i as f64 - half as f64).collect();
        let g: Vec<f64> = offs.iter().map(|x| (-x * x / (2.0 * sigma * sigma)).exp()).collect();
        let sum: f64 = g.iter().sum();
        let g0: Vec<f64> = g.iter().map(|v| v / sum).collect();
        // Correlation with x·G measures d/dx; scale so that f(x) = x gives 1.
        let g1_raw: Vec<f64> = offs.iter().zip(&g0).map(|(x, g)| x * g).collect();
        let s1: f64 = offs.iter().zip(&g1_raw).map(|(x, w)| x * w).sum();
        let g1 = g1_raw.iter().map(|w| w / s1).collect();
        // Second derivative: (x² − σ²)·G with zero sum; scale so that f(x) = x²/2 gives 1.
        let g2_raw: Vec<f64> = offs.iter().zip(&g0).map(|(x, g)| (x * x - sigma * sigma) * g).collect();
        let mean = g2_raw.iter().sum::<f64>() / g2_raw.len() as f64;
        let g2_zero: Vec<f64> = g2_raw.iter().map(|w| w - mean).collect();
        let s2: f64 = offs.iter().zip(&g2_zero).map(|(x, w)| 0.5 * x * x * w).sum();
        let g2 = g2_zero.iter().map(|w| w / s2).collect();
        Kernels { half, g0, g1, g2 }
    }

    /// Gradient and Hessian `(rx, ry, rxx, rxy, ryy)` of the smoothed image at pixel (x, y),
    /// or `None` if the kernel window leaves the image.
    fn derivatives<P: Pixel>(&self, f: &Frame<'_, P>, x: i64, y: i64) -> Option<[f64; 5]> {
        let m = self.half as i64;
        if x < m || y < m || x + m >= f.width as i64 || y + m >= f.height as i64 {
            return None;
        }
        let mut acc = [0.0; 5];
        for (j, yy) in (y - m..=y + m).enumerate() {
            // Row responses to the three horizontal kernels.
            let (mut h0, mut h1, mut h2) = (0.0, 0.0, 0.0);
            for (i, xx) in (x - m..=x + m).enumerate() {
                let v = f.at(xx as usize, yy as usize) as f64;
                h0 += v * self.g0[i];
                h1 += v * self.g1[i];
                h2 += v * self.g2[i];
            }
            acc[0] += self.g0[j] * h1;
            acc[1] += self.g1[j] * h0;
            acc[2] += self.g0[j] * h2;
            acc[3] += self.g1[j] * h1;
            acc[4] += self.g2[j] * h0;
        }
        Some(acc)
    }

    /// The centreline point near pixel (x, y): `(point, normal)`, or `None` if there is no
    /// bright line (no strongly negative curvature) there.
    fn centreline<P: Pixel>(&self, f: &Frame<'_, P>, x: i64, y: i64) -> Option<((f64, f64), (f64, f64))> {
        let [rx, ry, rxx, rxy, ryy] = self.derivatives(f, x, y)?;
        // Eigenvector of the most negative eigenvalue of [[rxx, rxy], [rxy, ryy]].
        let half_trace = 0.5 * (rxx + ryy);
        let disc = (0.25 * (rxx - ryy).powi(2) + rxy * rxy).sqrt();
        let lambda = half_trace - disc;
        if lambda >= 0.0 {
            return None;
        }
        let (nx, ny) = if rxy.abs() > 1e-12 {
            (lambda - ryy, rxy)
        } else if rxx < ryy {
            (1.0, 0.0)
        } else {
            (0.0, 1.0)
        };
        let norm = nx.hypot(ny);
        let (nx, ny) = (nx / norm, ny / norm);
        let t = -(rx * nx + ry * ny) / lambda;
        Some(((x as f64 + t * nx, y as f64 + t * ny), (nx, ny)))
    }

    /// Refines the coarse centre at radius `r` (px) on the ray from `centre` along unit `dir`:
    /// the ray's intersection with the stripe's local centreline, or `None` if the stripe runs
    /// nearly along the ray or the fit lands more than 1.5 px away.
    pub fn refine_along_ray<P: Pixel>(
        &self,
        f: &Frame<'_, P>,
        centre: (f64, f64),
        dir: (f64, f64),
        r: f64,
    ) -> Option<f64> {
        let (px, py) = (centre.0 + r * dir.0, centre.1 + r * dir.1);
        let (mut qx, mut qy) = (px.round() as i64, py.round() as i64);
        let mut fit = self.centreline(f, qx, qy)?;
        // One more evaluation at the pixel nearest the first estimate keeps the Taylor step small.
        let (cx, cy) = fit.0;
        if (cx - qx as f64).abs() > 0.5 || (cy - qy as f64).abs() > 0.5 {
            (qx, qy) = (cx.round() as i64, cy.round() as i64);
            fit = self.centreline(f, qx, qy)?;
        }
        let ((cx, cy), (nx, ny)) = fit;
        let along = nx * dir.0 + ny * dir.1;
        if along.abs() < 0.3 {
            return None;
        }
        let s = (nx * (cx - centre.0) + ny * (cy - centre.1)) / along;
        ((s - r).abs() <= 1.5).then_some(s)
    }
}
