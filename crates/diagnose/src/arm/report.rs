//! What the serial-arm diagnosis reports: its candidates, steps, residual map, ladder and
//! verdict.

use hapcal_calibrate::baseline::DataKind;
use hapcal_calibrate::model::Rung;
use hapcal_contract::Effect;
use serde::Serialize;

use crate::{Bin, ParamValue, Verdict};

/// Where the floor came from.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FloorSource {
    /// The instrument σ the user stated (`--sigma-m`).
    Stated,
    /// Repeated poses in the data (repeatability): pooled within-pose scatter of the residuals.
    RepeatedPoses {
        /// Degrees of freedom of the pooled variance.
        dof: usize,
    },
    /// The sockets' replicates: half the mean squared difference of the residuals of each
    /// configuration and its nearest configuration at the same socket (Rice 1984). An upper
    /// bound: model error that changes between neighbours adds to it.
    SocketReplicates {
        /// Pairs used.
        pairs: usize,
    },
    /// No floor: gaps are relative to the best model found.
    None,
}

/// One candidate tested in one round.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArmCandidate {
    /// The effect, serialised by its name.
    pub effect: Effect,
    /// Round (1 = against the geometric baseline).
    pub round: usize,
    /// Parameters visible in these data (not absorbed by the baseline).
    pub n_visible: usize,
    /// Cross-validated position RMS of the round's baseline on the training rows, m.
    #[serde(rename = "cv_rms_before_m")]
    pub heldout_rms_before_m: f64,
    /// Cross-validated position RMS with the candidate, m.
    #[serde(rename = "cv_rms_after_m")]
    pub heldout_rms_after_m: f64,
    /// Mean cross-validated weighted squared error per configuration, baseline minus
    /// candidate, and its blocked standard error (> 0: the candidate predicts better).
    #[serde(rename = "cv_improvement")]
    pub heldout_improvement: (f64, f64),
    /// One-sided Student-t p-value of the cross-validated improvement over the blocks (not
    /// adjusted: the gate is the improvement in standard errors).
    #[serde(rename = "cv_p_value")]
    pub heldout_p_value: f64,
    /// F-test p-value of the in-sample improvement, Holm-adjusted over the round.
    pub f_p_value: f64,
    /// Share of the round's gap it closes, %: `(MSE_before − MSE_after)/(MSE_before − floor²)`
    /// with the cross-validated MSEs (without a floor, of what the round's best candidate
    /// removes).
    pub gap_closed_pct: f64,
    /// Whether it was named.
    pub accepted: bool,
    /// Why it was, or was not.
    pub reason: String,
    /// Its parameters fitted with the baseline on all training rows.
    pub parameters: Vec<ParamValue>,
}

/// A rung of the diagnosis's ladder: a kinematic rung of the baseline (nominal, frames only,
/// joint offsets, geometric), or the geometric model with the effects named so far, in the
/// order they were named. Rendered and serialised as the user reads it: `geometric`,
/// `+ gravity_compliance + harmonic1`.
#[derive(Clone, Debug, PartialEq)]
pub enum ArmLadderRung {
    /// A rung of the calibration's ladder.
    Kinematic(Rung),
    /// Geometric plus these effects.
    Effects(Vec<Effect>),
}

impl std::fmt::Display for ArmLadderRung {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ArmLadderRung::Kinematic(r) => f.pad(&r.to_string()),
            ArmLadderRung::Effects(e) => {
                let names: Vec<String> = e.iter().map(|e| format!("+ {}", e.name())).collect();
                f.pad(&names.join(" "))
            }
        }
    }
}

impl Serialize for ArmLadderRung {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// One rung of the ladder.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArmRung {
    /// The rung.
    pub rung: ArmLadderRung,
    /// Cross-validated RMS of the 3-D position error on the training rows (blocked CV), m.
    pub cv_rms_m: f64,
    /// RMS on each held-out set (test file), m (order of [`ArmDiagnosis::test_sets`]).
    pub test_rms_m: Vec<f64>,
}

/// One accepted effect.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArmStep {
    /// The effect, serialised by its name.
    pub effect: Effect,
    /// Cross-validated position RMS on the training rows before it, m.
    #[serde(rename = "cv_rms_before_m")]
    pub heldout_rms_before_m: f64,
    /// After it.
    #[serde(rename = "cv_rms_after_m")]
    pub heldout_rms_after_m: f64,
    /// Share of the original gap (before the first effect) it closes, %.
    pub gap_closed_pct: f64,
    /// Share of the gap its round faced (left by the effects before it) it closes, %.
    pub round_gap_closed_pct: f64,
    /// Its parameters ± std.
    pub parameters: Vec<ParamValue>,
    /// Candidates the data confuse with it, each with the measurement that would separate them.
    pub confusable_with: Vec<(Effect, String)>,
    /// The same effect under another model that these data do not tell from it: for a
    /// compliance, the other torque model when, in its place beside the other named effects
    /// (a transversal compliance named beside it taking that model's loads too), it predicts
    /// worse by less than the two blocked standard errors that name an effect (held-out
    /// squared error, paired by block). Empty when the data name the model. A transversal
    /// compliance's torque model is its joint compliance's: it is open when that one is.
    pub alike: Vec<Effect>,
}

/// The diagnosis of a serial arm's data.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArmDiagnosis {
    /// What was measured.
    pub kind: DataKind,
    /// Training configurations.
    pub n_configurations: usize,
    /// Geometric parameters the baseline keeps.
    pub n_baseline_params: usize,
    /// How the floor was found, in words.
    pub floor_method: String,
    /// Where the floor came from.
    pub floor_source: FloorSource,
    /// Per-axis position σ of the floor, m (`None` without a floor).
    pub floor_sigma_m: Option<f64>,
    /// Floor of the held-out 3-D position RMS, m (`None` without a floor).
    pub floor_rms_m: Option<f64>,
    /// Cross-validated 3-D position RMS of the geometric baseline on the training rows, m.
    #[serde(rename = "cv_rms_m")]
    pub heldout_rms_m: f64,
    /// 3-D position RMS of the geometric baseline on each held-out set (test file), m (order
    /// of `test_sets`).
    pub test_rms_m: Vec<f64>,
    /// `sqrt(max(0, MSE − floor²))`, m; without a floor, relative to the best model found.
    pub gap_rms_m: f64,
    /// `P(χ² > Σe²/var)` of the held-out residuals under the floor (1 without a floor).
    pub gap_p_value: f64,
    /// Whether the gap is significant at `alpha`.
    pub gap_significant: bool,
    /// The residual map of the baseline's held-out residuals.
    #[serde(rename = "where")]
    pub where_: Vec<Bin>,
    /// Every candidate of every round of the final run of the rounds (after the stepwise
    /// revision; effects left out by it are named in the notes, with why).
    pub candidates: Vec<ArmCandidate>,
    /// Accepted effects in order.
    pub steps: Vec<ArmStep>,
    /// The effects named (`none`, or their names joined by `+` in the report).
    pub verdict: Verdict,
    /// Cross-validated position RMS after the accepted effects, m.
    #[serde(rename = "cv_rms_final_m")]
    pub heldout_rms_final_m: f64,
    /// Position RMS on each held-out set after the accepted effects, m (the training's
    /// estimate carried over; order of `test_sets`).
    pub test_rms_final_m: Vec<f64>,
    /// Share of the gap closed by the accepted effects, %.
    pub gap_closed_pct: f64,
    /// Held-out sets' names.
    pub test_sets: Vec<String>,
    /// The ladder: kinematic rungs, then each accepted effect.
    pub ladder: Vec<ArmRung>,
    /// Things the user should know.
    pub notes: Vec<String>,
}
