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
}
