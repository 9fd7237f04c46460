//! Sub-pixel laser-stripe centres in omnidirectional frames.
//!
//! Two samplings share the estimators, the threshold and the background rule:
//!
//! * [`Sampling::Normal`] (default, module `across`) measures each stripe across its own local
//!   normal, seeded from every pixel row and column, so a stripe in any direction is measured. A
//!   point is kept only if it agrees with its neighbours on the stripe (width, symmetry, a sheet
//!   that goes on): a profile cut by a silhouette or a crease has no reliable centre, whatever the
//!   ambient level. The blur's pull towards a curved stripe's centre of curvature is removed with
//!   the lens's blur where it is given, else with the blur measured on the frame itself.
//!   A laser's lopsided profile (a faint tail on one side, the same all along the stripe) pulls
//!   any centroid towards the tail: each point is moved by its stripe's mean offset between the
//!   estimator's centre and the centroid of its profile's top, then on to the peak of the light
//!   before the blur by its stripe's median top shape (a cubic through the top's logarithm: its
//!   vertex is the image's peak, and its skew gives the blur's shift of a lopsided peak). A
//!   stripe lopsided all along its length is the laser's shape, not a cut.
//! * [`Sampling::Rays`] samples along rays from the mirror centre, `ceil(2π · outer_radius)` of
//!   them so neighbours are ≤ 1 px apart at the rim; a stripe at angle β to its ray is measured
//!   with error / sin β, so rays crossing a stripe at β < 30° are skipped.
//!
//! Both find candidates with a fast row and column scan (pixels brighter than both neighbours
//! `max_width / 2 + 1` px away by more than the threshold) and resample only near them, with a
//! small Gaussian kernel [`SAMPLE_STEP_PX`] apart, because bilinear interpolation of a narrow
//! stripe pixel-locks. Contrast is measured against the local background (the larger of the
//! minima on either side), so a stripe on a lit surface needs no laser-off frame and the edge of
//! a lit area is not a stripe. Saturated profiles are located at the middle of their plateau and
//! flagged [`quality::SATURATED`]. Each point reports `u`, `v` (px), `intensity` (contrast above
//! the background, frame units), `width` (px) and quality flags. The centre estimator is a
//! [`Method`]: the paper's centroid (Eq. 16), a windowed centroid, a Gaussian fit, Blais–Rioux or
//! Steger's Hessian detector. Accuracy figures and the variants tried are in docs/DECISIONS.md.
//!
//! ```
//! use omni_vision::stripe::{Method, RidgeDetector, RidgeParams};
//! use omni_vision::image_io::GrayImage;
//! // A 64×64 frame with a bright ring of radius 20 px around the image centre.
//! let mut img = GrayImage::new(64, 64, 8);
//! for y in 0..64 { for x in 0..64 {
//!     let r = ((x as f64 - 31.5).powi(2) + (y as f64 - 31.5).powi(2)).sqrt();
//!     img.data[y * 64 + x] = (200.0 * (-(r - 20.0).powi(2) / 2.0).exp()) as u16;
//! }}
//! let det = RidgeDetector::for_image_centre(64, 64, RidgeParams { method: Method::Gauss, ..Default::default() });
//! let points = det.detect(&img);
//! assert!(points.len() > 100);
//! for p in &points {
//!     let r = ((p.u - 31.5).powi(2) + (p.v - 31.5).powi(2)).sqrt();
//!     assert!((r - 20.0).abs() < 0.05);
//! }
//! ```

mod across;
mod along;
#[cfg(target_arch = "x86_64")]
mod bilinear8;
mod estimators;
mod frames;
mod laser;
mod normal;
mod overlay;
mod reflections;
mod rowscan;
mod sampling;
mod scales;
mod steger;
mod stripes;

pub use along::{ShortStripes, refuse_short_stripes};
pub use estimators::Segment;
pub use frames::{
    LaserOffCache, STATIC_AMBIENT_MAX_FRAMES, STATIC_AMBIENT_MIN_FRAMES, check_frame_size, check_size, frame_points,
    load_frame_decoded_cached, load_frame_image, load_frame_image_cached, mosaic_site_points, static_ambient,
    static_ambient_frames,
};
pub use omni_formats::stream::{StripePoint, quality};
pub use overlay::draw_overlay;
pub use reflections::{REFLECTION_RATIO, ScanLines, drop_reflections};

use crate::image_io::GrayImage;
use omni_model::MirrorCircle;
use std::f64::consts::TAU;

/// Spacing of the samples along a ray (px). Half a pixel keeps the resampled profile close to
/// the continuous one for stripes a few pixels wide.
pub const SAMPLE_STEP_PX: f64 = 0.5;

/// The stripe-centre estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// The paper's threshold + intensity centroid (Eq. 16).
    Centroid,
    /// Centroid with the threshold subtracted from the weights.
    #[default]
    Windowed,
    /// Gaussian (3-point log-parabola) peak fit.
    Gauss,
    /// Blais–Rioux derivative-filter zero crossing.
    BlaisRioux,
    /// Steger's Hessian line detector in a band around the coarse centre.
    Hessian,
}

impl Method {
    /// All methods, for benchmarks and comparisons.
    pub const ALL: [Method; 5] =
        [Method::Centroid, Method::Windowed, Method::Gauss, Method::BlaisRioux, Method::Hessian];

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Centroid => "centroid",
            Method::Windowed => "windowed",
            Method::Gauss => "gauss",
            Method::BlaisRioux => "blais-rioux",
            Method::Hessian => "hessian",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown method \"{s}\" (known: centroid, windowed, gauss, blais-rioux, hessian)"))
    }
}

/// Where the profiles across the stripe are sampled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Sampling {
    /// Along each stripe's own normal, seeded from every row and column (module `across`):
    /// every stripe direction is measured.
    #[default]
    Normal,
    /// Along rays from the mirror centre: stripes running within 30° of a ray are not measured.
    Rays,
}

impl Sampling {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Sampling::Normal => "normal",
            Sampling::Rays => "rays",
        }
    }
}

impl std::str::FromStr for Sampling {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        [Sampling::Normal, Sampling::Rays]
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown sampling \"{s}\" (known: normal, rays)"))
    }
}

/// Detector settings. Intensities are in the frame's own units (0–255 for 8-bit frames,
/// 0–65535 for 16-bit ones); lengths in px.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RidgeParams {
    pub method: Method,
    /// Where profiles are sampled: across each stripe's normal (default) or along rays.
    pub sampling: Sampling,
    /// Contrast above the local background (in the Gaussian-sampled profile) that makes a
    /// stripe. `None`: 4 % of full scale (10.2 of 255).
    pub threshold: Option<f64>,
    /// Segments narrower than this (threshold crossing to crossing, along the ray) are noise.
    pub min_width: f64,
    /// Segments wider than this are glints, ambient blobs or stripes nearly along the ray.
    pub max_width: f64,
    /// Scale (px) of the Gaussian derivatives of [`Method::Hessian`].
    pub hessian_sigma: f64,
    /// Fit along the stripe over up to this many px of arc on either side (0 = off): across the
    /// normal, over ±3 px a line through the neighbours' offsets once a wider parabola's
    /// curvature is taken out, and over longer arcs (growing from ±3 px as far as the stripe's
    /// shape allows) a parabola, each taken while it agrees with the shorter ones within their
    /// noise, so tight curves, steps and ends keep a short one; along rays, each point's radius
    /// from a line through the same stripe's points over the whole arc (`along`). Averages speckle and noise (±3 px: about
    /// 35 % lower RMS under speckle) at the price of lateral resolution.
    pub along_stripe_px: f64,
    /// The lens's blur (Gaussian PSF σ, px of the frame), pixel integration not included, whose
    /// pull on curved stripes is removed (with the pixel's area and the sampling kernel on top).
    /// `None` (the default) measures the blur on each frame's stripes, which takes a wide laser
    /// sheet's own width for blur: wide curved stripes are then over-corrected.
    pub optics_blur_px: Option<f64>,
    /// With [`Sampling::Normal`]: the coarsest scale (1, 2, 4, 8 or 16: frames binned that many
    /// pixels square) at which stripes too wide for `max_width` are searched (`scales`).
    pub max_scale: u32,
    /// The frame's colour was demosaiced from a colour mosaic (Bayer): the laser's colour is
    /// sampled one pixel in two along each axis, and a profile's top (a few px) is shaped by
    /// the interpolation, alike all along a stripe that runs with the mosaic's rows or
    /// columns. Such a stripe's centres are not moved by its top's shape to the light's peak
    /// (by [`laser_profile`](Self::laser_profile)'s prediction instead, where one is given).
    pub mosaic: bool,
    /// The laser's cross-section, if known (a lopsided laser's tail). Where a stripe's own top
    /// shape cannot lead its points to the sheet's peak (no significant median: pieces too short
    /// or too speckled; or a width mostly the blur's), they are moved from their profiles' tops
    /// by what this profile, blurred by the lens (where known), the pixel and the sampling,
    /// predicts at the profile's width (`laser`), on the side their stripe's profiles give the
    /// tail. Across the normal only ([`Sampling::Normal`]).
    pub laser_profile: Option<omni_model::LaserProfile>,
    /// For a laser-triangulation sensor whose laser lights one point per image column (or
    /// row): drop the stripes that share such a line with one at least twice as bright, as its
    /// reflections ([`drop_reflections`]). `None` (the default) keeps every stripe.
    pub one_stripe_per: Option<ScanLines>,
}

impl Default for RidgeParams {
    fn default() -> Self {
        RidgeParams {
            method: Method::Windowed,
            sampling: Sampling::Normal,
            threshold: None,
            min_width: 1.0,
            max_width: 12.0,
            hessian_sigma: 1.0,
            along_stripe_px: 0.0,
            optics_blur_px: None,
            max_scale: 8,
            mosaic: false,
            laser_profile: None,
            one_stripe_per: None,
        }
    }
}

impl RidgeParams {
    /// These settings with the lens's blur taken from `camera` (its measured `lens_blur_px`, else
    /// what its optics imply) unless [`optics_blur_px`](Self::optics_blur_px) is set, checked;
    /// the message names the field.
    pub fn with_lens_blur_of(self, camera: &omni_formats::CameraFile) -> Result<RidgeParams, String> {
        let params = RidgeParams { optics_blur_px: self.optics_blur_px.or(camera.lens_blur()), ..self };
        params.validate().map_err(|e| format!("field lens_blur_px / optics: {e}"))?;
        Ok(params)
    }

    /// The threshold for a frame whose samples saturate at `max_value`.
    pub fn threshold_for(&self, max_value: f64) -> f64 {
        self.threshold.unwrap_or(0.04 * max_value)
    }

    /// The shortest stretch of stripe (px, end to end) the along-stripe fit works on: its
    /// shortest arc's window, 2 × min(`along_stripe_px`, 3 px) across the normal (longer arcs
    /// stop where the stripe ends), 2 × `along_stripe_px` along rays.
    pub fn along_stripe_window_px(&self) -> f64 {
        match self.sampling {
            Sampling::Normal => 2.0 * self.along_stripe_px.min(across::SHAPE_HALF_ARC_PX),
            Sampling::Rays => 2.0 * self.along_stripe_px,
        }
    }

    /// Checks the settings; the message names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(t) = self.threshold
            && !(t.is_finite() && t >= 0.0)
        {
            return Err(format!("threshold must be a finite number ≥ 0, got {t}"));
        }
        if !(self.min_width.is_finite() && self.min_width >= 0.0) {
            return Err(format!("min-width must be ≥ 0, got {}", self.min_width));
        }
        if !(self.max_width.is_finite() && self.max_width > self.min_width) {
            return Err(format!("max-width must be > min-width ({}), got {}", self.min_width, self.max_width));
        }
        if !(self.hessian_sigma.is_finite() && self.hessian_sigma >= 0.5 && self.hessian_sigma <= 8.0) {
            return Err(format!("hessian sigma must be in [0.5, 8] px, got {}", self.hessian_sigma));
        }
        if !(self.along_stripe_px.is_finite() && (0.0..=20.0).contains(&self.along_stripe_px)) {
            return Err(format!("along-stripe fit must be in [0, 20] px, got {}", self.along_stripe_px));
        }
        if let Some(blur) = self.optics_blur_px
            && !(blur.is_finite() && (0.0..=5.0).contains(&blur))
        {
            return Err(format!("optics blur must be in [0, 5] px, got {blur}"));
        }
        if !(self.max_scale.is_power_of_two() && self.max_scale <= 16) {
            return Err(format!("max scale must be 1, 2, 4, 8 or 16, got {}", self.max_scale));
        }
        if let Some(profile) = self.laser_profile {
            profile.validate().map_err(|e| format!("laser profile: {e}"))?;
        }
        Ok(())
    }
}

/// The variance (px² of a frame binned `scale` pixels square) of the blur that pulls curved
/// stripes when the lens's PSF σ (`sigma_px`, in the frame's own pixels) is known: the lens's,
/// the pixel's area (one binned pixel's box) and the sampling kernel's.
fn known_blur_variance(sigma_px: f64, scale: u32) -> f64 {
    (sigma_px / scale as f64).powi(2) + crate::PIXEL_AREA_VARIANCE_PX2 + sampling::SAMPLE_SIGMA_PX.powi(2)
}

/// A sample type the detector reads directly: 8- or 16-bit.
pub trait Pixel: Copy + Send + Sync + PartialOrd {
    fn to_f32(self) -> f32;
    /// The sample as an integer (the bilinear samplers interpolate in integers).
    fn to_u32(self) -> u32;
    /// The Gaussian sampler's kernel sum over a block of its rows (see `sampling`), where this pixel
    /// type has a faster form than the generic loop; `None` otherwise.
    #[inline(always)]
    fn kernel8(_block: &[Self], _w: usize, _wx: &[f32; sampling::TAPS], _wy: &[f32; sampling::TAPS]) -> Option<f32> {
        None
    }
    /// `Frame::bilinear_line`'s samples (`out[k]` at (`xf`, `yf`) + k·`step`, 32.32 fixed
    /// point, in frame `data` of `w` pixels per row) where this pixel type has a faster form
    /// than one sample at a time; returns whether it wrote them.
    #[inline(always)]
    fn bilinear_line_fast(_data: &[Self], _w: usize, _xf: i64, _yf: i64, _step: (i64, i64), _out: &mut [f32]) -> bool {
        false
    }
    /// `Frame::cross`'s four samples from its 4×4 block (rows `w` apart) and fractions (1/256
    /// px), where this pixel type has a faster form than four interpolations; `None` otherwise.
    #[inline(always)]
    fn cross_fast(_block: &[Self], _w: usize, _fx: u32, _fy: u32) -> Option<[f32; 4]> {
        None
    }
    /// The threshold as this type (floored: `v − m > T` ⇔ `v > m + floor(T)` for integers).
    fn from_threshold(t: f64) -> Self;
    /// Whether `v` exceeds both its row neighbours `l`, `r` or both its column neighbours `u`,
    /// `d` by more than `t`; written without branches so that it vectorises.
    fn contrast_above(v: Self, l: Self, r: Self, u: Self, d: Self, t: Self) -> bool;
    /// Calls `hit(i)` for each `i` (increasing) where [`Self::contrast_above`] holds for `c[i]`
    /// and its neighbours `l[i]`, `r[i]`, `u[i]`, `d[i]` (slices of one length: a row's stretch).
    #[inline(always)]
    fn for_each_contrast_hit(
        c: &[Self],
        l: &[Self],
        r: &[Self],
        u: &[Self],
        d: &[Self],
        t: Self,
        hit: impl FnMut(usize),
    ) {
        rowscan::for_each_hit_generic(c, l, r, u, d, t, hit)
    }
}

impl Pixel for u8 {
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self as u32
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn kernel8(block: &[u8], w: usize, wx: &[f32; sampling::TAPS], wy: &[f32; sampling::TAPS]) -> Option<f32> {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked); the function reads `block` through
            // bounds-checked slices.
            return Some(unsafe { sampling::kernel8_avx2(block, w, wx, wy) });
        }
        // SAFETY: SSE2 is part of the x86-64 baseline, so every x86-64 CPU has it; the function
        // has no other requirement (it reads `block` through bounds-checked slices).
        Some(unsafe { sampling::kernel8_sse2(block, w, wx, wy) })
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn bilinear_line_fast(data: &[u8], w: usize, xf: i64, yf: i64, step: (i64, i64), out: &mut [f32]) -> bool {
        // SAFETY: SSE2 is part of the x86-64 baseline (see `kernel8`); the function reads and
        // writes only through bounds-checked slices.
        unsafe { bilinear8::bilinear_line_sse2(data, w, xf, yf, step, out) };
        true
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn cross_fast(block: &[u8], w: usize, fx: u32, fy: u32) -> Option<[f32; 4]> {
        // SAFETY: SSE2 is part of the x86-64 baseline (see `kernel8`); the function reads only
        // through bounds-checked slices.
        Some(unsafe { bilinear8::cross_sse2(block, w, fx, fy) })
    }
    fn from_threshold(t: f64) -> Self {
        t.floor().clamp(0.0, 255.0) as u8
    }
    #[inline(always)]
    fn contrast_above(v: u8, l: u8, r: u8, u: u8, d: u8, t: u8) -> bool {
        (v > l.max(r).saturating_add(t)) | (v > u.max(d).saturating_add(t))
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn for_each_contrast_hit(c: &[u8], l: &[u8], r: &[u8], u: &[u8], d: &[u8], t: u8, hit: impl FnMut(usize)) {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked); the function reads only through
            // bounds-checked slices.
            unsafe { rowscan::for_each_hit_avx2(c, l, r, u, d, t, hit) }
        } else {
            // SAFETY: SSE2 is part of the x86-64 baseline (see `kernel8`); the function reads
            // only through bounds-checked slices.
            unsafe { rowscan::for_each_hit_sse2(c, l, r, u, d, t, hit) }
        }
    }
}

impl Pixel for u16 {
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self as u32
    }
    fn from_threshold(t: f64) -> Self {
        t.floor().clamp(0.0, 65535.0) as u16
    }
    #[inline(always)]
    fn contrast_above(v: u16, l: u16, r: u16, u: u16, d: u16, t: u16) -> bool {
        (v > l.max(r).saturating_add(t)) | (v > u.max(d).saturating_add(t))
    }
}

/// A borrowed single-channel frame.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a, P> {
    pub width: u32,
    pub height: u32,
    pub data: &'a [P],
    /// Saturation level (255 for 8-bit, 65535 for 16-bit frames).
    pub max_value: f64,
}

impl<P: Pixel> Frame<'_, P> {
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width as usize + x].to_f32()
    }

    /// Whether a pixel of the 3×3 neighbourhood of (x, y) px is at the saturation level.
    fn saturated_near(&self, x: f64, y: f64) -> bool {
        // Nearest pixel (`floor_i64`: `f64::round` is a library call on baseline x86-64).
        let (xi, yi) = (floor_i64(x + 0.5), floor_i64(y + 0.5));
        let sat = self.max_value as f32;
        (yi - 1..=yi + 1).any(|yy| {
            (xi - 1..=xi + 1).any(|xx| {
                xx >= 0
                    && yy >= 0
                    && xx < self.width as i64
                    && yy < self.height as i64
                    && self.at(xx as usize, yy as usize) >= sat
            })
        })
    }

    /// Bilinear sample at (x, y) px, or `None` if its 2×2 neighbourhood leaves the image.
    #[inline]
    fn bilinear(&self, x: f64, y: f64) -> Option<f32> {
        // `as` truncates: ⌊x⌋ for the non-negative coordinates accepted here.
        let inside =
            x >= 0.0 && y >= 0.0 && (x as usize) + 1 < self.width as usize && (y as usize) + 1 < self.height as usize;
        let ((xi, fx), (yi, fy)) = (fixed_point(x), fixed_point(y));
        inside.then(|| self.interpolate(yi * self.width as usize + xi, fx, fy))
    }

    /// Bilinear samples 1 px left, right, above and below (x, y) px, or `None` if one of them
    /// leaves the image: the four share their interpolation weights, so one position split and
    /// one bounds check serve all (same values as four [`Self::bilinear`] calls). Inlined: its
    /// four values returned through memory stalled the checks that read them (perf).
    #[inline(always)]
    fn cross(&self, x: f64, y: f64) -> Option<[f32; 4]> {
        if !(x >= 1.0 && y >= 1.0) {
            return None;
        }
        let ((xi, fx), (yi, fy)) = (fixed_point(x), fixed_point(y));
        let (w, h) = (self.width as usize, self.height as usize);
        if xi + 2 >= w || yi + 2 >= h {
            return None;
        }
        // The 4×4 pixels around (x, y) (corners unused), read through one bounds-checked slice.
        let block = &self.data[(yi - 1) * w + xi - 1..(yi + 2) * w + xi + 3];
        if let Some(values) = P::cross_fast(block, w, fx, fy) {
            return Some(values);
        }
        let at = |row: usize, col: usize| block[row * w + col].to_u32();
        let cell = |row: usize, col: usize| {
            lerp_q8([at(row, col), at(row, col + 1), at(row + 1, col), at(row + 1, col + 1)], fx, fy)
        };
        Some([cell(1, 0), cell(1, 2), cell(0, 1), cell(2, 1)])
    }

    /// The 2×2 neighbourhood whose top-left pixel is `data[i]`, interpolated at the fractions
    /// `fx`, `fy` (in 1/256 px) right and down: the one bilinear formula all the bilinear
    /// samplers share. In integers: the bilinear samples only find the stripes and their
    /// backgrounds and check gradients (the centres come from the Gaussian sampler), where a
    /// position rounded down to 1/256 px does not matter, and four integer products cost less
    /// than four integer → float conversions (callgrind: 65 → 39 instructions per sample).
    #[inline(always)]
    fn interpolate(&self, i: usize, fx: u32, fy: u32) -> f32 {
        let w = self.width as usize;
        // One bounds check for the four pixels.
        let px = &self.data[i..i + w + 2];
        lerp_q8([px[0].to_u32(), px[1].to_u32(), px[w].to_u32(), px[w + 1].to_u32()], fx, fy)
    }

    /// Appends the bilinear samples at `centre + (r0 + k)·dir`, k = 0..n, to `out` if all their
    /// 2×2 neighbourhoods are inside the image, and returns whether they are. The positions are
    /// stepped in 32.32 fixed point (integer additions instead of a multiplication and a
    /// saturating float → integer conversion per axis and sample; the steps' rounding drifts by
    /// < n · 2⁻³² px), so they are linear in k and the two ends' neighbourhoods being inside
    /// means all are.
    fn bilinear_line(&self, cx: f64, cy: f64, r0: f64, dir: (f64, f64), n: usize, out: &mut Vec<f32>) -> bool {
        let (w, h) = (self.width as usize, self.height as usize);
        let (mut xf, mut yf) = (to_fixed(cx + r0 * dir.0), to_fixed(cy + r0 * dir.1));
        let (step_x, step_y) = (to_fixed(dir.0), to_fixed(dir.1));
        let last = n.saturating_sub(1) as i64;
        let inside = |x: i64, y: i64| x >= 0 && y >= 0 && ((x >> 32) as usize) + 1 < w && ((y >> 32) as usize) + 1 < h;
        if !(inside(xf, yf) && inside(xf + last * step_x, yf + last * step_y)) {
            return false;
        }
        let start = out.len();
        out.resize(start + n, 0.0);
        if P::bilinear_line_fast(self.data, w, xf, yf, (step_x, step_y), &mut out[start..]) {
            return true;
        }
        for v in &mut out[start..] {
            let ((xi, fx), (yi, fy)) = (split_fixed(xf), split_fixed(yf));
            *v = self.interpolate(yi * w + xi, fx, fy);
            xf += step_x;
            yf += step_y;
        }
        true
    }
}

/// The sampling geometry of one image size and mirror annulus, plus settings. Build once per
/// camera and reuse for every frame; [`RidgeDetector::detect_frame`] is safe to call from many
/// threads at once.
#[derive(Debug, Clone)]
pub struct RidgeDetector {
    params: RidgeParams,
    width: u32,
    height: u32,
    /// Mirror centre (px).
    cx: f64,
    cy: f64,
    /// Annulus radii (px).
    r_in: f64,
    r_out: f64,
    /// Unit direction of each ray.
    dirs: Vec<(f64, f64)>,
    /// 64-bit words per ray in the radius bitmap.
    words_per_ray: usize,
    sampler: sampling::GaussSampler,
    steger: steger::Kernels,
    /// Gaussian derivatives that give each seed its stripe normal ([`Sampling::Normal`]).
    seed_normal: steger::Kernels,
    /// Where points are kept besides the annulus (a user's ROI or valid-pixel mask).
    region: Option<SearchRegion>,
    /// The detector for frames binned 2 × 2 (`scales`), built when first needed.
    coarser: std::sync::OnceLock<Box<RidgeDetector>>,
    /// Where the laser's tops lie from its sheet's peak at this detector's scale, built when
    /// first needed (only with [`RidgeParams::laser_profile`]).
    top_offsets: std::sync::OnceLock<laser::TopOffsets>,
    /// Where the laser's windowed centroids lie from its sheet's peak at this scale, built when
    /// first needed (only with [`RidgeParams::laser_profile`]).
    windowed_offsets: std::sync::OnceLock<laser::WindowedOffsets>,
    /// Where the laser's clipped plateaus' centres lie from its sheet's peak at this scale,
    /// built when first needed (only with [`RidgeParams::laser_profile`]).
    plateau_offsets: std::sync::OnceLock<laser::PlateauOffsets>,
}

/// A part of the frame the user restricts the search to, on top of the camera's annulus.
#[derive(Debug, Clone, PartialEq)]
pub enum SearchRegion {
    /// Pixels `x0 ≤ x < x1`, `y0 ≤ y < y1` (px; a point at (u, v) is inside when its nearest
    /// pixel is).
    Rect { x0: u32, y0: u32, x1: u32, y1: u32 },
    /// One flag per pixel, row-major, of the detector's image size: true where valid.
    Mask(std::sync::Arc<Vec<bool>>),
}

impl SearchRegion {
    /// Whether the pixel nearest (u, v) px is in the region (`width`: the image's).
    fn contains(&self, u: f64, v: f64, width: u32) -> bool {
        let (x, y) = (floor_i64(u + 0.5), floor_i64(v + 0.5));
        if x < 0 || y < 0 {
            return false;
        }
        let (x, y) = (x as u64, y as u64);
        match self {
            SearchRegion::Rect { x0, y0, x1, y1 } => {
                x >= *x0 as u64 && x < *x1 as u64 && y >= *y0 as u64 && y < *y1 as u64
            }
            SearchRegion::Mask(m) => {
                x < width as u64 && m.get((y * width as u64 + x) as usize).copied().unwrap_or(false)
            }
        }
    }
}

/// Per-call working memory (reuse it across frames on one thread to avoid allocations).
#[derive(Debug, Default)]
pub struct Scratch {
    /// For each ray, a bitmap of the 1-px radius bins holding a pixel above the threshold.
    bits: Vec<u64>,
    /// Bit per ray: whether it has a bit set in `bits`, to visit (and clear) only those rays,
    /// in order.
    touched: Vec<u64>,
    row: RowHits,
    profiles: Profiles,
}

/// The row scan's candidate pixels of one row: x offsets from the mirror centre (px) and their
/// polar coordinates (radius in px, azimuth in rad).
#[derive(Debug, Default)]
struct RowHits {
    dx: Vec<f64>,
    r: Vec<f64>,
    phi: Vec<f64>,
}

/// Where a point was measured: its ray (index into the detector's rays) and its radius (px)
/// along it from the mirror centre.
#[derive(Debug, Clone, Copy)]
struct RayRadius {
    ray: u32,
    r: f64,
}

/// Working buffers for one stretch of a ray.
#[derive(Debug, Default)]
struct Profiles {
    /// Bilinear samples, 1 px apart.
    coarse: Vec<f32>,
    /// Gaussian-kernel samples around one candidate, [`SAMPLE_STEP_PX`] apart.
    raw: Vec<f32>,
    /// Intensities minus the local background of the maximum being measured.
    contrast: Vec<f32>,
}

impl RidgeDetector {
    /// A detector for `width`×`height` frames sampled from `circle`'s centre within its annulus
    /// (clipped to the image).
    pub fn new(width: u32, height: u32, circle: MirrorCircle, params: RidgeParams) -> Self {
        let (cx, cy) = (circle.centre.x, circle.centre.y);
        // Rays need a start off the centre; profiles across the stripe do not.
        let r_in = if params.sampling == Sampling::Normal {
            circle.inner_radius.max(0.0)
        } else {
            circle.inner_radius.max(2.0)
        };
        // The rays never need to go past the farthest image corner.
        let corner = [(0.0, 0.0), (width as f64, 0.0), (0.0, height as f64), (width as f64, height as f64)]
            .iter()
            .map(|&(x, y)| (x - cx).hypot(y - cy))
            .fold(0.0, f64::max);
        // An annulus beyond the frame has nothing to search (`MirrorCircle::check_in_frame`
        // refuses such cameras); the tables stay the frame's size.
        let r_in = r_in.min(corner);
        let r_out = circle.outer_radius.min(corner).max(r_in + 1.0);
        let n_rays = ((TAU * r_out / MAX_RAY_STEP as f64).ceil().max(1.0) as usize) * MAX_RAY_STEP;
        let dirs = (0..n_rays).map(|i| (TAU * i as f64 / n_rays as f64).sin_cos()).map(|(s, c)| (c, s)).collect();
        let words_per_ray = (r_out as usize + 2).div_ceil(64);
        let steger = steger::Kernels::new(params.hessian_sigma);
        let seed_normal = steger::Kernels::with_half(3, across::SEED_NORMAL_SIGMA_PX);
        let sampler = sampling::GaussSampler::default();
        RidgeDetector {
            params,
            width,
            height,
            cx,
            cy,
            r_in,
            r_out,
            dirs,
            words_per_ray,
            sampler,
            steger,
            seed_normal,
            region: None,
            coarser: std::sync::OnceLock::new(),
            top_offsets: std::sync::OnceLock::new(),
            windowed_offsets: std::sync::OnceLock::new(),
            plateau_offsets: std::sync::OnceLock::new(),
        }
    }

    /// A detector for an ordinary lens: the whole `width`×`height` frame is searched (points
    /// are still ordered by azimuth about the image centre).
    pub fn whole_frame(width: u32, height: u32, params: RidgeParams) -> Self {
        let centre = omni_geom::Vector2::new((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
        let outer_radius = (width as f64).hypot(height as f64);
        Self::new(width, height, MirrorCircle { centre, inner_radius: 0.0, outer_radius }, params)
    }

    /// The same detector keeping only points inside `region` (a mask must have the detector's
    /// image size: checked, the message says both sizes).
    pub fn with_region(mut self, region: SearchRegion) -> Result<Self, String> {
        if let SearchRegion::Mask(m) = &region
            && m.len() != self.width as usize * self.height as usize
        {
            return Err(format!(
                "the mask has {} pixels, the frame {}x{} = {}",
                m.len(),
                self.width,
                self.height,
                self.width as usize * self.height as usize
            ));
        }
        self.region = Some(region);
        Ok(self)
    }

    /// The detector for this one's frames read at one colour's mosaic sites, the first at this
    /// detector's frame pixel `origin` ([`crate::colour::mosaic_sites`]): half the image size,
    /// the annulus and the settings in px halved, no search region (the points are judged in
    /// frame pixels by [`Self::points_from_mosaic_sites`]). The sites are samples, not 2 × 2
    /// bins: a stripe keeps its own sharpness and the lens's blur halves with the pixel.
    pub fn for_mosaic_sites(&self, origin: (u32, u32)) -> RidgeDetector {
        let p = self.params;
        let params = RidgeParams {
            min_width: p.min_width / 2.0,
            max_width: p.max_width / 2.0,
            hessian_sigma: (p.hessian_sigma / 2.0).max(0.5),
            along_stripe_px: p.along_stripe_px / 2.0,
            optics_blur_px: p.optics_blur_px.map(|s| s / 2.0),
            max_scale: (p.max_scale / 2).max(1),
            mosaic: false,
            // Reflections are judged once the frame's search region has kept its points
            // ([`Self::points_from_mosaic_sites`]).
            one_stripe_per: None,
            ..p
        };
        self.halved((origin.0 as f64, origin.1 as f64), params)
    }

    /// Frame points (this detector's pixels) placed on the image read at a mosaic's sites whose
    /// first is frame pixel `origin`: the inverse of [`Self::points_from_mosaic_sites`], for
    /// drawing them on that image.
    pub fn points_on_mosaic_sites(points: &[StripePoint], origin: (u32, u32)) -> Vec<StripePoint> {
        let (ox, oy) = (origin.0 as f64, origin.1 as f64);
        points
            .iter()
            .map(|p| StripePoint { u: (p.u - ox) / 2.0, v: (p.v - oy) / 2.0, width: p.width / 2.0, ..*p })
            .collect()
    }

    /// A detector for images of half this one's size whose pixel (i, j) lies at this one's
    /// (`first.0` + 2i, `first.1` + 2j), with `params`: the annulus as this detector clipped it,
    /// halved (not widened again by `new`'s corner rule).
    fn halved(&self, first: (f64, f64), params: RidgeParams) -> RidgeDetector {
        let circle = MirrorCircle {
            centre: omni_geom::Vector2::new((self.cx - first.0) / 2.0, (self.cy - first.1) / 2.0),
            inner_radius: self.r_in / 2.0,
            outer_radius: self.r_out / 2.0,
        };
        let mut half = RidgeDetector::new(self.width / 2, self.height / 2, circle, params);
        half.r_in = self.r_in / 2.0;
        half
    }

    /// Points that [`Self::for_mosaic_sites`]`(origin)`'s detector found, in this detector's frame
    /// pixels (positions and widths), those outside its search region dropped, then the
    /// reflections ([`RidgeParams::one_stripe_per`], judged on the sites: a line is one site).
    pub fn points_from_mosaic_sites(&self, mut points: Vec<StripePoint>, origin: (u32, u32)) -> Vec<StripePoint> {
        let (ox, oy) = (origin.0 as f64, origin.1 as f64);
        if let Some(region) = &self.region {
            points.retain(|p| region.contains(ox + 2.0 * p.u, oy + 2.0 * p.v, self.width));
        }
        if let Some(lines) = self.params.one_stripe_per {
            points = drop_reflections(points, lines).0;
        }
        points
            .into_iter()
            .map(|p| StripePoint { u: ox + 2.0 * p.u, v: oy + 2.0 * p.v, width: 2.0 * p.width, ..p })
            .collect()
    }

    /// A detector sampling from the image centre, over the largest circle inside the image.
    pub fn for_image_centre(width: u32, height: u32, params: RidgeParams) -> Self {
        let centre = omni_geom::Vector2::new((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
        let outer_radius = (width.min(height) as f64 - 1.0) / 2.0;
        Self::new(width, height, MirrorCircle { centre, inner_radius: 0.0, outer_radius }, params)
    }

    pub fn params(&self) -> &RidgeParams {
        &self.params
    }

    /// The image size the detector was built for.
    pub fn image_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Number of sampling rays (one per ≤ 1 px of rim).
    pub fn ray_count(&self) -> usize {
        self.dirs.len()
    }

    /// Stripe centres of a loaded frame (any bit depth).
    pub fn detect(&self, img: &GrayImage) -> Vec<StripePoint> {
        let frame = Frame { width: img.width, height: img.height, data: &img.data, max_value: img.max_value() as f64 };
        self.detect_frame(&frame, &mut Scratch::default())
    }

    /// Stripe centres of a frame, in ray order (azimuth from +x towards +y), then by radius;
    /// only those in the [`SearchRegion`] if the detector has one.
    /// Panics if the frame's size is not the detector's (check [`Self::image_size`] first).
    pub fn detect_frame<P: Pixel>(&self, frame: &Frame<'_, P>, scratch: &mut Scratch) -> Vec<StripePoint> {
        let mut points = self.detect_in_annulus(frame, scratch);
        if let Some(region) = &self.region {
            points.retain(|p| region.contains(p.u, p.v, self.width));
        }
        match self.params.one_stripe_per {
            Some(lines) => drop_reflections(points, lines).0,
            None => points,
        }
    }

    fn detect_in_annulus<P: Pixel>(&self, frame: &Frame<'_, P>, scratch: &mut Scratch) -> Vec<StripePoint> {
        assert_eq!((frame.width, frame.height), (self.width, self.height), "frame size differs from the detector's");
        assert_eq!(frame.data.len(), self.width as usize * self.height as usize, "frame buffer has the wrong length");
        let threshold = self.params.threshold_for(frame.max_value);
        if self.params.sampling == Sampling::Normal {
            return self.detect_across(frame, threshold);
        }
        self.mark_candidates(frame, threshold, scratch);
        let mut out = Vec::new();
        // Points of ray `rays[i].0` are `out[rays[i].1..rays[i + 1].1]`.
        let mut rays: Vec<(u32, usize)> = Vec::new();
        for word in 0..scratch.touched.len() {
            let mut m = std::mem::take(&mut scratch.touched[word]);
            while m != 0 {
                let ray = word * 64 + m.trailing_zeros() as usize;
                m &= m - 1;
                rays.push((ray as u32, out.len()));
                self.scan_ray(frame, ray, threshold, scratch, &mut out);
                let w = self.words_per_ray;
                scratch.bits[ray * w..(ray + 1) * w].fill(0);
            }
        }
        let (points, on_rays) = self.drop_isolated(out, &rays);
        // Oblique and tightly curved stripes: centres re-measured across the stripe (`normal`).
        let points = self.remeasure_across(frame, points, &on_rays, threshold);
        let l = self.params.along_stripe_px;
        if l > 0.0 {
            // Neighbours on the same stripe: within the radial step of a stripe crossing the
            // rays at 60° (the steepest measured) over the window, plus 1 px.
            along::fit_along_stripe(&points, (self.cx, self.cy), l, 1.0 + l * 3f64.sqrt())
        } else {
            points
        }
    }

    /// Keeps only points with a neighbour on the stripe [`MIN_STRIPE_ARC_PX`] away (on either
    /// side, across rays): a hot pixel or a speck of noise covers only the rays within 1 px of
    /// it, a stripe runs on. Returns the kept points and their rays and radii (px).
    fn drop_isolated(&self, out: Vec<StripePoint>, rays: &[(u32, usize)]) -> (Vec<StripePoint>, Vec<RayRadius>) {
        let n = self.dirs.len();
        // Points of the ray at `rays[i]`: `out[rays[i].1..end(i)]`.
        let end = |i: usize| rays.get(i + 1).map_or(out.len(), |r| r.1);
        // Radii of the points along their rays, computed once (each is compared with its
        // neighbours' several times).
        let mut radii = Vec::with_capacity(out.len());
        for (i, &(ray, start)) in rays.iter().enumerate() {
            let (dx, dy) = self.dirs[ray as usize];
            radii.extend(out[start..end(i)].iter().map(|p| (p.u - self.cx) * dx + (p.v - self.cy) * dy));
        }
        // Where each ray's points are in `rays` (a table: each point looks up two rays).
        let mut index_of = vec![u32::MAX; n];
        for (i, &(ray, _)) in rays.iter().enumerate() {
            index_of[ray as usize] = i as u32;
        }
        let radii_of = |ray: u32| match index_of[ray as usize] {
            u32::MAX => &radii[0..0],
            i => &radii[rays[i as usize].1..end(i as usize)],
        };
        // Largest radial step between neighbours on a stripe crossing the rays at 60°.
        let max_dr = MIN_STRIPE_ARC_PX * 3f64.sqrt() + 1.0;
        let has_neighbour = |ray: u32, r: f64, k: i64| {
            let other = (ray as i64 + k).rem_euclid(n as i64) as u32;
            radii_of(other).iter().any(|q| (q - r).abs() <= max_dr)
        };
        let mut kept = Vec::with_capacity(out.len());
        let mut kept_rays = Vec::with_capacity(out.len());
        for (i, &(ray, start)) in rays.iter().enumerate() {
            for (p, &r) in out[start..end(i)].iter().zip(&radii[start..end(i)]) {
                // Rays are 2π·r/n px apart at radius r; only every step-th one is sampled.
                let step = self.ray_step(r) as i64;
                let arc_rays = MIN_STRIPE_ARC_PX * n as f64 / (TAU * r) / step as f64;
                let k = (-floor_i64(-arc_rays)).max(1) * step;
                if has_neighbour(ray, r, k) || has_neighbour(ray, r, -k) {
                    kept.push(*p);
                    kept_rays.push(RayRadius { ray, r });
                }
            }
        }
        (kept, kept_rays)
    }

    /// Row scan: every pixel above the threshold inside the annulus marks its radius bin on the
    /// rays passing within 1 px of it.
    fn mark_candidates<P: Pixel>(&self, frame: &Frame<'_, P>, threshold: f64, scratch: &mut Scratch) {
        let n = self.dirs.len();
        scratch.bits.resize(n * self.words_per_ray, 0);
        scratch.touched.resize(n.div_ceil(64), 0);
        let t = P::from_threshold(threshold);
        let (w, h) = (self.width as usize, self.height as usize);
        let y_lo = (self.cy - self.r_out).floor().max(0.0) as usize;
        let y_hi = ((self.cy + self.r_out).ceil() as usize).min(h - 1);
        let rays_per_rad = n as f64 / TAU;
        let k = (0.5 * self.params.max_width).ceil() as usize + 1;
        // The row's candidate pixels (x offsets from the mirror centre, px), marked together
        // after the row's scan (`mark_row`).
        let mut hits = std::mem::take(&mut scratch.row.dx);
        for y in y_lo..=y_hi {
            let dy = y as f64 - self.cy;
            let half = (self.r_out * self.r_out - dy * dy).max(0.0).sqrt();
            // (`floor_i64`: `f64::floor` and `ceil` are library calls on baseline x86-64.)
            let x_lo = floor_i64(self.cx - half).max(0) as usize;
            let x_hi = (-floor_i64(-(self.cx + half))).clamp(0, w as i64 - 1) as usize;
            if x_lo > x_hi {
                continue;
            }
            // Pixels whose four neighbours k px away exist take the fast, branch-free test;
            // the few near the image border the general one.
            let interior = y >= k && y + k < h;
            let (a, b) = if interior { (x_lo.max(k), (x_hi + 1).min(w - k)) } else { (x_lo, x_lo) };
            hits.clear();
            let mut hit = |x: usize| hits.push(x as f64 - self.cx);
            for x in (x_lo..a.max(x_lo)).chain(b.max(a)..=x_hi) {
                if stands_out(frame, x, y, k, threshold as f32) {
                    hit(x);
                }
            }
            if a < b {
                let d = frame.data;
                let cur = &d[y * w + a..y * w + b];
                let left = &d[y * w + a - k..y * w + b - k];
                let right = &d[y * w + a + k..y * w + b + k];
                let up = &d[(y - k) * w + a..(y - k) * w + b];
                let down = &d[(y + k) * w + a..(y + k) * w + b];
                P::for_each_contrast_hit(cur, left, right, up, down, t, |i| hit(a + i));
            }
            if !hits.is_empty() {
                self.mark_row(&hits, dy, rays_per_rad, scratch);
            }
        }
        scratch.row.dx = hits;
    }

    /// Marks the candidate pixels of one row (x offsets `dxs` and y offset `dy` from the mirror
    /// centre, px): their polar coordinates first, all together (a loop the compiler vectorises,
    /// and whose square roots and divisions overlap, instead of one chain per pixel), then the
    /// rays near each.
    fn mark_row(&self, dxs: &[f64], dy: f64, rays_per_rad: f64, scratch: &mut Scratch) {
        let RowHits { r, phi, .. } = &mut scratch.row;
        r.clear();
        r.extend(dxs.iter().map(|&dx| (dx * dx + dy * dy).sqrt()));
        phi.clear();
        phi.extend(dxs.iter().map(|&dx| fast_atan2(dy, dx)));
        for (&r, &phi) in scratch.row.r.iter().zip(&scratch.row.phi) {
            self.mark_pixel(r, phi, rays_per_rad, &mut scratch.bits, &mut scratch.touched);
        }
    }

    #[inline]
    fn mark_pixel(&self, r: f64, phi: f64, rays_per_rad: f64, bits: &mut [u64], touched: &mut [u64]) {
        if r < self.r_in || r > self.r_out {
            return;
        }
        let n = self.dirs.len() as i64;
        let centre = phi * rays_per_rad;
        // Rays within 1 px of the pixel centre (covers the pixel and the atan2 approximation).
        let span = rays_per_rad / r.max(1.0);
        let step = self.ray_step(r) as i64;
        let (lo, hi) = (floor_i64(centre - span), -floor_i64(-(centre + span)));
        let bin = r as usize;
        let (word, bit) = (bin / 64, 1u64 << (bin % 64));
        // `step` is a power of two: `lo & -step` rounds down to a multiple of it (also below 0);
        // the rays wrap around once at most (no integer division in this per-pixel loop).
        let mut i = lo & -step;
        while i <= hi {
            let ray = if i < 0 {
                i + n
            } else if i >= n {
                i - n
            } else {
                i
            } as usize;
            i += step;
            touched[ray / 64] |= 1 << (ray % 64);
            bits[ray * self.words_per_ray + word] |= bit;
        }
    }

    /// Which rays sample radius `r`: every `ray_step(r)`-th one (a power of two ≤
    /// [`MAX_RAY_STEP`]), so that the rays used are 0.5–1 px apart at every radius instead of
    /// crowding towards the centre (fewer, barely correlated points; less work).
    #[inline]
    fn ray_step(&self, r: f64) -> usize {
        // The largest power of two ≤ r_out / r, at most MAX_RAY_STEP (comparisons, not log2:
        // this runs for every candidate pixel and every point).
        let ratio = self.r_out / r.max(1.0);
        let mut step = 1;
        while step < MAX_RAY_STEP && ratio >= (2 * step) as f64 {
            step *= 2;
        }
        step
    }

    /// Resamples the marked stretches of one ray and turns each valid segment into a point.
    fn scan_ray<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        ray: usize,
        threshold: f64,
        scratch: &mut Scratch,
        out: &mut Vec<StripePoint>,
    ) {
        let bits = &scratch.bits[ray * self.words_per_ray..(ray + 1) * self.words_per_ray];
        // Padding so that the background windows of the maxima within 2 px of a marked bin stay
        // inside. (The coarse maximum lies within 1 px of a marked bin, but for a saturated
        // plateau's last sample; + 3 gave the same points on the simulator's frames, + 1 lost 4
        // of 3071 saturated ones; each px of padding costs 4 % of the coarse samples.)
        let pad = self.background_window() + 2;
        // Overlapping padded bins merge into one stretch, scanned when the next one starts.
        // The stretch may reach past the annulus (for the background windows); only peaks
        // inside it are measured.
        let mut current: Option<(usize, usize)> = None;
        for (wi, &word) in bits.iter().enumerate() {
            let mut m = word;
            while m != 0 {
                let b = wi * 64 + m.trailing_zeros() as usize;
                m &= m - 1;
                let (lo, hi) = (b.saturating_sub(pad), b + 1 + pad);
                match &mut current {
                    Some(last) if lo <= last.1 => last.1 = last.1.max(hi),
                    _ => {
                        if let Some((l, h)) = current.replace((lo, hi)) {
                            self.scan_stretch(frame, ray, l as f64, h as f64, threshold, &mut scratch.profiles, out);
                        }
                    }
                }
            }
        }
        if let Some((l, h)) = current {
            self.scan_stretch(frame, ray, l as f64, h as f64, threshold, &mut scratch.profiles, out);
        }
    }

    /// Samples the ray from radius `r0` to `r1` and emits a point per accepted segment.
    ///
    /// A coarse profile (bilinear, 1 px steps) finds the candidate segments: local maxima whose
    /// contrast above the local background exceeds the threshold. The background of a maximum
    /// is the larger of the profile's minima within [`Self::background_window`] on either side:
    /// a stripe on a lit surface (ambient light without a laser-off frame) stands out from it,
    /// while the edge of a lit area (a step, not a ridge) does not. Each candidate is then
    /// resampled finely with the Gaussian kernel ([`SAMPLE_STEP_PX`] steps), where the threshold
    /// is applied again and the estimators work.
    fn scan_stretch<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        ray: usize,
        r0: f64,
        r1: f64,
        threshold: f64,
        scratch: &mut Profiles,
        out: &mut Vec<StripePoint>,
    ) {
        let (dx, dy) = self.dirs[ray];
        let n = (r1 - r0) as usize + 1;
        let Profiles { coarse: c, raw: p, contrast: q } = scratch;
        c.clear();
        // Outside the image is NaN; a segment or background window touching it is rejected.
        // A straight stretch whose two ends are inside lies inside: sampled without checks.
        let inside = frame.bilinear_line(self.cx, self.cy, r0, (dx, dy), n, c);
        if !inside {
            c.extend((0..n).map(|k| {
                let r = r0 + k as f64;
                frame.bilinear(self.cx + r * dx, self.cy + r * dy).unwrap_or(f32::NAN)
            }));
        }
        let t = threshold as f32;
        let w = self.background_window();
        let mut done_until = 0;
        for k in w.max(1)..n.saturating_sub(w.max(1)) {
            let is_max = c[k] >= c[k - 1] && c[k] > c[k + 1];
            let r_k = r0 + k as f64;
            if !is_max || k < done_until || r_k < self.r_in || r_k > self.r_out {
                continue;
            }
            // Most maxima are noise: the test below fails for them. Without NaNs it holds iff
            // some sample on each side is more than t below the maximum, which a short scan
            // that stops at the first such sample decides.
            let deep = |v: &f32| c[k] - v > t;
            if inside && !(c[k - w..=k].iter().any(deep) && c[k..=k + w].iter().any(deep)) {
                continue;
            }
            let (left, right) = (min_or_nan(&c[k - w..=k]), min_or_nan(&c[k..=k + w]));
            let background = left.max(right);
            if !(c[k] - background > t) || left.is_nan() || right.is_nan() {
                continue;
            }
            // A stripe lying on a step of the background (the edge of a lit object, where the
            // stripe itself is cut off) has no reliable centre.
            if (left - right).abs() > MAX_BACKGROUND_STEP * (c[k] - background)
                && !clear_of_step(c, k, w, (left, right))
            {
                done_until = k + 1;
                continue;
            }
            // Resample finely outwards from the coarse peak until a sample on each side is at or
            // below the threshold: the crossing, which the estimators' windows and the width
            // need; three for Blais–Rioux, whose filter reaches two samples beyond its zero
            // crossing.
            let tail = if self.params.method == Method::BlaisRioux { 3 } else { 1 };
            let coarse_end = (k + 1..n).find(|&i| !(c[i] - background > 0.5 * t)).unwrap_or(n);
            done_until = coarse_end;
            let r_peak = r0 + k as f64;
            let limit = ((0.5 * self.params.max_width + 3.0) / SAMPLE_STEP_PX) as i64;
            // Sample i at r_peak + i·SAMPLE_STEP_PX, stepped in 32.32 fixed point (integer
            // additions, no float conversions per sample); NaN where the kernel leaves the frame,
            // which only needs checking per sample when it leaves at an end of the walk's reach.
            let origin = (to_fixed(self.cx + r_peak * dx), to_fixed(self.cy + r_peak * dy));
            let step = (to_fixed(SAMPLE_STEP_PX * dx), to_fixed(SAMPLE_STEP_PX * dy));
            let at = |i: i64| (origin.0 + i * step.0, origin.1 + i * step.1);
            let reach_inside =
                self.sampler.kernel_inside(frame, at(-limit)) && self.sampler.kernel_inside(frame, at(limit));
            let fine = |i: i64| {
                let p = at(i);
                if reach_inside || self.sampler.kernel_inside(frame, p) {
                    self.sampler.sample_fixed(frame, p)
                } else {
                    f32::NAN
                }
            };
            let walk = |dir: i64, into: &mut Vec<f32>| {
                into.clear();
                let mut below = 0;
                for i in 1..=limit {
                    let v = fine(dir * i);
                    into.push(v);
                    if !(v - background > t) {
                        below += 1;
                        if below == tail {
                            break;
                        }
                    }
                }
            };
            walk(-1, q);
            p.clear();
            p.extend(q.iter().rev());
            let rf0 = r_peak - q.len() as f64 * SAMPLE_STEP_PX;
            p.push(fine(0));
            walk(1, q);
            p.extend(q.iter());
            q.clear();
            q.extend(p.iter().map(|v| v - background));
            let Some(seg) = fine_segment(q, t) else { continue };
            if let Some(point) = self.segment_point(frame, ray, rf0, p, q, &seg, t) {
                out.push(point);
            }
        }
    }

    /// Coarse samples (1 px) on either side of a maximum searched for its background: past the
    /// flank of the widest accepted stripe.
    fn background_window(&self) -> usize {
        // ⌈x⌉ as −⌊−x⌋ (`f64::ceil` is a library call on baseline x86-64; this runs per stretch).
        (-floor_i64(-(0.5 * self.params.max_width + 2.0))) as usize
    }

    /// The centre of one segment along the ray, or `None` if it is too narrow/wide or the fit
    /// fails. `p` is the sampled profile, `q` its contrast above the local background.
    fn segment_point<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        ray: usize,
        r0: f64,
        raw: &[f32],
        p: &[f32],
        seg: &Segment,
        t: f32,
    ) -> Option<StripePoint> {
        let (a, b) = self.crossings_within_width(p, seg, t)?;
        let width = (b - a) * SAMPLE_STEP_PX;
        let peak = p[seg.peak];
        let (dx, dy) = self.dirs[ray];
        let r_peak = r0 + seg.peak as f64 * SAMPLE_STEP_PX;
        let mut quality = 0;
        let index = if frame.saturated_near(self.cx + r_peak * dx, self.cy + r_peak * dy) {
            quality |= quality::SATURATED;
            estimators::plateau_centre(p, seg, t, peak)?
        } else {
            self.centre_index(raw, p, seg, t)?
        };
        let mut r = r0 + index * SAMPLE_STEP_PX;
        if !self.is_ridge_centre(frame, self.cx + r * dx, self.cy + r * dy, peak) {
            return None;
        }
        let (ra, rb) = (r0 + a * SAMPLE_STEP_PX, r0 + b * SAMPLE_STEP_PX);
        if !self.edge_faces_ray(frame, ra, (dx, dy)) || !self.edge_faces_ray(frame, rb, (dx, dy)) {
            return None;
        }
        if self.params.method == Method::Hessian && quality & quality::SATURATED == 0 {
            r = self.steger.refine_along_ray(frame, (self.cx, self.cy), (dx, dy), r)?;
        }
        quality |= self.contrast_and_width_flags(peak, width, t, self.params.max_width);
        Some(StripePoint { u: self.cx + r * dx, v: self.cy + r * dy, intensity: peak as f64, width, quality })
    }

    /// [`quality::WEAK`] and [`quality::WIDTH_MARGINAL`] for a segment of contrast `peak` and
    /// `width` (px) at threshold `t`.
    fn contrast_and_width_flags(&self, peak: f32, width: f64, t: f32, max_width: f64) -> u32 {
        let mut flags = 0;
        if peak < 3.0 * t {
            flags |= quality::WEAK;
        }
        if width < 1.2 * self.params.min_width || width > 0.8 * max_width {
            flags |= quality::WIDTH_MARGINAL;
        }
        flags
    }

    /// The segment's threshold crossings (sample indices) in `q`, the contrast profile, or `None`
    /// if they are missing or the width between them (px) is outside
    /// [`RidgeParams::min_width`]..[`RidgeParams::max_width`].
    fn crossings_within_width(&self, q: &[f32], seg: &Segment, t: f32) -> Option<(f64, f64)> {
        let (a, b) = estimators::crossings(q, seg, t)?;
        let width = (b - a) * SAMPLE_STEP_PX;
        (!(width < self.params.min_width || width > self.params.max_width)).then_some((a, b))
    }

    /// The selected [`Method`]'s centre of the segment (fractional sample index) from the sampled
    /// profile `raw` and its contrast `q` above the local background.
    fn centre_index(&self, raw: &[f32], q: &[f32], seg: &Segment, t: f32) -> Option<f64> {
        match self.params.method {
            // Eq. 16 weighs the raw intensities, background included.
            Method::Centroid => estimators::centroid(raw, seg),
            Method::Windowed | Method::Hessian => estimators::windowed_centroid(q, seg, t),
            Method::Gauss => estimators::gaussian(q, seg),
            Method::BlaisRioux => estimators::blais_rioux(q, seg),
        }
    }

    /// Whether the image is flat (gradient ≈ 0) at a found centre, as on a ridge's centreline.
    /// A ray that only grazes the edge of a bright blob (a glint, an ambient patch) also gives a
    /// short segment, but there the gradient is as steep as the blob's edge: reject those.
    fn is_ridge_centre<P: Pixel>(&self, frame: &Frame<'_, P>, x: f64, y: f64, peak: f32) -> bool {
        let Some([l, r, u, d]) = frame.cross(x, y) else {
            return false;
        };
        // |gradient| ≤ MAX_CENTRE_GRADIENT · peak (peak > threshold ≥ 0), squared: no square root.
        let gradient2 = 0.25 * ((r - l).powi(2) + (d - u).powi(2));
        gradient2 <= (MAX_CENTRE_GRADIENT * peak).powi(2)
    }
    /// Whether the intensity edge at radius `r` on the ray crosses the ray at more than
    /// [`MIN_EDGE_ANGLE_DEG`] (its gradient has a component along the ray). A stripe's edges run
    /// beside its centreline, so they face the ray unless the stripe is nearly radial; a ray
    /// grazing a bright blob (a glint wider than the ray's segment) meets edges running along it.
    fn edge_faces_ray<P: Pixel>(&self, frame: &Frame<'_, P>, r: f64, dir: (f64, f64)) -> bool {
        let (x, y) = (self.cx + r * dir.0, self.cy + r * dir.1);
        let Some([l, rt, u, d]) = frame.cross(x, y) else {
            return false;
        };
        let (gx, gy) = ((rt - l) as f64, (d - u) as f64);
        let along = (gx * dir.0 + gy * dir.1).abs();
        // sin(MIN_EDGE_ANGLE_DEG) = sin 30°; along ≥ sin · |g|, squared: no square root.
        const SIN_MIN_EDGE_ANGLE: f64 = 0.5;
        along * along >= SIN_MIN_EDGE_ANGLE * SIN_MIN_EDGE_ANGLE * (gx * gx + gy * gy)
    }
}

/// Smallest angle (degrees) between a stripe edge and the sampling ray (see
/// `edge_faces_ray`): stripes crossing the ray more obliquely than 90° − 30° are not measured
/// on that ray.
pub const MIN_EDGE_ANGLE_DEG: f64 = 30.0;

/// Largest stride between the rays sampled at small radii (see `RidgeDetector::ray_step`).
pub const MAX_RAY_STEP: usize = 8;

/// Largest difference between the backgrounds on the two sides of a stripe, relative to its
/// contrast, for the stripe to be measured, unless the stripe is clear of the step
/// ([`STEP_CLEARANCE_PX`]). Where a stripe runs along an object's silhouette or a crease, the
/// laser sheet is cut across its width and the centre moves towards the part left; the sides'
/// backgrounds then differ (lit surface on one side, the darker scene beyond on the other). The
/// value is the knee of the demo scans' σ against it (docs/DECISIONS.md).
pub const MAX_BACKGROUND_STEP: f32 = 0.2;

/// Samples (px) of flat background that a stripe on a step of the background needs between its
/// flank and the step to be measured after all (`clear_of_step`): about a stripe's σ and the
/// step's own blur. Without it, whole stripes right beside a silhouette would be dropped
/// too.
pub const STEP_CLEARANCE_PX: usize = 3;

/// Arc length (px) over which a stripe must continue on at least one side of a point.
pub const MIN_STRIPE_ARC_PX: f64 = 2.5;

/// The largest gradient (per px, relative to the peak) accepted at a stripe centre; a
/// Gaussian stripe of σ = 1.5 px measured 0.3 px off its centre has 0.13.
pub const MAX_CENTRE_GRADIENT: f32 = 0.25;

/// Whether the stripe peaking at `c[k]` ends on its lit side's background well before the darker
/// side's step: walking from the peak towards the lower of the two windows' minima (`w` coarse
/// samples, 1 px apart; `left`, `right`: the windows' minima), the profile falls to within a
/// quarter of the step of the higher side's level and stays there for [`STEP_CLEARANCE_PX`] samples before it drops. A
/// whole stripe beside a silhouette passes; one the silhouette cuts falls from its flank straight
/// into the step.
fn clear_of_step(c: &[f32], k: usize, w: usize, (left, right): (f32, f32)) -> bool {
    let (background, low) = (left.max(right), left.min(right));
    let margin = 0.25 * (background - low);
    let on_flank = |v: &&f32| **v > background + margin;
    let on_background = |v: &&f32| (**v - background).abs() <= margin;
    let flat = if left < right {
        c[k - w..=k].iter().rev().skip_while(on_flank).take(STEP_CLEARANCE_PX).filter(on_background).count()
    } else {
        c[k..=k + w].iter().skip_while(on_flank).take(STEP_CLEARANCE_PX).filter(on_background).count()
    };
    flat == STEP_CLEARANCE_PX
}

/// The smallest of `samples`, or NaN if one is NaN (outside the image).
fn min_or_nan(samples: &[f32]) -> f32 {
    // Without branches (`f32::min` skips NaNs; the flag remembers them): vectorised.
    let (min, nan) = samples.iter().fold((f32::INFINITY, false), |(m, nan), &v| (m.min(v), nan | v.is_nan()));
    if nan { f32::NAN } else { min }
}

/// The segment around the largest contrast of `q` whose samples stay above `t`, or `None` if
/// the peak is not above `t` or the segment reaches either end (or a NaN) of `q`.
fn fine_segment(q: &[f32], t: f32) -> Option<Segment> {
    // The last of the largest samples (NaNs never compare ≥).
    let mut peak = None;
    let mut largest = f32::NEG_INFINITY;
    for (i, &v) in q.iter().enumerate() {
        if v >= largest {
            (peak, largest) = (Some(i), v);
        }
    }
    segment_at(q, peak?, t)
}

/// The run of samples of `q` above `t` around `peak`, or `None` if the peak is not above `t` or
/// the run reaches either end (or a NaN) of `q`.
fn segment_at(q: &[f32], peak: usize, t: f32) -> Option<Segment> {
    if !(q[peak] > t) {
        return None;
    }
    let mut start = peak;
    while start > 0 && q[start - 1] > t {
        start -= 1;
    }
    let mut end = peak + 1;
    while end < q.len() && q[end] > t {
        end += 1;
    }
    let cut = start == 0 || end == q.len() || q[start - 1].is_nan() || q[end].is_nan();
    (!cut).then_some(Segment { start, end, peak })
}

/// Whether pixel (x, y) is brighter by more than `t` than both its neighbours `reach` px away
/// along the row, or than both along the column: true on a stripe (narrower than 2·reach) in
/// any direction, false inside a uniformly lit area and at the edge of one (a step). Beyond
/// the image counts as 0.
#[inline]
fn stands_out<P: Pixel>(f: &Frame<'_, P>, x: usize, y: usize, reach: usize, t: f32) -> bool {
    row_contrast(f, x, y, reach) > t || column_contrast(f, x, y, reach) > t
}

/// How much pixel (x, y) is brighter than the brighter of its row neighbours `reach` px away
/// (beyond the image counts as 0).
#[inline]
fn row_contrast<P: Pixel>(f: &Frame<'_, P>, x: usize, y: usize, reach: usize) -> f32 {
    let right = if x + reach < f.width as usize { f.at(x + reach, y) } else { 0.0 };
    let left = x.checked_sub(reach).map_or(0.0, |xx| f.at(xx, y));
    f.at(x, y) - left.max(right)
}

/// How much pixel (x, y) is brighter than the brighter of its column neighbours `reach` px
/// away (beyond the image counts as 0).
#[inline]
fn column_contrast<P: Pixel>(f: &Frame<'_, P>, x: usize, y: usize, reach: usize) -> f32 {
    let down = if y + reach < f.height as usize { f.at(x, y + reach) } else { 0.0 };
    let up = y.checked_sub(reach).map_or(0.0, |yy| f.at(x, yy));
    f.at(x, y) - up.max(down)
}

/// Bilinear interpolation of the 2×2 pixels `[top left, top right, bottom left, bottom right]`
/// at the fractions `fx`, `fy` (in 1/256) right and down (see `Frame::interpolate`).
#[inline(always)]
fn lerp_q8(px: [u32; 4], fx: u32, fy: u32) -> f32 {
    let (fx, fy) = (fx as u64, fy as u64);
    let top = px[0] as u64 * (256 - fx) + px[1] as u64 * fx;
    let bottom = px[2] as u64 * (256 - fx) + px[3] as u64 * fx;
    // < 2³³ for 16-bit pixels: exact in i64, and as f32 to 24 bits.
    let v = top * (256 - fy) + bottom * fy;
    v as i64 as f32 * (1.0 / 65536.0)
}

/// 1.0 in 32.32 fixed point: coordinates scaled by it keep 32 fractional bits exactly.
const FIXED_ONE: f64 = 4_294_967_296.0;

/// `x` (px, |x| < 2³¹) in 32.32 fixed point (truncated towards zero).
#[inline(always)]
pub(super) fn to_fixed(x: f64) -> i64 {
    (x * FIXED_ONE) as i64
}

/// The integer part of a non-negative 32.32 fixed-point coordinate and its fractional part in
/// 1/256 (rounded down).
#[inline(always)]
fn split_fixed(fixed: i64) -> (usize, u32) {
    ((fixed >> 32) as usize, ((fixed >> 24) & 0xFF) as u32)
}

/// The integer and fractional parts of a coordinate 0 ≤ x < 2³¹ px: ⌊x⌋ and x − ⌊x⌋ in 1/256
/// (rounded down), with a single float → integer conversion.
#[inline(always)]
fn fixed_point(x: f64) -> (usize, u32) {
    split_fixed(to_fixed(x))
}

/// ⌊x⌋ for finite `x` within ±2⁶³ (truncation and a correction: `f64::floor` is a libm call
/// on baseline x86-64).
#[inline]
pub(super) fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x { t - 1 } else { t }
}

/// atan2 in [0, 2π) with an error below 1e-5 rad (a 7th-order odd polynomial of the octant
/// ratio): the candidate scan only needs to know which rays pass near a pixel.
#[inline]
fn fast_atan2(y: f64, x: f64) -> f64 {
    // Selects instead of branches, so that a loop over pixels vectorises (`mark_row`).
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = (ax.min(ay), ax.max(ay));
    let z = if den == 0.0 { 0.0 } else { num / den };
    let z2 = z * z;
    // Minimax coefficients for atan on [0, 1].
    let a = z * (0.999_866_0 + z2 * (-0.330_299_5 + z2 * (0.180_141_0 + z2 * (-0.085_133_0 + z2 * 0.020_835_1))));
    let a = if ay > ax { std::f64::consts::FRAC_PI_2 - a } else { a };
    let a = if x < 0.0 { std::f64::consts::PI - a } else { a };
    let a = if y < 0.0 { TAU - a } else { a };
    if a >= TAU { 0.0 } else { a }
}

#[cfg(test)]
pub(super) mod tests;

/// The median of `v` (the lower of the two middle values for an even count); `None` if empty.
fn lower_median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let k = (v.len() - 1) / 2;
    Some(*v.select_nth_unstable_by(k, f64::total_cmp).1)
}

#[cfg(test)]
mod sim_tests;
