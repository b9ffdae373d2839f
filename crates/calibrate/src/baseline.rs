//! The geometric baseline that a diagnosis of the sim-to-real gap starts from
//! (docs/diagnosis.md, "Real robots"): any robot and measurement kind that `hapcal calibrate`
//! reads (URDF or D-H device; MUKCa socket folders, distance logs, marker / pose / distance
//! files), as calibration problems on the training and held-out rows, with the geometric
//! estimate on the training rows and the held-out error of each kinematic rung.
//!
//! Everything here is the calibration's own model ([`CalibrationProblem`]) and loaders: the
//! diagnosis adds effect terms to this baseline, it holds no model of its own.

use crate::model::ModelName;
use anyhow::{Context, Result, bail};
use faer::Col;
use hapcal_identify::Problem;
use hapcal_io::MeasurementTable;
use hapcal_kinematics::{Chain, Vector3};
use hapcal_problems::{CalibrationProblem, Observations, Weights};
use nalgebra::Rotation3;
use serde::Serialize;

use crate::data::{Data, DataSet, load_device};
use crate::fit::CV_REPEATS;
use crate::inputs::Plan;
use crate::measured::{MeasuredConfig, Robot, calibrate_measured, ladder_heldout};
pub use crate::model::DataKind;
use crate::model::Rung;

/// A held-out data set as a problem whose first [`GeometricBaseline::n_shared`] parameters are
/// the training problem's.
#[derive(Debug)]
pub struct HeldOutSet {
    /// Set name (placement folder, file stem, `… (last k)` for a `--test-last` split).
    pub name: String,
    /// The problem on its rows (its own unknown points, if any, after the shared parameters).
    pub problem: CalibrationProblem,
    /// Parameters: the training estimate, then its own nuisance parameters (socket points at
    /// the mean of the estimate's end points).
    pub x: Col<f64>,
    /// Configuration (0-based, in file order) of each problem row.
    pub configuration: Vec<usize>,
    /// Per configuration: its time on the training rows' clock, s, when the set has a time
    /// column that continues that clock (every time after the training's last); `None`
    /// otherwise (a clock that restarts with each file, no time column, sockets): the set is
    /// then taken to follow the training rows.
    pub time: Option<Vec<f64>>,
}

/// One rung of the kinematic ladder.
#[derive(Clone, Debug, Serialize)]
pub struct KinematicRung {
    /// The nominal model, frames only, joint offsets or geometric.
    pub rung: Rung,
    /// Held-out RMS of the 3-D position (or distance) error by blocked cross-validation on the
    /// training rows, m; for `nominal`, the training RMS (no parameter but the sockets).
    pub cv_rms_m: f64,
    /// RMS of the same error on each held-out set (order of [`GeometricBaseline::tests`]), m.
    pub test_rms_m: Vec<f64>,
}

/// The geometric calibration of the training rows and everything a diagnosis needs around it.
#[derive(Debug)]
pub struct GeometricBaseline {
    /// What was measured.
    pub kind: DataKind,
    /// The robot (joint names, limits, prismatic flags, URDF link masses).
    pub robot: Robot,
    /// The robot from its base to the first tip, without instrument or marker frames: the
    /// chain of gravity torques (base frame: gravity along −z).
    pub torque_chain: Chain,
    /// The robot's every tip, without instrument or marker frames: the tree of the gravity
    /// loads ([`hapcal_problems::GravityCompliance::joint_loads`]).
    pub torque_tips: Vec<Chain>,
    /// The geometric problem on the training rows.
    pub train: CalibrationProblem,
    /// The geometric estimate, in `train`'s layout.
    pub x: Col<f64>,
    /// Parameters (indices into `train`'s layout) the identification kept: free, and
    /// determined by the data.
    pub kept: Vec<usize>,
    /// Leading parameters shared by the training and held-out problems.
    pub n_shared: usize,
    /// Configuration (0-based) of each training problem row.
    pub configuration: Vec<usize>,
    /// Per configuration: its group (socket, or file), the unit of time-contiguous blocks.
    pub group: Vec<usize>,
    /// Per configuration: its time, s (`t` column), or its position in the file.
    pub time: Vec<f64>,
    /// Whether `time` comes from a time column (else it is the row order).
    pub time_from_data: bool,
    /// Per configuration: the joint readings, rad (m for a prismatic joint).
    pub q: Vec<Vec<f64>>,
    /// Held-out sets.
    pub tests: Vec<HeldOutSet>,
    /// Weights of the residuals (σ per measurement type).
    pub weights: Weights,
    /// The position σ the user stated (`--sigma-m`), m per axis.
    pub stated_sigma_m: Option<f64>,
    /// Rotation from the robot's base frame into the frame the position residuals are
    /// expressed in (the instrument's for marker data; identity otherwise).
    pub base_to_measurement: Rotation3<f64>,
    /// Held-out error of each kinematic rung (empty unless asked for).
    pub ladder: Vec<KinematicRung>,
    /// Plain-language warnings of the loaders and the fits.
    pub warnings: Vec<String>,
}

/// The kinematic rungs of a baseline's ladder ([`KinematicRung`]), simplest first.
const KINEMATIC_RUNGS: [ModelName; 3] = [
    ModelName::FramesOnly,
    ModelName::JointOffsets,
    ModelName::Geometric,
];

/// Loads `plan`'s device and data as `calibrate::run` does, and fits the geometric
/// baseline on the training data; `ladder`: also cross-validate the simpler kinematic rungs.
///
/// # Errors
/// Unreadable or inconsistent input; a haptic device with transmissions (its diagnosis is
/// the reference device's); too few configurations for the geometric model.
pub fn geometric_baseline(plan: &Plan, ladder: bool) -> Result<GeometricBaseline> {
    let device = load_device(&plan.device, &plan.tip)?;
    if device.has_transmissions() {
        bail!(
            "{}: a haptic device with transmissions is diagnosed from its own log (the reference \
             device's diagnosis), not as a serial arm",
            plan.device.display()
        );
    }
    let (train, test) = match crate::data::load(plan, &device)? {
        Data::Measurements { robot, train, test } => {
            return baseline_from_tables(&robot, train, test, plan, ladder);
        }
        Data::Joints { train, test, .. } => (train, test),
        Data::HapticLogs { .. } => bail!("a haptic device's logs are diagnosed as its own"),
    };
    let robot = crate::data::robot_of(plan, &device)?;
    let chain = device
        .chain()
        .with_context(|| format!("building the kinematic chain of {}", plan.device.display()))?;
    baseline_from_sets(&robot, &chain, &train, &test, plan, ladder)
}

/// [`geometric_baseline`] on marker tables in memory (`plan.test_last` splits `train`).
///
/// # Errors
/// As [`calibrate_measured`].
pub fn baseline_from_tables(
    robot: &Robot,
    mut train: Vec<MeasurementTable>,
    mut test: Vec<MeasurementTable>,
    plan: &Plan,
    ladder: bool,
) -> Result<GeometricBaseline> {
    crate::measured::split_test_last(&mut train, &mut test, plan.test_last)?;
    let n_tips = 1 + plan.tips.len();
    let cfg = |rung: Option<ModelName>| MeasuredConfig {
        rung,
        folds: plan.folds,
        sigma_m: plan.sigma_m,
        sigma_rad: plan.sigma_rad,
        marker_tips: (0..n_tips).collect(),
        ..MeasuredConfig::default()
    };
    let fit = |rung| calibrate_measured(robot, &train, &test, &cfg(Some(rung)));
    // The geometric fit and, for the ladder, the kinematic rungs' held-out errors as the
    // ladder of `--model auto` reports them and the simpler rungs' fits, independent of each
    // other: side by side on the cores.
    let (out, kinematic) = rayon::join(
        || fit(ModelName::Geometric),
        || {
            if !ladder {
                return None;
            }
            let (heldout, (frames, offsets)) = rayon::join(
                || ladder_heldout(robot, &train, &test, &cfg(None), &KINEMATIC_RUNGS),
                || {
                    rayon::join(
                        || fit(ModelName::FramesOnly),
                        || fit(ModelName::JointOffsets),
                    )
                },
            );
            Some((heldout, frames, offsets))
        },
    );
    let out = out?;
    let mut warnings: Vec<String> = (train.iter().chain(&test))
        .flat_map(|t| t.warnings.iter().cloned())
        .collect();
    warnings.extend(out.warnings.iter().cloned());
    let weights = out.weights;
    let (obs, configuration) = table_observations(&train);
    let train_problem =
        CalibrationProblem::on_tree(out.tree.clone(), obs, weights, Default::default())
            .context("building the calibration problem")?;
    let x = out.fitted.x.clone();
    let kept = kept_in_full_layout(&out.fitted.identified, &out.fitted.names);
    let mut tests = Vec::new();
    let last_training_time = (train.iter().flat_map(|t| &t.rows))
        .map(|r| r.t_s)
        .try_fold(f64::NEG_INFINITY, |m, t| t.map(|t| m.max(t)));
    for t in &test {
        let (obs, configuration) = table_observations(std::slice::from_ref(t));
        let problem =
            CalibrationProblem::on_tree(out.tree.clone(), obs, weights, Default::default())
                .context("building the held-out problem")?;
        let time: Option<Vec<f64>> = t.rows.iter().map(|r| r.t_s).collect();
        let time = time
            .filter(|time| last_training_time.is_some_and(|last| time.iter().all(|&s| s > last)));
        tests.push(HeldOutSet {
            name: t.name.clone(),
            problem,
            x: x.clone(),
            configuration,
            time,
        });
    }
    let (mut group, mut time, mut q) = (Vec::new(), Vec::new(), Vec::new());
    let time_from_data = train.iter().all(|t| t.rows.iter().all(|r| r.t_s.is_some()));
    let mut offset = 0.0;
    for (ti, t) in train.iter().enumerate() {
        for (ri, row) in t.rows.iter().enumerate() {
            group.push(ti);
            time.push(match (time_from_data, row.t_s) {
                (true, Some(t)) => t,
                _ => offset + ri as f64,
            });
            q.push(row.q.to_vec());
        }
        offset += t.rows.len() as f64;
    }
    let base_to_measurement = out.frames.first().map_or_else(Rotation3::identity, |f| {
        Rotation3::from_euler_angles(f.rpy_rad[0], f.rpy_rad[1], f.rpy_rad[2])
    });
    let mut rungs = Vec::new();
    if let Some((heldout, frames, offsets)) = kinematic {
        let (heldout, frames, offsets) = (heldout?, frames?, offsets?);
        for (rung, fitted) in KINEMATIC_RUNGS
            .into_iter()
            .zip([Some(frames), Some(offsets), None])
        {
            let o = fitted.as_ref().unwrap_or(&out);
            let rms = |p: &crate::measured::PoseFigures| {
                p.distance_rms_m
                    .filter(|_| p.position_rms_m == 0.0)
                    .unwrap_or(p.position_rms_m)
            };
            rungs.push(KinematicRung {
                rung: Rung::Model(rung),
                cv_rms_m: (heldout.iter())
                    .find(|r| r.rung == rung)
                    .map_or(f64::NAN, |r| r.heldout_rms_m),
                test_rms_m: (o.sets.iter())
                    .filter(|s| s.1 == crate::report::SetRole::Test)
                    .map(|s| rms(&s.4))
                    .collect(),
            });
        }
    }
    Ok(GeometricBaseline {
        kind: DataKind::Measurements,
        robot: Robot {
            tree: robot.tree.clone(),
            ..robot.clone()
        },
        torque_chain: robot.tree.tips()[0].clone(),
        torque_tips: robot.tree.tips().to_vec(),
        n_shared: x.nrows(),
        train: train_problem,
        x,
        kept,
        configuration,
        group,
        time,
        time_from_data,
        q,
        tests,
        weights,
        stated_sigma_m: plan.sigma_m,
        base_to_measurement,
        ladder: rungs,
        warnings,
    })
}

/// Observations of every row of `tables` ([`crate::measured::observations`]) and the
/// configuration of each problem row.
fn table_observations(tables: &[MeasurementTable]) -> (Observations, Vec<usize>) {
    let obs =
        crate::measured::observations(crate::measured::Training::measured(tables), &|_, _| true);
    let mut configuration = Vec::with_capacity(obs.rows.len());
    let mut c = 0;
    for t in tables {
        for row in &t.rows {
            let n = usize::from(row.distance_m.is_some()) + row.markers.len();
            configuration.extend(std::iter::repeat_n(c, n));
            c += 1;
        }
    }
    (obs, configuration)
}

/// The kept parameters of an identification over a subset, as indices of the full layout
/// whose names are `names`.
fn kept_in_full_layout(id: &hapcal_identify::Identified, names: &[String]) -> Vec<usize> {
    let mut kept: Vec<usize> = (id.identifiability.kept.iter())
        .filter_map(|&i| names.iter().position(|n| n == id.layout.name(i)))
        .collect();
    kept.sort_unstable();
    kept
}

/// Each test set as a held-out problem at the training estimate: the shared (kinematic)
/// parameters `x[..n_shared]` and each socket at the mean of the estimate's end points of its
/// configurations.
///
/// # Errors
/// A test set whose problem cannot be built.
fn held_out_sets(
    chain: &Chain,
    test: &[DataSet],
    socket_distance_m: f64,
    model: &hapcal_problems::CalibratedModel,
    x: &Col<f64>,
    n_shared: usize,
) -> Result<Vec<HeldOutSet>> {
    let all = |_: usize, _: usize, _: usize| true;
    let mut tests = Vec::new();
    for set in test {
        let obs = crate::solve::observations(std::slice::from_ref(set), socket_distance_m, &all);
        let n = obs.rows.len();
        let held = CalibrationProblem::new(chain.clone(), obs, Weights::default(), None)
            .context("building the held-out problem")?;
        let mut xt = held.initial_guess();
        for i in 0..n_shared {
            xt[i] = x[i];
        }
        // Each socket at the mean of the estimate's end points of its configurations.
        let mut sums = vec![(Vector3::zeros(), 0usize); held.observations().n_points];
        for row in &held.observations().rows {
            if let hapcal_problems::RowKind::Point { point } = row.kind {
                sums[point].0 += model.end_point(&row.q).coords;
                sums[point].1 += 1;
            }
        }
        let off = held.points_offset();
        for (p, (sum, k)) in sums.iter().enumerate() {
            let mean = sum / (*k).max(1) as f64;
            for a in 0..3 {
                xt[off + 3 * p + a] = mean[a];
            }
        }
        tests.push(HeldOutSet {
            name: set.name().to_owned(),
            problem: held,
            x: xt,
            configuration: (0..n).collect(),
            time: None,
        });
    }
    Ok(tests)
}

/// [`geometric_baseline`] on socket placements or distance logs in memory, for `chain` (the
/// calibration chain of the device file) and `robot` (its link masses and joints).
///
/// # Errors
/// No training configuration; fewer configurations than the geometric model keeps; a failed
/// identification.
pub fn baseline_from_sets(
    robot: &Robot,
    chain: &Chain,
    train: &[DataSet],
    test: &[DataSet],
    plan: &Plan,
    ladder: bool,
) -> Result<GeometricBaseline> {
    let all = |_: usize, _: usize, _: usize| true;
    let obs = crate::solve::observations(train, plan.socket_distance_m, &all);
    if obs.rows.is_empty() {
        bail!("the training data have no configuration");
    }
    let kind = if train.iter().all(|s| matches!(s, DataSet::Sockets(_))) {
        DataKind::Sockets
    } else {
        DataKind::Distances
    };
    let (problem, identified) =
        crate::solve::solve(chain, obs, ModelName::Geometric, plan.sigma_m, &[])?;
    let n_shared = problem.points_offset();
    let n_kept = (identified.identifiability.kept.iter())
        .filter(|&&i| i < n_shared)
        .count();
    let n_rows = problem.observations().rows.len();
    if n_kept == 0 || n_rows < n_kept {
        bail!(
            "{n_rows} configurations cannot determine the {n_kept} parameters of the geometric \
             model: record more configurations, spread over the joint ranges"
        );
    }
    let x = identified.fit.x.clone();
    let kept = identified.identifiability.kept.clone();
    let (mut group, mut time, mut q) = (Vec::new(), Vec::new(), Vec::new());
    let mut g = 0;
    for set in train {
        match set {
            DataSet::Sockets(p) => {
                for socket in &p.sockets {
                    for row in &socket.q {
                        group.push(g);
                        time.push(time.len() as f64);
                        q.push(row.clone());
                    }
                    g += 1;
                }
            }
            DataSet::Distances { q: rows, .. } => {
                for row in rows {
                    group.push(g);
                    time.push(time.len() as f64);
                    q.push(row.clone());
                }
                g += 1;
            }
        }
    }
    let configuration = (0..n_rows).collect();
    let model = problem.model(x.as_ref());
    let tests = held_out_sets(chain, test, plan.socket_distance_m, &model, &x, n_shared)?;
    let mut rungs = Vec::new();
    if ladder {
        let point_rms = |p: &CalibrationProblem, x: &Col<f64>| -> Result<f64> {
            let mut r = Col::<f64>::zeros(p.n_residuals());
            p.residuals(x.as_ref(), r.as_mut())
                .map_err(|e| anyhow::anyhow!("evaluating the residuals: {e}"))?;
            let n_rows = p.observations().rows.len().max(1);
            // Rows first (3 residuals each for sockets, 1 for distances), point distances last.
            let per_row = if kind == DataKind::Sockets { 3 } else { 1 };
            let n = n_rows * per_row;
            let ss: f64 = (0..n.min(r.nrows())).map(|i| r[i] * r[i]).sum();
            Ok((ss / n_rows as f64).sqrt())
        };
        // Nominal: the sockets at the mean of the nominal end points, nothing else fitted.
        let mut nominal_x = problem.initial_guess();
        let nominal_test: Vec<f64> = (tests.iter())
            .map(|t| {
                let x0 = t.problem.initial_guess();
                point_rms(&t.problem, &x0)
            })
            .collect::<Result<_>>()?;
        for i in 0..n_shared {
            nominal_x[i] = 0.0;
        }
        rungs.push(KinematicRung {
            rung: Rung::Nominal,
            cv_rms_m: point_rms(&problem, &nominal_x)?,
            test_rms_m: nominal_test,
        });
        let held = crate::solve::cross_validate(
            chain,
            train,
            plan,
            ModelName::Geometric,
            CV_REPEATS,
            &crate::solve::RowBounds::new(),
        )?;
        let cv = (held.sq_errors.iter().sum::<f64>() / held.sq_errors.len().max(1) as f64).sqrt();
        rungs.push(KinematicRung {
            rung: Rung::Model(ModelName::Geometric),
            cv_rms_m: cv,
            test_rms_m: (tests.iter())
                .map(|t| point_rms(&t.problem, &t.x))
                .collect::<Result<_>>()?,
        });
    }
    Ok(GeometricBaseline {
        kind,
        robot: robot.clone(),
        torque_chain: robot.tree.tips()[0].clone(),
        torque_tips: robot.tree.tips().to_vec(),
        train: problem,
        x,
        kept,
        n_shared,
        configuration,
        group,
        time,
        time_from_data: false,
        q,
        tests,
        weights: Weights::default(),
        stated_sigma_m: plan.sigma_m,
        base_to_measurement: Rotation3::identity(),
        ladder: rungs,
        warnings: Vec::new(),
    })
}
