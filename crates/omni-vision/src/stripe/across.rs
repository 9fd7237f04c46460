//! Stripe centres measured across each stripe's own normal, in every direction
//! ([`super::Sampling::Normal`]).
//!
//! Rule: a stripe is measured where it crosses the pixel rows if it runs steeper than 45°, and
//! where it crosses the columns otherwise, so that it is sampled about once per pixel of its
//! length whatever its direction; each seed (the brightest pixel of a run of ridge pixels in a
//! row or column) gets the stripe's normal from the Hessian of the smoothed image, and the
//! centre is located on a profile sampled along that normal, with the same estimators,
//! threshold and background rule as on a ray. The points are then linked to their neighbours on
//! the same stripe (close, with nearly parallel normals), which
//! * drops isolated specks and the last [`END_PX`] of a stripe;
//! * drops profiles cut by a silhouette or a crease: lopsided on average along the stripe, more
//!   than the stripe is as a whole ([`MAX_ASYMMETRY`]; one profile's lopsidedness is speckle,
//!   and a laser's own lopsided shape, a tail on one side, is the same all along its stripe),
//!   lopsided by twice that where the neighbours are too few to fit the stripe's shape, or much
//!   narrower than their neighbours ([`MIN_WIDTH_RATIO`]);
//! * drops lit areas of the ambient image, wider than the laser's line ([`MAX_HALF_WIDTH_RATIO`])
//!   or tapering ([`MAX_WIDTH_SLOPE`]);
//! * removes the blur's pull towards the stripe's centre of curvature: the centroid across a
//!   blurred line is the mean of the line's offset d(t) weighted by its contrast times the blur
//!   along it, so the stripe's local shape (a cubic through its neighbours) and the change of its
//!   contrast along it give the pull, σ²κ/2 on an evenly lit arc and more or less where the
//!   stripe bends faster, dims or brightens, as on a curved object's flank before its
//!   silhouette. σ² is the lens's blur when it is known ([`super::RidgeParams::optics_blur_px`])
//!   with the pixel's and the sampling kernel's; otherwise it is measured on the frame itself
//!   (the median, over the stripe points that pass the checks above, of the second moment that
//!   scales the pull, see [`RidgeDetector::pull_variance`]), so that the pull comes out right
//!   for any lens, Gaussian or defocused, without being told its blur, as long as the laser's
//!   sheet is narrower than the blur (its own width does not pull);
//! * moves each point to the peak of the light its profile blurs: by the mean offset of its
//!   stripe's profiles from their tops' centroids ([`Centre::lean`]), and by the stripe's median
//!   top shape from there to the image's peak and back by the blur's shift of a lopsided peak,
//!   −(s/2)·L‴/L″ for a blur of variance s and L the profile's logarithm
//!   ([`Centre::top_shape`]; the lens's blur where known, else the pixel's and the kernel's);
//!   with the laser's cross-section known, where the top shape cannot tell, by what it predicts
//!   from the top's centroid, or, for the windowed centroid, by what it predicts for that
//!   centroid itself and as much of the leans' departure from it as stands out of their noise
//!   (`super::laser`);
//! * fits the stripe along its length when asked ([`super::RidgeParams::along_stripe_px`]): over
//!   ±3 px a line through the neighbours once a wider parabola's curvature is taken out, so that
//!   a curved stripe keeps its centre, and over longer arcs a parabola, each taken only while it
//!   agrees with the shorter ones within their noise (a tight curve, a step or an end keeps the
//!   short arc); wide stripes' points, re-measured from a coarser scale, as well.
//!
//! The measurements behind these rules: docs/DECISIONS.md.

use super::estimators::{self, Segment};
use super::stripes::{StripeMedians, Stripes};
use super::{
    Frame, MAX_CENTRE_GRADIENT, Pixel, RidgeDetector, SAMPLE_STEP_PX, StripePoint, column_contrast, quality,
    row_contrast, stands_out,
};
use omni_geom::stats;

/// tan 47°: a seed from a row is measured if the stripe's normal is within 47° of the row (the
/// stripe within 47° of vertical), one from a column if within 47° of the column; the overlap
/// keeps stripes at 45° from falling between the two, and duplicates are merged.
const AXIS_OVERLAP_TAN: f64 = 1.072;
/// Scale (px) of the Gaussian derivatives that give a seed its stripe normal (kernel to 3σ).
pub const SEED_NORMAL_SIGMA_PX: f64 = 1.0;
/// Two points nearer than this (px) with parallel normals are one measurement.
const DUPLICATE_PX: f64 = 0.7;
/// Neighbours on the same stripe: normals within 30°.
const SAME_STRIPE_COS: f64 = 0.866;
/// Points of a walk across a coarse stripe's gap that met no point on the far side lie at the
/// stripe's end: those within this many half-maximum widths of where the walk stopped (at
/// least [`END_PX`]) are dropped. A surface's edge that crosses a wide stripe obliquely cuts
/// its profiles over a stretch about as long as the stripe is wide.
const TRACK_END_WIDTHS: f64 = 0.25;
/// A point needs the stripe to go on this far (px) on both sides: where a stripe ends (a
/// silhouette, a shadow, the sheet's edge) the blur mixes the end into the last profiles.
pub const END_PX: f64 = 1.5;
/// Half the arc (px) of the parabola that gives a point's curvature.
pub(super) const SHAPE_HALF_ARC_PX: f64 = 3.0;
/// A stripe whose profiles' two flanks (each from the half maximum down to [`ASYMMETRY_LEVEL`]
/// of the peak) differ, on average over the point's neighbours within ±3 px, by more than this
/// fraction of their sum beyond what they differ along the whole stripe (its median, the
/// laser's shape) is cut there (one flank falls off a silhouette or a crease).
pub const MAX_ASYMMETRY: f64 = 0.1;
/// A stripe's steady lopsidedness (its points' median) up to this is taken as the laser's
/// shape; beyond it no laser is that lopsided, and the stripe is judged as if symmetric.
pub const MAX_STEADY_ASYMMETRY: f64 = 0.5;
/// Least length of stripe (px of the frame's own scale, about one point per px), summed over
/// the frame's stripes that are lopsided alike, for that lopsidedness to be taken as the
/// laser's shape; with less the stripes are judged as if symmetric. A coarser scale's points
/// each stand for as many px as its binning, down to [`STEADY_MIN_POINTS`].
const STEADY_MIN_PX: usize = 64;
/// Fewest bends (the point's and its neighbours' within ±[`SHAPE_HALF_ARC_PX`]) whose mean
/// the blur's pull may take ([`smooth_pull_bends`]).
const PULL_MIN_BENDS: usize = 5;
/// Fewest points of a stripe whose median lopsidedness can count as the laser's shape, at any
/// scale.
pub(super) const STEADY_MIN_POINTS: usize = 16;
/// The fraction of the peak where lopsidedness is measured: low on the flanks, where a cut
/// shows first.
pub const ASYMMETRY_LEVEL: f32 = 0.25;
/// A profile narrower (half-maximum width) than this fraction of its neighbours' median is cut.
pub const MIN_WIDTH_RATIO: f64 = 0.7;
/// A profile whose half-maximum width exceeds this multiple of the frame's narrow ones (its
/// [`NARROW_PERCENTILE`] quantile) is a lit area, not the laser's line.
pub const MAX_HALF_WIDTH_RATIO: f64 = 1.7;
/// The quantile (%) of the frame's half-maximum widths that stands for its narrow profiles.
const NARROW_PERCENTILE: usize = 10;
/// A stripe whose half-maximum width changes faster than this (px per px along it, over ±3 px)
/// is a tapering lit area, not the laser's line.
pub const MAX_WIDTH_SLOPE: f64 = 0.2;
/// The fastest change of half-maximum width (px per px along the stripe) of a chain of points
/// re-measured from a coarser scale ([`drop_tapering`]): the lit faces' tips that coarse scales
/// find widen by 0.5–2.5; a wide laser line's width changes with the surface's distance, far
/// more slowly over a chain.
pub const MAX_CHAIN_WIDTH_SLOPE: f64 = 0.3;
/// The flattest profile (width at 90 % of the peak over the half-maximum width) counted as a
/// laser's line wider than its scale: a Gaussian has 0.39, a lit surface's blurred flat top
/// nearly 1.
pub const MAX_FLATNESS: f64 = 0.7;
/// The level, as a fraction of the peak, above which a profile's top is measured
/// ([`Centre::lean`]): high enough that a one-sided tail barely moves the top's centroid (a
/// fifth to a tenth of what it moves the centroid down to the threshold), low enough that the
/// top keeps a few samples (docs/DECISIONS.md). A cubic fitted to the top has its vertex above it.
pub const TOP_LEVEL: f32 = 0.8;
/// Half the window of the cubic fitted to a profile's top ([`Centre::top_shape`]), in
/// half-maximum half-widths: wide enough for a third derivative, narrow enough that a one-sided
/// tail's slope below the top does not bend the cubic (docs/DECISIONS.md).
const TOP_HALF_WINDOW: f64 = 0.75;
/// The largest median skew of a stripe's tops (L‴/L″ × the profile's σ, [`Centre::top_shape`])
/// that is a laser's shape: a one-sided tail holding a third of the light gives 0.17; a stripe
/// cut along its length (grazing a surface's edge) gives more. The limit is on the stripe's
/// median, not on each top: a limit inside the tops' noise cuts one side of the noise around a
/// laser's skew and pulls the median towards 0 (docs/DECISIONS.md).
const MAX_TOP_SKEW: f64 = 0.3;
/// A profile's coarse samples must still fall by this fraction of the threshold per px at both
/// ends of its reach to count as a stripe too wide for the scale: a laser's flanks are steep
/// there, a lit surface's shading is not (docs/DECISIONS.md).
const TOO_WIDE_SLOPE: f32 = 0.25;
/// Half the arc (px) over which a stripe's leans are averaged ([`remove_steady_lean`]).
const LEAN_HALF_ARC_PX: f64 = 12.0;
/// Fewer profiles than this within the arc leave a point's centre where its estimator put it.
const LEAN_MIN_PROFILES: usize = 8;
/// Profiles flatter than this ([`Centre::flatness`]; a Gaussian has 0.39) give no lean: a
/// flat top (a defocused lens's disc, a lit patch) is pulled by the stripe's bend unlike the
/// estimator's centre, so its lean is the bend's, not the laser's shape.
const LEAN_MAX_FLATNESS: f64 = 0.41;
/// A fit that moves its point farther than this (px) is not trusted (a kink, another stripe).
const MAX_MOVE_PX: f64 = 0.5;
/// The share of a profile's variance the blur makes beyond which a known laser profile, not
/// the top's own shape, leads a point to the sheet's peak ([`lean_to_sheet_peak`]): the
/// shape's undoing of the blur is a first-order rule in the blur's share.
const BLUR_DOMINATED_SHARE: f64 = 0.5;
/// FWHM / σ of a Gaussian.
const FWHM_PER_SIGMA: f64 = 2.354_820_045;
/// The most the noise of a stripe's median top shape may move its points, in the profile's σ,
/// for the shape rather than a known laser profile to lead them to the sheet's peak
/// ([`lean_to_sheet_peak`]): about what the profile's prediction misses where it describes a
/// real laser's shape only nearly (0.0033 σ at 5 px wide, 0.004 σ or more at 20), so the one
/// that errs less leads. Were the shape's median itself judged instead, a speckled stripe's
/// shape would lead only where its noise had inflated it.
const MAX_SHAPE_NOISE_SIGMAS: f64 = 0.004;

/// Which way a seed's run ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Axis {
    Row,
    Column,
}

/// How wide a stripe a profile measures (px between its threshold crossings) and how far from
/// its start the centre may lie (px).
#[derive(Debug, Clone, Copy)]
struct Reach {
    max_width: f64,
    far_px: f64,
}

impl Reach {
    /// A seed pixel's reach: the brightest pixel of a run lies within 2 px of a stripe's centre.
    fn of(max_width: f64) -> Reach {
        Reach { max_width, far_px: 2.0 }
    }
}

/// Profile buffers reused from seed to seed.
#[derive(Debug, Default)]
struct Buffers {
    /// Bilinear samples 1 px apart across the stripe, for the background.
    coarse: Vec<f32>,
    /// Fine samples on the −n side, outwards.
    left: Vec<f32>,
    /// The fine profile, −n to +n.
    raw: Vec<f32>,
    /// The profile above the background.
    contrast: Vec<f32>,
    /// Profiles still falling at both ends of their reach (too wide for this scale).
    too_wide: usize,
}

/// A point that passed the linking checks, with what a finer scale needs to re-measure it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Linked {
    pub point: StripePoint,
    /// Unit normal of the stripe.
    pub normal: (f64, f64),
    /// Half-maximum width (px).
    pub half_width: f64,
    /// The centre's offset along `normal` from the peak of the light its profile blurs (px;
    /// [`Centre::lean`] less the blur's shift of a lopsided peak), or from its top's centroid
    /// where [`Linked::tail_offset`] carries the rest; `None` where it says nothing of the
    /// laser's shape (saturated or flat-topped profiles).
    pub lean: Option<f64>,
    /// [`Centre::side_lean`]: the profile's vote on its tail's side.
    side_lean: Option<f64>,
    /// The profile's top shape ([`Centre::top_shape`]) where the lean has not taken its
    /// stripe's yet (points re-measured from a coarser scale).
    top_shape: Option<[f64; 2]>,
    /// How far (px) the sheet's peak still lies beyond where the lean leads, on the tail's
    /// side: with the laser's profile known, the top centroid's predicted offset where the
    /// stripe has no top shape of its own to lead the lean to the peak; for a saturated
    /// point, its plateau centre's ([`lead_plateaus_to_sheet_peak`]); else 0.
    tail_offset: f64,
    /// Whether the laser's profile, not the stripe's top shape, leads this point to the sheet's
    /// peak ([`lean_to_sheet_peak`]).
    led_by_profile: bool,
    /// With the laser's profile known, how far (px) the windowed centroid lies from the sheet's
    /// peak towards the tail ([`super::laser::WindowedOffsets`]), where the profile leads the
    /// point and the windowed centroid locates it; else `None`.
    window_offset: Option<f64>,
    /// [`Centre::plateau_edges`].
    plateau_edges: Option<[f64; 2]>,
    /// [`Centre::background_excess`].
    background_excess: f64,
}

/// A measured centre before linking.
#[derive(Debug, Clone, Copy)]
struct Centre {
    point: StripePoint,
    /// Unit normal of the stripe (px).
    normal: (f64, f64),
    /// Half-maximum width (px).
    half_width: f64,
    /// (flank towards −n − flank towards +n) / their sum (see [`MAX_ASYMMETRY`]).
    asymmetry: f64,
    /// The variance (px²) that scales the blur's pull on this profile's centre if the stripe
    /// curves ([`RidgeDetector::pull_variance`]); `None` for a saturated profile.
    pull_variance: Option<f64>,
    /// The profile's width at 90 % of its peak over its half-maximum width: 0.39 for a
    /// Gaussian, near 1 for a lit surface's flat top.
    flatness: f64,
    /// The estimator's centre minus the centroid of the profile's top ([`TOP_LEVEL`]), along
    /// `normal` (px): 0 on a symmetric straight stripe, the tail's pull on a lopsided one;
    /// `None` for a saturated profile (its plateau has no top to measure).
    lean: Option<f64>,
    /// With the laser's profile known, the windowed centroid minus the top's centroid (px
    /// along `normal`): the side of the tail ([`RidgeDetector::side_lean`]).
    side_lean: Option<f64>,
    /// The shape of the profile's top in units of the profile's σ (half-maximum width / 2.355):
    /// the top's centroid less the vertex of a cubic through the top's logarithm L, and L‴/L″
    /// there ([`stripe_top`]), both along `normal`. The vertex is the image's peak; a blur of
    /// variance s moved the lopsided peak of the light it blurred by −(s/2)·L‴/L″. `None` where
    /// the top fits no cubic.
    top_shape: Option<[f64; 2]>,
    /// For a saturated profile, the distance (px) between the edges whose midpoint is its
    /// centre ([`estimators::plateau_edges`]), and the threshold they were read with.
    plateau_edges: Option<[f64; 2]>,
    /// How far the background (the higher of the two sides' levels) lies above the other
    /// side's, positive where the side along `normal` is the higher: a lopsided laser's tail
    /// raises its side's.
    background_excess: f64,
}

impl RidgeDetector {
    /// Stripe centres of a frame measured across the stripes' normals (module docs), sorted by
    /// azimuth around the mirror centre, then radius.
    pub(super) fn detect_across<P: Pixel>(&self, frame: &Frame<'_, P>, threshold: f64) -> Vec<StripePoint> {
        let points = self.detect_at_scales(frame, threshold, 1).into_iter().map(|l| l.point).collect();
        azimuth_sorted(points, (self.cx, self.cy))
    }

    /// The stripes of `frame` (this detector's scale, `scale` × the original pixel) that this
    /// scale measures, and those wider ones that coarser scales find, re-measured here
    /// (`super::scales`).
    pub(super) fn detect_at_scales<P: Pixel>(&self, frame: &Frame<'_, P>, threshold: f64, scale: u32) -> Vec<Linked> {
        let mut buffers = Buffers::default();
        let centres: Vec<Centre> = self
            .seeds(frame, threshold)
            .into_iter()
            .filter_map(|(x, y, axis)| self.measure_seed(frame, x, y, axis, threshold, &mut buffers))
            .collect();
        let mut kept = self.link_and_correct(&centres, scale);
        // Profiles too wide for this scale that peak like a laser's line (a lit surface's flat
        // top is wide at every scale), measured or still falling where their reach ended.
        let measured_wide =
            centres.iter().filter(|c| c.half_width > super::scales::NARROW_HALF_WIDTH_PX && peaks(c)).count();
        let wide = measured_wide + buffers.too_wide;
        if let Some(coarse) = self.coarser_stripes(frame, threshold, scale, wide, kept.len()) {
            let mut refined = self.refine_coarse(frame, threshold, &coarse, &kept, &mut buffers);
            yield_tops_to_coarse(&mut kept, &refined, self.image_size());
            drop_tapering(&mut refined);
            lean_to_the_lights_peak(
                &mut refined,
                self.peak_blur_variance(scale),
                self.mosaic_at(scale),
                self.top_offsets(scale),
            );
            fit_along_stripe(&mut refined, self.params.along_stripe_px);
            kept.extend(refined);
        }
        if let Some(model) = self.windowed_offsets(scale) {
            lead_windows_to_sheet_peak(&mut kept, model, threshold);
        }
        let sides = lead_plateaus_to_sheet_peak(&mut kept, || self.plateau_offsets(scale));
        remove_steady_lean(&mut kept, sides);
        kept
    }

    /// Re-measures on this scale's `frame` the stripes a coarser scale found (in its pixels),
    /// where this scale kept none: two profiles per coarse point (½ px either side of it along
    /// the stripe), along its normal, each kept if its centre lies near the coarse one.
    fn refine_coarse<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        threshold: f64,
        coarse: &[Linked],
        kept: &[Linked],
        buffers: &mut Buffers,
    ) -> Vec<Linked> {
        // This scale's points block the re-measurement of the coarse stripes they lie on, but
        // one that may be a wider stripe's top alone ([`may_be_a_top`]) blocks only a stripe
        // less than [`TOP_RATIO`] times its width, and the stripe re-measured beside it must be
        // as many times as bright; it then yields ([`yield_tops_to_coarse`]).
        let (top_points, whole): (Vec<&Linked>, Vec<&Linked>) = kept.iter().partition(|l| may_be_a_top(l));
        let mut taken =
            super::scales::Occupancy::new(whole.iter().map(|l| (l.point.u, l.point.v, ())), self.image_size());
        let tops = super::scales::Occupancy::new(
            top_points.iter().map(|l| (l.point.u, l.point.v, (l.point.width, l.point.intensity))),
            self.image_size(),
        );
        let mut out = Vec::with_capacity(2 * coarse.len());
        for c in coarse {
            if c.half_width < super::scales::WIDE_HALF_WIDTH_PX {
                continue; // narrow at the coarse scale: this scale's to measure (or refuse)
            }
            let (u, v) = (2.0 * c.point.u + 0.5, 2.0 * c.point.v + 0.5);
            let half_width = 2.0 * c.half_width;
            let near = (0.5 * half_width).max(2.0);
            // (c's width in this scale's pixels is 2 × its own.)
            if taken.near(u, v, near)
                || tops.within(u, v, near).any(|(width, _)| TOP_RATIO * width >= 2.0 * c.point.width)
            {
                continue;
            }
            let brightest_top =
                tops.within(u, v, near).map(|(_, intensity)| intensity).fold(f64::NEG_INFINITY, f64::max);
            let (nx, ny) = c.normal;
            let reach = Reach { max_width: 3.0 * c.point.width + 4.0, far_px: (0.3 * half_width).max(1.5) };
            for side in [-0.5, 0.5] {
                let start = (u - side * ny, v + side * nx);
                if let Some(m) = self.measure_profile(frame, start, c.normal, threshold, reach, buffers)
                    && m.point.intensity >= TOP_RATIO * brightest_top
                {
                    out.push((m.linked(), reach));
                }
            }
        }
        // The walks across the gaps stop at every point this scale measured, tops included.
        for (l, _) in &out {
            taken.insert(l.point.u, l.point.v, ());
        }
        for l in &top_points {
            taken.insert(l.point.u, l.point.v, ());
        }
        let tracked = self.track_gaps(frame, threshold, &out, &mut taken, buffers);
        out.into_iter().map(|(l, _)| l).chain(tracked).collect()
    }

    /// Follows re-measured stripes across the gaps the coarse scale left (speckle, a dark
    /// square): from each point, a profile 1 px further along the stripe where no point is, on
    /// the same normal, up to [`super::scales::TRACK_PX`] px, as long as the profile finds the
    /// stripe within its reach. A walk that meets no point has gone past the stripe's end,
    /// whose last profiles are cut ([`TRACK_END_WIDTHS`]).
    fn track_gaps<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        threshold: f64,
        start: &[(Linked, Reach)],
        taken: &mut super::scales::Occupancy,
        buffers: &mut Buffers,
    ) -> Vec<Linked> {
        let mut out = Vec::new();
        for (first, reach) in start {
            let (nx, ny) = first.normal;
            for dir in [-1.0, 1.0] {
                let mut at = first.point;
                let mut walk: Vec<Linked> = Vec::new();
                let mut bridged = false;
                for _ in 0..super::scales::TRACK_PX {
                    let next = (at.u - dir * ny, at.v + dir * nx);
                    if taken.near(next.0, next.1, 0.7) {
                        bridged = true;
                        break;
                    }
                    let step = Reach { far_px: 1.0, ..*reach };
                    let Some(m) = self.measure_profile(frame, next, first.normal, threshold, step, buffers) else {
                        break;
                    };
                    taken.insert(m.point.u, m.point.v, ());
                    at = m.point;
                    walk.push(m.linked());
                }
                if !bridged {
                    let end = (at.u - dir * ny, at.v + dir * nx);
                    let reach = (TRACK_END_WIDTHS * first.half_width).max(END_PX);
                    walk.retain(|l| (l.point.u - end.0).hypot(l.point.v - end.1) >= reach);
                }
                out.extend(walk);
            }
        }
        out
    }

    /// The brightest pixel (smoothed [1 2 1] across the run) of every run of consecutive ridge
    /// pixels in a row (brighter by more than the threshold than both row neighbours
    /// `max_width / 2 + 1` px away) and in a column, inside the annulus.
    fn seeds<P: Pixel>(&self, frame: &Frame<'_, P>, threshold: f64) -> Vec<(u32, u32, Axis)> {
        let (w, h) = (frame.width as usize, frame.height as usize);
        let k = (0.5 * self.params.max_width).ceil() as usize + 1;
        let t = threshold as f32;
        let tp = P::from_threshold(threshold);
        let mut seeds = Vec::new();
        // Open column runs: the row they were last extended in, and their best (value, row).
        let mut col_last = vec![u32::MAX; w];
        let mut col_best = vec![(f32::NEG_INFINITY, 0u32); w];
        let mut hits = Vec::new();
        let (r_in2, r_out2) = (self.r_in * self.r_in, self.r_out * self.r_out);
        let y_lo = ((self.cy - self.r_out).floor().max(1.0)) as usize;
        let y_hi = ((self.cy + self.r_out).ceil() as usize).min(h.saturating_sub(2));
        let at = |x: usize, y: usize| frame.at(x, y);
        let zeros = vec![P::from_threshold(0.0); w];
        for y in y_lo..=y_hi {
            hits.clear();
            let dy = y as f64 - self.cy;
            // Only the row's chord of the annulus' outer circle, and 1 px inside the frame.
            let half = (r_out2 - dy * dy).max(0.0).sqrt();
            let x_lo = super::floor_i64(self.cx - half).max(1) as usize;
            let x_hi = (-super::floor_i64(-(self.cx + half))).min(w as i64 - 2);
            if x_hi < x_lo as i64 {
                continue;
            }
            let x_end = x_hi as usize + 1;
            // The branch-free test over the row's chord, its neighbours k px away taken from the
            // frame or, beyond its edges, from a row of zeros (as `stands_out` counts them); the
            // hits come in increasing x.
            let (a, b) = (x_lo.max(k), x_end.min(w.saturating_sub(k)));
            if a < b {
                let d = frame.data;
                let row = &d[y * w..(y + 1) * w];
                let up = if y >= k { &d[(y - k) * w..(y - k + 1) * w] } else { &zeros[..] };
                let down = if y + k < h { &d[(y + k) * w..(y + k + 1) * w] } else { &zeros[..] };
                let mut scan = |lo: usize, hi: usize, left: &[P], right: &[P]| {
                    P::for_each_contrast_hit(&row[lo..hi], left, right, &up[lo..hi], &down[lo..hi], tp, |i| {
                        hits.push(lo + i)
                    })
                };
                // Left border (left neighbours beyond the frame), stretch, right border.
                scan(x_lo, a, &zeros[..a - x_lo], &row[x_lo + k..a + k]);
                scan(a, b, &row[a - k..b - k], &row[a + k..b + k]);
                scan(b, x_end, &row[b - k..x_end - k], &zeros[..x_end - b]);
            } else {
                hits.extend((x_lo..x_end).filter(|&x| stands_out(frame, x, y, k, t)));
            }
            // The current row run: (last x, best value, best x).
            let mut run: Option<(usize, f32, usize)> = None;
            for &x in &hits {
                let dx = x as f64 - self.cx;
                let r2 = dx * dx + dy * dy;
                if r2 < r_in2 || r2 > r_out2 {
                    continue;
                }
                let v = at(x, y);
                if row_contrast(frame, x, y, k) > t {
                    let s = at(x, y - 1) + 2.0 * v + at(x, y + 1);
                    run = match run {
                        Some((last, best, bx)) if last + 1 == x => {
                            Some(if s > best { (x, s, x) } else { (x, best, bx) })
                        }
                        previous => {
                            if let Some((_, _, bx)) = previous {
                                seeds.push((bx as u32, y as u32, Axis::Row));
                            }
                            Some((x, s, x))
                        }
                    };
                }
                if column_contrast(frame, x, y, k) > t {
                    let s = at(x - 1, y) + 2.0 * v + at(x + 1, y);
                    if col_last[x] != u32::MAX && col_last[x] + 1 == y as u32 {
                        if s > col_best[x].0 {
                            col_best[x] = (s, y as u32);
                        }
                    } else {
                        if col_last[x] != u32::MAX {
                            seeds.push((x as u32, col_best[x].1, Axis::Column));
                        }
                        col_best[x] = (s, y as u32);
                    }
                    col_last[x] = y as u32;
                }
            }
            if let Some((_, _, bx)) = run {
                seeds.push((bx as u32, y as u32, Axis::Row));
            }
        }
        for (x, &last) in col_last.iter().enumerate() {
            if last != u32::MAX {
                seeds.push((x as u32, col_best[x].1, Axis::Column));
            }
        }
        seeds
    }

    /// The centre of the stripe through seed pixel (`x`, `y`), measured on a profile along its
    /// normal; `None` if the normal belongs to the other axis, or the profile fails a check.
    fn measure_seed<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        x: u32,
        y: u32,
        axis: Axis,
        threshold: f64,
        buffers: &mut Buffers,
    ) -> Option<Centre> {
        let (x0, y0) = (x as f64, y as f64);
        if clearly_other_axis(frame, x as usize, y as usize, axis) {
            return None;
        }
        let derivatives = self.seed_normal.derivatives_at_pixel(frame, x as usize, y as usize)?;
        let ((nx, ny), _) = super::steger::Kernels::normal(&derivatives)?;
        let fits_axis = match axis {
            Axis::Row => ny.abs() <= AXIS_OVERLAP_TAN * nx.abs(),
            Axis::Column => nx.abs() <= AXIS_OVERLAP_TAN * ny.abs(),
        };
        if !fits_axis {
            return None;
        }
        self.measure_profile(frame, (x0, y0), (nx, ny), threshold, Reach::of(self.params.max_width), buffers)
    }

    /// The centre of the stripe near (`x0`, `y0`) px, on a profile along the unit normal `n`;
    /// `None` if the profile fails a check. `reach` sets the widest stripe measured and how far
    /// the centre may lie from (`x0`, `y0`).
    fn measure_profile<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        (x0, y0): (f64, f64),
        (nx, ny): (f64, f64),
        threshold: f64,
        reach: Reach,
        buffers: &mut Buffers,
    ) -> Option<Centre> {
        let max_width = reach.max_width;
        // The background: the larger of the minima of a coarse profile (bilinear, 1 px steps) on
        // either side, past the flank of the widest accepted stripe.
        let far_px = reach.far_px;
        let reach = (0.5 * max_width + 2.0).ceil() as i64;
        let n = 2 * reach as usize + 1;
        let coarse = &mut buffers.coarse;
        coarse.clear();
        if !frame.bilinear_line(x0, y0, -reach as f64, (nx, ny), n, coarse) {
            return None; // the profile leaves the image
        }
        let min = |v: &[f32]| v.iter().fold(f32::INFINITY, |m, &x| m.min(x));
        let (left_min, right_min) = (min(&coarse[..=reach as usize]), min(&coarse[reach as usize..]));
        let background = left_min.max(right_min);
        let t = threshold as f32;
        // Still falling steeply at both ends of the reach, from a peak well above them: a stripe
        // too wide for this scale. A lit surface's top is level and its shading falls slowly.
        let (first, last) = (coarse[0], coarse[n - 1]);
        let falling = coarse[1] - first > TOO_WIDE_SLOPE * t && coarse[n - 2] - last > TOO_WIDE_SLOPE * t;
        if falling && first <= left_min && last <= right_min && coarse[reach as usize] - first.max(last) > 2.0 * t {
            buffers.too_wide += 1;
        }
        // Fine samples with the Gaussian kernel, outwards from the seed until `tail` samples on
        // each side are at or below the threshold and below the flank levels the checks use
        // (Blais–Rioux's filter reaches two samples further).
        let tail = if self.params.method == super::Method::BlaisRioux { 3 } else { 1 };
        let limit = (reach as f64 / SAMPLE_STEP_PX) as i64;
        // Sample i at the seed + i·SAMPLE_STEP_PX·n, stepped in 32.32 fixed point; the kernel's
        // bounds are checked per sample only where the walk's reach leaves the frame.
        let origin = (super::to_fixed(x0), super::to_fixed(y0));
        let step = (super::to_fixed(SAMPLE_STEP_PX * nx), super::to_fixed(SAMPLE_STEP_PX * ny));
        let at = |i: i64| (origin.0 + i * step.0, origin.1 + i * step.1);
        let reach_inside =
            self.sampler.kernel_inside(frame, at(-limit)) && self.sampler.kernel_inside(frame, at(limit));
        let fine = |i: i64| {
            let p = at(i);
            (reach_inside || self.sampler.kernel_inside(frame, p)).then(|| self.sampler.sample_fixed(frame, p))
        };
        let centre = fine(0)?;
        let stop = t.min(0.8 * ASYMMETRY_LEVEL * (centre - background));
        let walk = |dir: i64, out: &mut Vec<f32>| -> Option<()> {
            let mut below = 0;
            for i in 1..=limit {
                let v = fine(dir * i)?;
                out.push(v);
                if !(v - background > stop) {
                    below += 1;
                    if below == tail {
                        return Some(());
                    }
                }
            }
            None
        };
        let Buffers { left: before, raw, contrast: q, .. } = buffers;
        before.clear();
        walk(-1, before)?;
        let half = before.len();
        raw.clear();
        raw.extend(before.iter().rev());
        raw.push(centre);
        walk(1, raw)?;
        q.clear();
        q.extend(raw.iter().map(|v| v - background));
        let (raw, q) = (&raw[..], &q[..]);
        let seg = segment_near(q, half, t)?;
        let (a, b) = estimators::crossings(q, &seg, t)?;
        let width = (b - a) * SAMPLE_STEP_PX;
        if width > max_width || width < self.params.min_width {
            return None;
        }
        let peak = q[seg.peak];
        let saturated = frame.saturated_near(x0, y0);
        let (index, plateau_edges) = if saturated {
            let (a, b) = estimators::plateau_edges(q, &seg, t, peak)?;
            (0.5 * (a + b), Some([(b - a) * SAMPLE_STEP_PX, t as f64]))
        } else {
            (self.centre_index(raw, q, &seg, t)?, None)
        };
        let (ha, hb) = estimators::crossings(q, &seg, 0.5 * peak)?;
        let half_width = (hb - ha) * SAMPLE_STEP_PX;
        // A cut flank falls faster than the whole one: compare the flanks' spans between the
        // half maximum and ASYMMETRY_LEVEL of the peak.
        let (la, lb) = estimators::crossings(q, &seg, ASYMMETRY_LEVEL * peak)?;
        let (left, right) = (ha - la, lb - hb);
        let (ta, tb) = estimators::crossings(q, &seg, 0.9 * peak)?;
        let flatness = (tb - ta) / (hb - ha).max(1e-9);
        let asymmetry = (left - right) / (left + right).max(1e-9);
        let s = (index - half as f64) * SAMPLE_STEP_PX;
        if s.abs() > far_px {
            return None;
        }
        let (u, v) = (x0 + s * nx, y0 + s * ny);
        if !flat_across(frame, u, v, (nx, ny), peak) {
            return None;
        }
        let flags =
            if saturated { quality::SATURATED } else { 0 } | self.contrast_and_width_flags(peak, width, t, max_width);
        let point = StripePoint { u, v, intensity: peak as f64, width, quality: flags };
        let pull_variance = (!saturated).then(|| self.pull_variance(raw, q, &seg, t, index)).flatten();
        // The top: the samples above TOP_LEVEL of the peak, their centroid and shape.
        let top = if saturated { None } else { estimators::top_centroid(q, &seg, TOP_LEVEL * peak) };
        let lean = top.map(|(centre, _)| (index - centre) * SAMPLE_STEP_PX);
        let side_lean = self.side_lean(q, &seg, t, lean, top.map(|(centre, _)| centre));
        let sigma = half_width / FWHM_PER_SIGMA;
        let top_shape = top.filter(|_| flatness <= LEAN_MAX_FLATNESS).and_then(|(centre, top)| {
            let (vertex, skew) = stripe_top(q, &top, half_width)?;
            Some([(centre - vertex) * SAMPLE_STEP_PX / sigma, skew / SAMPLE_STEP_PX * sigma])
        });
        Some(Centre {
            point,
            normal: (nx, ny),
            half_width,
            asymmetry,
            pull_variance,
            flatness,
            lean,
            side_lean,
            top_shape,
            plateau_edges,
            background_excess: (right_min - left_min) as f64,
        })
    }

    /// With the laser's profile known, the windowed centroid's offset (px) from the top's
    /// centroid `top` (a sample index): towards the tail whatever the estimator (a Gaussian
    /// fit or Blais–Rioux finds the top itself, and their lean can have either sign), the
    /// profile's vote on its tail's side ([`tail_sides`]). `lean` where the estimator is the
    /// windowed centroid.
    fn side_lean(&self, q: &[f32], seg: &Segment, t: f32, lean: Option<f64>, top: Option<f64>) -> Option<f64> {
        self.params.laser_profile?;
        match self.params.method {
            super::Method::Windowed | super::Method::Hessian => lean,
            _ => Some((estimators::windowed_centroid(q, seg, t)? - top?) * SAMPLE_STEP_PX),
        }
    }

    /// The variance σ² (px²) for which the blur moves this profile's centre by σ²κ/2 towards the
    /// centre of curvature of a stripe curving by κ (1/px), for the configured estimator.
    ///
    /// For an isotropic PSF the tangential spread behind the pull follows from the profile L
    /// across the stripe itself (M(y) = ∫_{|y|}^∞ t·L(t) dt), and for the windowed centroid (weights
    /// L − t over the window where L > t) it integrates to σ² = Σ y²·L / Σ (L − t) over that
    /// window, whatever the PSF's shape: a Gaussian's variance, but about half the variance a
    /// defocused lens's half-maximum width suggests. The centroid weighs raw intensities; the
    /// Gaussian fit and Blais–Rioux assume a Gaussian profile, whose variance the half-maximum
    /// width gives.
    fn pull_variance(&self, raw: &[f32], q: &[f32], seg: &Segment, t: f32, index: f64) -> Option<f64> {
        let moment = |weight: &dyn Fn(usize) -> f64| {
            let (mut m2, mut sw) = (0.0, 0.0);
            for k in seg.start..seg.end {
                let y = (k as f64 - index) * SAMPLE_STEP_PX;
                m2 += y * y * q[k] as f64;
                sw += weight(k);
            }
            (sw > 0.0).then(|| m2 / sw)
        };
        match self.params.method {
            super::Method::Windowed | super::Method::Hessian => moment(&|k| (q[k] - t).max(0.0) as f64),
            super::Method::Centroid => moment(&|k| raw[k] as f64),
            super::Method::Gauss | super::Method::BlaisRioux => {
                let peak = q[seg.peak];
                let (ha, hb) = estimators::crossings(q, seg, 0.5 * peak)?;
                Some(((hb - ha) * SAMPLE_STEP_PX / FWHM_PER_SIGMA).powi(2))
            }
        }
    }

    /// The variance (px² of this scale) of the blur whose pull on curved stripes is removed: the
    /// lens's PSF given in the settings ([`super::RidgeParams::optics_blur_px`], in the frame's
    /// own pixels) with the pixel's area and the sampling kernel, else measured on `centres`,
    /// the stripe's own profiles (a frame's other candidates, lit areas and textures refused by
    /// the checks, are wider and would inflate it). A profile's width is the sheet's as well as
    /// the blur's, and only the blur pulls: where the sheet is wider than the blur the
    /// measured variance over-corrects (σ²κ/2 with the sheet's σ²), so a known lens is better.
    fn blur_variance<'a>(&self, centres: impl Iterator<Item = &'a Centre>, scale: u32) -> f64 {
        match self.params.optics_blur_px {
            Some(sigma) => super::known_blur_variance(sigma, scale),
            None => pull_variance_median(centres).unwrap_or(0.0),
        }
    }

    /// The variance (px² of this scale) of the blur between the light and the profiles' samples
    /// whose shift of lopsided peaks the leans undo ([`Linked::lean`]): the lens's PSF given in the
    /// settings with the pixel's area and the sampling kernel, else those two alone. Unlike the
    /// pull's, it is never measured on the profiles: a wide sheet's width would count as blur
    /// and over-correct, where leaving out an unknown lens under-corrects.
    fn peak_blur_variance(&self, scale: u32) -> f64 {
        super::known_blur_variance(self.params.optics_blur_px.unwrap_or(0.0), scale)
    }

    /// Where the laser's tops lie from its sheet's peak at this scale, by their width, if its
    /// profile is known ([`super::RidgeParams::laser_profile`]).
    fn top_offsets(&self, scale: u32) -> Option<&super::laser::TopOffsets> {
        let profile = self.params.laser_profile?;
        Some(self.top_offsets.get_or_init(|| super::laser::TopOffsets::new(&profile, self.peak_blur_variance(scale))))
    }

    /// Where the laser's windowed centroids lie from its sheet's peak at this scale, if its
    /// profile is known and the windowed centroid locates the stripes.
    fn windowed_offsets(&self, scale: u32) -> Option<&super::laser::WindowedOffsets> {
        let profile = self.params.laser_profile?;
        if !matches!(self.params.method, super::Method::Windowed | super::Method::Hessian) {
            return None;
        }
        Some(
            self.windowed_offsets
                .get_or_init(|| super::laser::WindowedOffsets::new(&profile, self.peak_blur_variance(scale))),
        )
    }

    /// Where the laser's clipped plateaus' centres lie from its sheet's peak at this scale, if
    /// its profile is known ([`super::RidgeParams::laser_profile`]).
    fn plateau_offsets(&self, scale: u32) -> Option<&super::laser::PlateauOffsets> {
        let profile = self.params.laser_profile?;
        let sample_sigma = super::sampling::SAMPLE_SIGMA_PX;
        let clipped_variance = self.peak_blur_variance(scale) - sample_sigma * sample_sigma;
        Some(
            self.plateau_offsets
                .get_or_init(|| super::laser::PlateauOffsets::new(&profile, clipped_variance, sample_sigma)),
        )
    }

    /// Whether this scale's stripes are read through a colour mosaic's interpolation
    /// ([`super::RidgeParams::mosaic`]): binned 2 × 2 or more, each coarse pixel holds every
    /// colour of the mosaic.
    fn mosaic_at(&self, scale: u32) -> bool {
        self.params.mosaic && scale == 1
    }

    /// Links each centre to its neighbours on the same stripe and returns the points that
    /// survive the checks, corrected for the blur's pull and fitted along the stripe (module docs).
    fn link_and_correct(&self, centres: &[Centre], scale: u32) -> Vec<Linked> {
        let widest =
            half_width_quantile(centres, NARROW_PERCENTILE).map_or(f64::INFINITY, |w| MAX_HALF_WIDTH_RATIO * w);
        let along = self.params.along_stripe_px;
        let reach = SHAPE_HALF_ARC_PX.max(2.0 * along).max(super::MIN_STRIPE_ARC_PX) + 1.0;
        let grid = Grid::new(centres, reach);
        let mut kept: Vec<OnStripe> = Vec::with_capacity(centres.len());
        let mut stripes = Stripes::new(centres.len());
        let (mut neighbours, mut indices) = (Vec::new(), Vec::new());
        // Each kept point's neighbours, for the along-stripe fit once the points kept (and the
        // frame's noise) are known.
        let mut along_fits = AlongFits::default();
        // Each kept point's neighbours within the shape's arc, for the pull's bends, where that
        // arc is the shortest ([`smooth_pull_bends`]).
        let smooth_bends = self.smooths_pull_bends();
        let mut shape_neighbours: Vec<usize> = Vec::new();
        for i in 0..centres.len() {
            if !neighbours_on_the_stripe(&grid, centres, i, reach, &mut stripes, &mut neighbours, &mut indices) {
                continue;
            }
            let Some(mut point) = self.on_its_stripe(i, &centres[i], &neighbours, widest) else { continue };
            if along > 0.0 {
                along_fits.push(i, &neighbours, &indices);
            }
            if smooth_bends {
                let start = shape_neighbours.len();
                let near = neighbours.iter().zip(&indices).filter(|&(n, &j)| j != i && n.0.abs() <= SHAPE_HALF_ARC_PX);
                shape_neighbours.extend(near.map(|(_, &j)| j));
                point.shape_neighbours = start..shape_neighbours.len();
            }
            kept.push(point);
        }
        let saturated = |i: usize| centres[i].point.quality & quality::SATURATED != 0;
        keep_steadily_lopsided(&mut kept, &mut stripes, scale, saturated);
        if smooth_bends {
            smooth_pull_bends(&mut kept, &shape_neighbours, centres.len());
        }
        if along > 0.0 {
            let along_fits = along_fits.of_kept(&kept, centres.len());
            fit_along_kept(&mut kept, along_fits, along);
        }
        self.corrected(centres, kept, &mut stripes, scale)
    }

    /// Whether the blur's pull may take its neighbours' mean bend ([`smooth_pull_bends`]): where
    /// the along-stripe fit sets no shape arc longer than ±[`SHAPE_HALF_ARC_PX`].
    fn smooths_pull_bends(&self) -> bool {
        2.0 * self.params.along_stripe_px <= SHAPE_HALF_ARC_PX
    }

    /// The stripe's point at `centre` (index `i`) with its `neighbours` on the stripe, if it
    /// passes the checks that need them: a stripe long enough, going on past it, a width like
    /// its neighbours' and not a lit area's; with the stripe's bend, shape and lopsidedness
    /// there (the along-stripe fit's offset comes once the points kept are known).
    fn on_its_stripe(&self, i: usize, c: &Centre, neighbours: &[Neighbour], widest: f64) -> Option<OnStripe> {
        let along = self.params.along_stripe_px;
        let shape_half_arc = SHAPE_HALF_ARC_PX.max(2.0 * along);
        // Everything the checks below need from the neighbours, in one pass.
        let mut sums = ShapeSums::default();
        let mut width_line = LineSums::default();
        let (mut first, mut last, mut asymmetry_sum) = (0.0f64, 0.0f64, 0.0);
        // How many neighbours (within the shape's arc) there are, and how many of them are
        // narrow enough that this profile is not too narrow beside them.
        let (mut count, mut not_wider) = (0usize, 0usize);
        // How many of them lie on either side (beyond ±0.5 px), as a parabola needs.
        let (mut before, mut after) = (0usize, 0usize);
        for n in neighbours {
            (first, last) = (first.min(n.0), last.max(n.0));
            if n.0.abs() <= shape_half_arc {
                sums.add(n);
            }
            if n.0.abs() <= SHAPE_HALF_ARC_PX {
                asymmetry_sum += n.3;
                count += 1;
                before += usize::from(n.0 < -0.5);
                after += usize::from(n.0 > 0.5);
                not_wider += usize::from(MIN_WIDTH_RATIO * n.2 <= c.half_width);
                width_line.add(n.0, n.2);
            }
        }
        if !(last >= super::MIN_STRIPE_ARC_PX || -first >= super::MIN_STRIPE_ARC_PX) {
            return None;
        }
        if !(last >= END_PX && -first >= END_PX) {
            return None;
        }
        // Narrower than MIN_WIDTH_RATIO of the neighbours' median width (the upper median:
        // sorted index count / 2): as many as that index or fewer are narrow enough.
        if not_wider <= count / 2 {
            return None;
        }
        // Lit areas of the ambient image (a face's tapering tip, a sliver between shadows)
        // are wider than the laser's line, whose width the lens sets, and their width
        // changes along them.
        if c.half_width > widest && c.point.quality & quality::SATURATED == 0 {
            return None;
        }
        // d(half-maximum width)/dt along the stripe.
        if let Some((_, slope)) = width_line.fit()
            && slope.abs() > MAX_WIDTH_SLOPE
        {
            return None;
        }
        let factors = sums.factors();
        let parabola = sums.parabola(&factors);
        let curvature = parabola.map(|f| f[2]);
        // Too few neighbours on one side for the stripe's shape are too few to outvote a
        // profile's own lopsidedness either: it is judged alone too, at twice the limit. The
        // neighbours that count are those within ±SHAPE_HALF_ARC_PX, as for the mean, even where
        // the along-stripe fit takes its shape over a longer arc: at a stripe's end that arc
        // reaches the dimmer, narrower profiles beyond, which say nothing of this one's cut.
        let shape_near = count >= 5 && before >= 2 && after >= 2;
        let own = (curvature.is_none() || !shape_near).then_some(c.asymmetry);
        let lopsided = Lopsided { mean: asymmetry_sum / count as f64, own };
        let local = sums.local_stripe(&factors);
        // What judges the bend against its neighbours' ([`smooth_pull_bends`]).
        let bend_noise = if local.is_some() && self.smooths_pull_bends() {
            let spread = factors.solve::<4>(&[0.0, 0.0, 1.0, 0.0]).map(|x| x[2].max(0.0).sqrt());
            spread.zip(parabola.and_then(|p| sums.scatter(p)))
        } else {
            None
        };
        // The along-stripe fit's offset waits for the points kept ([`fit_along_kept`]).
        Some(OnStripe { index: i, curvature, offset: 0.0, local, lopsided, bend_noise, shape_neighbours: 0..0 })
    }

    /// The stripe's points as measured, moved by the along-stripe fit's offset less the blur's
    /// pull (the points it moves too far are dropped) and given their leans to the light's peak.
    fn corrected(&self, centres: &[Centre], kept: Vec<OnStripe>, stripes: &mut Stripes, scale: u32) -> Vec<Linked> {
        let blur_variance = self.blur_variance(kept.iter().map(|k| &centres[k.index]), scale);
        // The laser's shape, like its steady lopsidedness, is the stripe's: the medians over the
        // stripe of its tops' shapes, in units of each profile's σ (alike for a laser's shape
        // at any width), where they stand out from the profiles' scatter. Per profile they are
        // noisy (a cubic's third derivative); along a bend or a step they are not the laser's.
        let shapes: Vec<(usize, [f64; 2])> =
            kept.iter().filter_map(|k| Some((k.index, centres[k.index].top_shape?))).collect();
        let top_offsets = self.top_offsets(scale);
        let placed = |i: usize| (centres[i].point.u, centres[i].point.v, centres[i].normal);
        let stripe_shape = stripe_shapes(stripes, &shapes, self.mosaic_at(scale), placed);
        let peak_blur = self.peak_blur_variance(scale);
        let mut out = Vec::with_capacity(kept.len());
        for OnStripe { index: i, curvature, offset, local, .. } in kept {
            let c = &centres[i];
            // A parabola d = c·t² has its centre of curvature on the +n side for c > 0; the blur
            // pulls the centre that way by σ²κ/2 = σ²·c (more where the stripe bends, brightens
            // or dims along its length: `LocalStripe::pull`).
            let pull = match local {
                Some(l) => l.pull(blur_variance),
                None => curvature.map_or(0.0, |k| blur_variance * k),
            };
            let shift = offset - pull;
            if shift.abs() > MAX_MOVE_PX {
                continue;
            }
            let mut p = c.point;
            p.u += shift * c.normal.0;
            p.v += shift * c.normal.1;
            let shape = stripe_shape.with_errors_of(stripes, i);
            let lean = c.lean.filter(|_| c.flatness <= LEAN_MAX_FLATNESS);
            let (lean, tail_offset, led_by_profile) = match lean {
                Some(lean) => {
                    let (lean, tail, by_profile) =
                        lean_to_sheet_peak(lean, c.half_width, shape, peak_blur, top_offsets);
                    (Some(lean), tail, by_profile)
                }
                None => (None, 0.0, false),
            };
            out.push(Linked { point: p, lean, top_shape: None, tail_offset, led_by_profile, ..c.linked() });
        }
        out
    }
}

/// A centre that passed the link's checks: its index, its stripe's bend c of d = c·t² (1/px),
/// the along-stripe fit's offset (px), the stripe's local shape and contrast for the blur's
/// pull, and the lopsidedness of its stretch of stripe, judged once the stripes' own steady
/// lopsidedness is known.
struct OnStripe {
    index: usize,
    curvature: Option<f64>,
    offset: f64,
    local: Option<LocalStripe>,
    lopsided: Lopsided,
    /// The standard error of `local`'s bend per unit of the points' noise, and the scatter of
    /// the neighbours within ±[`SHAPE_HALF_ARC_PX`] about their parabola (px).
    bend_noise: Option<(f64, f64)>,
    /// Where the indices of its neighbours within ±[`SHAPE_HALF_ARC_PX`] lie in the list that
    /// [`smooth_pull_bends`] is given.
    shape_neighbours: std::ops::Range<usize>,
}

/// Gives each of `kept` the mean of its own and its neighbours' bends (`neighbours`, centre
/// indices, at each point's `shape_neighbours`) for its blur's pull, where that mean lies within
/// [`ARC_AGREEMENT`] standard errors of its own bend, the noise being the frame's (the median
/// scatter about the points' parabolas, times [`CORRELATED_NOISE`]), as the along-stripe fit
/// takes its longer arcs (Lepski's rule). A speckle grain moves a point and its nearest
/// neighbours together, which a parabola over ±3 px reads as a bend, and the pull would move
/// the point further the way the grain did; the neighbours' own parabolas see the grain
/// elsewhere along them, and their mean bend, over about ±6 px of stripe, hardly depends on
/// the point's own error. A stripe that bends faster than that keeps the point's own bend.
fn smooth_pull_bends(kept: &mut [OnStripe], neighbours: &[usize], centres: usize) {
    let noise = frame_noise(kept.iter().filter_map(|k| Some(k.bend_noise?.1)).collect());
    let mut kept_at = vec![usize::MAX; centres];
    for (k, point) in kept.iter().enumerate() {
        kept_at[point.index] = k;
    }
    let bends: Vec<Option<f64>> = kept.iter().map(|k| k.local.map(|l| l.c)).collect();
    for (k, point) in kept.iter_mut().enumerate() {
        let (Some(local), Some((spread, _))) = (point.local.as_mut(), point.bend_noise) else { continue };
        let kept_bend = |j: usize| kept_at.get(j).and_then(|&at| bends.get(at).copied().flatten());
        let theirs = neighbours[point.shape_neighbours.clone()].iter().filter_map(|&j| kept_bend(j));
        let (sum, count) = theirs.chain(bends[k]).fold((0.0, 0usize), |(s, n), c| (s + c, n + 1));
        let mean = sum / count as f64;
        if count >= PULL_MIN_BENDS && (mean - local.c).abs() <= ARC_AGREEMENT * noise * spread {
            local.c = mean;
        }
    }
}

/// Fills `out` with centre `i`'s neighbours on its stripe within `reach` px (`indices` with
/// their centres) and joins it to those within [`SHAPE_HALF_ARC_PX`] in `stripes`; `false`
/// where another centre measured the same crossing and is kept instead (two seeds of one
/// crossing: a run broken by speckle, a stripe at 45° seen from a row and a column; the
/// brighter, then the first, is kept).
fn neighbours_on_the_stripe(
    grid: &Grid,
    centres: &[Centre],
    i: usize,
    reach: f64,
    stripes: &mut Stripes,
    out: &mut Vec<Neighbour>,
    indices: &mut Vec<usize>,
) -> bool {
    let c = &centres[i];
    let (px, py) = (c.point.u, c.point.v);
    let (nx, ny) = c.normal;
    let reach2 = reach * reach;
    out.clear();
    indices.clear();
    let mut duplicate = false;
    grid.visit(px, py, |j, &[ou, ov, onx, ony]| {
        let (ex, ey) = (ou - px, ov - py);
        let distance2 = ex * ex + ey * ey;
        if distance2 > reach2 {
            return;
        }
        let cos = onx * nx + ony * ny;
        if cos.abs() < SAME_STRIPE_COS {
            return;
        }
        let o = &centres[j];
        if distance2 < DUPLICATE_PX * DUPLICATE_PX
            && j != i
            && (o.point.intensity, std::cmp::Reverse(j)) > (c.point.intensity, std::cmp::Reverse(i))
        {
            duplicate = true;
        }
        let (t, d) = (-ny * ex + nx * ey, nx * ex + ny * ey);
        if d.abs() <= 0.5 + 0.25 * t.abs() {
            // The asymmetry as seen along this point's normal.
            let asymmetry = if cos > 0.0 { o.asymmetry } else { -o.asymmetry };
            out.push((t, d, o.half_width, asymmetry, o.point.intensity));
            indices.push(j);
            if t.abs() <= SHAPE_HALF_ARC_PX {
                stripes.join(i, j, cos < 0.0);
            }
        }
    });
    !duplicate
}

/// The along-stripe fit's offset of each of `kept` over up to ±`along` px, through its
/// neighbours that were kept themselves (`along_fits`, one entry each, [`AlongFits::of_kept`]):
/// the centres a stripe's end refused (its last profiles, those beyond it that a silhouette's
/// edge or a surface's turn spoils) would pull the fit towards them. The blur's pull still
/// takes the stripe's bend from every measured neighbour: beyond an end they trace its course
/// well enough, though not where its last points lie.
fn fit_along_kept(kept: &mut [OnStripe], along_fits: AlongFits, along: f64) {
    if along > SHAPE_HALF_ARC_PX {
        fit_longer_arcs(kept, &along_fits, along);
        return;
    }
    // One arc (±3 px or less): the line once the bend of the parabola over ±max(3, 2 × the
    // arc) px is taken out.
    for (k, point) in kept.iter_mut().enumerate() {
        if point.curvature.is_some() {
            point.offset = arc_offset(along_fits.of(k), along).map_or(0.0, |(offset, _)| offset);
        }
    }
}

/// The along-stripe fit over arcs longer than ±[`SHAPE_HALF_ARC_PX`] (`along` px at most), once
/// the frame's noise is known from every kept point's neighbours (`along_fits`, one entry per
/// point of `kept`). The blur's pull follows the stripe's shape over twice the arc the fit
/// took: where the stripe bends too fast for the longer arcs, their shape is not its shape here.
fn fit_longer_arcs(kept: &mut [OnStripe], along_fits: &AlongFits, along: f64) {
    let shape_half_arc = SHAPE_HALF_ARC_PX.max(2.0 * along);
    for (k, (offset, arc)) in along_fits.offsets(along).into_iter().enumerate() {
        let point = &mut kept[k];
        if point.curvature.is_none() {
            continue;
        }
        point.offset = offset;
        if 2.0 * arc < shape_half_arc {
            let sums = ShapeSums::new(along_fits.of(k), SHAPE_HALF_ARC_PX.max(2.0 * arc));
            let factors = sums.factors();
            point.curvature = sums.parabola(&factors).map(|f| f[2]).or(point.curvature);
            point.local = sums.local_stripe(&factors);
        }
    }
}

/// Drops the points whose stretch of stripe is lopsided unlike their stripe. A cut leaves the
/// profiles along it lopsided; speckle and noise lopsided at random, so the neighbours' mean
/// tells the two apart. A laser's own shape leaves its whole stripe lopsided the same way: a
/// cut is a departure from the stripe's steady lopsidedness. Clipped profiles (`saturated`)
/// are judged against their stripe's clipped ones where those have a steadiness: their flanks
/// are read relative to the plateau, lower down the light than an unclipped profile's, where a
/// lopsided laser is more lopsided.
fn keep_steadily_lopsided(
    kept: &mut Vec<OnStripe>,
    stripes: &mut Stripes,
    scale: u32,
    saturated: impl Fn(usize) -> bool,
) {
    let min_points = (STEADY_MIN_PX / scale as usize).max(STEADY_MIN_POINTS);
    let mut steady_of = |only_clipped: bool| {
        let means: Vec<(usize, f64)> =
            kept.iter().filter(|k| !only_clipped || saturated(k.index)).map(|k| (k.index, k.lopsided.mean)).collect();
        stripes.steady(&means, min_points)
    };
    let all = steady_of(false);
    let clipped = if kept.iter().any(|k| saturated(k.index)) { steady_of(true) } else { Vec::new() };
    kept.retain(|k| {
        // Clipped points without a steadiness of their own (too few on their stripe, or none
        // that holds) take the whole stripe's.
        let own = if saturated(k.index) { clipped[k.index] } else { None };
        let [lo, hi] = own.or(all[k.index]).unwrap_or([0.0, 0.0]);
        let departure = |a: f64| (lo - a).max(a - hi).max(0.0);
        departure(k.lopsided.mean) <= MAX_ASYMMETRY
            && k.lopsided.own.is_none_or(|a| departure(a) <= 2.0 * MAX_ASYMMETRY)
    });
}

impl Linked {
    /// Position and normal (u, v, nx, ny), as [`Grid`] places points.
    fn placed(&self) -> [f64; 4] {
        [self.point.u, self.point.v, self.normal.0, self.normal.1]
    }
}

impl Centre {
    fn linked(&self) -> Linked {
        Linked {
            point: self.point,
            normal: self.normal,
            half_width: self.half_width,
            lean: self.lean,
            top_shape: self.top_shape,
            side_lean: self.side_lean,
            tail_offset: 0.0,
            led_by_profile: false,
            window_offset: None,
            plateau_edges: self.plateau_edges,
            background_excess: self.background_excess,
        }
    }
}

/// Moves each point by the mean lean ([`Linked::lean`]) of its stripe within
/// ±[`LEAN_HALF_ARC_PX`]: from the estimator's centre to the peak of the light. A laser's tail
/// lies on the same side of its stripe all along it, so the mean keeps the tail's pull and
/// averages away each profile's noise, which at the top alone is 1.5–3 times the estimator's.
/// Where the leans lead only to the tops' centroids ([`Linked::tail_offset`], a laser's profile
/// known), the neighbours' mean tail offset is added on the tail's side ([`tail_sides`]); where
/// the profile also predicts the windowed centroid's own offset, the point moves by that
/// prediction, which has no top's noise, and by as much of the leans' departure from it as
/// stands out of their noise ([`WindowLeans`]). A saturated point has no lean: it moves by its
/// own tail offset, its plateau centre's ([`lead_plateaus_to_sheet_peak`]). `sides`: the tails'
/// sides where already known ([`tail_sides_of`]).
fn remove_steady_lean(points: &mut [Linked], sides: Option<Vec<f64>>) {
    let grid = Grid::from_placed(points.iter().map(Linked::placed), LEAN_HALF_ARC_PX);
    let sides = sides.unwrap_or_else(|| tail_sides(points));
    let shifts: Vec<f64> = points
        .iter()
        .enumerate()
        .map(|(i, l)| {
            if l.point.quality & quality::SATURATED != 0 {
                return sides.get(i).copied().unwrap_or(0.0) * l.tail_offset;
            }
            let here = l.placed();
            let side = sides.get(i).copied().unwrap_or(0.0);
            let (mut sum, mut offset_sum, mut count) = (0.0, 0.0, 0usize);
            let mut window = WindowLeans::default();
            grid.visit(here[0], here[1], |j, other| {
                if let Some(lean) = points[j].lean
                    && let Some((_, _, same_way)) = on_the_stripe(&here, other, LEAN_HALF_ARC_PX)
                {
                    let lean = if same_way { lean } else { -lean };
                    sum += lean;
                    offset_sum += points[j].tail_offset;
                    count += 1;
                    if l.window_offset.is_some() {
                        window.add(lean, side, points[j].tail_offset, points[j].window_offset);
                    }
                }
            });
            if count < LEAN_MIN_PROFILES {
                return 0.0;
            }
            if l.window_offset.is_some()
                && let Some(shift) = window.shift(count, side)
            {
                return shift;
            }
            sum / count as f64 + side * offset_sum / count as f64
        })
        .collect();
    for (l, shift) in points.iter_mut().zip(shifts) {
        l.point.u -= shift * l.normal.0;
        l.point.v -= shift * l.normal.1;
    }
}

/// The leans of a point's neighbours against what the laser's profile predicts for them
/// ([`Linked::window_offset`] less [`Linked::tail_offset`] on the tail's side), for
/// [`remove_steady_lean`]. A lean measured on a profile's top is noisy under speckle; the
/// profile's prediction has no noise but sees only the laser, where a lean also sees what else
/// tilts the profile (the room's light, a checkerboard's squares, a surface's slant). So the
/// leans' mean departure from the prediction is kept in proportion to how surely it stands out
/// of their noise.
#[derive(Default)]
struct WindowLeans {
    /// Sum of the leans less their predictions (px).
    residual: f64,
    /// Sum of their squares (px²).
    squares: f64,
    /// How many.
    count: usize,
    /// Sum of the window offsets (px).
    offsets: f64,
}

impl WindowLeans {
    fn add(&mut self, lean: f64, side: f64, top_offset: f64, window_offset: Option<f64>) {
        if let Some(window) = window_offset {
            let r = lean - side * (window - top_offset);
            self.residual += r;
            self.squares += r * r;
            self.count += 1;
            self.offsets += window;
        }
    }

    /// The point's shift (px along its normal) where every one of its `leans` neighbours has a
    /// prediction and the tail's `side` is known: the neighbours' mean window offset on that
    /// side, plus their leans' mean departure r from the prediction shrunk by r²/(r² + se²),
    /// se its standard error. A departure well beyond its noise is kept whole (the shift is
    /// then the leans' own), one within it mostly dropped, with no step between the two. The
    /// leans are correlated along the stripe, so se counts [`CORRELATED_NOISE`] times the
    /// independent error.
    fn shift(&self, leans: usize, side: f64) -> Option<f64> {
        if self.count != leans || self.count == 0 || side == 0.0 {
            return None;
        }
        let n = self.count as f64;
        let mean = self.residual / n;
        let variance = (self.squares / n - mean * mean).max(0.0);
        let se2 = CORRELATED_NOISE * CORRELATED_NOISE * variance / n;
        let kept = if mean == 0.0 { 0.0 } else { mean * mean * mean / (mean * mean + se2) };
        Some(side * self.offsets / n + kept)
    }
}

/// With the laser's profile known (`model`, built when first needed), sets each saturated
/// point's [`Linked::tail_offset`]: where its plateau centre lies from the sheet's peak
/// ([`super::laser::PlateauOffsets`]), by its edges' distance and the medians of its stripe's
/// unsaturated profiles within ±[`TAIL_SIDE_HALF_ARC_PX`] (at least [`LEAN_MIN_PROFILES`] of
/// them): their half-maximum width, which gives the sheet's width there, and the tail's light
/// in their background. A background counts the tail's light where it is higher on the tail's
/// side ([`tail_sides_of`]; an ambient slope the other way is not the laser's). Each offset is
/// then averaged over the clipped points within ±[`LEAN_HALF_ARC_PX`] whose edges lie as far
/// apart, give or take [`SAME_CLIP_EDGES`] (one plateau's edges are noisy; the offset grows
/// steeply with the clip's depth). A point the table cannot lead (too few unsaturated
/// neighbours, beyond the table) takes that average where at least [`LEAN_MIN_PROFILES`] of its
/// alike neighbours were led, else stays at its plateau's centre. Returns the tails' sides it
/// found, if it looked.
fn lead_plateaus_to_sheet_peak<'a>(
    points: &mut [Linked],
    model: impl FnOnce() -> Option<&'a super::laser::PlateauOffsets>,
) -> Option<Vec<f64>> {
    let is_saturated = |l: &Linked| l.point.quality & quality::SATURATED != 0;
    if !points.iter().any(|l| is_saturated(l) && l.plateau_edges.is_some()) {
        return None;
    }
    let model = model()?;
    let sides = tail_sides_of(points);
    // The tail's light in a background, from its `excess` along a normal on whose `side` the
    // tail lies.
    let tail_light = |excess: f64, side: f64| (side * excess).max(0.0);
    let grid = Grid::from_placed(points.iter().map(Linked::placed), TAIL_SIDE_HALF_ARC_PX);
    let (mut widths, mut shares) = (Vec::new(), Vec::new());
    let offsets: Vec<Option<f64>> = points
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let [edges, threshold] = l.plateau_edges.filter(|_| is_saturated(l))?;
            let side = sides[i];
            if side == 0.0 {
                return None;
            }
            let here = l.placed();
            widths.clear();
            shares.clear();
            grid.visit(here[0], here[1], |j, other| {
                let n = &points[j];
                if !is_saturated(n)
                    && let Some((_, _, same_way)) = on_the_stripe(&here, other, TAIL_SIDE_HALF_ARC_PX)
                {
                    let e = tail_light(n.background_excess, if same_way { side } else { -side });
                    widths.push(n.half_width);
                    shares.push(e / (n.point.intensity + e));
                }
            });
            if widths.len() < LEAN_MIN_PROFILES {
                return None;
            }
            let (half_width, background) = (stats::median(&widths)?, stats::median(&shares)?);
            let e = tail_light(l.background_excess, side);
            let threshold_share = (threshold + e) / (l.point.intensity + e);
            model.midpoint_at(half_width, background, edges, threshold_share)
        })
        .collect();
    let near = Grid::from_placed(points.iter().map(Linked::placed), LEAN_HALF_ARC_PX);
    let smoothed: Vec<f64> = points
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let Some([edges, _]) = l.plateau_edges.filter(|_| is_saturated(l)) else { return l.tail_offset };
            let here = l.placed();
            let (mut sum, mut count) = (0.0, 0usize);
            near.visit(here[0], here[1], |j, other| {
                if let (Some(offset), Some([other_edges, _])) = (offsets[j], points[j].plateau_edges)
                    && (other_edges - edges).abs() <= SAME_CLIP_EDGES.max(0.05 * edges)
                    && on_the_stripe(&here, other, LEAN_HALF_ARC_PX).is_some()
                {
                    sum += offset;
                    count += 1;
                }
            });
            // A point the table could not lead (too few unclipped profiles within its reach on
            // a tight curve or a long clipped stretch) takes its alike neighbours' offsets
            // where as many were led as a median would need.
            let enough = if offsets[i].is_some() { 1 } else { LEAN_MIN_PROFILES };
            if count < enough {
                return l.tail_offset;
            }
            sum / count as f64
        })
        .collect();
    for (l, offset) in points.iter_mut().zip(smoothed) {
        l.tail_offset = offset;
    }
    Some(sides)
}

/// Sets the [`Linked::window_offset`] of the points the laser's profile leads
/// ([`Linked::led_by_profile`]): `model`'s offset at each point's half-maximum width and the
/// level its weights start from, the `threshold` as a share of its peak. The background's
/// share of the tail's light is left out: in a lit frame the two sides' backgrounds differ by
/// the room's light as much as by the tail's (docs/DECISIONS.md).
fn lead_windows_to_sheet_peak(points: &mut [Linked], model: &super::laser::WindowedOffsets, threshold: f64) {
    for l in points.iter_mut().filter(|l| l.led_by_profile) {
        l.window_offset = model.offset_at(l.half_width, threshold / l.point.intensity);
    }
}

/// Plateaus whose edges' distances differ by at most this (px), or 5 % where more, are taken
/// as clipped alike ([`lead_plateaus_to_sheet_peak`]).
const SAME_CLIP_EDGES: f64 = 0.3;

/// Half the arc (px) over which a stripe's profiles tell on which side its tail lies.
const TAIL_SIDE_HALF_ARC_PX: f64 = 48.0;

/// The side of each point's stripe (±1 along its normal) where the laser's tail lies, where
/// a point still has a [`Linked::tail_offset`] to go: the side most of its stripe's profiles
/// within ±[`TAIL_SIDE_HALF_ARC_PX`] point to, each casting two votes, the signs of its
/// [`Centre::side_lean`] (a lopsided profile's windowed centroid lies beyond its top on the
/// tail's side) and of its [`Centre::background_excess`] (the tail's light raises the
/// background on its side); 0 where the votes tie. Signs, not sizes: under speckle a few
/// profiles' tops lean far the wrong way and would outweigh the rest, and the background
/// tells the side more often than the top does (docs/DECISIONS.md). Empty where no point has
/// one.
fn tail_sides(points: &[Linked]) -> Vec<f64> {
    if points.iter().all(|l| l.tail_offset == 0.0) {
        return Vec::new();
    }
    tail_sides_of(points)
}

/// [`tail_sides`] of every point.
fn tail_sides_of(points: &[Linked]) -> Vec<f64> {
    let grid = Grid::from_placed(points.iter().map(Linked::placed), TAIL_SIDE_HALF_ARC_PX);
    let sign = |x: f64| {
        if x > 0.0 {
            1.0
        } else if x < 0.0 {
            -1.0
        } else {
            0.0
        }
    };
    points
        .iter()
        .map(|l| {
            let here = l.placed();
            let mut votes = 0.0;
            grid.visit(here[0], here[1], |j, other| {
                if let Some(lean) = points[j].side_lean
                    && let Some((_, _, same_way)) = on_the_stripe(&here, other, TAIL_SIDE_HALF_ARC_PX)
                {
                    let vote = sign(lean) + sign(points[j].background_excess);
                    votes += if same_way { vote } else { -vote };
                }
            });
            sign(votes)
        })
        .collect()
}

/// Drops the points re-measured from a coarser scale whose chain (points within
/// [`super::along::STRIPE_LINK_PX`] of each other with nearly parallel normals, at least
/// [`CHAIN_MIN_PX`] end to end) widens or narrows along its length faster than
/// [`MAX_CHAIN_WIDTH_SLOPE`]: a lit area tapering to a tip, binned, is a narrow ridge at the
/// coarse scale, and only its width on the finer frame tells it from a laser's line. The
/// slope is fitted over the whole chain, where a wide laser line's width, noisy from profile
/// to profile, averages out; a lit wedge widens steadily all along.
fn drop_tapering(points: &mut Vec<Linked>) {
    let slopes = chain_width_slopes(points);
    let mut k = 0;
    points.retain(|_| {
        k += 1;
        !slopes[k - 1].is_some_and(|s| s.abs() > MAX_CHAIN_WIDTH_SLOPE)
    });
}

/// Each point's chain's half-maximum width slope (px per px along the chain: least squares
/// over the chain's points, placed along its principal direction), for chains that span at
/// least [`CHAIN_MIN_PX`]; `None` for shorter chains.
fn chain_width_slopes(points: &[Linked]) -> Vec<Option<f64>> {
    let link = super::along::STRIPE_LINK_PX;
    let grid = Grid::from_placed(points.iter().map(Linked::placed), link);
    let mut stripes = Stripes::new(points.len());
    for (i, l) in points.iter().enumerate() {
        let here = l.placed();
        grid.visit(here[0], here[1], |j, other| {
            if j != i && on_the_stripe(&here, other, link).is_some() {
                stripes.join(i, j, false);
            }
        });
    }
    let mut chains: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for i in 0..points.len() {
        chains.entry(stripes.find(i).0).or_default().push(i);
    }
    let mut slope_of = vec![None; points.len()];
    for chain in chains.values() {
        let at = |i: usize| (points[i].point.u, points[i].point.v);
        let n = chain.len() as f64;
        let (mu, mv) = chain.iter().fold((0.0, 0.0), |(a, b), &i| (a + at(i).0 / n, b + at(i).1 / n));
        let (mut suu, mut suv, mut svv) = (0.0, 0.0, 0.0);
        for &i in chain {
            let (du, dv) = (at(i).0 - mu, at(i).1 - mv);
            (suu, suv, svv) = (suu + du * du, suv + du * dv, svv + dv * dv);
        }
        // The principal direction of the chain's points.
        let angle = 0.5 * (2.0 * suv).atan2(suu - svv);
        let (cu, cv) = (angle.cos(), angle.sin());
        let mut line = LineSums::default();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &i in chain {
            let t = (at(i).0 - mu) * cu + (at(i).1 - mv) * cv;
            (lo, hi) = (lo.min(t), hi.max(t));
            line.add(t, points[i].half_width);
        }
        if hi - lo >= CHAIN_MIN_PX {
            let slope = line.slope();
            for &i in chain {
                slope_of[i] = slope;
            }
        }
    }
    slope_of
}

/// Shortest chain (px end to end) whose width slope [`chain_width_slopes`] judges.
const CHAIN_MIN_PX: f64 = 6.0;

/// The along-stripe fit ([`super::RidgeParams::along_stripe_px`], `along` px) of points
/// re-measured from a coarser scale, which [`RidgeDetector::link_and_correct`] never sees: as
/// there, each point moves to the line fitted to its stripe's neighbours within ±`along` once
/// the curvature of a parabola over the wider arc is taken out. A wide stripe's points carry
/// the most noise (it grows with the width), so they need the fit most. A point whose fit
/// would move it more than [`MAX_MOVE_PX`] stays where it is.
fn fit_along_stripe(points: &mut [Linked], along: f64) {
    if !(along > 0.0) {
        return;
    }
    let reach = SHAPE_HALF_ARC_PX.max(2.0 * along) + 1.0;
    let grid = Grid::from_placed(points.iter().map(Linked::placed), reach);
    let (mut neighbours, mut indices): (Vec<Neighbour>, Vec<usize>) = (Vec::new(), Vec::new());
    let mut along_fits = AlongFits::default();
    for l in points.iter() {
        let here = l.placed();
        neighbours.clear();
        indices.clear();
        grid.visit(here[0], here[1], |j, other| {
            if let Some((t, d, _)) = on_the_stripe(&here, other, reach) {
                neighbours.push((t, d, 0.0, 0.0, 0.0));
                indices.push(j);
            }
        });
        along_fits.push(along_fits.ends.len(), &neighbours, &indices);
    }
    let shifts: Vec<f64> = along_fits
        .offsets(along)
        .into_iter()
        .map(|(offset, _)| if offset.abs() > MAX_MOVE_PX { 0.0 } else { offset })
        .collect();
    for (l, shift) in points.iter_mut().zip(shifts) {
        l.point.u += shift * l.normal.0;
        l.point.v += shift * l.normal.1;
    }
}

/// Where the point `other` lies from the point `here` (both placed as (u, v, nx, ny), px), if
/// on the same stripe (within `reach` px, its normal within 30° either way, and within
/// 0.5 + 0.25·|t| px of `here`'s tangent): arc t and offset d along `here`'s normal (px), and
/// whether the two normals point the same way.
fn on_the_stripe(&[px, py, nx0, ny0]: &[f64; 4], &[u, v, nx, ny]: &[f64; 4], reach: f64) -> Option<(f64, f64, bool)> {
    let (ex, ey) = (u - px, v - py);
    let cos = nx * nx0 + ny * ny0;
    if ex * ex + ey * ey > reach * reach || cos.abs() < SAME_STRIPE_COS {
        return None;
    }
    let (t, d) = (-ny0 * ex + nx0 * ey, nx0 * ex + ny0 * ey);
    (d.abs() <= 0.5 + 0.25 * t.abs()).then_some((t, d, cos > 0.0))
}

/// Adds to each point's lean (from its top's centroid) its stripe's median top shape, as
/// `link_and_correct` does for the points it links: from the top's centroid to the image's peak
/// and back by the blur's shift of a lopsided peak (`blur_variance`, px²), or, with the laser's
/// profile known (`top_offsets`), sets its [`Linked::tail_offset`] where the shape cannot tell
/// ([`lean_to_sheet_peak`]). For points re-measured from a coarser scale, whose stripes are the
/// chains of points within [`super::along::STRIPE_LINK_PX`] of each other with nearly parallel
/// normals.
fn lean_to_the_lights_peak(
    points: &mut [Linked],
    blur_variance: f64,
    mosaic: bool,
    top_offsets: Option<&super::laser::TopOffsets>,
) {
    let grid = Grid::from_placed(points.iter().map(Linked::placed), super::along::STRIPE_LINK_PX);
    let mut stripes = Stripes::new(points.len());
    for (i, l) in points.iter().enumerate() {
        let (px, py, (nx, ny)) = (l.point.u, l.point.v, l.normal);
        grid.visit(px, py, |j, &[ou, ov, onx, ony]| {
            let (ex, ey) = (ou - px, ov - py);
            let cos = onx * nx + ony * ny;
            if j != i && ex * ex + ey * ey <= super::along::STRIPE_LINK_PX.powi(2) && cos.abs() >= SAME_STRIPE_COS {
                stripes.join(i, j, cos < 0.0);
            }
        });
    }
    let shapes: Vec<(usize, [f64; 2])> =
        points.iter().enumerate().filter_map(|(i, l)| Some((i, l.top_shape.filter(|_| l.lean.is_some())?))).collect();
    let stripe_shape =
        stripe_shapes(&mut stripes, &shapes, mosaic, |i| (points[i].point.u, points[i].point.v, points[i].normal));
    for (i, l) in points.iter_mut().enumerate() {
        let shape = stripe_shape.with_errors_of(&mut stripes, i);
        if let Some(lean) = l.lean {
            let (lean, tail, by_profile) = lean_to_sheet_peak(lean, l.half_width, shape, blur_variance, top_offsets);
            (l.lean, l.tail_offset, l.led_by_profile) = (Some(lean), tail, by_profile);
        }
        l.top_shape = None;
    }
}

/// Each stripe's median top shape ([`Stripes::medians`] of `shapes`), dropped where its skew is
/// beyond a laser's ([`MAX_TOP_SKEW`]) and where a colour mosaic's interpolation made it
/// (`mosaic`: [`RidgeDetector::mosaic_at`]); `placed(i)`: point i's position and normal.
fn stripe_shapes(
    stripes: &mut Stripes,
    shapes: &[(usize, [f64; 2])],
    mosaic: bool,
    placed: impl Fn(usize) -> (f64, f64, (f64, f64)),
) -> StripeMedians<2> {
    let mut medians = stripes.medians(shapes, STEADY_MIN_POINTS);
    medians.drop_where(|[_, skew]| skew.abs() > MAX_TOP_SKEW);
    if mosaic {
        let points = shapes.iter().map(|&(i, _)| {
            let (u, v, normal) = placed(i);
            (i, u, v, normal)
        });
        medians.keep_where_the_mosaic_averages_out(stripes, points);
    }
    medians
}

/// A lean from the top's centroid ([`Centre::lean`], px) carried on to the peak of the light by
/// its stripe's top shape `[top_offset, skew]` ([`Centre::top_shape`], in the profile's σ from
/// its half-maximum width `half_width`): to the image's peak, and back by the blur's shift of
/// a lopsided peak, −(s/2)·L‴/L″ for the blur's variance s = `blur_variance` (px²).
fn lean_to_peak(lean: f64, half_width: f64, [top_offset, skew]: [f64; 2], blur_variance: f64) -> f64 {
    let sigma = half_width / FWHM_PER_SIGMA;
    lean + top_offset * sigma - 0.5 * blur_variance * skew / sigma
}

/// A lean ([`lean_to_peak`]'s arguments; the stripe's top shape with its medians' standard
/// errors) carried towards the sheet's peak, and how far beyond it the peak still lies on the
/// tail's side (px), left to [`remove_steady_lean`], which knows that side ([`tail_sides`]). A
/// stripe with a top shape of its own is led to the peak by it ([`lean_to_peak`]), unless the
/// laser's profile is known (`top_offsets`) and either the blur makes most of the profile's
/// width (the shape's undoing of the blur holds to first order only) or the shape's noise
/// would move the point by more than [`MAX_SHAPE_NOISE_SIGMAS`]. Otherwise, with the profile
/// known, the lean leads to the top's centroid and the profile's offset of that centroid from
/// the sheet's peak remains: it needs no stretch of stripe for a median, only the profile's
/// width, but it sees only the profile, where a wide stripe's own top shape sees whatever else
/// shapes it in the image (docs/DECISIONS.md). The third value tells whether the profile led
/// it ([`Linked::led_by_profile`]).
fn lean_to_sheet_peak(
    lean: f64,
    half_width: f64,
    (shape, shape_error): ([f64; 2], [f64; 2]),
    blur_variance: f64,
    top_offsets: Option<&super::laser::TopOffsets>,
) -> (f64, f64, bool) {
    let sigma = half_width / FWHM_PER_SIGMA;
    let blur_share = blur_variance / (sigma * sigma);
    match top_offsets {
        Some(model)
            if shape == [0.0, 0.0]
                || blur_share > BLUR_DOMINATED_SHARE
                || top_shape_noise(shape_error, sigma, blur_variance) > MAX_SHAPE_NOISE_SIGMAS * sigma =>
        {
            (lean, model.centroid_at(half_width), true)
        }
        _ => (lean_to_peak(lean, half_width, shape, blur_variance), 0.0, false),
    }
}

/// How far (px) the noise of a stripe's median top shape (`error`, the medians' standard
/// errors as if independent) moves [`lean_to_peak`]'s result on a profile of σ `sigma` px under
/// a blur of variance `blur_variance` px²: neighbouring profiles share speckle grains and
/// pixels, so the errors count [`CORRELATED_NOISE`] times.
fn top_shape_noise([top_offset, skew]: [f64; 2], sigma: f64, blur_variance: f64) -> f64 {
    CORRELATED_NOISE * (top_offset * sigma).hypot(0.5 * blur_variance * skew / sigma)
}

/// The top of a profile (`q` above its background, half-maximum width `half_width` px; `top`
/// its samples above [`TOP_LEVEL`] of the peak) as [`estimators::log_cubic_top`] fits it:
/// (vertex, skew) in samples. `None` where the fit says nothing of the laser's shape: a vertex
/// outside the top. The skew is not limited here: only stripes' medians of it are used
/// ([`MAX_TOP_SKEW`]).
fn stripe_top(q: &[f32], top: &Segment, half_width: f64) -> Option<(f64, f64)> {
    // `as` truncates: ⌊x + ½⌋ rounds (`f64::round` is a library call on baseline x86-64).
    let half_window = ((TOP_HALF_WINDOW * 0.5 * half_width / SAMPLE_STEP_PX + 0.5) as usize).max(2);
    let (vertex, skew) = estimators::log_cubic_top(q, top.peak, half_window)?;
    let inside = (top.start as f64 - 1.0..=top.end as f64).contains(&vertex);
    inside.then_some((vertex, skew))
}

/// A point's lopsidedness ([`Centre::asymmetry`]): its neighbours' mean, and its own where too
/// few neighbours on one side give it no stripe shape.
#[derive(Debug, Clone, Copy)]
struct Lopsided {
    mean: f64,
    own: Option<f64>,
}

/// A neighbour of a point on its stripe, in the point's frame: arc t and offset d along its
/// normal (px), half-maximum width (px), asymmetry seen along the point's normal, contrast.
type Neighbour = (f64, f64, f64, f64, f64);

/// `points` sorted by azimuth around `centre` (atan2's order, from −π), then radius, through
/// keys that order as they do (no library calls); the index settles exact ties. A counting sort
/// on the azimuth key's leading bits (about one point per bucket) does most of the work; each
/// bucket is then sorted alone.
fn azimuth_sorted(points: Vec<StripePoint>, (cx, cy): (f64, f64)) -> Vec<StripePoint> {
    let keys: Vec<(f64, f64, u32)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let (dx, dy) = (p.u - cx, p.v - cy);
            (azimuth_order(dx, dy), dx * dx + dy * dy, i as u32)
        })
        .collect();
    // The key lies in (−2, 2]; the bucket index is monotonic in it.
    let buckets = points.len().next_power_of_two().max(16);
    let scale = buckets as f64 / 4.0;
    let bucket = |key: f64| (((key + 2.0) * scale) as usize).min(buckets - 1);
    let mut start = vec![0u32; buckets + 1];
    for k in &keys {
        start[bucket(k.0) + 1] += 1;
    }
    for b in 1..=buckets {
        start[b] += start[b - 1];
    }
    let mut sorted = vec![(0.0, 0.0, 0u32); keys.len()];
    let mut fill = start.clone();
    for &k in &keys {
        let slot = &mut fill[bucket(k.0)];
        sorted[*slot as usize] = k;
        *slot += 1;
    }
    for b in 0..buckets {
        let run = &mut sorted[start[b] as usize..start[b + 1] as usize];
        if run.len() > 1 {
            run.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
        }
    }
    sorted.iter().map(|k| points[k.2 as usize]).collect()
}

/// A key that orders directions (dx, dy) as `dy.atan2(dx)` does, from −π (exclusive) to π: the
/// "diamond angle", in (−2, 2], piecewise rational in dx and dy.
fn azimuth_order(dx: f64, dy: f64) -> f64 {
    let sum = dx.abs() + dy.abs();
    if sum == 0.0 {
        return 0.0;
    }
    let s = dy / sum;
    match (dx >= 0.0, dy >= 0.0) {
        (true, _) => s,
        (false, true) => 2.0 - s,
        (false, false) => -2.0 - s,
    }
}

/// Whether a profile peaks like a laser's line rather than lying flat across a lit surface
/// ([`MAX_FLATNESS`]); a saturated one always does. Only peaked wide profiles send the search to
/// coarser scales: binned, a lit face's tip is a narrow ridge there, which no coarse check tells
/// from a stripe.
fn peaks(c: &Centre) -> bool {
    c.point.quality & quality::SATURATED != 0 || c.flatness <= MAX_FLATNESS
}

/// Whether the seed's stripe clearly runs the other way (its normal more than 60° from the
/// seed's axis), from the [1 2 1]-smoothed second differences of the 3×3 pixels around it:
/// those seeds are the other axis's to measure, and this costs less than the Hessian that
/// would refuse them. Seeds lie at least 1 px inside the frame.
fn clearly_other_axis<P: Pixel>(frame: &Frame<'_, P>, x: usize, y: usize, axis: Axis) -> bool {
    let at = |x: usize, y: usize| frame.at(x, y);
    let (mut dxx, mut dyy) = (0.0f32, 0.0f32);
    for (k, w) in [(0usize, 1.0f32), (1, 2.0), (2, 1.0)] {
        let (row, col) = (y + k - 1, x + k - 1);
        dxx += w * (at(x - 1, row) - 2.0 * at(x, row) + at(x + 1, row));
        dyy += w * (at(col, y - 1) - 2.0 * at(col, y) + at(col, y + 1));
    }
    // tan² 60° = 3: the Hessian's eigen-direction test keeps 47°, so the margin is 13°.
    match axis {
        Axis::Row => dyy.abs() > 3.0 * dxx.abs(),
        Axis::Column => dxx.abs() > 3.0 * dyy.abs(),
    }
}

/// Whether the image is flat across the stripe at a found centre (u, v), as on a ridge's
/// centreline: the gradient along the normal `n` at most [`MAX_CENTRE_GRADIENT`] of the peak. A
/// profile grazing the edge of a bright blob (a glint, a lit patch) has a short segment too, but
/// there it is as steep as the edge. Along the stripe the gradient is left alone: speckle grains
/// make it steep there.
fn flat_across<P: Pixel>(frame: &Frame<'_, P>, u: f64, v: f64, n: (f64, f64), peak: f32) -> bool {
    let Some([l, r, up, down]) = frame.cross(u, v) else {
        return false;
    };
    let across = 0.5 * ((r - l) as f64 * n.0 + (down - up) as f64 * n.1);
    across.abs() <= (MAX_CENTRE_GRADIENT * peak) as f64
}

/// The segment of `q` around its largest sample within 2 px of the middle `mid`, whose samples
/// stay above `t`; `None` if there is none or it reaches an end of `q`.
fn segment_near(q: &[f32], mid: usize, t: f32) -> Option<Segment> {
    let reach = (2.0 / SAMPLE_STEP_PX) as usize;
    let (lo, hi) = (mid.saturating_sub(reach), (mid + reach).min(q.len() - 1));
    let peak = (lo..=hi).max_by(|&a, &b| q[a].total_cmp(&q[b]))?;
    super::segment_at(q, peak, t)
}

/// The median of the centres' pull variances (px², [`RidgeDetector::pull_variance`]); `None`
/// if no profile has one.
fn pull_variance_median<'a>(centres: impl Iterator<Item = &'a Centre>) -> Option<f64> {
    super::lower_median(centres.filter_map(|c| c.pull_variance).collect())
}

/// The `percent` quantile of the frame's unsaturated half-maximum widths (px); `None` if there
/// are none.
fn half_width_quantile(centres: &[Centre], percent: usize) -> Option<f64> {
    let mut w: Vec<f64> =
        centres.iter().filter(|c| c.point.quality & quality::SATURATED == 0).map(|c| c.half_width).collect();
    if w.is_empty() {
        return None;
    }
    let k = (w.len() - 1) * percent / 100;
    Some(*w.select_nth_unstable_by(k, f64::total_cmp).1)
}

/// Power sums over the neighbours `(t, d, …, contrast)` within ±`half_arc` of a point, from
/// which its stripe's shape and contrast are fitted by least squares: Σtᵏ (k ≤ 6), Σd·tᵏ
/// (k ≤ 3), Σcontrast·tᵏ (k ≤ 1), and how many lie before and after t = 0 (beyond ±0.5 px).
#[derive(Default)]
struct ShapeSums {
    t: [f64; 7],
    d: [f64; 4],
    /// Σd².
    d2: f64,
    contrast: [f64; 2],
    before: usize,
    after: usize,
}

impl ShapeSums {
    /// The sums over the neighbours within ±`half_arc` px of arc.
    fn new(neighbours: &[Neighbour], half_arc: f64) -> ShapeSums {
        let mut sums = ShapeSums::default();
        neighbours.iter().filter(|n| n.0.abs() <= half_arc).for_each(|n| sums.add(n));
        sums
    }

    fn add(&mut self, &(t, d, _, _, contrast): &Neighbour) {
        self.d2 += d * d;
        let mut power = 1.0;
        for k in 0..7 {
            self.t[k] += power;
            if k < 4 {
                self.d[k] += d * power;
            }
            if k < 2 {
                self.contrast[k] += contrast * power;
            }
            power *= t;
        }
        self.before += usize::from(t < -0.5);
        self.after += usize::from(t > 0.5);
    }

    /// The parabola d = a + b·t + c·t²; `None` unless at least five points with two on each
    /// side of t = 0.
    fn parabola(&self, factors: &MomentFactors) -> Option<[f64; 3]> {
        if self.t[0] < 5.0 || self.before < 2 || self.after < 2 {
            return None;
        }
        let x = factors.solve::<3>(&self.d)?;
        Some([x[0], x[1], x[2]])
    }

    /// The RMS residual (px) of the points about their least-squares `parabola`, over its
    /// degrees of freedom; `None` with fewer than six points.
    fn scatter(&self, [a, b, c]: [f64; 3]) -> Option<f64> {
        let count = self.t[0];
        if count < 6.0 {
            return None;
        }
        let squares = self.d2 - a * self.d[0] - b * self.d[1] - c * self.d[2];
        Some((squares.max(0.0) / (count - 3.0)).sqrt())
    }

    /// The stripe's cubic shape and contrast slope ([`LocalStripe`]); `None` unless at least
    /// six points with two on each side of t = 0.
    fn local_stripe(&self, factors: &MomentFactors) -> Option<LocalStripe> {
        if self.t[0] < 6.0 || self.before < 2 || self.after < 2 {
            return None;
        }
        let shape = factors.solve::<4>(&self.d)?;
        let det = self.t[0] * self.t[2] - self.t[1] * self.t[1];
        if det <= 1e-9 {
            return None;
        }
        let level = (self.contrast[0] * self.t[2] - self.contrast[1] * self.t[1]) / det;
        let slope = (self.t[0] * self.contrast[1] - self.t[1] * self.contrast[0]) / det;
        let alpha = if level > 0.0 { slope / level } else { 0.0 };
        Some(LocalStripe { b: shape[1], c: shape[2], e: shape[3], alpha })
    }

    /// The LDLᵀ factors of the normal equations' matrix Σ t^{i+j} (i, j < 4), shared by the
    /// parabola (its leading 3×3 block factors into the leading factors) and the cubic.
    fn factors(&self) -> MomentFactors {
        MomentFactors::new(|i, j| self.t[i + j])
    }
}

/// LDLᵀ factors of a symmetric 4×4 matrix, as far as its leading blocks are positive definite:
/// `size` of them (a moment matrix of points at fewer than four distinct t has fewer).
struct MomentFactors {
    l: [[f64; 4]; 4],
    d: [f64; 4],
    size: usize,
}

impl MomentFactors {
    /// A pivot below this fraction of its diagonal entry ends the factorisation (the points'
    /// t are too few or too close for that degree).
    const MIN_PIVOT: f64 = 1e-10;

    fn new(m: impl Fn(usize, usize) -> f64) -> MomentFactors {
        let mut f = MomentFactors { l: [[0.0; 4]; 4], d: [0.0; 4], size: 0 };
        for j in 0..4 {
            let mut dj = m(j, j);
            for k in 0..j {
                dj -= f.l[j][k] * f.l[j][k] * f.d[k];
            }
            if !(dj > Self::MIN_PIVOT * m(j, j)) {
                break;
            }
            f.d[j] = dj;
            f.l[j][j] = 1.0;
            for i in j + 1..4 {
                let mut a = m(i, j);
                for k in 0..j {
                    a -= f.l[i][k] * f.l[j][k] * f.d[k];
                }
                f.l[i][j] = a / dj;
            }
            f.size = j + 1;
        }
        f
    }

    /// The solution of the leading N×N block's equations for right-hand side `b[..N]`; `None`
    /// if that block is not positive definite.
    fn solve<const N: usize>(&self, b: &[f64; 4]) -> Option<[f64; N]> {
        if self.size < N {
            return None;
        }
        let mut x = [0.0; N];
        for i in 0..N {
            x[i] = b[i] - (0..i).map(|k| self.l[i][k] * x[k]).sum::<f64>();
        }
        for i in 0..N {
            x[i] /= self.d[i];
        }
        for i in (0..N).rev() {
            x[i] -= (i + 1..N).map(|k| self.l[k][i] * x[k]).sum::<f64>();
        }
        Some(x)
    }
}

/// The stripe around a point, in the point's frame: its offset d(t) = a + b·t + c·t² + e·t³
/// along the point's normal at arc t (px), and the relative change of its contrast along it,
/// α = (dI/dt) / I (1/px).
#[derive(Clone, Copy)]
struct LocalStripe {
    b: f64,
    c: f64,
    e: f64,
    alpha: f64,
}

impl LocalStripe {
    /// The blur's pull on the centre (px along the normal) for a Gaussian blur of variance
    /// `sigma2` (px²). The profile across a line blurred by a Gaussian has its centroid at the
    /// mean of the line's offset d(t) weighted by its contrast times the Gaussian along it; a
    /// contrast changing as e^{αt} shifts that Gaussian by μ = α·σ², so the mean is
    /// b·μ + c·(σ² + μ²) + e·(3μσ² + μ³) with d(0) = a taken out: σ²·c on an evenly lit arc.
    fn pull(&self, sigma2: f64) -> f64 {
        let mu = (self.alpha * sigma2).clamp(-MAX_CONTRAST_SHIFT_PX, MAX_CONTRAST_SHIFT_PX);
        self.b * mu + self.c * (sigma2 + mu * mu) + self.e * (3.0 * mu * sigma2 + mu * mu * mu)
    }
}

/// The largest shift (px) of the blur's weight along a stripe that its contrast gradient is
/// taken to make: beyond it the exponential model of the contrast no longer holds (an end).
const MAX_CONTRAST_SHIFT_PX: f64 = 1.0;

/// Sums for a least-squares line y = a + b·t through points (t, y), and how many lie before and
/// after t = 0 (beyond ±0.5 px).
#[derive(Default)]
struct LineSums {
    s0: f64,
    s1: f64,
    s2: f64,
    r0: f64,
    r1: f64,
    before: usize,
    after: usize,
}

impl LineSums {
    fn add(&mut self, t: f64, y: f64) {
        (self.s0, self.s1, self.s2, self.r0, self.r1) =
            (self.s0 + 1.0, self.s1 + t, self.s2 + t * t, self.r0 + y, self.r1 + t * y);
        self.before += usize::from(t < -0.5);
        self.after += usize::from(t > 0.5);
    }

    /// `(a, b)`, or `None` unless two points lie on each side of t = 0.
    fn fit(&self) -> Option<(f64, f64)> {
        let LineSums { s0, s1, s2, r0, r1, before, after } = *self;
        let det = s0 * s2 - s1 * s1;
        (before >= 2 && after >= 2 && det > 1e-9).then(|| ((r0 * s2 - r1 * s1) / det, (s0 * r1 - s1 * r0) / det))
    }

    /// The slope `b` of the least-squares line through three points or more; `None` with fewer
    /// or all at one t.
    fn slope(&self) -> Option<f64> {
        let LineSums { s0, s1, s2, r0, r1, .. } = *self;
        let det = s0 * s2 - s1 * s1;
        (s0 >= 3.0 && det > 1e-9).then(|| (s0 * r1 - s1 * r0) / det)
    }

    /// The standard error of the fit's `a` per unit of the points' independent noise.
    fn intercept_spread(&self) -> f64 {
        (self.s2 / (self.s0 * self.s2 - self.s1 * self.s1)).sqrt()
    }
}

/// The along-stripe fit's offset at t = 0 (px) over ±`arc` px, and its standard error per unit
/// of the points' noise; `None` where the fit has too few points. Over the shortest arc (±3 px
/// or less): the line through the neighbours' offsets once the bend c (d = c·t²) of a parabola
/// over ±max([`SHAPE_HALF_ARC_PX`], 2·`arc`) is taken out, a bend better determined than over
/// the arc itself; where a gap leaves fewer than two points on one side within the arc (a
/// profile refused on a dark speckle grain), the line reaches on towards the bend's arc until
/// it holds two. Over longer arcs: the parabola through the arc itself, and only where the
/// stripe goes on to both of the arc's ends (to within [`ARC_END_PX`]), gaps within it
/// allowed: there a bend from twice the arc, or a window the stripe's end cuts short, moves
/// the offset wherever the stripe's curvature changes along it (an ellipse's flanks, near a
/// silhouette).
fn arc_offset(neighbours: &[Neighbour], arc: f64) -> Option<(f64, f64)> {
    if arc > SHAPE_HALF_ARC_PX {
        let (first, last) = neighbours.iter().fold((0.0f64, 0.0f64), |(lo, hi), n| (lo.min(n.0), hi.max(n.0)));
        if last < arc - ARC_END_PX || -first < arc - ARC_END_PX {
            return None;
        }
        let sums = ShapeSums::new(neighbours, arc);
        let factors = sums.factors();
        let [offset, _, _] = sums.parabola(&factors)?;
        // The offset's variance per unit noise: the inverse moment matrix's first diagonal entry.
        let [spread2, _, _] = factors.solve::<3>(&[1.0, 0.0, 0.0, 0.0])?;
        return Some((offset, spread2.max(0.0).sqrt()));
    }
    let bend_arc = SHAPE_HALF_ARC_PX.max(2.0 * arc);
    let sums = ShapeSums::new(neighbours, bend_arc);
    let [_, _, bend] = sums.parabola(&sums.factors())?;
    let mut reach = arc;
    loop {
        let line = bent_line(neighbours, bend, reach);
        if let Some((offset, _)) = line.fit() {
            return Some((offset, line.intercept_spread()));
        }
        if reach >= bend_arc {
            return None;
        }
        reach = (reach * ARC_GROWTH).min(bend_arc);
    }
}

fn bent_line(neighbours: &[Neighbour], bend: f64, arc: f64) -> LineSums {
    let mut line = LineSums::default();
    neighbours.iter().filter(|n| n.0.abs() <= arc).for_each(|n| line.add(n.0, n.1 - bend * n.0 * n.0));
    line
}

/// How far short of a longer arc's ends (px) the stripe's farthest points may stop for that
/// arc to be fitted ([`arc_offset`]): about one point's spacing along the stripe, with a gap.
const ARC_END_PX: f64 = 1.5;
/// How far the along-stripe fit's arcs grow from one to the next ([`AlongFits::offsets`]).
const ARC_GROWTH: f64 = 1.5;
/// Standard errors by which a longer arc's offset may differ from a shorter one's
/// ([`AlongFits::offsets`]).
const ARC_AGREEMENT: f64 = 3.0;

/// The neighbours of each of a frame's points that the along-stripe fit uses, kept until the
/// fits over every arc are known.
#[derive(Default)]
struct AlongFits {
    neighbours: Vec<Neighbour>,
    /// The index of each of `neighbours` among the points linked.
    indices: Vec<usize>,
    ends: Vec<usize>,
    /// The point whose neighbours end at each of `ends`.
    owners: Vec<usize>,
}

impl AlongFits {
    fn push(&mut self, owner: usize, neighbours: &[Neighbour], indices: &[usize]) {
        self.neighbours.extend_from_slice(neighbours);
        self.indices.extend_from_slice(indices);
        self.ends.push(self.neighbours.len());
        self.owners.push(owner);
    }

    /// The fits of the points of `kept` (pushed in the same order, some of them since dropped),
    /// each with only the neighbours that are in `kept` too; `centres` centres in all.
    fn of_kept(self, kept: &[OnStripe], centres: usize) -> AlongFits {
        let mut is_kept = vec![false; centres];
        for k in kept {
            is_kept[k.index] = true;
        }
        let mut out = AlongFits::default();
        let mut start = 0;
        for (&end, &owner) in self.ends.iter().zip(&self.owners) {
            if is_kept[owner] {
                for k in (start..end).filter(|&k| is_kept[self.indices[k]]) {
                    out.neighbours.push(self.neighbours[k]);
                    out.indices.push(self.indices[k]);
                }
                out.ends.push(out.neighbours.len());
                out.owners.push(owner);
            }
            start = end;
        }
        out
    }

    /// The neighbours of the `k`-th point pushed.
    fn of(&self, k: usize) -> &[Neighbour] {
        let start = if k == 0 { 0 } else { self.ends[k - 1] };
        &self.neighbours[start..self.ends[k]]
    }

    /// Each point's along-stripe offset (px) at t = 0, over the longest arc up to ±`along` px
    /// that its stripe's shape allows; 0 where no arc has enough points. The arcs grow from
    /// ±[`SHAPE_HALF_ARC_PX`] (or ±`along` if shorter) by [`ARC_GROWTH`] ([`arc_offset`] on
    /// each; one too sparse to fit, a gap near the point, is passed over). A longer arc is taken
    /// while its offset lies within [`ARC_AGREEMENT`] standard errors of every shorter arc's
    /// (Lepski's rule) and the stripe reaches both of its ends: where the stripe bends faster
    /// than a parabola follows over the arc (a tight curve, a step), the longer fit moves by
    /// more than its noise allows.
    fn offsets(&self, along: f64) -> Vec<(f64, f64)> {
        let mut arcs = vec![along.min(SHAPE_HALF_ARC_PX)];
        while let Some(&last) = arcs.last().filter(|&&a| a < along) {
            arcs.push((last * ARC_GROWTH).min(along));
        }
        // A single arc is taken as it is: no noise needed to judge it.
        let noise = if arcs.len() > 1 { self.noise() } else { 0.0 };
        (0..self.ends.len())
            .map(|k| {
                let mut shorter: Vec<(f64, f64)> = Vec::with_capacity(arcs.len());
                let mut taken = (0.0, arcs[0]);
                for &arc in &arcs {
                    let Some((offset, spread)) = arc_offset(self.of(k), arc) else { continue };
                    if shorter.iter().any(|&(o, se)| (offset - o).abs() > ARC_AGREEMENT * se) {
                        break;
                    }
                    shorter.push((offset, noise * spread));
                    taken = (offset, arc);
                }
                taken
            })
            .collect()
    }

    /// The noise of one point's offset across its stripe (px), as it counts in a fit along the
    /// stripe: the median over the frame of the points' scatter about their stripes' parabolas
    /// over ±[`SHAPE_HALF_ARC_PX`], times [`CORRELATED_NOISE`].
    fn noise(&self) -> f64 {
        frame_noise((0..self.ends.len()).filter_map(|k| short_arc_scatter(self.of(k))).collect())
    }
}

/// The noise of one point's offset across its stripe (px) as it counts in a fit along the
/// stripe, from the points' `scatter` about their parabolas over ±[`SHAPE_HALF_ARC_PX`]: the
/// median times [`CORRELATED_NOISE`]; 0 without any.
fn frame_noise(mut scatter: Vec<f64>) -> f64 {
    if scatter.is_empty() {
        return 0.0;
    }
    let middle = scatter.len() / 2;
    CORRELATED_NOISE * *scatter.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// Neighbouring points' errors are correlated (the sampling kernel and the optics share
/// pixels between them, speckle grains span several), so a fit's offset varies by more than
/// independent noise would give, and the scatter about a short parabola, which follows part of
/// that correlated noise, is less than the noise.
const CORRELATED_NOISE: f64 = 2.0;

/// The RMS residual (px) of a point's neighbours within ±[`SHAPE_HALF_ARC_PX`] about their
/// parabola, over its degrees of freedom; `None` with fewer than six of them.
fn short_arc_scatter(neighbours: &[Neighbour]) -> Option<f64> {
    let sums = ShapeSums::new(neighbours, SHAPE_HALF_ARC_PX);
    sums.scatter(sums.parabola(&sums.factors())?)
}

#[cfg(test)]
mod pull_tests {
    use super::*;

    #[test]
    fn a_known_profile_leads_where_the_stripes_own_top_shape_is_too_noisy() {
        let profile = omni_model::LaserProfile::tailed(0.17, 4.0);
        let (blur, half_width) = (0.9, 4.6);
        let model = super::super::laser::TopOffsets::new(&profile, blur);
        let shape = [-0.005, 0.12];
        let lead = |error: [f64; 2]| lean_to_sheet_peak(0.1, half_width, (shape, error), blur, Some(&model));
        // A shape measured to a few thousandths leads by itself, whatever the profile says.
        let (lean, tail, by_profile) = lead([0.0006, 0.006]);
        assert!(!by_profile && tail == 0.0);
        assert!((lean - lean_to_peak(0.1, half_width, shape, blur)).abs() < 1e-15);
        // The same shape from speckled profiles (errors as a 0.25 contrast leaves them) moves
        // the point by more than the profile misses: the profile leads, from the top's centroid.
        let (lean, tail, by_profile) = lead([0.0025, 0.045]);
        assert!(by_profile && lean == 0.1);
        assert!((tail - model.centroid_at(half_width)).abs() < 1e-15);
        // No shape of its own: the profile leads; without a profile the shape does, noisy or not.
        assert!(lean_to_sheet_peak(0.1, half_width, ([0.0; 2], [f64::INFINITY; 2]), blur, Some(&model)).2);
        assert!(!lean_to_sheet_peak(0.1, half_width, (shape, [0.0025, 0.045]), blur, None).2);
    }

    /// Neighbours 1 px apart along a straight stripe 0.1 px off the point itself (at t = 0), with
    /// a deterministic scatter of 0.04 px, from `-reach` to `reach` px, none within `gap` (px of
    /// arc).
    fn straight(reach: i32, gap: std::ops::Range<f64>) -> Vec<Neighbour> {
        (-reach..=reach)
            .map(f64::from)
            .filter(|t| *t == 0.0 || !gap.contains(t))
            .map(|t| (t, if t == 0.0 { 0.0 } else { 0.1 + 0.04 * (1.7 * t + 0.3).sin() }, 2.0, 0.0, 100.0))
            .collect()
    }

    /// A gap in a stripe (a profile refused on a dark speckle grain) neither leaves a point
    /// without its fit nor stops the fit's arcs from growing past it; the stripe's end does.
    /// The point itself is one point of its fit, so the fit lands short of its neighbours' line.
    #[test]
    fn the_along_stripe_fit_reaches_across_a_gap_but_not_past_the_stripes_end() {
        let (offset, _) = arc_offset(&straight(8, 1.5..3.5), 3.0).expect("a line across the gap");
        assert!((0.05..0.13).contains(&offset), "{offset}");
        let (offset, _) = arc_offset(&straight(20, 9.5..12.5), 10.0).expect("a parabola across the gap");
        assert!((0.05..0.13).contains(&offset), "{offset}");
        assert!(arc_offset(&straight(7, 0.0..0.0), 10.0).is_none(), "the stripe ends 7 px away");
        // The frame's noise comes from its points' short arcs: two more points without a gap.
        let mut fits = AlongFits::default();
        for (owner, gap) in [(0, 1.5..4.0), (1, 0.0..0.0), (2, 0.0..0.0)] {
            fits.push(owner, &straight(20, gap), &[]);
        }
        let (offset, arc) = fits.offsets(16.0)[0];
        assert!((0.05..0.13).contains(&offset) && arc == 16.0, "{offset} over ±{arc}");
    }

    /// The closed form of the pull is the mean of d(t) under the contrast e^{αt} times the
    /// Gaussian along the stripe, integrated numerically, for shapes and gradients of either sign;
    /// with an even contrast it is σ²·c. The fit recovers a cubic and the contrast slope exactly.
    #[test]
    fn the_pull_is_the_weighted_mean_offset_and_the_fit_recovers_the_stripe() {
        let mut rng = omni_geom::rng::SplitMix64::new(5);
        for _ in 0..200 {
            let mut draw = |scale: f64| scale * (2.0 * rng.uniform() - 1.0);
            let (b, c, e, alpha, sigma2) = (draw(0.2), draw(0.1), draw(0.01), draw(0.3), 0.5 + draw(0.4).abs() * 2.0);
            let local = LocalStripe { b, c, e, alpha };
            let (mut weight, mut moment) = (0.0, 0.0);
            for k in -4000..=4000 {
                let t = k as f64 * 0.005;
                let w = (alpha * t - t * t / (2.0 * sigma2)).exp();
                weight += w;
                moment += w * (b * t + c * t * t + e * t * t * t);
            }
            let exact = moment / weight;
            assert!(
                (local.pull(sigma2) - exact).abs() < 1e-9,
                "{b} {c} {e} {alpha}: {} vs {exact}",
                local.pull(sigma2)
            );
            let even = LocalStripe { alpha: 0.0, ..local };
            assert!((even.pull(sigma2) - c * sigma2).abs() < 1e-12);
        }
        let neighbours: Vec<Neighbour> = (-6..=6)
            .map(|k| {
                let t = 0.5 * k as f64 + 0.1;
                (t, 0.02 + 0.1 * t - 0.05 * t * t + 0.004 * t * t * t, 1.0, 0.0, 80.0 * (1.0 + 0.1 * t))
            })
            .collect();
        let sums = ShapeSums::new(&neighbours, 3.0);
        let local = sums.local_stripe(&sums.factors()).unwrap();
        let (b, c, e) = (local.b, local.c, local.e);
        assert!((b - 0.1).abs() < 1e-9 && (c + 0.05).abs() < 1e-9 && (e - 0.004).abs() < 1e-9, "{b} {c} {e}");
        assert!((local.alpha - 0.1).abs() < 1e-9, "alpha {}", local.alpha);
    }

    /// A stripe's median skew ([`Centre::top_shape`]) of noisy lopsided tops stays at the
    /// noise-free top's skew: per profile the skew scatters widely (a third derivative), and a
    /// limit on each top's skew inside that scatter would cut more of the noise on the far side
    /// of the laser's skew than on the near one, pulling the median towards 0 (a limit of 0.3 on
    /// each top does: checked below), so the limit is on the median ([`MAX_TOP_SKEW`]).
    #[test]
    fn the_median_skew_of_noisy_lopsided_tops_keeps_the_lasers_skew() {
        // A Gaussian core with a wider, offset component on one side: a lopsided top, σ ≈ 3
        // samples (1.5 px), peak 150, noise σ 4 (the tops' skews scatter by 0.35 MAD).
        let light = |x: f64| 150.0 * (0.8 * (-x * x / 18.0).exp() + 0.2 * (-(x - 3.0).powi(2) / 72.0).exp());
        let skew_of = |q: &[f32]| -> Option<f64> {
            let peak = (0..q.len()).max_by(|&a, &b| q[a].total_cmp(&q[b]))?;
            let seg = super::super::segment_at(q, peak, 10.0)?;
            let (ha, hb) = estimators::crossings(q, &seg, 0.5 * q[seg.peak])?;
            let half_width = (hb - ha) * SAMPLE_STEP_PX;
            let (_, top) = estimators::top_centroid(q, &seg, TOP_LEVEL * q[seg.peak])?;
            let (_, skew) = stripe_top(q, &top, half_width)?;
            Some(skew * half_width / FWHM_PER_SIGMA / SAMPLE_STEP_PX)
        };
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let mut rng = omni_geom::rng::SplitMix64::new(7);
        let (mut exact, mut noisy) = (Vec::new(), Vec::new());
        for _ in 0..2000 {
            let c = 24.0 + rng.uniform();
            let clean: Vec<f32> = (0..48).map(|i| light(i as f64 - c) as f32).collect();
            exact.extend(skew_of(&clean));
            noisy.extend(skew_of(&clean.iter().map(|&v| v + (4.0 * rng.normal()) as f32).collect::<Vec<_>>()));
        }
        let within_old_limit = median(noisy.iter().copied().filter(|s| s.abs() <= 0.3).collect());
        let (exact, noisy) = (median(exact), median(noisy));
        assert!((noisy - exact).abs() <= 0.01, "median skew {noisy:.4} against {exact:.4} without noise");
        assert!((within_old_limit - exact).abs() >= 0.05, "within 0.3: {within_old_limit:.4} against {exact:.4}");
    }

    /// The shared LDLᵀ factors solve the parabola's and the cubic's normal equations as a
    /// general LU solve does, on random neighbourhoods; points at three distinct t give a
    /// parabola and no cubic.
    #[test]
    fn the_moment_factors_solve_the_normal_equations() {
        let mut rng = omni_geom::rng::SplitMix64::new(11);
        for _ in 0..500 {
            let count = 5 + (rng.uniform() * 10.0) as usize;
            let neighbours: Vec<Neighbour> =
                (0..count).map(|_| (6.0 * rng.uniform() - 3.0, 0.4 * rng.uniform() - 0.2, 1.0, 0.0, 50.0)).collect();
            let sums = ShapeSums::new(&neighbours, 3.0);
            let factors = sums.factors();
            for n in [3usize, 4] {
                let m = nalgebra::DMatrix::from_fn(n, n, |i, j| sums.t[i + j]);
                let exact = m.lu().solve(&nalgebra::DVector::from_column_slice(&sums.d[..n])).unwrap();
                let ours: Vec<f64> = if n == 3 {
                    factors.solve::<3>(&sums.d).unwrap().to_vec()
                } else {
                    factors.solve::<4>(&sums.d).unwrap().to_vec()
                };
                for (a, b) in ours.iter().zip(exact.iter()) {
                    assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "{n}: {ours:?} vs {exact}");
                }
            }
        }
        let three: Vec<Neighbour> =
            [-1.0, -1.0, 0.0, 1.0, 1.0].iter().map(|&t| (t, 0.1 * t * t, 1.0, 0.0, 50.0)).collect();
        let sums = ShapeSums::new(&three, 3.0);
        let factors = sums.factors();
        assert!(factors.solve::<4>(&sums.d).is_none());
        let p = factors.solve::<3>(&sums.d).unwrap();
        assert!(p[0].abs() < 1e-12 && p[1].abs() < 1e-12 && (p[2] - 0.1).abs() < 1e-12, "{p:?}");
    }
}

/// Centres bucketed in square cells (a counting sort into a dense table of cells over the
/// centres' bounding box: a frame with one short stripe needs a small table), for neighbour
/// queries within `reach` px.
struct Grid {
    cell: f64,
    /// The table's first cell row and column (cells from the frame's origin).
    first: (usize, usize),
    columns: usize,
    rows: usize,
    /// `order[start[k]..start[k + 1]]`: the centres in cell k (row-major), in index order.
    start: Vec<u32>,
    order: Vec<u32>,
    /// Position and normal (u, v, nx, ny) of `order`'s centres, beside each other for the visits.
    placed: Vec<[f64; 4]>,
}

impl Grid {
    fn new(centres: &[Centre], reach: f64) -> Grid {
        Grid::from_placed(centres.iter().map(|c| [c.point.u, c.point.v, c.normal.0, c.normal.1]), reach)
    }

    /// The grid of points given as (u, v, nx, ny).
    fn from_placed(points: impl Iterator<Item = [f64; 4]>, reach: f64) -> Grid {
        let points: Vec<[f64; 4]> = points.collect();
        let cell = reach.max(1.0);
        let absolute = |p: &[f64; 4]| ((p[1] / cell).max(0.0) as usize, (p[0] / cell).max(0.0) as usize);
        let (mut first, mut end) = ((usize::MAX, usize::MAX), (0, 0));
        for p in &points {
            let (r, q) = absolute(p);
            first = (first.0.min(r), first.1.min(q));
            end = (end.0.max(r + 1), end.1.max(q + 1));
        }
        let first = if points.is_empty() { (0, 0) } else { first };
        let (rows, columns) = (end.0.saturating_sub(first.0), end.1.saturating_sub(first.1));
        let key = |p: &[f64; 4]| {
            let (r, q) = absolute(p);
            (r - first.0, q - first.1)
        };
        let mut start = vec![0u32; rows * columns + 1];
        for p in &points {
            let (r, q) = key(p);
            start[r * columns + q + 1] += 1;
        }
        for k in 1..start.len() {
            start[k] += start[k - 1];
        }
        let mut fill = start.clone();
        let mut order = vec![0u32; points.len()];
        for (i, p) in points.iter().enumerate() {
            let (r, q) = key(p);
            let slot = &mut fill[r * columns + q];
            order[*slot as usize] = i as u32;
            *slot += 1;
        }
        let placed = order.iter().map(|&i| points[i as usize]).collect();
        Grid { cell, first, columns, rows, start, order, placed }
    }

    /// Calls `f` with the index, position and normal of every centre in the cells within one
    /// cell of (x, y), in index order per cell.
    fn visit(&self, x: f64, y: f64, mut f: impl FnMut(usize, &[f64; 4])) {
        // The table's cells within one of (x, y)'s: [lo, hi) in each axis.
        let span = |v: f64, first: usize, count: usize| {
            let at = (v / self.cell).max(0.0) as usize;
            (at.saturating_sub(first + 1), (at + 2).saturating_sub(first).min(count))
        };
        let (r0, r1) = span(y, self.first.0, self.rows);
        let (q0, q1) = span(x, self.first.1, self.columns);
        for r in r0..r1 {
            if q0 >= q1 {
                continue;
            }
            let (a, b) = (self.start[r * self.columns + q0] as usize, self.start[r * self.columns + q1] as usize);
            self.order[a..b].iter().zip(&self.placed[a..b]).for_each(|(&i, p)| f(i as usize, p));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::render;
    use super::super::*;
    use omni_geom::Vector2;

    /// A thin ring of radius `radius` (px) blurred by a Gaussian of `sigma` px: the exact image,
    /// exp(−(r − R)²/2σ²) · e^{−z} I₀(z) with z = rR/σ² (asymptotic series, z ≥ 10 here).
    fn blurred_ring(r: f64, radius: f64, sigma: f64) -> f64 {
        let z = r * radius / (sigma * sigma);
        let i0e = (1.0 + 1.0 / (8.0 * z) + 9.0 / (128.0 * z * z)) / (std::f64::consts::TAU * z).sqrt();
        (-(r - radius).powi(2) / (2.0 * sigma * sigma)).exp()
            * i0e
            * (std::f64::consts::TAU * radius / sigma.powi(2)).sqrt()
    }

    /// A curved stripe is not pulled towards its centre of curvature, whatever the lens's blur,
    /// which the detector is not told: the pull σ²κ/2 is estimated from the frame's own profiles.
    #[test]
    fn curved_stripes_keep_their_centre_for_any_blur() {
        let (w, h) = (160u32, 160u32);
        let (cx, cy) = (80.3, 79.6);
        for sigma in [0.4, 0.7, 1.0, 1.5] {
            for radius in [15.0, 30.0] {
                let img =
                    render(w, h, 16, 0.0, 1, |x, y| 40000.0 * blurred_ring((x - cx).hypot(y - cy), radius, sigma));
                let circle = MirrorCircle { centre: Vector2::new(cx, cy), inner_radius: 2.0, outer_radius: 75.0 };
                let det = RidgeDetector::new(w, h, circle, RidgeParams::default());
                let points = det.detect(&img);
                let errors: Vec<f64> = points.iter().map(|p| (p.u - cx).hypot(p.v - cy) - radius).collect();
                let n = errors.len() as f64;
                let bias = errors.iter().sum::<f64>() / n;
                let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
                eprintln!(
                    "blur σ {sigma} px, R {radius} px: {} points, bias {bias:+.4} px, rms {rms:.4} px",
                    errors.len()
                );
                assert!(n > 0.6 * std::f64::consts::TAU * radius, "σ {sigma} R {radius}: {n} points");
                assert!(bias.abs() <= 0.01, "σ {sigma} R {radius}: bias {bias:+.4} px");
            }
        }
    }

    /// The blur is measured on the stripe's own profiles, not on everything the frame offers:
    /// beside a small ring, five long lit bands 2.5× wider than the laser's line (refused as
    /// lit areas) give most of the profiles, and the ring is not over-corrected.
    #[test]
    fn the_blur_is_measured_on_the_stripe_not_on_lit_areas_beside_it() {
        let (w, h) = (160u32, 160u32);
        let (cx, cy) = (80.3, 79.6);
        let (radius, sigma) = (15.0, 0.7);
        let img = render(w, h, 16, 0.0, 1, |x, y| {
            let ring = 40000.0 * blurred_ring((x - cx).hypot(y - cy), radius, sigma);
            let bands: f64 = [20.0, 40.0, 120.0, 140.0]
                .iter()
                .map(|&b| 12000.0 * (-(x - b).powi(2) / (2.0 * 1.8 * 1.8)).exp())
                .sum::<f64>()
                + 12000.0 * (-(y - 140.0).powi(2) / (2.0 * 1.8 * 1.8)).exp();
            ring + bands
        });
        let circle = MirrorCircle { centre: Vector2::new(cx, cy), inner_radius: 2.0, outer_radius: 75.0 };
        let points = RidgeDetector::new(w, h, circle, RidgeParams::default()).detect(&img);
        let errors: Vec<f64> =
            points.iter().map(|p| (p.u - cx).hypot(p.v - cy) - radius).filter(|e| e.abs() < 2.0).collect();
        let n = errors.len() as f64;
        let bias = errors.iter().sum::<f64>() / n;
        eprintln!(
            "ring R {radius} px beside lit bands: {} of {} points, bias {bias:+.4} px",
            errors.len(),
            points.len()
        );
        assert!(n > 0.6 * std::f64::consts::TAU * radius, "{n} ring points");
        assert!(bias.abs() <= 0.01, "bias {bias:+.4} px");
    }
}

#[cfg(test)]
mod defocus_tests {
    use super::super::tests::render;
    use super::super::*;
    use omni_geom::Vector2;

    /// A thin ring of radius `radius` seen through a defocused lens (a uniform blur disc of
    /// radius `rho`), at distance `r` from its centre: the ring's arc inside the disc over the
    /// disc's area.
    fn defocused_ring(r: f64, radius: f64, rho: f64) -> f64 {
        if r <= 0.0 {
            return 0.0;
        }
        let cos = ((radius * radius + r * r - rho * rho) / (2.0 * radius * r)).clamp(-1.0, 1.0);
        2.0 * radius * cos.acos() / (std::f64::consts::PI * rho * rho)
    }

    /// The pull of a defocused lens (a disc PSF, far from Gaussian) on a curved stripe is removed
    /// too: the detector takes it from the profile's own second moment, not from a Gaussian
    /// fitted to its half-maximum width.
    #[test]
    fn curved_stripes_keep_their_centre_under_defocus() {
        let (w, h) = (160u32, 160u32);
        let (cx, cy) = (80.3, 79.6);
        for diameter in [2.0, 4.0, 6.0] {
            for radius in [15.0, 30.0] {
                let img = render(w, h, 16, 0.0, 1, |x, y| {
                    30000.0 * defocused_ring((x - cx).hypot(y - cy), radius, 0.5 * diameter)
                });
                let circle = MirrorCircle { centre: Vector2::new(cx, cy), inner_radius: 2.0, outer_radius: 75.0 };
                let det = RidgeDetector::new(w, h, circle, RidgeParams::default());
                let errors: Vec<f64> = det.detect(&img).iter().map(|p| (p.u - cx).hypot(p.v - cy) - radius).collect();
                let n = errors.len() as f64;
                let bias = errors.iter().sum::<f64>() / n;
                eprintln!("defocus disc {diameter} px, R {radius} px: {n} points, bias {bias:+.4} px");
                assert!(n > 0.6 * std::f64::consts::TAU * radius, "disc {diameter} R {radius}: {n} points");
                assert!(bias.abs() <= 0.01, "disc {diameter} R {radius}: bias {bias:+.4} px");
            }
        }
    }
}

#[cfg(test)]
mod direction_tests {
    use super::super::tests::render;
    use super::super::*;
    use omni_geom::Vector2;

    const W: u32 = 240;
    const H: u32 = 232;
    const CX: f64 = 121.3;
    const CY: f64 = 114.6;

    fn detector(params: RidgeParams) -> RidgeDetector {
        let circle = MirrorCircle { centre: Vector2::new(CX, CY), inner_radius: 20.0, outer_radius: 110.0 };
        RidgeDetector::new(W, H, circle, params)
    }

    /// Straight stripes at every angle to the rays from the mirror centre, radial ones included,
    /// are measured along their whole length inside the annulus, about once per px.
    #[test]
    fn stripes_in_every_direction_are_measured() {
        let det = detector(RidgeParams::default());
        for (i, d) in [0.0, 6.0, 25.0, 60.0].into_iter().enumerate() {
            for k in 0..12 {
                let theta = (15.0 * k as f64 + 3.7).to_radians();
                let (nx, ny) = (theta.cos(), theta.sin());
                // The line n·p = n·centre + d: distance d from the mirror centre (d = 0: radial).
                let c = CX * nx + CY * ny + d;
                let img = render(W, H, 8, 2.0, (i * 12 + k) as u64, |x, y| {
                    180.0 * (-(x * nx + y * ny - c).powi(2) / (2.0 * 1.2 * 1.2)).exp()
                });
                let points = det.detect(&img);
                let errors: Vec<f64> = points.iter().map(|p| p.u * nx + p.v * ny - c).collect();
                // The chord inside the annulus (radii 20–110), on both sides if it passes the hole.
                let half = |r: f64| (r * r - d * d).max(0.0).sqrt();
                let chord = 2.0 * (half(110.0) - half(20.0)) - 4.0 * super::END_PX;
                let n = errors.len() as f64;
                let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n.max(1.0)).sqrt();
                assert!(n >= 0.68 * chord, "d {d} θ {:.1}°: {n} points on a {chord:.0} px chord", theta.to_degrees());
                assert!(rms <= 0.03, "d {d} θ {:.1}°: rms {rms:.4} px", theta.to_degrees());
            }
        }
    }

    /// A ring stripe on a lit surface (`lit` DN) whose silhouette runs `gap` px inside it
    /// where the azimuth (from +x, radians) is below `cut_below`, 7 px inside elsewhere: the
    /// points found as (azimuth, radial error px).
    fn stripe_beside_a_silhouette(gap: f64, cut_below: f64, lit: f64) -> Vec<(f64, f64)> {
        const R: f64 = 60.0;
        let azimuth = |x: f64, y: f64| (y - CY).atan2(x - CX).rem_euclid(std::f64::consts::TAU);
        let img = render(W, H, 8, 1.0, 9, |x, y| {
            let r = (x - CX).hypot(y - CY);
            let stripe = 150.0 * (-(r - R).powi(2) / (2.0 * 1.2 * 1.2)).exp();
            let inside = if azimuth(x, y) < cut_below { gap } else { 7.0 };
            if r < R - inside { 0.0 } else { lit + stripe }
        });
        let pts = detector(RidgeParams::default()).detect(&img);
        pts.iter().map(|p| (azimuth(p.u, p.v), (p.u - CX).hypot(p.v - CY) - R)).collect()
    }

    /// A stripe cut by a silhouette along part of its length is refused there by its own
    /// lopsided profiles, whatever the light beside it (the background step), and kept where it
    /// is whole. A cut is a change along the stripe: a laser's own lopsidedness is the same
    /// all along it (here the cut third departs from the whole two thirds).
    #[test]
    fn stripes_cut_by_a_silhouette_are_refused_by_their_profile() {
        use std::f64::consts::TAU;
        for lit in [0.0, 10.0, 40.0] {
            let points = stripe_beside_a_silhouette(1.2, TAU / 3.0, lit);
            // Away from the two ends of the cut (0.15 rad: 9 px of arc).
            let cut = points.iter().filter(|p| p.0 > 0.15 && p.0 < TAU / 3.0 - 0.15).count();
            let whole: Vec<f64> =
                points.iter().filter(|p| p.0 > TAU / 3.0 + 0.15 && p.0 < TAU - 0.15).map(|p| p.1).collect();
            let n = whole.len() as f64;
            let bias = whole.iter().sum::<f64>() / n;
            let rms = (whole.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
            eprintln!("lit {lit} DN: cut third {cut} points, whole {n} points rms {rms:.4} bias {bias:+.4}");
            assert!(n > 180.0, "lit {lit}: {n} points on the whole part");
            assert!(rms <= 0.05 && bias.abs() <= 0.02, "lit {lit}: rms {rms} bias {bias}");
            assert!(cut * 25 <= whole.len(), "lit {lit}: the cut third gave {cut} points (whole part: {n})");
        }
    }

    /// The lateral resolution the along-stripe fit costs: a step of 0.3 px across a straight
    /// stripe (16-bit, noiseless) rises 10–90 % over 1.6 × 3 px with the fit over ±3 px, as
    /// through a moving average over the shortest arc; alone it rises over the blur's reach
    /// only. Longer arcs stop at the step, which moves their fit by far more than the noise
    /// allows, so it rises no more with ±6 or ±10 px than with ±3.
    #[test]
    fn along_stripe_fit_spreads_a_step_over_its_window() {
        const STEP_X: f64 = 121.0;
        let centre_line = |x: f64| if x < STEP_X { 60.0 } else { 60.3 };
        let img = render(W, H, 16, 0.0, 1, |x, y| 40000.0 * (-(y - centre_line(x)).powi(2) / (2.0 * 0.9 * 0.9)).exp());
        let rise = |along: f64| {
            let mut pts: Vec<(f64, f64)> = detector(RidgeParams { along_stripe_px: along, ..Default::default() })
                .detect(&img)
                .iter()
                .filter(|p| (p.v - 60.15).abs() < 1.0 && (p.u - STEP_X).abs() < 20.0)
                .map(|p| (p.u, (p.v - 60.0) / 0.3))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let first = |level: f64| pts.iter().find(|p| p.1 >= level).map(|p| p.0).unwrap();
            let last = |level: f64| pts.iter().rev().find(|p| p.1 <= level).map(|p| p.0).unwrap();
            (first(0.9) - last(0.1)).max(0.0)
        };
        let alone = rise(0.0);
        eprintln!("10-90 % rise of a 0.3 px step: alone {alone:.2} px");
        assert!(alone <= 2.5, "alone: {alone:.2} px");
        let shortest = rise(3.0);
        eprintln!("  along ±3 px: {shortest:.2} px");
        // A moving average over ±3 px rises 10–90 % in 1.6 × 3 px.
        assert!((4.2..=5.8).contains(&shortest), "along ±3: rise {shortest:.2} px");
        for l in [6.0, 10.0] {
            let r = rise(l);
            eprintln!("  along ±{l} px: {r:.2} px");
            assert!(r <= shortest + 0.1, "along ±{l}: rise {r:.2} px, ±3: {shortest:.2} px");
        }
    }

    /// The along-stripe parabola averages noise on a tightly curved stripe without moving it.
    #[test]
    fn along_stripe_fit_averages_noise_and_keeps_a_curved_stripe() {
        const R: f64 = 25.0;
        let img =
            render(W, H, 8, 12.0, 4, |x, y| 120.0 * (-((x - CX).hypot(y - CY) - R).powi(2) / (2.0 * 0.9 * 0.9)).exp());
        let measure = |along| {
            let pts = detector(RidgeParams { along_stripe_px: along, ..Default::default() }).detect(&img);
            let e: Vec<f64> = pts.iter().map(|p| (p.u - CX).hypot(p.v - CY) - R).collect();
            let n = e.len() as f64;
            (e.iter().sum::<f64>() / n, (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt(), e.len())
        };
        let (bias0, rms0, n0) = measure(0.0);
        let (bias3, rms3, n3) = measure(3.0);
        eprintln!(
            "R {R}: alone rms {rms0:.4} bias {bias0:+.4} ({n0}); along ±3 px rms {rms3:.4} bias {bias3:+.4} ({n3})"
        );
        assert!(rms3 <= 0.75 * rms0, "along fit: rms {rms3:.4} against {rms0:.4}");
        assert!(bias3.abs() <= 0.01, "along fit moved a curved stripe by {bias3:+.4} px");
    }
}

/// Whether a point of this scale may be the top alone of a stripe too wide for it: wider than
/// this scale measures ([`super::scales::NARROW_HALF_WIDTH_PX`]) and not clipped (a clipped core
/// is the sheet's peak, whatever glow spreads around it).
fn may_be_a_top(l: &Linked) -> bool {
    l.half_width > super::scales::NARROW_HALF_WIDTH_PX && l.point.quality & quality::SATURATED == 0
}

/// How much wider and brighter (above its background) a coarse stripe re-measured around a point
/// that [`may_be_a_top`] must be for the point to be its top alone: read against the stripe's own
/// flanks, a top keeps a fraction of the stripe's width and contrast, where a narrow core on a
/// wide glow keeps most of the contrast.
const TOP_RATIO: f64 = 2.0;

/// Drops this scale's points that [`may_be_a_top`] where the coarse scale's stripe, re-measured
/// here, is [`TOP_RATIO`] times as wide and as bright: their reach held the stripe's top alone,
/// so their centres follow the flanks' noise.
fn yield_tops_to_coarse(kept: &mut Vec<Linked>, refined: &[Linked], size: (u32, u32)) {
    let coarse = super::scales::Occupancy::new(
        refined.iter().map(|l| (l.point.u, l.point.v, (l.point.width, l.point.intensity))),
        size,
    );
    kept.retain(|l| {
        !may_be_a_top(l)
            || !coarse.within(l.point.u, l.point.v, (0.5 * l.half_width).max(2.0)).any(|(width, intensity)| {
                width >= TOP_RATIO * l.point.width && intensity >= TOP_RATIO * l.point.intensity
            })
    });
}

#[cfg(test)]
mod order_tests {
    use super::*;

    #[test]
    fn azimuth_order_orders_as_atan2() {
        let mut directions: Vec<(f64, f64)> = (0..720)
            .map(|k| {
                let a = (k as f64 * 0.5 + 0.013 * (k % 7) as f64).to_radians();
                (3.0 * a.cos(), 3.0 * a.sin())
            })
            .chain([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (-1.0, -1e-12), (-1.0, 1e-12)])
            .collect();
        directions.sort_by(|a, b| azimuth_order(a.0, a.1).total_cmp(&azimuth_order(b.0, b.1)));
        let angles: Vec<f64> = directions.iter().map(|d| d.1.atan2(d.0)).collect();
        assert!(angles.windows(2).all(|w| w[0] <= w[1]), "{angles:?}");
    }

    /// The bucketed sort puts points in the order a plain sort by (azimuth key, radius², index)
    /// gives, with points crowded into one direction, exact ties and both ends of the key.
    #[test]
    fn azimuth_sorted_orders_as_a_plain_sort() {
        let mut rng = omni_geom::rng::SplitMix64::new(3);
        let point = |u: f64, v: f64, i: usize| StripePoint { u, v, intensity: i as f64, width: 2.0, quality: 0 };
        let mut points: Vec<StripePoint> = (0..900)
            .map(|i| {
                let (a, r) = (std::f64::consts::TAU * rng.uniform(), 50.0 + 400.0 * rng.uniform());
                point(500.0 + r * a.cos(), 500.0 + r * a.sin(), i)
            })
            .collect();
        // Crowded: 100 points within 0.01° of one direction; ties: repeated points; the key's
        // ends: the −x axis from both sides.
        points.extend((0..100).map(|i| point(900.0 + i as f64, 500.0 + 1e-3 * i as f64, 900 + i)));
        points.extend((0..3).map(|i| point(700.0, 700.0, 1000 + i)));
        points.extend([point(100.0, 500.0, 1003), point(100.0, 500.0 - 1e-9, 1004), point(100.0, 500.0 + 1e-9, 1005)]);
        let centre = (500.0, 500.0);
        let mut expected = points.clone();
        let key = |p: &StripePoint| {
            let (dx, dy) = (p.u - centre.0, p.v - centre.1);
            (azimuth_order(dx, dy), dx * dx + dy * dy)
        };
        let index: std::collections::HashMap<u64, usize> =
            points.iter().enumerate().map(|(i, p)| (p.intensity.to_bits(), i)).collect();
        expected.sort_by(|a, b| {
            let (ka, kb) = (key(a), key(b));
            ka.0.total_cmp(&kb.0)
                .then(ka.1.total_cmp(&kb.1))
                .then(index[&a.intensity.to_bits()].cmp(&index[&b.intensity.to_bits()]))
        });
        let got: Vec<f64> = azimuth_sorted(points, centre).iter().map(|p| p.intensity).collect();
        let want: Vec<f64> = expected.iter().map(|p| p.intensity).collect();
        assert_eq!(got, want);
    }
}
