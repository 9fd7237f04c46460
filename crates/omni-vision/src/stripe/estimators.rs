//! One-dimensional peak estimators on a profile sampled across the stripe.
//!
//! A profile is `p[k]`, the intensity at position `k · step` (px) along the sampling ray. Each
//! estimator returns the stripe centre as a fractional sample index (multiply by the step to get
//! px), or `None` if the segment does not allow a fit.

/// One run of samples above the threshold: `start..end` (end exclusive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub start: usize,
    pub end: usize,
    /// Index of the brightest sample.
    pub peak: usize,
}

/// The paper's estimator (Eq. 16): intensity centroid of the samples above the threshold,
/// weighted by their raw intensity.
pub fn centroid(p: &[f32], s: &Segment) -> Option<f64> {
    let (mut sw, mut swk) = (0.0f64, 0.0f64);
    for k in s.start..s.end {
        let w = p[k] as f64;
        sw += w;
        swk += w * k as f64;
    }
    (sw > 0.0).then(|| swk / sw)
}

/// Centroid with the threshold subtracted from the weights, so that samples near the edges
/// weigh almost nothing and a sample crossing the threshold does not make the centre jump.
/// The window is the segment widened by one sample on each side (those weigh 0 if below `t`).
pub fn windowed_centroid(p: &[f32], s: &Segment, t: f32) -> Option<f64> {
    let lo = s.start.saturating_sub(1);
    let hi = (s.end + 1).min(p.len());
    let (mut sw, mut swk) = (0.0f64, 0.0f64);
    for k in lo..hi {
        let w = (p[k] - t).max(0.0) as f64;
        sw += w;
        swk += w * k as f64;
    }
    (sw > 0.0).then(|| swk / sw)
}

/// Centroid of the profile's top: the windowed centroid of the run of samples above `level`
/// around the peak. With a level high on the peak (see `across::TOP_LEVEL`) a one-sided tail
/// barely moves it, where a centroid down to the threshold follows the tail.
pub fn top_centroid(p: &[f32], s: &Segment, level: f32) -> Option<f64> {
    windowed_centroid(p, &super::segment_at(p, s.peak, level)?, level)
}

/// Gaussian peak fit: a parabola fitted to the logarithms of the samples above 30 % of the
/// peak (least squares, weighted by intensity² since the noise of ln p is σ/p), whose vertex
/// is the centre. Exact for a Gaussian profile on zero background; with three samples it is the
/// classic 3-point log-parabola.
pub fn gaussian(p: &[f32], s: &Segment) -> Option<f64> {
    let k = s.peak;
    let floor = 0.3 * p[k];
    let lo = (s.start..=k).rev().take_while(|&i| p[i] >= floor).last().unwrap_or(k).min(k.saturating_sub(1));
    let hi = (k..s.end).take_while(|&i| p[i] >= floor).last().unwrap_or(k).max(k + 1);
    if hi >= p.len() || !(p[lo] > 0.0 && p[hi] > 0.0) {
        return None;
    }
    // Normal equations of ln p ≈ a + b·x + c·x², x = i − k.
    let mut m = [[0.0f64; 3]; 3];
    let mut rhs = [0.0f64; 3];
    for i in lo..=hi {
        let v = p[i].max(1e-3) as f64;
        let (x, w, y) = (i as f64 - k as f64, v * v, v.ln());
        let basis = [1.0, x, x * x];
        for r in 0..3 {
            rhs[r] += w * basis[r] * y;
            for c in 0..3 {
                m[r][c] += w * basis[r] * basis[c];
            }
        }
    }
    let [_, b, c] = solve3(m, rhs)?;
    if c >= 0.0 {
        return None;
    }
    let off = -b / (2.0 * c);
    (off.abs() <= (hi - lo) as f64).then_some(k as f64 + off)
}

/// Solves a 3×3 linear system by Cramer's rule; `None` if it is singular.
pub(super) fn solve3(m: [[f64; 3]; 3], r: [f64; 3]) -> Option<[f64; 3]> {
    let det = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(m);
    let scale = m[0][0].abs();
    if d.abs() < (1e-12 * scale * scale * scale).max(1e-312) {
        return None;
    }
    let mut out = [0.0; 3];
    for (col, o) in out.iter_mut().enumerate() {
        let mut a = m;
        for row in 0..3 {
            a[row][col] = r[row];
        }
        *o = det(a) / d;
    }
    Some(out)
}

/// Blais–Rioux peak detector: the zero crossing of the fourth-order derivative filter
/// `g(i) = p(i−2) + p(i−1) − p(i+1) − p(i+2)` next to the peak, linearly interpolated.
pub fn blais_rioux(p: &[f32], s: &Segment) -> Option<f64> {
    let g = |i: usize| -> Option<f64> {
        if i < 2 || i + 2 >= p.len() {
            return None;
        }
        Some((p[i - 2] + p[i - 1] - p[i + 1] - p[i + 2]) as f64)
    };
    let k = s.peak;
    // The crossing lies between k−1 and k or between k and k+1.
    for i in [k.checked_sub(1)?, k] {
        let (g0, g1) = (g(i)?, g(i + 1)?);
        if g0 <= 0.0 && g1 > 0.0 {
            let off = -g0 / (g1 - g0);
            return Some(i as f64 + off);
        }
    }
    None
}

/// Where the profile crosses `level` going up before the peak and down after it, linearly
/// interpolated between samples: `(rising, falling)` as fractional indices.
pub fn crossings(p: &[f32], s: &Segment, level: f32) -> Option<(f64, f64)> {
    let mut i = s.peak;
    while i > 0 && p[i - 1] >= level {
        i -= 1;
    }
    if i == 0 {
        return None;
    }
    let rising = (i - 1) as f64 + ((level - p[i - 1]) / (p[i] - p[i - 1])) as f64;
    let mut j = s.peak;
    while j + 1 < p.len() && p[j + 1] >= level {
        j += 1;
    }
    if j + 1 >= p.len() {
        return None;
    }
    let falling = j as f64 + ((p[j] - level) / (p[j] - p[j + 1])) as f64;
    Some((rising, falling))
}

/// Centre of a saturated plateau: the midpoint of the two edges, taken where the profile
/// crosses half way between the threshold and the plateau level `top` (the steep,
/// well-sampled part of the edges), never the first saturated sample.
pub fn plateau_centre(p: &[f32], s: &Segment, t: f32, top: f32) -> Option<f64> {
    let (a, b) = crossings(p, s, 0.5 * (t + top))?;
    Some(0.5 * (a + b))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Gaussian profile of σ px centred at `c` (sample index), peak `a`, background `bg`.
    fn profile(n: usize, c: f64, sigma: f64, a: f64, bg: f64) -> Vec<f32> {
        (0..n).map(|k| (bg + a * (-(k as f64 - c).powi(2) / (2.0 * sigma * sigma)).exp()) as f32).collect()
    }

    fn segment(p: &[f32], t: f32) -> Segment {
        let start = p.iter().position(|&x| x > t).unwrap();
        let end = start + p[start..].iter().take_while(|&&x| x > t).count();
        let peak = (start..end).max_by(|&a, &b| p[a].total_cmp(&p[b])).unwrap();
        Segment { start, end, peak }
    }

    #[test]
    fn estimators_find_noise_free_gaussian_centres() {
        // Sub-sample offsets across one sample; σ = 1.5 samples; threshold 20 of peak 200.
        for i in 0..20 {
            let c = 10.0 + i as f64 * 0.05;
            let p = profile(24, c, 1.5, 200.0, 0.0);
            let s = segment(&p, 20.0);
            let e_paper = centroid(&p, &s).unwrap() - c;
            let e_win = windowed_centroid(&p, &s, 20.0).unwrap() - c;
            let e_gauss = gaussian(&p, &s).unwrap() - c;
            let e_br = blais_rioux(&p, &s).unwrap() - c;
            // The paper's centroid jumps when a sample crosses the threshold; the others are
            // near-exact on a clean Gaussian.
            assert!(e_paper.abs() < 0.12, "paper c={c} e={e_paper}");
            assert!(e_win.abs() < 0.03, "windowed c={c} e={e_win}");
            assert!(e_gauss.abs() < 1e-4, "gauss c={c} e={e_gauss}");
            assert!(e_br.abs() < 0.06, "blais-rioux c={c} e={e_br}");
        }
    }

    /// `omni_simulator::SheetProfile::real`'s shape: a Gaussian core of σ with 17 % of the light
    /// in the same Gaussian convolved with an exponential 4 σ long on the + side, at `x` from
    /// the core's centre (numerical convolution, unit peak of the core).
    fn tailed(x: f64, sigma: f64) -> f64 {
        let g = |d: f64| (-d * d / (2.0 * sigma * sigma)).exp();
        let tau = 4.0 * sigma;
        let tail: f64 = (0..4000).map(|j| j as f64 * 0.01).map(|e| (-e / tau).exp() / tau * g(x - e) * 0.01).sum();
        0.83 * g(x) + 0.17 * tail
    }

    #[test]
    fn the_top_centroid_barely_follows_a_one_sided_tail() {
        let sigma = 3.0;
        let mode =
            (0..4000).map(|i| i as f64 * 0.001).max_by(|a, b| tailed(*a, sigma).total_cmp(&tailed(*b, sigma))).unwrap();
        for i in 0..10 {
            let c = 30.0 + i as f64 * 0.1;
            let p: Vec<f32> = (0..90).map(|k| (200.0 * tailed(k as f64 - c, sigma)) as f32).collect();
            let s = segment(&p, 10.0);
            let top = top_centroid(&p, &s, 0.8 * p[s.peak]).unwrap() - c - mode;
            let windowed = windowed_centroid(&p, &s, 10.0).unwrap() - c - mode;
            assert!(windowed > 0.15 && top.abs() < 0.3 * windowed, "c={c}: top {top}, windowed {windowed}");
        }
        let core = profile(80, 30.3, sigma, 200.0, 0.0);
        let gauss = top_centroid(&core, &segment(&core, 10.0), 160.0).unwrap() - 30.3;
        assert!(gauss.abs() < 0.03, "Gaussian: {gauss}");
    }

    #[test]
    fn plateau_centre_is_the_middle_of_a_clipped_stripe() {
        for i in 0..10 {
            let c = 12.0 + i as f64 * 0.1;
            let p: Vec<f32> = profile(26, c, 2.0, 900.0, 0.0).iter().map(|&x| x.min(255.0)).collect();
            let s = segment(&p, 20.0);
            let e = plateau_centre(&p, &s, 20.0, 255.0).unwrap() - c;
            assert!(e.abs() < 0.02, "c={c} e={e}");
            // The first saturated sample is off by the plateau's half width (≈ 2 samples).
            let first_sat = p.iter().position(|&x| x >= 255.0).unwrap() as f64;
            assert!((first_sat - c).abs() > 1.0);
        }
    }
}
