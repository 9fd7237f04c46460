//! Real polynomials Σ c_k·x^k, coefficients lowest degree first.

/// The polynomial's value at `x` (Horner).
pub fn eval(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &k| acc * x + k)
}

/// The derivative's coefficients.
pub fn derivative(c: &[f64]) -> Vec<f64> {
    c.iter().enumerate().skip(1).map(|(k, &v)| k as f64 * v).collect()
}

/// The coefficients without the zero ones of highest degree, so that the degree is the true one.
fn trimmed(c: &[f64]) -> &[f64] {
    let n = c.iter().rposition(|&v| v != 0.0).map_or(0, |i| i + 1);
    &c[..n]
}

/// The x in [lo, hi] where the polynomial changes sign, by bisection to the last bit; `lo` must
/// have the sign of `positive_at_lo` (true: > 0) and `hi` the other (≤ 0 for true). Returns the
/// last x on `lo`'s side.
fn bisect(c: &[f64], mut lo: f64, mut hi: f64, positive_at_lo: bool) -> f64 {
    loop {
        let mid = 0.5 * (lo + hi);
        if !(mid > lo && mid < hi) {
            return lo;
        }
        if (eval(c, mid) > 0.0) == positive_at_lo {
            lo = mid;
        } else {
            hi = mid;
        }
    }
}

/// Every x in the open interval (lo, hi) where the polynomial changes sign or touches zero,
/// ascending. The derivative's roots (found the same way) split the interval into pieces on
/// which the polynomial is monotone, each holding at most one root, so no root is missed
/// however close two of them lie.
pub fn roots_in(c: &[f64], lo: f64, hi: f64) -> Vec<f64> {
    let c = trimmed(c);
    if c.len() <= 1 || !(lo < hi) {
        return Vec::new();
    }
    let mut ends = vec![lo];
    ends.extend(roots_in(&derivative(c), lo, hi));
    ends.push(hi);
    let mut roots = Vec::new();
    for piece in ends.windows(2) {
        let (a, b) = (piece[0], piece[1]);
        let (fa, fb) = (eval(c, a), eval(c, b));
        if fa == 0.0 {
            if a > lo {
                roots.push(a);
            }
        } else if fb != 0.0 && (fa > 0.0) != (fb > 0.0) {
            roots.push(bisect(c, a, b, fa > 0.0));
        }
    }
    roots
}

/// The first x in [lo, hi] where the polynomial is ≤ 0, to the last bit (the last x before it
/// where it is still positive), or `None` where it stays positive on the whole interval.
/// Exact however narrow a dip below zero is, as [`roots_in`].
pub fn first_non_positive(c: &[f64], lo: f64, hi: f64) -> Option<f64> {
    if !(eval(c, lo) > 0.0) {
        return Some(lo);
    }
    let mut start = lo;
    for end in roots_in(&derivative(trimmed(c)), lo, hi).into_iter().chain([hi]) {
        if !(eval(c, end) > 0.0) {
            return Some(bisect(c, start, end, true));
        }
        start = end;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Σ c_k·x^k of ∏ (x − r_i).
    fn from_roots(roots: &[f64]) -> Vec<f64> {
        roots.iter().fold(vec![1.0], |c, &r| {
            let mut next = vec![0.0; c.len() + 1];
            for (k, &v) in c.iter().enumerate() {
                next[k + 1] += v;
                next[k] -= r * v;
            }
            next
        })
    }

    #[test]
    fn finds_a_dip_a_scan_would_step_over() {
        // (x − 1.3)² − 1e-12 is negative only on (1.3 − 1e-6, 1.3 + 1e-6).
        let c = [1.69 - 1e-12, -2.6, 1.0];
        let x = first_non_positive(&c, 0.0, 100.0).unwrap();
        assert!((x - (1.3 - 1e-6)).abs() < 1e-9, "{x}");
        assert!(eval(&c, x) > 0.0);
        // Lifted above zero it has none.
        assert_eq!(first_non_positive(&[1.69 + 1e-12, -2.6, 1.0], 0.0, 100.0), None);
        assert_eq!(first_non_positive(&[-1.0, 1.0], 0.0, 1.0), Some(0.0));
        assert_eq!(first_non_positive(&[2.0, 0.0, 0.0], 0.0, 1.0), None);
    }

    proptest! {
        #[test]
        fn finds_every_root_of_a_product(mut roots in prop::collection::vec(-5.0..5.0f64, 1..7)) {
            roots.sort_by(f64::total_cmp);
            // Roots 0.1 apart or more: rounding in the coefficients then moves none by 1e-6.
            roots.dedup_by(|a, b| (*a - *b).abs() < 0.1);
            let c = from_roots(&roots);
            let found = roots_in(&c, -6.0, 6.0);
            prop_assert_eq!(found.len(), roots.len(), "{:?} vs {:?}", found, roots);
            for (f, r) in found.iter().zip(&roots) {
                prop_assert!((f - r).abs() < 1e-6, "{:?} vs {:?}", found, roots);
            }
            // Positive to the left of the first root for an even count, so the first root is
            // the first non-positive point on [−6, 6] (when it is).
            let signed: Vec<f64> = if roots.len() % 2 == 0 { c.clone() } else { c.iter().map(|v| -v).collect() };
            let first = first_non_positive(&signed, -6.0, 6.0).unwrap();
            prop_assert!((first - roots[0]).abs() < 1e-6, "{} vs {:?}", first, roots);
        }
    }
}
