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
//! blur only to first order. The same profile also gives the windowed centroid's own distance
//! from the sheet's peak ([`WindowedOffsets`]), which needs no top at all; the stripe's
//! measured leans then count only as far as they depart from it beyond their noise
//! (`across::WindowLeans`).

use super::SAMPLE_STEP_PX;
use super::estimators::{self, Segment};
use omni_model::LaserProfile;
use std::f64::consts::TAU;

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
        let (half_widths, centroids) = by_width(profile, |core| sampled_top(profile, core, blur_variance));
        TopOffsets { half_widths, centroids: centroids.into_iter().map(|[c]| c).collect() }
    }

    /// The top centroid's distance from the sheet's peak (px, towards the tail) for a profile
    /// of half-maximum width `half_width` (px).
    pub fn centroid_at(&self, half_width: f64) -> f64 {
        interpolate(&self.half_widths, &self.centroids, half_width)
    }
}

/// `sample(core σ)` of each tabulated sheet width ([`WIDTHS`]) whose half-maximum width (the
/// first of the pair) grows: the widths and the values, in order.
fn by_width<T>(profile: &LaserProfile, sample: impl Fn(f64) -> Option<(f64, T)>) -> (Vec<f64>, Vec<T>) {
    let (mut widths, mut values) = (Vec::new(), Vec::new());
    for k in 0..WIDTHS {
        let fwhm = NARROWEST_PX * WIDTH_RATIO.powi(k as i32);
        if let Some((half_width, value)) = sample(fwhm / profile.fwhm())
            && widths.last().is_none_or(|&last| half_width > last)
        {
            widths.push(half_width);
            values.push(value);
        }
    }
    (widths, values)
}

/// `values` at `x` over increasing `xs`: interpolated; below the table the first value, above
/// it the last growing with x (a profile's shape scales with its width once the blur no longer
/// matters).
fn interpolate(xs: &[f64], values: &[f64], x: f64) -> f64 {
    interpolate_by(xs, |k| values[k], x)
}

/// [`interpolate`] with the value at each of `xs` given by `value(index)`.
fn interpolate_by(xs: &[f64], value: impl Fn(usize) -> f64, x: f64) -> f64 {
    let Some(&last) = xs.last() else { return 0.0 };
    if !(x > xs[0]) {
        return value(0);
    }
    if x >= last {
        return value(xs.len() - 1) * x / last;
    }
    let i = xs.partition_point(|&v| v <= x);
    let f = (x - xs[i - 1]) / (xs[i] - xs[i - 1]);
    value(i - 1) + f * (value(i) - value(i - 1))
}

/// Levels at which the windowed centroid is tabulated ([`WindowedOffsets`]): shares of the
/// light's sampled peak, from [`LOWEST_LEVEL`] up by [`LEVEL_STEP`].
const WINDOW_LEVELS: usize = 38;
const LOWEST_LEVEL: f64 = 0.025;
const LEVEL_STEP: f64 = 0.025;

/// Where a stripe's windowed centroid ([`estimators::windowed_centroid`]) lies from its sheet's
/// peak (px, towards the tail), by the stripe's half-maximum width (px) and the level its
/// weights start from (the threshold as a share of the profile's peak), for one blur.
///
/// Rule: the windowed centroid weighs the light above a level, so a tail on one side pulls it
/// by an amount the profile, its width and that level fix. Unlike the top's centroid, which
/// the leans need to reach from the centre, it uses every sample above the threshold, so its
/// offset needs no noisy top to be measured on each profile.
#[derive(Debug, Clone)]
pub(super) struct WindowedOffsets {
    /// Increasing half-maximum widths (px) of the sampled profiles.
    half_widths: Vec<f64>,
    /// The windowed centroid's distance from the sheet's peak at each width and level (px).
    offsets: Vec<[f64; WINDOW_LEVELS]>,
}

impl WindowedOffsets {
    /// The table for `profile` under a Gaussian blur of variance `blur_variance` (px², the
    /// lens's, the pixel's area and the sampling kernel's).
    pub fn new(profile: &LaserProfile, blur_variance: f64) -> WindowedOffsets {
        let (half_widths, offsets) = by_width(profile, |core| sampled_windows(profile, core, blur_variance));
        WindowedOffsets { half_widths, offsets }
    }

    /// The windowed centroid's distance from the sheet's peak (px, towards the tail) for a
    /// profile of half-maximum width `half_width` (px) weighed from `level` (a share of its
    /// peak); `None` for a level outside the table's (a threshold under 2.5 % of the peak
    /// weighs a tail the table does not reach).
    pub fn offset_at(&self, half_width: f64, level: f64) -> Option<f64> {
        let x = (level - LOWEST_LEVEL) / LEVEL_STEP;
        if !(0.0..=(WINDOW_LEVELS - 1) as f64).contains(&x) {
            return None;
        }
        let i = (x as usize).min(WINDOW_LEVELS - 2);
        let at_level = |k: usize| {
            let offsets = &self.offsets[k];
            offsets[i] + (x - i as f64) * (offsets[i + 1] - offsets[i])
        };
        Some(interpolate_by(&self.half_widths, at_level, half_width))
    }
}

/// A sheet of core σ `core` px blurred by variance `blur_variance` px², sampled as the
/// detector samples it: its half-maximum width and its windowed centroid's place from the
/// sheet's peak (px) at each tabulated level ([`sampled_phases`]). On the tail's side the
/// samples reach 4 τ past 5 σ: the tail's share of the peak times e⁻⁴ is under the lowest level.
fn sampled_windows(profile: &LaserProfile, core: f64, blur_variance: f64) -> Option<(f64, [f64; WINDOW_LEVELS])> {
    sampled_phases(profile, core, blur_variance, 4.0, |q, top, place| {
        let mut offsets = [0.0; WINDOW_LEVELS];
        for (i, offset) in offsets.iter_mut().enumerate() {
            let level = (LOWEST_LEVEL + i as f64 * LEVEL_STEP) as f32 * q[top];
            let run = super::segment_at(q, top, level)?;
            *offset = place(estimators::windowed_centroid(q, &run, level)?);
        }
        Some(offsets)
    })
}

/// Clip levels tabulated, as shares of the profile's peak: from the peak itself down by
/// [`CLIP_RATIO`] each, to 2 % (a stripe 50 times brighter than the clip).
const CLIPS: usize = 48;
const CLIP_RATIO: f64 = 0.92;
/// Levels at which widths are tabulated, as the threshold's share of a clipped profile's
/// plateau (its edges are read half way between the two, [`estimators::plateau_edges`]) or
/// the background's share of an unclipped profile's peak (its half maximum above it).
const LEVEL_SHARES: [f64; 9] = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8];
/// The widest sheet (FWHM, px) tabulated for clipped stripes; wider ones scale from it.
const WIDEST_CLIPPED_PX: f64 = 32.0;

/// One tabulated sheet width's clipped profiles: for each threshold share and clip level, the
/// edges' distance (px, growing as the clip deepens; NaN past the sampled reach) and their
/// midpoint's distance from the sheet's peak (px, towards the tail).
#[derive(Debug, Clone)]
struct ClippedWidth {
    half_width: f64,
    edges: [[f64; CLIPS]; LEVEL_SHARES.len()],
    midpoints: [[f64; CLIPS]; LEVEL_SHARES.len()],
}

/// Where a clipped stripe's plateau centre (the midpoint of its edges,
/// [`estimators::plateau_edges`]) lies from its sheet's peak (px, towards the tail), by the
/// sheet's half-maximum width (px, unclipped), the edges' distance (px) and the threshold's
/// share of the plateau, for one blur.
///
/// Rule: clipping hides how far above the clip the peak lies, and with it how far down the
/// profile the edges were read; the deeper, the farther their midpoint lies in the tail. The
/// sheet's unclipped width, taken from the stripe's unclipped profiles nearby (same range,
/// dimmer surface), fixes the profile, and the edges' distance then fixes the depth: it grows
/// as the clip falls. The lens and the pixel blur the light before the sensor clips it, the
/// detector's sampling kernel after.
#[derive(Debug, Clone)]
pub(super) struct PlateauOffsets {
    /// By increasing half-maximum width (px) of the sampled, unclipped profiles.
    widths: Vec<ClippedWidth>,
}

impl PlateauOffsets {
    /// The table for `profile` blurred by variance `clipped_variance` (px²: the lens's and the
    /// pixel's) before it is clipped, and by a Gaussian of σ `sample_sigma` px (the sampling
    /// kernel) after.
    pub fn new(profile: &LaserProfile, clipped_variance: f64, sample_sigma: f64) -> PlateauOffsets {
        let mut widths: Vec<ClippedWidth> = Vec::new();
        for k in 0..WIDTHS {
            let fwhm = NARROWEST_PX * WIDTH_RATIO.powi(k as i32);
            if fwhm > WIDEST_CLIPPED_PX {
                break;
            }
            // Wider sheets are wider at every level (the lookup's bracketing needs it).
            if let Some(w) = clipped_width(profile, fwhm / profile.fwhm(), clipped_variance, sample_sigma)
                && widths.last().is_none_or(|last| (0..LEVEL_SHARES.len()).all(|i| w.edges[i][0] > last.edges[i][0]))
            {
                widths.push(w);
            }
        }
        PlateauOffsets { widths }
    }

    /// The plateau centre's distance from the sheet's peak (px, towards the tail) for a stripe
    /// whose unclipped profiles are `half_width` px wide at half their maximum above a
    /// background `background_share` of their peak, and whose plateau's edges lie `edges` px
    /// apart, read half way between the plateau and `threshold_share` of it; `None` below the
    /// table's widths or clipped deeper than its levels. Edges closer than an unclipped
    /// profile's are read as barely clipped. The shares count light from the laser alone:
    /// where the detector's background holds some of the tail's light, the widths were read
    /// that much higher up the profile.
    pub fn midpoint_at(&self, half_width: f64, background_share: f64, edges: f64, threshold_share: f64) -> Option<f64> {
        let (first, last) = (self.widths.first()?, self.widths.last()?);
        let (b, bf) = share_index(background_share)?;
        let unclipped = |w: &ClippedWidth| w.edges[b - 1][0] + bf * (w.edges[b][0] - w.edges[b - 1][0]);
        if !(half_width >= unclipped(first)) || !edges.is_finite() {
            return None;
        }
        let (i, g) = share_index(threshold_share)?;
        // A tabulated width's midpoint, scaled to this width: a profile's shape scales with its
        // width where the blur matters little, and the nearest widths differ by 12 %.
        let at = |w: &ClippedWidth| -> Option<f64> {
            let r = half_width / unclipped(w);
            let below = clip_midpoint(&w.edges[i - 1], &w.midpoints[i - 1], edges / r)?;
            let above = clip_midpoint(&w.edges[i], &w.midpoints[i], edges / r)?;
            Some(r * (below + g * (above - below)))
        };
        if half_width >= unclipped(last) {
            return at(last);
        }
        let k = self.widths.partition_point(|w| unclipped(w) <= half_width).max(1);
        let (lo, hi) = (&self.widths[k - 1], &self.widths[k]);
        let f = (half_width - unclipped(lo)) / (unclipped(hi) - unclipped(lo));
        let (below, above) = (at(lo)?, at(hi)?);
        Some(below + f * (above - below))
    }
}

/// The interval of [`LEVEL_SHARES`] that holds `share`: its upper index and the fraction of
/// the way to it; `None` beyond the table (negative shares count as 0).
fn share_index(share: f64) -> Option<(usize, f64)> {
    let last = LEVEL_SHARES.len() - 1;
    if !(share <= LEVEL_SHARES[last]) {
        return None;
    }
    let share = share.max(0.0);
    let i = LEVEL_SHARES.partition_point(|&s| s <= share).clamp(1, last);
    Some((i, (share - LEVEL_SHARES[i - 1]) / (LEVEL_SHARES[i] - LEVEL_SHARES[i - 1])))
}

/// The midpoint at the clip level whose edges lie `edges` apart, interpolated over one width's
/// levels; the unclipped profile's for closer edges, `None` past the deepest level.
fn clip_midpoint(edges_at: &[f64; CLIPS], midpoints: &[f64; CLIPS], edges: f64) -> Option<f64> {
    if edges_at[0].is_nan() {
        return None;
    }
    if !(edges > edges_at[0]) {
        return Some(midpoints[0]);
    }
    let j = edges_at.iter().position(|&e| !(e < edges)).filter(|&j| !edges_at[j].is_nan())?;
    let f = (edges - edges_at[j - 1]) / (edges_at[j] - edges_at[j - 1]);
    Some(midpoints[j - 1] + f * (midpoints[j] - midpoints[j - 1]))
}

/// A sheet of core σ `core` px, blurred by variance `clipped_variance` px², clipped at each of
/// [`CLIPS`] levels, blurred by a Gaussian of σ `sample_sigma` px and sampled
/// [`SAMPLE_STEP_PX`] apart, its plateau's edges read as the detector reads them; averaged over
/// [`PHASES`] sub-sample phases. Computed on a grid of 1/[`PHASES`] of a sample, where every
/// phase's samples lie.
fn clipped_width(profile: &LaserProfile, core: f64, clipped_variance: f64, sample_sigma: f64) -> Option<ClippedWidth> {
    let step = SAMPLE_STEP_PX / PHASES as f64;
    let s_clipped = (1.0 + clipped_variance / (core * core)).sqrt();
    let s_sampled = (s_clipped * s_clipped + (sample_sigma / core).powi(2)).sqrt();
    let spread = s_sampled * core;
    // Down to 1 % of the peak: 6 σ of the core and the blur, and on the tail's side 5 τ.
    let tail = if profile.tail_weight() > 0.0 { 5.0 * profile.tail_length() * core } else { 0.0 };
    let from = -6.0 * spread;
    let n = ((12.0 * spread + tail) / step).ceil() as usize;
    let x = |m: usize| x_px(from, step, m as f64);
    // The light as clipped (before the sampling kernel) and as sampled without clipping.
    let light: Vec<f64> = (0..n).map(|m| profile.unit(x(m) / core, s_clipped)).collect();
    let sampled: Vec<f64> = (0..n).map(|m| profile.unit(x(m) / core, s_sampled)).collect();
    let reach = (4.0 * sample_sigma / step).ceil() as usize;
    let kernel: Vec<f64> = (0..=reach)
        .map(|d| (-0.5 * (d as f64 * step / sample_sigma).powi(2)).exp() * step / (sample_sigma * TAU.sqrt()))
        .collect();
    let peak_light = light.iter().copied().fold(0.0, f64::max);
    let mode = (0..n).max_by(|&a, &b| sampled[a].total_cmp(&sampled[b]))?;
    let sheet_peak = profile.mode() * core;
    let mut w = ClippedWidth {
        half_width: 0.0,
        edges: [[0.0; CLIPS]; LEVEL_SHARES.len()],
        midpoints: [[0.0; CLIPS]; LEVEL_SHARES.len()],
    };
    let known = vec![std::cell::Cell::new(f64::NAN); n];
    for j in 0..CLIPS {
        let clip = peak_light * CLIP_RATIO.powi(j as i32);
        // The clipped run [a, b) of the light, and the sampled value at grid point m: the
        // unclipped one less the kernel's sum over what the clip cut off.
        let a = light.iter().position(|&v| v > clip).unwrap_or(mode);
        let b = a + light[a..].iter().take_while(|&&v| v > clip).count();
        // Each grid point once per clip: the shares' and phases' walks share them.
        known.iter().for_each(|c| c.set(f64::NAN));
        let value = |m: usize| {
            if known[m].get().is_nan() {
                let (lo, hi) = (m.saturating_sub(reach).max(a), (m + reach + 1).min(b));
                known[m].set(sampled[m] - (lo..hi).map(|y| (light[y] - clip) * kernel[y.abs_diff(m)]).sum::<f64>());
            }
            known[m].get()
        };
        // Walks start inside the plateau, where the kernel cannot reach past its edges; on a
        // narrower one, from each phase's highest sample, which sets that phase's plateau (the
        // detector's is its own highest sample).
        let wide = b - a > 2 * reach + 2;
        let (around, reach_top) = if b > a { ((a + b) / 2, (b - a) / 2 + reach) } else { (mode, PHASES) };
        for phase in 0..PHASES {
            let (top_at, top) = if wide {
                ((a + b) / 2, value((a + b) / 2))
            } else {
                let first = around.saturating_sub(reach_top);
                let first = first - first % PHASES + phase;
                (first..(around + reach_top + 1).min(n))
                    .step_by(PHASES)
                    .map(|m| (m, value(m)))
                    .max_by(|p, q| p.1.total_cmp(&q.1))?
            };
            let inside = if wide { (a + reach + 1, b - reach - 1) } else { (top_at, top_at) };
            for (i, share) in LEVEL_SHARES.iter().enumerate() {
                let level = 0.5 * (1.0 + share) * top;
                match sampled_crossings(&value, n, inside, phase, level) {
                    Some((rising, falling)) => {
                        w.edges[i][j] += (x_px(from, step, falling) - x_px(from, step, rising)) / PHASES as f64;
                        let midpoint = 0.5 * (x_px(from, step, rising) + x_px(from, step, falling)) - sheet_peak;
                        w.midpoints[i][j] += midpoint / PHASES as f64;
                    }
                    None => w.edges[i][j] = f64::NAN,
                }
            }
        }
    }
    w.half_width = w.edges[0][0];
    Some(w)
}

/// A grid point's place (px, possibly fractional).
fn x_px(from: f64, step: f64, m: f64) -> f64 {
    from + m * step
}

/// Where the samples of one phase (grid points `phase` mod [`PHASES`]) of a profile (`value`
/// at each of `n` grid points) cross `level`, walking out from the phase's highest sample next
/// to each of `inside` (the rising edge's start, the falling edge's), linearly interpolated
/// between samples as [`estimators::crossings`] does: (rising, falling) as fractional grid
/// points; `None` where a start lies below `level` or a walk leaves the grid.
fn sampled_crossings(
    value: &impl Fn(usize) -> f64,
    n: usize,
    (rising_from, falling_from): (usize, usize),
    phase: usize,
    level: f64,
) -> Option<(f64, f64)> {
    // The phase's highest sample next to each start.
    let start = |from: usize| {
        let m = from - from % PHASES + phase;
        [m.checked_sub(PHASES), Some(m), Some(m + PHASES)]
            .into_iter()
            .flatten()
            .filter(|&m| m < n)
            .map(|m| (m, value(m)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .filter(|&(_, v)| v >= level)
    };
    let (mut m, mut v) = start(falling_from)?;
    loop {
        if m + PHASES >= n {
            return None;
        }
        let next = value(m + PHASES);
        if next < level {
            break;
        }
        (m, v) = (m + PHASES, next);
    }
    let falling = m as f64 + PHASES as f64 * (v - level) / (v - value(m + PHASES));
    let (mut m, mut v) = start(rising_from)?;
    loop {
        if m < PHASES {
            return None;
        }
        let next = value(m - PHASES);
        if next < level {
            break;
        }
        (m, v) = (m - PHASES, next);
    }
    let rising = m as f64 - PHASES as f64 * (v - level) / (v - value(m - PHASES));
    Some((rising, falling))
}

/// A sheet of core σ `core` px blurred by variance `blur_variance` px², sampled as the
/// detector samples it: its half-maximum width and its top centroid's place from the sheet's
/// peak (px) ([`sampled_phases`]). On the tail's side the samples reach 2 τ past 5 σ, past
/// the half maximum for any share up to 0.9 (an exponential halves in 0.7 τ).
fn sampled_top(profile: &LaserProfile, core: f64, blur_variance: f64) -> Option<(f64, [f64; 1])> {
    sampled_phases(profile, core, blur_variance, 2.0, |q, top, place| {
        let seg = Segment { start: 1, end: q.len() - 1, peak: top };
        let (centre, _) = estimators::top_centroid(q, &seg, super::across::TOP_LEVEL * q[top])?;
        Some([place(centre)])
    })
}

/// A sheet of core σ `core` px blurred by variance `blur_variance` px², sampled
/// [`SAMPLE_STEP_PX`] apart from 5 σ of the core and the blur before its peak to 5 σ and
/// `tails` tail lengths after it, at each of [`PHASES`] sub-sample phases: the half-maximum
/// width and what `measure(samples, highest sample's index, place)` gives, averaged over the
/// phases; `place(index)` is where a fractional sample index lies from the sheet's peak (px).
fn sampled_phases<const N: usize>(
    profile: &LaserProfile,
    core: f64,
    blur_variance: f64,
    tails: f64,
    measure: impl Fn(&[f32], usize, &dyn Fn(f64) -> f64) -> Option<[f64; N]>,
) -> Option<(f64, [f64; N])> {
    let s = (1.0 + blur_variance / (core * core)).sqrt();
    let spread = s * core;
    let peak = profile.mode() * core;
    let tail = if profile.tail_weight() > 0.0 { tails * profile.tail_length() * core } else { 0.0 };
    let (from, to) = (-5.0 * spread, 5.0 * spread + tail);
    let n = ((to - from) / SAMPLE_STEP_PX).ceil() as usize + 3;
    let (mut half_width, mut sum) = (0.0, [0.0; N]);
    let mut q = vec![0.0f32; n];
    for phase in 0..PHASES {
        let first = from + SAMPLE_STEP_PX * (phase as f64 / PHASES as f64 - 1.0);
        for (k, v) in q.iter_mut().enumerate() {
            *v = profile.unit((first + k as f64 * SAMPLE_STEP_PX) / core, s) as f32;
        }
        let top = (0..n).max_by(|&a, &b| q[a].total_cmp(&q[b]))?;
        let seg = Segment { start: 1, end: n - 1, peak: top };
        let (a, b) = estimators::crossings(&q, &seg, 0.5 * q[top])?;
        half_width += (b - a) * SAMPLE_STEP_PX;
        let place = |index: f64| first + index * SAMPLE_STEP_PX - peak;
        for (total, value) in sum.iter_mut().zip(measure(&q, top, &place)?) {
            *total += value;
        }
    }
    let phases = PHASES as f64;
    Some((half_width / phases, sum.map(|v| v / phases)))
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
        let [sampled] = sampled_top(&p, core, blur).unwrap().1;
        assert!((sampled - continuous).abs() < 0.01, "sampled {sampled}, continuous {continuous}");
    }
}

#[cfg(test)]
mod clipped_tests {
    use super::*;
    use crate::stripe::sampling::SAMPLE_SIGMA_PX;

    /// One row across a vertical stripe as the camera and the detector see it: pixels
    /// integrate the light (`amplitude` × the profile of core σ `core` px blurred by a lens of
    /// σ `lens` px, sheet's peak at `centre` px; 1 px boxes, 64 points each), clip at 255, and
    /// the detector's Gaussian sampler (σ [`SAMPLE_SIGMA_PX`] on the pixel grid, taps −2..=3
    /// about ⌊x⌋) reads them every [`SAMPLE_STEP_PX`] from x = 10.
    fn detector_row(profile: &LaserProfile, core: f64, lens: f64, amplitude: f64, centre: f64) -> Vec<f32> {
        let s = (1.0 + lens * lens / (core * core)).sqrt();
        let pixels: Vec<f64> = (0..120)
            .map(|i| {
                let sum: f64 = (0..64)
                    .map(|k| {
                        profile.unit((i as f64 - 0.5 + (k as f64 + 0.5) / 64.0 - centre) / core + profile.mode(), s)
                    })
                    .sum();
                (amplitude * sum / 64.0).round().min(255.0)
            })
            .collect();
        (0..200)
            .map(|k| {
                let x = 10.0 + k as f64 * SAMPLE_STEP_PX;
                let base = x.floor();
                let w: Vec<f64> = (-2..=3)
                    .map(|d| (-(base + d as f64 - x).powi(2) / (2.0 * SAMPLE_SIGMA_PX.powi(2))).exp())
                    .collect();
                let sum: f64 = w.iter().sum();
                ((-2..=3).zip(&w).map(|(d, w)| w * pixels[(base as i64 + d) as usize]).sum::<f64>() / sum) as f32
            })
            .collect()
    }

    fn segment(q: &[f32]) -> Segment {
        let peak = (0..q.len()).max_by(|&a, &b| q[a].total_cmp(&q[b])).unwrap();
        Segment { start: 1, end: q.len() - 1, peak }
    }

    /// The windowed centroid's table against unclipped lopsided stripes read as the detector
    /// reads them (8-bit pixels, the sampling kernel, threshold 10 over a dark background, 8
    /// places of the sheet within a pixel): 0.07–0.11 px towards the tail, led back to the
    /// sheet's peak (2 / 4 / 8 px wide: −0.0004 / −0.0009 / −0.0047 px; asserted within 0.006);
    /// a Gaussian sheet's windowed centroid is its peak.
    #[test]
    fn the_windowed_table_finds_an_unclipped_lopsided_stripes_sheet_peak() {
        let lens = 0.7;
        let blur = lens * lens + 1.0 / 12.0 + SAMPLE_SIGMA_PX * SAMPLE_SIGMA_PX;
        let gauss = WindowedOffsets::new(&LaserProfile::gaussian(), blur);
        assert_eq!(gauss.offset_at(3.0, 0.01), None, "a level below the table's");
        for (h, level) in [(2.0, 0.05), (5.0, 0.3), (20.0, 0.6)] {
            let offset = gauss.offset_at(h, level).unwrap();
            assert!(offset.abs() < 2e-3, "{h} px at {level}: {offset}");
        }
        let profile = LaserProfile::tailed(0.17, 4.0);
        let model = WindowedOffsets::new(&profile, blur);
        for fwhm in [2.0, 4.0, 8.0] {
            let core = fwhm / profile.fwhm();
            let (mut raw, mut led) = (0.0, 0.0);
            let phases = 8;
            for phase in 0..phases {
                let centre = 40.0 + phase as f64 / phases as f64;
                let q = detector_row(&profile, core, lens, 150.0, centre);
                let seg = segment(&q);
                let t = 10.0f32;
                let run = crate::stripe::segment_at(&q, seg.peak, t).unwrap();
                let index = estimators::windowed_centroid(&q, &run, t).unwrap();
                let (a, b) = estimators::crossings(&q, &run, 0.5 * q[run.peak]).unwrap();
                let offset = model.offset_at((b - a) * SAMPLE_STEP_PX, (t / q[run.peak]) as f64).unwrap();
                let centroid = 10.0 + index * SAMPLE_STEP_PX - centre;
                raw += centroid / phases as f64;
                led += (centroid - offset) / phases as f64;
            }
            assert!(raw > 0.05, "FWHM {fwhm} px: the tail pulls the windowed centroid, {raw} px");
            assert!(led.abs() <= 0.006, "FWHM {fwhm} px: {led} px from the sheet's peak once led ({raw} px before)");
        }
    }

    /// A Gaussian sheet's plateau is centred on its peak at every depth.
    #[test]
    fn a_gaussian_sheets_plateau_centre_is_its_peak() {
        let model = PlateauOffsets::new(&LaserProfile::gaussian(), 0.5, SAMPLE_SIGMA_PX);
        for h in [3.0, 4.0, 10.0, 30.0, 60.0] {
            for edges in [0.5, 1.0, 1.4, 1.8].map(|r| r * h) {
                let m = model.midpoint_at(h, 0.05, edges, 0.1).unwrap();
                assert!(m.abs() < 2e-3, "{h} px, edges {edges} px: {m}");
            }
        }
        assert_eq!(model.midpoint_at(0.1, 0.0, 1.0, 0.0), None, "narrower than the blur");
        assert_eq!(model.midpoint_at(4.0, 0.0, 40.0, 0.0), None, "clipped beyond 50 ×");
    }

    /// The table against a clipped lopsided stripe read as the detector reads it: the sheet's
    /// width from an unclipped row of the same sheet, the plateau's edges from the clipped one
    /// (σ 0.8 px kernel on 8-bit pixels, 8 places of the sheet within a pixel). The plateau's
    /// centre lies 0.11-9 px towards the tail; the table takes it to within 0.006 px of the
    /// sheet's peak up to 8 px wide and 33 × the clip, and 0.008 px at 16 px up to 8 ×.
    #[test]
    fn the_table_finds_a_clipped_lopsided_stripes_sheet_peak() {
        let profile = LaserProfile::tailed(0.17, 4.0);
        let lens = 0.7;
        let model = PlateauOffsets::new(&profile, lens * lens + 1.0 / 12.0, SAMPLE_SIGMA_PX);
        for fwhm in [2.5, 4.0, 8.0, 16.0] {
            let core = fwhm / profile.fwhm();
            let peak_of = |a: f64| {
                let q = detector_row(&profile, core, lens, a, 60.3);
                q.iter().copied().fold(0.0f32, f32::max) as f64
            };
            let unit = peak_of(100.0) / 100.0;
            let depths: &[f64] = if fwhm <= 8.0 { &[1.5, 3.0, 8.0, 12.0, 20.0, 33.0] } else { &[1.5, 3.0, 8.0] };
            for &over in depths {
                let (mut raw, mut led) = (0.0, 0.0);
                let phases = 8;
                for phase in 0..phases {
                    let centre = 60.0 + phase as f64 / phases as f64;
                    let dim = detector_row(&profile, core, lens, 150.0 / unit, centre);
                    let seg = segment(&dim);
                    let (a, b) = estimators::crossings(&dim, &seg, 0.5 * dim[seg.peak]).unwrap();
                    let half_width = (b - a) * SAMPLE_STEP_PX;
                    let bright = detector_row(&profile, core, lens, over * 255.0 / unit, centre);
                    let seg = segment(&bright);
                    let (t, top) = (10.0, bright[seg.peak]);
                    let (a, b) = estimators::plateau_edges(&bright, &seg, t, top).unwrap();
                    let midpoint = 10.0 + 0.5 * (a + b) * SAMPLE_STEP_PX - centre;
                    let edges = (b - a) * SAMPLE_STEP_PX;
                    let offset = model.midpoint_at(half_width, 0.0, edges, (t / top) as f64).unwrap();
                    raw += midpoint / phases as f64;
                    led += (midpoint - offset) / phases as f64;
                }
                eprintln!("FWHM {fwhm} px, {over} × the clip: plateau centre {raw:+.4} px, led {led:+.4} px");
                assert!(raw > 0.1, "the tail pulls the plateau's centre: {raw} px");
                assert!(led.abs() <= 0.01, "FWHM {fwhm} px, {over} × the clip: {led} px from the sheet's peak");
            }
        }
    }
}
