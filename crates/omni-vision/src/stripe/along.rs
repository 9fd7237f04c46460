//! Fitting the stripe along its length ([`super::RidgeParams::along_stripe_px`]).
//!
//! Each ray measures the stripe on its own, so the noise of neighbouring points is nearly
//! independent while the stripe itself is smooth over a few pixels. Replacing each point's
//! radius by a least-squares line `r(s)` through the points of the same stripe within ±L px of
//! arc `s` (evaluated at the point itself) averages the noise of about `2L / 1.6 px`
//! independent measurements (the sampling kernel and the optics correlate rays closer than
//! that). A straight line leaves a curved stripe's centre off by about L²/(6R) px at a radius
//! of curvature R (0.015 px for L = 3 px, R = 100 px); at a kink (a room corner) the points
//! within L of it move by up to a quarter of L times the change of slope, so a point whose fit
//! moves it by more than [`MAX_MOVE_PX`] keeps its own measurement.

use super::StripePoint;
use std::f64::consts::{PI, TAU};

/// Fewest points (the point included) a fit needs.
const MIN_POINTS: usize = 5;
/// A fit that moves its point farther than this (px) is not trusted (kink, other stripe).
const MAX_MOVE_PX: f64 = 0.5;

/// The point's polar coordinates around the sampling centre: azimuth (rad, −π..π) and radius.
fn polar(p: &StripePoint, centre: (f64, f64)) -> (f64, f64) {
    let (dx, dy) = (p.u - centre.0, p.v - centre.1);
    (dy.atan2(dx), dx.hypot(dy))
}

/// Fits every point's radius along the stripe over ±`half_px` px of arc; neighbours belong to the
/// same stripe if their radius differs by at most `max_dr` px. Points keep their order, width,
/// intensity and flags; only `u`, `v` move, along their own ray.
pub fn fit_along_stripe(points: &[StripePoint], centre: (f64, f64), half_px: f64, max_dr: f64) -> Vec<StripePoint> {
    let mut pol: Vec<(f64, f64, usize)> =
        points.iter().enumerate().map(|(i, p)| (polar(p, centre), i)).map(|((a, r), i)| (a, r, i)).collect();
    pol.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = points.to_vec();
    let n = pol.len();
    for k in 0..n {
        let (phi, r, idx) = pol[k];
        let half_angle = half_px / r.max(1.0);
        // Sums of the least-squares line r = a + b·s over the neighbours (s = arc, px).
        let (mut s0, mut s1, mut s2, mut t0, mut t1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut count = 0;
        let mut add = |(phj, rj): (f64, f64)| {
            let mut d = phj - phi;
            if d > PI {
                d -= TAU;
            } else if d < -PI {
                d += TAU;
            }
            if d.abs() > half_angle || (rj - r).abs() > max_dr {
                return;
            }
            let s = d * r;
            s0 += 1.0;
            s1 += s;
            s2 += s * s;
            t0 += rj;
            t1 += s * rj;
            count += 1;
        };
        // Walk outwards from k in the azimuth order (wrapping around) until out of the window.
        add((phi, r));
        for dir in [1isize, -1] {
            for step in 1..n {
                let j = (k as isize + dir * step as isize).rem_euclid(n as isize) as usize;
                if j == k {
                    break;
                }
                let mut d = (pol[j].0 - phi).abs();
                if d > PI {
                    d = TAU - d;
                }
                if d > half_angle {
                    break;
                }
                add((pol[j].0, pol[j].1));
            }
        }
        if count < MIN_POINTS {
            continue;
        }
        let det = s0 * s2 - s1 * s1;
        if det.abs() < 1e-9 {
            continue;
        }
        // Line value at s = 0 (the point's own ray).
        let a = (s2 * t0 - s1 * t1) / det;
        if !a.is_finite() || (a - r).abs() > MAX_MOVE_PX {
            continue;
        }
        let (sin, cos) = phi.sin_cos();
        out[idx].u = centre.0 + a * cos;
        out[idx].v = centre.1 + a * sin;
    }
    out
}

/// Points of one stripe lie at most this far (px) from their nearest neighbour on it: about one
/// per pixel of length, with gaps where a point was dropped (a dark speckle).
pub(super) const STRIPE_LINK_PX: f64 = 2.5;

/// What [`refuse_short_stripes`] kept and refused.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShortStripes {
    pub kept: Vec<StripePoint>,
    /// Points removed: their stripe spans less than the window.
    pub refused: usize,
    /// The longest end-to-end span of a stripe in the frame (px).
    pub longest_px: f64,
}

/// Removes the points of stripes that span less than `window_px` end to end, which a fit along
/// the stripe over that window cannot be made on. A stripe is a chain of points each within
/// `STRIPE_LINK_PX` of the next; its span is the distance between its two farthest points
/// (the chord, shorter than the arc on a curved stripe). Order and attributes are kept.
pub fn refuse_short_stripes(points: Vec<StripePoint>, window_px: f64) -> ShortStripes {
    let labels = stripe_labels(&points);
    let stripes = labels.iter().max().map_or(0, |&m| m + 1);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); stripes];
    for (i, &l) in labels.iter().enumerate() {
        members[l].push(i);
    }
    let spans: Vec<f64> = members.iter().map(|m| span_px(&points, m)).collect();
    let longest_px = spans.iter().cloned().fold(0.0, f64::max);
    let total = points.len();
    let kept: Vec<StripePoint> =
        points.into_iter().zip(&labels).filter(|(_, l)| spans[**l] >= window_px).map(|(p, _)| p).collect();
    ShortStripes { refused: total - kept.len(), kept, longest_px }
}

/// The stripe (connected chain, 0-based) of every point: union-find over a grid of cells
/// [`STRIPE_LINK_PX`] wide.
pub(super) fn stripe_labels(points: &[StripePoint]) -> Vec<usize> {
    let cell = |p: &StripePoint| ((p.u / STRIPE_LINK_PX).floor() as i64, (p.v / STRIPE_LINK_PX).floor() as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = std::collections::HashMap::new();
    for (i, p) in points.iter().enumerate() {
        grid.entry(cell(p)).or_default().push(i);
    }
    let mut parent: Vec<usize> = (0..points.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for (i, p) in points.iter().enumerate() {
        let (cx, cy) = cell(p);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let Some(others) = grid.get(&(cx + dx, cy + dy)) else { continue };
                for &j in others.iter().filter(|&&j| j > i) {
                    if (points[j].u - p.u).hypot(points[j].v - p.v) <= STRIPE_LINK_PX {
                        let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                        parent[a.max(b)] = a.min(b);
                    }
                }
            }
        }
    }
    // Roots in order of first appearance become labels 0, 1, ...
    let mut label_of_root = vec![usize::MAX; points.len()];
    let mut next = 0;
    (0..points.len())
        .map(|i| {
            let r = root(&mut parent, i);
            if label_of_root[r] == usize::MAX {
                label_of_root[r] = next;
                next += 1;
            }
            label_of_root[r]
        })
        .collect()
}

/// The distance (px) between the two farthest of `members`, from two sweeps (farthest from the
/// first point, then farthest from that one): exact for a chain that does not curl back.
fn span_px(points: &[StripePoint], members: &[usize]) -> f64 {
    let farthest = |from: usize| {
        members
            .iter()
            .map(|&j| (j, (points[j].u - points[from].u).hypot(points[j].v - points[from].v)))
            .fold((from, 0.0), |best, c| if c.1 > best.1 { c } else { best })
    };
    let Some(&first) = members.first() else { return 0.0 };
    let (end, _) = farthest(first);
    farthest(end).1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(centre: (f64, f64), phi: f64, r: f64) -> StripePoint {
        StripePoint {
            u: centre.0 + r * phi.cos(),
            v: centre.1 + r * phi.sin(),
            intensity: 50.0,
            width: 3.0,
            quality: 0,
        }
    }

    #[test]
    fn noisy_circle_points_move_towards_the_circle_and_a_lone_point_stays() {
        // A circle of radius 80 px sampled every 0.95 px of arc, radii alternating
        // ±0.1 px around 80, across the ±π seam; plus one isolated point far away.
        let c = (100.3, 99.7);
        let mut pts: Vec<StripePoint> = (0..200)
            .map(|i| point(c, 2.0 + i as f64 * 0.95 / 80.0, 80.0 + if i % 2 == 0 { 0.1 } else { -0.1 }))
            .collect();
        pts.push(point(c, -1.0, 40.0));
        let fitted = fit_along_stripe(&pts, c, 3.0, 3.0);
        for (i, p) in fitted.iter().enumerate().take(200) {
            let r = polar(p, c).1;
            // ±3 px holds 7 points: the alternation averages to ±0.1/7. Near the ends the
            // windows are one-sided (or too small to fit): within the alternation's 0.1 px and
            // what a line fitted to 5 alternating points extrapolates from it.
            let tol = if (3..197).contains(&i) { 0.02 } else { 0.2 };
            assert!((r - 80.0).abs() < tol, "point {i}: r = {r}");
            // Only the radius changes: the azimuth stays the ray's.
            assert!((polar(p, c).0 - polar(&pts[i], c).0).abs() < 1e-12);
        }
        assert_eq!(fitted[200], pts[200]);
    }

    #[test]
    fn a_kink_is_left_alone_where_the_fit_would_move_points_too_far() {
        // A stripe whose radius jumps by 2 px (an occlusion edge): the jump is beyond max_dr
        // = 1.5 px, so the two sides never mix.
        let c = (0.0, 0.0);
        let pts: Vec<StripePoint> =
            (0..40).map(|i| point(c, i as f64 / 100.0, if i < 20 { 100.0 } else { 102.0 })).collect();
        let fitted = fit_along_stripe(&pts, c, 3.0, 1.5);
        for (p, q) in pts.iter().zip(&fitted) {
            assert!((polar(p, c).1 - polar(q, c).1).abs() < 1e-9);
        }
    }

    #[test]
    fn stripes_shorter_than_the_window_are_refused_and_the_longest_span_reported() {
        // A straight stripe 30 px long (points 1 px apart, one gap of 2 px) and a 6 px one.
        let at = |u: f64, v: f64| StripePoint { u, v, intensity: 50.0, width: 3.0, quality: 0 };
        let mut pts: Vec<StripePoint> = (0..=30).filter(|&i| i != 15).map(|i| at(10.0 + i as f64, 20.0)).collect();
        pts.extend((0..=6).map(|i| at(10.0 + i as f64, 40.0)));
        let r = refuse_short_stripes(pts.clone(), 10.0);
        assert_eq!((r.kept.len(), r.refused), (30, 7));
        assert!((r.longest_px - 30.0).abs() < 1e-9, "{}", r.longest_px);
        assert_eq!(r.kept, pts[..30].to_vec());
        let none = refuse_short_stripes(pts.clone(), 31.0);
        assert_eq!((none.kept.len(), none.refused), (0, 37));
        assert_eq!(refuse_short_stripes(pts.clone(), 6.0).kept, pts);
        assert_eq!(refuse_short_stripes(Vec::new(), 6.0), ShortStripes::default());
    }
}
