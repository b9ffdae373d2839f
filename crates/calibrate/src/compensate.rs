//! Compensation of a targets file with a calibrated robot: the targets read
//! ([`hapcal_io::read_targets`]), taken into the robot's root link frame (or its instrument's),
//! and one compensated joint command per target ([`hapcal_runtime::compensate`]): the command
//! that brings the deflected tip onto the target. What `hapcal compensate` writes.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use hapcal_runtime::{Compensation, Pose, Robot, Target, compensate};

/// Tolerances and steps of each compensation ([`hapcal_runtime::compensate`]).
pub use hapcal_runtime::CompensationConfig;

/// What to compensate: the calibrated robot, its tips, the targets file and the frame.
#[derive(Clone, Debug)]
pub struct CompensateInput<'a> {
    /// The calibrated robot as `hapcal calibrate --out` writes it: a URDF (its sidecar beside
    /// it) or a serial robot's device file (`.toml`).
    pub device: &'a Path,
    /// The tip link of a URDF the targets are for; `None` for a device file (its chain has one
    /// tip).
    pub tip: Option<&'a str>,
    /// Other tip links of a URDF's calibration (a tree's lumped weights hang on every tip).
    pub other_tips: &'a [String],
    /// The targets file ([`hapcal_io::read_targets`]).
    pub targets: &'a Path,
    /// The targets are in the calibration's instrument frame and for its marker on the tip
    /// (the record's `frames.instrument` and `frames.marker1`), not in the root link frame and
    /// for the tip link.
    pub instrument_frame: bool,
    /// Tolerances and steps of each compensation.
    pub config: CompensationConfig,
}

/// One target's compensation.
#[derive(Clone, Debug)]
pub struct CompensatedRow {
    /// The target's 1-based line in the targets file.
    pub line: u64,
    /// The joint command (rad, m for a prismatic joint), in the robot's joint order.
    pub command: Vec<f64>,
    /// Whether the target was reached, the residuals (m, rad) and the steps taken.
    pub result: Compensation,
    /// The joint (index) farthest past the calibration's region at the command and how far
    /// (rad, m for a prismatic joint; positive above the range), if the command lies outside.
    pub outside_region: Option<(usize, f64)>,
}

/// Every target's compensation, in the order of the targets file.
#[derive(Clone, Debug)]
pub struct Compensated {
    /// The robot compensated for (with the marker on its tip under
    /// [`CompensateInput::instrument_frame`]): its joint names, limits and kinds.
    pub robot: Robot,
    /// One per target.
    pub rows: Vec<CompensatedRow>,
    /// The note for a record not bound to its URDF
    /// ([`crate::predict::unbound_record_note`]), if any.
    pub unbound_note: Option<String>,
}

/// The calibrated robot of `input.device`: a URDF with the tip and the other tips, or a serial
/// robot's device file (`.toml`, no tips).
fn load_robot(input: &CompensateInput<'_>) -> Result<Robot> {
    let device = input.device;
    let context = || format!("loading the calibrated robot {}", device.display());
    let is_toml = (device.extension()).is_some_and(|e| e.eq_ignore_ascii_case("toml"));
    if is_toml {
        let given = input
            .tip
            .into_iter()
            .chain(input.other_tips.iter().map(String::as_str));
        if let Some(tip) = given.clone().next() {
            bail!(
                "--tip {tip}: {} is a device file, whose chain has one tip; compensate without \
                 --tip or --other-tip",
                device.display()
            );
        }
        return Robot::load_device(device).with_context(context);
    }
    let Some(tip) = input.tip else {
        bail!(
            "--tip: name the tip link of {} the targets are for (e.g. --tip ball_link)",
            device.display()
        );
    };
    let mut tips = vec![tip];
    tips.extend(input.other_tips.iter().map(String::as_str));
    Robot::load_urdf(device, &tips).with_context(context)
}

/// A target of the targets file: its line, the target, the command to start from if given.
type FileTarget = (u64, Target, Option<Vec<f64>>);

/// The targets of the file `path` for `robot`, in the frame the file gives them in.
fn read_targets(path: &Path, robot: &Robot) -> Result<Vec<FileTarget>> {
    let read =
        crate::predict::with_joint_schema(robot, |schema| hapcal_io::read_targets(path, schema));
    let rows = read.map_err(|e| match e {
        hapcal_io::Error::Io { source, .. } => {
            anyhow!(source).context(format!("cannot read the targets file {}", path.display()))
        }
        e => e.into(),
    })?;
    Ok((rows.into_iter())
        .map(|r| {
            let target = match r.orientation_wxyz {
                None => Target::Position(r.position_m),
                Some(q) => Target::Pose(Pose {
                    rotation: Pose::rotation_of_quaternion(q),
                    translation_m: r.position_m,
                }),
            };
            (r.line, target, r.start)
        })
        .collect())
}

/// `target` in the root link frame, given in the frame of which `to_root` is the pose in it.
fn into_root(to_root: &Pose, target: Target) -> Target {
    match target {
        Target::Position(p) => {
            let r = to_root.rotate(&p);
            let t = to_root.translation_m;
            Target::Position([r[0] + t[0], r[1] + t[1], r[2] + t[2]])
        }
        Target::Pose(p) => Target::Pose(to_root.compose(&p)),
    }
}

/// Compensates every target of `input.targets`: each from its start command, or without one
/// from the previous reached target's command (the first from all joints at zero, clamped to
/// their limits).
///
/// # Errors
/// Unreadable or invalid files (file, line, column), tips that do not fit the device, a robot
/// without an instrument frame under [`CompensateInput::instrument_frame`], a target the
/// runtime refuses (file:line). A target not reached is no error: see
/// [`CompensatedRow::result`].
///
/// `progress` is called with the targets done and the targets in all after each target.
pub fn compensate_targets(
    input: &CompensateInput<'_>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Compensated> {
    let robot = load_robot(input)?;
    let unbound_note = crate::predict::unbound_record_note(input.device, &robot);
    let mut targets = read_targets(input.targets, &robot)?;
    let robot = if input.instrument_frame {
        let Some(instrument) = robot.frame("instrument") else {
            bail!(
                "--instrument-frame: {} has no identified instrument frame (frames.instrument of its calibration record)",
                input.device.display()
            );
        };
        let to_root = instrument.inverse();
        for (_, target, _) in &mut targets {
            *target = into_root(&to_root, *target);
        }
        match robot.frame("marker1") {
            Some(marker) => robot.with_marker(0, &marker)?,
            None => robot,
        }
    } else {
        robot
    };
    let at = |line: u64| format!("{}:{line}", input.targets.display());
    let mut ws = robot.workspace();
    let mut previous: Vec<f64> = (robot.limits().iter())
        .map(|(lo, hi)| 0.0_f64.clamp(*lo, *hi))
        .collect();
    let mut command = vec![0.0; robot.n_joints()];
    let mut rows = Vec::with_capacity(targets.len());
    let n_targets = targets.len();
    // By value: each target's start command is freed once it is compensated.
    for (line, target, start) in targets {
        let start = start.as_deref().unwrap_or(&previous);
        let result = compensate(
            &robot,
            0,
            &target,
            start,
            &input.config,
            &mut ws,
            &mut command,
        )
        .map_err(|e| anyhow!("{}: {e}", at(line)))?;
        let outside_region =
            (robot.outside_region(&command)).map_err(|e| anyhow!("{}: {e}", at(line)))?;
        if result.reached {
            previous.copy_from_slice(&command);
        }
        rows.push(CompensatedRow {
            line,
            command: command.clone(),
            result,
            outside_region,
        });
        progress(rows.len(), n_targets);
    }
    Ok(Compensated {
        robot,
        rows,
        unbound_note,
    })
}

/// What `hapcal compensate` reports of a [`Compensated`]: the CSV of the reached targets, the
/// targets missed and the commands outside the calibration's region, each named by file:line.
#[derive(Clone, Debug)]
pub struct CompensationSummary {
    /// Per reached target its line in the targets file, the joint commands (rad, m for a
    /// prismatic joint) and the residuals (`position_error_m`, `orientation_error_rad`); a
    /// header of the joint names.
    pub csv: String,
    /// The largest position residual of a reached target, m.
    pub worst_position_m: f64,
    /// The largest orientation residual of a reached target, rad.
    pub worst_orientation_rad: f64,
    /// The first [`LISTED`] targets not reached, in words: file:line, the residuals (mm,
    /// mrad), the steps.
    pub missed: Vec<String>,
    /// Targets not reached, all of them.
    pub n_missed: usize,
    /// The first [`LISTED`] commands outside the calibration's region, in words: file:line,
    /// the joint and how far past its training range (rad, m for a prismatic joint).
    pub outside: Vec<String>,
    /// Commands outside the calibration's region, all of them.
    pub n_outside: usize,
}

/// Targets missed, and commands outside the region, that [`CompensationSummary`] words (the
/// others are counted): a day's targets may hold a million.
pub const LISTED: usize = 10;

impl Compensated {
    /// The summary of these compensations of the targets file `targets`.
    pub fn summary(&self, targets: &Path) -> CompensationSummary {
        let robot = &self.robot;
        let mut s = CompensationSummary {
            csv: format!(
                "line{},position_error_m,orientation_error_rad\n",
                (robot.joint_names().iter()).fold(String::new(), |h, n| h + "," + n)
            ),
            worst_position_m: 0.0,
            worst_orientation_rad: 0.0,
            missed: Vec::new(),
            n_missed: 0,
            outside: Vec::new(),
            n_outside: 0,
        };
        for row in &self.rows {
            let c = &row.result;
            s.n_outside += usize::from(row.outside_region.is_some());
            if let Some((j, past)) = row.outside_region.filter(|_| s.outside.len() < LISTED) {
                let (joint, prismatic) = (&robot.joint_names()[j], robot.is_prismatic(j));
                let file = targets.display().to_string();
                (s.outside).push(crate::predict::outside_region_words(
                    &file, row.line, joint, past, prismatic,
                ));
            }
            if c.reached {
                let (m, rad) = (c.position_error_m, c.orientation_error_rad);
                let _ = write!(s.csv, "{}", row.line);
                for q in &row.command {
                    let _ = write!(s.csv, ",{q:?}");
                }
                let _ = writeln!(s.csv, ",{m:?},{rad:?}");
                s.worst_position_m = s.worst_position_m.max(m);
                s.worst_orientation_rad = s.worst_orientation_rad.max(rad);
            } else {
                s.n_missed += 1;
                if s.missed.len() < LISTED {
                    s.missed.push(format!(
                        "{}:{}: not reached: {:.4} mm and {:.4} mrad from the target after {} \
                         steps",
                        targets.display(),
                        row.line,
                        c.position_error_m * 1e3,
                        c.orientation_error_rad * 1e3,
                        c.iterations
                    ));
                }
            }
        }
        s
    }
}
