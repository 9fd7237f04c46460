//! A line laser's cross-section measured from its stripe frames: the share of its light in a
//! one-sided tail and the tail's length ([`LaserProfile::tailed`]), which the stripe detector
//! takes as `--laser-tail SHARE,LENGTH`.
//!
//! Per frame: each stripe point's profile is sampled along the stripe's normal (from its
//! neighbours' line) over six FWHM either side ([`window_half_px`]), its background taken out (the
//! line through the window's two ends), aligned on its own peak and scaled to it; windows whose
//! ends differ or whose flanks step are left out. The median of the
//! frame's profiles is fitted by the tailed profile under the known blur (Levenberg–Marquardt:
//! centre, core σ, tail share and length, height, a linear background), with the tail on either
//! side. The normals of a frame are turned to one side of the stripe's mean direction, never by
//! a profile's own shape: a side chosen per profile by its heavier flank would make a tail out
//! of noise. A laser's tail lies on one side of its sheet, so one frame's stripe has it on one
//! side; the report gives it as an image direction, and the detector finds it per stripe
//! itself. The frames' medians are the laser's figures. The pixel values are taken as
//! proportional to the light: a gamma-encoded frame (sRGB) makes the tail look heavier.

use crate::fixed_plane::Skipped;
use omni_formats::stream::{StripePoint, quality};
use omni_geom::lm;
use omni_model::{LaserProfile, MirrorCircle};
use omni_vision::colour::{Channel, ColourSpec};
use omni_vision::image_io::{GrayImage, load_frame_channels};
use omni_vision::stripe::{RidgeDetector, RidgeParams};
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;

/// Settings of the measurement.
#[derive(Debug, Clone, Copy)]
pub struct TailOptions {
    /// The lens's blur σ (px): it widens the core, not the tail.
    pub blur_px: f64,
    /// Fewest usable profiles for a frame to be measured.
    pub min_profiles: usize,
    /// A catadioptric camera's mirror (px): its annulus is searched, and stripes that curve
    /// around its centre (rings about the mirror's axis) have their normals turned away from it.
    /// `None`: the whole frame, turned about the image's centre.
    pub mirror: Option<MirrorCircle>,
}

impl Default for TailOptions {
    fn default() -> Self {
        TailOptions { blur_px: 0.0, min_profiles: 30, mirror: None }
    }
}

/// One frame's measured cross-section.
#[derive(Debug, Clone, Serialize)]
pub struct FrameTail {
    pub name: String,
    /// Profiles in the frame's median.
    pub profiles: usize,
    /// The sheet's core σ in the image (px, the blur taken out) and the stripe's FWHM (px, the
    /// blur in).
    pub core_sigma_px: f64,
    pub fwhm_px: f64,
    /// Share of the light in the tail, and the tail's length in core σ, with their σ from the fit.
    pub tail_weight: f64,
    pub tail_weight_sigma: f64,
    pub tail_length: f64,
    pub tail_length_sigma: f64,
    /// The tail's side along the frame's oriented normals (±1), and the image direction (unit,
    /// x right, y down) it lies towards on average: `None` for a ring, whose normals are turned
    /// away from the centre (+1: the tail lies outwards).
    pub side: f64,
    pub tail_direction: Option<[f64; 2]>,
    /// RMS of the fit's residuals over the median profile (its peak is 1), and the same for a
    /// Gaussian (no tail) for comparison.
    pub residual_rms: f64,
    pub gaussian_residual_rms: f64,
}

/// Half the sampled window across a stripe (px) for a stripe of FWHM `fwhm` px: a tail of 4–6
/// core σ falls to a few per cent of its height within six FWHM.
pub fn window_half_px(fwhm: f64) -> f64 {
    (6.0 * fwhm).clamp(12.0, 80.0)
}

/// A tail counts as measured where the tailed profile's residual is at most this share of a
/// Gaussian's (rendered tailed sheets: 0.07-0.2; real frames where a tail shows: 0.44-0.77).
const MAX_RESIDUAL_RATIO: f64 = 0.85;
/// ... and its share's σ at most this, its length's σ at most this share of the length: beyond
/// them the fit trades share against length along a valley and tells neither.
const MAX_WEIGHT_SIGMA: f64 = 0.1;
const MAX_LENGTH_SIGMA: f64 = 0.5;
/// A tail's share must stand this many of its own σ above zero: a smaller one is the noise of a
/// profile with no tail, fitted as one.
const MIN_WEIGHT_SIGNIFICANCE: f64 = 3.0;

/// The level (share of full scale) above which the laser colour's contrast weighs the other two
/// channels less (`omni_vision::colour`).
const COMPRESSED_LEVEL: f64 = 0.75;

/// A fitted share at or above this (near its bound of 0.9), or a length outside these (core σ),
/// is a core of another shape taken for a tail: a tail shorter than half the core's σ is the
/// core's own flank, one longer than 50 σ the background's.
const MAX_FITTED_WEIGHT: f64 = 0.85;
const MIN_TAIL_LENGTH: f64 = 0.5;
const MAX_TAIL_LENGTH: f64 = 50.0;

/// Neighbours (px) whose line gives a point's normal.
const NORMAL_REACH_PX: f64 = 4.0;
/// Samples at each end of a window whose line is the profile's background.
const END_SAMPLES: usize = 6;
/// A window whose end samples scatter, or whose two ends differ, by more than this share of the
/// profile's height holds an edge or another light, not a background a line takes out.
const MAX_END_SCATTER: f64 = 0.05;
/// The normals of a frame must agree at least this well (mean resultant length of their doubled
/// angles) for one side to be theirs.
const MIN_NORMAL_AGREEMENT: f64 = 0.7;

/// Measures the laser's cross-section on one frame's stripe: `image` is what the detector read
/// (a colour's laser contrast, a channel), `points` its stripe points there. Where `image` is a
/// laser colour's contrast, `laser_channel` is that colour's own channel: the contrast weighs the
/// other two channels less above [`COMPRESSED_LEVEL`] of full scale, which flattens a profile's
/// top, so points brighter than that there are left out like saturated ones.
pub fn measure_frame(
    name: &str,
    image: &GrayImage,
    points: &[StripePoint],
    laser_channel: Option<&GrayImage>,
    opts: &TailOptions,
) -> Result<FrameTail, String> {
    let compressed = |p: &StripePoint| {
        laser_channel.is_some_and(|c| {
            let (x, y) =
                (p.u.round().clamp(0.0, f64::from(c.width) - 1.0), p.v.round().clamp(0.0, f64::from(c.height) - 1.0));
            f64::from(c.get(x as u32, y as u32)) > COMPRESSED_LEVEL * f64::from(c.max_value())
        })
    };
    let usable: Vec<&StripePoint> = points
        .iter()
        .filter(|p| p.quality & quality::SATURATED == 0 && p.width.is_finite() && !compressed(p))
        .collect();
    if usable.len() < opts.min_profiles {
        return Err(format!(
            "{} unsaturated stripe points, fewer than {} ({} saturated or above {:.0} % of full scale)",
            usable.len(),
            opts.min_profiles,
            points.len() - usable.len(),
            100.0 * COMPRESSED_LEVEL
        ));
    }
    let centre =
        opts.mirror.map_or((0.5 * (f64::from(image.width) - 1.0), 0.5 * (f64::from(image.height) - 1.0)), |m| {
            (m.centre.x, m.centre.y)
        });
    let normals = oriented_normals(&usable, centre)?;
    let (profiles, fwhm) = frame_profiles(image, &usable, &normals, opts.min_profiles)?;
    let median = median_profile(&profiles);
    let reach = median.len() / 2;
    let xs: Vec<f64> = (0..median.len()).map(|k| k as f64 - reach as f64).collect();
    // The blur of the frame's median profile: the lens's and the pixel's area (the stripe's
    // own), and the bilinear sampling across the stripe (a triangle at any phase, 1/6 px²); the
    // resampling onto the peak adds little, its phase the detector's small error.
    let own_blur = opts.blur_px * opts.blur_px + 1.0 / 12.0;
    let blur_variance = own_blur + 1.0 / 6.0;
    let fits: Vec<TailFit> =
        [1.0, -1.0].iter().filter_map(|&side| fit_tail(&xs, &median, side, blur_variance, fwhm)).collect();
    let best = fits
        .iter()
        .min_by(|a, b| a.rms.total_cmp(&b.rms))
        .ok_or_else(|| "the tailed profile does not fit the frame's median profile".to_string())?;
    let gaussian = fit_gaussian(&xs, &median, blur_variance, fwhm).unwrap_or(f64::NAN);
    accept(best, gaussian)?;
    let profile = LaserProfile::tailed(best.weight, best.length);
    let s = (1.0 + own_blur / (best.sigma * best.sigma)).sqrt();
    let (lo, hi) = profile.half_points(s);
    Ok(FrameTail {
        name: name.to_string(),
        profiles: profiles.len(),
        core_sigma_px: best.sigma,
        fwhm_px: (hi - lo) * best.sigma,
        tail_weight: best.weight,
        tail_weight_sigma: best.weight_sigma,
        tail_length: best.length,
        tail_length_sigma: best.length_sigma,
        side: best.side,
        tail_direction: mean_direction(&normals).map(|(x, y)| [best.side * x, best.side * y]),
        residual_rms: best.rms,
        gaussian_residual_rms: gaussian,
    })
}

/// Whether `best` measures a tail: it fits clearly better than a Gaussian (residual `gaussian`),
/// stays off its bounds, stands out of its noise and tells share from length.
fn accept(best: &TailFit, gaussian: f64) -> Result<(), String> {
    if !(best.rms <= MAX_RESIDUAL_RATIO * gaussian) {
        return Err(format!(
            "no tail stands out: the median profile fits a Gaussian as well (residual {:.4} against {:.4} of its peak)",
            best.rms, gaussian
        ));
    }
    if !(best.weight < MAX_FITTED_WEIGHT && (MIN_TAIL_LENGTH..=MAX_TAIL_LENGTH).contains(&best.length)) {
        return Err(format!(
            "the fit ends at its bounds (share {:.2}, length {:.2} core σ): a core of another shape, not a tail",
            best.weight, best.length
        ));
    }
    if !(best.weight >= MIN_WEIGHT_SIGNIFICANCE * best.weight_sigma) {
        return Err(format!(
            "no tail stands out of the noise (share {:.3} ± {:.3}, length {:.1} core σ)",
            best.weight, best.weight_sigma, best.length
        ));
    }
    if !(best.weight_sigma <= MAX_WEIGHT_SIGMA && best.length_sigma <= MAX_LENGTH_SIGMA * best.length) {
        return Err(format!(
            "the tail's share and length are not told apart (share {:.2} ± {:.2}, length {:.1} ± {:.1} core σ)",
            best.weight, best.weight_sigma, best.length, best.length_sigma
        ));
    }
    Ok(())
}

/// The frame's aligned profiles ([`aligned_profile`]) with a clean background over six FWHM
/// either side, and that FWHM (px): first from a narrower window (the detector's width, taken at
/// its threshold, is wider than the FWHM), where the median alone keeps the core's width and the
/// window may end in the tail.
fn frame_profiles(
    image: &GrayImage,
    usable: &[&StripePoint],
    normals: &[Option<(f64, f64)>],
    min_profiles: usize,
) -> Result<(Vec<Vec<f64>>, f64), String> {
    let profiles_over = |half: usize, clean: bool| -> Vec<Vec<f64>> {
        let profile =
            |(p, n): (&&StripePoint, &Option<(f64, f64)>)| aligned_profile(image, (p.u, p.v), (*n)?, half, clean);
        usable.iter().zip(normals).filter_map(profile).collect()
    };
    let widths: Vec<f64> = usable.iter().map(|p| p.width).collect();
    let first_half = (2.0 * omni_geom::stats::median(&widths).unwrap_or(f64::NAN)).clamp(6.0, 40.0);
    let first = profiles_over(first_half as usize, false);
    if first.len() < min_profiles {
        return Err(format!(
            "{} of {} profiles peak within ±{first_half:.0} px, fewer than {min_profiles}",
            first.len(),
            usable.len()
        ));
    }
    let median_first = median_profile(&first);
    let fwhm = half_maximum_width(&median_first, median_first.len() / 2)
        .ok_or_else(|| format!("the median profile does not fall to half its peak within ±{first_half:.0} px"))?;
    let half = window_half_px(fwhm).round() as usize;
    let profiles = profiles_over(half, true);
    if profiles.len() < min_profiles {
        return Err(format!(
            "{} of {} profiles lie in the image with a clean background over ±{half} px, fewer than {min_profiles}",
            profiles.len(),
            usable.len()
        ));
    }
    Ok((profiles, fwhm))
}

/// Each point's unit normal (px) from the line through its neighbours within
/// [`NORMAL_REACH_PX`], all turned to one side of the stripe; `None` for points with too few
/// neighbours. A stripe whose normals agree (a straight or gently curved one) is turned to the
/// side of their mean direction; one that bends further (a ring about a catadioptric camera's
/// axis) away from `centre` (px), which keeps one side of a ring about it, as of any line that
/// misses it. An error where neither holds: normals that spread, and neighbours' normals that
/// disagree once turned away from the centre (more than [`MAX_FLIPPED_SHARE`] of them).
fn oriented_normals(points: &[&StripePoint], centre: (f64, f64)) -> Result<Vec<Option<(f64, f64)>>, String> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].u.total_cmp(&points[b].u));
    let mut normals = vec![None; points.len()];
    let mut neighbours = vec![Vec::new(); points.len()];
    for (k, &i) in order.iter().enumerate() {
        let p = points[i];
        let near = |j: &&usize| (points[**j].u - p.u).abs() <= NORMAL_REACH_PX;
        let before = order[..k].iter().rev().take_while(near);
        let after = order[k + 1..].iter().take_while(near);
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for &j in before.chain(after) {
            let (dx, dy) = (points[j].u - p.u, points[j].v - p.v);
            if dx * dx + dy * dy <= NORMAL_REACH_PX * NORMAL_REACH_PX {
                (sxx, sxy, syy) = (sxx + dx * dx, sxy + dx * dy, syy + dy * dy);
                neighbours[i].push(j);
            }
        }
        if neighbours[i].len() >= 3 {
            // The tangent is the scatter's major axis; the normal is square to it.
            let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
            normals[i] = Some((-angle.sin(), angle.cos()));
        }
    }
    let (c, s, n) = normals.iter().flatten().fold((0.0, 0.0, 0usize), |(c, s, n), (x, y)| {
        let doubled = 2.0 * y.atan2(*x);
        (c + doubled.cos(), s + doubled.sin(), n + 1)
    });
    let agreement = c.hypot(s) / n.max(1) as f64;
    if agreement >= MIN_NORMAL_AGREEMENT {
        let mean = 0.5 * s.atan2(c);
        let (mx, my) = (mean.cos(), mean.sin());
        return Ok(normals
            .into_iter()
            .map(|n| n.map(|(x, y)| if x * mx + y * my < 0.0 { (-x, -y) } else { (x, y) }))
            .collect());
    }
    // Turned away from the centre, neighbours' normals must agree: they do along a ring about
    // it and a line that misses it, and flip where the stripe's tangent passes the centre.
    let away = |p: &StripePoint, (x, y): (f64, f64)| {
        if x * (p.u - centre.0) + y * (p.v - centre.1) < 0.0 { (-x, -y) } else { (x, y) }
    };
    let turned: Vec<Option<(f64, f64)>> = points.iter().zip(normals).map(|(p, n)| n.map(|n| away(p, n))).collect();
    let flipped = turned
        .iter()
        .zip(&neighbours)
        .filter(|(n, near)| {
            n.is_some_and(|(x, y)| near.iter().any(|&j| turned[j].is_some_and(|(a, b)| x * a + y * b < 0.0)))
        })
        .count();
    if flipped as f64 > MAX_FLIPPED_SHARE * turned.len() as f64 {
        return Err(format!(
            "the stripe's normals spread too widely to put its profiles on one side (agreement {agreement:.2} of 1, at least {MIN_NORMAL_AGREEMENT}), and turned away from the centre ({:.0}, {:.0}) {flipped} of {} disagree with a neighbour",
            centre.0,
            centre.1,
            turned.len()
        ));
    }
    Ok(turned)
}

/// The unit mean of the oriented `normals`; `None` where they cancel (a ring).
fn mean_direction(normals: &[Option<(f64, f64)>]) -> Option<(f64, f64)> {
    let (x, y, n) = normals.iter().flatten().fold((0.0, 0.0, 0usize), |(x, y, n), (a, b)| (x + a, y + b, n + 1));
    let length = x.hypot(y);
    (length >= 0.5 * n as f64 && n > 0).then(|| (x / length, y / length))
}

/// At most this share of a curved stripe's normals, turned away from the centre, may disagree
/// with a neighbour's.
const MAX_FLIPPED_SHARE: f64 = 0.02;

/// The profile through (`u`, `v`) along `normal`, sampled every 1 px over ±`half` px
/// (bilinear), its background line taken out, resampled onto its own peak (a parabola through
/// the top three samples) over ±(`half` − 2) px and scaled to that peak's height. `None` where
/// the window leaves the image or no peak stands out, and where `clean` asks for a clean
/// background and its ends scatter, differ or its flanks step.
fn aligned_profile(
    image: &GrayImage,
    (u, v): (f64, f64),
    (nx, ny): (f64, f64),
    half: usize,
    clean: bool,
) -> Option<Vec<f64>> {
    let n = 2 * half + 1;
    let mut q = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 - half as f64;
        q.push(bilinear(image, u + t * nx, v + t * ny)?);
    }
    let ends = |s: &[f64]| {
        let m = s.iter().sum::<f64>() / s.len() as f64;
        (m, (s.iter().map(|x| (x - m).powi(2)).sum::<f64>() / s.len() as f64).sqrt())
    };
    let ((left, left_sd), (right, right_sd)) = (ends(&q[..END_SAMPLES]), ends(&q[n - END_SAMPLES..]));
    let centre_of_ends = (END_SAMPLES as f64 - 1.0) / 2.0;
    let span = (n - 1) as f64 - 2.0 * centre_of_ends;
    for (k, x) in q.iter_mut().enumerate() {
        let f = (k as f64 - centre_of_ends) / span;
        *x -= left + f * (right - left);
    }
    let top = (1..n - 1).max_by(|&a, &b| q[a].total_cmp(&q[b]))?;
    let (a, b, c) = (q[top - 1], q[top], q[top + 1]);
    let curvature = a - 2.0 * b + c;
    if !(curvature < 0.0) {
        return None;
    }
    let offset = (0.5 * (a - c) / curvature).clamp(-0.5, 0.5);
    let height = b - 0.125 * (a - c) * (a - c) / curvature;
    let uneven = left_sd.max(right_sd).max((left - right).abs());
    if !(height > 0.0) || clean && (uneven > MAX_END_SCATTER * height || has_step(&q, top, half, height)) {
        return None;
    }
    let reach = half - 2;
    let peak = top as f64 + offset;
    (0..2 * reach + 1)
        .map(|k| {
            let x = peak + k as f64 - reach as f64;
            let i = x.floor();
            let f = x - i;
            (i >= 0.0 && (i as usize) + 1 < n).then(|| ((1.0 - f) * q[i as usize] + f * q[i as usize + 1]) / height)
        })
        .collect()
}

/// Whether the flanks of profile `q` (background out, peak `height` at `top`) step anywhere
/// beyond a third of the window from the peak: adjacent blocks of [`END_SAMPLES`] whose means
/// differ by more than [`MAX_END_SCATTER`] of the height (an edge between two albedos, another
/// light), where a laser's tail only falls smoothly.
fn has_step(q: &[f64], top: usize, half: usize, height: f64) -> bool {
    let clear = half / 3;
    let block = |k: usize| q[k..k + END_SAMPLES].iter().sum::<f64>() / END_SAMPLES as f64;
    let outside = |k: usize| k + END_SAMPLES <= top.saturating_sub(clear) || k >= top + clear;
    (0..q.len().saturating_sub(2 * END_SAMPLES))
        .filter(|&k| outside(k) && outside(k + END_SAMPLES))
        .any(|k| (block(k) - block(k + END_SAMPLES)).abs() > MAX_END_SCATTER * height)
}

/// The width (px) between the half-maximum crossings of a profile sampled every 1 px with its
/// peak of 1 at sample `mid`; `None` where it does not fall to half on both sides.
fn half_maximum_width(profile: &[f64], mid: usize) -> Option<f64> {
    let crossing = |step: isize| {
        let mut k = mid as isize;
        loop {
            let next = k + step;
            let y = *profile.get(usize::try_from(next).ok()?)?;
            if y < 0.5 {
                let y0 = profile[k as usize];
                return Some((k as f64 + step as f64 * (y0 - 0.5) / (y0 - y)) - mid as f64);
            }
            k = next;
        }
    };
    Some(crossing(1)? - crossing(-1)?)
}

/// The image at (x, y) px, bilinear; `None` outside it.
fn bilinear(image: &GrayImage, x: f64, y: f64) -> Option<f64> {
    let (x0, y0) = (x.floor(), y.floor());
    if !(x0 >= 0.0 && y0 >= 0.0 && x0 + 1.0 < image.width as f64 && y0 + 1.0 < image.height as f64) {
        return None;
    }
    let (fx, fy) = (x - x0, y - y0);
    let (i, j) = (x0 as u32, y0 as u32);
    let at = |a: u32, b: u32| f64::from(image.get(a, b));
    let top = (1.0 - fx) * at(i, j) + fx * at(i + 1, j);
    let bottom = (1.0 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1);
    Some((1.0 - fy) * top + fy * bottom)
}

/// The median of `profiles` (all of one length) at each sample.
fn median_profile(profiles: &[Vec<f64>]) -> Vec<f64> {
    let n = profiles[0].len();
    let mut column = Vec::with_capacity(profiles.len());
    (0..n)
        .map(|k| {
            column.clear();
            column.extend(profiles.iter().map(|p| p[k]));
            omni_geom::stats::median(&column).unwrap_or(f64::NAN)
        })
        .collect()
}

/// The tailed profile fitted to one frame's median profile.
#[derive(Debug, Clone, Copy)]
struct TailFit {
    side: f64,
    sigma: f64,
    weight: f64,
    weight_sigma: f64,
    length: f64,
    length_sigma: f64,
    rms: f64,
}

/// The largest tail share fitted ([`LaserProfile::validate`]'s bound).
const MAX_TAIL_WEIGHT: f64 = 0.9;

/// `median` at `xs` as a·P(side·(x − x0)) + b + c·x, P the tailed profile of core σ e^ls, share
/// 0.9·logistic(lw) and length e^ll core σ, widened by `blur_variance` (px²).
struct TailProblem<'a> {
    xs: &'a [f64],
    ys: &'a [f64],
    side: f64,
    blur_variance: f64,
}

impl lm::Problem for TailProblem<'_> {
    fn num_params(&self) -> usize {
        7
    }
    fn num_residuals(&self) -> usize {
        self.xs.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        let [x0, ls, lw, ll, a, b, c] = [p[0], p[1], p[2], p[3], p[4], p[5], p[6]];
        let sigma = ls.exp();
        let profile = LaserProfile::tailed(MAX_TAIL_WEIGHT / (1.0 + (-lw).exp()), ll.exp());
        let s = (1.0 + self.blur_variance / (sigma * sigma)).sqrt();
        for ((r, &x), &y) in out.iter_mut().zip(self.xs).zip(self.ys) {
            *r = a * profile.unit(self.side * (x - x0) / sigma, s) / sigma + b + c * x - y;
        }
    }
}

/// The tailed profile with its tail on `side`, from a start of core σ from `fwhm` (px).
fn fit_tail(xs: &[f64], ys: &[f64], side: f64, blur_variance: f64, fwhm: f64) -> Option<TailFit> {
    let problem = TailProblem { xs, ys, side, blur_variance };
    let sigma = (fwhm / 2.3548).powi(2) - blur_variance;
    let sigma = sigma.max(0.25).sqrt();
    // A few starts over share and length: a single one can settle where the tail vanishes.
    let logit = |w: f64| (w / (MAX_TAIL_WEIGHT - w)).ln();
    let report = [0.1, 0.3, 0.6]
        .iter()
        .flat_map(|&w| [1.0f64, 3.0, 8.0].map(|l| (w, l)))
        .map(|(w, l)| {
            let start = [0.0, sigma.ln(), logit(w), l.ln(), sigma * (2.0 * std::f64::consts::PI).sqrt(), 0.0, 0.0];
            lm::minimize(&problem, &start, &lm::Options { max_iterations: 200, ..Default::default() })
        })
        .filter(|r| r.params.iter().all(|x| x.is_finite()) && r.rms.is_finite())
        .min_by(|a, b| a.rms.total_cmp(&b.rms))?;
    let p = &report.params;
    let logistic = 1.0 / (1.0 + (-p[2]).exp());
    let weight = MAX_TAIL_WEIGHT * logistic;
    let length = p[3].exp();
    let std = report.std_devs().unwrap_or_else(|| vec![f64::NAN; 7]);
    Some(TailFit {
        side,
        sigma: p[1].exp(),
        weight,
        // Through the transforms' derivatives: d share / d lw, d length / d ll.
        weight_sigma: MAX_TAIL_WEIGHT * logistic * (1.0 - logistic) * std[2],
        length,
        length_sigma: length * std[3],
        rms: report.rms,
    })
}

/// RMS residual of a Gaussian (with a linear background) fitted to the median profile.
fn fit_gaussian(xs: &[f64], ys: &[f64], blur_variance: f64, fwhm: f64) -> Option<f64> {
    struct Gaussian<'a>(&'a [f64], &'a [f64]);
    impl lm::Problem for Gaussian<'_> {
        fn num_params(&self) -> usize {
            5
        }
        fn num_residuals(&self) -> usize {
            self.0.len()
        }
        fn residuals(&self, p: &[f64], out: &mut [f64]) {
            let sigma = p[1].exp();
            for ((r, &x), &y) in out.iter_mut().zip(self.0).zip(self.1) {
                *r = p[2] * (-0.5 * ((x - p[0]) / sigma).powi(2)).exp() + p[3] + p[4] * x - y;
            }
        }
    }
    let sigma = ((fwhm / 2.3548).powi(2)).max(blur_variance).sqrt();
    let report = lm::minimize(&Gaussian(xs, ys), &[0.0, sigma.ln(), 1.0, 0.0, 0.0], &lm::Options::default());
    report.rms.is_finite().then_some(report.rms)
}

/// The laser's figures from the frames measured: the medians of their tail shares and lengths.
pub fn combine(frames: &[FrameTail]) -> Option<(f64, f64)> {
    let weights: Vec<f64> = frames.iter().map(|f| f.tail_weight).collect();
    let lengths: Vec<f64> = frames.iter().map(|f| f.tail_length).collect();
    Some((omni_geom::stats::median(&weights)?, omni_geom::stats::median(&lengths)?))
}

/// The measurement over several frames.
#[derive(Debug, Clone, Serialize)]
pub struct TailReport {
    /// The laser's tail share and length (core σ): the medians over the frames measured, and
    /// the frames' lowest and highest.
    pub tail_weight: f64,
    pub tail_weight_range: [f64; 2],
    pub tail_length: f64,
    pub tail_length_range: [f64; 2],
    pub frames_total: usize,
    pub frames: Vec<FrameTail>,
    pub skipped: Vec<Skipped>,
}

/// Reads each frame as `colour` says, finds its stripe over the whole frame with `ridge`, and
/// measures the laser's cross-section on it ([`measure_frame`]), the frames in parallel. A frame
/// that cannot be read is an error naming it; frames whose tail is not measured are named in
/// `skipped`, and none measured is an error naming why.
pub fn measure_frames(
    paths: &[PathBuf],
    colour: &ColourSpec,
    ridge: &RidgeParams,
    opts: &TailOptions,
) -> Result<TailReport, String> {
    let results: Vec<Result<Result<FrameTail, Skipped>, String>> = paths
        .par_iter()
        .map(|path| {
            let name = path.display().to_string();
            // With a laser colour, its own channel too: where the contrast compresses.
            let own = match colour.channel {
                Channel::Laser(c) => Some(Channel::Single(c)),
                _ => None,
            };
            let (image, laser_channel) = load_frame_channels(path, colour, own).map_err(|e| e.to_string())?;
            let detector = match opts.mirror {
                Some(m) => RidgeDetector::new(image.width, image.height, m, *ridge),
                None => RidgeDetector::whole_frame(image.width, image.height, *ridge),
            };
            let points = detector.detect(&image);
            Ok(measure_frame(&name, &image, &points, laser_channel.as_ref(), opts)
                .map_err(|reason| Skipped { name, reason }))
        })
        .collect();
    let (mut frames, mut skipped) = (Vec::new(), Vec::new());
    for r in results {
        match r? {
            Ok(f) => frames.push(f),
            Err(s) => skipped.push(s),
        }
    }
    let Some((tail_weight, tail_length)) = combine(&frames) else {
        let why: Vec<String> = skipped.iter().map(|s| format!("{}: {}", s.name, s.reason)).collect();
        return Err(format!("none of the {} frames shows a tail to measure: {}", paths.len(), why.join("; ")));
    };
    let range = |v: &dyn Fn(&FrameTail) -> f64| {
        frames.iter().map(v).fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], x| [lo.min(x), hi.max(x)])
    };
    Ok(TailReport {
        tail_weight,
        tail_weight_range: range(&|f| f.tail_weight),
        tail_length,
        tail_length_range: range(&|f| f.tail_length),
        frames_total: paths.len(),
        frames,
        skipped,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(u: f64, v: f64) -> StripePoint {
        StripePoint { u, v, intensity: 100.0, width: 6.0, quality: 0 }
    }

    #[test]
    fn a_sampled_gaussians_half_maximum_width_is_its_fwhm() {
        let sigma = 2.5;
        let profile: Vec<f64> = (-30..=30).map(|k| (-0.5 * (f64::from(k) / sigma).powi(2)).exp()).collect();
        let width = half_maximum_width(&profile, 30).unwrap();
        // Linear interpolation between samples reads the crossing a little short of it.
        assert!((width - 2.3548 * sigma).abs() < 0.05, "{width}");
        assert!(half_maximum_width(&profile[28..33], 2).is_none());
    }

    #[test]
    fn a_straight_stripes_normals_point_one_way_and_a_rings_away_from_its_centre() {
        let line: Vec<StripePoint> = (0..100).map(|k| point(10.0 + f64::from(k), 50.0 + 0.3 * f64::from(k))).collect();
        let refs: Vec<&StripePoint> = line.iter().collect();
        let normals = oriented_normals(&refs, (0.0, 0.0)).unwrap();
        let expected = (-0.3f64, 1.0f64);
        let norm = expected.0.hypot(expected.1);
        let first = normals[50].unwrap();
        for n in normals.iter().flatten() {
            assert!((n.0 - first.0).abs() < 1e-9 && (n.1 - first.1).abs() < 1e-9);
        }
        assert!((first.0 * expected.0 + first.1 * expected.1).abs() / norm > 0.999999);
        let ring: Vec<StripePoint> = (0..360)
            .map(|k| f64::from(k).to_radians())
            .map(|t| point(200.0 + 100.0 * t.cos(), 200.0 + 100.0 * t.sin()))
            .collect();
        let refs: Vec<&StripePoint> = ring.iter().collect();
        // About its own centre a ring's normals all point outwards; about a point outside it,
        // some tangents pass on its other side.
        for (p, n) in ring.iter().zip(oriented_normals(&refs, (200.0, 200.0)).unwrap()) {
            let (x, y) = n.unwrap();
            assert!((x * (p.u - 200.0) + y * (p.v - 200.0) - 100.0).abs() < 0.1);
        }
        assert!(oriented_normals(&refs, (400.0, 200.0)).unwrap_err().contains("disagree with a neighbour"));
    }

    #[test]
    fn an_edge_in_the_flank_is_a_step_and_a_tail_is_not() {
        let half = 30;
        let tail: Vec<f64> = (0..=2 * half)
            .map(|k| {
                let x = k as f64 - half as f64;
                (-0.5 * (x / 2.0).powi(2)).exp() + if x > 0.0 { 0.05 * (-x / 6.0).exp() } else { 0.0 }
            })
            .collect();
        assert!(!has_step(&tail, half, half, 1.0));
        let mut edge = tail.clone();
        edge[45..].iter_mut().for_each(|y| *y += 0.1);
        assert!(has_step(&edge, half, half, 1.0));
    }
}
