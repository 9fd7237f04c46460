//! Image formation: exact camera rays, adaptive supersampling, the laser sheet's Gaussian
//! profile, shadows, ambient light, optical blur, sensor noise and quantisation.
//!
//! The pipeline of one frame:
//! 1. For every pixel *corner* cast the camera ray ([`CameraModel::pixel_to_ray`]) and record
//!    what it hits and on which side of each light plane. A pixel whose corners disagree (an
//!    object or checkerboard edge, the mirror rim, a light plane crossing it) or lie within
//!    4 σ of a light plane is supersampled on an `n × n` grid; any other pixel takes the mean of
//!    its four corners' samples.
//! 2. Each sample shades the first hit: `albedo · (ambient_e + Σ laser)` electrons, where a
//!    light plane contributes `laser_strength · cos(incidence) · g(d) / (π r)`: `g` the normalised
//!    Gaussian of the distance `d` (mm) from the plane (σ = FWHM / 2.3548), `1/(π r)` the spreading
//!    of the 180° fan at distance `r` from its (virtual) apex. A point gets laser light only if it is
//!    on the lit half-plane, faces the laser and nothing blocks the path from the facet to it.
//!    The scene's lighting scales `ambient_e` from place to place.
//! 3. Incoherent light is blurred with a Gaussian PSF (σ 0.7 px for the idealised sensor, the
//!    lens's diffraction + defocus otherwise). With a lens and speckle on, the laser light is
//!    imaged coherently instead ([`crate::coherent`]).
//! 4. Photon noise (Poisson), read noise (Gaussian), saturation at the full well, gamma and
//!    quantisation to the bit depth.

use crate::capture::{Bloom, Colour, ColourOutput, Halo};
use crate::coherent::{CellLight, CoherentImager, LaserField, MAX_DEFOCUS_PX};
use crate::frame::{Frame16, RgbFrame};
use crate::profile::{Shape, SheetProfile};
use crate::rng::{SplitMix64, mix};
use crate::scene::{Hit, Scene};
use crate::sensor::Sensor;
use omni_geom::{Point3, Vector2, Vector3, erf};
use omni_model::LightPlane;
use omni_model::Optics;
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// How the lens forms the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Imaging {
    /// The idealised sensor: every light, the laser's too, blurred by a Gaussian PSF of σ
    /// `sigma_px` (px), no speckle.
    Gaussian { sigma_px: f64 },
    /// A real lens ([`Optics`]): ambient light blurred by the diffraction + defocus PSF (its
    /// best-fitting Gaussian), the laser light imaged coherently through the pupil
    /// ([`crate::coherent`]: speckle, diffraction, defocus), or incoherently like the ambient
    /// light when `speckle` is false.
    Lens { optics: Optics, speckle: bool },
}

impl Imaging {
    /// σ of the optical PSF of incoherent light (px), the pixel area excluded.
    pub fn psf_sigma_px(&self) -> f64 {
        match self {
            Imaging::Gaussian { sigma_px } => *sigma_px,
            Imaging::Lens { optics, .. } => optics.psf_sigma_px(),
        }
    }

    /// σ (px) of the optical PSF of incoherent light at pixel `px` seeing a surface `distance_mm`
    /// along its ray: with a focus distance, the diffraction and the camera's defocus there; else
    /// [`Self::psf_sigma_px`].
    pub fn psf_sigma_at(&self, camera: &dyn omni_model::CameraModel, px: &Vector2<f64>, distance_mm: f64) -> f64 {
        match self {
            Imaging::Lens { optics, .. } if optics.field_dependent() => {
                let defocus = camera.defocus_sigma_px(px, distance_mm, optics).unwrap_or(0.0);
                optics.psf_sigma_with_defocus((4.0 * defocus).min(MAX_DEFOCUS_PX))
            }
            _ => self.psf_sigma_px(),
        }
    }

    /// The lens focused at a distance, where the defocus varies over the image.
    fn field_optics(&self) -> Option<&Optics> {
        match self {
            Imaging::Lens { optics, .. } if optics.field_dependent() => Some(optics),
            _ => None,
        }
    }

    /// The optics whose pupil images the laser coherently, if any.
    fn coherent(&self) -> Option<&Optics> {
        match self {
            Imaging::Lens { optics, speckle: true } => Some(optics),
            _ => None,
        }
    }
}

/// Rendering parameters. `Default` is the realistic sensor: a real industrial 8-bit monochrome
/// camera (full well 10 000 e⁻, read noise 6 e⁻, 8 bits over the full well, gamma 1) behind the
/// paper preset's lens ([`Optics::paper`]: F/4, 4.65 µm pixels, a 650 nm laser, 1.5 px of
/// defocus), laser speckle on, a real line laser (sheet FWHM 0.5 mm, [`REALISTIC_LASER_STRENGTH`])
/// in a mid-bright room (a white surface collects [`REALISTIC_AMBIENT_E`] = 3 000 e⁻, ≈ 77 of 255).
/// [`RenderOptions::ideal`] is the idealised sensor (Gaussian PSF σ 0.7 px, no speckle, a dim
/// room).
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Samples per axis for pixels near a stripe or an edge (n × n samples); with coherent
    /// imaging a multiple of its samples per pixel (4 or 8).
    pub supersample: u32,
    /// The lens: the PSF, and whether the laser is imaged coherently.
    pub imaging: Imaging,
    /// Full width at half maximum of the laser sheet's Gaussian profile across the light
    /// plane (mm).
    pub beam_fwhm_mm: f64,
    /// Electrons a pixel collects from a white Lambertian surface lit head-on by the laser
    /// with a fan-normalised irradiance of 1 mm⁻² (the whole fan's power on 1 mm²). Lumps laser
    /// power, exposure, aperture and quantum efficiency.
    pub laser_strength: f64,
    /// Electrons a pixel collects from a white (albedo 1) surface under the ambient light (the
    /// scene's lighting scales it from place to place).
    pub ambient_e: f64,
    /// Full-well capacity (e⁻): saturation, and the signal that maps to the largest value.
    pub full_well_e: f64,
    /// Read noise (e⁻ rms).
    pub read_noise_e: f64,
    /// Output gamma (1 = linear).
    pub gamma: f64,
    /// 8 or 16.
    pub bit_depth: u8,
    /// Photon and read noise on/off (off: a noiseless but still blurred, saturated, quantised frame).
    pub noise: bool,
    /// Noise seed; each frame derives its own stream from it and its mirror angle and facet.
    pub seed: u64,
    /// Polygon turn during the exposure (degrees); the stripe is integrated over
    /// [α − m/2, α + m/2]. 0 = a still mirror.
    pub motion_blur_deg: f64,
    /// Shape of the laser sheet's profile across the light plane ([`SheetProfile::Gaussian`] by
    /// default; [`SheetProfile::real`] is the measured real cross-section). Its peak lies on the
    /// light plane, where the ground truth is.
    pub profile: SheetProfile,
    /// Set the sheet's width per frame so that each laser's stripe is this wide (FWHM, px, the
    /// optics' blur and the pixel included) at the middle truth point of its stripe, instead of
    /// [`beam_fwhm_mm`](Self::beam_fwhm_mm). `None`: the fixed width.
    pub stripe_fwhm_px: Option<f64>,
    /// Veiling glare: a share of all light spread into a wide glow around bright parts.
    pub halo: Option<Halo>,
    /// Blooming: charge above the full well spills along the columns or rows instead of being
    /// clipped (a saturated stripe grows a flat plateau). `None`: clipped.
    pub bloom: Option<Bloom>,
    /// A colour camera (filter responses, mosaic, white balance, colour matrix, output).
    /// `None`: the monochrome camera.
    pub colour: Option<Colour>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            imaging: Imaging::Lens { optics: Optics::paper(), speckle: true },
            ambient_e: REALISTIC_AMBIENT_E,
            laser_strength: REALISTIC_LASER_STRENGTH,
            ..RenderOptions::ideal()
        }
    }
}

/// See [`RenderOptions::laser_strength`]; chosen so that the default stripe peaks at about 190
/// of 255 on the paper bench plane (measured by a test).
pub const DEFAULT_LASER_STRENGTH: f64 = 6.0e7;

/// Ambient signal of a white surface (e⁻) for checkerboard images: room lights on and the
/// exposure set so that white paper reads about 150–180 of 255, as one does for calibration.
pub const CALIBRATION_AMBIENT_E: f64 = 7000.0;

/// Ambient signal of a white surface (e⁻) in laser frames of the realistic sensor: a
/// mid-bright room (white ≈ 77 of 255 at the laser exposure).
pub const REALISTIC_AMBIENT_E: f64 = 3000.0;

/// The realistic sensor's laser: its sharper lens concentrates the stripe, so the exposure is
/// set for a mean stripe peak of about 90 DN over ambient on the bench plane, leaving room for
/// bright speckles (measured by a test).
pub const REALISTIC_LASER_STRENGTH: f64 = 0.5 * DEFAULT_LASER_STRENGTH;

impl RenderOptions {
    /// The idealised sensor: Gaussian PSF σ 0.7 px, no speckle, a dim lab (a white surface
    /// collects 2 000 e⁻, ≈ 51 of 255); camera and laser as [`Default`].
    pub fn ideal() -> Self {
        RenderOptions {
            supersample: 8,
            imaging: Imaging::Gaussian { sigma_px: 0.7 },
            beam_fwhm_mm: 0.5,
            laser_strength: DEFAULT_LASER_STRENGTH,
            ambient_e: 2000.0,
            full_well_e: 10_000.0,
            read_noise_e: 6.0,
            gamma: 1.0,
            bit_depth: 8,
            noise: true,
            seed: 0,
            motion_blur_deg: 0.0,
            profile: SheetProfile::Gaussian,
            stripe_fwhm_px: None,
            halo: None,
            bloom: None,
            colour: None,
        }
    }

    /// The realistic sensor with the room lit for checkerboard images ([`CALIBRATION_AMBIENT_E`]).
    pub fn calibration() -> Self {
        RenderOptions { ambient_e: CALIBRATION_AMBIENT_E, ..Default::default() }
    }

    /// The idealised sensor with a saturated stripe: the laser 4× stronger (the stripe clips at
    /// full scale on the bench plane).
    pub fn ideal_saturated() -> Self {
        RenderOptions { laser_strength: 4.0 * DEFAULT_LASER_STRENGTH, ..Self::ideal() }
    }

    /// The idealised sensor with a weak stripe: the laser at 40 % (≈ 60 DN above ambient on the
    /// bench plane).
    pub fn ideal_weak_stripe() -> Self {
        RenderOptions { laser_strength: 0.4 * DEFAULT_LASER_STRENGTH, ..Self::ideal() }
    }

    /// The idealised sensor in strong ambient light: 3× its own (a white surface ≈ 153 DN, the
    /// bench plane ≈ 122 DN; the stripe on top of it clips on bright surfaces).
    pub fn ideal_strong_ambient() -> Self {
        RenderOptions { ambient_e: 3.0 * Self::ideal().ambient_e, ..Self::ideal() }
    }

    /// The idealised sensor without photon and read noise.
    pub fn ideal_noiseless() -> Self {
        RenderOptions { noise: false, ..Self::ideal() }
    }

    /// The same options with the lens `optics` (laser speckle on).
    pub fn with_optics(self, optics: Optics) -> Self {
        RenderOptions { imaging: Imaging::Lens { optics, speckle: true }, ..self }
    }

    /// The same options with the real sheet profile ([`SheetProfile::real`]) at a stripe FWHM of
    /// `fwhm_px` (px, optics and pixel included) at the middle of each stripe.
    pub fn with_real_stripe(self, fwhm_px: f64) -> Self {
        RenderOptions { profile: SheetProfile::real(), stripe_fwhm_px: Some(fwhm_px), ..self }
    }

    /// The same options through a colour camera: [`CameraColour`]'s defaults with the mosaic
    /// `bayer`, the laser's response at the optics' wavelength (650 nm for the idealised sensor),
    /// delivering `output`.
    pub fn with_colour(self, bayer: Option<omni_model::BayerPattern>, output: ColourOutput) -> Self {
        let wavelength = match &self.imaging {
            Imaging::Lens { optics, .. } => optics.wavelength_nm,
            Imaging::Gaussian { .. } => 650.0,
        };
        let camera = omni_model::CameraColour { bayer, ..Default::default() };
        RenderOptions { colour: Some(Colour::new(&camera, wavelength, output)), ..self }
    }

    /// Checks that `sensor`'s camera can render these options: a lens focused at a distance
    /// needs a camera model that holds the mirror's geometry, and the blur it makes, for surfaces
    /// 50 mm to 10 m away, must stay within what the coherent imager reaches. The error names
    /// `optics.focus_mm`.
    pub fn check_sensor(&self, sensor: &Sensor) -> Result<(), String> {
        let Some(optics) = self.imaging.field_optics() else { return Ok(()) };
        let camera = sensor.camera.as_ref();
        let focus = optics.focus_mm.unwrap_or_default();
        match widest_defocus(camera, optics) {
            None => Err(format!(
                "optics.focus_mm ({focus} mm) needs a camera model that holds the mirror's geometry \
                 (hyperbolic); this camera's model does not: give one blur for the whole frame (defocus_px) instead"
            )),
            Some(widest) if widest.diameter > MAX_DEFOCUS_PX => {
                // Which way the focus moves that part of the image towards sharpness.
                let farther = optics.focused_at(focus * 1.01);
                let way = match camera.defocus_sigma_px(&widest.px, widest.distance, &farther) {
                    Some(s) if 4.0 * s < widest.diameter => "farther",
                    _ => "nearer",
                };
                Err(format!(
                    "optics.focus_mm ({focus} mm) blurs the image {:.0} px from its centre by a circle of \
                     {:.1} px, beyond the {MAX_DEFOCUS_PX} px the renderer images: focus {way} or close \
                     the lens (F/{})",
                    widest.radius, widest.diameter, optics.f_number
                ))
            }
            Some(_) => Ok(()),
        }
    }

    /// Checks values; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        let non_negative = [
            ("laser_strength", self.laser_strength),
            ("ambient_e", self.ambient_e),
            ("read_noise_e", self.read_noise_e),
            ("motion_blur_deg", self.motion_blur_deg),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be a non-negative number, got {v}"));
            }
        }
        for (name, v) in [("beam_fwhm_mm", self.beam_fwhm_mm), ("full_well_e", self.full_well_e), ("gamma", self.gamma)]
        {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a positive number, got {v}"));
            }
        }
        if !(1..=16).contains(&self.supersample) {
            return Err(format!("supersample must be in 1..=16, got {}", self.supersample));
        }
        if self.bit_depth != 8 && self.bit_depth != 16 {
            return Err(format!("bit_depth must be 8 or 16, got {}", self.bit_depth));
        }
        self.profile.validate().map_err(|e| format!("profile: {e}"))?;
        if let Some(w) = self.stripe_fwhm_px {
            if !(w.is_finite() && w > 0.0 && w <= 200.0) {
                return Err(format!("stripe_fwhm_px must be within 0–200 px, got {w}"));
            }
            let blur = (self.imaging.psf_sigma_px().powi(2) + 1.0 / 12.0).sqrt();
            if self.profile.sheet_fwhm_for_image_px(w, blur).is_none() {
                return Err(format!(
                    "stripe_fwhm_px {w} is narrower than the optics' blur alone ({:.2} px FWHM)",
                    self.profile.image_fwhm_px(1e-6, blur)
                ));
            }
        }
        if let Some(h) = &self.halo {
            h.validate().map_err(|e| format!("halo: {e}"))?;
        }
        if let Some(b) = &self.bloom {
            b.validate().map_err(|e| format!("bloom: {e}"))?;
        }
        if let Some(c) = &self.colour {
            c.validate().map_err(|e| format!("colour: {e}"))?;
        }
        match &self.imaging {
            Imaging::Gaussian { sigma_px } => {
                if !(sigma_px.is_finite() && (0.0..=10.0).contains(sigma_px)) {
                    return Err(format!("psf sigma_px must be within 0–10 px, got {sigma_px}"));
                }
            }
            Imaging::Lens { optics, speckle } => {
                optics.validate().map_err(|e| format!("optics: {e}"))?;
                let q = CoherentImager::samples_per_px(optics) as u32;
                if *speckle && optics.coherent_cutoff_per_px() > 3.0 {
                    return Err(format!(
                        "speckle needs λN ≥ 1/6 px to be sampled, got {:.3} px (F/{}): image the laser without speckle",
                        optics.lambda_n_px(),
                        optics.f_number
                    ));
                }
                if *speckle && !self.supersample.is_multiple_of(q) {
                    return Err(format!(
                        "supersample must be a multiple of {q} for speckle at F/{}, got {}",
                        optics.f_number, self.supersample
                    ));
                }
            }
        }
        Ok(())
    }

    /// σ of the laser sheet's profile (its core's) across the light plane (mm).
    pub(crate) fn beam_sigma(&self) -> f64 {
        match self.profile {
            SheetProfile::Gaussian => self.beam_fwhm_mm / (8.0 * 2f64.ln()).sqrt(),
            tailed => self.beam_fwhm_mm / tailed.fwhm_per_sigma(),
        }
    }
}

/// One light plane contributing to a frame, with its weight (motion blur splits a laser into
/// several planes).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Slice {
    pub lp: LightPlane,
    pub weight: f64,
    /// σ of the sheet's (core) profile (mm).
    pub sigma: f64,
}

/// The light planes of the given lasers at mirror angle `alpha` (radians), spread over the
/// motion-blur range, laser `lasers[i]` with the sheet σ `sigmas[i]` (mm). Lasers whose central
/// ray misses the facet are skipped.
pub(crate) fn light_slices(
    sensor: &Sensor,
    alpha: f64,
    facet: u32,
    lasers: &[u32],
    sigmas: &[f64],
    opts: &RenderOptions,
) -> Vec<Slice> {
    let blur = opts.motion_blur_deg.to_radians();
    let steps = if blur > 0.0 { ((opts.motion_blur_deg / 0.02).ceil() as usize).clamp(2, 32) } else { 1 };
    let mut out = Vec::new();
    for (&laser, &sigma) in lasers.iter().zip(sigmas) {
        for k in 0..steps {
            let a = alpha + blur * ((k as f64 + 0.5) / steps as f64 - 0.5);
            if let Some(lp) = sensor.transmitter.light_plane(a, facet, laser as usize).filter(|lp| lp.on_facet) {
                out.push(Slice { lp, weight: 1.0 / steps as f64, sigma });
            }
        }
    }
    out
}

/// Shading context for one frame.
struct Shader<'a> {
    scene: &'a Scene,
    slices: &'a [Slice],
    /// The tailed profile's shape; `None`: the Gaussian sheet.
    shape: Option<Shape>,
    /// Whether the fan's 1/r spreading and the incidence are taken on the stripe's centre line
    /// rather than at each point across the stripe, and smooth wide sheets are sampled 2 × 2
    /// (or at the coherent imager's rate) instead of n × n. On for the tailed profile and for
    /// widths set in px, which stand for a stripe widened by the optics (defocus, a beam's
    /// image), not for a sheet tens of mm thick: such a sheet would lean its stripe's peak off
    /// the plane by σ² · ∂ln(1/r)/∂d (0.2 px for a 20 px stripe on a 256 px sensor). The centre
    /// line's point is the one across the stripe *in the image* ([`Spread::centre_line`]): a
    /// surface seen obliquely maps the image's perpendicular onto a slant across the stripe,
    /// along which the fan's light changes as it does along the stripe (a 7 px stripe on a wall
    /// grazed by the fan leaned 0.25 px). The plain Gaussian's default rendering stays as it
    /// was, bit for bit.
    flat_across: bool,
    opts: &'a RenderOptions,
}

/// What a camera ray at a pixel corner sees, for deciding where to supersample.
#[derive(Clone, Copy, PartialEq)]
struct CornerKey {
    /// Object index · 4 + pattern, or `u32::MAX` for no scene (outside the mirror, no hit).
    surface: u32,
    /// Texture cell and light patches ([`Hit::class`]).
    class: u32,
    /// Bit i set if the hit is on the positive side of slice i's plane.
    sides: u64,
    /// Whether the hit lies within 4 σ of any light plane (the tailed profile: its core and
    /// the start of its tail, [`Shape::near`]).
    near: bool,
    /// Signal (e⁻) of a point sample at the corner.
    value: f64,
    /// Its laser part (e⁻).
    laser: f64,
    /// The slice whose plane is nearest in units of its σ, and the plane distance (mm).
    nearest: u32,
    dist: f64,
}

impl Shader<'_> {
    fn corner(&self, camera: &dyn omni_model::CameraModel, px: Vector2<f64>) -> CornerKey {
        let none = CornerKey {
            surface: u32::MAX,
            class: 0,
            sides: 0,
            near: false,
            value: 0.0,
            laser: 0.0,
            nearest: u32::MAX,
            dist: 0.0,
        };
        let Some(ray) = camera.pixel_to_ray(&px) else { return none };
        let Some(hit) = self.scene.cast(&ray.origin, &ray.dir, 1e-6, f64::INFINITY) else { return none };
        let mut sides = 0u64;
        let mut near = false;
        let (mut nearest, mut dist, mut best) = (u32::MAX, 0.0, f64::INFINITY);
        for (i, s) in self.slices.iter().enumerate().take(64) {
            let d = s.lp.plane.signed_distance(&hit.point);
            if (d / s.sigma).abs() < best {
                (nearest, dist, best) = (i as u32, d, (d / s.sigma).abs());
            }
            sides |= u64::from(d > 0.0) << i;
            near |= match &self.shape {
                None => d.abs() < 4.0 * s.sigma,
                Some(shape) => {
                    let (lo, hi) = shape.near(s.sigma);
                    d > lo && d < hi
                }
            };
        }
        let (value, laser) = if near {
            (0.0, 0.0)
        } else {
            let signal = self.shade(&hit, &ray.dir, |_| Spread::default());
            (signal.total(), signal.laser)
        };
        CornerKey {
            surface: hit.object as u32 * 4 + hit.pattern as u32,
            class: hit.class,
            sides,
            near,
            value,
            laser,
            nearest,
            dist,
        }
    }

    /// Electrons collected at a hit seen along `view`, ambient and laser apart; `spread(i)` is
    /// slice i's [`Spread`] at the sample (the default for a point sample).
    fn shade(&self, hit: &Hit, view: &Vector3<f64>, spread: impl Fn(usize) -> Spread) -> Signal {
        let mut laser = 0.0;
        for (i, s) in self.slices.iter().enumerate() {
            laser += s.weight * self.laser_irradiance(s, &hit.point, &hit.normal, view, spread(i));
        }
        let ambient = self.opts.ambient_e * self.scene.ambient_factor(&hit.point);
        Signal { ambient: hit.albedo * ambient, laser: hit.albedo * laser }
    }

    /// Laser signal (e⁻ for albedo 1) of one light plane at a surface point seen along `view`,
    /// with the sheet profile widened by the sample's footprint ([`Spread`]).
    fn laser_irradiance(
        &self,
        slice: &Slice,
        p: &Point3<f64>,
        n: &Vector3<f64>,
        view: &Vector3<f64>,
        spread: Spread,
    ) -> f64 {
        let footprint = spread.footprint_mm;
        let lp = &slice.lp;
        let d = lp.plane.signed_distance(p);
        let profile = match &self.shape {
            None => {
                let sigma = (slice.sigma * slice.sigma + footprint.powi(2)).sqrt();
                if d.abs() > 6.0 * sigma {
                    return 0.0;
                }
                (-0.5 * (d / sigma).powi(2)).exp() / (sigma * (2.0 * std::f64::consts::PI).sqrt())
            }
            Some(shape) => {
                let (lo, hi) = shape.support(slice.sigma, footprint);
                if d < lo || d > hi {
                    return 0.0;
                }
                shape.density(d, slice.sigma, footprint)
            }
        };
        if !lp.lights(p) {
            return 0.0;
        }
        let to_p = p - lp.virtual_source;
        let r = to_p.norm();
        let u = to_p / r;
        // The light must arrive on the side the camera looks at (thin two-sided objects).
        if u.dot(n) * view.dot(n) <= 0.0 {
            return 0.0;
        }
        if !self.path_is_clear(lp, p, &u) {
            return 0.0;
        }
        if self.flat_across {
            // The fan's spreading and the incidence on the stripe's centre line across the
            // stripe in the image from p (else where the sheet's plane crosses the surface's
            // tangent plane, along it), not at p: across the stripe the light follows the
            // sheet's profile alone, however wide the sheet (see `Shader::flat_across`).
            let p0 = spread.centre_line.unwrap_or_else(|| {
                let normal = lp.plane.normal.into_inner();
                let t = normal - n * normal.dot(n);
                let t2 = t.norm_squared();
                if t2 > 0.01 { p - t * (d / t2) } else { *p }
            });
            let to_p0 = p0 - lp.virtual_source;
            let r0 = to_p0.norm();
            let cos0 = (to_p0 / r0).dot(n).abs();
            return self.opts.laser_strength * cos0 * profile / (std::f64::consts::PI * r0);
        }
        let cos_inc = u.dot(n).abs();
        self.opts.laser_strength * cos_inc * profile / (std::f64::consts::PI * r)
    }

    /// Whether the reflected ray from the facet to `p` is unobstructed (laser shadows).
    fn path_is_clear(&self, lp: &LightPlane, p: &Point3<f64>, u: &Vector3<f64>) -> bool {
        let start = facet_exit(lp, u);
        !self.scene.occluded(&start, p, 1e-5)
    }
}

/// The farthest (in steps between neighbouring samples) that a sample's [`Spread::centre_line`]
/// is linearised: 6 σ of a 20 px stripe sampled 2 × 2 is about 100.
const CENTRE_LINE_MAX_STEPS: f64 = 200.0;

/// What a sample's patch of the pixel adds to a light plane's profile at its surface point.
#[derive(Debug, Clone, Copy, Default)]
struct Spread {
    /// σ (mm) of the plane distance over the patch.
    footprint_mm: f64,
    /// Where the stripe's centre line lies across the stripe *in the image* from the sample:
    /// the surface point at the foot of the image's perpendicular from the sample to the line
    /// where the plane distance is 0 (linearised from the neighbouring samples); `None` where
    /// the neighbours do not tell, or the light is not taken on the centre line
    /// ([`Shader::flat_across`]).
    centre_line: Option<Point3<f64>>,
}

/// Electrons of one sample: the incoherent ambient light and the laser light.
#[derive(Debug, Clone, Copy, Default)]
struct Signal {
    ambient: f64,
    laser: f64,
}

impl Signal {
    fn total(&self) -> f64 {
        self.ambient + self.laser
    }
}

/// Where the reflected ray along `u` (from the virtual source) leaves the facet.
pub(crate) fn facet_exit(lp: &LightPlane, u: &Vector3<f64>) -> Point3<f64> {
    let denom = lp.facet.normal.dot(u);
    if denom.abs() < 1e-12 {
        return lp.facet_point;
    }
    let t = -lp.facet.signed_distance(&lp.virtual_source) / denom;
    lp.virtual_source + u * t.max(0.0)
}

/// Renders the noiseless electron image, optical blur included, with adaptive supersampling.
///
/// The optics blur the continuous image before the pixels integrate it, so each sample is
/// spread with the PSF integrated over a pixel's area, K(t) = Φ((t + ½)/σ) − Φ((t − ½)/σ) per
/// axis, from its own sub-pixel position: a stripe narrower than a pixel keeps its sub-pixel
/// position in the image (blurring the pixel-integrated image instead would snap it to pixel
/// centres).
fn render_electrons(sensor: &Sensor, scene: &Scene, slices: &[Slice], opts: &RenderOptions) -> Vec<f64> {
    render_light(sensor, scene, slices, opts, false).0
}

/// [`render_electrons`], with the laser light in an image of its own when `split` (the ambient
/// light alone in the first): `(ambient or all light, laser light if split)`.
fn render_light(
    sensor: &Sensor,
    scene: &Scene,
    slices: &[Slice],
    opts: &RenderOptions,
    split: bool,
) -> (Vec<f64>, Option<Vec<f64>>) {
    let camera = sensor.camera.as_ref();
    let (w, h) = camera.image_size();
    let (w, h) = (w as usize, h as usize);
    let shape = match opts.profile {
        SheetProfile::Gaussian => None,
        tailed => Some(tailed.shape()),
    };
    let flat_across = shape.is_some() || opts.stripe_fwhm_px.is_some();
    let shader = Shader { scene, slices, shape, flat_across, opts };
    let cw = w + 1;
    let corners: Vec<CornerKey> = (0..=h)
        .into_par_iter()
        .flat_map_iter(|cy| {
            let shader = &shader;
            (0..=w).map(move |cx| shader.corner(camera, Vector2::new(cx as f64 - 0.5, cy as f64 - 0.5)))
        })
        .collect();
    let n = opts.supersample.max(1) as usize;
    let field_optics = opts.imaging.field_optics();
    let defocus = field_optics.map(|optics| pixel_defocus(camera, scene, optics, w, h));
    // Each pixel's σ level, shared by the PSFs of supersampled and of coarsely sampled pixels.
    let levels: Option<Vec<u16>> = field_optics
        .zip(defocus.as_ref())
        .map(|(optics, d)| d.par_iter().map(|d| sigma_level(optics.psf_sigma_with_defocus(*d))).collect());
    let psf = FramePsfs::new(opts.imaging.psf_sigma_px(), levels.as_deref(), n, w);
    let coherent = opts.imaging.coherent().filter(|_| !slices.is_empty());
    let q = coherent.map(CoherentImager::samples_per_px);
    // One defocus for the frame: its imager is known before the light is (and made, the first
    // time, before the frame's large buffers, which keeps the heap's peak where it was).
    let one_imager = coherent.filter(|_| defocus.is_none()).map(|o| coherent_imager(o, crate::coherent::MARGIN_PX));
    // A sheet wide against the pixel (its plane distance changing by less than σ/2 across it)
    // is smooth there: 2 × 2 samples (the coherent imager's q × q) integrate it, each box-filtered.
    let n_coarse = q.unwrap_or(2).min(n);
    let psf_coarse = FramePsfs::new(opts.imaging.psf_sigma_px(), levels.as_deref(), n_coarse, w);
    let coarse = |c: &[CornerKey; 4]| {
        if !shader.flat_across
            || c.iter().any(|k| k.nearest != c[0].nearest || k.surface != c[0].surface || k.class != c[0].class)
        {
            return false;
        }
        let Some(slice) = slices.get(c[0].nearest as usize) else { return false };
        let (lo, hi) =
            c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), k| (lo.min(k.dist), hi.max(k.dist)));
        hi - lo < 0.5 * slice.sigma
    };
    // The laser light of uniform pixels is kept apart from the ambient light when it has an image
    // of its own, or when the coherent imager must image it too (the tailed profile's tail lies
    // mostly in uniform pixels; the Gaussian's few uniform pixels 4–6 σ out stay incoherent, as
    // they always were).
    let laser_apart = split || (q.is_some() && shader.shape.is_some());
    // Pixels whose corners agree take the mean of their corners (spread later by a discrete
    // convolution); the others get a supersampled patch spread from the exact sample positions,
    // their laser light going to the coherent imager instead where there is one.
    let rows: Vec<RowResult> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut row = RowResult { centre: vec![0.0; w], ..Default::default() };
            if split {
                row.centre_laser = vec![0.0; w];
            }
            for x in 0..w {
                let c = [
                    corners[y * cw + x],
                    corners[y * cw + x + 1],
                    corners[(y + 1) * cw + x],
                    corners[(y + 1) * cw + x + 1],
                ];
                let uniform = c
                    .iter()
                    .all(|k| k.surface == c[0].surface && k.class == c[0].class && k.sides == c[0].sides && !k.near);
                if uniform && c[0].surface == u32::MAX {
                    continue;
                }
                if uniform {
                    // Same surface and pattern, far from every light plane at all four corners:
                    // the signal is smooth over the pixel and the corners' mean integrates it.
                    if !laser_apart {
                        row.centre[x] = 0.25 * c.iter().map(|k| k.value).sum::<f64>();
                        continue;
                    }
                    let laser = 0.25 * c.iter().map(|k| k.laser).sum::<f64>();
                    row.centre[x] = 0.25 * c.iter().map(|k| k.value - k.laser).sum::<f64>();
                    match q {
                        Some(q) if laser > 0.0 => {
                            row.laser.push((x, vec![CellLight::uniform(laser / (q * q) as f64, q); q * q]));
                        }
                        Some(_) => {}
                        None => row.centre_laser[x] = laser,
                    }
                    continue;
                }
                let (n, psf) = if coarse(&c) { (n_coarse, &psf_coarse) } else { (n, &psf) };
                let psf = psf.at(x, y);
                let samples = pixel_samples(&shader, camera, x as f64, y as f64, n as u32);
                match q {
                    Some(q) => {
                        let ambient: Vec<f64> = samples.iter().map(|s| s.ambient).collect();
                        row.patches.push((x, psf.radius, psf.patch(&ambient)));
                        let laser: Vec<f64> = samples.iter().map(|s| s.laser).collect();
                        if laser.iter().any(|v| *v > 0.0) {
                            row.laser.push((x, CellLight::from_samples(&laser, n, q)));
                        }
                    }
                    None if split => {
                        let ambient: Vec<f64> = samples.iter().map(|s| s.ambient).collect();
                        row.patches.push((x, psf.radius, psf.patch(&ambient)));
                        let laser: Vec<f64> = samples.iter().map(|s| s.laser).collect();
                        if laser.iter().any(|v| *v > 0.0) {
                            row.laser_patches.push((x, psf.radius, psf.patch(&laser)));
                        }
                    }
                    None => {
                        let total: Vec<f64> = samples.iter().map(Signal::total).collect();
                        row.patches.push((x, psf.radius, psf.patch(&total)));
                    }
                }
            }
            row
        })
        .collect();
    let centre: Vec<f64> = rows.iter().flat_map(|r| r.centre.iter().copied()).collect();
    let mut out = psf.convolve_centres(&centre, w, h);
    add_patches(&mut out, rows.iter().map(|r| &r.patches), w, h);
    let mut laser_out = split.then(|| {
        let centre: Vec<f64> = rows.iter().flat_map(|r| r.centre_laser.iter().copied()).collect();
        let mut img = psf.convolve_centres(&centre, w, h);
        add_patches(&mut img, rows.iter().map(|r| &r.laser_patches), w, h);
        img
    });
    if let (Some(optics), Some(q)) = (coherent, q) {
        let mut field = LaserField::new(q);
        for (y, row) in rows.iter().enumerate() {
            for (x, energies) in &row.laser {
                match &defocus {
                    None => field.add_pixel(*x, y, energies),
                    Some(d) => field.add_defocused_pixel(*x, y, energies, d[y * w + x]),
                }
            }
        }
        // With the defocus varying, the PSF reaches as far as the laser's widest blur needs.
        let imager = one_imager.unwrap_or_else(|| {
            let flat = Optics { defocus_px: 0.0, focus_mm: None, ..*optics };
            coherent_imager(&flat, CoherentImager::margin_for(field.max_tile_defocus_px()))
        });
        imager.image_into(&field, laser_out.as_mut().unwrap_or(&mut out), w, h, surface_seed(opts.seed));
    }
    (out, laser_out)
}

/// Adds each row's supersampled pixels' PSF patches (row y, column x, the PSF's radius) into
/// `out`.
fn add_patches<'a>(out: &mut [f64], rows: impl Iterator<Item = &'a Vec<Patch>>, w: usize, h: usize) {
    for (y, row) in rows.enumerate() {
        for (x, radius, patch) in row {
            let r = *radius as isize;
            let side = 2 * radius + 1;
            for dy in -r..=r {
                let yy = y as isize + dy;
                if yy < 0 || yy >= h as isize {
                    continue;
                }
                for dx in -r..=r {
                    let xx = *x as isize + dx;
                    if xx < 0 || xx >= w as isize {
                        continue;
                    }
                    out[yy as usize * w + xx as usize] += patch[(dy + r) as usize * side + (dx + r) as usize];
                }
            }
        }
    }
}

/// The coherent imager of `optics` whose PSF reaches `margin` px, built once per process for
/// each set in use.
fn coherent_imager(optics: &Optics, margin: usize) -> Arc<CoherentImager> {
    static CACHE: Mutex<Vec<(Optics, usize, Arc<CoherentImager>)>> = Mutex::new(Vec::new());
    let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, _, imager)) = cache.iter().find(|(o, m, _)| o == optics && *m == margin) {
        return imager.clone();
    }
    let imager = Arc::new(CoherentImager::with_margin(optics, margin));
    cache.push((*optics, margin, imager.clone()));
    imager
}

/// Where a lens focused at a distance blurs the mirror's image most.
struct WidestDefocus {
    /// The blur circle (px across).
    diameter: f64,
    /// Where: the pixel, its distance from the mirror circle's centre (px), and the surface's
    /// distance along its ray (mm).
    px: Vector2<f64>,
    radius: f64,
    distance: f64,
}

/// The widest blur `optics` make over the mirror's annulus (sampled every 1/64 of its width,
/// edges included, in 32 directions) for surfaces 50 mm and 10 m away; `None` if the camera model
/// does not know its defocus.
fn widest_defocus(camera: &dyn omni_model::CameraModel, optics: &Optics) -> Option<WidestDefocus> {
    let circle = camera.mirror_circle();
    let (inner, outer) = (circle.inner_radius + 0.5, circle.outer_radius - 0.5);
    let mut widest: Option<WidestDefocus> = None;
    for k in 0..=64 {
        let radius = inner + (outer - inner) * k as f64 / 64.0;
        for j in 0..32 {
            let angle = std::f64::consts::TAU * j as f64 / 32.0;
            let px = circle.centre + Vector2::new(angle.cos(), angle.sin()) * radius;
            for distance in [50.0, 1e4] {
                if let Some(sigma) = camera.defocus_sigma_px(&px, distance, optics)
                    && widest.as_ref().is_none_or(|w| 4.0 * sigma > w.diameter)
                {
                    widest = Some(WidestDefocus { diameter: 4.0 * sigma, px, radius, distance });
                }
            }
        }
    }
    widest
}

/// Each pixel's blur circle diameter (px) through `optics` focused at its focus distance: the
/// camera's defocus at the pixel's centre for the mean distance (along their rays) of what its
/// corners see. A pixel across the mirror's rim or blind centre (its centre has no ray) shows
/// the mirror's edge, which lies at the mirror, not at the scene's virtual image: the blur of
/// the mirror's own surface at its seeing corners, so that no scene light spills past the rim.
/// 0 where no corner sees anything.
fn pixel_defocus(camera: &dyn omni_model::CameraModel, scene: &Scene, optics: &Optics, w: usize, h: usize) -> Vec<f64> {
    // The corners' distances (NaN: nothing seen), kept apart from the corners' keys, which every
    // frame holds.
    let cw = w + 1;
    let distances: Vec<f32> = (0..=h)
        .into_par_iter()
        .flat_map_iter(|cy| {
            (0..=w).map(move |cx| {
                let px = Vector2::new(cx as f64 - 0.5, cy as f64 - 0.5);
                camera
                    .pixel_to_ray(&px)
                    .and_then(|ray| scene.cast(&ray.origin, &ray.dir, 1e-6, f64::INFINITY))
                    .map_or(f32::NAN, |hit| hit.t as f32)
            })
        })
        .collect();
    (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let distances = &distances;
            (0..w).map(move |x| {
                let c =
                    [y * cw + x, y * cw + x + 1, (y + 1) * cw + x, (y + 1) * cw + x + 1].map(|i| distances[i] as f64);
                let seeing = || c.iter().copied().enumerate().filter(|(_, d)| d.is_finite());
                let count = seeing().count();
                if count == 0 {
                    return 0.0;
                }
                let mean = seeing().map(|(_, d)| d).sum::<f64>() / count as f64;
                let centre = Vector2::new(x as f64, y as f64);
                let sigma = camera.defocus_sigma_px(&centre, mean, optics).unwrap_or_else(|| {
                    let corner = |i: usize| centre + Vector2::new((i % 2) as f64 - 0.5, (i / 2) as f64 - 0.5);
                    let sigmas: Vec<f64> =
                        seeing().filter_map(|(i, _)| camera.defocus_sigma_px(&corner(i), 0.0, optics)).collect();
                    sigmas.iter().sum::<f64>() / sigmas.len().max(1) as f64
                });
                (4.0 * sigma).min(MAX_DEFOCUS_PX)
            })
        })
        .collect()
}

/// A supersampled pixel's PSF patch: its column, the PSF's radius (px), the (2r+1)² values.
type Patch = (usize, usize, Vec<f64>);

/// The optical PSF of each pixel integrated over a pixel ([`PixelPsf`]): one for the frame, or,
/// where the defocus varies over the image, each pixel's own (σ rounded to [`SIGMA_STEP_PX`]).
struct FramePsfs<'a> {
    /// Indexed by σ level; only the levels in use are made.
    psfs: Vec<Option<PixelPsf>>,
    /// Each pixel's σ level ([`sigma_level`], w × h); `None`: `psfs[0]` everywhere.
    levels: Option<&'a [u16]>,
    w: usize,
}

/// The step of the per-pixel PSFs' σ (px).
const SIGMA_STEP_PX: f64 = 0.01;

/// The level of a PSF of σ `sigma` px: σ in [`SIGMA_STEP_PX`].
fn sigma_level(sigma: f64) -> u16 {
    (sigma / SIGMA_STEP_PX).round() as u16
}

impl<'a> FramePsfs<'a> {
    /// The PSF of σ `sigma` px everywhere, or, with `levels` ([`sigma_level`], w × h), each
    /// pixel's; `n` sub-samples per axis for supersampled pixels.
    fn new(sigma: f64, levels: Option<&'a [u16]>, n: usize, w: usize) -> Self {
        let Some(levels) = levels else {
            return FramePsfs { psfs: vec![Some(PixelPsf::new(sigma, n))], levels: None, w };
        };
        let mut used = vec![false; levels.iter().copied().max().unwrap_or(0) as usize + 1];
        levels.iter().for_each(|l| used[*l as usize] = true);
        let psfs = used
            .par_iter()
            .enumerate()
            .map(|(l, used)| used.then(|| PixelPsf::new(l as f64 * SIGMA_STEP_PX, n)))
            .collect();
        FramePsfs { psfs, levels: Some(levels), w }
    }

    /// The PSF of pixel (x, y).
    fn at(&self, x: usize, y: usize) -> &PixelPsf {
        let level = self.levels.map_or(0, |l| l[y * self.w + x] as usize);
        self.psfs[level].as_ref().expect("every pixel's level has its PSF")
    }

    /// Separable discrete convolution of the centre-sampled image with K (zero outside): with
    /// one PSF, the convolution; with a PSF varying slowly over the image, a gather form (each
    /// pass with the kernel of the pixel it computes), which keeps a constant field constant.
    fn convolve_centres(&self, img: &[f64], w: usize, h: usize) -> Vec<f64> {
        let rows = self.convolve_along(img, w, h, false);
        self.convolve_along(&rows, w, h, true)
    }

    /// One pass of [`Self::convolve_centres`]: along the columns if `vertical`, else the rows.
    fn convolve_along(&self, img: &[f64], w: usize, h: usize, vertical: bool) -> Vec<f64> {
        let mut out = vec![0.0; w * h];
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, o) in row.iter_mut().enumerate() {
                let psf = self.at(x, y);
                let r = psf.radius as isize;
                // The pixel's place along the pass, the pass's length, and where its line starts.
                let (at, len, stride, start) = if vertical { (y, h, w, x) } else { (x, w, 1, y * w) };
                let mut s = 0.0;
                for (i, kv) in psf.centre.iter().enumerate() {
                    let p = at as isize + i as isize - r;
                    if p >= 0 && p < len as isize {
                        s += kv * img[start + p as usize * stride];
                    }
                }
                *o = s;
            }
        });
        out
    }
}

/// One image row: centre samples of uniform pixels, (column, PSF patch) of supersampled ones,
/// and (column, q × q sample energies) of the laser light left to the coherent imager.
#[derive(Default)]
struct RowResult {
    centre: Vec<f64>,
    patches: Vec<Patch>,
    laser: Vec<(usize, Vec<CellLight>)>,
    /// With the laser light apart and no coherent imager: the laser light of uniform pixels
    /// and the laser patches of supersampled ones.
    centre_laser: Vec<f64>,
    laser_patches: Vec<Patch>,
}

/// The optical PSF (Gaussian, σ in px) integrated over a pixel: K(t) = Φ((t + ½)/σ) − Φ((t − ½)/σ).
struct PixelPsf {
    radius: usize,
    /// Spread of a uniform pixel (source: the whole pixel area) at offsets −radius..=radius.
    centre: Vec<f64>,
    /// K at offsets −radius..=radius from each of the n sub-sample positions.
    sub: Vec<Vec<f64>>,
    n: usize,
}

impl PixelPsf {
    fn new(sigma: f64, n: usize) -> Self {
        let radius = if sigma > 0.0 { (4.0 * sigma + 0.5).ceil() as usize } else { 1 };
        let k = |t: f64| {
            if sigma > 0.0 {
                let s = sigma * std::f64::consts::SQRT_2;
                0.5 * (erf((t + 0.5) / s) - erf((t - 0.5) / s))
            } else if t.abs() < 0.5 {
                1.0
            } else {
                0.0
            }
        };
        let r = radius as isize;
        let sub: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let s = (i as f64 + 0.5) / n as f64 - 0.5;
                (-r..=r).map(|o| k(o as f64 - s)).collect()
            })
            .collect();
        // A uniform pixel's light comes from its whole area, like a supersampled pixel's: its
        // kernel is the mean of the sub-sample kernels. (K at the centre alone would be narrower,
        // so a constant field crossing from uniform to supersampled pixels would show a ±3 DN
        // dip-and-bump along every light plane that a laser-off frame lacks.)
        let centre = (0..sub[0].len()).map(|o| sub.iter().map(|kernel| kernel[o]).sum::<f64>() / n as f64).collect();
        PixelPsf { radius, centre, sub, n }
    }

    /// The (2r+1)² spread of one supersampled pixel's samples (row-major n × n), each standing
    /// for 1/n² of the pixel.
    fn patch(&self, samples: &[f64]) -> Vec<f64> {
        let side = 2 * self.radius + 1;
        let mut patch = vec![0.0; side * side];
        let area = 1.0 / (self.n * self.n) as f64;
        for j in 0..self.n {
            let mut row = vec![0.0; side];
            for i in 0..self.n {
                let v = samples[j * self.n + i] * area;
                if v != 0.0 {
                    for (r, k) in row.iter_mut().zip(&self.sub[i]) {
                        *r += v * k;
                    }
                }
            }
            for (dy, ky) in self.sub[j].iter().enumerate() {
                for (dx, v) in row.iter().enumerate() {
                    patch[dy * side + dx] += ky * v;
                }
            }
        }
        patch
    }
}

/// Signal of an `n × n` grid of samples inside pixel (x, y), row-major.
///
/// Each sample stands for a 1/n × 1/n patch of the pixel. The sheet is far thinner than a
/// pixel's footprint on distant surfaces, so point samples would alias its profile; instead the
/// profile is box-filtered analytically over the patch: the plane distance d varies linearly
/// across it with the gradient measured between neighbouring samples on the same surface, and a
/// Gaussian convolved with boxes of widths a, b is, to the order that matters here, a Gaussian
/// with σ² + (a² + b²)/12 (same area, same centre).
fn pixel_samples(shader: &Shader, camera: &dyn omni_model::CameraModel, x: f64, y: f64, n: u32) -> Vec<Signal> {
    let n = n as usize;
    let sample_px = |k: usize| {
        let (i, j) = (k % n, k / n);
        Vector2::new(x + (i as f64 + 0.5) / n as f64 - 0.5, y + (j as f64 + 0.5) / n as f64 - 0.5)
    };
    let hits: Vec<Option<(Hit, Vector3<f64>)>> = (0..n * n)
        .map(|k| {
            let ray = camera.pixel_to_ray(&sample_px(k))?;
            let dir = ray.dir.into_inner();
            shader.scene.cast(&ray.origin, &dir, 1e-6, f64::INFINITY).map(|h| (h, dir))
        })
        .collect();
    let same_surface = |a: usize, b: usize| match (&hits[a], &hits[b]) {
        (Some((ha, _)), Some((hb, _))) => ha.object == hb.object && ha.normal.dot(&hb.normal) > 0.9,
        _ => false,
    };
    let mut values = vec![Signal::default(); n * n];
    for k in 0..n * n {
        let Some((hit, dir)) = &hits[k] else { continue };
        let (i, j) = (k % n, k / n);
        // Neighbour along each axis on the same surface (forward, else backward).
        let along = |step: usize, ok_fwd: bool, ok_bwd: bool| {
            if ok_fwd && same_surface(k, k + step) {
                Some(k + step)
            } else if ok_bwd && same_surface(k, k - step) {
                Some(k - step)
            } else {
                None
            }
        };
        let nx = along(1, i + 1 < n, i > 0);
        let ny = along(n, j + 1 < n, j > 0);
        let spread = |s: usize| {
            let plane = &shader.slices[s].lp.plane;
            let d0 = plane.signed_distance(&hit.point);
            // Each neighbour's step in plane distance and on the surface (the same pixel step).
            let step = |m: Option<usize>| {
                m.and_then(|m| hits[m].as_ref()).map_or((0.0, Vector3::zeros()), |(h, _)| {
                    (plane.signed_distance(&h.point) - d0, h.point - hit.point)
                })
            };
            let ((gx, px), (gy, py)) = (step(nx), step(ny));
            let g2 = gx * gx + gy * gy;
            // Not where the plane distance barely changes across the image (a surface along the
            // sheet): the foot would lie farther than the linearisation holds.
            let near = d0 * d0 <= (CENTRE_LINE_MAX_STEPS * CENTRE_LINE_MAX_STEPS) * g2;
            let centre_line =
                (shader.flat_across && g2 > 0.0 && near).then(|| hit.point - (px * gx + py * gy) * (d0 / g2));
            Spread { footprint_mm: (g2 / 12.0).sqrt(), centre_line }
        };
        values[k] = shader.shade(hit, dir, spread);
    }
    values
}

/// Photon and read noise, saturation, gamma and quantisation.
fn digitise(electrons: &[f64], w: usize, opts: &RenderOptions, frame_seed: u64) -> Vec<u16> {
    let max = if opts.bit_depth == 8 { 255.0 } else { 65535.0 };
    let mut out = vec![0u16; electrons.len()];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut e = electrons[y * w + x];
            if opts.noise {
                let mut rng = SplitMix64::pixel(frame_seed, x, y);
                e = rng.poisson(e) + opts.read_noise_e * rng.normal();
            }
            let level = (e / opts.full_well_e).clamp(0.0, 1.0).powf(1.0 / opts.gamma);
            *o = (level * max).round() as u16;
        }
    });
    out
}

fn finish(sensor: &Sensor, electrons: Vec<f64>, opts: &RenderOptions, frame_seed: u64) -> Frame16 {
    let (w, h) = sensor.camera.image_size();
    Frame16 { width: w, height: h, data: digitise(&electrons, w as usize, opts, frame_seed), bit_depth: opts.bit_depth }
}

/// The seed of the scene's surfaces' roughness: the user's seed alone. Speckle belongs to the
/// surface a camera cell sees and the light on it, not to the frame: a sensor that stands still
/// sees the same grains at every mirror angle and facet that light the same place (frames a
/// hundredth of a degree apart, one light plane from two facets), where photon noise is new.
fn surface_seed(seed: u64) -> u64 {
    mix(seed ^ 0x0050_FACE)
}

/// The noise seed of one frame: the user's seed mixed with what identifies the frame, so that
/// the frames of a scan get independent noise yet each is reproducible.
fn frame_seed(seed: u64, alpha: f64, facet: u32, lasers: &[u32]) -> u64 {
    let mut s = mix(seed ^ 0x5EED) ^ mix(alpha.to_bits()) ^ mix(0xFACE_0000 + facet as u64);
    for l in lasers {
        s = mix(s ^ (1 + *l as u64));
    }
    s
}

/// A stripe point of the ground truth: on the scene surface, exactly on the light plane, lit,
/// visible, and its exact pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthPoint {
    /// World point (mm).
    pub xyz: [f64; 3],
    /// Its pixel (x right, y down, top-left pixel centre = (0, 0)).
    pub pixel: [f64; 2],
    /// Which laser drew it.
    pub laser: u32,
}

/// A rendered laser frame with its ground truth.
#[derive(Debug, Clone)]
pub struct LaserFrame {
    /// The grey frame (values in 0..=255 for 8-bit frames): the monochrome camera's frame, a
    /// colour camera's raw Bayer mosaic ([`ColourOutput::Raw`]), or the luma of its RGB frame.
    pub image: Frame16,
    /// A colour camera's RGB frame ([`ColourOutput::Rgb`]).
    pub colour: Option<RgbFrame>,
    /// Dense samples (≤ 0.25 px apart) along each visible stripe curve, laser by laser, ordered
    /// along the curve; split into curves with [`crate::truth_polylines`]. Each lies on its light
    /// plane: the peak of the sheet's profile.
    pub truth: Vec<TruthPoint>,
    /// The sheet's FWHM across the light plane (mm) of each laser asked for, in order: the
    /// options' [`beam_fwhm_mm`](RenderOptions::beam_fwhm_mm), or the width that
    /// [`stripe_fwhm_px`](RenderOptions::stripe_fwhm_px) chose for this frame.
    pub sheet_fwhm_mm: Vec<f64>,
}

/// Renders the frame taken at mirror angle `alpha` (radians, within the facet) with laser 0 on
/// facet `facet` and the given lasers on, with its ground truth (always the still mirror at
/// `alpha`, also under motion blur).
///
/// Panics if `opts` is invalid (see [`RenderOptions::validate`] and
/// [`RenderOptions::check_sensor`]) or `alpha_rad` is not finite.
/// Lasers the transmitter does not have, or whose central ray misses the facet, stay dark.
pub fn render_laser_frame(
    sensor: &Sensor,
    scene: &Scene,
    alpha_rad: f64,
    facet: u32,
    lasers: &[u32],
    opts: &RenderOptions,
) -> LaserFrame {
    if let Err(e) = opts.validate().and_then(|()| opts.check_sensor(sensor)) {
        panic!("invalid RenderOptions: {e}");
    }
    assert!(alpha_rad.is_finite(), "render_laser_frame: mirror angle must be finite, got {alpha_rad}");
    let truth = crate::truth::stripe_truth(sensor, scene, alpha_rad, facet, lasers);
    let sigmas = sheet_sigmas(sensor, scene, alpha_rad, facet, lasers, &truth, opts);
    let slices = light_slices(sensor, alpha_rad, facet, lasers, &sigmas, opts);
    let seed = frame_seed(opts.seed, alpha_rad, facet, lasers);
    let (image, colour) = capture_frame(sensor, scene, &slices, opts, seed);
    let per_sigma = opts.beam_fwhm_mm / opts.beam_sigma();
    let sheet_fwhm_mm = sigmas.iter().map(|s| s * per_sigma).collect();
    LaserFrame { image, colour, truth, sheet_fwhm_mm }
}

/// The sheet's σ (mm) for each laser: the options' width, or the width that gives each stripe
/// [`RenderOptions::stripe_fwhm_px`] at the middle truth point of its stripe.
fn sheet_sigmas(
    sensor: &Sensor,
    scene: &Scene,
    alpha_rad: f64,
    facet: u32,
    lasers: &[u32],
    truth: &[TruthPoint],
    opts: &RenderOptions,
) -> Vec<f64> {
    let Some(target) = opts.stripe_fwhm_px else { return vec![opts.beam_sigma(); lasers.len()] };
    let per_sigma = opts.beam_fwhm_mm / opts.beam_sigma();
    lasers
        .iter()
        .map(|&laser| {
            let points: Vec<&TruthPoint> = truth.iter().filter(|t| t.laser == laser).collect();
            let mid = points.len() / 2;
            // The middle point, else the nearest one to it whose neighbourhood is one surface.
            let scale = (0..points.len()).find_map(|k| {
                let i = if k % 2 == 0 { mid + k / 2 } else { mid.checked_sub(k / 2 + 1)? };
                let t = points.get(i)?;
                let g = sheet_gradient_at(sensor, scene, alpha_rad, facet, t)?;
                Some(((g[0] * g[0] + g[1] * g[1]).sqrt(), blur_at(sensor, t, opts)))
            });
            match scale
                .and_then(|(mm_per_px, blur)| Some((mm_per_px, opts.profile.sheet_fwhm_for_image_px(target, blur)?)))
            {
                Some((mm_per_px, px)) => px * mm_per_px / per_sigma,
                None => opts.beam_sigma(),
            }
        })
        .collect()
}

/// The largest turn (degrees) of a surface's normal over a quarter pixel that
/// [`sheet_gradient_at`] counts as one surface.
const SAME_SURFACE_DEG: f64 = 5.0;

/// How the distance from a truth point's light plane changes across the image at its pixel: the
/// gradient (mm per px) of the plane distance of the surface each pixel sees, pointing across
/// the stripe towards the plane's normal side (the side of a [`SheetProfile::Tailed`] tail with
/// `tail_side` 1); its length is the sheet's mm per px there. `None` where the pixels around it
/// do not all see the truth point's surface (a silhouette or an edge), or the plane is missing.
pub fn sheet_gradient_at(
    sensor: &Sensor,
    scene: &Scene,
    alpha_rad: f64,
    facet: u32,
    t: &TruthPoint,
) -> Option<[f64; 2]> {
    let lp = sensor.transmitter.light_plane(alpha_rad, facet, t.laser as usize)?;
    let camera = sensor.camera.as_ref();
    let h = 0.25;
    let cast = |dx: f64, dy: f64| {
        let ray = camera.pixel_to_ray(&Vector2::new(t.pixel[0] + dx, t.pixel[1] + dy))?;
        scene.cast(&ray.origin, &ray.dir, 1e-6, f64::INFINITY)
    };
    // The surface the truth point lies on, seen through its own pixel.
    let centre = Point3::from(t.xyz);
    let own = cast(0.0, 0.0).filter(|hit| (hit.point - centre).norm() < 1e-3 * (1.0 + centre.coords.norm()))?;
    let seen = |dx: f64, dy: f64| -> Option<f64> {
        let hit = cast(dx, dy)?;
        // The same surface: the same object, its normal turned by less than SAME_SURFACE_DEG
        // over the quarter pixel (a curved surface turns by far less; an edge by far more).
        let same = hit.object == own.object && hit.normal.dot(&own.normal) > SAME_SURFACE_DEG.to_radians().cos();
        same.then(|| lp.plane.signed_distance(&hit.point))
    };
    let gx = (seen(h, 0.0)? - seen(-h, 0.0)?) / (2.0 * h);
    let gy = (seen(0.0, h)? - seen(0.0, -h)?) / (2.0 * h);
    Some([gx, gy])
}

/// Where the stripe's peak lies in the image near truth point `t` once the optics have blurred
/// it: the truth pixel moved along the sheet gradient by the blur's pull on an asymmetric profile
/// ([`SheetProfile::blurred_peak_offset_px`], towards the tail; 0 for the Gaussian), for the
/// sheet of FWHM `sheet_fwhm_mm` ([`LaserFrame::sheet_fwhm_mm`]) rendered with `opts` (the PSF's
/// best Gaussian and the pixel's area). `None` where [`sheet_gradient_at`] is.
pub fn blurred_peak_at(
    sensor: &Sensor,
    scene: &Scene,
    alpha_rad: f64,
    facet: u32,
    t: &TruthPoint,
    sheet_fwhm_mm: f64,
    opts: &RenderOptions,
) -> Option<[f64; 2]> {
    let g = sheet_gradient_at(sensor, scene, alpha_rad, facet, t)?;
    let mm_per_px = (g[0] * g[0] + g[1] * g[1]).sqrt();
    let blur = blur_at(sensor, t, opts);
    let (pull, side) = match opts.profile {
        SheetProfile::Gaussian => (0.0, 1.0),
        p @ SheetProfile::Tailed { tail_side, .. } => {
            (p.blurred_peak_offset_px(sheet_fwhm_mm / mm_per_px, blur), f64::from(tail_side))
        }
    };
    let k = side * pull / mm_per_px;
    Some([t.pixel[0] + k * g[0], t.pixel[1] + k * g[1]])
}

/// σ (px) of the optics' blur and the pixel's area at truth point `t`.
fn blur_at(sensor: &Sensor, t: &TruthPoint, opts: &RenderOptions) -> f64 {
    let camera = sensor.camera.as_ref();
    let px = Vector2::new(t.pixel[0], t.pixel[1]);
    let distance = camera.pixel_to_ray(&px).map_or(f64::INFINITY, |ray| (Point3::from(t.xyz) - ray.origin).norm());
    (opts.imaging.psf_sigma_at(camera, &px, distance).powi(2) + 1.0 / 12.0).sqrt()
}

/// The frame a camera delivers from the light of `slices` in `scene`: its grey frame and, for
/// RGB output, its colour frame.
fn capture_frame(
    sensor: &Sensor,
    scene: &Scene,
    slices: &[Slice],
    opts: &RenderOptions,
    seed: u64,
) -> (Frame16, Option<RgbFrame>) {
    if opts.halo.is_none() && opts.bloom.is_none() && opts.colour.is_none() {
        let electrons = render_electrons(sensor, scene, slices, opts);
        return (finish(sensor, electrons, opts, seed), None);
    }
    let (main, laser) = render_light(sensor, scene, slices, opts, opts.colour.is_some());
    let (w, h) = sensor.camera.image_size();
    crate::capture::capture(main, laser, w as usize, h as usize, opts, seed)
}

/// Renders the frame with all lasers off (ambient light only): the grey frame of
/// [`render_ambient_images`].
///
/// Panics if `opts` is invalid (see [`RenderOptions::validate`]).
pub fn render_ambient_frame(sensor: &Sensor, scene: &Scene, opts: &RenderOptions) -> Frame16 {
    render_ambient_images(sensor, scene, opts).0
}

/// Renders the frame with all lasers off (ambient light only): the grey frame and, for a colour
/// camera's RGB output, the colour frame (as [`LaserFrame`]).
///
/// Panics if `opts` is invalid (see [`RenderOptions::validate`] and
/// [`RenderOptions::check_sensor`]).
pub fn render_ambient_images(sensor: &Sensor, scene: &Scene, opts: &RenderOptions) -> (Frame16, Option<RgbFrame>) {
    if let Err(e) = opts.validate().and_then(|()| opts.check_sensor(sensor)) {
        panic!("invalid RenderOptions: {e}");
    }
    let seed = frame_seed(opts.seed, f64::NAN, u32::MAX, &[]);
    capture_frame(sensor, scene, &[], opts, seed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pixel's noise is its own: in rows of low counts, whose Poisson draws take as many
    /// uniforms as their counts need, changing one pixel's expected light changes no other
    /// pixel's digitised value (frames rendered before and after a change to the optics'
    /// last bits differ only where the light did).
    #[test]
    fn one_pixels_light_changes_no_other_pixels_noise() {
        let (w, h) = (64, 3);
        let opts = RenderOptions { bit_depth: 16, full_well_e: 400.0, read_noise_e: 2.0, ..RenderOptions::default() };
        assert!(opts.noise);
        let electrons: Vec<f64> = (0..w * h).map(|k| 5.0 + (k % 17) as f64).collect();
        let before = digitise(&electrons, w, &opts, 7);
        for changed in [0, 30, w + 5] {
            let mut moved = electrons.clone();
            moved[changed] += 20.0;
            let after = digitise(&moved, w, &opts, 7);
            let differing: Vec<usize> = (0..w * h).filter(|&k| k != changed && after[k] != before[k]).collect();
            assert!(differing.is_empty(), "pixel {changed} moved pixels {differing:?}");
        }
        // The noise is there: the same light digitised under another seed differs.
        let other = digitise(&electrons, w, &opts, 8);
        assert!(other.iter().zip(&before).filter(|(a, b)| a != b).count() > w * h / 2);
    }

    /// Per-pixel streams are independent: a flat field's digitised counts have Poisson's mean and
    /// variance plus the read noise's, and no correlation between neighbours along a row or a
    /// column (standard errors 0.004 for 65 536 pixels).
    #[test]
    fn a_flat_fields_noise_has_its_moments_and_no_correlation() {
        let (w, h) = (256, 256);
        // One electron per DN (full well 65 535 at 16 bits, gamma 1): counts read back directly.
        let opts = RenderOptions {
            bit_depth: 16,
            full_well_e: 65_535.0,
            read_noise_e: 2.0,
            gamma: 1.0,
            ..RenderOptions::default()
        };
        let light = 12.0;
        let counts: Vec<f64> = digitise(&vec![light; w * h], w, &opts, 3).iter().map(|&v| v as f64).collect();
        let n = counts.len() as f64;
        let mean = counts.iter().sum::<f64>() / n;
        let var = counts.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / n;
        // Rounding to whole DN adds 1/12.
        let expected_var = light + 4.0 + 1.0 / 12.0;
        assert!((mean - light).abs() < 0.05, "mean {mean}");
        assert!((var / expected_var - 1.0).abs() < 0.03, "variance {var}, expected {expected_var}");
        let correlation = |step: usize| {
            let pairs = (0..w * h).filter(|&k| k + step < w * h && (step == w || k % w + step < w));
            let (sum, count) =
                pairs.fold((0.0, 0.0), |(s, c), k| (s + (counts[k] - mean) * (counts[k + step] - mean), c + 1.0));
            sum / count / var
        };
        for step in [1, 2, w] {
            let r = correlation(step);
            assert!(r.abs() < 0.02, "correlation {r} at a step of {step} px");
        }
    }

    #[test]
    fn pixel_psf_preserves_energy_and_centre() {
        let psf = PixelPsf::new(0.7, 8);
        // One sample lit off-centre: the patch keeps its energy and its sub-pixel position.
        let mut samples = vec![0.0; 64];
        samples[3 * 8 + 6] = 64.0;
        let patch = psf.patch(&samples);
        let side = 2 * psf.radius + 1;
        let sum: f64 = patch.iter().sum();
        assert!((sum - 1.0).abs() < 1e-6, "sum {sum}");
        let r = psf.radius as f64;
        let cx: f64 = patch.iter().enumerate().map(|(k, v)| v * ((k % side) as f64 - r)).sum::<f64>() / sum;
        let cy: f64 = patch.iter().enumerate().map(|(k, v)| v * ((k / side) as f64 - r)).sum::<f64>() / sum;
        assert!((cx - (6.5 / 8.0 - 0.5)).abs() < 1e-4 && (cy - (3.5 / 8.0 - 0.5)).abs() < 1e-4, "{cx} {cy}");
        assert!((erf(0.5) - 0.520_499_877_8).abs() < 2e-7 && (erf(-1.5) + 0.966_105_146_5).abs() < 2e-7);
    }

    #[test]
    fn uniform_and_supersampled_pixels_spread_a_constant_field_alike() {
        // A constant field must stay constant where uniform pixels meet supersampled ones (the
        // band around every light plane): the two spreads must be the same kernel.
        let psf = PixelPsf::new(0.7, 8);
        let patch = psf.patch(&[3.0; 64]);
        let side = 2 * psf.radius + 1;
        for (k, v) in patch.iter().enumerate() {
            let uniform = 3.0 * psf.centre[k / side] * psf.centre[k % side];
            assert!((v - uniform).abs() < 1e-12, "offset {k}: supersampled {v}, uniform {uniform}");
        }
    }

    /// A pixel across the mirror's rim (its centre beyond it, a corner inside) shows the
    /// mirror's edge, blurred as the mirror's surface is (a 3.9 px circle focused at 91 mm, where
    /// the scene inside the rim is blurred by 17 px). The scene's blurred light still reaches a
    /// little past the rim (1.3 % of the level inside at 3–12 px, measured; under 2 % asserted),
    /// and none beyond 12 px (under 0.1 %).
    #[test]
    fn pixels_across_the_rim_show_the_mirrors_edge() {
        let sensor = Sensor::paper();
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata/scenes/room.json");
        let scene = Scene::load(std::path::Path::new(path)).unwrap();
        let optics = Optics::paper().focused_at(91.0);
        let camera = sensor.camera.as_ref();
        let (w, h) = (1024usize, 1024usize);
        let defocus = pixel_defocus(camera, &scene, &optics, w, h);
        let circle = camera.mirror_circle();
        let edge = Vector2::new(circle.centre.x + circle.outer_radius - 0.5, circle.centre.y);
        let edge_blur = 4.0 * camera.defocus_sigma_px(&edge, 0.0, &optics).unwrap();
        let radius = |x: usize, y: usize| (Vector2::new(x as f64, y as f64) - circle.centre).norm();
        let band = |lo: f64, hi: f64| {
            (0..h)
                .flat_map(move |y| (0..w).map(move |x| (x, y)))
                .filter(move |&(x, y)| (lo..hi).contains(&(radius(x, y) - circle.outer_radius)))
        };
        let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let across: Vec<f64> = band(0.0, 0.7).map(|(x, y)| defocus[y * w + x]).filter(|d| *d > 0.0).collect();
        let n = across.len();
        let (across, inside) = (mean(across), mean(band(-3.0, -1.0).map(|(x, y)| defocus[y * w + x]).collect()));
        eprintln!(
            "{n} pixels across the rim: blur circle {across:.2} px (the mirror's {edge_blur:.2}), inside {inside:.2} px"
        );
        assert!(n > 500 && (across / edge_blur - 1.0).abs() < 0.05 && inside > 3.0 * across);
        let opts = RenderOptions {
            noise: false,
            bit_depth: 16,
            full_well_e: 1e5,
            ..RenderOptions::default().with_optics(optics)
        };
        let frame = render_ambient_frame(&sensor, &scene, &opts);
        let level = |lo: f64, hi: f64| mean(band(lo, hi).map(|(x, y)| frame.data[y * w + x] as f64).collect());
        let (near, far, within) = (level(3.0, 12.0), level(12.0, 20.0), level(-12.0, -3.0));
        eprintln!("ambient level outside the rim: 3–12 px {near:.2}, 12–20 px {far:.3}; inside {within:.1}");
        assert!(near < 0.02 * within && far < 0.001 * within, "outside {near:.2} / {far:.3}, inside {within:.1}");
    }
}
