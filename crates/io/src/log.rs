//! The hapcal measurement log (CSV, docs/design.md §5).

use std::fmt::Write as _;
use std::path::Path;

use crate::Error;
use crate::columns::{ColumnInfo, Quantity, Units, conversions, si_of};
use crate::device::Device;
use crate::measure::{Reach, reach};
use crate::table::{Frozen, Repeats, Table, check_separator, first_duplicate, metres, number};

/// Number of external encoder columns (`ext1..ext4`, one per transmission output shaft).
pub const N_EXT: usize = 4;

/// Unknown columns warned about one by one; more are summed up in one further warning.
const MAX_UNKNOWN_WARNINGS: usize = 10;

/// A measurement log: one row per sample, in file order.
#[derive(Clone, Debug, PartialEq)]
pub struct Log {
    /// The samples.
    pub rows: Vec<LogRow>,
    /// Things worth telling the user that did not stop the reading (unknown columns),
    /// each starting with `file:line:column:`.
    pub warnings: Vec<String>,
}

/// One sample of a measurement log.
#[derive(Clone, Debug, PartialEq)]
pub struct LogRow {
    /// Joint readings `q1..qn`, rad (length = the device's number of joints).
    pub q: Vec<f64>,
    /// Cable-encoder distance, m.
    pub distance_m: f64,
    /// External encoder output angles `ext1..ext4`, rad; always length [`N_EXT`], `None`
    /// where the column is absent or the cell empty. `ext[k]` of a joint the device has lies
    /// within that joint's limits widened by [`JOINT_LIMIT_SLACK`](crate::JOINT_LIMIT_SLACK)
    /// of its range ([`read_log`]).
    pub ext: Vec<Option<f64>>,
    /// Time, s, if the log has a `t_s` column.
    pub t_s: Option<f64>,
    /// 1-based line in the file.
    pub line: u64,
}

impl LogRow {
    /// The row's joint readings, distance and external-encoder angles (not its time or
    /// line) as [`read_log`] compares rows to find repeats: bit patterns, −0 as +0, an empty
    /// external-encoder cell as NaN. Two rows with equal keys are copies of one another (the
    /// reader's warning about repeated rows). The key borrows the row: a hash map of a
    /// million rows' keys holds no copy of their values.
    pub fn repeat_key(&self) -> RepeatKey<'_> {
        RepeatKey(self)
    }

    fn repeat_values(&self) -> impl Iterator<Item = f64> + '_ {
        let ext = self.ext.iter().map(|e| e.unwrap_or(f64::NAN));
        self.q.iter().copied().chain([self.distance_m]).chain(ext)
    }
}

/// A [`LogRow`]'s values as [`LogRow::repeat_key`] compares them (equality and hash of their
/// bit patterns, −0 as +0, an empty external-encoder cell as NaN).
#[derive(Clone, Copy, Debug)]
pub struct RepeatKey<'a>(&'a LogRow);

impl RepeatKey<'_> {
    fn bits(&self) -> impl Iterator<Item = u64> + '_ {
        self.0.repeat_values().map(|v| (v + 0.0).to_bits())
    }
}

impl PartialEq for RepeatKey<'_> {
    fn eq(&self, other: &Self) -> bool {
        self.bits().eq(other.bits())
    }
}

impl Eq for RepeatKey<'_> {}

impl std::hash::Hash for RepeatKey<'_> {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        for bits in self.bits() {
            bits.hash(state);
        }
    }
}

/// What a header column holds.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum Column {
    Q(usize),
    Distance,
    Ext(usize),
    Time,
    Unknown,
}

fn classify(name: &str) -> Column {
    let index = |prefix: &str| {
        let digits = name.strip_prefix(prefix)?;
        let canonical = !digits.is_empty()
            && digits.bytes().all(|b| b.is_ascii_digit())
            && !digits.starts_with('0');
        canonical.then(|| digits.parse::<usize>().ok()).flatten()
    };
    match name {
        "distance_m" => Column::Distance,
        "t_s" => Column::Time,
        _ => match (index("q"), index("ext")) {
            (Some(j), _) => Column::Q(j - 1),
            (_, Some(k)) if k <= N_EXT => Column::Ext(k - 1),
            _ => Column::Unknown,
        },
    }
}

/// Reads a measurement log for `device`.
///
/// The header row names the columns, in any order: `q1..qn` (rad; n = the device's number
/// of joints) and `distance_m` (m) are required; `ext1..ext4` (rad; an empty cell means no
/// reading) and `t_s` (s, non-decreasing) are optional. Unknown columns are ignored with a
/// warning in [`Log::warnings`] (one per column for the first ten, then one for the rest).
/// Joint readings must lie within the device's limits (inclusive). An external-encoder
/// reading `ext{k}` measures the output angle of joint k, which differs from the reading
/// `q{k}` by the transmission's error, so it may lie up to
/// [`JOINT_LIMIT_SLACK`](crate::JOINT_LIMIT_SLACK) of joint k's range past its limits (as
/// the readings of a measurement file may); an `ext{k}` column of a joint the device does not
/// have is only checked to be a finite number. Rows that repeat an earlier row's joint
/// readings, distance and external readings are kept, with one warning naming the first and
/// how many there are. The header is checked in time linear in its number of columns.
///
/// # Errors
///
/// [`Error::Io`] if the file cannot be read; [`Error::TooFewRows`] without a header or a
/// data row; [`Error::DuplicateColumn`]; [`Error::JointCount`] if the header has another
/// number of `q` columns than the device has joints; [`Error::MissingColumn`];
/// [`Error::Ragged`] for a row with another number of fields than the header;
/// [`Error::Separator`] for a file separated by semicolons, tabs or spaces;
/// [`Error::NotANumber`], [`Error::NotFinite`], [`Error::OutsideJointLimits`],
/// [`Error::ExtOutsideJointLimits`], [`Error::LengthOutOfRange`] and
/// [`Error::NegativeDistance`] for a bad cell and [`Error::TimeOrder`] if `t_s` decreases
/// (all with file:line:column, column = field number); [`Error::FrozenMeasurement`] (file,
/// header line and `distance_m`'s column) if `distance_m` holds the same value in every one
/// of two or more rows (a frozen or disconnected cable encoder; joint columns may be
/// constant); [`Error::Csv`] for invalid UTF-8.
pub fn read_log(path: &Path, device: &Device) -> Result<Log, Error> {
    read_log_in(path, device, &Units::default())
}

/// Reads a measurement log for `device` as [`read_log`] does, with its readings in `units`:
/// `q1..qn` and `ext1..ext4` in [`Units::angle`], `distance_m` in [`Units::length`] (the
/// column keeps its name whatever the unit), and the edits of [`Units::columns`] (a joint
/// column may be named `q{j}` or by the device's joint name). Readings are converted to SI
/// before the limit and length checks.
///
/// # Errors
///
/// As [`read_log`]; [`Error::UnknownColumn`], [`Error::ColumnUnitKind`] and
/// [`Error::ColumnNotEditable`] for an edit that names no column of the log, gives a unit of
/// the wrong kind, or names `t_s` or an unknown column.
pub fn read_log_in(path: &Path, device: &Device, units: &Units) -> Result<Log, Error> {
    let mut reader = LogReader::open(path, device, units)?;
    let mut rows = Vec::new();
    while let Some(row) = reader.next_row()? {
        rows.push(row);
    }
    let LogSummary { warnings, .. } = reader.finish()?;
    Ok(Log { rows, warnings })
}

/// The number of data rows of the log at `path` (its records after the header; blank lines
/// are not rows), counted without reading their cells: what [`LogReader`] will give when the
/// file reads without error. A file that cannot be opened or read counts the rows before the
/// fault (the reader then reports it, with its line).
pub fn count_log_rows(path: &Path) -> usize {
    let Ok(file) = std::fs::File::open(path) else {
        return 0;
    };
    // Records as the reader sees them (it skips empty lines only), neither trimmed nor
    // checked as UTF-8.
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .buffer_capacity(1 << 16)
        .from_reader(file);
    let mut record = csv::ByteRecord::new();
    let mut records = 0_usize;
    while let Ok(true) = reader.read_byte_record(&mut record) {
        records += 1;
    }
    records.saturating_sub(1)
}

/// What a log holds besides its rows, known once [`LogReader`] has read them all.
#[derive(Clone, Debug, PartialEq)]
pub struct LogSummary {
    /// Number of data rows.
    pub n_rows: usize,
    /// As [`Log::warnings`].
    pub warnings: Vec<String>,
}

/// A measurement log read row by row, as [`read_log_in`] reads it whole: the same checks,
/// the same errors, in the same order, with memory bounded by one row (and the repeat
/// detector's 8-byte hash and line per distinct row), whatever the log's length.
pub struct LogReader<'a> {
    path: &'a Path,
    device: &'a Device,
    table: Table<'a>,
    header_line: u64,
    names: Vec<String>,
    columns: Vec<Column>,
    conversion: Vec<crate::columns::Conversion>,
    limits: Vec<(f64, f64)>,
    warnings: Vec<String>,
    previous_t: Option<f64>,
    repeats: Repeats,
    distances: Frozen,
    n_rows: usize,
}

impl std::fmt::Debug for LogReader<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogReader")
            .field("path", &self.path)
            .field("n_rows", &self.n_rows)
            .finish_non_exhaustive()
    }
}

impl<'a> LogReader<'a> {
    /// Opens the log at `path` for `device` with its readings in `units` and reads its
    /// header (see [`read_log_in`] for the format).
    ///
    /// # Errors
    ///
    /// [`read_log_in`]'s errors of the header: [`Error::Io`], [`Error::TooFewRows`] without
    /// a header, [`Error::Separator`], [`Error::DuplicateColumn`], [`Error::JointCount`],
    /// [`Error::MissingColumn`] and the column edits' errors.
    pub fn open(path: &'a Path, device: &'a Device, units: &Units) -> Result<Self, Error> {
        let n_joints = device.n_joints();
        let limits = device.joint_limits();
        let mut table = Table::open(path)?;
        let Some((header_line, header)) = table.next_record()? else {
            return Err(Error::TooFewRows {
                path: path.to_path_buf(),
                min: 1,
                found: 0,
            });
        };
        check_separator(path, header_line, header, n_joints + 1)?;
        let names: Vec<String> = header.iter().map(str::to_owned).collect();
        let columns: Vec<Column> = names.iter().map(|n| classify(n)).collect();
        if let Some(c) = first_duplicate(&names) {
            return Err(Error::DuplicateColumn {
                path: path.to_path_buf(),
                column: c as u64 + 1,
                name: names.get(c).cloned().unwrap_or_default(),
            });
        }
        let mut warnings = Vec::new();
        let unknown: Vec<usize> = (columns.iter().enumerate())
            .filter(|(_, column)| **column == Column::Unknown)
            .map(|(c, _)| c)
            .collect();
        for &c in unknown.iter().take(MAX_UNKNOWN_WARNINGS) {
            warnings.push(format!(
                "{}:{header_line}:{}: unknown column {:?} ignored",
                path.display(),
                c + 1,
                names.get(c).map_or("", String::as_str)
            ));
        }
        if unknown.len() > MAX_UNKNOWN_WARNINGS {
            warnings.push(format!(
                "{}:{header_line}: {} more unknown columns ignored ({} in all)",
                path.display(),
                unknown.len() - MAX_UNKNOWN_WARNINGS,
                unknown.len()
            ));
        }
        let n_q = columns.iter().filter(|c| matches!(c, Column::Q(_))).count();
        if n_q != n_joints {
            return Err(Error::JointCount {
                path: path.to_path_buf(),
                line: header_line,
                expected: n_joints,
                found: n_q,
            });
        }
        let required = (0..n_joints)
            .map(|j| (Column::Q(j), format!("q{}", j + 1)))
            .chain([(Column::Distance, "distance_m".to_owned())]);
        let present: std::collections::HashSet<Column> = columns.iter().copied().collect();
        for (column, name) in required {
            if !present.contains(&column) {
                return Err(Error::MissingColumn {
                    path: path.to_path_buf(),
                    name,
                });
            }
        }
        let infos: Vec<ColumnInfo> = (names.iter().zip(&columns))
            .map(|(name, column)| match *column {
                Column::Q(j) => ColumnInfo::joint(
                    name,
                    j,
                    device.joints.get(j).map(|s| s.name.as_str()),
                    Quantity::Angle,
                ),
                Column::Distance => ColumnInfo::plain(name, Quantity::Length),
                Column::Ext(_) => ColumnInfo::plain(name, Quantity::Angle),
                Column::Time => ColumnInfo::plain(name, Quantity::Fixed("times in s")),
                Column::Unknown => ColumnInfo::plain(
                    name,
                    Quantity::Fixed("nothing hapcal reads (it is ignored)"),
                ),
            })
            .collect();
        let conversion = conversions(path, header_line, &infos, units)?;
        Ok(LogReader {
            path,
            device,
            table,
            header_line,
            names,
            columns,
            conversion,
            limits,
            warnings,
            previous_t: None,
            repeats: Repeats::default(),
            distances: Frozen::default(),
            n_rows: 0,
        })
    }

    /// The next row, or `None` after the last one.
    ///
    /// # Errors
    ///
    /// [`read_log_in`]'s errors of a row (file:line:column): [`Error::Ragged`],
    /// [`Error::Separator`], [`Error::NotANumber`], [`Error::NotFinite`],
    /// [`Error::OutsideJointLimits`], [`Error::ExtOutsideJointLimits`],
    /// [`Error::LengthOutOfRange`], [`Error::NegativeDistance`], [`Error::TimeOrder`] and
    /// [`Error::Csv`].
    pub fn next_row(&mut self) -> Result<Option<LogRow>, Error> {
        let n_joints = self.device.n_joints();
        let (path, device, limits) = (self.path, self.device, &self.limits);
        let (names, columns, conversion) = (&self.names, &self.columns, &self.conversion);
        let Some((line, record)) = self.table.next_record()? else {
            return Ok(None);
        };
        if record.len() != columns.len() {
            check_separator(path, line, record, columns.len())?;
            return Err(Error::Ragged {
                path: path.to_path_buf(),
                line,
                expected: columns.len(),
                found: record.len(),
            });
        }
        let mut row = LogRow {
            q: vec![0.0; n_joints],
            distance_m: 0.0,
            ext: vec![None; N_EXT],
            t_s: None,
            line,
        };
        // The raw reading of column `k` of this row (a coupled column's too).
        let raw_of = |k: usize| {
            let name = names.get(k).map_or("", String::as_str);
            number(path, line, k as u64 + 1, name, record.get(k).unwrap_or(""))
        };
        for (c, ((cell, column), name)) in record.iter().zip(columns).zip(names).enumerate() {
            let col = c as u64 + 1;
            let parse = || number(path, line, col, name, cell);
            let parse_si = || si_of(conversion, c, &raw_of);
            match *column {
                Column::Q(j) => {
                    let value = parse_si()?;
                    let (min_rad, max_rad) = limits
                        .get(j)
                        .copied()
                        .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
                    if !(min_rad..=max_rad).contains(&value) {
                        let joint =
                            (device.joints.get(j)).map_or_else(|| name.clone(), |s| s.name.clone());
                        return Err(Error::OutsideJointLimits {
                            path: path.to_path_buf(),
                            line,
                            column: col,
                            joint,
                            value_rad: value,
                            min_rad,
                            max_rad,
                        });
                    }
                    if let Some(q) = row.q.get_mut(j) {
                        *q = value;
                    }
                }
                Column::Distance => {
                    let value = parse_si()?;
                    Error::check_length(path, line, col, name, value)?;
                    if value < 0.0 {
                        return Err(Error::NegativeDistance {
                            path: path.to_path_buf(),
                            line,
                            column: col,
                            name: name.clone(),
                            value_m: value,
                            limit_m: crate::MAX_LENGTH_M,
                        });
                    }
                    row.distance_m = value;
                }
                Column::Ext(k) if !cell.is_empty() => {
                    let value = parse_si()?;
                    if let Some(&(min_rad, max_rad)) = limits.get(k)
                        && reach(value, (min_rad, max_rad)) == Reach::Outside
                    {
                        let joint =
                            (device.joints.get(k)).map_or_else(|| name.clone(), |s| s.name.clone());
                        return Err(Error::ExtOutsideJointLimits {
                            path: path.to_path_buf(),
                            line,
                            column: col,
                            name: name.clone(),
                            joint,
                            value_rad: value,
                            min_rad,
                            max_rad,
                            slack_rad: crate::JOINT_LIMIT_SLACK * (max_rad - min_rad),
                        });
                    }
                    if let Some(ext) = row.ext.get_mut(k) {
                        *ext = Some(value);
                    }
                }
                Column::Time => row.t_s = Some(parse()?),
                Column::Ext(_) | Column::Unknown => {}
            }
        }
        if let (Some(t_s), Some(previous_t_s)) = (row.t_s, self.previous_t)
            && t_s < previous_t_s
        {
            return Err(Error::TimeOrder {
                path: path.to_path_buf(),
                line,
                t_s,
                previous_t_s,
            });
        }
        self.previous_t = row.t_s;
        self.distances.see(&[row.distance_m]);
        // Joint readings and measurements; the time of a repeated pose differs.
        self.repeats.see(row.repeat_values(), line);
        self.n_rows += 1;
        Ok(Some(row))
    }

    /// The log's number of rows and its warnings, once every row has been read.
    ///
    /// # Errors
    ///
    /// [`Error::TooFewRows`] without a data row; [`Error::FrozenMeasurement`] if
    /// `distance_m` holds one value in every one of two or more rows.
    pub fn finish(self) -> Result<LogSummary, Error> {
        if self.n_rows == 0 {
            return Err(Error::TooFewRows {
                path: self.path.to_path_buf(),
                min: 1,
                found: 0,
            });
        }
        if let Some((value, rows)) = self.distances.frozen() {
            let column = self.columns.iter().position(|c| *c == Column::Distance);
            return Err(Error::FrozenMeasurement {
                path: self.path.to_path_buf(),
                line: self.header_line,
                column: column.map_or(0, |c| c as u64 + 1),
                name: "distance_m".to_owned(),
                value: metres(value),
                rows,
                what: "rows",
            });
        }
        let mut warnings = self.warnings;
        warnings.extend(self.repeats.warning(self.path));
        Ok(LogSummary {
            n_rows: self.n_rows,
            warnings,
        })
    }
}

/// The CSV text of `rows` in the format [`read_log`] reads: `q1..qn`, `distance_m`, then
/// each `ext{k}` that some row has a value for, then `t_s` if some row has a time.
/// Numbers are written in Rust's shortest form that parses back to the same `f64`; `None`
/// is an empty cell. `line` is not written.
///
/// # Panics
///
/// If the rows do not all have the same number of joint readings (a bug in the caller).
#[track_caller]
pub fn write_log(rows: &[LogRow]) -> String {
    let n_joints = rows.first().map_or(0, |r| r.q.len());
    assert!(
        rows.iter().all(|r| r.q.len() == n_joints),
        "write_log: rows have different numbers of joint readings"
    );
    let ext_columns: Vec<usize> = (0..N_EXT)
        .filter(|k| {
            rows.iter()
                .any(|r| r.ext.get(*k).copied().flatten().is_some())
        })
        .collect();
    let has_time = rows.iter().any(|r| r.t_s.is_some());

    let mut header: Vec<String> = (1..=n_joints).map(|j| format!("q{j}")).collect();
    header.push("distance_m".into());
    header.extend(ext_columns.iter().map(|k| format!("ext{}", k + 1)));
    if has_time {
        header.push("t_s".into());
    }
    let mut out = header.join(",");
    out.push('\n');
    let cell = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:?}"));
    for row in rows {
        let mut cells: Vec<String> = row.q.iter().map(|v| format!("{v:?}")).collect();
        cells.push(format!("{:?}", row.distance_m));
        cells.extend((ext_columns.iter()).map(|k| cell(row.ext.get(*k).copied().flatten())));
        if has_time {
            cells.push(cell(row.t_s));
        }
        let _ = writeln!(out, "{}", cells.join(","));
    }
    out
}
