//! The first stage of a measurement CSV: its header. What each column holds, each joint's
//! column, each marker's columns, the distance and time columns, the columns ignored, and
//! each column's conversion to SI.

use std::path::Path;

use super::JointSchema;
use crate::Error;
use crate::columns::{ColumnInfo, Conversion, Quantity, Units, conversions};
use crate::table::{Table, check_separator, first_duplicate};

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

impl Column {
    /// The marker a marker column belongs to.
    fn marker(self) -> Option<usize> {
        match self {
            Column::Position(k, _) | Column::Quaternion(k, _) | Column::Rpy(k, _) => Some(k),
            _ => None,
        }
    }
}

/// Column indices (0-based) of one marker's cells.
#[derive(Clone, Debug, Default)]
pub(super) struct MarkerColumns {
    pub(super) position: [Option<usize>; 3],
    pub(super) quaternion: [Option<usize>; 4],
    pub(super) rpy: [Option<usize>; 3],
}

impl MarkerColumns {
    /// Every column of the marker: position, quaternion, roll / pitch / yaw.
    pub(super) fn all(&self) -> impl Iterator<Item = &usize> {
        (self
            .position
            .iter()
            .chain(&self.quaternion)
            .chain(&self.rpy))
        .flatten()
    }
}

/// The header stage's output.
pub(super) struct Header {
    /// The header's line.
    pub(super) line: u64,
    /// The column names, in file order.
    pub(super) names: Vec<String>,
    /// Each joint's column, in chain order.
    pub(super) joint_column: Vec<usize>,
    /// Each marker's columns (as many as the highest marker number).
    pub(super) markers: Vec<MarkerColumns>,
    pub(super) distance_column: Option<usize>,
    pub(super) time_column: Option<usize>,
    /// Columns that mean nothing to hapcal, in file order.
    pub(super) ignored_columns: Vec<String>,
    /// Each column's conversion to SI.
    pub(super) conversion: Vec<Conversion>,
}

/// Reads and checks the header of `table` (its first record) against `schema` and `units`.
///
/// # Errors
/// As [`super::read_measurement_file`], for the header.
pub(super) fn read_header(
    path: &Path,
    table: &mut Table<'_>,
    schema: &JointSchema<'_>,
    units: &Units,
) -> Result<Header, Error> {
    let Some((line, header)) = table.next_record()? else {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    };
    check_separator(path, line, header, schema.names.len() + 1)?;
    let names: Vec<String> = header.iter().map(str::to_owned).collect();
    let columns: Vec<Column> = names.iter().map(|c| classify(c, schema)).collect();
    if let Some(c) = first_duplicate(&names) {
        return Err(duplicate(path, &names, c));
    }
    let joint_column = joint_columns(path, line, &names, &columns, schema)?;
    let markers = marker_columns(path, line, &names, &columns)?;
    let (distance_column, time_column) = single_columns(path, &names, &columns)?;
    let ignored_columns: Vec<String> = (names.iter().zip(&columns))
        .filter(|(_, c)| **c == Column::Ignored)
        .map(|(n, _)| n.clone())
        .collect();
    // Each column's conversion to SI, before any check on its readings.
    let conversion = conversions(path, line, &column_infos(&names, &columns, schema), units)?;
    Ok(Header {
        line,
        names,
        joint_column,
        markers,
        distance_column,
        time_column,
        ignored_columns,
        conversion,
    })
}

/// [`Error::DuplicateColumn`] for column `c` (0-based).
fn duplicate(path: &Path, names: &[String], c: usize) -> Error {
    Error::DuplicateColumn {
        path: path.to_path_buf(),
        column: c as u64 + 1,
        name: names[c].clone(),
    }
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

/// Each joint's column, in chain order: each joint exactly once (a joint named both `q2`
/// and by name is a duplicate).
fn joint_columns(
    path: &Path,
    line: u64,
    names: &[String],
    columns: &[Column],
    schema: &JointSchema<'_>,
) -> Result<Vec<usize>, Error> {
    let n = schema.names.len();
    let mut joint_column = vec![None; n];
    for (c, column) in columns.iter().enumerate() {
        if let Column::Joint(j) = *column {
            if joint_column[j].is_some() {
                return Err(duplicate(path, names, c));
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
            line,
            n,
            expected: schema.names.to_vec(),
            missing,
            found: names.to_vec(),
        });
    }
    Ok(joint_column.into_iter().flatten().collect())
}

/// The header's markers, for [`Error::IncompleteMarker`] at the header.
struct MarkerHeader<'a> {
    path: &'a Path,
    line: u64,
    names: &'a [String],
    /// Whether marker 1 is spelled without its number (`x, y, z`).
    unnumbered: bool,
}

impl MarkerHeader<'_> {
    /// [`Error::IncompleteMarker`] of marker `k`'s component `stem`.
    fn incomplete(&self, k: usize, stem: &str, what: &str) -> Error {
        Error::IncompleteMarker {
            path: self.path.to_path_buf(),
            line: self.line,
            column: self.names.len() as u64 + 1,
            name: spelled(stem, k, self.unnumbered),
            marker: k + 1,
            what: what.to_owned(),
        }
    }
}

/// The column name of marker `k`'s component `stem` as the file spells it.
fn spelled(stem: &str, k: usize, unnumbered: bool) -> String {
    if unnumbered {
        stem.to_owned()
    } else {
        format!("{stem}{}", k + 1)
    }
}

/// Each marker's columns, up to the highest marker number: every marker with a full
/// position, and a full orientation (quaternion or roll / pitch / yaw, not both) if any.
fn marker_columns(
    path: &Path,
    line: u64,
    names: &[String],
    columns: &[Column],
) -> Result<Vec<MarkerColumns>, Error> {
    let header = MarkerHeader {
        path,
        line,
        names,
        unnumbered: names.iter().any(|c| c == "x" || c == "y" || c == "z"),
    };
    let n_markers = (columns.iter().filter_map(|c| c.marker()))
        .map(|k| k + 1)
        .max()
        .unwrap_or(0);
    if n_markers > names.len() {
        // A marker number past the number of columns (`x123456789012`): some marker below
        // it has no column at all, and a table of that many markers must not be allocated.
        let present: std::collections::HashSet<usize> =
            columns.iter().filter_map(|c| c.marker()).collect();
        let k = (0..=names.len())
            .find(|k| !present.contains(k))
            .unwrap_or(0);
        return Err(header.incomplete(k, "x", "missing from the header"));
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
            return Err(duplicate(path, names, c));
        }
        *slot = Some(c);
    }
    for (k, m) in markers.iter().enumerate() {
        check_marker(&header, k, m)?;
    }
    Ok(markers)
}

/// Marker `k` has its full position, and a full quaternion or roll / pitch / yaw if any of
/// it, not both.
fn check_marker(header: &MarkerHeader<'_>, k: usize, m: &MarkerColumns) -> Result<(), Error> {
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
            return Err(header.incomplete(k, stem.1, "missing from the header"));
        }
    }
    if m.quaternion[0].is_some() && m.rpy[0].is_some() {
        return Err(header.incomplete(
            k,
            "phix",
            "given beside a quaternion: give one orientation, qw,qx,qy,qz or phix,phiy,phiz",
        ));
    }
    Ok(())
}

/// The distance and time columns, each at most once.
fn single_columns(
    path: &Path,
    names: &[String],
    columns: &[Column],
) -> Result<(Option<usize>, Option<usize>), Error> {
    let distance_column = columns.iter().position(|c| *c == Column::Distance);
    let time_column = columns.iter().position(|c| *c == Column::Time);
    if columns.iter().filter(|c| **c == Column::Distance).count() > 1
        || columns.iter().filter(|c| **c == Column::Time).count() > 1
    {
        let (c, _) = (columns.iter().enumerate())
            .filter(|(_, c)| matches!(c, Column::Distance | Column::Time))
            .nth(1)
            .unwrap_or((0, &Column::Ignored));
        return Err(duplicate(path, names, c));
    }
    Ok((distance_column, time_column))
}

/// What each column holds, for its conversion to SI by the units.
fn column_infos(names: &[String], columns: &[Column], schema: &JointSchema<'_>) -> Vec<ColumnInfo> {
    (names.iter().zip(columns))
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
        .collect()
}
