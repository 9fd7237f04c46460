//! The camera behind the optics, beyond the plain monochrome sensor: veiling glare ([`Halo`]),
//! colour filters (a Bayer mosaic or three channels per pixel, [`Colour`]), blooming ([`Bloom`]),
//! photon and read noise, clipping at the full well and, for RGB output, demosaicing, white
//! balance and the colour matrix.
//!
//! Order of events, as in a camera: the light's glare spreads before the pixels; each pixel's
//! filter passes its channel's share of the ambient and the laser light; photons arrive with
//! Poisson noise; charge above the full well spills along the column (or row) into the next
//! pixels that have room, whatever their colour, half each way (the rest of it, `1 − spill`, is
//! drained); read noise; clipping; then the camera's processing of RGB output.

use crate::frame::{Frame16, RgbFrame};
use crate::render::RenderOptions;
use crate::rng::{SplitMix64, mix};
use omni_model::{BayerPattern, CameraColour};
use rayon::prelude::*;

/// Veiling glare: `fraction` of all light is spread by a Gaussian of σ `sigma_px` (px), the rest
/// stays (a wide, faint glow around bright parts, centred on them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Halo {
    pub fraction: f64,
    pub sigma_px: f64,
}

impl Halo {
    /// Checks values; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.fraction.is_finite() && (0.0..=1.0).contains(&self.fraction)) {
            return Err(format!("fraction must be within 0–1, got {}", self.fraction));
        }
        if !(self.sigma_px.is_finite() && (0.3..=200.0).contains(&self.sigma_px)) {
            return Err(format!("sigma_px must be within 0.3–200 px, got {}", self.sigma_px));
        }
        Ok(())
    }

    /// The glare applied to an image (w × h, row-major): light spread past the frame is lost.
    pub(crate) fn apply(&self, img: &[f64], w: usize, h: usize) -> Vec<f64> {
        let blurred = gaussian_blur(img, w, h, self.sigma_px);
        img.iter().zip(&blurred).map(|(v, b)| (1.0 - self.fraction) * v + self.fraction * b).collect()
    }
}

/// Along which image axis saturated charge spills.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BloomAxis {
    /// Up and down the column (a CCD's or most CMOS sensors' vertical bloom).
    Columns,
    /// Left and right along the row.
    Rows,
}

/// Blooming: charge above the full well leaves a pixel, half each way along `axis`, and fills
/// the next pixels that have room; a share `spill` of it spills, the rest is drained (0 = plain
/// clipping, 1 = no anti-blooming drain).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bloom {
    pub axis: BloomAxis,
    pub spill: f64,
}

impl Bloom {
    /// All excess charge spills along the columns.
    pub fn columns() -> Self {
        Bloom { axis: BloomAxis::Columns, spill: 1.0 }
    }

    /// Checks values; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.spill.is_finite() && (0.0..=1.0).contains(&self.spill)) {
            return Err(format!("spill must be within 0–1, got {}", self.spill));
        }
        Ok(())
    }
}

/// What a colour camera delivers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColourOutput {
    /// An RGB frame: the mosaic (if any) demosaiced bilinearly, white-balanced, through the colour
    /// matrix ([`crate::LaserFrame::colour`]; [`crate::LaserFrame::image`] holds its luma).
    Rgb,
    /// The raw Bayer mosaic as a grey frame: pixel (x, y) holds the channel the pattern puts there.
    Raw,
}

/// A colour camera, resolved for rendering: the raw responses to the laser and to the room
/// light (monochrome pixel = 1), the mosaic, white balance, colour matrix and output
/// ([`omni_model::CameraColour`] says what each means).
#[derive(Debug, Clone, PartialEq)]
pub struct Colour {
    pub laser_rgb: [f64; 3],
    pub ambient_rgb: [f64; 3],
    pub white_balance: [f64; 3],
    pub matrix: [[f64; 3]; 3],
    pub bayer: Option<BayerPattern>,
    pub output: ColourOutput,
}

impl Colour {
    /// The camera `camera` imaging a laser of `wavelength_nm` (its filter curves unless the camera
    /// gives `laser_rgb`).
    pub fn new(camera: &CameraColour, wavelength_nm: f64, output: ColourOutput) -> Colour {
        Colour {
            laser_rgb: camera.laser_response(wavelength_nm),
            ambient_rgb: camera.ambient_rgb,
            white_balance: camera.white_balance,
            matrix: camera.matrix,
            bayer: camera.bayer,
            output,
        }
    }

    /// Checks values; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        let camera = CameraColour {
            bayer: self.bayer,
            laser_rgb: Some(self.laser_rgb),
            ambient_rgb: self.ambient_rgb,
            white_balance: self.white_balance,
            matrix: self.matrix,
        };
        camera.validate()?;
        if self.output == ColourOutput::Raw && self.bayer.is_none() {
            return Err("raw output needs a Bayer mosaic".into());
        }
        Ok(())
    }
}

/// The frame a camera delivers from the light on its pixels (`main`: all light, or the ambient
/// light alone when `laser` holds the laser light apart; e⁻, w × h): the grey frame and, for RGB
/// output, the colour frame.
pub(crate) fn capture(
    main: Vec<f64>,
    laser: Option<Vec<f64>>,
    w: usize,
    h: usize,
    opts: &RenderOptions,
    seed: u64,
) -> (Frame16, Option<RgbFrame>) {
    let (mut main, mut laser) = (main, laser);
    if let Some(halo) = &opts.halo {
        main = halo.apply(&main, w, h);
        laser = laser.map(|l| halo.apply(&l, w, h));
    }
    let planes: Vec<Vec<f64>> = match (&opts.colour, laser) {
        (None, None) => vec![main],
        (None, Some(l)) => vec![main.iter().zip(&l).map(|(a, b)| a + b).collect()],
        (Some(c), laser) => {
            let l = laser.unwrap_or_else(|| vec![0.0; main.len()]);
            let mix = |ch: usize, a: f64, b: f64| c.ambient_rgb[ch] * a + c.laser_rgb[ch] * b;
            match c.bayer {
                Some(p) => vec![(0..w * h).map(|i| mix(p.channel(i % w, i / w), main[i], l[i])).collect()],
                None => (0..3).map(|ch| main.iter().zip(&l).map(|(a, b)| mix(ch, *a, *b)).collect()).collect(),
            }
        }
    };
    let levels: Vec<Vec<f64>> = planes
        .into_iter()
        .enumerate()
        .map(|(k, e)| expose(e, w, h, opts, mix(seed ^ (0xC0_10DE + k as u64))))
        .collect();
    let max = if opts.bit_depth == 8 { 255.0 } else { 65535.0 };
    let quantise = |v: f64| (v.clamp(0.0, 1.0).powf(1.0 / opts.gamma) * max).round() as u16;
    let grey = |data: &[f64]| Frame16 {
        width: w as u32,
        height: h as u32,
        data: data.iter().map(|v| quantise(*v)).collect(),
        bit_depth: opts.bit_depth,
    };
    let c = match &opts.colour {
        Some(c) if c.output == ColourOutput::Rgb => c,
        _ => return (grey(&levels[0]), None),
    };
    let raw = match c.bayer {
        Some(p) => demosaic(&levels[0], p, w, h),
        None => levels,
    };
    let mut data = vec![0u16; 3 * w * h];
    data.par_chunks_mut(3 * w).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let i = y * w + x;
            let balanced: [f64; 3] = std::array::from_fn(|ch| (raw[ch][i] * c.white_balance[ch]).min(1.0));
            for (ch, m) in c.matrix.iter().enumerate() {
                row[3 * x + ch] = quantise(m[0] * balanced[0] + m[1] * balanced[1] + m[2] * balanced[2]);
            }
        }
    });
    let rgb = RgbFrame { width: w as u32, height: h as u32, data, bit_depth: opts.bit_depth };
    (rgb.luma(), Some(rgb))
}

/// Photon noise, blooming, read noise and clipping of one plane of signals (e⁻): the pixels'
/// levels as shares of the full well, 0–1.
fn expose(mut e: Vec<f64>, w: usize, h: usize, opts: &RenderOptions, seed: u64) -> Vec<f64> {
    if opts.noise {
        e.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            row.iter_mut().enumerate().for_each(|(x, v)| *v = SplitMix64::pixel(seed, x, y).poisson(*v));
        });
    }
    if let Some(bloom) = &opts.bloom {
        bloom_image(&mut e, w, h, opts.full_well_e, bloom);
    }
    let read_seed = mix(seed ^ 0x4EAD);
    e.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, v) in row.iter_mut().enumerate() {
            let noisy =
                if opts.noise { *v + opts.read_noise_e * SplitMix64::pixel(read_seed, x, y).normal() } else { *v };
            *v = (noisy / opts.full_well_e).clamp(0.0, 1.0);
        }
    });
    e
}

/// Blooming of a whole image along `bloom.axis` ([`bloom_line`] on every column or row).
fn bloom_image(e: &mut [f64], w: usize, h: usize, full_well: f64, bloom: &Bloom) {
    match bloom.axis {
        BloomAxis::Rows => e.par_chunks_mut(w).for_each(|row| bloom_line(row, full_well, bloom.spill)),
        BloomAxis::Columns => {
            let mut columns: Vec<Vec<f64>> = (0..w).map(|x| (0..h).map(|y| e[y * w + x]).collect()).collect();
            columns.par_iter_mut().for_each(|c| bloom_line(c, full_well, bloom.spill));
            for (x, c) in columns.iter().enumerate() {
                for (y, v) in c.iter().enumerate() {
                    e[y * w + x] = *v;
                }
            }
        }
    }
}

/// Blooming along one line of pixels: each pixel's charge above `full_well` leaves it, a share
/// `spill` of it split equally between the two directions (the rest drained); each half passes
/// through full pixels and fills the next ones that have room, in order; what reaches the line's
/// end is lost. So an isolated saturated run grows on each side until the pixels there have
/// taken half of its excess.
pub fn bloom_line(v: &mut [f64], full_well: f64, spill: f64) {
    let mut half = vec![0.0; v.len()];
    let mut any = false;
    for (x, h) in v.iter_mut().zip(half.iter_mut()) {
        if *x > full_well {
            *h = 0.5 * spill * (*x - full_well);
            *x = full_well;
            any = true;
        }
    }
    if !any {
        return;
    }
    let fill = |v: &mut [f64], i: usize, carry: &mut f64| {
        *carry += half[i];
        let room = full_well - v[i];
        if room > 0.0 && *carry > 0.0 {
            let take = room.min(*carry);
            v[i] += take;
            *carry -= take;
        }
    };
    let mut carry = 0.0;
    for i in 0..v.len() {
        fill(v, i, &mut carry);
    }
    carry = 0.0;
    for i in (0..v.len()).rev() {
        fill(v, i, &mut carry);
    }
}

/// Bilinear demosaicing: each channel at each pixel is its own value where the mosaic has it,
/// else the mean of the pixels of that channel among its 8 neighbours.
pub(crate) fn demosaic(mosaic: &[f64], pattern: BayerPattern, w: usize, h: usize) -> Vec<Vec<f64>> {
    (0..3)
        .map(|ch| {
            let mut out = vec![0.0; w * h];
            out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
                for (x, o) in row.iter_mut().enumerate() {
                    if pattern.channel(x, y) == ch {
                        *o = mosaic[y * w + x];
                        continue;
                    }
                    let (mut sum, mut n) = (0.0, 0);
                    for yy in y.saturating_sub(1)..(y + 2).min(h) {
                        for xx in x.saturating_sub(1)..(x + 2).min(w) {
                            if pattern.channel(xx, yy) == ch {
                                sum += mosaic[yy * w + xx];
                                n += 1;
                            }
                        }
                    }
                    *o = if n > 0 { sum / n as f64 } else { 0.0 };
                }
            });
            out
        })
        .collect()
}

/// Separable Gaussian blur (σ px, cut at 4 σ, zero outside the image).
fn gaussian_blur(img: &[f64], w: usize, h: usize, sigma: f64) -> Vec<f64> {
    let r = (4.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-r..=r).map(|i| (-0.5 * (i as f64 / sigma).powi(2)).exp()).collect();
    let total: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / total).collect();
    let mut tmp = vec![0.0; w * h];
    tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            *o = kernel
                .iter()
                .enumerate()
                .filter_map(|(i, k)| {
                    let xx = x as isize + i as isize - r;
                    (xx >= 0 && xx < w as isize).then(|| k * img[y * w + xx as usize])
                })
                .sum();
        }
    });
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            *o = kernel
                .iter()
                .enumerate()
                .filter_map(|(i, k)| {
                    let yy = y as isize + i as isize - r;
                    (yy >= 0 && yy < h as isize).then(|| k * tmp[yy as usize * w + x])
                })
                .sum();
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_saturated_run_grows_by_half_its_excess_on_each_side() {
        // A run of 3 pixels 2 full wells over, on a floor of 0.2: 6 wells of excess, 3 each way;
        // each pixel beside it has room for 0.8, so 3 / 0.8 = 3.75 pixels fill on each side.
        let mut v = vec![0.2; 21];
        v[9..12].copy_from_slice(&[3.0, 3.0, 3.0]);
        bloom_line(&mut v, 1.0, 1.0);
        let full = v.iter().filter(|x| **x >= 1.0).count();
        assert_eq!(full, 3 + 2 * 3, "{v:?}");
        assert!((v[5] - (0.2 + 0.75 * 0.8)).abs() < 1e-12 && (v[15] - v[5]).abs() < 1e-12, "{v:?}");
        assert!((v.iter().sum::<f64>() - (0.2 * 18.0 + 9.0)).abs() < 1e-9, "charge is kept");
        // No spill: plain clipping.
        let mut c = vec![0.2, 3.0, 0.2];
        bloom_line(&mut c, 1.0, 0.0);
        assert_eq!(c, vec![0.2, 1.0, 0.2]);
    }

    #[test]
    fn the_halo_keeps_the_light_and_its_centre() {
        let (w, h) = (64, 64);
        let mut img = vec![0.0; w * h];
        img[32 * w + 30] = 100.0;
        let out = Halo { fraction: 0.3, sigma_px: 4.0 }.apply(&img, w, h);
        let sum: f64 = out.iter().sum();
        let cx: f64 = out.iter().enumerate().map(|(i, v)| v * (i % w) as f64).sum::<f64>() / sum;
        assert!((sum - 100.0).abs() < 1e-9 && (cx - 30.0).abs() < 1e-9, "{sum} {cx}");
        assert!((out[32 * w + 30] - 70.0 - 30.0 / (2.0 * std::f64::consts::PI * 16.0)).abs() < 0.05);
    }

    /// A flat field of ambient and laser light through a colour camera, noiseless.
    fn flat(colour: Colour, bit_depth: u8) -> (Frame16, Option<RgbFrame>, [f64; 3]) {
        let (w, h) = (6, 4);
        let opts = RenderOptions { noise: false, bit_depth, colour: Some(colour.clone()), ..RenderOptions::ideal() };
        let (ambient, laser) = (2000.0, 3000.0);
        let raw =
            std::array::from_fn(|c| (colour.ambient_rgb[c] * ambient + colour.laser_rgb[c] * laser) / opts.full_well_e);
        let (grey, rgb) = capture(vec![ambient; w * h], Some(vec![laser; w * h]), w, h, &opts, 1);
        (grey, rgb, raw)
    }

    fn camera(bayer: Option<BayerPattern>, output: ColourOutput) -> Colour {
        let c = CameraColour {
            bayer,
            laser_rgb: Some([0.9, 0.3, 0.1]),
            ambient_rgb: [0.2, 0.5, 0.7],
            ..Default::default()
        };
        Colour::new(&c, 650.0, output)
    }

    #[test]
    fn a_bayer_mosaic_holds_each_channel_where_its_order_puts_it() {
        for bit_depth in [8u8, 16] {
            let max = if bit_depth == 8 { 255.0 } else { 65535.0 };
            for p in BayerPattern::ALL {
                let (mosaic, rgb, raw) = flat(camera(Some(p), ColourOutput::Raw), bit_depth);
                assert!(rgb.is_none() && mosaic.bit_depth == bit_depth);
                let value = |c: usize| (raw[c] * max).round() as u16;
                for y in 0..mosaic.height {
                    for x in 0..mosaic.width {
                        assert_eq!(mosaic.get(x, y), value(p.channel(x as usize, y as usize)), "{p:?} ({x}, {y})");
                    }
                }
                // The order's name reads row 0 then row 1.
                let names = p.name().as_bytes();
                for (k, (x, y)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
                    let c = match names[k] {
                        b'r' => 0,
                        b'g' => 1,
                        _ => 2,
                    };
                    assert_eq!(mosaic.get(x, y), value(c), "{p:?}: pixel ({x}, {y}) is {}", names[k] as char);
                }
            }
        }
    }

    #[test]
    fn rgb_output_is_the_balanced_raw_through_the_colour_matrix() {
        let reference = flat(camera(None, ColourOutput::Rgb), 8);
        let colour = camera(None, ColourOutput::Rgb);
        let (_, rgb, raw) = &reference;
        let balanced: [f64; 3] = std::array::from_fn(|c| (raw[c] * colour.white_balance[c]).min(1.0));
        let want: [u16; 3] = std::array::from_fn(|c| {
            let m = colour.matrix[c];
            ((m[0] * balanced[0] + m[1] * balanced[1] + m[2] * balanced[2]).clamp(0.0, 1.0) * 255.0).round() as u16
        });
        let rgb = rgb.as_ref().unwrap();
        assert!(
            (0..rgb.height).all(|y| (0..rgb.width).all(|x| rgb.get(x, y) == want)),
            "{:?} vs {want:?}",
            rgb.get(0, 0)
        );
        // A mosaic demosaiced gives a flat colour back exactly.
        for p in BayerPattern::ALL {
            let (grey, demosaiced, _) = flat(camera(Some(p), ColourOutput::Rgb), 8);
            assert_eq!(demosaiced.as_ref(), Some(rgb), "{p:?}");
            assert_eq!(grey, rgb.luma());
        }
        assert!(camera(None, ColourOutput::Raw).validate().unwrap_err().contains("Bayer"));
    }

    #[test]
    fn demosaicing_a_flat_colour_gives_it_back() {
        let (w, h) = (6, 4);
        for p in BayerPattern::ALL {
            let mosaic: Vec<f64> = (0..w * h).map(|i| [0.7, 0.4, 0.1][p.channel(i % w, i / w)]).collect();
            let rgb = demosaic(&mosaic, p, w, h);
            for (ch, want) in [0.7, 0.4, 0.1].into_iter().enumerate() {
                assert!(rgb[ch].iter().all(|v| (v - want).abs() < 1e-12), "{p:?} channel {ch}");
            }
        }
    }
}
