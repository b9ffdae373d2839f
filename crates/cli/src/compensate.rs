//! Flags of `hapcal compensate` and the output of its summary
//! ([`hapcal_calibrate::compensate::CompensationSummary`]): the commands of the reached targets
//! to a CSV file, the targets missed and outside the calibration's region in words.

use std::path::PathBuf;

use anyhow::{Result, bail};
use hapcal_calibrate::compensate::{
    CompensateInput, CompensationConfig, CompensationSummary, compensate_targets,
};

/// Flags of `hapcal compensate`.
#[derive(Clone, Debug, clap::Args)]
pub struct CompensateArgs {
    /// The calibrated robot as `hapcal calibrate --out` writes it: a URDF (its sidecar
    /// robot.calibration.toml, compliances and frames, is read from beside it), or a serial
    /// robot's device file (.toml with a D-H table and the record in its calibration table).
    #[arg(long)]
    pub device: PathBuf,
    /// The tip link of a URDF the targets are for (e.g. ball_link); a device file's chain has
    /// one tip: no --tip.
    #[arg(long)]
    pub tip: Option<String>,
    /// Another tip link of a URDF's calibration (repeatable): a robot calibrated as a tree
    /// without link masses carries lumped weights at every tip of the calibration.
    #[arg(long = "other-tip")]
    pub other_tips: Vec<String>,
    /// Targets (CSV with a header): columns x, y, z (m, the robot's root link frame), and
    /// optionally qw, qx, qy, qz (the tip's orientation as a unit quaternion) and one column
    /// per joint (rad, m for a prismatic joint: the nominal inverse kinematics' solution to
    /// start from; without them each row starts from the previous row's command, the first
    /// from all joints at zero).
    #[arg(long)]
    pub targets: PathBuf,
    /// Output CSV: per reached target its line in the targets file, the joint commands (rad,
    /// m for a prismatic joint) and the residuals (m, rad).
    #[arg(long)]
    pub out: PathBuf,
    /// A target is reached when the deflected tip is within this distance, mm.
    #[arg(long, default_value_t = 0.001)]
    pub tolerance_mm: f64,
    /// … and within this angle of a target orientation, mrad.
    #[arg(long, default_value_t = 0.001)]
    pub tolerance_mrad: f64,
    /// The targets are in the frame of the calibration's instrument (the sidecar's
    /// frames.instrument) and for its marker on the tip (frames.marker1), as the measurements
    /// were; without it, in the robot's root link frame and for the tip link.
    #[arg(long)]
    pub instrument_frame: bool,
    /// Most damped least-squares steps per target (1 to 10,000).
    #[arg(long, default_value_t = 50, value_parser = crate::count_in::<1, 10_000>)]
    pub max_iterations: usize,
}

/// Runs `hapcal compensate`: writes the commands of the reached targets and returns the
/// summary to print.
///
/// # Errors
/// Unreadable or invalid files (file, line, column), invalid flags, an unwritable output;
/// after writing the output, any target not reached within the tolerance (file:line and
/// residuals); with a target not reached, an existing output file is not replaced.
pub fn run(args: &CompensateArgs) -> Result<String> {
    for (flag, value) in [
        ("--tolerance-mm", args.tolerance_mm),
        ("--tolerance-mrad", args.tolerance_mrad),
    ] {
        if !(value.is_finite() && value > 0.0) {
            bail!("{flag} must be a positive number, got {value}");
        }
    }
    crate::calibrate::check_extension(&args.out, &["csv"], "the joint commands", false)?;
    crate::calibrate::check_output(&args.out, &[&args.device, &args.targets])?;
    let input = CompensateInput {
        device: &args.device,
        tip: args.tip.as_deref(),
        other_tips: &args.other_tips,
        targets: &args.targets,
        instrument_frame: args.instrument_frame,
        config: CompensationConfig {
            tolerance_m: args.tolerance_mm * 1e-3,
            tolerance_rad: args.tolerance_mrad * 1e-3,
            max_iterations: args.max_iterations,
            ..CompensationConfig::default()
        },
    };
    // A progress bar on a terminal, once the targets are read.
    let compensated = crate::with_bar("compensating {bar:40} {pos}/{len} targets", |progress| {
        compensate_targets(&input, progress)
    })?;
    let CompensationSummary {
        csv,
        missed,
        n_missed,
        outside,
        n_outside,
        worst_position_m,
        worst_orientation_rad,
    } = compensated.summary(&args.targets);
    let (reached, targets) = (compensated.rows.len() - n_missed, compensated.rows.len());
    // The first ones in words, the others counted.
    let listed = |words: &[String], n: usize| {
        let more = n - words.len();
        let tail = (more > 0).then(|| format!("… and {more} more"));
        (words.iter().cloned())
            .chain(tail)
            .collect::<Vec<_>>()
            .join("\n")
    };
    // A partial result never replaces an earlier complete one: with a target missed, an
    // existing --out is left as it was.
    let kept = n_missed > 0 && args.out.exists();
    if !kept {
        crate::calibrate::write_new(&args.out, &csv, &[&args.device, &args.targets])?;
    }
    let region = if n_outside == 0 {
        String::new()
    } else {
        format!(
            "warning: the commands of {n_outside} targets lie outside the calibration's region (the model extrapolates there):\n{}\n",
            listed(&outside, n_outside)
        )
    };
    if n_missed > 0 {
        let written = if kept {
            format!(
                "{} exists and was left as it was: the {reached} reached are not written; \
                 give a new --out to keep them",
                args.out.display()
            )
        } else {
            format!("wrote the {reached} reached to {}", args.out.display())
        };
        bail!(
            "{n_missed} of {targets} targets not reached within {} mm / {} mrad ({written}):\n{}{}",
            args.tolerance_mm,
            args.tolerance_mrad,
            listed(&missed, n_missed),
            if region.is_empty() {
                String::new()
            } else {
                format!("\n{}", region.trim_end())
            }
        );
    }
    Ok(format!(
        "{reached} targets reached; largest residual {:.3e} mm, {:.3e} mrad; wrote {}\n{region}{}",
        worst_position_m * 1e3,
        worst_orientation_rad * 1e3,
        args.out.display(),
        (compensated.unbound_note).map_or(String::new(), |n| format!("{n}\n"))
    ))
}
