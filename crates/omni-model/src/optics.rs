//! The camera's lens and sensor optics: what sets the blur and the laser speckle of its images.
//!
//! The image-side quantities follow from three numbers, the wavelength λ, the lens F-number N
//! and the pixel pitch p (scalar diffraction, a circular pupil, image-side NA = 1/(2N)):
//! * the coherent cutoff frequency of the pupil, 1/(2λN) (cycles per µm, × p per pixel);
//! * the speckle grain, ≈ λN (the correlation width of a speckle pattern imaged through the pupil);
//! * the diffraction PSF, an Airy pattern whose best-fitting Gaussian has σ = 0.42 λN;
//! * defocus, a blur circle of diameter d (a uniform disc, σ = d/4), i.e. a wavefront error
//!   W₂₀ = d / (8N) at the pupil's edge.
//!
//! Speckle diversity: a matte surface depolarises the light it scatters, so its image is the sum
//! of two independent speckle patterns (one per polarisation) and the speckle contrast is 1/√2
//! instead of 1 (Goodman, *Speckle Phenomena in Optics*, 2007, §3.1 and §5.2). A diode laser's
//! spectral width (≈ 1 nm) would decorrelate speckle only on a surface whose height spread nears
//! its coherence length λ²/Δλ (≈ 0.4 mm at 650 nm), so it is not counted.

use serde::{Deserialize, Serialize};

/// Lens and sensor optics of a camera (units in the field names).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Optics {
    /// Laser wavelength (nm).
    pub wavelength_nm: f64,
    /// Lens working F-number (image side).
    pub f_number: f64,
    /// Pixel pitch (µm).
    pub pixel_pitch_um: f64,
    /// Defocus: the diameter of the geometric blur circle (px); 0 = in focus. One figure for
    /// the whole image; 0 when `focus_mm` is given.
    #[serde(default)]
    pub defocus_px: f64,
    /// The distance (mm) from the lens, along its axis, of the plane it is focused on. Given,
    /// the defocus varies over the image and with the scene's depth as the camera's geometry
    /// makes it (a catadioptric camera sees the mirror's virtual image of the scene, a curved
    /// surface, so it is sharp along one ring only): see
    /// [`CameraModel::defocus_sigma_px`](crate::CameraModel::defocus_sigma_px).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_mm: Option<f64>,
    /// Independent speckle patterns that add in intensity (2 for a depolarising matte surface,
    /// 1 for a polarisation-preserving one); the speckle contrast is 1/√n.
    #[serde(default = "default_speckle_patterns")]
    pub speckle_patterns: u32,
}

fn default_speckle_patterns() -> u32 {
    2
}

/// The Gaussian σ that best fits the Airy intensity pattern, in units of λN.
const AIRY_GAUSS_SIGMA: f64 = 0.42;

impl Optics {
    /// The paper preset's plausible lens for a 1024² industrial sensor: a red line laser
    /// (650 nm), an F/4 lens on 4.65 µm pixels, focused to a blur circle of 1.5 px (a
    /// catadioptric image cannot be sharp everywhere: the mirror's virtual image of the scene is
    /// curved), a matte depolarising scene.
    pub fn paper() -> Optics {
        Optics {
            wavelength_nm: 650.0,
            f_number: 4.0,
            pixel_pitch_um: 4.65,
            defocus_px: 1.5,
            focus_mm: None,
            speckle_patterns: 2,
        }
    }

    /// Checks ranges; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.wavelength_nm.is_finite() && (200.0..=2000.0).contains(&self.wavelength_nm)) {
            return Err(format!("wavelength_nm must be within 200–2000 nm, got {}", self.wavelength_nm));
        }
        if !(self.f_number.is_finite() && self.f_number > 0.0) {
            return Err(format!("f_number must be a positive number, got {}", self.f_number));
        }
        if !(self.f_number >= 0.7 && self.f_number <= 64.0) {
            return Err(format!("f_number must be within 0.7–64, got {}", self.f_number));
        }
        if !(self.pixel_pitch_um.is_finite() && self.pixel_pitch_um > 0.0 && self.pixel_pitch_um <= 100.0) {
            return Err(format!("pixel_pitch_um must be within (0, 100] µm, got {}", self.pixel_pitch_um));
        }
        if !(self.defocus_px.is_finite() && (0.0..=8.0).contains(&self.defocus_px)) {
            return Err(format!("defocus_px must be within 0–8 px, got {}", self.defocus_px));
        }
        if let Some(focus) = self.focus_mm {
            if !(focus.is_finite() && focus > 0.0 && focus <= 1e6) {
                return Err(format!("focus_mm must be within (0, 1e6] mm, got {focus}"));
            }
            if self.defocus_px != 0.0 {
                return Err(format!(
                    "defocus_px ({}) and focus_mm ({focus}) exclude each other: with a focus distance \
                     the defocus follows from the camera's geometry",
                    self.defocus_px
                ));
            }
        }
        if !(1..=16).contains(&self.speckle_patterns) {
            return Err(format!("speckle_patterns must be within 1–16, got {}", self.speckle_patterns));
        }
        Ok(())
    }

    /// λN in pixels: the speckle grain and the scale of diffraction.
    pub fn lambda_n_px(&self) -> f64 {
        self.wavelength_nm * 1e-3 * self.f_number / self.pixel_pitch_um
    }

    /// The pupil's coherent cutoff frequency (cycles per pixel): amplitude frequencies above it
    /// do not pass the lens.
    pub fn coherent_cutoff_per_px(&self) -> f64 {
        0.5 / self.lambda_n_px()
    }

    /// σ of the Gaussian that best fits the diffraction PSF (px).
    pub fn diffraction_sigma_px(&self) -> f64 {
        AIRY_GAUSS_SIGMA * self.lambda_n_px()
    }

    /// Radius (mm) of the lens's entrance pupil for a camera whose focal length is `f_px`
    /// pixels: the working F-number is image-side, N = f / (2 R).
    pub fn pupil_radius_mm(&self, f_px: f64) -> f64 {
        self.focal_length_mm(f_px) / (2.0 * self.f_number)
    }

    /// The same optics focused on the plane `focus_mm` ahead of the lens (mm), the defocus then
    /// varying over the image (`defocus_px` 0).
    pub fn focused_at(self, focus_mm: f64) -> Optics {
        Optics { defocus_px: 0.0, focus_mm: Some(focus_mm), ..self }
    }

    /// σ of the optical PSF (px) with a blur circle of `defocus_px` across: diffraction and
    /// that defocus.
    pub fn psf_sigma_with_defocus(&self, defocus_px: f64) -> f64 {
        self.diffraction_sigma_px().hypot(defocus_px / 4.0)
    }

    /// Whether the defocus varies over the image (a focus distance is given) rather than being
    /// the one figure `defocus_px`.
    pub fn field_dependent(&self) -> bool {
        self.focus_mm.is_some()
    }

    /// σ of the optical PSF, diffraction and the constant defocus `defocus_px` (px); the pixel
    /// area comes on top. With a focus distance this is the sharpest the image gets.
    pub fn psf_sigma_px(&self) -> f64 {
        self.psf_sigma_with_defocus(self.defocus_px)
    }

    /// The same optics with the defocus that makes the optical PSF's σ equal `sigma_px`; an error
    /// if that is below the diffraction limit.
    pub fn with_psf_sigma(self, sigma_px: f64) -> Result<Optics, String> {
        let diffraction = self.diffraction_sigma_px();
        if !(sigma_px.is_finite() && sigma_px >= diffraction) {
            return Err(format!(
                "a blur of {sigma_px} px is below the diffraction limit of F/{} at {} nm on {} µm pixels \
                 (σ {diffraction:.3} px)",
                self.f_number, self.wavelength_nm, self.pixel_pitch_um
            ));
        }
        Ok(Optics { defocus_px: 4.0 * (sigma_px * sigma_px - diffraction * diffraction).sqrt(), ..self })
    }

    /// Defocus as the wavefront error at the pupil's edge, in waves: W₂₀ = d / (8N) / λ.
    pub fn defocus_waves(&self) -> f64 {
        self.defocus_px * self.pixel_pitch_um / (8.0 * self.f_number) / (self.wavelength_nm * 1e-3)
    }

    /// The speckle contrast of the light reaching the lens: 1/√(independent patterns).
    pub fn speckle_contrast(&self) -> f64 {
        1.0 / (self.speckle_patterns as f64).sqrt()
    }

    /// Dorsch, Häusler and Herrmann (Appl. Opt. 33:1306, 1994): the speckle-limited uncertainty
    /// of a resolved laser spot's image position, C·λ / (2π sin u) with sin u = 1/(2N), i.e.
    /// C·λN/π (px).
    pub fn dorsch_sigma_px(&self) -> f64 {
        self.speckle_contrast() * self.lambda_n_px() / std::f64::consts::PI
    }

    /// The lens focal length (mm) of a camera whose focal length is `f_px` pixels.
    pub fn focal_length_mm(&self, f_px: f64) -> f64 {
        f_px * self.pixel_pitch_um * 1e-3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_optics_have_the_textbook_scales() {
        let o = Optics::paper();
        o.validate().unwrap();
        // λN = 2.6 µm = 0.559 px; Dorsch at C = 1/√2: 0.126 px; f = 1950 px → 9.07 mm.
        assert!((o.lambda_n_px() - 2.6 / 4.65).abs() < 1e-12);
        assert!((o.dorsch_sigma_px() - 2.6 / 4.65 / std::f64::consts::PI / 2f64.sqrt()).abs() < 1e-12);
        assert!((o.focal_length_mm(1950.0) - 9.0675).abs() < 1e-9);
        let sharp = Optics { defocus_px: 0.0, ..o };
        assert!((sharp.psf_sigma_px() - 0.42 * 2.6 / 4.65).abs() < 1e-12);
        let blurred = o.with_psf_sigma(1.2).unwrap();
        assert!((blurred.psf_sigma_px() - 1.2).abs() < 1e-12);
        assert!(o.with_psf_sigma(0.1).unwrap_err().contains("diffraction limit"));
    }

    #[test]
    fn bad_optics_name_the_field() {
        let o = Optics::paper();
        for (bad, field) in [
            (Optics { f_number: 0.0, ..o }, "f_number"),
            (Optics { f_number: -2.0, ..o }, "f_number"),
            (Optics { wavelength_nm: 100.0, ..o }, "wavelength_nm"),
            (Optics { wavelength_nm: 2500.0, ..o }, "wavelength_nm"),
            (Optics { pixel_pitch_um: 0.0, ..o }, "pixel_pitch_um"),
            (Optics { pixel_pitch_um: f64::NAN, ..o }, "pixel_pitch_um"),
            (Optics { speckle_patterns: 0, ..o }, "speckle_patterns"),
            (Optics { focus_mm: Some(-1.0), defocus_px: 0.0, ..o }, "focus_mm"),
            (Optics { focus_mm: Some(f64::INFINITY), defocus_px: 0.0, ..o }, "focus_mm"),
            (Optics { focus_mm: Some(90.0), ..o }, "exclude each other"),
        ] {
            let e = bad.validate().unwrap_err();
            assert!(e.contains(field), "{e}");
        }
    }
}
