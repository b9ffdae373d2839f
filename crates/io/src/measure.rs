//! Measurement files of external instruments: marker positions, full poses and distances
//! against joint readings (CSV), and the observations of ROS-Industrial `industrial_calibration`
//! (YAML).

use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, UnitQuaternion};
use serde::Deserialize;

use crate::Error;
use crate::columns::{ColumnInfo, Quantity, Units, conversions, si_of};
use crate::table::{Frozen, Repeats, Table, check_separator, first_duplicate, metres, number};

/// What a measurement file's joint columns must match: the device's joints in chain order.
#[derive(Clone, Copy, Debug)]
pub struct JointSchema<'a> {
    /// Joint names (`n` entries).
    pub names: &'a [String],
    /// Whether each joint is prismatic (its reading a length); `n` entries.
    pub prismatic: &'a [bool],
    /// Each joint's range (rad, m for a prismatic joint), inclusive; `n` entries.
    pub limits: &'a [(f64, f64)],
}

/// One marker seen in one row.
#[derive(Clone, Debug, PartialEq)]
pub struct MarkerSample {
    /// The marker's index, 0-based (`x1,y1,z1` is marker 0).
    pub marker: usize,
    /// Its position in the instrument frame, m.
    pub position_m: [f64; 3],
    /// Its orientation in the instrument frame, unit quaternion `[w, x, y, z]`, if the file
    /// has orientation columns for it.
    pub rotation: Option<[f64; 4]>,
}

/// One row of a measurement file, in SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct MeasuredRow {
    /// 1-based line in the file (for YAML, the line of the observation's key).
    pub line: u64,
    /// Joint readings in chain order, rad (m for a prismatic joint).
    pub q: Vec<f64>,
    /// Time, s, if the file has a `t` or `t_s` column.
    pub t_s: Option<f64>,
    /// The markers seen in this row (a marker whose cells are all empty is not seen).
    pub markers: Vec<MarkerSample>,
    /// Distance from the anchor, m, if the file has a distance column and the cell is not
    /// empty.
    pub distance_m: Option<f64>,
}

impl MeasuredRow {
    /// The row's joint readings and measured values (not its time or line) as the reader
    /// compares rows to find repeats: bit patterns, −0 as +0, an absent value as NaN. Two rows
    /// with equal keys are copies of one another (the reader's warning about repeated rows).
    pub fn repeat_key(&self) -> Vec<u64> {
        crate::table::repeat_key(measured_values(self))
    }
}

/// A measurement file, read and converted to SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct MeasurementTable {
    /// The file's stem (`calibration` for `calibration.csv`).
    pub name: String,
    /// The file.
    pub path: PathBuf,
    /// The data rows, in file order.
    pub rows: Vec<MeasuredRow>,
    /// Things worth telling the user that did not stop the reading (joint readings slightly
    /// outside their limits), each starting with `file:line:column:`.
    pub warnings: Vec<String>,
    /// Number of markers (the highest marker number in the header).
    pub n_markers: usize,
    /// Whether any marker has orientation columns.
    pub has_orientation: bool,
    /// Whether the file has a distance column.
    pub has_distance: bool,
    /// Header columns that mean nothing to hapcal and were ignored, in file order.
    pub ignored_columns: Vec<String>,
}

/// How far past its limits a joint reading may lie, as a fraction of the joint's range, and
/// still be used (with a warning): real encoders read a little past a description's nominal
/// limits; a reading further out is more likely a wrong unit or column.
pub const JOINT_LIMIT_SLACK: f64 = 0.1;

/// Where a joint reading lies against its limits, by the rule of [`JOINT_LIMIT_SLACK`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Reach {
    /// Within `[min, max]`.
    Within,
    /// Past a limit by at most [`JOINT_LIMIT_SLACK`] of the range: used, with a warning.
    Slack,
    /// Further out (or not a number): an error.
    Outside,
}

/// Where `v` lies against `(min, max)`: the one rule of every reader that checks joint
/// readings (measurement CSV and YAML files, MUKCa socket files).
pub(crate) fn reach(v: f64, (min, max): (f64, f64)) -> Reach {
    let slack = JOINT_LIMIT_SLACK * (max - min);
    if (min..=max).contains(&v) {
        Reach::Within
    } else if (min - slack..=max + slack).contains(&v) {
        Reach::Slack
    } else {
        Reach::Outside
    }
}

/// What a header column holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Column {
    Joint(usize),
    /// Marker (0-based), coordinate 0..3.
    Position(usize, usize),
    /// Marker, quaternion component w, x, y, z.
    Quaternion(usize, usize),
    /// Marker, figaroh roll / pitch / yaw.
    Rpy(usize, usize),
    Distance,
    Time,
    Ignored,
}

/// `name` split into a known stem and a marker number: `x` → (`x`, 0), `x3` → (`x`, 2).
fn marker_column(name: &str, stems: &[&str]) -> Option<(usize, usize)> {
    for (i, stem) in stems.iter().enumerate() {
        let Some(rest) = name.strip_prefix(stem) else {
            continue;
        };
        if rest.is_empty() {
            return Some((i, 0));
        }
        if rest.bytes().all(|b| b.is_ascii_digit()) && !rest.starts_with('0') {
            let k: usize = rest.parse().ok()?;
            return Some((i, k - 1));
        }
    }
    None
}

fn classify(name: &str, schema: &JointSchema<'_>) -> Column {
    if let Some(j) = schema.names.iter().position(|n| n == name) {
        return Column::Joint(j);
    }
    if let Some(digits) = name.strip_prefix('q')
        && !digits.is_empty()
        && digits.bytes().all(|b| b.is_ascii_digit())
        && !digits.starts_with('0')
        && let Ok(k) = digits.parse::<usize>()
        && k <= schema.names.len()
    {
        return Column::Joint(k - 1);
    }
    match name {
        "distance_m" | "distance" | "d" => return Column::Distance,
        "t" | "t_s" => return Column::Time,
        _ => {}
    }
    if let Some((c, k)) = marker_column(name, &["qw", "qx", "qy", "qz"]) {
        return Column::Quaternion(k, c);
    }
    if let Some((c, k)) = marker_column(name, &["phix", "phiy", "phiz"]) {
        return Column::Rpy(k, c);
    }
    if let Some((c, k)) = marker_column(name, &["x", "y", "z"]) {
        return Column::Position(k, c);
    }
    Column::Ignored
}

/// Column indices (0-based) of one marker's cells.
#[derive(Clone, Debug, Default)]
struct MarkerColumns {
    position: [Option<usize>; 3],
    quaternion: [Option<usize>; 4],
    rpy: [Option<usize>; 3],
}

/// The column name of marker `k`'s component `stem` as the file spells it.
fn spelled(stem: &str, k: usize, unnumbered: bool) -> String {
    if unnumbered {
        stem.to_owned()
    } else {
        format!("{stem}{}", k + 1)
    }
}

/// Reads a measurement file: CSV (below) or, for `.yaml` / `.yml`, the observations of
/// ROS-Industrial `industrial_calibration` ([`read_industrial_yaml`]).
///
/// CSV: a header row names the columns, in any order.
///
/// - Joints: `q1..qn` (chain order) or the device's joint names; every joint needs a column.
///   Readings in rad (m for a prismatic joint), or in `units`.
///
/// Every reading is converted to SI by `units` (the file-wide unit of its kind, or its
/// column's edit: unit, reversed sign, offset) before any check on it.
/// - Marker positions in the instrument frame: `x,y,z` (one marker) or `x1,y1,z1,x2,…`.
/// - Marker orientations (optional): a unit quaternion `qw,qx,qy,qz` (or `qw1,…`), or
///   figaroh's `phix,phiy,phiz` (or `phix1,…`): roll, pitch, yaw with
///   `R = Rz(phiz) · Ry(phiy) · Rx(phix)`.
/// - Distance from an anchor (cable encoder, ballbar): `distance_m`, `distance` or `d`, ≥ 0.
/// - Time: `t` or `t_s`, s, non-decreasing.
///
/// Other columns are listed in [`MeasurementTable::ignored_columns`]. A row whose cells of a
/// marker are all empty did not see that marker; an empty distance cell is no distance.
/// Rows that repeat an earlier row's joint readings and measurements (CSV or YAML) are kept,
/// with one warning in [`MeasurementTable::warnings`] naming the first and how many there are.
///
/// # Errors
///
/// [`Error::Io`]; [`Error::TooFewRows`] without a header and a data row;
/// [`Error::DuplicateColumn`]; [`Error::JointColumns`] (the columns expected and found)
/// unless every joint has a column; [`Error::IncompleteMarker`] for a marker whose header
/// lacks a coordinate, or a row that gives some of a marker's cells but not all (file, line,
/// column of the empty cell); [`Error::Ragged`]; [`Error::NotANumber`], [`Error::NotFinite`],
/// [`Error::OutsideJointRange`] for a reading more than [`JOINT_LIMIT_SLACK`] of its joint's
/// range past the limits (a reading closer than that is kept, with one warning in
/// [`MeasurementTable::warnings`]) and [`Error::TimeOrder`], with file:line:column; [`Error::Csv`]
/// (file, line, column named in the message) for a negative distance, a quaternion whose norm
/// is not 1 within 10⁻³, or invalid UTF-8; [`Error::FrozenMeasurement`] (file, header line,
/// column) if the distance column holds the same value (m) in every one of two or more rows,
/// or a marker's `x, y, z` the same position (m) in every one of two or more rows where it is
/// seen: a frozen or disconnected instrument (joint columns may be constant);
/// [`Error::NothingMeasured`] (file, header line, first measurement column) if the file has
/// marker or distance columns but every one of their cells is empty; [`Error::UnknownColumn`],
/// [`Error::ColumnUnitKind`] and [`Error::ColumnNotEditable`] for an edit of
/// [`Units::columns`] that names no column of the file, gives a unit of the wrong kind, or
/// names a column without a unit (time, a quaternion component, an ignored column).
///
/// The header is handled in time linear in its number of columns.
pub fn read_measurement_file(
    path: &Path,
    schema: &JointSchema<'_>,
    units: &Units,
) -> Result<MeasurementTable, Error> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if matches!(ext.as_deref(), Some("yaml" | "yml")) {
        return read_industrial_yaml_in(path, schema, units);
    }
    let n = schema.names.len();
    let mut table = Table::open(path)?;
    let Some((header_line, header)) = table.next_record()? else {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    };
    check_separator(path, header_line, header, n + 1)?;
    let names: Vec<String> = header.iter().map(str::to_owned).collect();
    let columns: Vec<Column> = names.iter().map(|c| classify(c, schema)).collect();
    if let Some(c) = first_duplicate(&names) {
        return Err(Error::DuplicateColumn {
            path: path.to_path_buf(),
            column: c as u64 + 1,
            name: names[c].clone(),
        });
    }
    // Joints: each exactly once (a joint named both `q2` and by name is a duplicate).
    let mut joint_column = vec![None; n];
    for (c, column) in columns.iter().enumerate() {
        if let Column::Joint(j) = *column {
            if joint_column[j].is_some() {
                return Err(Error::DuplicateColumn {
                    path: path.to_path_buf(),
                    column: c as u64 + 1,
                    name: names[c].clone(),
                });
            }
            joint_column[j] = Some(c);
        }
    }
    let missing: Vec<String> = (0..n)
        .filter(|&j| joint_column[j].is_none())
        .map(|j| schema.names[j].clone())
        .collect();
    if !missing.is_empty() {
        return Err(Error::JointColumns {
            path: path.to_path_buf(),
            line: header_line,
            n,
            expected: schema.names.to_vec(),
            missing,
            found: names.clone(),
        });
    }
    let joint_column: Vec<usize> = joint_column.into_iter().flatten().collect();

    // Markers.
    let n_markers = columns
        .iter()
        .filter_map(|c| match *c {
            Column::Position(k, _) | Column::Quaternion(k, _) | Column::Rpy(k, _) => Some(k + 1),
            _ => None,
        })
        .max()
        .unwrap_or(0);
    let unnumbered = names.iter().any(|c| c == "x" || c == "y" || c == "z");
    let incomplete = |k: usize, stem: &str, what: &str| Error::IncompleteMarker {
        path: path.to_path_buf(),
        line: header_line,
        column: names.len() as u64 + 1,
        name: spelled(stem, k, unnumbered),
        marker: k + 1,
        what: what.to_owned(),
    };
    let marker_of = |c: &Column| match *c {
        Column::Position(k, _) | Column::Quaternion(k, _) | Column::Rpy(k, _) => Some(k),
        _ => None,
    };
    if n_markers > names.len() {
        // A marker number past the number of columns (`x123456789012`): some marker below
        // it has no column at all, and a table of that many markers must not be allocated.
        let present: std::collections::HashSet<usize> =
            columns.iter().filter_map(marker_of).collect();
        let k = (0..=names.len())
            .find(|k| !present.contains(k))
            .unwrap_or(0);
        return Err(incomplete(k, "x", "missing from the header"));
    }
    let mut markers = vec![MarkerColumns::default(); n_markers];
    for (c, column) in columns.iter().enumerate() {
        let slot = match *column {
            Column::Position(k, i) => &mut markers[k].position[i],
            Column::Quaternion(k, i) => &mut markers[k].quaternion[i],
            Column::Rpy(k, i) => &mut markers[k].rpy[i],
            _ => continue,
        };
        // `x` and `x1` both name marker 1's x.
        if slot.is_some() {
            return Err(Error::DuplicateColumn {
                path: path.to_path_buf(),
                column: c as u64 + 1,
                name: names[c].clone(),
            });
        }
        *slot = Some(c);
    }
    for (k, m) in markers.iter().enumerate() {
        let sets: [(&[Option<usize>], &[&str]); 3] = [
            (&m.position, &["x", "y", "z"]),
            (&m.quaternion, &["qw", "qx", "qy", "qz"]),
            (&m.rpy, &["phix", "phiy", "phiz"]),
        ];
        for (i, (set, stems)) in sets.iter().enumerate() {
            let given = set.iter().filter(|c| c.is_some()).count();
            if (i == 0 || given > 0)
                && given < set.len()
                && let Some(stem) = set.iter().zip(*stems).find(|(c, _)| c.is_none())
            {
                return Err(incomplete(k, stem.1, "missing from the header"));
            }
        }
        if m.quaternion[0].is_some() && m.rpy[0].is_some() {
            return Err(incomplete(
                k,
                "phix",
                "given beside a quaternion: give one orientation, qw,qx,qy,qz or phix,phiy,phiz",
            ));
        }
    }
    let distance_column = columns.iter().position(|c| *c == Column::Distance);
    let time_column = columns.iter().position(|c| *c == Column::Time);
    if columns.iter().filter(|c| **c == Column::Distance).count() > 1
        || columns.iter().filter(|c| **c == Column::Time).count() > 1
    {
        let (c, _) = (columns.iter().enumerate())
            .filter(|(_, c)| matches!(c, Column::Distance | Column::Time))
            .nth(1)
            .unwrap_or((0, &Column::Ignored));
        return Err(Error::DuplicateColumn {
            path: path.to_path_buf(),
            column: c as u64 + 1,
            name: names[c].clone(),
        });
    }
    let ignored_columns: Vec<String> = (names.iter().zip(&columns))
        .filter(|(_, c)| **c == Column::Ignored)
        .map(|(n, _)| n.clone())
        .collect();

    // Each column's conversion to SI, before any check on its readings.
    let infos: Vec<ColumnInfo> = (names.iter().zip(&columns))
        .map(|(name, column)| match *column {
            Column::Joint(j) => {
                let prismatic = schema.prismatic.get(j).copied().unwrap_or(false);
                let quantity = if prismatic {
                    Quantity::JointLength
                } else {
                    Quantity::Angle
                };
                ColumnInfo::joint(name, j, schema.names.get(j).map(String::as_str), quantity)
            }
            Column::Position(..) | Column::Distance => ColumnInfo::plain(name, Quantity::Length),
            Column::Rpy(..) => ColumnInfo::plain(name, Quantity::Angle),
            Column::Quaternion(..) => {
                ColumnInfo::plain(name, Quantity::Fixed("a quaternion component (no unit)"))
            }
            Column::Time => ColumnInfo::plain(name, Quantity::Fixed("times in s")),
            Column::Ignored => ColumnInfo::plain(
                name,
                Quantity::Fixed("nothing hapcal reads (it is ignored)"),
            ),
        })
        .collect();
    let conversion = conversions(path, header_line, &infos, units)?;
    let mut rows = Vec::new();
    let mut previous_t: Option<f64> = None;
    let mut outside = Vec::new();
    let mut first_outside = String::new();
    let mut repeats = Repeats::default();
    let mut frozen_distance = Frozen::default();
    let mut frozen_position: Vec<Frozen> = (0..n_markers).map(|_| Frozen::default()).collect();
    while let Some((line, record)) = table.next_record()? {
        if record.len() != names.len() {
            check_separator(path, line, record, names.len())?;
            return Err(Error::Ragged {
                path: path.to_path_buf(),
                line,
                expected: names.len(),
                found: record.len(),
            });
        }
        let cell = |c: usize| record.get(c).unwrap_or("");
        let value = |c: usize| number(path, line, c as u64 + 1, &names[c], cell(c));
        let si = |c: usize| si_of(&conversion, c, &value);
        let mut q = Vec::with_capacity(n);
        for (j, &c) in joint_column.iter().enumerate() {
            let prismatic = schema.prismatic.get(j).copied().unwrap_or(false);
            let v = si(c)?;
            if prismatic {
                Error::check_length(path, line, c as u64 + 1, &names[c], v)?;
            }
            let (min, max) = schema
                .limits
                .get(j)
                .copied()
                .unwrap_or((f64::MIN, f64::MAX));
            match reach(v, (min, max)) {
                Reach::Within => {}
                Reach::Slack => {
                    let unit = if prismatic { "m" } else { "rad" };
                    outside.push((line, c, j, v));
                    if outside.len() == 1 {
                        first_outside = format!(
                            "{}:{line}:{}: joint {:?} = {v} {unit} is outside its limits [{min}, {max}] {unit}",
                            path.display(),
                            c + 1,
                            schema.names[j]
                        );
                    }
                }
                Reach::Outside => {
                    return Err(Error::OutsideJointRange {
                        path: path.to_path_buf(),
                        line,
                        column: c as u64 + 1,
                        joint: schema.names[j].clone(),
                        value: v,
                        min,
                        max,
                        unit: if prismatic { "m" } else { "rad" },
                    });
                }
            }
            q.push(v);
        }
        let t_s = time_column.map(value).transpose()?;
        if let (Some(t), Some(before)) = (t_s, previous_t)
            && t < before
        {
            return Err(Error::TimeOrder {
                path: path.to_path_buf(),
                line,
                t_s: t,
                previous_t_s: before,
            });
        }
        previous_t = t_s.or(previous_t);
        let distance_m = match distance_column {
            Some(c) if !cell(c).is_empty() => {
                let d = si(c)?;
                Error::check_length(path, line, c as u64 + 1, &names[c], d)?;
                if d < 0.0 {
                    return Err(Error::Csv {
                        path: path.to_path_buf(),
                        line,
                        message: format!(
                            "column {} ({:?}): expected a distance ≥ 0, found {}",
                            c + 1,
                            names[c],
                            cell(c)
                        ),
                    });
                }
                frozen_distance.see(&[d]);
                Some(d)
            }
            _ => None,
        };
        let mut seen = Vec::new();
        for (k, m) in markers.iter().enumerate() {
            let all: Vec<usize> = (m.position.iter().chain(&m.quaternion).chain(&m.rpy))
                .flatten()
                .copied()
                .collect();
            let empty: Vec<usize> = all
                .iter()
                .copied()
                .filter(|&c| cell(c).is_empty())
                .collect();
            if empty.len() == all.len() {
                continue;
            }
            if let Some(&c) = empty.first() {
                let given: Vec<&str> = (all.iter())
                    .filter(|c| !empty.contains(c))
                    .map(|&c| names[c].as_str())
                    .collect();
                return Err(Error::IncompleteMarker {
                    path: path.to_path_buf(),
                    line,
                    column: c as u64 + 1,
                    name: names[c].clone(),
                    marker: k + 1,
                    what: format!("empty while {} are given", given.join(", ")),
                });
            }
            let mut position_m = [0.0; 3];
            for (p, c) in position_m.iter_mut().zip(m.position.iter().flatten()) {
                *p = si(*c)?;
                Error::check_length(path, line, *c as u64 + 1, &names[*c], *p)?;
            }
            if let Some(frozen) = frozen_position.get_mut(k) {
                frozen.see(&position_m);
            }
            let rotation = if let [Some(w), Some(x), Some(y), Some(z)] = m.quaternion {
                let quaternion = [value(w)?, value(x)?, value(y)?, value(z)?];
                let norm = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
                if (norm - 1.0).abs() > 1e-3 {
                    return Err(Error::Csv {
                        path: path.to_path_buf(),
                        line,
                        message: format!(
                            "columns {}..{}: expected a unit quaternion qw,qx,qy,qz, found one of norm {norm}",
                            w + 1,
                            z + 1
                        ),
                    });
                }
                Some(quaternion.map(|v| v / norm))
            } else if let [Some(r), Some(p), Some(y)] = m.rpy {
                let rotation = UnitQuaternion::from_euler_angles(si(r)?, si(p)?, si(y)?);
                Some([rotation.w, rotation.i, rotation.j, rotation.k])
            } else {
                None
            };
            seen.push(MarkerSample {
                marker: k,
                position_m,
                rotation,
            });
        }
        let row = MeasuredRow {
            line,
            q,
            t_s,
            markers: seen,
            distance_m,
        };
        repeats.see(measured_values(&row), line);
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    }
    let has_measurements = n_markers > 0 || distance_column.is_some();
    if has_measurements
        && rows
            .iter()
            .all(|r| r.markers.is_empty() && r.distance_m.is_none())
    {
        // Every measurement cell is empty: the file holds joint readings and nothing measured.
        let first = (markers.iter().flat_map(|m| m.position.iter().flatten()))
            .chain(distance_column.as_ref())
            .copied()
            .min()
            .unwrap_or(0);
        let measured: Vec<&str> = (markers.iter())
            .flat_map(|m| {
                m.position
                    .iter()
                    .chain(&m.quaternion)
                    .chain(&m.rpy)
                    .flatten()
            })
            .chain(distance_column.as_ref())
            .map(|c| names[*c].as_str())
            .collect();
        return Err(Error::NothingMeasured {
            path: path.to_path_buf(),
            line: header_line,
            column: first as u64 + 1,
            columns: measured.join(", "),
            rows: rows.len(),
        });
    }
    if let (Some(c), Some((value, rows))) = (distance_column, frozen_distance.frozen()) {
        return Err(Error::FrozenMeasurement {
            path: path.to_path_buf(),
            line: header_line,
            column: c as u64 + 1,
            name: names[c].clone(),
            value: metres(value),
            rows,
            what: "rows",
        });
    }
    for (m, frozen) in markers.iter().zip(&frozen_position) {
        if let Some((value, rows)) = frozen.frozen() {
            let position: Vec<usize> = m.position.iter().flatten().copied().collect();
            return Err(Error::FrozenMeasurement {
                path: path.to_path_buf(),
                line: header_line,
                column: position.first().map_or(0, |c| *c as u64 + 1),
                name: (position.iter().map(|c| names[*c].as_str()))
                    .collect::<Vec<_>>()
                    .join(", "),
                value: metres(value),
                rows,
                what: "rows where the marker is seen",
            });
        }
    }
    let mut warnings = Vec::new();
    if !outside.is_empty() {
        warnings.push(format!(
            "{first_outside}{}; such readings are used as they are",
            match outside.len() {
                1 => String::new(),
                n => format!(
                    " (and {} more readings outside their joint's limits)",
                    n - 1
                ),
            }
        ));
    }
    warnings.extend(repeats.warning(path));
    warnings.extend(identical_markers(path, &rows, n_markers));
    Ok(MeasurementTable {
        name: stem(path),
        path: path.to_path_buf(),
        rows,
        warnings,
        n_markers,
        has_orientation: markers
            .iter()
            .any(|m| m.quaternion[0].is_some() || m.rpy[0].is_some()),
        has_distance: distance_column.is_some(),
        ignored_columns,
    })
}

/// A warning for each set of markers seen in the same rows at the same positions (a column
/// set copied twice: the same point would count twice in the fit). Linear in the number of
/// cells: markers are grouped by the sequence of their (row, position) pairs.
fn identical_markers(path: &Path, rows: &[MeasuredRow], n_markers: usize) -> Vec<String> {
    let mut seen: Vec<Vec<(usize, [u64; 3])>> = vec![Vec::new(); n_markers];
    for (i, row) in rows.iter().enumerate() {
        for m in &row.markers {
            if let Some(list) = seen.get_mut(m.marker) {
                list.push((i, m.position_m.map(|v| (v + 0.0).to_bits())));
            }
        }
    }
    let mut groups: std::collections::HashMap<&[(usize, [u64; 3])], Vec<usize>> =
        std::collections::HashMap::new();
    for (k, list) in seen.iter().enumerate() {
        if !list.is_empty() {
            groups.entry(list.as_slice()).or_default().push(k);
        }
    }
    let mut groups: Vec<(usize, Vec<usize>)> = (groups.into_iter())
        .filter(|(_, markers)| markers.len() > 1)
        .map(|(list, markers)| (list.len(), markers))
        .collect();
    groups.sort_by_key(|(_, markers)| markers.first().copied());
    groups
        .into_iter()
        .filter_map(|(both, markers)| {
            let numbers: Vec<String> = markers.iter().map(|k| (k + 1).to_string()).collect();
            let (last, others) = numbers.split_last()?;
            Some(format!(
                "{}: markers {} and {last} have the same position in all {both} rows where {} \
                 seen: one point counted {} (drop the copied column sets)",
                path.display(),
                others.join(", "),
                if numbers.len() == 2 {
                    "both are"
                } else {
                    "they are"
                },
                if numbers.len() == 2 {
                    "twice".to_owned()
                } else {
                    format!("{} times", numbers.len())
                },
            ))
        })
        .collect()
}

/// A row's joint readings and measurements (not its time or line), to find repeated rows;
/// an absent value is NaN.
fn measured_values(row: &MeasuredRow) -> Vec<f64> {
    let mut values = row.q.clone();
    values.push(row.distance_m.unwrap_or(f64::NAN));
    for m in &row.markers {
        values.push(m.marker as f64);
        values.extend(m.position_m);
        values.extend(m.rotation.unwrap_or([f64::NAN; 4]));
    }
    values
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map_or_else(|| "data".to_owned(), |s| s.to_string_lossy().into_owned())
}

/// The observations of an `industrial_calibration` file in its order, with their keys.
struct Observations(Vec<(serde_yaml_ng::Value, Observation)>);

impl Observations {
    /// Whether no key is given twice (a YAML mapping read as values refuses that).
    fn distinct_keys(&self) -> bool {
        let mut seen = std::collections::HashSet::new();
        self.0.iter().all(|(k, _)| seen.insert(key_name(k)))
    }
}

impl<'de> Deserialize<'de> for Observations {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Entries;
        impl<'de> serde::de::Visitor<'de> for Entries {
            type Value = Observations;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a mapping of observations")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<Observations, A::Error> {
                let mut out = Vec::with_capacity(map.size_hint().unwrap_or(0));
                while let Some(entry) = map.next_entry()? {
                    out.push(entry);
                }
                Ok(Observations(out))
            }
        }
        deserializer.deserialize_map(Entries)
    }
}

/// An observation's key as the findings name it: the text of a string key, else the key
/// written as YAML.
fn key_name(key: &serde_yaml_ng::Value) -> String {
    match key {
        serde_yaml_ng::Value::String(s) => s.clone(),
        other => serde_yaml_ng::to_string(other)
            .unwrap_or_default()
            .trim()
            .to_owned(),
    }
}

/// One observation of `industrial_calibration`'s kinematic calibration.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Observation {
    camera_joints: Vec<f64>,
    pose: Pose,
    target_joints: Vec<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    qw: f64,
    qx: f64,
    qy: f64,
    qz: f64,
    x: f64,
    y: f64,
    z: f64,
}

/// Reads the observations of ROS-Industrial `industrial_calibration`'s kinematic calibration:
/// a map from an observation key to `{camera_joints, pose: {x, y, z, qw, qx, qy, qz},
/// target_joints}`, the pose (m, unit quaternion) of a target on the robot's tip as the
/// static camera measures it. Rows come in file order; each has one marker with a rotation.
/// Units are those of `industrial_calibration` (m, rad: the format has no unit field, its
/// poses and joint angles are SI as everywhere in ROS, REP 103); [`read_measurement_file`]
/// reads the file in other [`Units`] (pose `x, y, z` in [`Units::length`], `target_joints`
/// in [`Units::angle`] or [`Units::joint_length`], and edits of the columns `x`, `y`, `z`
/// and `q1..qn` or the joints' names). Joint readings within
/// [`JOINT_LIMIT_SLACK`] past their limits are kept with a warning, as in CSV files.
///
/// # Errors
///
/// [`Error::Io`]; [`Error::Yaml`] (file:line:column) for malformed YAML, a missing or unknown
/// field, a non-empty `camera_joints` (a moving camera is not supported), a joint count other
/// than the device's, a non-finite number, a joint outside its range or a quaternion that is
/// not of unit norm, or collections nested deeper than [`MAX_YAML_DEPTH`] (at the line and
/// column where the limit is passed, found in one linear pass before parsing);
/// [`Error::TooFewRows`] without observations; [`Error::FrozenMeasurement`] (file, line of
/// the first observation) if two or more observations all have the same pose translation
/// `x, y, z` (m): a frozen camera or target detection.
pub fn read_industrial_yaml(
    path: &Path,
    schema: &JointSchema<'_>,
) -> Result<MeasurementTable, Error> {
    read_industrial_yaml_in(path, schema, &Units::default())
}

/// [`read_industrial_yaml`] with its positions and joint readings in `units`.
fn read_industrial_yaml_in(
    path: &Path,
    schema: &JointSchema<'_>,
    units: &Units,
) -> Result<MeasurementTable, Error> {
    // The columns the edits may name: the pose's x, y, z (qw..qz have no unit) and the
    // joints, q1..qn or by name.
    let n = schema.names.len();
    let infos: Vec<ColumnInfo> = (["x", "y", "z"].into_iter())
        .map(|c| ColumnInfo::plain(c, Quantity::Length))
        .chain(
            ["qw", "qx", "qy", "qz"]
                .into_iter()
                .map(|c| ColumnInfo::plain(c, Quantity::Fixed("a quaternion component (no unit)"))),
        )
        .chain((0..n).map(|j| {
            let prismatic = schema.prismatic.get(j).copied().unwrap_or(false);
            let quantity = if prismatic {
                Quantity::JointLength
            } else {
                Quantity::Angle
            };
            let name = format!("q{}", j + 1);
            ColumnInfo::joint(&name, j, schema.names.get(j).map(String::as_str), quantity)
        }))
        .collect();
    let conversion = conversions(path, 1, &infos, units)?;
    let text = Error::read_text(path, |line, column, message| Error::Yaml {
        path: path.to_path_buf(),
        line,
        column,
        message,
    })?;
    check_yaml_depth(path, &text)?;
    // Lines of the top-level keys (the first of each), to locate each observation.
    let mut key_lines: std::collections::HashMap<String, u64> = std::collections::HashMap::new();
    for (i, l) in text.lines().enumerate() {
        if !l.starts_with([' ', '\t', '#', '-']) && l.contains(':') {
            let key = l.split(':').next().unwrap_or("").trim();
            key_lines
                .entry(key.trim_matches(['\'', '"']).to_owned())
                .or_insert(i as u64 + 1);
        }
    }
    let at = |key: &str| key_lines.get(key).copied().unwrap_or(0);
    // Straight into observations; a file that does not read so is read again through YAML
    // values, whose errors name the observation and its line.
    let direct = serde_yaml_ng::from_str::<Observations>(&text)
        .ok()
        .filter(|o| o.distinct_keys());
    let observations: Vec<(serde_yaml_ng::Value, Observation)> = match direct {
        Some(o) => o.0,
        None => {
            let mapping: serde_yaml_ng::Mapping =
                serde_yaml_ng::from_str(&text).map_err(|e| yaml_error(path, &e))?;
            (mapping.into_iter())
                .map(|(key, value)| {
                    let name = key_name(&key);
                    serde_yaml_ng::from_value(value)
                        .map(|o| (key, o))
                        .map_err(|e| (name, e))
                })
                .collect::<Result<_, _>>()
                .map_err(|(name, e)| Error::Yaml {
                    path: path.to_path_buf(),
                    line: at(&name),
                    column: 1,
                    message: format!("observation {name:?}: {e}"),
                })?
        }
    };
    let bad = |line: u64, message: String| Error::Yaml {
        path: path.to_path_buf(),
        line,
        column: 1,
        message,
    };
    let mut rows = Vec::with_capacity(observations.len());
    let (mut n_outside, mut first_outside) = (0usize, String::new());
    let mut repeats = Repeats::default();
    let mut frozen = Frozen::default();
    for (key, o) in observations {
        let key = key_name(&key);
        let line = at(&key);
        if !o.camera_joints.is_empty() {
            return Err(bad(
                line,
                format!(
                    "observation {key:?}: camera_joints is not empty: a camera on a moving chain is not supported"
                ),
            ));
        }
        if o.target_joints.len() != schema.names.len() {
            return Err(bad(
                line,
                format!(
                    "observation {key:?}: expected {} target_joints (as the device has), found {}",
                    schema.names.len(),
                    o.target_joints.len()
                ),
            ));
        }
        let mut o = o;
        // The raw values in the order of `infos`: x, y, z, the quaternion, the joints.
        let p = &o.pose;
        let raw: Vec<f64> = [p.x, p.y, p.z, 0.0, 0.0, 0.0, 0.0]
            .into_iter()
            .chain(o.target_joints.iter().copied())
            .collect();
        let read =
            |c: usize| Ok::<f64, std::convert::Infallible>(raw.get(c).copied().unwrap_or(0.0));
        let si = |c: usize| match si_of(&conversion, c, &read) {
            Ok(v) => v,
            Err(never) => match never {},
        };
        for (j, v) in o.target_joints.iter_mut().enumerate() {
            *v = si(7 + j);
        }
        let p = &mut o.pose;
        [p.x, p.y, p.z] = [si(0), si(1), si(2)];
        for (j, &v) in o.target_joints.iter().enumerate() {
            let (min, max) = schema
                .limits
                .get(j)
                .copied()
                .unwrap_or((f64::MIN, f64::MAX));
            let within = reach(v, (min, max));
            if v.is_finite() && within == Reach::Slack {
                n_outside += 1;
                if n_outside == 1 {
                    first_outside = format!(
                        "{}:{line}: observation {key:?}: joint {:?} = {v} is outside its limits [{min}, {max}]",
                        path.display(),
                        schema.names[j]
                    );
                }
            } else if !(v.is_finite() && within == Reach::Within) {
                return Err(bad(
                    line,
                    format!(
                        "observation {key:?}: joint {:?} = {v} is outside [{min}, {max}]",
                        schema.names[j]
                    ),
                ));
            }
        }
        let p = &o.pose;
        let quaternion = [p.qw, p.qx, p.qy, p.qz];
        let norm = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
        if ![p.x, p.y, p.z].iter().all(|v| v.is_finite()) || (norm - 1.0).abs() > 1e-3 {
            return Err(bad(
                line,
                format!(
                    "observation {key:?}: expected a finite position and a unit quaternion, found quaternion norm {norm}"
                ),
            ));
        }
        frozen.see(&[p.x, p.y, p.z]);
        let q = UnitQuaternion::from_quaternion(Quaternion::new(p.qw, p.qx, p.qy, p.qz));
        let row = MeasuredRow {
            line,
            q: o.target_joints,
            t_s: None,
            markers: vec![MarkerSample {
                marker: 0,
                position_m: [p.x, p.y, p.z],
                rotation: Some([q.w, q.i, q.j, q.k]),
            }],
            distance_m: None,
        };
        repeats.see(measured_values(&row), line);
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    }
    if let Some((value, n_rows)) = frozen.frozen() {
        let first = rows.first().map_or(0, |r| r.line);
        return Err(Error::FrozenMeasurement {
            path: path.to_path_buf(),
            line: first,
            column: 1,
            name: "pose x, y, z".to_owned(),
            value: metres(value),
            rows: n_rows,
            what: "observations",
        });
    }
    Ok(MeasurementTable {
        name: stem(path),
        path: path.to_path_buf(),
        rows,
        warnings: match n_outside {
            0 => Vec::new(),
            1 => vec![format!(
                "{first_outside}; such readings are used as they are"
            )],
            n => vec![format!(
                "{first_outside} (and {} more readings outside their joint's limits); such readings are used as they are",
                n - 1
            )],
        }
        .into_iter()
        .chain(repeats.warning(path))
        .collect(),
        n_markers: 1,
        has_orientation: true,
        has_distance: false,
        ignored_columns: Vec::new(),
    })
}

/// Deepest nesting of YAML collections (mappings and sequences, block or flow) that
/// [`read_industrial_yaml`] reads. industrial_calibration's observations nest three deep
/// (observations → observation → pose or joint list); 32 leaves room for comments of any
/// layout and refuses in linear time the deeply nested files whose parsing time grows with the
/// square of the depth (the YAML parser re-scans its stack of open keys at every token).
pub const MAX_YAML_DEPTH: usize = 32;

/// `Err(`[`Error::Yaml`]`)` at the first place (line, column) where `text` nests collections
/// deeper than [`MAX_YAML_DEPTH`]. One pass over the text: block nesting from the indentation
/// (a stack of open indents) and `- ` / `? ` entry markers, flow nesting from brackets and
/// braces outside quotes and comments. It may count a level too many (a block scalar holding
/// brackets), never one too few where it matters: a collection is always opened by an indent,
/// a marker or a bracket.
fn check_yaml_depth(path: &Path, text: &str) -> Result<(), Error> {
    let too_deep = |line: usize, column: usize| Error::Yaml {
        path: path.to_path_buf(),
        line: line as u64 + 1,
        column: column as u64 + 1,
        message: format!(
            "collections nest deeper than {MAX_YAML_DEPTH} levels (industrial_calibration's observations nest 3 deep)"
        ),
    };
    let mut indents: Vec<usize> = Vec::new();
    let mut flow = 0usize;
    // An open quoted scalar, which may span lines: its quote character.
    let mut quote: Option<char> = None;
    for (i, line) in text.lines().enumerate() {
        let content = line.trim_start_matches([' ', '\t']);
        let mut block = indents.len();
        if flow == 0 && quote.is_none() && !content.is_empty() && !content.starts_with('#') {
            let indent = line.len() - content.len();
            while indents.last().is_some_and(|&open| open >= indent) {
                indents.pop();
            }
            indents.push(indent);
            // `- - - x`: each entry marker opens one more collection on the same line.
            let mut rest = content;
            let mut markers = 0;
            while let Some(after) = rest.strip_prefix("- ").or_else(|| rest.strip_prefix("? ")) {
                markers += 1;
                rest = after.trim_start_matches(' ');
            }
            block = indents.len() + markers;
            if block > MAX_YAML_DEPTH {
                return Err(too_deep(i, indent));
            }
        }
        let mut previous = ' ';
        for (column, c) in line.chars().enumerate() {
            match (quote, c) {
                (Some('"'), '"') if previous != '\\' => quote = None,
                (Some('\''), '\'') => quote = None,
                (Some(_), _) => {}
                (None, '#') if previous == ' ' || previous == '\t' || column == 0 => break,
                (None, '"' | '\'')
                    if matches!(previous, ' ' | '\t' | '[' | '{' | ',' | ':') || column == 0 =>
                {
                    quote = Some(c);
                }
                (None, '[' | '{') => {
                    flow += 1;
                    if block + flow > MAX_YAML_DEPTH {
                        return Err(too_deep(i, column));
                    }
                }
                (None, ']' | '}') => flow = flow.saturating_sub(1),
                (None, _) => {}
            }
            previous = if previous == '\\' && c == '\\' {
                ' '
            } else {
                c
            };
        }
    }
    Ok(())
}

fn yaml_error(path: &Path, e: &serde_yaml_ng::Error) -> Error {
    let (line, column) = e
        .location()
        .map_or((0, 0), |l| (l.line() as u64, l.column() as u64));
    Error::Yaml {
        path: path.to_path_buf(),
        line,
        column,
        message: e.to_string(),
    }
}
