//! Which effect: the candidates of the library tested round by round against what the effects
//! named before them leave (in-sample F-test with Holm, blocked cross-validation, share of the
//! gap), the greedy choice of each round, the stepwise revision of the named effects, and the
//! torque models a named compliance leaves open.

use hapcal_calibrate::baseline::DataKind;
use hapcal_calibrate::calibrate::blocked_mean_difference;
use hapcal_contract::Effect;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::baseline::{Baseline, gap_p_value};
use super::columns::effect_columns;
use super::cv::{HeldOut, beside, cross_validate, one_sided_p, visible_columns};
use super::revise::{Named, Revision, compliance_not_needed, revise, swapped};
use super::{
    ArmCandidate, ArmConfig, ArmStep, CONFUSABLE_COSINE, HELDOUT_SIGNIFICANCE_Z, arm_candidates,
};
use crate::ParamValue;
use crate::solve::lstsq;
use crate::stats::{cosine, f_sf, holm, pivoted_basis};

/// One run of the rounds: what they named and tested.
#[derive(Clone)]
pub(super) struct Run {
    /// The held-out errors of the baseline with the named effects.
    pub(super) base: HeldOut,
    /// Every candidate of every round.
    pub(super) candidates: Vec<ArmCandidate>,
    /// The named effects, in order.
    pub(super) steps: Vec<ArmStep>,
    pub(super) accepted: Vec<Effect>,
    /// The named effects' columns on the training rows.
    pub(super) effect_cols: Vec<Named>,
    /// Effects these data cannot test, with why (`effect: reason`).
    pub(super) untestable: Vec<String>,
    /// After each named effect: the χ² p-value of what is left under the floor.
    pub(super) p_after: Vec<f64>,
    /// Each named effect's share of its round's in-sample excess (RSS − dof, in floor units).
    pub(super) in_sample_share: Vec<f64>,
}

/// The selection stage's output: the run that stands, the notes of the revisions, and the
/// named joint compliance a named transversal compliance does not need
/// ([`compliance_not_needed`]), which the verdict leaves out.
pub(super) struct Selection {
    pub(super) run: Run,
    pub(super) revisions: Vec<String>,
    pub(super) not_named: Option<(Effect, String)>,
}

/// The model a round tests its candidates beside: the baseline and the effects named before.
struct RoundBase<'m> {
    round: usize,
    /// Its columns, their orthonormal basis, and the residuals orthogonal to them.
    a: &'m DMatrix<f64>,
    qb: DMatrix<f64>,
    r_perp: DVector<f64>,
    /// `‖r_perp‖²` and its degrees of freedom.
    rss_b: f64,
    dof_b: f64,
}

/// Stepwise selection: the rounds add effects greedily; once they stop, every named effect is
/// checked against the others ([`revise`]): one that no longer earns its place beside the
/// later ones, or whose alternative under the other torque model or harmonic order now
/// predicts better, is left out of the library and the rounds run again from the geometric
/// baseline. A swap stands only if the rounds run again name the alternative by their own
/// tests; otherwise the run before it is kept.
pub(super) fn select(b: &Baseline<'_>, cfg: &ArmConfig) -> Selection {
    let mut excluded: Vec<Effect> = Vec::new();
    let mut revisions: Vec<String> = Vec::new();
    // The run before a swap, the alternative and the effect left out.
    let mut before_swap: Option<(Effect, Effect, Run)> = None;
    // Whether a transversal compliance is a candidate before a joint compliance is named: not
    // on socket recordings, whose calibration ladder holds no transversal rung (the tip at two
    // points, where the tilts alone mimic a joint compliance).
    let mut alone = b.ctx.baseline.kind != DataKind::Sockets;
    loop {
        let mut run = run_rounds(b, cfg, &excluded, alone);
        if alone && tilts_before_compliance(&run.accepted) {
            // The tilts took the first round and a joint compliance followed: the pair is the
            // calibration's `transversal-compliance` model, tested as it is fitted (the joint
            // compliance first, the tilts on its loads), so the rounds run again so.
            alone = false;
            revisions.push(format!(
                "{} was named before {}: the rounds were run again with the transversal \
                 compliance tested beside the joint compliance, on its loads",
                run.accepted
                    .iter()
                    .find(|e| e.is_transversal())
                    .map_or("", |e| e.name()),
                run.accepted
                    .iter()
                    .find(|e| e.is_joint_compliance())
                    .map_or("", |e| e.name()),
            ));
            run = run_rounds(b, cfg, &excluded, alone);
        }
        if let Some((alt, left_out, saved)) = before_swap.take()
            && !run.accepted.contains(&alt)
        {
            // The alternative did not pass beside the others: the run before the swap stands.
            revisions.pop();
            revisions.push(format!(
                "{} stays: run again without it, the rounds did not name {} in its place",
                Effect::name(left_out),
                Effect::name(alt)
            ));
            return finish(b, cfg, saved, revisions);
        }
        match revise(b, &run.effect_cols, &run.base, cfg, &excluded) {
            Some(Revision {
                leave_out,
                instead,
                note,
            }) => {
                if let Some(alt) = instead {
                    before_swap = Some((alt, leave_out, run));
                }
                excluded.push(leave_out);
                revisions.push(note);
            }
            None => return finish(b, cfg, run, revisions),
        }
    }
}

/// Whether the effects `accepted` (in the order named) name a transversal compliance before a
/// joint compliance.
fn tilts_before_compliance(accepted: &[Effect]) -> bool {
    match (
        accepted.iter().position(|e| e.is_transversal()),
        accepted.iter().position(|e| e.is_joint_compliance()),
    ) {
        (Some(t), Some(j)) => t < j,
        _ => false,
    }
}

/// The selection of `run` once its revisions stand: the joint compliance a named transversal
/// compliance does not need, if any ([`compliance_not_needed`]), with its note.
fn finish(b: &Baseline<'_>, cfg: &ArmConfig, run: Run, revisions: Vec<String>) -> Selection {
    let not_named = compliance_not_needed(b, &run.effect_cols, &run.base, cfg);
    Selection {
        run,
        revisions,
        not_named,
    }
}

/// One run of the rounds from the geometric baseline, the effects `excluded` left out of the
/// library: each round tests the candidates beside the effects named before, names the best
/// that passes, and the rounds stop when none passes, at `max_effects`, or when what is left
/// is consistent with the floor. With `alone`, a transversal compliance is a candidate from
/// the first round on; without, only beside a named joint compliance.
fn run_rounds(b: &Baseline<'_>, cfg: &ArmConfig, excluded: &[Effect], alone: bool) -> Run {
    let mut run = Run {
        base: b.held.clone(),
        candidates: Vec::new(),
        steps: Vec::new(),
        accepted: Vec::new(),
        effect_cols: Vec::new(),
        untestable: Vec::new(),
        p_after: Vec::new(),
        in_sample_share: Vec::new(),
    };
    let mut a = b.jb.clone();
    for round in 1..=cfg.max_effects {
        let (qb, _) = pivoted_basis(&a, &DMatrix::zeros(a.nrows(), 0), 1e-9);
        let r_perp = &b.r - &qb * (qb.transpose() * &b.r);
        let rss_b = r_perp.norm_squared();
        let dof_b = (b.r.len() as f64 - qb.ncols() as f64).max(1.0);
        let fit = RoundBase {
            round,
            a: &a,
            qb,
            r_perp,
            rss_b,
            dof_b,
        };
        // The candidates are independent: tested in parallel, taken in the library's order.
        let offered_now: Vec<Effect> = arm_candidates()
            .filter(|&e| offered(e, &run.accepted, excluded, alone))
            .collect();
        let results: Vec<Result<Tested, String>> = (offered_now.par_iter())
            .map(|&effect| test_candidate(b, &fit, &run, effect, cfg))
            .collect();
        let mut tested: Vec<Tested> = Vec::new();
        for (effect, result) in offered_now.into_iter().zip(results) {
            match result {
                Ok(t) => tested.push(t),
                Err(reason) => {
                    let note = format!("{}: {reason}", effect.name());
                    if (round == 1 || effect.is_transversal()) && !run.untestable.contains(&note) {
                        run.untestable.push(note);
                    }
                }
            }
        }
        let Some(w) = judge(b, &run.base, &mut tested, cfg) else {
            run.candidates.extend(tested.into_iter().map(|t| t.cand));
            break;
        };
        a = name_winner(b, &fit, &mut run, tested, w);
        // Stop when what is left is consistent with the floor.
        if b.floor.var.is_some() && gap_p_value(&b.rows, &run.base) >= cfg.alpha {
            break;
        }
    }
    run
}

/// Whether `effect` is a candidate beside the effects `accepted`. Gravity and lumped compliance
/// are one effect under two torque models, the two transversal compliances one effect in two
/// forms: once one is named, the other is not a further effect. A transversal compliance is a
/// candidate from the first round on (`alone`), on the loads of
/// [`super::columns::transversal_loads`], or only once a joint compliance is named.
fn offered(effect: Effect, accepted: &[Effect], excluded: &[Effect], alone: bool) -> bool {
    let compliance = accepted.iter().any(|e| e.is_joint_compliance());
    !(accepted.contains(&effect)
        || excluded.contains(&effect)
        || (effect.is_joint_compliance() && compliance)
        || (effect.is_transversal()
            && (accepted.iter().any(|e| e.is_transversal()) || !(alone || compliance))))
}

/// Tests `effect` beside the round's model `fit`: its visible columns, the in-sample F-test,
/// the cross-validated improvement and its parameters; `Err` with the reason when these data
/// cannot test it.
fn test_candidate(
    b: &Baseline<'_>,
    fit: &RoundBase<'_>,
    run: &Run,
    effect: Effect,
    cfg: &ArmConfig,
) -> Result<Tested, String> {
    let (r, base) = (&b.r, &run.base);
    let (cols, names) = effect_columns(effect, &b.ctx, &b.rows, &b.d, &run.accepted)?;
    let (qc, visible) = visible_columns(&cols, &fit.qb, fit.a);
    let mut cand = ArmCandidate {
        effect,
        round: fit.round,
        n_visible: visible.len(),
        heldout_rms_before_m: base.mse().sqrt(),
        heldout_rms_after_m: base.mse().sqrt(),
        heldout_improvement: (0.0, 0.0),
        heldout_p_value: 1.0,
        f_p_value: 1.0,
        gap_closed_pct: 0.0,
        accepted: false,
        reason: String::new(),
        parameters: Vec::new(),
    };
    if visible.is_empty() {
        cand.reason = "absorbed by the geometric parameters in these data".into();
        return Ok(Tested {
            effect,
            cand,
            columns: DMatrix::zeros(r.len(), 0),
            visible,
            held: None,
            fitted: DVector::zeros(r.len()),
            p_cv: 1.0,
            p_f: 1.0,
            improvement: 0.0,
        });
    }
    let c_vis = cols.select_columns(&visible);
    let proj = qc.transpose() * &fit.r_perp;
    let drss = proj.norm_squared();
    let k = visible.len() as f64;
    let dof = (fit.dof_b - k).max(1.0);
    let p_f = f_sf((drss / k) / ((fit.rss_b - drss).max(1e-300) / dof), k, dof);
    let ac = beside(fit.a, &[&c_vis]);
    let held = cross_validate(&ac, r, &b.rows, &b.folds, cfg.folds, b.floor.var);
    let (m, se, filled) = blocked_mean_difference(&base.score, &held.score, &b.block);
    let p_cv = one_sided_p(m, se, filled.saturating_sub(1) as f64);
    let (params, _) = parameters(&ac, r, fit.a.ncols(), &names, &visible);
    cand.heldout_rms_after_m = held.mse().sqrt();
    cand.heldout_improvement = (m, se);
    cand.parameters = params;
    Ok(Tested {
        effect,
        cand,
        columns: c_vis,
        visible,
        held: Some(held),
        fitted: &qc * proj,
        p_cv,
        p_f,
        improvement: m,
    })
}

/// Judges the candidates of a round against its model's held-out errors `base`: the p-values
/// (F-test Holm-adjusted over the round), the share of the round's gap each closes, whether it
/// passes and why; returns the winner, if any passes.
fn judge(
    b: &Baseline<'_>,
    base: &HeldOut,
    tested: &mut [Tested],
    cfg: &ArmConfig,
) -> Option<usize> {
    let block = &b.block;
    let p_cv: Vec<f64> = tested.iter().map(|t| t.p_cv).collect();
    let adj_f = holm(&tested.iter().map(|t| t.p_f).collect::<Vec<_>>());
    // The gap of this round, what the effects named so far left: above the floor, or (no
    // floor) above the best candidate. A second effect is judged by the share of that gap it
    // closes, not of the gap before the first effect (which the first one may have mostly
    // closed: drift then a gear ratio, 85 % then all of what was left).
    let best_mse = (tested.iter())
        .filter_map(|t| t.held.as_ref().map(HeldOut::mse))
        .fold(base.mse(), f64::min);
    let gap2 = match b.floor0 {
        Some(f) => base.mse() - f,
        None => base.mse() - best_mse,
    };
    for (t, (pc, pf)) in tested.iter_mut().zip(p_cv.iter().zip(&adj_f)) {
        t.cand.heldout_p_value = *pc;
        t.cand.f_p_value = *pf;
        let Some(h) = &t.held else { continue };
        let share = if gap2 > 0.0 {
            (base.mse() - h.mse()) / gap2
        } else {
            0.0
        };
        t.cand.gap_closed_pct = 100.0 * share.clamp(-9.99, 9.99);
        let (m, se) = t.cand.heldout_improvement;
        let reason = if *pf >= cfg.alpha {
            format!("in-sample F-test not significant (Holm-adjusted p = {pf:.2e})")
        } else if m <= HELDOUT_SIGNIFICANCE_Z * se || m.is_nan() {
            format!(
                "held-out improvement {:.1} standard errors, not the {HELDOUT_SIGNIFICANCE_Z} required",
                m / se
            )
        } else if b.floor0.is_some() && share < cfg.min_gap_share {
            format!(
                "closes only {:.0} % of the gap left above the floor",
                100.0 * share
            )
        } else {
            String::new()
        };
        t.cand.accepted = reason.is_empty();
        t.cand.reason = if reason.is_empty() {
            format!(
                "F-test p = {pf:.1e} (Holm), held-out better by {:.1} standard errors (p = \
                 {pc:.1e}), closes {:.0} % of the gap",
                m / se.max(1e-300),
                100.0 * share
            )
        } else {
            reason
        };
    }
    // The best held-out improvement wins; among the named candidates that predict as well
    // within one blocked standard error (the one-standard-error rule), the one with fewer
    // parameters, then the earlier in the library (which uses more of what is known about the
    // robot: its link masses before a unit weight).
    let best = (tested.iter().enumerate())
        .filter(|(_, t)| t.cand.accepted)
        .max_by(|a, b| a.1.improvement.total_cmp(&b.1.improvement))
        .map(|(i, _)| i);
    let winner = best.map(|b| {
        let best_score = tested[b]
            .held
            .as_ref()
            .map(|h| h.score.clone())
            .unwrap_or_default();
        (tested.iter().enumerate())
            .filter(|(_, t)| t.cand.accepted)
            .filter(|(_, t)| {
                let Some(h) = &t.held else { return false };
                let (d, se, _) = blocked_mean_difference(&h.score, &best_score, block);
                d <= se
            })
            .min_by_key(|(i, t)| (t.cand.n_visible, *i))
            .map_or(b, |(i, _)| i)
    });
    // The tilts alone against a joint compliance: the calibration nests the two (its
    // `transversal-compliance` model is `compliance` plus the tilts), so the tilts take the
    // round from a joint compliance that passes only when they predict better by the entry
    // margin of HELDOUT_SIGNIFICANCE_Z blocked standard errors; otherwise the joint compliance
    // is named and the tilts are tested beside it in the next round.
    let winner = winner.map(|w| {
        let Some(win) = tested[w]
            .held
            .as_ref()
            .filter(|_| tested[w].effect.is_transversal())
        else {
            return w;
        };
        (tested.iter().enumerate())
            .filter(|(_, t)| t.cand.accepted && t.effect.is_joint_compliance())
            .filter(|(_, t)| {
                let Some(h) = &t.held else { return false };
                let (d, se, _) = blocked_mean_difference(&h.score, &win.score, block);
                d <= HELDOUT_SIGNIFICANCE_Z * se
            })
            .max_by(|a, b| a.1.improvement.total_cmp(&b.1.improvement))
            .map_or(w, |(i, _)| i)
    });
    for (i, t) in tested.iter_mut().enumerate() {
        if Some(i) != winner && t.cand.accepted {
            t.cand.accepted = false;
            t.cand.reason = format!(
                "passes, but predicts less well than the winner ({})",
                t.cand.reason
            );
        }
    }
    winner
}

/// Names the round's winner `tested[w]`: its step (with the candidates it is confusable
/// with), its columns beside the round's model; the round's candidates join the run's. Returns
/// the next round's model columns.
fn name_winner(
    b: &Baseline<'_>,
    fit: &RoundBase<'_>,
    run: &mut Run,
    tested: Vec<Tested>,
    w: usize,
) -> DMatrix<f64> {
    let (mse0, base) = (b.mse0, &run.base);
    let win_fit = tested[w].fitted.clone();
    let excess = fit.rss_b * b.floor_units - fit.dof_b;
    run.in_sample_share.push(if excess > 0.0 {
        (win_fit.norm_squared() * b.floor_units - tested[w].cand.n_visible as f64) / excess
    } else {
        0.0
    });
    let win_effect = tested[w].effect;
    let confusable: Vec<(Effect, String)> = (tested.iter().enumerate())
        .filter(|(i, t)| {
            *i != w && t.cand.n_visible > 0 && cosine(&t.fitted, &win_fit) > CONFUSABLE_COSINE
        })
        .map(|(_, t)| {
            (
                t.cand.effect,
                win_effect.separating_measurement(t.effect).to_owned(),
            )
        })
        .collect();
    let win = &tested[w];
    let held = win.held.clone().unwrap_or_else(|| base.clone());
    let before = base.mse().sqrt();
    let after = held.mse().sqrt();
    let gap_orig = match b.floor0 {
        Some(f) => mse0 - f,
        None => mse0 - held.mse(),
    };
    run.steps.push(ArmStep {
        effect: win.cand.effect,
        heldout_rms_before_m: before,
        heldout_rms_after_m: after,
        gap_closed_pct: if gap_orig > 0.0 {
            100.0 * (before * before - after * after) / gap_orig
        } else {
            0.0
        },
        round_gap_closed_pct: win.cand.gap_closed_pct,
        parameters: win.cand.parameters.clone(),
        confusable_with: confusable,
        alike: Vec::new(),
    });
    let grown = beside(fit.a, &[&win.columns]);
    run.effect_cols
        .push((win.effect, win.columns.clone(), win.visible.clone()));
    run.accepted.push(win.effect);
    run.base = held;
    run.candidates.extend(tested.into_iter().map(|t| t.cand));
    run.p_after.push(gap_p_value(&b.rows, &run.base));
    grown
}

/// The compliance's torque model is named only on the evidence that names an effect: beside
/// the other named effects (a transversal compliance on the other model's loads too), the
/// other torque model predicts worse by [`HELDOUT_SIGNIFICANCE_Z`] blocked standard errors.
/// Otherwise the data do not tell the two apart, and the step says so ([`ArmStep::alike`]).
/// (The two forms of a transversal compliance are told apart by the rounds and the revision,
/// and reported as confusable when their fits look alike.)
pub(super) fn alike(b: &Baseline<'_>, run: &mut Run, cfg: &ArmConfig) {
    for (k, (effect, _, _)) in run.effect_cols.iter().enumerate() {
        let Some(alt) = effect.alternative().filter(|a| a.is_joint_compliance()) else {
            continue;
        };
        let Some((other, _)) = swapped(b, &run.effect_cols, k, alt, cfg) else {
            continue;
        };
        let (d, se, _) = blocked_mean_difference(&other.score, &run.base.score, &b.block);
        if d <= HELDOUT_SIGNIFICANCE_Z * se || d.is_nan() || se.is_nan() {
            run.steps[k].alike.push(alt);
        }
    }
}

/// The fitted parameters of `names` (columns `from..` of `a`) on all rows, ± std with σ² from
/// the residuals (`RSS/(n − p)`).
fn parameters(
    a: &DMatrix<f64>,
    r: &DVector<f64>,
    from: usize,
    names: &[(String, &'static str)],
    visible: &[usize],
) -> (Vec<ParamValue>, DVector<f64>) {
    let (x, cov) = lstsq(a, r);
    let dof = (r.len() as f64 - a.ncols() as f64).max(1.0);
    let s2 = (r - a * &x).norm_squared() / dof;
    let params = (visible.iter().enumerate())
        .map(|(k, &c)| ParamValue {
            name: names[c].0.clone(),
            value: x[from + k],
            std: (cov[(from + k, from + k)] * s2).sqrt(),
            unit: names[c].1.to_owned(),
        })
        .collect();
    (params, x)
}

/// One candidate's evaluation in a round.
struct Tested {
    effect: Effect,
    cand: ArmCandidate,
    /// Its visible columns on the training rows.
    columns: DMatrix<f64>,
    visible: Vec<usize>,
    held: Option<HeldOut>,
    fitted: DVector<f64>,
    p_cv: f64,
    p_f: f64,
    improvement: f64,
}
