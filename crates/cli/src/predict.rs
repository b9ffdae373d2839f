//! Flags of `hapcal predict` and the glue that runs it: joint readings from a measurement
//! file, the calibrated model's tip positions (or poses) with their 1σ uncertainty and the
//! region flag ([`hapcal_runtime::Predictor`]), to a CSV file; with measured columns, the
//! errors of the predictions against them, without refitting.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use hapcal_io::{JointSchema, MeasurementTable, Units};
use hapcal_runtime::{
    MarkerObservation, MeasuredErrors, PredictionFrame, Predictor, Robot, TipPrediction,
};
use serde::Serialize;

/// Flags of `hapcal predict`.
#[derive(Clone, Debug, clap::Args)]
pub struct PredictArgs {
    /// The calibrated robot: a URDF as `hapcal calibrate --out robot.urdf` writes it; its
    /// sidecar robot.calibration.toml (the calibration record: values with their σ, the
    /// covariance, the region, the frames) is read from beside it.
    #[arg(long)]
    pub device: PathBuf,
    /// A tip link to predict (e.g. ball_link); repeat it for a tree, in the calibration's
    /// order (marker k sits on the k-th tip).
    #[arg(long = "tip", required = true)]
    pub tips: Vec<String>,
    /// Joint readings: a measurement file as hapcal calibrate reads it (CSV with the joints as
    /// q1..qn or by name, or industrial_calibration's YAML). Marker positions (x,y,z or
    /// x1,y1,z1,…), orientations and distances, if present, are compared with the predictions;
    /// a file of joint columns alone is predicted only.
    #[arg(long)]
    pub data: PathBuf,
    /// Predict in the calibration's instrument frame, the poses of the markers on the tips
    /// (the sidecar's frames.instrument and frames.marker1, …), as the instrument measures
    /// them; without it, the tip links in the robot's root link frame.
    #[arg(long)]
    pub instrument_frame: bool,
    /// Predict poses: also the orientation (a unit quaternion qw, qx, qy, qz) and its 1σ.
    #[arg(long)]
    pub poses: bool,
    /// Write the predictions to this CSV file (one row per reading: its line in the data
    /// file, the positions in m, their σ, the region flag); without it they go to standard
    /// output, unless --json.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON document (the summary and every prediction) instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One tip's prediction at one row, SI units.
#[derive(Clone, Debug, Serialize)]
pub struct TipRow {
    /// Position, m.
    pub position_m: [f64; 3],
    /// Orientation, unit quaternion `[w, x, y, z]` (with `--poses`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quaternion_wxyz: Option<[f64; 4]>,
    /// 1σ of the position (RMS length of its error), m; absent without an uncertainty.
    pub sigma_m: Option<f64>,
    /// 1σ of the orientation, rad (with `--poses`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma_rad: Option<f64>,
}

/// Where a reading lies outside the calibration's region.
#[derive(Clone, Debug, Serialize)]
pub struct OutsideRegion {
    /// The joint farthest past its training range (by share of the range).
    pub joint: String,
    /// How far past the range: positive above it, negative below; rad (m for a prismatic
    /// joint).
    pub past: f64,
}

/// One row's prediction.
#[derive(Clone, Debug, Serialize)]
pub struct PredictedRow {
    /// The row's line in the data file.
    pub line: u64,
    /// One per tip, in the order of `--tip`.
    pub tips: Vec<TipRow>,
    /// Whether and where the reading lies outside the calibration's region.
    pub outside_region: Option<OutsideRegion>,
}

/// Mean, RMS and largest of one kind of error.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Figures {
    /// Number of samples.
    pub count: usize,
    /// Mean, in the unit of the key.
    pub mean: f64,
    /// RMS.
    pub rms: f64,
    /// Largest.
    pub max: f64,
}

impl Figures {
    fn of(f: &hapcal_runtime::ErrorFigures) -> Option<Figures> {
        (f.count > 0).then(|| Figures {
            count: f.count,
            mean: f.mean(),
            rms: f.rms(),
            max: f.max(),
        })
    }
}

/// The errors of the predictions against the data's measured columns (no refit).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Errors {
    /// 3-D position error per marker sample, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub position_m: Option<Figures>,
    /// Orientation error per marker sample with an orientation, rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation_rad: Option<Figures>,
    /// Absolute distance error per row with a distance, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_m: Option<Figures>,
}

/// What `hapcal predict --json` prints.
#[derive(Clone, Debug, Serialize)]
pub struct Prediction {
    /// The data file.
    pub data: String,
    /// `root` (the robot's root link frame, tip links) or `instrument` (the calibration's
    /// instrument frame, markers).
    pub frame: &'static str,
    /// The tips, in the order of each row's `tips`.
    pub tips: Vec<String>,
    /// What σ rests on: `covariance`, `stds-only` (no covariance recorded: the values'
    /// standard deviations, correlations ignored) or `none`.
    pub uncertainty: &'static str,
    /// Number of values σ propagates.
    pub n_values: usize,
    /// Why there is no σ, or what it leaves out, in words.
    pub uncertainty_note: Option<String>,
    /// Rows outside the calibration's region.
    pub n_outside_region: usize,
    /// The errors against the measured columns, if the data have any.
    pub errors: Option<Errors>,
    /// What the reader noticed (columns ignored, readings slightly past a limit).
    pub warnings: Vec<String>,
    /// Every row.
    pub rows: Vec<PredictedRow>,
}

/// The quaternion `[w, x, y, z]` (w ≥ 0) of the rotation matrix `r` (Shepperd's method:
/// the largest of the four squared components first, for accuracy at every angle).
fn quaternion_of(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let trace = r[0][0] + r[1][1] + r[2][2];
    let q = if trace > 0.0 {
        let s = 2.0 * (1.0 + trace).sqrt();
        [
            s / 4.0,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt();
        [
            (r[2][1] - r[1][2]) / s,
            s / 4.0,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt();
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            s / 4.0,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt();
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            s / 4.0,
        ]
    };
    if q[0] < 0.0 { q.map(|v| -v) } else { q }
}

/// Reads the measurement file `path` with `robot`'s joints (the columns calibrate reads).
fn read_data(path: &Path, robot: &Robot, units: &Units) -> Result<MeasurementTable> {
    if path.is_dir() {
        bail!(
            "{}: a folder; predict reads a measurement file (CSV with the joints as q1..qn or \
             by name), not socket recordings",
            path.display()
        );
    }
    hapcal_calibrate::data::check_csv_header(path)?;
    let prismatic: Vec<bool> = (0..robot.n_joints())
        .map(|j| robot.is_prismatic(j))
        .collect();
    let schema = JointSchema {
        names: robot.joint_names(),
        prismatic: &prismatic,
        limits: robot.limits(),
    };
    let table = hapcal_io::read_measurement_file(path, &schema, units)
        .with_context(|| format!("reading joint readings {}", path.display()))?;
    if table.rows.is_empty() {
        bail!(
            "{}: no data row: expected one joint configuration per row",
            path.display()
        );
    }
    Ok(table)
}

/// Predicts every row of `table` with `predictor`; the errors against the measured columns
/// where the table has them. `progress` is called after each row with the rows done.
///
/// # Errors
/// A reading the runtime refuses (file:line).
pub fn predict_table(
    predictor: &Predictor,
    table: &MeasurementTable,
    poses: bool,
    progress: &mut dyn FnMut(usize),
) -> Result<(Vec<PredictedRow>, Option<MeasuredErrors>)> {
    let robot = predictor.robot();
    let mut ws = predictor.workspace();
    let mut tips = vec![TipPrediction::default(); robot.tip_names().len()];
    let measured = table.n_markers > 0 || table.has_distance;
    let mut errors = MeasuredErrors::default();
    let mut markers = Vec::new();
    let mut rows = Vec::with_capacity(table.rows.len());
    let at = |line: u64| format!("{}:{line}", table.path.display());
    for (done, row) in table.rows.iter().enumerate() {
        predictor
            .predict(&row.q, &mut ws, &mut tips)
            .with_context(|| at(row.line))?;
        let outside = robot.outside_region(&row.q).with_context(|| at(row.line))?;
        if measured {
            markers.clear();
            markers.extend(row.markers.iter().map(|m| MarkerObservation {
                marker: m.marker,
                position_m: m.position_m,
                rotation_wxyz: m.rotation,
            }));
            predictor
                .add_errors(&row.q, &markers, row.distance_m, &mut ws, &mut errors)
                .with_context(|| at(row.line))?;
        }
        rows.push(PredictedRow {
            line: row.line,
            tips: (tips.iter())
                .map(|t| TipRow {
                    position_m: t.pose.translation_m,
                    quaternion_wxyz: poses.then(|| quaternion_of(&t.pose.rotation)),
                    sigma_m: t.sigma_m,
                    sigma_rad: if poses { t.sigma_rad } else { None },
                })
                .collect(),
            outside_region: outside.map(|(j, past)| OutsideRegion {
                joint: robot.joint_names()[j].clone(),
                past,
            }),
        });
        progress(done + 1);
    }
    Ok((rows, measured.then_some(errors)))
}

/// The uncertainty's basis and note, in words.
fn uncertainty_words(predictor: &Predictor) -> (&'static str, Option<String>) {
    let basis = predictor.basis().name();
    let note = predictor.uncertainty_note();
    (basis, note)
}

/// The CSV of `prediction`: `line`, per tip `x, y, z` (numbered `x1, y1, z1, …` for several
/// tips), with `poses` also `qw, qx, qy, qz`, then `sigma_m` (with `poses` also `sigma_rad`),
/// then `outside_region` (0 or 1), `region_joint` and `region_past`.
pub fn csv(prediction: &Prediction, poses: bool) -> String {
    let numbered = prediction.tips.len() > 1;
    let mut out = String::from("line");
    for k in 1..=prediction.tips.len() {
        let n = if numbered {
            k.to_string()
        } else {
            String::new()
        };
        for c in ["x", "y", "z"] {
            let _ = write!(out, ",{c}{n}");
        }
        if poses {
            for c in ["qw", "qx", "qy", "qz"] {
                let _ = write!(out, ",{c}{n}");
            }
        }
        let _ = write!(out, ",sigma{n}_m");
        if poses {
            let _ = write!(out, ",sigma{n}_rad");
        }
    }
    out.push_str(",outside_region,region_joint,region_past\n");
    let number = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:?}"));
    for row in &prediction.rows {
        let _ = write!(out, "{}", row.line);
        for t in &row.tips {
            for v in t.position_m {
                let _ = write!(out, ",{v:?}");
            }
            if let Some(q) = t.quaternion_wxyz {
                for v in q {
                    let _ = write!(out, ",{v:?}");
                }
            }
            let _ = write!(out, ",{}", number(t.sigma_m));
            if poses {
                let _ = write!(out, ",{}", number(t.sigma_rad));
            }
        }
        match &row.outside_region {
            Some(o) => {
                let _ = writeln!(out, ",1,{},{:?}", o.joint, o.past);
            }
            None => out.push_str(",0,,\n"),
        }
    }
    out
}

/// The summary of `prediction` in words.
pub fn summary(prediction: &Prediction, robot: &Robot) -> String {
    let mut s = String::new();
    let frame = match prediction.frame {
        "instrument" => "markers in the calibration's instrument frame",
        _ => "tip links in the root link frame",
    };
    let _ = writeln!(
        s,
        "predicted {} rows of {} at {} ({}), m",
        prediction.rows.len(),
        prediction.data,
        prediction.tips.join(", "),
        frame
    );
    match &prediction.uncertainty_note {
        Some(note) => {
            let _ = writeln!(s, "{note}");
        }
        None => {
            let _ = writeln!(
                s,
                "σ: 1σ of each predicted position from the calibration's covariance of {} values",
                prediction.n_values
            );
        }
    }
    if robot
        .calibration()
        .and_then(|c| c.region.as_ref())
        .is_none()
    {
        let _ = writeln!(
            s,
            "region: the calibration records no training region; no reading is flagged"
        );
    } else if prediction.n_outside_region == 0 {
        let _ = writeln!(
            s,
            "region: every reading lies inside the calibration's region"
        );
    } else {
        let _ = writeln!(
            s,
            "region: {} of {} readings lie outside the calibration's region (extrapolated):",
            prediction.n_outside_region,
            prediction.rows.len()
        );
        let outside =
            (prediction.rows.iter()).filter_map(|r| r.outside_region.as_ref().map(|o| (r.line, o)));
        for (line, o) in outside.clone().take(10) {
            let unit = match robot.joint_names().iter().position(|j| *j == o.joint) {
                Some(j) if robot.is_prismatic(j) => "m",
                _ => "rad",
            };
            let _ = writeln!(
                s,
                "  {}:{line}: {} {:.4} {unit} {} its training range",
                prediction.data,
                o.joint,
                o.past.abs(),
                if o.past > 0.0 { "above" } else { "below" }
            );
        }
        if prediction.n_outside_region > 10 {
            let _ = writeln!(s, "  … and {} more", prediction.n_outside_region - 10);
        }
    }
    if let Some(e) = &prediction.errors {
        let _ = writeln!(
            s,
            "errors against the measured columns (no refit; mean, RMS, max):"
        );
        let lines = [
            ("position   ", e.position_m, "mm", "marker samples"),
            ("orientation", e.orientation_rad, "mrad", "samples"),
            ("distance   ", e.distance_m, "mm", "rows"),
        ];
        for (what, figures, unit, over) in lines {
            if let Some(f) = figures {
                let _ = writeln!(
                    s,
                    "  {what}  {:.4} {:.4} {:.4} {unit} over {} {over}",
                    f.mean * 1e3,
                    f.rms * 1e3,
                    f.max * 1e3,
                    f.count
                );
            }
        }
    }
    s
}

/// The loaded robot, its predictor and the data, as `hapcal predict` and the Python package
/// prepare them.
///
/// # Errors
/// A device that is not a URDF, an unreadable robot or data file (file:line:column),
/// `instrument_frame` on a robot without an identified instrument frame.
pub fn prepare(
    device: &Path,
    tips: &[String],
    data: &Path,
    units: &Units,
    instrument_frame: bool,
) -> Result<(Predictor, MeasurementTable)> {
    let is_urdf = device
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    if !is_urdf {
        bail!(
            "{}: predict reads a calibrated URDF (hapcal calibrate --out robot.urdf) and its \
             sidecar robot.calibration.toml",
            device.display()
        );
    }
    let tip_refs: Vec<&str> = tips.iter().map(String::as_str).collect();
    let robot = Robot::load_urdf(device, &tip_refs)
        .with_context(|| format!("loading the calibrated robot {}", device.display()))?;
    let frame = if instrument_frame {
        if robot.frame("instrument").is_none() {
            bail!(
                "--instrument-frame: {} has no identified instrument frame (frames.instrument \
                 of its calibration sidecar)",
                device.display()
            );
        }
        PredictionFrame::Instrument
    } else {
        PredictionFrame::Root
    };
    let table = read_data(data, &robot, units)?;
    let predictor = Predictor::new(&robot, frame)
        .with_context(|| format!("preparing the predictions of {}", device.display()))?;
    Ok((predictor, table))
}

/// Runs `hapcal predict`: returns what to print on standard output and the messages for
/// standard error; writes `--out` (atomically, never over an input).
///
/// # Errors
/// As [`prepare`]; an output that would overwrite an input or cannot be written.
pub fn run(args: &PredictArgs, units: &Units) -> Result<(String, Vec<String>)> {
    let sidecar = args.device.with_extension("calibration.toml");
    let inputs: [&Path; 3] = [&args.device, &args.data, &sidecar];
    if let Some(out) = &args.out {
        crate::calibrate::check_extension(out, &["csv"], "the predictions", false)?;
        crate::calibrate::check_output(out, &inputs)?;
    }
    let (predictor, table) = prepare(
        &args.device,
        &args.tips,
        &args.data,
        units,
        args.instrument_frame,
    )?;
    // A progress bar when the work is long (rows × robots evaluated), on a terminal only.
    let work = table.rows.len() * (2 * predictor.n_values() + 1);
    let bar = (work > 200_000).then(|| {
        let bar = indicatif::ProgressBar::new(table.rows.len() as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template("predicting {bar:40} {pos}/{len} rows")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    });
    let mut progress = |done: usize| {
        if let Some(bar) = &bar {
            bar.set_position(done as u64);
        }
    };
    let (rows, errors) = predict_table(&predictor, &table, args.poses, &mut progress)?;
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    let (uncertainty, uncertainty_note) = uncertainty_words(&predictor);
    let prediction = Prediction {
        data: args.data.display().to_string(),
        frame: match predictor.frame() {
            PredictionFrame::Root => "root",
            PredictionFrame::Instrument => "instrument",
        },
        tips: args.tips.clone(),
        uncertainty,
        n_values: predictor.n_values(),
        uncertainty_note,
        n_outside_region: rows.iter().filter(|r| r.outside_region.is_some()).count(),
        errors: errors.map(|e| Errors {
            position_m: Figures::of(&e.position),
            orientation_rad: Figures::of(&e.orientation),
            distance_m: Figures::of(&e.distance),
        }),
        warnings: table.warnings.clone(),
        rows,
    };
    let mut notes: Vec<String> = (prediction.warnings.iter())
        .map(|w| format!("hapcal: warning: {w}"))
        .collect();
    if !prediction.rows.is_empty() && errors_without_instrument(&predictor, &prediction) {
        notes.push(
            "hapcal: warning: the calibration identified no instrument frame: the measured \
             columns are compared in the robot's root link frame"
                .to_owned(),
        );
    }
    let csv_text = csv(&prediction, args.poses);
    let text = summary(&prediction, predictor.robot());
    let stdout = if args.json {
        format!("{}\n", serde_json::to_string_pretty(&prediction)?)
    } else if args.out.is_some() {
        text
    } else {
        notes.extend(text.lines().map(str::to_owned));
        csv_text.clone()
    };
    if let Some(out) = &args.out {
        crate::calibrate::write_new(out, &csv_text, &inputs)?;
        notes.push(format!("hapcal: wrote {}", out.display()));
    }
    Ok((stdout, notes))
}

/// Whether the data's measured columns are compared without an identified instrument frame.
fn errors_without_instrument(predictor: &Predictor, prediction: &Prediction) -> bool {
    prediction.errors.is_some() && predictor.robot().frame("instrument").is_none()
}
