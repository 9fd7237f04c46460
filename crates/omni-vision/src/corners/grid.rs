//! Growing a checkerboard grid from corner candidates by local neighbourhood consistency.
//!
//! A seed is a candidate whose four neighbours along its own two edge lines and the four
//! diagonal corners all exist (a 3×3 patch). The grid then grows one cell at a time: a missing
//! cell next to the grid is predicted from the nearest known cells (quadratic or linear
//! extrapolation along a grid line, or a parallelogram with a known diagonal neighbour), and the
//! nearest free candidate within a fraction of the local spacing whose edge lines agree with the
//! local grid directions is taken. Nothing assumes global straight lines, so strongly curved
//! boards (mirror images) grow as well as flat ones, and boards cut by the image or mirror edge
//! simply stop growing there.

use super::saddle::{Candidate, axial_difference};
use std::collections::HashMap;

/// Grid cell index (column i, row j); may be negative while growing.
pub type Cell = (i32, i32);

/// A grown grid: cell → candidate index.
#[derive(Debug, Clone, Default)]
pub struct Grid {
    pub cells: HashMap<Cell, usize>,
}

impl Grid {
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Inclusive index bounds (imin, imax, jmin, jmax).
    pub fn bounds(&self) -> (i32, i32, i32, i32) {
        let mut b = (i32::MAX, i32::MIN, i32::MAX, i32::MIN);
        for &(i, j) in self.cells.keys() {
            b = (b.0.min(i), b.1.max(i), b.2.min(j), b.3.max(j));
        }
        b
    }
}

/// Limits of the grid growth.
#[derive(Debug, Clone, Copy)]
pub struct GrowLimits {
    /// Largest extent along either grid axis (the longer board side, in corners).
    pub max_long: i32,
    /// Largest extent along the shorter grid axis.
    pub max_short: i32,
    /// Search radius as a fraction of the local corner spacing.
    pub search_fraction: f64,
    /// Largest angle (rad) between a candidate's edge line and the local grid direction.
    pub max_line_angle: f64,
}

struct Index {
    cell_size: f64,
    buckets: HashMap<(i64, i64), Vec<usize>>,
}

impl Index {
    fn new(cands: &[Candidate], cell_size: f64) -> Self {
        let mut buckets: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (k, c) in cands.iter().enumerate() {
            buckets.entry(Self::key(c.px, cell_size)).or_default().push(k);
        }
        Index { cell_size, buckets }
    }

    fn key(p: [f64; 2], s: f64) -> (i64, i64) {
        ((p[0] / s).floor() as i64, (p[1] / s).floor() as i64)
    }

    /// Candidates within `radius` of `p`, nearest first.
    fn within(&self, cands: &[Candidate], p: [f64; 2], radius: f64) -> Vec<(f64, usize)> {
        let (kx0, ky0) = Self::key([p[0] - radius, p[1] - radius], self.cell_size);
        let (kx1, ky1) = Self::key([p[0] + radius, p[1] + radius], self.cell_size);
        let mut out = Vec::new();
        for kx in kx0..=kx1 {
            for ky in ky0..=ky1 {
                if let Some(list) = self.buckets.get(&(kx, ky)) {
                    for &k in list {
                        let d = dist(cands[k].px, p);
                        if d <= radius {
                            out.push((d, k));
                        }
                    }
                }
            }
        }
        out.sort_by(|a, b| a.0.total_cmp(&b.0));
        out
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn angle_of(v: [f64; 2]) -> f64 {
    v[1].atan2(v[0])
}

/// Whether the candidate has an edge line within `tol` of direction `dir` (any sign).
fn has_line_along(c: &Candidate, dir: [f64; 2], tol: f64) -> bool {
    let a = angle_of(dir);
    c.lines.iter().any(|&l| axial_difference(l, a) < tol)
}

/// A check of the squares beyond a corner the grid grows to: `(corner, out, along)` with `out`
/// the grid step from the grid to the corner and `along` the step along the new grid line (px);
/// true if the squares half a step further out continue the checkerboard (see
/// [`outward_steps`]).
pub type BeyondCheck<'a> = &'a dyn Fn([f64; 2], [f64; 2], [f64; 2]) -> bool;

/// Grows the largest consistent grid found from the strongest seeds.
///
/// `verify(position, local spacing)` re-checks a candidate at the scale of the grid around it
/// (e.g. an X-junction test on a circle that stays inside the four squares), so that junctions
/// at the board's border, which look like corners at a coarser scale, are not taken; `beyond`
/// stops the growth at the board's outer squares.
pub fn grow_best_grid(
    cands: &[Candidate],
    limits: &GrowLimits,
    max_seeds: usize,
    verify: &dyn Fn([f64; 2], f64) -> bool,
    beyond: BeyondCheck,
) -> Grid {
    if cands.len() < 9 {
        return Grid::default();
    }
    let index = Index::new(cands, 16.0);
    let mut order: Vec<usize> = (0..cands.len()).collect();
    order.sort_by(|&a, &b| cands[b].response.total_cmp(&cands[a].response));
    let mut best = Grid::default();
    let mut used_as_member = vec![false; cands.len()];
    let target = (limits.max_long * limits.max_short) as usize;
    let mut tried = 0;
    for &seed in &order {
        if tried >= max_seeds || best.len() >= target {
            break;
        }
        if used_as_member[seed] {
            continue; // already part of a grid at least as large as any it would seed
        }
        let Some(grid) = seed_grid(cands, &index, seed, limits, verify) else {
            continue;
        };
        tried += 1;
        let grid = grow(cands, &index, grid, limits, verify, beyond);
        for &k in grid.cells.values() {
            used_as_member[k] = true;
        }
        if grid.len() > best.len() {
            best = grid;
        }
    }
    best
}

/// `grid` grown further under other `limits` (e.g. without the board's size, to see how far the
/// pattern of this board really extends).
pub fn grow_further(
    cands: &[Candidate],
    grid: &Grid,
    limits: &GrowLimits,
    verify: &dyn Fn([f64; 2], f64) -> bool,
    beyond: BeyondCheck,
) -> Grid {
    if grid.is_empty() {
        return Grid::default();
    }
    grow(cands, &Index::new(cands, 16.0), grid.clone(), limits, verify, beyond)
}

/// The nearest candidate from `p` along direction `dir` (± `tol` rad) within `max_d`, which
/// also has an edge line along `dir`.
fn neighbour_along(
    cands: &[Candidate],
    index: &Index,
    from: usize,
    dir: [f64; 2],
    max_d: f64,
    tol: f64,
) -> Option<(usize, f64)> {
    let p = cands[from].px;
    let a = angle_of(dir);
    index.within(cands, p, max_d).into_iter().find_map(|(d, k)| {
        if k == from || d < 2.0 {
            return None;
        }
        let b = angle_of(sub(cands[k].px, p));
        let diff = (b - a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
        (diff.abs() < tol && has_line_along(&cands[k], dir, tol)).then_some((k, d))
    })
}

/// A 3×3 seed patch around `seed`, or `None`.
fn seed_grid(
    cands: &[Candidate],
    index: &Index,
    seed: usize,
    limits: &GrowLimits,
    verify: &dyn Fn([f64; 2], f64) -> bool,
) -> Option<Grid> {
    let c = &cands[seed];
    let tol = limits.max_line_angle;
    let max_d = 120.0;
    let dirs: Vec<[f64; 2]> = c.lines.iter().map(|&l| [l.cos(), l.sin()]).collect();
    let mut nb = [[0usize; 2]; 2]; // [axis][sign]
    for axis in 0..2 {
        for (s, sign) in [1.0, -1.0].iter().enumerate() {
            let d = [dirs[axis][0] * sign, dirs[axis][1] * sign];
            let (k, _) = neighbour_along(cands, index, seed, d, max_d, tol)?;
            nb[axis][s] = k;
        }
        let d_plus = dist(cands[nb[axis][0]].px, c.px);
        let d_minus = dist(cands[nb[axis][1]].px, c.px);
        let ratio = d_plus / d_minus;
        if !(0.5..=2.0).contains(&ratio) {
            return None;
        }
    }
    let mut grid = Grid::default();
    grid.cells.insert((0, 0), seed);
    grid.cells.insert((1, 0), nb[0][0]);
    grid.cells.insert((-1, 0), nb[0][1]);
    grid.cells.insert((0, 1), nb[1][0]);
    grid.cells.insert((0, -1), nb[1][1]);
    for (di, dj) in [(1, 1), (1, -1), (-1, 1), (-1, -1)] {
        let a = cands[grid.cells[&(di, 0)]].px;
        let b = cands[grid.cells[&(0, dj)]].px;
        let pred = [a[0] + b[0] - c.px[0], a[1] + b[1] - c.px[1]];
        let spacing = dist(a, c.px).min(dist(b, c.px));
        let k = index
            .within(cands, pred, limits.search_fraction * spacing)
            .into_iter()
            .map(|(_, k)| k)
            .find(|k| !grid.cells.values().any(|v| v == k))?;
        grid.cells.insert((di, dj), k);
    }
    let distinct: std::collections::HashSet<usize> = grid.cells.values().cloned().collect();
    let spacing = [(1, 0), (-1, 0), (0, 1), (0, -1)]
        .iter()
        .map(|n| dist(cands[grid.cells[n]].px, c.px))
        .fold(f64::INFINITY, f64::min);
    let verified = grid.cells.values().all(|&k| verify(cands[k].px, spacing));
    (distinct.len() == 9 && verified).then_some(grid)
}

/// A prediction of the position of a missing cell from its known neighbours: (position,
/// local spacing, local direction of a grid line through the cell), all px.
pub fn predict_cell(pos: &dyn Fn(Cell) -> Option<[f64; 2]>, cell: Cell) -> Option<([f64; 2], f64, [f64; 2])> {
    let (i, j) = cell;
    let mut preds: Vec<([f64; 2], f64)> = Vec::new(); // (position, weight)
    let mut spacing = f64::INFINITY;
    let mut line_dir = [0.0, 0.0];
    for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
        let Some(p1) = pos((i - di, j - dj)) else { continue };
        let Some(p2) = pos((i - 2 * di, j - 2 * dj)) else { continue };
        spacing = spacing.min(dist(p1, p2));
        line_dir = sub(p1, p2);
        if let Some(p3) = pos((i - 3 * di, j - 3 * dj)) {
            // Quadratic extrapolation follows the curvature of mirror images.
            preds.push(([3.0 * p1[0] - 3.0 * p2[0] + p3[0], 3.0 * p1[1] - 3.0 * p2[1] + p3[1]], 2.0));
        } else {
            preds.push(([2.0 * p1[0] - p2[0], 2.0 * p1[1] - p2[1]], 1.0));
        }
    }
    for (di, dj) in [(1, 1), (1, -1), (-1, 1), (-1, -1)] {
        let (Some(a), Some(b), Some(d)) = (pos((i - di, j)), pos((i, j - dj)), pos((i - di, j - dj))) else {
            continue;
        };
        spacing = spacing.min(dist(a, d)).min(dist(b, d));
        if line_dir == [0.0, 0.0] {
            line_dir = sub(b, d);
        }
        preds.push(([a[0] + b[0] - d[0], a[1] + b[1] - d[1]], 2.0));
    }
    if preds.is_empty() || !spacing.is_finite() {
        return None;
    }
    let wsum: f64 = preds.iter().map(|p| p.1).sum();
    let x = preds.iter().map(|p| p.0[0] * p.1).sum::<f64>() / wsum;
    let y = preds.iter().map(|p| p.0[1] * p.1).sum::<f64>() / wsum;
    Some(([x, y], spacing, line_dir))
}

fn predict(cands: &[Candidate], grid: &Grid, cell: Cell) -> Option<([f64; 2], f64, [f64; 2])> {
    predict_cell(&|c: Cell| grid.cells.get(&c).map(|&k| cands[k].px), cell)
}

/// Whether adding `cell` keeps a grid with these cells within the board size.
pub fn fits_limits_bounds(bounds: (i32, i32, i32, i32), cell: Cell, limits: &GrowLimits) -> bool {
    let (i0, i1, j0, j1) = bounds;
    let wi = i1.max(cell.0) - i0.min(cell.0) + 1;
    let wj = j1.max(cell.1) - j0.min(cell.1) + 1;
    wi.max(wj) <= limits.max_long && wi.min(wj) <= limits.max_short
}

/// The steps `(out, along)` (px) at a corner placed at `p` in `cell` for every side on which it
/// would end the grid: `out` from its neighbour inside the grid to `p`, `along` one step along
/// that neighbour's perpendicular grid line. A corner is an inner corner of the board only if
/// the squares half an `out` beyond it still alternate like the ones inside; the board's edge
/// (T-junctions with the margin, or a background pattern behind it) fails that.
pub fn outward_steps(pos: &dyn Fn(Cell) -> Option<[f64; 2]>, cell: Cell, p: [f64; 2]) -> Vec<([f64; 2], [f64; 2])> {
    let (i, j) = cell;
    let mut out = Vec::new();
    for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
        let Some(inner) = pos((i - di, j - dj)) else { continue };
        if pos((i + di, j + dj)).is_some() {
            continue;
        }
        let n = (i - di, j - dj);
        let (pi, pj) = (dj, di);
        let along = match (pos((n.0 + pi, n.1 + pj)), pos((n.0 - pi, n.1 - pj))) {
            (Some(a), _) => sub(a, inner),
            (None, Some(b)) => sub(inner, b),
            (None, None) => continue,
        };
        out.push((sub(p, inner), along));
    }
    out
}

fn fits_limits(grid: &Grid, cell: Cell, limits: &GrowLimits) -> bool {
    fits_limits_bounds(grid.bounds(), cell, limits)
}

/// Grows `grid` until no missing neighbour cell finds a consistent candidate.
fn grow(
    cands: &[Candidate],
    index: &Index,
    mut grid: Grid,
    limits: &GrowLimits,
    verify: &dyn Fn([f64; 2], f64) -> bool,
    beyond: BeyondCheck,
) -> Grid {
    let mut used: std::collections::HashSet<usize> = grid.cells.values().cloned().collect();
    loop {
        let mut frontier: Vec<Cell> = Vec::new();
        for &(i, j) in grid.cells.keys() {
            for n in [(i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)] {
                if !grid.cells.contains_key(&n) && !frontier.contains(&n) {
                    frontier.push(n);
                }
            }
        }
        frontier.sort();
        let mut added = false;
        for cell in frontier {
            if grid.cells.contains_key(&cell) || !fits_limits(&grid, cell, limits) {
                continue;
            }
            let Some((pred, spacing, line_dir)) = predict(cands, &grid, cell) else { continue };
            let radius = limits.search_fraction * spacing;
            let at = |c: Cell| grid.cells.get(&c).map(|&m| cands[m].px);
            let hit = index.within(cands, pred, radius).into_iter().find(|&(_, k)| {
                !used.contains(&k)
                    && has_line_along(&cands[k], line_dir, limits.max_line_angle)
                    && verify(cands[k].px, spacing)
                    && outward_steps(&at, cell, cands[k].px).iter().all(|&(o, a)| beyond(cands[k].px, o, a))
            });
            if let Some((_, k)) = hit {
                grid.cells.insert(cell, k);
                used.insert(k);
                added = true;
            }
        }
        if !added {
            return grid;
        }
    }
}
