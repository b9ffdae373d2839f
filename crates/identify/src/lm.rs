//! Levenberg–Marquardt for `min_x ½‖r(x)‖²` over a subset of the parameters.
//!
//! Source: J. J. Moré, "The Levenberg–Marquardt algorithm: implementation and theory",
//! Numerical Analysis, LNM 630, Springer 1978, and its implementation MINPACK `lmder`/`lmpar`
//! (Moré, Garbow, Hillstrom, 1980): column scaling `D`, a trust region of radius `Δ` in the
//! scaled variables, `λ` found from `Δ` by Moré's safeguarded Newton iteration, the damped
//! subproblem solved by QR (never by forming `JᵀJ`), and the MINPACK stopping tests. Choosing
//! `λ` from the trust region (rather than a direct `λ` update such as Nielsen's) gives `λ = 0`,
//! i.e. exact Gauss–Newton steps, whenever the Gauss–Newton step fits in the region: linear
//! problems are solved in one step and small-residual problems converge quadratically.
//!
//! The iteration ([`run`]) is written once for every back end: it sees the problem through
//! [`Linearised`] (residual norms at trial points, column norms and gradient at the current
//! point) and the trust-region [`Subproblem`] of each linearisation, which the dense and
//! streaming back ends solve from the triangle of `[J r]` ([`ScaledQr`]) and the sparse one by
//! sparse QR factorisations ([`crate::sparse`]).

use faer::{Col, ColRef, Mat, MatRef};

use crate::error::{Error, check_config, check_factor};
use crate::householder::{self, ColMajor};
use crate::problem::{ParamLayout, Problem};

/// Stopping tolerances of [`levenberg_marquardt`] (the MINPACK `lmder` tests).
///
/// Tolerances below machine epsilon act as machine epsilon, so the solver stops when no
/// further progress is possible in floating point (MINPACK `info` 6–8).
#[derive(Clone, Debug, PartialEq)]
pub struct LmConfig {
    /// Stop when both the actual and the predicted relative reduction of the cost in one step
    /// are at most `ftol` ([`Termination::FtolReached`]).
    pub ftol: f64,
    /// Stop when the trust radius `Δ`, which bounds the scaled step `‖D·p‖`, is at most
    /// `xtol·(‖D·x‖ + xtol)` ([`Termination::XtolReached`]); `D` are the (running maximum)
    /// column norms of `J`. The `+ xtol` lets a solution at `x = 0` stop too.
    pub xtol: f64,
    /// Stop when the largest cosine between `r` and a column of `J`,
    /// `max_j |J_jᵀ r| / (‖J_j‖·‖r‖)`, is at most `gtol` ([`Termination::GtolReached`]).
    pub gtol: f64,
    /// Stop after this many evaluations of `r` (the initial one included)
    /// ([`Termination::MaxEvaluations`]).
    pub max_evaluations: usize,
    /// Initial trust radius: `factor·‖D·x0‖`, or `factor` when `x0 = 0` (MINPACK's `factor`,
    /// default 100). From `x0 = 0` on a problem whose scaled Gauss–Newton step is much longer
    /// than 100, the radius needs one doubling per iteration to reach it; `f64::INFINITY`
    /// tries the full Gauss–Newton step first (the radius then starts at its length), which
    /// suits calibrations started near their solution at the nominal.
    pub factor: f64,
    /// The one-step estimator (Le Cam's): when set, stop after the first step if it is a
    /// Gauss–Newton step (`λ = 0`), accepted, whose actual relative reduction of the cost
    /// differs from the one its linearisation predicted by at most this much
    /// ([`Termination::OneStep`]); the trial point's Jacobian is then never evaluated. From a
    /// start within the statistical error of the solution (a cross-validation fold refitted
    /// from the full-data estimate), one Gauss–Newton step leaves an error of second order in
    /// that distance; the test checks that the linearisation held over the step, and the
    /// iteration goes on as without it when it did not. `None` (the default): every step is
    /// iterated to `ftol`/`xtol`/`gtol`.
    pub one_step: Option<f64>,
}

impl Default for LmConfig {
    /// `ftol = xtol = gtol = 1e-12`, `max_evaluations = 200`, `factor = 100`, MINPACK-like (`lmder1` takes
    /// `ftol = xtol = tol`, `gtol = 0`, `100·(n + 1)` evaluations). 1e-12 puts the stopping
    /// error far below any statistical uncertainty of a calibration; 200 evaluations are ample
    /// for problems started near their solution (calibration starts at the nominal), which
    /// converge in a few tens, and a fit that needs more is reported rather than run on.
    fn default() -> Self {
        Self {
            ftol: 1e-12,
            xtol: 1e-12,
            gtol: 1e-12,
            max_evaluations: 200,
            factor: FACTOR,
            one_step: None,
        }
    }
}

/// Why [`levenberg_marquardt`] stopped.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Termination {
    /// The relative reduction of the cost fell below [`LmConfig::ftol`].
    FtolReached,
    /// The trust radius, which bounds the scaled step, fell below [`LmConfig::xtol`]
    /// relative to `‖D·x‖`.
    XtolReached,
    /// The gradient (as a cosine, see [`LmConfig::gtol`]) fell below `gtol`; also reported
    /// for a zero residual and for an empty free set.
    GtolReached,
    /// [`LmConfig::max_evaluations`] residual evaluations were spent without convergence.
    MaxEvaluations,
    /// The step or the Jacobian became NaN or infinite, or the damping overflowed.
    Numerical,
    /// The Jacobian could not be evaluated at an accepted point.
    EvalFailed(crate::problem::EvalError),
    /// The first step was a Gauss–Newton step whose actual reduction matched its predicted
    /// one within [`LmConfig::one_step`]: the one-step estimate.
    OneStep,
}

impl Termination {
    /// True for the three convergence criteria (`Ftol`, `Xtol`, `Gtol`) and for the one-step
    /// estimate asked for ([`LmConfig::one_step`]).
    pub fn is_success(&self) -> bool {
        matches!(
            self,
            Self::FtolReached | Self::XtolReached | Self::GtolReached | Self::OneStep
        )
    }
}

/// Result of [`levenberg_marquardt`]: the estimate and how it was reached.
#[derive(Clone, Debug)]
pub struct Fit {
    /// The estimate, length `n` (entries not in `free` are exactly those of `x0`).
    pub x: Col<f64>,
    /// Why the solver stopped; check [`Termination::is_success`].
    pub termination: Termination,
    /// Number of evaluations of `r` (the one at `x0` included).
    pub n_evaluations: usize,
    /// Number of evaluations of `J`: every one, including those at trial points that were
    /// then rejected (the dense back end evaluates `J` with `r` after an accepted step).
    pub n_jacobians: usize,
    /// Number of iterations: linearisations from which at least one step was tried (one QR
    /// each, MINPACK's outer loop). The cost of one iteration is the solve's time divided by
    /// this, the evaluation at `x0` and any Jacobian evaluated but not used included.
    pub n_iterations: usize,
    /// `½‖r(x)‖²` at [`Fit::x`], in squared residual units.
    pub cost: f64,
    /// `r(x)` at [`Fit::x`], length `m`.
    pub residuals: Col<f64>,
}

impl Fit {
    /// The fit when no parameter is free: `x0` itself, after the one evaluation of `r` there
    /// (`cost = ½‖r(x0)‖²`; `residuals` as the back end keeps them).
    pub(crate) fn nothing_free(x0: Col<f64>, cost: f64, residuals: Col<f64>) -> Self {
        Fit {
            x: x0,
            termination: Termination::GtolReached,
            n_evaluations: 1,
            n_jacobians: 0,
            n_iterations: 0,
            cost,
            residuals,
        }
    }
}

/// The input checks of the dense and streaming LM: `x0` has one entry per layout parameter,
/// `free` is valid ([`check_free`]), the tolerances and the trust-region factor are valid, and
/// the problem has at least as many residuals as free parameters.
pub(crate) fn check_inputs(
    p: &impl Problem,
    x0: ColRef<'_, f64>,
    free: &[usize],
    cfg: &LmConfig,
) -> Result<(), Error> {
    let layout = p.layout();
    crate::error::check_x0_length(x0, layout)?;
    check_free(free, layout)?;
    check_config("ftol", cfg.ftol, false)?;
    check_config("xtol", cfg.xtol, false)?;
    check_config("gtol", cfg.gtol, false)?;
    if let Some(tol) = cfg.one_step {
        check_config("one_step", tol, false)?;
    }
    check_factor(cfg.factor)?;
    let m = p.n_residuals();
    if m < free.len() {
        return Err(Error::TooFewResiduals {
            n_residuals: m,
            n_free: free.len(),
        });
    }
    Ok(())
}

/// Checks that `free` holds distinct indices of `layout`.
pub(crate) fn check_free(free: &[usize], layout: &ParamLayout) -> Result<(), Error> {
    let n_params = layout.len();
    let mut seen = vec![false; n_params];
    for &index in free {
        match seen.get_mut(index) {
            None => return Err(Error::FreeOutOfRange { index, n_params }),
            Some(true) => {
                return Err(Error::DuplicateFree {
                    name: layout.name(index).to_owned(),
                });
            }
            Some(s) => *s = true,
        }
    }
    Ok(())
}

/// Whether every entry of `m` is finite (column by column, vectorised).
pub(crate) fn mat_all_finite(m: MatRef<'_, f64>) -> bool {
    (0..m.ncols()).all(|j| match m.col(j).try_as_col_major() {
        Some(c) => householder::all_finite(c.as_slice()),
        None => m.col(j).iter().all(|v| v.is_finite()),
    })
}

/// `‖c‖`: [`householder::norm2`] (vectorised, rescaled when the sum of squares under- or
/// overflows; non-finite exactly when an entry is) for a contiguous column.
pub(crate) fn col_norm(c: ColRef<'_, f64>) -> f64 {
    match c.try_as_col_major() {
        Some(c) => householder::norm2(c.as_slice()),
        None => c.norm_l2(),
    }
}

/// Returns `Err(NonFiniteJacobian)` naming the first non-finite entry of `jac`.
pub(crate) fn check_jacobian_finite(
    jac: MatRef<'_, f64>,
    layout: &ParamLayout,
) -> Result<(), Error> {
    if mat_all_finite(jac) {
        return Ok(());
    }
    for j in 0..jac.ncols() {
        if let Some(row) = (0..jac.nrows()).find(|&i| !jac[(i, j)].is_finite()) {
            return Err(Error::NonFiniteJacobian {
                row,
                name: layout.name(j).to_owned(),
            });
        }
    }
    Ok(())
}

/// Initial trust radius relative to `‖D·x0‖` (MINPACK `factor`).
const FACTOR: f64 = 100.0;

/// Minimises `½‖r(x)‖²` over the parameters listed in `free`, starting from `x0`.
///
/// The Jacobian is evaluated in full (`m × n`) and its `free` columns are used; the other
/// entries of `x` keep their `x0` values (this is how pruning is applied).
///
/// Algorithm (MINPACK `lmder`, Moré 1978): `D` holds the column norms of `J`, as their running
/// maximum over iterations (`mode = 1`; a zero column gets 1). In the scaled variables
/// `u = D·p`, each trial step solves the damped problem `[J D⁻¹; √λ·I] u ≈ [−r; 0]` with the
/// smallest `λ ≥ 0` such that `‖u‖ ≤ Δ` (within 10 %): once per Jacobian, `[J_f r]` is reduced
/// to its `(n_free+1)`-square triangle by Householder QR (256 rows at a time, in place in
/// `J`'s columns, the reflections applied in blocks of four),
/// whose scaled leading block stands for the QR of `J D⁻¹` (the same Gram matrix, so the
/// same `R` and `Q₁ᵀr` up to rounding): as it is when its condition estimate is far from
/// singular, else after a column-pivoted Householder QR (MINPACK `qrfac`, norms downdated) that
/// reveals the numerical rank;
/// for each `λ` tried, `[R; √λ·I]` is reduced by a Householder QR that uses its structure
/// (in place of MINPACK `qrsolv`'s Givens rotations; the same `S` up to rounding). `Δ`
/// starts at `factor·‖D·x0‖` (`factor` if zero; [`LmConfig::factor`]) and follows the
/// gain ratio `ρ = actual / predicted reduction`: shrunk when `ρ ≤ 1/4`, set to `2‖u‖` when
/// `ρ ≥ 3/4` or `λ = 0`; a step is accepted when `ρ ≥ 10⁻⁴`. A trial point where `r` cannot be
/// evaluated or is not finite is rejected like a step that increases the cost tenfold (`Δ` is
/// divided by 10). See [`LmConfig`] for the stopping tests.
///
/// Evaluations: `r` and `J` at `x0` come from one [`Problem::residuals_and_jacobian`] call,
/// and so do `r` and `J` at a trial point that follows an accepted step (such steps are
/// usually accepted, and the Jacobian at an accepted point is then already there); after a
/// rejected step, and at a trial point whose predicted reduction already meets the `ftol`
/// test (where the iteration usually stops), only `r` is evaluated, and `J` follows if the
/// iteration goes on. [`Fit::n_jacobians`] counts every Jacobian evaluated, including those
/// at trial points that were then rejected.
///
/// Non-convergence is a result: check `fit.termination.is_success()`.
///
/// # Errors
/// - [`Error::WrongLength`] if `x0.nrows() != p.layout().len()`;
/// - [`Error::FreeOutOfRange`], [`Error::DuplicateFree`] for a bad `free`;
/// - [`Error::TooFewResiduals`] if `m < free.len()`;
/// - [`Error::InvalidConfig`] for a negative or non-finite tolerance;
/// - [`Error::Eval`] if `r` or `J` cannot be evaluated at `x0`;
/// - [`Error::NonFiniteResidual`], [`Error::NonFiniteJacobian`] for NaN or ∞ at `x0`.
///
/// # Panics
/// If the problem writes outside the shapes it declared (faer's shape checks).
pub fn levenberg_marquardt(
    p: &impl Problem,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
) -> Result<Fit, Error> {
    check_inputs(p, x0.as_ref(), free, cfg)?;
    let layout = p.layout();
    let n = layout.len();
    let m = p.n_residuals();

    let mut r = Col::<f64>::zeros(m);
    let non_finite_residual = |r: &Col<f64>| (0..m).find(|&i| !r[i].is_finite());
    if free.is_empty() {
        p.residuals(x0.as_ref(), r.as_mut())?;
        if let Some(index) = non_finite_residual(&r) {
            return Err(Error::NonFiniteResidual { index });
        }
        return Ok(levenberg_marquardt_at(
            p,
            x0,
            free,
            cfg,
            r,
            Mat::zeros(0, 0),
        ));
    }
    let mut jac = Mat::<f64>::zeros(m, n);
    // Both in one pass; when that fails, apart, so that the error is the one of the
    // evaluation that failed (residuals first).
    if p.residuals_and_jacobian(x0.as_ref(), r.as_mut(), jac.as_mut())
        .is_err()
    {
        p.residuals(x0.as_ref(), r.as_mut())?;
        if let Some(index) = non_finite_residual(&r) {
            return Err(Error::NonFiniteResidual { index });
        }
        p.jacobian(x0.as_ref(), jac.as_mut())?;
    }
    if let Some(index) = non_finite_residual(&r) {
        return Err(Error::NonFiniteResidual { index });
    }
    check_jacobian_finite(jac.as_ref(), layout)?;
    Ok(levenberg_marquardt_at(p, x0, free, cfg, r, jac))
}

/// [`levenberg_marquardt`] from the residuals `r0` (length `m`) and the Jacobian `jac0`
/// (`m × n`) of `p` at `x0`, which the caller evaluated (e.g. the rows of one evaluation on
/// every row of a larger problem, of which `p` keeps a subset: the cross-validation folds of
/// one model share the Jacobian at their common start). The iterates are those of
/// [`levenberg_marquardt`] when `r0` and `jac0` are what `p` evaluates at `x0`.
///
/// # Errors
/// As [`levenberg_marquardt`] (inputs, [`Error::NonFiniteResidual`] and
/// [`Error::NonFiniteJacobian`] for the given `r0` and `jac0`).
///
/// # Panics
/// If `r0` or `jac0` does not have `p`'s shapes (`m`, `m × n`).
#[track_caller]
pub fn levenberg_marquardt_from(
    p: &impl Problem,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
    r0: Col<f64>,
    jac0: Mat<f64>,
) -> Result<Fit, Error> {
    let (m, n) = (p.n_residuals(), p.layout().len());
    assert_eq!(r0.nrows(), m, "residuals at x0: length");
    assert!(
        jac0.nrows() == m && jac0.ncols() == n,
        "jacobian at x0: {} × {}, expected {m} × {n}",
        jac0.nrows(),
        jac0.ncols()
    );
    check_inputs(p, x0.as_ref(), free, cfg)?;
    check_residuals_finite(r0.as_ref())?;
    if free.is_empty() {
        return Ok(levenberg_marquardt_at(
            p,
            x0,
            free,
            cfg,
            r0,
            Mat::zeros(0, 0),
        ));
    }
    check_jacobian_finite(jac0.as_ref(), p.layout())?;
    Ok(levenberg_marquardt_at(p, x0, free, cfg, r0, jac0))
}

/// [`levenberg_marquardt_from`] with the Jacobian at `x0` given reduced: `r_free`, the
/// upper-triangular `(n_f+1) × (n_f+1)` R factor of `[J_f r]` at `x0` (`J_f` the columns
/// `free`, in that order; any factor with the same Gram matrix, such as the triangles of its
/// blocks of rows stacked, [`crate::stacked_r_factor`]), and `r0 = r(x0)`. A
/// cross-validation fold's refit starts so from the triangles of its blocks of rows, reduced
/// once for every fold that trains on them ([`crate::rows_r_factor`]): the fold's `J` is
/// neither evaluated nor copied at `x0`. The column norms are taken from `r_free`. The
/// iterates are those of [`levenberg_marquardt_from`] up to rounding; later linearisations
/// evaluate `J` as there.
///
/// # Errors
/// As [`levenberg_marquardt_from`]; [`Error::Eval`] when `r_free` is not finite.
///
/// # Panics
/// If `r0` is not of length `m` or `r_free` not `(n_f+1) × (n_f+1)`.
#[track_caller]
pub fn levenberg_marquardt_from_triangle(
    p: &impl Problem,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
    r0: Col<f64>,
    r_free: MatRef<'_, f64>,
) -> Result<Fit, Error> {
    let (m, n1) = (p.n_residuals(), free.len() + 1);
    assert_eq!(r0.nrows(), m, "residuals at x0: length");
    assert!(
        r_free.nrows() == n1 && r_free.ncols() == n1,
        "R factor of [J_f r]: {} × {}, expected {n1} × {n1}",
        r_free.nrows(),
        r_free.ncols()
    );
    check_inputs(p, x0.as_ref(), free, cfg)?;
    check_residuals_finite(r0.as_ref())?;
    if !r_free.is_all_finite() {
        return Err(Error::Eval(crate::problem::EvalError {
            reason: "the reduced Jacobian at the start is not finite".to_owned(),
        }));
    }
    if free.is_empty() {
        let cost = 0.5 * r0.squared_norm_l2();
        return Ok(Fit::nothing_free(x0, cost, r0));
    }
    let dense = Dense::from_triangle(p, free, r0, r_free);
    Ok(dense_fit(dense, x0, free, cfg))
}

/// [`Error::NonFiniteResidual`] at the first residual of `r0` (at `x0`) that is not finite.
fn check_residuals_finite(r0: ColRef<'_, f64>) -> Result<(), Error> {
    match (0..r0.nrows()).find(|&i| !r0[i].is_finite()) {
        Some(index) => Err(Error::NonFiniteResidual { index }),
        None => Ok(()),
    }
}

/// The iteration ([`run`]) on the dense back end linearised at `x0`, and its fit.
fn dense_fit<P: Problem>(
    mut dense: Dense<'_, P>,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
) -> Fit {
    let f_norm = col_norm(dense.r.as_ref());
    let run = run(&mut dense, x0, free, cfg, f_norm);
    let cost = 0.5 * dense.r.squared_norm_l2();
    Fit {
        x: run.x,
        termination: run.termination,
        n_evaluations: run.n_evaluations,
        n_jacobians: dense.n_jacobians,
        n_iterations: run.n_iterations,
        cost,
        residuals: dense.r,
    }
}

/// [`levenberg_marquardt`] from residuals `r` and Jacobian `jac` already evaluated (and found
/// finite) at `x0`, with the inputs already checked ([`check_inputs`]); `jac` may be empty
/// when `free` is. Counts the evaluations at `x0` as the caller's (1 each).
pub(crate) fn levenberg_marquardt_at(
    p: &impl Problem,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
    r: Col<f64>,
    jac: Mat<f64>,
) -> Fit {
    let nf = free.len();
    if nf == 0 {
        let cost = 0.5 * r.squared_norm_l2();
        return Fit::nothing_free(x0, cost, r);
    }
    dense_fit(Dense::new(p, free, r, jac), x0, free, cfg)
}

/// What the iteration needs from the problem, dense or streamed: residual norms at trial
/// points and the linearisation at the current point.
pub(crate) trait Linearised {
    /// `‖r(x_trial)‖`, or `∞` when `r` cannot be evaluated or is not finite there.
    /// `may_continue` is false when the step's predicted reduction already meets the `ftol`
    /// test, so that the iteration most likely stops at this point: a back end that evaluates
    /// `J` with `r` can then leave `J` out (it is evaluated by [`Linearised::relinearise`] if
    /// the iteration goes on after all).
    fn trial_norm(&mut self, x_trial: ColRef<'_, f64>, may_continue: bool) -> f64;
    /// Makes the last trial point the current one.
    fn accept(&mut self);
    /// Evaluates the Jacobian at the current point `x`.
    fn relinearise(&mut self, x: ColRef<'_, f64>) -> Result<(), Termination>;
    /// `‖J_j‖` for the free columns.
    fn col_norms(&self) -> Vec<f64>;
    /// `|J_jᵀ r|` for the free columns.
    fn gradient_abs(&self, j: usize) -> f64;
    /// The trust-region subproblem of the current linearisation, in the variables scaled by
    /// `diag` (one entry per free column).
    type Subproblem: Subproblem;
    /// The subproblem of the current linearisation for the scaling `diag`: for the dense and
    /// streaming back ends the QR of `J_f D⁻¹` (column-pivoted where it is near singular) and
    /// `Q₁ᵀ r`; for the sparse one the scaled sparse Jacobian and `r`.
    fn subproblem(&mut self, diag: &[f64]) -> Self::Subproblem;
}

/// The trust-region subproblem `min ‖J̃ u + r‖` subject to `‖u‖ ≤ Δ` in the scaled variables
/// `u = D·p` (`J̃ = J_f D⁻¹`), solved as Moré's `lmpar` does: the damping `λ ≥ 0` with `‖u(λ)‖`
/// within 10 % of `Δ`, or `λ = 0` when the Gauss–Newton step is shorter than `1.1·Δ`, where
/// `u(λ)` solves `[J̃; √λ·I] u ≈ [−r; 0]`.
pub(crate) trait Subproblem {
    /// The step for trust radius `delta`, starting the `λ` search at `lambda0` (the previous
    /// iteration's `λ`).
    ///
    /// # Errors
    /// [`Error::Sparse`] when a sparse factorisation fails (the dense ones cannot).
    fn step(&mut self, delta: f64, lambda0: f64) -> Result<Step, Error>;
}

/// A step of [`Subproblem::step`].
pub(crate) struct Step {
    /// `u = D·p`, one entry per free column, in the order of `free`.
    pub(crate) u: Vec<f64>,
    /// `‖u‖`.
    pub(crate) u_norm: f64,
    /// The damping `λ` of the step (0: Gauss–Newton).
    pub(crate) lambda: f64,
    /// `‖J̃ u‖` (MINPACK's `‖R u‖`), for the predicted reduction.
    pub(crate) jp_norm: f64,
}

/// The dense back end: `J` stored `m × n`, and reduced at each linearisation to the triangle
/// `R₊` of `[J_f r]` (`R₊ᵀR₊ = [J_f r]ᵀ[J_f r]`), from which the gradient and the scaled QR
/// are taken in `O(n_f²)` and `O(n_f³)`, as the streaming back end does.
///
/// At a trial point that follows an accepted step (or the linearisation at `x0`), the
/// residuals and the Jacobian are evaluated together ([`Problem::residuals_and_jacobian`]):
/// such steps are usually accepted (MINPACK accepts any step with `ρ ≥ 10⁻⁴`), and an accepted
/// point then needs no Jacobian pass of its own. After a rejected step, and when the step's
/// predicted reduction meets `ftol`, the trial evaluates the residuals only. The iterates are
/// MINPACK's either way; only the evaluation count changes ([`Fit::n_jacobians`] counts every
/// Jacobian evaluated, used or not).
struct Dense<'a, P: Problem> {
    p: &'a P,
    free: &'a [usize],
    /// `J` at `x` until [`Dense::fold`] has reduced it; afterwards scratch, into which a trial
    /// point's Jacobian is evaluated (it becomes `J` at `x` if the step is accepted).
    jac: Mat<f64>,
    r: Col<f64>,
    r_trial: Col<f64>,
    /// Whether `jac` holds `J` at the last trial point.
    trial_has_jac: bool,
    /// Whether `jac` holds `J` at the current point, taken over from the trial point.
    jac_is_current: bool,
    /// Whether the next trial point gets its Jacobian too (the last step was accepted).
    jac_at_next_trial: bool,
    /// Successful Jacobian evaluations, at `x0` included.
    n_jacobians: usize,
    /// `R₊`, `(n_f+1) × (n_f+1)` column-major, at the current linearisation.
    tri: Vec<f64>,
    /// `‖J_j‖` for the free columns at the current linearisation (taken before the fold,
    /// which uses the columns of `jac` as scratch).
    col_norms: Vec<f64>,
    /// Copy of `r` folded as the last column of `[J_f r]`.
    r_scratch: Vec<f64>,
}

impl<'a, P: Problem> Dense<'a, P> {
    /// Linearised at `x0`, where `r` and `jac` were evaluated (and found finite).
    fn new(p: &'a P, free: &'a [usize], r: Col<f64>, jac: Mat<f64>) -> Self {
        let m = jac.nrows();
        let n1 = free.len() + 1;
        let mut dense = Self {
            p,
            free,
            jac,
            r,
            r_trial: Col::zeros(m),
            trial_has_jac: false,
            jac_is_current: false,
            jac_at_next_trial: true,
            n_jacobians: 1,
            tri: vec![0.0; n1 * n1],
            col_norms: Vec::new(),
            r_scratch: vec![0.0; m],
        };
        dense.fold();
        dense
    }

    /// Linearised at `x0`, where `r` was evaluated and `[J_f r]` reduced to the triangle
    /// `r_free` (`(n_f+1) × (n_f+1)`, upper triangular): `J` is evaluated only if the iteration
    /// relinearises (its `m × n` scratch allocated then).
    fn from_triangle(p: &'a P, free: &'a [usize], r: Col<f64>, r_free: MatRef<'_, f64>) -> Self {
        let (m, n1) = (r.nrows(), free.len() + 1);
        Self {
            p,
            free,
            jac: Mat::new(),
            r,
            r_trial: Col::zeros(m),
            trial_has_jac: false,
            jac_is_current: false,
            jac_at_next_trial: true,
            n_jacobians: 0,
            tri: (0..n1 * n1).map(|k| r_free[(k % n1, k / n1)]).collect(),
            col_norms: (0..n1 - 1)
                .map(|j| r_free.col(j).subrows(0, j + 1).norm_l2())
                .collect(),
            r_scratch: vec![0.0; m],
        }
    }

    /// Allocates `jac` (`m × n`) if it is not (a start from a triangle).
    fn ensure_jac(&mut self) {
        if self.jac.nrows() == 0 {
            self.jac = Mat::zeros(self.r.nrows(), self.p.layout().len());
        }
    }

    /// `tri ← R₊` of `[J_f r]`, folded in place block of rows by block of rows
    /// ([`householder::fold_cols`], each block in cache), after `col_norms ← ‖J_j‖`. The
    /// columns of `jac` are scratch afterwards (only a new evaluation writes `jac` again).
    fn fold(&mut self) {
        self.col_norms = self
            .free
            .iter()
            .map(|&k| col_norm(self.jac.col(k)))
            .collect();
        self.tri.iter_mut().for_each(|v| *v = 0.0);
        for (d, v) in self.r_scratch.iter_mut().zip(self.r.iter()) {
            *d = *v;
        }
        // The columns of an owned `Mat` are contiguous, and `free` holds distinct indices
        // (`check_free`), so each free column is taken once.
        let mut all: Vec<Option<&mut [f64]>> = self
            .jac
            .as_mut()
            .col_iter_mut()
            .map(|c| c.try_as_col_major_mut().map(|c| c.as_slice_mut()))
            .collect();
        let mut cols: Vec<&mut [f64]> = Vec::with_capacity(self.free.len() + 1);
        for &k in self.free {
            match all.get_mut(k).and_then(Option::take) {
                Some(c) => cols.push(c),
                None => unreachable!("free column {k} missing or taken twice"),
            }
        }
        let m = self.r_scratch.len();
        cols.push(&mut self.r_scratch);
        if m <= FOLD_ROWS {
            householder::fold_cols(&mut self.tri, &mut cols);
            return;
        }
        for start in (0..m).step_by(FOLD_ROWS) {
            let rows = start..m.min(start + FOLD_ROWS);
            let mut block: Vec<&mut [f64]> =
                cols.iter_mut().map(|c| &mut c[rows.clone()]).collect();
            householder::fold_cols(&mut self.tri, &mut block);
        }
    }
}

impl<P: Problem> Linearised for Dense<'_, P> {
    fn trial_norm(&mut self, x_trial: ColRef<'_, f64>, may_continue: bool) -> f64 {
        let with_jac = std::mem::take(&mut self.jac_at_next_trial) && may_continue;
        if with_jac {
            self.ensure_jac();
        }
        self.trial_has_jac = with_jac
            && self
                .p
                .residuals_and_jacobian(x_trial, self.r_trial.as_mut(), self.jac.as_mut())
                .is_ok();
        let evaluated = if self.trial_has_jac {
            self.n_jacobians += 1;
            Ok(())
        } else {
            // Without the Jacobian, or again alone when the joint evaluation failed (the
            // residuals may still be evaluable; `relinearise` then reports the Jacobian's
            // failure, as when the two are evaluated apart).
            self.p.residuals(x_trial, self.r_trial.as_mut())
        };
        // The norm is finite exactly when every residual is (an overflowing sum of squares is
        // rescaled, see `householder::norm2`).
        match evaluated.map(|()| col_norm(self.r_trial.as_ref())) {
            Ok(n) if n.is_finite() => n,
            _ => f64::INFINITY,
        }
    }
    fn accept(&mut self) {
        std::mem::swap(&mut self.r, &mut self.r_trial);
        // `jac` holds `J` at the trial point, now the current one.
        self.jac_is_current = std::mem::take(&mut self.trial_has_jac);
        self.jac_at_next_trial = true;
    }
    fn relinearise(&mut self, x: ColRef<'_, f64>) -> Result<(), Termination> {
        if !std::mem::take(&mut self.jac_is_current) {
            self.ensure_jac();
            self.p
                .jacobian(x, self.jac.as_mut())
                .map_err(Termination::EvalFailed)?;
            self.n_jacobians += 1;
        }
        self.fold();
        // A column norm is finite exactly when the column is (`col_norm`); the columns that
        // are not free do not enter the step.
        if self.col_norms.iter().all(|c| c.is_finite()) {
            Ok(())
        } else {
            Err(Termination::Numerical)
        }
    }
    fn col_norms(&self) -> Vec<f64> {
        // From `J` itself (as MINPACK), not from `R₊`, which has the same column norms up to
        // rounding; taken by `fold`.
        self.col_norms.clone()
    }
    fn gradient_abs(&self, j: usize) -> f64 {
        // `J_jᵀr = Σᵢ R₊[i, j]·R₊[i, n_f]` (`R₊ᵀR₊ = [J_f r]ᵀ[J_f r]`), in O(n_f).

        let n1 = self.free.len() + 1;
        let col = &self.tri[j * n1..j * n1 + j + 1];
        let qtr = &self.tri[(n1 - 1) * n1..];
        col.iter().zip(qtr).map(|(a, b)| a * b).sum::<f64>().abs()
    }
    type Subproblem = ScaledQr;
    fn subproblem(&mut self, diag: &[f64]) -> ScaledQr {
        let nf = self.free.len();
        ScaledQr::from_triangle(
            MatRef::from_column_major_slice(&self.tri, nf + 1, nf + 1),
            diag,
        )
    }
}

/// Rows of `[J_f r]` folded into the triangle at a time by the dense back end: a block of
/// `256 × (n_f+1)` values stays in the L2 cache for the tens of columns of a calibration.
pub(crate) const FOLD_ROWS: usize = 256;

/// Outcome of [`run`].
pub(crate) struct Run {
    pub(crate) x: Col<f64>,
    pub(crate) termination: Termination,
    pub(crate) n_evaluations: usize,
    pub(crate) n_jacobians: usize,
    /// Linearisations from which a step was tried ([`Fit::n_iterations`]).
    pub(crate) n_iterations: usize,
    pub(crate) f_norm: f64,
    /// Whether the last linearisation was taken at `x` (no step accepted since).
    pub(crate) linearised_at_x: bool,
    /// The error of a subproblem that could not be solved (the run then ends with
    /// [`Termination::Numerical`]).
    pub(crate) error: Option<Error>,
}

/// The MINPACK `lmder` iteration from `x0`, where `lin` is linearised and `f_norm = ‖r(x0)‖`.
pub(crate) fn run(
    lin: &mut impl Linearised,
    x0: Col<f64>,
    free: &[usize],
    cfg: &LmConfig,
    f_norm0: f64,
) -> Run {
    let nf = free.len();
    let mut x = x0;
    let mut n_evaluations = 1;
    let mut n_jacobians = 1;
    let mut n_iterations = 0;
    let ftol = cfg.ftol.max(f64::EPSILON);
    let xtol = cfg.xtol.max(f64::EPSILON);
    let gtol = cfg.gtol.max(f64::EPSILON);
    let scaled_norm = |diag: &[f64], x: &Col<f64>| {
        free.iter()
            .zip(diag)
            .map(|(&k, d)| (d * x[k]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let mut diag = vec![0.0_f64; nf];
    let mut delta = 0.0_f64;
    let mut x_norm = 0.0_f64;
    let mut lambda = 0.0_f64;
    let mut f_norm = f_norm0;
    let mut first = true;
    let mut x_trial = x.clone();
    // The last trial point and its residual norm (a rejected point may come back, see below).
    let mut last_trial: Option<(Col<f64>, f64)> = None;
    let mut linearised_at_x = true;
    let mut error = None;

    let termination = 'outer: loop {
        let col_norms = lin.col_norms();
        update_scaling(&mut diag, &col_norms, first);
        if first {
            x_norm = scaled_norm(&diag, &x);
            delta = if x_norm > 0.0 {
                cfg.factor * x_norm
            } else {
                cfg.factor
            };
        }
        if f_norm == 0.0 {
            break Termination::GtolReached;
        }
        if gradient_cosine(lin, &col_norms, f_norm) <= gtol {
            break Termination::GtolReached;
        }
        n_iterations += 1;
        let mut subproblem = lin.subproblem(&diag);

        loop {
            if n_evaluations >= cfg.max_evaluations {
                break 'outer Termination::MaxEvaluations;
            }
            let step = match subproblem.step(delta, lambda) {
                Ok(step) => step,
                Err(e) => {
                    error = Some(e);
                    break 'outer Termination::Numerical;
                }
            };
            lambda = step.lambda;
            let u_norm = step.u_norm;
            if !u_norm.is_finite() || !lambda.is_finite() {
                break 'outer Termination::Numerical;
            }
            if first {
                delta = delta.min(u_norm);
            }
            let (predicted, directional) =
                trial_point(&x, free, &diag, &step, f_norm, &mut x_trial);
            // A first Gauss–Newton step may be the one-step estimate (the test below).
            let one_step = cfg.one_step.filter(|_| first && lambda == 0.0);
            // After a rejected Gauss–Newton step MINPACK sets Δ = ‖u‖, and the next `lmpar`
            // returns the same step (λ = 0 again): the same trial point, whose residual norm
            // (and, for `accept`, residuals) the problem has just produced. Reuse it rather
            // than evaluate twice; the iterates are MINPACK's either way.
            let f_norm_trial = match &last_trial {
                Some((xt, norm)) if xt.as_ref() == x_trial.as_ref() => *norm,
                _ => {
                    n_evaluations += 1;
                    // A predicted reduction within `ftol` usually ends the iteration here
                    // (the `ftol` test below), and the Jacobian there would go unused; so
                    // does a step that may be the one-step estimate.
                    lin.trial_norm(x_trial.as_ref(), predicted > ftol && one_step.is_none())
                }
            };
            last_trial = Some((x_trial.clone(), f_norm_trial));
            let Reduction { actual, ratio } = update_trust_region(
                &mut TrustRegion {
                    delta: &mut delta,
                    lambda: &mut lambda,
                },
                (f_norm, f_norm_trial),
                (predicted, directional),
                u_norm,
            );
            let accepted = ratio >= 1e-4;
            if accepted {
                std::mem::swap(&mut x, &mut x_trial);
                lin.accept();
                // `accept` took the trial residuals: the cache no longer matches them.
                last_trial = None;
                linearised_at_x = false;
                f_norm = f_norm_trial;
                x_norm = scaled_norm(&diag, &x);
            }
            if actual.abs() <= ftol && predicted <= ftol && 0.5 * ratio <= 1.0 {
                break 'outer Termination::FtolReached;
            }
            if accepted && one_step.is_some_and(|tol| (actual - predicted).abs() <= tol) {
                break 'outer Termination::OneStep;
            }
            if delta <= xtol * (x_norm + xtol) {
                break 'outer Termination::XtolReached;
            }
            if accepted {
                break;
            }
        }
        first = false;
        n_jacobians += 1;
        if let Err(t) = lin.relinearise(x.as_ref()) {
            if matches!(t, Termination::EvalFailed(_)) {
                n_jacobians -= 1;
            }
            break t;
        }
        linearised_at_x = true;
    };
    Run {
        x,
        termination,
        n_evaluations,
        n_jacobians,
        n_iterations,
        f_norm,
        linearised_at_x,
        error,
    }
}

/// The trial point of `step` into `x_trial`: `x` with each free entry `free[i]` moved by
/// `u_i / diag_i` (the scaled step back in the parameters' units). Returns the step's
/// predicted relative reduction of `‖r‖²` and its directional derivative from `‖r‖ = f_norm`
/// (MINPACK's `prered`, `dirder`).
fn trial_point(
    x: &Col<f64>,
    free: &[usize],
    diag: &[f64],
    step: &Step,
    f_norm: f64,
    x_trial: &mut Col<f64>,
) -> (f64, f64) {
    x_trial.copy_from(x);
    for ((&k, u), d) in free.iter().zip(&step.u).zip(diag) {
        x_trial[k] += u / d;
    }
    let t1 = step.jp_norm / f_norm;
    let t2 = step.lambda.sqrt() * step.u_norm / f_norm;
    (t1 * t1 + 2.0 * t2 * t2, -(t1 * t1 + t2 * t2))
}

/// MINPACK's `gnorm`: the largest cosine between a column of the Jacobian (norms
/// `col_norms`) and the residual vector (norm `f_norm`); 0 at a stationary point.
fn gradient_cosine(lin: &impl Linearised, col_norms: &[f64], f_norm: f64) -> f64 {
    (0..col_norms.len())
        .filter(|&j| col_norms[j] > 0.0)
        .map(|j| lin.gradient_abs(j) / (col_norms[j] * f_norm))
        .fold(0.0_f64, f64::max)
}

/// MINPACK's column scaling: `diag[j]` the largest norm column `j` has had (its norm at the
/// first iteration), 1 for a zero column.
fn update_scaling(diag: &mut [f64], col_norms: &[f64], first: bool) {
    for (d, &c) in diag.iter_mut().zip(col_norms) {
        *d = if first { c } else { d.max(c) };
        if *d == 0.0 {
            *d = 1.0;
        }
    }
}

/// The trust region's radius Δ (scaled) and the Levenberg–Marquardt parameter λ.
struct TrustRegion<'a> {
    /// Δ.
    delta: &'a mut f64,
    /// λ.
    lambda: &'a mut f64,
}

/// The actual relative reduction of ‖r‖² of a trial step and its ratio to the predicted one.
struct Reduction {
    /// MINPACK's `actred` (−1 when the trial residual is ten times larger).
    actual: f64,
    /// `actred / prered` (0 when nothing was predicted).
    ratio: f64,
}

/// MINPACK's trust-region update after a trial step of scaled length `u_norm`: from the
/// residual norms `(f_norm, f_norm_trial)` and the predicted reduction and directional
/// derivative `(predicted, directional)`, shrinks Δ (and grows λ) when the step did poorly
/// (ratio ≤ 0.25), widens Δ to twice the step (and halves λ) when it did well (ratio ≥ 0.75,
/// or a Gauss–Newton step).
fn update_trust_region(
    region: &mut TrustRegion<'_>,
    (f_norm, f_norm_trial): (f64, f64),
    (predicted, directional): (f64, f64),
    u_norm: f64,
) -> Reduction {
    let actual = if 0.1 * f_norm_trial < f_norm {
        1.0 - (f_norm_trial / f_norm).powi(2)
    } else {
        -1.0
    };
    let ratio = if predicted != 0.0 {
        actual / predicted
    } else {
        0.0
    };
    if ratio <= 0.25 {
        let mut shrink = if actual >= 0.0 {
            0.5
        } else {
            0.5 * directional / (directional + 0.5 * actual)
        };
        if 0.1 * f_norm_trial >= f_norm || shrink < 0.1 {
            shrink = 0.1;
        }
        *region.delta = shrink * region.delta.min(u_norm / 0.1);
        *region.lambda /= shrink;
    } else if *region.lambda == 0.0 || ratio >= 0.75 {
        *region.delta = u_norm / 0.5;
        *region.lambda *= 0.5;
    }
    Reduction { actual, ratio }
}

/// `‖v‖` (plain sum of squares; the iterates depend on this exact summation order).
pub(crate) fn norm(v: &[f64]) -> f64 {
    v.iter().map(|a| a * a).sum::<f64>().sqrt()
}

/// An upper-triangular `n × n` matrix, column-major (`data[j·n + i] = T_ij`, zeros below the
/// diagonal), with the products and triangular solves of [`lmpar`] written out for the small
/// `n` of a calibration (tens): no allocation beyond the result, no dispatch.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Upper {
    data: Vec<f64>,
    n: usize,
}

impl Upper {
    /// `T_ij`.
    ///
    /// # Panics
    /// If `i` or `j` is out of range.
    pub(crate) fn at(&self, i: usize, j: usize) -> f64 {
        assert!(
            i < self.n && j < self.n,
            "({i}, {j}) outside {0} × {0}",
            self.n
        );
        self.data[j * self.n + i]
    }

    /// `T[..=j, j]`, the nonzero part of column `j`.
    fn col(&self, j: usize) -> &[f64] {
        &self.data[j * self.n..j * self.n + j + 1]
    }

    /// `T·u` (`u` of length `n`), each entry summed along its row from the diagonal.
    fn times(&self, u: &[f64]) -> Vec<f64> {
        (0..self.n)
            .map(|i| (i..self.n).map(|j| self.data[j * self.n + i] * u[j]).sum())
            .collect()
    }

    /// `Tᵀ·v` (`v` of length `n`): entry `j` is `T[..=j, j]ᵀ v[..=j]`.
    fn transposed_times(&self, v: &[f64]) -> Vec<f64> {
        (0..self.n)
            .map(|j| self.col(j).iter().zip(v).map(|(a, b)| a * b).sum())
            .collect()
    }

    /// Solves `T[..k, ..k] y = b` in place (`b` of length `k ≤ n`, nonzero diagonal): back
    /// substitution by columns, each a contiguous update.
    fn solve_in_place(&self, b: &mut [f64]) {
        for j in (0..b.len()).rev() {
            b[j] /= self.data[j * self.n + j];
            let bj = b[j];
            for (bi, t) in b[..j].iter_mut().zip(&self.data[j * self.n..]) {
                *bi -= t * bj;
            }
        }
    }

    /// An estimate of the condition number `κ∞ = ‖T‖∞·‖T⁻¹‖∞` (LINPACK `dtrco`, Cline, Moler,
    /// Stewart and Wilkinson 1979): `Tᵀz = e` with the signs of `e = (±1)` chosen one by one to
    /// make `z` grow, then `T y = z`, and `‖T⁻¹‖∞ ≈ ‖y‖∞/‖z‖∞`, a lower bound that is rarely
    /// short by more than a small factor. `O(n²)`; `∞` (or NaN) for a zero diagonal entry.
    fn condition_estimate(&self) -> f64 {
        let n = self.n;
        if n == 0 {
            return 0.0;
        }
        // Only the decision depends on this estimate, not the iterates: products by the
        // reciprocal pivots and reassociated sums (which vectorise) are good enough.
        let inv: Vec<f64> = (0..n).map(|j| 1.0 / self.data[j * n + j]).collect();
        if !inv.iter().all(|v| v.is_finite()) {
            return f64::INFINITY;
        }
        let mut z = vec![0.0; n];
        for j in 0..n {
            let s = householder::dot(&self.col(j)[..j], &z[..j]);
            let e = if s > 0.0 { -1.0 } else { 1.0 };
            z[j] = (e - s) * inv[j];
        }
        let max_abs = |v: &[f64]| v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let z_max = max_abs(&z);
        for j in (0..n).rev() {
            z[j] *= inv[j];
            let zj = z[j];
            for (zi, t) in z[..j].iter_mut().zip(self.col(j)) {
                *zi -= t * zj;
            }
        }
        // ‖T‖∞: the row sums of |T|, accumulated column by column.
        let mut row_sums = vec![0.0; n];
        for j in 0..n {
            for (s, t) in row_sums.iter_mut().zip(self.col(j)) {
                *s += t.abs();
            }
        }
        // `f64::max` passes over NaN: a non-finite z (overflow) must not slip through.
        if z_max == 0.0 || !z_max.is_finite() || !z.iter().all(|v| v.is_finite()) {
            return f64::INFINITY;
        }
        max_abs(&row_sums) * max_abs(&z) / z_max
    }

    /// Solves `Tᵀ y = b` in place (`b` of length `n`, nonzero diagonal): forward substitution,
    /// each entry a contiguous dot product with a column of `T`.
    fn solve_transposed_in_place(&self, b: &mut [f64]) {
        for j in 0..b.len() {
            let col = self.col(j);
            let sum: f64 = col[..j].iter().zip(&b[..j]).map(|(t, y)| t * y).sum();
            b[j] = (b[j] - sum) / col[j];
        }
    }
}

/// Largest condition estimate ([`Upper::condition_estimate`]) of the scaled triangle `T D⁻¹`
/// that [`ScaledQr::from_triangle`] uses without pivoting: `√(1/ε) ≈ 6.7e7`, six orders of
/// magnitude below the condition (`≈ 1/(n·ε)`) at which a pivot would be declared zero, so an
/// estimate short by even a factor of 10⁵ keeps the rank decision the pivoted QR's.
const UNPIVOTED_COND: f64 = 6.7e7;

/// QR of the scaled free Jacobian, `J D⁻¹ Π = Q R`, and `Q₁ᵀ r` (`Π` the identity unless the
/// triangle was near singular, see [`ScaledQr::from_triangle`]).
pub(crate) struct ScaledQr {
    /// `R`, `n_free × n_free` upper triangular.
    r: Upper,
    /// `perm[k]`: position in `free` of pivot column `k`.
    perm: Vec<usize>,
    /// First `n_free` entries of `Qᵀ r`.
    qtr: Vec<f64>,
    /// Number of leading pivots with a nonzero `|R_kk|` (MINPACK `nsing`).
    n_sing: usize,
}

impl ScaledQr {
    /// The factorisation from the triangle `R₊` (`(n_f+1) × (n_f+1)`, upper triangular) of
    /// `[J_f r]`, for the scaling `diag` (one entry per free column), in `O(n_f³)` (shared by
    /// the dense and streaming back ends). With `T` the leading `n_f × n_f` block and `t` the
    /// first `n_f` entries of the last column, `T D⁻¹` is itself an `R` of `J_f D⁻¹` (the same
    /// Gram matrix) with `Q₁ᵀr = t`:
    ///
    /// - when `T D⁻¹` is far from singular (condition estimate below [`UNPIVOTED_COND`]), it
    ///   is used as it stands, in the original column order: every pivot is then well above
    ///   the rank threshold below, so the pivoted QR would find no singular pivot either, and
    ///   the step `u` (which does not depend on the column order in exact arithmetic) differs
    ///   from the pivoted one by rounding only (relative `O(κ·ε)`);
    /// - otherwise, the column-pivoted Householder QR (MINPACK `qrfac`) of `[T D⁻¹ | t]` with
    ///   `t` never a pivot, which sorts `|R_kk|` down and so reveals the numerical rank.
    pub(crate) fn from_triangle(tri: MatRef<'_, f64>, diag: &[f64]) -> Self {
        let nf = diag.len();
        debug_assert!(tri.nrows() == nf + 1 && tri.ncols() == nf + 1);
        let mut data = vec![0.0; nf * nf];
        for (j, &d) in diag.iter().enumerate() {
            // Rows ..=j (zeros below); divisions, not products by `1/d` (which round
            // differently), in a loop that vectorises.
            let dst = &mut data[j * nf..j * nf + j + 1];
            match tri.col(j).subrows(0, j + 1).try_as_col_major() {
                Some(src) => {
                    for (dst, v) in dst.iter_mut().zip(src.as_slice()) {
                        *dst = v / d;
                    }
                }
                None => {
                    for (dst, v) in dst.iter_mut().zip(tri.col(j).iter()) {
                        *dst = v / d;
                    }
                }
            }
        }
        let scaled = Upper { data, n: nf };
        if scaled.condition_estimate() <= UNPIVOTED_COND {
            return Self {
                r: scaled,
                perm: (0..nf).collect(),
                qtr: tri.col(nf).iter().take(nf).copied().collect(),
                n_sing: nf,
            };
        }
        Self::pivoted(&scaled, tri.col(nf).subrows(0, nf))
    }

    /// The column-pivoted Householder QR (MINPACK `qrfac`) of `[T | t]` (`T` upper triangular
    /// `n_f × n_f`, `t` of length `n_f` and never a pivot), with the rank decision on the
    /// sorted diagonal (see [`ScaledQr::from_triangle`]).
    pub(crate) fn pivoted(scaled: &Upper, t: ColRef<'_, f64>) -> Self {
        let nf = scaled.n;
        let mut a = ColMajor::zeros(nf, nf + 1);
        a.data[..nf * nf].copy_from_slice(&scaled.data);
        for (dst, v) in a.col_mut(nf).iter_mut().zip(t.iter()) {
            *dst = *v;
        }
        let mut perm = householder::qr_in_place(&mut a, nf);
        perm.truncate(nf);
        let qtr = a.col(nf).to_vec();
        // `a` holds R in its first n_f columns (zeros below the diagonal).
        a.data.truncate(nf * nf);
        let r = Upper {
            data: a.data,
            n: nf,
        };
        // Pivoting sorts |R_kk| down; below ε·n·|R_00| a pivot is zero at working precision
        // and the Gauss–Newton step leaves its component at 0.
        let r00 = if nf > 0 { r.at(0, 0).abs() } else { 0.0 };
        let tiny = f64::EPSILON * nf as f64 * r00;
        let n_sing = (0..nf).find(|&k| r.at(k, k).abs() <= tiny).unwrap_or(nf);
        Self {
            r,
            perm,
            qtr,
            n_sing,
        }
    }

    /// `R·u` (the scaled `J·p` up to `Q`).
    fn r_times(&self, u: &[f64]) -> Vec<f64> {
        self.r.times(u)
    }
}

impl Subproblem for ScaledQr {
    fn step(&mut self, delta: f64, lambda0: f64) -> Result<Step, Error> {
        let (u, lambda) = lmpar(self, delta, lambda0);
        // Norms in pivot order, the step back in the order of `free`.
        let u_norm = if u.iter().all(|v| v.is_finite()) {
            norm(&u)
        } else {
            f64::NAN
        };
        let jp_norm = norm(&self.r_times(&u));
        let mut unpivoted = vec![0.0; u.len()];
        for (&pos, v) in self.perm.iter().zip(&u) {
            unpivoted[pos] = *v;
        }
        Ok(Step {
            u: unpivoted,
            u_norm,
            lambda,
            jp_norm,
        })
    }
}

/// Moré's `lmpar`: the step `u` (pivoted scaled coordinates) and `λ ≥ 0` with
/// `‖u‖ ≈ Δ` (within 10 %) or `λ = 0` when the Gauss–Newton step is shorter than `1.1·Δ`.
/// `lambda0` is the previous `λ`, the starting guess.
fn lmpar(f: &ScaledQr, delta: f64, lambda0: f64) -> (Vec<f64>, f64) {
    let nf = f.qtr.len();
    // Gauss–Newton step: R₁₁ u₁ = −(Qᵀr)₁, zero in the singular part.
    let mut u = vec![0.0; nf];
    let ns = f.n_sing;
    for (ui, q) in u[..ns].iter_mut().zip(&f.qtr) {
        *ui = -q;
    }
    f.r.solve_in_place(&mut u[..ns]);
    let u_norm = norm(&u);
    let fp = u_norm - delta;
    if fp <= 0.1 * delta {
        return (u, 0.0);
    }
    // Lower bound from the Newton step at λ = 0 (full rank only): ‖T⁻ᵀ u/‖u‖‖².
    let lower = if ns == nf {
        let w: Vec<f64> = u.iter().map(|v| v / u_norm).collect();
        (fp / delta) / transposed_solve_norm_sq(&f.r, w)
    } else {
        0.0
    };
    // Upper bound: ‖Rᵀ Qᵀr‖ / Δ.
    let g_norm = norm(&f.r.transposed_times(&f.qtr));
    let mut damped = DenseDamped { f, s: None };
    match lambda_search(&mut damped, delta, lambda0, (u, u_norm), lower, g_norm) {
        Ok(step) => step,
        Err(never) => match never {},
    }
}

/// `‖T⁻ᵀ w‖²`.
fn transposed_solve_norm_sq(t: &Upper, mut w: Vec<f64>) -> f64 {
    t.solve_transposed_in_place(&mut w);
    w.iter().map(|v| v * v).sum::<f64>()
}

/// The damped steps of one trust-region subproblem, for [`lambda_search`]: `u(λ)` solving
/// `[J̃; √λ·I] u ≈ [−r; 0]`, and for the last `λ` solved `‖S⁻ᵀ w‖²` with `SᵀS = J̃ᵀJ̃ + λI`
/// (the derivative of `‖u(λ)‖` that Moré's Newton step needs).
pub(crate) trait DampedSteps {
    /// Why a step cannot be computed (`Infallible` for the dense back ends).
    type Error;
    /// `u(λ)` for `λ > 0`.
    fn damped(&mut self, lambda: f64) -> Result<Vec<f64>, Self::Error>;
    /// `‖S⁻ᵀ w‖²` at the `λ` of the last [`DampedSteps::damped`].
    fn newton_denominator(&mut self, w: Vec<f64>) -> Result<f64, Self::Error>;
}

/// The dense damped steps: [`damped_step`] on the triangle of [`ScaledQr`].
struct DenseDamped<'a> {
    f: &'a ScaledQr,
    /// `S` of the last damped step.
    s: Option<Upper>,
}

impl DampedSteps for DenseDamped<'_> {
    type Error = std::convert::Infallible;
    fn damped(&mut self, lambda: f64) -> Result<Vec<f64>, Self::Error> {
        let (u, s) = damped_step(&self.f.r, &self.f.qtr, lambda);
        self.s = Some(s);
        Ok(u)
    }
    fn newton_denominator(&mut self, w: Vec<f64>) -> Result<f64, Self::Error> {
        Ok(self
            .s
            .as_ref()
            .map_or(f64::NAN, |s| transposed_solve_norm_sq(s, w)))
    }
}

/// Moré's safeguarded Newton iteration for `λ` (MINPACK `lmpar`, Moré 1978 §5), shared by the
/// dense and sparse back ends: from the Gauss–Newton step `(u, ‖u‖)` (longer than `1.1·Δ`),
/// the bounds `lower` (0 unless known) and `‖J̃ᵀr‖ / Δ`, and the previous `λ`, at most ten
/// damped steps until `‖u(λ)‖` lies within 10 % of `Δ`. Returns the last step and its `λ`.
///
/// # Errors
/// The first error of `steps`.
pub(crate) fn lambda_search<D: DampedSteps>(
    steps: &mut D,
    delta: f64,
    lambda0: f64,
    gauss_newton: (Vec<f64>, f64),
    lower: f64,
    g_norm: f64,
) -> Result<(Vec<f64>, f64), D::Error> {
    let (mut u, mut u_norm) = gauss_newton;
    let mut fp = u_norm - delta;
    let mut lower = lower;
    let mut upper = g_norm / delta;
    if upper == 0.0 {
        upper = f64::MIN_POSITIVE / delta.min(0.1);
    }
    let mut lambda = lambda0.max(lower).min(upper);
    if lambda == 0.0 {
        lambda = g_norm / u_norm;
    }
    for iteration in 1..=10 {
        if lambda == 0.0 {
            lambda = f64::MIN_POSITIVE.max(0.001 * upper);
        }
        u = steps.damped(lambda)?;
        u_norm = norm(&u);
        let fp_old = fp;
        fp = u_norm - delta;
        if !u_norm.is_finite()
            || fp.abs() <= 0.1 * delta
            || (lower == 0.0 && fp <= fp_old && fp_old < 0.0)
            || iteration == 10
        {
            break;
        }
        let w: Vec<f64> = u.iter().map(|v| v / u_norm).collect();
        let correction = (fp / delta) / steps.newton_denominator(w)?;
        if fp > 0.0 {
            lower = lower.max(lambda);
        } else if fp < 0.0 {
            upper = upper.min(lambda);
        }
        lambda = lower.max(lambda + correction);
    }
    Ok((u, lambda))
}

/// Solves `min ‖[R; √λ·I] u + [Qᵀr; 0]‖` for upper-triangular `R` (`n × n`); returns `u` and
/// the triangular factor `S` (`SᵀS = RᵀR + λI`).
///
/// The QR of the stacked `[R | −Qᵀr; √λ·I | 0]` by Householder reflections with its structure
/// used: reflection `k` acts on row `k` of `R` (the rows below it are not reached yet) and on
/// rows `0..=k` of the lower block (`√λ·I` fills in above its diagonal as the reflections
/// pass), so it costs `≈ 4(k+1)(n−k)` flops and one square root; `≈ 2n³/3` flops in all, with
/// every update a contiguous row operation. MINPACK `qrsolv` eliminates the same rows by
/// `n²/2` Givens rotations instead, each with a square root and a division on the critical
/// path; the results agree up to rounding (and the signs of `S`'s rows, which `SᵀS` and `u`
/// do not see).
fn damped_step(rmat: &Upper, qtr: &[f64], lambda: f64) -> (Vec<f64>, Upper) {
    let n = qtr.len();
    let n1 = n + 1;
    let sqrt_lambda = lambda.sqrt();
    // [R | −Qᵀr] and [√λ·I | 0], row-major (row k at k·(n+1)).
    let mut a = vec![0.0; n * n1];
    let mut low = vec![0.0; n * n1];
    for k in 0..n {
        for (j, v) in a[k * n1..(k + 1) * n1]
            .iter_mut()
            .enumerate()
            .take(n)
            .skip(k)
        {
            *v = rmat.data[j * n + k];
        }
        a[k * n1 + n] = -qtr[k];
        low[k * n1 + k] = sqrt_lambda;
    }
    let mut x = vec![0.0; n];
    let mut f = vec![0.0; n1];
    for k in 0..n {
        // x = the lower block's column k (rows 0..=k; zero below).
        for (i, xi) in x[..=k].iter_mut().enumerate() {
            *xi = low[i * n1 + k];
        }
        let x_tail = norm(&x[..=k]);
        if x_tail == 0.0 {
            continue;
        }
        let (alpha, v0, tau) = householder::reflector(a[k * n1 + k], x_tail);
        // f_j = τ·(v0·A_kj + Σ_i x_i·L_ij) for the columns j > k (and the right-hand side).
        let fk = &mut f[k + 1..];
        let a_row = &mut a[k * n1 + k + 1..(k + 1) * n1];
        for (fj, akj) in fk.iter_mut().zip(a_row.iter()) {
            *fj = v0 * akj;
        }
        for (i, &xi) in x[..=k].iter().enumerate() {
            for (fj, lij) in fk.iter_mut().zip(&low[i * n1 + k + 1..(i + 1) * n1]) {
                *fj += xi * lij;
            }
        }
        fk.iter_mut().for_each(|fj| *fj *= tau);
        for (akj, fj) in a_row.iter_mut().zip(fk.iter()) {
            *akj -= v0 * fj;
        }
        for (i, &xi) in x[..=k].iter().enumerate() {
            for (lij, fj) in low[i * n1 + k + 1..(i + 1) * n1].iter_mut().zip(fk.iter()) {
                *lij -= xi * fj;
            }
        }
        a[k * n1 + k] = alpha;
    }
    // S column-major: the transpose of the row-major `a`.
    let mut data = vec![0.0; n * n];
    for k in 0..n {
        for j in k..n {
            data[j * n + k] = a[k * n1 + j];
        }
    }
    let s = Upper { data, n };
    // S u = w; a zero pivot (λ = 0 with singular R) leaves the trailing components at 0.
    let n_sing = (0..n).find(|&k| s.at(k, k) == 0.0).unwrap_or(n);
    let mut u = vec![0.0; n];
    for (ui, k) in u[..n_sing].iter_mut().zip(0..) {
        *ui = a[k * n1 + n];
    }
    s.solve_in_place(&mut u[..n_sing]);
    (u, s)
}

#[cfg(test)]
pub(crate) mod tests;
