//! Where a lopsided stripe's top lies from its sheet's peak, for a laser whose cross-section
//! is known ([`super::RidgeParams::laser_profile`]).
//!
//! Rule: the stripe's image is the sheet's profile blurred by the lens, the pixel and the
//! sampling kernel (Gaussians: the variances add, and the profile family stays closed). That
//! profile, sampled as the detector samples it, has its top's centroid (the samples above
//! [`super::across::TOP_LEVEL`] of the peak, weighed as [`estimators::top_centroid`] weighs
//! them) a computable distance from the sheet's peak towards the tail, which depends on the
//! sheet's width, and so on the profile's half-maximum width. The detector moves a stripe's
//! points from their tops' centroid by that distance where the stripe's own top shape cannot
//! lead them to the peak (`across::lean_to_sheet_peak`): pieces too short or too speckled for
//! its median, and stripes whose width is mostly the blur's, where the top shape undoes the
//! blur only to first order.

use super::SAMPLE_STEP_PX;
use super::estimators::{self, Segment};
use omni_model::LaserProfile;

/// Sub-sample phases averaged for each width (the samples fall anywhere on the profile).
const PHASES: usize = 8;
/// Sheet widths tabulated: FWHM from [`NARROWEST_PX`] up by [`WIDTH_RATIO`] each.
const WIDTHS: usize = 72;
const NARROWEST_PX: f64 = 0.05;
const WIDTH_RATIO: f64 = 1.12;

/// Where a stripe's top centroid lies from its sheet's peak (px, towards the tail), by the
/// stripe's half-maximum width (px), for one blur.
#[derive(Debug, Clone)]
pub(super) struct TopOffsets {
    /// Increasing half-maximum widths (px) of the sampled profiles.
    half_widths: Vec<f64>,
    /// The top centroid's distance from the sheet's peak at each (px).
    centroids: Vec<f64>,
}

impl TopOffsets {
    /// The table for `profile` under a Gaussian blur of variance `blur_variance` (px², the
    /// lens's, the pixel's area and the sampling kernel's).
    pub fn new(profile: &LaserProfile, blur_variance: f64) -> TopOffsets {
        let mut t = TopOffsets { half_widths: Vec::new(), centroids: Vec::new() };
        for k in 0..WIDTHS {
            let fwhm = NARROWEST_PX * WIDTH_RATIO.powi(k as i32);
            if let Some(top) = sampled_top(profile, fwhm / profile.fwhm(), blur_variance)
                && t.half_widths.last().is_none_or(|&last| top.half_width > last)
            {
                t.half_widths.push(top.half_width);
                t.centroids.push(top.centroid);
            }
        }
        t
    }

    /// The top centroid's distance from the sheet's peak (px, towards the tail) for a profile
    /// of half-maximum width `half_width` (px).
    pub fn centroid_at(&self, half_width: f64) -> f64 {
        interpolate(&self.half_widths, &self.centroids, half_width)
    }
}

/// `values` at `x` over increasing `xs`: interpolated; below the table the first value, above
/// it the last growing with x (a profile's shape scales with its width once the blur no longer
/// matters).
fn interpolate(xs: &[f64], values: &[f64], x: f64) -> f64 {
    let Some(&last) = xs.last() else { return 0.0 };
    if !(x > xs[0]) {
        return values[0];
    }
    if x >= last {
        return values[values.len() - 1] * x / last;
    }
    let i = xs.partition_point(|&v| v <= x);
    let f = (x - xs[i - 1]) / (xs[i] - xs[i - 1]);
    values[i - 1] + f * (values[i] - values[i - 1])
}

/// A sampled profile's half-maximum width and its top centroid's place from the sheet's peak
/// (px).
struct SampledTop {
    half_width: f64,
    centroid: f64,
}

/// A sheet of core σ `core` px blurred by variance `blur_variance` px², sampled
/// [`SAMPLE_STEP_PX`] apart and measured as the detector measures a profile, averaged over
/// [`PHASES`] sub-sample phases.
fn sampled_top(profile: &LaserProfile, core: f64, blur_variance: f64) -> Option<SampledTop> {
    let s = (1.0 + blur_variance / (core * core)).sqrt();
    let spread = s * core;
    let peak = profile.mode() * core;
    // Past the half maximum on both sides: on the tail's, within 2 τ for any share up to 0.9
    // (an exponential halves in 0.7 τ).
    let tail = if profile.tail_weight() > 0.0 { 2.0 * profile.tail_length() * core } else { 0.0 };
    let (from, to) = (-5.0 * spread, 5.0 * spread + tail);
    let n = ((to - from) / SAMPLE_STEP_PX).ceil() as usize + 3;
    let mut sum = SampledTop { half_width: 0.0, centroid: 0.0 };
    let mut q = vec![0.0f32; n];
    for phase in 0..PHASES {
        let first = from + SAMPLE_STEP_PX * (phase as f64 / PHASES as f64 - 1.0);
        for (k, v) in q.iter_mut().enumerate() {
            *v = profile.unit((first + k as f64 * SAMPLE_STEP_PX) / core, s) as f32;
        }
        let top = (0..n).max_by(|&a, &b| q[a].total_cmp(&q[b]))?;
        let seg = Segment { start: 1, end: n - 1, peak: top };
        let (a, b) = estimators::crossings(&q, &seg, 0.5 * q[top])?;
        let half_width = (b - a) * SAMPLE_STEP_PX;
        let (centre, _) = estimators::top_centroid(&q, &seg, super::across::TOP_LEVEL * q[top])?;
        sum.half_width += half_width;
        sum.centroid += first + centre * SAMPLE_STEP_PX - peak;
    }
    let n = PHASES as f64;
    Some(SampledTop { half_width: sum.half_width / n, centroid: sum.centroid / n })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gaussian_sheets_top_is_its_peak_and_a_tailed_ones_leans_to_the_tail() {
        let blur = 0.7f64.powi(2) + 1.0 / 12.0 + 0.64;
        let gauss = TopOffsets::new(&LaserProfile::gaussian(), blur);
        for h in [1.5, 3.0, 10.0, 40.0] {
            assert!(gauss.centroid_at(h).abs() < 2e-3, "{h}: {}", gauss.centroid_at(h));
        }
        let real = TopOffsets::new(&LaserProfile::tailed(0.17, 4.0), blur);
        let offsets: Vec<f64> = [2.0, 3.0, 5.0, 10.0, 20.0, 50.0, 100.0].map(|h| real.centroid_at(h)).to_vec();
        assert!(offsets.iter().all(|&o| o > 0.0), "{offsets:?}");
        // Wide sheets: the blur no longer matters and the offset grows with the width, also past
        // the table; below it (narrower than the blur alone: noise) the narrowest sheet's.
        assert!((real.centroid_at(100.0) / real.centroid_at(50.0) - 2.0).abs() < 0.15, "{offsets:?}");
        let widest = *real.half_widths.last().unwrap();
        assert!((real.centroid_at(2.0 * widest) / real.centroid_at(widest) - 2.0).abs() < 1e-9);
        assert_eq!(real.centroid_at(0.5), real.centroids[0]);
        assert_eq!(real.centroid_at(f64::NAN), real.centroids[0]);
    }

    /// The table against the top centroid of the continuous profile, computed directly.
    #[test]
    fn the_sampled_top_agrees_with_the_continuous_profiles_top() {
        let p = LaserProfile::tailed(0.3, 2.0);
        let (core, blur) = (3.0f64, 1.0f64);
        let s = (1.0 + blur / (core * core)).sqrt();
        let f = |x: f64| p.unit(x / core, s);
        let (lo, hi, n) = (-20.0, 40.0, 600_000);
        let h = (hi - lo) / n as f64;
        let xs = (0..n).map(|i| lo + (i as f64 + 0.5) * h);
        let top = xs.clone().map(f).fold(0.0, f64::max);
        let level = super::super::across::TOP_LEVEL as f64 * top;
        let (sw, swx) = xs.fold((0.0, 0.0), |(a, b), x| {
            let w = (f(x) - level).max(0.0);
            (a + w, b + w * x)
        });
        let continuous = swx / sw - p.mode() * core;
        let sampled = sampled_top(&p, core, blur).unwrap().centroid;
        assert!((sampled - continuous).abs() < 0.01, "sampled {sampled}, continuous {continuous}");
    }
}
