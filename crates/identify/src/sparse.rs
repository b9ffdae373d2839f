//! Sparse back end: block-structured problems (many nuisance or per-unit parameters, a few
//! shared ones) whose dense Jacobian would not fit in memory, on faer's sparse QR.
//!
//! The iteration is the dense back end's (Moré 1978, MINPACK `lmder`: column scaling, trust
//! region, gain ratio, stopping tests; [`crate::lm`]); only the trust-region subproblem is
//! solved differently. For each damping `λ` that Moré's `lmpar` tries, the damped, column-scaled
//! system `[J D⁻¹; √λ·I] u ≈ [−r; 0]` is factorised by a sparse Householder QR (faer's
//! supernodal/simplicial multifrontal QR with a COLAMD fill-reducing column ordering; T. A.
//! Davis, "Algorithm 915, SuiteSparseQR", ACM TOMS 38, 2011); the symbolic analysis is done
//! once. The Newton correction of `λ` needs `‖S⁻ᵀ w‖²` with `SᵀS = D⁻¹JᵀJD⁻¹ + λI`: it is
//! `wᵀ z` with `z = (SᵀS)⁻¹ w`, one more solve with the same factors (the least-squares solution
//! of `[J D⁻¹; √λ·I] z ≈ [0; w/√λ]`). Marginal standard deviations come from the distance of a
//! column to the span of the others (Björck 1996, §1.1.4):
//! `Var(x_j) = σ² / ‖(I − P₋ⱼ) J_j‖²`, with `P₋ⱼ` the projector onto the other columns.

use std::sync::Arc;

use faer::linalg::solvers::SolveLstsqCore;
use faer::sparse::linalg::solvers::{Qr, SymbolicQr};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Col, ColRef, Conj, Mat};

use crate::covariance::Covariance;
use crate::error::Error;
use crate::lm::{
    DampedSteps, Fit, Linearised, LmConfig, Step, Subproblem, Termination, check_inputs,
    lambda_search, norm, run,
};
use crate::problem::{EvalError, Problem};

/// A Jacobian with a fixed sparsity pattern, evaluated straight into compressed-column form.
pub trait SparseJacobian: Sync {
    /// Column pointers (length `n + 1`) and row indices (sorted within each column) of the
    /// pattern, compressed sparse column (CSC) form: column `j` has its entries at
    /// `row_idx[col_ptr[j]..col_ptr[j+1]]`. Must not depend on `x`.
    fn pattern(&self) -> (Vec<usize>, Vec<usize>);
    /// Writes `r(x)` (length `m`) and the Jacobian values in pattern order (length
    /// `row_idx.len()`), same units as [`Problem::residuals`] / [`Problem::jacobian`].
    ///
    /// # Errors
    /// [`EvalError`] when the model cannot be evaluated at `x`.
    fn residuals_and_values(
        &self,
        x: ColRef<'_, f64>,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), EvalError>;
    /// Layout indices of the parameters whose covariance [`identify`](crate::identify)
    /// reports (default: all). A problem with thousands of per-unit parameters names the few
    /// shared ones: a dense covariance of all would not fit in memory.
    fn covariance_of(&self) -> Vec<usize> {
        (0..self.pattern().0.len().saturating_sub(1)).collect()
    }
}

/// Result of [`levenberg_marquardt_sparse`]: the fit and the marginal standard deviations of
/// the parameters asked for.
#[derive(Clone, Debug)]
pub struct SparseFit {
    /// The estimate; [`Fit::residuals`] holds `r` at the estimate (length `m`).
    pub fit: Fit,
    /// `σ̂ = √(‖r‖²/(m − n))`, residual units.
    pub sigma: f64,
    /// Covariance of the parameters `std_of` (in that order), with `σ̂` as the residual noise.
    pub covariance: Covariance,
    /// Number of nonzeros of the Jacobian pattern.
    pub nnz: usize,
}

fn sparse_error(e: impl std::fmt::Debug) -> Error {
    Error::Sparse {
        reason: format!("{e:?}"),
    }
}

/// The pattern of the Jacobian and of the damped system `[J D⁻¹; √λ·I]` (J's pattern with one
/// extra row entry per column), with its symbolic QR: fixed for the whole fit.
struct Pattern {
    m: usize,
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Column of each Jacobian value.
    col_of: Vec<usize>,
    /// Pattern of `[J; I]`.
    augmented: SymbolicSparseColMat<usize>,
    /// Position of each Jacobian value in the augmented values.
    jac_pos: Vec<usize>,
    /// Position of each diagonal entry of the `√λ·I` block.
    diag_pos: Vec<usize>,
    qr_symbolic: SymbolicQr<usize>,
}

impl Pattern {
    fn new(m: usize, col_ptr: Vec<usize>, row_idx: Vec<usize>) -> Result<Self, Error> {
        let n = col_ptr.len() - 1;
        let mut aug_ptr = Vec::with_capacity(n + 1);
        let mut aug_idx = Vec::with_capacity(row_idx.len() + n);
        let mut jac_pos = Vec::with_capacity(row_idx.len());
        let mut diag_pos = Vec::with_capacity(n);
        aug_ptr.push(0);
        for j in 0..n {
            for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
                jac_pos.push(aug_idx.len());
                aug_idx.push(i);
            }
            diag_pos.push(aug_idx.len());
            aug_idx.push(m + j);
            aug_ptr.push(aug_idx.len());
        }
        let augmented = SymbolicSparseColMat::new_checked(m + n, n, aug_ptr, None, aug_idx);
        let qr_symbolic = SymbolicQr::try_new(augmented.as_ref()).map_err(sparse_error)?;
        let col_of = (0..n)
            .flat_map(|j| std::iter::repeat_n(j, col_ptr[j + 1] - col_ptr[j]))
            .collect();
        Ok(Self {
            m,
            n,
            col_ptr,
            row_idx,
            col_of,
            augmented,
            jac_pos,
            diag_pos,
            qr_symbolic,
        })
    }
}

/// The sparse linearisation at the current point: `r` and the Jacobian values, and the same at
/// the last trial point (every evaluation gives both).
struct SparseLinearised<'a> {
    sj: &'a dyn SparseJacobian,
    pattern: Arc<Pattern>,
    r: Vec<f64>,
    values: Vec<f64>,
    r_trial: Vec<f64>,
    values_trial: Vec<f64>,
    /// `‖J_j‖` and `J_jᵀ r` at the current point.
    col_norms: Vec<f64>,
    gradient: Vec<f64>,
}

impl SparseLinearised<'_> {
    /// `col_norms` and `gradient` from the current values.
    fn summarise(&mut self) {
        let n = self.pattern.n;
        self.col_norms = vec![0.0; n];
        self.gradient = vec![0.0; n];
        for ((&j, &i), &v) in self
            .pattern
            .col_of
            .iter()
            .zip(&self.pattern.row_idx)
            .zip(&self.values)
        {
            self.col_norms[j] += v * v;
            self.gradient[j] += v * self.r[i];
        }
        self.col_norms.iter_mut().for_each(|c| *c = c.sqrt());
    }
}

impl Linearised for SparseLinearised<'_> {
    fn trial_norm(&mut self, x_trial: ColRef<'_, f64>, _may_continue: bool) -> f64 {
        match self
            .sj
            .residuals_and_values(x_trial, &mut self.r_trial, &mut self.values_trial)
        {
            Ok(()) if self.r_trial.iter().all(|v| v.is_finite()) => norm(&self.r_trial),
            _ => f64::INFINITY,
        }
    }
    fn accept(&mut self) {
        std::mem::swap(&mut self.r, &mut self.r_trial);
        std::mem::swap(&mut self.values, &mut self.values_trial);
    }
    fn relinearise(&mut self, _x: ColRef<'_, f64>) -> Result<(), Termination> {
        // The Jacobian was evaluated with the residuals at the accepted point.
        if !self.values.iter().all(|v| v.is_finite()) {
            return Err(Termination::Numerical);
        }
        self.summarise();
        Ok(())
    }
    fn col_norms(&self) -> Vec<f64> {
        self.col_norms.clone()
    }
    fn gradient_abs(&self, j: usize) -> f64 {
        self.gradient[j].abs()
    }
    type Subproblem = SparseSubproblem;
    fn subproblem(&mut self, diag: &[f64]) -> SparseSubproblem {
        let scaled = self
            .values
            .iter()
            .zip(&self.pattern.col_of)
            .map(|(v, &j)| v / diag[j])
            .collect();
        let gradient = self.gradient.iter().zip(diag).map(|(g, d)| g / d).collect();
        SparseSubproblem {
            pattern: Arc::clone(&self.pattern),
            scaled,
            r: self.r.clone(),
            gradient,
            augmented: vec![0.0; self.pattern.augmented.row_idx().len()],
            gauss_newton: None,
            last: None,
        }
    }
}

/// The trust-region subproblem of the sparse back end: Moré's `lmpar` with each `λ` tried
/// factorised by sparse QR (see the module documentation).
pub(crate) struct SparseSubproblem {
    pattern: Arc<Pattern>,
    /// `J D⁻¹` in pattern order.
    scaled: Vec<f64>,
    r: Vec<f64>,
    /// `D⁻¹ Jᵀ r`.
    gradient: Vec<f64>,
    /// Values of `[J D⁻¹; √λ·I]` (scratch).
    augmented: Vec<f64>,
    /// The Gauss–Newton step and its norm, once computed.
    gauss_newton: Option<(Vec<f64>, f64)>,
    /// The factors of the last damped step and its `λ`.
    last: Option<(Qr<usize, f64>, f64)>,
}

impl SparseSubproblem {
    /// The sparse QR of `[J D⁻¹; √λ·I]`.
    fn factorise(&mut self, lambda: f64) -> Result<Qr<usize, f64>, Error> {
        let pattern = &*self.pattern;
        for (&pos, &v) in pattern.jac_pos.iter().zip(&self.scaled) {
            self.augmented[pos] = v;
        }
        let s = lambda.sqrt();
        for &pos in &pattern.diag_pos {
            self.augmented[pos] = s;
        }
        let mat = SparseColMatRef::new(pattern.augmented.as_ref(), &self.augmented);
        Qr::try_new_with_symbolic(pattern.qr_symbolic.clone(), mat).map_err(sparse_error)
    }

    /// The least-squares solution of `[J D⁻¹; √λ·I] z ≈ [top; bottom]` (`top` of length `m`
    /// or empty for zeros, `bottom` of length `n` or empty for zeros).
    fn solve(&self, qr: &Qr<usize, f64>, top: &[f64], bottom: &[f64]) -> Vec<f64> {
        let (m, n) = (self.pattern.m, self.pattern.n);
        let mut rhs = Mat::<f64>::zeros(m + n, 1);
        for (i, v) in top.iter().enumerate() {
            rhs[(i, 0)] = *v;
        }
        for (j, v) in bottom.iter().enumerate() {
            rhs[(m + j, 0)] = *v;
        }
        qr.solve_lstsq_in_place_with_conj(Conj::No, rhs.as_mut());
        (0..n).map(|j| rhs[(j, 0)]).collect()
    }

    /// `u(λ)`: the damped step.
    fn damped_step(&self, qr: &Qr<usize, f64>) -> Vec<f64> {
        let minus_r: Vec<f64> = self.r.iter().map(|v| -v).collect();
        self.solve(qr, &minus_r, &[])
    }

    /// `‖J D⁻¹ u‖`.
    fn jacobian_times_norm(&self, u: &[f64]) -> f64 {
        let mut ju = vec![0.0; self.pattern.m];
        for ((&i, &j), v) in self
            .pattern
            .row_idx
            .iter()
            .zip(&self.pattern.col_of)
            .zip(&self.scaled)
        {
            ju[i] += v * u[j];
        }
        norm(&ju)
    }
}

impl Subproblem for SparseSubproblem {
    /// Moré's `lmpar` ([`lambda_search`], as the dense back end) with one sparse factorisation
    /// per `λ` tried. The lower bound of `λ` is 0 (MINPACK's bound for a rank-deficient `J`:
    /// the bound for a full-rank one needs `R⁻ᵀ` at `λ = 0`, which the sparse factors do not
    /// expose); the safeguarded Newton iteration converges from either.
    fn step(&mut self, delta: f64, lambda0: f64) -> Result<Step, Error> {
        // Gauss–Newton step, once per linearisation (a rejected step tries again with a
        // smaller Δ); a singular J (not finite) makes it infinitely long.
        let (u, u_norm) = match &self.gauss_newton {
            Some(gn) => gn.clone(),
            None => {
                let qr = self.factorise(0.0)?;
                let u = self.damped_step(&qr);
                let u_norm = if u.iter().all(|v| v.is_finite()) {
                    norm(&u)
                } else {
                    f64::INFINITY
                };
                self.gauss_newton = Some((u.clone(), u_norm));
                (u, u_norm)
            }
        };
        let (u, u_norm, lambda) = if u_norm - delta <= 0.1 * delta {
            (u, u_norm, 0.0)
        } else {
            let g_norm = norm(&self.gradient);
            let (u, lambda) = lambda_search(self, delta, lambda0, (u, u_norm), 0.0, g_norm)?;
            let u_norm = norm(&u);
            (u, u_norm, lambda)
        };
        Ok(Step {
            jp_norm: self.jacobian_times_norm(&u),
            u,
            u_norm,
            lambda,
        })
    }
}

impl DampedSteps for SparseSubproblem {
    type Error = Error;
    fn damped(&mut self, lambda: f64) -> Result<Vec<f64>, Error> {
        let qr = self.factorise(lambda)?;
        let u = self.damped_step(&qr);
        self.last = Some((qr, lambda));
        Ok(u)
    }
    /// `wᵀ z` with `z = (SᵀS)⁻¹ w`, the least-squares solution of `[J D⁻¹; √λ·I] z ≈
    /// [0; w/√λ]` with the last factors.
    fn newton_denominator(&mut self, w: Vec<f64>) -> Result<f64, Error> {
        let Some((qr, lambda)) = &self.last else {
            return Ok(f64::NAN);
        };
        let bottom: Vec<f64> = w.iter().map(|v| v / lambda.sqrt()).collect();
        let z = self.solve(qr, &[], &bottom);
        Ok(w.iter().zip(&z).map(|(a, b)| a * b).sum())
    }
}

/// Levenberg–Marquardt on the sparse back end, over all parameters of `p` (no pruning: the
/// layout must be identifiable), then the covariance of the parameters `std_of` (layout
/// indices).
///
/// The iteration is [`levenberg_marquardt`](crate::levenberg_marquardt)'s (Moré 1978: `D` the
/// running maximum of the Jacobian column norms, trust radius `Δ` from
/// [`LmConfig::factor`], the MINPACK stopping tests of [`LmConfig`]); each trial step solves
/// the trust-region subproblem by sparse QR factorisations of `[J D⁻¹; √λ·I]`, one per `λ`
/// tried (module documentation). Every evaluation gives `r` and the Jacobian values together,
/// so [`Fit::n_jacobians`] equals [`Fit::n_evaluations`].
///
/// Memory: the pattern, its values, and the sparse QR factors; never `m × n`.
///
/// # Errors
/// [`Error::NoSparseJacobian`] if `p` has no [`Problem::sparse_jacobian`];
/// [`Error::WrongLength`], [`Error::TooFewResiduals`], [`Error::InvalidConfig`],
/// [`Error::Eval`], [`Error::NonFiniteResidual`], [`Error::NonFiniteJacobian`] as the dense
/// solver; [`Error::Sparse`] if a sparse factorisation fails; [`Error::Singular`] if a
/// parameter of `std_of` is not determined.
pub fn levenberg_marquardt_sparse(
    p: &impl Problem,
    x0: Col<f64>,
    cfg: &LmConfig,
    std_of: &[usize],
) -> Result<SparseFit, Error> {
    let sj = p.sparse_jacobian().ok_or(Error::NoSparseJacobian)?;
    let layout = p.layout();
    let n = layout.len();
    let free: Vec<usize> = (0..n).collect();
    check_inputs(p, x0.as_ref(), &free, cfg)?;
    let m = p.n_residuals();
    let (col_ptr, row_idx) = sj.pattern();
    let nnz = row_idx.len();
    let pattern = Arc::new(Pattern::new(m, col_ptr, row_idx)?);

    let mut r = vec![0.0; m];
    let mut values = vec![0.0; nnz];
    sj.residuals_and_values(x0.as_ref(), &mut r, &mut values)
        .map_err(Error::Eval)?;
    if let Some(index) = r.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteResidual { index });
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteJacobian {
            row: pattern.row_idx[k],
            name: layout.name(pattern.col_of[k]).to_owned(),
        });
    }
    let f_norm = norm(&r);
    let mut lin = SparseLinearised {
        sj,
        pattern: Arc::clone(&pattern),
        r,
        values,
        r_trial: vec![0.0; m],
        values_trial: vec![0.0; nnz],
        col_norms: Vec::new(),
        gradient: Vec::new(),
    };
    lin.summarise();
    let run = run(&mut lin, x0, &free, cfg, f_norm);
    if let Some(e) = run.error {
        return Err(e);
    }
    let cost = 0.5 * run.f_norm * run.f_norm;
    let sigma = if m > n {
        (2.0 * cost / (m - n) as f64).sqrt()
    } else {
        0.0
    };
    let covariance = covariance_block(
        m,
        &pattern.col_ptr,
        &pattern.row_idx,
        &lin.values,
        std_of,
        sigma,
        layout,
    )?;
    Ok(SparseFit {
        fit: Fit {
            x: run.x,
            termination: run.termination,
            n_evaluations: run.n_evaluations,
            n_jacobians: run.n_evaluations,
            n_iterations: run.n_iterations,
            cost,
            residuals: Col::from_fn(m, |i| lin.r[i]),
        },
        sigma,
        covariance,
        nnz,
    })
}

/// Covariance block `σ²·[(JᵀJ)⁻¹]_SS` of the columns `which` (= S): the S columns are
/// regressed on the others by one sparse least-squares solve, `E = (I − P₋S) J_S`, and
/// `Cov_SS = σ²·(EᵀE)⁻¹` from the R factor of `E` (Björck 1996, §1.1.4: the covariance of a
/// subset is the inverse of its Schur complement).
pub(crate) fn covariance_block(
    m: usize,
    col_ptr: &[usize],
    row_idx: &[usize],
    values: &[f64],
    which: &[usize],
    sigma: f64,
    layout: &crate::ParamLayout,
) -> Result<Covariance, Error> {
    let n = col_ptr.len() - 1;
    let k = which.len();
    for &j in which {
        if j >= n {
            return Err(Error::FreeOutOfRange {
                index: j,
                n_params: n,
            });
        }
    }
    let in_s = |c: usize| which.contains(&c);
    let others: Vec<usize> = (0..n).filter(|&c| !in_s(c)).collect();
    // E = J_S, then minus its projection on the other columns.
    let mut e = Mat::<f64>::zeros(m, k);
    for (a, &j) in which.iter().enumerate() {
        for t in col_ptr[j]..col_ptr[j + 1] {
            e[(row_idx[t], a)] = values[t];
        }
    }
    if !others.is_empty() {
        let mut ptr = vec![0];
        let mut idx = Vec::new();
        let mut val = Vec::new();
        for &c in &others {
            idx.extend_from_slice(&row_idx[col_ptr[c]..col_ptr[c + 1]]);
            val.extend_from_slice(&values[col_ptr[c]..col_ptr[c + 1]]);
            ptr.push(idx.len());
        }
        let sym = SymbolicSparseColMat::new_checked(m, others.len(), ptr, None, idx);
        let mat = SparseColMatRef::new(sym.as_ref(), &val);
        let qr_sym = SymbolicQr::try_new(sym.as_ref()).map_err(|e| Error::Sparse {
            reason: format!("{e:?}"),
        })?;
        let qr = Qr::try_new_with_symbolic(qr_sym, mat).map_err(|e| Error::Sparse {
            reason: format!("{e:?}"),
        })?;
        let mut beta = e.clone();
        qr.solve_lstsq_in_place_with_conj(Conj::No, beta.as_mut());
        for (b, &c) in others.iter().enumerate() {
            for t in col_ptr[c]..col_ptr[c + 1] {
                let i = row_idx[t];
                for a in 0..k {
                    e[(i, a)] -= values[t] * beta[(b, a)];
                }
            }
        }
    }
    let free_layout =
        crate::ParamLayout::new(which.iter().map(|&j| layout.spec(j).clone()).collect());
    let all: Vec<usize> = (0..k).collect();
    let mut cov = crate::covariance::covariance(e.as_ref(), &free_layout, &all, sigma)?;
    cov.free = which.to_vec();
    Ok(cov)
}

#[cfg(test)]
mod tests;
