//! The second stage of a measurement CSV: its data rows, each cell converted to SI and
//! checked (joint ranges, time order, distances, markers seen whole, unit quaternions), with
//! what the later checks and warnings need (readings past their joint's limits, repeated
//! rows, frozen measurements).

use std::path::Path;

use nalgebra::UnitQuaternion;

use super::header::{Header, MarkerColumns};
use super::{
    IdenticalMarkers, JointSchema, MarkerSample, MeasuredRow, MeasurementTable, Reach,
    measured_values, reach,
};
use crate::Error;
use crate::columns::{Conversion, si_of};
use crate::table::{Frozen, Repeats, Table, check_separator, number};

impl MeasurementTable {
    /// A table of marker positions built in memory (a simulation, a test) rather than read:
    /// `rows` with `n_markers` markers each, named `name` as if read from `path`; no
    /// orientation, no distance, no warnings, no ignored columns.
    pub fn positions(
        name: impl Into<String>,
        path: impl Into<std::path::PathBuf>,
        n_markers: usize,
        rows: Vec<MeasuredRow>,
    ) -> MeasurementTable {
        MeasurementTable {
            name: name.into(),
            path: path.into(),
            rows,
            warnings: Vec::new(),
            n_markers,
            has_orientation: false,
            has_distance: false,
            ignored_columns: Vec::new(),
        }
    }
}

/// The rows stage's output.
pub(super) struct Body {
    /// The data rows kept (every `stride`-th from the first), in file order.
    pub(super) rows: Vec<MeasuredRow>,
    /// How many data rows the file has.
    pub(super) n_rows: usize,
    /// Whether any row has a marker seen or a distance.
    pub(super) any_measured: bool,
    /// The markers' positions, to find copied column sets.
    pub(super) identical: IdenticalMarkers,
    pub(super) outside: Outside,
    pub(super) repeats: Repeats,
    /// The distance column's values.
    pub(super) frozen_distance: Frozen,
    /// Each marker's positions where it is seen.
    pub(super) frozen_position: Vec<Frozen>,
}

/// Joint readings past their limits by at most the slack: how many, and the first.
#[derive(Default)]
pub(super) struct Outside {
    n: usize,
    first: String,
}

impl Outside {
    /// One more reading past its limits, described by `message` if it is the first.
    pub(super) fn see(&mut self, message: impl FnOnce() -> String) {
        self.n += 1;
        if self.n == 1 {
            self.first = message();
        }
    }

    /// The warning about them, if any.
    pub(super) fn warning(&self) -> Option<String> {
        match self.n {
            0 => None,
            1 => Some(format!(
                "{}; such readings are used as they are",
                self.first
            )),
            n => Some(format!(
                "{} (and {} more readings outside their joint's limits); such readings are used as they are",
                self.first,
                n - 1
            )),
        }
    }
}

/// One record's cells, read as the header says.
struct Cells<'a> {
    path: &'a Path,
    line: u64,
    names: &'a [String],
    record: &'a csv::StringRecord,
    conversion: &'a [Conversion],
}

impl Cells<'_> {
    fn cell(&self, c: usize) -> &str {
        self.record.get(c).unwrap_or("")
    }
    /// Cell `c` as a finite number, as written.
    fn value(&self, c: usize) -> Result<f64, Error> {
        number(
            self.path,
            self.line,
            c as u64 + 1,
            &self.names[c],
            self.cell(c),
        )
    }
    /// Cell `c` in SI units.
    fn si(&self, c: usize) -> Result<f64, Error> {
        si_of(self.conversion, c, &|k| self.value(k))
    }
    fn check_length(&self, c: usize, v: f64) -> Result<(), Error> {
        Error::check_length(self.path, self.line, c as u64 + 1, &self.names[c], v)
    }
}

/// Reads the data rows of `table` after its header `h`, keeping every `stride`-th (≥ 1) from
/// the first; every row is checked and seen by the checks over all rows.
///
/// # Errors
/// As [`super::read_measurement_file`], for a row.
pub(super) fn read_rows(
    path: &Path,
    table: &mut Table<'_>,
    schema: &JointSchema<'_>,
    h: &Header,
    stride: usize,
) -> Result<Body, Error> {
    let mut body = Body {
        rows: Vec::new(),
        n_rows: 0,
        any_measured: false,
        identical: IdenticalMarkers::default(),
        outside: Outside::default(),
        repeats: Repeats::default(),
        frozen_distance: Frozen::default(),
        frozen_position: (0..h.markers.len()).map(|_| Frozen::default()).collect(),
    };
    let mut previous_t: Option<f64> = None;
    while let Some((line, record)) = table.next_record()? {
        if record.len() != h.names.len() {
            check_separator(path, line, record, h.names.len())?;
            return Err(Error::Ragged {
                path: path.to_path_buf(),
                line,
                expected: h.names.len(),
                found: record.len(),
            });
        }
        let cells = Cells {
            path,
            line,
            names: &h.names,
            record,
            conversion: &h.conversion,
        };
        let q = joint_readings(&cells, schema, &h.joint_column, &mut body.outside)?;
        let t_s = time(&cells, h.time_column, &mut previous_t)?;
        let distance_m = distance(&cells, h.distance_column, &mut body.frozen_distance)?;
        let markers = marker_samples(&cells, &h.markers, &mut body.frozen_position)?;
        let row = MeasuredRow {
            line,
            q: q.into(),
            t_s,
            markers,
            distance_m,
        };
        body.repeats.see(measured_values(&row), line);
        body.identical.see(body.n_rows, &row.markers);
        body.any_measured |= !row.markers.is_empty() || row.distance_m.is_some();
        if body.n_rows.is_multiple_of(stride) {
            body.rows.push(row);
        }
        body.n_rows += 1;
    }
    // The rows were pushed one by one: give back what the vector's growth reserved.
    body.rows.shrink_to_fit();
    Ok(body)
}

/// The row's joint readings in chain order, each within its joint's limits or (noted in
/// `outside`) past them by at most the slack.
fn joint_readings(
    cells: &Cells<'_>,
    schema: &JointSchema<'_>,
    joint_column: &[usize],
    outside: &mut Outside,
) -> Result<Vec<f64>, Error> {
    let mut q = Vec::with_capacity(joint_column.len());
    for (j, &c) in joint_column.iter().enumerate() {
        let prismatic = schema.prismatic.get(j).copied().unwrap_or(false);
        let v = cells.si(c)?;
        if prismatic {
            cells.check_length(c, v)?;
        }
        let (min, max) = schema
            .limits
            .get(j)
            .copied()
            .unwrap_or((f64::MIN, f64::MAX));
        let unit = if prismatic { "m" } else { "rad" };
        match reach(v, (min, max)) {
            Reach::Within => {}
            Reach::Slack => outside.see(|| {
                format!(
                    "{}:{}:{}: joint {:?} = {v} {unit} is outside its limits [{min}, {max}] {unit}",
                    cells.path.display(),
                    cells.line,
                    c + 1,
                    schema.names[j]
                )
            }),
            Reach::Outside => {
                return Err(Error::OutsideJointRange {
                    path: cells.path.to_path_buf(),
                    line: cells.line,
                    column: c as u64 + 1,
                    joint: schema.names[j].clone(),
                    value: v,
                    min,
                    max,
                    unit,
                });
            }
        }
        q.push(v);
    }
    Ok(q)
}

/// The row's time, if the file has a time column: not before the last time given.
fn time(
    cells: &Cells<'_>,
    time_column: Option<usize>,
    previous_t: &mut Option<f64>,
) -> Result<Option<f64>, Error> {
    let t_s = time_column.map(|c| cells.value(c)).transpose()?;
    if let (Some(t), Some(before)) = (t_s, *previous_t)
        && t < before
    {
        return Err(Error::TimeOrder {
            path: cells.path.to_path_buf(),
            line: cells.line,
            t_s: t,
            previous_t_s: before,
        });
    }
    *previous_t = t_s.or(*previous_t);
    Ok(t_s)
}

/// The row's distance, if the file has a distance column and the cell is not empty: ≥ 0.
fn distance(
    cells: &Cells<'_>,
    distance_column: Option<usize>,
    frozen: &mut Frozen,
) -> Result<Option<f64>, Error> {
    let Some(c) = distance_column.filter(|&c| !cells.cell(c).is_empty()) else {
        return Ok(None);
    };
    let d = cells.si(c)?;
    cells.check_length(c, d)?;
    if d < 0.0 {
        return Err(Error::Csv {
            path: cells.path.to_path_buf(),
            line: cells.line,
            message: format!(
                "column {} ({:?}): expected a distance ≥ 0, found {}",
                c + 1,
                cells.names[c],
                cells.cell(c)
            ),
        });
    }
    frozen.see(&[d]);
    Ok(Some(d))
}

/// The markers seen in the row: each whose cells are all given (one whose cells are all
/// empty is not seen).
fn marker_samples(
    cells: &Cells<'_>,
    markers: &[MarkerColumns],
    frozen_position: &mut [Frozen],
) -> Result<Vec<MarkerSample>, Error> {
    let mut seen = Vec::with_capacity(markers.len());
    for (k, m) in markers.iter().enumerate() {
        if !marker_seen(cells, k, m)? {
            continue;
        }
        let mut position_m = [0.0; 3];
        for (p, c) in position_m.iter_mut().zip(m.position.iter().flatten()) {
            *p = cells.si(*c)?;
            cells.check_length(*c, *p)?;
        }
        if let Some(frozen) = frozen_position.get_mut(k) {
            frozen.see(&position_m);
        }
        seen.push(MarkerSample {
            marker: k,
            position_m,
            rotation: rotation(cells, m)?,
        });
    }
    Ok(seen)
}

/// Whether marker `k` is seen in the row: all its cells given (`Ok(true)`) or none
/// (`Ok(false)`).
fn marker_seen(cells: &Cells<'_>, k: usize, m: &MarkerColumns) -> Result<bool, Error> {
    let all: Vec<usize> = m.all().copied().collect();
    let empty: Vec<usize> = all
        .iter()
        .copied()
        .filter(|&c| cells.cell(c).is_empty())
        .collect();
    if empty.len() == all.len() {
        return Ok(false);
    }
    if let Some(&c) = empty.first() {
        let given: Vec<&str> = (all.iter())
            .filter(|c| !empty.contains(c))
            .map(|&c| cells.names[c].as_str())
            .collect();
        return Err(Error::IncompleteMarker {
            path: cells.path.to_path_buf(),
            line: cells.line,
            column: c as u64 + 1,
            name: cells.names[c].clone(),
            marker: k + 1,
            what: format!("empty while {} are given", given.join(", ")),
        });
    }
    Ok(true)
}

/// The marker's orientation, `[w, x, y, z]`: its quaternion (of unit norm within 10⁻³,
/// normalised), or its roll, pitch, yaw; `None` without orientation columns.
fn rotation(cells: &Cells<'_>, m: &MarkerColumns) -> Result<Option<[f64; 4]>, Error> {
    if let [Some(w), Some(x), Some(y), Some(z)] = m.quaternion {
        let quaternion = [
            cells.value(w)?,
            cells.value(x)?,
            cells.value(y)?,
            cells.value(z)?,
        ];
        let norm = quaternion.iter().map(|v| v * v).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > 1e-3 {
            return Err(Error::Csv {
                path: cells.path.to_path_buf(),
                line: cells.line,
                message: format!(
                    "columns {}..{}: expected a unit quaternion qw,qx,qy,qz, found one of norm {norm}",
                    w + 1,
                    z + 1
                ),
            });
        }
        Ok(Some(quaternion.map(|v| v / norm)))
    } else if let [Some(r), Some(p), Some(y)] = m.rpy {
        let rotation = UnitQuaternion::from_euler_angles(cells.si(r)?, cells.si(p)?, cells.si(y)?);
        Ok(Some([rotation.w, rotation.i, rotation.j, rotation.k]))
    } else {
        Ok(None)
    }
}
