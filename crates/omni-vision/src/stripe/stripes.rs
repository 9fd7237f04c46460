//! The stripes of a frame as connected sets of centres (union–find) and what is the stripe's
//! rather than one profile's: its steady lopsidedness and its median top shape.

use super::across::{MAX_ASYMMETRY, MAX_STEADY_ASYMMETRY, STEADY_MIN_POINTS};

/// A stripe's median top shape counts when it exceeds this many of its standard errors (as if
/// its profiles scattered independently; neighbours share pixels, so they do not).
const SIGNIFICANT_ERRORS: f64 = 5.0;

/// The stripes as connected sets of centres (union–find), with each centre's normal's sign
/// relative to its set's first: a normal's sign is arbitrary, so lopsidedness is compared along
/// one orientation per stripe.
pub(super) struct Stripes {
    parent: Vec<u32>,
    /// Whether a centre's normal points against its parent's.
    flipped: Vec<bool>,
}

impl Stripes {
    pub(super) fn new(n: usize) -> Stripes {
        Stripes { parent: (0..n as u32).collect(), flipped: vec![false; n] }
    }

    /// The set's root and whether `i`'s normal points against the root's; the path is
    /// compressed onto the root.
    pub(super) fn find(&mut self, i: usize) -> (usize, bool) {
        let (mut root, mut flip) = (i, false);
        while self.parent[root] as usize != root {
            flip ^= self.flipped[root];
            root = self.parent[root] as usize;
        }
        let (mut node, mut node_flip) = (i, flip);
        while node != root {
            let (next, step) = (self.parent[node] as usize, self.flipped[node]);
            self.parent[node] = root as u32;
            self.flipped[node] = node_flip;
            node_flip ^= step;
            node = next;
        }
        (root, flip)
    }

    /// The points' `(index, value)` grouped by stripe, each value along its stripe's orientation
    /// (`negate`d where the point's normal points against it).
    fn grouped<T: Copy>(&mut self, points: &[(usize, T)], negate: impl Fn(T) -> T) -> ByRoot<T> {
        let oriented: Vec<(usize, T)> = points
            .iter()
            .map(|&(i, value)| {
                let (root, flip) = self.find(i);
                (root, if flip { negate(value) } else { value })
            })
            .collect();
        ByRoot::new(self.parent.len(), &oriented)
    }

    /// Joins the stripes of `a` and `b`, whose normals point against each other if `opposite`.
    pub(super) fn join(&mut self, a: usize, b: usize, opposite: bool) {
        let ((ra, fa), (rb, fb)) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[rb] = ra as u32;
            self.flipped[rb] = fa ^ fb ^ opposite;
        }
    }

    /// Each stripe's medians of its points' `(index, values)` (values along each point's own
    /// normal) where they stand out from their scatter (over [`SIGNIFICANT_ERRORS`] of their
    /// standard error, from their median absolute deviation), else 0; stripes of fewer than
    /// `min_points` have none.
    pub(super) fn medians<const N: usize>(
        &mut self,
        points: &[(usize, [f64; N])],
        min_points: usize,
    ) -> StripeMedians<N> {
        let grouped = self.grouped(points, |values| values.map(|v| -v));
        let mut by_root = vec![[0.0; N]; self.parent.len()];
        let mut errors = vec![[f64::INFINITY; N]; self.parent.len()];
        let mut values = Vec::new();
        for (root, run) in grouped.runs().filter(|(_, run)| run.len() >= min_points) {
            for k in 0..N {
                values.clear();
                values.extend(run.iter().map(|v| v[k]));
                (by_root[root][k], errors[root][k]) = significant_median(&mut values);
            }
        }
        StripeMedians { by_root, errors }
    }

    /// Each stripe's steady lopsidedness, from its points' `(index, asymmetry)` (along each
    /// point's own normal): the median along the stripe's orientation where it is the laser's
    /// shape, 0 where it is not. A laser is lopsided by about as much on all its stripes, so a
    /// stripe's median counts if it lies within [`MAX_ASYMMETRY`] of the frame's typical one
    /// (the median of the stripes' medians' magnitudes, weighted by their points) and below
    /// [`MAX_STEADY_ASYMMETRY`], and the stripes that agree so hold `min_points` points in all:
    /// the laser's shape is the frame's evidence, not one stripe's, so a laser seen only on
    /// short stripes keeps it. Stripes of fewer than [`STEADY_MIN_POINTS`] have none.
    /// Returns, for every centre and as seen along its own normal, the range its lopsidedness
    /// departs from: the laser's shape where it counts; else from 0 to the stripe's median where
    /// that lies within [`MAX_ASYMMETRY`] (most of the stripe passes as not lopsided, so its
    /// median is the stripe's own baseline, and an end lopsided a little beyond 0's limit in the
    /// same direction is no change along it); `None` where the stripe has no median or neither
    /// holds (judged from 0).
    pub(super) fn steady(&mut self, points: &[(usize, f64)], min_points: usize) -> Vec<Option<[f64; 2]>> {
        let grouped = self.grouped(points, |asymmetry| -asymmetry);
        let mut scratch = Vec::new();
        let medians: Vec<(usize, f64, usize)> = grouped
            .runs()
            .filter(|(_, a)| a.len() >= STEADY_MIN_POINTS)
            .map(|(root, a)| {
                scratch.clear();
                scratch.extend_from_slice(a);
                (root, *scratch.select_nth_unstable_by(a.len() / 2, f64::total_cmp).1, a.len())
            })
            .collect();
        let mut sizes: Vec<(f64, usize)> = medians.iter().map(|&(_, m, n)| (m.abs(), n)).collect();
        sizes.sort_by(|a, b| a.0.total_cmp(&b.0));
        let total: usize = sizes.iter().map(|s| s.1).sum();
        let mut seen = 0;
        let typical = sizes
            .iter()
            .find(|s| {
                seen += s.1;
                2 * seen >= total
            })
            .map_or(0.0, |s| s.0);
        let agrees = |m: f64| m.abs() <= MAX_STEADY_ASYMMETRY && (m.abs() - typical).abs() <= MAX_ASYMMETRY;
        let support: usize = medians.iter().filter(|m| agrees(m.1)).map(|m| m.2).sum();
        let mut baseline = vec![None; self.parent.len()];
        for (root, m, _) in medians {
            baseline[root] = if support >= min_points && agrees(m) {
                Some([m, m])
            } else if m.abs() <= MAX_ASYMMETRY {
                Some([m.min(0.0), m.max(0.0)])
            } else {
                None
            };
        }
        (0..self.parent.len())
            .map(|i| {
                let (root, flip) = self.find(i);
                let [lo, hi] = baseline[root]?;
                Some(if flip { [-hi, -lo] } else { [lo, hi] })
            })
            .collect()
    }
}

/// The longest mean unit phasor of a stripe's places across a colour mosaic's period for its
/// top's shape to count ([`StripeMedians::keep_where_the_mosaic_averages_out`]): 0 for places
/// spread evenly over the period, 1 for one place.
const MOSAIC_PHASE_RESULTANT: f64 = 0.5;

/// Values grouped by their stripe's root, in increasing root order: a counting sort, since the
/// roots are centre indices below `roots`.
struct ByRoot<T> {
    /// `values[start[r]..start[r + 1]]`: root r's values.
    start: Vec<u32>,
    values: Vec<T>,
}

impl<T: Copy> ByRoot<T> {
    fn new(roots: usize, rooted: &[(usize, T)]) -> ByRoot<T> {
        let mut start = vec![0u32; roots + 1];
        for &(root, _) in rooted {
            start[root + 1] += 1;
        }
        for r in 1..start.len() {
            start[r] += start[r - 1];
        }
        let mut fill = start.clone();
        // As many slots as values, each then written once at its root's next place.
        let mut values: Vec<T> = rooted.iter().map(|p| p.1).collect();
        for &(root, value) in rooted {
            values[fill[root] as usize] = value;
            fill[root] += 1;
        }
        ByRoot { start, values }
    }

    /// Each root that has values, with them.
    fn runs(&self) -> impl Iterator<Item = (usize, &[T])> {
        self.start
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[1] > w[0])
            .map(|(root, w)| (root, &self.values[w[0] as usize..w[1] as usize]))
    }
}

/// Per-stripe values ([`Stripes::medians`]), indexed by the stripe's root.
pub(super) struct StripeMedians<const N: usize> {
    by_root: Vec<[f64; N]>,
    /// Each median's standard error, as if its profiles scattered independently (infinite
    /// where a stripe has too few points for a median).
    errors: Vec<[f64; N]>,
}

impl<const N: usize> StripeMedians<N> {
    /// Drops the values of the stripes that do not cross a colour mosaic's phases. Through a
    /// mosaic the laser's colour is sampled on a 2 px pitch, and interpolating it shapes each
    /// profile's top by where the stripe lies between the samples: the same all along a stripe
    /// that runs with the mosaic's rows or columns, averaged out of the median of one that
    /// crosses them. A stripe crosses them where its centres' places across it, modulo 2 px
    /// (along the normal's larger axis), are spread around the period: the mean of their unit
    /// phasors is shorter than [`MOSAIC_PHASE_RESULTANT`]. `points`: (index, u, v, normal).
    pub(super) fn keep_where_the_mosaic_averages_out(
        &mut self,
        stripes: &mut Stripes,
        points: impl Iterator<Item = (usize, f64, f64, (f64, f64))>,
    ) {
        let mut phasors = vec![(0.0f64, 0.0f64, 0usize); self.by_root.len()];
        for (i, u, v, (nx, ny)) in points {
            let across = if nx.abs() >= ny.abs() { u } else { v };
            let (s, c) = (std::f64::consts::PI * across).sin_cos();
            let p = &mut phasors[stripes.find(i).0];
            *p = (p.0 + c, p.1 + s, p.2 + 1);
        }
        for (values, (c, s, n)) in self.by_root.iter_mut().zip(phasors) {
            if n > 0 && c.hypot(s) > MOSAIC_PHASE_RESULTANT * n as f64 {
                *values = [0.0; N];
            }
        }
    }

    /// Drops the values of the stripes for which `beyond` holds.
    pub(super) fn drop_where(&mut self, beyond: impl Fn([f64; N]) -> bool) {
        for values in &mut self.by_root {
            if beyond(*values) {
                *values = [0.0; N];
            }
        }
    }

    /// The values of centre `i`'s stripe, as seen along its own normal, with their medians'
    /// standard errors ([`StripeMedians::errors`]).
    pub(super) fn with_errors_of(&self, stripes: &mut Stripes, i: usize) -> ([f64; N], [f64; N]) {
        let (root, flip) = stripes.find(i);
        let values = self.by_root[root];
        (if flip { values.map(|v| -v) } else { values }, self.errors[root])
    }
}

/// The median of `values` (reordered) if it exceeds [`SIGNIFICANT_ERRORS`] of its standard
/// error, else 0; and that error, 1.2533 σ/√n, σ = 1.4826 × the median absolute deviation
/// (normal scatter).
fn significant_median(values: &mut [f64]) -> (f64, f64) {
    let mid = values.len() / 2;
    let median = *values.select_nth_unstable_by(mid, f64::total_cmp).1;
    for v in values.iter_mut() {
        *v = (*v - median).abs();
    }
    let mad = *values.select_nth_unstable_by(mid, f64::total_cmp).1;
    let error = 1.2533 * 1.4826 * mad / (values.len() as f64).sqrt();
    (if median.abs() > SIGNIFICANT_ERRORS * error { median } else { 0.0 }, error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mosaics_shape_of_the_top_counts_only_on_stripes_that_cross_its_phases() {
        // Two stripes of 20 points with the same top shape: one along a column, its centres
        // all 0.3 px past a red column; one oblique, across 7 px of columns.
        let mut stripes = Stripes::new(40);
        for i in 1..20 {
            stripes.join(0, i, false);
            stripes.join(20, 20 + i, false);
        }
        let shapes: Vec<(usize, [f64; 2])> = (0..40).map(|i| (i, [0.1, 0.2])).collect();
        let mut medians = stripes.medians(&shapes, STEADY_MIN_POINTS);
        let placed = (0..40).map(|i| {
            let k = (i % 20) as f64;
            let u = if i < 20 { 10.3 } else { 10.0 + 0.37 * k };
            (i, u, k, (1.0, 0.0))
        });
        medians.keep_where_the_mosaic_averages_out(&mut stripes, placed);
        assert_eq!(medians.with_errors_of(&mut stripes, 5).0, [0.0, 0.0]);
        assert_eq!(medians.with_errors_of(&mut stripes, 25).0, [0.1, 0.2]);
    }

    #[test]
    fn a_short_stripe_departs_from_the_range_between_zero_and_its_median() {
        // Three stripes of 30 points, too few for a laser's shape (64 asked): lopsided by 0.08
        // with ends at 0.15 (its second half's normals the other way round), by 0.3 all along
        // (shaded or cut), and by -0.05.
        let mut stripes = Stripes::new(90);
        for i in 1..30 {
            stripes.join(0, i, i >= 15);
            stripes.join(30, 30 + i, false);
            stripes.join(60, 60 + i, false);
        }
        let lopsided = |i: usize| match i {
            0..30 => {
                let own = if (3..27).contains(&i) { 0.08 } else { 0.15 };
                if i >= 15 { -own } else { own }
            }
            30..60 => 0.3,
            _ => -0.05,
        };
        let means: Vec<(usize, f64)> = (0..90).map(|i| (i, lopsided(i))).collect();
        let steady = stripes.steady(&means, 64);
        assert_eq!(steady[1], Some([0.0, 0.08]));
        assert_eq!(steady[20], Some([-0.08, 0.0]), "seen along the point's own normal");
        assert_eq!(steady[40], None);
        assert_eq!(steady[70], Some([-0.05, 0.0]));
        // With the frame's support, the medians that agree with its typical one (0.08) are the
        // laser's shape; 0.3 does not agree and, beyond the cut limit, is judged from 0.
        let steady = stripes.steady(&means, 16);
        assert_eq!(steady[1], Some([0.08, 0.08]));
        assert_eq!(steady[40], None);
        assert_eq!(steady[70], Some([-0.05, -0.05]));
    }
}
