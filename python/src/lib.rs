//! Python bindings of hapcal (`hapcal._hapcal`): devices, measurements (files or arrays), the
//! calibration of `hapcal-calibrate`, and the `simulate`, `plan-poses`, `diagnose`, `check` and
//! `import-urdf` workflows (`hapcal-sim`, `hapcal_calibrate::plan`, `hapcal-diagnose`,
//! `hapcal_calibrate::setup`, `hapcal_io::import_urdf_tree`). The Python package `hapcal`
//! (python/hapcal) wraps this module with NumPy / pandas conveniences; everything numeric
//! happens here, in the same library functions the `hapcal` command line calls.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use hapcal_calibrate::calibrate::{self, ModelChoice, Outcome, Plan};
use hapcal_calibrate::measured::{self, Robot};
use hapcal_calibrate::setup::Gated;
use hapcal_io::{
    AngleUnit, JOINT_LIMIT_SLACK, LengthUnit, MarkerSample, MeasuredRow, MeasurementTable, Units,
};
use nalgebra::UnitQuaternion;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

mod measurements;
mod runtime;
use measurements::*;
use runtime::*;

create_exception!(
    hapcal,
    HapcalError,
    PyValueError,
    "An error reported by hapcal: unreadable or inconsistent input, or data that cannot determine the model. The message is the whole chain of causes (file:line:column where there is one)."
);

/// The anyhow chain as one message (`outer: inner: …`), as the command line prints it.
fn py_err(e: anyhow::Error) -> PyErr {
    HapcalError::new_err(hapcal_calibrate::calibrate::error_chain(&e))
}

fn units(length_unit: &str, angle_unit: &str) -> Result<Units> {
    let length: LengthUnit = length_unit
        .parse()
        .map_err(|e: String| anyhow!("length_unit: {e}"))?;
    let angle: AngleUnit = angle_unit
        .parse()
        .map_err(|e: String| anyhow!("angle_unit: {e}"))?;
    Ok(Units::new(length, angle))
}

/// The column edits of a measurement file, as the command line's `--column-unit`,
/// `--column-sign`, `--column-offset`, `--column-scale` and `--column-coupling` give them, each
/// in the dict's (list's) order: `units` `{"q3": "deg", "x2,y2,z2": "mm"}`, `signs`
/// `["q3"]`, `offsets` `{"q2": -1.5708}` (rad, m for a length), `scales` `{"q3": 0.01}`,
/// `couplings` `{"q6": "-0.5*q5"}`.
#[derive(Default)]
struct ColumnArgs {
    units: Option<Vec<(String, String)>>,
    signs: Option<Vec<String>>,
    offsets: Option<Vec<(String, f64)>>,
    scales: Option<Vec<(String, f64)>>,
    couplings: Option<Vec<(String, String)>>,
}

/// `units` with the edits of `args` ([`ColumnArgs`]), parsed as the command line parses its
/// options.
///
/// # Errors
/// A value the option's parser refuses, named with the Python argument.
fn with_column_edits(units: Units, args: ColumnArgs) -> Result<Units> {
    use hapcal_io::ColumnEdit;
    type Parse = fn(&str) -> std::result::Result<ColumnEdit, String>;
    let pairs = |v: Option<Vec<(String, String)>>| {
        (v.unwrap_or_default().into_iter())
            .map(|(c, x)| format!("{c}={x}"))
            .collect()
    };
    let numbers = |v: Option<Vec<(String, f64)>>| {
        (v.unwrap_or_default().into_iter())
            .map(|(c, x)| format!("{c}={x:?}"))
            .collect()
    };
    // Each argument, its option's parser, and its values as the option's text.
    let options: [(&str, Parse, Vec<String>); 5] = [
        ("column_units", ColumnEdit::parse_unit, pairs(args.units)),
        (
            "column_signs",
            ColumnEdit::parse_sign,
            args.signs.unwrap_or_default(),
        ),
        (
            "column_offsets",
            ColumnEdit::parse_offset,
            numbers(args.offsets),
        ),
        (
            "column_scales",
            ColumnEdit::parse_scale,
            numbers(args.scales),
        ),
        (
            "column_couplings",
            ColumnEdit::parse_coupling,
            pairs(args.couplings),
        ),
    ];
    let mut edits = Vec::new();
    for (argument, parse, values) in options {
        for value in values {
            edits.push(parse(&value).map_err(|e| anyhow!("{argument}: {e}"))?);
        }
    }
    Ok(units.with_columns(edits))
}

/// A device: a URDF with one or more tip links, or a hapcal device file (TOML).
#[pyclass(module = "hapcal", name = "Device", frozen)]
struct PyDevice {
    path: PathBuf,
    tip: String,
    tips: Vec<String>,
    device: hapcal_io::Device,
    /// The robot of the marker workflow, or why there is none (a haptic device's chain).
    robot: std::result::Result<Robot, String>,
}

impl PyDevice {
    fn is_urdf(path: &Path) -> bool {
        path.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
    }
}

#[pymethods]
impl PyDevice {
    /// Reads a serial URDF whose tool sits on link `tip`; `tips` names further tip links of a
    /// tree (marker k+1 sits on the k-th of `[tip, *tips]`; markers past the last on the last).
    ///
    /// Raises HapcalError for an unreadable URDF or an unknown link.
    #[staticmethod]
    #[pyo3(signature = (path, tip, tips = None))]
    fn from_urdf(path: PathBuf, tip: String, tips: Option<Vec<String>>) -> PyResult<Self> {
        let tips = tips.unwrap_or_default();
        let device = calibrate::load_device(&path, &tip).map_err(py_err)?;
        let all: Vec<String> = std::iter::once(tip.clone())
            .chain(tips.iter().cloned())
            .collect();
        let robot = measured::robot_from_urdf(&path, &all).map_err(py_err)?;
        Ok(Self {
            path,
            tip,
            tips,
            device,
            robot: Ok(robot),
        })
    }

    /// Reads a hapcal device file (TOML): a D-H / modified D-H table, URDF placements, or a
    /// capstan-driven haptic device with its transmissions.
    ///
    /// Raises HapcalError for an unreadable or invalid file (file:line:column).
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Self> {
        if Self::is_urdf(&path) {
            return Err(py_err(anyhow!(
                "{}: a URDF: use Device.from_urdf(path, tip=...)",
                path.display()
            )));
        }
        let device = calibrate::load_device(&path, "").map_err(py_err)?;
        let robot = measured::robot_from_device(&device).map_err(|e| calibrate::error_chain(&e));
        Ok(Self {
            path,
            tip: String::new(),
            tips: Vec::new(),
            device,
            robot,
        })
    }

    /// Joint names in chain order: the columns `q1..qn` of a measurement table, in order.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        match &self.robot {
            Ok(r) => r.joint_names.clone(),
            Err(_) => self.device.joints.iter().map(|j| j.name.clone()).collect(),
        }
    }

    /// Number of joints.
    #[getter]
    fn n_joints(&self) -> usize {
        self.joint_names().len()
    }

    /// Joint limits `(lower, upper)` per joint, rad (m for a prismatic joint).
    #[getter]
    fn joint_limits(&self) -> Vec<(f64, f64)> {
        match &self.robot {
            Ok(r) => r.limits.clone(),
            Err(_) => self.device.joint_limits(),
        }
    }

    /// The file the device was read from.
    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }

    /// Tip links (`[tip, *tips]`; empty for a device file).
    #[getter]
    fn tips(&self) -> Vec<String> {
        if self.tip.is_empty() {
            return Vec::new();
        }
        std::iter::once(self.tip.clone())
            .chain(self.tips.iter().cloned())
            .collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "Device({:?}, joints={:?})",
            self.path.display().to_string(),
            self.joint_names()
        )
    }
}

/// The result of one calibration.
#[pyclass(module = "hapcal._hapcal", name = "_Calibration", frozen)]
struct PyCalibration {
    outcome: Outcome,
    json: String,
    /// The setup check's warnings (the command line prints them on standard error).
    setup_warnings: Vec<String>,
}

#[pymethods]
impl PyCalibration {
    /// The setup check's warnings, as the command line prints them (without its prefix).
    #[getter]
    fn setup_warnings(&self) -> Vec<String> {
        self.setup_warnings.clone()
    }

    /// The report as the command line prints it with `--json`.
    fn to_json(&self) -> String {
        self.json.clone()
    }

    /// Writes the calibrated device (`write_outputs`: the files read back first with the runtime,
    /// nothing written unless they give the calibration); returns the paths written.
    fn write_outputs(&self, py: Python<'_>, path: PathBuf) -> PyResult<Vec<PathBuf>> {
        let outcome = &self.outcome;
        py.detach(|| calibrate::write_outputs(outcome, &path))
            .map_err(py_err)
    }

    /// The calibration library's predicted positions at the joint readings `q` (one row per
    /// configuration, the device's joints in order; rad, m for a prismatic joint), m: per row
    /// and marker of a robot, the position in the instrument frame from the calibrated model
    /// the report's errors come from (`CalibratedModel::end_poses_of`, marker k on tip
    /// min(k, last)); per row of a haptic device, its end point (the readings through the
    /// identified transmissions and handle compliance; `DistanceLogModel`'s points).
    fn predicted_positions(
        &self,
        py: Python<'_>,
        q: Vec<Vec<f64>>,
    ) -> PyResult<Vec<Vec<[f64; 3]>>> {
        let outcome = &self.outcome;
        py.detach(|| library_positions(outcome, &q)).map_err(py_err)
    }
}

/// [`PyCalibration::predicted_positions`].
fn library_positions(outcome: &Outcome, q: &[Vec<f64>]) -> Result<Vec<Vec<[f64; 3]>>> {
    let model = &outcome.model;
    let n_joints = model.chain.n_joints();
    for (i, row) in q.iter().enumerate() {
        if row.len() != n_joints {
            bail!(
                "q: row {i} has {} values, expected {n_joints} (one per joint of the device)",
                row.len()
            );
        }
        if let Some(j) = row.iter().position(|v| !v.is_finite()) {
            bail!("q: row {i}, joint {j}: {} is not a finite number", row[j]);
        }
    }
    let device = &outcome.device;
    let haptic = device.has_transmissions();
    if let (true, Some(calibrated)) = (haptic, &outcome.calibrated) {
        use hapcal_calibrate::haptic;
        let nominal = haptic::HapticDevice::new(device.clone())?;
        let mut state = haptic::calibrated_log_state(calibrated)?;
        state.x_kin.clone_from(&model.x_kin);
        let rows: Vec<hapcal_io::LogRow> = (q.iter())
            .map(|q| hapcal_io::LogRow {
                q: q.clone(),
                distance_m: 0.0,
                ext: vec![None; hapcal_io::N_EXT],
                t_s: None,
                line: 0,
            })
            .collect();
        let log = haptic::log_model(&nominal, &rows, Vec::new()).context(
            "the positions of a haptic device come from its distance-log model, which needs the \
             device file's [handle] mass",
        )?;
        let lin = log.linearise(&state)?;
        return Ok((lin.points.iter()).map(|p| vec![[p.x, p.y, p.z]]).collect());
    }
    let tips: Vec<usize> = (0..model.tips.len().max(1)).collect();
    Ok((q.iter())
        .map(|row| {
            (model.end_poses_of(&tips, row).iter())
                .map(|p| {
                    let t = p.translation.vector;
                    [t.x, t.y, t.z]
                })
                .collect()
        })
        .collect())
}

/// The names of every model, as the command line's `--model` takes them (`ModelChoice`).
fn model_names() -> Vec<String> {
    ModelChoice::all()
        .iter()
        .map(|m| m.name().to_owned())
        .collect()
}

fn model_choice(model: &str) -> Result<ModelChoice> {
    ModelChoice::from_name(model).ok_or_else(|| {
        anyhow!(
            "model: expected one of {}, found {model:?}",
            model_names().join(", ")
        )
    })
}

/// The measurement tables of `sources` for `robot`: files through the command line's loader
/// (`measured::load_tables`), arrays as they are.
fn load_sources(sources: &[Source], robot: &Robot) -> Result<Vec<MeasurementTable>> {
    let mut out = Vec::new();
    for s in sources {
        match s {
            Source::Path { path, units } => out.extend(measured::load_tables(
                std::slice::from_ref(path),
                robot,
                units,
            )?),
            Source::Arrays(a) => out.push(table(a, robot)?),
        }
    }
    Ok(out)
}

/// The setup check before a calibration or diagnosis of files, as the command line's
/// (`hapcal_calibrate::setup::gate`, its messages naming `accept_setup=True`).
fn setup_gate(plan: &Plan, accept_setup: bool) -> Result<Gated> {
    let cfg = hapcal_calibrate::setup::SetupConfig {
        accept_setup,
        accept_option: "accept_setup=True",
    };
    hapcal_calibrate::setup::gate(plan, &cfg)
}

/// The paths and units of `sources`, if every one is a file.
fn file_sources(sources: &[Source]) -> Option<Vec<(PathBuf, Units)>> {
    sources
        .iter()
        .map(|s| match s {
            Source::Path { path, units } => Some((path.clone(), units.clone())),
            Source::Arrays(_) => None,
        })
        .collect()
}

/// A plan for `device` without data or test files (each call fills them in once it knows
/// their units), with [`Plan::bundled_default`]'s settings otherwise: SI units, gravity down,
/// sockets 0.05 m apart, the model chosen by cross-validation.
fn device_plan(device: &PyDevice) -> Plan {
    Plan {
        device: device.path.clone(),
        tip: device.tip.clone(),
        tips: device.tips.clone(),
        data: Vec::new(),
        test: Vec::new(),
        ..Plan::bundled_default()
    }
}

/// Calibrates `device` from `train` (`test` only evaluated). See `hapcal.calibrate`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (device, train, test, model, sigma_m, sigma_rad, test_last, folds, socket_distance_m, joint, accept_setup))]
fn _calibrate(
    py: Python<'_>,
    device: &PyDevice,
    train: Vec<PyRef<'_, PyMeasurements>>,
    test: Vec<PyRef<'_, PyMeasurements>>,
    model: &str,
    sigma_m: Option<f64>,
    sigma_rad: Option<f64>,
    test_last: Option<f64>,
    folds: usize,
    socket_distance_m: f64,
    joint: bool,
    accept_setup: bool,
) -> PyResult<PyCalibration> {
    let model = model_choice(model).map_err(py_err)?;
    if train.is_empty() {
        return Err(py_err(anyhow!("no training measurements")));
    }
    let train: Vec<Source> = train.iter().map(|m| m.source.clone()).collect();
    let test: Vec<Source> = test.iter().map(|m| m.source.clone()).collect();
    let mut plan = Plan {
        sigma_rad,
        test_last,
        socket_distance_m,
        model,
        folds,
        sigma_m,
        joint,
        ..device_plan(device)
    };
    // Files that share their units go through `calibrate::run`, exactly as the command line.
    // The setup check runs on files, as the command line's (arrays are taken as given).
    let files = file_sources(&train).zip(file_sources(&test));
    let mut setup_warnings = Vec::new();
    let mut setup_classes = Vec::new();
    let outcome = match files {
        Some((tr, te)) if tr.iter().chain(&te).all(|(_, u)| *u == tr[0].1) => {
            plan.units = tr[0].1.clone();
            plan.data = tr.into_iter().map(|(p, _)| p).collect();
            plan.test = te.into_iter().map(|(p, _)| p).collect();
            py.detach(|| -> Result<Outcome> {
                plan.validate()?;
                let gated = setup_gate(&plan, accept_setup)?;
                (setup_warnings, setup_classes) = (gated.warnings, gated.classes);
                calibrate::run(&plan)
            })
        }
        _ => {
            let hapcal_device = &device.device;
            let robot = device.robot.as_ref();
            py.detach(|| -> Result<Outcome> {
                let start = Instant::now();
                if hapcal_device.has_transmissions() {
                    bail!(
                        "{}: a haptic device with transmissions is calibrated from its log files (Measurements.from_csv); arrays hold marker or distance measurements of an external instrument",
                        plan.device.display()
                    );
                }
                let robot = robot.map_err(|e| anyhow!("{e}"))?;
                let train = load_sources(&train, robot)?;
                let test = load_sources(&test, robot)?;
                measured::run_tables(&plan, hapcal_device, robot, train, test, start)
            })
        }
    }
    .map_err(py_err)?;
    // After the fit, as the command line: deviations no real device has say the data are
    // another's (an error unless accepted, then a warning).
    let after_fit = hapcal_calibrate::setup::SetupConfig {
        accept_setup,
        accept_option: "accept_setup=True",
    };
    setup_warnings.extend(
        hapcal_calibrate::setup::gate_after_fit(&outcome.report, &after_fit, &setup_classes)
            .map_err(py_err)?,
    );
    let json = serde_json::to_string_pretty(&outcome.report)
        .context("serialising the report")
        .map_err(py_err)?;
    Ok(PyCalibration {
        outcome,
        json,
        setup_warnings,
    })
}

/// The log columns of `rows` as `hapcal_io::write_log` writes them: `q1..qn`, `distance_m`,
/// the `ext1..ext4` present in any row (NaN where a row has none), `t_s` if any row has one.
/// Returns the column names and the values, column-major.
fn log_columns(rows: &[hapcal_io::LogRow]) -> (Vec<String>, Vec<Vec<f64>>) {
    let n_joints = rows.first().map_or(0, |r| r.q.len());
    let mut names: Vec<String> = (1..=n_joints).map(|j| format!("q{j}")).collect();
    let mut columns: Vec<Vec<f64>> = (0..n_joints)
        .map(|j| rows.iter().map(|r| r.q[j]).collect())
        .collect();
    names.push("distance_m".to_owned());
    columns.push(rows.iter().map(|r| r.distance_m).collect());
    for k in 0..hapcal_io::N_EXT {
        let cell = |r: &hapcal_io::LogRow| r.ext.get(k).copied().flatten();
        if rows.iter().any(|r| cell(r).is_some()) {
            names.push(format!("ext{}", k + 1));
            columns.push(rows.iter().map(|r| cell(r).unwrap_or(f64::NAN)).collect());
        }
    }
    if rows.iter().any(|r| r.t_s.is_some()) {
        names.push("t_s".to_owned());
        columns.push(rows.iter().map(|r| r.t_s.unwrap_or(f64::NAN)).collect());
    }
    (names, columns)
}

/// Simulates a log from a truth device, as `hapcal simulate` does (the same `hapcal_sim`
/// calls); writes it to `path` (atomically, never over an input) when given. Returns the log's
/// columns. See `hapcal.simulate`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (truth, device, seed, poses, noise, effects, motion, period_s, path))]
fn _simulate(
    py: Python<'_>,
    truth: Option<PathBuf>,
    device: Option<PathBuf>,
    seed: u64,
    poses: usize,
    noise: String,
    effects: Vec<String>,
    motion: bool,
    period_s: f64,
    path: Option<PathBuf>,
) -> PyResult<(Vec<String>, Vec<Vec<f64>>)> {
    py.detach(move || -> Result<(Vec<String>, Vec<Vec<f64>>)> {
        if poses < 1 {
            bail!("poses: must be at least 1, got {poses}");
        }
        let mut inputs: Vec<PathBuf> = device.iter().chain(&truth).cloned().collect();
        if let Some(t) = (truth.as_ref()).and_then(|t| Some((t, hapcal_sim::read_truth(t).ok()?))) {
            inputs.push(t.1.device_path(t.0));
        }
        let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
        if let Some(out) = &path {
            calibrate::check_extension(out, &["csv"], "the simulated log", false)?;
            calibrate::check_output(out, &inputs)?;
        }
        let (device, truth) = match (device, truth) {
            (device, Some(truth_path)) => {
                let truth = hapcal_sim::read_truth(&truth_path)?;
                let device = match device {
                    Some(d) => hapcal_io::read_device(&d)?,
                    None => truth.read_device(&truth_path)?,
                };
                (device, truth)
            }
            (device, None) => {
                let path = device.unwrap_or_else(|| {
                    hapcal_calibrate::project_root().join("fixtures/reference-device/device.toml")
                });
                let device = hapcal_io::read_device(&path)?;
                let truth = hapcal_sim::Truth::nominal(path, &device);
                (device, truth)
            }
        };
        let Some(cable) = device.cable_encoder.as_ref() else {
            bail!("the device has no [cable_encoder]: nothing to simulate the distance with");
        };
        let noise = match noise.as_str() {
            "paper" => hapcal_sim::NoiseModel::paper(cable),
            "arc-length" => hapcal_sim::NoiseModel::arc_length(cable),
            other => bail!("noise must be `paper` or `arc-length`, got {other:?}"),
        };
        let cfg = hapcal_sim::SimConfig::new(seed, poses).with_noise(noise);
        let effects = (effects.iter())
            .map(|e| e.parse::<hapcal_sim::Injected>())
            .collect::<Result<Vec<_>, _>>()?;
        let rows = if motion || !effects.is_empty() {
            let motion = hapcal_sim::MotionConfig {
                sample_period_s: period_s,
            };
            hapcal_sim::simulate_motion(&device, &truth, &cfg, &motion, &effects)?
        } else {
            hapcal_sim::simulate(&device, &truth, &cfg)?
        };
        if let Some(out) = &path {
            calibrate::write_new(out, &hapcal_io::write_log(&rows), &inputs)?;
        }
        Ok(log_columns(&rows))
    })
    .map_err(py_err)
}

/// Chooses the poses to measure, as `hapcal plan-poses` does (`plan::plan_poses`); writes
/// them to `path` (`plan::poses_csv`, atomically) when given. Returns the joint names and the
/// readings (rad, one row per pose). See `hapcal.plan_poses`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (device, measurement, count, candidates, seed, criterion, sigma_m, separate_transmission_run, refine, path, model))]
fn _plan_poses(
    py: Python<'_>,
    device: &PyDevice,
    measurement: &str,
    count: usize,
    candidates: usize,
    seed: u64,
    criterion: &str,
    sigma_m: Option<f64>,
    separate_transmission_run: bool,
    refine: bool,
    path: Option<PathBuf>,
    model: &str,
) -> PyResult<(Vec<String>, Vec<Vec<f64>>)> {
    use clap::ValueEnum;
    use hapcal_calibrate::plan::{self, Measurement, PlanConfig};
    let hapcal_device = &device.device;
    let device_path = device.path.as_path();
    py.detach(move || -> Result<(Vec<String>, Vec<Vec<f64>>)> {
        let measurement = Measurement::from_str(measurement, false).map_err(|_| {
            anyhow!("measurement: expected distance or position, found {measurement:?}")
        })?;
        let criterion: hapcal_identify::Criterion = criterion
            .parse()
            .map_err(|e: String| anyhow!("criterion: {e}"))?;
        if let Some(s) = sigma_m
            && !(s.is_finite() && s > 0.0)
        {
            bail!("sigma_m must be a positive length, got {s}");
        }
        if let Some(out) = &path {
            calibrate::check_extension(out, &["csv"], "the planned poses", false)?;
            calibrate::check_output(out, &[device_path])?;
        }
        let cfg = PlanConfig {
            measurement,
            count,
            n_candidates: candidates,
            seed,
            criterion,
            sigma_m,
            transmission_rows: !separate_transmission_run,
            refine,
            model: model_choice(model)?,
        };
        let planned = plan::plan_poses(hapcal_device, &cfg)?;
        let names: Vec<String> = hapcal_device
            .chain()?
            .joint_names()
            .iter()
            .map(|n| n.to_string())
            .collect();
        if let Some(out) = &path {
            calibrate::write_new(
                out,
                &plan::poses_csv(&names, &planned.readings),
                &[device_path],
            )?;
        }
        Ok((names, planned.readings))
    })
    .map_err(py_err)
}

/// Diagnoses the sim-to-real gap, as `hapcal diagnose` does: a haptic device with
/// transmissions from its own log (`hapcal_diagnose::diagnose`), any other robot from what
/// `hapcal calibrate` reads (sockets, distances, markers, poses; `hapcal_diagnose::arm`).
/// Returns the report as `hapcal diagnose --json` prints it (without the final newline) and
/// the data's warnings. See `hapcal.diagnose`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (device, data, test, baseline, folds, sigma_m, test_last, accept_setup))]
fn _diagnose(
    py: Python<'_>,
    device: &PyDevice,
    data: Vec<PyRef<'_, PyMeasurements>>,
    test: Vec<PyRef<'_, PyMeasurements>>,
    baseline: Option<String>,
    folds: usize,
    sigma_m: Option<f64>,
    test_last: Option<f64>,
    accept_setup: bool,
) -> PyResult<(String, Vec<String>)> {
    let hapcal_device = &device.device;
    let train: Vec<Source> = data.iter().map(|m| m.source.clone()).collect();
    let test: Vec<Source> = test.iter().map(|m| m.source.clone()).collect();
    if folds < 2 {
        return Err(py_err(anyhow!("folds must be at least 2, got {folds}")));
    }
    if hapcal_device.has_transmissions() {
        return diagnose_log_file(
            py,
            device,
            &train,
            &test,
            baseline,
            folds,
            sigma_m,
            test_last,
            accept_setup,
        );
    }
    hapcal_diagnose::arm::robot_baseline(baseline.as_deref()).map_err(|e| py_err(e.into()))?;
    let mut plan = Plan {
        test_last,
        folds,
        sigma_m,
        ..device_plan(device)
    };
    let files = file_sources(&train).zip(file_sources(&test));
    let robot = device.robot.as_ref();
    let cfg = hapcal_diagnose::arm::ArmConfig {
        folds,
        ..Default::default()
    };
    py.detach(move || -> Result<(String, Vec<String>)> {
        // Files that share their units go through the command line's loaders, setup check
        // and diagnosis.
        let mut gated = Gated::default();
        let (mut d, baseline_warnings) = match files {
            Some((tr, te)) if tr.iter().chain(&te).all(|(_, u)| *u == tr[0].1) => {
                plan.units = tr[0].1.clone();
                plan.data = tr.into_iter().map(|(p, _)| p).collect();
                plan.test = te.into_iter().map(|(p, _)| p).collect();
                gated = setup_gate(&plan, accept_setup)?;
                hapcal_diagnose::plan::diagnose_arm_data(&plan, &cfg)?
            }
            _ => {
                let robot = robot.map_err(|e| anyhow!("{e}"))?;
                let baseline = hapcal_calibrate::baseline::baseline_from_tables(
                    robot,
                    load_sources(&train, robot)?,
                    load_sources(&test, robot)?,
                    &plan,
                    true,
                )?;
                let d = hapcal_diagnose::arm::diagnose_arm(&baseline, &cfg)
                    .context("diagnosing the geometric baseline")?;
                (d, baseline.warnings)
            }
        };
        let Gated {
            mut warnings,
            accepted,
            ..
        } = gated;
        if let Some(finding) = accepted {
            d.verdict.on_accepted_setup(&mut d.notes, finding);
        }
        let json = serde_json::to_string_pretty(&d).context("serialising the diagnosis")?;
        warnings.extend(baseline_warnings);
        Ok((json, warnings))
    })
    .map_err(py_err)
}

/// [`_diagnose`] of a haptic device: the reference device's diagnosis of one log file
/// (`train`), its own held-out folds, with the command line's setup check of the log.
/// The arguments are [`_diagnose`]'s; `sigma_m`, `test_last` and `test` are refused (they
/// apply to robots measured by an instrument).
#[allow(clippy::too_many_arguments)]
fn diagnose_log_file(
    py: Python<'_>,
    device: &PyDevice,
    train: &[Source],
    test: &[Source],
    baseline: Option<String>,
    folds: usize,
    sigma_m: Option<f64>,
    test_last: Option<f64>,
    accept_setup: bool,
) -> PyResult<(String, Vec<String>)> {
    let hapcal_device = &device.device;
    let path = match train {
        [Source::Path { path, units }] if *units == Units::default() => path,
        [Source::Path { path, .. }] => {
            return Err(py_err(anyhow!(
                "{}: a log is in m and rad; read it with Measurements.from_csv(path)",
                path.display()
            )));
        }
        [Source::Arrays(a)] => {
            return Err(py_err(anyhow!(
                "{}: diagnose reads a log file; give its path or \
                 Measurements.from_csv(path)",
                a.name
            )));
        }
        _ => {
            return Err(py_err(anyhow!(
                "{}: a haptic device is diagnosed from one log file, found {}",
                device.path.display(),
                train.len()
            )));
        }
    };
    if !test.is_empty() || sigma_m.is_some() || test_last.is_some() {
        return Err(py_err(anyhow!(
            "test, sigma_m and test_last apply to robots measured by an instrument, not to \
             a haptic device's log"
        )));
    }
    let data = path.clone();
    let device_path = device.path.clone();
    py.detach(move || -> Result<(String, Vec<String>)> {
        let baseline = hapcal_diagnose::baseline_model(
            (baseline.as_deref())
                .unwrap_or(hapcal_calibrate::model::ModelName::Transmissions.name()),
        )?;
        let config = hapcal_diagnose::DiagnoseConfig {
            baseline,
            folds,
            ..hapcal_diagnose::DiagnoseConfig::default()
        };
        // The setup check of the log, as the command line runs it.
        let gate_plan = Plan::log_check(
            device_path.clone(),
            vec![data.clone()],
            Units::default(),
            0.05,
            folds,
        );
        let Gated {
            mut warnings,
            accepted,
            ..
        } = setup_gate(&gate_plan, accept_setup)?;
        let log = hapcal_io::read_log(&data, hapcal_device)
            .with_context(|| format!("reading log {}", data.display()))?;
        let mut d = hapcal_diagnose::diagnose(hapcal_device, &log.rows, &config)
            .with_context(|| format!("diagnosing {}", data.display()))?;
        if let Some(finding) = accepted {
            d.verdict.on_accepted_setup(&mut d.notes, finding);
        }
        let json = serde_json::to_string_pretty(&d).context("serialising the diagnosis")?;
        warnings.extend(log.warnings);
        Ok((json, warnings))
    })
    .map_err(py_err)
}

/// The setup check of measurement files (marker positions, poses, distances), a haptic
/// device's logs or MUKCa socket folders, as `hapcal check` runs it
/// (`hapcal_calibrate::setup::check_plan`). Returns the report as `hapcal check --json`
/// prints it (without the final newline) and, when the data show a mistake overwhelmingly,
/// the message `hapcal check` stops with (exit code 2); a failing check is a result, not an
/// error. See `hapcal.check`.
#[pyfunction]
#[pyo3(signature = (device, data, socket_distance_m))]
fn _check(
    py: Python<'_>,
    device: &PyDevice,
    data: Vec<PyRef<'_, PyMeasurements>>,
    socket_distance_m: f64,
) -> PyResult<(String, Option<String>)> {
    let sources: Vec<Source> = data.iter().map(|m| m.source.clone()).collect();
    let plan = (|| -> Result<Plan> {
        let Some(files) = file_sources(&sources) else {
            bail!(
                "check reads files (measurement files, a haptic device's logs, socket folders); \
                 measurements given as arrays are taken as given: write them to a CSV file to \
                 check them"
            );
        };
        let Some((_, units)) = files.first().cloned() else {
            bail!("data: give the measurement files to check");
        };
        if files.iter().any(|(_, u)| *u != units) {
            bail!(
                "data: the files of one check are read in one length unit and one angle unit; \
                 give every file the same length_unit and angle_unit"
            );
        }
        Ok(Plan {
            units,
            data: files.into_iter().map(|(p, _)| p).collect(),
            socket_distance_m,
            ..device_plan(device)
        })
    })()
    .map_err(py_err)?;
    py.detach(move || -> Result<(String, Option<String>)> {
        if let Some(missing) = plan.data.iter().find(|p| !p.exists()) {
            bail!("data {}: no such file", missing.display());
        }
        plan.validate()?;
        let Some(report) = hapcal_calibrate::setup::check_plan(&plan)? else {
            bail!(
                "check applies to measurement files (marker positions, poses, distances), a \
                 haptic device's logs and socket folders; {} holds none",
                (plan.data.iter())
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        };
        let json = serde_json::to_string_pretty(&report).context("serialising the check")?;
        let error =
            (report.overwhelming()).map(|f| format!("setup check [{}]: {}", f.class, f.text()));
        Ok((json, error))
    })
    .map_err(py_err)
}

/// Imports a URDF chain, or a tree with several tips, as a hapcal device file, as `hapcal
/// import-urdf` does (`hapcal_io::import_urdf_tree`, `hapcal_io::write_device`); also writes
/// it to `path` (atomically, never over the URDF) when given. Returns the device file's text
/// (TOML). See `hapcal.import_urdf`.
#[pyfunction]
#[pyo3(signature = (urdf, tips, path))]
fn _import_urdf(
    py: Python<'_>,
    urdf: PathBuf,
    tips: Vec<String>,
    path: Option<PathBuf>,
) -> PyResult<String> {
    py.detach(move || -> Result<String> {
        if tips.is_empty() {
            bail!(
                "tips: give the tip link (e.g. \"ball_link\"), and one more per branch of a tree"
            );
        }
        if let Some(out) = &path {
            calibrate::check_extension(out, &["toml"], "a device file", true)?;
            calibrate::check_output(out, &[urdf.as_path()])?;
        }
        let device = hapcal_io::import_urdf_tree(&urdf, &tips)?;
        let text = hapcal_io::write_device(&device);
        if let Some(out) = &path {
            calibrate::write_new(out, &text, &[urdf.as_path()])?;
        }
        Ok(text)
    })
    .map_err(py_err)
}

/// hapcal's compiled core; use the `hapcal` package.
#[pymodule]
fn _hapcal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("HapcalError", m.py().get_type::<HapcalError>())?;
    m.add_class::<PyDevice>()?;
    m.add_class::<PyMeasurements>()?;
    m.add_class::<PyCalibration>()?;
    m.add_class::<PyRuntimeRobot>()?;
    m.add_class::<PyRuntimeModel>()?;
    m.add_function(wrap_pyfunction!(_calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(_simulate, m)?)?;
    m.add_function(wrap_pyfunction!(_plan_poses, m)?)?;
    m.add_function(wrap_pyfunction!(_diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(_check, m)?)?;
    m.add_function(wrap_pyfunction!(_import_urdf, m)?)?;
    m.add_function(wrap_pyfunction!(_predict, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The models `calibrate` takes, from the one definition of the model choice.
    m.add("MODELS", model_names())?;
    Ok(())
}
