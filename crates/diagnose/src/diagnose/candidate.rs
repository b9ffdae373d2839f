//! One candidate's test against a round's baseline: its signature beside the baseline (what
//! is visible, what the baseline absorbs), the refit with its visible terms and their
//! in-sample F-test, and the held-out check.

use hapcal_contract::Effect;
use nalgebra::{DMatrix, DVector};

use super::VISIBLE_TOL;
use super::baseline::Fit;
use super::cv::cross_validate;
use super::{Candidate, ParamValue};
use crate::model::{Data, Linear, Setup, State, Term};
use crate::solve::{lstsq, refine};
use crate::stats::f_sf;
use crate::stats::mean;

/// What the candidates of one round are tested against.
pub(super) struct Round<'a> {
    pub(super) setup: &'a Setup,
    pub(super) data: &'a Data,
    /// The fit with the effects accepted before this round.
    pub(super) fit: &'a Fit,
    /// The round, 1-based.
    pub(super) round: usize,
    pub(super) folds: usize,
}

/// One candidate tested.
pub(super) struct Tested {
    pub(super) cand: Candidate,
    /// Its visible terms.
    pub(super) terms: Vec<Term>,
    /// Its visible columns' fit of the round's residual (beside the baseline), per sample.
    pub(super) fitted: DVector<f64>,
    /// The F-test's p-value, before Holm.
    pub(super) p_raw: f64,
    /// Whether the held-out RMS beats the round's by one standard error.
    pub(super) cv_ok: bool,
    /// Share of the round's held-out gap it closes.
    pub(super) share: f64,
}

/// Tests `effect`'s `terms` against the round; `Err` with the reason if the model cannot take
/// them.
pub(super) fn test_candidate(
    r: &Round<'_>,
    effect: Effect,
    terms: Vec<Term>,
) -> Result<Tested, String> {
    let n = r.data.n_rows();
    let base = &r.fit.base;
    let sig = signature(r, &terms)?;
    let mut cand = candidate(r, effect, &sig);
    let kept_terms: Vec<Term> = sig.visible.iter().map(|&c| terms[c].clone()).collect();
    if sig.visible.is_empty() {
        cand.reason = format!(
            "indistinguishable from baseline parameters {}",
            if sig.absorbed_by.is_empty() {
                "(zero signature)".to_owned()
            } else {
                sig.absorbed_by.join(", ")
            }
        );
        return Ok(Tested {
            cand,
            terms: kept_terms,
            fitted: DVector::zeros(n),
            p_raw: 1.0,
            cv_ok: false,
            share: 0.0,
        });
    }
    let proj = sig.qc.transpose() * &base.r_perp;
    let fitted_all = &sig.qc * proj;
    let fitted = DVector::from_iterator(n, (0..n).map(|i| fitted_all[i]));
    let refit = refit(r, &terms, &sig.visible)?;
    cand.bic_gain = refit.bic_gain;
    cand.parameters = refit.parameters;
    let held = held_out(r, &refit.lin, sig.visible.len());
    cand.heldout_rms_after_m = held.rms_after_m;
    cand.gap_closed_pct = 100.0 * held.share.clamp(-9.99, 9.99);
    Ok(Tested {
        cand,
        terms: kept_terms,
        fitted,
        p_raw: refit.p_raw,
        cv_ok: held.cv_ok,
        share: held.share,
    })
}

/// The candidate's report before its refit: the round's held-out RMS on both sides, its
/// signature, rejected until judged.
fn candidate(r: &Round<'_>, effect: Effect, sig: &Signature) -> Candidate {
    let before = r.fit.base.cv.mse().sqrt();
    Candidate {
        effect,
        round: r.round,
        heldout_rms_before_m: before,
        heldout_rms_after_m: before,
        gap_closed_pct: 0.0,
        accepted: false,
        reason: String::new(),
        parameters: Vec::new(),
        p_value: 1.0,
        n_visible: sig.visible.len(),
        visible_fraction: sig.visible_fraction.clone(),
        absorbed_by: sig.absorbed_by.clone(),
        bic_gain: 0.0,
    }
}

/// A candidate's columns beside the round's baseline.
struct Signature {
    /// Orthonormal basis of the visible columns' parts orthogonal to the baseline.
    qc: DMatrix<f64>,
    /// The visible (not absorbed) terms.
    visible: Vec<usize>,
    /// Per term, the fraction of its column's norm left after projecting out the baseline.
    visible_fraction: Vec<f64>,
    /// Baseline parameters that carry the absorbed terms (the two largest shares of each).
    absorbed_by: Vec<String>,
}

/// The candidate's `terms` linearised at the round's state and set beside its baseline.
fn signature(r: &Round<'_>, terms: &[Term]) -> Result<Signature, String> {
    let base = &r.fit.base;
    let k_all = terms.len();
    let beside = r.fit.beside(r.setup, terms.to_vec(), VISIBLE_TOL);
    let (lin, c_all, qc, picked) = beside.map_err(|e| e.to_string())?;
    let visible: Vec<usize> = (0..k_all).filter(|&c| picked[c].is_some()).collect();
    let visible_fraction: Vec<f64> = (0..k_all)
        .map(|c| {
            let col = c_all.column(c);
            let nrm = col.norm();
            if nrm == 0.0 {
                return 0.0;
            }
            let perp = col - &base.q * (base.q.transpose() * col);
            perp.norm() / nrm
        })
        .collect();
    // A zero column is absorbed by nothing.
    let zero = |c: usize| visible_fraction[c] == 0.0 && c_all.column(c).norm() == 0.0;
    let absorbed: Vec<usize> = (0..k_all)
        .filter(|&c| picked[c].is_none() && !zero(c))
        .collect();
    let absorbed_by = absorbed_by(r, &lin, &c_all, &absorbed);
    Ok(Signature {
        qc,
        visible,
        visible_fraction,
        absorbed_by,
    })
}

/// Which baseline parameters carry the `absorbed` columns of `c_all`: the two largest
/// contributions to each, in order, without repeats.
fn absorbed_by(
    r: &Round<'_>,
    lin: &Linear,
    c_all: &DMatrix<f64>,
    absorbed: &[usize],
) -> Vec<String> {
    let base = &r.fit.base;
    let mut names = Vec::new();
    for &c in absorbed {
        let jb = lin.j.select_columns(&base.cols);
        let (coef, _) = lstsq(&jb, &c_all.column(c).into_owned());
        let mut contrib: Vec<(f64, usize)> = (0..base.cols.len())
            .map(|k| (coef[k].abs() * jb.column(k).norm(), base.cols[k]))
            .collect();
        contrib.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (_, col) in contrib.iter().take(2) {
            let name = base.lin.names.get(*col).cloned().unwrap_or_default();
            if !names.contains(&name) {
                names.push(name);
            }
        }
    }
    names
}

/// The in-sample fit of the visible terms with the baseline.
struct Refit {
    /// The model linearised at the refined state.
    lin: Linear,
    p_raw: f64,
    bic_gain: f64,
    parameters: Vec<ParamValue>,
}

/// Nonlinear refit with the `visible` terms: an effect the baseline mostly absorbs moves the
/// baseline's parameters far, and only a refit sees what is left. Then the F-test of the
/// added parameters and the BIC gain.
fn refit(r: &Round<'_>, terms: &[Term], visible: &[usize]) -> Result<Refit, String> {
    let (base, state) = (&r.fit.base, &r.fit.state);
    let n_base_cols = base.lin.j.ncols();
    let k = visible.len() as f64;
    let mut s_vis = state.clone();
    s_vis
        .terms
        .extend(visible.iter().map(|&c| (terms[c].clone(), 0.0)));
    let (s_vis, lin) = refine(r.setup, s_vis, 10).map_err(|e| e.to_string())?;
    let mut cols = base.cols.clone();
    cols.extend((0..visible.len()).map(|c| n_base_cols + c));
    let a = lin.j.select_columns(&cols);
    let (x, cov) = lstsq(&a, &lin.r);
    let n_rows = base.lin.r.len() as f64;
    let rss_c = (&lin.r - &a * &x).norm_squared().max(1e-300);
    let drss = (base.rss - rss_c).max(0.0);
    let dof = (base.dof() - k).max(1.0);
    let f = (drss / k) / (rss_c / dof);
    let s2 = (rss_c / dof).max(1.0);
    let parameters = visible
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            let idx = base.cols.len() + i;
            ParamValue {
                name: terms[c].name.clone(),
                value: added_value(state, &s_vis, i) + x[idx],
                std: (cov[(idx, idx)] * s2).sqrt(),
                unit: terms[c].unit.to_owned(),
            }
        })
        .collect();
    Ok(Refit {
        lin,
        p_raw: f_sf(f, k, dof),
        bic_gain: drss - k * n_rows.ln(),
        parameters,
    })
}

/// The value of the `i`-th term added to `state` in `refined`.
fn added_value(state: &State, refined: &State, i: usize) -> f64 {
    refined
        .terms
        .get(state.terms.len() + i)
        .map_or(0.0, |(_, v)| *v)
}

/// The held-out check of a refit.
struct HeldOut {
    rms_after_m: f64,
    cv_ok: bool,
    share: f64,
}

/// The held-out errors with the `k` visible columns of `lin` beside the baseline's: whether
/// they beat the round's by one standard error of the mean weighted improvement, and the
/// share of the round's gap they close.
fn held_out(r: &Round<'_>, lin: &Linear, k: usize) -> HeldOut {
    let base = &r.fit.base;
    let n = r.data.n_rows();
    let gap2 = base.cv.mse() - base.cv.floor();
    let cvis = lin.j.columns(base.lin.j.ncols(), k).into_owned();
    let cv = cross_validate(lin, &base.cols, Some(&cvis), r.folds, n);
    let d: Vec<f64> = (0..n)
        .map(|i| (base.cv.e[i].powi(2) - cv.e[i].powi(2)) / cv.sigma2[i].max(1e-300))
        .collect();
    let md = mean(d.iter().copied());
    let sd = (d.iter().map(|v| (v - md).powi(2)).sum::<f64>() / (n as f64 - 1.0).max(1.0)).sqrt();
    let share = if gap2 > 0.0 {
        (base.cv.mse() - cv.mse()) / gap2
    } else {
        0.0
    };
    HeldOut {
        rms_after_m: cv.mse().sqrt(),
        cv_ok: md > sd / (n as f64).sqrt(),
        share,
    }
}
