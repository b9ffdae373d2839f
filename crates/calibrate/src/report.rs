//! The typed results of a calibration, every workflow's: rendered as text by the command line,
//! as JSON by `--json`, as dictionaries by the Python package, all from these types.

use hapcal_io::Device;
use hapcal_problems::CalibratedModel;
use serde::Serialize;
use std::path::PathBuf;

use crate::model::ModelName;

/// The role of a data set in a calibration (JSON: `train`, `test`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SetRole {
    /// Fitted (and cross-validated).
    Train,
    /// Only evaluated, never fitted nor used to choose.
    Test,
}

/// How the note starts of a `--model auto` ladder that left rungs out because every
/// cross-validation fold could not fit their parameters from its training rows
/// ([`CalibrationReport::ladder_notes`]).
pub const UNTRIED_RUNGS_NOTE: &str = "--model auto tried the ladder up to ";

/// How the note starts of a `--model auto` ladder that left out a rung whose fit did not
/// converge ([`CalibrationReport::ladder_notes`]).
pub const UNCONVERGED_RUNG_NOTE: &str = "--model auto left out the ";

impl CalibrationReport {
    /// The warnings that say which rungs of the ladder were not tried for too few rows, and
    /// why (rows, parameters), or were left out because their fit did not converge: the
    /// command line prints them on standard error as well.
    pub fn ladder_notes(&self) -> impl Iterator<Item = &str> {
        (self.warnings.iter())
            .map(String::as_str)
            .filter(|w| w.starts_with(UNTRIED_RUNGS_NOTE) || w.starts_with(UNCONVERGED_RUNG_NOTE))
    }
}

/// What makes an estimate one no real robot can have ([`Implausible`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ImplausibleKind {
    /// Compliances below zero beyond their uncertainty that another direction of gravity in
    /// the root frame (a ceiling or wall mount) makes non-negative, with a smaller residual.
    Mounting,
    /// Compliances below zero beyond their uncertainty, no mounting explaining them.
    NegativeCompliance,
    /// An identified marker frame no mounting can have (metres from its link).
    Frame,
    /// The final least-squares fit stopped before converging.
    Unconverged,
    /// Compliances so large that the torque equilibrium under the robot's weight is not
    /// reached (its fixed-point iteration does not contract): the fit's prediction depends on
    /// where the iteration stops.
    NoEquilibrium,
}

/// An estimate no real robot can have, found after the fit (measurement files): never a
/// result; `hapcal calibrate` stops on it (`setup::after_fit`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Implausible {
    /// What kind.
    pub kind: ImplausibleKind,
    /// What was found and why it cannot be, in plain words.
    pub message: String,
    /// The flag or the edit that applies.
    pub fix: String,
}

impl std::fmt::Display for SetRole {
    /// `train` or `test`, as the JSON report writes it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(match self {
            SetRole::Train => "train",
            SetRole::Test => "test",
        })
    }
}

/// Why a parameter was pruned (JSON: `near_zero_column`, `dependent`, `insensitive`,
/// `at_zero`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PruneCause {
    /// The data do not move the residuals with it: its Jacobian column is (nearly) zero.
    NearZeroColumn,
    /// Kept parameters reproduce its effect (`depends_on`).
    Dependent,
    /// Nearly independent of the kept ones but too small for the noise: its standard deviation
    /// would exceed its plausible range.
    Insensitive,
    /// A compliance held at zero: fitted free it fell below zero within the noise
    /// ([`hapcal_identify::PruneReason::AtBound`]); `std_if_kept` is its standard deviation
    /// in that fit.
    AtZero,
}

/// Figures of one data set under one model.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Figures {
    /// MUKCa mean absolute error ("consistency"), m; socket data only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_absolute_error_m: Option<f64>,
    /// MUKCa distance error ("distortion"), m; socket data with two sockets only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_error_m: Option<f64>,
    /// RMS of the distance residual, m; distance logs only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_rms_m: Option<f64>,
    /// Position and orientation errors of marker data.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<PoseFigures>,
}

/// Figures of one data set before and after calibration.
#[derive(Clone, Debug, Serialize)]
pub struct SetReport {
    /// Placement folder or log name.
    pub name: String,
    /// Training or test data.
    pub role: SetRole,
    /// Number of rows.
    pub n_rows: usize,
    /// With the nominal model.
    pub before: Figures,
    /// With the calibrated model.
    pub after: Figures,
    /// Marker and distance data: the error of every sample, frames only and calibrated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub errors: Option<SampleErrors>,
}

/// One identified parameter.
#[derive(Clone, Debug, Serialize)]
pub struct ParamReport {
    /// Stable name (`joint_a2.rx`, `dtheta3`, `compliance.joint_a4`).
    pub name: String,
    /// Identified deviation from nominal.
    pub value: f64,
    /// Standard deviation.
    pub std: f64,
    /// `m` or `rad`; `rad/(N·m)` (`rad/m` under lumped weights) for a compliance.
    pub unit: &'static str,
}

/// The nominal origin of one URDF joint as the length check after the fit
/// (`setup::after_fit`) words a link: the translation from the frame of the moving
/// joint before it (or the root) to its origin, expressed in the frame its `{joint}.x`, `.y`,
/// `.z` deviations move along (URDF `<origin>`, fixed joints between folded in).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JointOrigin {
    /// The joint (URDF name; the prefix of its length parameters).
    pub joint: String,
    /// The moving joint before it on the chain, whose link this origin ends (`None`: the root).
    pub after: Option<String>,
    /// The translation, m, in the deviations' frame.
    pub origin_m: [f64; 3],
}

/// One pruned parameter and why.
#[derive(Clone, Debug, Serialize)]
pub struct PrunedReport {
    /// Parameter name.
    pub name: String,
    /// Why it was pruned.
    pub reason: PruneCause,
    /// For `dependent`: kept parameters that reproduce it, with coefficients.
    pub depends_on: Vec<(String, f64)>,
    /// Its standard deviation had it been kept, in its unit.
    pub std_if_kept: f64,
}

/// A model's comparison with the simpler alternative of its own ladder level that it contains
/// ([`crate::model::ModelRules::contains`]: per-axis transversal compliance holds the
/// isotropic one, harmonic2 holds harmonic): the richer model is taken only where it beats the
/// simpler by [`crate::model::LADDER_SIGNIFICANCE_Z`] blocked standard errors.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NestedComparison {
    /// The simpler alternative it contains.
    pub contains: ModelName,
    /// Mean held-out score per row of this model minus the simpler one's, and its blocked
    /// standard error, in the units of the report's other differences (m² for
    /// [`CvReport`], the weighted squared error `Σ e²/σ²` for [`RungReport`]).
    pub difference: (f64, f64),
    /// Whether the difference is below zero by [`crate::model::LADDER_SIGNIFICANCE_Z`]
    /// standard errors: the condition for taking this model over the simpler one (the
    /// joint-range folds of marker data judge a rung against the one chosen below it, not
    /// against the alternative it contains).
    pub beats: bool,
}

/// Cross-validation score of one candidate model.
#[derive(Clone, Debug, Serialize)]
pub struct CvReport {
    /// Candidate.
    pub model: ModelName,
    /// Held-out RMS of the 3-D point (or distance) error over all folds, m.
    pub heldout_rms_m: f64,
    /// Mean over held-out rows of this model's squared error minus the geometric model's, m²,
    /// and its standard error from the contiguous blocks (rows of one block are correlated);
    /// `(0, 0)` for the geometric model itself.
    pub difference_to_geometric_m2: (f64, f64),
    /// Whether the difference is below zero by [`crate::model::LADDER_SIGNIFICANCE_Z`] standard errors (the
    /// condition for choosing this model over the geometric one).
    pub beats_geometric: bool,
    /// The model this one was compared with on the climb (the one chosen so far when its
    /// level was reached; `None` for the bottom rung).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compared_with: Option<ModelName>,
    /// Mean over held-out rows of this model's squared error minus `compared_with`'s, m², and
    /// its blocked standard error; `(0, 0)` for the bottom rung. The model is taken when the
    /// difference is below zero by [`crate::model::LADDER_SIGNIFICANCE_Z`] standard errors
    /// (and it has the lowest held-out RMS of its level's passing alternatives).
    pub difference_to_compared_m2: (f64, f64),
    /// The comparison with the alternative of its own level this model contains
    /// ([`crate::model::ModelRules::contains`]; difference in m²), which it must also beat to
    /// be taken; `None` when it contains none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nested: Option<NestedComparison>,
    /// Number of kept parameters on the full training data.
    pub n_kept: usize,
}

/// Everything `hapcal calibrate` found; printed as a table or as one JSON document.
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationReport {
    /// Device path.
    pub device: String,
    /// Chosen model.
    pub model: ModelName,
    /// Cross-validation folds (time-contiguous blocks per socket).
    pub folds: usize,
    /// Cross-validation scores (empty when the model was given).
    pub cross_validation: Vec<CvReport>,
    /// The training rows the cross-validation judged when it judged a sample of them, spread
    /// over every log (a log longer than the ladder's row cap, 20,000 rows); `None` when it
    /// judged every one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cross_validated_rows: Option<usize>,
    /// Marker data: held-out score of each rung of the model ladder (empty otherwise).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub ladder: Vec<RungReport>,
    /// Marker data: the identified instrument and marker frames.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<FrameReport>,
    /// Residual noise used for the rank decision and the covariance, m.
    pub sigma_m: f64,
    /// `given` or `residuals`.
    pub sigma_source: &'static str,
    /// Identified parameters (kept model parameters).
    pub parameters: Vec<ParamReport>,
    /// Pruned parameters.
    pub pruned: Vec<PrunedReport>,
    /// Pairs of kept parameters with |correlation| > 0.95.
    pub correlated: Vec<(String, String, f64)>,
    /// Observability indices O1–O5 of the scaled Jacobian at the estimate.
    pub observability: Option<crate::support::ObservabilityReport>,
    /// Plain-language warnings about what the data cannot support.
    pub warnings: Vec<String>,
    /// Why the final Levenberg–Marquardt fit stopped; rendered and serialised in plain words
    /// ([`termination_text`]: `converged (relative cost reduction below ftol)`).
    #[serde(serialize_with = "termination_words")]
    pub termination: hapcal_identify::Termination,
    /// The least-squares back end of the final fit and why (`dense: auto: a 372 × 47
    /// Jacobian, …`).
    pub backend: String,
    /// Residual evaluations of the final fit.
    pub n_evaluations: usize,
    /// Jacobian evaluations of the final fit.
    pub n_jacobians: usize,
    /// Prune-and-refit rounds (identifiability re-decided at the estimate).
    pub rounds: usize,
    /// Data sets, training first.
    pub placements: Vec<SetReport>,
    /// Wall time from reading the files to the finished report, s.
    pub elapsed_s: f64,
    /// The training samples the Huber loss bounded (marker positions, socket rows, distance
    /// log rows), each with its file, line and residual (empty when none was).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub downweighted: Vec<Downweighted>,
    /// Measurement files: the joint-range folds the ladder judged extrapolation by (empty
    /// when no test row lies beyond a joint's training range).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub range_folds: Vec<RangeFold>,
    /// Measurement files with `--workspace` or test rows: where the calibration will be used
    /// against its training ranges, and what the model choice did about it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coverage: Option<Coverage>,
    /// Compliance models on measurement files: how far one more fixed-point step of the
    /// torque equilibrium would move the tips, at most over the training rows, m
    /// (`CalibratedModel::equilibrium_step_m`); small against σ, no iteration is needed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub equilibrium_step_m: Option<f64>,
    /// Compliance models on measurement files: refits with the gravity loads at the torque
    /// equilibrium of the estimate (0: the loads of the undeflected robot were close enough).
    pub equilibrium_refits: usize,
    /// Estimates no real robot can have (negative compliances, a torque equilibrium the
    /// deflection does not reach, a marker frame metres from its link, an unconverged fit),
    /// each with its cause and fix; empty when the estimate is plausible. Every workflow
    /// judges its fit's compliances and convergence; the measurement workflow also the
    /// mounting, the equilibrium and the marker frames.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub implausible: Vec<Implausible>,
    /// When the final fit held robot lengths at their nominal values (pruned as not
    /// identifiable, or not free in the chosen model): every robot length after one
    /// least-squares step at the estimate that fits the held ones too, the held ones first,
    /// each with its deviation from nominal (`value`, m) and σ in that fit (`std`, m). The
    /// check after the fit judges them (`setup::after_fit`), so that pruning cannot
    /// hide another robot's dimensions. Empty when nothing was held (or the fit streamed).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub refitted_lengths: Vec<ParamReport>,
    /// The nominal origins of the URDF joints whose lengths are parameters, chain order: the
    /// links the check after the fit names (empty for a D-H device).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub origins: Vec<JointOrigin>,
}

/// Output of a calibration: the report plus what is needed to write the calibrated files.
#[derive(Debug)]
pub struct Outcome {
    /// The report.
    pub report: CalibrationReport,
    /// The device as read.
    pub device: Device,
    /// Path of the device file.
    pub device_path: PathBuf,
    /// The calibrated kinematic model.
    pub model: CalibratedModel,
    /// The calibrated device file when the workflow writes more than kinematic deviations (a
    /// haptic device's transmissions); `None`: `calibrate::write_outputs` applies the report's
    /// parameters to `device`.
    pub calibrated: Option<Device>,
    /// The calibration record the written files carry (model, tips, torque source, region,
    /// values as identified, covariance; `hapcal-contract`); `None`: a haptic calibration,
    /// whose calibrated device file (`calibrated`) holds its record.
    pub record: Option<hapcal_contract::Calibration>,
}

/// Position and orientation errors of one data set under one model.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PoseFigures {
    /// Mean 3-D position error over every marker sample, m.
    pub position_mean_m: f64,
    /// RMS of the 3-D position error, m.
    pub position_rms_m: f64,
    /// Largest 3-D position error, m.
    pub position_max_m: f64,
    /// Mean orientation error (angle of the relative rotation), rad; pose data only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation_mean_rad: Option<f64>,
    /// RMS orientation error, rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation_rms_rad: Option<f64>,
    /// Largest orientation error, rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation_max_rad: Option<f64>,
    /// Mean absolute distance error over the distance rows, m; distance data only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_mean_m: Option<f64>,
    /// RMS distance error, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_rms_m: Option<f64>,
    /// Largest absolute distance error, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_max_m: Option<f64>,
}

/// Per-sample errors of one data set, frames only and calibrated, in file order: what a
/// residual plot shows.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SampleErrors {
    /// 3-D position error of every marker sample with frames only, m.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub position_before_m: Vec<f64>,
    /// The same with the calibrated model, m.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub position_after_m: Vec<f64>,
    /// Distance error (model − measured) of every distance row with frames only, m.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub distance_before_m: Vec<f64>,
    /// The same with the calibrated model, m.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub distance_after_m: Vec<f64>,
    /// The rows behind the samples, in file order: what the figures of the HTML report plot the
    /// errors against (not serialised: the JSON report is unchanged).
    #[serde(skip)]
    pub rows: Vec<SampleRow>,
    /// The robot's joints in chain order, each with the unit of its readings (`rad`, or `m`
    /// for a prismatic joint); not serialised.
    #[serde(skip)]
    pub joints: Vec<(String, &'static str)>,
}

/// One row of a measurement file as the figures see it: its line, its joint readings and the
/// markers its position samples belong to.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SampleRow {
    /// 1-based line in the file.
    pub line: u64,
    /// Joint readings in chain order, rad (m for a prismatic joint): the measurement file
    /// row's own readings ([`hapcal_io::MeasuredRow::q`]), shared rather than copied.
    pub q: std::sync::Arc<[f64]>,
    /// The 0-based marker of each of the row's position samples, in the order of
    /// [`SampleErrors::position_before_m`].
    pub markers: Vec<usize>,
    /// Whether the row has a distance sample (one entry of [`SampleErrors::distance_before_m`]).
    pub distance: bool,
}

/// The rows of `table` as [`SampleErrors::rows`] holds them.
pub fn sample_rows(table: &hapcal_io::MeasurementTable) -> Vec<SampleRow> {
    (table.rows.iter())
        .map(|r| SampleRow {
            line: r.line,
            q: r.q.clone(),
            markers: r.markers.iter().map(|m| m.marker).collect(),
            distance: r.distance_m.is_some(),
        })
        .collect()
}

/// The joints named `names` (chain order) with the unit of their readings: `m` where
/// `prismatic` says so, else `rad` ([`SampleErrors::joints`]).
pub fn joint_units(names: &[String], prismatic: &[bool]) -> Vec<(String, &'static str)> {
    (names.iter().enumerate())
        .map(|(j, n)| {
            let unit = if prismatic.get(j).copied().unwrap_or(false) {
                "m"
            } else {
                "rad"
            };
            (n.clone(), unit)
        })
        .collect()
}

/// One rung's cross-validation score.
#[derive(Clone, Debug, Serialize)]
pub struct RungReport {
    /// The rung.
    pub rung: ModelName,
    /// Held-out RMS of the 3-D position error over all folds, m.
    pub heldout_rms_m: f64,
    /// Mean held-out weighted squared error per row (`Σ |e_p|²/σ_p² + θ²/σ_θ²` over the row's
    /// markers, dimensionless) minus the frames-only rung's, and its blocked standard error.
    pub score_difference_to_frames: (f64, f64),
    /// Held-out RMS of the 3-D position error per row over the joint-range folds (each
    /// holds out one end of one joint's training range, [`RangeFold`]), m; `None` without
    /// such folds.
    pub range_rms_m: Option<f64>,
    /// Mean weighted squared error per row over the judged joint-range folds minus the
    /// frames-only rung's (dimensionless; negative: better than frames only where the model
    /// must extrapolate; 0 without such folds).
    pub range_difference_to_frames: f64,
    /// The same difference predicted at the extrapolation needed, and its standard error:
    /// per fold, the straight line through the differences of its blocks of rows against
    /// their extrapolation, evaluated at the share needed on its side, averaged over the
    /// folds (`(0, 0)` without such folds).
    pub range_predicted_to_frames: (f64, f64),
    /// The comparison with the alternative of its own level this rung contains, which it must
    /// also beat to be taken; `None` when it contains none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nested: Option<NestedComparison>,
    /// Kept model parameters (kinematic and compliance) on the full training data.
    pub n_kept: usize,
}

/// Whether the parameter `name` belongs to the instrument's or a marker's frame
/// (`instrument.x` … `marker<k>.rz`) rather than to the robot.
pub(crate) fn is_frame_param(name: &str) -> bool {
    name.starts_with("instrument.") || name.starts_with("marker")
}

/// An identified frame: the instrument-to-base transform or a marker on its link.
#[derive(Clone, Debug, Serialize)]
pub struct FrameReport {
    /// `instrument` or `marker1`, `marker2`, ….
    pub name: String,
    /// Translation, m.
    pub xyz_m: [f64; 3],
    /// Rotation as roll, pitch, yaw (R = Rz(yaw)·Ry(pitch)·Rx(roll)), rad.
    pub rpy_rad: [f64; 3],
}

/// A fold that holds out one end of one joint's training range: the model is fitted on the
/// rest and judged where it must extrapolate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RangeFold {
    /// The joint's name.
    pub joint: String,
    /// `true`: the rows at the top of its range are held out; `false`: the bottom.
    pub upper: bool,
    /// Whether a test or workspace configuration lies beyond the training range on this side
    /// of this joint by more than `OUTSIDE_SHARE` (measured) of it (the folds the ladder judges
    /// extrapolation by).
    pub relevant: bool,
    /// Share of the training rows held out (from `RANGE_FOLD_SHARE` up to
    /// `MAX_RANGE_FOLD_SHARE`, measured).
    pub held_out_share: f64,
    /// The extrapolation the fold emulates: how far its held-out readings reach beyond the
    /// readings it is fitted on, as a share of their range (dimensionless).
    pub emulated_share: f64,
    /// The extrapolation needed on this side: how far the farthest test or workspace reading
    /// lies beyond the training range, as a share of that range (dimensionless).
    pub needed_share: f64,
}

impl RangeFold {
    /// Whether the fold reaches as far beyond its fitted readings, relative to their range, as
    /// the calibration must beyond its training range.
    pub fn emulates(&self) -> bool {
        self.emulated_share >= self.needed_share
    }
}

/// Where the calibration will be used against where it was trained (measurement files with
/// `--workspace` or test rows): per joint and side, the configurations beyond the training
/// range and how far, and what the model choice did about it.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Coverage {
    /// Workspace configurations given (0 without `--workspace`).
    pub n_workspace: usize,
    /// Test rows.
    pub n_test: usize,
    /// Each side of a joint's training range that workspace configurations or test rows lie
    /// beyond by more than `OUTSIDE_SHARE` (measured) of the range, joints in chain order
    /// (empty: they all lie within the training ranges).
    pub sides: Vec<CoverageSide>,
    /// Whether the model was chosen on the ladder (`false`: it was given, and no fold judged
    /// it).
    pub chosen: bool,
    /// The rungs the joint-range folds stopped: each beat the rung chosen below it on the
    /// blocked folds but not on the joint-range folds.
    pub stopped: Vec<RangeStop>,
    /// The workspace configurations (rad, m for a prismatic joint; chain order), for the
    /// figures of the HTML report (not serialised).
    #[serde(skip)]
    pub workspace_q: Vec<Vec<f64>>,
}

/// One side of one joint's training range, and what lies beyond it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CoverageSide {
    /// The joint's name.
    pub joint: String,
    /// `true`: beyond the top of the training range; `false`: below its bottom.
    pub upper: bool,
    /// `rad`, or `m` for a prismatic joint.
    pub unit: &'static str,
    /// The training rows' readings of the joint, min and max (`unit`).
    pub training_range: (f64, f64),
    /// The workspace configurations beyond this side (`None` without `--workspace`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub workspace: Option<Beyond>,
    /// The test rows beyond this side (`None` without test rows).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub test: Option<Beyond>,
    /// The joint-range fold that judged the rungs on this side (`None`: the model was given,
    /// or the training readings' ties leave no fold).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fold: Option<RangeFold>,
}

/// Configurations of one set (workspace or test rows) beyond one side of a joint's training
/// range.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Beyond {
    /// Configurations beyond the side by more than `OUTSIDE_SHARE` (measured) of the range.
    pub n_beyond: usize,
    /// Configurations in the set.
    pub n: usize,
    /// How far the farthest lies beyond the end of the training range (rad, or m for a
    /// prismatic joint); 0 when none does.
    pub farthest: f64,
    /// `farthest` as a share of the training range (dimensionless).
    pub farthest_share: f64,
}

/// A rung the joint-range folds stopped on the climb.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RangeStop {
    /// The rung stopped.
    pub rung: ModelName,
    /// The rung it was compared with (chosen below it).
    pub compared_with: ModelName,
    /// Its weighted squared error per row minus `compared_with`'s predicted at the
    /// extrapolation needed, averaged over the joint-range folds (dimensionless), and the
    /// prediction's standard error (docs/engine.md, "Extrapolation").
    pub range_difference: (f64, f64),
    /// How that difference changes per unit of extrapolation share across the folds' rows
    /// (positive: its advantage shrinks the farther it extrapolates). It was stopped because
    /// the difference is not below zero by `LADDER_SIGNIFICANCE_Z` standard errors, or because
    /// this is positive.
    pub range_growth: f64,
    /// Whether the folds could fit it (`false`: a joint-range fold leaves fewer rows than its
    /// parameters need, so the folds cannot judge it where the calibration extrapolates, and
    /// it is not taken; the differences are then 0).
    pub judged: bool,
}

/// A sample the Huber loss bounded (module `robust`): a marker's position, a socket row's
/// end point, a distance log's distance; its residual under the fit as measured, and the
/// bound the fit saw instead.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Downweighted {
    /// The file.
    pub file: String,
    /// Its line (1-based).
    pub line: u64,
    /// The marker, 1-based (measurement files; none for a socket row or a distance).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub marker: Option<usize>,
    /// Residual under the model the loss was evaluated with (3-D for a marker or a socket
    /// row, the distance's for a log), m.
    pub residual_m: f64,
    /// The residual the fit saw (the Huber corner), m.
    pub bound_m: f64,
}

impl Downweighted {
    /// Where it is: `file:line`, and ` marker k` for a marker.
    pub fn place(&self) -> String {
        let marker = self
            .marker
            .map_or_else(String::new, |m| format!(" marker {m}"));
        format!("{}:{}{marker}", self.file, self.line)
    }
}

/// [`CalibrationReport::termination`] in the report's words.
fn termination_words<S: serde::Serializer>(
    t: &hapcal_identify::Termination,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_str(&termination_text(t))
}

/// How the least-squares fit ended, in plain words for the report: `converged (…)` for the
/// three convergence criteria, else `not converged (…)` or `stopped (…)`.
pub fn termination_text(termination: &hapcal_identify::Termination) -> String {
    use hapcal_identify::Termination as T;
    match termination {
        T::FtolReached => "converged (relative cost reduction below ftol)".to_owned(),
        T::XtolReached => "converged (step below xtol)".to_owned(),
        T::GtolReached => "converged (gradient below gtol)".to_owned(),
        T::MaxEvaluations => "not converged (evaluation limit reached)".to_owned(),
        T::Numerical => "stopped (the step or the Jacobian is not finite)".to_owned(),
        T::EvalFailed(e) => format!("stopped ({e})"),
        T::OneStep => "converged (one Gauss-Newton step, as linearised)".to_owned(),
        other if other.is_success() => "converged".to_owned(),
        _ => "stopped".to_owned(),
    }
}

/// The nominal origin of every URDF joint of `chains` whose `{joint}.x`, `.y`, `.z` are
/// length parameters ([`hapcal_kinematics::Chain::from_placements`]: the origin's fixed
/// transform, then the six deviations), each once, chain order: what
/// `setup::after_fit` words a link by. Empty for D-H chains (their lengths are `a` and `d`).
pub fn joint_origins(chains: &[hapcal_kinematics::Chain]) -> Vec<JointOrigin> {
    use hapcal_kinematics::{Factor, ParamUnit};
    let mut out: Vec<JointOrigin> = Vec::new();
    for chain in chains {
        let factors = chain.factors();
        for (i, factor) in factors.iter().enumerate() {
            let Factor::Screw {
                param: Some(p),
                joint: None,
                ..
            } = factor
            else {
                continue;
            };
            let Some(info) = chain.params().get(*p) else {
                continue;
            };
            let Some(joint) = info.name.strip_suffix(".x") else {
                continue;
            };
            if info.unit != ParamUnit::Meter || out.iter().any(|o| o.joint == joint) {
                continue;
            }
            let Some(Factor::Fixed(origin)) = i.checked_sub(1).and_then(|k| factors.get(k)) else {
                continue;
            };
            let after = (factors[..i].iter().rev()).find_map(|f| match f {
                Factor::Screw { joint: Some(j), .. } => chain.joint_names().get(*j).cloned(),
                _ => None,
            });
            let o = origin.rotation.inverse() * origin.translation.vector;
            out.push(JointOrigin {
                joint: joint.to_owned(),
                after,
                origin_m: [o.x, o.y, o.z],
            });
        }
    }
    out
}
