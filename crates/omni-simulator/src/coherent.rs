//! Coherent imaging of the laser light: speckle, diffraction and defocus from the lens pupil.
//!
//! Laser light scattered by a rough surface leaves it with a random phase at every point. Its
//! image is the field convolved with the lens's amplitude PSF h (the Fourier transform of the
//! pupil: a disc cut off at 1/(2λN), with defocus as a quadratic phase), then |·|² and the
//! pixel's area. So the object field is a circular complex Gaussian whose intensity is the
//! geometric laser irradiance (sampled q × q per pixel), and the image is |h ∗ field|² summed
//! over each pixel's samples. Grain (≈ λN), contrast and the stripe's diffraction blur come out
//! of this; none is set by hand. Σ|h|² = 1 keeps the mean: its expectation is the geometric
//! image blurred by the intensity PSF |h|². A depolarising surface adds `speckle_patterns`
//! independent patterns, each carrying an equal share of the light.
//!
//! A laser sheet is often far thinner than a sample cell (¼ px), so where the light lies within
//! each cell counts: a cell's scatterers at offsets u from its centre sum to A·h − D·∇h +
//! ½ Q:∇∇h (Taylor to second order), with D and Q the phasor-weighted first and second moments
//! of u. D is A times the light's centroid (without it the stripe would snap to the cell grid)
//! plus a random part as wide as the light's spread about the centroid (the depth of a thin
//! sheet's scatterers, which makes its speckled centre scatter); Q, at its mean, keeps the
//! image's energy. So five more fields, convolved with the derivatives of h.
//!
//! The laser lights a thin band of the image, so the field lives in tiles of [`TILE_PX`] pixels
//! that hold light; each is convolved by FFT with a margin of [`MARGIN_PX`] (h is cut there;
//! [`WIDE_MARGIN_PX`] for a defocus beyond [`MARGIN_PX`]'s reach) and the overlapping outputs
//! are summed as fields, in a fixed order, before squaring. Where the defocus varies over the
//! image, each tile is convolved with the pupil of its own light's defocus.

use crate::rng::{SplitMix64, mix};
use omni_model::Optics;
use rayon::prelude::*;
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

/// Side of a field tile (px).
pub(crate) const TILE_PX: usize = 16;
/// How far the amplitude PSF reaches (px); it is tapered to zero there. Room for a blur circle
/// of [`MARGIN_PX`] px across and the diffraction rings around it.
pub(crate) const MARGIN_PX: usize = 8;
/// The reach for blur circles up to [`MAX_DEFOCUS_PX`] across (the 3 × 3 tiles around an
/// output tile still hold every source that reaches it).
pub(crate) const WIDE_MARGIN_PX: usize = TILE_PX;
/// The largest blur circle (px across) the wide margin holds.
pub(crate) const MAX_DEFOCUS_PX: f64 = 24.0;
/// A tile's defocus is rounded to this step (px of blur circle diameter; a wavefront error of
/// 0.045 waves at F/4, 4.65 µm pixels and 650 nm) up to [`LINEAR_LEVELS`] steps, and beyond to
/// a ratio of [`DEFOCUS_RATIO`]: a wide blur needs no finer grading, and fewer levels keep
/// fewer transfers.
pub(crate) const DEFOCUS_STEP_PX: f64 = 0.2;
const LINEAR_LEVELS: u32 = 20;
const DEFOCUS_RATIO: f64 = 1.05;

/// The defocus level of a blur circle `diameter` px across ([`DEFOCUS_STEP_PX`]).
fn defocus_level(diameter: f64) -> u32 {
    let linear_end = LINEAR_LEVELS as f64 * DEFOCUS_STEP_PX;
    if diameter <= linear_end {
        (diameter / DEFOCUS_STEP_PX).round() as u32
    } else {
        LINEAR_LEVELS + ((diameter / linear_end).ln() / DEFOCUS_RATIO.ln()).round() as u32
    }
}

/// The blur circle (px across) of defocus level `level`.
fn level_diameter(level: u32) -> f64 {
    let linear_end = LINEAR_LEVELS as f64 * DEFOCUS_STEP_PX;
    if level <= LINEAR_LEVELS {
        level as f64 * DEFOCUS_STEP_PX
    } else {
        linear_end * DEFOCUS_RATIO.powi((level - LINEAR_LEVELS) as i32)
    }
}
/// How many defocus levels' transfers an imager keeps beyond those of the frame it images.
const CACHED_LEVELS: usize = 32;

type C64 = Complex<f64>;
type C32 = Complex<f32>;

/// One sample cell's light: its energy (e⁻), the energy-weighted offset of its centroid from
/// the cell centre (e⁻ · px) and the energy-weighted second moments of the offsets (e⁻ · px²).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct CellLight {
    pub energy: f64,
    pub moment_x: f64,
    pub moment_y: f64,
    pub moment_xx: f64,
    pub moment_xy: f64,
    pub moment_yy: f64,
}

impl CellLight {
    /// A cell of `energy` (e⁻) spread evenly over its square of 1/q px.
    pub fn uniform(energy: f64, q: usize) -> CellLight {
        let spread = energy / (12 * q * q) as f64;
        CellLight { energy, moment_xx: spread, moment_yy: spread, ..Default::default() }
    }

    /// A pixel's q × q cells (row-major) from its n × n signal densities (e⁻ per pixel area at
    /// each sample; n a multiple of q), each sample standing for its square of 1/n px.
    pub fn from_samples(density: &[f64], n: usize, q: usize) -> Vec<CellLight> {
        let k = n / q;
        let area = 1.0 / (n * n) as f64;
        // Offset of sample i from its cell's centre (px), and a sample square's own variance.
        let offset = |i: usize| ((i % k) as f64 + 0.5 - 0.5 * k as f64) / n as f64;
        let own = area / 12.0;
        let mut out = vec![CellLight::default(); q * q];
        for (j, row) in density.chunks_exact(n).enumerate() {
            for (i, v) in row.iter().enumerate() {
                let c = &mut out[(j / k) * q + i / k];
                let (e, ox, oy) = (v * area, offset(i), offset(j));
                c.energy += e;
                c.moment_x += e * ox;
                c.moment_y += e * oy;
                c.moment_xx += e * (ox * ox + own);
                c.moment_xy += e * ox * oy;
                c.moment_yy += e * (oy * oy + own);
            }
        }
        out
    }

    /// Adds another share of light in the same cell.
    fn add(&mut self, other: &CellLight) {
        self.energy += other.energy;
        self.moment_x += other.moment_x;
        self.moment_y += other.moment_y;
        self.moment_xx += other.moment_xx;
        self.moment_xy += other.moment_xy;
        self.moment_yy += other.moment_yy;
    }

    /// The lower-triangular factor (l11, l21, l22) of the covariance of the light's position
    /// within the cell about its centroid (px²): the spread of the scatterers whose random
    /// phases the cell's one phasor sums.
    fn spread_factor(&self) -> (f64, f64, f64) {
        let (mx, my) = (self.moment_x / self.energy, self.moment_y / self.energy);
        let cxx = (self.moment_xx / self.energy - mx * mx).max(0.0);
        let cyy = (self.moment_yy / self.energy - my * my).max(0.0);
        let cxy = self.moment_xy / self.energy - mx * my;
        let l11 = cxx.sqrt();
        let l21 = if l11 > 0.0 { cxy / l11 } else { 0.0 };
        (l11, l21, (cyy - l21 * l21).max(0.0).sqrt())
    }
}

/// The laser's geometric irradiance on the q × q sample grid, tile by tile, row-major within a
/// tile of (q·TILE_PX)² cells.
pub(crate) struct LaserField {
    pub q: usize,
    pub tiles: BTreeMap<(u32, u32), Vec<CellLight>>,
    /// Where the defocus varies over the image: per tile, the energy-weighted sum of its
    /// pixels' blur circle diameters (e⁻ · px) and their energy (e⁻).
    defocus: BTreeMap<(u32, u32), (f64, f64)>,
}

impl LaserField {
    pub fn new(q: usize) -> Self {
        LaserField { q, tiles: BTreeMap::new(), defocus: BTreeMap::new() }
    }

    /// Adds pixel (x, y)'s q × q cells (row-major), imaged with a blur circle of
    /// `defocus_px` across (px).
    pub fn add_defocused_pixel(&mut self, x: usize, y: usize, cells: &[CellLight], defocus_px: f64) {
        self.add_pixel(x, y, cells);
        let energy: f64 = cells.iter().map(|c| c.energy).sum();
        let acc = self.defocus.entry(((x / TILE_PX) as u32, (y / TILE_PX) as u32)).or_default();
        acc.0 += energy * defocus_px;
        acc.1 += energy;
    }

    /// Tile `key`'s defocus level ([`defocus_level`]): its light's mean blur circle, at most
    /// [`MAX_DEFOCUS_PX`]; `None` if the field's defocus is one for the whole image.
    fn tile_defocus_level(&self, key: (u32, u32)) -> Option<u32> {
        let (sum, energy) = *self.defocus.get(&key)?;
        let diameter = if energy > 0.0 { (sum / energy).min(MAX_DEFOCUS_PX) } else { 0.0 };
        Some(defocus_level(diameter))
    }

    /// The largest blur circle (px across) of any tile; 0 for one defocus over the image.
    pub fn max_tile_defocus_px(&self) -> f64 {
        level_diameter(self.tiles.keys().filter_map(|k| self.tile_defocus_level(*k)).max().unwrap_or(0))
    }

    /// Adds pixel (x, y)'s q × q cells (row-major).
    pub fn add_pixel(&mut self, x: usize, y: usize, cells: &[CellLight]) {
        let q = self.q;
        let side = q * TILE_PX;
        let key = ((x / TILE_PX) as u32, (y / TILE_PX) as u32);
        let tile = self.tiles.entry(key).or_insert_with(|| vec![CellLight::default(); side * side]);
        let (ox, oy) = ((x % TILE_PX) * q, (y % TILE_PX) * q);
        for j in 0..q {
            for i in 0..q {
                tile[(oy + j) * side + ox + i].add(&cells[j * q + i]);
            }
        }
    }
}

/// FFT of the amplitude PSF on the n × n grid, transposed, with the inverse's 1/n² folded in,
/// and the same for the terms of its Taylor expansion in a source's offset u from its cell's
/// centre: h, −∂h/∂x, −∂h/∂y (per px), ½∂²h/∂x², ∂²h/∂x∂y, ½∂²h/∂y² (per px²).
struct Transfers([Vec<C64>; 6]);

/// The frames imaged so far, and each defocus level's transfers with the frame that last used
/// them.
type LevelCache = (u64, BTreeMap<u32, (u64, Arc<Transfers>)>);

/// The imaging system for one set of optics.
pub(crate) struct CoherentImager {
    q: usize,
    /// FFT size per axis: q · (TILE_PX + 2 · margin).
    n: usize,
    /// How far the amplitude PSF reaches (px).
    margin: usize,
    optics: Optics,
    /// The transfers of the optics' own defocus.
    transfers: Transfers,
    /// Those of other defocus levels ([`defocus_level`]), made when a
    /// field with defocus varying over the image first needs them, each with when it was last
    /// used (the count of frames imaged).
    levels: Mutex<LevelCache>,
    /// Phase ramps (transposed like the transfers) that move the image field by (∓¼, ∓¼) of
    /// a cell: its values between the cells' centres.
    shifts_t: [Vec<C64>; 4],
    fft: Arc<dyn Fft<f64>>,
    ifft: Arc<dyn Fft<f64>>,
    patterns: u32,
}

impl CoherentImager {
    /// Samples per pixel axis for `optics`: the intensity's band (twice the pupil's cutoff) must
    /// stay below the sampling rate.
    pub fn samples_per_px(optics: &Optics) -> usize {
        if 2.0 * optics.coherent_cutoff_per_px() <= 3.0 { 4 } else { 8 }
    }

    /// The imager whose amplitude PSF reaches `margin` px ([`MARGIN_PX`] or [`WIDE_MARGIN_PX`]).
    pub fn with_margin(optics: &Optics, margin: usize) -> Self {
        Self::with_samples(optics, Self::samples_per_px(optics), margin)
    }

    /// The imager with `q` sample cells per pixel axis (at least [`Self::samples_per_px`]).
    fn with_samples(optics: &Optics, q: usize, margin: usize) -> Self {
        let n = q * (TILE_PX + 2 * margin);
        let mut planner = FftPlanner::new();
        let fft = planner.plan_fft_forward(n);
        let ifft = planner.plan_fft_inverse(n);
        let transfers = Self::transfers(optics, q, margin, &fft, &mut planner);
        let omega = |k: usize| 2.0 * std::f64::consts::PI * freq(k, n) * q as f64 / n as f64;
        // f(x + δ) has the spectrum F(ω)·e^{iωδ}.
        let quarter = 0.25 / q as f64;
        let shifts_t = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)].map(|(sx, sy): (f64, f64)| {
            (0..n * n).map(|k| C64::from_polar(1.0, quarter * (sx * omega(k / n) + sy * omega(k % n)))).collect()
        });
        CoherentImager {
            q,
            n,
            margin,
            optics: *optics,
            transfers,
            levels: Mutex::new((0, BTreeMap::new())),
            shifts_t,
            fft,
            ifft,
            patterns: optics.speckle_patterns,
        }
    }

    /// The transfers of `optics` on the grid of `q` cells per px with a reach of `margin` px.
    fn transfers(
        optics: &Optics,
        q: usize,
        margin: usize,
        fft: &Arc<dyn Fft<f64>>,
        planner: &mut FftPlanner<f64>,
    ) -> Transfers {
        let n = q * (TILE_PX + 2 * margin);
        let kernel = amplitude_psf(optics, q, margin, planner);
        // Embed the kernel (centred at 0, wrapped) and transform it.
        let r = (margin * q) as isize;
        let side = 2 * r as usize + 1;
        let mut grid = vec![C64::new(0.0, 0.0); n * n];
        for dy in -r..=r {
            for dx in -r..=r {
                let v = kernel[(dy + r) as usize * side + (dx + r) as usize];
                let (x, y) = (dx.rem_euclid(n as isize) as usize, dy.rem_euclid(n as isize) as usize);
                grid[y * n + x] = v;
            }
        }
        fft2_transposed(&mut grid, n, fft);
        let scale = 1.0 / (n * n) as f64;
        let transfer_t: Vec<C64> = grid.into_iter().map(|c| c * scale).collect();
        // Transposed layout: row index = x frequency bin, column = y frequency bin. A derivative
        // along x multiplies the spectrum by iωx.
        let omega = |k: usize| 2.0 * std::f64::consts::PI * freq(k, n) * q as f64 / n as f64;
        let times = |factor: &dyn Fn(f64, f64) -> C64| -> Vec<C64> {
            transfer_t.iter().enumerate().map(|(k, t)| factor(omega(k / n), omega(k % n)) * t).collect()
        };
        Transfers([
            transfer_t.clone(),
            times(&|wx, _| C64::new(0.0, -wx)),
            times(&|_, wy| C64::new(0.0, -wy)),
            times(&|wx, _| C64::new(-0.5 * wx * wx, 0.0)),
            times(&|wx, wy| C64::new(-wx * wy, 0.0)),
            times(&|_, wy| C64::new(-0.5 * wy * wy, 0.0)),
        ])
    }

    /// The transfers of defocus levels `levels` ([`level_diameter`]): those kept from earlier frames, the others made in parallel. The least recently
    /// used beyond [`CACHED_LEVELS`] are dropped, never one of `levels`; the transfers are a
    /// function of the level alone, so what is kept changes no image.
    fn level_transfers(&self, levels: &std::collections::BTreeSet<u32>) -> BTreeMap<u32, Arc<Transfers>> {
        // Those kept are taken (shared) at once: another frame may drop them from the cache.
        let mut out: BTreeMap<u32, Arc<Transfers>> = {
            let cache = self.levels.lock().unwrap_or_else(|e| e.into_inner());
            levels.iter().filter_map(|l| Some((*l, cache.1.get(l)?.1.clone()))).collect()
        };
        let missing: Vec<u32> = levels.iter().copied().filter(|l| !out.contains_key(l)).collect();
        let made: Vec<(u32, Arc<Transfers>)> = missing
            .par_iter()
            .map(|&level| {
                let optics = Optics { defocus_px: level_diameter(level), focus_mm: None, ..self.optics };
                (level, Arc::new(Self::transfers(&optics, self.q, self.margin, &self.fft, &mut FftPlanner::new())))
            })
            .collect();
        let mut cache = self.levels.lock().unwrap_or_else(|e| e.into_inner());
        cache.0 += 1;
        let now = cache.0;
        for (level, t) in made {
            out.insert(level, t.clone());
            cache.1.insert(level, (now, t));
        }
        for level in levels {
            if let Some(entry) = cache.1.get_mut(level) {
                entry.0 = now;
            }
        }
        while cache.1.len() > CACHED_LEVELS + levels.len() {
            let oldest = cache.1.iter().filter(|(l, _)| !levels.contains(l)).min_by_key(|(_, (used, _))| *used);
            let Some((&level, _)) = oldest else { break };
            cache.1.remove(&level);
        }
        out
    }

    /// The margin (px) an imager needs for a field whose largest blur circle is `defocus_px`
    /// across.
    pub fn margin_for(defocus_px: f64) -> usize {
        if defocus_px <= MARGIN_PX as f64 { MARGIN_PX } else { WIDE_MARGIN_PX }
    }

    #[cfg(test)]
    pub fn q(&self) -> usize {
        self.q
    }

    /// Adds the laser's image (e⁻ per pixel) to `out` (w × h, row-major). Each sample cell's
    /// random phasor is drawn from `surface_seed` and the cell's place in the image alone, so a
    /// still camera sees the same rough surface, and the same grains, in every frame that
    /// lights it.
    pub fn image_into(&self, field: &LaserField, out: &mut [f64], w: usize, h: usize, surface_seed: u64) {
        debug_assert_eq!(field.q, self.q);
        let keys: Vec<(u32, u32)> = field.tiles.keys().copied().collect();
        let index: BTreeMap<(u32, u32), usize> = keys.iter().enumerate().map(|(i, k)| (*k, i)).collect();
        let outputs = output_tiles(&keys);
        let mut intensity = vec![vec![0.0; TILE_PX * TILE_PX]; outputs.len()];
        let share = 1.0 / self.patterns as f64;
        let tile_levels: BTreeMap<(u32, u32), u32> =
            keys.iter().filter_map(|k| Some((*k, field.tile_defocus_level(*k)?))).collect();
        let transfers = self.level_transfers(&tile_levels.values().copied().collect());
        for pattern in 0..self.patterns {
            let pattern_seed = mix(surface_seed ^ mix(0x5BEC_0000 + pattern as u64));
            let spectra: Vec<Vec<C32>> = keys
                .par_iter()
                .map(|key| {
                    let transfers = tile_levels.get(key).map_or(&self.transfers, |l| &*transfers[l]);
                    self.tile_spectrum(&field.tiles[key], share, *key, pattern_seed, transfers)
                })
                .collect();
            // The image field on the four grids shifted by (±¼, ±¼) of a cell, one grid at a
            // time: together each pixel's 2q × 2q sub-cells' centres.
            for ramp in &self.shifts_t {
                let fields: Vec<Vec<C32>> = spectra.par_iter().map(|s| self.shifted_field(s, ramp)).collect();
                intensity.par_iter_mut().zip(&outputs).for_each(|(acc, key)| {
                    let pixels = self.tile_intensity(*key, &index, &fields);
                    acc.iter_mut().zip(&pixels).for_each(|(a, p)| *a += 0.25 * p);
                });
            }
        }
        for (&(tx, ty), pixels) in outputs.iter().zip(&intensity) {
            for j in 0..TILE_PX {
                let y = ty as usize * TILE_PX + j;
                if y >= h {
                    break;
                }
                for i in 0..TILE_PX {
                    let x = tx as usize * TILE_PX + i;
                    if x < w {
                        out[y * w + x] += pixels[j * TILE_PX + i];
                    }
                }
            }
        }
    }

    /// One tile's random field (a share of its energy; each cell's phasor from `pattern_seed`
    /// and the cell's place in the image), convolved with h: the spectrum (transposed) of the
    /// n × n output covering the tile and its margin.
    fn tile_spectrum(
        &self,
        cells: &[CellLight],
        share: f64,
        key: (u32, u32),
        pattern_seed: u64,
        transfers: &Transfers,
    ) -> Vec<C32> {
        let (n, q) = (self.n, self.q);
        let side = q * TILE_PX;
        let off = q * self.margin;
        let zero = C64::new(0.0, 0.0);
        let mut fields: [Vec<C64>; 6] = std::array::from_fn(|_| vec![zero; n * n]);
        for j in 0..side {
            for i in 0..side {
                let c = cells[j * side + i];
                if c.energy > 0.0 {
                    // The cell's scatterers, at offsets u from its centre, sum to
                    // Σ aₖ·h(x − uₖ) ≈ A·h − D·∇h + ½ Q:∇∇h, with A = Σ aₖ a circular complex
                    // Gaussian of variance energy·share, D = Σ aₖ·uₖ and Q = Σ aₖ·uₖuₖᵀ. D is
                    // A times the light's centroid plus a part uncorrelated with A, whose
                    // covariance is the light's spread about that centroid (scatterers at random
                    // places within the cell: a thin sheet's depth); Q is taken at its mean
                    // given A, which keeps the image's energy to second order.
                    let cell = (key.0 as u64 * side as u64 + i as u64, key.1 as u64 * side as u64 + j as u64);
                    let mut rng = SplitMix64::stream(pattern_seed, (cell.1 << 32) | cell.0);
                    let s = (0.5 * c.energy * share).sqrt();
                    let mut draw = || C64::new(s * rng.normal(), s * rng.normal());
                    let a = draw();
                    let (z1, z2) = (draw(), draw());
                    let (l11, l21, l22) = c.spread_factor();
                    let per_energy = a / c.energy;
                    let k = (off + j) * n + off + i;
                    fields[0][k] = a;
                    fields[1][k] = per_energy * c.moment_x + z1 * l11;
                    fields[2][k] = per_energy * c.moment_y + z1 * l21 + z2 * l22;
                    fields[3][k] = per_energy * c.moment_xx;
                    fields[4][k] = per_energy * c.moment_xy;
                    fields[5][k] = per_energy * c.moment_yy;
                }
            }
        }
        for grid in &mut fields {
            // Rows outside the tile's core are zero: their transforms are zero too.
            for row in grid.chunks_exact_mut(n).skip(off).take(side) {
                self.fft.process(row);
            }
            transpose(grid, n);
            self.fft.process(grid);
        }
        let mut spectrum = vec![zero; n * n];
        for (field, transfer) in fields.iter().zip(&transfers.0) {
            spectrum.iter_mut().zip(field.iter().zip(transfer)).for_each(|(g, (f, t))| *g += f * t);
        }
        spectrum.into_iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect()
    }

    /// The image field of a tile's spectrum moved by a phase ramp (`shifts_t`): the n × n
    /// output on a shifted grid.
    fn shifted_field(&self, spectrum: &[C32], ramp: &[C64]) -> Vec<C32> {
        let n = self.n;
        let mut grid: Vec<C64> =
            spectrum.iter().zip(ramp).map(|(s, r)| C64::new(s.re as f64, s.im as f64) * r).collect();
        self.ifft.process(&mut grid);
        transpose(&mut grid, n);
        self.ifft.process(&mut grid);
        grid.into_iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect()
    }

    /// Pixel intensities of output tile `key` on one shifted grid: the fields of the input tiles
    /// around it summed (in a fixed order), squared and summed over each pixel's q × q samples.
    /// Summed over the four grids (2q × 2q per pixel) they weigh the intensity's finest detail
    /// right: the field is band-limited far below the cells' rate, but its square's band, twice
    /// the pupil's cutoff, comes close to it.
    fn tile_intensity(&self, key: (u32, u32), index: &BTreeMap<(u32, u32), usize>, fields: &[Vec<C32>]) -> Vec<f64> {
        let (n, q) = (self.n, self.q);
        let side = q * TILE_PX;
        let mut field = vec![C64::new(0.0, 0.0); side * side];
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let (sx, sy) = (key.0 as i64 + dx, key.1 as i64 + dy);
                if sx < 0 || sy < 0 {
                    continue;
                }
                let Some(&src) = index.get(&(sx as u32, sy as u32)) else { continue };
                // Source tile's output sample (0, 0) sits at q·(MARGIN − TILE) samples from its
                // own origin; this tile's origin is (−dx, −dy) tiles from the source's.
                let ox = (q * self.margin) as i64 - dx * side as i64;
                let oy = (q * self.margin) as i64 - dy * side as i64;
                for j in 0..side as i64 {
                    let y = oy + j;
                    if y < 0 || y >= n as i64 {
                        continue;
                    }
                    let row = &fields[src][y as usize * n..(y as usize + 1) * n];
                    for i in 0..side as i64 {
                        let x = ox + i;
                        if x >= 0 && x < n as i64 {
                            let c = row[x as usize];
                            field[j as usize * side + i as usize] += C64::new(c.re as f64, c.im as f64);
                        }
                    }
                }
            }
        }
        let mut pixels = vec![0.0; TILE_PX * TILE_PX];
        for (j, row) in field.chunks_exact(side).enumerate() {
            for (i, c) in row.iter().enumerate() {
                pixels[(j / q) * TILE_PX + i / q] += c.norm_sqr();
            }
        }
        pixels
    }
}

/// Every tile whose pixels can receive light from the given input tiles (their 3 × 3 blocks).
fn output_tiles(inputs: &[(u32, u32)]) -> Vec<(u32, u32)> {
    let mut out = std::collections::BTreeSet::new();
    for &(x, y) in inputs {
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let (tx, ty) = (x as i64 + dx, y as i64 + dy);
                if tx >= 0 && ty >= 0 {
                    out.insert((tx as u32, ty as u32));
                }
            }
        }
    }
    out.into_iter().collect()
}

/// The amplitude PSF on the q-per-pixel grid within `margin` px, tapered to zero at its edge and
/// scaled to Σ|h|² = 1: the inverse transform of the pupil (a disc at the coherent cutoff with
/// the defocus phase 2π·W₂₀·ρ²), sampled finely in frequency.
fn amplitude_psf(optics: &Optics, q: usize, margin: usize, planner: &mut FftPlanner<f64>) -> Vec<C64> {
    let big = 512usize;
    let df = q as f64 / big as f64; // cycles per px between frequency samples
    let cutoff = optics.coherent_cutoff_per_px();
    let waves = optics.defocus_waves();
    let mut pupil = vec![C64::new(0.0, 0.0); big * big];
    for j in 0..big {
        let fy = freq(j, big) * df;
        for i in 0..big {
            let fx = freq(i, big) * df;
            let rho2 = (fx * fx + fy * fy) / (cutoff * cutoff);
            if rho2 <= 1.0 {
                pupil[j * big + i] = C64::from_polar(1.0, 2.0 * std::f64::consts::PI * waves * rho2);
            }
        }
    }
    let ifft = planner.plan_fft_inverse(big);
    fft2_with(&mut pupil, big, &ifft);
    let r = (margin * q) as isize;
    let side = 2 * r as usize + 1;
    let mut kernel = vec![C64::new(0.0, 0.0); side * side];
    for dy in -r..=r {
        for dx in -r..=r {
            let dist = ((dx * dx + dy * dy) as f64).sqrt() / r as f64;
            if dist >= 1.0 {
                continue;
            }
            // cos² taper over the outer quarter: the cut leaves no ringing edge.
            let taper =
                if dist < 0.75 { 1.0 } else { (0.5 * std::f64::consts::PI * (dist - 0.75) / 0.25).cos().powi(2) };
            let (x, y) = (dx.rem_euclid(big as isize) as usize, dy.rem_euclid(big as isize) as usize);
            kernel[(dy + r) as usize * side + (dx + r) as usize] = pupil[y * big + x] * taper;
        }
    }
    let energy: f64 = kernel.iter().map(|c| c.norm_sqr()).sum();
    kernel.iter_mut().for_each(|c| *c /= energy.sqrt());
    kernel
}

/// Signed frequency index of FFT bin `i` of `n`.
fn freq(i: usize, n: usize) -> f64 {
    if i < n / 2 { i as f64 } else { i as f64 - n as f64 }
}

/// In-place 2-D transform that leaves the result transposed (rows, transpose, rows).
fn fft2_transposed(grid: &mut [C64], n: usize, fft: &Arc<dyn Fft<f64>>) {
    fft.process(grid);
    transpose(grid, n);
    fft.process(grid);
}

/// In-place 2-D transform in the original orientation.
fn fft2_with(grid: &mut [C64], n: usize, fft: &Arc<dyn Fft<f64>>) {
    fft2_transposed(grid, n, fft);
    transpose(grid, n);
}

fn transpose<T: Copy>(grid: &mut [T], n: usize) {
    for j in 0..n {
        for i in j + 1..n {
            grid.swap(j * n + i, i * n + j);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniformly lit square: the mean is kept (over four surfaces: one holds about a thousand
    /// grains at F/8, whose mean scatters by 3 %), and the contrast of fully developed speckle
    /// (one pattern) integrated over pixels is below 1 and grows with the F-number.
    #[test]
    fn speckle_keeps_the_mean_and_its_contrast_follows_the_aperture() {
        let mut contrasts = vec![];
        for f_number in [2.8, 8.0] {
            let optics = Optics { f_number, defocus_px: 0.0, speckle_patterns: 1, ..Optics::paper() };
            let imager = CoherentImager::with_margin(&optics, MARGIN_PX);
            let q = imager.q();
            let mut field = LaserField::new(q);
            let e = vec![CellLight { energy: 100.0 / (q * q) as f64, ..Default::default() }; q * q];
            for y in 16..80 {
                for x in 16..80 {
                    field.add_pixel(x, y, &e);
                }
            }
            let (w, h) = (96, 96);
            let surfaces = 4;
            let (mut means, mut sds, mut totals) = (0.0, 0.0, 0.0);
            for seed in 7..7 + surfaces {
                let mut out = vec![0.0; w * h];
                imager.image_into(&field, &mut out, w, h, seed);
                let inner: Vec<f64> =
                    (24..72).flat_map(|y| (24..72).map(move |x| (x, y))).map(|(x, y)| out[y * w + x]).collect();
                let mean = inner.iter().sum::<f64>() / inner.len() as f64;
                means += mean / surfaces as f64;
                sds += (inner.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / inner.len() as f64).sqrt()
                    / surfaces as f64;
                totals += out.iter().sum::<f64>() / surfaces as f64;
            }
            assert!((means / 100.0 - 1.0).abs() < 0.05, "F/{f_number}: mean {means}");
            contrasts.push(sds / means);
            assert!((totals / (64.0 * 64.0 * 100.0) - 1.0).abs() < 0.05, "energy {totals}");
        }
        assert!(contrasts[0] < contrasts[1] && contrasts[1] < 1.0 && contrasts[0] > 0.3, "{contrasts:?}");
    }

    /// A laser sheet of σ `sigma` px across, on the line y = `y0` px (x 8..56), as q × q cells
    /// per pixel from 32 × 32 samples, with 1000 e⁻ per px of its length.
    fn thin_sheet(q: usize, y0: f64, sigma: f64) -> LaserField {
        let n = 32;
        let mut field = LaserField::new(q);
        for y in 14..34 {
            for x in 8..56 {
                let density: Vec<f64> = (0..n * n)
                    .map(|k| {
                        let d = y as f64 + ((k / n) as f64 + 0.5) / n as f64 - y0;
                        1000.0 * (-0.5 * d * d / (sigma * sigma)).exp() / (sigma * (2.0 * std::f64::consts::PI).sqrt())
                    })
                    .collect();
                if density.iter().any(|v| *v > 1e-9) {
                    field.add_pixel(x, y, &CellLight::from_samples(&density, n, q));
                }
            }
        }
        field
    }

    /// A sheet 0.03 px deep (far thinner than a ¼ px cell) and one 0.2 px deep lie along the
    /// rows; a speckled centre scatters through the depth of its scatterers and the pixels,
    /// which the cells must not change. With q = 4 cells per px (the renderer's) against q = 16,
    /// over 40 surfaces, with the sheet at a cell's edge and a quarter of the way in, the
    /// scatter of the centre in columns 16..48 agrees within 8 %; and over 200 surfaces the
    /// image keeps the sheet's energy within 2.5 % wherever the sheet lies in its cells.
    #[test]
    fn a_thin_sheets_speckle_does_not_depend_on_the_cell_size() {
        let optics = Optics { defocus_px: 0.0, speckle_patterns: 1, ..Optics::paper() };
        let (w, h) = (64, 48);
        let image = |imager: &CoherentImager, field: &LaserField, seed: u64| {
            let mut out = vec![0.0; w * h];
            imager.image_into(field, &mut out, w, h, seed);
            out
        };
        let scatter = |q: usize, y0: f64, sigma: f64| {
            let imager = CoherentImager::with_samples(&optics, q, MARGIN_PX);
            let field = thin_sheet(q, y0, sigma);
            let mut offsets = vec![];
            for seed in 0..40 {
                let out = image(&imager, &field, 1000 + seed);
                for x in 16..48 {
                    let (s, sy) = (14..34)
                        .fold((0.0, 0.0), |(s, sy), y| (s + out[y * w + x], sy + out[y * w + x] * (y as f64 + 0.5)));
                    offsets.push(sy / s - y0);
                }
            }
            let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
            (offsets.iter().map(|o| (o - mean).powi(2)).sum::<f64>() / offsets.len() as f64).sqrt()
        };
        for (sigma, y0) in [(0.03, 23.0), (0.03, 23.0625), (0.2, 23.0), (0.2, 23.0625)] {
            let (coarse, fine) = (scatter(4, y0, sigma), scatter(16, y0, sigma));
            eprintln!("sheet σ {sigma} px at y {y0}: centre scatter q = 4 {coarse:.4} px, q = 16 {fine:.4} px");
            assert!(
                (coarse / fine - 1.0).abs() < 0.08,
                "σ {sigma} px at y {y0}: q = 4 {coarse:.4} px against q = 16 {fine:.4} px"
            );
        }
        let imager = CoherentImager::with_samples(&optics, 4, MARGIN_PX);
        for y0 in [23.0, 23.125] {
            let field = thin_sheet(4, y0, 0.03);
            let input: f64 = field.tiles.values().flatten().map(|c| c.energy).sum();
            let kept =
                (0..200).map(|seed| image(&imager, &field, seed).iter().sum::<f64>()).sum::<f64>() / (200.0 * input);
            eprintln!("sheet at y {y0}: image energy / input {kept:.4}");
            assert!((kept - 1.0).abs() < 0.025, "y {y0}: image energy / input {kept:.4}");
        }
    }

    /// A tile's own defocus, beyond the default margin's reach: a line imaged with a blur circle
    /// of 20 px keeps its energy (within 2 % over 24 surfaces) and widens by the circle's
    /// variance d²/16 = 25 px² (within 10 %), measured against the same line in focus.
    #[test]
    fn a_tile_is_imaged_with_its_own_defocus_out_to_the_wide_margin() {
        let optics = Optics { defocus_px: 0.0, speckle_patterns: 4, ..Optics::paper() };
        let imager = CoherentImager::with_margin(&optics, CoherentImager::margin_for(20.0));
        let q = imager.q();
        let (w, h, y0) = (96, 96, 48);
        let image = |defocus: Option<f64>, seed: u64| {
            let mut field = LaserField::new(q);
            // 1000 e⁻ per px of line, in the middle row of each pixel's cells.
            let cells: Vec<CellLight> = (0..q * q)
                .map(|k| if k / q == q / 2 { CellLight::uniform(1000.0 / q as f64, q) } else { CellLight::default() })
                .collect();
            for x in 16..80 {
                match defocus {
                    Some(d) => field.add_defocused_pixel(x, y0, &cells, d),
                    None => field.add_pixel(x, y0, &cells),
                }
            }
            let mut out = vec![0.0; w * h];
            imager.image_into(&field, &mut out, w, h, seed);
            out
        };
        let spread = |defocus: Option<f64>| {
            let (mut energy, mut variance) = (0.0, 0.0);
            for seed in 0..24 {
                let out = image(defocus, seed);
                energy += out.iter().sum::<f64>() / (24.0 * 64.0 * 1000.0);
                let profile: Vec<f64> = (0..h).map(|y| (32..64).map(|x| out[y * w + x]).sum()).collect();
                let sum: f64 = profile.iter().sum();
                let mean = profile.iter().enumerate().map(|(y, v)| y as f64 * v).sum::<f64>() / sum;
                variance +=
                    profile.iter().enumerate().map(|(y, v)| (y as f64 - mean).powi(2) * v).sum::<f64>() / (24.0 * sum);
            }
            (energy, variance)
        };
        let (sharp_energy, sharp) = spread(None);
        let (energy, blurred) = spread(Some(20.0));
        eprintln!("energy {sharp_energy:.4} / {energy:.4}, variance across {sharp:.3} → {blurred:.3} px²");
        assert!((energy - 1.0).abs() < 0.02 && (sharp_energy - 1.0).abs() < 0.02, "{sharp_energy} {energy}");
        assert!(((blurred - sharp) / 25.0 - 1.0).abs() < 0.1, "variance across {sharp:.3} → {blurred:.3} px²");
    }

    /// Three frames of 19 tiles each, every tile with its own defocus level, more than the
    /// imager keeps: the first frame imaged again after the others (some of its levels dropped
    /// and made again) and by a fresh imager gives the same image. The levels step by 0.2 px up
    /// to 4 px and by 5 % beyond, up to 24 px.
    #[test]
    fn the_defocus_levels_kept_change_no_image() {
        assert_eq!((defocus_level(4.0), defocus_level(4.2), defocus_level(24.0)), (20, 21, 57));
        for level in 0..=57 {
            assert_eq!(defocus_level(level_diameter(level)), level);
        }
        let optics = Optics { defocus_px: 0.0, speckle_patterns: 1, ..Optics::paper() };
        let imager = CoherentImager::with_margin(&optics, WIDE_MARGIN_PX);
        let q = imager.q();
        let cells = vec![CellLight::uniform(100.0 / (q * q) as f64, q); q * q];
        let (w, h) = (19 * TILE_PX, 24);
        let image = |imager: &CoherentImager, first_level: u32| {
            let mut field = LaserField::new(q);
            for tile in 0..19 {
                let defocus = level_diameter(first_level + tile as u32);
                for x in 0..TILE_PX {
                    field.add_defocused_pixel(tile * TILE_PX + x, 8, &cells, defocus);
                }
            }
            let mut out = vec![0.0; w * h];
            imager.image_into(&field, &mut out, w, h, 5);
            out
        };
        let first = image(&imager, 0);
        image(&imager, 19);
        image(&imager, 38);
        let kept = imager.levels.lock().unwrap().1.len();
        assert!(kept <= CACHED_LEVELS + 19, "{kept} levels kept of 57 made");
        assert_eq!(first, image(&imager, 0));
        assert_eq!(first, image(&CoherentImager::with_margin(&optics, WIDE_MARGIN_PX), 0));
    }
}
