//! Flags of `hapcal plan-poses` and the glue that runs it: the poses of a first calibration
//! at the nominal model, or, with `--data` and `--workspace`, the poses to add to rows already
//! measured so that the calibration predicts best where it will be used.

use anyhow::{Result, bail};
use hapcal_calibrate::model::ModelChoice;
use hapcal_calibrate::model::ModelName;
use hapcal_calibrate::plan::{
    AfterConfig, Measurement, PlanConfig, after_summary, plan_after_files, plan_poses, poses_csv,
    summary,
};
use hapcal_identify::Criterion;
use std::path::{Path, PathBuf};

/// Flags of `hapcal plan-poses`.
#[derive(Clone, Debug, clap::Args)]
pub struct PlanArgs {
    /// Device file (.toml) or URDF (.urdf, with --tip): the nominal model, or the calibrated
    /// one the measured rows (--data) were taken on.
    #[arg(long)]
    pub device: PathBuf,
    /// Tip link when the device is a URDF.
    #[arg(long, default_value = "ball_link")]
    pub tip: String,
    /// Measurement files already measured (marker positions, poses or anchor distances, as
    /// calibrate reads them): plan the poses to add to them, of the same kind, that most
    /// reduce the predicted position uncertainty over --workspace.
    #[arg(long, num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// With --data: a CSV of the joint configurations where the calibration will be used
    /// (joint columns as in the data); the poses are planned to predict there.
    #[arg(long)]
    pub workspace: Option<PathBuf>,
    /// What the rig measures (without --data; default distance). With --data the poses
    /// measure what the measured rows do.
    #[arg(long, value_enum)]
    pub measurement: Option<Measurement>,
    /// Number of poses to choose (1 to 10,000).
    #[arg(long, default_value_t = 30, value_parser = crate::count_in::<1, 10_000>)]
    pub count: usize,
    /// Candidate poses sampled uniformly within the joint limits (1 to 100,000).
    #[arg(long, default_value_t = 1000, value_parser = crate::count_in::<1, 100_000>)]
    pub candidates: usize,
    /// Seed of the candidate sampling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Criterion: d-optimal (= o1 for a fixed count), o3, o4, o5 or i-optimal; default
    /// d-optimal, and i-optimal with --data (i-optimal or d-optimal there).
    #[arg(long)]
    pub criterion: Option<Criterion>,
    /// Measurement noise σ, m, between 1e-9 and 0.1 as calibrate takes it (default: the
    /// paper's σ_m of the cable encoder, else 10 µm; with --data, the calibration's residual
    /// on the measured rows).
    #[arg(long)]
    pub sigma_m: Option<f64>,
    /// With --data: orientation noise σ of pose rows, rad, as calibrate takes it (default:
    /// estimated from the residuals).
    #[arg(long)]
    pub sigma_rad: Option<f64>,
    /// The transmissions are identified from a separate external-encoder run: plan the
    /// measurement poses alone (without the external-encoder rows).
    #[arg(long)]
    pub separate_transmission_run: bool,
    /// Refine the chosen poses by coordinate exchange over the joint box (distance, with
    /// --separate-transmission-run; or with --data; i-optimal or d-optimal).
    #[arg(long)]
    pub refine: bool,
    /// The model the poses are planned for (its --model name, as calibrate takes it): the
    /// parameters the chosen poses must determine. geometric (the default; with transmissions
    /// on a haptic device), or a richer model you will calibrate: compliance,
    /// transversal-compliance, harmonic, … (not auto, frames-only or joint-offsets). With
    /// --data the default is auto: the model calibrate chooses on the measured rows.
    #[arg(long, value_enum, hide_possible_values = true)]
    pub model: Option<ModelChoice>,
    /// Output CSV (joint readings, rad, one pose per row); without it the poses go to
    /// standard output and the summary to standard error.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// What `hapcal plan-poses` produced: the summary, the poses as CSV, and the file written.
#[derive(Clone, Debug)]
pub struct Planned {
    /// Summary of the design, plain text.
    pub summary: String,
    /// The poses as CSV (a header of joint names, one pose per row, rad).
    pub csv: String,
    /// The file the poses were written to (`--out`), if any.
    pub out: Option<PathBuf>,
}

/// Runs `hapcal plan-poses`; `units` are those of the measurement and workspace files.
///
/// # Errors
/// Unreadable device or files, invalid flags, a design failure, or an unwritable output.
pub fn run_plan(args: &PlanArgs, units: &hapcal_io::Units) -> Result<Planned> {
    // The range of calibrate's --sigma-m: the σ the poses are planned for is the one they
    // will be calibrated with.
    crate::check_sigma("--sigma-m", args.sigma_m, crate::SIGMA_M_RANGE, "m")?;
    crate::check_sigma("--sigma-rad", args.sigma_rad, crate::SIGMA_RAD_RANGE, "rad")?;
    let mut inputs: Vec<&Path> = vec![&args.device];
    inputs.extend(args.data.iter().map(PathBuf::as_path));
    inputs.extend(args.workspace.as_deref());
    if let Some(out) = &args.out {
        crate::calibrate::check_extension(out, &["csv"], "the planned poses", false)?;
        crate::calibrate::check_output(out, &inputs)?;
    }
    let device = crate::calibrate::load_device(&args.device, &args.tip)?;
    let (summary, readings) = if args.data.is_empty() {
        plan_nominal(args, &device)?
    } else {
        plan_after_measured(args, &device, units)?
    };
    let names: Vec<String> = device
        .chain()?
        .joint_names()
        .iter()
        .map(|n| n.to_owned())
        .collect();
    let csv = poses_csv(&names, &readings);
    if let Some(out) = &args.out {
        crate::calibrate::write_new(out, &csv, &inputs)?;
    }
    Ok(Planned {
        summary,
        csv,
        out: args.out.clone(),
    })
}

/// The poses of a first calibration, at the nominal model.
fn plan_nominal(args: &PlanArgs, device: &hapcal_io::Device) -> Result<(String, Vec<Vec<f64>>)> {
    for (given, flag) in [
        (args.workspace.is_some(), "--workspace"),
        (args.sigma_rad.is_some(), "--sigma-rad"),
    ] {
        if given {
            bail!("{flag} goes with --data: the rows already measured that the poses are added to");
        }
    }
    let cfg = PlanConfig {
        measurement: args.measurement.unwrap_or(Measurement::Distance),
        count: args.count,
        n_candidates: args.candidates,
        seed: args.seed,
        criterion: args.criterion.unwrap_or(Criterion::DOptimal),
        sigma_m: args.sigma_m,
        transmission_rows: !args.separate_transmission_run,
        refine: args.refine,
        model: args.model.unwrap_or(ModelName::Geometric.into()),
    };
    let plan = plan_poses(device, &cfg)?;
    Ok((summary(&plan, &cfg), plan.readings))
}

/// The poses to add to the measured rows of `args.data`, for the workspace of
/// `args.workspace`.
fn plan_after_measured(
    args: &PlanArgs,
    device: &hapcal_io::Device,
    units: &hapcal_io::Units,
) -> Result<(String, Vec<Vec<f64>>)> {
    if let Some(m) = args.measurement {
        bail!(
            "--measurement {}: with --data the poses measure what the measured rows do; leave \
             it out",
            clap::ValueEnum::to_possible_value(&m)
                .map_or_else(String::new, |v| v.get_name().to_owned())
        );
    }
    if args.separate_transmission_run {
        bail!(
            "--separate-transmission-run plans a haptic device's distance poses; --data plans \
             poses to add to measurement files"
        );
    }
    let cfg = AfterConfig {
        count: args.count,
        n_candidates: args.candidates,
        seed: args.seed,
        criterion: args.criterion.unwrap_or(Criterion::IOptimal),
        model: args.model.unwrap_or(ModelChoice::Auto),
        sigma_m: args.sigma_m,
        sigma_rad: args.sigma_rad,
        refine: args.refine,
    };
    let plan = plan_after_files(
        &args.device,
        &args.tip,
        device,
        &args.data,
        args.workspace.as_deref(),
        units,
        &cfg,
    )?;
    Ok((after_summary(&plan), plan.readings))
}
