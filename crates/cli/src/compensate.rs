//! Flags of `hapcal compensate` and the glue that runs it: targets from a CSV file, one
//! compensated joint command per target ([`hapcal_runtime::compensate`]), commands to a CSV
//! file.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use hapcal_runtime::{CompensationConfig, Pose, Robot, Target, compensate};

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

/// One row of the targets file.
struct TargetRow {
    line: u64,
    target: Target,
    start: Option<Vec<f64>>,
}

/// The rotation matrix of the unit quaternion `(w, x, y, z)`.
fn rotation_of(w: f64, x: f64, y: f64, z: f64) -> [[f64; 3]; 3] {
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// `Ok` when every start command `q` (rad, m for a prismatic joint, in the robot's joint
/// order) lies within its joint's limits; else the joints outside, with their limits, in
/// words, and when the values read as degrees lie within them, that they look like degrees.
fn check_start(q: &[f64], robot: &Robot) -> std::result::Result<(), String> {
    let outside: Vec<usize> = (0..q.len())
        .filter(|&j| {
            let (lo, hi) = robot.limits()[j];
            !(lo..=hi).contains(&q[j])
        })
        .collect();
    if outside.is_empty() {
        return Ok(());
    }
    let mut words: Vec<String> = (outside.iter())
        .map(|&j| {
            let (lo, hi) = robot.limits()[j];
            let unit = if robot.is_prismatic(j) { "m" } else { "rad" };
            format!(
                "{} = {} {unit}, limits [{lo}, {hi}] {unit}",
                robot.joint_names()[j],
                q[j]
            )
        })
        .collect();
    // Degrees read as radians: every revolute start within its limits once converted, and
    // some beyond a turn's worth of radians no arm reaches.
    let revolute: Vec<usize> = (0..q.len()).filter(|&j| !robot.is_prismatic(j)).collect();
    let in_degrees = (revolute.iter()).all(|&j| {
        let (lo, hi) = robot.limits()[j];
        (lo..=hi).contains(&q[j].to_radians())
    });
    if in_degrees && outside.iter().all(|j| revolute.contains(j)) {
        words.push(
            "the start columns look like degrees read as radians (converted from degrees every \
             one lies within its limits): write them in rad"
                .to_owned(),
        );
    } else {
        words.push("the start columns are in rad (m for a prismatic joint)".to_owned());
    }
    Err(words.join("; "))
}

/// Reads the targets file: errors name the file, line, column and what was expected.
fn read_targets(path: &Path, robot: &Robot) -> Result<Vec<TargetRow>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the targets file {}", path.display()))?;
    let file = path.display();
    let mut lines = (1u64..).zip(text.lines()).filter(|(_, l)| {
        let t = l.trim();
        !t.is_empty() && !t.starts_with('#')
    });
    let Some((header_line, header)) = lines.next() else {
        bail!("{file}: no header line: expected columns x, y, z [, qw, qx, qy, qz] [, joints]");
    };
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let column = |name: &str| names.iter().position(|n| *n == name);
    let mut position = [0; 3];
    for (slot, name) in position.iter_mut().zip(["x", "y", "z"]) {
        let Some(c) = column(name) else {
            bail!(
                "{file}:{header_line}: no column {name:?} in the header: expected x, y, z (m) [, qw, qx, qy, qz] [, one column per joint: {}]",
                robot.joint_names().join(", ")
            );
        };
        *slot = c;
    }
    let quaternion: Vec<Option<usize>> = ["qw", "qx", "qy", "qz"].map(column).to_vec();
    let orientation = match quaternion.iter().filter(|c| c.is_some()).count() {
        0 => None,
        4 => Some(quaternion.iter().flatten().copied().collect::<Vec<_>>()),
        _ => bail!("{file}:{header_line}: an orientation needs all four columns qw, qx, qy, qz"),
    };
    let joints: Vec<Option<usize>> = robot.joint_names().iter().map(|j| column(j)).collect();
    let n_joint_columns = joints.iter().filter(|c| c.is_some()).count();
    let starts = match n_joint_columns {
        0 => None,
        n if n == joints.len() => Some(joints.iter().flatten().copied().collect::<Vec<_>>()),
        _ => {
            let missing: Vec<&str> = (robot.joint_names().iter().zip(&joints))
                .filter(|(_, c)| c.is_none())
                .map(|(n, _)| n.as_str())
                .collect();
            bail!(
                "{file}:{header_line}: start commands need one column per joint; missing {}",
                missing.join(", ")
            );
        }
    };
    let known = 3 + orientation.as_ref().map_or(0, Vec::len) + n_joint_columns;
    if known != names.len() {
        let unknown: Vec<&str> = (names.iter())
            .filter(|n| {
                !["x", "y", "z", "qw", "qx", "qy", "qz"].contains(n)
                    && !robot.joint_names().iter().any(|j| j == *n)
            })
            .copied()
            .collect();
        bail!(
            "{file}:{header_line}: unknown or repeated columns {}: expected x, y, z, qw, qx, qy, qz and the joints {}",
            unknown.join(", "),
            robot.joint_names().join(", ")
        );
    }
    let mut rows = Vec::new();
    for (line, text) in lines {
        let cells: Vec<&str> = text.split(',').map(str::trim).collect();
        if cells.len() != names.len() {
            bail!(
                "{file}:{line}: {} values, the header has {} columns",
                cells.len(),
                names.len()
            );
        }
        let value = |c: usize| -> Result<f64> {
            let cell = cells[c];
            match cell.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => bail!(
                    "{file}:{line}:{}: expected a number in column {:?}, found {cell:?}",
                    c + 1,
                    names[c]
                ),
            }
        };
        let p = [
            value(position[0])?,
            value(position[1])?,
            value(position[2])?,
        ];
        let target = match &orientation {
            None => Target::Position(p),
            Some(cols) => {
                let q = [
                    value(cols[0])?,
                    value(cols[1])?,
                    value(cols[2])?,
                    value(cols[3])?,
                ];
                let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                if (norm - 1.0).abs() > 1e-3 {
                    bail!(
                        "{file}:{line}: the quaternion (qw, qx, qy, qz) = {q:?} has norm {norm}, expected a unit quaternion"
                    );
                }
                let [w, x, y, z] = q.map(|v| v / norm);
                Target::Pose(Pose {
                    rotation: rotation_of(w, x, y, z),
                    translation_m: p,
                })
            }
        };
        let start = match &starts {
            None => None,
            Some(cols) => {
                let q = cols.iter().map(|&c| value(c)).collect::<Result<Vec<_>>>()?;
                check_start(&q, robot).map_err(|why| {
                    anyhow::anyhow!(
                        "{file}:{line}: a start command outside the robot's limits: {why}"
                    )
                })?;
                Some(q)
            }
        };
        rows.push(TargetRow {
            line,
            target,
            start,
        });
    }
    Ok(rows)
}

/// The calibrated robot of `args.device`: a URDF with `--tip` and `--other-tip`, or a serial
/// robot's device file (`.toml`, no tips).
fn load_robot(args: &CompensateArgs) -> Result<Robot> {
    let device = &args.device;
    let context = || format!("loading the calibrated robot {}", device.display());
    let is_toml = (device.extension()).is_some_and(|e| e.eq_ignore_ascii_case("toml"));
    if is_toml {
        if let Some(tip) = args.tip.iter().chain(&args.other_tips).next() {
            bail!(
                "--tip {tip}: {} is a device file, whose chain has one tip; compensate without \
                 --tip or --other-tip",
                device.display()
            );
        }
        return Robot::load_device(device).with_context(context);
    }
    let Some(tip) = &args.tip else {
        bail!(
            "--tip: name the tip link of {} the targets are for (e.g. --tip ball_link)",
            device.display()
        );
    };
    let mut tips = vec![tip.as_str()];
    tips.extend(args.other_tips.iter().map(String::as_str));
    Robot::load_urdf(device, &tips).with_context(context)
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
    let robot = load_robot(args)?;
    let unbound = crate::predict::unbound_record_note(&args.device, &robot);
    let mut rows = read_targets(&args.targets, &robot)?;
    let robot = if args.instrument_frame {
        let Some(instrument) = robot.frame("instrument") else {
            bail!(
                "--instrument-frame: {} has no identified instrument frame (frames.instrument of its calibration record)",
                args.device.display()
            );
        };
        let to_root = instrument.inverse();
        for row in &mut rows {
            row.target = match row.target {
                Target::Position(p) => {
                    let r = to_root.rotate(&p);
                    let t = to_root.translation_m;
                    Target::Position([r[0] + t[0], r[1] + t[1], r[2] + t[2]])
                }
                Target::Pose(p) => Target::Pose(to_root.compose(&p)),
            };
        }
        match robot.frame("marker1") {
            Some(marker) => robot.with_marker(0, &marker)?,
            None => robot,
        }
    } else {
        robot
    };
    let cfg = CompensationConfig {
        tolerance_m: args.tolerance_mm * 1e-3,
        tolerance_rad: args.tolerance_mrad * 1e-3,
        max_iterations: args.max_iterations,
        ..CompensationConfig::default()
    };
    let n = robot.n_joints();
    let mut ws = robot.workspace();
    let mut previous: Vec<f64> = (robot.limits().iter())
        .map(|(lo, hi)| 0.0_f64.clamp(*lo, *hi))
        .collect();
    let mut command = vec![0.0; n];
    let mut out = String::from("line");
    for name in robot.joint_names() {
        let _ = write!(out, ",{name}");
    }
    out.push_str(",position_error_m,orientation_error_rad\n");
    let mut missed = Vec::new();
    let mut outside = Vec::new();
    let (mut worst_m, mut worst_rad) = (0.0_f64, 0.0_f64);
    for row in &rows {
        let start = row.start.as_deref().unwrap_or(&previous);
        let c = compensate(&robot, 0, &row.target, start, &cfg, &mut ws, &mut command)
            .map_err(|e| anyhow::anyhow!("{}:{}: {e}", args.targets.display(), row.line))?;
        if let Some((j, past)) = robot
            .outside_region(&command)
            .map_err(|e| anyhow::anyhow!("{}:{}: {e}", args.targets.display(), row.line))?
        {
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
            for q in &command {
                let _ = write!(out, ",{q:?}");
            }
            let _ = writeln!(
                out,
                ",{:?},{:?}",
                c.position_error_m, c.orientation_error_rad
            );
            worst_m = worst_m.max(c.position_error_m);
            worst_rad = worst_rad.max(c.orientation_error_rad);
            previous.copy_from_slice(&command);
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
