//! What every workflow's fits share: the identification settings of a kinematic calibration,
//! the repeated blocked cross-validation's folds and statistics, and the fit's termination,
//! back end and pruned parameters in the report's words.

use hapcal_identify::{Identified, IdentifyConfig, PruneReason};

use crate::report::{PruneCause, PrunedReport};

/// The back end of an identification and why, for the report.
pub fn backend_of(id: &Identified) -> String {
    format!("{}: {}", id.backend.name, id.backend.reason)
}

/// Identification settings of a kinematic calibration: exact ties between collinear
/// parameters keep the one further from the base (the gauge goes to the base side).
pub fn identify_config(sigma_m: Option<f64>) -> IdentifyConfig {
    let mut cfg = IdentifyConfig {
        sigma: sigma_m,
        ..IdentifyConfig::default()
    };
    cfg.rank.tie_break = hapcal_identify::TieBreak::LaterInLayout;
    cfg
}

pub use crate::report::termination_text;

/// Repeats of the cross-validation: repeat `r` shifts every block boundary by `r/CV_REPEATS` of
/// a block. Averaging the held-out errors over shifted partitions makes the choice less
/// sensitive to where the fold boundaries fall (measured for 3…10 folds on the MUKCa training
/// placements in docs/results/mukca.md: kuka_14, panda_1 and panda_6 keep their model, panda_7
/// moves between two compliance models), at three times the cost of one k-fold pass.
pub const CV_REPEATS: usize = 3;

/// The index ranges of sets of `lengths[i]` rows held one after the other.
pub fn log_ranges(lengths: &[usize]) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
    lengths.iter().scan(0, |start, &len| {
        *start += len;
        Some(*start - len..*start)
    })
}

/// Cross-validation folds of the model ladder unless told otherwise (the command line's
/// `--folds` default).
pub const DEFAULT_FOLDS: usize = 5;

/// Training rows beyond which `--model auto` on haptic logs chooses its model on a sample of
/// them ([`ladder_sample`]); the chosen model is then fitted on every row. The ladder refits
/// each rung `CV_REPEATS × folds` times, so its cost grows with the rows while the choice does
/// not need them: on a simulated log of the reference device with transmission errors and no
/// compliance (`hapcal simulate --truth fixtures/reference-device/truth.toml --seed 7 --poses
/// 100000`), 20,000 of its rows put the transmissions 134 blocked standard errors ahead of
/// the deviations alone (all 100,000 rows: 126) and the compliance no better than the
/// transmissions, the choice of all the rows (docs/engine.md, "Long logs").
pub const LADDER_ROWS: usize = 20_000;

/// The training rows a long log's ladder judges ([`ladder_sample`]).
#[derive(Clone, Debug, PartialEq)]
pub struct LadderSample {
    /// Every `stride`-th row of each log, from the log's first.
    pub stride: usize,
    /// Indices of the sampled rows in the logs' rows one after the other, increasing.
    pub rows: Vec<usize>,
    /// Sampled rows of each log, in the logs' order.
    pub lengths: Vec<usize>,
}

/// The rows of logs of `lengths[i]` rows (one after the other) that the ladder judges when
/// they hold more than `cap` rows in all: every `stride`-th row of each log, from its first,
/// the stride the smallest that leaves at most `cap` rows. A stride keeps the log's spread
/// over time and joint space, and its blocked folds stay contiguous in time. `None` when the
/// logs hold `cap` rows or fewer: every row is judged.
pub fn ladder_sample(lengths: &[usize], cap: usize) -> Option<LadderSample> {
    let n: usize = lengths.iter().sum();
    if n <= cap || cap == 0 {
        return None;
    }
    // ceil(len / stride) rows of each log; the smallest stride whose sum fits under the cap.
    let kept = |stride: usize| -> usize { lengths.iter().map(|l| l.div_ceil(stride)).sum() };
    let mut stride = n.div_ceil(cap);
    while kept(stride) > cap {
        stride += 1;
    }
    let mut rows = Vec::with_capacity(kept(stride));
    let mut start = 0;
    for &len in lengths {
        rows.extend((start..start + len).step_by(stride));
        start += len;
    }
    Some(LadderSample {
        stride,
        rows,
        lengths: lengths.iter().map(|l| l.div_ceil(stride)).collect(),
    })
}

/// Held-out errors of one candidate: one entry per training row, in a fixed order.
#[derive(Clone, Debug, Default)]
pub struct HeldOut {
    /// Squared held-out error per row, m² (3-D point or distance), averaged over the repeats.
    pub sq_errors: Vec<f64>,
    /// Block of each row: `(data set, socket, fold)` of the first repeat, numbered in that
    /// order (a block with no row, for a socket shorter than the folds, stays empty).
    pub block: Vec<usize>,
}

/// Fold (`0..k`) of row `row` of `n` in repeat `r` of `repeats`: the rows, circularly shifted
/// by `r·n/(k·repeats)`, cut into `k` contiguous blocks of (nearly) equal length. Repeat 0 is
/// plain contiguous k-fold.
pub fn fold_of(row: usize, n: usize, k: usize, r: usize, repeats: usize) -> usize {
    let n = n.max(1);
    let shifted = (row * k * repeats + r * n) % (n * k * repeats);
    shifted / (n * repeats)
}

/// The original of every row of a data set: the index of the earliest row whose key it
/// repeats (a copy of that row), or its own index. Keys are the readers' repeat keys
/// ([`hapcal_io::MeasuredRow::repeat_key`], [`hapcal_io::LogRow::repeat_key`]) or, for
/// rows those do not describe, the values the fit sees as bit patterns.
pub fn originals<K: std::hash::Hash + Eq>(keys: impl IntoIterator<Item = K>) -> Vec<usize> {
    let mut first = std::collections::HashMap::new();
    (keys.into_iter().enumerate())
        .map(|(i, key)| *first.entry(key).or_insert(i))
        .collect()
}

/// Number of rows of `original` ([`originals`]) that repeat an earlier row.
pub fn n_copies(original: &[usize]) -> usize {
    (original.iter().enumerate())
        .filter(|&(i, &o)| o != i)
        .count()
}

/// Fold (`0..k`) of every row of a data set in repeat `r` of `repeats`, copies held out with
/// the row they copy: the distinct rows (those that are their own `original`, [`originals`])
/// in file order are cut by [`fold_of`], and every copy takes its original's fold. Without
/// copies, row `i` of `n` falls in `fold_of(i, n, k, r, repeats)`. A copy trained on while
/// its original is held out would reward a model for memorising rows.
///
/// # Panics
/// If an entry of `original` is not an index at or before its own row.
#[track_caller]
pub fn folds_of_rows(original: &[usize], k: usize, r: usize, repeats: usize) -> Vec<usize> {
    let mut rank = vec![0; original.len()];
    let mut n_distinct = 0;
    for (i, &o) in original.iter().enumerate() {
        assert!(o <= i, "row {i}'s original {o} is not an earlier row");
        if o == i {
            rank[i] = n_distinct;
            n_distinct += 1;
        }
    }
    (original.iter())
        .map(|&o| fold_of(rank[o], n_distinct, k, r, repeats))
        .collect()
}

/// Held-out rows of one cross-validation fold: per data set (table, log), per row, whether
/// it is held out.
pub(crate) type Fold = Vec<Vec<bool>>;

/// The repeated blocked folds of data sets whose rows have the originals `sets[set]`
/// ([`originals`]): repeat `r` of [`CV_REPEATS`] cuts each set's distinct rows (file order,
/// circularly shifted by `r/CV_REPEATS` of a block) into `k` contiguous blocks, each copy
/// in its original's ([`folds_of_rows`]); `CV_REPEATS · k` folds, repeat by repeat.
pub(crate) fn blocked_folds(sets: &[Vec<usize>], k: usize) -> Vec<Fold> {
    let mut folds = Vec::new();
    for rep in 0..CV_REPEATS {
        let of_rows: Vec<Vec<usize>> = (sets.iter())
            .map(|original| folds_of_rows(original, k, rep, CV_REPEATS))
            .collect();
        for fold in 0..k {
            folds.push(
                (of_rows.iter())
                    .map(|rows| rows.iter().map(|&f| f == fold).collect())
                    .collect(),
            );
        }
    }
    folds
}

/// The block of every row of data sets whose rows have the originals `sets[set]`, the sets'
/// rows one after the other: `set · k + fold` of the first repeat ([`HeldOut::block`]).
pub(crate) fn first_repeat_blocks(sets: &[Vec<usize>], k: usize) -> Vec<usize> {
    (sets.iter().enumerate())
        .flat_map(|(set, original)| {
            (folds_of_rows(original, k, 0, CV_REPEATS).into_iter()).map(move |f| set * k + f)
        })
        .collect()
}

/// The warning of a cross-validation whose training rows hold copies (`n_copies` of them),
/// `None` without.
pub(crate) fn copies_warning(n_copies: usize) -> Option<String> {
    (n_copies > 0).then(|| {
        let rows = if n_copies == 1 {
            "1 training row repeats an earlier row".to_owned()
        } else {
            format!("{n_copies} training rows repeat earlier rows")
        };
        format!(
            "{rows}: each is held out with the row it copies in every cross-validation fold, \
             so a copy cannot reward a model that memorises rows"
        )
    })
}

/// Change of χ² below which a fit of the measured workflow on every training row stops: with
/// `χ² = Σ rᵢ²/σ²` (σ the residuals' noise, `‖r‖²/(m − n)` at the estimate for `m` residuals
/// and `n` parameters), the fit stops when a step lowers χ², and the Gauss–Newton model
/// predicts it would lower it, by at most this ([`full_fit_lm`]). The cost left above the
/// minimum is then about that change, and `χ²(x) − χ²(x̂) = (x − x̂)ᵀ Σ⁻¹ (x − x̂)` near it
/// (Σ the covariance), so every parameter is within `√(10⁻⁶) = 10⁻³` of its standard deviation
/// of the least-squares estimate: a thousandth of what the data can tell, where the default
/// relative tolerance of 10⁻¹² asks for 10⁻¹²·(m − n) of χ², 10⁻⁹ on the simulated humanoid's
/// 2,310 residuals (Press et al., *Numerical Recipes*, 3rd ed., 2007, §15.5: stop once χ²
/// decreases by a negligible amount). On that humanoid the per-axis transversal compliance
/// crawled through 50 iterations whose last 18 lowered χ² by about 2·10⁻⁶ in all.
pub(crate) const CHI2_TOLERANCE: f64 = 1e-6;

/// The Levenberg–Marquardt settings of a fit on every training row of `n_residuals`
/// residuals (`lm` the identification's): `ftol` raised to `CHI2_TOLERANCE / n_residuals`,
/// the relative cost reduction that is a χ² change of [`CHI2_TOLERANCE`] or less (the
/// residuals' sum of squares is about `(m − n)·σ²`, at most `m·σ²`); never lowered.
pub(crate) fn full_fit_lm(
    lm: hapcal_identify::LmConfig,
    n_residuals: usize,
) -> hapcal_identify::LmConfig {
    hapcal_identify::LmConfig {
        ftol: lm.ftol.max(CHI2_TOLERANCE / n_residuals.max(1) as f64),
        ..lm
    }
}

/// Relative tolerance (cost reduction, step) of a cross-validation fold's refit. A fold's
/// estimate is judged by its held-out error: a relative cost reduction of 10⁻⁶ changes that
/// error by about 10⁻⁶ of itself, far below the blocked standard errors the ladder compares
/// (a few per cent of the error).
pub(crate) const FOLD_TOLERANCE: f64 = 1e-6;

/// How far, in χ² (the fit's cost in units of its residual variance), a marker fold's first
/// Gauss–Newton step from the full-data estimate may miss the reduction its linearisation
/// predicted and still be the fold's estimate ([`hapcal_identify::LmConfig::one_step`]). The
/// full-data estimate lies within the statistical error of the fold's (a fifth of the rows
/// moves it by about half a standard error), so one Gauss–Newton step leaves an error of
/// second order in that distance (Le Cam's one-step estimator); when the linearisation held
/// over the step to 0.1 of χ², a tenth of the Δχ² = 1 that marks one standard error, the
/// step's estimate is taken, and the fold needs no Jacobian beyond the one at the full-data
/// estimate that every fold shares. A step that missed by more is iterated as before. On the
/// simulated humanoids this moved every rung's cross-validated RMS by at most 7·10⁻⁵ of
/// itself and every blocked score difference by at most 0.04 of its standard error
/// (docs/results/speed.md).
pub(crate) const FOLD_STEP_CHI2: f64 = 0.1;

/// The Levenberg–Marquardt settings of a marker fold's refit (`lm` the identification's) with
/// `n_residuals` residuals and `n_free` free parameters: stopped at [`FOLD_TOLERANCE`], and
/// at the first Gauss–Newton step when it is within [`FOLD_STEP_CHI2`] of its prediction (the
/// relative tolerance `FOLD_STEP_CHI2 / (n_residuals − n_free)`, χ² being about
/// `n_residuals − n_free` at the estimate).
pub(crate) fn fold_step_lm(
    lm: hapcal_identify::LmConfig,
    n_residuals: usize,
    n_free: usize,
) -> hapcal_identify::LmConfig {
    let dof = n_residuals.saturating_sub(n_free).max(1) as f64;
    hapcal_identify::LmConfig {
        ftol: FOLD_TOLERANCE,
        xtol: FOLD_TOLERANCE,
        one_step: Some(FOLD_STEP_CHI2 / dof),
        ..lm
    }
}

/// Mean over rows of `a − b` and its standard error from the block means (rows of one
/// contiguous block are correlated, so the blocks, not the rows, are the independent units:
/// Roberts et al. 2017, "Cross-validation strategies for data with temporal, spatial,
/// hierarchical, or phylogenetic structure", Ecography 40(8)). `(0, ∞)` with fewer than 2 blocks.
pub fn blocked_difference(a: &HeldOut, b: &HeldOut) -> (f64, f64) {
    match blocked_mean_difference(&a.sq_errors, &b.sq_errors, &a.block) {
        (_, _, filled) if filled < 2 => (0.0, f64::INFINITY),
        (mean, se, _) => (mean, se),
    }
}

/// Mean over rows of `a − b` (the first `min(a.len(), b.len())` rows), its standard error from
/// the blocks `block[row]` (the independent units of correlated rows), and the number of
/// non-empty blocks; the standard error is `∞` with fewer than 2 blocks. The variance is the
/// ratio estimator of a mean over clusters of unequal size (Cochran, "Sampling Techniques",
/// 3rd ed., 1977, §6.4): `v = Σ (y_b − ȳ·m_b)² / ((n_b − 1)·n_b·m̄²)`.
///
/// # Panics
/// If `block` is shorter than the rows compared.
#[track_caller]
pub fn blocked_mean_difference(a: &[f64], b: &[f64], block: &[usize]) -> (f64, f64, usize) {
    let n = a.len().min(b.len());
    let n_blocks = block[..n].iter().max().map_or(0, |m| m + 1);
    let mut sum = vec![0.0; n_blocks];
    let mut count = vec![0usize; n_blocks];
    for i in 0..n {
        sum[block[i]] += a[i] - b[i];
        count[block[i]] += 1;
    }
    let filled = count.iter().filter(|&&c| c > 0).count();
    let mean = sum.iter().sum::<f64>() / n.max(1) as f64;
    if filled < 2 {
        return (mean, f64::INFINITY, filled);
    }
    let nb = filled as f64;
    let m_bar = n as f64 / nb;
    let var = (sum.iter().zip(&count))
        .map(|(s, &c)| (s - mean * c as f64).powi(2))
        .sum::<f64>()
        / (nb - 1.0)
        / (nb * m_bar * m_bar);
    (mean, var.sqrt(), filled)
}

/// The model choice of `--model auto` from the held-out errors of each candidate: the one rule
/// of [`crate::model::climb`] over the candidates' ladder levels `level` (candidate 0 the
/// geometric model, the reference of the reported differences). A candidate beats another when
/// its held-out squared error is lower by [`crate::model::LADDER_SIGNIFICANCE_Z`] blocked
/// standard errors; one that contains another alternative of its level
/// ([`crate::model::ModelRules::contains`]) must beat that one too, and its report says by
/// how much ([`crate::report::CvReport::nested`]).
///
/// # Panics
/// If `held`, `level` and `candidates` differ in length or are empty.
#[track_caller]
pub(crate) fn choose(
    candidates: &[crate::model::ModelName],
    level: &[usize],
    held: &[HeldOut],
) -> (crate::model::ModelName, Vec<crate::report::CvReport>) {
    assert!(
        !held.is_empty() && held.len() == candidates.len() && level.len() == held.len(),
        "one held-out set and one level per candidate"
    );
    let rms =
        |h: &HeldOut| (h.sq_errors.iter().sum::<f64>() / h.sq_errors.len().max(1) as f64).sqrt();
    let beats = |i: usize, j: usize| {
        let (d, se) = blocked_difference(&held[i], &held[j]);
        i != j && d + crate::model::LADDER_SIGNIFICANCE_Z * se < 0.0
    };
    use crate::model::ModelRules;
    let contains = |i: usize, j: usize| candidates[i].contains(candidates[j]);
    let beats_contained = |i: usize, j: usize| contains(i, j).then(|| beats(i, j));
    let chosen = crate::model::climb(level, &beats, &|i| rms(&held[i]), &beats_contained);
    // The rung each candidate was compared with: the one chosen on the levels below its own.
    let compared = |i: usize| {
        let below = level.iter().take_while(|&&l| l < level[i]).count();
        (below > 0).then(|| {
            crate::model::climb(
                &level[..below],
                &beats,
                &|j| rms(&held[j]),
                &beats_contained,
            )
        })
    };
    // The alternative of its own level each candidate contains, and the comparison with it.
    let nested_report = |i: usize| {
        (0..candidates.len())
            .find(|&j| j != i && level[j] == level[i] && contains(i, j))
            .map(|j| crate::report::NestedComparison {
                contains: candidates[j],
                difference: blocked_difference(&held[i], &held[j]),
                beats: beats(i, j),
            })
    };
    let reports = (candidates.iter().zip(held).enumerate())
        .map(|(i, (candidate, h))| crate::report::CvReport {
            compared_with: compared(i).map(|j| candidates[j]),
            difference_to_compared_m2: compared(i)
                .map_or((0.0, 0.0), |j| blocked_difference(h, &held[j])),
            model: *candidate,
            heldout_rms_m: rms(h),
            difference_to_geometric_m2: if i == 0 {
                (0.0, 0.0)
            } else {
                blocked_difference(h, &held[0])
            },
            beats_geometric: beats(i, 0),
            nested: nested_report(i),
            n_kept: 0,
        })
        .collect();
    (candidates[chosen], reports)
}

/// Largest Jacobian, in entries (`m·n`), of which [`refitted_lengths`] evaluates the step:
/// the dense back end's own bound ([`hapcal_identify::STREAMING_AUTO_ENTRIES`]); beyond it
/// the fit streamed and no held length is judged.
pub(crate) const REFIT_MAX_ENTRIES: usize = hapcal_identify::STREAMING_AUTO_ENTRIES;

/// Smallest singular value of the held lengths' unit-norm columns, orthogonal to the kept
/// columns, along which [`refitted_lengths`] fits them: below it the data hardly see the
/// direction, and a systematic residual (an effect the model lacks) projected on it makes a
/// move of decimetres look determined. Exact gauges lie at rounding (10⁻¹⁵); one socket of an
/// iiwa 14 (no socket distance, so no scale) leaves directions at 7·10⁻⁵ to 6·10⁻⁴ that its
/// geometric residual moves by 210 ± 26 mm; the UR5e description's upper arm on the UR10e
/// recording, the weakest direction another robot's lengths were found in, lies at 0.024.
pub(crate) const SEEN_SINGULAR_VALUE: f64 = 1e-3;

/// The lengths `held` (layout indices of `p`: lengths the final fit held at their nominal
/// values, pruned as not identifiable or not free in the model) fitted at the estimate `x` of
/// the parameters `kept` (layout indices, the fit's free set): one Gauss–Newton step over
/// `kept` and `held` together, from `x`. Columns are scaled to unit norm; the step of the
/// `held` columns' components orthogonal to the `kept` ones is their pseudo-inverse's,
/// directions the data do not see at all (a singular value below [`SEEN_SINGULAR_VALUE`],
/// exact gauges such as a base height a free instrument frame absorbs) left out, so that the
/// `held` part is the minimum-norm move; the `kept` parameters follow it.
///
/// Entries, `held` then `report` (layout indices of kept parameters to report too): the
/// parameter's name, its deviation from nominal after the step (`value`: `x` plus the step,
/// in its unit) and its standard deviation in the joint fit (`std`, from `sigma`, the residual
/// noise in `p`'s residual units). A parameter whose column is zero is left out. Empty when
/// `held` is, when the Jacobian has more than [`REFIT_MAX_ENTRIES`] entries or cannot be
/// evaluated, or when the `kept` columns are singular. Source: the Schur complement of the
/// partitioned normal equations, Björck, *Numerical Methods for Least Squares Problems*,
/// SIAM 1996, §2.7.
pub(crate) fn refitted_lengths(
    p: &impl hapcal_identify::Problem,
    x: faer::ColRef<'_, f64>,
    sigma: f64,
    kept: &[usize],
    held: &[usize],
    report: &[usize],
) -> Vec<crate::report::ParamReport> {
    use nalgebra::{DMatrix, DVector};
    let (m, n) = (p.n_residuals(), p.layout().len());
    if held.is_empty() || m.saturating_mul(n) > REFIT_MAX_ENTRIES || x.nrows() != n {
        return Vec::new();
    }
    let mut r = faer::Col::<f64>::zeros(m);
    let mut jac = faer::Mat::<f64>::zeros(m, n);
    if p.residuals(x, r.as_mut()).is_err() || p.jacobian(x, jac.as_mut()).is_err() {
        return Vec::new();
    }
    let norm = |j: usize| jac.col(j).norm_l2();
    let seen = |j: usize| j < n && norm(j) > 0.0 && norm(j).is_finite();
    let held: Vec<usize> = held.iter().copied().filter(|&j| seen(j)).collect();
    let kept: Vec<usize> = kept.iter().copied().filter(|&j| seen(j)).collect();
    if held.is_empty() {
        return Vec::new();
    }
    let cols: Vec<usize> = kept.iter().chain(&held).copied().collect();
    let scale: Vec<f64> = cols.iter().map(|&j| norm(j)).collect();
    let q = cols.len();
    let a = faer::Mat::<f64>::from_fn(m, q, |i, k| jac[(i, cols[k])] / scale[k]);
    let gram = a.transpose() * &a;
    let at_r = a.transpose() * &r;
    let g = DMatrix::from_fn(q, q, |i, k| gram[(i, k)]);
    let h = DVector::from_fn(q, |i, _| at_r[i]);
    let (nk, nh) = (kept.len(), held.len());
    let g_kk = g.view((0, 0), (nk, nk)).into_owned();
    let g_kh = g.view((0, nk), (nk, nh)).into_owned();
    let h_k = h.rows(0, nk).into_owned();
    // G_KK⁻¹ (identity-sized zero without kept columns).
    let g_kk_inv = if nk == 0 {
        DMatrix::zeros(0, 0)
    } else {
        match g_kk.cholesky() {
            Some(c) => c.inverse(),
            None => return Vec::new(),
        }
    };
    // The held columns with the kept columns' span taken out, by the kept columns' thin QR
    // (orthogonal projection to working precision: the normal equations' Schur complement
    // would lose the exact gauges, whose singular values are rounding, in its squared
    // condition), then their SVD.
    let a_h = a.subcols(nk, nh).to_owned();
    let projected = if nk == 0 {
        a_h
    } else {
        let basis = a.subcols(0, nk).qr().compute_thin_Q();
        let coefficients = basis.transpose() * &a_h;
        &a_h - &basis * &coefficients
    };
    let p_h = DMatrix::from_fn(m, nh, |i, k| projected[(i, k)]);
    let r_vec = DVector::from_fn(m, |i, _| r[i]);
    // P_hᵀ·r: the held columns' part of the normal equations with the kept ones eliminated.
    let rhs = p_h.transpose() * &r_vec;
    let svd = nalgebra::SVD::new(p_h, false, true);
    let Some(v_t) = svd.v_t else {
        return Vec::new();
    };
    let mut pinv = DMatrix::<f64>::zeros(nh, nh);
    for (k, &sv) in svd.singular_values.iter().enumerate() {
        if sv > SEEN_SINGULAR_VALUE {
            let v = v_t.row(k).transpose();
            pinv += &v * v.transpose() / (sv * sv);
        }
    }
    let step_h = -(&pinv * rhs);
    let step_k = -(&g_kk_inv * (&h_k + &g_kh * &step_h));
    // Joint covariance of the kept part: G_KK⁻¹ + G_KK⁻¹·G_KH·S⁺·G_HK·G_KK⁻¹ (scaled units).
    let coupling = &g_kk_inv * &g_kh;
    let cov_kk = &g_kk_inv + &coupling * &pinv * coupling.transpose();
    let entry = |j: usize, step: f64, var: f64, k: usize| crate::report::ParamReport {
        name: p.layout().name(j).to_owned(),
        value: x[j] + step / scale[k],
        std: sigma * var.max(0.0).sqrt() / scale[k],
        unit: p.layout().spec(j).unit.symbol(),
    };
    let held_entries =
        (held.iter().enumerate()).map(|(k, &j)| entry(j, step_h[k], pinv[(k, k)], nk + k));
    let kept_entries = (kept.iter().enumerate())
        .filter(|(_, j)| report.contains(j))
        .map(|(k, &j)| entry(j, step_k[k], cov_kk[(k, k)], k));
    held_entries.chain(kept_entries).collect()
}

/// The pruned parameters of `identified`, each with why.
pub fn pruned_report(identified: &Identified) -> Vec<PrunedReport> {
    identified
        .identifiability
        .pruned
        .iter()
        .map(|p| {
            let (reason, depends_on) = match &p.reason {
                PruneReason::NearZeroColumn => (PruneCause::NearZeroColumn, Vec::new()),
                PruneReason::Dependent { on } => (PruneCause::Dependent, on.clone()),
                PruneReason::AtBound => (PruneCause::AtZero, Vec::new()),
                _ => (PruneCause::Insensitive, Vec::new()),
            };
            PrunedReport {
                name: p.name.clone(),
                reason,
                depends_on,
                std_if_kept: p.std_if_kept,
            }
        })
        .collect()
}

/// The compliance estimates of `identified` (every value a record names as a compliance:
/// `compliance.*`, `transversal.*`, `joint_compliance.j*`) below zero by more than
/// [`hapcal_contract::negative_compliance_sigmas`] of their count standard deviations, most
/// significant first: `(name, value, σ)` in the parameter's unit (rad/(N·m) or rad/m); with
/// the number of compliance estimates the bound was taken over. `std_scale` multiplies the
/// identification's σ: `√(rows / distinct rows)` when rows repeat (a copy adds no
/// information, but the least-squares covariance counts it), else 1.
pub(crate) fn negative_compliances(
    identified: &Identified,
    std_scale: f64,
) -> (Vec<(String, f64, f64)>, usize) {
    let compliances: Vec<(String, f64, f64)> = free_compliances(identified)
        .map(|(i, value, std)| (identified.layout.name(i).to_owned(), value, std * std_scale))
        .collect();
    let n = compliances.len();
    let z = hapcal_contract::negative_compliance_sigmas(n);
    let mut negative: Vec<(String, f64, f64)> = (compliances.into_iter())
        .filter(|(_, value, std)| value + z * std < 0.0)
        .collect();
    let score = |c: &(String, f64, f64)| c.1 / c.2.max(f64::MIN_POSITIVE);
    negative.sort_by(|a, b| score(a).total_cmp(&score(b)));
    (negative, n)
}

/// The compliances among the free parameters of `identified`, in the covariance's order:
/// `(layout index, estimate, σ)` (units of the compliance: rad/(N·m) or rad/m).
fn free_compliances(identified: &Identified) -> impl Iterator<Item = (usize, f64, f64)> + '_ {
    (identified.covariance.free.iter())
        .zip(identified.covariance.std())
        .filter(|&(&i, _)| {
            hapcal_contract::ValueName::parse(identified.layout.name(i))
                .is_ok_and(|v| v.is_compliance())
        })
        .map(|(&i, std)| (i, identified.fit.x[i], std))
}

/// The compliance estimates of `identified` below zero, as `(layout index, σ)`: those
/// [`hold_compliances_at_zero`] holds.
fn compliances_below_zero(identified: &Identified) -> Vec<(usize, f64)> {
    free_compliances(identified)
        .filter(|&(_, value, _)| value < 0.0)
        .map(|(i, _, std)| (i, std))
        .collect()
}

/// The covariance of a fit with compliances held at zero (`held_fit`; the held ones' layout
/// indices and σ in the fit that had them free, `held`) as the fit that had them free gives
/// it (`free`): its block over `held_fit`'s free parameters and the held ones, in layout
/// order (`layout` names them), when `free` has every one of them. A held compliance is not
/// known to be zero, only not below it: it is recorded as 0 ± its σ in the free fit, and the
/// others are no better known than the data tell them with the held ones free; predictions
/// through this
/// covariance carry the held compliances' uncertainty and their correlation with the others.
/// When `held_fit` keeps a parameter `free` pruned (one the data could not tell from a held
/// compliance), `held_fit`'s own covariance with each held compliance added at its σ,
/// uncorrelated.
fn bounded_covariance(
    free: &hapcal_identify::Covariance,
    held_fit: hapcal_identify::Covariance,
    held: &[(usize, f64)],
    layout: &hapcal_identify::ParamLayout,
) -> hapcal_identify::Covariance {
    let mut order: Vec<usize> = (held_fit.free.iter().copied())
        .chain(held.iter().map(|&(i, _)| i))
        .collect();
    order.sort_unstable();
    order.dedup();
    let position: Option<Vec<usize>> = (order.iter())
        .map(|i| free.free.iter().position(|j| j == i))
        .collect();
    if let Some(position) = position {
        return hapcal_identify::Covariance {
            matrix: faer::Mat::from_fn(position.len(), position.len(), |a, b| {
                free.matrix[(position[a], position[b])]
            }),
            names: (order.iter()).map(|&i| layout.name(i).to_owned()).collect(),
            free: order,
        };
    }
    // Each parameter's row in `held_fit`'s matrix, or its held σ.
    let source: Vec<Result<usize, f64>> = (order.iter())
        .map(|i| match held_fit.free.iter().position(|j| j == i) {
            Some(a) => Ok(a),
            None => Err(held
                .iter()
                .find(|&&(h, _)| h == *i)
                .map_or(0.0, |&(_, s)| s)),
        })
        .collect();
    let names = (order.iter()).map(|&i| layout.name(i).to_owned()).collect();
    hapcal_identify::Covariance {
        matrix: faer::Mat::from_fn(order.len(), order.len(), |a, b| {
            match (source[a], source[b]) {
                (Ok(x), Ok(y)) => held_fit.matrix[(x, y)],
                (Err(s), Err(_)) if a == b => s * s,
                _ => 0.0,
            }
        }),
        names,
        free: order,
    }
}

/// The physical bound compliance ≥ 0 on the identification `free_fit` of `problem` (`cfg` its
/// configuration): when none of its compliances is below zero by more than
/// [`negative_compliances`]' bound (that is a stop, [`implausible_estimates`], judged on the
/// fit with every compliance free), those below zero are held at zero and the others
/// refitted from the estimate ([`hapcal_identify::identify_held`]), again until none is
/// below zero: each held one is reported among the pruned parameters, at zero, with its σ
/// in the fit that had it free, and the covariance is that fit's ([`bounded_covariance`]: a
/// held compliance is 0 ± that σ, written so in the record). `free_fit` itself when no
/// compliance is below zero or one is significantly. `std_scale` as [`negative_compliances`]' (rows that repeat others add no
/// information, so they do not make a compliance significantly negative).
///
/// # Errors
/// As [`hapcal_identify::identify`] for a refit.
pub(crate) fn hold_compliances_at_zero(
    problem: &(impl hapcal_identify::Problem + Sync),
    cfg: &hapcal_identify::IdentifyConfig,
    free_fit: Identified,
    std_scale: impl FnOnce() -> f64,
) -> Result<Identified, hapcal_identify::Error> {
    let mut more = compliances_below_zero(&free_fit);
    if more.is_empty() || !negative_compliances(&free_fit, std_scale()).0.is_empty() {
        return Ok(free_fit);
    }
    let free_covariance = free_fit.covariance.clone();
    let mut id = free_fit;
    let mut held: Vec<(usize, f64)> = Vec::new();
    while !more.is_empty() {
        let mut start = id.fit.x.clone();
        for &(i, _) in &more {
            start[i] = 0.0;
        }
        held.extend(more);
        id = hapcal_identify::identify_held(problem, start, cfg, &held)?;
        more = compliances_below_zero(&id);
    }
    id.covariance = bounded_covariance(&free_covariance, id.covariance, &held, &id.layout);
    Ok(id)
}

/// "`k` of `n` below zero by more than z standard deviations: name value ± σ unit, …" for the
/// report's words on [`negative_compliances`]' result; values in µ`unit` (`unit` is
/// `rad/(N·m)` or `rad/m`), the three most significant listed.
pub(crate) fn negative_compliance_words(
    negative: &[(String, f64, f64)],
    n_compliances: usize,
    unit: &str,
) -> String {
    let listed: Vec<String> = (negative.iter().take(3))
        .map(|(name, value, std)| format!("{name} {:.0} ± {:.0} µ{unit}", value * 1e6, std * 1e6))
        .collect();
    let more = if negative.len() > 3 { ", …" } else { "" };
    format!(
        "{} of {n_compliances} below zero by more than {:.1} standard deviations: {}{more}",
        negative.len(),
        hapcal_contract::negative_compliance_sigmas(n_compliances),
        listed.join(", ")
    )
}

/// What no real device can be, in any workflow's fit of `rung` ([`crate::report::Implausible`]):
/// an unconverged fit (its estimate is the last iterate, not a minimum), and compliances
/// below zero beyond the bound ([`negative_compliances`]; `unit` and `std_scale` as there).
/// `given`: the
/// rung was asked for with `--model` (the fix names `--model auto`). A mounting is not
/// tested here: the measurement workflow does it where gravity is an option.
pub(crate) fn implausible_estimates(
    identified: &Identified,
    rung: crate::model::ModelName,
    given: bool,
    unit: &str,
    std_scale: f64,
) -> Vec<crate::report::Implausible> {
    use crate::report::{Implausible, ImplausibleKind};
    let mut out = Vec::new();
    if let Some(i) = unconverged(identified, rung, given) {
        out.push(i);
    }
    let (negative, n) = negative_compliances(identified, std_scale);
    if !negative.is_empty() {
        out.push(Implausible {
            kind: ImplausibleKind::NegativeCompliance,
            message: format!(
                "the compliances of the {rung} model are negative ({}): a joint does not bend \
                 against its load; the model absorbs an effect it lacks or a setup mistake",
                negative_compliance_words(&negative, n, unit)
            ),
            fix: "check the device's masses and mounting, or give a model without compliance \
                  (--model geometric)"
                .to_owned(),
        });
    }
    out
}

/// An unconverged fit of `rung` as an implausible estimate ([`implausible_estimates`]), or
/// `None` when the fit converged.
pub(crate) fn unconverged(
    identified: &Identified,
    rung: crate::model::ModelName,
    given: bool,
) -> Option<crate::report::Implausible> {
    let fit = &identified.fit;
    if fit.termination.is_success() {
        return None;
    }
    Some(crate::report::Implausible {
        kind: crate::report::ImplausibleKind::Unconverged,
        message: format!(
            "the least-squares fit of the {rung} model stopped after {} evaluations, {}: its \
             estimate is the last iterate, not a minimum",
            fit.n_evaluations,
            termination_text(&fit.termination)
        ),
        fix: if given {
            format!(
                "give a simpler --model than {rung} (or --model auto, which keeps the highest \
                 model whose fit converged)"
            )
        } else {
            "give a simpler --model".to_owned()
        },
    })
}

#[cfg(test)]
mod tests {
    use super::{
        CV_REPEATS, blocked_folds, first_repeat_blocks, fold_of, folds_of_rows, originals,
    };

    #[test]
    fn a_long_logs_ladder_sample_is_spread_over_every_log_and_under_the_cap() {
        assert_eq!(super::ladder_sample(&[300, 200], 500), None);
        for (lengths, cap) in [
            (vec![1_000_000], 20_000),
            (vec![100_001], 20_000),
            (vec![7, 50_000, 3, 12_345], 1_000),
            (vec![20_001], 20_000),
        ] {
            let n: usize = lengths.iter().sum();
            let s = super::ladder_sample(&lengths, cap).expect("more rows than the cap");
            assert!(s.rows.len() <= cap, "{lengths:?}: {} rows", s.rows.len());
            // The smallest stride: one less would exceed the cap.
            assert!(s.stride >= 2, "{lengths:?}: stride {}", s.stride);
            let more: usize = lengths.iter().map(|l| l.div_ceil(s.stride - 1)).sum();
            assert!(more > cap, "{lengths:?}: stride {}", s.stride);
            assert_eq!(s.lengths.iter().sum::<usize>(), s.rows.len());
            assert!(s.rows.windows(2).all(|w| w[0] < w[1]) && s.rows.last() < Some(&n));
            // Each log's first row is sampled, and its rows are its own.
            let mut start = 0;
            let mut taken = 0;
            for (&len, &kept) in lengths.iter().zip(&s.lengths) {
                let own = &s.rows[taken..taken + kept];
                assert_eq!(own.first(), Some(&start));
                assert!(own.iter().all(|&i| (start..start + len).contains(&i)));
                assert!(own.windows(2).all(|w| w[1] - w[0] == s.stride));
                start += len;
                taken += kept;
            }
        }
    }

    #[test]
    fn copies_fall_in_the_fold_of_the_row_they_copy_in_every_repeat() {
        // 13 distinct rows, then the file appended again, then two more copies of row 4.
        let keys: Vec<u32> = (0..13).chain(0..13).chain([4, 4]).collect();
        let original = originals(keys.iter().copied());
        assert_eq!(original[13..26], (0..13).collect::<Vec<_>>()[..]);
        assert_eq!(original[26..], [4, 4]);
        assert_eq!(super::n_copies(&original), 15);
        let k = 5;
        for r in 0..CV_REPEATS {
            let folds = folds_of_rows(&original, k, r, CV_REPEATS);
            for (row, &o) in original.iter().enumerate() {
                assert_eq!(folds[row], folds[o], "repeat {r}, row {row}");
            }
            // The distinct rows are cut as 13 rows without copies would be.
            for (row, &fold) in folds.iter().enumerate().take(13) {
                assert_eq!(fold, fold_of(row, 13, k, r, CV_REPEATS));
            }
        }
        // Every row held out exactly once per repeat, copies with their originals.
        let sets = vec![original.clone(), (0..7).collect()];
        let folds = blocked_folds(&sets, k);
        assert_eq!(folds.len(), CV_REPEATS * k);
        for rep in folds.chunks(k) {
            for (set, rows) in sets.iter().enumerate() {
                for row in 0..rows.len() {
                    assert_eq!(rep.iter().filter(|f| f[set][row]).count(), 1);
                }
            }
        }
        let blocks = first_repeat_blocks(&sets, k);
        assert_eq!(blocks[13], blocks[0]);
        assert_eq!(blocks[27], blocks[4]);
        assert_eq!(blocks[original.len()], k, "the second set's first block");
    }

    #[test]
    fn without_copies_the_folds_are_plain_blocked_folds() {
        let (n, k) = (23, 4);
        let own: Vec<usize> = (0..n).collect();
        for r in 0..CV_REPEATS {
            let expected: Vec<usize> = (0..n)
                .map(|row| fold_of(row, n, k, r, CV_REPEATS))
                .collect();
            assert_eq!(folds_of_rows(&own, k, r, CV_REPEATS), expected);
        }
    }
}

#[cfg(test)]
mod bound_tests {
    use faer::{Col, Mat};
    use hapcal_identify::{
        IdentifyConfig, LinearProblem, ParamLayout, ParamSpec, PruneReason, Role, Subset, Unit,
        identify,
    };
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    use super::{bounded_covariance, hold_compliances_at_zero, negative_compliances};

    /// The covariance reported with compliance 1 held: the free fit's block over the kept
    /// parameters and the held one; when the refit keeps parameter 2, which the free fit
    /// pruned, the refit's own covariance with the held one at its σ, uncorrelated.
    #[test]
    fn a_held_compliance_stays_in_the_covariance_at_its_free_sigma() {
        let spec = |name: &str| ParamSpec {
            name: name.to_owned(),
            unit: Unit::RadianPerNewtonMeter,
            role: Role::Model,
        };
        let layout = ParamLayout::new(vec![spec("a"), spec("compliance.b"), spec("c")]);
        let covariance = |free: Vec<usize>, m: &[f64]| {
            let n = free.len();
            hapcal_identify::Covariance {
                names: free.iter().map(|&i| layout.name(i).to_owned()).collect(),
                free,
                matrix: Mat::from_fn(n, n, |a, b| m[a * n + b]),
            }
        };
        let free = covariance(vec![0, 1], &[4.0, 1.0, 1.0, 9.0]);
        let within = bounded_covariance(&free, covariance(vec![0], &[2.0]), &[(1, 3.0)], &layout);
        assert_eq!(within.free, [0, 1]);
        assert_eq!(within.names, ["a", "compliance.b"]);
        assert_eq!(within.matrix, free.matrix);
        let refit = covariance(vec![0, 2], &[2.0, 0.5, 0.5, 5.0]);
        let beyond = bounded_covariance(&free, refit, &[(1, 3.0)], &layout);
        assert_eq!(beyond.free, [0, 1, 2]);
        assert_eq!(beyond.names, ["a", "compliance.b", "c"]);
        let expected = [2.0, 0.0, 0.5, 0.0, 9.0, 0.0, 0.5, 0.0, 5.0];
        assert_eq!(
            beyond.matrix,
            Mat::from_fn(3, 3, |a, b| expected[a * 3 + b])
        );
    }

    /// 40 rows, noise 1e-3 per row: a joint offset (rad) and two compliances (rad/(N·m))
    /// under torques of about 10 N·m, the second's truth `c2`.
    fn problem(c2: f64) -> LinearProblem {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(47);
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        let a = Mat::from_fn(40, 3, |_, j| if j == 0 { 1.0 } else { 10.0 } * normal());
        let truth = Col::from_fn(3, |j| [2e-3, 1e-4, c2][j]);
        let y = &a * &truth + Col::from_fn(40, |_| 1e-3 * normal());
        let spec = |name: &str, unit| ParamSpec {
            name: name.to_owned(),
            unit,
            role: Role::Model,
        };
        LinearProblem {
            layout: ParamLayout::new(vec![
                spec("j1.offset", Unit::Radian),
                spec("compliance.j1", Unit::RadianPerNewtonMeter),
                spec("compliance.j2", Unit::RadianPerNewtonMeter),
            ]),
            a,
            y,
        }
    }

    #[test]
    fn a_compliance_below_zero_within_the_noise_is_held_at_zero_and_reported() {
        // The second compliance's truth, −2.5e-5, is some 1.5 σ below zero (σ ≈ 1e-3/(10·√40)
        // ≈ 1.6e-5): this seed's noise puts its free estimate below zero, within the bound.
        let p = problem(-2.5e-5);
        let cfg = IdentifyConfig::default();
        let free = identify(&p, Col::zeros(3), &cfg).expect("valid");
        assert!(free.fit.x[2] < 0.0, "{}", free.fit.x[2]);
        assert!(negative_compliances(&free, 1.0).0.is_empty());
        let free_std = free.std("compliance.j2").expect("kept");
        let free_offset_std = free.std("j1.offset").expect("kept");
        let held = hold_compliances_at_zero(&p, &cfg, free, || 1.0).expect("valid");
        assert_eq!(held.fit.x[2], 0.0);
        let at_zero = held
            .identifiability
            .find_pruned("compliance.j2")
            .expect("reported");
        assert_eq!(at_zero.reason, PruneReason::AtBound);
        assert_eq!(at_zero.std_if_kept, free_std);
        // Bounded, not known: it stays in the covariance at its σ in the free fit, beside
        // the others' block of that fit.
        assert_eq!(held.covariance.free, [0, 1, 2]);
        assert_eq!(held.std("compliance.j2"), Some(free_std));
        assert_eq!(held.std("j1.offset"), Some(free_offset_std));
        // The others are the fit of the problem without it.
        let without = Subset::new(&p, vec![0, 1], Col::zeros(3));
        let reference = identify(&without, without.initial_free(), &cfg).expect("valid");
        for k in 0..2 {
            assert!((held.fit.x[k] - reference.fit.x[k]).abs() < 1e-12, "{k}");
        }
    }

    #[test]
    fn a_compliance_significantly_below_zero_is_left_for_the_stop() {
        // Truth −1e-3, some 60 σ below zero: beyond the bound, the fit is returned as it is
        // and the implausible-estimate stop sees it.
        let p = problem(-1e-3);
        let cfg = IdentifyConfig::default();
        let free = identify(&p, Col::zeros(3), &cfg).expect("valid");
        assert_eq!(negative_compliances(&free, 1.0).0.len(), 1);
        let x = free.fit.x.clone();
        let same = hold_compliances_at_zero(&p, &cfg, free, || 1.0).expect("valid");
        assert_eq!(same.fit.x, x);
        assert!(same.identifiability.find_pruned("compliance.j2").is_none());
    }
}
