//! A small, generic Levenberg–Marquardt solver for dense nonlinear least squares, with an
//! optional robust (Huber) loss applied by iteratively reweighting residuals.
//!
//! Problems supply residuals and, ideally, an exact Jacobian; the default Jacobian is a
//! central finite difference, adequate for the low-dimensional geometric fits in this crate.

use nalgebra::{DMatrix, DVector};

/// A nonlinear least-squares problem: minimise Σ ρ(r_i(p)²).
pub trait Problem {
    fn num_params(&self) -> usize;
    fn num_residuals(&self) -> usize;
    /// Fills `out` (length `num_residuals`) with the residuals at `params`.
    fn residuals(&self, params: &[f64], out: &mut [f64]);
    /// Fills `jac` (num_residuals × num_params) with ∂r/∂p. Default: central differences.
    fn jacobian(&self, params: &[f64], jac: &mut DMatrix<f64>) {
        numeric_jacobian(self, params, jac)
    }
}

/// Central-difference Jacobian of `problem` at `params`.
pub fn numeric_jacobian<P: Problem + ?Sized>(problem: &P, params: &[f64], jac: &mut DMatrix<f64>) {
    let m = problem.num_residuals();
    let mut p = params.to_vec();
    let mut plus = vec![0.0; m];
    let mut minus = vec![0.0; m];
    for j in 0..params.len() {
        let h = 1e-6 * params[j].abs().max(1e-3);
        p[j] = params[j] + h;
        problem.residuals(&p, &mut plus);
        p[j] = params[j] - h;
        problem.residuals(&p, &mut minus);
        p[j] = params[j];
        for i in 0..m {
            jac[(i, j)] = (plus[i] - minus[i]) / (2.0 * h);
        }
    }
}

/// Solver settings.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    pub max_iterations: usize,
    /// Stop when the relative cost decrease falls below this.
    pub cost_tolerance: f64,
    /// Stop when the step is below this relative to the parameter norm.
    pub step_tolerance: f64,
    /// Huber threshold (same unit as the residuals); `None` = plain least squares.
    pub huber: Option<f64>,
}

impl Default for Options {
    fn default() -> Self {
        Options { max_iterations: 100, cost_tolerance: 1e-14, step_tolerance: 1e-14, huber: None }
    }
}

/// What the solver found.
#[derive(Debug, Clone)]
pub struct Report {
    pub params: Vec<f64>,
    /// Final ½Σ w_i r_i² (robust-weighted).
    pub cost: f64,
    /// Root mean square of the unweighted residuals.
    pub rms: f64,
    pub iterations: usize,
    pub converged: bool,
    /// Parameter covariance estimate σ²(JᵀWJ)⁻¹ with σ² = Σw r²/(m − n); `None` if singular.
    pub covariance: Option<DMatrix<f64>>,
}

impl Report {
    /// Standard deviations of the parameters (sqrt of the covariance diagonal).
    pub fn std_devs(&self) -> Option<Vec<f64>> {
        self.covariance.as_ref().map(|c| (0..c.nrows()).map(|i| c[(i, i)].max(0.0).sqrt()).collect())
    }
}

fn huber_weights(r: &[f64], huber: Option<f64>, w: &mut [f64]) {
    for (wi, ri) in w.iter_mut().zip(r) {
        *wi = match huber {
            Some(k) if ri.abs() > k => k / ri.abs(),
            _ => 1.0,
        };
    }
}

fn weighted_cost(r: &[f64], w: &[f64]) -> f64 {
    0.5 * r.iter().zip(w).map(|(r, w)| w * r * r).sum::<f64>()
}

/// Minimises the problem from `initial` with Levenberg–Marquardt (Marquardt's diagonal scaling).
pub fn minimize<P: Problem + ?Sized>(problem: &P, initial: &[f64], options: &Options) -> Report {
    let n = problem.num_params();
    let m = problem.num_residuals();
    let mut params = initial.to_vec();
    let mut r = vec![0.0; m];
    let mut w = vec![1.0; m];
    let mut jac = DMatrix::zeros(m, n);
    problem.residuals(&params, &mut r);
    huber_weights(&r, options.huber, &mut w);
    let mut cost = weighted_cost(&r, &w);
    let mut lambda = 1e-3;
    let mut converged = false;
    let mut iterations = 0;
    let mut trial = vec![0.0; n];
    let mut r_trial = vec![0.0; m];
    while iterations < options.max_iterations && !converged {
        iterations += 1;
        problem.jacobian(&params, &mut jac);
        let (jtj, jtr) = normal_equations(&jac, &r, &w);
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&(-&jtr))) else {
                lambda *= 10.0;
                continue;
            };
            for i in 0..n {
                trial[i] = params[i] + step[i];
            }
            problem.residuals(&trial, &mut r_trial);
            let new_cost = weighted_cost(&r_trial, &w);
            if new_cost.is_finite() && new_cost <= cost {
                let rel = (cost - new_cost) / cost.max(1e-300);
                let pnorm = params.iter().map(|x| x * x).sum::<f64>().sqrt();
                params.copy_from_slice(&trial);
                std::mem::swap(&mut r, &mut r_trial);
                huber_weights(&r, options.huber, &mut w);
                cost = weighted_cost(&r, &w);
                lambda = (lambda * 0.3).max(1e-12);
                improved = true;
                if rel < options.cost_tolerance
                    || step.norm() < options.step_tolerance * (pnorm + options.step_tolerance)
                {
                    converged = true;
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            converged = true;
        }
    }
    problem.jacobian(&params, &mut jac);
    let (jtj, _) = normal_equations(&jac, &r, &w);
    let dof = m.saturating_sub(n).max(1) as f64;
    let sigma2 = 2.0 * cost / dof;
    let covariance = jtj.try_inverse().map(|inv| inv * sigma2);
    let rms = (r.iter().map(|x| x * x).sum::<f64>() / m.max(1) as f64).sqrt();
    Report { params, cost, rms, iterations, converged, covariance }
}

fn normal_equations(jac: &DMatrix<f64>, r: &[f64], w: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
    let (m, n) = jac.shape();
    let mut jtj = DMatrix::zeros(n, n);
    let mut jtr = DVector::zeros(n);
    for i in 0..m {
        let row = jac.row(i);
        let wi = w[i];
        for a in 0..n {
            let ja = row[a] * wi;
            if ja == 0.0 {
                continue;
            }
            jtr[a] += ja * r[i];
            for b in a..n {
                jtj[(a, b)] += ja * row[b];
            }
        }
    }
    for a in 0..n {
        for b in 0..a {
            jtj[(a, b)] = jtj[(b, a)];
        }
    }
    (jtj, jtr)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Exp {
        t: Vec<f64>,
        y: Vec<f64>,
    }
    impl Problem for Exp {
        fn num_params(&self) -> usize {
            2
        }
        fn num_residuals(&self) -> usize {
            self.t.len()
        }
        fn residuals(&self, p: &[f64], out: &mut [f64]) {
            for i in 0..self.t.len() {
                out[i] = p[0] * (p[1] * self.t[i]).exp() - self.y[i];
            }
        }
    }

    #[test]
    fn fits_exponential_exactly() {
        let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
        let y = t.iter().map(|t| 2.5 * (-1.3 * t).exp()).collect();
        let rep = minimize(&Exp { t, y }, &[1.0, 0.0], &Options::default());
        assert!((rep.params[0] - 2.5).abs() < 1e-9, "{:?}", rep.params);
        assert!((rep.params[1] + 1.3).abs() < 1e-9);
    }
}
