//! Diagnosis of a serial arm's sim-to-real gap (docs/diagnosis.md, "Real robots"): after the
//! geometric calibration of [`GeometricBaseline`], how far the held-out residual lies above
//! the noise floor, where it lies, which effect of the serial-arm library explains it, how
//! far it shrinks once that effect is modelled, and what each model step buys.
//!
//! Every effect is a small parametric term on top of the calibration's own problem
//! ([`hapcal_problems::CalibrationProblem`]): a joint-angle error `Δq_j = c·b_j(row)` enters
//! through the problem's derivative with respect to the readings (central differences of its
//! residuals), a displacement `Δp = c·v(row)` of the measured point through the position
//! residuals. The tests are linear about the geometric estimate (one Gauss–Newton step from a
//! converged fit, the reference device's scheme), so that each candidate costs a few small
//! least-squares solves (`solve::lstsq`, the identify engine), not a nonlinear fit.
//!
//! Statistics, as on the reference device: the in-sample F-test of each candidate's added
//! parameters with Holm–Bonferroni over the candidates of a round (the family-wise control at
//! `alpha`), and blocked k-fold cross-validation (contiguous configurations of one socket or
//! file per block, three shifted repeats): the held-out error must undercut the round's
//! baseline by two blocked standard errors (the calibration ladder's margin). An effect is
//! named only when both hold and it closes at least `min_gap_share` of the gap its round
//! faces: the held-out error left by the effects named before it, above the floor. Rounds go
//! on while that error is significantly above the floor and a candidate passes, up to
//! `max_effects`. Once they stop, each named effect is checked beside the others (`revise`,
//! stepwise selection with backward elimination): one the others do not need, or whose
//! alternative predicts better, is left out and the rounds run again; a swap stands only if the
//! rounds then name the alternative. A transversal compliance is a candidate of every round,
//! alone on the link masses' gravity loads; a joint compliance named with a transversal
//! compliance beside it is last checked the other way round: when the transversal compliance
//! and the other effects predict as well without it, the verdict names the transversal
//! compliance alone.
//!
//! Errors are lengths: the 3-D error of a position, or the error of a distance (a distance
//! log); the RMS figures below are of those.
//!
//! The diagnosis is a pipeline of stages, each with a typed output:
//!
//! 1. `baseline`: the training rows, the baseline's residuals and derivatives at the
//!    geometric estimate, the cross-validation folds, the floor and the gap above it;
//! 2. `residual_map` (where): the baseline's held-out residuals binned by signal;
//! 3. `which`: the candidate columns (`columns`) tested round by round, the greedy choice
//!    and the stepwise revision (`revise`), the alternatives a step leaves open;
//! 4. `how_far`: the gap the named effects close, the sufficiency rule and the verdict;
//! 5. `ladder`: the rung table, cross-validated and on each held-out set.

mod baseline;
mod columns;
mod cv;
mod how_far;
mod ladder;
mod problem;
mod report;
mod residual_map;
mod revise;
mod which;

use hapcal_calibrate::baseline::GeometricBaseline;
use hapcal_calibrate::model::ModelName;
use hapcal_contract::Effect;

use crate::Error;

pub use columns::{approach_signs, transversal_columns};
pub use report::{ArmCandidate, ArmDiagnosis, ArmLadderRung, ArmRung, ArmStep, FloorSource};

/// Remaining fraction of a candidate column's norm, after projecting out the baseline, below
/// which the column is absorbed by the baseline (invisible in these data).
const VISIBLE_TOL: f64 = 0.02;

/// Step of the central differences with respect to a joint reading, rad (m for a prismatic
/// joint): truncation error ~h² relative, rounding ~ε/h; both far below the noise.
const READING_STEP: f64 = 1e-6;

/// The tip's reach or height must span more than this (m) for the workspace maps: at sockets
/// it does not move.
const WORKSPACE_SPREAD_M: f64 = 0.01;

/// Blocked standard errors by which a candidate's held-out error must undercut the round's
/// baseline: the calibration ladder's margin (`hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z`).
/// The family-wise control is the in-sample F-test's (Holm); the held-out test guards against
/// a term that fits the training rows and predicts worse, with as few as 5 blocks (4 degrees of
/// freedom), where a Holm-corrected held-out test has little power.
const HELDOUT_SIGNIFICANCE_Z: f64 = hapcal_calibrate::model::LADDER_SIGNIFICANCE_Z;

/// A joint's basis below this fraction of the effect's largest is left out (numerical zero).
const NEGLIGIBLE_BASIS: f64 = 1e-6;

/// Repeats of the cross-validation, each with the block boundaries shifted by a fraction of a
/// block (as the calibration's own, [`hapcal_calibrate::calibrate::CV_REPEATS`]).
const CV_REPEATS: usize = hapcal_calibrate::calibrate::CV_REPEATS;

/// Cosine of two candidates' fitted corrections above which the data confuse them.
const CONFUSABLE_COSINE: f64 = 0.8;

/// Joint readings agreeing to this (rad, or m for a prismatic joint) on every joint are a
/// repeated pose (a floor from repeatability).
pub const REPEAT_TOLERANCE: f64 = 1e-4;

/// The serial-arm diagnosis's library, in report order: the effects it tests on measurement
/// files and socket recordings (one vocabulary with calibration: [`Effect`]), from the first
/// round on, with [`ARM_TRANSVERSAL`].
pub const ARM_LIBRARY: [Effect; 9] = [
    Effect::GravityCompliance,
    Effect::LumpedCompliance,
    Effect::FirstHarmonic,
    Effect::SecondHarmonic,
    Effect::Backlash,
    Effect::GearRatio,
    Effect::ThermalDrift,
    Effect::LinkDeflection,
    Effect::InstrumentScale,
];

/// The transversal compliances the serial-arm diagnosis tests, from the first round on: one
/// per revolute joint (isotropic) or one per axis normal to the joint axis, each the other's
/// alternative; wherever the calibration can fit them (a robot whose revolute joints carry
/// rotation deviations: URDF placements).
///
/// Their loads: beside a named joint compliance, that compliance's (the calibration fits the
/// tilts on top of it, `--model transversal-compliance` being `compliance` plus the tilts);
/// alone, the gravity moments of the link masses (of unit weights at the tips when the masses
/// are unknown). A tilt normal to a joint axis needs a moment normal to it, which the weight
/// of the links below gives in every configuration, so the candidate is tested on those loads
/// rather than after a joint compliance: links that bend sideways on gearboxes stiff about
/// their axes are then named without a joint compliance they do not have, and the columns
/// differ from a joint compliance's (a rotation about the axis) and from a geometric error
/// (constant in the link frame, where the tilt follows the moment through the configurations).
/// Alone only on measurement files: socket recordings (the tip held at two points) have no
/// transversal rung on the calibration's ladder, and there the tilts alone mimic a joint
/// compliance (on the arm blind test's socket data they took 3 of its 64 two-effect cases).
/// The tilts alone take a round from a joint compliance that passes it only when they predict
/// better by two blocked standard errors, the entry margin (the calibration nests the two:
/// `transversal-compliance` is `compliance` plus the tilts; on the serial arms' socket data of
/// the arm blind test, per-axis tilts with twice the parameters otherwise took some joint
/// compliances' first round). When the rounds name a transversal compliance and then a joint
/// compliance, they are run
/// again with the tilts tested only beside a named joint compliance, on its loads: the pair is
/// then tested as the calibration fits it (a per-axis tilt named first on the masses' loads
/// absorbs part of the joint compliance's columns, which its isotropic alternative beside the
/// joint compliance would then lack). A joint compliance named with the tilts is left out of
/// the verdict when the tilts predict as well without it ([`ArmDiagnosis::verdict`]).
pub const ARM_TRANSVERSAL: [Effect; 2] = [Effect::TransversalCompliance, Effect::TransversalAxes];

/// Every candidate of the diagnosis, in report order: [`ARM_LIBRARY`], then
/// [`ARM_TRANSVERSAL`].
fn arm_candidates() -> impl Iterator<Item = Effect> {
    ARM_LIBRARY.into_iter().chain(ARM_TRANSVERSAL)
}

/// Settings of [`diagnose_arm`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmConfig {
    /// Cross-validation folds (contiguous blocks of configurations per socket or file), ≥ 2.
    pub folds: usize,
    /// Family-wise significance level (Holm) of the candidate tests and of the map's bins.
    pub alpha: f64,
    /// Largest number of effects added one after the other.
    pub max_effects: usize,
    /// Smallest share of its round's gap a named effect must close, 0–1: the held-out error
    /// left by the effects named before it, above the floor (not used without a floor).
    pub min_gap_share: f64,
    /// Quantile bins per signal of the residual map.
    pub bins: usize,
}

impl Default for ArmConfig {
    /// 5 folds, α = 0.01, up to 3 effects, each closing ≥ 20 % of the gap its round faces,
    /// 6 bins: the reference device's settings (docs/diagnosis.md).
    fn default() -> Self {
        Self {
            folds: 5,
            alpha: 0.01,
            max_effects: 3,
            min_gap_share: 0.2,
            bins: 6,
        }
    }
}

/// Checks the `--baseline` asked for a robot measured by an instrument: it is diagnosed on its
/// geometric calibration, so only `geometric` (or nothing; `full`, the older default, is read
/// as it) is taken.
///
/// # Errors
/// [`Error::Config`] naming the value given, in the user's words.
pub fn robot_baseline(name: Option<&str>) -> Result<(), Error> {
    match name {
        None => Ok(()),
        Some(n)
            if ModelName::from_name(n) == Some(ModelName::Geometric)
                || n.trim().eq_ignore_ascii_case("full") =>
        {
            Ok(())
        }
        Some(n) => Err(Error::Config {
            message: format!(
                "baseline {n:?}: a robot measured by an instrument is diagnosed on its geometric \
                 calibration (baseline geometric); the other baselines apply to a haptic \
                 device's log"
            ),
        }),
    }
}

/// Diagnoses `baseline` (see the module documentation): the stages one after the other.
///
/// # Errors
/// [`Error::Config`] for settings out of range; [`Error::Data`] for fewer than 2 folds'
/// worth of configurations; [`Error::Baseline`] if the problem cannot be evaluated.
pub fn diagnose_arm(baseline: &GeometricBaseline, cfg: &ArmConfig) -> Result<ArmDiagnosis, Error> {
    crate::error::check_rounds(cfg.folds, cfg.alpha, cfg.max_effects)?;
    let b = baseline::Baseline::new(baseline, cfg)?;
    let where_ = residual_map::residual_map(&b.ctx, &b.rows, &b.held, b.floor.var, cfg);
    let which::Selection {
        mut run,
        mut revisions,
        not_named,
    } = which::select(&b, cfg);
    which::alike(&b, &mut run, cfg);
    let mut far = how_far::how_far(
        &b,
        &run.base,
        &mut run.steps,
        &run.accepted,
        (&run.p_after, &run.in_sample_share),
        cfg,
    );
    // The joint compliance a transversal compliance does not need leaves the verdict, while
    // the transversal compliance stands in it.
    if let Some((left, note)) = not_named {
        let kept: Vec<Effect> = (far.verdict.effects().iter().copied())
            .filter(|&e| e != left)
            .collect();
        if kept.iter().any(|e| e.is_transversal()) {
            far.verdict = crate::Verdict::of(&kept);
            revisions.push(note);
        }
    }
    let ladder = ladder::ladder(&b, &run.effect_cols, cfg)?;
    let test_rms_final = match run.effect_cols.is_empty() {
        true => ladder.geometric_test_rms.clone(),
        false => (ladder.rungs.last()).map_or_else(Vec::new, |l| l.test_rms_m.clone()),
    };
    let mut notes = b.notes.clone();
    notes.extend(revisions);
    notes.extend(run.untestable.iter().map(|u| format!("not testable: {u}")));
    notes.extend(far.notes);
    Ok(ArmDiagnosis {
        kind: baseline.kind,
        n_configurations: b.rows.n_configurations(),
        n_baseline_params: b.jb.ncols(),
        floor_method: b.floor.method.clone(),
        floor_source: b.floor.source.clone(),
        floor_sigma_m: b.floor.var.map(f64::sqrt),
        floor_rms_m: b.floor0.map(f64::sqrt),
        heldout_rms_m: b.mse0.sqrt(),
        test_rms_m: ladder.geometric_test_rms,
        gap_rms_m: far.gap2.max(0.0).sqrt(),
        gap_p_value: b.gap_p,
        gap_significant: b.chi_known && b.gap_p < cfg.alpha,
        where_,
        candidates: run.candidates,
        steps: run.steps,
        verdict: far.verdict,
        heldout_rms_final_m: far.final_mse.sqrt(),
        test_rms_final_m: test_rms_final,
        gap_closed_pct: 100.0 * far.closed,
        test_sets: baseline.tests.iter().map(|t| t.name.clone()).collect(),
        ladder: ladder.rungs,
        notes,
    })
}
