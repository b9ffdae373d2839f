//! `hapcal calibrate`: reads the device and the data, types the data's kind, and runs the
//! workflow of that kind: socket recordings and distance logs here (their fits in `solve`),
//! measurement files in [`crate::measured`], a haptic device's logs in [`crate::haptic`]; every
//! one chooses its model on the ladder of [`crate::model`] and reports in the types of
//! [`crate::report`].

use anyhow::{Context, Result, bail};
use hapcal_identify::{Identified, Problem};
use hapcal_io::Device;
use hapcal_kinematics::Point3;
use hapcal_metrics::socket_figures;
use hapcal_problems::{CalibratedModel, CalibrationProblem, RowKind};
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::data::{
    Data, DataSet, NamedLog, check_csv_header, check_sockets, load, load_data, load_device,
    load_device_tips,
};
pub use crate::fit::{
    CV_REPEATS, HeldOut, backend_of, blocked_difference, blocked_mean_difference, fold_of,
    identify_config, pruned_report, termination_text,
};
pub use crate::inputs::{
    GRAVITY_DOWN, Plan, SIGMA_M_RANGE, SIGMA_RAD_RANGE, check_sigma, gravity_words, parse_gravity,
};
pub use crate::model::{DataKind, LADDER_SIGNIFICANCE_Z, ModelChoice, ModelName};
use crate::record::{output_files, runtime_robot, runtime_robot_of, source_urdf};
pub use crate::report::{
    CalibrationReport, CvReport, Figures, Outcome, ParamReport, PruneCause, PrunedReport,
    SetReport, SetRole,
};
use crate::solve::{cross_validate, observations, residual_scale, solve};

/// Refuses a calibration whose data determine no parameter, or fewer configurations than the
/// parameters they would keep.
fn check_determined(n_configurations: usize, n_kept: usize, n_model_params: usize) -> Result<()> {
    if n_kept == 0 {
        bail!(
            "{n_configurations} configurations determine none of the {n_model_params} model parameters: \
             record more configurations, spread over the joint ranges (or, with --sigma-m, give \
             the instrument's σ: a σ far above the residual keeps nothing)"
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

/// Figures of one data set with the end point `end_point` gives at each configuration (m,
/// in the base frame): a calibrated model's ([`CalibratedModel::end_point`]) or the
/// runtime's robot's ([`runtime_robot`]).
///
/// # Errors
/// A socket with no row; `end_point`'s own error.
pub fn figures(
    set: &DataSet,
    end_point: &mut dyn FnMut(&[f64]) -> Result<Point3<f64>>,
    socket_distance_m: f64,
) -> Result<Figures> {
    Ok(match set {
        DataSet::Sockets(p) => {
            let points: Vec<Vec<_>> = (p.sockets.iter())
                .map(|s| s.q.iter().map(|q| end_point(q)).collect::<Result<_>>())
                .collect::<Result<_>>()?;
            let f = socket_figures(&points, socket_distance_m)?;
            Figures {
                mean_absolute_error_m: Some(f.mean_absolute_error_m),
                distance_error_m: f.distance_error_m,
                distance_rms_m: None,
                pose: None,
            }
        }
        DataSet::Distances { q, distance_m, .. } => {
            let r: Vec<f64> = (q.iter().zip(distance_m))
                .map(|(q, d)| Ok(end_point(q)?.coords.norm() - d))
                .collect::<Result<_>>()?;
            Figures {
                mean_absolute_error_m: None,
                distance_error_m: None,
                distance_rms_m: Some(hapcal_metrics::rms(&r)),
                pose: None,
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
/// data, identifies, and evaluates on training and test data. The stages: `load_checked`,
/// then the workflow of the data's kind (a haptic device's logs in
/// [`crate::haptic::calibrate_logs`], measurement files in [`crate::measured::run_tables`],
/// socket recordings and distance logs in `calibrate_joints`).
///
/// # Errors
/// Unreadable or inconsistent input, or too few configurations for the kept parameters.
pub fn run(plan: &Plan) -> Result<Outcome> {
    let start = Instant::now();
    let (device, data) = load_checked(plan)?;
    match data {
        Data::HapticLogs { train, test } => {
            refuse_options(
                plan,
                "a haptic device's log (the cable-encoder σ comes from the residuals, the \
                 held-out data from --test)",
            )?;
            crate::haptic::calibrate_logs(plan, device, train, test, start)
        }
        Data::Measurements { robot, train, test } => {
            crate::measured::run_tables(plan, &device, &robot, train, test, start)
        }
        Data::Joints { kind, train, test } => {
            calibrate_joints(plan, device, kind, train, test, start)
        }
    }
}

/// The load stage of [`run`]: the plan's own checks, the device and the data, and the options
/// that do not apply to the data's kind refused.
///
/// # Errors
/// An invalid plan, an unreadable device or data file, or an option the data's kind has no use
/// for (`--joint`, `--workspace`, `--gravity`), named with the flag's value.
fn load_checked(plan: &Plan) -> Result<(Device, Data)> {
    plan.validate()?;
    check_distinct_inputs(plan)?;
    let device = if plan.tips.is_empty() {
        load_device(&plan.device, &plan.tip)?
    } else {
        load_device_tips(&plan.device, &plan.tip, &plan.tips)?
    };
    let data = crate::data::load(plan, &device)?;
    let kind = data.kind();
    if kind != DataKind::HapticLogs && plan.joint {
        bail!("--joint applies to a haptic device with transmissions (capstans, parallelogram)");
    }
    plan.model.check_fits(kind)?;
    if let Some(w) = &plan.workspace
        && kind != DataKind::Measurements
    {
        bail!(
            "--workspace {} applies to measurement files (positions, poses, anchor distances): \
             {} have no joint-range folds",
            w.display(),
            kind.words()
        );
    }
    if plan.gravity != crate::inputs::GRAVITY_DOWN && kind != DataKind::Measurements {
        bail!(
            "--gravity {} applies to measurement files of a URDF robot (its compliance models' \
             loads): {} take the mounting from the device file",
            gravity_words(plan.gravity),
            kind.words()
        );
    }
    Ok((device, data))
}

/// The training rows of a socket or distance-log calibration as every fit sees them: the
/// gross errors bounded by the Huber loss (every fit weights the bounded rows by their Huber
/// weights; the figures are of the data as measured).
struct JointRows {
    /// Each bounded row's bound, by (set, socket, row).
    bounds: crate::solve::RowBounds,
    /// The bounded rows, for the report.
    downweighted: Vec<crate::report::Downweighted>,
    /// Per-residual scale of the bounded rows (empty when none is bounded).
    scale: Vec<f64>,
    /// Every training row's observation.
    obs: hapcal_problems::Observations,
    /// Each joint's range over the rows (rad or m), for the record.
    ranges: Vec<(f64, f64)>,
    /// Distinct configurations: copies of one add residuals but no information.
    n_configurations: usize,
}

/// The rows stage of [`calibrate_joints`]: bounds the gross errors of `train` and builds the
/// observations every fit shares ([`JointRows`]).
fn joint_rows(chain: &hapcal_kinematics::Chain, train: &[DataSet], plan: &Plan) -> JointRows {
    let (bounds, downweighted) = crate::solve::winsorize(chain, train, plan);
    let all = |_: usize, _: usize, _: usize| true;
    let scale = residual_scale(train, &bounds, &all);
    let obs = observations(train, plan.socket_distance_m, &all);
    let ranges =
        crate::measured::reading_ranges(obs.rows.iter().map(|r| &r.q[..]), chain.n_joints());
    let n_configurations = (obs.rows.iter())
        .map(|row| {
            let point = match row.kind {
                RowKind::Point { point } => point,
                _ => usize::MAX,
            };
            let q: Vec<u64> = row.q.iter().map(|v| (v + 0.0).to_bits()).collect();
            (point, q)
        })
        .collect::<std::collections::HashSet<_>>()
        .len();
    JointRows {
        bounds,
        downweighted,
        scale,
        obs,
        ranges,
        n_configurations,
    }
}

/// Kinematic parameters (indices below the points' offset) an identification kept.
fn n_kept(problem: &CalibrationProblem, identified: &Identified) -> usize {
    (identified.identifiability.kept.iter())
        .filter(|&&i| i < problem.points_offset())
        .count()
}

/// The model choice of a socket or distance-log calibration: the plan's model, or with
/// `--model auto` the ladder's choice by blocked cross-validation.
struct JointChoice {
    /// The chosen model.
    model: ModelName,
    /// The ladder's held-out scores (empty when the model was given).
    cross_validation: Vec<CvReport>,
    /// The warning about copies of a configuration, if the training data hold any.
    copies: Option<String>,
}

/// The ladder stage of [`calibrate_joints`]: with `--model auto`, every rung of the data's
/// ladder the robot carries (transversal compliance needs rotation deviations on a revolute
/// joint) cross-validated and chosen by the rule every workflow uses (docs/engine.md). Within
/// one placement the gravity torques hardly change, so compliance and geometry are nearly
/// confounded and a win inside the noise does not carry to other placements: hence the margin.
///
/// # Errors
/// A cross-validation fit that fails.
fn choose_joint_model(
    chain: &hapcal_kinematics::Chain,
    train: &[DataSet],
    plan: &Plan,
    kind: DataKind,
    bounds: &crate::solve::RowBounds,
) -> Result<JointChoice> {
    if let ModelChoice::Model(fixed) = plan.model {
        return Ok(JointChoice {
            model: fixed,
            cross_validation: Vec::new(),
            copies: None,
        });
    }
    let (candidates, level) =
        crate::model::ladder_for(kind, chain.joint_names(), std::slice::from_ref(chain));
    let held = (candidates.iter())
        .map(|&candidate| cross_validate(chain, train, plan, candidate, CV_REPEATS, bounds))
        .collect::<Result<Vec<_>>>()?;
    let (model, cross_validation) = crate::fit::choose(&candidates, &level, &held);
    let n_copies = (crate::solve::set_originals(train).iter().flatten())
        .map(|o| crate::fit::n_copies(o))
        .sum();
    Ok(JointChoice {
        model,
        cross_validation,
        copies: crate::fit::copies_warning(n_copies),
    })
}

/// The workflow of socket recordings and distance logs: rows ([`joint_rows`]) → geometric fit
/// (it refuses data that cannot determine the model before any time goes into
/// cross-validation, and it is the answer whenever the geometric model is chosen) → ladder
/// ([`choose_joint_model`]) → final fit → report ([`joint_report`]) → record.
///
/// # Errors
/// `--test-last` (measurement files only), a chain the device cannot build, too few
/// configurations for the kept parameters or the folds, a fit or a figure that fails.
fn calibrate_joints(
    plan: &Plan,
    device: Device,
    kind: DataKind,
    train: Vec<DataSet>,
    test: Vec<DataSet>,
    start: Instant,
) -> Result<Outcome> {
    if plan.test_last.is_some() {
        bail!(
            "--test-last applies to measurement files (positions, poses, distances); hold out \
             MUKCa socket folders or distance logs with --test"
        );
    }
    let chain = device
        .chain()
        .with_context(|| format!("building the kinematic chain of {}", plan.device.display()))?;
    let rows = joint_rows(&chain, &train, plan);
    let n_training_rows = rows.obs.rows.len();
    let geometric = solve(
        &chain,
        rows.obs.clone(),
        ModelName::Geometric,
        plan.sigma_m,
        &rows.scale,
    )?;
    check_determined(
        rows.n_configurations,
        n_kept(&geometric.0, &geometric.1),
        geometric.0.points_offset(),
    )?;
    // Cross-validation splits the training configurations into `folds` blocks: more folds than
    // configurations would leave folds without a row to hold out.
    let n_configurations = rows.n_configurations;
    if n_configurations > 0 && plan.folds > n_configurations {
        bail!(
            "--folds {} is not possible with {n_configurations} training configurations (2 to {n_configurations})",
            plan.folds
        );
    }
    let mut choice = choose_joint_model(&chain, &train, plan, kind, &rows.bounds)?;
    let (problem, identified) = if choice.model == ModelName::Geometric {
        geometric
    } else {
        solve(&chain, rows.obs, choice.model, plan.sigma_m, &rows.scale)?
    };
    let model = problem.model(identified.fit.x.as_ref());
    let n_kept_model = n_kept(&problem, &identified);
    check_determined(n_configurations, n_kept_model, problem.points_offset())?;
    if let Some(cv) = (choice.cross_validation.iter_mut()).find(|c| c.model == choice.model) {
        cv.n_kept = n_kept_model;
    }
    let fitted = JointFit {
        chain: &chain,
        problem: &problem,
        identified: &identified,
        model: &model,
        n_configurations,
    };
    let report = joint_report(
        plan,
        kind,
        &fitted,
        choice,
        rows.downweighted,
        (&train, &test),
        start,
    )?;
    let record = joint_record(
        plan,
        &device,
        &fitted,
        &report,
        rows.ranges,
        n_training_rows,
    );
    let mut outcome = Outcome {
        report,
        device,
        device_path: plan.device.clone(),
        model,
        calibrated: None,
        record: Some(record),
    };
    // The calibrated figures are the runtime's evaluation of the files calibrate writes.
    if let Some(robot) = runtime_robot(&outcome)? {
        let mut markers = crate::predict::MarkerPoses::new(&robot)?;
        let mut end_point = |q: &[f64]| Ok(markers.at(q, &[0])?[0].translation.vector.into());
        let sets = outcome.report.placements.iter_mut();
        for (set, data) in sets.zip(train.iter().chain(&test)) {
            set.after = figures(data, &mut end_point, plan.socket_distance_m)?;
        }
    }
    Ok(outcome)
}

/// The final fit of a socket or distance-log calibration, as its report and record read it.
struct JointFit<'a> {
    /// The robot's chain.
    chain: &'a hapcal_kinematics::Chain,
    /// The chosen model's problem.
    problem: &'a CalibrationProblem,
    /// Its identification on every training row.
    identified: &'a Identified,
    /// The calibrated model at the identified values.
    model: &'a CalibratedModel,
    /// Distinct training configurations.
    n_configurations: usize,
}

/// The report stage of [`calibrate_joints`]: parameters, pruned and correlated ones, the
/// lengths refitted, observability, warnings and every placement's figures before and after.
///
/// # Errors
/// A placement's figures that cannot be computed.
fn joint_report(
    plan: &Plan,
    kind: DataKind,
    fitted: &JointFit<'_>,
    choice: JointChoice,
    downweighted: Vec<crate::report::Downweighted>,
    (train, test): (&[DataSet], &[DataSet]),
    start: Instant,
) -> Result<CalibrationReport> {
    let JointFit {
        chain,
        problem,
        identified,
        model,
        n_configurations,
    } = *fitted;
    let layout = problem.layout();
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
    let pruned = pruned_report(identified);
    // The lengths the fit held at nominal (pruned), and every length after fitting them.
    let lengths: Vec<usize> = (0..problem.points_offset())
        .filter(|&i| layout.spec(i).unit == hapcal_identify::Unit::Meter)
        .collect();
    let held: Vec<usize> = (lengths.iter().copied())
        .filter(|i| !identified.identifiability.kept.contains(i))
        .collect();
    // Not after the Huber loss bounded rows: a bounded row's leftover residual, far from the
    // others' configurations, pulls the weak directions the held lengths lie along.
    let refitted_lengths = if downweighted.is_empty() {
        crate::fit::refitted_lengths(
            problem,
            identified.fit.x.as_ref(),
            identified.sigma,
            &identified.identifiability.kept,
            &held,
            &lengths,
        )
    } else {
        Vec::new()
    };
    let correlated = identified
        .covariance
        .correlated_pairs(0.95)
        .into_iter()
        .filter(|(a, b, _)| *a < problem.points_offset() && *b < problem.points_offset())
        .map(|(a, b, c)| (layout.name(a).to_string(), layout.name(b).to_string(), c))
        .collect();
    let priors = identify_config(plan.sigma_m).rank;
    let observability =
        crate::support::observability_report(problem, identified, &priors, n_configurations);
    let mut warnings = crate::support::warnings(
        identified,
        &priors,
        problem.points_offset(),
        0.95,
        observability.as_ref(),
    );
    warnings.extend(residual_warning(plan, choice.model, identified, train));
    let placements = joint_placements(plan, chain, model, train, test)?;
    // A test placement the calibration made worse is the first thing an engineer must see.
    warnings.splice(0..0, worse_placements(&placements));
    warnings.extend(choice.copies);
    warnings.extend(bounded_warnings(kind, &downweighted));
    Ok(CalibrationReport {
        device: plan.device.display().to_string(),
        model: choice.model,
        folds: plan.folds,
        cross_validation: choice.cross_validation,
        cross_validated_rows: None,
        ladder: Vec::new(),
        frames: Vec::new(),
        sigma_m: identified.sigma,
        sigma_source: identified.sigma_source.name(),
        parameters,
        pruned,
        correlated,
        observability,
        warnings,
        termination: identified.fit.termination.clone(),
        backend: backend_of(identified),
        n_evaluations: identified.fit.n_evaluations,
        n_jacobians: identified.fit.n_jacobians,
        rounds: identified.rounds,
        placements,
        elapsed_s: start.elapsed().as_secs_f64(),
        downweighted,
        range_folds: Vec::new(),
        coverage: None,
        equilibrium_step_m: None,
        equilibrium_refits: 0,
        // What no real robot has: an unconverged fit, compliances below zero beyond the bound.
        implausible: crate::fit::implausible_estimates(
            identified,
            choice.model,
            matches!(plan.model, ModelChoice::Model(_)),
            compliance_unit_of(model),
            1.0,
        ),
        refitted_lengths,
        origins: crate::report::joint_origins(std::slice::from_ref(chain)),
    })
}

/// The calibrated residual against the stated σ or, for sockets, the robots' repeatability
/// ([`crate::noise`]): far above it, the model lacks an effect or the setup is wrong. `None`
/// when the plan states σ or the fit did not estimate it from the residuals.
fn residual_warning(
    plan: &Plan,
    choice: ModelName,
    identified: &Identified,
    train: &[DataSet],
) -> Option<String> {
    if plan.sigma_m.is_some()
        || !matches!(
            identified.sigma_source,
            hapcal_identify::SigmaSource::Residuals
        )
    {
        return None;
    }
    let sockets = train.iter().any(|s| matches!(s, DataSet::Sockets(_)));
    let (sigma, class) = if sockets {
        (
            crate::noise::SOCKET_SIGMA_M,
            "a robot's repeatability in a socket",
        )
    } else {
        (crate::noise::ANCHOR_DISTANCE_SIGMA_M, "a draw-wire encoder")
    };
    crate::noise::residual_warning(
        &choice.to_string(),
        identified.sigma,
        sigma,
        Some(class),
        crate::noise::DEFAULT_SIGMA_RATIO,
    )
}

/// Every training and test placement's figures with the nominal and the calibrated model.
///
/// # Errors
/// A placement's figures that cannot be computed.
fn joint_placements(
    plan: &Plan,
    chain: &hapcal_kinematics::Chain,
    model: &CalibratedModel,
    train: &[DataSet],
    test: &[DataSet],
) -> Result<Vec<SetReport>> {
    let nominal = CalibratedModel::nominal(chain.clone());
    let d = plan.socket_distance_m;
    let mut placements = Vec::new();
    for (role, sets) in [(SetRole::Train, train), (SetRole::Test, test)] {
        for set in sets.iter() {
            placements.push(SetReport {
                name: set.name().to_string(),
                role,
                n_rows: n_rows(set),
                before: figures(set, &mut |q| Ok(nominal.end_point(q)), d)?,
                after: figures(set, &mut |q| Ok(model.end_point(q)), d)?,
                errors: None,
            });
        }
    }
    Ok(placements)
}

/// One warning per test placement the calibration made worse than the nominal model.
fn worse_placements(placements: &[SetReport]) -> Vec<String> {
    let mut worse = Vec::new();
    for p in placements.iter().filter(|p| p.role == SetRole::Test) {
        if let (Some(before), Some(after)) = (
            p.before.mean_absolute_error_m,
            p.after.mean_absolute_error_m,
        ) && after > before
        {
            worse.push(format!(
                "test placement {}: the calibrated model is worse than the nominal one (mean \
                     absolute error {:.3} → {:.3} mm). The training data do not determine what \
                     matters there (record a placement closer to it), or the robot has an effect \
                     the model lacks (backlash, compliance): do not use this calibration there",
                p.name,
                before * 1e3,
                after * 1e3
            ));
        }
    }
    worse
}

/// The warnings about rows the Huber loss bounded, and those left out of every fit.
fn bounded_warnings(kind: DataKind, downweighted: &[crate::report::Downweighted]) -> Vec<String> {
    let rows = if kind == DataKind::Sockets {
        "socket rows"
    } else {
        "log rows"
    };
    let mut warnings: Vec<String> =
        crate::robust::bounded_warning(downweighted, rows, &ModelName::Geometric.to_string())
            .into_iter()
            .collect();
    let n_left_out = (downweighted.iter())
        .filter(|d| d.residual_m > crate::robust::REJECTION * d.bound_m)
        .count();
    if n_left_out > 0 {
        warnings.push(format!(
            "{n_left_out} of the {} bounded {rows} lie beyond {} times the corner and were \
             left out of every fit: the corner's force alone would let a row far from the \
             others (a glitch in its joint readings) move the parameters by many standard \
             deviations",
            downweighted.len(),
            crate::robust::REJECTION
        ));
    }
    warnings
}

/// The record stage of [`calibrate_joints`]: the record of the calibrated chain (the URDF's
/// tip when the device is a URDF robot).
fn joint_record(
    plan: &Plan,
    device: &Device,
    fitted: &JointFit<'_>,
    report: &CalibrationReport,
    ranges: Vec<(f64, f64)>,
    n_training_rows: usize,
) -> hapcal_contract::Calibration {
    let chain = fitted.chain;
    let joint_names = chain.joint_names().to_vec();
    let prismatic: Vec<bool> = (hapcal_kinematics::joint_motions(std::slice::from_ref(chain)))
        .into_iter()
        .map(|m| m == Some(hapcal_kinematics::Motion::Translation))
        .collect();
    let is_urdf = plan
        .device
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
        || device.urdf.is_some();
    let tips = if is_urdf {
        vec![plan.tip.clone()]
    } else {
        Vec::new()
    };
    crate::record::measured_record(&crate::record::MeasuredRecord {
        model: report.model,
        tips: &tips,
        load_tips: &[],
        joint_names: &joint_names,
        prismatic: &prismatic,
        calibrated: fitted.model,
        parameters: &report.parameters,
        covariance: &fitted.identified.covariance,
        frames: &[],
        frame_values: &[],
        held: crate::record::held_values(fitted.identified),
        ranges,
        rows: n_training_rows,
    })
}

/// Extensions of the formats hapcal reads or writes: an output whose extension names one of
/// them but not the format written is refused by [`check_extension`].
const KNOWN_EXTENSIONS: [&str; 9] = [
    "toml", "urdf", "csv", "svg", "json", "yaml", "yml", "md", "xml",
];

/// Checks that `path` can take an output of a command that read `inputs`: its folder exists,
/// it is not a folder itself, and it is none of the inputs (compared canonicalized, so a link,
/// `./` or `..` does not hide an input). Commands call it before their work, so a bad output
/// path fails in a second rather than after the computation; [`write_new`] calls it again.
///
/// # Errors
/// Each refusal names the path: `cannot write <path>: <folder> does not exist`, `… is a
/// folder`, `… is an input of this command (<input>)`.
pub fn check_output(path: &Path, inputs: &[&Path]) -> Result<()> {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.exists() {
        bail!(
            "cannot write {}: {} does not exist",
            path.display(),
            folder.display()
        );
    }
    if !folder.is_dir() {
        bail!(
            "cannot write {}: {} is not a folder",
            path.display(),
            folder.display()
        );
    }
    if path.is_dir() {
        bail!("cannot write {}: it is a folder", path.display());
    }
    if let Ok(target) = path.canonicalize()
        && let Some(input) = (inputs.iter()).find(|i| i.canonicalize().is_ok_and(|i| i == target))
    {
        bail!(
            "cannot write {}: it is an input of this command ({}); write the output elsewhere",
            path.display(),
            input.display()
        );
    }
    Ok(())
}

/// Checks the extension of an output that is written as `what` in one of the formats
/// `allowed` (lowercase, without the dot). With `strict` (the format follows the extension),
/// any other extension, or none, is refused; otherwise only an extension naming another format
/// hapcal reads or writes (`log.toml` for a CSV log) is refused, and `.txt` or none passes.
///
/// # Errors
/// A mismatched extension, naming the path and the formats allowed.
pub fn check_extension(path: &Path, allowed: &[&str], what: &str, strict: bool) -> Result<()> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let ok = match &ext {
        Some(e) if allowed.contains(&e.as_str()) => true,
        Some(e) => !strict && !KNOWN_EXTENSIONS.contains(&e.as_str()),
        None => !strict,
    };
    if ok {
        return Ok(());
    }
    let allowed: Vec<String> = allowed.iter().map(|a| format!(".{a}")).collect();
    bail!(
        "cannot write {}: {what} is written as {}, not as {}",
        path.display(),
        allowed.join(" or "),
        ext.map_or_else(
            || "a file without extension".to_owned(),
            |e| format!(".{e}")
        )
    )
}

/// The error and its causes joined by `: `, as `{:#}` prints them, but without a cause whose
/// text the message before it already ends with: an error type that prints its source in its
/// own message (`cannot read <path>: <io error>`) would otherwise show it twice. The command
/// line and the Python package print errors with it, so both say the same.
pub fn error_chain(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if text.is_empty() {
            text = part;
        } else if !text.ends_with(&part) {
            text.push_str(": ");
            text.push_str(&part);
        }
    }
    text
}

/// `Err` when one file or folder is given twice among `plan`'s training and test data (by
/// path, or as byte-identical files): held-out data that are the training data measure
/// nothing, and a training file given twice counts every row twice (every σ shrinks by √2).
///
/// # Errors
/// Naming both arguments.
pub fn check_distinct_inputs(plan: &Plan) -> Result<()> {
    let named: Vec<(&str, &PathBuf)> = (plan.data.iter().map(|p| ("--data", p)))
        .chain(plan.test.iter().map(|p| ("--test", p)))
        .collect();
    let key = |p: &Path| -> Option<(PathBuf, Option<Vec<u8>>)> {
        let canonical = p.canonicalize().ok()?;
        let bytes = if canonical.is_file() {
            std::fs::read(&canonical).ok()
        } else {
            None
        };
        Some((canonical, bytes))
    };
    let keys: Vec<_> = named.iter().map(|(_, p)| key(p)).collect();
    for b in 0..named.len() {
        for a in 0..b {
            let (Some((pa, ba)), Some((pb, bb))) = (&keys[a], &keys[b]) else {
                continue;
            };
            let same_file = pa == pb;
            let same_bytes = ba.is_some() && ba == bb;
            if same_file || same_bytes {
                let how = if same_file {
                    "the same file"
                } else {
                    "byte-identical files"
                };
                bail!(
                    "{} {} and {} {} are {how}: {}",
                    named[a].0,
                    named[a].1.display(),
                    named[b].0,
                    named[b].1.display(),
                    match (named[a].0, named[b].0) {
                        ("--data", "--data") => {
                            "every row would count twice and every σ shrink by √2"
                        }
                        ("--test", "--test") => "the held-out rows would count twice",
                        _ => "held-out data must not be training data",
                    }
                );
            }
        }
    }
    Ok(())
}

/// `Err` naming the first of `plan`'s measurement-file options that was given, for a kind of
/// data (`what`) that does not use them.
fn refuse_options(plan: &Plan, what: &str) -> Result<()> {
    for (option, given) in [
        ("--sigma-m", plan.sigma_m.is_some()),
        ("--sigma-rad", plan.sigma_rad.is_some()),
        ("--test-last", plan.test_last.is_some()),
    ] {
        if given {
            bail!("{option} does not apply to {what}");
        }
    }
    Ok(())
}

/// Writes `text` to `path` atomically (a sibling temporary file renamed over it, so a reader
/// never sees half a file and a failed write leaves any earlier file intact), after
/// [`check_output`]: never over one of `inputs`, every error naming `path`. A path that is not
/// a regular file (`/dev/null`, `/dev/stdout`, a named pipe) is written through, never
/// replaced: a rename would put a regular file in the device's place.
///
/// # Errors
/// What [`check_output`] refuses, or an I/O error (`cannot write <path>: …`, e.g. `No space
/// left on device` for `/dev/full`).
pub fn write_new(path: &Path, text: &str, inputs: &[&Path]) -> Result<()> {
    check_output(path, inputs)?;
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        use std::io::Write;
        return std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .and_then(|mut f| {
                f.write_all(text.as_bytes())?;
                f.flush()
            })
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()));
    }
    let name = path.file_name().map_or_else(
        || std::ffi::OsString::from("output"),
        std::ffi::OsStr::to_os_string,
    );
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(&name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    if let Err(e) = std::fs::write(&tmp, text) {
        let _ = std::fs::remove_file(&tmp);
        bail!("cannot write {}: {e}", path.display());
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        anyhow::anyhow!("cannot write {}: {e}", path.display())
    })
}

/// Writes the calibrated device: a `.urdf` path gets a copy of the source URDF with the
/// calibrated joint origins; a `.toml` path a device TOML with a `[calibration]` table (any
/// other extension is refused). With
/// marker frames or values a URDF cannot hold (compliance, harmonics), `<out>.calibration.toml`
/// beside it. The files are read back first as `predict` reads them ([`check_written`]), and
/// nothing is written unless they give the calibration's own marker positions. Files are
/// written atomically. Returns the paths written.
///
/// # Errors
/// A `.urdf` output for a device that did not come from a URDF, an output that is neither
/// `.toml` nor `.urdf`, an output path that is the device file or its source URDF, files that
/// do not give the calibration ([`check_written`]), or an I/O error.
pub fn write_outputs(outcome: &Outcome, out: &Path) -> Result<Vec<PathBuf>> {
    write_outputs_beside(outcome, out, &[])
}

/// Checks the outputs of a calibration before it runs: `out` must end in `.toml` or `.urdf`
/// (the format follows the extension), and neither it nor its `<out>.calibration.toml`
/// sidecar may be the `device` or one of `inputs` (data and test files), or sit in a missing
/// folder.
///
/// # Errors
/// The first refusal, naming the path.
pub fn check_outputs(device: &Path, out: &Path, inputs: &[&Path]) -> Result<()> {
    check_extension(out, &["toml", "urdf"], "the calibrated device", true)?;
    let mut all: Vec<&Path> = vec![device];
    all.extend_from_slice(inputs);
    check_output(out, &all)?;
    check_output(&out.with_extension("calibration.toml"), &all)
}

/// [`write_outputs`], refusing also to write over one of `inputs` (the data and test files
/// the calibration read; the device and its source URDF are always refused). The files are
/// read back first ([`check_written`]).
///
/// # Errors
/// As [`write_outputs`], and an output path that is one of `inputs`.
pub fn write_outputs_beside(
    outcome: &Outcome,
    out: &Path,
    inputs: &[&Path],
) -> Result<Vec<PathBuf>> {
    check_outputs(&outcome.device_path, out, inputs)?;
    let urdf_source = source_urdf(outcome);
    let mut inputs: Vec<&Path> = inputs.to_vec();
    inputs.push(&outcome.device_path);
    inputs.extend(urdf_source.as_deref());
    let files = output_files(outcome, out)?;
    write_all(outcome, files, &inputs)
}

/// Writes `files` (path, text; the calibrated URDF or device file first, then the sidecar)
/// once they give the calibration ([`check_written`]): nothing is written otherwise. Returns
/// the paths written.
fn write_all(
    outcome: &Outcome,
    files: Vec<(PathBuf, String)>,
    inputs: &[&Path],
) -> Result<Vec<PathBuf>> {
    check_written(outcome, &files)?;
    for (path, text) in &files {
        write_new(path, text, inputs)?;
    }
    Ok(files.into_iter().map(|(p, _)| p).collect())
}

/// The unit of `model`'s compliances: rad/(N·m) under link masses, rad/m under the lumped
/// unit weights (also for a model without compliance).
fn compliance_unit_of(model: &hapcal_problems::CalibratedModel) -> &'static str {
    match &model.compliance {
        Some((g, _)) if !g.masses.is_empty() => "rad/(N·m)",
        _ => "rad/m",
    }
}

/// Whether the files a calibration is about to write (`files`, `output_files`) give its
/// calibration: their robot as the runtime loads it ([`runtime_robot_of`]) against the
/// calibration's own prediction ([`check_reproduced`]); nothing is checked where the runtime
/// reads no robot from them. A haptic device's file needs no check here: its report's figures
/// are already the runtime's evaluation of this text, checked row by row against the
/// calibration's model ([`crate::haptic::calibrate_logs`]).
///
/// # Errors
/// Files the runtime refuses, or markers farther from the calibration's prediction than
/// [`REPRODUCTION_TOLERANCE_M`].
pub fn check_written(outcome: &Outcome, files: &[(PathBuf, String)]) -> Result<()> {
    match runtime_robot_of(outcome, files)? {
        Some(robot) => check_reproduced(outcome, &robot),
        None => Ok(()),
    }
}

/// Largest distance, m, between a marker position the calibration predicts and the one its
/// written files give ([`check_reproduced`]): both evaluate the same equations in double
/// precision (they agree to 10⁻¹² m on every model of the round-trip tests), so a micrometre,
/// far below any instrument's noise, is a difference of model, never of rounding.
pub const REPRODUCTION_TOLERANCE_M: f64 = 1e-6;

/// Whether the written files reproduce the calibration: at every row of every data set the
/// report lists (training and test), each marker's position as the calibrated model predicts
/// it (`Outcome::model`, m, in the instrument frame) and as `robot`, the runtime's robot of
/// the files about to be written ([`runtime_robot_of`]), gives it
/// ([`crate::predict::MarkerPoses`], as `hapcal predict` and the report's calibrated figures
/// evaluate it), within [`REPRODUCTION_TOLERANCE_M`]. A calibration whose torque equilibrium
/// the deflection does not reach is not compared (its finding,
/// [`ImplausibleKind::NoEquilibrium`](crate::report::ImplausibleKind::NoEquilibrium), is the
/// stop): the fixed-point iteration amplifies rounding, so its prediction is not a function
/// of its values to any tolerance (on the simulated z-axes humanoid with its compliances
/// ×100, changing one compliance by 10⁻¹³ of itself moves a marker by up to 1 m), and a
/// difference would blame the files for what the finding names.
///
/// # Errors
/// A marker farther than the tolerance (the worst one named with its set, line and both
/// positions), or a reading the runtime refuses.
pub fn check_reproduced(outcome: &Outcome, robot: &hapcal_runtime::Robot) -> Result<()> {
    let no_equilibrium = (outcome.report.implausible.iter())
        .any(|i| i.kind == crate::report::ImplausibleKind::NoEquilibrium);
    if no_equilibrium {
        return Ok(());
    }
    let mut markers = crate::predict::MarkerPoses::new(robot)?;
    // (distance, set, line, marker)
    let mut worst: Option<(f64, &str, u64, usize)> = None;
    for set in &outcome.report.placements {
        let Some(errors) = &set.errors else {
            continue;
        };
        let rows = (errors.rows.iter()).filter(|r| !r.markers.is_empty());
        for row in rows {
            let from_files = markers.at(&row.q, &row.markers)?;
            let fitted = outcome.model.end_poses_of(&row.markers, &row.q);
            for ((pose, p), &m) in fitted.iter().zip(from_files).zip(&row.markers) {
                let d = (pose.translation.vector - p.translation.vector).norm();
                if worst.is_none_or(|w| d > w.0 || !d.is_finite()) {
                    worst = Some((d, &set.name, row.line, m));
                }
            }
        }
    }
    match worst {
        Some((d, set, line, m)) if d.is_nan() || d > REPRODUCTION_TOLERANCE_M => bail!(
            "the files calibrate would write do not give its calibration: at line {line} of {set}, \
             marker {} lies {:.3} mm from the calibration's prediction when the written URDF and \
             record are evaluated as hapcal predict evaluates them; nothing was written (the \
             estimate is likely one no real robot has: check the setup findings, or give a \
             simpler --model)",
            m + 1,
            d * 1e3
        ),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::{HeldOut, ModelName, blocked_difference, fold_of};
    use crate::fit::choose;

    /// Held-out errors on 10 blocks of 5 rows: `base` everywhere, minus `gain` in every block,
    /// with ±`spread` alternating between blocks (the block-to-block scatter of the gain).
    fn held(base: f64, gain: f64, spread: f64) -> HeldOut {
        HeldOut {
            sq_errors: (0..50)
                .map(|i| {
                    let sign = if (i / 5) % 2 == 0 { 1.0 } else { -1.0 };
                    base - gain + sign * spread
                })
                .collect(),
            block: (0..50).map(|i| i / 5).collect(),
        }
    }

    #[test]
    fn a_candidate_must_beat_the_geometric_model_by_the_margin() {
        use ModelName::{ActuatorCompliance, Compliance, Geometric, MassCompliance};
        let geometric = held(10.0, 0.0, 0.0);
        // Block scatter ±1 over 10 blocks: standard error 1/3 (sample SD 1.054, /√10).
        // A gain of 0.2 is 0.6 SE (not enough), 0.6 is 1.8 SE (not enough at 2 SE), 0.8 is
        // 2.4 SE and 0.9 is 2.7 SE (enough).
        let candidates = [Geometric, Compliance, MassCompliance, ActuatorCompliance];
        let level = [0, 1, 1, 1];
        let sets = [
            geometric.clone(),
            held(10.0, 0.6, 1.0),
            held(10.0, 0.8, 1.0),
            held(10.0, 0.9, 1.0),
        ];
        let (choice, reports) = choose(&candidates, &level, &sets);
        let beats: Vec<bool> = reports.iter().map(|r| r.beats_geometric).collect();
        assert_eq!(beats, [false, false, true, true]);
        // Among the alternatives of a level that pass, the lowest held-out RMS.
        assert_eq!(choice, ActuatorCompliance);
        let (choice, _) = choose(&candidates[..3], &level[..3], &sets[..3]);
        assert_eq!(choice, MassCompliance);
        // Only a gain inside the margin: the geometric model stays.
        let (choice, _) = choose(&candidates[..2], &level[..2], &sets[..2]);
        assert_eq!(choice, Geometric);
        // A small gain without block scatter is decisive.
        let (choice, _) = choose(
            &candidates[..2],
            &level[..2],
            &[geometric, held(10.0, 0.2, 0.0)],
        );
        assert_eq!(choice, Compliance);
    }

    #[test]
    fn every_repeat_holds_each_row_out_once_in_contiguous_blocks() {
        let (n, k, repeats) = (31, 5, 3);
        for r in 0..repeats {
            let folds: Vec<usize> = (0..n).map(|row| fold_of(row, n, k, r, repeats)).collect();
            let mut sizes = vec![0; k];
            for &f in &folds {
                sizes[f] += 1;
            }
            // Equal blocks up to one row.
            assert!(sizes.iter().all(|&s| s == 6 || s == 7), "{sizes:?}");
            // Contiguous up to the circular wrap: the fold changes k times around the circle.
            let changes = (0..n).filter(|&i| folds[i] != folds[(i + 1) % n]).count();
            assert_eq!(changes, k, "repeat {r}: {folds:?}");
        }
        // Repeat 0 is plain k-fold; the others shift the boundaries.
        assert_eq!(fold_of(0, n, k, 0, repeats), 0);
        assert_eq!(fold_of(n - 1, n, k, 0, repeats), k - 1);
        assert_ne!(fold_of(6, n, k, 1, repeats), fold_of(6, n, k, 0, repeats));
    }

    #[test]
    fn blocked_standard_error_counts_blocks_not_rows() {
        // Two blocks of 50 rows, differences −2 in one and 0 in the other: per block the mean
        // differences are −2 and 0, so the mean is −1 with standard error 1 (two blocks, sample
        // SD √2, /√2). Counting the 100 rows as independent would give ≈ 0.1.
        let block: Vec<usize> = (0..100).map(|i| i / 50).collect();
        let a = HeldOut {
            sq_errors: (0..100).map(|i| if i < 50 { 1.0 } else { 3.0 }).collect(),
            block: block.clone(),
        };
        let b = HeldOut {
            sq_errors: vec![3.0; 100],
            block,
        };
        let (mean, se) = blocked_difference(&a, &b);
        assert!((mean + 1.0).abs() < 1e-12, "{mean}");
        assert!((se - 1.0).abs() < 1e-12, "{se}");
        // One block: no standard error.
        let one = HeldOut {
            sq_errors: vec![1.0; 4],
            block: vec![0; 4],
        };
        assert_eq!(blocked_difference(&one, &one).1, f64::INFINITY);
    }
}
