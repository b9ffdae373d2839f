//! Measurement files of external instruments: marker positions, full poses and distances
//! against joint readings (CSV), and the observations of ROS-Industrial `industrial_calibration`
//! (YAML).

//!
//! A CSV file is read in stages: its header (`header`: what each column holds and its
//! conversion to SI), its rows (`rows`: each cell converted and checked), then the checks
//! over all rows (something measured, nothing frozen) and the warnings. The YAML reader's
//! stages are in `yaml`.

mod header;
mod rows;
mod yaml;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::Error;
use crate::columns::Units;
use crate::table::{Table, metres};

use header::Header;
use rows::Body;

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
    /// Joint readings in chain order, rad (m for a prismatic joint). A shared slice: the
    /// observation rows built from this row (one per marker and distance) share it rather
    /// than copy it.
    pub q: Arc<[f64]>,
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

    /// A 64-bit hash of [`MeasuredRow::repeat_key`]'s values, the one the reader's warning
    /// about repeated rows keys them by: rows with equal keys have equal hashes, and two
    /// different rows share one with probability about n²/2⁶⁵ among n rows. 8 bytes where the
    /// key holds every value of the row.
    pub fn repeat_hash(&self) -> u64 {
        crate::table::row_hash(measured_values(self))
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
    MeasurementTable::read_every(path, schema, units, 1).map(|(table, _)| table)
}

impl MeasurementTable {
    /// Reads a measurement file as [`read_measurement_file`] does (every row read and checked,
    /// the same errors and warnings, its checks over all rows), keeping in
    /// [`MeasurementTable::rows`] only every `stride`-th data row from the first (rows `0,
    /// stride, 2·stride, …`; every row for a stride of 0 or 1). A CSV file is streamed: the
    /// memory is that of the rows kept, and of the repeat detector's 16 bytes a row, whatever
    /// the file's length. Returns the table and the number of data rows in the file.
    ///
    /// # Errors
    /// As [`read_measurement_file`].
    pub fn read_every(
        path: &Path,
        schema: &JointSchema<'_>,
        units: &Units,
        stride: usize,
    ) -> Result<(MeasurementTable, usize), Error> {
        let stride = stride.max(1);
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        if matches!(ext.as_deref(), Some("yaml" | "yml")) {
            let mut table = yaml::read_industrial_yaml_in(path, schema, units)?;
            let n_rows = table.rows.len();
            if stride > 1 {
                let rows = std::mem::take(&mut table.rows);
                table.rows = rows.into_iter().step_by(stride).collect();
            }
            return Ok((table, n_rows));
        }
        let mut table = Table::open(path)?;
        let header = header::read_header(path, &mut table, schema, units)?;
        let body = rows::read_rows(path, &mut table, schema, &header, stride)?;
        check_measured(path, &header, &body)?;
        check_frozen(path, &header, &body)?;
        let n_markers = header.markers.len();
        let mut warnings: Vec<String> = body.outside.warning().into_iter().collect();
        warnings.extend(body.repeats.warning(path));
        warnings.extend(body.identical.warnings(path));
        let table = MeasurementTable {
            name: stem(path),
            path: path.to_path_buf(),
            rows: body.rows,
            warnings,
            n_markers,
            has_orientation: (header.markers.iter())
                .any(|m| m.quaternion[0].is_some() || m.rpy[0].is_some()),
            has_distance: header.distance_column.is_some(),
            ignored_columns: header.ignored_columns,
        };
        Ok((table, body.n_rows))
    }
}

/// At least one data row; and in a file with marker or distance columns, at least one of
/// their cells given (else the file holds joint readings and nothing measured).
fn check_measured(path: &Path, header: &Header, body: &Body) -> Result<(), Error> {
    if body.n_rows == 0 {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    }
    let (markers, names) = (&header.markers, &header.names);
    let has_measurements = !markers.is_empty() || header.distance_column.is_some();
    if !has_measurements || body.any_measured {
        return Ok(());
    }
    let first = (markers.iter().flat_map(|m| m.position.iter().flatten()))
        .chain(header.distance_column.as_ref())
        .copied()
        .min()
        .unwrap_or(0);
    let measured: Vec<&str> = (markers.iter().flat_map(|m| m.all()))
        .chain(header.distance_column.as_ref())
        .map(|c| names[*c].as_str())
        .collect();
    Err(Error::NothingMeasured {
        path: path.to_path_buf(),
        line: header.line,
        column: first as u64 + 1,
        columns: measured.join(", "),
        rows: body.n_rows,
    })
}

/// Neither the distance nor a marker's position the same in every one of two or more rows
/// (where the marker is seen): a frozen or disconnected instrument.
fn check_frozen(path: &Path, header: &Header, body: &Body) -> Result<(), Error> {
    let names = &header.names;
    if let (Some(c), Some((value, rows))) = (header.distance_column, body.frozen_distance.frozen())
    {
        return Err(Error::FrozenMeasurement {
            path: path.to_path_buf(),
            line: header.line,
            column: c as u64 + 1,
            name: names[c].clone(),
            value: metres(value),
            rows,
            what: "rows",
        });
    }
    for (m, frozen) in header.markers.iter().zip(&body.frozen_position) {
        if let Some((value, rows)) = frozen.frozen() {
            let position: Vec<usize> = m.position.iter().flatten().copied().collect();
            return Err(Error::FrozenMeasurement {
                path: path.to_path_buf(),
                line: header.line,
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
    Ok(())
}

/// Each marker's positions where it is seen, to warn about markers seen in the same rows at
/// the same positions (a column set copied twice: the same point would count twice in the
/// fit). Streams: a 64-bit hash of each marker's sequence of (row, position) pairs and their
/// number, so its memory does not grow with the rows; two different sequences share a hash
/// with probability 2⁻⁶⁴.
#[derive(Default)]
pub(crate) struct IdenticalMarkers {
    /// Per marker: the hash of its (row, position) pairs so far, and how many.
    seen: Vec<(std::hash::DefaultHasher, usize)>,
}

impl IdenticalMarkers {
    /// Records the markers seen in data row `i` (0-based, every row of the file).
    pub(crate) fn see(&mut self, i: usize, markers: &[MarkerSample]) {
        use std::hash::Hasher as _;
        for m in markers {
            if self.seen.len() <= m.marker {
                self.seen.resize_with(m.marker + 1, Default::default);
            }
            if let Some((hash, n)) = self.seen.get_mut(m.marker) {
                hash.write_usize(i);
                for v in m.position_m {
                    hash.write_u64((v + 0.0).to_bits());
                }
                *n += 1;
            }
        }
    }

    /// A warning for each set of markers seen in the same rows at the same positions.
    pub(crate) fn warnings(&self, path: &Path) -> Vec<String> {
        use std::hash::Hasher as _;
        let mut groups: std::collections::HashMap<(u64, usize), Vec<usize>> =
            std::collections::HashMap::new();
        for (k, (hash, n)) in self.seen.iter().enumerate() {
            if *n > 0 {
                groups.entry((hash.finish(), *n)).or_default().push(k);
            }
        }
        let mut groups: Vec<(usize, Vec<usize>)> = (groups.into_iter())
            .filter(|(_, markers)| markers.len() > 1)
            .map(|((_, n), markers)| (n, markers))
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
}

/// A row's joint readings and measurements (not its time or line), to find repeated rows;
/// an absent value is NaN.
fn measured_values(row: &MeasuredRow) -> Vec<f64> {
    let mut values = row.q.to_vec();
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
    yaml::read_industrial_yaml_in(path, schema, &Units::default())
}

/// Deepest nesting of YAML collections (mappings and sequences, block or flow) that
/// [`read_industrial_yaml`] reads. industrial_calibration's observations nest three deep
/// (observations → observation → pose or joint list); 32 leaves room for comments of any
/// layout and refuses in linear time the deeply nested files whose parsing time grows with the
/// square of the depth (the YAML parser re-scans its stack of open keys at every token).
pub const MAX_YAML_DEPTH: usize = 32;
