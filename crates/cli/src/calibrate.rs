//! `hapcal calibrate`: identify kinematic deviations (and, when cross-validation on the
//! training data asks for it, joint compliance) from socket or distance measurements.

use anyhow::{Context, Result, bail};
use hapcal_identify::{Identified, IdentifyConfig, Problem, PruneReason, identify};
use hapcal_io::{Device, SocketPlacement};
use hapcal_kinematics::Chain;
use hapcal_metrics::socket_figures;
use hapcal_problems::{
    CalibratedModel, CalibrationProblem, GravityCompliance, Observations, PointDistance, Row,
    RowKind, Weights,
};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Which model to identify.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum ModelChoice {
    /// Choose by k-fold cross-validation on the training data only.
    Auto,
    /// Kinematic parameters only.
    Geometric,
    /// Kinematic parameters plus lumped gravity compliance per joint.
    Compliance,
    /// Kinematic parameters plus gravity compliance per joint, with the torque of the robot's
    /// published link masses (Franka Panda, KUKA LBR iiwa 14; see
    /// [`GravityCompliance::published`]). Not available for other robots.
    MassCompliance,
    /// As [`ModelChoice::MassCompliance`], with one compliance per actuator size
    /// ([`GravityCompliance::published_by_actuator`]).
    ActuatorCompliance,
}

impl ModelChoice {
    /// The compliance term of a fixed choice (`None` for geometric); an error for
    /// [`ModelChoice::MassCompliance`] on a robot without published masses.
    fn compliance(self, chain: &Chain) -> Result<Option<GravityCompliance>> {
        Ok(match self {
            ModelChoice::Auto | ModelChoice::Geometric => None,
            ModelChoice::Compliance => Some(GravityCompliance::default()),
            ModelChoice::MassCompliance => Some(
                GravityCompliance::published(chain.joint_names()).context(
                    "--model mass-compliance: no published link masses for this robot's joint names",
                )?,
            ),
            ModelChoice::ActuatorCompliance => Some(
                GravityCompliance::published_by_actuator(chain.joint_names()).context(
                    "--model actuator-compliance: no published link masses for this robot's joint names",
                )?,
            ),
        })
    }
}

/// Validated inputs of one calibration.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Device file (`.toml`) or URDF (`.urdf`, with `tip`).
    pub device: PathBuf,
    /// Tip link for a URDF device.
    pub tip: String,
    /// Training data: MUKCa placement or run folders, or hapcal log CSVs.
    pub data: Vec<PathBuf>,
    /// Test data (same kinds); never used to fit or to choose settings.
    pub test: Vec<PathBuf>,
    /// Known distance between the two sockets of a placement, m.
    pub socket_distance_m: f64,
    /// Model choice.
    pub model: ModelChoice,
    /// Folds of the cross-validation (time-contiguous blocks per socket).
    pub folds: usize,
    /// Measurement noise (m) if known; otherwise estimated from the residuals.
    pub sigma_m: Option<f64>,
}

impl Plan {
    /// The bundled default: MUKCa `kuka_14`, training on `front`, testing on `left_back` and
    /// `raised_left` (fixtures/mukca, MIT licence, TU Delft).
    pub fn bundled_default() -> Self {
        let root = crate::project_root().join("fixtures/mukca");
        Self {
            device: root.join("urdf/iiwa14.urdf"),
            tip: "ball_link".into(),
            data: vec![root.join("data/kuka_14/front")],
            test: vec![
                root.join("data/kuka_14/left_back"),
                root.join("data/kuka_14/raised_left"),
            ],
            socket_distance_m: 0.05,
            model: ModelChoice::Auto,
            folds: 5,
            sigma_m: None,
        }
    }
}

/// One measured data set: a socket placement or a distance log.
#[derive(Clone, Debug)]
pub enum DataSet {
    /// MUKCa-style placement: rows per socket.
    Sockets(SocketPlacement),
    /// Distance log (DESIGN.md §5): joint readings and cable distance per row.
    Distances {
        /// Name (file stem).
        name: String,
        /// Joint readings per row, rad.
        q: Vec<Vec<f64>>,
        /// Distance per row, m.
        distance_m: Vec<f64>,
    },
}

impl DataSet {
    fn name(&self) -> &str {
        match self {
            DataSet::Sockets(p) => &p.name,
            DataSet::Distances { name, .. } => name,
        }
    }
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
}

/// Figures of one data set before and after calibration.
#[derive(Clone, Debug, Serialize)]
pub struct SetReport {
    /// Placement folder or log name.
    pub name: String,
    /// `train` or `test`.
    pub role: &'static str,
    /// Number of rows.
    pub n_rows: usize,
    /// With the nominal model.
    pub before: Figures,
    /// With the calibrated model.
    pub after: Figures,
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
    /// `m` or `rad`.
    pub unit: &'static str,
}

/// One pruned parameter and why.
#[derive(Clone, Debug, Serialize)]
pub struct PrunedReport {
    /// Parameter name.
    pub name: String,
    /// `near_zero_column` or `dependent`.
    pub reason: &'static str,
    /// For `dependent`: kept parameters that reproduce it, with coefficients.
    pub depends_on: Vec<(String, f64)>,
    /// Its standard deviation had it been kept, in its unit.
    pub std_if_kept: f64,
}

/// Cross-validation score of one candidate model.
#[derive(Clone, Debug, Serialize)]
pub struct CvReport {
    /// Candidate.
    pub model: ModelChoice,
    /// Held-out RMS of the 3-D point (or distance) error over all folds, m.
    pub heldout_rms_m: f64,
    /// Mean over held-out rows of this model's squared error minus the geometric model's, m²,
    /// and its standard error (0 for the geometric model itself).
    pub paired_difference_m2: (f64, f64),
    /// Number of kept parameters on the full training data.
    pub n_kept: usize,
}

/// Everything `hapcal calibrate` found; printed as a table or as one JSON document.
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationReport {
    /// Device path.
    pub device: String,
    /// Chosen model.
    pub model: ModelChoice,
    /// Cross-validation folds (time-contiguous blocks per socket).
    pub folds: usize,
    /// Cross-validation scores (empty when the model was given).
    pub cross_validation: Vec<CvReport>,
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
    /// LM termination.
    pub termination: String,
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
    /// The calibrated model.
    pub model: CalibratedModel,
}

/// Reads the device: a TOML device file, or a URDF imported with `tip`.
///
/// # Errors
/// Whatever `hapcal-io` reports, with the path as context.
pub fn load_device(path: &Path, tip: &str) -> Result<Device> {
    let is_urdf = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    if is_urdf {
        hapcal_io::import_urdf(path, tip).with_context(|| format!("importing {}", path.display()))
    } else {
        hapcal_io::read_device(path).with_context(|| format!("reading device {}", path.display()))
    }
}

/// Reads data sets: MUKCa placement or run folders, or hapcal log CSV files.
///
/// # Errors
/// Missing files, malformed rows (file, line, column), joint-count mismatch.
pub fn load_data(paths: &[PathBuf], device: &Device) -> Result<Vec<DataSet>> {
    let mut sets = Vec::new();
    for path in paths {
        if path.is_file() {
            let log = hapcal_io::read_log(path, device)
                .with_context(|| format!("reading log {}", path.display()))?;
            let name = path.file_stem().map_or_else(
                || path.display().to_string(),
                |s| s.to_string_lossy().into_owned(),
            );
            sets.push(DataSet::Distances {
                name,
                q: log.rows.iter().map(|r| r.q.clone()).collect(),
                distance_m: log.rows.iter().map(|r| r.distance_m).collect(),
            });
        } else {
            let placements =
                hapcal_io::read_mukca_paths(std::slice::from_ref(path), device.n_joints())
                    .with_context(|| format!("reading measurements in {}", path.display()))?;
            sets.extend(placements.into_iter().map(DataSet::Sockets));
        }
    }
    Ok(sets)
}

/// Observations of `sets`; `keep(set, socket, row)` selects rows (for cross-validation).
fn observations(
    sets: &[DataSet],
    socket_distance_m: f64,
    keep: &dyn Fn(usize, usize, usize) -> bool,
) -> Observations {
    let mut obs = Observations::default();
    for (set_idx, set) in sets.iter().enumerate() {
        match set {
            DataSet::Sockets(p) => {
                let first = obs.n_points;
                for (socket_idx, socket) in p.sockets.iter().enumerate() {
                    let point = obs.n_points;
                    obs.n_points += 1;
                    for (row_idx, q) in socket.q.iter().enumerate() {
                        if keep(set_idx, socket_idx, row_idx) {
                            obs.rows.push(Row {
                                q: q.clone(),
                                kind: RowKind::Point { point },
                            });
                        }
                    }
                }
                if p.sockets.len() == 2 {
                    obs.point_distances.push(PointDistance {
                        a: first,
                        b: first + 1,
                        distance_m: socket_distance_m,
                    });
                }
            }
            DataSet::Distances { q, distance_m, .. } => {
                for (row_idx, (q, d)) in q.iter().zip(distance_m).enumerate() {
                    if keep(set_idx, 0, row_idx) {
                        obs.rows.push(Row {
                            q: q.clone(),
                            kind: RowKind::Distance { distance_m: *d },
                        });
                    }
                }
            }
        }
    }
    obs
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

fn solve(
    chain: &Chain,
    obs: Observations,
    compliance: Option<GravityCompliance>,
    sigma_m: Option<f64>,
) -> Result<(CalibrationProblem, Identified)> {
    let n_rows = obs.rows.len();
    let problem = CalibrationProblem::new(chain.clone(), obs, Weights::default(), compliance)
        .context("building the calibration problem")?;
    let x0 = problem.initial_guess();
    let identified = identify(&problem, x0, &identify_config(sigma_m))
        .with_context(|| format!("identifying parameters from {n_rows} configurations"))?;
    Ok((problem, identified))
}

/// Held-out squared errors (m², one per training row, in a fixed order) of k-fold
/// cross-validation with time-contiguous blocks per socket.
fn cross_validate(
    chain: &Chain,
    sets: &[DataSet],
    plan: &Plan,
    compliance: Option<&GravityCompliance>,
) -> Result<Vec<f64>> {
    let lens: Vec<Vec<usize>> = sets
        .iter()
        .map(|s| match s {
            DataSet::Sockets(p) => p.sockets.iter().map(|s| s.q.len()).collect(),
            DataSet::Distances { q, .. } => vec![q.len()],
        })
        .collect();
    let block = |set: usize, socket: usize, row: usize| row * plan.folds / lens[set][socket].max(1);
    let mut errors = Vec::new();
    for fold in 0..plan.folds {
        let obs = observations(sets, plan.socket_distance_m, &|s, k, r| {
            block(s, k, r) != fold
        });
        let (problem, identified) = solve(chain, obs, compliance.cloned(), plan.sigma_m)?;
        let model = problem.model(identified.fit.x.as_ref());
        let points = problem.points(identified.fit.x.as_ref());
        let mut point_base = 0;
        for (set_idx, set) in sets.iter().enumerate() {
            match set {
                DataSet::Sockets(p) => {
                    for (socket_idx, socket) in p.sockets.iter().enumerate() {
                        for (row_idx, q) in socket.q.iter().enumerate() {
                            if block(set_idx, socket_idx, row_idx) == fold {
                                errors.push(
                                    (model.end_point(q) - points[point_base + socket_idx])
                                        .norm_squared(),
                                );
                            }
                        }
                    }
                    point_base += p.sockets.len();
                }
                DataSet::Distances { q, distance_m, .. } => {
                    for (row_idx, (q, d)) in q.iter().zip(distance_m).enumerate() {
                        if block(set_idx, 0, row_idx) == fold {
                            errors.push((model.end_point(q).coords.norm() - d).powi(2));
                        }
                    }
                }
            }
        }
    }
    if errors.is_empty() {
        bail!("cross-validation held out no row");
    }
    Ok(errors)
}

/// Mean and standard error of `a − b`, element by element (paired held-out errors).
fn paired_difference(a: &[f64], b: &[f64]) -> (f64, f64) {
    let n = a.len().min(b.len());
    if n < 2 {
        return (0.0, f64::INFINITY);
    }
    let d: Vec<f64> = a.iter().zip(b).map(|(a, b)| a - b).collect();
    let mean = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (mean, (var / n as f64).sqrt())
}

/// Refuses a calibration whose data determine no parameter, or fewer configurations than the
/// parameters they would keep.
fn check_determined(n_configurations: usize, n_kept: usize, n_model_params: usize) -> Result<()> {
    if n_kept == 0 {
        bail!(
            "{n_configurations} configurations determine none of the {n_model_params} model parameters: \
             record more configurations, spread over the joint ranges"
        );
    }
    if n_configurations < n_kept {
        bail!(
            "{n_configurations} configurations cannot determine the {n_kept} parameters the data would keep: \
             record at least {n_kept} configurations (a few times more for a useful calibration)"
        );
    }
    Ok(())
}

/// Figures of one data set under `model`.
///
/// # Errors
/// A socket with no row.
pub fn figures(set: &DataSet, model: &CalibratedModel, socket_distance_m: f64) -> Result<Figures> {
    Ok(match set {
        DataSet::Sockets(p) => {
            let points: Vec<Vec<_>> = p
                .sockets
                .iter()
                .map(|s| s.q.iter().map(|q| model.end_point(q)).collect())
                .collect();
            let f = socket_figures(&points, socket_distance_m)?;
            Figures {
                mean_absolute_error_m: Some(f.mean_absolute_error_m),
                distance_error_m: f.distance_error_m,
                distance_rms_m: None,
            }
        }
        DataSet::Distances { q, distance_m, .. } => {
            let r: Vec<f64> = q
                .iter()
                .zip(distance_m)
                .map(|(q, d)| model.end_point(q).coords.norm() - d)
                .collect();
            Figures {
                mean_absolute_error_m: None,
                distance_error_m: None,
                distance_rms_m: Some(hapcal_metrics::rms(&r)),
            }
        }
    })
}

fn n_rows(set: &DataSet) -> usize {
    match set {
        DataSet::Sockets(p) => p.sockets.iter().map(|s| s.q.len()).sum(),
        DataSet::Distances { q, .. } => q.len(),
    }
}

/// Runs a calibration: reads everything, chooses the model by cross-validation on the training
/// data, identifies, and evaluates on training and test data.
///
/// # Errors
/// Unreadable or inconsistent input, or too few configurations for the kept parameters.
pub fn run(plan: &Plan) -> Result<Outcome> {
    let start = Instant::now();
    if plan.folds < 2 {
        bail!("--folds must be at least 2, got {}", plan.folds);
    }
    if !(plan.socket_distance_m.is_finite() && plan.socket_distance_m > 0.0) {
        bail!(
            "--socket-distance-m must be a positive length, got {}",
            plan.socket_distance_m
        );
    }
    let device = load_device(&plan.device, &plan.tip)?;
    let chain = device
        .chain()
        .with_context(|| format!("building the kinematic chain of {}", plan.device.display()))?;
    let train = load_data(&plan.data, &device)?;
    let test = load_data(&plan.test, &device)?;

    // The geometric fit on all training data comes first: it refuses data that cannot determine
    // the model before any time goes into cross-validation, and it is the answer whenever the
    // geometric model is chosen.
    let obs = observations(&train, plan.socket_distance_m, &|_, _, _| true);
    let n_configurations = obs.rows.len();
    let geometric = solve(&chain, obs.clone(), None, plan.sigma_m)?;
    let n_kept = |p: &CalibrationProblem, id: &Identified| {
        id.identifiability
            .kept
            .iter()
            .filter(|&&i| i < p.points_offset())
            .count()
    };
    check_determined(
        n_configurations,
        n_kept(&geometric.0, &geometric.1),
        geometric.0.points_offset(),
    )?;
    let mut cross_validation = Vec::new();
    let choice = match plan.model {
        ModelChoice::Auto => {
            // Every model the robot supports is a candidate; the lowest held-out RMS wins. The
            // paired difference to the geometric model (and its standard error) is reported so
            // that a reader sees how clear the choice is.
            let mut candidates = vec![ModelChoice::Geometric, ModelChoice::Compliance];
            if GravityCompliance::published(chain.joint_names()).is_some() {
                candidates.push(ModelChoice::MassCompliance);
                candidates.push(ModelChoice::ActuatorCompliance);
            }
            let mut geometric_errors = Vec::new();
            let mut best = (f64::INFINITY, ModelChoice::Geometric);
            for candidate in candidates {
                let compliance = candidate.compliance(&chain)?;
                let errors = cross_validate(&chain, &train, plan, compliance.as_ref())?;
                let rms = (errors.iter().sum::<f64>() / errors.len() as f64).sqrt();
                let paired = if candidate == ModelChoice::Geometric {
                    geometric_errors = errors;
                    best = (rms, candidate);
                    (0.0, 0.0)
                } else {
                    if rms < best.0 {
                        best = (rms, candidate);
                    }
                    paired_difference(&errors, &geometric_errors)
                };
                cross_validation.push(CvReport {
                    model: candidate,
                    heldout_rms_m: rms,
                    paired_difference_m2: paired,
                    n_kept: 0,
                });
            }
            best.1
        }
        fixed => fixed,
    };
    let (problem, identified) = if choice == ModelChoice::Geometric {
        geometric
    } else {
        solve(&chain, obs, choice.compliance(&chain)?, plan.sigma_m)?
    };
    let model = problem.model(identified.fit.x.as_ref());
    let layout = problem.layout();
    let n_kept_model = n_kept(&problem, &identified);
    check_determined(n_configurations, n_kept_model, problem.points_offset())?;
    if let Some(cv) = cross_validation.iter_mut().find(|c| c.model == choice) {
        cv.n_kept = n_kept_model;
    }

    let stds = identified.covariance.std();
    let parameters = identified
        .covariance
        .free
        .iter()
        .zip(stds.iter())
        .filter(|(i, _)| **i < problem.points_offset())
        .map(|(&i, &std)| ParamReport {
            name: layout.name(i).to_string(),
            value: identified.fit.x[i],
            std,
            unit: layout.spec(i).unit.symbol(),
        })
        .collect();
    let pruned = identified
        .identifiability
        .pruned
        .iter()
        .map(|p| {
            let (reason, depends_on) = match &p.reason {
                PruneReason::NearZeroColumn => ("near_zero_column", Vec::new()),
                PruneReason::Dependent { on } => ("dependent", on.clone()),
                _ => ("other", Vec::new()),
            };
            PrunedReport {
                name: p.name.clone(),
                reason,
                depends_on,
                std_if_kept: p.std_if_kept,
            }
        })
        .collect();
    let correlated = identified
        .covariance
        .correlated_pairs(0.95)
        .into_iter()
        .filter(|(a, b, _)| *a < problem.points_offset() && *b < problem.points_offset())
        .map(|(a, b, c)| (layout.name(a).to_string(), layout.name(b).to_string(), c))
        .collect();

    let priors = identify_config(plan.sigma_m).rank;
    let observability =
        crate::support::observability_report(&problem, &identified, &priors, n_configurations);
    let warnings = crate::support::warnings(
        &identified,
        &priors,
        problem.points_offset(),
        0.95,
        observability.as_ref(),
    );

    let nominal = CalibratedModel::nominal(chain.clone());
    let mut placements = Vec::new();
    for (role, sets) in [("train", &train), ("test", &test)] {
        for set in sets.iter() {
            placements.push(SetReport {
                name: set.name().to_string(),
                role,
                n_rows: n_rows(set),
                before: figures(set, &nominal, plan.socket_distance_m)?,
                after: figures(set, &model, plan.socket_distance_m)?,
            });
        }
    }
    let report = CalibrationReport {
        device: plan.device.display().to_string(),
        model: choice,
        folds: plan.folds,
        cross_validation,
        sigma_m: identified.sigma,
        sigma_source: match identified.sigma_source {
            hapcal_identify::SigmaSource::Given => "given",
            _ => "residuals",
        },
        parameters,
        pruned,
        correlated,
        observability,
        warnings,
        termination: format!("{:?}", identified.fit.termination),
        n_evaluations: identified.fit.n_evaluations,
        n_jacobians: identified.fit.n_jacobians,
        rounds: identified.rounds,
        placements,
        elapsed_s: start.elapsed().as_secs_f64(),
    };
    Ok(Outcome {
        report,
        device,
        device_path: plan.device.clone(),
        model,
    })
}

/// Writes the calibrated device: a `.urdf` path gets a copy of the source URDF with the
/// calibrated joint origins; any other path a device TOML with a `[calibration]` table.
///
/// # Errors
/// A `.urdf` output for a device that did not come from a URDF, or an I/O error.
pub fn write_outputs(outcome: &Outcome, out: &Path) -> Result<()> {
    let values: Vec<hapcal_io::CalibratedValue> = outcome
        .report
        .parameters
        .iter()
        .filter(|p| outcome.model.chain.param_index(&p.name).is_some())
        .map(|p| hapcal_io::CalibratedValue {
            name: p.name.clone(),
            value: p.value,
            std: p.std,
            unit: p.unit.to_string(),
        })
        .collect();
    let meta = hapcal_io::CalibrationMeta {
        date: None,
        data_hash: None,
        notes: Some(format!(
            "hapcal calibrate, model {:?}; {} kept parameters; compliance terms are not part of the kinematic description",
            outcome.report.model,
            outcome.report.parameters.len()
        )),
    };
    let calibrated = outcome
        .device
        .with_calibration(&values, meta)
        .context("applying the identified deviations to the device description")?;
    let text = if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
    {
        let from_urdf = outcome
            .device_path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
        let source = if from_urdf {
            Some(outcome.device_path.clone())
        } else {
            outcome
                .device
                .urdf
                .as_ref()
                .map(|u| u.resolve(&outcome.device_path))
        };
        let Some(source) = source else {
            bail!(
                "{} is a URDF output, but the device {} did not come from a URDF",
                out.display(),
                outcome.device_path.display()
            );
        };
        hapcal_io::write_calibrated_urdf(&source, &calibrated.placements).with_context(|| {
            format!(
                "writing the calibrated joint origins into a copy of {}",
                source.display()
            )
        })?
    } else {
        hapcal_io::write_device(&calibrated)
    };
    std::fs::write(out, text).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}
