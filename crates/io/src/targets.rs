//! Targets files: the tip positions (and orientations) a compensation is asked to reach, one
//! per row, with the joint commands to start from if the file gives them.

use std::path::Path;

use crate::Error;
use crate::measure::JointSchema;
use crate::table::Table;

/// One row of a targets file.
#[derive(Clone, Debug, PartialEq)]
pub struct TargetRow {
    /// The row's 1-based line in the file.
    pub line: u64,
    /// Target position `[x, y, z]`, m.
    pub position_m: [f64; 3],
    /// Target orientation as a quaternion `[w, x, y, z]`, as the file gives it (its norm
    /// within 10⁻³ of 1: normalise it before use), if the file has the columns `qw, qx, qy, qz`.
    pub orientation_wxyz: Option<[f64; 4]>,
    /// The joint commands to start from (rad, m for a prismatic joint), in the schema's joint
    /// order, if the file has one column per joint; each within its joint's limits.
    pub start: Option<Vec<f64>>,
}

/// The columns of the header: where `x, y, z`, the quaternion and the joints are.
struct Header {
    /// The column names, trimmed.
    names: Vec<String>,
    /// Columns of `x, y, z`.
    position: [usize; 3],
    /// Columns of `qw, qx, qy, qz`, if present.
    orientation: Option<[usize; 4]>,
    /// Columns of the joints in the schema's order, if present.
    starts: Option<Vec<usize>>,
}

/// Whether a record is no row: a blank line (one empty field) or a comment (`#`).
fn skipped(record: &csv::StringRecord) -> bool {
    let first = record.get(0).unwrap_or_default();
    first.starts_with('#') || (record.len() == 1 && first.is_empty())
}

/// The [`Error::Targets`] at `line` (`column`; 0 for none) of `path`.
fn targets_error(path: &Path, line: u64, column: u64, message: String) -> Error {
    Error::Targets {
        path: path.to_path_buf(),
        line,
        column,
        message,
    }
}

/// Reads the header of a targets file at `line`.
fn header(
    path: &Path,
    line: u64,
    record: &csv::StringRecord,
    joints: &JointSchema<'_>,
) -> Result<Header, Error> {
    let names: Vec<String> = record.iter().map(str::to_owned).collect();
    let column = |name: &str| names.iter().position(|n| n == name);
    let joint_list = joints.names.join(", ");
    let mut position = [0; 3];
    for (slot, name) in position.iter_mut().zip(["x", "y", "z"]) {
        *slot = column(name).ok_or_else(|| {
            targets_error(
                path,
                line,
                0,
                format!(
                    "no column {name:?} in the header: expected x, y, z (m) [, qw, qx, qy, qz] \
                     [, one column per joint: {joint_list}]"
                ),
            )
        })?;
    }
    let quaternion = ["qw", "qx", "qy", "qz"].map(column);
    let orientation = match quaternion {
        [None, None, None, None] => None,
        [Some(w), Some(x), Some(y), Some(z)] => Some([w, x, y, z]),
        _ => {
            return Err(targets_error(
                path,
                line,
                0,
                "an orientation needs all four columns qw, qx, qy, qz".to_owned(),
            ));
        }
    };
    let found: Vec<Option<usize>> = joints.names.iter().map(|j| column(j)).collect();
    let n_joint_columns = found.iter().flatten().count();
    let starts = match n_joint_columns {
        0 => None,
        n if n == found.len() => Some(found.iter().flatten().copied().collect()),
        _ => {
            let missing: Vec<&str> = (joints.names.iter().zip(&found))
                .filter(|(_, c)| c.is_none())
                .map(|(n, _)| n.as_str())
                .collect();
            return Err(targets_error(
                path,
                line,
                0,
                format!(
                    "start commands need one column per joint; missing {}",
                    missing.join(", ")
                ),
            ));
        }
    };
    let known = 3 + orientation.map_or(0, |o| o.len()) + n_joint_columns;
    if known != names.len() {
        let unknown: Vec<&str> = (names.iter())
            .filter(|n| {
                !["x", "y", "z", "qw", "qx", "qy", "qz"].contains(&n.as_str())
                    && !joints.names.contains(n)
            })
            .map(String::as_str)
            .collect();
        return Err(targets_error(
            path,
            line,
            0,
            format!(
                "unknown or repeated columns {}: expected x, y, z, qw, qx, qy, qz and the joints \
                 {joint_list}",
                unknown.join(", ")
            ),
        ));
    }
    Ok(Header {
        names,
        position,
        orientation,
        starts,
    })
}

/// `Ok` when every start command `q` (rad, m for a prismatic joint, in the schema's joint
/// order) lies within its joint's limits; else the joints outside, with their limits, in
/// words, and when the values read as degrees lie within them, that they look like degrees.
fn check_start(q: &[f64], joints: &JointSchema<'_>) -> Result<(), String> {
    let limits = |j: usize| {
        joints
            .limits
            .get(j)
            .copied()
            .unwrap_or((f64::MIN, f64::MAX))
    };
    let prismatic = |j: usize| joints.prismatic.get(j) == Some(&true);
    let within = |j: usize, v: f64| {
        let (lo, hi) = limits(j);
        (lo..=hi).contains(&v)
    };
    let outside: Vec<usize> = (0..q.len()).filter(|&j| !within(j, q[j])).collect();
    if outside.is_empty() {
        return Ok(());
    }
    let mut words: Vec<String> = (outside.iter())
        .map(|&j| {
            let (lo, hi) = limits(j);
            let unit = if prismatic(j) { "m" } else { "rad" };
            let name = joints.names.get(j).map_or("?", String::as_str);
            format!("{name} = {} {unit}, limits [{lo}, {hi}] {unit}", q[j])
        })
        .collect();
    // Degrees read as radians: every revolute start within its limits once converted, and
    // some beyond a turn's worth of radians no arm reaches.
    let revolute: Vec<usize> = (0..q.len()).filter(|&j| !prismatic(j)).collect();
    let in_degrees = (revolute.iter()).all(|&j| within(j, q[j].to_radians()));
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

/// Reads a targets file: a CSV file with a header naming the columns `x, y, z` (m), optionally
/// `qw, qx, qy, qz` (a unit quaternion) and one column per joint of
/// `joints` (the start commands, rad or m); blank lines and lines starting with `#` are
/// skipped.
///
/// # Errors
/// [`Error::Targets`] naming the file, the line and what was expected: no header, a missing
/// or unknown column, a row of another width than the header, a quaternion whose norm is not
/// 1 (within 10⁻³), a start command outside its joint's limits (saying when the values look
/// like degrees); [`Error::NotANumber`] for a cell that is not a finite number (file, line,
/// column, column name, the text found); [`Error::Io`] or [`Error::Csv`] for an unreadable file.
pub fn read_targets(path: &Path, joints: &JointSchema<'_>) -> Result<Vec<TargetRow>, Error> {
    let mut table = Table::open(path)?;
    let mut head: Option<Header> = None;
    let mut rows = Vec::new();
    while let Some((line, record)) = table.next_record()? {
        if skipped(record) {
            continue;
        }
        let Some(h) = &head else {
            head = Some(header(path, line, record, joints)?);
            continue;
        };
        if record.len() != h.names.len() {
            return Err(targets_error(
                path,
                line,
                0,
                format!(
                    "{} values, the header has {} columns",
                    record.len(),
                    h.names.len()
                ),
            ));
        }
        let value = |c: usize| -> Result<f64, Error> {
            let cell = record.get(c).unwrap_or_default();
            let name = h.names.get(c).map_or("", String::as_str);
            let parsed = cell.parse::<f64>().ok().filter(|v| v.is_finite());
            parsed.ok_or_else(|| Error::NotANumber {
                path: path.to_path_buf(),
                line,
                column: c as u64 + 1,
                name: name.to_owned(),
                found: cell.to_owned(),
            })
        };
        let [x, y, z] = h.position;
        let position_m = [value(x)?, value(y)?, value(z)?];
        let orientation_wxyz = match h.orientation {
            None => None,
            Some([w, x, y, z]) => {
                let q = [value(w)?, value(x)?, value(y)?, value(z)?];
                let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                if (norm - 1.0).abs() > 1e-3 {
                    return Err(targets_error(
                        path,
                        line,
                        0,
                        format!(
                            "the quaternion (qw, qx, qy, qz) = {q:?} has norm {norm}, expected a \
                             unit quaternion"
                        ),
                    ));
                }
                Some(q)
            }
        };
        let start = match &h.starts {
            None => None,
            Some(cols) => {
                let q = cols
                    .iter()
                    .map(|&c| value(c))
                    .collect::<Result<Vec<_>, _>>()?;
                check_start(&q, joints).map_err(|why| {
                    targets_error(
                        path,
                        line,
                        0,
                        format!("a start command outside the robot's limits: {why}"),
                    )
                })?;
                Some(q)
            }
        };
        rows.push(TargetRow {
            line,
            position_m,
            orientation_wxyz,
            start,
        });
    }
    if head.is_none() {
        return Err(targets_error(
            path,
            0,
            0,
            "no header line: expected columns x, y, z [, qw, qx, qy, qz] [, joints]".to_owned(),
        ));
    }
    Ok(rows)
}
