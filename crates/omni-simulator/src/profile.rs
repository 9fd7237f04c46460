//! The laser sheet's irradiance profile across the light plane.
//!
//! [`SheetProfile::Gaussian`] is the physically derived default (a Gaussian beam waist).
//! [`SheetProfile::Tailed`] is the shape measured on real line-laser photographs
//! (docs/DECISIONS.md, "Real stripe cross-sections"): a Gaussian core with a one-sided
//! exponential tail, i.e. `(1 − w)·N(σ) + w·(N(σ) ∗ Exp(τ))`, the tail on one side of the plane
//! along its whole length. Both components have unit area, so the laser's energy does not depend
//! on the shape. The family is closed under Gaussian blur (σ² adds, the tail's τ stays), which is
//! how a sample's footprint and the optics widen it, and how [`SheetProfile::image_fwhm_px`]
//! predicts the FWHM the rendered stripe shows.
//!
//! Placement: the light plane (d = 0, where the ground truth lies) is the **peak** (mode) of the
//! sheet's irradiance profile; for the Gaussian that is also its centroid.

pub use omni_model::GAUSS_FWHM_PER_SIGMA;
use omni_model::LaserProfile;
use serde::{Deserialize, Serialize};

/// Shape of the laser sheet's irradiance across the light plane; its width is
/// [`crate::RenderOptions::beam_fwhm_mm`] (or set per frame by
/// [`crate::RenderOptions::stripe_fwhm_px`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum SheetProfile {
    /// A Gaussian, centred on the light plane.
    #[default]
    Gaussian,
    /// A Gaussian core of σ with a one-sided exponential tail: a share `tail_weight` of the
    /// energy in `N(σ) ∗ Exp(τ)`, τ = `tail_length` · σ, on the side `tail_side` (+1: towards the
    /// light plane's normal, −1: away from it). Its peak lies on the light plane.
    Tailed { tail_weight: f64, tail_length: f64, tail_side: i8 },
}

impl SheetProfile {
    /// The cross-section measured on the real frames (docs/DECISIONS.md): 17 % of the energy in a
    /// tail 4 σ long, on the plane normal's side.
    pub fn real() -> Self {
        SheetProfile::Tailed { tail_weight: 0.17, tail_length: 4.0, tail_side: 1 }
    }

    /// Checks the parameters; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            SheetProfile::Gaussian => Ok(()),
            SheetProfile::Tailed { tail_weight, tail_length, tail_side } => {
                LaserProfile::tailed(tail_weight, tail_length).validate()?;
                if tail_side != 1 && tail_side != -1 {
                    return Err(format!("tail_side must be 1 or -1, got {tail_side}"));
                }
                Ok(())
            }
        }
    }

    /// The shape's constants (mode and FWHM of the unit-σ profile).
    pub(crate) fn shape(&self) -> Shape {
        match *self {
            SheetProfile::Gaussian => Shape { profile: LaserProfile::gaussian(), side: 1.0 },
            SheetProfile::Tailed { tail_weight, tail_length, tail_side } => {
                Shape { profile: LaserProfile::tailed(tail_weight, tail_length), side: f64::from(tail_side) }
            }
        }
    }

    /// FWHM of the sheet in units of its core σ.
    pub fn fwhm_per_sigma(&self) -> f64 {
        self.shape().profile.fwhm()
    }

    /// The profile as a function (unit area) of the offset from the light plane's image, for a
    /// sheet imaged `fwhm` wide, after a Gaussian blur of σ `blur` (same unit as `fwhm`; positive
    /// offsets towards the plane's normal, the tail's side for `tail_side` 1). Builds the shape
    /// once: cheap to call many times.
    pub fn curve(&self, fwhm: f64, blur: f64) -> impl Fn(f64) -> f64 + use<> {
        let shape = self.shape();
        let sigma = fwhm / shape.profile.fwhm();
        move |x| shape.density(x, sigma, blur)
    }

    /// The FWHM (px) of a stripe whose sheet images `fwhm_px` wide (px, before the optics), after
    /// a Gaussian blur of σ `blur_px` (the lens's PSF and the pixel's area).
    pub fn image_fwhm_px(&self, fwhm_px: f64, blur_px: f64) -> f64 {
        let shape = self.shape();
        let sigma = fwhm_px / shape.profile.fwhm();
        let s = (1.0 + (blur_px / sigma).powi(2)).sqrt();
        let (lo, hi) = shape.profile.half_points(s);
        (hi - lo) * sigma
    }

    /// The sheet's FWHM (px, before the optics) that gives a stripe of FWHM `target_px` after a
    /// Gaussian blur of σ `blur_px`; `None` if the blur alone is already that wide.
    pub fn sheet_fwhm_for_image_px(&self, target_px: f64, blur_px: f64) -> Option<f64> {
        if !(target_px.is_finite() && target_px > 0.0) || self.image_fwhm_px(1e-6, blur_px) >= target_px {
            return None;
        }
        let (mut lo, mut hi) = (1e-6, target_px);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if self.image_fwhm_px(mid, blur_px) < target_px {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(0.5 * (lo + hi))
    }

    /// Where the peak of the stripe blurred by a Gaussian of σ `blur_px` lies from the light
    /// plane's image (px, positive towards the tail), for a sheet imaged `fwhm_px` wide: the
    /// blur's pull on an asymmetric profile's peak (0 for the Gaussian).
    pub fn blurred_peak_offset_px(&self, fwhm_px: f64, blur_px: f64) -> f64 {
        let shape = self.shape();
        let sigma = fwhm_px / shape.profile.fwhm();
        let s = (1.0 + (blur_px / sigma).powi(2)).sqrt();
        (shape.profile.mode_at(s) - shape.profile.mode()) * sigma
    }

    /// The profile's centroid from the light plane (in units of its FWHM, positive towards the
    /// tail): where a centre of mass over the whole profile lands.
    pub fn centroid_offset(&self) -> f64 {
        let shape = self.shape();
        (shape.profile.tail_weight() * shape.profile.tail_length() - shape.profile.mode()) / shape.profile.fwhm()
    }
}

/// A profile placed across the light plane: its shape for a core σ of 1 and the side of the
/// plane its tail lies on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Shape {
    pub profile: LaserProfile,
    pub side: f64,
}

impl Shape {
    /// Profile (unit area) at plane distance `d` (mm) for a core σ `sigma` (mm) widened by a
    /// Gaussian of σ `extra` (mm), placed with its unwidened mode on the plane.
    pub fn density(&self, d: f64, sigma: f64, extra: f64) -> f64 {
        let s = (1.0 + (extra / sigma).powi(2)).sqrt();
        let x = self.side * d / sigma + self.profile.mode();
        self.profile.unit(x, s) / sigma
    }

    /// The plane distances (mm) outside which the profile is taken as 0: 6 σ on the core's side,
    /// 6 σ + 10 τ on the tail's.
    pub fn support(&self, sigma: f64, extra: f64) -> (f64, f64) {
        let s = (sigma * sigma + extra * extra).sqrt();
        let tail = if self.profile.tail_weight() > 0.0 { 10.0 * self.profile.tail_length() * sigma } else { 0.0 };
        self.range(-6.0 * s, 6.0 * s + tail, sigma)
    }

    /// The plane distances (mm) within which pixels are supersampled: 4 σ on the core's side,
    /// 4 σ + τ on the tail's (the tail further out is smooth at the pixel scale).
    pub fn near(&self, sigma: f64) -> (f64, f64) {
        let tail = if self.profile.tail_weight() > 0.0 { self.profile.tail_length() * sigma } else { 0.0 };
        self.range(-4.0 * sigma, 4.0 * sigma + tail, sigma)
    }

    /// Plane distances of the offsets `lo`, `hi` (mm) from the core's centre towards the tail.
    fn range(&self, lo: f64, hi: f64, sigma: f64) -> (f64, f64) {
        let centre = -self.side * self.profile.mode() * sigma;
        let (a, b) = (centre + self.side * lo, centre + self.side * hi);
        (a.min(b), a.max(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Numerical integral of f over [a, b] (midpoint rule).
    fn integral(f: impl Fn(f64) -> f64, a: f64, b: f64) -> f64 {
        let n = 200_000;
        let h = (b - a) / n as f64;
        (0..n).map(|i| f(a + (i as f64 + 0.5) * h)).sum::<f64>() * h
    }

    #[test]
    fn the_profiles_have_unit_area_and_their_peak_on_the_plane() {
        for p in [
            SheetProfile::Gaussian,
            SheetProfile::real(),
            SheetProfile::Tailed { tail_weight: 0.4, tail_length: 1.5, tail_side: -1 },
        ] {
            let shape = p.shape();
            for extra in [0.0, 0.7] {
                let area = integral(|d| shape.density(d, 1.0, extra), -30.0, 80.0);
                assert!((area - 1.0).abs() < 1e-6, "{p:?}: area {area}");
                let (lo, hi) = shape.support(1.0, extra);
                let kept = integral(|d| shape.density(d, 1.0, extra), lo, hi);
                assert!(kept > 1.0 - 1e-5, "{p:?}: {kept} within the support");
            }
            // The unwidened profile peaks at d = 0.
            let f = |d: f64| shape.density(d, 1.0, 0.0);
            assert!(f(0.0) > f(1e-3) && f(0.0) > f(-1e-3), "{p:?}: {} {} {}", f(-1e-3), f(0.0), f(1e-3));
            // FWHM in σ: half the peak at the two half points.
            let (lo, hi) = shape.profile.half_points(1.0);
            let at = |x: f64| shape.profile.unit(x, 1.0) / shape.profile.unit(shape.profile.mode(), 1.0);
            assert!((at(lo) - 0.5).abs() < 1e-9 && (at(hi) - 0.5).abs() < 1e-9);
        }
        assert!((SheetProfile::Gaussian.fwhm_per_sigma() - GAUSS_FWHM_PER_SIGMA).abs() < 1e-12);
    }

    #[test]
    fn the_blurred_width_is_solved_back() {
        let p = SheetProfile::real();
        for target in [2.0, 5.0, 20.0] {
            let sheet = p.sheet_fwhm_for_image_px(target, 0.757).unwrap();
            assert!((p.image_fwhm_px(sheet, 0.757) - target).abs() < 1e-9);
        }
        assert!(p.sheet_fwhm_for_image_px(1.5, 0.757).is_none(), "narrower than the blur");
        // The blur's pull on the real profile's peak is small and towards the tail.
        let pull = p.blurred_peak_offset_px(5.0, 0.757);
        assert!(pull > 0.0 && pull < 0.02, "{pull}");
        assert_eq!(SheetProfile::Gaussian.blurred_peak_offset_px(5.0, 0.757), 0.0);
    }
}
