//! The data of a calibration, read once and typed by what they measured: socket recordings,
//! distance logs, measurement files (markers, poses, anchor distances) or a haptic device's
//! logs. [`load`] reads the training and held-out paths of a [`Plan`] with the reader of their
//! kind and returns them as a [`Data`]; the workflows take the typed data, never the paths.
//! The robot that measurement files are read against ([`Robot`], from a URDF or a device
//! file) and its readers live here too.

use anyhow::{Context, Result, bail};
use hapcal_io::{Device, JointSchema, LogRow, MeasurementTable, SocketPlacement, Units};
use hapcal_kinematics::{Tree, Vector3};
use hapcal_problems::LinkMass;
use std::path::{Path, PathBuf};

use crate::inputs::Plan;
use crate::model::DataKind;

/// A haptic device's log, read: its name (file stem), its rows and the reader's warnings.
#[derive(Clone, Debug)]
pub struct NamedLog {
    /// File stem.
    pub name: String,
    /// The file read (the Huber loss lists a bounded row with it and the row's line).
    pub path: PathBuf,
    /// The rows: joint readings (rad), external encoders (rad), cable distance (m), time (s).
    pub rows: Vec<LogRow>,
    /// What the reader noticed (columns ignored, …), in the user's words.
    pub warnings: Vec<String>,
}

/// The training and held-out data of one calibration, typed by what they measured.
#[derive(Debug)]
#[allow(clippy::large_enum_variant)] // one value per command, moved once: no box needed
pub enum Data {
    /// Logs of a haptic device with transmissions (the device file has capstans or a
    /// parallelogram).
    HapticLogs {
        /// Training logs.
        train: Vec<NamedLog>,
        /// Held-out logs.
        test: Vec<NamedLog>,
    },
    /// Measurement files: marker positions, poses or anchor distances in an instrument's frame.
    Measurements {
        /// The robot the tables' joint columns were read for (URDF tips or device file).
        robot: Robot,
        /// Training tables, one per file.
        train: Vec<MeasurementTable>,
        /// Held-out tables, one per file.
        test: Vec<MeasurementTable>,
    },
    /// Socket recordings (every training path a MUKCa placement or run folder) or distance logs
    /// of a device with a cable encoder of its own, possibly with socket folders beside them.
    Joints {
        /// [`DataKind::Sockets`] when every training set is a socket placement, else
        /// [`DataKind::Distances`].
        kind: DataKind,
        /// Training sets.
        train: Vec<DataSet>,
        /// Held-out sets.
        test: Vec<DataSet>,
    },
}

impl Data {
    /// What the training data measured.
    pub fn kind(&self) -> DataKind {
        match self {
            Data::HapticLogs { .. } => DataKind::HapticLogs,
            Data::Measurements { .. } => DataKind::Measurements,
            Data::Joints { kind, .. } => *kind,
        }
    }
}

/// The training and test tables of `plan`'s marker files for `robot`: every row, or with
/// [`Plan::read_rows`] and more rows than it in all, every `s`-th row of each file (the
/// stride of [`crate::fit::ladder_sample`] over the files' rows), each sampled table's
/// warnings saying so.
///
/// # Errors
/// As [`load_tables`].
fn load_marker_rows(
    plan: &Plan,
    robot: &Robot,
) -> Result<(Vec<MeasurementTable>, Vec<MeasurementTable>)> {
    let files: Vec<PathBuf> = plan.data.iter().chain(&plan.test).cloned().collect();
    let stride = plan.read_rows.map_or(1, |cap| {
        let lengths: Vec<usize> = files.iter().map(|p| hapcal_io::count_log_rows(p)).collect();
        crate::fit::ladder_sample(&lengths, cap).map_or(1, |sample| sample.stride)
    });
    let (mut tables, n_rows) = load_tables_every(&files, robot, &plan.units, stride)?;
    if stride > 1 {
        for (t, n) in tables.iter_mut().zip(n_rows) {
            t.warnings.push(format!(
                "{}: {n} rows, of which one in {stride} ({} rows, spread over the file) is \
                 used",
                t.path.display(),
                t.rows.len()
            ));
        }
    }
    let test = tables.split_off(plan.data.len());
    Ok((tables, test))
}

/// Reads `plan`'s training and held-out paths for `device`, each with the reader of its kind:
/// a haptic device's logs when the device has transmissions; measurement files when any
/// training file is a measurement file ([`is_marker_file`]: marker, pose or, on a device
/// without a cable encoder of its own, anchor-distance columns); socket folders and distance
/// logs otherwise.
///
/// # Errors
/// A CSV file no reader can take ([`check_csv_header`]), a folder given for a haptic device's
/// log, socket folders mixed with measurement files, and whatever the readers report (file,
/// line, column).
pub fn load(plan: &Plan, device: &Device) -> Result<Data> {
    if device.has_transmissions() {
        let read = |paths: &[PathBuf]| -> Result<Vec<NamedLog>> {
            paths
                .iter()
                .map(|p| read_log(p, device, &plan.units))
                .collect()
        };
        return Ok(Data::HapticLogs {
            train: read(&plan.data)?,
            test: read(&plan.test)?,
        });
    }
    for path in plan.data.iter().chain(&plan.test) {
        check_csv_header(path)?;
    }
    // A device without a cable encoder of its own: a distance comes from an anchor whose
    // position the data must determine, as a tracker's frame.
    let anchor_distances = device.cable_encoder.is_none();
    if (plan.data.iter()).any(|p| is_marker_file(p, anchor_distances)) {
        // Measurement files and MUKCa socket folders are two calibrations (a marker's positions
        // against sockets' unknown points): one kind per run.
        let files: Vec<&PathBuf> = plan.data.iter().chain(&plan.test).collect();
        if let (Some(folder), Some(file)) = (
            files.iter().find(|p| p.is_dir()),
            files.iter().find(|p| !p.is_dir()),
        ) {
            bail!(
                "{} is a folder (MUKCa sockets) and {} a measurement file: calibrate from one \
                 kind of data at a time",
                folder.display(),
                file.display()
            );
        }
        let robot = robot_of(plan, device)?;
        let (train, test) = load_marker_rows(plan, &robot)?;
        return Ok(Data::Measurements { robot, train, test });
    }
    let train = load_data(&plan.data, device, &plan.units)?;
    let test = load_data(&plan.test, device, &plan.units)?;
    let kind = if train.iter().all(|s| matches!(s, DataSet::Sockets(_))) {
        DataKind::Sockets
    } else {
        DataKind::Distances
    };
    Ok(Data::Joints { kind, train, test })
}

/// The robot of `plan`'s device: the URDF with the plan's tips, or the device file's chain or
/// tree.
///
/// A URDF's joints off the measured paths whose readings the data files hold (the other arm
/// of a torso when one hand is measured) are read, not held at zero: the links below them
/// become further tips after the plan's ([`hapcal_io::load_tips`]), which carry no marker but
/// load the gravity torques of the joints they share with the measured paths.
///
/// # Errors
/// A URDF or device whose kinematics do not compile.
pub fn robot_of(plan: &Plan, device: &Device) -> Result<Robot> {
    let is_urdf = (plan.device.extension()).is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    if is_urdf {
        let mut tips: Vec<String> = std::iter::once(plan.tip.clone())
            .chain(plan.tips.iter().cloned())
            .collect();
        let robot = robot_from_urdf(&plan.device, &tips)?;
        if robot.held_joints.is_empty() {
            return Ok(robot);
        }
        let read: Vec<String> = (plan.data.iter().chain(&plan.test))
            .flat_map(|p| csv_columns(p))
            .collect();
        let load = hapcal_io::load_tips(&plan.device, &tips, &read)
            .with_context(|| format!("importing {}", plan.device.display()))?;
        if load.is_empty() {
            return Ok(robot);
        }
        tips.extend(load.iter().cloned());
        Ok(Robot {
            load_tips: load,
            ..robot_from_urdf(&plan.device, &tips)?
        })
    } else {
        robot_from_device(device)
    }
}

/// The robot as the measured workflow needs it: its tree (one chain per tip, sharing one
/// parameter vector), its joints and, from a URDF, its link masses.
#[derive(Clone, Debug)]
pub struct Robot {
    /// The kinematic tree, root to each tip.
    pub tree: Tree,
    /// Joint names, chain order (the columns of the measurement files).
    pub joint_names: Vec<String>,
    /// Prismatic flag per joint.
    pub prismatic: Vec<bool>,
    /// Joint limits per joint, rad or m.
    pub limits: Vec<(f64, f64)>,
    /// Link masses from the URDF's `<inertial>` tags (empty for a D-H device).
    pub masses: Vec<LinkMass>,
    /// Moving joints off the measured paths that the masses hold at zero (a head's pan and
    /// tilt between its mass and the torso), URDF names; empty for a D-H device.
    pub held_joints: Vec<String>,
    /// Tips after the measured ones that carry no marker, only loads: the links below joints
    /// off the measured paths whose readings the data hold ([`robot_of`]); URDF link names.
    pub load_tips: Vec<String>,
    /// Unit direction of gravity in the root frame: the mounting the compliance models load
    /// the joints with (−z, upright, unless `--gravity` says otherwise).
    pub gravity_dir: Vector3<f64>,
}

/// Robot of a URDF with one or more tips.
///
/// # Errors
/// Whatever the URDF reader reports, with the path as context.
pub fn robot_from_urdf(path: &std::path::Path, tips: &[String]) -> Result<Robot> {
    let urdf = hapcal_io::import_urdf_tips(path, tips)
        .with_context(|| format!("importing {}", path.display()))?;
    let tree = Tree::from_placement_paths(&urdf.paths)
        .with_context(|| format!("building the kinematic tree of {}", path.display()))?;
    let masses = urdf
        .inertials
        .iter()
        .filter(|l| l.mass_kg > 0.0)
        .map(|l| LinkMass {
            joint: l.joint,
            mass_kg: l.mass_kg,
            com_m: Vector3::from(l.com_m),
        })
        .collect();
    Ok(Robot {
        joint_names: tree.joint_names().to_vec(),
        prismatic: prismatic_joints(&tree),
        limits: urdf
            .joints
            .iter()
            .map(|j| (j.lower_rad, j.upper_rad))
            .collect(),
        masses,
        held_joints: urdf.held_joints,
        load_tips: Vec::new(),
        gravity_dir: -Vector3::z(),
        tree,
    })
}

/// Per joint of `tree`: whether its screw is a translation (a prismatic joint).
fn prismatic_joints(tree: &Tree) -> Vec<bool> {
    (hapcal_kinematics::joint_motions(tree.tips()).iter())
        .map(|m| *m == Some(hapcal_kinematics::Motion::Translation))
        .collect()
}

/// Robot of a device file (a D-H, modified D-H or placement chain; a placement tree with
/// `[[branch]]` rows, one tip per path).
///
/// # Errors
/// A device whose chain does not compile.
pub fn robot_from_device(device: &hapcal_io::Device) -> Result<Robot> {
    let tree = device.tree()?;
    Ok(Robot {
        joint_names: tree.joint_names().to_vec(),
        prismatic: device.prismatic_joints(),
        limits: device.joint_limits(),
        masses: Vec::new(),
        held_joints: Vec::new(),
        load_tips: Vec::new(),
        gravity_dir: -Vector3::z(),
        tree,
    })
}

/// Reads the measurement files of `robot` ([`hapcal_io::read_measurement_file`]).
///
/// # Errors
/// Unreadable files (file, line, column), a file without markers.
pub fn load_tables(
    paths: &[std::path::PathBuf],
    robot: &Robot,
    units: &Units,
) -> Result<Vec<MeasurementTable>> {
    Ok(load_tables_every(paths, robot, units, 1)?.0)
}

/// Reads the measurement files of `robot` as [`load_tables`] does (every row read and
/// checked), keeping every `stride`-th row of each file from its first
/// ([`MeasurementTable::read_every`]): a sample of a long file read in the memory of the sample.
/// Returns the tables and each file's number of data rows.
///
/// # Errors
/// As [`load_tables`].
pub fn load_tables_every(
    paths: &[std::path::PathBuf],
    robot: &Robot,
    units: &Units,
    stride: usize,
) -> Result<(Vec<MeasurementTable>, Vec<usize>)> {
    let schema = JointSchema {
        names: &robot.joint_names,
        prismatic: &robot.prismatic,
        limits: &robot.limits,
    };
    paths
        .iter()
        .map(|p| {
            let (t, n_rows) = MeasurementTable::read_every(p, &schema, units, stride)
                .with_context(|| format!("reading measurements {}", p.display()))?;
            if t.n_markers == 0 && !t.has_distance {
                bail!(
                    "{}: no measurement columns: expected marker positions (x,y,z or \
                     x1,y1,z1,…) or a distance (distance_m, distance or d); the columns are {}",
                    p.display(),
                    t.ignored_columns.join(", ")
                );
            }
            Ok((t, n_rows))
        })
        .collect()
}

/// The joint configurations of a workspace file (`--workspace`): a CSV with the robot's joint
/// columns as the measurement files have them (q1..qn or the joint names; other columns
/// ignored), rad or m for a prismatic joint.
///
/// # Errors
/// An unreadable or malformed file (file, line, column), or one without a row.
pub fn workspace_configurations(
    path: &std::path::Path,
    robot: &Robot,
    units: &Units,
) -> Result<Vec<Vec<f64>>> {
    let schema = JointSchema {
        names: &robot.joint_names,
        prismatic: &robot.prismatic,
        limits: &robot.limits,
    };
    let t = hapcal_io::read_measurement_file(path, &schema, units)
        .with_context(|| format!("reading the workspace {}", path.display()))?;
    if t.rows.is_empty() {
        bail!(
            "{}: the workspace file has no row: expected one joint configuration per row",
            path.display()
        );
    }
    Ok(t.rows.into_iter().map(|r| r.q.to_vec()).collect())
}

/// Reads one log of a haptic device.
fn read_log(path: &Path, device: &Device, units: &Units) -> Result<NamedLog> {
    if !path.is_file() {
        bail!(
            "{}: a haptic device is calibrated from log files (CSV with q1..q{}, distance_m, \
             ext1..ext4), not a folder",
            path.display(),
            device.n_joints()
        );
    }
    let log = hapcal_io::read_log_in(path, device, units)
        .with_context(|| format!("reading log {}", path.display()))?;
    Ok(NamedLog {
        name: file_stem(path),
        path: path.to_path_buf(),
        rows: log.rows,
        warnings: log.warnings,
    })
}

/// A file's stem, or the whole path when it has none.
fn file_stem(path: &Path) -> String {
    path.file_stem().map_or_else(
        || path.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    )
}

/// One measured data set: a socket placement or a distance log.
#[derive(Clone, Debug)]
pub enum DataSet {
    /// MUKCa-style placement: rows per socket.
    Sockets(SocketPlacement),
    /// Distance log (docs/design.md §5): joint readings and cable distance per row.
    Distances {
        /// Name (file stem).
        name: String,
        /// The file read.
        file: PathBuf,
        /// 1-based line of each row in `file`.
        lines: Vec<u64>,
        /// Joint readings per row, rad.
        q: Vec<Vec<f64>>,
        /// Distance per row, m.
        distance_m: Vec<f64>,
    },
}

impl DataSet {
    pub(crate) fn name(&self) -> &str {
        match self {
            DataSet::Sockets(p) => &p.name,
            DataSet::Distances { name, .. } => name,
        }
    }
}

/// Reads the device: a TOML device file, or a URDF imported with `tip`.
///
/// # Errors
/// Whatever `hapcal-io` reports, with the path as context.
pub fn load_device(path: &Path, tip: &str) -> Result<Device> {
    let is_urdf = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    if is_urdf {
        hapcal_io::import_urdf(path, tip).with_context(|| format!("importing {}", path.display()))
    } else {
        hapcal_io::read_device(path).with_context(|| format!("reading device {}", path.display()))
    }
}

/// Reads the device of a tree: a TOML device file, or a URDF imported with the tip `tip` and
/// the further tips `tips` ([`hapcal_io::import_urdf_tree`]: one `[[branch]]` per further tip).
///
/// # Errors
/// Whatever `hapcal-io` reports, with the path as context.
pub fn load_device_tips(path: &Path, tip: &str, tips: &[String]) -> Result<Device> {
    let is_urdf = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"));
    if is_urdf {
        let all: Vec<String> = std::iter::once(tip.to_owned())
            .chain(tips.iter().cloned())
            .collect();
        hapcal_io::import_urdf_tree(path, &all)
            .with_context(|| format!("importing {}", path.display()))
    } else {
        load_device(path, tip)
    }
}

/// `Err` if the CSV file `path` (by extension) shows on its first line why no reader can take
/// it: cells separated by semicolons or tabs instead of commas, or numbers where the header
/// row naming the columns belongs. Anything else passes (the readers report the rest), and so
/// does a path that is not a readable CSV file.
///
/// # Errors
/// `{path}:1:1: …` naming the separator found, or the first cell of a missing header.
pub fn check_csv_header(path: &Path) -> Result<()> {
    let is_csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if !is_csv || !path.is_file() {
        return Ok(());
    }
    let mut first = String::new();
    let read = std::fs::File::open(path)
        .and_then(|f| std::io::BufRead::read_line(&mut std::io::BufReader::new(f), &mut first));
    if read.is_err() {
        return Ok(());
    }
    let first = first.trim_start_matches('\u{feff}').trim();
    if !first.contains(',') {
        for (separator, name) in [(';', "semicolons"), ('\t', "tabs")] {
            if first.contains(separator) {
                bail!(
                    "{}:1:1: expected comma-separated columns, found cells separated by {name}: \
                     measurement files and logs are CSV with a comma between cells and a point \
                     as the decimal mark",
                    path.display()
                );
            }
        }
    }
    let cells: Vec<&str> = first.split(',').map(str::trim).collect();
    if !first.is_empty() && cells.iter().all(|c| c.parse::<f64>().is_ok()) {
        bail!(
            "{}:1:1: the first line holds numbers ({} …), not column names: the header row is \
             missing; a measurement file starts with one naming its columns (the joints as \
             q1..qn or by name, markers as x1,y1,z1,…, a distance as distance_m)",
            path.display(),
            cells.first().copied().unwrap_or_default()
        );
    }
    Ok(())
}

/// Whether `path` holds measurements of an external instrument for the marker workflow: an
/// industrial_calibration YAML, or a CSV whose header has marker columns (`x`, `x1`), or, with
/// `distances` (a device without a cable encoder of its own, so the anchor is unknown), a
/// distance column (`distance_m`, `distance`, `d`).
pub fn is_marker_file(path: &std::path::Path, distances: bool) -> bool {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("yaml" | "yml") => true,
        // The header alone decides; the file is read in full once, by its reader.
        Some("csv") => csv_columns(path).iter().any(|c| match c.as_str() {
            "x" | "x1" => true,
            "distance_m" | "distance" | "d" => distances,
            _ => false,
        }),
        _ => false,
    }
}

/// The column names of a CSV file's header (trimmed, a byte-order mark dropped as the readers
/// drop it); empty for another file or one that cannot be read (its reader reports that).
pub(crate) fn csv_columns(path: &Path) -> Vec<String> {
    let is_csv = (path.extension()).is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let mut header = String::new();
    let read = std::fs::File::open(path)
        .and_then(|f| std::io::BufRead::read_line(&mut std::io::BufReader::new(f), &mut header));
    if !is_csv || read.is_err() {
        return Vec::new();
    }
    (header.trim_start_matches('\u{feff}').split(','))
        .map(|c| c.trim().to_owned())
        .collect()
}

/// Reads data sets: MUKCa placement or run folders, or hapcal log CSV files, with their
/// readings in `units` (file-wide units and column edits; the columns of socket files are
/// `q1..qn`).
///
/// # Errors
/// Missing files, malformed rows (file, line, column), joint-count mismatch, an edit of
/// `units` naming a column the file does not have or giving a unit of the wrong kind.
pub fn load_data(paths: &[PathBuf], device: &Device, units: &Units) -> Result<Vec<DataSet>> {
    let mut sets = Vec::new();
    for path in paths {
        if path.is_file() {
            let log = hapcal_io::read_log_in(path, device, units)
                .with_context(|| format!("reading log {}", path.display()))?;
            sets.push(DataSet::Distances {
                name: file_stem(path),
                file: path.clone(),
                lines: log.rows.iter().map(|r| r.line).collect(),
                q: log.rows.iter().map(|r| r.q.clone()).collect(),
                distance_m: log.rows.iter().map(|r| r.distance_m).collect(),
            });
        } else {
            let placements =
                hapcal_io::read_mukca_paths_in(std::slice::from_ref(path), device, units)
                    .with_context(|| format!("reading measurements in {}", path.display()))?;
            for placement in &placements {
                check_sockets(placement)?;
            }
            sets.extend(placements.into_iter().map(DataSet::Sockets));
        }
    }
    Ok(sets)
}

/// Refuses a placement that cannot determine its sockets: a socket whose rows are all one joint
/// configuration (its position takes that one; the copies fit exactly and σ would shrink
/// towards 0), or two sockets with the same readings row for row (a copied file).
///
/// # Errors
/// The socket file and what is wrong with it.
pub fn check_sockets(placement: &SocketPlacement) -> Result<()> {
    for socket in &placement.sockets {
        let distinct: std::collections::HashSet<Vec<u64>> = (socket.q.iter())
            .map(|q| q.iter().map(|v| (v + 0.0).to_bits()).collect())
            .collect();
        if socket.q.len() > 1 && distinct.len() == 1 {
            bail!(
                "{}: the {} rows are copies of one joint configuration: a socket's position \
                 (3 coordinates) takes that one, and the copies add no information; measure \
                 at least 2 distinct configurations per socket",
                socket.file.display(),
                socket.q.len()
            );
        }
    }
    for (b, later) in placement.sockets.iter().enumerate() {
        if let Some(earlier) = placement.sockets[..b].iter().find(|s| s.q == later.q) {
            bail!(
                "{} repeats {} row for row: two sockets are two points and cannot give the \
                 same joint readings (a copied file?)",
                later.file.display(),
                earlier.file.display()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simulated humanoid's 550-row recording read for at most 100 rows: one row in
    /// `s` of the file from its first, with its line, and a warning that says so.
    #[test]
    fn a_marker_file_longer_than_read_rows_is_read_one_row_in_s() {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/sim-humanoid");
        let mut plan = Plan::bundled_default();
        plan.device = root.join("humanoid.urdf");
        plan.tip = "l_hand".to_owned();
        plan.tips = vec!["r_hand".to_owned()];
        plan.data = vec![root.join("mocap.csv")];
        plan.test = Vec::new();
        let device = load_device_tips(&plan.device, &plan.tip, &plan.tips).expect("the URDF");
        let mut tables = |read_rows| {
            plan.read_rows = read_rows;
            match load(&plan, &device).expect("the recording") {
                Data::Measurements { train, .. } => train,
                _ => panic!("a marker file is read as measurements"),
            }
        };
        let every = tables(None);
        let sampled = tables(Some(100));
        let (every, sampled) = (&every[0], &sampled[0]);
        assert_eq!(every.rows.len(), 550);
        let stride = every.rows.len().div_ceil(100);
        assert_eq!(sampled.rows.len(), every.rows.len().div_ceil(stride));
        for (k, row) in sampled.rows.iter().enumerate() {
            let whole = &every.rows[k * stride];
            assert_eq!(
                (row.line, &row.q),
                (whole.line, &whole.q),
                "sampled row {k}"
            );
        }
        let said = format!(
            "550 rows, of which one in {stride} ({} rows",
            sampled.rows.len()
        );
        assert!(
            sampled.warnings.iter().any(|w| w.contains(&said)),
            "{:?}",
            sampled.warnings
        );
        assert!(!every.warnings.iter().any(|w| w.contains("of which one in")));
    }
}
