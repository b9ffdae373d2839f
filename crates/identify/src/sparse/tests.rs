use faer::linalg::solvers::Solve;
use faer::{ColRef, col};

use super::*;
use crate::lm::tests::{Rosenbrock, rosenbrock};

/// The dense tests' Rosenbrock problem (`J₁₁ = 0`), its Jacobian also in sparse form.
impl SparseJacobian for Rosenbrock {
    fn pattern(&self) -> (Vec<usize>, Vec<usize>) {
        (vec![0, 2, 3], vec![0, 1, 0])
    }
    fn residuals_and_values(
        &self,
        x: ColRef<'_, f64>,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), EvalError> {
        r[0] = 10.0 * (x[1] - x[0] * x[0]);
        r[1] = 1.0 - x[0];
        values.copy_from_slice(&[-20.0 * x[0], -1.0, 10.0]);
        Ok(())
    }
}

#[test]
fn rosenbrock_from_the_standard_start_reaches_the_dense_back_ends_minimum() {
    let p = rosenbrock();
    // MINPACK's initial radius (factor 100) from (−1.2, 1): damped steps until the valley.
    let cfg = LmConfig::default();
    let sparse = levenberg_marquardt_sparse(&p, col![-1.2, 1.0], &cfg, &[0, 1]).expect("valid");
    let dense = crate::levenberg_marquardt(&p, col![-1.2, 1.0], &[0, 1], &cfg).expect("valid");
    for fit in [&sparse.fit, &dense] {
        assert!(fit.termination.is_success(), "{:?}", fit.termination);
        assert!(
            (fit.x[0] - 1.0).abs() < 1e-10 && (fit.x[1] - 1.0).abs() < 1e-10,
            "{:?}",
            fit.x
        );
    }
    // The same iteration (only the λ search's lower bound differs): the same number of
    // linearisations within a few.
    assert!(
        sparse.fit.n_iterations.abs_diff(dense.n_iterations) <= 3,
        "sparse {} iterations, dense {}",
        sparse.fit.n_iterations,
        dense.n_iterations
    );
    assert_eq!(sparse.fit.n_jacobians, sparse.fit.n_evaluations);
}

/// A block-angular `J` (3 groups of 12 rows, each with 2 own columns, and 2 shared columns)
/// with values spread over two orders of magnitude, and a residual.
fn block_system() -> (Pattern, Vec<f64>, Vec<f64>) {
    let (groups, rows, own) = (3, 12, 2);
    let m = groups * rows;
    let n = groups * own + 2;
    let value = |i: usize, j: usize| {
        let s = ((i * 7 + j * 13) as f64 * 0.7).sin() + 0.1 * j as f64;
        s * 10f64.powf((j % 3) as f64 - 1.0)
    };
    let mut col_ptr = vec![0];
    let mut row_idx = Vec::new();
    let mut values = Vec::new();
    for j in 0..n {
        let rows_of: Vec<usize> = if j < groups * own {
            let g = j / own;
            (g * rows..(g + 1) * rows).collect()
        } else {
            (0..m).collect()
        };
        for i in rows_of {
            row_idx.push(i);
            values.push(value(i, j));
        }
        col_ptr.push(row_idx.len());
    }
    let r = (0..m).map(|i| (i as f64 * 1.3).cos()).collect();
    (
        Pattern::new(m, col_ptr, row_idx).expect("pattern"),
        values,
        r,
    )
}

fn subproblem(pattern: Pattern, scaled: Vec<f64>, r: Vec<f64>) -> SparseSubproblem {
    let mut gradient = vec![0.0; pattern.n];
    for ((&j, &i), v) in pattern.col_of.iter().zip(&pattern.row_idx).zip(&scaled) {
        gradient[j] += v * r[i];
    }
    let n_aug = pattern.augmented.row_idx().len();
    SparseSubproblem {
        pattern: Arc::new(pattern),
        scaled,
        r,
        gradient,
        augmented: vec![0.0; n_aug],
        gauss_newton: None,
        last: None,
    }
}

/// `J` dense from the pattern.
fn dense(pattern: &Pattern, values: &[f64]) -> Mat<f64> {
    let mut a = Mat::<f64>::zeros(pattern.m, pattern.n);
    for ((&j, &i), v) in pattern.col_of.iter().zip(&pattern.row_idx).zip(values) {
        a[(i, j)] = *v;
    }
    a
}

/// `(JᵀJ + λI)⁻¹(−Jᵀr)` from the normal equations (well conditioned here), as reference.
fn damped_reference(a: &Mat<f64>, r: &[f64], lambda: f64) -> Vec<f64> {
    let n = a.ncols();
    let mut normal = a.transpose() * a;
    for j in 0..n {
        normal[(j, j)] += lambda;
    }
    let rc = Col::from_fn(r.len(), |i| -r[i]);
    let rhs = a.transpose() * &rc;
    let u = normal.full_piv_lu().solve(&rhs);
    (0..n).map(|j| u[j]).collect()
}

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    norm(&a.iter().zip(b).map(|(x, y)| x - y).collect::<Vec<_>>()) / norm(b)
}

#[test]
fn a_long_gauss_newton_step_is_damped_onto_the_trust_region() {
    let (pattern, values, r) = block_system();
    let a = dense(&pattern, &values);
    let gauss_newton = damped_reference(&a, &r, 0.0);
    let delta = 0.3 * norm(&gauss_newton);
    let mut sub = subproblem(pattern, values, r.clone());
    let step = sub.step(delta, 0.0).expect("factorises");
    assert!(step.lambda > 0.0, "λ = {}", step.lambda);
    // lmpar's acceptance: ‖u‖ within 10 % of Δ.
    assert!(
        (step.u_norm - delta).abs() <= 0.1 * delta,
        "‖u‖ = {}, Δ = {delta}",
        step.u_norm
    );
    // The step solves the damped system of its λ (the condition of JᵀJ + λI is below 1e4,
    // so the normal-equation reference is good to ~1e-12).
    let reference = damped_reference(&a, &r, step.lambda);
    assert!(
        rel_diff(&step.u, &reference) < 1e-10,
        "{:?} vs {reference:?}",
        step.u
    );
    let jp = &a * Col::from_fn(step.u.len(), |j| step.u[j]);
    assert!((step.jp_norm - jp.norm_l2()).abs() <= 1e-12 * jp.norm_l2());
}

#[test]
fn a_short_gauss_newton_step_is_taken_undamped() {
    let (pattern, values, r) = block_system();
    let a = dense(&pattern, &values);
    let gauss_newton = damped_reference(&a, &r, 0.0);
    let mut sub = subproblem(pattern, values, r.clone());
    let step = sub
        .step(2.0 * norm(&gauss_newton), 0.5)
        .expect("factorises");
    assert_eq!(step.lambda, 0.0);
    assert!(rel_diff(&step.u, &gauss_newton) < 1e-10);
}
