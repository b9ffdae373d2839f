//! The crate's error type: input that the solvers cannot accept.

use crate::problem::{EvalError, ParamLayout};

/// Input that [`levenberg_marquardt`](crate::levenberg_marquardt),
/// [`covariance`](crate::covariance) or [`identify`](crate::identify) cannot work with.
///
/// Data-dependent outcomes (no convergence, a pruned parameter) are not errors: they are
/// reported in [`Fit::termination`](crate::Fit::termination) and
/// [`Identifiability::pruned`](crate::Identifiability::pruned).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// `x0` does not have one entry per parameter of the layout.
    #[error("x0 has {found} entries but the layout has {expected} parameters")]
    WrongLength {
        /// `layout().len()`.
        expected: usize,
        /// `x0.nrows()`.
        found: usize,
    },
    /// An index in `free` is not a parameter of the layout.
    #[error("free parameter index {index} is out of range for a layout of {n_params} parameters")]
    FreeOutOfRange {
        /// The offending index.
        index: usize,
        /// `layout().len()`.
        n_params: usize,
    },
    /// An index appears twice in `free`.
    #[error("parameter {name:?} appears twice in the free set")]
    DuplicateFree {
        /// Name of the repeated parameter.
        name: String,
    },
    /// Fewer residuals than free parameters: the least-squares problem is underdetermined.
    #[error("{n_residuals} residuals cannot determine {n_free} free parameters")]
    TooFewResiduals {
        /// Number of residuals `m`.
        n_residuals: usize,
        /// Number of free parameters.
        n_free: usize,
    },
    /// As many residuals as kept parameters, so the noise cannot be estimated from the residuals.
    #[error(
        "{n_residuals} residuals for {n_free} kept parameters leave no degree of freedom to \
         estimate the noise sigma from the residuals (with as many or fewer residuals than \
         parameters, the data can at most interpolate): measure more configurations than \
         parameters, or give the noise sigma"
    )]
    NoDegreesOfFreedom {
        /// Number of residuals `m`.
        n_residuals: usize,
        /// Number of free parameters.
        n_free: usize,
    },
    /// The sparse back end was requested for a problem without a sparse Jacobian.
    #[error(
        "the sparse back end needs a problem with a sparse jacobian (Problem::sparse_jacobian)"
    )]
    NoSparseJacobian,
    /// faer's sparse QR failed (out of memory, or an invalid pattern).
    #[error("sparse QR failed: {reason}")]
    Sparse {
        /// faer's error, in words.
        reason: String,
    },
    /// The streaming back end was requested for a problem without row blocks.
    #[error("the streaming back end needs a problem with row blocks (Problem::row_blocks)")]
    NoRowBlocks,
    /// The dense back end was requested (or is the only one available) for a Jacobian that
    /// does not fit in the memory budget.
    #[error(
        "the dense jacobian would take {bytes} bytes ({n_residuals} x {n_params}), over the \
         dense back end's limit of {limit} bytes; provide row blocks or a sparse jacobian"
    )]
    DenseTooLarge {
        /// Number of residuals `m`.
        n_residuals: usize,
        /// Number of parameters `n`.
        n_params: usize,
        /// `8·m·n`.
        bytes: u128,
        /// [`DENSE_LIMIT_BYTES`](crate::DENSE_LIMIT_BYTES).
        limit: u128,
    },
    /// The problem could not be evaluated at the initial guess.
    #[error("at the initial guess x0")]
    Eval(#[from] EvalError),
    /// The problem could not be evaluated at the estimate (after a successful fit).
    #[error("at the estimate")]
    EvalAtEstimate(#[source] EvalError),
    /// A residual is NaN or infinite at the initial guess.
    #[error("residual {index} is not finite at x0")]
    NonFiniteResidual {
        /// Row of the residual.
        index: usize,
    },
    /// A Jacobian entry is NaN or infinite.
    #[error("jacobian entry (row {row}, parameter {name:?}) is not finite")]
    NonFiniteJacobian {
        /// Row (residual index).
        row: usize,
        /// Parameter name of the column.
        name: String,
    },
    /// The free columns of the Jacobian are linearly dependent (or one is zero), so the
    /// covariance does not exist.
    #[error("covariance is singular: parameter {name:?} is not determined by the data")]
    Singular {
        /// The parameter whose column made `R` singular.
        name: String,
    },
    /// Pose selection: `n_select` is 0 or more than the candidates.
    #[error("cannot choose {n_select} poses from {n_candidates} candidates")]
    TooFewCandidates {
        /// Number of candidate blocks.
        n_candidates: usize,
        /// Number of poses asked for.
        n_select: usize,
    },
    /// Pose selection: a candidate block is empty, has the wrong number of columns, or holds a
    /// non-finite entry.
    #[error(
        "candidate block {index} is {nrows} × {ncols} (expected ≥ 1 row and {expected_ncols} \
         columns, all finite)"
    )]
    BlockShape {
        /// Index of the block.
        index: usize,
        /// Its rows.
        nrows: usize,
        /// Its columns.
        ncols: usize,
        /// Columns of block 0.
        expected_ncols: usize,
    },
    /// Pose selection: the information matrix of the candidates (or of `n_select` of them) is
    /// singular, so some parameter cannot be determined; prune it first.
    #[error(
        "{n_select} poses cannot determine the {n_params} parameters: the information matrix \
         is singular (prune the parameters the candidates cannot see, or choose more poses)"
    )]
    NotDetermined {
        /// Number of parameters (columns).
        n_params: usize,
        /// Number of poses asked for.
        n_select: usize,
    },
    /// Pose selection: I-optimality needs a finite `n × n` weight matrix.
    #[error("the i-optimal criterion needs a finite {n_params} × {n_params} weight matrix")]
    MissingWeight {
        /// Number of parameters (columns).
        n_params: usize,
    },
    /// A configuration value is out of its domain.
    #[error("{field} = {value} is invalid: it must be finite and {requirement}")]
    InvalidConfig {
        /// Name of the field, e.g. `sigma`.
        field: &'static str,
        /// The value given.
        value: f64,
        /// What it must satisfy besides being finite, e.g. `positive`.
        requirement: &'static str,
    },
}

/// Checks a configuration value: finite and `> 0` (`positive`) or `>= 0`.
pub(crate) fn check_config(field: &'static str, value: f64, positive: bool) -> Result<(), Error> {
    let ok = value.is_finite() && if positive { value > 0.0 } else { value >= 0.0 };
    if ok {
        Ok(())
    } else {
        Err(Error::InvalidConfig {
            field,
            value,
            requirement: if positive { "positive" } else { "non-negative" },
        })
    }
}

/// `LmConfig::factor` must be positive (`+∞` allowed: start with the Gauss–Newton step).
pub(crate) fn check_factor(value: f64) -> Result<(), Error> {
    if value > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidConfig {
            field: "factor",
            value,
            requirement: "positive",
        })
    }
}

/// `x0` must have one entry per parameter of `layout` ([`Error::WrongLength`] otherwise).
pub(crate) fn check_x0_length(
    x0: faer::ColRef<'_, f64>,
    layout: &ParamLayout,
) -> Result<(), Error> {
    if x0.nrows() == layout.len() {
        Ok(())
    } else {
        Err(Error::WrongLength {
            expected: layout.len(),
            found: x0.nrows(),
        })
    }
}
