//! Small statistics of samples shared by the fits and the reports.

/// The median of `v` (the mean of the middle two for an even count); `None` if empty.
pub fn median(v: &[f64]) -> Option<f64> {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    (n > 0).then(|| if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// The jackknife's standard error of a statistic from its leave-one-out (or leave-one-block-out)
/// values θₖ: √((g − 1)/g · Σ(θₖ − θ̄)²) over the g values; `None` with fewer than two.
pub fn jackknife_sigma(values: &[f64]) -> Option<f64> {
    let g = values.len() as f64;
    if values.len() < 2 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / g;
    Some(((g - 1.0) / g * values.iter().map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_and_the_jackknife_of_a_mean() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(&[]), None);
        // The leave-one-out means of x: their jackknife σ is the mean's standard error, s/√n.
        let x = [1.0, 4.0, 2.0, 8.0, 5.0];
        let n = x.len() as f64;
        let sum: f64 = x.iter().sum();
        let leave_outs: Vec<f64> = x.iter().map(|v| (sum - v) / (n - 1.0)).collect();
        let mean = sum / n;
        let s = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!((jackknife_sigma(&leave_outs).unwrap() - s / n.sqrt()).abs() < 1e-12);
        assert_eq!(jackknife_sigma(&[1.0]), None);
    }
}
