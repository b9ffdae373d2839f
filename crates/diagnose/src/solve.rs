//! Every least-squares solve of the diagnosis, through `hapcal-identify` (its Levenberg–Marquardt,
//! QR-based, and its covariance), so that the project has one numerical engine.
//!
//! - [`lstsq`]: the linear problem `min ‖a·x − b‖` as a [`Problem`] with residual `a·x − b` and
//!   Jacobian `a`, solved by one Gauss–Newton step of [`levenberg_marquardt`] from `x = 0`, with
//!   `(aᵀa)⁻¹` from [`covariance`].
//! - [`fit_model`]: the nonlinear fit of the diagnosis model ([`Setup::linearise`]) by
//!   [`levenberg_marquardt`]; [`refine`] at the model's rank tolerance.
//!
//! Dependent columns are dropped before either solve ([`pivoted_basis`]): the identify solvers
//! expect a free set the data determine.
//!
//! - [`lstsq_leverage`]: the many small solves of a cross-validation, each with the leverage of
//!   the held-out rows: one Householder QR of the column-scaled matrix (faer, as
//!   [`covariance`]) instead of [`lstsq`]'s column selection, solver step and covariance, the
//!   same least-squares solution when the columns are independent (else [`lstsq`]).

use std::cell::RefCell;

use faer::prelude::SolveLstsq;
use faer::{Col, ColMut, ColRef, Mat, MatMut};
use hapcal_identify::{
    EvalError, LinearProblem, LmConfig, ParamLayout, Problem, Unit, covariance, levenberg_marquardt,
};
use nalgebra::{DMatrix, DVector};

use crate::model::{Linear, RANK_TOL, Setup, State};
use crate::stats::{NUMERICAL_ZERO_COLUMN, largest_column_norm, pivoted_basis};

/// Relative remaining norm below which [`lstsq`] drops a column as dependent on the columns
/// picked before it (the scaled problem's numerical rank; the SVD solve it replaces cut
/// singular values below `1e-9·s_max`).
const LSTSQ_RANK_TOL: f64 = 1e-9;

/// Linear least squares `min ‖a·x − b‖` on the columns of `a` that are independent at
/// [`LSTSQ_RANK_TOL`] (the others get `x = 0`, and zero rows and columns in the covariance).
/// Returns `x` and `(aᵀa)⁻¹` on the kept columns (the unscaled covariance for σ = 1).
///
/// The solve is [`levenberg_marquardt`] from `x = 0`, stopped after its first step: with the
/// trust region unbounded (`factor = ∞`) that step is the Gauss–Newton step, i.e. the
/// least-squares solution, from the QR of the column-scaled `a`. The covariance is
/// [`covariance`] (QR of the column-scaled kept columns).
pub(crate) fn lstsq(a: &DMatrix<f64>, b: &DVector<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let (m, k) = a.shape();
    let mut x = DVector::zeros(k);
    let mut cov = DMatrix::zeros(k, k);
    if k == 0 || m == 0 {
        return (x, cov);
    }
    let (_, picked) = pivoted_basis(a, &DMatrix::zeros(m, 0), LSTSQ_RANK_TOL);
    let free: Vec<usize> = (0..k).filter(|&c| picked[c].is_some()).collect();
    if free.is_empty() {
        return (x, cov);
    }
    let problem = LinearProblem {
        layout: ParamLayout::numbered("x", k, Unit::Dimensionless),
        a: Mat::from_fn(m, k, |i, j| a[(i, j)]),
        y: Col::from_fn(m, |i| b[i]),
    };
    let cfg = LmConfig {
        // The initial evaluation and the one trial point of the Gauss–Newton step.
        max_evaluations: 2,
        factor: f64::INFINITY,
        ..LmConfig::default()
    };
    if let Ok(fit) = levenberg_marquardt(&problem, Col::zeros(k), &free, &cfg) {
        for &c in &free {
            x[c] = fit.x[c];
        }
    }
    if let Ok(c) = covariance(problem.a.as_ref(), &problem.layout, &free, 1.0) {
        for (p, &i) in free.iter().enumerate() {
            for (q, &j) in free.iter().enumerate() {
                cov[(i, j)] = c.matrix[(p, q)];
            }
        }
    }
    (x, cov)
}

/// [`lstsq`] on `a`, `b`, with the leverage `hᵢ = tᵢ·(aᵀa)⁻¹·tᵢᵀ` of each row `tᵢ` of `test`
/// (on the kept columns; the quantity that makes a held-out error's variance `σ²(1 + h)`).
///
/// When every column of `a` is independent of the ones before it at [`LSTSQ_RANK_TOL`] (the
/// Householder QR `a·D⁻¹ = Q·R` of the columns scaled to unit norm, `|R_jj| ≥` the
/// tolerance) and none is rounding noise ([`NUMERICAL_ZERO_COLUMN`] of the largest), the
/// solution is `D⁻¹R⁻¹Qᵀb` and `hᵢ = ‖R⁻ᵀD⁻¹tᵢᵀ‖²`: the least-squares
/// solution and covariance [`lstsq`] computes, from one factorisation instead of three.
/// Otherwise it is [`lstsq`]'s, which drops the dependent columns.
///
/// Source: Golub and Van Loan, *Matrix Computations*, 4th ed., 2013, §5.3 (least squares by
/// QR); the leverage as in Hastie, Tibshirani and Friedman, *The Elements of Statistical
/// Learning*, 2nd ed., 2009, §7.10.
///
/// # Panics
/// If `b` or `test` do not match `a`'s rows or columns.
#[track_caller]
pub(crate) fn lstsq_leverage(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    test: &DMatrix<f64>,
) -> (DVector<f64>, Vec<f64>) {
    let (m, k) = a.shape();
    assert!(
        b.len() == m && test.ncols() == k,
        "lstsq_leverage: {m}×{k} matrix, {} right-hand side, {} test columns",
        b.len(),
        test.ncols()
    );
    let by_lstsq = || {
        let (x, cov) = lstsq(a, b);
        let h = (0..test.nrows())
            .map(|i| {
                let row = test.row(i);
                (row * &cov * row.transpose())[0]
            })
            .collect();
        (x, h)
    };
    let scale: Vec<f64> = (0..k).map(|j| a.column(j).norm()).collect();
    let largest = largest_column_norm(a);
    if k == 0
        || m < k
        || (scale.iter()).any(|s| !(s.is_finite() && *s > NUMERICAL_ZERO_COLUMN * largest))
    {
        return by_lstsq();
    }
    let scaled = Mat::from_fn(m, k, |i, j| a[(i, j)] / scale[j]);
    let qr = scaled.qr();
    let r = qr.thin_R();
    if (0..k).any(|j| r[(j, j)].abs() < LSTSQ_RANK_TOL || r[(j, j)].is_nan()) {
        return by_lstsq();
    }
    let mut rhs = Mat::from_fn(m, 1, |i, _| b[i]);
    qr.solve_lstsq_in_place(rhs.as_mut());
    let x = DVector::from_fn(k, |j, _| rhs[(j, 0)] / scale[j]);
    let mut w = Mat::from_fn(k, test.nrows(), |j, i| test[(i, j)] / scale[j]);
    r.transpose().solve_lower_triangular_in_place(w.as_mut());
    let h = (0..test.nrows())
        .map(|i| w.col(i).squared_norm_l2())
        .collect();
    (x, h)
}

/// The diagnosis model as a [`Problem`]: `x` is the change of the parameters from `start`
/// ([`State::apply`], in the column order of [`Setup::linearise`]), the residuals are
/// `(model − measured)/σ` (the negated [`Linear::r`]) and the Jacobian is [`Linear::j`].
struct ModelProblem<'a> {
    setup: &'a Setup,
    start: &'a State,
    layout: &'a ParamLayout,
    n_residuals: usize,
    /// The last linearisation and the `x` it was taken at: the solver asks for the residuals
    /// and the Jacobian of one point together, and the caller for the linearisation at the
    /// estimate.
    last: RefCell<Option<(Vec<f64>, Linear)>>,
}

impl ModelProblem<'_> {
    fn state_at(&self, x: &[f64]) -> State {
        let mut s = self.start.clone();
        s.apply(x);
        s
    }
    /// Evaluates the linearisation at `x` (or reuses the last one) and passes it to `f`.
    fn with_linear<T>(
        &self,
        x: ColRef<'_, f64>,
        f: impl FnOnce(&Linear) -> T,
    ) -> Result<T, EvalError> {
        let x: Vec<f64> = x.iter().copied().collect();
        let mut last = self.last.borrow_mut();
        if last.as_ref().is_none_or(|(at, _)| *at != x) {
            let lin = (self.setup.linearise(&self.state_at(&x))).map_err(|e| EvalError {
                reason: e.to_string(),
            })?;
            *last = Some((x, lin));
        }
        match last.as_ref() {
            Some((_, lin)) => Ok(f(lin)),
            None => unreachable!("linearisation stored above"),
        }
    }
    fn write(lin: &Linear, out: Option<ColMut<'_, f64>>, jac: Option<MatMut<'_, f64>>) {
        if let Some(mut out) = out {
            for (i, r) in lin.r.iter().enumerate() {
                out[i] = -r;
            }
        }
        if let Some(mut jac) = jac {
            for c in 0..lin.j.ncols() {
                for i in 0..lin.j.nrows() {
                    jac[(i, c)] = lin.j[(i, c)];
                }
            }
        }
    }
}

impl Problem for ModelProblem<'_> {
    fn layout(&self) -> &ParamLayout {
        self.layout
    }
    fn n_residuals(&self) -> usize {
        self.n_residuals
    }
    fn residuals(&self, x: ColRef<'_, f64>, out: ColMut<'_, f64>) -> Result<(), EvalError> {
        self.with_linear(x, |lin| Self::write(lin, Some(out), None))
    }
    fn jacobian(&self, x: ColRef<'_, f64>, jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.with_linear(x, |lin| Self::write(lin, None, Some(jac)))
    }
    fn residuals_and_jacobian(
        &self,
        x: ColRef<'_, f64>,
        out: ColMut<'_, f64>,
        jac: MatMut<'_, f64>,
    ) -> Result<(), EvalError> {
        self.with_linear(x, |lin| Self::write(lin, Some(out), Some(jac)))
    }
}

/// Trial points per iteration of [`fit_model`]'s budget: the Gauss–Newton it replaces tried
/// up to 8 step lengths per iteration.
const TRIALS_PER_ITERATION: usize = 8;

/// The columns of `lin.j` independent at `rank_tol` ([`pivoted_basis`]).
fn independent_columns(lin: &Linear, rank_tol: f64) -> Vec<usize> {
    let (_, picked) = pivoted_basis(&lin.j, &DMatrix::zeros(lin.j.nrows(), 0), rank_tol);
    (0..picked.len()).filter(|&c| picked[c].is_some()).collect()
}

/// Fits the model from `s` by [`levenberg_marquardt`] on the columns of [`Setup::linearise`]
/// that are independent at `rank_tol` ([`pivoted_basis`]), with the budget of `iters`
/// Gauss–Newton iterations with step halving: at most `iters·`[`TRIALS_PER_ITERATION`] trial
/// points (model evaluations besides the one at `s`); returns the fitted state and its
/// linearisation. Which columns the data determine can change as the estimate moves (a
/// near-dependency at the nominal becomes a dependency at the estimate): when the solver
/// stops on a set that is no longer the independent one at its estimate, it goes on from
/// there on the new set, with what is left of the budget. `iters = 0` leaves `s` as it is.
///
/// # Errors
/// The model's, for a state that does not fit the log or the chain.
pub(crate) fn fit_model(
    setup: &Setup,
    mut s: State,
    iters: usize,
    rank_tol: f64,
) -> Result<(State, Linear), hapcal_problems::Error> {
    let mut lin = setup.linearise(&s)?;
    let (m, n) = lin.j.shape();
    let layout = ParamLayout::numbered("x", n, Unit::Dimensionless);
    let mut free = independent_columns(&lin, rank_tol);
    let budget = iters * TRIALS_PER_ITERATION;
    let mut used = 0;
    while used < budget && !free.is_empty() {
        let cfg = LmConfig {
            max_evaluations: budget - used + 1,
            // The model is close to linear about the calibrated baseline: try the
            // Gauss–Newton step first.
            factor: f64::INFINITY,
            ..LmConfig::default()
        };
        let problem = ModelProblem {
            setup,
            start: &s,
            layout: &layout,
            n_residuals: m,
            last: RefCell::new(Some((vec![0.0; n], lin))),
        };
        let fit = levenberg_marquardt(&problem, Col::zeros(n), &free, &cfg);
        let x: Vec<f64> = match &fit {
            Ok(fit) => fit.x.iter().copied().collect(),
            Err(_) => vec![0.0; n],
        };
        let next = problem.state_at(&x);
        lin = match problem.last.into_inner() {
            Some((at, lin)) if at == x => lin,
            _ => setup.linearise(&next)?,
        };
        s = next;
        let Ok(fit) = fit else { break };
        used += fit.n_evaluations.saturating_sub(1).max(1);
        let now = independent_columns(&lin, rank_tol);
        if now == free {
            break;
        }
        free = now;
    }
    Ok((s, lin))
}

/// Fits the model of `setup` from `s` by [`fit_model`] on the identifiable columns
/// ([`RANK_TOL`], re-picked when they change at the estimate), within a budget of `iters`
/// Gauss–Newton iterations; returns the refined state and the linearisation there.
///
/// # Errors
/// The model's, for a state that does not fit the log or the chain.
pub(crate) fn refine(
    setup: &Setup,
    s: State,
    iters: usize,
) -> Result<(State, Linear), hapcal_problems::Error> {
    fit_model(setup, s, iters, RANK_TOL)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A well-conditioned 40 × 4 design whose columns differ in scale, as the weighted
    /// Jacobians' do.
    fn design() -> DMatrix<f64> {
        DMatrix::from_fn(40, 4, |i, j| {
            let t = i as f64 / 40.0;
            [1.0, 10.0 * t, (3.0 * t).sin(), 0.1 * (5.0 * t).cos()][j]
        })
    }

    #[test]
    fn lstsq_leverage_is_the_least_squares_solution_and_its_leverage() {
        let a = design();
        let b = DVector::from_fn(40, |i, _| (0.7 * i as f64).cos() + 0.1 * i as f64);
        let test = DMatrix::from_fn(3, 4, |i, j| 0.5 + (i * 4 + j) as f64 * 0.1);
        let (x, h) = lstsq_leverage(&a, &b, &test);
        // The normal equations hold: aᵀ(b − a·x) = 0 to rounding, relative to ‖aᵀ‖·‖b‖.
        let g = a.transpose() * (&b - &a * &x);
        for j in 0..4 {
            let scale = a.column(j).norm() * b.norm();
            assert!(g[j].abs() < 1e-12 * scale, "normal equation {j}: {}", g[j]);
        }
        // The leverage is t·(aᵀa)⁻¹·tᵀ, here from the normal equations' inverse (aᵀa of these
        // columns is conditioned well enough for agreement to 1e-8 relative).
        let inv = (a.transpose() * &a).try_inverse().expect("invertible");
        for (i, hi) in h.iter().enumerate() {
            let row = test.row(i);
            let want = (row * &inv * row.transpose())[0];
            assert!((hi - want).abs() < 1e-8 * want.abs(), "{hi} vs {want}");
        }
    }

    #[test]
    fn lstsq_leverage_drops_a_dependent_column_as_lstsq() {
        let mut a = design().insert_column(4, 0.0);
        let dup = a.column(1) * 2.0;
        a.set_column(4, &dup);
        let b = DVector::from_fn(40, |i, _| (0.3 * i as f64).sin());
        let test = DMatrix::from_fn(2, 5, |i, j| (i + j) as f64);
        let (x, h) = lstsq_leverage(&a, &b, &test);
        let (x_ref, cov) = lstsq(&a, &b);
        assert_eq!(x, x_ref);
        assert_eq!(x.iter().filter(|v| **v == 0.0).count(), 1);
        for (i, hi) in h.iter().enumerate() {
            let row = test.row(i);
            assert_eq!(*hi, (row * &cov * row.transpose())[0]);
        }
    }
}
