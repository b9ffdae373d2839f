//! `hapcal`: kinematic calibration of haptic devices and serial robots.
//!
//! All standard output goes through [`emit`], all messages through [`note!`]: a closed or full
//! standard output never panics.

use anyhow::{Context, Result};
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use hapcal::calibrate::{self, ModelChoice, Plan};
use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// A message on standard error, `format!`-style; a failed write is ignored (there is nowhere
/// left to report it).
macro_rules! note {
    ($($arg:tt)*) => {{
        let mut err = std::io::stderr().lock();
        let _ = writeln!(err, $($arg)*);
    }};
}

/// Writes `text` to standard output and flushes it. A reader that went away (`hapcal … | head`,
/// a broken pipe) ends the program quietly with exit code 0, as a Unix filter does; any other
/// write error (a full disk, a closed descriptor) is reported on standard error with exit
/// code 2. Never panics.
fn emit(text: &str) {
    let written = {
        let mut stdout = std::io::stdout().lock();
        stdout
            .write_all(text.as_bytes())
            .and_then(|()| stdout.flush())
    };
    if let Err(e) = written {
        exit_on_stdout_error(&e);
    }
}

/// Ends the program after a failed write to standard output: see [`emit`].
fn exit_on_stdout_error(e: &std::io::Error) -> ! {
    if e.kind() == ErrorKind::BrokenPipe {
        std::process::exit(0);
    }
    note!("hapcal: error: cannot write to standard output: {e}");
    std::process::exit(2);
}

/// Kinematic calibration of capstan-driven haptic devices and serial robots.
///
/// Exit codes: 0 success, 2 error (bad input, unreadable file; the message names the file,
/// line and column), clap's own 2 for bad usage.
#[derive(Parser, Debug)]
#[command(name = "hapcal", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The units of measurement files, the same options on every command that reads them.
#[derive(clap::Args, Clone, Debug)]
struct UnitArgs {
    /// Unit of positions and distances in measurement files and logs: m, mm, cm, in or ft.
    #[arg(long, default_value = "m")]
    length_unit: hapcal_io::LengthUnit,
    /// Unit of prismatic joint readings in measurement files: m, mm, cm, in or ft (their own
    /// unit, whatever the instrument's).
    #[arg(long, default_value = "m")]
    joint_length_unit: hapcal_io::LengthUnit,
    /// Unit of angles (joints, external encoders, phix/phiy/phiz) in data files: rad, deg,
    /// grad or rev.
    #[arg(long, default_value = "rad")]
    angle_unit: hapcal_io::AngleUnit,
    /// The unit of some columns, over the file-wide unit of their kind: COLUMNS=UNIT, the
    /// columns as the header spells them (q1..qn for socket files, which have none), separated
    /// by commas; a length unit (m, mm, cm, in, ft) or an angle unit (rad, deg, grad, rev).
    /// Repeatable. Example: --column-unit q3=deg --column-unit x2,y2,z2=mm.
    #[arg(long = "column-unit", value_name = "COLUMNS=UNIT", value_parser = hapcal_io::ColumnEdit::parse_unit)]
    column_units: Vec<hapcal_io::ColumnEdit>,
    /// A column whose encoder counts the other way: its readings change sign (after their
    /// unit). Repeatable. Example: --column-sign q3.
    #[arg(long = "column-sign", value_name = "COLUMNS", value_parser = hapcal_io::ColumnEdit::parse_sign)]
    column_signs: Vec<hapcal_io::ColumnEdit>,
    /// A value added to a column's readings after their unit and sign, in rad (m for a length
    /// column): a joint's zero. Repeatable. Example: --column-offset q2=-1.5708.
    #[arg(long = "column-offset", value_name = "COLUMNS=VALUE", value_parser = hapcal_io::ColumnEdit::parse_offset, allow_hyphen_values = true)]
    column_offsets: Vec<hapcal_io::ColumnEdit>,
    /// A factor each reading of some columns is multiplied by, after their unit and before
    /// their sign and offset: COLUMNS=FACTOR. A joint read on the motor side of a 100:1 gear
    /// takes 0.01, one in encoder counts of 2^17 per revolution 2π/2^17 = 4.793689962e-5.
    /// Repeatable. Example: --column-scale q3=0.01.
    #[arg(long = "column-scale", value_name = "COLUMNS=FACTOR", value_parser = hapcal_io::ColumnEdit::parse_scale, allow_hyphen_values = true)]
    column_scales: Vec<hapcal_io::ColumnEdit>,
    /// Another column's value (its unit, scale, sign and offset applied; rad or m) times COEF
    /// added to a column's, after every other edit: COLUMN=COEF*OTHER. A reading that depends
    /// on another joint, q6 + 0.5·q5 (a coupled wrist), is fixed by COEF = -0.5. Repeatable.
    /// Example: --column-coupling q6=-0.5*q5.
    #[arg(long = "column-coupling", value_name = "COLUMN=COEF*OTHER", value_parser = hapcal_io::ColumnEdit::parse_coupling, allow_hyphen_values = true)]
    column_couplings: Vec<hapcal_io::ColumnEdit>,
}

impl UnitArgs {
    /// The units the readers take.
    fn units(&self) -> hapcal_io::Units {
        hapcal_io::Units::new(self.length_unit, self.angle_unit)
            .with_joint_length(self.joint_length_unit)
            .with_columns(
                (self.column_units.iter())
                    .chain(&self.column_signs)
                    .chain(&self.column_offsets)
                    .chain(&self.column_scales)
                    .chain(&self.column_couplings)
                    .cloned(),
            )
    }
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Identify kinematic deviations from measurements and report accuracy before and after.
    ///
    /// With no arguments: MUKCa kuka_14, training on the front placement, testing on left_back
    /// and raised_left (bundled in fixtures/mukca).
    #[command(allow_negative_numbers = true)]
    Calibrate(CalibrateArgs),
    /// Reproduce the paper's tables on the simulated reference device (Tables 2, 3, Figs. 7, 8)
    /// and write them to --out; with --check, compare with fixtures/golden/ours/paper.csv.
    Reproduce(ReproduceArgs),
    /// Simulate a measurement log (docs/design.md §5) from a truth device: joint readings quantised
    /// to the encoders, true transmissions and deviations, Gaussian encoder and cable noise.
    #[command(allow_negative_numbers = true)]
    Simulate(SimulateArgs),
    /// Diagnose the sim-to-real gap: how far the calibrated model's held-out residual lies
    /// above the noise floor, where (residual maps), which unmodelled effect explains it and
    /// how far it shrinks. A haptic device's TOML with its log: the reference device's
    /// diagnosis (transmissions and kinematics). A URDF or D-H device with anything hapcal
    /// calibrate reads (MUKCa socket folders, distance logs, marker / pose / distance files):
    /// the serial-arm diagnosis on the geometric calibration, with the model ladder. Prints a
    /// table (or one JSON document with --json); with --svg FILE, also the residual maps.
    Diagnose(DiagnoseArgs),
    /// Check the setup of measurement files, a haptic device's logs or socket folders before
    /// calibrating: units, quaternion and Euler order, mirrored or swapped axes, joint column
    /// order, joint rows out of step, frozen joints, the tip link, the order of the tips,
    /// another robot. Fits the frames only (for socket folders: the scatter of the nominal tip
    /// about each socket) under each hypothesis of a mistake and compares the residual with the
    /// data as given.
    ///
    /// Exit codes: 0 nothing found or only warnings, 2 a mistake the data show overwhelmingly
    /// (the message names the fix) or bad input.
    Check(CheckArgs),
    /// Run the blind test of diagnose on the reference device and print the Markdown report
    /// (confusion matrix, the paper's story); cargo xtask blind-test writes it to
    /// docs/results/diagnose.md.
    BlindTest(BlindTestArgs),
    /// Force rendering before and after calibration (paper Figs. 11–12): the virtual-wall
    /// experiment at the home pose and the errors over random poses, printed as Markdown; writes
    /// the Fig. 12 SVG (Fx, Fy, Fz − Fd against the wall travel).
    #[command(allow_negative_numbers = true)]
    Force(ForceArgs),
    /// Choose the poses to measure: from candidates sampled within the joint limits, the ones
    /// that maximise an observability criterion of the identification Jacobian at the nominal
    /// model (greedy start + DETMAX exchange). With --data and --workspace: the poses to add
    /// to the rows already measured that most reduce the predicted position uncertainty where
    /// the calibration will be used (sequential I-optimal design). Writes the readings as CSV.
    PlanPoses {
        #[command(flatten)]
        plan: hapcal::plan_args::PlanArgs,
        #[command(flatten)]
        units: UnitArgs,
    },
    /// Monte Carlo study of planned vs random poses on the reference device (distance data);
    /// writes a Markdown table. Run it in release.
    PoseStudy(hapcal::pose_study::StudyArgs),
    /// The optimal-design bound of planned distance poses (continuous I-optimal design with its
    /// equivalence-theorem certificate) against random poses; writes a Markdown table.
    PoseBound(hapcal::pose_study::BoundArgs),
    /// Joint commands that bring a tip of a calibrated robot, sagging under its own weight,
    /// onto target positions or poses (exit 2 if a target is not reached).
    Compensate(hapcal::compensate::CompensateArgs),
    /// The calibrated model's tip positions (or poses) at new joint readings, each with its
    /// 1σ uncertainty from the calibration's covariance and a flag where the readings lie
    /// outside the region the calibration was fitted on; with measured columns, the errors
    /// against them (no refit).
    Predict {
        #[command(flatten)]
        args: hapcal::predict::PredictArgs,
        #[command(flatten)]
        units: UnitArgs,
    },
    /// Import a URDF chain as a hapcal device file (TOML on stdout).
    ImportUrdf {
        /// The URDF file.
        urdf: PathBuf,
        /// The tip link (e.g. ball_link); repeat it for a tree (one branch table per further tip).
        #[arg(long = "tip", value_name = "TIP", required = true)]
        tips: Vec<String>,
    },
}

/// Flags of `hapcal calibrate`.
#[derive(clap::Args, Debug)]
struct CalibrateArgs {
    /// Device file (.toml) or URDF (.urdf, with --tip).
    #[arg(long)]
    device: Option<PathBuf>,
    /// Tip link when the device is a URDF; repeat it for a tree with several tips (marker
    /// k sits on the k-th tip given, markers past the last on the last).
    #[arg(long = "tip", default_values_t = ["ball_link".to_owned()])]
    tips: Vec<String>,
    /// Training data: MUKCa placement folders (hole_0.csv, hole_1.csv), run folders of
    /// placements, hapcal log CSV files, or measurement files.
    ///
    /// Measurement CSV columns: joints as q1..qn (chain order) or by the device's joint
    /// names in any order; markers x,y,z or x1,y1,z1,x2,… in the instrument's frame;
    /// orientation per marker as qw,qx,qy,qz (qw1,…) or figaroh's phix,phiy,phiz (roll,
    /// pitch, yaw: R = Rz·Ry·Rx); distance_m, distance or d for a distance from an anchor
    /// (cable encoder, ballbar) to the first marker's frame, on a device without a
    /// cable_encoder table of its own; t or t_s for time; other columns are reported once and
    /// ignored. industrial_calibration's measurements.yaml is read as it is (m, rad). The
    /// instrument frame (the anchor) and each marker's frame on its link are identified.
    #[arg(long, num_args = 1..)]
    data: Vec<PathBuf>,
    /// Test data, same kinds; only evaluated, never fitted.
    #[arg(long, num_args = 1..)]
    test: Vec<PathBuf>,
    /// Measurement files: a CSV of the joint configurations where the calibration will be
    /// used (joint columns as in the data). The model choice also judges each model where
    /// they lie beyond a joint's training range, and the report names them.
    #[arg(long)]
    workspace: Option<PathBuf>,
    /// Write the calibrated device: .urdf (a copy of the source URDF with the calibrated
    /// joint origins) or .toml (a device file with a calibration table).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as one JSON document instead of a table.
    #[arg(long)]
    json: bool,
    /// Also write the report as one self-contained HTML file (figures, tables, the text
    /// report; nothing fetched, readable offline).
    #[arg(long)]
    report: Option<PathBuf>,
    /// Model to identify (--help says what each value fits to each kind of data).
    ///
    /// Which values apply, and what they fit, depends on the data: socket recordings and
    /// distance logs, measurement files, or a haptic device's logs; a value the data do not
    /// take is refused.
    #[arg(long, value_enum, default_value_t = ModelChoice::Auto)]
    model: ModelChoice,
    /// Known distance between the two sockets of a placement, m.
    #[arg(long, default_value_t = 0.05, allow_hyphen_values = true)]
    socket_distance_m: f64,
    /// Cross-validation folds (time-contiguous blocks, at least 2).
    #[arg(
        long,
        default_value_t = hapcal_calibrate::fit::DEFAULT_FOLDS,
        value_parser = hapcal::count_in::<2, { usize::MAX }>
    )]
    folds: usize,
    /// Measurement noise standard deviation, m (default: estimated from the residuals).
    #[arg(long, allow_hyphen_values = true)]
    sigma_m: Option<f64>,
    /// Orientation noise standard deviation of pose data, rad (default: estimated).
    #[arg(long, allow_hyphen_values = true)]
    sigma_rad: Option<f64>,
    /// Measurement files: hold out this fraction of each training file's rows, the last
    /// ones in file order, as a test set (0.3: the first 70 % train).
    #[arg(long, allow_hyphen_values = true)]
    test_last: Option<f64>,
    /// Measurement files: the direction of gravity in the robot's root frame, the mounting
    /// the compliance models load the joints with: -z upright on a floor (the default), +z
    /// hanging from a ceiling, ±x or ±y on a wall, or three numbers gx,gy,gz. It is written
    /// into the calibration record.
    #[arg(long, allow_hyphen_values = true, value_parser = calibrate::parse_gravity)]
    gravity: Option<[f64; 3]>,
    #[command(flatten)]
    units: UnitArgs,
    /// Haptic device with transmissions: identify the transmissions and the kinematics in
    /// one problem instead of the paper's two steps.
    #[arg(long)]
    joint: bool,
    /// Calibrate measurement files as they are even when the setup check finds a mistake
    /// (hapcal check).
    #[arg(long)]
    accept_setup: bool,
}

/// Flags of `hapcal reproduce`.
#[derive(clap::Args, Debug)]
struct ReproduceArgs {
    /// Truth file (its device file is named inside).
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Monte Carlo seeds (seed 0 is the single-seed run; at most 10,000).
    #[arg(long, default_value_t = 100, value_parser = hapcal::count_in::<0, 10_000>)]
    seeds: usize,
    /// Poses per identification and per validation (1 to 100,000).
    #[arg(long, default_value_t = 200, value_parser = hapcal::count_in::<1, 100_000>)]
    poses: usize,
    /// Output folder.
    #[arg(long, default_value = "docs/results/paper")]
    out: PathBuf,
    /// Compare with the golden file instead of writing (UPDATE_GOLDEN=1 rewrites it and fails).
    #[arg(long)]
    check: bool,
    /// Choose the identification poses from --candidates random ones by this criterion of
    /// the distance Jacobian at the nominal model (d-optimal, o1, o3, o4, o5, i-optimal)
    /// instead of taking random poses as the paper does.
    #[arg(long)]
    design: Option<hapcal_identify::Criterion>,
    /// Random candidates per seed for --design (1 to 100,000).
    #[arg(long, default_value_t = 2000, value_parser = hapcal::count_in::<1, 100_000>)]
    candidates: usize,
}

/// Flags of `hapcal simulate`.
#[derive(clap::Args, Debug)]
struct SimulateArgs {
    /// Nominal device file (TOML); defaults to the truth's device, or the reference device.
    #[arg(long)]
    device: Option<PathBuf>,
    /// Truth file (deviations and transmission parameters); without it, the nominal device.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Random seed (the log is the same for the same seed).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Number of poses (1 to 1,000,000).
    #[arg(long, default_value_t = 200, value_parser = hapcal::count_in::<1, 1_000_000>)]
    poses: usize,
    /// Cable noise: paper (σ_m = 2π·R_d·σ_e, the paper's formula) or arc-length (R_d·σ_e).
    #[arg(long, default_value = "paper")]
    noise: String,
    /// Output log CSV.
    #[arg(long)]
    out: PathBuf,
    /// Inject an unmodelled effect (docs/design.md §6), e.g. backlash:j2=1e-3 or
    /// cable_angle:k=2e-4; repeatable. Implies --motion.
    #[arg(long = "effect")]
    effects: Vec<String>,
    /// Time-ordered motion (t_s column, every joint in both directions) instead of
    /// independent random poses.
    #[arg(long)]
    motion: bool,
    /// Time between samples of the time-ordered motion, s.
    #[arg(long, default_value_t = 0.5, allow_hyphen_values = true)]
    period_s: f64,
}

/// Flags of `hapcal diagnose`.
#[derive(clap::Args, Debug)]
struct DiagnoseArgs {
    /// Device: a haptic device's TOML, a URDF (with --tip) or a D-H device file.
    #[arg(long)]
    device: PathBuf,
    /// Tip link of a URDF; repeat for a tree (marker k sits on the k-th tip).
    #[arg(long = "tip", default_values_t = ["ball_link".to_owned()])]
    tips: Vec<String>,
    /// Data: the haptic device's log (CSV, docs/design.md §5), or the training data of an
    /// arm as hapcal calibrate --data takes them.
    #[arg(long, num_args = 1..)]
    data: Vec<PathBuf>,
    /// Held-out data of an arm (never used to fit or to choose): its error at each rung.
    #[arg(long, num_args = 1..)]
    test: Vec<PathBuf>,
    /// Measurement files: hold out this fraction of each training file's last rows.
    #[arg(long)]
    test_last: Option<f64>,
    /// Instrument position σ, m per axis: the noise floor (default: repeated poses, socket
    /// replicates, or no floor).
    #[arg(long)]
    sigma_m: Option<f64>,
    /// Orientation σ of pose data, rad (default: estimated).
    #[arg(long)]
    sigma_rad: Option<f64>,
    /// Known distance between the two sockets of a placement, m.
    #[arg(long, default_value_t = 0.05)]
    socket_distance_m: f64,
    #[command(flatten)]
    units: UnitArgs,
    /// The model the gap is measured against, by its --model name. A haptic device's log:
    /// transmissions (the paper's full calibration, the default) or geometric (the
    /// kinematic deviations alone; the transmission models then join the candidates); full
    /// and kinematics are read as these. Any other robot: geometric, the only one.
    #[arg(long)]
    baseline: Option<String>,
    /// Cross-validation folds (time-contiguous blocks, at least 2).
    #[arg(long, default_value_t = 5, value_parser = hapcal::count_in::<2, { usize::MAX }>)]
    folds: usize,
    /// Print one JSON document instead of the table.
    #[arg(long)]
    json: bool,
    /// Also write the residual maps (SVG) to this file; without it no file is written.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Also write the diagnosis as one self-contained HTML file (the verdict, the
    /// candidates, the residual maps, the text report).
    #[arg(long)]
    report: Option<PathBuf>,
    /// Diagnose measurement files as they are even when the setup check finds a mistake
    /// (hapcal check).
    #[arg(long)]
    accept_setup: bool,
}

/// Flags of `hapcal check`.
#[derive(clap::Args, Debug)]
struct CheckArgs {
    /// Device: a URDF (with --tip) or a D-H device file.
    #[arg(long)]
    device: PathBuf,
    /// Tip link of a URDF; repeat for a tree (marker k sits on the k-th tip).
    #[arg(long = "tip", default_values_t = ["ball_link".to_owned()])]
    tips: Vec<String>,
    /// Measurement files (marker positions, poses, distances), a haptic device's logs, or
    /// MUKCa socket folders.
    #[arg(long, num_args = 1..)]
    data: Vec<PathBuf>,
    /// Known distance between the two sockets of a placement, m (socket folders).
    #[arg(long, default_value_t = 0.05)]
    socket_distance_m: f64,
    #[command(flatten)]
    units: UnitArgs,
    /// Print the findings as one JSON document instead of text.
    #[arg(long)]
    json: bool,
}

/// Flags of `hapcal blind-test`.
#[derive(clap::Args, Debug)]
struct BlindTestArgs {
    /// Number of cases (kinds stratified: 1/8 none, 1/8 outside, 1/8 two, 5/8 one effect).
    #[arg(long, default_value_t = 240, value_parser = hapcal::count_in::<1, 100_000>)]
    cases: usize,
    /// First seed.
    #[arg(long, default_value_t = 0)]
    first_seed: u64,
    /// Seeds of the paper's story (geometric baseline on static poses).
    #[arg(long, default_value_t = 5)]
    story: usize,
}

/// Flags of `hapcal force`.
#[derive(clap::Args, Debug)]
struct ForceArgs {
    /// Nominal device file (the uncalibrated model).
    #[arg(long)]
    device: PathBuf,
    /// Truth file (the simulated device).
    #[arg(long)]
    truth: PathBuf,
    /// Calibrated device file (from hapcal calibrate --out calibrated.toml).
    #[arg(long)]
    calibrated: PathBuf,
    /// Force-feedback gain G of the closed-loop rows.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true)]
    gain: f64,
    /// Random poses (1 to 100,000).
    #[arg(long, default_value_t = 200, value_parser = hapcal::count_in::<1, 100_000>)]
    poses: usize,
    /// Seed of the random poses.
    #[arg(long, default_value_t = 4)]
    seed: u64,
    /// Where to write the SVG.
    #[arg(long, default_value = "fig12_force.svg")]
    svg: PathBuf,
}

/// Largest `force --gain` (dimensionless): a hundred times the default of 10. Far above it the
/// closed loop renders the desired wrench to rounding whatever the model, and the comparison
/// of models says nothing.
const MAX_FORCE_GAIN: f64 = 1000.0;

use hapcal::{SIGMA_M_RANGE, SIGMA_RAD_RANGE, check_sigma};

/// Reads the MUKCa socket folders among `plan`'s data with the device's joint limits, so that
/// a reading past a limit by more than [`hapcal_io::JOINT_LIMIT_SLACK`] of the joint's range
/// is an error naming file:line:column (and one slightly past it a warning on standard
/// error). Only for a single-tip arm whose device file reads; anything else is left to
/// [`calibrate::run`], which reports it. (`calibrate::load_data` checks the same limits; this
/// check also prints the readers' warnings and refuses a socket whose rows are all one
/// configuration before any fit.)
fn check_socket_folders(plan: &Plan) -> Result<()> {
    let folders: Vec<&PathBuf> = (plan.data.iter().chain(&plan.test))
        .filter(|p| p.is_dir())
        .collect();
    if folders.is_empty() || !plan.tips.is_empty() {
        return Ok(());
    }
    let Ok(device) = calibrate::load_device(&plan.device, &plan.tip) else {
        return Ok(());
    };
    if device.has_transmissions() {
        return Ok(());
    }
    for folder in folders {
        let placements =
            hapcal_io::read_mukca_paths_in(std::slice::from_ref(folder), &device, &plan.units)
                .with_context(|| format!("reading measurements in {}", folder.display()))?;
        for warning in placements.iter().flat_map(|p| &p.warnings) {
            note!("hapcal: warning: {warning}");
        }
        // Copied sockets and sockets of one configuration: `calibrate::run` refuses them
        // (`calibrate::check_sockets`) before any fit.
        for placement in &placements {
            calibrate::check_sockets(placement)?;
        }
    }
    Ok(())
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Calibrate(args) => run_calibrate(&args),
        Command::Reproduce(args) => run_reproduce(&args),
        Command::Simulate(args) => run_simulate(&args),
        Command::Diagnose(args) => run_diagnose(&args),
        Command::Check(args) => run_check(&args),
        Command::BlindTest(args) => run_blind_test(&args),
        Command::Force(args) => run_force(&args),
        Command::PlanPoses { plan, units } => run_plan_poses(&plan, &units),
        Command::PoseStudy(args) => {
            let bar = indicatif::ProgressBar::new(args.seeds);
            let text = hapcal::pose_study::run_study(&args, &|done| bar.set_position(done))?;
            bar.finish_and_clear();
            emit(&text);
            note!("hapcal: wrote {}", args.out.display());
            Ok(())
        }
        Command::PoseBound(args) => {
            emit(&hapcal::pose_study::run_bound(&args, &|stage| {
                note!("hapcal: {stage}")
            })?);
            note!("hapcal: wrote {}", args.out.display());
            Ok(())
        }
        Command::Compensate(args) => {
            emit(&hapcal::compensate::run(&args)?);
            Ok(())
        }
        Command::Predict { args, units } => {
            let (stdout, notes) = hapcal::predict::run(&args, &units.units())?;
            for note in notes {
                note!("{note}");
            }
            emit(&stdout);
            Ok(())
        }
        Command::ImportUrdf { urdf, tips } => {
            emit(&hapcal_io::write_device(&hapcal_io::import_urdf_tree(
                &urdf, &tips,
            )?));
            Ok(())
        }
    }
}

/// `tips` as a plan takes them: the first (`ball_link` if none) and the others.
fn split_tips(tips: &[String]) -> (String, Vec<String>) {
    match tips.split_first() {
        Some((first, rest)) => (first.clone(), rest.to_vec()),
        None => ("ball_link".to_owned(), Vec::new()),
    }
}

/// Prints the report as one JSON document (`doc()`) with `--json`, else its text `text`.
fn emit_report(
    json: bool,
    doc: impl FnOnce() -> serde_json::Result<String>,
    text: &str,
) -> Result<()> {
    if json {
        emit(&format!("{}\n", doc()?));
    } else {
        emit(text);
    }
    Ok(())
}

/// Each of `warnings` on standard error.
fn warn_all(warnings: &[String]) {
    for w in warnings {
        note!("hapcal: warning: {w}");
    }
}

impl CalibrateArgs {
    /// The plan these flags ask for: with no device and no data, the bundled MUKCa kuka_14
    /// ([`Plan::bundled_default`]) with the flags' settings.
    fn plan(&self) -> Plan {
        let plan = Plan {
            workspace: self.workspace.clone(),
            model: self.model,
            socket_distance_m: self.socket_distance_m,
            folds: self.folds,
            sigma_m: self.sigma_m,
            joint: self.joint,
            sigma_rad: self.sigma_rad,
            units: self.units.units(),
            test_last: self.test_last,
            gravity: self.gravity.unwrap_or(calibrate::GRAVITY_DOWN),
            ..Plan::bundled_default()
        };
        if self.device.is_none() && self.data.is_empty() && self.test.is_empty() {
            return plan;
        }
        let (tip, tips) = split_tips(&self.tips);
        Plan {
            device: self.device.clone().unwrap_or(plan.device),
            tip,
            tips,
            data: self.data.clone(),
            test: self.test.clone(),
            ..plan
        }
    }
}

/// `hapcal calibrate`: the setup check, the fit, the report on standard output, then the
/// HTML report (`--report`) and the calibrated device (`--out`).
fn run_calibrate(args: &CalibrateArgs) -> Result<()> {
    let plan = args.plan();
    let inputs: Vec<&Path> = (plan.data.iter().chain(&plan.test))
        .chain(&plan.workspace)
        .map(PathBuf::as_path)
        .collect();
    if let Some(out) = &args.out {
        calibrate::check_outputs(&plan.device, out, &inputs)?;
    }
    if let Some(report) = &args.report {
        hapcal::html::check(report, &[&[plan.device.as_path()], &inputs[..]].concat())?;
    }
    plan.validate()?;
    // The setup check first: socket files in degrees or with swapped columns are named
    // before the reader's joint-limit check reports the first reading past a limit.
    let (_, warned) = setup_gate(&plan, args.accept_setup)?;
    check_socket_folders(&plan)?;
    let outcome = hapcal::with_spinner("calibrating", || calibrate::run(&plan))?;
    for ladder_note in outcome.report.ladder_notes() {
        note!("hapcal: note: {ladder_note}");
    }
    // After the fit: deviations no real device has say the data are another's.
    let cfg = setup_config(args.accept_setup);
    if let Some(warning) = hapcal_calibrate::setup::gate_after_fit(&outcome.report, &cfg, &warned)?
    {
        note!("hapcal: warning: {warning}");
    }
    let text = hapcal::report::render(&outcome.report);
    emit_report(
        args.json,
        || serde_json::to_string_pretty(&outcome.report),
        &text,
    )?;
    if let Some(path) = &args.report {
        hapcal::html::write_calibration(path, &outcome.report, &plan.device, &inputs)?;
        note!("hapcal: wrote {}", path.display());
    }
    if let Some(out) = &args.out {
        for path in calibrate::write_outputs_beside(&outcome, out, &inputs)? {
            note!("hapcal: wrote {}", path.display());
        }
    }
    Ok(())
}

/// `hapcal reproduce`: the paper's tables on the simulated reference device, written to
/// `--out` or, with `--check`, compared with the golden file.
fn run_reproduce(args: &ReproduceArgs) -> Result<()> {
    let root = hapcal::project_root();
    let truth = (args.truth.clone()).unwrap_or_else(|| root.join(hapcal_sim::REFERENCE_TRUTH));
    // The truth's device file is an input too; an unreadable truth fails in `run` below.
    let truth_device = hapcal_sim::read_truth(&truth)
        .ok()
        .map(|t| t.device_path(&truth));
    let mut inputs: Vec<&Path> = vec![&truth];
    inputs.extend(truth_device.as_deref());
    if !args.check {
        output_folder(&args.out)?;
    }
    let bar = hapcal::progress_bar(
        args.seeds as u64,
        "{msg} [{bar:40}] {pos}/{len} seeds, eta {eta}",
    );
    bar.set_message("reproducing");
    let criterion = (args.design).unwrap_or(hapcal_identify::Criterion::DOptimal);
    let select = |reference: &hapcal::paper::Reference, readings: &[Vec<f64>], n: usize| {
        hapcal::reproduce::planned_poses(reference, readings, n, criterion)
    };
    let choice = match args.design {
        None => hapcal::paper::PoseChoice::Random,
        Some(criterion) => hapcal::paper::PoseChoice::Planned {
            n_candidates: args.candidates,
            name: criterion.to_string(),
            select: &select,
        },
    };
    let result = hapcal::reproduce::run(&truth, args.seeds, args.poses, &choice, &|done| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    if args.check {
        let golden = root.join(hapcal::reproduce::GOLDEN_FILE);
        let update = std::env::var_os("UPDATE_GOLDEN").is_some();
        emit(&hapcal::reproduce::check_against_golden(
            &result, &golden, &inputs, update,
        )?);
        return Ok(());
    }
    for (name, text) in &result.files {
        calibrate::write_new(&args.out.join(name), text, &inputs)?;
    }
    emit(&result.summary);
    note!(
        "hapcal: wrote {} files to {}",
        result.files.len(),
        args.out.display()
    );
    Ok(())
}

/// Creates the output folder `out` if it does not exist; `Err` if it is a file.
fn output_folder(out: &Path) -> Result<()> {
    if out.exists() && !out.is_dir() {
        anyhow::bail!(
            "cannot write {}: --out is an output folder, and this is a file",
            out.display()
        );
    }
    if !out.exists() {
        std::fs::create_dir_all(out)
            .with_context(|| format!("cannot create the folder {}", out.display()))?;
    }
    Ok(())
}

/// `hapcal simulate`: a log of `--poses` readings of the truth device, written to `--out`.
fn run_simulate(args: &SimulateArgs) -> Result<()> {
    calibrate::check_extension(&args.out, &["csv"], "the simulated log", false)?;
    if !(args.period_s.is_finite() && args.period_s > 0.0) {
        anyhow::bail!(
            "--period-s must be a finite, positive time, s, got {}",
            args.period_s
        );
    }
    let mut inputs: Vec<PathBuf> = args.device.iter().chain(&args.truth).cloned().collect();
    if let Some(t) = (args.truth.as_ref()).and_then(|t| Some((t, hapcal_sim::read_truth(t).ok()?)))
    {
        inputs.push(t.1.device_path(t.0));
    }
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    calibrate::check_output(&args.out, &inputs)?;
    let (device, truth) = simulated_device(args)?;
    let Some(cable) = device.cable_encoder.as_ref() else {
        anyhow::bail!("the device has no [cable_encoder]: nothing to simulate the distance with");
    };
    let Some(noise) = hapcal_sim::NoiseModel::named(&args.noise, cable) else {
        anyhow::bail!(
            "--noise must be `paper` or `arc-length`, got {:?}",
            args.noise
        );
    };
    let cfg = hapcal_sim::SimConfig::new(args.seed, args.poses).with_noise(noise);
    let effects = (args.effects.iter())
        .map(|e| e.parse::<hapcal_sim::Injected>())
        .collect::<Result<Vec<_>, _>>()?;
    let rows = if args.motion || !effects.is_empty() {
        let motion = hapcal_sim::MotionConfig {
            sample_period_s: args.period_s,
        };
        hapcal_sim::simulate_motion(&device, &truth, &cfg, &motion, &effects)
    } else {
        hapcal_sim::simulate(&device, &truth, &cfg)
    }
    .with_context(|| match &args.truth {
        Some(t) => format!("simulating the truth {}", t.display()),
        None => "simulating the nominal device".to_owned(),
    })?;
    calibrate::write_new(&args.out, &hapcal_io::write_log(&rows), &inputs)?;
    note!(
        "hapcal: wrote {} poses to {}",
        rows.len(),
        args.out.display()
    );
    Ok(())
}

/// The nominal device and the truth `simulate` draws from: `--truth` (on its own device, or
/// on `--device`), else the nominal `--device` (the reference device by default).
fn simulated_device(args: &SimulateArgs) -> Result<(hapcal_io::Device, hapcal_sim::Truth)> {
    let Some(truth_path) = &args.truth else {
        let path = (args.device.clone())
            .unwrap_or_else(|| hapcal::project_root().join(hapcal_sim::REFERENCE_DEVICE));
        let device = hapcal_io::read_device(&path)?;
        let truth = hapcal_sim::Truth::nominal(path, &device);
        return Ok((device, truth));
    };
    let truth = hapcal_sim::read_truth(truth_path)?;
    let device = match &args.device {
        Some(d) => hapcal_io::read_device(d)?,
        None => truth.read_device(truth_path)?,
    };
    Ok((device, truth))
}

/// `hapcal force`: the force experiment's Markdown on standard output, its Fig. 12 to `--svg`.
fn run_force(args: &ForceArgs) -> Result<()> {
    let ForceArgs {
        device,
        truth,
        calibrated,
        gain,
        ..
    } = args;
    calibrate::check_extension(&args.svg, &["svg"], "the Fig. 12 plot", true)?;
    if !(gain.is_finite() && (0.0..=MAX_FORCE_GAIN).contains(gain)) {
        anyhow::bail!(
            "--gain must lie between 0 and {MAX_FORCE_GAIN} (a force-feedback gain, \
             dimensionless), got {gain:e}"
        );
    }
    let inputs = [device.as_path(), truth.as_path(), calibrated.as_path()];
    calibrate::check_output(&args.svg, &inputs)?;
    let read_device =
        |p: &PathBuf| hapcal_io::read_device(p).with_context(|| format!("reading {}", p.display()));
    let nominal = read_device(device)?;
    let cal = read_device(calibrated)?;
    let truth_file =
        hapcal_sim::read_truth(truth).with_context(|| format!("reading {}", truth.display()))?;
    let mut plan = hapcal::force::ForcePlan::reference_device();
    plan.gain = *gain;
    plan.sweep.n_poses = args.poses;
    plan.sweep.seed = args.seed;
    let report = hapcal::force::run(&nominal, &truth_file, &cal, &plan).with_context(|| {
        format!(
            "force experiment with {}, {}, {}",
            device.display(),
            truth.display(),
            calibrated.display()
        )
    })?;
    emit(&report.markdown);
    if let Some((_, text)) = report.files.iter().find(|(n, _)| n.ends_with(".svg")) {
        calibrate::write_new(&args.svg, text, &inputs)?;
        note!("hapcal: wrote {}", args.svg.display());
    }
    Ok(())
}

/// `hapcal plan-poses`: the planned poses to `--out` (the summary on standard output), or
/// to standard output (the summary on standard error).
fn run_plan_poses(plan: &hapcal::plan_args::PlanArgs, units: &UnitArgs) -> Result<()> {
    let planned = hapcal::with_spinner("planning poses", || {
        hapcal::plan_args::run_plan(plan, &units.units())
    })?;
    match &planned.out {
        Some(out) => {
            emit(&planned.summary);
            note!("hapcal: wrote {}", out.display());
        }
        None => {
            note!("{}", planned.summary.trim_end());
            emit(&planned.csv);
        }
    }
    Ok(())
}

/// A diagnosis as the command writes it besides standard output: its text report, its
/// residual maps (SVG) and the view of its HTML report.
struct Diagnosed {
    /// The text report.
    text: String,
    /// The residual maps.
    svg: String,
    /// What the HTML report shows.
    view: hapcal::html::DiagnosisView,
}

/// `hapcal diagnose`: a haptic device's log ([`diagnose_haptic`]) or an arm's data
/// ([`diagnose_arm`]); then the residual maps (`--svg`) and the HTML report (`--report`).
fn run_diagnose(args: &DiagnoseArgs) -> Result<()> {
    let mut inputs: Vec<&Path> = vec![args.device.as_path()];
    inputs.extend(args.data.iter().chain(&args.test).map(PathBuf::as_path));
    if let Some(svg) = &args.svg {
        calibrate::check_extension(svg, &["svg"], "the residual maps", false)?;
        calibrate::check_output(svg, &inputs)?;
    }
    if let Some(report) = &args.report {
        hapcal::html::check(report, &inputs)?;
    }
    if args.data.is_empty() {
        anyhow::bail!("--data: give the log or the measurements to diagnose");
    }
    // A device file that does not read is left to the arm's loaders, which name the fault.
    let haptic = hapcal_calibrate::predict::haptic_device(&args.device).is_ok_and(|d| d.is_some());
    let d = if haptic {
        diagnose_haptic(args)?
    } else {
        diagnose_arm(args)?
    };
    // The maps are an output asked for: failing to write them fails the command.
    if let Some(svg) = &args.svg {
        calibrate::write_new(svg, &d.svg, &inputs)?;
        note!("hapcal: wrote residual maps to {}", svg.display());
    }
    if let Some(path) = &args.report {
        hapcal::html::write_diagnosis(path, &d.view, &d.text, &d.svg, &inputs)?;
        note!("hapcal: wrote {}", path.display());
    }
    Ok(())
}

/// A haptic device's diagnosis from its one log, after the setup check of the log as
/// `calibrate` runs it (units, column order, rows out of step, the external encoders).
fn diagnose_haptic(args: &DiagnoseArgs) -> Result<Diagnosed> {
    if args.data.len() != 1 || !args.test.is_empty() {
        anyhow::bail!("a haptic device is diagnosed from one log: --data <log.csv>");
    }
    // The floor comes from the encoders' specification, the held-out rows from
    // cross-validation: these options would be silently ignored.
    for (option, given) in [
        ("--sigma-m", args.sigma_m.is_some()),
        ("--sigma-rad", args.sigma_rad.is_some()),
        ("--test-last", args.test_last.is_some()),
    ] {
        if given {
            anyhow::bail!(
                "{option} does not apply to a haptic device's diagnosis (the floor comes from \
                 the encoders' specification, the held-out rows from --folds)"
            );
        }
    }
    let (accepted, _) = setup_gate(&log_plan(args), args.accept_setup)?;
    let baseline = (args.baseline.as_deref())
        .unwrap_or(hapcal_calibrate::model::ModelName::Transmissions.name());
    let config = hapcal_diagnose::DiagnoseConfig {
        baseline: hapcal_diagnose::baseline_model(baseline)?,
        folds: args.folds,
        ..Default::default()
    };
    let units = args.units.units();
    let (mut d, warnings) = hapcal::with_spinner("diagnosing", || {
        hapcal_diagnose::plan::diagnose_log(&args.device, &args.data[0], &units, &config)
    })?;
    // No physical effect is named on data set up wrong: the note says what the check found.
    if let Some(finding) = accepted {
        d.verdict.on_accepted_setup(&mut d.notes, finding);
    }
    warn_all(&warnings);
    let text = hapcal_diagnose::text::render(&d);
    emit_report(args.json, || serde_json::to_string_pretty(&d), &text)?;
    Ok(Diagnosed {
        svg: hapcal_diagnose::maps::residual_map_svg(&d),
        view: hapcal::html::DiagnosisView::haptic(&d).with_warnings(warnings),
        text,
    })
}

/// The plan of `diagnose`'s data with the defaults of everything else
/// ([`Plan::log_check`]: the geometric model).
fn log_plan(args: &DiagnoseArgs) -> Plan {
    Plan::log_check(
        args.device.clone(),
        args.data.clone(),
        args.units.units(),
        args.socket_distance_m,
        args.folds,
    )
}

/// A serial arm's diagnosis on its geometric calibration, after the setup check.
fn diagnose_arm(args: &DiagnoseArgs) -> Result<Diagnosed> {
    hapcal_diagnose::arm::robot_baseline(args.baseline.as_deref())?;
    check_sigma("--sigma-m", args.sigma_m, SIGMA_M_RANGE, "m")?;
    check_sigma("--sigma-rad", args.sigma_rad, SIGMA_RAD_RANGE, "rad")?;
    let (tip, tips) = split_tips(&args.tips);
    let plan = Plan {
        tip,
        tips,
        sigma_m: args.sigma_m,
        sigma_rad: args.sigma_rad,
        test_last: args.test_last,
        test: args.test.clone(),
        ..log_plan(args)
    };
    let (accepted, _) = setup_gate(&plan, args.accept_setup)?;
    let cfg = hapcal_diagnose::arm::ArmConfig {
        folds: args.folds,
        ..Default::default()
    };
    let (mut d, warnings) = hapcal::with_spinner("diagnosing", || {
        hapcal_diagnose::plan::diagnose_arm_data(&plan, &cfg)
    })?;
    // No physical effect is named on data set up wrong: the note says what the check found.
    if let Some(finding) = accepted {
        d.verdict.on_accepted_setup(&mut d.notes, finding);
    }
    warn_all(&warnings);
    let text = hapcal_diagnose::text::render_arm(&d);
    emit_report(args.json, || serde_json::to_string_pretty(&d), &text)?;
    Ok(Diagnosed {
        svg: hapcal_diagnose::maps::arm_map_svg(&d),
        view: hapcal::html::DiagnosisView::arm(&d).with_warnings(warnings),
        text,
    })
}

/// `hapcal blind-test`: the blind test's Markdown report on standard output.
fn run_blind_test(args: &BlindTestArgs) -> Result<()> {
    let bar = indicatif::ProgressBar::new(args.cases as u64);
    let truth_file = hapcal::project_root().join(hapcal_sim::REFERENCE_TRUTH);
    let truth = hapcal_sim::read_truth(&truth_file)?;
    let device = truth.read_device(&truth_file)?;
    let md = hapcal_diagnose::blind::report(
        &device,
        &truth,
        args.cases,
        args.first_seed,
        args.story,
        &|done| bar.set_position(done as u64),
    )?;
    bar.finish_and_clear();
    emit(&md);
    Ok(())
}

/// The setup check at the start of a calibration or diagnosis: its findings printed as
/// warnings, or the error that stops the command. Returns the error finding the user accepted
/// with `--accept-setup`, as the warning says it, if any (a diagnosis then names no physical
/// effect), and the classes of every finding (the check after the fit weighs its own against
/// them).
fn setup_gate(
    plan: &Plan,
    accept_setup: bool,
) -> Result<(Option<String>, Vec<hapcal_calibrate::setup::MistakeClass>)> {
    let gated = hapcal_calibrate::setup::gate(plan, &setup_config(accept_setup))?;
    warn_all(&gated.warnings);
    Ok((gated.accepted, gated.classes))
}

/// The setup check's settings: `accept_setup` as `--accept-setup` says it.
fn setup_config(accept_setup: bool) -> hapcal_calibrate::setup::SetupConfig {
    hapcal_calibrate::setup::SetupConfig {
        accept_setup,
        accept_option: "--accept-setup",
    }
}

/// `hapcal check`: the findings on standard output; an overwhelming one is the error.
fn run_check(args: &CheckArgs) -> Result<()> {
    let (tip, tips) = split_tips(&args.tips);
    let plan = Plan {
        device: args.device.clone(),
        tip,
        tips,
        units: args.units.units(),
        data: args.data.clone(),
        test: Vec::new(),
        socket_distance_m: args.socket_distance_m,
        ..Plan::bundled_default()
    };
    if plan.data.is_empty() {
        anyhow::bail!("--data: give the measurement files to check");
    }
    if let Some(missing) = plan.data.iter().find(|p| !p.exists()) {
        anyhow::bail!("--data {}: no such file", missing.display());
    }
    plan.validate()?;
    let Some(report) = hapcal::with_spinner("checking the setup", || {
        hapcal_calibrate::setup::check_plan(&plan)
    })?
    else {
        anyhow::bail!(
            "hapcal check applies to measurement files (marker positions, poses, distances), \
             a haptic device's logs and socket folders; {} holds none",
            plan.data
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    };
    emit_report(
        args.json,
        || serde_json::to_string_pretty(&report),
        &report.render(),
    )?;
    match report.overwhelming() {
        Some(f) => anyhow::bail!("setup check [{}]: {}", f.class, f.text()),
        None => Ok(()),
    }
}

/// The command line as `main` parses it: [`Cli`], with the value help of the studies' enums
/// (doc comments written for rustdoc) as plain text.
fn command() -> clap::Command {
    use hapcal::PlainEnum;
    use hapcal::plan::RowNoise;
    use hapcal::pose_study::TransmissionData;
    Cli::command()
        .mut_subcommand("pose-study", |c| {
            c.mut_arg("transmissions", |a| {
                a.value_parser(PlainEnum::<TransmissionData>::default())
            })
        })
        .mut_subcommand("pose-bound", |c| {
            c.mut_arg("noise", |a| {
                a.value_parser(PlainEnum::<RowNoise>::default())
            })
        })
}

/// Help as plain text: clap's bracketed notations (`[OPTIONS]`, `[default: 5]`,
/// `[possible values: …]`) in parentheses, so that square brackets never stand in what a user
/// reads (the help text's own words have none either; a test checks both).
fn plain_help(text: &str) -> String {
    let mut out = text
        .replace(" [OPTIONS]", " (options)")
        .replace(" [COMMAND]", " (command)");
    for (from, to) in [
        ("[default: ", "(default: "),
        ("[possible values: ", "(one of: "),
        ("[aliases: ", "(also: "),
    ] {
        while let Some(start) = out.find(from) {
            let Some(len) = out[start..].find(']') else {
                break;
            };
            let inner = out[start + from.len()..start + len].to_owned();
            out.replace_range(start..=start + len, &format!("{to}{inner})"));
        }
    }
    out
}

fn main() -> ExitCode {
    let parsed = command()
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m));
    let cli = match parsed {
        Ok(cli) => cli,
        Err(e) => {
            // Help and version go to standard output, usage errors to standard error (where a
            // failed write has nowhere left to be reported). Help is plain text in words.
            let printed = if e.kind() == clap::error::ErrorKind::DisplayHelp {
                let mut out = std::io::stdout();
                out.write_all(plain_help(&e.render().to_string()).as_bytes())
                    .and_then(|()| out.flush())
            } else {
                e.print().and_then(|()| std::io::stdout().flush())
            };
            if let Err(io) = printed
                && !e.use_stderr()
            {
                exit_on_stdout_error(&io);
            }
            return ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2));
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            note!("hapcal: error: {}", calibrate::error_chain(&err));
            ExitCode::from(2)
        }
    }
}
