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
//! rounds then name the alternative.
//!
//! Errors are lengths: the 3-D error of a position, or the error of a distance (a distance
//! log); the RMS figures below are of those.

use hapcal_calibrate::baseline::{DataKind, GeometricBaseline, HeldOutSet};
use hapcal_calibrate::calibrate::blocked_mean_difference;
use hapcal_calibrate::model::{ModelName, Rung};
use hapcal_contract::Effect;
use hapcal_identify::Problem;
use hapcal_kinematics::Tree;
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, JointLoad, ModelTerms, Observations, RowKind,
    Transversal, TransversalTerm, Weights,
};
use nalgebra::{DMatrix, DVector, Vector3};
use serde::Serialize;

use crate::solve::lstsq;
use crate::stats::{chi2_sf, f_sf, holm, largest_column_norm, pivoted_basis, pivoted_basis_beside};
use crate::{Error, Verdict};

/// Remaining fraction of a candidate column's norm, after projecting out the baseline, below
/// which the column is absorbed by the baseline (invisible in these data).
const VISIBLE_TOL: f64 = 0.02;

/// Step of the central differences with respect to a joint reading, rad (m for a prismatic
/// joint): truncation error ~h² relative, rounding ~ε/h; both far below the noise.
const READING_STEP: f64 = 1e-6;

/// The tip's reach or height must span more than this (m) for the workspace maps: at sockets
/// it does not move.
const WORKSPACE_SPREAD_M: f64 = 0.01;

/// Share of the gap its round faced (the held-out error left by the effects before it, above
/// the floor) the last named effect must close, unless what it leaves is consistent with the
/// floor; below it the effect is not named, and the rule goes on with the one before it
/// (docs/diagnosis.md, the reference device's rule taken round by round).
const SUFFICIENT_SHARE: f64 = 0.8;

/// The same on the in-sample excess `RSS − dof` (in floor units) of the round: an effect that
/// is estimated poorly on training folds (a weakly determined parameter among several) closes
/// less of the held-out gap than of the in-sample excess (the reference device's second
/// chance).
const SUFFICIENT_SHARE_IN_SAMPLE: f64 = 0.9;

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
/// round on; [`ARM_BESIDE_COMPLIANCE`] adds the effects tested once a joint compliance is named.
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

/// The effects the serial-arm diagnosis tests beside a joint compliance, in the rounds after
/// [`Effect::GravityCompliance`] or [`Effect::LumpedCompliance`] is named, with that
/// compliance's weights as their loads: transversal compliance, one per revolute joint
/// (isotropic) or one per axis normal to the joint axis, each the other's alternative. Wherever
/// the calibration can fit them: a robot whose revolute joints carry rotation deviations (URDF
/// placements).
///
/// Why after the joint compliance rather than as one candidate with its columns: the
/// calibration fits transversal compliance only with the joint compliance, from the same gravity
/// loads (`--model transversal-compliance` is `compliance` plus the tilts, the rung above it on
/// the ladder), so the verdict names the two effects of that model, each on its own evidence:
/// the joint compliance against the geometric baseline, the tilts against what it leaves. A
/// candidate holding both would be named for the joint compliance alone (its columns carry
/// most of the signal), with 33 parameters where 16 explain it, and would fix the torque model
/// of the joint compliance to its own instead of leaving it to the joint compliance's test
/// ([`ArmStep::alike`]).
pub const ARM_BESIDE_COMPLIANCE: [Effect; 2] =
    [Effect::TransversalCompliance, Effect::TransversalAxes];

/// Every candidate of the diagnosis, in report order: [`ARM_LIBRARY`], then
/// [`ARM_BESIDE_COMPLIANCE`].
fn arm_candidates() -> impl Iterator<Item = Effect> {
    ARM_LIBRARY.into_iter().chain(ARM_BESIDE_COMPLIANCE)
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

/// One identified effect parameter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EffectParam {
    /// `effect.joint` (`gravity_compliance.joint_a2`) or `effect.axis`.
    pub name: String,
    /// Value, in `unit`.
    pub value: f64,
    /// Standard deviation (σ from the residuals).
    pub std: f64,
    /// Unit (`rad/(N·m)`, `rad/m`, `rad`, `m`, `1`).
    pub unit: String,
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
    pub parameters: Vec<EffectParam>,
}

/// One bin of the residual map.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArmBin {
    /// Signal (`q2`, `time`, `torque2`, `reach`, `height`, `azimuth`).
    pub signal: String,
    /// Lower edge, in the signal's unit (rad, m, s, N·m).
    pub lo: f64,
    /// Upper edge.
    pub hi: f64,
    /// Configurations in the bin.
    pub n: usize,
    /// Held-out 3-D position RMS in the bin, m.
    pub rms_m: f64,
    /// The floor's RMS in the bin (the overall held-out RMS without a floor), m.
    pub floor_rms_m: f64,
    /// `P(χ² > Σe²/var)`, Holm-adjusted over every bin.
    pub p_value: f64,
    /// Significantly above the floor at `alpha`.
    pub flagged: bool,
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
    pub parameters: Vec<EffectParam>,
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
    pub where_: Vec<ArmBin>,
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

/// What one residual measures.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Res {
    /// Axis `axis` of a position (marker, position or socket), σ of its weight, m.
    Position { axis: usize, sigma: f64 },
    /// An orientation component, σ rad.
    Orientation,
    /// A distance, σ m.
    Distance { sigma: f64 },
    /// A constraint between unknown points (never held out, never scored).
    Constraint,
}

impl Res {
    /// σ (m) of a residual that is a length error — a position axis or a distance — whose
    /// squares the held-out RMS, the floor and the residual map add up; `None` for an
    /// orientation or a constraint. (On a distance log every scored residual is a distance.)
    fn length_sigma(&self) -> Option<f64> {
        match self {
            Res::Position { sigma, .. } | Res::Distance { sigma } => Some(*sigma),
            Res::Orientation | Res::Constraint => None,
        }
    }
}

/// The rows of one problem, described for the effects.
struct Rows {
    /// Per residual: its kind and configuration (`usize::MAX` for constraints).
    res: Vec<(Res, usize)>,
    /// Per residual: the measured position of its row in the measurement frame (m), if any.
    measured: Vec<Option<[f64; 3]>>,
    /// Per configuration: readings.
    q: Vec<Vec<f64>>,
    /// Per configuration: group.
    group: Vec<usize>,
    /// Per configuration: time.
    time: Vec<f64>,
}

impl Rows {
    fn new(
        problem: &CalibrationProblem,
        configuration: &[usize],
        q: Vec<Vec<f64>>,
        group: Vec<usize>,
        time: Vec<f64>,
    ) -> Rows {
        let w = problem.weights();
        let obs = problem.observations();
        let mut res = Vec::new();
        let mut measured = Vec::new();
        for (row, &c) in obs.rows.iter().zip(configuration) {
            match &row.kind {
                RowKind::Distance { distance_m } => {
                    res.push((
                        Res::Distance {
                            sigma: w.sigma_distance_m,
                        },
                        c,
                    ));
                    measured.push(Some([*distance_m, 0.0, 0.0]));
                }
                RowKind::Position { position_m } | RowKind::Marker { position_m, .. } => {
                    for axis in 0..3 {
                        res.push((
                            Res::Position {
                                axis,
                                sigma: w.sigma_position_m,
                            },
                            c,
                        ));
                        measured.push(Some(*position_m));
                    }
                }
                RowKind::Pose { position_m, .. } => {
                    for axis in 0..3 {
                        res.push((
                            Res::Position {
                                axis,
                                sigma: w.sigma_position_m,
                            },
                            c,
                        ));
                        measured.push(Some(*position_m));
                    }
                    for _ in 0..3 {
                        res.push((Res::Orientation, c));
                        measured.push(None);
                    }
                }
                RowKind::Point { .. } => {
                    for axis in 0..3 {
                        res.push((
                            Res::Position {
                                axis,
                                sigma: w.sigma_point_m,
                            },
                            c,
                        ));
                        measured.push(None);
                    }
                }
            }
        }
        for _ in 0..obs.point_distances.len() {
            res.push((Res::Constraint, usize::MAX));
            measured.push(None);
        }
        Rows {
            res,
            measured,
            q,
            group,
            time,
        }
    }

    fn n_configurations(&self) -> usize {
        self.q.len()
    }
}

/// Residuals of `problem` at `x`, as a vector.
fn residuals(problem: &CalibrationProblem, x: &faer::Col<f64>) -> Result<DVector<f64>, Error> {
    let mut r = faer::Col::<f64>::zeros(problem.n_residuals());
    problem
        .residuals(x.as_ref(), r.as_mut())
        .map_err(|e| Error::Baseline {
            message: format!("evaluating the residuals: {e}"),
        })?;
    Ok(DVector::from_iterator(r.nrows(), r.iter().copied()))
}

/// Jacobian columns of `problem` at `x`, one matrix per set of `sets` (a `None` entry is a
/// zero column), from one evaluation of the Jacobian.
fn jacobian_sets<const N: usize>(
    problem: &CalibrationProblem,
    x: &faer::Col<f64>,
    sets: [&[Option<usize>]; N],
) -> Result<[DMatrix<f64>; N], Error> {
    let mut j = faer::Mat::<f64>::zeros(problem.n_residuals(), problem.layout().len());
    problem
        .jacobian(x.as_ref(), j.as_mut())
        .map_err(|e| Error::Baseline {
            message: format!("evaluating the Jacobian: {e}"),
        })?;
    Ok(sets.map(|cols| {
        DMatrix::from_fn(j.nrows(), cols.len(), |i, k| {
            cols[k].map_or(0.0, |c| j[(i, c)])
        })
    }))
}

/// Per joint of `names`, the indices of its placement's rotation deviations `{joint}.rx`,
/// `.ry`, `.rz` in `problem`'s layout, three entries per joint (`None` for a joint without
/// them: a D-H row, or no rotation deviations).
fn rotation_params(problem: &CalibrationProblem, names: &[String]) -> Vec<Option<usize>> {
    let chain = problem.chain();
    (names.iter())
        .flat_map(|name| ["rx", "ry", "rz"].map(|a| chain.param_index(&format!("{name}.{a}"))))
        .collect()
}

/// What the effects are built from: the problem's derivatives at the estimate.
struct Derivatives {
    /// `∂r/∂q_j` for every joint (`n_residuals × n_joints`).
    dq: DMatrix<f64>,
    /// `∂r/∂ρ_{j,a}` for the rotation deviations `rx`, `ry`, `rz` of every joint's placement
    /// (`n_residuals × 3·n_joints`, columns `3j..3j + 3`; zero for a joint without them).
    rotation: DMatrix<f64>,
}

/// `∂r/∂q_j` for every joint (n_residuals × n_joints), by central differences of the problem
/// with every row's reading of joint `j` moved by ±[`READING_STEP`].
fn reading_derivatives(
    problem: &CalibrationProblem,
    x: &faer::Col<f64>,
    n_joints: usize,
) -> Result<DMatrix<f64>, Error> {
    let obs = problem.observations();
    let mut d = DMatrix::zeros(problem.n_residuals(), n_joints);
    for j in 0..n_joints {
        let moved = |h: f64| -> Result<DVector<f64>, Error> {
            let mut o: Observations = obs.clone();
            for row in &mut o.rows {
                row.q[j] += h;
            }
            let p = problem.with_observations(o).map_err(|e| Error::Baseline {
                message: e.to_string(),
            })?;
            residuals(&p, x)
        };
        let plus = moved(READING_STEP)?;
        let minus = moved(-READING_STEP)?;
        d.set_column(j, &((plus - minus) / (2.0 * READING_STEP)));
    }
    Ok(d)
}

/// What the effects need to know about the robot.
struct Context<'a> {
    baseline: &'a GeometricBaseline,
    /// Gravity-torque model of the link masses, if any are known.
    masses: Option<GravityCompliance>,
    /// Gravity direction in the measurement frame.
    gravity: Vector3<f64>,
    /// Largest horizontal reach over the training configurations, m.
    reach_max: f64,
    /// The drift's time origin (the first training time), the training's span and its
    /// median time step, s.
    time_origin: f64,
    time_span: f64,
    time_step: f64,
    /// The calibration's transversal compliance terms of the robot, isotropic and per axis
    /// ([`library_transversal`]), or why it has none.
    transversal: Result<[Vec<TransversalTerm>; 2], String>,
}

impl Context<'_> {
    fn n_joints(&self) -> usize {
        self.baseline.robot.joint_names.len()
    }

    /// The gravity loads of a joint compliance `effect`: the link masses for
    /// [`Effect::GravityCompliance`], unit weights for [`Effect::LumpedCompliance`]; `Err`
    /// with the reason when the robot's masses are unknown.
    fn torque_model(&self, effect: Effect) -> Result<GravityCompliance, String> {
        match effect {
            Effect::GravityCompliance => self.masses.clone().ok_or_else(|| {
                "no link masses: the URDF has no <inertial> and the robot's published masses \
                 are unknown"
                    .to_owned()
            }),
            _ => Ok(GravityCompliance::default()),
        }
    }

    /// Tip position on the nominal robot, base frame, m.
    fn tip(&self, q: &[f64]) -> Vector3<f64> {
        let chain = &self.baseline.torque_chain;
        chain.end_point(&vec![0.0; chain.n_params()], q).coords
    }

    fn reach(&self, q: &[f64]) -> f64 {
        let p = self.tip(q);
        (p.x * p.x + p.y * p.y).sqrt()
    }
}

/// The joint-angle basis of `effect` at every configuration: per parameter, its name, unit,
/// joint and per-configuration value; `Err` with the reason when the data cannot test it.
#[allow(clippy::type_complexity)]
fn joint_terms(
    effect: Effect,
    ctx: &Context<'_>,
    rows: &Rows,
) -> Result<Vec<(String, &'static str, usize, Vec<f64>)>, String> {
    let names = &ctx.baseline.robot.joint_names;
    let prismatic = &ctx.baseline.robot.prismatic;
    let n = ctx.n_joints();
    // A joint whose basis is negligible beside the effect's largest (a torque that gravity
    // never loads, on a joint whose axis is vertical or carries the tip on its axis) is left
    // out: its column would be numerical noise.
    let per_joint = |unit: &'static str, f: &dyn Fn(usize, usize) -> f64, revolute_only: bool| {
        let all: Vec<(usize, Vec<f64>)> = (0..n)
            .filter(|&j| !(revolute_only && prismatic[j]))
            .map(|j| (j, (0..rows.n_configurations()).map(|c| f(c, j)).collect()))
            .collect();
        let size = |b: &Vec<f64>| b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let largest = all.iter().map(|(_, b)| size(b)).fold(0.0, f64::max);
        all.into_iter()
            .filter(|(_, b)| size(b) > NEGLIGIBLE_BASIS * largest)
            .map(|(j, b)| (format!("{}.{}", effect.name(), names[j]), unit, j, b))
            .collect::<Vec<_>>()
    };
    Ok(match effect {
        Effect::GravityCompliance | Effect::LumpedCompliance => {
            let model = ctx.torque_model(effect)?;
            // Every link's weight on every branch of the robot's tree (its loads).
            let tips = &ctx.baseline.torque_tips;
            let torques: Vec<Vec<f64>> = (rows.q.iter())
                .map(|q| {
                    (model.joint_loads(tips, q).iter())
                        .map(|l| l.torque)
                        .collect()
                })
                .collect();
            let unit = if effect == Effect::GravityCompliance {
                "rad/(N·m)"
            } else {
                "rad/m"
            };
            per_joint(unit, &|c, j| torques[c][j], false)
        }
        Effect::FirstHarmonic | Effect::SecondHarmonic => {
            let h = if effect == Effect::FirstHarmonic {
                1.0
            } else {
                2.0
            };
            let mut out = Vec::new();
            for (label, f) in [("sin", f64::sin as fn(f64) -> f64), ("cos", f64::cos)] {
                for mut t in per_joint("rad", &|c, j| f(h * rows.q[c][j]), true) {
                    t.0 = format!("{}_{label}", t.0);
                    out.push(t);
                }
            }
            out
        }
        Effect::Backlash => {
            let signs = approach_signs(&rows.q, &rows.group);
            per_joint("rad", &|c, j| signs[c][j], false)
        }
        Effect::GearRatio => per_joint("1", &|c, j| rows.q[c][j], false),
        _ => return Err("not a joint-angle effect".into()),
    })
}

/// The calibration's transversal compliance terms of `robot` (its tree without instrument
/// frames, whose tips carry the gravity loads), isotropic and per axis: the terms
/// [`CalibrationProblem`] builds for `--model transversal-compliance` and `transversal-axes`
/// (joint and, per axis, the axis normal to the joint axis), read from such a problem on no
/// rows, so that the joints and axes are the calibration's own. `Err` with the calibration's
/// reason when the robot has none (a D-H chain, no revolute joint).
fn library_transversal(robot: &Tree) -> Result<[Vec<TransversalTerm>; 2], String> {
    let terms = |transversal| {
        let problem = CalibrationProblem::on_tree(
            robot.clone(),
            Observations::default(),
            Weights::default(),
            ModelTerms {
                compliance: Some(GravityCompliance::default()),
                transversal,
                ..ModelTerms::default()
            },
        )
        .map_err(|e| e.to_string())?;
        Ok::<_, String>(problem.model(problem.initial_guess().as_ref()).transversal)
    };
    Ok([terms(Transversal::Isotropic)?, terms(Transversal::PerAxis)?])
}

/// The columns of the transversal compliance terms `terms` on `rows`, under the gravity loads
/// `loads[c]` of each configuration `c`: for term `t` of joint `j` and residual `i` of
/// configuration `c`, `Σ_a ∂r_i/∂ρ_{j,a} · tilt_t(c)_a`, with `ρ_j = (rx, ry, rz)` joint
/// `j`'s placement rotation deviations (its frame before its motion; `rotation`, three columns
/// per joint) and `tilt_t(c)` [`TransversalTerm::tilt`]. The calibration adds `c_t·tilt_t(c)`
/// to `ρ_j` in every row ([`hapcal_problems::Transversal`]), so each column is the exact first
/// derivative of its residuals in `c_t` at zero compliance: the tilt carried through the
/// chain to every marker or tip below the joint and into the instrument frame.
fn transversal_block(
    terms: &[TransversalTerm],
    rotation: &DMatrix<f64>,
    rows: &Rows,
    loads: &[Vec<JointLoad>],
) -> DMatrix<f64> {
    let tilts: Vec<Vec<Vector3<f64>>> = (loads.iter())
        .map(|l| terms.iter().map(|t| t.tilt(&l[t.joint])).collect())
        .collect();
    let mut m = DMatrix::zeros(rows.res.len(), terms.len());
    for (i, (_, c)) in rows.res.iter().enumerate() {
        if *c == usize::MAX {
            continue;
        }
        for (p, (t, tilt)) in terms.iter().zip(&tilts[*c]).enumerate() {
            m[(i, p)] = (0..3)
                .map(|a| rotation[(i, 3 * t.joint + a)] * tilt[a])
                .sum();
        }
    }
    m
}

/// The parameter names of transversal compliance terms (`effect.joint`, and `.u` / `.v` per
/// axis, the calibration's `transversal.{joint}[.u|.v]`), and their unit under `compliance`'s
/// loads.
fn transversal_names(
    effect: Effect,
    terms: &[TransversalTerm],
    joint_names: &[String],
    compliance: Effect,
) -> Vec<(String, &'static str)> {
    let unit = if compliance == Effect::GravityCompliance {
        "rad/(N·m)"
    } else {
        "rad/m"
    };
    (terms.iter().enumerate())
        .map(|(k, t)| {
            let axis = match (t.direction, k % 2) {
                (None, _) => "",
                (Some(_), 0) => ".u",
                (Some(_), _) => ".v",
            };
            (
                format!("{}.{}{axis}", effect.name(), joint_names[t.joint]),
                unit,
            )
        })
        .collect()
}

/// The columns the diagnosis tests for the transversal compliance `effect`
/// ([`Effect::TransversalCompliance`] or [`Effect::TransversalAxes`]) on `problem` at `x`,
/// with the gravity loads of `weights` on the tips of `robot` (the robot's tree without
/// instrument frames, as [`GeometricBaseline::torque_tips`]): per parameter, its name (as in
/// [`ArmCandidate::parameters`]) and the derivative of each of `problem`'s residuals (its
/// order and weighting) per unit compliance, rad/(N·m) with link masses, rad/m with unit
/// weights. They are the exact first derivatives of the calibration's transversal model
/// (`--model transversal-compliance` and `transversal-axes`: the tilt `c·m⊥(q)` added to each
/// revolute joint's rotation deviations) at zero compliance; `problem` is a geometric
/// calibration problem, or one whose compliances are zero at `x`.
///
/// # Errors
/// [`Error::Config`] for an effect that is not a transversal compliance; [`Error::Data`] when
/// the robot has none (no revolute joint with rotation deviations); [`Error::Baseline`] if
/// the problem cannot be evaluated.
///
/// # Panics
/// If `x.nrows()` differs from `problem`'s parameter count, or `robot`'s joints from
/// `problem`'s.
#[track_caller]
pub fn transversal_columns(
    problem: &CalibrationProblem,
    x: &faer::Col<f64>,
    robot: &Tree,
    weights: &GravityCompliance,
    effect: Effect,
) -> Result<Vec<(String, Vec<f64>)>, Error> {
    if !effect.is_transversal() {
        return Err(Error::Config {
            message: format!("{} is not a transversal compliance", effect.name()),
        });
    }
    let terms = library_transversal(robot).map_err(|message| Error::Data { message })?;
    let terms = &terms[usize::from(effect == Effect::TransversalAxes)];
    let obs = problem.observations();
    let q: Vec<Vec<f64>> = obs.rows.iter().map(|r| r.q.clone()).collect();
    let n_rows = q.len();
    let rows = Rows::new(
        problem,
        &(0..n_rows).collect::<Vec<_>>(),
        q,
        vec![0; n_rows],
        vec![0.0; n_rows],
    );
    let names = robot.joint_names();
    let [rotation] = jacobian_sets(problem, x, [&rotation_params(problem, names)])?;
    let loads: Vec<Vec<JointLoad>> = (rows.q.iter())
        .map(|q| weights.joint_loads(robot.tips(), q))
        .collect();
    let m = transversal_block(terms, &rotation, &rows, &loads);
    let compliance = if weights.masses.is_empty() {
        Effect::LumpedCompliance
    } else {
        Effect::GravityCompliance
    };
    Ok(transversal_names(effect, terms, names, compliance)
        .into_iter()
        .enumerate()
        .map(|(k, (name, _))| (name, m.column(k).iter().copied().collect()))
        .collect())
}

/// The sign of each joint's last motion at every configuration (`q[c]`, rad or m), from the
/// configurations before it in the same group (`group[c]`), in order: `+1` or `−1` when the
/// joint moved by at least [`REPEAT_TOLERANCE`] since the previous configuration, the previous
/// sign when it did not (the gear stays on the flank it was driven against), 0 before the
/// group's first motion. The basis of [`Effect::Backlash`]; shape `q.len() × n_joints`.
pub fn approach_signs(q: &[Vec<f64>], group: &[usize]) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::with_capacity(q.len());
    for c in 0..q.len() {
        let same_group = c > 0 && group.get(c) == group.get(c - 1);
        let signs = (0..q[c].len())
            .map(|j| {
                if !same_group {
                    return 0.0;
                }
                let d = q[c][j] - q[c - 1].get(j).copied().unwrap_or(q[c][j]);
                if d.abs() >= REPEAT_TOLERANCE {
                    d.signum()
                } else {
                    out[c - 1][j]
                }
            })
            .collect();
        out.push(signs);
    }
    out
}

/// The columns (weighted residual per unit parameter) of `effect` on `rows` (derivatives
/// `d`), named with the effects `with` (a transversal compliance takes the gravity loads of
/// the joint compliance among them), and their names and units; `Err` with the reason when
/// these data cannot test it.
#[allow(clippy::type_complexity)]
fn effect_columns(
    effect: Effect,
    ctx: &Context<'_>,
    rows: &Rows,
    d: &Derivatives,
    with: &[Effect],
) -> Result<(DMatrix<f64>, Vec<(String, &'static str)>), String> {
    let n_res = rows.res.len();
    let positional = |basis: &dyn Fn(usize, usize, Option<[f64; 3]>) -> Vec<[f64; 3]>,
                      names: Vec<(String, &'static str)>|
     -> DMatrix<f64> {
        let k = names.len();
        let mut m = DMatrix::zeros(n_res, k);
        for (i, ((kind, c), meas)) in rows.res.iter().zip(&rows.measured).enumerate() {
            let (axis, sigma) = match kind {
                Res::Position { axis, sigma } => (*axis, *sigma),
                Res::Distance { sigma } => (usize::MAX, *sigma),
                _ => continue,
            };
            let v = basis(*c, axis, *meas);
            for (p, v) in v.iter().enumerate().take(k) {
                m[(i, p)] = (if axis == usize::MAX { v[0] } else { v[axis] }) / sigma;
            }
        }
        m
    };
    let has_distance = rows.res.iter().any(|r| matches!(r.0, Res::Distance { .. }));
    let has_position = rows.res.iter().any(|r| matches!(r.0, Res::Position { .. }));
    match effect {
        Effect::ThermalDrift => {
            if ctx.time_span <= 0.0 {
                return Err("all configurations at one time".into());
            }
            let s = |c: usize| (rows.time[c] - ctx.time_origin) / ctx.time_span;
            let mut names = Vec::new();
            if has_position {
                names.extend(["x", "y", "z"].map(|a| (format!("thermal_drift.{a}"), "m")));
            }
            if has_distance {
                names.push(("thermal_drift.d".into(), "m"));
            }
            let n_pos = if has_position { 3 } else { 0 };
            let m = positional(
                &|c, axis, _| {
                    let t = s(c);
                    if axis == usize::MAX {
                        let mut v = vec![[0.0; 3]; n_pos + 1];
                        v[n_pos] = [t, 0.0, 0.0];
                        v
                    } else {
                        vec![[t, 0.0, 0.0], [0.0, t, 0.0], [0.0, 0.0, t]]
                    }
                },
                names.clone(),
            );
            Ok((m, names))
        }
        Effect::LinkDeflection => {
            if !has_position {
                return Err("no position measured".into());
            }
            let g = ctx.gravity;
            let m = positional(
                &|c, axis, _| {
                    if axis == usize::MAX {
                        return vec![[0.0; 3]];
                    }
                    let s = (ctx.reach(&rows.q[c]) / ctx.reach_max).powi(3);
                    vec![(g * s).into()]
                },
                vec![("link_deflection.sag".into(), "m")],
            );
            Ok((m, vec![("link_deflection.sag".into(), "m")]))
        }
        Effect::InstrumentScale => {
            if ctx.baseline.kind == DataKind::Sockets {
                return Err("socket data have no instrument".into());
            }
            let m = positional(
                &|_, _, meas| vec![meas.unwrap_or([0.0; 3])],
                vec![("instrument_scale.s".into(), "1")],
            );
            Ok((m, vec![("instrument_scale.s".into(), "1")]))
        }
        Effect::TransversalCompliance | Effect::TransversalAxes => {
            let Some(&compliance) = with.iter().find(|e| e.is_joint_compliance()) else {
                return Err("tested beside a joint compliance, none is named".into());
            };
            let model = ctx.torque_model(compliance)?;
            let terms = &ctx.transversal.as_ref().map_err(Clone::clone)?
                [usize::from(effect == Effect::TransversalAxes)];
            let loads: Vec<Vec<JointLoad>> = (rows.q.iter())
                .map(|q| model.joint_loads(&ctx.baseline.torque_tips, q))
                .collect();
            let m = transversal_block(terms, &d.rotation, rows, &loads);
            if (0..m.ncols()).all(|k| m.column(k).norm() == 0.0) {
                return Err("no variation in these data".into());
            }
            let names =
                transversal_names(effect, terms, &ctx.baseline.robot.joint_names, compliance);
            Ok((m, names))
        }
        _ => {
            let terms = joint_terms(effect, ctx, rows)?;
            let mut m = DMatrix::zeros(n_res, terms.len());
            for (i, (_, c)) in rows.res.iter().enumerate() {
                if *c == usize::MAX {
                    continue;
                }
                for (p, (_, _, j, basis)) in terms.iter().enumerate() {
                    m[(i, p)] = d.dq[(i, *j)] * basis[*c];
                }
            }
            let norms_zero = (0..m.ncols()).all(|k| m.column(k).norm() == 0.0);
            if norms_zero {
                return Err("no variation in these data".into());
            }
            Ok((m, terms.into_iter().map(|t| (t.0, t.1)).collect()))
        }
    }
}

impl Context<'_> {
    /// Times of the `n` configurations of a held-out set on the training's clock: a held-out
    /// set carries no time of its own, so it is taken to follow the training rows (the last
    /// rows of a file, or a file recorded after it), at the training's median time step.
    fn held_out_times(&self, n: usize) -> Vec<f64> {
        let end = self.time_origin + self.time_span;
        (1..=n).map(|k| end + k as f64 * self.time_step).collect()
    }
}

/// Median of the positive steps between consecutive times (1 without any).
fn median_step(time: &[f64]) -> f64 {
    let mut d: Vec<f64> = (time.windows(2))
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(1.0)
}

/// The fold of each configuration in each of [`CV_REPEATS`] repeats (contiguous blocks within
/// each group, repeat `r` shifting the boundaries by `r/CV_REPEATS` of a block,
/// [`hapcal_calibrate::calibrate`]'s scheme), and each configuration's block (group, fold) in
/// the first repeat: the independent units of the standard errors.
fn folds_of(group: &[usize], k: usize) -> (Vec<Vec<usize>>, Vec<usize>) {
    let n_groups = group.iter().max().map_or(0, |g| g + 1);
    let mut size = vec![0usize; n_groups];
    for &g in group {
        size[g] += 1;
    }
    let mut folds: Vec<Vec<usize>> = (0..CV_REPEATS)
        .map(|_| Vec::with_capacity(group.len()))
        .collect();
    let mut block = Vec::with_capacity(group.len());
    let mut seen = vec![0usize; n_groups];
    for &g in group {
        let (pos, n) = (seen[g], size[g].max(1));
        seen[g] += 1;
        for (r, f) in folds.iter_mut().enumerate() {
            let shifted = (pos * k * CV_REPEATS + r * n) % (n * k * CV_REPEATS);
            f.push(shifted / (n * CV_REPEATS));
        }
        block.push(g * k + folds[0][folds[0].len() - 1]);
    }
    (folds, block)
}

/// Held-out results of one linear model, averaged over the repeats.
#[derive(Clone)]
struct HeldOut {
    /// Per configuration: weighted squared held-out error (every residual kind).
    score: Vec<f64>,
    /// Per configuration: squared 3-D position error, m².
    position_m2: Vec<f64>,
    /// Per configuration: the floor of `position_m2` (σ²(1 + h) summed), m².
    floor_m2: Vec<f64>,
}

impl HeldOut {
    fn mse(&self) -> f64 {
        mean(&self.position_m2)
    }
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Repeated blocked k-fold cross-validation of the linear model `a·δ ≈ r` (weighted
/// residuals); `folds[r][c]` is configuration `c`'s fold in repeat `r`.
fn cross_validate(
    a: &DMatrix<f64>,
    r: &DVector<f64>,
    rows: &Rows,
    folds: &[Vec<usize>],
    k: usize,
    floor_var: Option<f64>,
) -> HeldOut {
    let n_c = rows.n_configurations();
    let mut out = HeldOut {
        score: vec![0.0; n_c],
        position_m2: vec![0.0; n_c],
        floor_m2: vec![0.0; n_c],
    };
    let w = 1.0 / folds.len().max(1) as f64;
    for fold in folds {
        for f in 0..k {
            let held = |i: usize| {
                let c = rows.res[i].1;
                c != usize::MAX && fold[c] == f
            };
            let train: Vec<usize> = (0..r.len()).filter(|&i| !held(i)).collect();
            let test: Vec<usize> = (0..r.len()).filter(|&i| held(i)).collect();
            if test.is_empty() || train.is_empty() {
                continue;
            }
            let at = a.select_rows(&train);
            let bt = DVector::from_iterator(train.len(), train.iter().map(|&i| r[i]));
            let (x, cov) = lstsq(&at, &bt);
            for &i in &test {
                let row = a.row(i);
                let e = r[i] - (row * &x)[0];
                let c = rows.res[i].1;
                out.score[c] += w * e * e;
                if let Some(sigma) = rows.res[i].0.length_sigma() {
                    out.position_m2[c] += w * (e * sigma).powi(2);
                    if let Some(v) = floor_var {
                        let h = (row * &cov * row.transpose())[0];
                        out.floor_m2[c] += w * v * (1.0 + h.max(0.0));
                    }
                }
            }
        }
    }
    out
}

/// One-sided p-value of a mean `m` with standard error `se` being ≤ 0, Student t with `dof`.
fn one_sided_p(m: f64, se: f64, dof: f64) -> f64 {
    if !(se.is_finite() && se > 0.0) {
        return if m > 0.0 && se == 0.0 { 0.0 } else { 1.0 };
    }
    let t = m / se;
    let two = f_sf(t * t, 1.0, dof.max(1.0));
    if t > 0.0 { 0.5 * two } else { 1.0 - 0.5 * two }
}

/// The floor: per-axis position variance (m²) and its source.
fn floor(
    baseline: &GeometricBaseline,
    rows: &Rows,
    r: &DVector<f64>,
) -> (Option<f64>, FloorSource, String) {
    if let Some(s) = baseline.stated_sigma_m {
        let per = if baseline.kind == DataKind::Distances {
            "per distance"
        } else {
            "per axis"
        };
        return (
            Some(s * s),
            FloorSource::Stated,
            format!("stated instrument σ = {:.4} mm {per}", s * 1e3),
        );
    }
    // Residuals (m) of the position residuals per configuration, axis order.
    let n_c = rows.n_configurations();
    let mut pos: Vec<Vec<f64>> = vec![Vec::new(); n_c];
    for (i, (kind, c)) in rows.res.iter().enumerate() {
        if let Some(sigma) = kind.length_sigma() {
            pos[*c].push(r[i] * sigma);
        }
    }
    // Repeated poses.
    let q = &rows.q;
    let same = |a: usize, b: usize| {
        q[a].iter()
            .zip(&q[b])
            .all(|(x, y)| (x - y).abs() < REPEAT_TOLERANCE)
    };
    let mut label = vec![usize::MAX; n_c];
    let mut n_labels = 0;
    for a in 0..n_c {
        if label[a] != usize::MAX {
            continue;
        }
        label[a] = n_labels;
        for b in a + 1..n_c {
            if label[b] == usize::MAX && same(a, b) && pos[a].len() == pos[b].len() {
                label[b] = n_labels;
            }
        }
        n_labels += 1;
    }
    let mut ss = 0.0;
    let mut dof = 0usize;
    for l in 0..n_labels {
        let members: Vec<usize> = (0..n_c).filter(|&c| label[c] == l).collect();
        if members.len() < 2 || pos[members[0]].is_empty() {
            continue;
        }
        #[allow(clippy::needless_range_loop)] // k indexes the residual of every member
        for k in 0..pos[members[0]].len() {
            let m = members.iter().map(|&c| pos[c][k]).sum::<f64>() / members.len() as f64;
            ss += members
                .iter()
                .map(|&c| (pos[c][k] - m).powi(2))
                .sum::<f64>();
            dof += members.len() - 1;
        }
    }
    if dof >= 10 {
        return (
            Some(ss / dof as f64),
            FloorSource::RepeatedPoses { dof },
            format!(
                "repeatability: pooled scatter of the residuals of repeated poses (readings within \
                 {REPEAT_TOLERANCE} of each other), {dof} degrees of freedom"
            ),
        );
    }
    if baseline.kind == DataKind::Sockets {
        let mut ss = 0.0;
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        for a in 0..n_c {
            let nearest = (0..n_c)
                .filter(|&b| b != a && rows.group[b] == rows.group[a])
                .min_by(|&b, &c| {
                    let d = |x: usize| -> f64 {
                        q[a].iter().zip(&q[x]).map(|(u, v)| (u - v).powi(2)).sum()
                    };
                    d(b).total_cmp(&d(c))
                });
            if let Some(b) = nearest {
                let pair = (a.min(b), a.max(b));
                if !pairs.contains(&pair) {
                    pairs.push(pair);
                    ss += (pos[a].iter().zip(&pos[b]))
                        .map(|(x, y)| (x - y).powi(2))
                        .sum::<f64>();
                }
            }
        }
        if pairs.len() >= 5 {
            let var = ss / (2.0 * 3.0 * pairs.len() as f64);
            return (
                Some(var),
                FloorSource::SocketReplicates { pairs: pairs.len() },
                format!(
                    "socket replicates: half the mean squared residual difference of each \
                     configuration and its nearest configuration at the same socket ({} pairs); \
                     an upper bound of the seating noise (model error that changes between \
                     neighbours adds to it), so the gap is a lower bound",
                    pairs.len()
                ),
            );
        }
    }
    (
        None,
        FloorSource::None,
        "no floor: no stated σ, no repeated pose, no socket replicates; gaps are relative to the \
         best model found"
            .to_owned(),
    )
}

/// The fitted parameters of `names` (columns `from..` of `a`) on all rows, ± std with σ² from
/// the residuals (`RSS/(n − p)`).
fn parameters(
    a: &DMatrix<f64>,
    r: &DVector<f64>,
    from: usize,
    names: &[(String, &'static str)],
    visible: &[usize],
) -> (Vec<EffectParam>, DVector<f64>) {
    let (x, cov) = lstsq(a, r);
    let dof = (r.len() as f64 - a.ncols() as f64).max(1.0);
    let s2 = (r - a * &x).norm_squared() / dof;
    let params = (visible.iter().enumerate())
        .map(|(k, &c)| EffectParam {
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
    names: Vec<(String, &'static str)>,
    visible: Vec<usize>,
    held: Option<HeldOut>,
    fitted: DVector<f64>,
    p_cv: f64,
    p_f: f64,
    improvement: f64,
}

/// What [`revise`] found: an effect to leave out of the library, the alternative expected to
/// take its place (a swap), and the note that says why.
struct Revision {
    leave_out: Effect,
    instead: Option<Effect>,
    note: String,
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
#[allow(clippy::too_many_arguments)] // the pieces of one diagnosis
fn revise(
    ctx: &Context<'_>,
    rows: &Rows,
    r: &DVector<f64>,
    jb: &DMatrix<f64>,
    d: &Derivatives,
    named: &[(Effect, DMatrix<f64>, Vec<usize>)],
    full: &HeldOut,
    folds: &[Vec<usize>],
    block: &[usize],
    floor_var: Option<f64>,
    cfg: &ArmConfig,
    excluded: &[Effect],
) -> Option<Revision> {
    let with = |parts: &[&DMatrix<f64>]| beside(jb, parts);
    let held = |a: &DMatrix<f64>| cross_validate(a, r, rows, folds, cfg.folds, floor_var);
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
                let others: Vec<&DMatrix<f64>> = (named.iter().enumerate())
                    .filter(|(i, _)| *i != k)
                    .map(|(_, (_, c, _))| c)
                    .collect();
                let without = held(&with(&others));
                let (m, se, _) = blocked_mean_difference(&without.score, &full.score, block);
                (k, m, se)
            })
            .min_by(|a, b| (a.1 / a.2).total_cmp(&(b.1 / b.2)));
        if let Some((k, m, se)) = least
            && (m <= HELDOUT_SIGNIFICANCE_Z * se || m.is_nan())
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
        let Some((swapped, n_visible)) =
            swapped(ctx, rows, r, jb, d, named, k, alt, folds, floor_var, cfg)
        else {
            continue;
        };
        // Improvement of the alternative over the named effect.
        let (m, se, _) = blocked_mean_difference(&full.score, &swapped.score, block);
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

/// The held-out errors of the named effects (`named`, as in [`revise`]) with the `k`-th
/// replaced by `alt`, and the number of `alt`'s columns visible beside the others; `None` when
/// `alt` cannot be built on these data or none of its columns is visible. A transversal
/// compliance named beside a joint compliance that gives way to its other torque model is
/// rebuilt on that model's loads (the same visible columns).
#[allow(clippy::too_many_arguments)] // the pieces of one diagnosis
fn swapped(
    ctx: &Context<'_>,
    rows: &Rows,
    r: &DVector<f64>,
    jb: &DMatrix<f64>,
    d: &Derivatives,
    named: &[(Effect, DMatrix<f64>, Vec<usize>)],
    k: usize,
    alt: Effect,
    folds: &[Vec<usize>],
    floor_var: Option<f64>,
    cfg: &ArmConfig,
) -> Option<(HeldOut, usize)> {
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

/// `a` with the columns of `parts` appended, in order.
fn beside(a: &DMatrix<f64>, parts: &[&DMatrix<f64>]) -> DMatrix<f64> {
    let n = a.ncols() + parts.iter().map(|p| p.ncols()).sum::<usize>();
    let mut out = DMatrix::zeros(a.nrows(), n);
    out.columns_mut(0, a.ncols()).copy_from(a);
    let mut at = a.ncols();
    for p in parts {
        out.columns_mut(at, p.ncols()).copy_from(*p);
        at += p.ncols();
    }
    out
}

/// The columns of a candidate `cols` visible beside the baseline `base` (`qb` its orthonormal
/// basis): pivoted against `qb` at [`VISIBLE_TOL`] of the baseline's largest column
/// ([`pivoted_basis_beside`]); returns their orthonormal basis and their indices.
fn visible_columns(
    cols: &DMatrix<f64>,
    qb: &DMatrix<f64>,
    base: &DMatrix<f64>,
) -> (DMatrix<f64>, Vec<usize>) {
    let (qc, picked) = pivoted_basis_beside(cols, qb, VISIBLE_TOL, largest_column_norm(base));
    let visible = (0..cols.ncols()).filter(|&c| picked[c].is_some()).collect();
    (qc, visible)
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

/// Diagnoses `baseline` (see the module documentation).
///
/// # Errors
/// [`Error::Config`] for settings out of range; [`Error::Data`] for fewer than 2 folds'
/// worth of configurations; [`Error::Baseline`] if the problem cannot be evaluated.
pub fn diagnose_arm(baseline: &GeometricBaseline, cfg: &ArmConfig) -> Result<ArmDiagnosis, Error> {
    if cfg.folds < 2 || !(cfg.alpha > 0.0 && cfg.alpha < 1.0) || cfg.max_effects == 0 {
        return Err(Error::Config {
            message: format!(
                "need folds ≥ 2 (got {}), 0 < alpha < 1 (got {}), max_effects ≥ 1",
                cfg.folds, cfg.alpha
            ),
        });
    }
    let problem = &baseline.train;
    let n_c = baseline.q.len();
    if n_c < 2 * cfg.folds {
        return Err(Error::Data {
            message: format!(
                "{n_c} training configurations; the diagnosis needs at least {} for {} folds",
                2 * cfg.folds,
                cfg.folds
            ),
        });
    }
    let n_joints = baseline.robot.joint_names.len();
    let rows = Rows::new(
        problem,
        &baseline.configuration,
        baseline.q.clone(),
        baseline.group.clone(),
        baseline.time.clone(),
    );
    let r = -residuals(problem, &baseline.x)?;
    let kept: Vec<Option<usize>> = baseline.kept.iter().copied().map(Some).collect();
    let rotation = rotation_params(problem, &baseline.robot.joint_names);
    let [jb, rotation] = jacobian_sets(problem, &baseline.x, [&kept, &rotation])?;
    let d = Derivatives {
        dq: reading_derivatives(problem, &baseline.x, n_joints)?,
        rotation,
    };
    let masses = if baseline.robot.masses.is_empty() {
        GravityCompliance::published(&baseline.robot.joint_names)
    } else {
        Some(GravityCompliance::from_link_masses(
            baseline.robot.masses.clone(),
            -Vector3::z(),
        ))
    };
    let t_min = baseline.time.iter().copied().fold(f64::INFINITY, f64::min);
    let t_max = (baseline.time.iter().copied()).fold(f64::NEG_INFINITY, f64::max);
    let mut ctx = Context {
        baseline,
        masses,
        gravity: baseline.base_to_measurement * -Vector3::z(),
        reach_max: 1.0,
        time_origin: if t_min.is_finite() { t_min } else { 0.0 },
        time_span: (t_max - t_min).max(0.0),
        time_step: median_step(&baseline.time),
        transversal: library_transversal(&baseline.robot.tree),
    };
    ctx.reach_max = (baseline.q.iter())
        .map(|q| ctx.reach(q))
        .fold(0.0, f64::max)
        .max(1e-3);
    let (floor_var, floor_source, floor_method) = floor(baseline, &rows, &r);
    let (folds, block) = folds_of(&rows.group, cfg.folds);
    let mut notes = Vec::new();
    if !baseline.time_from_data {
        notes.push(
            "no time column: time is the row order (thermal drift and backlash assume the rows \
             were recorded in file order)"
                .to_owned(),
        );
    }

    // Round 0: the geometric baseline.
    let mut a = jb.clone();
    let mut base = cross_validate(&a, &r, &rows, &folds, cfg.folds, floor_var);
    let mse0 = base.mse();
    let floor0 = floor_var.map(|_| mean(&base.floor_m2));
    let (gap_p, chi_known) = match floor_var {
        Some(_) => (gap_p_value(&rows, &base), true),
        None => (1.0, false),
    };
    let where_ = residual_map(&ctx, &rows, &base, floor_var, cfg);

    let mut candidates = Vec::new();
    let mut steps: Vec<ArmStep> = Vec::new();
    let mut accepted: Vec<Effect> = Vec::new();
    // Accepted effects' columns on the training rows and their names (for the ladder).
    let mut effect_cols: Vec<(Effect, DMatrix<f64>, Vec<usize>)> = Vec::new();
    let mut untestable = Vec::new();
    // After each named effect: the χ² p-value of what is left under the floor.
    let mut p_after: Vec<f64> = Vec::new();
    // Each named effect's share of its round's in-sample excess (RSS − dof, in floor units).
    let mut in_sample_share: Vec<f64> = Vec::new();
    let floor_units = match (
        floor_var,
        rows.res.iter().find_map(|(kind, _)| kind.length_sigma()),
    ) {
        (Some(v), Some(s)) if v > 0.0 => s * s / v,
        _ => 1.0,
    };
    // Stepwise: the rounds add effects greedily; once they stop, every named effect is checked
    // against the others (revise): one that no longer earns its place beside the later ones,
    // or whose alternative under the other torque model or harmonic order now predicts better,
    // is left out of the library and the rounds run again from the geometric baseline.
    let base0 = base.clone();
    let mut excluded: Vec<Effect> = Vec::new();
    let mut revisions: Vec<String> = Vec::new();
    // A swap stands only if the rounds run again name the alternative by their own tests;
    // otherwise the run before it is kept. The run before a swap, and the alternative.
    let mut before_swap = None;
    loop {
        a = jb.clone();
        base = base0.clone();
        candidates.clear();
        steps.clear();
        accepted.clear();
        effect_cols.clear();
        untestable.clear();
        p_after.clear();
        in_sample_share.clear();
        for round in 1..=cfg.max_effects {
            let (qb, _) = pivoted_basis(&a, &DMatrix::zeros(a.nrows(), 0), 1e-9);
            let r_perp = &r - &qb * (qb.transpose() * &r);
            let rss_b = r_perp.norm_squared();
            let dof_b = (r.len() as f64 - qb.ncols() as f64).max(1.0);
            let mut tested: Vec<Tested> = Vec::new();
            for effect in arm_candidates() {
                // Gravity and lumped compliance are one effect under two torque models, the
                // two transversal compliances one effect in two forms: once one is named, the
                // other is not a further effect. A transversal compliance is tested once a
                // joint compliance is named (ARM_BESIDE_COMPLIANCE).
                if accepted.contains(&effect)
                    || excluded.contains(&effect)
                    || (effect.is_joint_compliance()
                        && accepted.iter().any(|e| e.is_joint_compliance()))
                    || (effect.is_transversal()
                        && (accepted.iter().any(|e| e.is_transversal())
                            || !accepted.iter().any(|e| e.is_joint_compliance())))
                {
                    continue;
                }
                let (cols, names) = match effect_columns(effect, &ctx, &rows, &d, &accepted) {
                    Ok(c) => c,
                    Err(reason) => {
                        let note = format!("{}: {reason}", effect.name());
                        if (round == 1 || effect.is_transversal()) && !untestable.contains(&note) {
                            untestable.push(note);
                        }
                        continue;
                    }
                };
                let (qc, visible) = visible_columns(&cols, &qb, &a);
                let mut cand = ArmCandidate {
                    effect,
                    round,
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
                    tested.push(Tested {
                        effect,
                        cand,
                        columns: DMatrix::zeros(r.len(), 0),
                        names,
                        visible,
                        held: None,
                        fitted: DVector::zeros(r.len()),
                        p_cv: 1.0,
                        p_f: 1.0,
                        improvement: 0.0,
                    });
                    continue;
                }
                let c_vis = cols.select_columns(&visible);
                let proj = qc.transpose() * &r_perp;
                let drss = proj.norm_squared();
                let k = visible.len() as f64;
                let dof = (dof_b - k).max(1.0);
                let p_f = f_sf((drss / k) / ((rss_b - drss).max(1e-300) / dof), k, dof);
                let ac = beside(&a, &[&c_vis]);
                let held = cross_validate(&ac, &r, &rows, &folds, cfg.folds, floor_var);
                let (m, se, filled) = blocked_mean_difference(&base.score, &held.score, &block);
                let p_cv = one_sided_p(m, se, filled.saturating_sub(1) as f64);
                let (params, _) = parameters(&ac, &r, a.ncols(), &names, &visible);
                cand.heldout_rms_after_m = held.mse().sqrt();
                cand.heldout_improvement = (m, se);
                cand.parameters = params;
                tested.push(Tested {
                    effect,
                    cand,
                    columns: c_vis,
                    names,
                    visible,
                    held: Some(held),
                    fitted: &qc * proj,
                    p_cv,
                    p_f,
                    improvement: m,
                });
            }
            let p_cv: Vec<f64> = tested.iter().map(|t| t.p_cv).collect();
            let adj_f = holm(&tested.iter().map(|t| t.p_f).collect::<Vec<_>>());
            // The gap of this round, what the effects named so far left: above the floor, or
            // (no floor) above the best candidate. A second effect is judged by the share of that
            // gap it closes, not of the gap before the first effect (which the first one may have
            // mostly closed: drift then a gear ratio, 85 % then all of what was left).
            let best_mse = (tested.iter())
                .filter_map(|t| t.held.as_ref().map(HeldOut::mse))
                .fold(base.mse(), f64::min);
            let gap2 = match floor0 {
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
                } else if floor0.is_some() && share < cfg.min_gap_share {
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
            // parameters, then the earlier in the library (which uses more of what is known about
            // the robot: its link masses before a unit weight).
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
                        let (d, se, _) = blocked_mean_difference(&h.score, &best_score, &block);
                        d <= se
                    })
                    .min_by_key(|(i, t)| (t.cand.n_visible, *i))
                    .map_or(b, |(i, _)| i)
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
            let Some(w) = winner else {
                candidates.extend(tested.into_iter().map(|t| t.cand));
                break;
            };
            let win_fit = tested[w].fitted.clone();
            let excess = rss_b * floor_units - dof_b;
            in_sample_share.push(if excess > 0.0 {
                (win_fit.norm_squared() * floor_units - tested[w].cand.n_visible as f64) / excess
            } else {
                0.0
            });
            let win_effect = tested[w].effect;
            let confusable: Vec<(Effect, String)> = (tested.iter().enumerate())
                .filter(|(i, t)| {
                    *i != w
                        && t.cand.n_visible > 0
                        && cosine(&t.fitted, &win_fit) > CONFUSABLE_COSINE
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
            let gap_orig = match floor0 {
                Some(f) => mse0 - f,
                None => mse0 - held.mse(),
            };
            steps.push(ArmStep {
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
            let grown = beside(&a, &[&win.columns]);
            effect_cols.push((win.effect, win.columns.clone(), win.visible.clone()));
            let _ = &win.names;
            accepted.push(win.effect);
            a = grown;
            base = held;
            candidates.extend(tested.into_iter().map(|t| t.cand));
            p_after.push(gap_p_value(&rows, &base));
            // Stop when what is left is consistent with the floor.
            if floor_var.is_some() && gap_p_value(&rows, &base) >= cfg.alpha {
                break;
            }
        }
        if let Some((alt, left_out, saved)) = before_swap.take()
            && !accepted.contains(&alt)
        {
            // The alternative did not pass beside the others: the run before the swap stands.
            (
                base,
                candidates,
                steps,
                accepted,
                effect_cols,
                untestable,
                p_after,
                in_sample_share,
            ) = saved;
            revisions.pop();
            revisions.push(format!(
                "{} stays: run again without it, the rounds did not name {} in its place",
                Effect::name(left_out),
                Effect::name(alt)
            ));
            break;
        }
        match revise(
            &ctx,
            &rows,
            &r,
            &jb,
            &d,
            &effect_cols,
            &base,
            &folds,
            &block,
            floor_var,
            cfg,
            &excluded,
        ) {
            Some(Revision {
                leave_out,
                instead,
                note,
            }) => {
                if let Some(alt) = instead {
                    before_swap = Some((
                        alt,
                        leave_out,
                        (
                            base.clone(),
                            candidates.clone(),
                            steps.clone(),
                            accepted.clone(),
                            effect_cols.clone(),
                            untestable.clone(),
                            p_after.clone(),
                            in_sample_share.clone(),
                        ),
                    ));
                }
                excluded.push(leave_out);
                revisions.push(note);
            }
            None => break,
        }
    }
    // The compliance's torque model is named only on the evidence that names an effect: beside
    // the other named effects (a transversal compliance on the other model's loads too), the
    // other torque model predicts worse by HELDOUT_SIGNIFICANCE_Z blocked standard errors.
    // Otherwise the data do not tell the two apart, and the step says so. (The two forms of a
    // transversal compliance are told apart by the rounds and the revision, and reported as
    // confusable when their fits look alike.)
    for (k, (effect, _, _)) in effect_cols.iter().enumerate() {
        let Some(alt) = effect.alternative().filter(|a| a.is_joint_compliance()) else {
            continue;
        };
        let Some((other, _)) = swapped(
            &ctx,
            &rows,
            &r,
            &jb,
            &d,
            &effect_cols,
            k,
            alt,
            &folds,
            floor_var,
            cfg,
        ) else {
            continue;
        };
        let (d, se, _) = blocked_mean_difference(&other.score, &base.score, &block);
        if d <= HELDOUT_SIGNIFICANCE_Z * se || d.is_nan() || se.is_nan() {
            steps[k].alike.push(alt);
        }
    }
    notes.extend(revisions);
    for u in untestable {
        notes.push(format!("not testable: {u}"));
    }
    let final_mse = base.mse();
    let gap2 = match floor0 {
        Some(f) => mse0 - f,
        None => mse0 - final_mse,
    };
    if floor0.is_none() && mse0 > final_mse {
        // Without a floor, each step's share is of what the best model found removes.
        for st in &mut steps {
            st.gap_closed_pct = 100.0
                * (st.heldout_rms_before_m.powi(2) - st.heldout_rms_after_m.powi(2))
                / (mse0 - final_mse);
        }
    }
    let closed = if gap2 > 0.0 {
        (mse0 - final_mse) / gap2
    } else {
        0.0
    };
    // Sufficiency, from the last named effect back: an effect that closes less than
    // SUFFICIENT_SHARE of the gap its round faced (what the effects before it left) and leaves
    // a significant residual explains a part of something else, not itself; it is not named,
    // and the rule applies to the one before it.
    let mut named = accepted.len();
    if let Some(f) = floor0 {
        while named > 0 {
            let st = &steps[named - 1];
            let (before, after) = (
                st.heldout_rms_before_m.powi(2),
                st.heldout_rms_after_m.powi(2),
            );
            let faced = before - f;
            let share = if faced > 0.0 {
                (before - after) / faced
            } else {
                1.0
            };
            let share_in = in_sample_share[named - 1];
            if share >= SUFFICIENT_SHARE
                || share_in >= SUFFICIENT_SHARE_IN_SAMPLE
                || p_after[named - 1] >= cfg.alpha
            {
                break;
            }
            notes.push(format!(
                "{} closes {:.0} % of the gap left before it ({:.0} % in-sample) and a \
                 significant residual remains: not enough to name it (the effect at work is \
                 likely outside the library)",
                st.effect,
                100.0 * share,
                100.0 * share_in
            ));
            named -= 1;
        }
    }
    let verdict = Verdict::of(&accepted[..named]);
    if named > 0
        && let Some(f) = floor0
        && p_after[named - 1] < cfg.alpha
    {
        let final_mse = steps[named - 1].heldout_rms_after_m.powi(2);
        let why = if named >= cfg.max_effects {
            format!(
                "the search stops at {} effects (max_effects)",
                cfg.max_effects
            )
        } else {
            "no further candidate of the library passes".to_owned()
        };
        notes.push(format!(
            "after {verdict} the cross-validated RMS is {:.3} mm, {:.1}× the floor's {:.3} mm, \
             a significant residual: another effect is at work that the verdict does not name \
             ({why})",
            final_mse.sqrt() * 1e3,
            (final_mse / f).sqrt(),
            f.sqrt() * 1e3
        ));
    }
    if let Some(step) = steps.first()
        && step.heldout_rms_after_m > 0.95 * step.heldout_rms_before_m
    {
        notes.push(format!(
            "{} is significant but buys little: held-out RMS {:.3} → {:.3} mm ({:+.1} %)",
            step.effect,
            step.heldout_rms_before_m * 1e3,
            step.heldout_rms_after_m * 1e3,
            100.0 * (step.heldout_rms_after_m / step.heldout_rms_before_m - 1.0)
        ));
    }
    let (ladder, test_rms) = ladder(baseline, &ctx, &rows, &r, &jb, &effect_cols, &folds, cfg)?;
    let test_rms_final = match effect_cols.is_empty() {
        true => test_rms.clone(),
        false => ladder
            .last()
            .map_or_else(Vec::new, |l| l.test_rms_m.clone()),
    };
    Ok(ArmDiagnosis {
        kind: baseline.kind,
        n_configurations: n_c,
        n_baseline_params: jb.ncols(),
        floor_method,
        floor_source,
        floor_sigma_m: floor_var.map(f64::sqrt),
        floor_rms_m: floor0.map(f64::sqrt),
        heldout_rms_m: mse0.sqrt(),
        test_rms_m: test_rms,
        gap_rms_m: gap2.max(0.0).sqrt(),
        gap_p_value: gap_p,
        gap_significant: chi_known && gap_p < cfg.alpha,
        where_,
        candidates,
        steps,
        verdict,
        heldout_rms_final_m: final_mse.sqrt(),
        test_rms_final_m: test_rms_final,
        gap_closed_pct: 100.0 * closed,
        test_sets: baseline.tests.iter().map(|t| t.name.clone()).collect(),
        ladder,
        notes,
    })
}

/// `P(χ²_k > Σ e²/var)` of the held-out position residuals under the floor (pooled variance
/// `Σ floor / k`, k position residuals).
fn gap_p_value(rows: &Rows, held: &HeldOut) -> f64 {
    let k = (rows.res.iter())
        .filter(|(kind, c)| kind.length_sigma().is_some() && *c != usize::MAX)
        .count() as f64;
    let floor: f64 = held.floor_m2.iter().sum();
    let ss: f64 = held.position_m2.iter().sum();
    if floor > 0.0 && k > 0.0 {
        chi2_sf(ss / (floor / k), k)
    } else {
        1.0
    }
}

fn cosine(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    let d = a.norm() * b.norm();
    if d > 0.0 { (a.dot(b) / d).abs() } else { 0.0 }
}

/// The ladder: the baseline's kinematic rungs, then each accepted effect with its
/// cross-validated error on the training rows and its error on every held-out set; and the
/// geometric estimate's error on every held-out set (at the linearisation point, as the
/// effects' rungs).
#[allow(clippy::too_many_arguments)] // the pieces of one diagnosis
fn ladder(
    baseline: &GeometricBaseline,
    ctx: &Context<'_>,
    rows: &Rows,
    r: &DVector<f64>,
    jb: &DMatrix<f64>,
    effects: &[(Effect, DMatrix<f64>, Vec<usize>)],
    folds: &[Vec<usize>],
    cfg: &ArmConfig,
) -> Result<(Vec<ArmRung>, Vec<f64>), Error> {
    let mut out: Vec<ArmRung> = (baseline.ladder.iter())
        .map(|k| ArmRung {
            rung: ArmLadderRung::Kinematic(k.rung),
            cv_rms_m: k.cv_rms_m,
            test_rms_m: k.test_rms_m.clone(),
        })
        .collect();
    // Held-out sets: their residuals, shared-parameter columns, own nuisance columns and
    // derivatives at the training estimate.
    struct Test {
        rows: Rows,
        r: DVector<f64>,
        shared: DMatrix<f64>,
        own: DMatrix<f64>,
        d: Derivatives,
    }
    let n_joints = ctx.n_joints();
    let shared_kept: Vec<usize> = (baseline.kept.iter().enumerate())
        .filter(|(_, i)| **i < baseline.n_shared)
        .map(|(k, _)| k)
        .collect();
    let mut tests = Vec::new();
    for t in &baseline.tests {
        tests.push(test_of(t, baseline, ctx, n_joints)?);
    }
    fn test_of(
        t: &HeldOutSet,
        b: &GeometricBaseline,
        ctx: &Context<'_>,
        n_joints: usize,
    ) -> Result<Test, Error> {
        let n_c = t.configuration.iter().max().map_or(0, |m| m + 1);
        let q: Vec<Vec<f64>> = {
            let mut q = vec![Vec::new(); n_c];
            for (row, &c) in t.problem.observations().rows.iter().zip(&t.configuration) {
                q[c] = row.q.clone();
            }
            q
        };
        // The set's own times where they continue the training's clock, else the training's
        // clock continued at its median step.
        let time = (t.time.clone())
            .filter(|time| time.len() == n_c)
            .unwrap_or_else(|| ctx.held_out_times(n_c));
        let rows = Rows::new(&t.problem, &t.configuration, q, vec![0; n_c], time);
        let r = -residuals(&t.problem, &t.x)?;
        let shared_idx: Vec<Option<usize>> = (b.kept.iter().copied())
            .filter(|&i| i < b.n_shared)
            .map(Some)
            .collect();
        let own_idx: Vec<Option<usize>> =
            (b.n_shared..t.problem.layout().len()).map(Some).collect();
        let rotation_idx = rotation_params(&t.problem, &b.robot.joint_names);
        let [shared, own, rotation] =
            jacobian_sets(&t.problem, &t.x, [&shared_idx, &own_idx, &rotation_idx])?;
        let d = Derivatives {
            dq: reading_derivatives(&t.problem, &t.x, n_joints)?,
            rotation,
        };
        Ok(Test {
            rows,
            r,
            shared,
            own,
            d,
        })
    }
    // The training coefficients of the shared columns (and the effects' after them) carried
    // to a held-out set, then the set's own nuisance parameters (socket points) re-fitted.
    let test_rms = |t: &Test, cols: &DMatrix<f64>, coef: Vec<f64>| {
        let mut e = &t.r - cols * DVector::from_vec(coef);
        if t.own.ncols() > 0 {
            let (y, _) = lstsq(&t.own, &e);
            e -= &t.own * y;
        }
        position_rms(&t.rows, &e)
    };
    let (x0, _) = lstsq(jb, r);
    let geometric: Vec<f64> = (tests.iter())
        .map(|t| test_rms(t, &t.shared, shared_kept.iter().map(|&k| x0[k]).collect()))
        .collect();
    let mut a = jb.clone();
    let mut test_cols: Vec<DMatrix<f64>> = tests.iter().map(|t| t.shared.clone()).collect();
    let mut named_so_far: Vec<Effect> = Vec::new();
    for (effect, cols, visible) in effects {
        a = beside(&a, &[cols]);
        let held = cross_validate(&a, r, rows, folds, cfg.folds, None);
        let (x, _) = lstsq(&a, r);
        let mut rms = Vec::new();
        for (t, tc) in tests.iter().zip(&mut test_cols) {
            let (c, _) = effect_columns(*effect, ctx, &t.rows, &t.d, &named_so_far)
                .unwrap_or_else(|_| (DMatrix::zeros(t.r.len(), visible.len().max(1)), Vec::new()));
            let c_vis = if c.ncols() >= visible.iter().max().map_or(0, |m| m + 1) {
                c.select_columns(visible)
            } else {
                DMatrix::zeros(t.r.len(), visible.len())
            };
            *tc = beside(tc, &[&c_vis]);
            let coef: Vec<f64> = (shared_kept.iter().copied())
                .chain(jb.ncols()..a.ncols())
                .map(|k| x[k])
                .collect();
            rms.push(test_rms(t, tc, coef));
        }
        named_so_far.push(*effect);
        out.push(ArmRung {
            rung: ArmLadderRung::Effects(named_so_far.clone()),
            cv_rms_m: held.mse().sqrt(),
            test_rms_m: rms,
        });
    }
    Ok((out, geometric))
}

/// RMS of the 3-D position error per configuration, m, of weighted residuals `e`.
fn position_rms(rows: &Rows, e: &DVector<f64>) -> f64 {
    let mut per = vec![0.0; rows.n_configurations()];
    for (i, (kind, c)) in rows.res.iter().enumerate() {
        if let Some(sigma) = kind.length_sigma()
            && *c != usize::MAX
        {
            per[*c] += (e[i] * sigma).powi(2);
        }
    }
    mean(&per).sqrt()
}

/// The residual map: held-out position RMS in quantile bins of each signal (joint readings,
/// time, gravity torques, reach, height, azimuth), against the floor (or the overall RMS
/// without one), Holm over every bin.
fn residual_map(
    ctx: &Context<'_>,
    rows: &Rows,
    held: &HeldOut,
    floor_var: Option<f64>,
    cfg: &ArmConfig,
) -> Vec<ArmBin> {
    let n_c = rows.n_configurations();
    let names = &ctx.baseline.robot.joint_names;
    let mut signals: Vec<(String, Vec<f64>)> = Vec::new();
    for (j, _) in names.iter().enumerate() {
        signals.push((format!("q{}", j + 1), rows.q.iter().map(|q| q[j]).collect()));
    }
    signals.push(("time".into(), rows.time.clone()));
    if let Some(m) = &ctx.masses {
        let t: Vec<Vec<f64>> = (rows.q.iter())
            .map(|q| {
                (m.joint_loads(&ctx.baseline.torque_tips, q).iter())
                    .map(|l| l.torque)
                    .collect::<Vec<f64>>()
            })
            .collect();
        for j in 0..names.len() {
            let v: Vec<f64> = t.iter().map(|t| t[j]).collect();
            if v.iter().any(|x| x.abs() > 1e-9) {
                signals.push((format!("torque{}", j + 1), v));
            }
        }
    }
    // The workspace, when the tip moves through it (not at sockets).
    let tips: Vec<Vector3<f64>> = rows.q.iter().map(|q| ctx.tip(q)).collect();
    let spread = |f: &dyn Fn(&Vector3<f64>) -> f64| {
        let v: Vec<f64> = tips.iter().map(f).collect();
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
                (l.min(*x), h.max(*x))
            });
        (v, hi - lo)
    };
    let (reach, reach_spread) = spread(&|p| (p.x * p.x + p.y * p.y).sqrt());
    let (height, height_spread) = spread(&|p| p.z);
    if reach_spread.max(height_spread) > WORKSPACE_SPREAD_M {
        signals.push(("reach".into(), reach));
        signals.push(("height".into(), height));
        signals.push((
            "azimuth".into(),
            tips.iter().map(|p| p.y.atan2(p.x)).collect(),
        ));
    }
    // Per configuration: number of position residuals.
    let mut n_pos = vec![0usize; n_c];
    for (kind, c) in &rows.res {
        if kind.length_sigma().is_some() && *c != usize::MAX {
            n_pos[*c] += 1;
        }
    }
    let overall = held.mse();
    let mut bins = Vec::new();
    let mut p_raw = Vec::new();
    for (name, v) in &signals {
        let mut order: Vec<usize> = (0..n_c).collect();
        order.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
        let lo_all = v[order[0]];
        let hi_all = v[order[n_c - 1]];
        if hi_all <= lo_all || hi_all.is_nan() || lo_all.is_nan() {
            continue;
        }
        let k = cfg.bins.min(n_c).max(1);
        for b in 0..k {
            let members = &order[b * n_c / k..(b + 1) * n_c / k];
            if members.is_empty() {
                continue;
            }
            let ss: f64 = members.iter().map(|&c| held.position_m2[c]).sum();
            let floor_ss: f64 = match floor_var {
                Some(_) => members.iter().map(|&c| held.floor_m2[c]).sum(),
                None => overall * members.len() as f64,
            };
            let dof: f64 = match floor_var {
                Some(_) => members.iter().map(|&c| n_pos[c] as f64).sum(),
                None => members.len() as f64 * 3.0,
            };
            let per_axis = floor_ss / dof.max(1.0);
            let p = if per_axis > 0.0 {
                chi2_sf(ss / per_axis, dof)
            } else {
                1.0
            };
            p_raw.push(p);
            bins.push(ArmBin {
                signal: name.clone(),
                lo: v[members[0]],
                hi: v[*members.last().unwrap_or(&members[0])],
                n: members.len(),
                rms_m: (ss / members.len() as f64).sqrt(),
                floor_rms_m: (floor_ss / members.len() as f64).sqrt(),
                p_value: p,
                flagged: false,
            });
        }
    }
    let adj = holm(&p_raw);
    for (b, p) in bins.iter_mut().zip(adj) {
        b.p_value = p;
        b.flagged = p < cfg.alpha;
    }
    bins
}
