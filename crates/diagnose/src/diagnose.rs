//! The diagnosis of a haptic device's log: baseline, gap against the floor, where, which,
//! how far.
//!
//! The diagnosis is a pipeline of stages, each with a typed output:
//!
//! 1. `baseline`: the log checked (and sampled when long), the baseline fitted, the floor
//!    decided and the held-out gap above it;
//! 2. `residual_map` (where): the baseline's held-out residuals binned by signal;
//! 3. `probe`: which joint's angle the residual lives on;
//! 4. `which`: the library's candidates (`terms`) tested round by round (`candidate`), the
//!    winner of each round refitted with the baseline;
//! 5. `how_far`: the gap the accepted effects close, the sufficiency rule and the verdict.

mod baseline;
mod candidate;
mod cv;
mod how_far;
mod probe;
mod residual_map;
mod terms;
mod which;

use hapcal_calibrate::model::ModelName;
use hapcal_contract::Effect;
use hapcal_io::{Device, LogRow};
use serde::Serialize;

use crate::{Error, Verdict};

pub use baseline::baseline_residuals_m;

/// Smallest fraction of a candidate column's norm left after projecting out the baseline for
/// the column to count as visible (below: indistinguishable from the baseline).
const VISIBLE_TOL: f64 = 0.005;

/// The model a haptic device's log is diagnosed against, by the name `--baseline` takes: one
/// of the two models `hapcal calibrate` fits to such a log ([`ModelName`], the one
/// definition of a model):
///
/// - `transmissions`: the transmissions (paper eq. 1 on the capstans, the joint-4 polynomial)
///   from the external encoders, plus the kinematic deviations: the paper's full calibration
///   (Fig. 6); `full` is read as this;
/// - `geometric`: the kinematic deviations alone on the raw readings; the paper's capstan and
///   parallelogram models join the candidates (`capstan`, `parallelogram`); `kinematics` is
///   read as this.
///
/// # Errors
/// [`Error::Config`] for any other name, in the user's words.
pub fn baseline_model(name: &str) -> Result<ModelName, Error> {
    match name.trim().to_ascii_lowercase().as_str() {
        "full" => return Ok(ModelName::Transmissions),
        "kinematics" => return Ok(ModelName::Geometric),
        _ => {}
    }
    match ModelName::from_name(name) {
        Some(m @ (ModelName::Transmissions | ModelName::Geometric)) => Ok(m),
        Some(m) => Err(Error::Config {
            message: format!(
                "baseline must be transmissions or geometric (full and kinematics are the same): \
                 a haptic device's log is diagnosed against one of the two, not {m}"
            ),
        }),
        None => Err(Error::Config {
            message: format!(
                "baseline must be transmissions or geometric (full and kinematics are the same), \
                 got {name:?}"
            ),
        }),
    }
}

/// Settings of [`diagnose`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiagnoseConfig {
    /// The baseline model: transmissions or geometric ([`baseline_model`]).
    pub baseline: ModelName,
    /// Number of cross-validation folds (time-contiguous blocks of samples), ≥ 2.
    pub folds: usize,
    /// Family-wise significance level of the candidate tests (Holm–Bonferroni) and of the
    /// gap test.
    pub alpha: f64,
    /// Largest number of effects added greedily (rounds go on while the cross-validated
    /// error is significantly above the floor and a candidate passes).
    pub max_effects: usize,
    /// Smallest share of its round's gap a winner must close, 0–1: the cross-validated error
    /// left by the effects accepted before it, above the floor.
    pub min_gap_share: f64,
    /// Most rows diagnosed: a longer log is diagnosed on every `s`-th row from its first,
    /// the smallest stride that leaves at most this many (`hapcal_calibrate::fit::ladder_sample`),
    /// and the diagnosis's notes say so. The candidates' columns take about 57 kB a row (567 MB
    /// peak at 10,000 rows of the reference device, `hapcal diagnose`, release build), so
    /// 10,000 keeps a day's log within 1 GB.
    pub max_rows: usize,
}

impl Default for DiagnoseConfig {
    /// Transmissions baseline, 5 folds, α = 0.01, up to 3 effects, each winner closes ≥ 20 % of the
    /// gap left by the effects before it (so that two effects of similar size, or a small one
    /// after a large one, can be found one after the other);
    /// together the accepted effects must close ≥ 80 % of the gap or leave a residual
    /// consistent with the floor, else the verdict is `none` (docs/diagnosis.md §3 (d)).
    fn default() -> DiagnoseConfig {
        DiagnoseConfig {
            baseline: ModelName::Transmissions,
            folds: 5,
            alpha: 0.01,
            max_effects: 3,
            min_gap_share: 0.2,
            max_rows: 10_000,
        }
    }
}

/// One identified effect parameter with its standard deviation (the haptic and the arm
/// diagnosis).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamValue {
    /// `effect.key`: `backlash.j2`, `gravity_compliance.joint_a2`, or `effect.axis`.
    pub name: String,
    /// Value, in `unit`.
    pub value: f64,
    /// Standard deviation, in `unit` (σ from the spec or the residuals, whichever is larger,
    /// on a haptic device; from the residuals on a robot).
    pub std: f64,
    /// SI unit (`rad`, `m`, `rad/(N·m)`, `rad/m`, `1`).
    pub unit: String,
}

/// One candidate effect, tested against the current baseline.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Candidate {
    /// The effect (docs/design.md §6; `capstan`/`parallelogram` with the geometric baseline),
    /// serialised by its name.
    pub effect: Effect,
    /// Greedy round (1 = against the baseline; 2 = after the first winner was added).
    pub round: usize,
    /// Cross-validated distance RMS of the round's baseline, m.
    #[serde(rename = "cv_rms_before_m")]
    pub heldout_rms_before_m: f64,
    /// Cross-validated distance RMS with this candidate's parameters added, m.
    #[serde(rename = "cv_rms_after_m")]
    pub heldout_rms_after_m: f64,
    /// Share of the round's held-out gap the candidate closes, %:
    /// `(MSE_before − MSE_after)/(MSE_before − floor)`.
    pub gap_closed_pct: f64,
    /// Whether it passed every test (see `reason`).
    pub accepted: bool,
    /// Why it was accepted or rejected.
    pub reason: String,
    /// Its parameters fitted with the baseline on all samples, ± std (σ from the spec, or
    /// from the residuals when they are larger).
    pub parameters: Vec<ParamValue>,
    /// F-test p-value of the added parameters (visible parts only), Holm-adjusted.
    pub p_value: f64,
    /// Number of visible (not absorbed) parameters.
    pub n_visible: usize,
    /// Fraction of the candidate's signature (in norm) left after projecting out the
    /// baseline's columns, per parameter.
    pub visible_fraction: Vec<f64>,
    /// Baseline parameters that absorb the candidate's invisible parameters.
    pub absorbed_by: Vec<String>,
    /// `ΔRSS − k·ln N` (weighted, spec σ): the BIC gain; > 0 beats the penalty.
    pub bic_gain: f64,
}

/// One bin of a residual map (the haptic and the arm diagnosis).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Bin {
    /// The binned signal: on a haptic device `q3`, `motor_phase2`, `distance`, `cable_angle`,
    /// `direction5`, `time`, `drum_phase`; on a robot `q2`, `time`, `torque2`, `reach`,
    /// `height`, `azimuth`.
    pub signal: String,
    /// Lower edge, in the signal's unit (rad, m, s, N·m; direction −1 or +1).
    pub lo: f64,
    /// Upper edge.
    pub hi: f64,
    /// Samples (configurations on a robot) in the bin.
    pub n: usize,
    /// Held-out residual RMS in the bin (of the cable distance, or of the 3-D position), m.
    pub rms_m: f64,
    /// Held-out residual mean in the bin, m (a haptic device's signed distance residual;
    /// `None` for a robot's 3-D error, and then not written).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_m: Option<f64>,
    /// The floor's RMS in the bin (on a robot without a floor, the overall held-out RMS), m.
    pub floor_rms_m: f64,
    /// `P(χ²_n > Σ e²/var)`: the chance of this RMS from noise alone (Holm-adjusted over
    /// every bin on a robot).
    pub p_value: f64,
    /// Significantly above the floor at `alpha` (Bonferroni over all bins on a haptic device,
    /// Holm on a robot).
    pub flagged: bool,
}

/// How strongly the residual depends on one signal.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SignalTest {
    /// The signal.
    pub signal: String,
    /// Between-bin F-test p-value on the squared standardised residuals.
    pub p_value: f64,
    /// Significant (Bonferroni over signals at `alpha`).
    pub significant: bool,
}

/// How much of the gap a free joint-angle error (a degree-6 polynomial of one joint's
/// reading) would explain: which joint the residual lives on.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JointProbe {
    /// Joint, 1-based.
    pub joint: usize,
    /// Share of the gap (in-sample weighted excess) it explains, %.
    pub explained_pct: f64,
    /// F-test p-value.
    pub p_value: f64,
}

/// One accepted effect and how far it shrinks the residual.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Step {
    /// The effect, serialised by its name.
    pub effect: Effect,
    /// Cross-validated distance RMS before adding it, m.
    #[serde(rename = "cv_rms_before_m")]
    pub heldout_rms_before_m: f64,
    /// Cross-validated distance RMS after adding it (nonlinear refit), m.
    #[serde(rename = "cv_rms_after_m")]
    pub heldout_rms_after_m: f64,
    /// Share of the original gap closed by this step, %.
    pub gap_closed_pct: f64,
    /// Identified parameters ± std.
    pub parameters: Vec<ParamValue>,
    /// Candidates whose signature resembles this one's (cosine > 0.9).
    pub confusable_with: Vec<Effect>,
}

/// The diagnosis of one log (see [`diagnose`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Diagnosis {
    /// The baseline used: transmissions or geometric ([`baseline_model`]).
    pub baseline: ModelName,
    /// Samples in the log.
    pub n_samples: usize,
    /// Identifiable baseline parameters.
    pub n_params: usize,
    /// How the floor was estimated.
    pub floor_method: String,
    /// σ of the cable distance from the spec, m.
    pub sigma_m_m: f64,
    /// σ of the external encoders from the spec, rad.
    pub sigma_e_rad: f64,
    /// Floor of the held-out distance RMS, m: `sqrt(mean(σ_i²·(1 + h_i)))`.
    pub floor_rms_m: f64,
    /// Cross-validated distance RMS of the baseline, m.
    #[serde(rename = "cv_rms_m")]
    pub heldout_rms_m: f64,
    /// The gap `sqrt(max(0, MSE_cv − floor²))`, m.
    pub gap_rms_m: f64,
    /// The gap in units of the floor.
    pub gap_in_floors: f64,
    /// `P(χ² > Σ e²/var)` of the held-out residuals: the chance of this gap from noise.
    pub gap_p_value: f64,
    /// Whether the gap is significant at `alpha`.
    pub gap_significant: bool,
    /// The residual map of the baseline (held-out residuals).
    #[serde(rename = "where")]
    pub where_: Vec<Bin>,
    /// Per signal: does the residual depend on it?
    pub signals: Vec<SignalTest>,
    /// Per joint: a free joint-angle error's share of the gap.
    pub joints: Vec<JointProbe>,
    /// Every candidate of every round.
    pub candidates: Vec<Candidate>,
    /// Accepted effects in order.
    pub steps: Vec<Step>,
    /// Cross-validated distance RMS after all accepted effects, m.
    #[serde(rename = "cv_rms_final_m")]
    pub heldout_rms_final_m: f64,
    /// Share of the held-out gap closed by all accepted effects, %.
    pub gap_closed_pct: f64,
    /// Share of the in-sample excess `RSS − dof` (weighted) closed by all accepted effects, %.
    pub gap_closed_in_sample_pct: f64,
    /// The effects named (`none`, or their names joined by `+` in the report).
    pub verdict: Verdict,
    /// Signals along which the final residual still varies (leads when nothing fits).
    pub leads: Vec<String>,
    /// Things the user should know (baseline fallbacks, untestable candidates).
    pub notes: Vec<String>,
}

/// Diagnoses a log: the gap between the calibrated model and the floor, where it lies,
/// which library effect explains it, and how far it shrinks (docs/design.md §6, docs/diagnosis.md).
///
/// `device` is the nominal device file; `rows` a log in docs/design.md §5 format (time order
/// when `t_s` is given). No truth is used.
///
/// **Floor.** From the encoder specification: the paper's noise model (docs/design.md §3) with
/// the cable encoder's counts and drum radius, `σ_e = 2π/counts/3`, `σ_m = 2π·R_d·σ_e`, plus
/// each joint reading's quantisation `ρ_j²/12` (`ρ_j = 2π/(counts·R_j)`) propagated through
/// `∂d/∂q_j`; the held-out floor adds each prediction's variance (`σ²·(1 + h)`,
/// docs/diagnosis.md §1). If the baseline's residuals are significantly *below* that floor (as
/// in logs simulated with the truth computed from the quantised reading), the quantisation
/// term is dropped, and [`Diagnosis::floor_method`] says so.
///
/// **Which.** Every candidate is linearised at the baseline estimate; its columns are
/// projected on the orthogonal complement of the baseline's (absorbed columns are reported
/// with the baseline parameters that absorb them); an F-test (Holm–Bonferroni over the
/// library), a BIC penalty, k-fold cross-validation over time-contiguous blocks (held-out
/// improvement > 1 standard error) and a share of the gap ≥ `min_gap_share` decide. The
/// best accepted candidate is refitted with the baseline (Levenberg–Marquardt) and the next
/// round starts from there, up to `max_effects`.
///
/// # Errors
/// [`Error::Config`] for bad settings; [`Error::Data`] for a log with fewer than 20 rows or
/// rows that do not fit the device; [`Error::Baseline`] if the device has no chain or the
/// transmissions cannot be fitted.
pub fn diagnose(
    device: &Device,
    rows: &[LogRow],
    cfg: &DiagnoseConfig,
) -> Result<Diagnosis, Error> {
    crate::error::check_rounds(cfg.folds, cfg.alpha, cfg.max_effects)?;
    let (b, fit) = baseline::baseline(device, rows, cfg)?;
    let (where_, signals) =
        residual_map::residual_map(device, &b.data, &fit.base.lin, &fit.base.cv, cfg.alpha);
    let joints = probe::joint_probes(device, &b, &fit);
    let run = which::select(device, &b, fit, cfg)?;
    let far = how_far::how_far(device, &b, &run, cfg);
    let gap = &b.gap;
    let floor_rms = gap.floor0.sqrt();
    let gap_rms = gap.gap2.max(0.0).sqrt();
    let mut notes = b.notes.clone();
    notes.extend(run.notes);
    notes.extend(far.notes);
    Ok(Diagnosis {
        baseline: b.model,
        n_samples: b.n(),
        n_params: b.n_params,
        floor_method: b.floor_method.clone(),
        sigma_m_m: b.setup.sigma_m_m(),
        sigma_e_rad: b.setup.sigma_e_rad(),
        floor_rms_m: floor_rms,
        heldout_rms_m: gap.mse0.sqrt(),
        gap_rms_m: gap_rms,
        gap_in_floors: if floor_rms > 0.0 {
            gap_rms / floor_rms
        } else {
            0.0
        },
        gap_p_value: gap.p,
        gap_significant: gap.significant,
        where_,
        signals,
        joints,
        candidates: run.candidates,
        steps: run.steps,
        heldout_rms_final_m: far.final_mse.sqrt(),
        gap_closed_pct: if gap.gap2 > 0.0 {
            100.0 * (gap.mse0 - far.final_mse) / gap.gap2
        } else {
            0.0
        },
        gap_closed_in_sample_pct: 100.0 * far.closed_in_sample,
        verdict: far.verdict,
        leads: far.leads,
        notes,
    })
}

#[cfg(test)]
mod tests;
