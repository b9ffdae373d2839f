//! Which: the library's candidates tested round by round against the baseline with the
//! effects accepted before them (F-test with Holm over the round, BIC, held-out check, share
//! of the round's gap), the best accepted one refitted with the baseline, and the next round
//! started from there while a significant gap remains.

use hapcal_calibrate::model::ModelName;
use hapcal_contract::Effect;
use hapcal_io::Device;
use rayon::prelude::*;

use super::baseline::{Baseline, Fit, baseline_error};
use super::candidate::{Round, Tested, test_candidate};
use super::cv::Base;
use super::terms::candidate_terms;
use super::{Candidate, DiagnoseConfig, ParamValue, Step};
use crate::Error;
use crate::model::{State, Term};
use crate::solve::{lstsq, refine};
use crate::stats::{chi2_sf, cosine, holm};
use crate::verdict::RoundShare;

/// Cosine of two candidates' fits of the round's residual above which they are reported as
/// confusable with each other.
const CONFUSABLE_COSINE: f64 = 0.9;

/// The which stage's output.
pub(super) struct Run {
    /// The fit with the accepted effects.
    pub(super) fit: Fit,
    /// Every candidate of every round.
    pub(super) candidates: Vec<Candidate>,
    /// Accepted effects in order, and how far each shrinks the residual.
    pub(super) steps: Vec<Step>,
    pub(super) accepted: Vec<Effect>,
    /// Per accepted effect, what it closes of the gap its round faced.
    pub(super) shares: Vec<RoundShare>,
    /// The candidates that cannot be tested on this log, and why.
    pub(super) notes: Vec<String>,
}

/// The rounds, from the baseline's `fit`, up to `cfg.max_effects`.
///
/// # Errors
/// [`Error::Baseline`] if a winner's refit with the baseline fails.
pub(super) fn select(
    device: &Device,
    b: &Baseline,
    fit: Fit,
    cfg: &DiagnoseConfig,
) -> Result<Run, Error> {
    let library = library(device, b.model);
    let mut run = Run {
        fit,
        candidates: Vec::new(),
        steps: Vec::new(),
        accepted: Vec::new(),
        shares: Vec::new(),
        notes: Vec::new(),
    };
    let mut gap_significant = b.gap.significant;
    for round in 1..=cfg.max_effects {
        let mut tested = test_round(device, b, &mut run, &library, round, cfg.folds);
        judge(&mut tested, gap_significant, cfg);
        let Some((w, confusable)) = rank(&mut tested) else {
            run.candidates.extend(tested.into_iter().map(|t| t.cand));
            break;
        };
        gap_significant = accept(b, &mut run, tested, w, confusable, cfg)?;
        // Another round while what is left is significantly above the floor: a second
        // effect is judged by the gap the first one left, however small a share of the
        // original gap that is.
        if !gap_significant {
            break;
        }
    }
    Ok(run)
}

/// The candidates: the simulator's library, and with the geometric baseline the paper's
/// capstan and parallelogram models of a device that has them.
fn library(device: &Device, model: ModelName) -> Vec<Effect> {
    let mut library = hapcal_sim::HAPTIC_LIBRARY.to_vec();
    if model == ModelName::Geometric && !device.capstans.is_empty() {
        library.push(Effect::Capstans);
        if device.parallelogram.is_some() {
            library.push(Effect::Parallelogram);
        }
    }
    library
}

/// The candidates of `library` not yet accepted, tested against the run's fit. They are
/// independent: tested in parallel (rayon), collected in library order, so the result does
/// not depend on the number of threads. Those that cannot be tested are noted in round 1.
fn test_round(
    device: &Device,
    b: &Baseline,
    run: &mut Run,
    library: &[Effect],
    round: usize,
    folds: usize,
) -> Vec<Tested> {
    let r = Round {
        setup: &b.setup,
        data: &b.data,
        fit: &run.fit,
        round,
        folds,
    };
    let outcomes: Vec<(Effect, Result<Tested, String>)> = library
        .par_iter()
        .filter(|e| !run.accepted.contains(e))
        .map(|&effect| {
            let tested = candidate_terms(effect, device, &b.data, b.n_joints)
                .and_then(|terms| test_candidate(&r, effect, terms));
            (effect, tested)
        })
        .collect();
    let mut tested: Vec<Tested> = Vec::new();
    for (effect, outcome) in outcomes {
        match outcome {
            Ok(t) => tested.push(t),
            Err(reason) => {
                if round == 1 {
                    run.notes.push(format!("{effect}: {reason}"));
                }
            }
        }
    }
    tested
}

/// Holm's adjustment over the round, and each visible candidate accepted or rejected with
/// its reason.
fn judge(tested: &mut [Tested], gap_significant: bool, cfg: &DiagnoseConfig) {
    let adjusted = holm(&tested.iter().map(|t| t.p_raw).collect::<Vec<_>>());
    for (t, &p) in tested.iter_mut().zip(&adjusted) {
        t.cand.p_value = p;
        if t.cand.n_visible == 0 {
            continue;
        }
        let rejected = rejection(t, p, gap_significant, cfg);
        t.cand.accepted = rejected.is_none();
        t.cand.reason = rejected.unwrap_or_else(|| {
            format!(
                "significant (p = {p:.1e}), beats BIC and the held-out baseline, closes {:.0} % of the gap",
                100.0 * t.share
            )
        });
    }
}

/// Why a candidate with Holm-adjusted p-value `p` is rejected; `None` if it passes.
fn rejection(t: &Tested, p: f64, gap_significant: bool, cfg: &DiagnoseConfig) -> Option<String> {
    if !gap_significant {
        Some("no significant gap to explain".to_owned())
    } else if p >= cfg.alpha {
        Some(format!("not significant (Holm-adjusted p = {p:.2e})"))
    } else if t.cand.bic_gain <= 0.0 {
        Some(format!(
            "does not beat the BIC penalty (gain {:.1})",
            t.cand.bic_gain
        ))
    } else if !t.cv_ok {
        Some("held-out RMS not better than the baseline by one standard error".to_owned())
    } else if t.share < cfg.min_gap_share {
        Some(format!("closes only {:.0} % of the gap", 100.0 * t.share))
    } else {
        None
    }
}

/// The winner (the accepted candidate of largest BIC gain) and the candidates confusable
/// with it; the other accepted candidates rank below it and are no longer accepted.
fn rank(tested: &mut [Tested]) -> Option<(usize, Vec<Effect>)> {
    let w = tested
        .iter()
        .enumerate()
        .filter(|(_, t)| t.cand.accepted)
        .max_by(|a, b| a.1.cand.bic_gain.total_cmp(&b.1.cand.bic_gain))
        .map(|(i, _)| i)?;
    let confusable: Vec<Effect> = tested
        .iter()
        .enumerate()
        .filter(|(i, t)| {
            *i != w
                && t.cand.n_visible > 0
                && cosine(&t.fitted, &tested[w].fitted) > CONFUSABLE_COSINE
        })
        .map(|(_, t)| t.cand.effect)
        .collect();
    for (i, t) in tested.iter_mut().enumerate() {
        if i != w && t.cand.accepted {
            t.cand.accepted = false;
            t.cand.reason = format!("passes, but ranks below the winner ({})", t.cand.reason);
        }
    }
    Some((w, confusable))
}

/// The round's winner `tested[w]` refitted with the baseline (Levenberg–Marquardt): its
/// step, the round's candidates, and the new fit in `run`. Returns whether a significant
/// gap remains.
fn accept(
    b: &Baseline,
    run: &mut Run,
    tested: Vec<Tested>,
    w: usize,
    confusable: Vec<Effect>,
    cfg: &DiagnoseConfig,
) -> Result<bool, Error> {
    let n = b.n();
    let win = &tested[w];
    let mut s = run.fit.state.clone();
    s.terms.extend(win.terms.iter().cloned().map(|t| (t, 0.0)));
    let (state, lin) = refine(&b.setup, s, 10).map_err(baseline_error)?;
    let n_base_cols = lin.j.ncols();
    let before = run.fit.base.cv.mse().sqrt();
    let base = Base::new(lin, n_base_cols, cfg.folds, n);
    let parameters = step_parameters(&base, &state, &win.terms);
    let after = base.cv.mse().sqrt();
    let gap2 = b.gap.gap2;
    run.steps.push(Step {
        effect: win.cand.effect,
        heldout_rms_before_m: before,
        heldout_rms_after_m: after,
        gap_closed_pct: if gap2 > 0.0 {
            100.0 * (before * before - after * after) / gap2
        } else {
            0.0
        },
        parameters,
        confusable_with: confusable,
    });
    run.accepted.push(win.cand.effect);
    run.candidates.extend(tested.into_iter().map(|t| t.cand));
    let old = std::mem::replace(&mut run.fit, Fit { state, base });
    let new = &run.fit.base;
    let significant = chi2_sf(new.cv.chi2(), n as f64) < cfg.alpha;
    let share = |b: f64, a: f64, gap: f64| if gap > 0.0 { (b - a) / gap } else { 1.0 };
    let (mse_b, floor_b, excess_b) = (old.base.cv.mse(), old.base.cv.floor(), old.base.excess());
    run.shares.push(RoundShare {
        heldout: share(mse_b, new.cv.mse(), mse_b - floor_b),
        in_sample: share(excess_b, new.excess(), excess_b),
        significant,
    });
    Ok(significant)
}

/// The added `terms`' values at the refined `state`, ± std at `base`'s linearisation (σ
/// from the spec, or from the residuals when they are larger).
fn step_parameters(base: &Base, state: &State, terms: &[Term]) -> Vec<ParamValue> {
    let a = base.lin.j.select_columns(&base.cols);
    let (_, cov) = lstsq(&a, &base.lin.r);
    let s2 = (base.rss / base.dof()).max(1.0);
    let n_prev = base.lin.j.ncols() - terms.len();
    terms
        .iter()
        .enumerate()
        .map(|(k, term)| {
            let col = n_prev + k;
            let pos = base.cols.iter().position(|&c| c == col);
            ParamValue {
                name: term.name.clone(),
                value: state
                    .terms
                    .iter()
                    .find(|(t, _)| t.name == term.name)
                    .map_or(0.0, |(_, v)| *v),
                std: pos.map_or(f64::NAN, |p| (cov[(p, p)] * s2).sqrt()),
                unit: term.unit.to_owned(),
            }
        })
        .collect()
}
