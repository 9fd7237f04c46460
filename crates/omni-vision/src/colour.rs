//! What the stripe detector reads from a colour or raw Bayer frame: one channel, or the laser's
//! colour contrast.
//!
//! A red laser on lit white paper is darker than the paper in luma (the paper reflects green
//! and blue too), but clearly brighter in the red channel and brighter still in red minus the
//! mean of green and blue, where white and grey surfaces cancel. [`Channel::Laser`] is that
//! contrast, `L − w·(A + B)/2` for the laser's colour `L` and the other two `A`, `B`, clamped at
//! 0, with `w` = 1 while `L` is below ¾ of full scale, falling linearly to 0 at full scale. A close
//! laser's core saturates all three channels (white) and its rim leaks into the other two
//! (sensor cross-talk, JPEG's half-resolution colour), where the plain difference would fall to
//! 0 at the stripe's centre and leave two humps; as `L` nears full scale its own level is the
//! better evidence, so the contrast rises monotonically into a saturated core, which reads full
//! scale and is located at its plateau's centre like any saturated stripe. The price: a grey
//! surface above ¾ of full scale reads as a plateau in this contrast too (a step at its edge,
//! not a stripe).
//!
//! Raw Bayer frames ([`BayerPattern`]) are demosaiced ([`demosaic`]) before the channel is taken,
//! so that points stay in full-resolution pixel coordinates.

use crate::image_io::GrayImage;
use std::fmt;
use std::str::FromStr;

/// A colour channel of an RGB frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Colour {
    Red,
    Green,
    Blue,
}

impl Colour {
    /// Index in an RGB triple.
    fn index(self) -> usize {
        match self {
            Colour::Red => 0,
            Colour::Green => 1,
            Colour::Blue => 2,
        }
    }

    /// Indices of this colour and the other two in an RGB triple.
    fn laser_and_others(self) -> (usize, usize, usize) {
        match self {
            Colour::Red => (0, 1, 2),
            Colour::Green => (1, 0, 2),
            Colour::Blue => (2, 0, 1),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Colour::Red => "red",
            Colour::Green => "green",
            Colour::Blue => "blue",
        }
    }
}

impl FromStr for Colour {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "red" => Ok(Colour::Red),
            "green" => Ok(Colour::Green),
            "blue" => Ok(Colour::Blue),
            _ => Err(format!("unknown colour \"{s}\" (known: red, green, blue)")),
        }
    }
}

/// What one sample of the detector's grey image is, per pixel of a colour frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Channel {
    /// Luma as the `image` crate computes it (sRGB weights); grey frames as they are.
    #[default]
    Luma,
    /// One channel as it is.
    Single(Colour),
    /// The laser colour's contrast over the other two channels (module docs).
    Laser(Colour),
}

impl Channel {
    /// Whether this reading needs a colour (or Bayer) frame.
    pub fn needs_colour(self) -> bool {
        self != Channel::Luma
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Channel::Luma => f.write_str("luma"),
            Channel::Single(c) => f.write_str(c.name()),
            Channel::Laser(c) => write!(f, "laser {}", c.name()),
        }
    }
}

/// The colour filter array of a raw Bayer frame (the simulator writes the same ones).
pub use omni_model::BayerPattern;

/// How a frame file becomes the detector's grey image: the channel, and whether the file is a
/// raw Bayer mosaic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ColourSpec {
    pub channel: Channel,
    pub bayer: Option<BayerPattern>,
    /// With `bayer`: the mosaic is read at the channel colour's own sites, at half the frame's
    /// size ([`mosaic_sites`]), instead of demosaiced.
    pub sites: bool,
}

impl ColourSpec {
    /// The options as a user wrote them, for error messages.
    pub fn describe(&self) -> String {
        let channel = self.channel_option();
        let bayer = self.bayer.map(|b| format!("--bayer {}", b.name()));
        let sites = self.sites.then(|| "--bayer-sites".to_string());
        [bayer, sites, channel].into_iter().flatten().collect::<Vec<_>>().join(" ")
    }

    /// Checks that a reading at the mosaic's sites has a mosaic and one colour with one site per
    /// cell (red or blue); the message names the options.
    pub fn validate(&self) -> Result<(), String> {
        if !self.sites {
            return Ok(());
        }
        if self.bayer.is_none() {
            return Err("--bayer-sites reads a raw Bayer mosaic: give its order with --bayer".into());
        }
        match self.site_colour() {
            Some(_) => Ok(()),
            None => Err(format!(
                "--bayer-sites reads the sites of one colour with one site per 2x2 cell: --laser or --channel red or blue, not {}",
                self.channel_option().unwrap_or_else(|| "luma".into())
            )),
        }
    }

    /// The channel's option as a user writes it; `None` for luma, the default.
    fn channel_option(&self) -> Option<String> {
        match self.channel {
            Channel::Luma => None,
            Channel::Single(c) => Some(format!("--channel {}", c.name())),
            Channel::Laser(c) => Some(format!("--laser {}", c.name())),
        }
    }

    /// A raw mosaic of this spec's `order` as an RGB image: read at the channel colour's sites
    /// (half size, [`mosaic_sites`]) where the spec asks for them, else demosaiced
    /// ([`demosaic`]).
    pub fn read_mosaic(&self, raw: &GrayImage, order: BayerPattern) -> Result<RgbImage, String> {
        match self.site_colour() {
            Some(colour) => mosaic_sites(raw, order, colour).map(|(sites, _)| sites),
            None => demosaic(raw, order),
        }
    }

    /// The colour whose mosaic sites are read: with `sites`, red or blue from `channel`.
    pub fn site_colour(&self) -> Option<Colour> {
        match self.channel {
            Channel::Single(c) | Channel::Laser(c) if self.sites && c != Colour::Green => Some(c),
            _ => None,
        }
    }

    /// For a mosaic read at its sites, the frame pixel (x, y) of the first site: site (i, j)
    /// of the frame as read is frame pixel (x + 2i, y + 2j). `None` for any other reading.
    pub fn site_origin(&self) -> Option<(u32, u32)> {
        first_site(self.bayer?, self.site_colour()?)
    }
}

/// The frame pixel (x, y) of `colour`'s site in the first 2 × 2 cell of a mosaic: `None` for
/// green, which has two.
fn first_site(order: BayerPattern, colour: Colour) -> Option<(u32, u32)> {
    let own = colour.index();
    let mut sites = [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().filter(|&(x, y)| order.channel(x, y) == own);
    match (sites.next(), sites.next()) {
        (Some((x, y)), None) => Some((x as u32, y as u32)),
        _ => None,
    }
}

/// An RGB frame, samples in the file's own units (`bit_depth` 8 or 16).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub bit_depth: u8,
    /// `[r, g, b]` per pixel, row-major.
    pub data: Vec<[u16; 3]>,
}

impl RgbImage {
    fn max_value(&self) -> u16 {
        if self.bit_depth <= 8 { 255 } else { u16::MAX }
    }

    /// The grey image `channel` makes of this frame.
    pub fn channel(&self, channel: Channel) -> GrayImage {
        let max = self.max_value();
        let data = match channel {
            // As the `image` crate converts colour frames (sRGB luminance weights, truncated).
            Channel::Luma => self
                .data
                .iter()
                .map(|&[r, g, b]| ((2126 * r as u32 + 7152 * g as u32 + 722 * b as u32) / 10000) as u16)
                .collect(),
            Channel::Single(c) => self.data.iter().map(|px| px[c.index()]).collect(),
            Channel::Laser(c) => {
                let (l, a, b) = c.laser_and_others();
                self.data.iter().map(|px| laser_contrast(px[l], px[a], px[b], max)).collect()
            }
        };
        GrayImage { width: self.width, height: self.height, bit_depth: self.bit_depth, data }
    }
}

/// `l − w·(a + b)/2` rounded, clamped at 0, `w` = min(1, 4·(max − l)/max) (module docs): for
/// 8-bit samples in integers ([`laser_contrast8`]), for 16-bit ones in `f32`.
#[inline(always)]
fn laser_contrast(l: u16, a: u16, b: u16, max: u16) -> u16 {
    if max == 255 {
        return laser_contrast8(l as u32, a as u32 + b as u32);
    }
    laser_contrast_f32(l as f32, a as f32 + b as f32, max as f32, 4.0 / max as f32)
}

/// [`laser_contrast`] of 8-bit samples, `others` the sum of the two other channels: `w` in
/// 1/4096 (`(255 − l)·16448/256`, rounded: 4·(255 − l)/255 to 0.002 %), the result rounded;
/// 32-bit integer lanes and no division, so that a frame's pass vectorises.
#[inline(always)]
fn laser_contrast8(l: u32, others: u32) -> u16 {
    let w4096 = (((255 - l) * 16448 + 128) >> 8).min(4096);
    let scaled = (8192 * l + 4096) as i32 - (w4096 * others) as i32;
    (scaled.max(0) >> 13) as u16
}

/// [`laser_contrast`] of the laser's level `l` and the sum `others` of the other two, with
/// `four_over_max` = 4 / `max` precomputed.
#[inline(always)]
fn laser_contrast_f32(l: f32, others: f32, max: f32, four_over_max: f32) -> u16 {
    let w = ((max - l) * four_over_max).min(1.0);
    // ≤ l ≤ max, so the rounding cannot pass full scale; `as` saturates at 0.
    ((l - 0.5 * w * others).max(0.0) + 0.5) as u16
}

/// The 8-bit grey samples `channel` makes of interleaved 8-bit samples, `stride` per pixel (3
/// for RGB, 4 for RGBA; red, green, blue first), in one pass over the frame: every channel of an
/// 8-bit frame fits a byte, and the stripe detector reads bytes faster than wider samples.
pub fn channel_bytes_of_rgb8(samples: &[u8], stride: usize, channel: Channel) -> Vec<u8> {
    let pixels = samples.chunks_exact(stride);
    match channel {
        // ≤ 255: the weights sum to 10000.
        Channel::Luma => {
            pixels.map(|p| ((2126 * p[0] as u32 + 7152 * p[1] as u32 + 722 * p[2] as u32) / 10000) as u8).collect()
        }
        Channel::Single(c) => pixels.map(|p| p[c.index()]).collect(),
        Channel::Laser(c) => laser_contrast_rgb8(samples, stride, c.laser_and_others()),
    }
}

/// [`laser_contrast8`] of every pixel of interleaved samples (≤ the laser's own level, so a
/// byte). Where the processor has SSE4.1 (with SSSE3's byte shuffles), sixteen pixels at a time:
/// de-interleaved by shuffles, and below ¾ of full scale, where the weight is 1, in 16-bit lanes
/// (`(2·l + 1 − others) / 2`, exactly what the 32-bit formula gives there); blocks holding a
/// brighter laser level take the 32-bit formula. The rest, and other processors, pixel by pixel.
fn laser_contrast_rgb8(samples: &[u8], stride: usize, channels: (usize, usize, usize)) -> Vec<u8> {
    let count = samples.len() / stride;
    let mut out = vec![0u8; count];
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if (stride == 3 || stride == 4)
        && std::arch::is_x86_feature_detected!("ssse3")
        && std::arch::is_x86_feature_detected!("sse4.1")
    {
        // SAFETY: the processor has SSSE3 and SSE4.1, checked on the lines above.
        done = unsafe { contrast_sse41::laser_contrast_blocks(samples, stride, channels, &mut out) };
    }
    let (l, a, b) = channels;
    for (o, p) in out[done..].iter_mut().zip(samples[done * stride..].chunks_exact(stride)) {
        *o = laser_contrast8(p[l] as u32, p[a] as u32 + p[b] as u32) as u8;
    }
    out
}

#[cfg(target_arch = "x86_64")]
mod contrast_sse41 {
    use std::arch::x86_64::*;

    /// Pixels per block: one 16-byte register of each channel.
    const BLOCK: usize = 16;

    /// [`super::laser_contrast_rgb8`] of the whole blocks of `samples` (`stride` 3 or 4) into
    /// `out`; returns how many pixels it wrote.
    #[target_feature(enable = "ssse3,sse4.1")]
    pub(super) fn laser_contrast_blocks(
        samples: &[u8],
        stride: usize,
        (l, a, b): (usize, usize, usize),
        out: &mut [u8],
    ) -> usize {
        let blocks = out.len().min(samples.len() / stride) / BLOCK;
        let (ml, ma, mb) = (gather_masks(stride, l), gather_masks(stride, a), gather_masks(stride, b));
        let zero = _mm_setzero_si128();
        let one = _mm_set1_epi16(1);
        let dim = _mm_set1_epi8(191u8 as i8);
        for (block, o) in samples.chunks_exact(stride * BLOCK).zip(out.chunks_exact_mut(BLOCK)).take(blocks) {
            let (vl, va, vb) = (gather(block, stride, &ml), gather(block, stride, &ma), gather(block, stride, &mb));
            let (l_lo, l_hi) = (_mm_unpacklo_epi8(vl, zero), _mm_unpackhi_epi8(vl, zero));
            let o_lo = _mm_add_epi16(_mm_unpacklo_epi8(va, zero), _mm_unpacklo_epi8(vb, zero));
            let o_hi = _mm_add_epi16(_mm_unpackhi_epi8(va, zero), _mm_unpackhi_epi8(vb, zero));
            // Every laser level ≤ 191 (below ¾ of full scale: the weight is 1).
            let dim_only = _mm_movemask_epi8(_mm_cmpeq_epi8(_mm_min_epu8(vl, dim), vl)) == 0xFFFF;
            let contrast = if dim_only {
                let half = |l: __m128i, others: __m128i| {
                    let twice = _mm_sub_epi16(_mm_add_epi16(_mm_add_epi16(l, l), one), others);
                    _mm_srai_epi16(_mm_max_epi16(twice, zero), 1)
                };
                _mm_packus_epi16(half(l_lo, o_lo), half(l_hi, o_hi))
            } else {
                let lanes = |x: __m128i| (_mm_cvtepu16_epi32(x), _mm_cvtepu16_epi32(_mm_srli_si128(x, 8)));
                let ((l0, l1), (l2, l3)) = (lanes(l_lo), lanes(l_hi));
                let ((o0, o1), (o2, o3)) = (lanes(o_lo), lanes(o_hi));
                let lo = _mm_packus_epi32(weighted(l0, o0), weighted(l1, o1));
                let hi = _mm_packus_epi32(weighted(l2, o2), weighted(l3, o3));
                _mm_packus_epi16(lo, hi)
            };
            // SAFETY: `o` holds BLOCK = 16 bytes.
            unsafe { _mm_storeu_si128(o.as_mut_ptr().cast(), contrast) };
        }
        blocks * BLOCK
    }

    /// [`laser_contrast8`] in four 32-bit lanes: laser levels `l`, sums of the others `others`.
    #[inline]
    #[target_feature(enable = "ssse3,sse4.1")]
    fn weighted(l: __m128i, others: __m128i) -> __m128i {
        let w = _mm_srli_epi32(
            _mm_add_epi32(
                _mm_mullo_epi32(_mm_sub_epi32(_mm_set1_epi32(255), l), _mm_set1_epi32(16448)),
                _mm_set1_epi32(128),
            ),
            8,
        );
        let w4096 = _mm_min_epi32(w, _mm_set1_epi32(4096));
        let scaled =
            _mm_sub_epi32(_mm_add_epi32(_mm_slli_epi32(l, 13), _mm_set1_epi32(4096)), _mm_mullo_epi32(w4096, others));
        _mm_srai_epi32(_mm_max_epi32(scaled, _mm_setzero_si128()), 13)
    }

    /// One channel's bytes of a block's `stride` registers gathered into one: shuffle masks per
    /// register, placing byte `stride·i + channel` at lane i where that register holds it (a
    /// mask byte with its top bit set zeroes the lane).
    fn gather_masks(stride: usize, channel: usize) -> [[u8; 16]; 4] {
        let mut masks = [[0x80u8; 16]; 4];
        for i in 0..BLOCK {
            let at = stride * i + channel;
            masks[at / 16][i] = (at % 16) as u8;
        }
        masks
    }

    /// The channel of `masks` ([`gather_masks`]) from a block of `stride` × 16 bytes.
    #[inline]
    #[target_feature(enable = "ssse3,sse4.1")]
    fn gather(block: &[u8], stride: usize, masks: &[[u8; 16]; 4]) -> __m128i {
        let mut v = _mm_setzero_si128();
        for (k, mask) in masks.iter().enumerate().take(stride) {
            // SAFETY: `block` holds stride × 16 bytes, so bytes 16k..16k + 16 are inside it.
            let (bytes, mask) =
                unsafe { (_mm_loadu_si128(block.as_ptr().add(16 * k).cast()), _mm_loadu_si128(mask.as_ptr().cast())) };
            v = _mm_or_si128(v, _mm_shuffle_epi8(bytes, mask));
        }
        v
    }

    #[cfg(test)]
    #[test]
    fn blocks_equal_the_formula_for_every_level() {
        use super::laser_contrast8;
        let mut rgb = Vec::new();
        for l in 0..=255u8 {
            for o in [0u8, 1, 2, 50, 127, 128, 191, 192, 254, 255] {
                rgb.extend([l, o, o.wrapping_mul(3)]);
            }
        }
        rgb.truncate(rgb.len() / 48 * 48);
        let want: Vec<u8> =
            rgb.chunks_exact(3).map(|p| laser_contrast8(p[0] as u32, p[1] as u32 + p[2] as u32) as u8).collect();
        let mut got = vec![0; want.len()];
        if std::arch::is_x86_feature_detected!("sse4.1") {
            // SAFETY: checked on the line above.
            assert_eq!(unsafe { laser_contrast_blocks(&rgb, 3, (0, 1, 2), &mut got) }, want.len());
            assert_eq!(got, want);
        }
    }
}

/// A raw mosaic read at `colour`'s own sites (red or blue: one per 2 × 2 cell) as an RGB image
/// of half the frame's size: each site's own sample, green the mean of its four row and column
/// neighbours, the third colour the mean of its four diagonal ones; with the frame pixel (x, y)
/// of the first site, so that site (i, j) is frame pixel (x + 2i, y + 2j). A laser of that
/// colour is then sampled on one regular 2 px grid, none of its samples interpolated: a
/// demosaiced frame mixes measured and interpolated samples whose share changes with the
/// stripe's place across the mosaic's phases.
pub fn mosaic_sites(raw: &GrayImage, order: BayerPattern, colour: Colour) -> Result<(RgbImage, (u32, u32)), String> {
    let (w, h) = (raw.width as usize, raw.height as usize);
    if w % 2 != 0 || h % 2 != 0 || w < 2 || h < 2 {
        return Err(format!(
            "a {}x{} px frame is not a Bayer mosaic of whole 2x2 cells ({} needs even sides)",
            w,
            h,
            order.name()
        ));
    }
    let Some((x0, y0)) = first_site(order, colour) else {
        return Err(
            "green has two sites in each 2x2 cell of a Bayer mosaic: only red and blue are read at their sites".into(),
        );
    };
    let (own, x0, y0) = (colour.index(), x0 as usize, y0 as usize);
    let opposite = 2 - own;
    let at = |x: i64, y: i64| {
        let (x, y) = (x.clamp(0, w as i64 - 1) as usize, y.clamp(0, h as i64 - 1) as usize);
        raw.data[y * w + x] as u32
    };
    let (hw, hh) = (w / 2, h / 2);
    let mut data = Vec::with_capacity(hw * hh);
    for j in 0..hh {
        for i in 0..hw {
            let (x, y) = ((x0 + 2 * i) as i64, (y0 + 2 * j) as i64);
            let cross = at(x - 1, y) + at(x + 1, y) + at(x, y - 1) + at(x, y + 1);
            let diagonal = at(x - 1, y - 1) + at(x + 1, y - 1) + at(x - 1, y + 1) + at(x + 1, y + 1);
            let mut px = [0u16; 3];
            px[own] = at(x, y) as u16;
            px[1] = ((cross + 2) / 4) as u16;
            px[opposite] = ((diagonal + 2) / 4) as u16;
            data.push(px);
        }
    }
    let image = RgbImage { width: hw as u32, height: hh as u32, bit_depth: raw.bit_depth, data };
    Ok((image, (x0 as u32, y0 as u32)))
}

/// Demosaics a raw Bayer frame with Malvar, He and Cutler's gradient-corrected linear filters
/// (ICASSP 2004): each missing colour is the bilinear estimate corrected by the Laplacian of the
/// pixel's own colour, which keeps the false colour along edges (zippers) that plain bilinear
/// interpolation leaves small, since a zipper in R − (G+B)/2 is a thin bright line: a false
/// stripe. Borders are mirrored about the edge pixel, which keeps the mosaic's pattern. The
/// frame's sides must be even: a mosaic is whole 2×2 cells.
pub fn demosaic(raw: &GrayImage, order: BayerPattern) -> Result<RgbImage, String> {
    let (w, h) = (raw.width as usize, raw.height as usize);
    if w % 2 != 0 || h % 2 != 0 || w < 2 || h < 2 {
        return Err(format!(
            "a {}x{} px frame is not a Bayer mosaic of whole 2x2 cells ({} needs even sides)",
            w,
            h,
            order.name()
        ));
    }
    let max = raw.max_value() as i64;
    let mirror = |i: i64, n: usize| -> usize {
        let n = n as i64;
        let i = if i < 0 { -i } else { i };
        (if i >= n { 2 * (n - 1) - i } else { i }).clamp(0, n - 1) as usize
    };
    let at = |x: i64, y: i64| raw.data[mirror(y, h) * w + mirror(x, w)] as i64;
    let mut data = vec![[0u16; 3]; w * h];
    for y in 0..h {
        for x in 0..w {
            let (xi, yi) = (x as i64, y as i64);
            let own = order.channel(x, y);
            // Sums of the 5×5 neighbourhood's rings, by position.
            let v = |dx: i64, dy: i64| at(xi + dx, yi + dy);
            let centre = v(0, 0);
            let cross1 = v(-1, 0) + v(1, 0) + v(0, -1) + v(0, 1);
            let cross2 = v(-2, 0) + v(2, 0) + v(0, -2) + v(0, 2);
            let diag1 = v(-1, -1) + v(1, -1) + v(-1, 1) + v(1, 1);
            let row1 = v(-1, 0) + v(1, 0);
            let col1 = v(0, -1) + v(0, 1);
            let row2 = v(-2, 0) + v(2, 0);
            let col2 = v(0, -2) + v(0, 2);
            // Eighths, as in the paper's filters.
            let green_at_rb = 4 * centre + 2 * cross1 - cross2;
            // The colour found left and right of a green pixel (its row's other colour).
            let along_row = 5 * centre + 4 * row1 - diag1 - row2 + col2 / 2;
            let along_column = 5 * centre + 4 * col1 - diag1 - col2 + row2 / 2;
            let opposite = 6 * centre + 2 * diag1 - 3 * cross2 / 2;
            let mut px = [0i64; 3];
            px[own] = 8 * centre;
            if own == 1 {
                // Green: the row's neighbours are one of R/B, the column's the other.
                let row_colour = order.channel(x + 1, y);
                px[row_colour] = along_row;
                px[2 - row_colour] = along_column;
            } else {
                px[1] = green_at_rb;
                px[2 - own] = opposite;
            }
            data[y * w + x] = px.map(|v| ((v + 4).div_euclid(8)).clamp(0, max) as u16);
        }
    }
    Ok(RgbImage { width: raw.width, height: raw.height, bit_depth: raw.bit_depth, data })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgb(w: u32, h: u32, f: impl Fn(usize, usize) -> [u16; 3]) -> RgbImage {
        let data = (0..h as usize).flat_map(|y| (0..w as usize).map(move |x| (x, y))).map(|(x, y)| f(x, y)).collect();
        RgbImage { width: w, height: h, bit_depth: 8, data }
    }

    #[test]
    fn laser_contrast_cancels_grey_and_saturates_with_its_channel() {
        // Below half scale: the plain difference (grey cancels; a half level rounds up).
        let img = rgb(4, 1, |x, _| [[100, 100, 100], [101, 40, 40], [120, 30, 50], [10, 100, 100]][x]);
        assert_eq!(img.channel(Channel::Laser(Colour::Red)).data, vec![0, 61, 80, 0]);
        assert_eq!(img.channel(Channel::Laser(Colour::Green)).data, vec![0, 0, 0, 45]);
        assert_eq!(img.channel(Channel::Single(Colour::Green)).data, vec![100, 40, 30, 100]);
        // Towards full scale the laser's own level takes over (w = 4·(255 − R)/255 above ¾ of
        // it); white and a saturated red read full scale.
        let bright = rgb(4, 1, |x, _| [[191, 100, 100], [255, 255, 255], [255, 0, 0], [230, 200, 200]][x]);
        let want_230 = 230.0 - (4.0 * (255.0 - 230.0) / 255.0) * (200.0 + 200.0) / 2.0f64;
        let got = img_red(&bright);
        assert_eq!(got[..3], [91, 255, 255]);
        assert!((got[3] as f64 - want_230).abs() <= 0.5 + 1e-9, "{} against {want_230}", got[3]);
        // The 8-bit integer form is the formula to within its rounding everywhere.
        for l in 0..=255u32 {
            for others in (0..=510).step_by(3) {
                let w = (4.0 * (255.0 - l as f64) / 255.0).min(1.0);
                let exact = (l as f64 - w * others as f64 / 2.0).max(0.0);
                let got = laser_contrast8(l, others) as f64;
                assert!((got - exact).abs() <= 0.55, "l {l} others {others}: {got} against {exact}");
            }
        }
        // Monotonic in the laser's level for a fixed leak into the other channels.
        let ramp = rgb(256, 1, |x, _| [x as u16, (x as u16) / 2, (x as u16) / 2]);
        let c = img_red(&ramp);
        assert!(c.windows(2).all(|w| w[1] >= w[0]), "{c:?}");
    }

    #[test]
    fn the_one_pass_8_bit_reading_equals_the_general_one() {
        // Every (r, g, b) on a coarse lattice, in RGB and RGBA layout.
        let values: Vec<u8> = (0..=255).step_by(5).map(|v| v as u8).chain([254, 255]).collect();
        let mut px: Vec<[u8; 3]> = Vec::new();
        for &r in &values {
            for &g in &values {
                px.extend(values.iter().map(|&b| [r, g, b]));
            }
        }
        let general = RgbImage {
            width: px.len() as u32,
            height: 1,
            bit_depth: 8,
            data: px.iter().map(|p| p.map(u16::from)).collect(),
        };
        let rgb: Vec<u8> = px.iter().flatten().copied().collect();
        let rgba: Vec<u8> = px.iter().flat_map(|p| [p[0], p[1], p[2], 7]).collect();
        let channels = [
            Channel::Luma,
            Channel::Single(Colour::Blue),
            Channel::Laser(Colour::Red),
            Channel::Laser(Colour::Green),
            Channel::Laser(Colour::Blue),
        ];
        for channel in channels {
            let want: Vec<u8> = general.channel(channel).data.iter().map(|&v| v as u8).collect();
            assert_eq!(channel_bytes_of_rgb8(&rgb, 3, channel), want, "{channel}");
            assert_eq!(channel_bytes_of_rgb8(&rgba, 4, channel), want, "{channel}");
        }
        // The bytes as the detector reads them, and the pixels after the last whole block.
        let red: Vec<u8> = general.channel(Channel::Laser(Colour::Red)).data.iter().map(|&v| v as u8).collect();
        assert_eq!(channel_bytes_of_rgb8(&rgb, 3, Channel::Laser(Colour::Red)), red);
        assert_eq!(channel_bytes_of_rgb8(&rgba[..4 * 21], 4, Channel::Laser(Colour::Red)), red[..21]);
    }

    fn img_red(img: &RgbImage) -> Vec<u16> {
        img.channel(Channel::Laser(Colour::Red)).data
    }

    #[test]
    fn each_bayer_order_demosaics_a_flat_colour_to_itself() {
        let colour = [180u16, 90, 30];
        for order in BayerPattern::ALL {
            let (w, h) = (8, 6);
            let mut raw = GrayImage::new(w, h, 8);
            for y in 0..h as usize {
                for x in 0..w as usize {
                    raw.data[y * w as usize + x] = colour[order.channel(x, y)];
                }
            }
            let out = demosaic(&raw, order).unwrap();
            assert!(out.data.iter().all(|&px| px == colour), "{order:?}");
        }
    }

    #[test]
    fn demosaicing_interpolates_a_ramp_exactly() {
        // A horizontal ramp in every channel: the interpolated samples are exact (the mirrored
        // border included, where the ramp's slope changes sign only beyond the edge pixel's
        // neighbours: checked inside), whatever the order.
        for order in BayerPattern::ALL {
            let (w, h) = (10usize, 8usize);
            let mut raw = GrayImage::new(w as u32, h as u32, 16);
            for y in 0..h {
                for x in 0..w {
                    raw.data[y * w + x] = (1000 + 100 * x + 1000 * order.channel(x, y)) as u16;
                }
            }
            let out = demosaic(&raw, order).unwrap();
            for y in 2..h - 2 {
                for x in 2..w - 2 {
                    for c in 0..3 {
                        assert_eq!(out.data[y * w + x][c], (1000 + 100 * x + 1000 * c) as u16, "{order:?} {x} {y} {c}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_mosaic_is_read_at_its_red_and_blue_sites_without_interpolating_them() {
        // A ramp in every channel: each site keeps its own sample, its row and column neighbours
        // (green) and its diagonal ones (the third colour) average to their values at the site.
        for order in BayerPattern::ALL {
            let (w, h) = (10usize, 8usize);
            let mut raw = GrayImage::new(w as u32, h as u32, 16);
            let value = |x: usize, y: usize, c: usize| (1000 + 100 * x + 10 * y + 1000 * c) as u16;
            for y in 0..h {
                for x in 0..w {
                    raw.data[y * w + x] = value(x, y, order.channel(x, y));
                }
            }
            for colour in [Colour::Red, Colour::Blue] {
                let (sites, (x0, y0)) = mosaic_sites(&raw, order, colour).unwrap();
                assert_eq!((sites.width, sites.height), (5, 4));
                assert_eq!(order.channel(x0 as usize, y0 as usize), colour.index(), "{order:?} {colour:?}");
                for j in 1..3 {
                    for i in 1..4 {
                        let (x, y) = (x0 as usize + 2 * i, y0 as usize + 2 * j);
                        let want = [0, 1, 2].map(|c| value(x, y, c));
                        assert_eq!(sites.data[j * 5 + i], want, "{order:?} {colour:?} site {i} {j}");
                    }
                }
            }
        }
        let e = mosaic_sites(&GrayImage::new(8, 6, 8), BayerPattern::Rggb, Colour::Green).unwrap_err();
        assert!(e.contains("green has two sites"), "{e}");
        let e = mosaic_sites(&GrayImage::new(7, 6, 8), BayerPattern::Rggb, Colour::Red).unwrap_err();
        assert!(e.contains("7x6") && e.contains("even sides"), "{e}");
    }

    #[test]
    fn odd_sized_mosaics_and_unknown_names_are_refused() {
        let e = demosaic(&GrayImage::new(5, 4, 8), BayerPattern::Rggb).unwrap_err();
        assert!(e.contains("5x4") && e.contains("rggb"), "{e}");
        assert!(BayerPattern::parse("rgbg").unwrap_err().contains("rggb, bggr"));
        assert!("violet".parse::<Colour>().is_err());
    }
}
