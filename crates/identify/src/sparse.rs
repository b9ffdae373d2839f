//! Sparse back end: block-structured problems (many nuisance or per-unit parameters, a few
//! shared ones) whose dense Jacobian would not fit in memory, on faer's sparse QR.
//!
//! Sources: Levenberg–Marquardt with the damping update of H. B. Nielsen, "Damping parameter in
//! Marquardt's method", IMM-REP-1999-05, DTU (λ scaled by `max(1/3, 1 − (2ρ − 1)³)` on success,
//! doubled-then-doubling on failure), on the column-scaled problem of Moré (1978); each step
//! solves the damped system `[J D⁻¹; √λ·I] u ≈ [−r; 0]` by a sparse Householder QR (faer's
//! supernodal/simplicial multifrontal QR with a COLAMD fill-reducing column ordering; T. A.
//! Davis, "Algorithm 915, SuiteSparseQR", ACM TOMS 38, 2011). The symbolic analysis is done
//! once, the numeric factorisation once per trial step. Marginal standard deviations come from
//! the distance of a column to the span of the others (Björck 1996, §1.1.4):
//! `Var(x_j) = σ² / ‖(I − P₋ⱼ) J_j‖²`, with `P₋ⱼ` the projector onto the other columns, one
//! extra sparse least-squares solve per parameter asked for.

use faer::linalg::solvers::SolveLstsqCore;
use faer::sparse::linalg::solvers::{Qr, SymbolicQr};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Col, ColRef, Conj, Mat};

use crate::covariance::Covariance;
use crate::error::{Error, check_config};
use crate::lm::{Fit, LmConfig, Termination};
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

fn eval_err(e: EvalError) -> Error {
    Error::Eval(e)
}

/// Column-scaled, damped Gauss–Newton step: `min ‖[J D⁻¹; √λ·I] u + [r; 0]‖`.
struct DampedSystem {
    m: usize,
    n: usize,
    /// Pattern of `[J; I]` (J's pattern with one extra row entry per column).
    symbolic: SymbolicSparseColMat<usize>,
    /// Position of each Jacobian value in the augmented values.
    jac_pos: Vec<usize>,
    /// Position of each diagonal entry of the `√λ·I` block.
    diag_pos: Vec<usize>,
    values: Vec<f64>,
    qr_symbolic: SymbolicQr<usize>,
}

impl DampedSystem {
    fn new(m: usize, col_ptr: &[usize], row_idx: &[usize]) -> Result<Self, Error> {
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
        let symbolic = SymbolicSparseColMat::new_checked(m + n, n, aug_ptr, None, aug_idx);
        let qr_symbolic = SymbolicQr::try_new(symbolic.as_ref()).map_err(|e| Error::Sparse {
            reason: format!("{e:?}"),
        })?;
        let values = vec![0.0; symbolic.row_idx().len()];
        Ok(Self {
            m,
            n,
            symbolic,
            jac_pos,
            diag_pos,
            values,
            qr_symbolic,
        })
    }

    /// The step `p = D⁻¹ u` (unscaled) and `‖J p‖` for damping `lambda`.
    fn step(
        &mut self,
        jac_values: &[f64],
        col_of: &[usize],
        diag: &[f64],
        r: &[f64],
        lambda: f64,
    ) -> Result<(Vec<f64>, Vec<f64>), Error> {
        for (k, &pos) in self.jac_pos.iter().enumerate() {
            self.values[pos] = jac_values[k] / diag[col_of[k]];
        }
        let s = lambda.sqrt();
        for &pos in &self.diag_pos {
            self.values[pos] = s;
        }
        let mat = SparseColMatRef::new(self.symbolic.as_ref(), &self.values);
        let qr = Qr::try_new_with_symbolic(self.qr_symbolic.clone(), mat).map_err(|e| {
            Error::Sparse {
                reason: format!("{e:?}"),
            }
        })?;
        let mut rhs = Mat::<f64>::zeros(self.m + self.n, 1);
        for i in 0..self.m {
            rhs[(i, 0)] = -r[i];
        }
        qr.solve_lstsq_in_place_with_conj(Conj::No, rhs.as_mut());
        let u: Vec<f64> = (0..self.n).map(|j| rhs[(j, 0)]).collect();
        let p = u.iter().zip(diag).map(|(u, d)| u / d).collect();
        Ok((p, u))
    }
}

/// Levenberg–Marquardt on the sparse back end, over all parameters of `p` (no pruning: the
/// layout must be identifiable), then the covariance of the parameters `std_of` (layout
/// indices).
///
/// Each iteration evaluates `r` and the sparse Jacobian once, and factorises the damped,
/// column-scaled system by sparse QR (once per trial step). `D` holds the Jacobian column
/// norms (running maximum, Moré 1978); `λ` starts at 0 (a Gauss–Newton step) and follows
/// Nielsen's update. Stopping tests as [`LmConfig`]: relative cost reduction (actual and
/// predicted) at most `ftol`, scaled step at most `xtol·(‖D·x‖ + xtol)`, largest gradient
/// cosine at most `gtol`, or `max_evaluations` evaluations of `r`.
///
/// Memory: the pattern, its values, and the sparse QR factors; never `m × n`.
///
/// # Errors
/// [`Error::NoSparseJacobian`] if `p` has no [`Problem::sparse_jacobian`];
/// [`Error::WrongLength`], [`Error::TooFewResiduals`], [`Error::InvalidConfig`],
/// [`Error::Eval`], [`Error::NonFiniteResidual`] as the dense solver; [`Error::Sparse`] if the
/// sparse factorisation fails; [`Error::Singular`] if a parameter of `std_of` is not determined.
pub fn levenberg_marquardt_sparse(
    p: &impl Problem,
    x0: Col<f64>,
    cfg: &LmConfig,
    std_of: &[usize],
) -> Result<SparseFit, Error> {
    let sj = p.sparse_jacobian().ok_or(Error::NoSparseJacobian)?;
    let layout = p.layout();
    let n = layout.len();
    if x0.nrows() != n {
        return Err(Error::WrongLength {
            expected: n,
            found: x0.nrows(),
        });
    }
    check_config("ftol", cfg.ftol, false)?;
    check_config("xtol", cfg.xtol, false)?;
    check_config("gtol", cfg.gtol, false)?;
    let m = p.n_residuals();
    if m < n {
        return Err(Error::TooFewResiduals {
            n_residuals: m,
            n_free: n,
        });
    }
    let (col_ptr, row_idx) = sj.pattern();
    let nnz = row_idx.len();
    let col_of: Vec<usize> = (0..n)
        .flat_map(|j| std::iter::repeat_n(j, col_ptr[j + 1] - col_ptr[j]))
        .collect();
    let mut system = DampedSystem::new(m, &col_ptr, &row_idx)?;

    let mut x = x0;
    let mut r = vec![0.0; m];
    let mut values = vec![0.0; nnz];
    sj.residuals_and_values(x.as_ref(), &mut r, &mut values)
        .map_err(eval_err)?;
    if let Some(index) = r.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteResidual { index });
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        let row = row_idx[k];
        return Err(Error::NonFiniteJacobian {
            row,
            name: layout.name(col_of[k]).to_owned(),
        });
    }
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let mut f_norm = norm(&r);
    let (ftol, xtol, gtol) = (
        cfg.ftol.max(f64::EPSILON),
        cfg.xtol.max(f64::EPSILON),
        cfg.gtol.max(f64::EPSILON),
    );
    let mut diag = vec![0.0_f64; n];
    let mut lambda = 0.0_f64;
    let mut nu = 2.0_f64;
    let mut n_evaluations = 1;
    let mut n_jacobians = 1;
    let mut n_iterations = 0;
    let mut r_trial = vec![0.0; m];
    let mut values_trial = vec![0.0; nnz];
    let termination = 'outer: loop {
        let mut col_norm = vec![0.0; n];
        let mut grad = vec![0.0; n];
        for k in 0..nnz {
            let j = col_of[k];
            col_norm[j] += values[k] * values[k];
            grad[j] += values[k] * r[row_idx[k]];
        }
        for j in 0..n {
            col_norm[j] = col_norm[j].sqrt();
            diag[j] = diag[j].max(col_norm[j]);
            if diag[j] == 0.0 {
                diag[j] = 1.0;
            }
        }
        if f_norm == 0.0 {
            break Termination::GtolReached;
        }
        let g_cos = (0..n)
            .filter(|&j| col_norm[j] > 0.0)
            .map(|j| grad[j].abs() / (col_norm[j] * f_norm))
            .fold(0.0_f64, f64::max);
        if g_cos <= gtol {
            break Termination::GtolReached;
        }
        n_iterations += 1;
        loop {
            if n_evaluations >= cfg.max_evaluations {
                break 'outer Termination::MaxEvaluations;
            }
            let (step, u) = system.step(&values, &col_of, &diag, &r, lambda)?;
            if !step.iter().all(|v| v.is_finite()) {
                break 'outer Termination::Numerical;
            }
            // Predicted reduction: ‖r‖² − ‖r + J p‖² (MINPACK's prered, relative).
            let mut jp = vec![0.0; m];
            for k in 0..nnz {
                jp[row_idx[k]] += values[k] * step[col_of[k]];
            }
            let jp_norm = norm(&jp);
            let u_norm = norm(&u);
            let t1 = jp_norm / f_norm;
            let t2 = lambda.sqrt() * u_norm / f_norm;
            let predicted = t1 * t1 + 2.0 * t2 * t2;
            let mut x_trial = x.clone();
            for j in 0..n {
                x_trial[j] += step[j];
            }
            n_evaluations += 1;
            let f_trial =
                match sj.residuals_and_values(x_trial.as_ref(), &mut r_trial, &mut values_trial) {
                    Ok(()) if r_trial.iter().all(|v| v.is_finite()) => norm(&r_trial),
                    _ => f64::INFINITY,
                };
            let actual = if 0.1 * f_trial < f_norm {
                1.0 - (f_trial / f_norm).powi(2)
            } else {
                -1.0
            };
            let ratio = if predicted != 0.0 {
                actual / predicted
            } else {
                0.0
            };
            let accepted = ratio >= 1e-4;
            if accepted {
                x = x_trial;
                std::mem::swap(&mut r, &mut r_trial);
                std::mem::swap(&mut values, &mut values_trial);
                f_norm = f_trial;
                n_jacobians += 1;
                if !values.iter().all(|v| v.is_finite()) {
                    break 'outer Termination::Numerical;
                }
                lambda *= (1.0_f64 / 3.0).max(1.0 - (2.0 * ratio - 1.0).powi(3));
                if lambda < 1e-12 {
                    lambda = 0.0;
                }
                nu = 2.0;
            } else {
                // The columns are scaled to unit norm, so λ is relative to 1.
                lambda = if lambda == 0.0 { 1e-6 } else { lambda * nu };
                nu *= 2.0;
            }
            let x_norm = (0..n).map(|j| (diag[j] * x[j]).powi(2)).sum::<f64>().sqrt();
            if actual.abs() <= ftol && predicted <= ftol && 0.5 * ratio <= 1.0 {
                break 'outer Termination::FtolReached;
            }
            if u_norm <= xtol * (x_norm + xtol) {
                break 'outer Termination::XtolReached;
            }
            if accepted {
                break;
            }
            if lambda > 1e16 {
                break 'outer Termination::Numerical;
            }
        }
    };
    let cost = 0.5 * f_norm * f_norm;
    let sigma = if m > n {
        (2.0 * cost / (m - n) as f64).sqrt()
    } else {
        0.0
    };
    let covariance = covariance_block(m, &col_ptr, &row_idx, &values, std_of, sigma, layout)?;
    Ok(SparseFit {
        fit: Fit {
            x,
            termination,
            n_evaluations,
            n_jacobians,
            n_iterations,
            cost,
            residuals: Col::from_fn(m, |i| r[i]),
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
