//! Flags of `hapcal plan-poses` and the glue that runs it.

use anyhow::Result;
use hapcal_calibrate::plan::{Measurement, PlanConfig, plan_poses, poses_csv, summary};
use hapcal_identify::Criterion;

/// Flags of `hapcal plan-poses`.
#[derive(Clone, Debug, clap::Args)]
pub struct PlanArgs {
    /// Device file (.toml) or URDF (.urdf, with --tip).
    #[arg(long)]
    pub device: std::path::PathBuf,
    /// Tip link when the device is a URDF.
    #[arg(long, default_value = "ball_link")]
    pub tip: String,
    /// What the rig measures.
    #[arg(long, value_enum, default_value_t = Measurement::Distance)]
    pub measurement: Measurement,
    /// Number of poses to choose (1 to 10,000).
    #[arg(long, default_value_t = 30, value_parser = crate::count_in::<1, 10_000>)]
    pub count: usize,
    /// Candidate poses sampled uniformly within the joint limits (1 to 100,000).
    #[arg(long, default_value_t = 1000, value_parser = crate::count_in::<1, 100_000>)]
    pub candidates: usize,
    /// Seed of the candidate sampling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Criterion: d-optimal (= o1 for a fixed count), o3, o4 or o5.
    #[arg(long, default_value = "d-optimal")]
    pub criterion: Criterion,
    /// Measurement noise σ, m, between 1e-9 and 0.1 as calibrate takes it (default: the
    /// paper's σ_m of the cable encoder, else 10 µm).
    #[arg(long)]
    pub sigma_m: Option<f64>,
    /// The transmissions are identified from a separate external-encoder run: plan the
    /// measurement poses alone (without the external-encoder rows).
    #[arg(long)]
    pub separate_transmission_run: bool,
    /// Refine the chosen poses by coordinate exchange over the joint box (distance, with
    /// --separate-transmission-run; i-optimal or d-optimal).
    #[arg(long)]
    pub refine: bool,
    /// The model the poses are planned for (its --model name, as calibrate takes it): the
    /// parameters the chosen poses must determine. geometric (the default; with transmissions
    /// on a haptic device), or a richer model you will calibrate: compliance,
    /// transversal-compliance, harmonic, … (not auto, frames-only or joint-offsets).
    #[arg(long, value_enum, hide_possible_values = true, default_value_t = hapcal_calibrate::model::ModelChoice::Geometric)]
    pub model: hapcal_calibrate::model::ModelChoice,
    /// Output CSV (joint readings, rad, one pose per row).
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// Runs `hapcal plan-poses`: returns the summary to print and the path written.
///
/// # Errors
/// Unreadable device, invalid flags, a design failure, or an unwritable output.
pub fn run_plan(args: &PlanArgs) -> Result<(String, std::path::PathBuf)> {
    // The range of calibrate's --sigma-m: the σ the poses are planned for is the one they
    // will be calibrated with.
    crate::check_sigma("--sigma-m", args.sigma_m, crate::SIGMA_M_RANGE, "m")?;
    crate::calibrate::check_extension(&args.out, &["csv"], "the planned poses", false)?;
    crate::calibrate::check_output(&args.out, &[&args.device])?;
    let device = crate::calibrate::load_device(&args.device, &args.tip)?;
    let cfg = PlanConfig {
        measurement: args.measurement,
        count: args.count,
        n_candidates: args.candidates,
        seed: args.seed,
        criterion: args.criterion,
        sigma_m: args.sigma_m,
        transmission_rows: !args.separate_transmission_run,
        refine: args.refine,
        model: args.model,
    };
    let plan = plan_poses(&device, &cfg)?;
    let names: Vec<String> = device
        .chain()?
        .joint_names()
        .iter()
        .map(|n| n.to_owned())
        .collect();
    crate::calibrate::write_new(
        &args.out,
        &poses_csv(&names, &plan.readings),
        &[&args.device],
    )?;
    Ok((summary(&plan, &cfg), args.out.clone()))
}
