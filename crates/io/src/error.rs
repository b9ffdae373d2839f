//! The crate's one error type.

use std::path::PathBuf;

/// Everything that can go wrong turning a file into a domain value.
///
/// Every parse error names the file, the 1-based line and (where one cell or value is at
/// fault) the 1-based column. In CSV files the column is the field number (first field = 1);
/// in TOML and XML files it is the character column within the line.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file or folder could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// A cell that must hold a number does not parse as one.
    #[error("{path}:{line}:{column}: expected a number in column {name:?}, found {found:?}")]
    NotANumber {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column (CSV field number).
        column: u64,
        /// Column name (`q3`, `distance_m`, …).
        name: String,
        /// The text found in the cell.
        found: String,
    },
    /// A number is NaN or infinite.
    #[error("{path}:{line}:{column}: expected a finite number in {name:?}, found {found}")]
    NotFinite {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// Column or field name.
        name: String,
        /// The value found (`NaN`, `inf`, …).
        found: String,
    },
    /// A CSV row has a different number of fields than the rows (or header) before it.
    #[error("{path}:{line}: expected {expected} fields, found {found}")]
    Ragged {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// Number of fields of the header or first row.
        expected: usize,
        /// Number of fields of this row.
        found: usize,
    },
    /// A file has a different number of joints than the device.
    #[error("{path}:{line}: expected {expected} joints (as the device has), found {found}")]
    JointCount {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// The device's number of joints.
        expected: usize,
        /// The number of joints in the file.
        found: usize,
    },
    /// A required column is absent from a CSV header.
    #[error("{path}:1: missing column {name:?}")]
    MissingColumn {
        /// The file.
        path: PathBuf,
        /// The missing column's name.
        name: String,
    },
    /// A CSV header names the same column twice.
    #[error("{path}:1:{column}: column {name:?} appears twice")]
    DuplicateColumn {
        /// The file.
        path: PathBuf,
        /// 1-based column of the second occurrence.
        column: u64,
        /// The column name.
        name: String,
    },
    /// A joint reading lies outside the device's joint limits (bounds inclusive).
    #[error(
        "{path}:{line}:{column}: joint {joint:?} = {v} rad is outside [{min_rad}, {max_rad}] rad",
        v = readable(*.value_rad)
    )]
    OutsideJointLimits {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// The joint's name in the device file.
        joint: String,
        /// The reading in rad.
        value_rad: f64,
        /// Lower limit in rad.
        min_rad: f64,
        /// Upper limit in rad.
        max_rad: f64,
    },
    /// An external-encoder reading (`ext1..ext4`, the output angle of joint k) lies further
    /// past the joint's limits than [`JOINT_LIMIT_SLACK`](crate::JOINT_LIMIT_SLACK) of the
    /// joint's range.
    #[error(
        "{path}:{line}:{column}: {name} = {v} rad (the external encoder of joint {joint:?}) is outside [{lo}, {hi}] rad: the joint's limits [{min_rad}, {max_rad}] rad widened by {pct}% of its range",
        v = readable(*.value_rad),
        lo = tidy(*.min_rad - *.slack_rad),
        hi = tidy(*.max_rad + *.slack_rad),
        pct = crate::JOINT_LIMIT_SLACK * 100.0
    )]
    ExtOutsideJointLimits {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// The column's name (`ext1` … `ext4`).
        name: String,
        /// The joint's name in the device file.
        joint: String,
        /// The reading in rad.
        value_rad: f64,
        /// The joint's lower limit in rad.
        min_rad: f64,
        /// The joint's upper limit in rad.
        max_rad: f64,
        /// How far past a limit a reading is accepted, rad.
        slack_rad: f64,
    },
    /// A measured quantity (a log's `distance_m`, a marker's position, an observed pose's
    /// translation) has bit-identical values in every one of at least two rows: a frozen or
    /// disconnected sensor, whose data would fit any model with a residual of 0.
    #[error(
        "{path}:{line}:{column}: {name} is {value} in all {rows} {what}: the measurement does not change (a frozen or disconnected sensor?)"
    )]
    FrozenMeasurement {
        /// The file.
        path: PathBuf,
        /// 1-based line of the header (of the first observation for YAML).
        line: u64,
        /// 1-based column of the (first) column.
        column: u64,
        /// The column name or names as the file spells them (`distance_m`, `x, y, z`).
        name: String,
        /// The constant value with its unit (`0.512 m`, `(0.1, 0.2, 0.3) m`).
        value: String,
        /// The number of rows (observations) holding it.
        rows: usize,
        /// `rows` or `observations`.
        what: &'static str,
    },
    /// `t_s` decreases from one row to the next.
    #[error("{path}:{line}: t_s = {t_s} s is before the previous row's {previous_t_s} s")]
    TimeOrder {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// This row's time in s.
        t_s: f64,
        /// The previous row's time in s.
        previous_t_s: f64,
    },
    /// The CSV reader failed (invalid UTF-8, …).
    #[error("{path}:{line}: {message}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// What went wrong.
        message: String,
    },
    /// A measurement file whose marker and distance cells are empty in every row: joint
    /// readings and nothing measured.
    #[error(
        "{path}:{line}:{column}: the measurement columns ({columns}) are empty in all {rows} rows: no row measures a marker or a distance, so there is nothing to calibrate from"
    )]
    NothingMeasured {
        /// The file.
        path: PathBuf,
        /// 1-based line of the header.
        line: u64,
        /// 1-based column of the first measurement column.
        column: u64,
        /// The measurement columns, comma-separated.
        columns: String,
        /// Number of data rows.
        rows: usize,
    },
    /// A column edit (`--column-unit`, `--column-sign`, `--column-offset`) names a column the
    /// file does not have.
    #[error("{path}:{line}: {flag}: the file has no column {name:?}; its columns are {columns}")]
    UnknownColumn {
        /// The file.
        path: PathBuf,
        /// 1-based line of the column names (1; for a file without a header, its first row).
        line: u64,
        /// The edit as its flag spells it.
        flag: String,
        /// The column named.
        name: String,
        /// The file's columns, comma-separated (`q1..qn` for a file without a header).
        columns: String,
    },
    /// A column edit gives a length unit to an angle column, or an angle unit to a length
    /// column.
    #[error(
        "{path}:{line}: {flag}: {unit} is {} but column {name:?} holds {}; give it a unit of its kind",
        .unit.kind_words(),
        .unit.other_words()
    )]
    ColumnUnitKind {
        /// The file.
        path: PathBuf,
        /// 1-based line of the column names.
        line: u64,
        /// The edit as its flag spells it.
        flag: String,
        /// The column.
        name: String,
        /// The unit given (the column holds the other kind of quantity).
        unit: crate::ColumnUnit,
    },
    /// A column edit names a column that has no unit, sign or offset (time, a quaternion
    /// component, a column the reader ignores).
    #[error(
        "{path}:{line}: {flag}: column {name:?} holds {holds}: it takes no unit, sign or offset"
    )]
    ColumnNotEditable {
        /// The file.
        path: PathBuf,
        /// 1-based line of the column names.
        line: u64,
        /// The edit as its flag spells it.
        flag: String,
        /// The column.
        name: String,
        /// What the column holds, in words.
        holds: &'static str,
    },
    /// A file holds fewer data rows than needed.
    #[error("{path}: expected at least {min} data rows, found {found}")]
    TooFewRows {
        /// The file.
        path: PathBuf,
        /// The minimum number of rows.
        min: usize,
        /// The number of rows found.
        found: usize,
    },
    /// A TOML syntax or type error.
    #[error("{path}:{line}:{column}: {message}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// What the TOML parser expected.
        message: String,
    },
    /// A device file is well-formed TOML but describes an impossible device.
    #[error("{path}:{line}:{column}: {message}")]
    InvalidDevice {
        /// The file.
        path: PathBuf,
        /// 1-based line of the offending row or value (1 if the whole file is at fault).
        line: u64,
        /// 1-based column.
        column: u64,
        /// What is wrong.
        message: String,
    },
    /// A URDF file cannot be parsed or holds something hapcal does not support.
    #[error("{path}: {message}")]
    Urdf {
        /// The URDF file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A URDF joint type other than revolute, continuous, prismatic or fixed lies on the chain.
    #[error(
        "{path}: joint {joint:?} is {kind}; only revolute, continuous, prismatic and fixed joints are supported"
    )]
    UnsupportedJoint {
        /// The URDF file.
        path: PathBuf,
        /// The joint's name.
        joint: String,
        /// Its type (`prismatic`, `floating`, …).
        kind: String,
    },
    /// The joint columns of a measurement file match no joint of the device.
    #[error(
        "{path}:{line}: expected a column per joint, named q1..q{n} or {}; missing {}; the file's columns are {}",
        expected.join(", "), missing.join(", "), found.join(", ")
    )]
    JointColumns {
        /// The file.
        path: PathBuf,
        /// 1-based line of the header.
        line: u64,
        /// Number of joints of the device.
        n: usize,
        /// The device's joint names, in chain order.
        expected: Vec<String>,
        /// The joints (by name) without a column.
        missing: Vec<String>,
        /// Every column of the file's header, in file order.
        found: Vec<String>,
    },
    /// A marker's coordinate or orientation column set lacks a column.
    #[error("{path}:{line}:{column}: column {name:?} of marker {marker} is {what}")]
    IncompleteMarker {
        /// The file.
        path: PathBuf,
        /// 1-based line (1 = the header).
        line: u64,
        /// 1-based column: the missing cell's, or for a header the column after the last.
        column: u64,
        /// The missing column's name (`y2`, `qw`, …).
        name: String,
        /// The marker's number, 1-based.
        marker: usize,
        /// What is wrong (`missing from the header`, `empty while x2, z2 are given`, …).
        what: String,
    },
    /// A joint reading lies outside the joint's range (bounds inclusive).
    #[error(
        "{path}:{line}:{column}: joint {joint:?} = {v} {unit} is outside [{min}, {max}] {unit}",
        v = readable(*.value)
    )]
    OutsideJointRange {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// The joint's name.
        joint: String,
        /// The reading, in `unit`.
        value: f64,
        /// Lower limit.
        min: f64,
        /// Upper limit.
        max: f64,
        /// `rad` or `m`.
        unit: &'static str,
    },
    /// A YAML syntax or structure error.
    #[error("{path}:{line}:{column}: {message}")]
    Yaml {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 if unknown).
        line: u64,
        /// 1-based column (0 if unknown).
        column: u64,
        /// What is wrong.
        message: String,
    },
    /// The requested tip link is not in the URDF.
    #[error("{path}: no link named {tip:?}; the links are: {}", available.join(", "))]
    TipNotFound {
        /// The URDF file.
        path: PathBuf,
        /// The requested tip.
        tip: String,
        /// Every link of the URDF, in file order.
        available: Vec<String>,
    },
    /// A placement to write back names a joint that the URDF does not have.
    #[error("{path}: no joint named {joint:?} to write back")]
    UnknownJoint {
        /// The URDF file.
        path: PathBuf,
        /// The joint's name.
        joint: String,
    },
    /// The XML of a URDF is malformed.
    #[error("{path}:{line}:{column}: {message}")]
    Xml {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// What the XML reader said.
        message: String,
    },
    /// A MUKCa placement folder (or run folder) holds no `hole_0.csv`.
    #[error("{dir}: no socket file hole_0.csv, neither in it nor in its subfolders")]
    NoSockets {
        /// The folder.
        dir: PathBuf,
    },
    /// The socket files of a MUKCa placement are not numbered 0, 1, … without gaps.
    #[error("{dir}: {missing} is missing, but a socket file with a higher number exists")]
    SocketGap {
        /// The placement folder.
        dir: PathBuf,
        /// The missing file name (`hole_1.csv`).
        missing: String,
    },
    /// The kinematics crate rejected the chain description.
    #[error("invalid kinematic chain: {source}")]
    Chain {
        /// Why.
        source: hapcal_kinematics::Error,
    },
    /// A length is finite but its magnitude exceeds [`MAX_LENGTH_M`](crate::MAX_LENGTH_M).
    #[error(
        "{path}:{line}:{column}: {name} = {value_m:e} m is out of range: a length must lie within ±{limit_m} m"
    )]
    LengthOutOfRange {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// Column, key or attribute name (`distance_m`, `dh[2].a_m`, …).
        name: String,
        /// The value found, m.
        value_m: f64,
        /// [`MAX_LENGTH_M`](crate::MAX_LENGTH_M).
        limit_m: f64,
    },
    /// A distance (cable encoder, ballbar) is negative.
    #[error(
        "{path}:{line}:{column}: {name} = {value_m} m is negative: a distance must lie within [0, {limit_m}] m"
    )]
    NegativeDistance {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: u64,
        /// The column's name.
        name: String,
        /// The value found, m.
        value_m: f64,
        /// [`MAX_LENGTH_M`](crate::MAX_LENGTH_M).
        limit_m: f64,
    },
    /// A CSV row is one field holding another separator: the file is not comma-separated.
    #[error(
        "{path}:{line}:1: expected comma-separated columns, found one field {found:?}; the columns look separated by {separator}"
    )]
    Separator {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// The field (cut to 60 characters).
        found: String,
        /// The separator seen (`';'`, a tab, …), described.
        separator: &'static str,
    },
    /// A URDF's links and joints do not form one tree (a joint names an undefined link, a link
    /// has two parent joints, several roots, lengths that are not in metres).
    #[error("{path}:{line}:{column}: {message}")]
    UrdfStructure {
        /// The file.
        path: PathBuf,
        /// 1-based line of the element at fault (0 if it cannot be located).
        line: u64,
        /// 1-based column.
        column: u64,
        /// What is wrong, naming the joint or link.
        message: String,
    },
    /// A calibration record the file contract refuses (`hapcal-contract`): an unknown
    /// value name, a wrong unit, a missing key of its schema, a newer schema.
    #[error("{source}")]
    Contract {
        /// The contract's message, with the record's origin and, where known, line and
        /// column.
        source: hapcal_contract::ContractError,
    },
    /// A targets file (the positions and orientations a compensation is asked to reach) that
    /// does not hold targets: no header, missing or unknown columns, a row of the wrong width,
    /// a quaternion that is not a unit one, a start command outside the joint limits.
    #[error("{}: {message}", place(path, *line, *column))]
    Targets {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when the file as a whole is at fault).
        line: u64,
        /// 1-based column (0 when the line as a whole is at fault).
        column: u64,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A calibrated value cannot be applied to the device.
    #[error("parameter {name:?}: {message}")]
    Parameter {
        /// The parameter name (`dtheta3`, `joint_a2.rx`).
        name: String,
        /// What is wrong.
        message: String,
    },
}

impl Error {
    /// `Ok` if `value_m` is a length within ±[`MAX_LENGTH_M`](crate::MAX_LENGTH_M) (NaN and
    /// infinities are left to the finiteness checks), else [`Error::LengthOutOfRange`].
    pub(crate) fn check_length(
        path: &std::path::Path,
        line: u64,
        column: u64,
        name: &str,
        value_m: f64,
    ) -> Result<(), Error> {
        if value_m.abs() > crate::MAX_LENGTH_M && value_m.is_finite() {
            return Err(Error::LengthOutOfRange {
                path: path.to_path_buf(),
                line,
                column,
                name: name.to_owned(),
                value_m,
                limit_m: crate::MAX_LENGTH_M,
            });
        }
        Ok(())
    }

    /// Reads `path` as UTF-8 text. Invalid UTF-8 is not an [`Error::Io`] but the error that
    /// `located` makes from the 1-based line and column of the first invalid byte and a
    /// message, so that it names file:line:column like every other parse error.
    pub(crate) fn read_text(
        path: &std::path::Path,
        located: impl FnOnce(u64, u64, String) -> Error,
    ) -> Result<String, Error> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        String::from_utf8(bytes).map_err(|e| {
            let valid = e.utf8_error().valid_up_to();
            let prefix = std::str::from_utf8(e.as_bytes().get(..valid).unwrap_or_default())
                .unwrap_or_default();
            let (line, column) = line_column(prefix, valid);
            located(line, column, "invalid UTF-8".to_owned())
        })
    }

    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// `path`, `path:line` or `path:line:column` as far as `line` and `column` are known (0 for
/// unknown).
fn place(path: &std::path::Path, line: u64, column: u64) -> String {
    match (line, column) {
        (0, _) => path.display().to_string(),
        (line, 0) => format!("{}:{line}", path.display()),
        (line, column) => format!("{}:{line}:{column}", path.display()),
    }
}

/// 1-based (line, column) of byte offset `offset` in `text` as this crate's errors hold them:
/// [`hapcal_contract::line_column`] (columns count characters; an offset past the end or
/// inside a character is clamped; never panics). Used for TOML spans here and in `hapcal-sim`.
pub fn line_column(text: &str, offset: usize) -> (u64, u64) {
    let (line, column) = hapcal_contract::line_column(text, offset);
    (line as u64, column as u64)
}

/// [`hapcal_contract::toml_error_at`] with this crate's `u64` positions: the line and column
/// of a TOML error in `text` (1, 1 when it has none) and its message. Used for device files
/// here and truth files in `hapcal-sim`.
pub fn toml_error_at(text: &str, e: &toml::de::Error) -> (u64, u64, String) {
    let (line, column, message) = hapcal_contract::toml_error_at(text, e);
    (line as u64, column as u64, message)
}

/// `value` as a user reads it: scientific notation for magnitudes of a million and more (a
/// 1e308 in a file is printed as `1e308`, not as 309 digits), plain otherwise.
pub(crate) fn readable(value: f64) -> String {
    if value.abs() >= 1e6 {
        format!("{value:e}")
    } else {
        format!("{value}")
    }
}

/// A computed bound as a user reads it: rounded to 12 significant digits (−1.5 − 0.3 is
/// shown as `-1.8`, not `-1.8000000000000003`), then as [`readable`].
fn tidy(value: f64) -> String {
    readable(format!("{value:.11e}").parse().unwrap_or(value))
}

#[cfg(test)]
mod tests {
    use super::tidy;

    #[test]
    fn tidy_rounds_sums_of_limits() {
        assert_eq!(tidy(-1.5 - 0.1 * 3.0), "-1.8");
        assert_eq!(tidy(2e7), "2e7");
        assert_eq!(tidy(0.125), "0.125");
    }
}
