//! Stripes wider than the detector's reach, found where they are narrow.
//!
//! Rule: a stripe is found at the scale where it is a few pixels wide. The profiles' reach,
//! the seeds' neighbours, the linking distances and the speckle they average all scale with the
//! stripe, so the checks that suit a 2–4 px stripe suit a 20 px one in a frame binned 4 × 4
//! and a saturated 60 px core binned 8 × 8. When the frame's own scale measures enough profiles
//! wider than [`NARROW_HALF_WIDTH_PX`] that peak like a laser's line (a lit surface's flat top
//! does not, and binned it would pass for a stripe), or the frame has more saturated pixels than
//! its points explain ([`SATURATED_PER_POINT`]), the frame is binned 2 × 2, 4 × 4, … up to the
//! largest scale allowed and searched at each. Each coarse point is re-measured on the next
//! finer frame, two profiles along its normal, down to the original pixels, and the re-measured
//! stripe is followed across the gaps the coarse scale left ([`TRACK_PX`]). A finer scale's own
//! points win where both have one, and coarse points that are narrow at their scale
//! ([`WIDE_HALF_WIDTH_PX`]) are left to the finer scale, which measured (or refused) them; but a
//! finer point itself too wide for its scale, on a coarse stripe at least twice as wide and bright,
//! is that stripe's top read against its flanks, and yields to the stripe re-measured.

use super::across::Linked;
use super::{Frame, Pixel, RidgeDetector};

/// Half-maximum width (px) above which a profile is better measured one scale coarser.
pub const NARROW_HALF_WIDTH_PX: f64 = 4.5;
/// Half-maximum width (px, at its own scale) a coarse point needs to be re-measured on the
/// finer frame; narrower ones are the finer scale's (overlap with [`NARROW_HALF_WIDTH_PX`] / 2,
/// so that no width falls between two scales).
pub const WIDE_HALF_WIDTH_PX: f64 = 1.75;
/// Profiles too wide for a scale that make the next scale worth searching.
pub const MIN_WIDE_PROFILES: usize = 20;
/// Saturated pixels per kept point that a saturated stripe narrow enough for this scale leaves
/// (its plateau is a few px wide); more, and a wider core went unseen.
pub const SATURATED_PER_POINT: usize = 8;
/// How far (px) a re-measured stripe is followed across a gap the coarse scale left.
pub const TRACK_PX: usize = 8;
/// Rows apart (px) that the saturation count samples.
const SATURATION_ROW_STEP: usize = 4;
/// Smallest binned frame side (px) worth searching.
const MIN_SIDE_PX: u32 = 32;

impl RidgeDetector {
    /// The points of the next coarser scale (in its pixels), if this one warrants it: `wide`
    /// profiles were too wide here, or the frame has more saturated pixels than its `kept`
    /// points explain (a saturated core wider than the seeds' reach has no seed at all).
    pub(super) fn coarser_stripes<P: Pixel>(
        &self,
        frame: &Frame<'_, P>,
        threshold: f64,
        scale: u32,
        wide: usize,
        kept: usize,
    ) -> Option<Vec<Linked>> {
        if 2 * scale > self.params.max_scale || frame.width / 2 < MIN_SIDE_PX || frame.height / 2 < MIN_SIDE_PX {
            return None;
        }
        // The frame's own scale decides: once it has wide stripes, every coarser scale is
        // searched (each costs a quarter of the one before), since a stripe too wide for one
        // scale may be speckled or lopsided at the next and found only at the one after.
        let wide_stripes =
            || wide >= MIN_WIDE_PROFILES || saturated_pixels(frame) > SATURATED_PER_POINT * (kept + MIN_WIDE_PROFILES);
        if scale == 1 && !wide_stripes() {
            return None;
        }
        let binned = Binned::of(frame);
        let coarse_frame = binned.frame();
        let coarse_threshold = threshold * coarse_frame.max_value / frame.max_value;
        Some(self.coarser().detect_at_scales(&coarse_frame, coarse_threshold, 2 * scale))
    }

    /// The detector for this one's frames binned 2 × 2 (built once).
    fn coarser(&self) -> &RidgeDetector {
        // Coarse pixel i covers fine pixels 2i and 2i + 1: its centre is at 2i + 0.5.
        self.coarser.get_or_init(|| Box::new(self.halved((0.5, 0.5), self.params)))
    }
}

/// About how many samples of the frame are at its saturation level, from every
/// [`SATURATION_ROW_STEP`]th row: a core wide enough to matter spans several of them.
fn saturated_pixels<P: Pixel>(frame: &Frame<'_, P>) -> usize {
    let (full, w) = (P::from_threshold(frame.max_value), frame.width as usize);
    let rows = frame.data.chunks_exact(w).step_by(SATURATION_ROW_STEP);
    // Compared in the samples' own width and counted in bytes (255 samples at most per count),
    // without branches: vectorised at a byte per lane for 8-bit frames.
    let count = |row: &[P]| -> usize {
        row.chunks(255).map(|c| c.iter().fold(0u8, |n, &v| n + u8::from(v >= full)) as usize).sum()
    };
    rows.map(count).sum::<usize>() * SATURATION_ROW_STEP
}

/// A frame binned 2 × 2: sums while they fit 16 bits (exact, and a sum saturates only where
/// its four samples do), means otherwise.
struct Binned {
    width: u32,
    height: u32,
    data: Vec<u16>,
    max_value: f64,
}

impl Binned {
    fn of<P: Pixel>(frame: &Frame<'_, P>) -> Binned {
        let (w, h) = (frame.width as usize / 2, frame.height as usize / 2);
        let fw = frame.width as usize;
        let sums = 4.0 * frame.max_value <= u16::MAX as f64;
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            let top = &frame.data[2 * y * fw..2 * y * fw + 2 * w];
            let bottom = &frame.data[(2 * y + 1) * fw..(2 * y + 1) * fw + 2 * w];
            data.extend(top.chunks_exact(2).zip(bottom.chunks_exact(2)).map(|(a, b)| {
                let sum = a[0].to_u32() + a[1].to_u32() + b[0].to_u32() + b[1].to_u32();
                if sums { sum as u16 } else { sum.div_ceil(4).min(u16::MAX as u32) as u16 }
            }));
        }
        let max_value = if sums { 4.0 * frame.max_value } else { frame.max_value };
        Binned { width: w as u32, height: h as u32, data, max_value }
    }

    fn frame(&self) -> Frame<'_, u16> {
        Frame { width: self.width, height: self.height, data: &self.data, max_value: self.max_value }
    }
}

/// Which cells of a frame hold a point (with something `T` about it): answers "which points lie
/// within r px" for r up to a few cells, by scanning the cells around.
pub(super) struct Occupancy<T = ()> {
    cell: f64,
    columns: usize,
    rows: usize,
    points: Vec<Vec<(f64, f64, T)>>,
}

impl<T: Copy> Occupancy<T> {
    const CELL_PX: f64 = 4.0;

    pub(super) fn new(points: impl Iterator<Item = (f64, f64, T)>, (width, height): (u32, u32)) -> Occupancy<T> {
        let cell = Self::CELL_PX;
        let columns = (width as f64 / cell).ceil() as usize + 1;
        let rows = (height as f64 / cell).ceil() as usize + 1;
        let mut grid = Occupancy { cell, columns, rows, points: vec![Vec::new(); columns * rows] };
        for (u, v, t) in points {
            grid.insert(u, v, t);
        }
        grid
    }

    pub(super) fn insert(&mut self, u: f64, v: f64, t: T) {
        if let Some(k) = self.index(u, v) {
            self.points[k].push((u, v, t));
        }
    }

    fn index(&self, u: f64, v: f64) -> Option<usize> {
        let (c, r) = ((u / self.cell).floor(), (v / self.cell).floor());
        (c >= 0.0 && r >= 0.0 && (c as usize) < self.columns && (r as usize) < self.rows)
            .then(|| r as usize * self.columns + c as usize)
    }

    /// Whether a point lies within `radius` px of (u, v).
    pub(super) fn near(&self, u: f64, v: f64, radius: f64) -> bool {
        self.within(u, v, radius).next().is_some()
    }

    /// What is known of the points within `radius` px of (u, v).
    pub(super) fn within(&self, u: f64, v: f64, radius: f64) -> impl Iterator<Item = T> + '_ {
        let span = (radius / self.cell).ceil() as i64;
        let (c0, r0) = ((u / self.cell).floor() as i64, (v / self.cell).floor() as i64);
        let (columns, rows) = (self.columns as i64, self.rows as i64);
        (r0 - span..=r0 + span)
            .flat_map(move |r| (c0 - span..=c0 + span).map(move |c| (r, c)))
            .filter(move |&(r, c)| r >= 0 && c >= 0 && r < rows && c < columns)
            .flat_map(move |(r, c)| &self.points[(r * columns + c) as usize])
            .filter(move |p| (p.0 - u).powi(2) + (p.1 - v).powi(2) <= radius * radius)
            .map(|p| p.2)
    }
}
