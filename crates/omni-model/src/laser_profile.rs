//! A line laser's irradiance across its light sheet: a Gaussian core with a one-sided
//! exponential tail, `(1 − w)·N(σ) + w·(N(σ) ∗ Exp(τ))`, τ = `tail_length`·σ, the tail on one
//! side of the sheet along its whole length (w = 0: a Gaussian). Both components have unit
//! area. The family is closed under Gaussian blur (σ² adds, τ stays), which is how optics,
//! pixels and sampling kernels widen a stripe's image: the renderer draws sheets with it and the
//! stripe detector, told a laser's shape, predicts where a blurred stripe's top lies from the
//! sheet's peak.
//!
//! Units: offsets and widths in core σ (of the unblurred sheet), positive towards the tail.

/// A laser sheet's cross-section (module docs), with its mode and FWHM for a core σ of 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserProfile {
    tail_weight: f64,
    tail_length: f64,
    mode: f64,
    fwhm: f64,
}

/// FWHM of a Gaussian in units of its σ: √(8 ln 2).
pub const GAUSS_FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949;

impl LaserProfile {
    /// The profile with a share `tail_weight` of its light in a tail `tail_length` core σ long.
    pub fn tailed(tail_weight: f64, tail_length: f64) -> LaserProfile {
        let mut p = LaserProfile { tail_weight, tail_length, mode: 0.0, fwhm: GAUSS_FWHM_PER_SIGMA };
        if tail_weight > 0.0 {
            p.mode = p.mode_at(1.0);
            let (lo, hi) = p.half_points(1.0);
            p.fwhm = hi - lo;
        }
        p
    }

    /// A Gaussian sheet.
    pub fn gaussian() -> LaserProfile {
        LaserProfile::tailed(0.0, 1.0)
    }

    /// Share of the light in the tail (0 ≤ w ≤ 0.9).
    pub fn tail_weight(&self) -> f64 {
        self.tail_weight
    }

    /// The tail's decay length τ in core σ (> 0).
    pub fn tail_length(&self) -> f64 {
        self.tail_length
    }

    /// Checks the parameters; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.tail_weight.is_finite() && (0.0..=0.9).contains(&self.tail_weight)) {
            return Err(format!("tail_weight must be within 0–0.9, got {}", self.tail_weight));
        }
        if !(self.tail_length.is_finite() && (0.05..=50.0).contains(&self.tail_length)) {
            return Err(format!("tail_length must be within 0.05–50 (in core σ), got {}", self.tail_length));
        }
        Ok(())
    }

    /// The unblurred profile's mode (its peak, where the light plane lies) from the core's
    /// centre, in core σ.
    pub fn mode(&self) -> f64 {
        self.mode
    }

    /// The unblurred profile's FWHM in core σ.
    pub fn fwhm(&self) -> f64 {
        self.fwhm
    }

    /// Unit-area profile of core σ 1 widened to σ `s` (≥ 1), at `x` from the core's centre
    /// towards the tail.
    pub fn unit(&self, x: f64, s: f64) -> f64 {
        let core = (-0.5 * (x / s).powi(2)).exp() / (s * (2.0 * std::f64::consts::PI).sqrt());
        if self.tail_weight == 0.0 {
            core
        } else {
            (1.0 - self.tail_weight) * core + self.tail_weight * emg(x, s, self.tail_length)
        }
    }

    /// The mode of the profile widened to σ `s`, from the core's centre.
    pub fn mode_at(&self, s: f64) -> f64 {
        if self.tail_weight == 0.0 {
            return 0.0;
        }
        // Golden-section search: the mode lies between the core's centre and one core σ towards
        // the tail for any tail that leaves a single peak, and the profile is unimodal there.
        let (mut a, mut b) = (-0.5 * s, 2.0 * s);
        let g = 0.5 * (5f64.sqrt() - 1.0);
        let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
        let (mut fc, mut fd) = (self.unit(c, s), self.unit(d, s));
        for _ in 0..120 {
            if fc > fd {
                b = d;
                d = c;
                fd = fc;
                c = b - g * (b - a);
                fc = self.unit(c, s);
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + g * (b - a);
                fd = self.unit(d, s);
            }
        }
        0.5 * (a + b)
    }

    /// The half-maximum points (lower, upper) of the profile widened to σ `s`, from the core's
    /// centre towards the tail.
    pub fn half_points(&self, s: f64) -> (f64, f64) {
        let m = self.mode_at(s);
        let half = 0.5 * self.unit(m, s);
        let solve = |mut inside: f64, mut outside: f64| {
            for _ in 0..100 {
                let mid = 0.5 * (inside + outside);
                if self.unit(mid, s) > half {
                    inside = mid;
                } else {
                    outside = mid;
                }
            }
            0.5 * (inside + outside)
        };
        (solve(m, m - 10.0 * s), solve(m, m + 10.0 * s + 20.0 * self.tail_length))
    }
}

/// `SHARE,LENGTH`: [`LaserProfile::tailed`], checked (the message names the bad part).
impl std::str::FromStr for LaserProfile {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        let [share, length] = parts[..] else {
            return Err(format!("expected SHARE,LENGTH (e.g. 0.17,4), got \"{s}\""));
        };
        let number = |v: &str, what: &str| v.parse::<f64>().map_err(|_| format!("{what} \"{v}\" is not a number"));
        let p = LaserProfile::tailed(number(share, "tail share")?, number(length, "tail length")?);
        p.validate()?;
        Ok(p)
    }
}

/// The exponentially modified Gaussian: a unit Gaussian of σ `s` convolved with the exponential
/// `exp(−x/t)/t` (x > 0), at `x`; evaluated without overflow on both sides.
pub fn emg(x: f64, s: f64, t: f64) -> f64 {
    let z = (s / t - x / s) / std::f64::consts::SQRT_2;
    let e = if z >= 0.0 {
        // exp(s²/2t² − x/t)·erfc(z) = exp(−x²/2s²)·erfcx(z)
        (-0.5 * (x / s).powi(2)).exp() * erfcx(z)
    } else {
        (0.5 * (s / t).powi(2) - x / t).exp() * (2.0 - erfcx(-z) * (-z * z).exp())
    };
    0.5 / t * e
}

/// The scaled complementary error function exp(z²)·erfc(z) for z ≥ 0 (Numerical Recipes'
/// Chebyshev fit of erfc: fractional error below 1.2e-7 everywhere).
fn erfcx(z: f64) -> f64 {
    debug_assert!(z >= 0.0);
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98 + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    t * poly.exp()
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
    fn the_emg_matches_its_convolution_integral() {
        let (s, t) = (1.3, 2.0);
        for x in [-8.0, -2.0, 0.0, 0.5, 3.0, 12.0, 40.0] {
            let direct = integral(
                |u| {
                    let g = (-0.5 * ((x - u) / s).powi(2)).exp() / (s * (2.0 * std::f64::consts::PI).sqrt());
                    g * (-u / t).exp() / t
                },
                0.0,
                200.0,
            );
            let v = emg(x, s, t);
            assert!((v - direct).abs() <= 1e-6 * direct.max(1e-12) + 1e-15, "x {x}: {v} vs {direct}");
        }
    }

    #[test]
    fn profiles_have_unit_area_a_single_peak_and_their_half_points_at_half_of_it() {
        for p in [LaserProfile::gaussian(), LaserProfile::tailed(0.17, 4.0), LaserProfile::tailed(0.4, 1.5)] {
            for s in [1.0, 1.7] {
                let area = integral(|x| p.unit(x, s), -30.0, 90.0);
                assert!((area - 1.0).abs() < 1e-6, "{p:?}: area {area}");
                let m = p.mode_at(s);
                assert!(p.unit(m, s) > p.unit(m + 1e-3, s) && p.unit(m, s) > p.unit(m - 1e-3, s), "{p:?}");
                let (lo, hi) = p.half_points(s);
                for x in [lo, hi] {
                    assert!((p.unit(x, s) / p.unit(m, s) - 0.5).abs() < 1e-9, "{p:?} at {x}");
                }
            }
        }
        assert!((LaserProfile::gaussian().fwhm() - GAUSS_FWHM_PER_SIGMA).abs() < 1e-12);
        assert!(LaserProfile::tailed(0.17, 4.0).validate().is_ok());
        assert!(LaserProfile::tailed(0.95, 4.0).validate().unwrap_err().contains("tail_weight"));
        assert!(LaserProfile::tailed(0.2, 0.0).validate().unwrap_err().contains("tail_length"));
        assert_eq!("0.17, 4".parse::<LaserProfile>().unwrap(), LaserProfile::tailed(0.17, 4.0));
        assert!("0.17".parse::<LaserProfile>().unwrap_err().contains("SHARE,LENGTH"));
        assert!("x,4".parse::<LaserProfile>().unwrap_err().contains("tail share \"x\""));
        assert!("0.95,4".parse::<LaserProfile>().unwrap_err().contains("tail_weight"));
    }
}
