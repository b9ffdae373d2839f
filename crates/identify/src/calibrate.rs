//! The identification procedure users run: prune, fit, re-decide at the estimate, covariance.

use faer::{Col, Mat};

use crate::blocks::{Linearisation, RowBlocks, StreamError, error_at_x0, linearise, streaming_fit};
use crate::covariance::{Covariance, covariance, sigma_from_residuals};
use crate::error::{Error, check_config};
use crate::householder;
use crate::lm::{
    FOLD_ROWS, Fit, LmConfig, check_inputs, check_jacobian_finite, levenberg_marquardt,
    levenberg_marquardt_at,
};
use crate::problem::{EvalError, ParamLayout, Problem};
use crate::rank::{Identifiability, PruneReason, Pruned, RankConfigBase, identifiability};
use crate::subset::Subset;

/// Most fits [`identify`] runs while the kept set changes.
pub const MAX_ROUNDS: usize = 3;

/// Smallest noise level used for the rank decision, in residual units, so that exact
/// (synthetic) data still give a finite, purely numerical decision.
pub const SIGMA_FLOOR: f64 = 1e-12;

/// Configuration of [`identify`].
#[derive(Clone, Debug, PartialEq)]
pub struct IdentifyConfig {
    /// The solver's stopping tests.
    pub lm: LmConfig,
    /// Priors and numerical floor of the rank decision (the noise comes from `sigma`).
    pub rank: RankConfigBase,
    /// Standard deviation of one residual, in residual units, when known; `None` estimates it
    /// from the residuals of the fit ([`sigma_from_residuals`]).
    pub sigma: Option<f64>,
    /// Which linear-algebra back end evaluates and factorises the Jacobian.
    pub backend: Backend,
    /// Most fits to run while the decision at the estimate changes the kept set (at least 1;
    /// default [`MAX_ROUNDS`]). `1` decides the pruning once, at `x0`, and fits once: the
    /// decision at the estimate is still taken and reported through
    /// [`Identified::pruning_converged`]. Near-ties between gauge parameters (Baser &
    /// Konukseven's `d0`, `θ0`, `θ1`) can flip the decision between estimates when the data
    /// make every direction significant (10⁶ poses), and each flip costs a refit.
    pub max_rounds: usize,
}

impl Default for IdentifyConfig {
    /// MINPACK tolerances ([`LmConfig::default`]), default priors, `sigma` estimated from the
    /// residuals, [`Backend::Auto`], [`MAX_ROUNDS`] rounds.
    fn default() -> Self {
        Self {
            lm: LmConfig::default(),
            rank: RankConfigBase::default(),
            sigma: None,
            backend: Backend::Auto,
            max_rounds: MAX_ROUNDS,
        }
    }
}

/// The linear-algebra back end of [`identify`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum Backend {
    /// Streaming when the problem has row blocks ([`Problem::row_blocks`]) and its dense
    /// Jacobian would exceed [`STREAMING_AUTO_ENTRIES`] entries; dense otherwise (the default).
    #[default]
    Auto,
    /// The whole `m × n` Jacobian in memory, reduced by Householder QR at each iteration
    /// (Moré's `lmder`).
    Dense,
    /// The Jacobian streamed block by block into its R factor (TSQR): memory independent of
    /// `m`, results equal to the dense path's up to rounding.
    Streaming,
    /// The Jacobian in compressed sparse columns, steps by faer's sparse QR
    /// ([`levenberg_marquardt_sparse`](crate::levenberg_marquardt_sparse)); no pruning (the
    /// layout must be identifiable), covariance of [`SparseJacobian::covariance_of`](crate::SparseJacobian::covariance_of) only.
    Sparse,
}

/// [`Backend::Auto`] chooses the sparse back end when the problem has a sparse Jacobian whose
/// density (nonzeros / `m·n`) is below this, and the dense Jacobian would exceed
/// [`STREAMING_AUTO_ENTRIES`] entries.
pub const SPARSE_AUTO_DENSITY: f64 = 0.05;

/// Above this many Jacobian entries (`m·n`, i.e. 32 MB of `f64`), [`Backend::Auto`] streams
/// when it can: the dense path then spends its time in memory traffic and its memory grows
/// with `m`.
pub const STREAMING_AUTO_ENTRIES: usize = 4_000_000;

/// Largest dense Jacobian the dense back end allocates, in bytes (4 GiB): beyond it
/// [`identify`] returns [`Error::DenseTooLarge`] instead of exhausting the machine's memory.
pub const DENSE_LIMIT_BYTES: u128 = 4 << 30;

/// Where [`Identified::sigma`] comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SigmaSource {
    /// [`IdentifyConfig::sigma`].
    Given,
    /// Estimated from the residuals of the final fit, `√(‖r‖²/(m − n_kept))`.
    Residuals,
}

impl SigmaSource {
    /// `"given"` or `"residuals"`, as reports name the source.
    pub fn name(self) -> &'static str {
        match self {
            SigmaSource::Given => "given",
            SigmaSource::Residuals => "residuals",
        }
    }
}

/// Result of [`identify`].
#[derive(Clone, Debug)]
pub struct Identified {
    /// The final fit over the kept parameters (pruned entries keep their `x0` values).
    pub fit: Fit,
    /// Number of residuals `m` of the problem ([`Problem::n_residuals`]): on the streaming
    /// back end `fit.residuals` is empty, this is not.
    pub n_residuals: usize,
    /// The pruning decision; `identifiability.kept` is the free set of `fit`.
    pub identifiability: Identifiability,
    /// Covariance of the kept parameters at the estimate.
    pub covariance: Covariance,
    /// Residual noise used for the covariance (and the last rank decision), residual units.
    pub sigma: f64,
    /// Whether `sigma` was given or estimated.
    pub sigma_source: SigmaSource,
    /// The problem's layout (for names and units).
    pub layout: ParamLayout,
    /// Number of fits run (1 to [`IdentifyConfig::max_rounds`]).
    pub rounds: usize,
    /// True when the decision at the estimate reproduced the kept set of the fit; false when
    /// [`IdentifyConfig::max_rounds`] fits did not settle it (then `identifiability` is the decision the last
    /// fit used, taken at the previous estimate).
    pub pruning_converged: bool,
    /// The back end that ran the fit (`dense`, `streaming` or `sparse`) and why
    /// ([`IdentifyConfig::backend`], or [`Backend::Auto`]'s rule with the sizes it saw).
    pub backend: BackendChoice,
}

/// Which back end [`identify`] used and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BackendChoice {
    /// `dense`, `streaming` or `sparse`.
    pub name: &'static str,
    /// Why: the configured back end, or the sizes that made [`Backend::Auto`] choose it.
    pub reason: String,
}

impl Identified {
    /// Estimated value of parameter `name` (pruned ones hold their `x0` value), in its unit.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.layout.index_of(name).map(|j| self.fit.x[j])
    }
    /// Standard deviation of parameter `name`, in its unit; `None` if unknown or pruned.
    pub fn std(&self, name: &str) -> Option<f64> {
        self.covariance.std_of(name)
    }
}

/// Identifies the parameters of `p` that the data determine, starting from the nominal `x0`.
///
/// 1. Prune at `x0` ([`identifiability`]) with `σ₀` = `cfg.sigma`, or the RMS of `r(x0)` when
///    `None` (an overestimate: it contains the deviations still to be identified), floored at
///    [`SIGMA_FLOOR`].
/// 2. Fit the kept parameters from `x0` ([`levenberg_marquardt`]).
/// 3. Re-estimate `σ` from the fit residuals (unless given) and re-decide the pruning with the
///    Jacobian at the estimate: identifiability is a property of the estimate, not of the
///    nominal.
/// 4. If the kept set changed, refit with the new set (at most
///    [`IdentifyConfig::max_rounds`] fits), starting
///    from the previous estimate for the kept parameters and from `x0` for the others.
/// 5. Covariance of the kept parameters at the estimate ([`covariance`]).
///
/// Non-convergence of the fit is reported in `fit.termination`, not as an error.
///
/// # Errors
/// - [`Error::InvalidConfig`] for a non-positive `sigma`, a non-positive prior, a negative
///   `rel_tol` or tolerance;
/// - [`Error::WrongLength`], [`Error::Eval`], [`Error::NonFiniteResidual`],
///   [`Error::NonFiniteJacobian`], [`Error::TooFewResiduals`] as for [`levenberg_marquardt`];
/// - [`Error::EvalAtEstimate`] if `J` cannot be evaluated (or is not finite) at an estimate;
/// - [`Error::NoDegreesOfFreedom`] if `sigma` is `None` and `m` equals the number of kept
///   parameters;
/// - [`Error::Singular`] if the kept columns are singular at the estimate (only possible when
///   the last decision was not reproduced, see [`Identified::pruning_converged`]).
pub fn identify(p: &impl Problem, x0: Col<f64>, cfg: &IdentifyConfig) -> Result<Identified, Error> {
    check_identify_config(cfg)?;
    let m = p.n_residuals();
    let n = p.layout().len();
    let entries = m.saturating_mul(n);
    let sparse = match cfg.backend {
        Backend::Sparse => true,
        Backend::Auto => p.sparse_jacobian().is_some_and(|sj| {
            let nnz = sj.pattern().1.len();
            entries > STREAMING_AUTO_ENTRIES && (nnz as f64) < SPARSE_AUTO_DENSITY * entries as f64
        }),
        _ => false,
    };
    let auto = cfg.backend == Backend::Auto;
    let choice = |name: &'static str, why: String| BackendChoice {
        name,
        reason: if auto {
            format!("auto: {why}")
        } else {
            "configured".to_owned()
        },
    };
    if sparse {
        let mut id = identify_sparse(p, x0, cfg)?;
        id.backend = choice(
            "sparse",
            format!(
                "a {m} × {n} Jacobian (more than {STREAMING_AUTO_ENTRIES} entries) with a sparse \
                 pattern below {SPARSE_AUTO_DENSITY} density"
            ),
        );
        return Ok(id);
    }
    let streaming = match cfg.backend {
        Backend::Dense | Backend::Sparse => false,
        Backend::Streaming => true,
        Backend::Auto => p.row_blocks().is_some() && entries > STREAMING_AUTO_ENTRIES,
    };
    if streaming {
        let blocks = p.row_blocks().ok_or(Error::NoRowBlocks)?;
        let mut id = identify_streaming(p, blocks, x0, cfg)?;
        id.backend = choice(
            "streaming",
            format!(
                "a {m} × {n} Jacobian, more than {STREAMING_AUTO_ENTRIES} entries, in row blocks"
            ),
        );
        return Ok(id);
    }
    let bytes = 8 * m as u128 * n as u128;
    if bytes > DENSE_LIMIT_BYTES {
        return Err(Error::DenseTooLarge {
            n_residuals: m,
            n_params: n,
            bytes,
            limit: DENSE_LIMIT_BYTES,
        });
    }
    let mut id = identify_dense(p, x0, cfg)?;
    id.backend = choice(
        "dense",
        format!("a {m} × {n} Jacobian, at most {STREAMING_AUTO_ENTRIES} entries or no row blocks"),
    );
    Ok(id)
}

/// [`identify`] with the parameters `held` held at their values in `x0`: a physical bound
/// (a compliance held at zero, which a fit with it free put below zero) while the others are
/// identified. `held` gives each held parameter's index in `p`'s layout and its standard
/// deviation in the fit that had it free (in its unit; reported as
/// [`Pruned::std_if_kept`]).
///
/// The result is over `p`'s whole layout, as [`identify`]'s: the held parameters keep their
/// `x0` values and are listed among the pruned ones with [`PruneReason::AtBound`]; every
/// other entry is [`identify`]'s of the problem without them ([`Subset`]).
///
/// # Errors
/// As [`identify`]; [`Error::WrongLength`] if `x0` is not of `p`'s layout length.
///
/// # Panics
/// If a held index is out of `p`'s layout.
#[track_caller]
pub fn identify_held(
    p: &(impl Problem + Sync),
    x0: Col<f64>,
    cfg: &IdentifyConfig,
    held: &[(usize, f64)],
) -> Result<Identified, Error> {
    let layout = p.layout().clone();
    let n = layout.len();
    crate::error::check_x0_length(x0.as_ref(), &layout)?;
    let is_held = |i: usize| held.iter().any(|&(h, _)| h == i);
    for &(h, _) in held {
        assert!(
            h < n,
            "held parameter {h} is out of range for {n} parameters"
        );
    }
    let free: Vec<usize> = (0..n).filter(|&i| !is_held(i)).collect();
    let subset = Subset::new(p, free.clone(), x0);
    let inner = identify(&subset, subset.initial_free(), cfg)?;
    let x = subset.full_x(inner.fit.x.as_ref());
    let mut pruned: Vec<Pruned> = (inner.identifiability.pruned.into_iter())
        .map(|q| Pruned {
            index: free[q.index],
            ..q
        })
        .collect();
    pruned.extend(held.iter().map(|&(index, std)| Pruned {
        index,
        name: layout.name(index).to_owned(),
        reason: PruneReason::AtBound,
        std_if_kept: std,
    }));
    pruned.sort_by_key(|q| q.index);
    let mut pivot_order: Vec<usize> = (inner.identifiability.pivot_order.iter())
        .map(|&k| free[k])
        .collect();
    let mut r_diag = inner.identifiability.r_diag;
    for &(index, _) in held {
        pivot_order.push(index);
        r_diag.push(0.0);
    }
    let mut covariance = inner.covariance;
    covariance.free = covariance.free.iter().map(|&k| free[k]).collect();
    Ok(Identified {
        fit: Fit { x, ..inner.fit },
        identifiability: Identifiability {
            kept: (inner.identifiability.kept.iter())
                .map(|&k| free[k])
                .collect(),
            pruned,
            r_diag,
            pivot_order,
        },
        covariance,
        layout,
        ..inner
    })
}

fn check_identify_config(cfg: &IdentifyConfig) -> Result<(), Error> {
    if cfg.max_rounds == 0 {
        return Err(Error::InvalidConfig {
            field: "max_rounds",
            value: 0.0,
            requirement: "at least 1",
        });
    }
    if let Some(sigma) = cfg.sigma {
        check_config("sigma", sigma, true)?;
    }
    check_config("prior_m", cfg.rank.prior_m, true)?;
    check_config("prior_rad", cfg.rank.prior_rad, true)?;
    check_config("prior_dimensionless", cfg.rank.prior_dimensionless, true)?;
    check_config("prior_rad_per_n_m", cfg.rank.prior_rad_per_n_m, true)?;
    check_config("prior_rad_per_m", cfg.rank.prior_rad_per_m, true)?;
    check_config("rel_tol", cfg.rank.rel_tol, false)
}

/// [`identify`] on the streaming back end: every Jacobian is reduced to the R factor of
/// `[J r]` (see [`levenberg_marquardt_streaming`](crate::levenberg_marquardt_streaming)); the rank decision and the covariance are
/// taken on `R`, which has the same Gram matrix as `J`.
fn identify_streaming(
    p: &impl Problem,
    blocks: &dyn RowBlocks,
    x0: Col<f64>,
    cfg: &IdentifyConfig,
) -> Result<Identified, Error> {
    let layout = p.layout().clone();
    let n = layout.len();
    crate::error::check_x0_length(x0.as_ref(), &layout)?;
    check_config("ftol", cfg.lm.ftol, false)?;
    check_config("xtol", cfg.lm.xtol, false)?;
    check_config("gtol", cfg.lm.gtol, false)?;
    crate::error::check_factor(cfg.lm.factor)?;
    let m = p.n_residuals();
    let mut lin = linearise(blocks, x0.as_ref(), n).map_err(|e| error_at_x0(e, &layout))?;
    let (mut sigma, sigma_source) = initial_sigma(cfg.sigma, lin.r_norm_sq, m);
    finite_sigma(sigma, true)?;
    let candidates: Vec<usize> = (0..n).collect();
    let decide = |lin: &Linearisation, sigma: f64| {
        identifiability(
            lin.r_aug.as_ref().submatrix(0, 0, n, n),
            &layout,
            &candidates,
            &cfg.rank.with_sigma(sigma.max(SIGMA_FLOOR)),
        )
    };
    let mut ident = decide(&lin, sigma);
    let mut rounds = 0;
    let mut x_start = x0.clone();
    let (fit, pruning_converged) = loop {
        rounds += 1;
        if m < ident.kept.len() {
            return Err(Error::TooFewResiduals {
                n_residuals: m,
                n_free: ident.kept.len(),
            });
        }
        let (fit, last, current) =
            streaming_fit(blocks, n, x_start.clone(), &ident.kept, &cfg.lm, lin);
        if sigma_source == SigmaSource::Residuals {
            let k = ident.kept.len();
            if m <= k {
                return Err(Error::NoDegreesOfFreedom {
                    n_residuals: m,
                    n_free: k,
                });
            }
            sigma = finite_sigma((2.0 * fit.cost / (m - k) as f64).sqrt(), false)?;
        }
        lin = if current {
            last
        } else {
            linearise(blocks, fit.x.as_ref(), n).map_err(|e| match e {
                StreamError::Eval(e) => Error::EvalAtEstimate(e),
                StreamError::NonFinite { .. } => Error::EvalAtEstimate(EvalError {
                    reason: "the jacobian is not finite".to_owned(),
                }),
            })?
        };
        let next = decide(&lin, sigma);
        match next_round(&ident.kept, &next.kept, rounds, cfg.max_rounds, &x0, &fit.x) {
            NextRound::Settled => {
                ident = next;
                break (fit, true);
            }
            NextRound::Spent => break (fit, false),
            NextRound::Again(x) => x_start = x,
        }
        // The next fit starts elsewhere: linearise there.
        lin = linearise(blocks, x_start.as_ref(), n).map_err(|e| error_at_x0(e, &layout))?;
        ident = next;
    };
    let covariance = covariance(
        lin.r_aug.as_ref().submatrix(0, 0, n, n),
        &layout,
        &ident.kept,
        sigma,
    )?;
    Ok(Identified {
        n_residuals: p.n_residuals(),
        fit,
        identifiability: ident,
        covariance,
        sigma,
        sigma_source,
        layout,
        rounds,
        pruning_converged,
        backend: BackendChoice {
            name: "dense",
            reason: String::new(),
        },
    })
}

/// [`identify`] on the sparse back end: one fit of all parameters, covariance of the ones the
/// problem names.
fn identify_sparse(
    p: &impl Problem,
    x0: Col<f64>,
    cfg: &IdentifyConfig,
) -> Result<Identified, Error> {
    let sj = p.sparse_jacobian().ok_or(Error::NoSparseJacobian)?;
    let which = sj.covariance_of();
    let sf = crate::sparse::levenberg_marquardt_sparse(p, x0, &cfg.lm, &which)?;
    let layout = p.layout().clone();
    let n = layout.len();
    let (sigma, sigma_source, covariance) = match cfg.sigma {
        Some(s) => {
            let mut cov = sf.covariance;
            let scale = if sf.sigma > 0.0 {
                (s / sf.sigma).powi(2)
            } else {
                0.0
            };
            for a in 0..cov.matrix.nrows() {
                for b in 0..cov.matrix.ncols() {
                    cov.matrix[(a, b)] *= scale;
                }
            }
            (s, SigmaSource::Given, cov)
        }
        None => (sf.sigma, SigmaSource::Residuals, sf.covariance),
    };
    Ok(Identified {
        n_residuals: p.n_residuals(),
        fit: sf.fit,
        identifiability: Identifiability {
            kept: (0..n).collect(),
            pruned: Vec::new(),
            r_diag: Vec::new(),
            pivot_order: (0..n).collect(),
        },
        covariance,
        sigma,
        sigma_source,
        layout,
        rounds: 1,
        pruning_converged: true,
        backend: BackendChoice {
            name: "sparse",
            reason: String::new(),
        },
    })
}

/// [`identify`] on the dense back end (`cfg` already checked by [`identify`]).
fn identify_dense(
    p: &impl Problem,
    x0: Col<f64>,
    cfg: &IdentifyConfig,
) -> Result<Identified, Error> {
    let layout = p.layout().clone();
    let n = layout.len();
    crate::error::check_x0_length(x0.as_ref(), &layout)?;
    let m = p.n_residuals();
    let mut r0 = Col::<f64>::zeros(m);
    p.residuals(x0.as_ref(), r0.as_mut())?;
    if let Some(index) = (0..m).find(|&i| !r0[i].is_finite()) {
        return Err(Error::NonFiniteResidual { index });
    }
    let mut jac = Mat::<f64>::zeros(m, n);
    p.jacobian(x0.as_ref(), jac.as_mut())?;
    check_jacobian_finite(jac.as_ref(), &layout)?;

    let (mut sigma, sigma_source) = initial_sigma(cfg.sigma, r0.squared_norm_l2(), m);
    finite_sigma(sigma, true)?;
    let candidates: Vec<usize> = (0..n).collect();
    // On the R factor of J (`n × n`, the same Gram matrix), as the streaming back end decides:
    // the decision's own QR is then of n rows, not m. Where the unscaled fold is not finite
    // (a haptic log of two poses, each a hundred times, gave such an R from a finite J), on J
    // itself, whose columns the decision scales to unit norm first.
    let decide = |jac: &Mat<f64>, sigma: f64| {
        let r = dense_r_factor(jac.as_ref());
        identifiability(
            if r.is_all_finite() {
                r.as_ref()
            } else {
                jac.as_ref()
            },
            &layout,
            &candidates,
            &cfg.rank.with_sigma(sigma.max(SIGMA_FLOOR)),
        )
    };
    let mut ident = decide(&jac, sigma);
    let mut rounds = 0;
    // Later rounds start from the previous estimate (warm start): the kept parameters are already
    // near their optimum, and newly pruned ones return to their x0 values.
    let mut x_start = x0.clone();
    // The first fit starts where r and J were just evaluated: hand them over.
    let mut at_x0 = Some((r0, jac.clone()));
    let (fit, pruning_converged) = loop {
        rounds += 1;
        let fit = match at_x0.take() {
            Some((r0, jac0)) => {
                check_inputs(p, x_start.as_ref(), &ident.kept, &cfg.lm)?;
                levenberg_marquardt_at(p, x_start.clone(), &ident.kept, &cfg.lm, r0, jac0)
            }
            None => levenberg_marquardt(p, x_start.clone(), &ident.kept, &cfg.lm)?,
        };
        if sigma_source == SigmaSource::Residuals {
            sigma = sigma_from_residuals(fit.residuals.as_ref(), ident.kept.len()).ok_or(
                Error::NoDegreesOfFreedom {
                    n_residuals: m,
                    n_free: ident.kept.len(),
                },
            )?;
            sigma = finite_sigma(sigma, false)?;
        }
        p.jacobian(fit.x.as_ref(), jac.as_mut())
            .map_err(Error::EvalAtEstimate)?;
        if !jac.is_all_finite() {
            return Err(Error::EvalAtEstimate(crate::problem::EvalError {
                reason: "the jacobian is not finite".to_owned(),
            }));
        }
        let next = decide(&jac, sigma);
        match next_round(&ident.kept, &next.kept, rounds, cfg.max_rounds, &x0, &fit.x) {
            NextRound::Settled => {
                ident = next;
                break (fit, true);
            }
            NextRound::Spent => break (fit, false),
            NextRound::Again(x) => x_start = x,
        }
        ident = next;
    };
    let covariance = covariance(jac.as_ref(), &layout, &ident.kept, sigma)?;
    Ok(Identified {
        n_residuals: p.n_residuals(),
        fit,
        identifiability: ident,
        covariance,
        sigma,
        sigma_source,
        layout,
        rounds,
        pruning_converged,
        backend: BackendChoice {
            name: "dense",
            reason: String::new(),
        },
    })
}

/// The R factor (`n × n`, upper triangular) of the dense `m × n` Jacobian `jac`: `RᵀR =
/// JᵀJ`, folded block of rows by block of rows ([`householder::fold_rows`]) as the dense
/// Levenberg–Marquardt folds `[J_f r]`, each block copied first (`jac` is left as it is).
/// Column norms, distances to spans and the least-squares coefficients between columns are
/// those of `jac` up to rounding, so the rank decision ([`identifiability`]) and its reasons
/// are the same on `R` (the streaming back end decides on its `R` so).
pub(crate) fn dense_r_factor(jac: faer::MatRef<'_, f64>) -> Mat<f64> {
    let (m, n) = (jac.nrows(), jac.ncols());
    let mut tri = vec![0.0; n * n];
    let mut block = vec![0.0; FOLD_ROWS.min(m) * n];
    for start in (0..m).step_by(FOLD_ROWS) {
        let len = FOLD_ROWS.min(m - start);
        for j in 0..n {
            let col = jac.col(j).subrows(start, len);
            for (i, b) in block[j * len..(j + 1) * len].iter_mut().enumerate() {
                *b = col[i];
            }
        }
        householder::fold_rows(&mut tri, n, &mut block, len, len);
    }
    Mat::from_fn(n, n, |i, j| tri[j * n + i])
}

/// `sigma` if it is finite and not negative, as the rank decision needs it; otherwise an
/// evaluation error (at `x0` or at the estimate). Residuals that are each finite can still
/// overflow their sum of squares (a measured length of 1e200 m), which makes the RMS infinite.
fn finite_sigma(sigma: f64, at_x0: bool) -> Result<f64, Error> {
    if sigma.is_finite() && sigma >= 0.0 {
        return Ok(sigma);
    }
    let e = EvalError {
        reason: format!(
            "the residuals' RMS is {sigma}: a measurement or a nominal length is far out of \
             range (the sum of squared residuals overflows)"
        ),
    };
    Err(if at_x0 {
        Error::Eval(e)
    } else {
        Error::EvalAtEstimate(e)
    })
}

/// Start of the noise level: `given`, or the RMS of the `m` residuals at `x0`
/// (`√(‖r‖²/m)`, in the residuals' units; 0 without residuals).
fn initial_sigma(given: Option<f64>, r_norm_sq: f64, m: usize) -> (f64, SigmaSource) {
    match given {
        Some(s) => (s, SigmaSource::Given),
        None => {
            let rms = if m > 0 {
                (r_norm_sq / m as f64).sqrt()
            } else {
                0.0
            };
            (rms, SigmaSource::Residuals)
        }
    }
}

/// What one pruning round of [`identify`] leads to.
enum NextRound {
    /// The decision at the estimate keeps the same parameters: done, converged.
    Settled,
    /// It differs, but `max_rounds` are spent: done, not converged.
    Spent,
    /// Refit from this start: `x0` with the newly kept parameters at their estimates (warm
    /// start; newly pruned ones return to their `x0` values).
    Again(Col<f64>),
}

/// Compares the kept set a round fitted with (`kept`) to the decision at its estimate `x`
/// (`next_kept`), after `rounds` of at most `max_rounds`.
fn next_round(
    kept: &[usize],
    next_kept: &[usize],
    rounds: usize,
    max_rounds: usize,
    x0: &Col<f64>,
    x: &Col<f64>,
) -> NextRound {
    if next_kept == kept {
        return NextRound::Settled;
    }
    if rounds >= max_rounds {
        return NextRound::Spent;
    }
    let mut start = x0.clone();
    for &i in next_kept {
        start[i] = x[i];
    }
    NextRound::Again(start)
}

#[cfg(test)]
mod tests {
    use faer::Mat;

    use super::dense_r_factor;
    use crate::problem::{ParamLayout, Unit};
    use crate::rank::{PruneReason, RankConfigBase, identifiability};

    #[test]
    fn the_rank_decision_on_the_r_factor_is_the_decision_on_the_jacobian() {
        // 700 rows (three row blocks of the fold) of 8 columns: p0..p2 generic, p3 = p0 + 2·p1
        // exactly, p4 a copy of p2, p5 zero, p6 generic but tiny (σ/‖p6‖ above its prior),
        // p7 = p0 − p2 plus a part orthogonal at 10⁻⁹ of it (dependent at working tolerance
        // but not exactly).
        let m = 700;
        let g = |i: usize, j: usize| ((i * 31 + j * j * 17 + i * j * 7) as f64 * 0.37).sin();
        let jac = Mat::from_fn(m, 8, |i, j| match j {
            0..=2 => g(i, j),
            3 => g(i, 0) + 2.0 * g(i, 1),
            4 => g(i, 2),
            5 => 0.0,
            6 => 1e-9 * g(i, 6),
            _ => g(i, 0) - g(i, 2) + 1e-9 * g(i, 7),
        });
        let layout = ParamLayout::numbered("p", 8, Unit::Meter);
        let candidates: Vec<usize> = (0..8).collect();
        let cfg = RankConfigBase::default().with_sigma(1e-4);
        let on_j = identifiability(jac.as_ref(), &layout, &candidates, &cfg);
        let r = dense_r_factor(jac.as_ref());
        assert_eq!(r.nrows(), 8);
        // Upper triangular with the Gram matrix of J, to rounding.
        let gram = jac.transpose() * &jac;
        let gram_r = r.transpose() * &r;
        for a in 0..8 {
            for b in 0..8 {
                if a > b {
                    assert_eq!(r[(a, b)], 0.0);
                }
                let scale = (gram[(a, a)] * gram[(b, b)]).sqrt().max(f64::MIN_POSITIVE);
                assert!((gram[(a, b)] - gram_r[(a, b)]).abs() <= 1e-13 * scale);
            }
        }
        let on_r = identifiability(r.as_ref(), &layout, &candidates, &cfg);
        assert_eq!(on_j.kept, [0, 1, 2]);
        assert_eq!(on_r.kept, on_j.kept);
        assert_eq!(on_r.pivot_order, on_j.pivot_order);
        assert_eq!(on_r.pruned_names(), on_j.pruned_names());
        for (a, b) in on_r.pruned.iter().zip(&on_j.pruned) {
            match (&a.reason, &b.reason) {
                (PruneReason::Dependent { on: x }, PruneReason::Dependent { on: y }) => {
                    assert_eq!(x.len(), y.len(), "{}", a.name);
                    for ((nx, cx), (ny, cy)) in x.iter().zip(y) {
                        assert_eq!(nx, ny);
                        assert!((cx - cy).abs() <= 1e-9 * cy.abs().max(1.0), "{}", a.name);
                    }
                }
                (x, y) => assert_eq!(x, y, "{}", a.name),
            }
            // σ if kept: of an exactly dependent column, rounding over a distance of
            // 10⁻¹⁶ (above 10⁸ m, or infinite) in both; else the same to 10⁻⁵ (p7's distance
            // of 10⁻⁹ keeps about seven digits of its cancellation in either factorisation).
            if b.std_if_kept < 1e8 {
                let rel = (a.std_if_kept - b.std_if_kept).abs() / b.std_if_kept;
                assert!(
                    rel < 1e-5,
                    "{}: {} vs {}",
                    a.name,
                    a.std_if_kept,
                    b.std_if_kept
                );
            } else {
                assert!(a.std_if_kept >= 1e8, "{}: {}", a.name, a.std_if_kept);
            }
        }
    }
}
