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
/// Also returns the top's samples.
pub fn top_centroid(p: &[f32], s: &Segment, level: f32) -> Option<(f64, Segment)> {
    let top = super::segment_at(p, s.peak, level)?;
    Some((windowed_centroid(p, &top, level)?, top))
}

/// The profile's top as a cubic in the logarithm of the samples within `half_window` samples
/// of `peak` (least squares): `(vertex, skew)`, the cubic's stationary point (fractional
/// index) and L‴/L″ there (per sample), L = ln p. A Gaussian blur of variance s moves the peak
/// of the profile it blurs by −(s/2)·L‴/L″ to first order, so `vertex + (s/2)·skew` is the
/// peak before that blur; a symmetric top has no skew. `None` where the window leaves the
/// profile, reaches a sample at or below 0, or the top is not a maximum.
pub fn log_cubic_top(p: &[f32], peak: usize, half_window: usize) -> Option<(f64, f64)> {
    let (lo, hi) = (peak.checked_sub(half_window)?, peak + half_window);
    if hi >= p.len() {
        return None;
    }
    // On the window's symmetric grid x = −n..n the odd and even powers are orthogonal, so
    // ln p ≈ c0 + c1·x + c2·x² + c3·x³ splits into two 2×2 systems of the sums Σxᵏ·ln p.
    let n = half_window as f64;
    let mut t = [0.0f64; 4];
    for (i, &v) in p[lo..=hi].iter().enumerate() {
        if !(v > 0.0) {
            return None;
        }
        let (x, y) = (i as f64 - n, ln(v as f64));
        t[0] += y;
        t[1] += x * y;
        t[2] += x * x * y;
        t[3] += x * x * x * y;
    }
    let [s0, s2, s4, s6] = symmetric_power_sums(n);
    let c2 = (s0 * t[2] - s2 * t[0]) / (s0 * s4 - s2 * s2);
    let odd = s2 * s6 - s4 * s4;
    let (c1, c3) = ((s6 * t[1] - s4 * t[3]) / odd, (s2 * t[3] - s4 * t[1]) / odd);
    if !(c2 < 0.0) {
        return None;
    }
    // The stationary point next to the window's middle: Newton from the parabola's vertex (c3
    // is small beside c2 on a laser's top, so two steps reach it to 1e-6).
    let mut x = -c1 / (2.0 * c2);
    for _ in 0..2 {
        x -= (c1 + 2.0 * c2 * x + 3.0 * c3 * x * x) / (2.0 * c2 + 6.0 * c3 * x);
    }
    let curvature = 2.0 * c2 + 6.0 * c3 * x;
    if !(x.abs() <= n && curvature < 0.0) {
        return None;
    }
    Some((peak as f64 + x, 6.0 * c3 / curvature))
}

/// Σxᵏ over x = −n..n for k = 0, 2, 4, 6 (the odd ones vanish).
fn symmetric_power_sums(n: f64) -> [f64; 4] {
    let base = n * (n + 1.0) * (2.0 * n + 1.0);
    [
        2.0 * n + 1.0,
        base / 3.0,
        base * (3.0 * n * n + 3.0 * n - 1.0) / 15.0,
        base * (3.0 * n.powi(4) + 6.0 * n.powi(3) - 3.0 * n + 1.0) / 21.0,
    ]
}

/// ln x for a positive, normal `x`, within 1e-9: the exponent, and the mantissa m scaled into
/// [√½, √2) by the series ln m = 2·atanh((m − 1)/(m + 1)) to its z⁹ term. Inlined where
/// glibc's `log` is a call per sample.
#[inline(always)]
fn ln(x: f64) -> f64 {
    let bits = x.to_bits();
    let mut exponent = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mut m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
    if m > std::f64::consts::SQRT_2 {
        m *= 0.5;
        exponent += 1;
    }
    let z = (m - 1.0) / (m + 1.0);
    let z2 = z * z;
    let series = z * (2.0 + z2 * (2.0 / 3.0 + z2 * (2.0 / 5.0 + z2 * (2.0 / 7.0 + z2 * (2.0 / 9.0)))));
    exponent as f64 * std::f64::consts::LN_2 + series
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
    let (a, b) = plateau_edges(p, s, t, top)?;
    Some(0.5 * (a + b))
}

/// The two edges of a saturated plateau whose midpoint [`plateau_centre`] is (fractional
/// indices).
pub fn plateau_edges(p: &[f32], s: &Segment, t: f32, top: f32) -> Option<(f64, f64)> {
    crossings(p, s, 0.5 * (t + top))
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
        tailed_by(x, sigma, 4.0 * sigma)
    }

    /// [`tailed`] with a tail `tau` samples long; blurred by a Gaussian of variance s it is
    /// `tailed_by` with σ² + s and the same `tau`.
    fn tailed_by(x: f64, sigma: f64, tau: f64) -> f64 {
        let g = |d: f64| (-d * d / (2.0 * sigma * sigma)).exp();
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
            let top = top_centroid(&p, &s, 0.8 * p[s.peak]).unwrap().0 - c - mode;
            let windowed = windowed_centroid(&p, &s, 10.0).unwrap() - c - mode;
            assert!(windowed > 0.15 && top.abs() < 0.3 * windowed, "c={c}: top {top}, windowed {windowed}");
        }
        let core = profile(80, 30.3, sigma, 200.0, 0.0);
        let gauss = top_centroid(&core, &segment(&core, 10.0), 160.0).unwrap().0 - 30.3;
        assert!(gauss.abs() < 0.03, "Gaussian: {gauss}");
    }

    /// The light's peak behind a blur from the blurred top's log-cubic: a tailed light of core σ
    /// 2 samples, blurred by a variance of 4 samples², at 20 sub-sample shifts. The top's
    /// centroid and the vertex (the image's peak: the blur's shift of a lopsided peak) lie
    /// 0.05–0.07 sample off the light's peak towards the tail; the vertex moved back by
    /// (s/2)·skew lies −0.010 sample from it on average (asserted 0.015), each shift within
    /// −0.033 to +0.009 (asserted 0.04: the window moves with the brightest sample).
    #[test]
    fn the_log_cubic_top_undoes_the_blur_of_a_lopsided_peak() {
        let (sigma, tau, blur) = (2.0f64, 8.0, 4.0);
        let mut sum = 0.0;
        let light = |x: f64| tailed_by(x, sigma, tau);
        let peak = (0..6000).map(|i| i as f64 * 0.0005).max_by(|a, b| light(*a).total_cmp(&light(*b))).unwrap();
        let blurred = (sigma * sigma + blur).sqrt();
        for i in 0..20 {
            let c = 30.0 + i as f64 * 0.05;
            let p: Vec<f32> = (0..90).map(|k| (200.0 * tailed_by(k as f64 - c, blurred, tau)) as f32).collect();
            let s = segment(&p, 10.0);
            let top = top_centroid(&p, &s, 0.8 * p[s.peak]).unwrap().0 - c - peak;
            let (vertex, skew) = log_cubic_top(&p, s.peak, 3).unwrap();
            let image_peak = vertex - c - peak;
            let light_peak = image_peak + 0.5 * blur * skew;
            assert!(top > 0.04 && image_peak > 0.04, "c={c}: top {top}, vertex {image_peak}");
            assert!(light_peak.abs() < 0.04, "c={c}: light's peak off by {light_peak}");
            sum += light_peak;
        }
        assert!((sum / 20.0).abs() < 0.015, "light's peak off by {} on average", sum / 20.0);
        // A symmetric top has no skew.
        let gauss = profile(60, 30.3, 2.5, 200.0, 0.0);
        let (vertex, skew) = log_cubic_top(&gauss, 30, 3).unwrap();
        assert!((vertex - 30.3).abs() < 1e-6 && skew.abs() < 1e-6, "Gaussian: vertex {vertex}, skew {skew}");
    }

    #[test]
    fn power_sums_in_closed_form() {
        for n in 1..40 {
            let sums = symmetric_power_sums(n as f64);
            for (k, sum) in [0, 2, 4, 6].iter().zip(sums) {
                let exact: f64 = (-n..=n).map(|x: i32| (x as f64).powi(*k)).sum();
                assert!((sum - exact).abs() <= 1e-9 * exact, "n {n}, k {k}: {sum} against {exact}");
            }
        }
    }

    #[test]
    fn ln_agrees_with_the_library() {
        for i in 0..20000 {
            let x = 1e-3 * 1.0013f64.powi(i);
            assert!((ln(x) - x.ln()).abs() < 1e-9, "ln {x}: {} against {}", ln(x), x.ln());
        }
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
