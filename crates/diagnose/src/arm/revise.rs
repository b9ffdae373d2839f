//! The stepwise revision of the effects the rounds named: backward elimination, and the
//! alternatives (the other torque model, harmonic order or transversal form) beside the others.

use hapcal_calibrate::calibrate::blocked_mean_difference;
use hapcal_calibrate::model::ModelName;
use hapcal_contract::Effect;
use nalgebra::DMatrix;

use super::baseline::Baseline;
use super::columns::effect_columns;
use super::cv::{HeldOut, beside, cross_validate, visible_columns};
use super::{ArmConfig, HELDOUT_SIGNIFICANCE_Z, arm_candidates};
use crate::stats::pivoted_basis;

/// An effect the rounds named: the effect, its columns visible beside the baseline and the
/// effects before it (training rows), and their indices among its columns.
pub(super) type Named = (Effect, DMatrix<f64>, Vec<usize>);

/// What [`revise`] found: an effect to leave out of the library, the alternative expected to
/// take its place (a swap), and the note that says why.
pub(super) struct Revision {
    pub(super) leave_out: Effect,
    pub(super) instead: Option<Effect>,
    pub(super) note: String,
}

/// The stepwise check of the effects the rounds named (`named`: each with its visible
/// columns, in the order named; `full`: their held-out errors together). Returns the effect to
/// leave out of the library, with the note that says why, or `None` when every named effect
/// stands:
///
/// - backward: an effect (of two or more) without which the others predict as well, the
///   others not beaten by [`HELDOUT_SIGNIFICANCE_Z`] blocked standard errors — the entry
///   margin — is not needed beside them (a first-round harmonic that a later gear-ratio term
///   explains better); the least needed one goes;
/// - alternatives: gravity and lumped compliance are one effect under two torque models, the
///   two harmonic orders one effect at two frequencies, isotropic and per-axis transversal
///   compliance one effect in two forms; beside the later effects the named one gives way to
///   its alternative by the rounds' own rule (better by one blocked standard error, or within
///   one and earlier in the library).
///
/// A joint compliance with a transversal compliance named beside it is not left out: the
/// transversal compliance is tested on its loads and fitted with it (the calibration's
/// `transversal-compliance` model holds both).
///
/// Source: stepwise selection with backward elimination (Efroymson, "Multiple regression
/// analysis", 1960; Miller, "Subset Selection in Regression", 2nd ed., 2002, §3.3). An effect
/// left out is never offered again, so the revisions end.
pub(super) fn revise(
    b: &Baseline<'_>,
    named: &[Named],
    full: &HeldOut,
    cfg: &ArmConfig,
    excluded: &[Effect],
) -> Option<Revision> {
    let set = |skip: usize| -> String {
        (named.iter().enumerate())
            .filter(|(i, _)| *i != skip)
            .map(|(_, (e, _, _))| e.name())
            .collect::<Vec<_>>()
            .join("+")
    };
    // Backward: the least needed effect, if it is not needed.
    let transversal = named.iter().any(|(e, _, _)| e.is_transversal());
    if named.len() >= 2 {
        let least = (0..named.len())
            .filter(|&k| !(transversal && named[k].0.is_joint_compliance()))
            .map(|k| {
                let (m, se) = gain_beside_others(b, named, full, cfg, k);
                (k, m, se)
            })
            .min_by(|a, b| (a.1 / a.2).total_cmp(&(b.1 / b.2)));
        if let Some((k, m, se)) = least
            && !needed(m, se)
        {
            let effect = named[k].0;
            return Some(Revision {
                leave_out: effect,
                instead: None,
                note: format!(
                    "{} left out: beside {} it improves the held-out error by {:.1} standard \
                     errors, not the {HELDOUT_SIGNIFICANCE_Z} required; the rounds were run \
                     again without it",
                    effect.name(),
                    set(k),
                    m / se
                ),
            });
        }
    }
    // Alternatives, beside the other named effects.
    let order = |e: Effect| arm_candidates().position(|l| l == e);
    for (k, (effect, cols, _)) in named.iter().enumerate() {
        let Some(alt) = effect.alternative() else {
            continue;
        };
        if excluded.contains(&alt) || named.iter().any(|(e, _, _)| *e == alt) {
            continue;
        }
        let Some((swapped, n_visible)) = swapped(b, named, k, alt, cfg) else {
            continue;
        };
        // Improvement of the alternative over the named effect.
        let (m, se, _) = blocked_mean_difference(&full.score, &swapped.score, &b.block);
        let simpler = (n_visible, order(alt)) < (cols.ncols(), order(*effect));
        if m > se || (m >= -se && simpler) {
            return Some(Revision {
                leave_out: *effect,
                instead: Some(alt),
                note: format!(
                    "{} gives way to {}: beside the other named effects it predicts {} ({:+.1} \
                     standard errors); the rounds were run again without {}",
                    effect.name(),
                    alt.name(),
                    if m > se {
                        "better"
                    } else {
                        "as well, with fewer or earlier terms"
                    },
                    m / se,
                    effect.name()
                ),
            });
        }
    }
    None
}

/// What the `k`-th named effect (`named` and `full` as in [`revise`]) improves the held-out
/// error by beside the others, their columns kept as named: the blocked mean difference of the
/// held-out squared errors without it and with every named effect, and its standard error.
fn gain_beside_others(
    b: &Baseline<'_>,
    named: &[Named],
    full: &HeldOut,
    cfg: &ArmConfig,
    k: usize,
) -> (f64, f64) {
    let others: Vec<&DMatrix<f64>> = (named.iter().enumerate())
        .filter(|(i, _)| *i != k)
        .map(|(_, (_, c, _))| c)
        .collect();
    let without = cross_validate(
        &beside(&b.jb, &others),
        &b.r,
        &b.rows,
        &b.folds,
        cfg.folds,
        b.floor.var,
    );
    let (m, se, _) = blocked_mean_difference(&without.score, &full.score, &b.block);
    (m, se)
}

/// Whether a held-out gain `m` with standard error `se` ([`gain_beside_others`]) keeps an
/// effect beside the others: better by the entry margin of [`HELDOUT_SIGNIFICANCE_Z`] blocked
/// standard errors (a NaN gain does not).
fn needed(m: f64, se: f64) -> bool {
    !(m <= HELDOUT_SIGNIFICANCE_Z * se || m.is_nan())
}

/// The joint compliance a transversal compliance does not need, once the revisions stand
/// (`named` and `full` as in [`revise`]): when a joint compliance and a transversal compliance
/// are both named and, without the joint compliance's columns (the transversal compliance
/// kept on its loads), the other named effects predict as well — the joint compliance not
/// better by [`HELDOUT_SIGNIFICANCE_Z`] blocked standard errors, the entry margin — the data
/// show the links bending sideways and no compliance about the joint axes. Returns the joint
/// compliance and the note that says why; the rounds are not run again, since the transversal
/// compliance is tested on the joint compliance's loads ([`super::ARM_TRANSVERSAL`]).
///
/// The verdict then names the transversal compliance alone; the calibration still fits it on
/// top of a joint compliance (`transversal-compliance`), whose estimates the data leave near
/// zero.
pub(super) fn compliance_not_needed(
    b: &Baseline<'_>,
    named: &[Named],
    full: &HeldOut,
    cfg: &ArmConfig,
) -> Option<(Effect, String)> {
    let k = named.iter().position(|(e, _, _)| e.is_joint_compliance())?;
    let transversal = named.iter().find(|(e, _, _)| e.is_transversal())?.0;
    let (m, se) = gain_beside_others(b, named, full, cfg, k);
    if needed(m, se) {
        return None;
    }
    let compliance = named[k].0;
    Some((
        compliance,
        format!(
            "{} not named: beside {} (on its loads) it improves the held-out error by {:.1} \
             standard errors, not the {HELDOUT_SIGNIFICANCE_Z} required; the calibration's \
             {} model still holds a joint compliance, which these data leave near zero",
            compliance.name(),
            transversal.name(),
            m / se,
            transversal
                .model()
                .unwrap_or(ModelName::TransversalCompliance)
        ),
    ))
}

/// The held-out errors of the named effects (`named`, as in [`revise`]) with the `k`-th
/// replaced by `alt`, and the number of `alt`'s columns visible beside the others; `None` when
/// `alt` cannot be built on these data or none of its columns is visible. A transversal
/// compliance named beside a joint compliance that gives way to its other torque model is
/// rebuilt on that model's loads (the same visible columns).
pub(super) fn swapped(
    b: &Baseline<'_>,
    named: &[Named],
    k: usize,
    alt: Effect,
    cfg: &ArmConfig,
) -> Option<(HeldOut, usize)> {
    let (ctx, rows, r, jb, d) = (&b.ctx, &b.rows, &b.r, &b.jb, &b.d);
    let (folds, floor_var) = (&b.folds, b.floor.var);
    let with: Vec<Effect> = (named.iter().enumerate())
        .map(|(i, (e, _, _))| if i == k { alt } else { *e })
        .collect();
    let (alt_cols, _) = effect_columns(alt, ctx, rows, d, &with).ok()?;
    let mut rebuilt: Vec<DMatrix<f64>> = Vec::new();
    for (i, (e, _, visible)) in named.iter().enumerate() {
        if i != k && e.is_transversal() && alt.is_joint_compliance() {
            let (c, _) = effect_columns(*e, ctx, rows, d, &with).ok()?;
            rebuilt.push(c.select_columns(visible));
        }
    }
    let mut rebuilt = rebuilt.iter();
    let others: Vec<&DMatrix<f64>> = (named.iter().enumerate())
        .filter(|(i, _)| *i != k)
        .filter_map(|(_, (e, c, _))| {
            if e.is_transversal() && alt.is_joint_compliance() {
                rebuilt.next()
            } else {
                Some(c)
            }
        })
        .collect();
    let base = beside(jb, &others);
    let (qb, _) = pivoted_basis(&base, &DMatrix::zeros(base.nrows(), 0), 1e-9);
    let (_, visible) = visible_columns(&alt_cols, &qb, &base);
    if visible.is_empty() {
        return None;
    }
    let alt_vis = alt_cols.select_columns(&visible);
    let mut parts = others;
    parts.push(&alt_vis);
    let held = cross_validate(&beside(jb, &parts), r, rows, folds, cfg.folds, floor_var);
    Some((held, visible.len()))
}
