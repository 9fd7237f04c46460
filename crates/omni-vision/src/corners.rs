//! Checkerboard corners in omnidirectional (mirror) images.
//!
//! Pipeline ([`detect_board`]):
//! 1. X-junction candidates: negative Hessian determinant of the smoothed image, local maxima,
//!    verified on a circle (exactly four bright/dark transitions forming two lines), see [`saddle`].
//! 2. A grid grown from 3×3 seeds by local neighbourhood consistency ([`grid`]): no global
//!    straight lines, so strongly curved, small, rotated and partly cut boards are found.
//! 3. The checker colours must alternate over the grid (else the grid is rejected), then the
//!    grid indices are put in a canonical orientation: a fixed handedness in the image
//!    (column direction × row direction > 0 with y down, i.e. as a board seen directly with
//!    columns to the right and rows downwards), and placed inside the board's `cols × rows`
//!    corners, honouring the colour of the first square when the caller knows it.
//! 4. Sub-pixel refinement by gradient orthogonality (as OpenCV's `cornerSubPix`), on the
//!    pixel grid (no interpolation, no pixel locking), in the window (an ellipse spanned by a
//!    fraction of the two local grid steps: the same part of each of the four squares however
//!    the image stretches and skews them) whose solution spreads least, then its first-order
//!    bias on curved edges
//!    removed (`curvature`: the mirror images the board's lines as arcs, which pulls every
//!    corner away from the arcs' concave side).
//!
//! A full board of a symmetric pattern (e.g. 7 × 11 corners: 180° rotation maps it onto itself)
//! has two equally valid labelings; either is a proper rigid motion of the board, so a pose
//! absorbs it. A partial board's placement inside the full board is ambiguous in general; the
//! labeling is still a proper, colour-consistent placement (and [`Orientation`] says so).
//!
//! Seen through one mirror, a board appears mirror-reversed; the calibration decides once per
//! data set whether the labeling must be mirrored ([`BoardCorners::mirrored`]).
//!
//! ```no_run
//! use omni_vision::corners::{detect_board, load_gray, DetectorOptions};
//! let img = load_gray(std::path::Path::new("board.png")).unwrap();
//! let board = detect_board(&img, 9, 6, &DetectorOptions::default()).unwrap();
//! println!("{} corners", board.corners.len());
//! ```

mod curvature;
pub mod edge_blur;
pub mod gray;
pub mod grid;
pub mod overlay;
pub mod saddle;
#[cfg(test)]
mod tests;

pub use edge_blur::{EdgeBlur, edge_blur};
pub use gray::{GrayF32, gaussian_blur, load_gray};
pub use saddle::{Candidate, SaddleOptions, Window};

use grid::{Cell, Grid, GrowLimits};
use std::collections::HashMap;
use std::fmt;

/// Options of the board detector.
#[derive(Debug, Clone, Copy)]
pub struct DetectorOptions {
    pub saddle: SaddleOptions,
    /// Search radius for the next corner as a fraction of the local corner spacing.
    pub search_fraction: f64,
    /// Largest angle (rad) between a corner's edge line and the local grid direction.
    pub max_line_angle: f64,
    /// Fewest corners accepted for a (partial) board.
    pub min_corners: usize,
    /// Seeds tried before giving up (strongest first).
    pub max_seeds: usize,
    /// Smoothing (px) of the image used by the sub-pixel refinement.
    pub refine_sigma: f64,
    /// If known: whether the board square between corners (0,0) and (1,1) is dark.
    pub first_square_dark: Option<bool>,
    /// Optional mirror annulus (centre x, centre y, inner radius, outer radius, all px): only
    /// candidates inside it are considered, and corners whose refinement window reaches within
    /// 1 px of the inner or outer rim are dropped (the rim's edge pulls the sub-pixel position by
    /// up to 3 px on rendered boards cut by the rim).
    pub annulus: Option<[f64; 4]>,
}

impl Default for DetectorOptions {
    fn default() -> Self {
        DetectorOptions {
            saddle: SaddleOptions::default(),
            search_fraction: 0.35,
            max_line_angle: 0.4,
            min_corners: 12,
            max_seeds: 60,
            refine_sigma: 0.8,
            first_square_dark: None,
            annulus: None,
        }
    }
}

/// One detected board corner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardCorner {
    /// (column, row) index of the inner corner on the board, 0-based.
    pub index: [u32; 2],
    /// Sub-pixel position (px; x right, y down, (0, 0) = centre of the top-left pixel).
    pub px: [f64; 2],
}

/// How certain the corner labeling is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Orientation {
    /// Exactly one placement fits the board (size and colours).
    Unique,
    /// The full board was found; its placements differ by a symmetry of the pattern.
    Symmetric,
    /// A partial board: several placements fit; the one given is proper and colour-consistent.
    Partial,
}

/// A board found in an image.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardCorners {
    pub cols: u32,
    pub rows: u32,
    pub corners: Vec<BoardCorner>,
    pub orientation: Orientation,
    /// The board's size in inner corners (longer side, shorter side) as the image shows it,
    /// whatever `cols × rows` was asked for: the corner grid grown without the board's limits,
    /// when all four of its sides end at the board's outer squares ([`seen_board_size`]);
    /// `None` if a side is cut (image, mirror rim, occlusion) or unclear.
    pub seen_size: Option<[u32; 2]>,
}

impl BoardCorners {
    /// The same corners labeled with the opposite handedness (columns reversed).
    pub fn mirrored(&self) -> BoardCorners {
        let mut out = self.clone();
        for c in &mut out.corners {
            c.index[0] = self.cols - 1 - c.index[0];
        }
        out.corners.sort_by_key(|c| (c.index[1], c.index[0]));
        out
    }
}

/// Why no board was accepted in an image.
#[derive(Debug, Clone, PartialEq)]
pub enum Rejection {
    /// No checkerboard-like corner grid at all.
    NoBoard { candidates: usize },
    /// A grid was found but with too few corners.
    TooFewCorners { found: usize, needed: usize },
    /// The grid is larger than the board in some direction (wrong board size?).
    LargerThanBoard { found: (u32, u32) },
    /// The checker colours do not alternate over the grid.
    InconsistentColours,
    /// No placement satisfies the requested first-square colour.
    AmbiguousOrientation,
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rejection::NoBoard { candidates } => write!(f, "no board found ({candidates} corner candidates)"),
            Rejection::TooFewCorners { found, needed } => {
                write!(f, "too few corners ({found} found, at least {needed} needed)")
            }
            Rejection::LargerThanBoard { found } => {
                write!(f, "corner grid {} × {} does not fit the board", found.0, found.1)
            }
            Rejection::InconsistentColours => write!(f, "checker colours do not alternate over the grid"),
            Rejection::AmbiguousOrientation => write!(f, "no board orientation fits the square colours"),
        }
    }
}

/// Detects a `cols × rows` (inner corners) checkerboard in a grey image.
pub fn detect_board(img: &GrayF32, cols: u32, rows: u32, opts: &DetectorOptions) -> Result<BoardCorners, Rejection> {
    let annulus = opts.annulus;
    let mask = move |x: f64, y: f64| match annulus {
        Some([cx, cy, r0, r1]) => {
            let r = (x - cx).hypot(y - cy);
            r >= r0 && r <= r1
        }
        None => true,
    };
    let cands = saddle::find_candidates(img, &opts.saddle, &mask);
    let limits = GrowLimits {
        max_long: cols.max(rows) as i32,
        max_short: cols.min(rows) as i32,
        search_fraction: opts.search_fraction,
        max_line_angle: opts.max_line_angle,
    };
    let refine_img = gaussian_blur(img, opts.refine_sigma);
    let verify = |p: [f64; 2], spacing: f64| local_x_junction(&refine_img, p, spacing, opts.saddle.min_contrast);
    let beyond = |p: [f64; 2], out: [f64; 2], along: [f64; 2]| squares_continue(&refine_img, &mask, p, out, along);
    let grid = grid::grow_best_grid(&cands, &limits, opts.max_seeds, &verify, &beyond);
    if grid.is_empty() {
        return Err(Rejection::NoBoard { candidates: cands.len() });
    }
    // A grid that keeps growing well past the board's size means the board file is wrong (a
    // smaller board would otherwise be "found" inside a larger one). One extra row or column is
    // tolerated: on tiny, blurred boards the junctions along the border can pass for corners.
    let unbounded = GrowLimits { max_long: 4 * limits.max_long + 8, max_short: 4 * limits.max_long + 8, ..limits };
    let wide = grid::grow_further(&cands, &grid, &unbounded, &verify, &beyond);
    let (i0, i1, j0, j1) = wide.bounds();
    let (wi, wj) = (i1 - i0 + 1, j1 - j0 + 1);
    if wi.max(wj) > limits.max_long + 1 || wi.min(wj) > limits.max_short + 1 {
        return Err(Rejection::LargerThanBoard { found: (wi.max(0) as u32, wj.max(0) as u32) });
    }
    let mut windows = HashMap::new();
    let positions = refine_grid(&refine_img, &cands, &grid, &mut windows);
    let positions = drop_unsmooth(positions);
    let smooth = gaussian_blur(img, opts.saddle.sigma);
    let positions = fill_missing(&refine_img, &smooth, positions, &limits, opts, &mut windows, &beyond);
    let positions = drop_unsmooth(positions);
    let positions = curvature::remove_curvature_bias(&refine_img, &positions, |cell: Cell| windows[&cell]);
    let positions = match opts.annulus {
        Some(annulus) => drop_near_rim(positions, annulus, &windows),
        None => positions,
    };
    if positions.len() < opts.min_corners {
        return Err(Rejection::TooFewCorners { found: positions.len(), needed: opts.min_corners });
    }
    let positions = canonical_handedness(positions);
    let colours = cell_colours(&refine_img, &positions).ok_or(Rejection::InconsistentColours)?;
    let mut found = place_on_board(positions, colours, cols, rows, opts.first_square_dark)?;
    let wide: HashMap<Cell, [f64; 2]> = wide.cells.iter().map(|(c, &k)| (*c, cands[k].px)).collect();
    found.seen_size = seen_board_size(&refine_img, &wide, &mask);
    Ok(found)
}

/// The size (longer, shorter side, inner corners) of a grid of corner positions if all four of
/// its sides end at the board's outer squares: beyond the outermost line of corners, half a
/// square out, the squares still alternate (the board's outer squares, ≥ half the contrast of
/// the last inner squares), and one square further they do not (< a quarter: the margin or the
/// background). Grid lines are extrapolated quadratically (the mirror bends them); every sample
/// must lie in the image and in `inside` (the annulus).
pub fn seen_board_size(
    img: &GrayF32,
    pos: &HashMap<Cell, [f64; 2]>,
    inside: &dyn Fn(f64, f64) -> bool,
) -> Option<[u32; 2]> {
    if pos.is_empty() {
        return None;
    }
    let (i0, i1, j0, j1) = bounds(pos.keys());
    // Each side: the cell of line `l` inwards (0 = outermost) at position `u` along it.
    type Side = Box<dyn Fn(i32, i32) -> Cell>;
    let sides: [(Side, i32, i32); 4] = [
        (Box::new(move |l, u| (i1 - l, u)), j0, j1),
        (Box::new(move |l, u| (i0 + l, u)), j0, j1),
        (Box::new(move |l, u| (u, j1 - l)), i0, i1),
        (Box::new(move |l, u| (u, j0 + l)), i0, i1),
    ];
    let sample = |p: [f64; 2], along: [f64; 2], across: [f64; 2]| -> Option<f64> {
        let mut sum = 0.0;
        for (a, b) in [(0.0, 0.0), (0.2, 0.0), (-0.2, 0.0), (0.0, 0.2), (0.0, -0.2)] {
            let (x, y) = (p[0] + a * along[0] + b * across[0], p[1] + a * along[1] + b * across[1]);
            if !img.inside(x, y, 2.0) || !inside(x, y) {
                return None;
            }
            sum += img.bilinear(x, y) as f64;
        }
        Some(sum / 5.0)
    };
    for (cell, u0, u1) in &sides {
        let (mut inner, mut half, mut beyond) = (Vec::new(), Vec::new(), Vec::new());
        for u in *u0..*u1 {
            // Midpoints of the segment (u, u + 1) on lines 0, 1, 2.
            let mid = |l: i32| -> Option<[f64; 2]> {
                let (a, b) = (pos.get(&cell(l, u))?, pos.get(&cell(l, u + 1))?);
                Some([0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])])
            };
            let (Some(m0), Some(m1)) = (mid(0), mid(1)) else { return None };
            let grad = [m0[0] - m1[0], m0[1] - m1[1]];
            let curve = mid(2).map_or([0.0; 2], |m2| [m0[0] - 2.0 * m1[0] + m2[0], m0[1] - 2.0 * m1[1] + m2[1]]);
            let at = |t: f64| {
                let q = 0.5 * t * (t + 1.0);
                [m0[0] + t * grad[0] + q * curve[0], m0[1] + t * grad[1] + q * curve[1]]
            };
            let (a, b) = (pos.get(&cell(0, u))?, pos.get(&cell(0, u + 1))?);
            let along = [b[0] - a[0], b[1] - a[1]];
            inner.push(sample(at(-0.5), along, grad)?);
            half.push(sample(at(0.5), along, grad)?);
            beyond.push(sample(at(1.5), along, grad)?);
        }
        if inner.len() < 2 {
            return None;
        }
        let alternation = |v: &[f64]| v.windows(2).map(|w| (w[0] - w[1]).abs()).sum::<f64>() / (v.len() - 1) as f64;
        let contrast = alternation(&inner);
        if !(alternation(&half) > 0.5 * contrast && alternation(&beyond) < 0.25 * contrast) {
            return None;
        }
    }
    let (wi, wj) = ((i1 - i0 + 1) as u32, (j1 - j0 + 1) as u32);
    Some([wi.max(wj), wi.min(wj)])
}

/// Whether the squares beyond a corner continue the checkerboard ([`grid::outward_steps`]): the
/// two squares half a step `out` beyond `p` (either side of the grid line along `along`) differ
/// by half to twice the contrast of the two squares inside, with the opposite sign (an
/// X-junction: each square beyond has the colour of the square diagonally across). Both bounds
/// matter: a grid on the board must not run into a fainter pattern behind it, nor one on that
/// pattern into the board. Samples
/// outside the image or `inside` (the annulus) cannot tell, and pass.
fn squares_continue(
    img: &GrayF32,
    inside: &dyn Fn(f64, f64) -> bool,
    p: [f64; 2],
    out: [f64; 2],
    along: [f64; 2],
) -> bool {
    let square = |s: f64, t: f64| -> Option<f64> {
        let c = [p[0] + s * out[0] + t * along[0], p[1] + s * out[1] + t * along[1]];
        let mut sum = 0.0;
        for (a, b) in [(0.0, 0.0), (0.15, 0.0), (-0.15, 0.0), (0.0, 0.15), (0.0, -0.15)] {
            let (x, y) = (c[0] + a * out[0] + b * along[0], c[1] + a * out[1] + b * along[1]);
            if !img.inside(x, y, 1.0) || !inside(x, y) {
                return None;
            }
            sum += img.bilinear(x, y) as f64;
        }
        Some(sum / 5.0)
    };
    let (Some(in_plus), Some(in_minus), Some(out_plus), Some(out_minus)) =
        (square(-0.5, 0.5), square(-0.5, -0.5), square(0.5, 0.5), square(0.5, -0.5))
    else {
        return true;
    };
    let (inner, outer) = (in_plus - in_minus, out_plus - out_minus);
    inner * outer < 0.0 && (0.5..=2.0).contains(&(outer.abs() / inner.abs().max(1e-6)))
}

/// An X-junction test at the grid's own scale: a circle of 0.35 × the corner spacing stays inside
/// the four squares around a true corner, while T-junctions at the board's border (black square,
/// white square, white margin) show only two transitions there.
fn local_x_junction(img: &GrayF32, p: [f64; 2], spacing: f64, min_contrast: f32) -> bool {
    let radius = (0.35 * spacing).clamp(2.5, 6.5);
    saddle::circle_test(img, p, radius, 0.35 * min_contrast).is_some()
}

/// The refinement windows tried on each corner, as fractions of the local grid steps. Larger
/// windows (0.7) move corners of rendered mirror boards by up to 0.24 px (docs/DECISIONS.md,
/// 2026-12-04).
const WINDOW_FRACTIONS: [f64; 4] = [0.3, 0.4, 0.5, 0.6];
/// Bounds of the refinement window (px): its shortest semi-axis at least the first, the radius
/// of the circle of its area at most the second. Above 12 px rendered mirror boards lose
/// accuracy (the curvature step removes the first-order bias only); bounding the area rather
/// than the longest axis keeps a stretched window as large as a circular one.
const HALF_WINDOW_PX: (f64, f64) = (2.5, 12.0);

/// The local grid at a corner: the steps (px vectors) to its neighbours along the two grid
/// lines, each the shorter of the two sides' steps in the direction of the line through both
/// (one side where the other is missing), so that the window stays clear of the nearer
/// neighbour where the image compresses the board; `None` where a line has no neighbour.
fn grid_steps(at: &dyn Fn(Cell) -> Option<[f64; 2]>, (i, j): Cell, p: [f64; 2]) -> Option<[[f64; 2]; 2]> {
    let step = |(di, dj): Cell| -> Option<[f64; 2]> {
        let (plus, minus) = (at((i + di, j + dj)), at((i - di, j - dj)));
        let (dir, len) = match (plus, minus) {
            (Some(a), Some(b)) => {
                let d = [a[0] - b[0], a[1] - b[1]];
                (d, (a[0] - p[0]).hypot(a[1] - p[1]).min((p[0] - b[0]).hypot(p[1] - b[1])))
            }
            (Some(a), None) => ([a[0] - p[0], a[1] - p[1]], (a[0] - p[0]).hypot(a[1] - p[1])),
            (None, Some(b)) => ([p[0] - b[0], p[1] - b[1]], (p[0] - b[0]).hypot(p[1] - b[1])),
            (None, None) => return None,
        };
        let n = dir[0].hypot(dir[1]);
        (n > 1e-9).then(|| [dir[0] / n * len, dir[1] / n * len])
    };
    Some([step((1, 0))?, step((0, 1))?])
}

/// The window of `fraction` at a corner: shaped by the grid steps where both are known (see
/// [`saddle::Window`]), else a circle of `fraction` × `spacing`; scaled to stay within
/// [`HALF_WINDOW_PX`] (the upper bound wins).
fn window_at(steps: Option<[[f64; 2]; 2]>, spacing: f64, fraction: f64) -> Window {
    let w =
        steps.and_then(|[e1, e2]| Window::grid(e1, e2, fraction)).unwrap_or_else(|| Window::circle(fraction * spacing));
    let (short, long) = w.semi_axes();
    let k = (HALF_WINDOW_PX.0 / short).max(1.0).min(HALF_WINDOW_PX.1 / (short * long).sqrt());
    w.scaled(k)
}

/// Refines a corner with the window (a fraction of the local grid steps, [`WINDOW_FRACTIONS`])
/// whose solution spreads least ([`saddle::refine_corner_spread`]): large windows average the
/// noise of big, sharp squares, small ones keep clear of neighbouring edges on small, blurred
/// ones. Windows must lie in the image. Returns the corner and its window.
fn refine_adaptive(
    img: &GrayF32,
    start: [f64; 2],
    steps: Option<[[f64; 2]; 2]>,
    spacing: f64,
) -> Option<([f64; 2], Window)> {
    let mut best: Option<([f64; 2], Window, f64)> = None;
    for frac in WINDOW_FRACTIONS {
        let window = window_at(steps, spacing, frac);
        if !img.inside(start[0], start[1], window.semi_axes().1 + 2.0) {
            continue;
        }
        if let Some((p, spread)) = saddle::refine_corner_spread(img, start, &window)
            && best.is_none_or(|b| spread < b.2)
        {
            best = Some((p, window, spread));
        }
    }
    best.map(|(p, window, _)| (p, window))
}

/// Removes corners whose refinement window reaches within 1 px of the annulus' rims
/// (`[cx, cy, inner radius, outer radius]`, px), measured along the radius through the corner.
fn drop_near_rim(
    pos: HashMap<Cell, [f64; 2]>,
    annulus: [f64; 4],
    windows: &HashMap<Cell, Window>,
) -> HashMap<Cell, [f64; 2]> {
    let [cx, cy, r0, r1] = annulus;
    let keep = |cell: &Cell, p: &[f64; 2]| {
        let r = (p[0] - cx).hypot(p[1] - cy);
        let radial = if r > 1e-9 { [(p[0] - cx) / r, (p[1] - cy) / r] } else { [1.0, 0.0] };
        let margin = windows.get(cell).map_or(8.0, |w| w.reach(radial)) + 1.0;
        r >= r0 + margin && r <= r1 - margin
    };
    pos.iter().filter(|(c, p)| keep(c, p)).map(|(c, p)| (*c, *p)).collect()
}

/// Refines every grid corner; the window follows the local grid.
fn refine_grid(
    img: &GrayF32,
    cands: &[Candidate],
    grid: &Grid,
    windows: &mut HashMap<Cell, Window>,
) -> HashMap<Cell, [f64; 2]> {
    let mut out = HashMap::new();
    let at = |c: Cell| grid.cells.get(&c).map(|&k| cands[k].px);
    for (&(i, j), &k) in &grid.cells {
        let p = cands[k].px;
        let spacing = [(i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)]
            .iter()
            .filter_map(|n| grid.cells.get(n))
            .map(|&m| (cands[m].px[0] - p[0]).hypot(cands[m].px[1] - p[1]))
            .fold(f64::INFINITY, f64::min);
        if let Some((r, w)) = refine_adaptive(img, p, grid_steps(&at, (i, j), p), spacing) {
            out.insert((i, j), r);
            windows.insert((i, j), w);
        }
    }
    out
}

/// Fills grid cells the candidate search missed (blurred or low-contrast corners near the rim):
/// the corner is refined from the predicted position and kept if it stays close to the
/// prediction and shows an X-junction whose edge line follows the grid.
fn fill_missing(
    refine_img: &GrayF32,
    smooth: &GrayF32,
    mut pos: HashMap<Cell, [f64; 2]>,
    limits: &GrowLimits,
    opts: &DetectorOptions,
    windows: &mut HashMap<Cell, Window>,
    beyond: grid::BeyondCheck,
) -> HashMap<Cell, [f64; 2]> {
    loop {
        let current = bounds(pos.keys());
        let mut frontier: Vec<Cell> = Vec::new();
        for &(i, j) in pos.keys() {
            for n in [(i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)] {
                if !pos.contains_key(&n) && !frontier.contains(&n) && grid::fits_limits_bounds(current, n, limits) {
                    frontier.push(n);
                }
            }
        }
        frontier.sort();
        let mut added = Vec::new();
        for cell in frontier {
            let Some((pred, spacing, line_dir)) = grid::predict_cell(&|c: Cell| pos.get(&c).copied(), cell) else {
                continue;
            };
            let steps = grid_steps(&|c: Cell| pos.get(&c).copied(), cell, pred);
            let Some((p, window)) = refine_adaptive(refine_img, pred, steps, spacing) else { continue };
            if (p[0] - pred[0]).hypot(p[1] - pred[1]) > opts.search_fraction * spacing {
                continue;
            }
            let radius = (0.35 * spacing).clamp(2.5, 6.5);
            let Some((lines, _)) = saddle::circle_test(smooth, p, radius, 0.5 * opts.saddle.min_contrast) else {
                continue;
            };
            let dir_angle = line_dir[1].atan2(line_dir[0]);
            let at = |c: Cell| pos.get(&c).copied();
            let inner = grid::outward_steps(&at, cell, p).iter().all(|&(o, a)| beyond(p, o, a));
            if inner && lines.iter().any(|&l| saddle::axial_difference(l, dir_angle) < opts.max_line_angle) {
                added.push((cell, p, window));
            }
        }
        if added.is_empty() {
            return pos;
        }
        for (cell, p, window) in added {
            // Each pass adds cells found from the previous grid only; bounds are rechecked next pass.
            if grid::fits_limits_bounds(bounds(pos.keys()), cell, limits) {
                pos.insert(cell, p);
                windows.insert(cell, window);
            }
        }
    }
}

/// Removes corners that break the local smoothness of the grid: along a grid line a corner lies
/// close to the line through its two neighbours (mirror curvature bends lines only slowly) and
/// between them (spacing may change quickly, so the position along the line is loosely checked).
fn drop_unsmooth(mut pos: HashMap<Cell, [f64; 2]>) -> HashMap<Cell, [f64; 2]> {
    loop {
        let mut worst: Option<(Cell, f64)> = None;
        for (&(i, j), p) in &pos {
            for (di, dj) in [(1, 0), (0, 1)] {
                let (Some(a), Some(b)) = (pos.get(&(i - di, j - dj)), pos.get(&(i + di, j + dj))) else {
                    continue;
                };
                let ab = [b[0] - a[0], b[1] - a[1]];
                let len2 = (ab[0] * ab[0] + ab[1] * ab[1]).max(1e-18);
                let ap = [p[0] - a[0], p[1] - a[1]];
                let t = (ap[0] * ab[0] + ap[1] * ab[1]) / len2;
                let off_line = (ap[0] * ab[1] - ap[1] * ab[0]).abs() / len2 * 2.0;
                let dev = if (0.2..=0.8).contains(&t) { off_line } else { f64::INFINITY };
                if dev > 0.2 && worst.is_none_or(|w| dev > w.1) {
                    worst = Some(((i, j), dev));
                }
            }
        }
        match worst {
            Some((cell, _)) => {
                pos.remove(&cell);
            }
            None => return pos,
        }
    }
}

/// Relabels (i, j) → (−i, j) if needed so that e_i × e_j > 0 in image coordinates (y down).
fn canonical_handedness(pos: HashMap<Cell, [f64; 2]>) -> HashMap<Cell, [f64; 2]> {
    let mut votes = 0i64;
    for (&(i, j), p) in &pos {
        if let (Some(a), Some(b)) = (pos.get(&(i + 1, j)), pos.get(&(i, j + 1))) {
            let ei = [a[0] - p[0], a[1] - p[1]];
            let ej = [b[0] - p[0], b[1] - p[1]];
            votes += if ei[0] * ej[1] - ei[1] * ej[0] > 0.0 { 1 } else { -1 };
        }
    }
    if votes >= 0 { pos } else { pos.into_iter().map(|((i, j), p)| ((-i, j), p)).collect() }
}

/// Colour of each complete grid cell (keyed by its lowest corner): true = dark. `None` if the
/// colours do not alternate like a checkerboard: fewer than 85 % of the pairs of side-by-side
/// cells have the darker one where the parity pattern puts it. Each cell is compared with its
/// neighbours, not with one threshold over the board: the light falls off across a board (a
/// lamp to one side, vignetting), so a white square at one end can be darker than the mean of
/// the whites, and a laser stripe across the board lights the black squares it crosses
/// brighter than any white one; neither changes which of two adjacent squares is darker,
/// except across the stripe.
fn cell_colours(img: &GrayF32, pos: &HashMap<Cell, [f64; 2]>) -> Option<HashMap<Cell, bool>> {
    let mut values = HashMap::new();
    for (&(i, j), a) in pos {
        let (Some(b), Some(c), Some(d)) = (pos.get(&(i + 1, j)), pos.get(&(i, j + 1)), pos.get(&(i + 1, j + 1))) else {
            continue;
        };
        let cx = 0.25 * (a[0] + b[0] + c[0] + d[0]);
        let cy = 0.25 * (a[1] + b[1] + c[1] + d[1]);
        values.insert((i, j), img.bilinear(cx, cy));
    }
    // Over the pairs of side-by-side cells: how many have their even-parity cell the darker.
    let (mut pairs, mut even_darker) = (0usize, 0usize);
    for (&(i, j), &v) in &values {
        for next in [(i + 1, j), (i, j + 1)] {
            if let Some(&w) = values.get(&next) {
                let (even, odd) = if (i + j).rem_euclid(2) == 0 { (v, w) } else { (w, v) };
                pairs += 1;
                even_darker += usize::from(even < odd);
            }
        }
    }
    let even_dark = 2 * even_darker >= pairs;
    let agree = if even_dark { even_darker } else { pairs - even_darker };
    if pairs == 0 || (agree as f64) < 0.85 * pairs as f64 {
        return None;
    }
    Some(values.into_keys().map(|c| (c, ((c.0 + c.1).rem_euclid(2) == 0) == even_dark)).collect())
}

/// The four proper rotations of grid indices.
fn rotate(k: usize, (i, j): Cell) -> Cell {
    match k {
        0 => (i, j),
        1 => (-j, i),
        2 => (-i, -j),
        _ => (j, -i),
    }
}

/// Puts the grid inside the board: the first rotation and offset that fit its size and colours.
fn place_on_board(
    pos: HashMap<Cell, [f64; 2]>,
    colours: HashMap<Cell, bool>,
    cols: u32,
    rows: u32,
    first_square_dark: Option<bool>,
) -> Result<BoardCorners, Rejection> {
    let (cols_i, rows_i) = (cols as i32, rows as i32);
    // One complete cell to check colours: its 4 corners after rotation give its board cell.
    let probe = colours.iter().min_by_key(|(c, _)| **c).map(|(c, d)| (*c, *d));
    let mut placements = Vec::new();
    let mut extent_fits = false;
    for k in 0..4 {
        let rotated: Vec<Cell> = pos.keys().map(|&c| rotate(k, c)).collect();
        let imin = rotated.iter().map(|c| c.0).min().unwrap_or(0);
        let imax = rotated.iter().map(|c| c.0).max().unwrap_or(0);
        let jmin = rotated.iter().map(|c| c.1).min().unwrap_or(0);
        let jmax = rotated.iter().map(|c| c.1).max().unwrap_or(0);
        if imax - imin >= cols_i || jmax - jmin >= rows_i {
            continue;
        }
        extent_fits = true;
        for oi in -imin..=(cols_i - 1 - imax) {
            for oj in -jmin..=(rows_i - 1 - jmax) {
                let colour_ok = match (first_square_dark, probe) {
                    (Some(want), Some(((i, j), dark))) => {
                        let corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)].map(|c| rotate(k, c));
                        let bi = corners.iter().map(|c| c.0).min().unwrap_or(0) + oi;
                        let bj = corners.iter().map(|c| c.1).min().unwrap_or(0) + oj;
                        // Board cell (bi, bj) is dark iff its parity matches the first square's.
                        let board_dark = ((bi + bj).rem_euclid(2) == 0) == want;
                        board_dark == dark
                    }
                    _ => true,
                };
                if colour_ok {
                    placements.push((k, oi, oj));
                }
            }
        }
    }
    if !extent_fits {
        let (i0, i1, j0, j1) = bounds(pos.keys());
        return Err(Rejection::LargerThanBoard { found: ((i1 - i0 + 1) as u32, (j1 - j0 + 1) as u32) });
    }
    let Some(&(k, oi, oj)) = placements.first() else {
        return Err(Rejection::AmbiguousOrientation);
    };
    let orientation = if placements.len() == 1 {
        Orientation::Unique
    } else if pos.len() == (cols * rows) as usize {
        Orientation::Symmetric
    } else {
        Orientation::Partial
    };
    let mut corners: Vec<BoardCorner> = pos
        .into_iter()
        .map(|(c, px)| {
            let (i, j) = rotate(k, c);
            BoardCorner { index: [(i + oi) as u32, (j + oj) as u32], px }
        })
        .collect();
    corners.sort_by_key(|c| (c.index[1], c.index[0]));
    Ok(BoardCorners { cols, rows, corners, orientation, seen_size: None })
}

fn bounds<'a>(cells: impl Iterator<Item = &'a Cell>) -> (i32, i32, i32, i32) {
    cells.fold((i32::MAX, i32::MIN, i32::MAX, i32::MIN), |b, &(i, j)| (b.0.min(i), b.1.max(i), b.2.min(j), b.3.max(j)))
}
