//! Pose selection (experiment design): from candidate poses, each contributing a block of
//! Jacobian rows, choose `N` that maximise an observability criterion.
//!
//! Generic: a candidate is any block of rows of a scaled identification Jacobian (one row per
//! distance, three per position, …); nothing here knows what a pose is.
//!
//! Algorithm: a greedy start (add, one at a time, the candidate that most increases the
//! regularised log-determinant of the information matrix `M = Σ BᵢᵀBᵢ`), then DETMAX-style
//! exchanges with excursions of length one (T. J. Mitchell, "An algorithm for the construction of
//! D-optimal experimental designs", *Technometrics* 16(2), 1974; V. V. Fedorov, *Theory of
//! Optimal Experiments*, 1972, ch. 3): add the candidate that most improves the criterion, then
//! remove the selected pose whose loss hurts least; stop when the pose removed is the one just
//! added (no exchange improves the design) or after `max_exchanges`. The determinant updates use
//! `det(M + BᵀB) = det M · det(I + B M⁻¹ Bᵀ)` (the matrix determinant lemma), so one D-optimal
//! step costs `O(C·r·n²)` for `C` candidates of `r` rows and `n` parameters. For O3/O4/O5, which
//! need eigenvalues, additions are short-listed by their D-optimal gain (the best
//! [`DesignConfig::shortlist`]) and then scored exactly; I-optimality uses the
//! Sherman–Morrison–Woodbury update of `trace(W·M⁻¹)`. When an excursion no longer improves
//! the design, the best single swap of a chosen pose for a candidate (Fedorov's exchange) is
//! tried before stopping, so the result is swap-optimal: a local optimum, not necessarily the
//! global one (the unit tests show both cases on small problems).
//!
//! [`i_optimal_weights`] solves the continuous (approximate) I-optimal design problem on the
//! candidates by the multiplicative algorithm and returns the equivalence-theorem certificate
//! ([`ContinuousDesign`]): a lower bound of the criterion of every design, exact designs of `N`
//! poses included (divided by `N`).

use faer::{Mat, MatRef, Side};

use crate::error::Error;
use crate::observability::{Observability, observability_from_singular_values};

/// What [`select_poses`] maximises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Criterion {
    /// D-optimality, `log det(JᵀJ)`; for a fixed number of poses the same ranking as O1
    /// (Borm & Menq), which is `det(JᵀJ)^(1/2n)/√L`.
    DOptimal,
    /// O1 (Borm & Menq): identical selections to [`Criterion::DOptimal`]; kept as a name.
    O1,
    /// O3 (Nahvi, Hollerbach & Hayward): the minimum singular value.
    O3,
    /// O4 (Nahvi & Hollerbach): the noise amplification index `σ_min²/σ_max`.
    O4,
    /// O5 (Sun & Hollerbach): `1/Σ(1/σ_i)`.
    O5,
    /// I-optimality (Fedorov 1972, ch. 2; V-optimality in Atkinson, Donev & Tobias, *Optimum
    /// Experimental Designs*, 2007, §10.6): minimise `trace(W·(JᵀJ)⁻¹)`, the average variance of
    /// the predictions `g·δx` whose second moment is `W = mean(gᵀg)`
    /// ([`DesignConfig::weight`]), e.g. the end-point position over the workspace. The value
    /// reported is `−trace(W·(JᵀJ)⁻¹)`.
    IOptimal,
}

impl std::fmt::Display for Criterion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Criterion::DOptimal => "d-optimal",
            Criterion::O1 => "o1",
            Criterion::O3 => "o3",
            Criterion::O4 => "o4",
            Criterion::O5 => "o5",
            Criterion::IOptimal => "i-optimal",
        })
    }
}

impl std::str::FromStr for Criterion {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "d-optimal" => Ok(Criterion::DOptimal),
            "o1" => Ok(Criterion::O1),
            "o3" => Ok(Criterion::O3),
            "o4" => Ok(Criterion::O4),
            "o5" => Ok(Criterion::O5),
            "i-optimal" => Ok(Criterion::IOptimal),
            other => Err(format!(
                "unknown criterion {other:?}: expected d-optimal, o1, o3, o4, o5 or i-optimal"
            )),
        }
    }
}

/// Configuration of [`select_poses`].
#[derive(Clone, Debug, PartialEq)]
pub struct DesignConfig {
    /// The criterion to maximise.
    pub criterion: Criterion,
    /// Most exchange steps after the greedy start (each is one addition and one removal).
    pub max_exchanges: usize,
    /// For O3/O4/O5: how many of the best additions by D-optimal gain are scored exactly.
    pub shortlist: usize,
    /// For [`Criterion::IOptimal`]: the `n × n` symmetric positive semi-definite weight `W`
    /// (second moment of the prediction gradients, in the units of the block columns).
    pub weight: Option<Mat<f64>>,
    /// The information already in hand, `M₀` (`n × n`, symmetric positive semi-definite, the
    /// units of `BᵀB`): the rows measured before, plus any prior on the parameters. Every
    /// criterion is then of `M₀ + Σ BᵢᵀBᵢ` over the chosen blocks, the sequential design of
    /// Atkinson, Donev & Tobias (*Optimum Experimental Designs*, 2007, §11.5); with a positive
    /// definite `M₀`, fewer blocks than parameters can be chosen. `None`: nothing measured.
    pub prior: Option<Mat<f64>>,
}

impl DesignConfig {
    /// `criterion` with `max_exchanges = 1000` (the exchange converges in far fewer steps in
    /// practice; the cap only bounds the run time) and `shortlist = 20`.
    pub fn new(criterion: Criterion) -> Self {
        Self {
            criterion,
            max_exchanges: 1000,
            shortlist: 20,
            weight: None,
            prior: None,
        }
    }
}

/// Result of [`select_poses`].
#[derive(Clone, Debug, PartialEq)]
pub struct Design {
    /// Indices of the chosen candidates, ascending (length `n_select`).
    pub selected: Vec<usize>,
    /// Value of the criterion for the chosen set (`log det` for D-optimal, else the index).
    pub value: f64,
    /// `log det(JᵀJ)` of the chosen set (natural log; with [`DesignConfig::prior`], of
    /// `M₀ + JᵀJ`, as every figure here).
    pub log_det: f64,
    /// O1–O5 of the chosen set (`n_poses = n_select`).
    pub observability: Observability,
    /// Exchange steps that improved the design.
    pub n_exchanges: usize,
    /// True when the exchange stopped because no exchange improved the design; false when it hit
    /// `max_exchanges`.
    pub converged: bool,
}

/// Scores of a candidate set: the criterion of [`Criterion`] for the information matrix `m`
/// (`n × n`, `JᵀJ`), `-∞` when `m` is singular.
fn score(cfg: &DesignConfig, m: &Mat<f64>, n_poses: usize) -> f64 {
    let criterion = cfg.criterion;
    match criterion {
        Criterion::DOptimal | Criterion::O1 => log_det(m).unwrap_or(f64::NEG_INFINITY),
        Criterion::IOptimal => {
            let (Some(w), Some(minv)) = (cfg.weight.as_ref(), spd_inverse(m)) else {
                return f64::NEG_INFINITY;
            };
            -trace_product(w, &minv)
        }
        Criterion::O3 | Criterion::O4 | Criterion::O5 => {
            let Some(o) = observability_of_information(m, n_poses) else {
                return f64::NEG_INFINITY;
            };
            match criterion {
                Criterion::O3 => o.o3,
                Criterion::O4 => o.o4,
                _ => o.o5,
            }
        }
    }
}

/// O1–O5 from the information matrix `JᵀJ` (its eigenvalues are the squared singular values).
fn observability_of_information(m: &Mat<f64>, n_poses: usize) -> Option<Observability> {
    let ev = m.self_adjoint_eigenvalues(Side::Lower).ok()?;
    let sv: Vec<f64> = ev.iter().map(|l| l.max(0.0).sqrt()).collect();
    Some(observability_from_singular_values(&sv, m.nrows(), n_poses))
}

/// Cholesky factor `L` (lower, `LLᵀ = m`) or `None` if `m` is not numerically positive
/// definite (a pivot below `1e-13·max diag`).
fn cholesky(m: &Mat<f64>) -> Option<Mat<f64>> {
    let n = m.nrows();
    let max_diag = (0..n).map(|i| m[(i, i)]).fold(0.0_f64, f64::max);
    let mut l = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        let mut d = m[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if d.is_nan() || d <= 1e-13 * max_diag {
            return None;
        }
        let d = d.sqrt();
        l[(j, j)] = d;
        for i in j + 1..n {
            let mut s = m[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / d;
        }
    }
    Some(l)
}

/// `m⁻¹` of a symmetric positive definite `m`, `None` if it is not.
fn spd_inverse(m: &Mat<f64>) -> Option<Mat<f64>> {
    let l = cholesky(m)?;
    let mut x = Mat::<f64>::identity(m.nrows(), m.nrows());
    l.as_ref().solve_lower_triangular_in_place(x.as_mut());
    Some(x.transpose() * &x)
}

/// `trace(a·b)` for symmetric `a`, `b`.
fn trace_product(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    let n = a.nrows();
    (0..n)
        .map(|i| (0..n).map(|j| a[(i, j)] * b[(j, i)]).sum::<f64>())
        .sum()
}

/// Change of `trace(W·M⁻¹)` when block `b` is added (`sign = 1`) or removed (`sign = −1`):
/// `−sign·trace(S⁻¹·UᵀWU)` with `U = M⁻¹Bᵀ`, `S = I + sign·B·U` (Sherman–Morrison–Woodbury);
/// `None` when the removal makes `M` singular.
fn i_change(minv: &Mat<f64>, w: &Mat<f64>, b: MatRef<'_, f64>, sign: f64) -> Option<f64> {
    let u = minv * b.transpose();
    let s = Mat::<f64>::identity(b.nrows(), b.nrows()) + (b * &u) * sign;
    let s_inv = spd_inverse(&s)?;
    let k = u.transpose() * w * &u;
    Some(-sign * trace_product(&s_inv, &k))
}

fn log_det(m: &Mat<f64>) -> Option<f64> {
    let l = cholesky(m)?;
    Some(2.0 * (0..m.nrows()).map(|i| l[(i, i)].ln()).sum::<f64>())
}

/// `W = L⁻¹·Bᵀ` (`n × r`) for a block `B` (`r × n`), so that `B M⁻¹ Bᵀ = WᵀW`.
fn whiten(l: &Mat<f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    let mut w = b.transpose().to_owned();
    l.as_ref().solve_lower_triangular_in_place(w.as_mut());
    w
}

/// `log det(I ± WᵀW)`; `None` when `I − WᵀW` is not positive definite.
fn log_det_update(w: &Mat<f64>, sign: f64) -> Option<f64> {
    let r = w.ncols();
    let g = Mat::from_fn(r, r, |i, j| {
        let dot: f64 = (0..w.nrows()).map(|k| w[(k, i)] * w[(k, j)]).sum();
        f64::from(u8::from(i == j)) + sign * dot
    });
    log_det(&g)
}

fn add_info(m: &mut Mat<f64>, b: MatRef<'_, f64>, sign: f64) {
    let n = m.nrows();
    for i in 0..n {
        for j in 0..n {
            let dot: f64 = (0..b.nrows()).map(|k| b[(k, i)] * b[(k, j)]).sum();
            m[(i, j)] += sign * dot;
        }
    }
}

/// The checks of [`select_poses`]: `n_select` of the candidates, blocks of one width `n`, a
/// weight for I-optimality, a prior of that width; and the candidates together must
/// determine the parameters. Returns `n` and the prior information (zeros without one).
///
/// # Errors
/// [`Error::TooFewCandidates`], the errors of the blocks' check, [`Error::MissingWeight`],
/// [`Error::NotDetermined`].
///
/// # Panics
/// If the prior is not `n × n` and finite.
#[track_caller]
fn checked_information(
    blocks: &[Mat<f64>],
    n_select: usize,
    cfg: &DesignConfig,
) -> Result<(usize, Mat<f64>), Error> {
    let n_candidates = blocks.len();
    if n_select == 0 || n_select > n_candidates {
        return Err(Error::TooFewCandidates {
            n_candidates,
            n_select,
        });
    }
    let n = check_blocks(blocks)?;
    if cfg.criterion == Criterion::IOptimal
        && cfg
            .weight
            .as_ref()
            .is_none_or(|w| w.nrows() != n || w.ncols() != n || !w.is_all_finite())
    {
        return Err(Error::MissingWeight { n_params: n });
    }
    let prior = match &cfg.prior {
        Some(p) => {
            assert!(
                p.nrows() == n && p.ncols() == n && p.is_all_finite(),
                "the prior information is {} × {} (finite: {}), the blocks have {n} columns",
                p.nrows(),
                p.ncols(),
                p.is_all_finite()
            );
            p.clone()
        }
        None => Mat::<f64>::zeros(n, n),
    };
    let mut total = prior.clone();
    for b in blocks {
        add_info(&mut total, b.as_ref(), 1.0);
    }
    if cholesky(&total).is_none() {
        return Err(Error::NotDetermined {
            n_params: n,
            n_select,
        });
    }
    Ok((n, prior))
}

/// The greedy start of [`select_poses`]: `n_select` candidates added one by one, each the
/// best D-optimal addition (`in_set` per candidate).
///
/// # Errors
/// [`Error::NotDetermined`] when the information stops being positive definite.
fn greedy_start(
    blocks: &[Mat<f64>],
    prior: &Mat<f64>,
    n_select: usize,
) -> Result<Vec<bool>, Error> {
    let n_candidates = blocks.len();
    let n = prior.nrows();
    let mut total = prior.clone();
    for b in blocks {
        add_info(&mut total, b.as_ref(), 1.0);
    }
    // Greedy start on M = δI + Σ BᵢᵀBᵢ; δ is 1e-8 of the average diagonal of one candidate's
    // information, small enough not to steer the choice once n rows are in.
    let mean_diag = (0..n).map(|i| total[(i, i)]).sum::<f64>() / (n * n_candidates) as f64;
    let delta = 1e-8 * mean_diag.max(f64::MIN_POSITIVE);
    let mut m = Mat::<f64>::from_fn(n, n, |i, j| {
        prior[(i, j)] + if i == j { delta } else { 0.0 }
    });
    let mut in_set = vec![false; n_candidates];
    for _ in 0..n_select {
        let l = cholesky(&m).ok_or(Error::NotDetermined {
            n_params: n,
            n_select,
        })?;
        let best = best_addition(blocks, &in_set, &l);
        let Some((c, _)) = best else {
            break;
        };
        in_set[c] = true;
        add_info(&mut m, blocks[c].as_ref(), 1.0);
    }
    Ok(in_set)
}

/// The exchange's addition: the candidate outside the set `in_set` with the best criterion
/// for S ∪ {j}, given the information `m` of S and its Cholesky factor `l`. `Err(())` when
/// the I-optimal criterion cannot be scored (no weight, or `m` not invertible): the search
/// stops there, unconverged.
fn best_added(
    blocks: &[Mat<f64>],
    in_set: &[bool],
    cfg: &DesignConfig,
    m: &Mat<f64>,
    l: &Mat<f64>,
    n_select: usize,
) -> Result<Option<usize>, ()> {
    let n_candidates = blocks.len();
    Ok(match cfg.criterion {
        Criterion::DOptimal | Criterion::O1 => best_addition(blocks, in_set, l).map(|b| b.0),
        Criterion::IOptimal => {
            let (Some(w), Some(minv)) = (cfg.weight.as_ref(), spd_inverse(m)) else {
                return Err(());
            };
            (0..n_candidates)
                .filter(|&c| !in_set[c])
                .filter_map(|c| i_change(&minv, w, blocks[c].as_ref(), 1.0).map(|d| (c, d)))
                .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
                .map(|b| b.0)
        }
        _ => {
            let mut gains = additions(blocks, in_set, l);
            gains.sort_by(|a, b| b.1.total_cmp(&a.1));
            gains
                .iter()
                .take(cfg.shortlist.max(1))
                .map(|&(c, _)| {
                    let mut trial = m.clone();
                    add_info(&mut trial, blocks[c].as_ref(), 1.0);
                    (c, score(cfg, &trial, n_select + 1))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|b| b.0)
        }
    })
}

/// Chooses `n_select` of the candidate blocks that maximise `cfg.criterion` (greedy start and
/// DETMAX-like exchange, see the module docs).
///
/// `blocks[c]` is candidate `c`'s rows of the scaled Jacobian (`r_c × n`, any `r_c ≥ 1`, the same
/// `n` columns for all; residuals divided by their σ, columns scaled by their priors, e.g.
/// [`scale_by_priors`](crate::scale_by_priors)); only parameters the candidates determine should
/// be columns (prune first with [`identifiability`](crate::identifiability)). A candidate is used
/// at most once. Returns the chosen indices and their observability.
///
/// # Errors
/// - [`Error::TooFewCandidates`] if `n_select` exceeds the number of candidates or is 0;
/// - [`Error::BlockShape`] if a block has no row, another column count than block 0, or a
///   non-finite entry;
/// - [`Error::MissingWeight`] for [`Criterion::IOptimal`] without a finite `n × n` weight;
/// - [`Error::NotDetermined`] if even all candidates together leave `JᵀJ` singular (a column
///   is not determined by any selection), or if `n_select` poses cannot give a non-singular
///   `JᵀJ` (too few rows); `JᵀJ` includes [`DesignConfig::prior`] when given.
///
/// # Panics
/// If [`DesignConfig::prior`] is not `n × n` or has a non-finite entry (misuse: the caller
/// builds it from the same columns as the blocks).
#[track_caller]
pub fn select_poses(
    blocks: &[Mat<f64>],
    n_select: usize,
    cfg: &DesignConfig,
) -> Result<Design, Error> {
    let n_candidates = blocks.len();
    if n_select == 0 || n_select > n_candidates {
        return Err(Error::TooFewCandidates {
            n_candidates,
            n_select,
        });
    }
    let (n, prior) = checked_information(blocks, n_select, cfg)?;
    let mut in_set = greedy_start(blocks, &prior, n_select)?;
    let mut m = prior.clone();
    for (c, b) in blocks.iter().enumerate() {
        if in_set[c] {
            add_info(&mut m, b.as_ref(), 1.0);
        }
    }
    let mut value = score(cfg, &m, n_select);
    if value == f64::NEG_INFINITY {
        return Err(Error::NotDetermined {
            n_params: n,
            n_select,
        });
    }

    let mut n_exchanges = 0;
    let mut converged = false;
    for _ in 0..cfg.max_exchanges {
        // Addition: the candidate with the best criterion for S ∪ {j}.
        let Some(l) = cholesky(&m) else {
            break;
        };
        let Ok(added) = best_added(blocks, &in_set, cfg, &m, &l, n_select) else {
            break;
        };
        let Some(added) = added else {
            converged = true;
            break;
        };
        let mut m_plus = m.clone();
        add_info(&mut m_plus, blocks[added].as_ref(), 1.0);
        in_set[added] = true;
        // Removal: the member of S ∪ {added} whose removal leaves the best criterion.
        let members: Vec<usize> = (0..n_candidates).filter(|&c| in_set[c]).collect();
        let l_plus = cholesky(&m_plus);
        let minv_plus = match cfg.criterion {
            Criterion::IOptimal => spd_inverse(&m_plus),
            _ => None,
        };
        let removal_score = |c: usize| -> f64 {
            match cfg.criterion {
                Criterion::DOptimal | Criterion::O1 => {
                    let Some(lp) = l_plus.as_ref() else {
                        return f64::NEG_INFINITY;
                    };
                    let w = whiten(lp, blocks[c].as_ref());
                    log_det_update(&w, -1.0).map_or(f64::NEG_INFINITY, |d| d)
                }
                Criterion::IOptimal => {
                    let (Some(w), Some(minv)) = (cfg.weight.as_ref(), minv_plus.as_ref()) else {
                        return f64::NEG_INFINITY;
                    };
                    // Larger is better: minus the increase of trace(W M⁻¹).
                    i_change(minv, w, blocks[c].as_ref(), -1.0).map_or(f64::NEG_INFINITY, |d| -d)
                }
                _ => {
                    let mut trial = m_plus.clone();
                    add_info(&mut trial, blocks[c].as_ref(), -1.0);
                    score(cfg, &trial, n_select)
                }
            }
        };
        let removed = members
            .iter()
            .map(|&c| (c, removal_score(c)))
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
            .map_or(added, |b| b.0);
        in_set[removed] = false;
        let mut m_next = m_plus;
        add_info(&mut m_next, blocks[removed].as_ref(), -1.0);
        let next_value = score(cfg, &m_next, n_select);
        // A negligible improvement (rounding) ends the search as well.
        let improved = next_value > value + 1e-12 * value.abs().max(1.0);
        if removed == added || !improved {
            if removed != added {
                // Undo: the exchange did not help.
                in_set[removed] = true;
                in_set[added] = false;
            } else {
                in_set[added] = false;
            }
            // The excursion is stuck: try the best single swap (Fedorov's exchange).
            match best_swap(blocks, &in_set, cfg, n_select, &m) {
                Some((out, into, swapped)) if swapped > value + 1e-12 * value.abs().max(1.0) => {
                    in_set[out] = false;
                    in_set[into] = true;
                    add_info(&mut m, blocks[out].as_ref(), -1.0);
                    add_info(&mut m, blocks[into].as_ref(), 1.0);
                    value = score(cfg, &m, n_select);
                    n_exchanges += 1;
                    continue;
                }
                _ => {
                    converged = true;
                    break;
                }
            }
        }
        m = m_next;
        value = next_value;
        n_exchanges += 1;
    }
    // Recompute M from scratch: the rank-one updates accumulate rounding.
    let selected: Vec<usize> = (0..n_candidates).filter(|&c| in_set[c]).collect();
    let mut m = prior;
    for &c in &selected {
        add_info(&mut m, blocks[c].as_ref(), 1.0);
    }
    let log_det = log_det(&m).unwrap_or(f64::NEG_INFINITY);
    let observability =
        observability_of_information(&m, selected.len()).ok_or(Error::NotDetermined {
            n_params: n,
            n_select,
        })?;
    Ok(Design {
        value: score(cfg, &m, selected.len()),
        selected,
        log_det,
        observability,
        n_exchanges,
        converged,
    })
}

/// The best swap of one member for one non-member (V. V. Fedorov's exchange, 1972, ch. 3):
/// `(member out, candidate in, criterion after the swap)`. For O3/O4/O5 only the best
/// [`DesignConfig::shortlist`] candidates by D-optimal gain are tried per member.
fn best_swap(
    blocks: &[Mat<f64>],
    in_set: &[bool],
    cfg: &DesignConfig,
    n_select: usize,
    m: &Mat<f64>,
) -> Option<(usize, usize, f64)> {
    let mut best: Option<(usize, usize, f64)> = None;
    let mut consider = |out: usize, into: usize, v: f64| {
        if best.is_none_or(|b| v > b.2) {
            best = Some((out, into, v));
        }
    };
    for out in (0..blocks.len()).filter(|&c| in_set[c]) {
        let mut m_out = m.clone();
        add_info(&mut m_out, blocks[out].as_ref(), -1.0);
        let outside = |c: usize| !in_set[c] && c != out;
        match cfg.criterion {
            Criterion::DOptimal | Criterion::O1 => {
                let Some(l) = cholesky(&m_out) else { continue };
                let base = 2.0 * (0..l.nrows()).map(|i| l[(i, i)].ln()).sum::<f64>();
                for into in (0..blocks.len()).filter(|&c| outside(c)) {
                    if let Some(g) = log_det_update(&whiten(&l, blocks[into].as_ref()), 1.0) {
                        consider(out, into, base + g);
                    }
                }
            }
            Criterion::IOptimal => {
                let (Some(w), Some(minv)) = (cfg.weight.as_ref(), spd_inverse(&m_out)) else {
                    continue;
                };
                let base = trace_product(w, &minv);
                for into in (0..blocks.len()).filter(|&c| outside(c)) {
                    if let Some(d) = i_change(&minv, w, blocks[into].as_ref(), 1.0) {
                        consider(out, into, -(base + d));
                    }
                }
            }
            _ => {
                let Some(l) = cholesky(&m_out) else { continue };
                let mut gains: Vec<(usize, f64)> = (0..blocks.len())
                    .filter(|&c| outside(c))
                    .filter_map(|c| {
                        log_det_update(&whiten(&l, blocks[c].as_ref()), 1.0).map(|g| (c, g))
                    })
                    .collect();
                gains.sort_by(|a, b| b.1.total_cmp(&a.1));
                for &(into, _) in gains.iter().take(cfg.shortlist.max(1)) {
                    let mut trial = m_out.clone();
                    add_info(&mut trial, blocks[into].as_ref(), 1.0);
                    consider(out, into, score(cfg, &trial, n_select));
                }
            }
        }
    }
    best
}

/// `(candidate, log det(I + B M⁻¹ Bᵀ))` for every candidate not in the set.
fn additions(blocks: &[Mat<f64>], in_set: &[bool], l: &Mat<f64>) -> Vec<(usize, f64)> {
    blocks
        .iter()
        .enumerate()
        .filter(|(c, _)| !in_set[*c])
        .filter_map(|(c, b)| log_det_update(&whiten(l, b.as_ref()), 1.0).map(|g| (c, g)))
        .collect()
}

/// The candidate with the largest D-optimal gain (ties: the lowest index).
fn best_addition(blocks: &[Mat<f64>], in_set: &[bool], l: &Mat<f64>) -> Option<(usize, f64)> {
    additions(blocks, in_set, l)
        .into_iter()
        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
}

/// `log det(JᵀJ)` (natural log) and O1–O5 of the candidates `chosen` (`n_poses = chosen.len()`),
/// for comparing a design with another set (e.g. random poses).
///
/// # Errors
/// [`Error::BlockShape`] for inconsistent blocks; [`Error::NotDetermined`] if `JᵀJ` is singular.
///
/// # Panics
/// If an index in `chosen` is out of range (misuse).
#[track_caller]
pub fn design_quality(
    blocks: &[Mat<f64>],
    chosen: &[usize],
) -> Result<(f64, Observability), Error> {
    let n = blocks.first().map_or(0, |b| b.ncols());
    let mut m = Mat::<f64>::zeros(n, n);
    for &c in chosen {
        let b = &blocks[c];
        if b.ncols() != n || !b.is_all_finite() {
            return Err(Error::BlockShape {
                index: c,
                nrows: b.nrows(),
                ncols: b.ncols(),
                expected_ncols: n,
            });
        }
        add_info(&mut m, b.as_ref(), 1.0);
    }
    let not_determined = Error::NotDetermined {
        n_params: n,
        n_select: chosen.len(),
    };
    let ld = log_det(&m).ok_or(not_determined.clone())?;
    let o = observability_of_information(&m, chosen.len().max(1)).ok_or(not_determined)?;
    Ok((ld, o))
}

/// Settings of [`i_optimal_weights`].
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousConfig {
    /// Most multiplicative updates.
    pub max_iterations: usize,
    /// Stop once the equivalence-theorem gap `max_c d_c / Φ(ξ) − 1` is at most this
    /// (dimensionless; 0 at the optimum, see [`ContinuousDesign`]).
    pub tolerance: f64,
}

impl ContinuousConfig {
    /// `max_iterations = 20_000`, `tolerance = 1e-3` (a design within 0.1 % of the optimum
    /// value: the certificate's bound then lies within 0.1 % of `Φ(ξ)`).
    pub fn new() -> Self {
        Self {
            max_iterations: 20_000,
            tolerance: 1e-3,
        }
    }
}

impl Default for ContinuousConfig {
    fn default() -> Self {
        Self::new()
    }
}

/// An approximate (continuous) I-optimal design on a finite candidate set, with the
/// equivalence-theorem certificate of how far it is from the optimum.
///
/// Notation (V. V. Fedorov, *Theory of Optimal Experiments*, 1972, §2.4–2.9; A. C. Atkinson,
/// A. N. Donev & R. D. Tobias, *Optimum Experimental Designs, with SAS*, 2007, ch. 9–10): a
/// design `ξ` puts weight `w_c ≥ 0` (`Σ w_c = 1`) on candidate `c`, whose block `B_c`
/// (`r_c × n`, rows divided by their σ) gives the normalised information
/// `M(ξ) = Σ_c w_c B_cᵀB_c` (`n × n`, per pose). The I-criterion (L-optimality with weight `W`)
/// is `Φ(ξ) = tr(W·M(ξ)⁻¹)` and the sensitivity of candidate `c` is
/// `d_c(ξ) = tr(B_c·M⁻¹WM⁻¹·B_cᵀ)`. Always `Σ_c w_c d_c = Φ(ξ)`; the general equivalence
/// theorem (Kiefer & Wolfowitz 1960, *Can. J. Math.* 12, for D/G; Fedorov 1972, Th. 2.9.2 for
/// linear criteria) says `ξ` is optimal iff `max_c d_c(ξ) ≤ Φ(ξ)`.
///
/// The certificate used here, valid for every design `ξ` and every other design `ξ'` on the
/// same design space: `Φ(ξ') ≥ Φ(ξ)² / sup_x d_x(ξ)`. Proof (Cauchy–Schwarz in the trace
/// inner product, `M = M(ξ)`, `M' = M(ξ')`): with `A = W^½M'^{-½}` and
/// `B = W^½M⁻¹M'^½`, `tr(ABᵀ) = Φ(ξ)`, `tr(AAᵀ) = Φ(ξ')` and
/// `tr(BBᵀ) = tr(M⁻¹WM⁻¹·M') = Σ w'_x d_x(ξ) ≤ sup_x d_x(ξ)`; so
/// `Φ(ξ)² ≤ Φ(ξ')·sup_x d_x(ξ)`. At the optimum `sup d = Φ` and the bound is tight.
///
/// An exact design of `N` poses `S` has `Σ_{c∈S} B_cᵀB_c = N·M(ξ_S)`, so
/// `tr(W(Σ_{c∈S} B_cᵀB_c)⁻¹) ≥ lower_bound / N` for every `S` in the design space: the best
/// `N`-pose design cannot beat the optimal continuous design spread over `N` poses.
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousDesign {
    /// Weight of each candidate (length `n_candidates`, sum 1).
    pub weights: Vec<f64>,
    /// `Φ(ξ) = tr(W·M(ξ)⁻¹)`: for rows divided by σ and `W` the second moment of a
    /// prediction's gradient, the mean prediction variance of one pose's worth of
    /// information, in units of σ² (e.g. m² per (σ = 1) for end-point positions).
    pub value: f64,
    /// `d_c(ξ)` per candidate (same units as `value`).
    pub sensitivity: Vec<f64>,
    /// `max_c d_c(ξ)` over the candidates.
    pub max_sensitivity: f64,
    /// `value² / max_sensitivity`: a lower bound of `Φ` of every design on the candidates.
    pub lower_bound: f64,
    /// `M(ξ)⁻¹·W·M(ξ)⁻¹` (`n × n`), to evaluate the sensitivity of points that are not
    /// candidates ([`ContinuousDesign::sensitivity_of`]).
    pub sensitivity_matrix: Mat<f64>,
    /// Multiplicative updates done.
    pub iterations: usize,
    /// True when the gap fell below [`ContinuousConfig::tolerance`].
    pub converged: bool,
}

impl ContinuousDesign {
    /// Sensitivity `d(ξ) = tr(B·M⁻¹WM⁻¹·Bᵀ)` of a block `B` (`r × n`), e.g. of a point of the
    /// design space outside the candidates.
    ///
    /// # Panics
    /// If `block.ncols()` differs from the design's `n` (misuse).
    #[track_caller]
    pub fn sensitivity_of(&self, block: MatRef<'_, f64>) -> f64 {
        assert_eq!(
            block.ncols(),
            self.sensitivity_matrix.nrows(),
            "block columns"
        );
        let bd = block * &self.sensitivity_matrix;
        (0..block.nrows())
            .map(|i| {
                (0..block.ncols())
                    .map(|j| bd[(i, j)] * block[(i, j)])
                    .sum::<f64>()
            })
            .sum()
    }

    /// The certificate's bound `Φ(ξ)² / max(sup_d, max_sensitivity)` for a design space whose
    /// supremum of the sensitivity is `sup_d` (e.g. found by searching beyond the candidates):
    /// a lower bound of `Φ` of every design on that space.
    pub fn lower_bound_given(&self, sup_d: f64) -> f64 {
        self.value * self.value / sup_d.max(self.max_sensitivity)
    }
}

/// Approximate I-optimal design on the candidate blocks by the multiplicative algorithm
/// (S. D. Silvey, D. M. Titterington & B. Torsney, "An algorithm for optimal designs on a
/// finite design space", *Commun. Stat. A* 7, 1978), `w_c ← w_c·(d_c/Φ)^½`, renormalised;
/// the exponent ½ makes each step decrease `Φ` for A- and L-type criteria (Y. Yu,
/// "Monotonic convergence of a general algorithm for computing optimal designs", *Ann. Stat.*
/// 38(3), 2010). Returns the design with its certificate ([`ContinuousDesign`]).
///
/// `blocks` as in [`select_poses`] (`r_c × n`, rows divided by σ); `weight` is `W`, `n × n`
/// symmetric positive semi-definite. Starts from equal weights.
///
/// # Errors
/// - [`Error::TooFewCandidates`] for no candidate;
/// - [`Error::BlockShape`] for an empty, mis-sized or non-finite block;
/// - [`Error::MissingWeight`] for a `weight` of another size or with a non-finite entry;
/// - [`Error::NotDetermined`] if all candidates together leave `M` singular.
pub fn i_optimal_weights(
    blocks: &[Mat<f64>],
    weight: &Mat<f64>,
    cfg: &ContinuousConfig,
) -> Result<ContinuousDesign, Error> {
    let n_candidates = blocks.len();
    if n_candidates == 0 {
        return Err(Error::TooFewCandidates {
            n_candidates,
            n_select: 1,
        });
    }
    let n = check_blocks(blocks)?;
    let mut offsets = Vec::with_capacity(n_candidates + 1);
    offsets.push(0);
    for (index, b) in blocks.iter().enumerate() {
        offsets.push(offsets[index] + b.nrows());
    }
    if weight.nrows() != n || weight.ncols() != n || !weight.is_all_finite() {
        return Err(Error::MissingWeight { n_params: n });
    }
    // All rows stacked: J (R × n), block c = rows offsets[c]..offsets[c + 1].
    let n_rows = offsets[n_candidates];
    let mut j = Mat::<f64>::zeros(n_rows, n);
    for (c, b) in blocks.iter().enumerate() {
        for r in 0..b.nrows() {
            for k in 0..n {
                j[(offsets[c] + r, k)] = b[(r, k)];
            }
        }
    }
    let not_determined = Error::NotDetermined {
        n_params: n,
        n_select: n_candidates,
    };
    let row_candidate: Vec<usize> = (0..n_candidates)
        .flat_map(|c| std::iter::repeat_n(c, offsets[c + 1] - offsets[c]))
        .collect();
    let mut w = vec![1.0 / n_candidates as f64; n_candidates];
    // Φ, d and D for the weights w.
    let evaluate = |w: &[f64]| -> Option<(f64, Vec<f64>, Mat<f64>)> {
        let scaled = Mat::from_fn(n_rows, n, |i, k| j[(i, k)] * w[row_candidate[i]].sqrt());
        let m = scaled.transpose() * &scaled;
        let minv = spd_inverse(&m)?;
        let d_mat = &minv * weight * &minv;
        let value = trace_product(weight, &minv);
        let jd = &j * &d_mat;
        let mut d = vec![0.0; n_candidates];
        for (c, dc) in d.iter_mut().enumerate() {
            for i in offsets[c]..offsets[c + 1] {
                *dc += (0..n).map(|k| jd[(i, k)] * j[(i, k)]).sum::<f64>();
            }
        }
        Some((value, d, d_mat))
    };
    let (mut value, mut d, mut d_mat) = evaluate(&w).ok_or(not_determined.clone())?;
    let mut iterations = 0;
    let mut converged = false;
    loop {
        let max_d = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if max_d <= value * (1.0 + cfg.tolerance) {
            converged = true;
            break;
        }
        if iterations >= cfg.max_iterations || value <= 0.0 {
            break;
        }
        for (wc, dc) in w.iter_mut().zip(&d) {
            *wc *= (dc.max(0.0) / value).sqrt();
        }
        let total: f64 = w.iter().sum();
        w.iter_mut().for_each(|wc| *wc /= total);
        let Some(next) = evaluate(&w) else {
            return Err(not_determined);
        };
        (value, d, d_mat) = next;
        iterations += 1;
    }
    let max_sensitivity = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Ok(ContinuousDesign {
        weights: w,
        value,
        lower_bound: value * value / max_sensitivity,
        sensitivity: d,
        max_sensitivity,
        sensitivity_matrix: d_mat,
        iterations,
        converged,
    })
}

/// Checks candidate blocks (non-empty `blocks`, each `r_c × n`, finite, at least one row) and
/// returns their common column count `n`.
///
/// # Errors
/// [`Error::BlockShape`] for the first block that is empty, of another width, or not finite.
fn check_blocks(blocks: &[Mat<f64>]) -> Result<usize, Error> {
    let n = blocks[0].ncols();
    for (index, b) in blocks.iter().enumerate() {
        if b.nrows() == 0 || b.ncols() != n || !b.is_all_finite() {
            return Err(Error::BlockShape {
                index,
                nrows: b.nrows(),
                ncols: b.ncols(),
                expected_ncols: n,
            });
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows `(cos t, sin t)` for angles `t`: the information of a set is
    /// `Σ [cos² cs; cs sin²]`, maximal in determinant for angles spread evenly over π.
    fn directions(angles: &[f64]) -> Vec<Mat<f64>> {
        angles
            .iter()
            .map(|t| Mat::from_fn(1, 2, |_, j| if j == 0 { t.cos() } else { t.sin() }))
            .collect()
    }

    #[test]
    fn d_optimal_picks_orthogonal_directions() {
        // Candidates at 0°, 5°, 10°, 85°, 90°: the best pair is {0°, 90°} (det = 1).
        let deg = std::f64::consts::PI / 180.0;
        let blocks = directions(&[0.0, 5.0 * deg, 10.0 * deg, 85.0 * deg, 90.0 * deg]);
        for criterion in [
            Criterion::DOptimal,
            Criterion::O4,
            Criterion::O3,
            Criterion::O5,
        ] {
            let d = select_poses(&blocks, 2, &DesignConfig::new(criterion)).expect("design");
            assert_eq!(d.selected, [0, 4], "{criterion}");
            assert!(d.log_det.abs() < 1e-12, "{}", d.log_det);
            assert!((d.observability.o3 - 1.0).abs() < 1e-12);
        }
    }

    /// Deterministic entries in [−0.5, 0.5) from `seed` (a 64-bit LCG, Knuth's MMIX
    /// constants).
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        }
    }

    #[test]
    fn exchange_beats_a_bad_greedy_start_and_matches_brute_force() {
        // 12 random 2-row blocks in 4 parameters; choose 3. Compare with all 220 subsets.
        let mut next = uniform(12345);
        let blocks: Vec<Mat<f64>> = (0..12).map(|_| Mat::from_fn(2, 4, |_, _| next())).collect();
        let d = select_poses(&blocks, 3, &DesignConfig::new(Criterion::DOptimal)).expect("design");
        let mut best = f64::NEG_INFINITY;
        for a in 0..12 {
            for b in a + 1..12 {
                for c in b + 1..12 {
                    if let Ok((ld, _)) = design_quality(&blocks, &[a, b, c]) {
                        best = best.max(ld);
                    }
                }
            }
        }
        // DETMAX is a local search; on this small problem it must reach the global optimum
        // within rounding.
        assert!((d.log_det - best).abs() < 1e-9, "{} vs {best}", d.log_det);
        assert!(d.converged);
        assert_eq!(d.selected.len(), 3);
    }

    #[test]
    fn a_prior_steers_the_design_to_what_it_does_not_determine() {
        // The prior determines parameter 0 a hundred times better than one row can: the one
        // pose to add is the one that sees parameter 1, for every criterion; without the
        // prior, one pose cannot determine two parameters (O3 scores the singular set 0, a
        // design, where D- and I-optimality find none).
        let blocks = directions(&[0.0, 0.7, std::f64::consts::FRAC_PI_2]);
        let prior = Mat::from_fn(2, 2, |i, j| if i == 0 && j == 0 { 100.0 } else { 0.0 });
        for criterion in [Criterion::DOptimal, Criterion::IOptimal, Criterion::O3] {
            let cfg = DesignConfig {
                weight: Some(Mat::<f64>::identity(2, 2)),
                prior: Some(prior.clone()),
                ..DesignConfig::new(criterion)
            };
            let d = select_poses(&blocks, 1, &cfg).expect("design");
            assert_eq!(d.selected, [2], "{criterion}");
            // M = diag(100, 1): log det = ln 100.
            assert!((d.log_det - 100f64.ln()).abs() < 1e-12, "{}", d.log_det);
            let alone = DesignConfig { prior: None, ..cfg };
            if criterion != Criterion::O3 {
                assert!(
                    matches!(
                        select_poses(&blocks, 1, &alone),
                        Err(Error::NotDetermined { .. })
                    ),
                    "{criterion}"
                );
            }
        }
        // On random blocks and a random positive definite prior, the I-optimal pair is the
        // best of all 28 pairs, found by enumeration.
        let mut next = uniform(4242);
        let blocks: Vec<Mat<f64>> = (0..8).map(|_| Mat::from_fn(1, 3, |_, _| next())).collect();
        let a = Mat::from_fn(3, 3, |_, _| next());
        let prior = a.transpose() * &a + Mat::<f64>::identity(3, 3) * 0.01;
        let w = Mat::from_fn(3, 3, |i, j| if i == j { 1.0 + i as f64 } else { 0.0 });
        let cfg = DesignConfig {
            weight: Some(w.clone()),
            prior: Some(prior.clone()),
            ..DesignConfig::new(Criterion::IOptimal)
        };
        let d = select_poses(&blocks, 2, &cfg).expect("design");
        let value = |set: &[usize]| {
            let mut m = prior.clone();
            for &c in set {
                add_info(&mut m, blocks[c].as_ref(), 1.0);
            }
            spd_inverse(&m).map_or(f64::INFINITY, |inv| trace_product(&w, &inv))
        };
        let best = (0..8)
            .flat_map(|a| (a + 1..8).map(move |b| [a, b]))
            .map(|set| value(&set))
            .fold(f64::INFINITY, f64::min);
        assert!(
            (value(&d.selected) - best).abs() <= 1e-12 * best,
            "{} vs {best}",
            value(&d.selected)
        );
        assert!((d.value + best).abs() <= 1e-12 * best);
    }

    #[test]
    fn i_optimal_design_is_swap_optimal() {
        let mut next = uniform(777);
        let blocks: Vec<Mat<f64>> = (0..10).map(|_| Mat::from_fn(2, 3, |_, _| next())).collect();
        // Only parameter 0's prediction matters: W = e0·e0ᵀ, the criterion is −Var(x0)/σ².
        let w = Mat::from_fn(3, 3, |i, j| if i == 0 && j == 0 { 1.0 } else { 0.0 });
        let cfg = DesignConfig {
            weight: Some(w.clone()),
            ..DesignConfig::new(Criterion::IOptimal)
        };
        let d = select_poses(&blocks, 3, &cfg).expect("design");
        let var0 = |set: &[usize]| {
            let mut m = Mat::<f64>::zeros(3, 3);
            for &c in set {
                add_info(&mut m, blocks[c].as_ref(), 1.0);
            }
            spd_inverse(&m).map_or(f64::INFINITY, |inv| inv[(0, 0)])
        };
        let mut best = f64::INFINITY;
        for a in 0..10 {
            for b in a + 1..10 {
                for c in b + 1..10 {
                    best = best.min(var0(&[a, b, c]));
                }
            }
        }
        // The exchange is a local search: no single swap of a chosen block for another may
        // improve the design (here the global optimum, found by enumeration, needs two swaps).
        let sel = d.selected.clone();
        assert!(
            (-d.value - var0(&sel)).abs() <= 1e-12 * best,
            "{} vs {}",
            -d.value,
            var0(&sel)
        );
        for k in 0..3 {
            for c in (0..10).filter(|c| !sel.contains(c)) {
                let mut swapped = sel.clone();
                swapped[k] = c;
                assert!(
                    var0(&swapped) >= var0(&sel) * (1.0 - 1e-12),
                    "{swapped:?} is better"
                );
            }
        }
        assert!(var0(&sel) >= best);
        let err = select_poses(&blocks, 3, &DesignConfig::new(Criterion::IOptimal))
            .expect_err("no weight");
        assert_eq!(err, Error::MissingWeight { n_params: 3 });
    }

    #[test]
    fn errors_name_the_problem() {
        let blocks = directions(&[0.0, 0.0, 0.0]);
        let err = select_poses(&blocks, 2, &DesignConfig::new(Criterion::DOptimal))
            .expect_err("the second column is never seen");
        assert_eq!(
            err,
            Error::NotDetermined {
                n_params: 2,
                n_select: 2
            }
        );
        let err =
            select_poses(&blocks, 4, &DesignConfig::new(Criterion::O4)).expect_err("too many");
        assert_eq!(err.to_string(), "cannot choose 4 poses from 3 candidates");
    }

    /// Quadratic regression `(1, x, x²)` on a grid of [−1, 1] (21 points).
    fn quadratic_blocks() -> (Vec<f64>, Vec<Mat<f64>>) {
        let xs: Vec<f64> = (0..21).map(|i| -1.0 + 0.1 * f64::from(i)).collect();
        let blocks = xs
            .iter()
            .map(|&x| Mat::from_fn(1, 3, |_, k| x.powi(k as i32)))
            .collect();
        (xs, blocks)
    }

    #[test]
    fn continuous_a_optimal_design_of_quadratic_regression_is_known() {
        // A-optimal (W = I) design for (1, x, x²) on [−1, 1]: weights ¼, ½, ¼ at −1, 0, 1 and
        // tr M⁻¹ = 2/(m₂(1 − m₂)) = 8 at m₂ = ½ (derivation: M has m₂ = m₄ = weight on ±1).
        let (xs, blocks) = quadratic_blocks();
        let w = Mat::<f64>::identity(3, 3);
        let cfg = ContinuousConfig {
            max_iterations: 200_000,
            tolerance: 1e-6,
        };
        let d = i_optimal_weights(&blocks, &w, &cfg).expect("design");
        assert!(d.converged, "gap {}", d.max_sensitivity / d.value - 1.0);
        assert!(
            d.lower_bound <= 8.0 && 8.0 <= d.value,
            "{} {}",
            d.lower_bound,
            d.value
        );
        assert!((d.value - 8.0).abs() < 1e-4, "{}", d.value);
        let at = |x: f64| {
            xs.iter()
                .position(|&v| (v - x).abs() < 1e-9)
                .map_or(0.0, |i| d.weights[i])
        };
        assert!((at(-1.0) - 0.25).abs() < 1e-2, "{}", at(-1.0));
        assert!((at(0.0) - 0.5).abs() < 1e-2, "{}", at(0.0));
        assert!((at(1.0) - 0.25).abs() < 1e-2, "{}", at(1.0));
        // Σ w d = Φ, and the sensitivity of a block evaluated outside the candidates agrees.
        let wd: f64 = d
            .weights
            .iter()
            .zip(&d.sensitivity)
            .map(|(a, b)| a * b)
            .sum();
        assert!((wd - d.value).abs() < 1e-9 * d.value);
        assert!((d.sensitivity_of(blocks[3].as_ref()) - d.sensitivity[3]).abs() < 1e-9);
    }

    #[test]
    fn equivalence_certificate_rejects_a_non_optimal_design_and_bounds_exact_designs() {
        let (_, blocks) = quadratic_blocks();
        // I-optimality: W = ∫ f fᵀ dx / 2 over [−1, 1].
        let w = Mat::from_fn(3, 3, |i, j| {
            let k = i + j;
            if k % 2 == 1 {
                0.0
            } else {
                1.0 / (k as f64 + 1.0)
            }
        });
        // No iteration: the equal-weight design, which the theorem must reject.
        let start = ContinuousConfig {
            max_iterations: 0,
            tolerance: 1e-6,
        };
        let d0 = i_optimal_weights(&blocks, &w, &start).expect("design");
        assert!(!d0.converged);
        assert!(
            d0.max_sensitivity > 1.2 * d0.value,
            "{}",
            d0.max_sensitivity
        );
        let d = i_optimal_weights(&blocks, &w, &ContinuousConfig::new()).expect("design");
        assert!(d.converged && d.value < d0.value);
        // Every exact 4-point design (with repeats allowed: brute force over all multisets of
        // 4 of the 21 points) respects tr(W (Σ BᵀB)⁻¹) ≥ bound / 4, and the best one is close.
        let mut best = f64::INFINITY;
        for a in 0..21 {
            for b in a..21 {
                for c in b..21 {
                    for e in c..21 {
                        let mut m = Mat::<f64>::zeros(3, 3);
                        for &k in &[a, b, c, e] {
                            add_info(&mut m, blocks[k].as_ref(), 1.0);
                        }
                        if let Some(inv) = spd_inverse(&m) {
                            best = best.min(trace_product(&w, &inv));
                        }
                    }
                }
            }
        }
        assert!(
            best >= d.lower_bound / 4.0,
            "{best} < {}",
            d.lower_bound / 4.0
        );
        assert!(best <= 1.2 * d.value / 4.0, "{best} vs {}", d.value / 4.0);
        let err = i_optimal_weights(&blocks, &Mat::<f64>::identity(2, 2), &start)
            .expect_err("weight of the wrong size");
        assert_eq!(err, Error::MissingWeight { n_params: 3 });
    }

    #[test]
    fn criterion_names_round_trip() {
        for c in [
            Criterion::DOptimal,
            Criterion::O1,
            Criterion::O3,
            Criterion::O4,
            Criterion::O5,
            Criterion::IOptimal,
        ] {
            assert_eq!(c.to_string().parse::<Criterion>(), Ok(c));
        }
    }
}
