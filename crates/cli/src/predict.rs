//! Flags of `hapcal predict` and the rendering of its result
//! ([`hapcal_calibrate::predict`]): the CSV of the predictions, the summary in words, the JSON
//! document and the HTML report.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use hapcal_calibrate::predict::{
    Errors, Figures, Prediction, errors_without_instrument, haptic_device, predict_haptic,
    predict_robot, prepare, unbound_record_note,
};
use hapcal_io::Units;
use hapcal_runtime::Robot;

/// Flags of `hapcal predict`.
#[derive(Clone, Debug, clap::Args)]
pub struct PredictArgs {
    /// The calibrated device as `hapcal calibrate --out` writes it: a URDF (its sidecar
    /// robot.calibration.toml, the calibration record with the values' σ, the covariance, the
    /// region and the frames, is read from beside it), or a device file (.toml) with the
    /// record in its calibration table: a serial robot's D-H table, or a haptic device.
    #[arg(long)]
    pub device: PathBuf,
    /// A tip link of a URDF to predict (e.g. ball_link); repeat it for a tree, in the
    /// calibration's order (marker k sits on the k-th tip). A device file's chain has one
    /// tip: no --tip.
    #[arg(long = "tip")]
    pub tips: Vec<String>,
    /// Joint readings: a measurement file as hapcal calibrate reads it (CSV with the joints as
    /// q1..qn or by name, or industrial_calibration's YAML). Marker positions (x,y,z or
    /// x1,y1,z1,…), orientations and distances, if present, are compared with the predictions;
    /// a file of joint columns alone is predicted only. For a haptic device, its log (q1..qn,
    /// with distance_m the cable distances to compare with the handle's predicted distance).
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
    /// Also write the prediction as one self-contained HTML file (the errors, each row's
    /// predicted σ, the rows outside the calibration's region).
    #[arg(long)]
    pub report: Option<PathBuf>,
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

/// What the summary needs to know of the calibrated model: whether its record holds a
/// training region, and which joints are prismatic (their ranges in m).
pub struct SummaryModel<'a> {
    /// Whether the record holds a training region.
    pub has_region: bool,
    /// The joints' names, in the order of the readings.
    pub joint_names: &'a [String],
    /// Whether each joint is prismatic.
    pub prismatic: Vec<bool>,
}

impl<'a> SummaryModel<'a> {
    /// The summary's view of `robot`.
    pub fn of_robot(robot: &'a Robot) -> SummaryModel<'a> {
        SummaryModel {
            has_region: (robot.calibration()).is_some_and(|c| c.region.is_some()),
            joint_names: robot.joint_names(),
            prismatic: (0..robot.n_joints())
                .map(|j| robot.is_prismatic(j))
                .collect(),
        }
    }
}

/// The summary of `prediction` in words.
pub fn summary(prediction: &Prediction, model: &SummaryModel<'_>) -> String {
    let mut s = String::new();
    let frame = match prediction.frame {
        "instrument" => "markers in the calibration's instrument frame",
        "base" => "the handle in the device's base frame, where the cable encoder is",
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
    if !model.has_region {
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
            let unit = match model.joint_names.iter().position(|j| *j == o.joint) {
                Some(j) if model.prismatic.get(j) == Some(&true) => "m",
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
        for (what, f, unit, over) in error_kinds(e) {
            let (mean, rms, max) = (f.mean * 1e3, f.rms * 1e3, f.max * 1e3);
            let count = f.count;
            let _ = writeln!(
                s,
                "  {what:<11}  {mean:.4} {rms:.4} {max:.4} {unit} over {count} {over}"
            );
        }
    }
    s
}

/// The errors of `e` that were measured, as both reports show them: name, figures (m or
/// rad), the unit they are shown in (mm or mrad) and what they are counted over.
pub(crate) fn error_kinds(e: &Errors) -> Vec<(&'static str, Figures, &'static str, &'static str)> {
    let kinds = [
        ("position", e.position_m, "mm", "marker samples"),
        ("orientation", e.orientation_rad, "mrad", "samples"),
        ("distance", e.distance_m, "mm", "rows"),
    ];
    (kinds.into_iter())
        .filter_map(|(what, f, unit, over)| Some((what, f?, unit, over)))
        .collect()
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
    if let Some(report) = &args.report {
        crate::html::check(report, &inputs)?;
    }
    if let Some(device) = haptic_device(&args.device)? {
        if !args.tips.is_empty() {
            bail!(
                "--tip {}: {} is a haptic device, whose prediction is its handle; predict it \
                 without --tip",
                args.tips.join(" --tip "),
                args.device.display()
            );
        }
        if args.instrument_frame {
            bail!(
                "--instrument-frame: {} is a haptic device, calibrated from cable distances \
                 measured in its base frame: it has no instrument frame",
                args.device.display()
            );
        }
        let (prediction, model) =
            predict_haptic(&args.device, &device, &args.data, units, args.poses)?;
        let joint_names: Vec<String> = (1..=model.n_joints()).map(|j| format!("q{j}")).collect();
        let view = SummaryModel {
            has_region: model.has_region(),
            joint_names: &joint_names,
            prismatic: vec![false; model.n_joints()],
        };
        return finish(
            args,
            &inputs,
            &prediction,
            &summary(&prediction, &view),
            Vec::new(),
        );
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
        crate::progress_bar(
            table.rows.len() as u64,
            "predicting {bar:40} {pos}/{len} rows",
        )
    });
    let mut progress = |done: usize| {
        if let Some(bar) = &bar {
            bar.set_position(done as u64);
        }
    };
    let prediction = predict_robot(&predictor, &table, &args.data, args.poses, &mut progress)?;
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    let mut extra: Vec<String> = unbound_record_note(&args.device, predictor.robot())
        .into_iter()
        .collect();
    if !prediction.rows.is_empty() && errors_without_instrument(&predictor, &prediction) {
        extra.push(
            "hapcal: warning: the calibration identified no instrument frame: the measured \
             columns are compared in the robot's root link frame"
                .to_owned(),
        );
    }
    let text = summary(&prediction, &SummaryModel::of_robot(predictor.robot()));
    finish(args, &inputs, &prediction, &text, extra)
}

/// Prints or writes `prediction` as `args` ask: the CSV to `--out` or standard output, the
/// JSON document with `--json`, the summary `text`; `extra` notes after the reader's
/// warnings.
fn finish(
    args: &PredictArgs,
    inputs: &[&Path],
    prediction: &Prediction,
    text: &str,
    extra: Vec<String>,
) -> Result<(String, Vec<String>)> {
    let mut notes: Vec<String> = (prediction.warnings.iter())
        .map(|w| format!("hapcal: warning: {w}"))
        .collect();
    notes.extend(extra);
    let text = text.to_owned();
    let text_for_report = text.clone();
    let csv_text = csv(prediction, args.poses);
    let stdout = if args.json {
        format!("{}\n", serde_json::to_string_pretty(prediction)?)
    } else if args.out.is_some() {
        text
    } else {
        notes.extend(text.lines().map(str::to_owned));
        csv_text.clone()
    };
    if let Some(out) = &args.out {
        crate::calibrate::write_new(out, &csv_text, inputs)?;
        notes.push(format!("hapcal: wrote {}", out.display()));
    }
    if let Some(path) = &args.report {
        crate::html::write_page(path, inputs, |command, files| {
            crate::html::prediction_page(prediction, &text_for_report, command, files)
        })?;
        notes.push(format!("hapcal: wrote {}", path.display()));
    }
    Ok((stdout, notes))
}
