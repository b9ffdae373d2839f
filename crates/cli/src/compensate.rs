//! Flags of `hapcal compensate` and the rendering of its result
//! ([`hapcal_calibrate::compensate`]): the commands of the reached targets to a CSV file, the
//! targets missed and outside the calibration's region in words.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Result, bail};
use hapcal_calibrate::compensate::{CompensateInput, Compensated, compensate_targets};
use hapcal_runtime::CompensationConfig;

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
    let Compensated {
        robot,
        rows,
        unbound_note: unbound,
    } = compensate_targets(&input)?;
    let mut out = String::from("line");
    for name in robot.joint_names() {
        let _ = write!(out, ",{name}");
    }
    out.push_str(",position_error_m,orientation_error_rad\n");
    let mut missed = Vec::new();
    let mut outside = Vec::new();
    let (mut worst_m, mut worst_rad) = (0.0_f64, 0.0_f64);
    for row in &rows {
        let c = &row.result;
        if let Some((j, past)) = row.outside_region {
            outside.push(format!(
                "{}:{}: {} {:.4} {} {} its training range",
                args.targets.display(),
                row.line,
                robot.joint_names()[j],
                past.abs(),
                if robot.is_prismatic(j) { "m" } else { "rad" },
                if past > 0.0 { "above" } else { "below" }
            ));
        }
        if c.reached {
            let _ = write!(out, "{}", row.line);
            for q in &row.command {
                let _ = write!(out, ",{q:?}");
            }
            let _ = writeln!(
                out,
                ",{:?},{:?}",
                c.position_error_m, c.orientation_error_rad
            );
            worst_m = worst_m.max(c.position_error_m);
            worst_rad = worst_rad.max(c.orientation_error_rad);
        } else {
            missed.push(format!(
                "{}:{}: not reached: {:.4} mm and {:.4} mrad from the target after {} steps",
                args.targets.display(),
                row.line,
                c.position_error_m * 1e3,
                c.orientation_error_rad * 1e3,
                c.iterations
            ));
        }
    }
    // A partial result never replaces an earlier complete one: with a target missed, an
    // existing --out is left as it was.
    let kept = !missed.is_empty() && args.out.exists();
    if !kept {
        crate::calibrate::write_new(&args.out, &out, &[&args.device, &args.targets])?;
    }
    let reached = rows.len() - missed.len();
    let region = if outside.is_empty() {
        String::new()
    } else {
        format!(
            "warning: the commands of {} targets lie outside the calibration's region (the model extrapolates there):\n{}\n",
            outside.len(),
            outside.join("\n")
        )
    };
    if !missed.is_empty() {
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
            "{} of {} targets not reached within {} mm / {} mrad ({written}):\n{}{}",
            missed.len(),
            rows.len(),
            args.tolerance_mm,
            args.tolerance_mrad,
            missed.join("\n"),
            if region.is_empty() {
                String::new()
            } else {
                format!("\n{}", region.trim_end())
            }
        );
    }
    Ok(format!(
        "{reached} targets reached; largest residual {:.3e} mm, {:.3e} mrad; wrote {}\n{region}{}",
        worst_m * 1e3,
        worst_rad * 1e3,
        args.out.display(),
        unbound.map_or(String::new(), |n| format!("{n}\n"))
    ))
}
