//! MUKCa real-robot recordings: `hole_0.csv`, `hole_1.csv`, … per tool placement.
//!
//! Layout (Franzese et al., "MUKCa", arXiv:2503.12584; `fixtures/mukca/README.md`): a
//! placement folder holds one file per socket, `hole_{k}.csv`, no header, one row per
//! configuration, one column per joint angle in rad. A run folder holds placement folders.

use std::path::{Path, PathBuf};

use crate::Error;
use crate::columns::{ColumnInfo, Quantity, Units, conversions, si_of};
use crate::device::{Device, JointSpec};
use crate::measure::{Reach, reach};
use crate::table::{Repeats, Table, check_separator, number};

/// One tool placement: the socket recordings of one folder.
#[derive(Clone, Debug, PartialEq)]
pub struct SocketPlacement {
    /// The folder's name (`front`, `left_back`, …).
    pub name: String,
    /// Socket `k` is `sockets[k]`, read from `hole_{k}.csv`.
    pub sockets: Vec<SocketSamples>,
    /// Things worth telling the user that did not stop the reading (readings slightly past a
    /// joint's limits, repeated rows), each starting with `file:line:`.
    pub warnings: Vec<String>,
}

/// The configurations recorded with the ball in one socket.
#[derive(Clone, Debug, PartialEq)]
pub struct SocketSamples {
    /// The file read.
    pub file: PathBuf,
    /// Joint angles, rad: `q[row][joint]`, rows × n_joints.
    pub q: Vec<Vec<f64>>,
    /// 1-based line of each row in `file`.
    pub line_numbers: Vec<u64>,
}

/// Reads the socket files `hole_0.csv` … `hole_k.csv` of one placement folder.
///
/// Each row must hold `n_joints` finite numbers. Joint limits are *not* checked here (use
/// [`read_mukca_placement_for`] with the device to check them).
///
/// # Errors
///
/// [`Error::Io`] if the folder or a file cannot be read; [`Error::NoSockets`] if there is
/// no `hole_*.csv`; [`Error::SocketGap`] if the numbers are not 0, 1, … without gaps;
/// [`Error::JointCount`] if the first row of a file does not have `n_joints` fields,
/// [`Error::Ragged`] if a later one does not; [`Error::Separator`] for a file separated by
/// semicolons, tabs or spaces; [`Error::NotANumber`], [`Error::NotFinite`] for a bad cell
/// (file:line:column, column = field number); [`Error::TooFewRows`] for a file without rows;
/// [`Error::Csv`] for invalid UTF-8.
pub fn read_mukca_placement(dir: &Path, n_joints: usize) -> Result<SocketPlacement, Error> {
    read_placement(dir, n_joints, &[], &Units::default())
}

/// Reads one placement folder as [`read_mukca_placement`] does for `device`'s joints, and
/// checks every reading against the device's joint limits by the rule of measurement files
/// ([`JOINT_LIMIT_SLACK`](crate::JOINT_LIMIT_SLACK)): a reading past a limit by less than
/// that fraction of the joint's range is kept, with one warning per file in
/// [`SocketPlacement::warnings`] (real recordings may exceed a URDF's limits slightly); a
/// reading further out is an error. Rows that repeat an earlier row of the same file are kept,
/// with one warning naming the first and how many there are.
///
/// # Errors
///
/// As [`read_mukca_placement`]; [`Error::OutsideJointRange`] (file:line:column, the reading
/// and the limits) for a reading further past its limits.
pub fn read_mukca_placement_for(dir: &Path, device: &Device) -> Result<SocketPlacement, Error> {
    read_placement(dir, device.n_joints(), &device.joints, &Units::default())
}

/// Reads MUKCa placements from `paths`, each a placement folder (it holds `hole_*.csv`)
/// or a run folder whose subfolders holding `hole_*.csv` are placements, taken in name
/// order (other subfolders are skipped). Joint limits are not checked (see
/// [`read_mukca_paths_for`]).
///
/// # Errors
///
/// As [`read_mukca_placement`]; [`Error::NoSockets`] for a run folder without any placement.
pub fn read_mukca_paths(paths: &[PathBuf], n_joints: usize) -> Result<Vec<SocketPlacement>, Error> {
    read_paths(paths, n_joints, &[], &Units::default())
}

/// Reads MUKCa placements from `paths` as [`read_mukca_paths`] does, with every reading checked
/// against `device`'s joint limits as [`read_mukca_placement_for`] checks them.
///
/// # Errors
///
/// As [`read_mukca_placement_for`]; [`Error::NoSockets`] for a run folder without any
/// placement.
pub fn read_mukca_paths_for(
    paths: &[PathBuf],
    device: &Device,
) -> Result<Vec<SocketPlacement>, Error> {
    read_paths(paths, device.n_joints(), &device.joints, &Units::default())
}

/// Reads MUKCa placements from `paths` as [`read_mukca_paths_for`] does, with the readings in
/// `units`: every column in [`Units::angle`], and the edits of [`Units::columns`], which name
/// the columns `q1..qn` (chain order; the files have no header) or by the device's joint
/// names. Readings are converted to rad before the limit check.
///
/// # Errors
///
/// As [`read_mukca_paths_for`]; [`Error::UnknownColumn`] (the socket file, line 1, the
/// columns `q1..qn`) for an edit naming another column, [`Error::ColumnUnitKind`] for a length
/// unit.
pub fn read_mukca_paths_in(
    paths: &[PathBuf],
    device: &Device,
    units: &Units,
) -> Result<Vec<SocketPlacement>, Error> {
    read_paths(paths, device.n_joints(), &device.joints, units)
}

/// [`read_mukca_paths`] with the limits of `joints` checked (none if `joints` is empty).
fn read_paths(
    paths: &[PathBuf],
    n_joints: usize,
    joints: &[JointSpec],
    units: &Units,
) -> Result<Vec<SocketPlacement>, Error> {
    let mut placements = Vec::new();
    for path in paths {
        if !socket_numbers(path)?.is_empty() {
            placements.push(read_placement(path, n_joints, joints, units)?);
            continue;
        }
        let mut subdirs = Vec::new();
        for entry in std::fs::read_dir(path).map_err(|e| Error::io(path, e))? {
            let entry = entry.map_err(|e| Error::io(path, e))?;
            let sub = entry.path();
            if sub.is_dir() && !socket_numbers(&sub)?.is_empty() {
                subdirs.push(sub);
            }
        }
        if subdirs.is_empty() {
            return Err(Error::NoSockets { dir: path.clone() });
        }
        subdirs.sort();
        for sub in subdirs {
            placements.push(read_placement(&sub, n_joints, joints, units)?);
        }
    }
    Ok(placements)
}

/// [`read_mukca_placement`] with the limits of `joints` checked (none if `joints` is empty).
fn read_placement(
    dir: &Path,
    n_joints: usize,
    joints: &[JointSpec],
    units: &Units,
) -> Result<SocketPlacement, Error> {
    let mut numbers = socket_numbers(dir)?;
    if numbers.is_empty() {
        return Err(Error::NoSockets {
            dir: dir.to_path_buf(),
        });
    }
    numbers.sort_unstable();
    if let Some(missing) = (0..)
        .zip(&numbers)
        .find_map(|(k, n)| (k != *n).then_some(k))
    {
        return Err(Error::SocketGap {
            dir: dir.to_path_buf(),
            missing: format!("hole_{missing}.csv"),
        });
    }
    let mut sockets = Vec::with_capacity(numbers.len());
    let mut warnings = Vec::new();
    for k in &numbers {
        let (socket, mut w) =
            read_socket(&dir.join(format!("hole_{k}.csv")), n_joints, joints, units)?;
        sockets.push(socket);
        warnings.append(&mut w);
    }
    let name = dir.file_name().map_or_else(
        || dir.to_string_lossy().into_owned(),
        |n| n.to_string_lossy().into_owned(),
    );
    Ok(SocketPlacement {
        name,
        sockets,
        warnings,
    })
}

/// The `k` of every `hole_{k}.csv` in `dir` (not `hole_0_pose.csv`), unsorted.
fn socket_numbers(dir: &Path) -> Result<Vec<usize>, Error> {
    let mut numbers = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let name = entry.file_name();
        let Some(digits) = name
            .to_str()
            .and_then(|n| n.strip_prefix("hole_"))
            .and_then(|n| n.strip_suffix(".csv"))
        else {
            continue;
        };
        let canonical = !digits.is_empty()
            && digits.bytes().all(|b| b.is_ascii_digit())
            && (digits == "0" || !digits.starts_with('0'));
        if let Some(k) = canonical.then(|| digits.parse().ok()).flatten() {
            numbers.push(k);
        }
    }
    Ok(numbers)
}

/// One socket file and its warnings; readings checked against `joints`' limits unless
/// `joints` is empty.
fn read_socket(
    path: &Path,
    n_joints: usize,
    joints: &[JointSpec],
    units: &Units,
) -> Result<(SocketSamples, Vec<String>), Error> {
    let infos: Vec<ColumnInfo> = (0..n_joints)
        .map(|j| {
            let name = format!("q{}", j + 1);
            let joint = joints.get(j).map(|s| s.name.as_str());
            ColumnInfo::joint(&name, j, joint, Quantity::Angle)
        })
        .collect();
    let conversion = conversions(path, 1, &infos, units)?;
    let mut table = Table::open(path)?;
    let mut q = Vec::new();
    let mut line_numbers = Vec::new();
    let mut repeats = Repeats::default();
    // The first reading past its limits within the slack, and how many there are.
    let mut outside: Option<String> = None;
    let mut n_outside = 0usize;
    while let Some((line, record)) = table.next_record()? {
        if record.len() != n_joints {
            check_separator(path, line, record, n_joints)?;
            return Err(if q.is_empty() {
                Error::JointCount {
                    path: path.to_path_buf(),
                    line,
                    expected: n_joints,
                    found: record.len(),
                }
            } else {
                Error::Ragged {
                    path: path.to_path_buf(),
                    line,
                    expected: n_joints,
                    found: record.len(),
                }
            });
        }
        let raw_of = |c: usize| {
            let cell = record.get(c).unwrap_or("");
            number(path, line, c as u64 + 1, &format!("q{}", c + 1), cell)
        };
        let row = (0..record.len())
            .map(|c| si_of(&conversion, c, &raw_of))
            .collect::<Result<Vec<f64>, _>>()?;
        for (j, (&v, spec)) in row.iter().zip(joints).enumerate() {
            let limits = (spec.lower_rad, spec.upper_rad);
            match reach(v, limits) {
                Reach::Within => {}
                Reach::Slack => {
                    n_outside += 1;
                    outside.get_or_insert_with(|| {
                        format!(
                            "{}:{line}:{}: joint {:?} = {v} rad is outside its limits [{}, {}] rad",
                            path.display(),
                            j + 1,
                            spec.name,
                            limits.0,
                            limits.1
                        )
                    });
                }
                Reach::Outside => {
                    return Err(Error::OutsideJointRange {
                        path: path.to_path_buf(),
                        line,
                        column: j as u64 + 1,
                        joint: spec.name.clone(),
                        value: v,
                        min: limits.0,
                        max: limits.1,
                        unit: "rad",
                    });
                }
            }
        }
        repeats.see(row.iter().copied(), line);
        q.push(row);
        line_numbers.push(line);
    }
    if q.is_empty() {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    }
    let mut warnings: Vec<String> = outside
        .map(|first| match n_outside {
            1 => format!("{first}; such readings are used as they are"),
            n => format!(
                "{first} (and {} more readings outside their joint's limits); such readings are used as they are",
                n - 1
            ),
        })
        .into_iter()
        .collect();
    warnings.extend(repeats.warning(path));
    Ok((
        SocketSamples {
            file: path.to_path_buf(),
            q,
            line_numbers,
        },
        warnings,
    ))
}
