//! Python bindings of hapcal (`hapcal._hapcal`): devices, measurements (files or arrays), the
//! calibration of `hapcal-calibrate`, and the `simulate`, `plan-poses`, `diagnose`, `check` and
//! `import-urdf` workflows (`hapcal-sim`, `hapcal_calibrate::plan`, `hapcal-diagnose`,
//! `hapcal_calibrate::setup`, `hapcal_io::import_urdf_tree`). The Python package `hapcal`
//! (python/hapcal) wraps this module with NumPy / pandas conveniences; everything numeric
//! happens here, in the same library functions the `hapcal` command line calls.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use hapcal_calibrate::calibrate::{self, ModelChoice, Outcome, Plan};
use hapcal_calibrate::measured::{self, Robot};
use hapcal_calibrate::setup::Gated;
use hapcal_io::{
    AngleUnit, JOINT_LIMIT_SLACK, LengthUnit, MarkerSample, MeasuredRow, MeasurementTable, Units,
};
use nalgebra::UnitQuaternion;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

create_exception!(
    hapcal,
    HapcalError,
    PyValueError,
    "An error reported by hapcal: unreadable or inconsistent input, or data that cannot determine the model. The message is the whole chain of causes (file:line:column where there is one)."
);

/// The anyhow chain as one message (`outer: inner: …`), as the command line prints it.
fn py_err(e: anyhow::Error) -> PyErr {
    HapcalError::new_err(hapcal_calibrate::calibrate::error_chain(&e))
}

fn units(length_unit: &str, angle_unit: &str) -> Result<Units> {
    let length: LengthUnit = length_unit
        .parse()
        .map_err(|e: String| anyhow!("length_unit: {e}"))?;
    let angle: AngleUnit = angle_unit
        .parse()
        .map_err(|e: String| anyhow!("angle_unit: {e}"))?;
    Ok(Units::new(length, angle))
}

/// The column edits of a measurement file, as the command line's `--column-unit`,
/// `--column-sign`, `--column-offset`, `--column-scale` and `--column-coupling` give them, each
/// in the dict's (list's) order: `units` `{"q3": "deg", "x2,y2,z2": "mm"}`, `signs`
/// `["q3"]`, `offsets` `{"q2": -1.5708}` (rad, m for a length), `scales` `{"q3": 0.01}`,
/// `couplings` `{"q6": "-0.5*q5"}`.
#[derive(Default)]
struct ColumnArgs {
    units: Option<Vec<(String, String)>>,
    signs: Option<Vec<String>>,
    offsets: Option<Vec<(String, f64)>>,
    scales: Option<Vec<(String, f64)>>,
    couplings: Option<Vec<(String, String)>>,
}

/// `units` with the edits of `args` ([`ColumnArgs`]), parsed as the command line parses its
/// options.
///
/// # Errors
/// A value the option's parser refuses, named with the Python argument.
fn with_column_edits(units: Units, args: ColumnArgs) -> Result<Units> {
    use hapcal_io::ColumnEdit;
    type Parse = fn(&str) -> std::result::Result<ColumnEdit, String>;
    let pairs = |v: Option<Vec<(String, String)>>| {
        (v.unwrap_or_default().into_iter())
            .map(|(c, x)| format!("{c}={x}"))
            .collect()
    };
    let numbers = |v: Option<Vec<(String, f64)>>| {
        (v.unwrap_or_default().into_iter())
            .map(|(c, x)| format!("{c}={x:?}"))
            .collect()
    };
    // Each argument, its option's parser, and its values as the option's text.
    let options: [(&str, Parse, Vec<String>); 5] = [
        ("column_units", ColumnEdit::parse_unit, pairs(args.units)),
        (
            "column_signs",
            ColumnEdit::parse_sign,
            args.signs.unwrap_or_default(),
        ),
        (
            "column_offsets",
            ColumnEdit::parse_offset,
            numbers(args.offsets),
        ),
        (
            "column_scales",
            ColumnEdit::parse_scale,
            numbers(args.scales),
        ),
        (
            "column_couplings",
            ColumnEdit::parse_coupling,
            pairs(args.couplings),
        ),
    ];
    let mut edits = Vec::new();
    for (argument, parse, values) in options {
        for value in values {
            edits.push(parse(&value).map_err(|e| anyhow!("{argument}: {e}"))?);
        }
    }
    Ok(units.with_columns(edits))
}

/// A device: a URDF with one or more tip links, or a hapcal device file (TOML).
#[pyclass(module = "hapcal", name = "Device", frozen)]
struct PyDevice {
    path: PathBuf,
    tip: String,
    tips: Vec<String>,
    device: hapcal_io::Device,
    /// The robot of the marker workflow, or why there is none (a haptic device's chain).
    robot: std::result::Result<Robot, String>,
}

impl PyDevice {
    fn is_urdf(path: &Path) -> bool {
        path.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
    }
}

#[pymethods]
impl PyDevice {
    /// Reads a serial URDF whose tool sits on link `tip`; `tips` names further tip links of a
    /// tree (marker k+1 sits on the k-th of `[tip, *tips]`; markers past the last on the last).
    ///
    /// Raises HapcalError for an unreadable URDF or an unknown link.
    #[staticmethod]
    #[pyo3(signature = (path, tip, tips = None))]
    fn from_urdf(path: PathBuf, tip: String, tips: Option<Vec<String>>) -> PyResult<Self> {
        let tips = tips.unwrap_or_default();
        let device = calibrate::load_device(&path, &tip).map_err(py_err)?;
        let all: Vec<String> = std::iter::once(tip.clone())
            .chain(tips.iter().cloned())
            .collect();
        let robot = measured::robot_from_urdf(&path, &all).map_err(py_err)?;
        Ok(Self {
            path,
            tip,
            tips,
            device,
            robot: Ok(robot),
        })
    }

    /// Reads a hapcal device file (TOML): a D-H / modified D-H table, URDF placements, or a
    /// capstan-driven haptic device with its transmissions.
    ///
    /// Raises HapcalError for an unreadable or invalid file (file:line:column).
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Self> {
        if Self::is_urdf(&path) {
            return Err(py_err(anyhow!(
                "{}: a URDF: use Device.from_urdf(path, tip=...)",
                path.display()
            )));
        }
        let device = calibrate::load_device(&path, "").map_err(py_err)?;
        let robot = measured::robot_from_device(&device).map_err(|e| calibrate::error_chain(&e));
        Ok(Self {
            path,
            tip: String::new(),
            tips: Vec::new(),
            device,
            robot,
        })
    }

    /// Joint names in chain order: the columns `q1..qn` of a measurement table, in order.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        match &self.robot {
            Ok(r) => r.joint_names.clone(),
            Err(_) => self.device.joints.iter().map(|j| j.name.clone()).collect(),
        }
    }

    /// Number of joints.
    #[getter]
    fn n_joints(&self) -> usize {
        self.joint_names().len()
    }

    /// Joint limits `(lower, upper)` per joint, rad (m for a prismatic joint).
    #[getter]
    fn joint_limits(&self) -> Vec<(f64, f64)> {
        match &self.robot {
            Ok(r) => r.limits.clone(),
            Err(_) => self.device.joint_limits(),
        }
    }

    /// The file the device was read from.
    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }

    /// Tip links (`[tip, *tips]`; empty for a device file).
    #[getter]
    fn tips(&self) -> Vec<String> {
        if self.tip.is_empty() {
            return Vec::new();
        }
        std::iter::once(self.tip.clone())
            .chain(self.tips.iter().cloned())
            .collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "Device({:?}, joints={:?})",
            self.path.display().to_string(),
            self.joint_names()
        )
    }
}

/// Measurements given as arrays, in SI units but for the joints (converted when the device,
/// and so which joints are prismatic, is known).
#[derive(Clone, Debug)]
struct Arrays {
    name: String,
    /// Joint readings per row, in the columns' order and `units`.
    q: Vec<Vec<f64>>,
    /// Column names of `q` (device joint names or `q1..qn`), or chain order.
    joint_names: Option<Vec<String>>,
    markers: Vec<Vec<MarkerSample>>,
    n_markers: usize,
    has_orientation: bool,
    distances: Option<Vec<Option<f64>>>,
    t_s: Option<Vec<f64>>,
    units: Units,
    ignored_columns: Vec<String>,
    /// Columns of `q` named in `joint_names` that are no joint of the device are ignored (and
    /// reported) rather than an error: a data frame's columns, as a CSV header's.
    ignore_unknown_joints: bool,
}

#[derive(Clone, Debug)]
enum Source {
    /// A measurement file (CSV, YAML), a MUKCa placement or run folder, or a hapcal log.
    Path {
        path: PathBuf,
        units: Units,
    },
    Arrays(Box<Arrays>),
}

/// Measurements: a file or folder read at calibration time, or arrays.
#[pyclass(module = "hapcal._hapcal", name = "_Measurements", frozen)]
struct PyMeasurements {
    source: Source,
}

fn check_len(what: &str, got: usize, want: usize) -> Result<()> {
    if got != want {
        bail!("{what}: expected {want} values, found {got}");
    }
    Ok(())
}

/// The marker columns of one array input, flattened row-major: `positions` `(n, k, 3)` in
/// the input's length unit, with `quaternions` `(n, k, 4)` (w, x, y, z) or `rpy` `(n, k, 3)`
/// in its angle unit; `length` and `angle` convert to m and rad.
struct FlatMarkers<'a> {
    /// Markers per row.
    n_markers: usize,
    /// Positions, `n · k · 3`.
    positions: &'a [f64],
    /// Unit quaternions, `n · k · 4`.
    quaternions: Option<&'a [f64]>,
    /// Roll, pitch, yaw, `n · k · 3`.
    rpy: Option<&'a [f64]>,
    /// The length unit in m.
    length: f64,
    /// The angle unit in rad.
    angle: f64,
}

impl FlatMarkers<'_> {
    /// The markers seen in row `i` (0-based; a marker not seen has every cell NaN).
    ///
    /// # Errors
    /// NaN beside values, a value not finite, a quaternion not of unit norm; each names
    /// `name`, the row and the marker (1-based).
    fn row(&self, name: &str, i: usize) -> Result<Vec<MarkerSample>> {
        let n_markers = self.n_markers;
        let mut seen = Vec::new();
        for k in 0..n_markers {
            let pos = &self.positions[(i * n_markers + k) * 3..][..3];
            let rot: Option<(&[f64], bool)> = match (self.quaternions, self.rpy) {
                (Some(r), _) => Some((&r[(i * n_markers + k) * 4..][..4], true)),
                (_, Some(r)) => Some((&r[(i * n_markers + k) * 3..][..3], false)),
                _ => None,
            };
            let cells: Vec<f64> = pos
                .iter()
                .chain(rot.map_or(&[][..], |r| r.0))
                .copied()
                .collect();
            let nan = cells.iter().filter(|v| v.is_nan()).count();
            if nan == cells.len() {
                continue; // not seen in this row
            }
            if nan > 0 {
                bail!(
                    "{name}: row {}, marker {}: NaN beside values ({cells:?}): a marker not seen has all its cells NaN",
                    i + 1,
                    k + 1
                );
            }
            if cells.iter().any(|v| !v.is_finite()) {
                bail!(
                    "{name}: row {}, marker {}: not finite: {cells:?}",
                    i + 1,
                    k + 1
                );
            }
            let position_m = [
                pos[0] * self.length,
                pos[1] * self.length,
                pos[2] * self.length,
            ];
            let rotation = match rot {
                Some((r, true)) => {
                    let norm = r.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if (norm - 1.0).abs() > 1e-3 {
                        bail!(
                            "{name}: row {}, marker {}: expected a unit quaternion (w, x, y, z), found one of norm {norm}",
                            i + 1,
                            k + 1
                        );
                    }
                    Some([r[0] / norm, r[1] / norm, r[2] / norm, r[3] / norm])
                }
                Some((r, false)) => {
                    let rotation = UnitQuaternion::from_euler_angles(
                        r[0] * self.angle,
                        r[1] * self.angle,
                        r[2] * self.angle,
                    );
                    Some([rotation.w, rotation.i, rotation.j, rotation.k])
                }
                None => None,
            };
            seen.push(MarkerSample {
                marker: k,
                position_m,
                rotation,
            });
        }
        Ok(seen)
    }
}

#[pymethods]
impl PyMeasurements {
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (path, length_unit, angle_unit, column_units=None, column_signs=None, column_offsets=None, column_scales=None, column_couplings=None))]
    fn from_path(
        path: PathBuf,
        length_unit: &str,
        angle_unit: &str,
        column_units: Option<Vec<(String, String)>>,
        column_signs: Option<Vec<String>>,
        column_offsets: Option<Vec<(String, f64)>>,
        column_scales: Option<Vec<(String, f64)>>,
        column_couplings: Option<Vec<(String, String)>>,
    ) -> PyResult<Self> {
        let columns = ColumnArgs {
            units: column_units,
            signs: column_signs,
            offsets: column_offsets,
            scales: column_scales,
            couplings: column_couplings,
        };
        let units = units(length_unit, angle_unit)
            .and_then(|u| with_column_edits(u, columns))
            .map_err(py_err)?;
        std::fs::metadata(&path)
            .with_context(|| format!("reading measurements {}", path.display()))
            .map_err(py_err)?;
        Ok(Self {
            source: Source::Path { path, units },
        })
    }

    /// A path in m and rad, not checked here: the workflow that reads it reports a missing
    /// file in its own words (`hapcal diagnose`'s "reading log …").
    #[staticmethod]
    fn from_path_unchecked(path: PathBuf) -> Self {
        Self {
            source: Source::Path {
                path,
                units: Units::default(),
            },
        }
    }

    /// Flat row-major arrays (shapes checked by the Python wrapper, again here).
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (name, n_rows, n_joints, q, n_markers, positions, quaternions, rpy, distances, t_s, joint_names, length_unit, angle_unit, ignored_columns, ignore_unknown_joints))]
    fn from_flat(
        name: String,
        n_rows: usize,
        n_joints: usize,
        q: Vec<f64>,
        n_markers: usize,
        positions: Option<Vec<f64>>,
        quaternions: Option<Vec<f64>>,
        rpy: Option<Vec<f64>>,
        distances: Option<Vec<f64>>,
        t_s: Option<Vec<f64>>,
        joint_names: Option<Vec<String>>,
        length_unit: &str,
        angle_unit: &str,
        ignored_columns: Vec<String>,
        ignore_unknown_joints: bool,
    ) -> PyResult<Self> {
        let arrays = (|| -> Result<Arrays> {
            let units = units(length_unit, angle_unit)?;
            if n_rows == 0 {
                bail!("{name}: no rows");
            }
            if n_joints == 0 {
                bail!("{name}: q has no joint columns");
            }
            check_len("q", q.len(), n_rows * n_joints)?;
            if let Some(names) = &joint_names {
                check_len("joint_names", names.len(), n_joints)?;
            }
            if positions.is_none() && distances.is_none() {
                bail!(
                    "{name}: no measurements: give marker positions (n, 3) or (n, k, 3), or distances (n,)"
                );
            }
            if quaternions.is_some() && rpy.is_some() {
                bail!("{name}: give one orientation, quaternions or rpy, not both");
            }
            if (quaternions.is_some() || rpy.is_some()) && positions.is_none() {
                bail!("{name}: orientations need marker positions");
            }
            if let Some(p) = &positions {
                check_len("positions", p.len(), n_rows * n_markers * 3)?;
            }
            if let Some(r) = &quaternions {
                check_len("quaternions", r.len(), n_rows * n_markers * 4)?;
            }
            if let Some(r) = &rpy {
                check_len("rpy", r.len(), n_rows * n_markers * 3)?;
            }
            if let Some(d) = &distances {
                check_len("distances", d.len(), n_rows)?;
            }
            if let Some(t) = &t_s {
                check_len("t", t.len(), n_rows)?;
            }
            let length = units.length.to_m();
            let angle = units.angle.to_rad();
            let q: Vec<Vec<f64>> = q.chunks(n_joints).map(<[f64]>::to_vec).collect();
            for (i, row) in q.iter().enumerate() {
                if let Some((j, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    bail!(
                        "{name}: row {}: q[{i}, {j}] = {v}: joint readings must be finite",
                        i + 1
                    );
                }
            }
            let flat = positions.as_deref().map(|positions| FlatMarkers {
                n_markers,
                positions,
                quaternions: quaternions.as_deref(),
                rpy: rpy.as_deref(),
                length,
                angle,
            });
            let markers = (0..n_rows)
                .map(|i| flat.as_ref().map_or(Ok(Vec::new()), |f| f.row(&name, i)))
                .collect::<Result<Vec<_>>>()?;
            let distances = match distances {
                Some(d) => Some(
                    d.iter()
                        .enumerate()
                        .map(|(i, &v)| {
                            if v.is_nan() {
                                Ok(None)
                            } else if !(v.is_finite() && v >= 0.0) {
                                bail!(
                                    "{name}: row {}: expected a distance ≥ 0, found {v}",
                                    i + 1
                                )
                            } else {
                                Ok(Some(v * length))
                            }
                        })
                        .collect::<Result<Vec<_>>>()?,
                ),
                None => None,
            };
            if let Some(t) = &t_s {
                for i in 1..t.len() {
                    if !(t[i].is_finite()) || t[i] < t[i - 1] {
                        bail!(
                            "{name}: row {}: time {} s is before the previous row's {} s (or not finite)",
                            i + 1,
                            t[i],
                            t[i - 1]
                        );
                    }
                }
            }
            Ok(Arrays {
                name: name.clone(),
                q,
                joint_names,
                markers,
                n_markers: if positions.is_some() { n_markers } else { 0 },
                has_orientation: quaternions.is_some() || rpy.is_some(),
                distances,
                t_s,
                units,
                ignored_columns,
                ignore_unknown_joints,
            })
        })()
        .map_err(py_err)?;
        Ok(Self {
            source: Source::Arrays(Box::new(arrays)),
        })
    }

    /// Number of rows (`None` for a file, read at calibration time).
    #[getter]
    fn n_rows(&self) -> Option<usize> {
        match &self.source {
            Source::Path { .. } => None,
            Source::Arrays(a) => Some(a.q.len()),
        }
    }

    /// The file or folder, for measurements read from one.
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        match &self.source {
            Source::Path { path, .. } => Some(path.clone()),
            Source::Arrays(_) => None,
        }
    }

    /// Whether the values are read (or were given) in m and rad.
    #[getter]
    fn si_units(&self) -> bool {
        match &self.source {
            Source::Path { units, .. } => *units == Units::default(),
            Source::Arrays(a) => a.units == Units::default(),
        }
    }

    /// Name of the data set in the report.
    #[getter]
    fn name(&self) -> String {
        match &self.source {
            Source::Path { path, .. } => path.file_stem().map_or_else(
                || path.display().to_string(),
                |s| s.to_string_lossy().into_owned(),
            ),
            Source::Arrays(a) => a.name.clone(),
        }
    }
}

/// The column of each device joint in `names` (a joint name or `q1..qn`), as a CSV header.
fn joint_columns(a: &Arrays, robot: &Robot) -> Result<(Vec<usize>, Vec<String>)> {
    let n = robot.joint_names.len();
    let width = a.q.first().map_or(0, Vec::len);
    let Some(names) = &a.joint_names else {
        if width != n {
            bail!(
                "{}: q has {width} columns, the device has {n} joints ({}); give q as (n, {n}) in chain order, or name the columns with joint_names",
                a.name,
                robot.joint_names.join(", ")
            );
        }
        return Ok(((0..n).collect(), Vec::new()));
    };
    let mut column = vec![None; n];
    let mut unknown = Vec::new();
    for (c, name) in names.iter().enumerate() {
        let j = robot
            .joint_names
            .iter()
            .position(|j| j == name)
            .or_else(|| {
                name.strip_prefix('q')
                    .filter(|d| !d.is_empty() && !d.starts_with('0'))
                    .and_then(|d| d.parse::<usize>().ok())
                    .filter(|&k| (1..=n).contains(&k))
                    .map(|k| k - 1)
            });
        match j {
            Some(j) if column[j].is_some() => {
                bail!(
                    "{}: joint {:?} has two columns in joint_names ({name:?})",
                    a.name,
                    robot.joint_names[j]
                )
            }
            Some(j) => column[j] = Some(c),
            None => unknown.push(name.clone()),
        }
    }
    let missing: Vec<&str> = (0..n)
        .filter(|&j| column[j].is_none())
        .map(|j| robot.joint_names[j].as_str())
        .collect();
    if !missing.is_empty() || !(unknown.is_empty() || a.ignore_unknown_joints) {
        bail!(
            "{}: expected one column per joint of the device, named {} (or q1..q{n}); found columns {}; missing {}{}",
            a.name,
            robot.joint_names.join(", "),
            names.join(", "),
            if missing.is_empty() {
                "none".to_owned()
            } else {
                missing.join(", ")
            },
            if unknown.is_empty() {
                String::new()
            } else {
                format!("; not joints of the device: {}", unknown.join(", "))
            }
        );
    }
    Ok((column.into_iter().flatten().collect(), unknown))
}

/// The measurement table of `a` for `robot`: joints in chain order and SI units, checked
/// against the joint limits as a measurement file is ([`JOINT_LIMIT_SLACK`]).
fn table(a: &Arrays, robot: &Robot) -> Result<MeasurementTable> {
    let (columns, unknown) = joint_columns(a, robot)?;
    let length = a.units.length.to_m();
    let angle = a.units.angle.to_rad();
    let mut warnings = Vec::new();
    let mut n_outside = 0usize;
    let mut rows = Vec::with_capacity(a.q.len());
    for (i, raw) in a.q.iter().enumerate() {
        let mut q = Vec::with_capacity(columns.len());
        for (j, &c) in columns.iter().enumerate() {
            let prismatic = robot.prismatic.get(j).copied().unwrap_or(false);
            let v = raw[c] * if prismatic { length } else { angle };
            let (min, max) = robot.limits.get(j).copied().unwrap_or((f64::MIN, f64::MAX));
            let slack = JOINT_LIMIT_SLACK * (max - min);
            let unit = if prismatic { "m" } else { "rad" };
            if (min..=max).contains(&v) {
            } else if (min - slack..=max + slack).contains(&v) {
                n_outside += 1;
                if n_outside == 1 {
                    warnings.push(format!(
                        "{}: row {}: joint {:?} = {v} {unit} is outside its limits [{min}, {max}] {unit}",
                        a.name,
                        i + 1,
                        robot.joint_names[j]
                    ));
                }
            } else {
                bail!(
                    "{}: row {}, column {}: joint {:?} = {v} {unit} is outside its range [{min}, {max}] {unit} (by more than {JOINT_LIMIT_SLACK} of the range): wrong unit or column?",
                    a.name,
                    i + 1,
                    c + 1,
                    robot.joint_names[j]
                );
            }
            q.push(v);
        }
        rows.push(MeasuredRow {
            line: i as u64 + 1,
            q,
            t_s: a.t_s.as_ref().map(|t| t[i]),
            markers: a.markers[i].clone(),
            distance_m: a.distances.as_ref().and_then(|d| d[i]),
        });
    }
    if let Some(w) = warnings.first_mut() {
        w.push_str(&match n_outside {
            1 => String::new(),
            n => format!(
                " (and {} more readings outside their joint's limits)",
                n - 1
            ),
        });
        w.push_str("; such readings are used as they are");
    }
    Ok(MeasurementTable {
        name: a.name.clone(),
        path: PathBuf::from(&a.name),
        rows,
        warnings,
        n_markers: a.n_markers,
        has_orientation: a.has_orientation,
        has_distance: a.distances.is_some(),
        ignored_columns: (a.ignored_columns.iter().chain(&unknown))
            .cloned()
            .collect(),
    })
}

/// The result of one calibration.
#[pyclass(module = "hapcal._hapcal", name = "_Calibration", frozen)]
struct PyCalibration {
    outcome: Outcome,
    json: String,
    /// The setup check's warnings (the command line prints them on standard error).
    setup_warnings: Vec<String>,
}

#[pymethods]
impl PyCalibration {
    /// The setup check's warnings, as the command line prints them (without its prefix).
    #[getter]
    fn setup_warnings(&self) -> Vec<String> {
        self.setup_warnings.clone()
    }

    /// The report as the command line prints it with `--json`.
    fn to_json(&self) -> String {
        self.json.clone()
    }

    /// Writes the calibrated device (`write_outputs`: the files read back first with the runtime,
    /// nothing written unless they give the calibration); returns the paths written.
    fn write_outputs(&self, py: Python<'_>, path: PathBuf) -> PyResult<Vec<PathBuf>> {
        let outcome = &self.outcome;
        py.detach(|| calibrate::write_outputs(outcome, &path))
            .map_err(py_err)
    }

    /// The calibration library's predicted positions at the joint readings `q` (one row per
    /// configuration, the device's joints in order; rad, m for a prismatic joint), m: per row
    /// and marker of a robot, the position in the instrument frame from the calibrated model
    /// the report's errors come from (`CalibratedModel::end_poses_of`, marker k on tip
    /// min(k, last)); per row of a haptic device, its end point (the readings through the
    /// identified transmissions and handle compliance; `DistanceLogModel`'s points).
    fn predicted_positions(
        &self,
        py: Python<'_>,
        q: Vec<Vec<f64>>,
    ) -> PyResult<Vec<Vec<[f64; 3]>>> {
        let outcome = &self.outcome;
        py.detach(|| library_positions(outcome, &q)).map_err(py_err)
    }
}

/// [`PyCalibration::predicted_positions`].
fn library_positions(outcome: &Outcome, q: &[Vec<f64>]) -> Result<Vec<Vec<[f64; 3]>>> {
    let model = &outcome.model;
    let n_joints = model.chain.n_joints();
    for (i, row) in q.iter().enumerate() {
        if row.len() != n_joints {
            bail!(
                "q: row {i} has {} values, expected {n_joints} (one per joint of the device)",
                row.len()
            );
        }
        if let Some(j) = row.iter().position(|v| !v.is_finite()) {
            bail!("q: row {i}, joint {j}: {} is not a finite number", row[j]);
        }
    }
    let device = &outcome.device;
    let haptic = device.has_transmissions();
    if let (true, Some(calibrated)) = (haptic, &outcome.calibrated) {
        use hapcal_calibrate::haptic;
        let nominal = haptic::HapticDevice::new(device.clone())?;
        let mut state = haptic::calibrated_log_state(calibrated)?;
        state.x_kin.clone_from(&model.x_kin);
        let rows: Vec<hapcal_io::LogRow> = (q.iter())
            .map(|q| hapcal_io::LogRow {
                q: q.clone(),
                distance_m: 0.0,
                ext: vec![None; hapcal_io::N_EXT],
                t_s: None,
                line: 0,
            })
            .collect();
        let log = haptic::log_model(&nominal, &rows, Vec::new()).context(
            "the positions of a haptic device come from its distance-log model, which needs the \
             device file's [handle] mass",
        )?;
        let lin = log.linearise(&state)?;
        return Ok((lin.points.iter()).map(|p| vec![[p.x, p.y, p.z]]).collect());
    }
    let tips: Vec<usize> = (0..model.tips.len().max(1)).collect();
    Ok((q.iter())
        .map(|row| {
            (model.end_poses_of(&tips, row).iter())
                .map(|p| {
                    let t = p.translation.vector;
                    [t.x, t.y, t.z]
                })
                .collect()
        })
        .collect())
}

/// The names of every model, as the command line's `--model` takes them (`ModelChoice`).
fn model_names() -> Vec<String> {
    ModelChoice::all()
        .iter()
        .map(|m| m.name().to_owned())
        .collect()
}

fn model_choice(model: &str) -> Result<ModelChoice> {
    ModelChoice::from_name(model).ok_or_else(|| {
        anyhow!(
            "model: expected one of {}, found {model:?}",
            model_names().join(", ")
        )
    })
}

/// The measurement tables of `sources` for `robot`: files through the command line's loader
/// (`measured::load_tables`), arrays as they are.
fn load_sources(sources: &[Source], robot: &Robot) -> Result<Vec<MeasurementTable>> {
    let mut out = Vec::new();
    for s in sources {
        match s {
            Source::Path { path, units } => out.extend(measured::load_tables(
                std::slice::from_ref(path),
                robot,
                units,
            )?),
            Source::Arrays(a) => out.push(table(a, robot)?),
        }
    }
    Ok(out)
}

/// The setup check before a calibration or diagnosis of files, as the command line's
/// (`hapcal_calibrate::setup::gate`, its messages naming `accept_setup=True`).
fn setup_gate(plan: &Plan, accept_setup: bool) -> Result<Gated> {
    let cfg = hapcal_calibrate::setup::SetupConfig {
        accept_setup,
        accept_option: "accept_setup=True",
    };
    hapcal_calibrate::setup::gate(plan, &cfg)
}

/// The paths and units of `sources`, if every one is a file.
fn file_sources(sources: &[Source]) -> Option<Vec<(PathBuf, Units)>> {
    sources
        .iter()
        .map(|s| match s {
            Source::Path { path, units } => Some((path.clone(), units.clone())),
            Source::Arrays(_) => None,
        })
        .collect()
}

/// Calibrates `device` from `train` (`test` only evaluated). See `hapcal.calibrate`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (device, train, test, model, sigma_m, sigma_rad, test_last, folds, socket_distance_m, joint, accept_setup))]
fn _calibrate(
    py: Python<'_>,
    device: &PyDevice,
    train: Vec<PyRef<'_, PyMeasurements>>,
    test: Vec<PyRef<'_, PyMeasurements>>,
    model: &str,
    sigma_m: Option<f64>,
    sigma_rad: Option<f64>,
    test_last: Option<f64>,
    folds: usize,
    socket_distance_m: f64,
    joint: bool,
    accept_setup: bool,
) -> PyResult<PyCalibration> {
    let model = model_choice(model).map_err(py_err)?;
    if train.is_empty() {
        return Err(py_err(anyhow!("no training measurements")));
    }
    let train: Vec<Source> = train.iter().map(|m| m.source.clone()).collect();
    let test: Vec<Source> = test.iter().map(|m| m.source.clone()).collect();
    let mut plan = Plan {
        workspace: None,
        device: device.path.clone(),
        tip: device.tip.clone(),
        tips: device.tips.clone(),
        units: Units::default(),
        gravity: hapcal_calibrate::calibrate::GRAVITY_DOWN,
        sigma_rad,
        test_last,
        data: Vec::new(),
        test: Vec::new(),
        socket_distance_m,
        model,
        folds,
        ladder_rows: hapcal_calibrate::fit::LADDER_ROWS,
        sigma_m,
        joint,
    };
    // Files that share their units go through `calibrate::run`, exactly as the command line.
    // The setup check runs on files, as the command line's (arrays are taken as given).
    let files = file_sources(&train).zip(file_sources(&test));
    let mut setup_warnings = Vec::new();
    let mut setup_classes = Vec::new();
    let outcome = match files {
        Some((tr, te)) if tr.iter().chain(&te).all(|(_, u)| *u == tr[0].1) => {
            plan.units = tr[0].1.clone();
            plan.data = tr.into_iter().map(|(p, _)| p).collect();
            plan.test = te.into_iter().map(|(p, _)| p).collect();
            py.detach(|| -> Result<Outcome> {
                plan.validate()?;
                let gated = setup_gate(&plan, accept_setup)?;
                (setup_warnings, setup_classes) = (gated.warnings, gated.classes);
                calibrate::run(&plan)
            })
        }
        _ => {
            let hapcal_device = &device.device;
            let robot = device.robot.as_ref();
            py.detach(|| -> Result<Outcome> {
                let start = Instant::now();
                if hapcal_device.has_transmissions() {
                    bail!(
                        "{}: a haptic device with transmissions is calibrated from its log files (Measurements.from_csv); arrays hold marker or distance measurements of an external instrument",
                        plan.device.display()
                    );
                }
                let robot = robot.map_err(|e| anyhow!("{e}"))?;
                let train = load_sources(&train, robot)?;
                let test = load_sources(&test, robot)?;
                measured::run_tables(&plan, hapcal_device, robot, train, test, start)
            })
        }
    }
    .map_err(py_err)?;
    // After the fit, as the command line: deviations no real device has say the data are
    // another's (an error unless accepted, then a warning).
    let after_fit = hapcal_calibrate::setup::SetupConfig {
        accept_setup,
        accept_option: "accept_setup=True",
    };
    setup_warnings.extend(
        hapcal_calibrate::setup::gate_after_fit(&outcome.report, &after_fit, &setup_classes)
            .map_err(py_err)?,
    );
    let json = serde_json::to_string_pretty(&outcome.report)
        .context("serialising the report")
        .map_err(py_err)?;
    Ok(PyCalibration {
        outcome,
        json,
        setup_warnings,
    })
}

/// The log columns of `rows` as `hapcal_io::write_log` writes them: `q1..qn`, `distance_m`,
/// the `ext1..ext4` present in any row (NaN where a row has none), `t_s` if any row has one.
/// Returns the column names and the values, column-major.
fn log_columns(rows: &[hapcal_io::LogRow]) -> (Vec<String>, Vec<Vec<f64>>) {
    let n_joints = rows.first().map_or(0, |r| r.q.len());
    let mut names: Vec<String> = (1..=n_joints).map(|j| format!("q{j}")).collect();
    let mut columns: Vec<Vec<f64>> = (0..n_joints)
        .map(|j| rows.iter().map(|r| r.q[j]).collect())
        .collect();
    names.push("distance_m".to_owned());
    columns.push(rows.iter().map(|r| r.distance_m).collect());
    for k in 0..hapcal_io::N_EXT {
        let cell = |r: &hapcal_io::LogRow| r.ext.get(k).copied().flatten();
        if rows.iter().any(|r| cell(r).is_some()) {
            names.push(format!("ext{}", k + 1));
            columns.push(rows.iter().map(|r| cell(r).unwrap_or(f64::NAN)).collect());
        }
    }
    if rows.iter().any(|r| r.t_s.is_some()) {
        names.push("t_s".to_owned());
        columns.push(rows.iter().map(|r| r.t_s.unwrap_or(f64::NAN)).collect());
    }
    (names, columns)
}

/// Simulates a log from a truth device, as `hapcal simulate` does (the same `hapcal_sim`
/// calls); writes it to `path` (atomically, never over an input) when given. Returns the log's
/// columns. See `hapcal.simulate`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (truth, device, seed, poses, noise, effects, motion, period_s, path))]
fn _simulate(
    py: Python<'_>,
    truth: Option<PathBuf>,
    device: Option<PathBuf>,
    seed: u64,
    poses: usize,
    noise: String,
    effects: Vec<String>,
    motion: bool,
    period_s: f64,
    path: Option<PathBuf>,
) -> PyResult<(Vec<String>, Vec<Vec<f64>>)> {
    py.detach(move || -> Result<(Vec<String>, Vec<Vec<f64>>)> {
        if poses < 1 {
            bail!("poses: must be at least 1, got {poses}");
        }
        let mut inputs: Vec<PathBuf> = device.iter().chain(&truth).cloned().collect();
        if let Some(t) = (truth.as_ref()).and_then(|t| Some((t, hapcal_sim::read_truth(t).ok()?))) {
            inputs.push(t.1.device_path(t.0));
        }
        let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
        if let Some(out) = &path {
            calibrate::check_extension(out, &["csv"], "the simulated log", false)?;
            calibrate::check_output(out, &inputs)?;
        }
        let (device, truth) = match (device, truth) {
            (device, Some(truth_path)) => {
                let truth = hapcal_sim::read_truth(&truth_path)?;
                let device = match device {
                    Some(d) => hapcal_io::read_device(&d)?,
                    None => truth.read_device(&truth_path)?,
                };
                (device, truth)
            }
            (device, None) => {
                let path = device.unwrap_or_else(|| {
                    hapcal_calibrate::project_root().join("fixtures/reference-device/device.toml")
                });
                let device = hapcal_io::read_device(&path)?;
                let truth = hapcal_sim::Truth::nominal(path, &device);
                (device, truth)
            }
        };
        let Some(cable) = device.cable_encoder.as_ref() else {
            bail!("the device has no [cable_encoder]: nothing to simulate the distance with");
        };
        let noise = match noise.as_str() {
            "paper" => hapcal_sim::NoiseModel::paper(cable),
            "arc-length" => hapcal_sim::NoiseModel::arc_length(cable),
            other => bail!("noise must be `paper` or `arc-length`, got {other:?}"),
        };
        let cfg = hapcal_sim::SimConfig::new(seed, poses).with_noise(noise);
        let effects = (effects.iter())
            .map(|e| e.parse::<hapcal_sim::Injected>())
            .collect::<Result<Vec<_>, _>>()?;
        let rows = if motion || !effects.is_empty() {
            let motion = hapcal_sim::MotionConfig {
                sample_period_s: period_s,
            };
            hapcal_sim::simulate_motion(&device, &truth, &cfg, &motion, &effects)?
        } else {
            hapcal_sim::simulate(&device, &truth, &cfg)?
        };
        if let Some(out) = &path {
            calibrate::write_new(out, &hapcal_io::write_log(&rows), &inputs)?;
        }
        Ok(log_columns(&rows))
    })
    .map_err(py_err)
}

/// Chooses the poses to measure, as `hapcal plan-poses` does (`plan::plan_poses`); writes
/// them to `path` (`plan::poses_csv`, atomically) when given. Returns the joint names and the
/// readings (rad, one row per pose). See `hapcal.plan_poses`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (device, measurement, count, candidates, seed, criterion, sigma_m, separate_transmission_run, refine, path, model))]
fn _plan_poses(
    py: Python<'_>,
    device: &PyDevice,
    measurement: &str,
    count: usize,
    candidates: usize,
    seed: u64,
    criterion: &str,
    sigma_m: Option<f64>,
    separate_transmission_run: bool,
    refine: bool,
    path: Option<PathBuf>,
    model: &str,
) -> PyResult<(Vec<String>, Vec<Vec<f64>>)> {
    use clap::ValueEnum;
    use hapcal_calibrate::plan::{self, Measurement, PlanConfig};
    let hapcal_device = &device.device;
    let device_path = device.path.as_path();
    py.detach(move || -> Result<(Vec<String>, Vec<Vec<f64>>)> {
        let measurement = Measurement::from_str(measurement, false).map_err(|_| {
            anyhow!("measurement: expected distance or position, found {measurement:?}")
        })?;
        let criterion: hapcal_identify::Criterion = criterion
            .parse()
            .map_err(|e: String| anyhow!("criterion: {e}"))?;
        if let Some(s) = sigma_m
            && !(s.is_finite() && s > 0.0)
        {
            bail!("sigma_m must be a positive length, got {s}");
        }
        if let Some(out) = &path {
            calibrate::check_extension(out, &["csv"], "the planned poses", false)?;
            calibrate::check_output(out, &[device_path])?;
        }
        let cfg = PlanConfig {
            measurement,
            count,
            n_candidates: candidates,
            seed,
            criterion,
            sigma_m,
            transmission_rows: !separate_transmission_run,
            refine,
            model: model_choice(model)?,
        };
        let planned = plan::plan_poses(hapcal_device, &cfg)?;
        let names: Vec<String> = hapcal_device
            .chain()?
            .joint_names()
            .iter()
            .map(|n| n.to_string())
            .collect();
        if let Some(out) = &path {
            calibrate::write_new(
                out,
                &plan::poses_csv(&names, &planned.readings),
                &[device_path],
            )?;
        }
        Ok((names, planned.readings))
    })
    .map_err(py_err)
}

/// Diagnoses the sim-to-real gap, as `hapcal diagnose` does: a haptic device with
/// transmissions from its own log (`hapcal_diagnose::diagnose`), any other robot from what
/// `hapcal calibrate` reads (sockets, distances, markers, poses; `hapcal_diagnose::arm`).
/// Returns the report as `hapcal diagnose --json` prints it (without the final newline) and
/// the data's warnings. See `hapcal.diagnose`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (device, data, test, baseline, folds, sigma_m, test_last, accept_setup))]
fn _diagnose(
    py: Python<'_>,
    device: &PyDevice,
    data: Vec<PyRef<'_, PyMeasurements>>,
    test: Vec<PyRef<'_, PyMeasurements>>,
    baseline: Option<String>,
    folds: usize,
    sigma_m: Option<f64>,
    test_last: Option<f64>,
    accept_setup: bool,
) -> PyResult<(String, Vec<String>)> {
    let hapcal_device = &device.device;
    let train: Vec<Source> = data.iter().map(|m| m.source.clone()).collect();
    let test: Vec<Source> = test.iter().map(|m| m.source.clone()).collect();
    if folds < 2 {
        return Err(py_err(anyhow!("folds must be at least 2, got {folds}")));
    }
    if hapcal_device.has_transmissions() {
        // The reference device's diagnosis: one log, its own held-out folds.
        let path = match train.as_slice() {
            [Source::Path { path, units }] if *units == Units::default() => path,
            [Source::Path { path, .. }] => {
                return Err(py_err(anyhow!(
                    "{}: a log is in m and rad; read it with Measurements.from_csv(path)",
                    path.display()
                )));
            }
            [Source::Arrays(a)] => {
                return Err(py_err(anyhow!(
                    "{}: diagnose reads a log file; give its path or \
                     Measurements.from_csv(path)",
                    a.name
                )));
            }
            _ => {
                return Err(py_err(anyhow!(
                    "{}: a haptic device is diagnosed from one log file, found {}",
                    device.path.display(),
                    train.len()
                )));
            }
        };
        if !test.is_empty() || sigma_m.is_some() || test_last.is_some() {
            return Err(py_err(anyhow!(
                "test, sigma_m and test_last apply to robots measured by an instrument, not to \
                 a haptic device's log"
            )));
        }
        let data = path.clone();
        let device_path = device.path.clone();
        return py
            .detach(move || -> Result<(String, Vec<String>)> {
                let baseline = hapcal_diagnose::baseline_model(
                    (baseline.as_deref())
                        .unwrap_or(hapcal_calibrate::model::ModelName::Transmissions.name()),
                )?;
                let config = hapcal_diagnose::DiagnoseConfig {
                    baseline,
                    folds,
                    ..hapcal_diagnose::DiagnoseConfig::default()
                };
                // The setup check of the log, as the command line runs it.
                let gate_plan = Plan::log_check(
                    device_path.clone(),
                    vec![data.clone()],
                    Units::default(),
                    0.05,
                    folds,
                );
                let Gated {
                    mut warnings,
                    accepted,
                    ..
                } = setup_gate(&gate_plan, accept_setup)?;
                let log = hapcal_io::read_log(&data, hapcal_device)
                    .with_context(|| format!("reading log {}", data.display()))?;
                let mut d = hapcal_diagnose::diagnose(hapcal_device, &log.rows, &config)
                    .with_context(|| format!("diagnosing {}", data.display()))?;
                if let Some(finding) = accepted {
                    d.verdict.on_accepted_setup(&mut d.notes, finding);
                }
                let json = serde_json::to_string_pretty(&d).context("serialising the diagnosis")?;
                warnings.extend(log.warnings);
                Ok((json, warnings))
            })
            .map_err(py_err);
    }
    hapcal_diagnose::arm::robot_baseline(baseline.as_deref()).map_err(|e| py_err(e.into()))?;
    let mut plan = Plan {
        workspace: None,
        device: device.path.clone(),
        tip: device.tip.clone(),
        tips: device.tips.clone(),
        units: Units::default(),
        gravity: hapcal_calibrate::calibrate::GRAVITY_DOWN,
        sigma_rad: None,
        test_last,
        data: Vec::new(),
        test: Vec::new(),
        socket_distance_m: 0.05,
        model: ModelChoice::Auto,
        folds,
        ladder_rows: hapcal_calibrate::fit::LADDER_ROWS,
        sigma_m,
        joint: false,
    };
    let files = file_sources(&train).zip(file_sources(&test));
    let robot = device.robot.as_ref();
    py.detach(move || -> Result<(String, Vec<String>)> {
        // Files that share their units go through the command line's loaders and setup check.
        let mut gated = Gated::default();
        let baseline = match files {
            Some((tr, te)) if tr.iter().chain(&te).all(|(_, u)| *u == tr[0].1) => {
                plan.units = tr[0].1.clone();
                plan.data = tr.into_iter().map(|(p, _)| p).collect();
                plan.test = te.into_iter().map(|(p, _)| p).collect();
                gated = setup_gate(&plan, accept_setup)?;
                hapcal_calibrate::baseline::geometric_baseline(&plan, true)?
            }
            _ => {
                let robot = robot.map_err(|e| anyhow!("{e}"))?;
                hapcal_calibrate::baseline::baseline_from_tables(
                    robot,
                    load_sources(&train, robot)?,
                    load_sources(&test, robot)?,
                    &plan,
                    true,
                )?
            }
        };
        let cfg = hapcal_diagnose::arm::ArmConfig {
            folds,
            ..Default::default()
        };
        let mut d = hapcal_diagnose::arm::diagnose_arm(&baseline, &cfg)
            .context("diagnosing the geometric baseline")?;
        let Gated {
            mut warnings,
            accepted,
            ..
        } = gated;
        if let Some(finding) = accepted {
            d.verdict.on_accepted_setup(&mut d.notes, finding);
        }
        let json = serde_json::to_string_pretty(&d).context("serialising the diagnosis")?;
        warnings.extend(baseline.warnings);
        Ok((json, warnings))
    })
    .map_err(py_err)
}

/// The setup check of measurement files (marker positions, poses, distances), a haptic
/// device's logs or MUKCa socket folders, as `hapcal check` runs it
/// (`hapcal_calibrate::setup::check_plan`). Returns the report as `hapcal check --json`
/// prints it (without the final newline) and, when the data show a mistake overwhelmingly,
/// the message `hapcal check` stops with (exit code 2); a failing check is a result, not an
/// error. See `hapcal.check`.
#[pyfunction]
#[pyo3(signature = (device, data, socket_distance_m))]
fn _check(
    py: Python<'_>,
    device: &PyDevice,
    data: Vec<PyRef<'_, PyMeasurements>>,
    socket_distance_m: f64,
) -> PyResult<(String, Option<String>)> {
    let sources: Vec<Source> = data.iter().map(|m| m.source.clone()).collect();
    let plan = (|| -> Result<Plan> {
        let Some(files) = file_sources(&sources) else {
            bail!(
                "check reads files (measurement files, a haptic device's logs, socket folders); \
                 measurements given as arrays are taken as given: write them to a CSV file to \
                 check them"
            );
        };
        let Some((_, units)) = files.first().cloned() else {
            bail!("data: give the measurement files to check");
        };
        if files.iter().any(|(_, u)| *u != units) {
            bail!(
                "data: the files of one check are read in one length unit and one angle unit; \
                 give every file the same length_unit and angle_unit"
            );
        }
        Ok(Plan {
            device: device.path.clone(),
            tip: device.tip.clone(),
            tips: device.tips.clone(),
            units,
            data: files.into_iter().map(|(p, _)| p).collect(),
            test: Vec::new(),
            socket_distance_m,
            ..Plan::bundled_default()
        })
    })()
    .map_err(py_err)?;
    py.detach(move || -> Result<(String, Option<String>)> {
        if let Some(missing) = plan.data.iter().find(|p| !p.exists()) {
            bail!("data {}: no such file", missing.display());
        }
        plan.validate()?;
        let Some(report) = hapcal_calibrate::setup::check_plan(&plan)? else {
            bail!(
                "check applies to measurement files (marker positions, poses, distances), a \
                 haptic device's logs and socket folders; {} holds none",
                (plan.data.iter())
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        };
        let json = serde_json::to_string_pretty(&report).context("serialising the check")?;
        let error =
            (report.overwhelming()).map(|f| format!("setup check [{}]: {}", f.class, f.text()));
        Ok((json, error))
    })
    .map_err(py_err)
}

/// Imports a URDF chain, or a tree with several tips, as a hapcal device file, as `hapcal
/// import-urdf` does (`hapcal_io::import_urdf_tree`, `hapcal_io::write_device`); also writes
/// it to `path` (atomically, never over the URDF) when given. Returns the device file's text
/// (TOML). See `hapcal.import_urdf`.
#[pyfunction]
#[pyo3(signature = (urdf, tips, path))]
fn _import_urdf(
    py: Python<'_>,
    urdf: PathBuf,
    tips: Vec<String>,
    path: Option<PathBuf>,
) -> PyResult<String> {
    py.detach(move || -> Result<String> {
        if tips.is_empty() {
            bail!(
                "tips: give the tip link (e.g. \"ball_link\"), and one more per branch of a tree"
            );
        }
        if let Some(out) = &path {
            calibrate::check_extension(out, &["toml"], "a device file", true)?;
            calibrate::check_output(out, &[urdf.as_path()])?;
        }
        let device = hapcal_io::import_urdf_tree(&urdf, &tips)?;
        let text = hapcal_io::write_device(&device);
        if let Some(out) = &path {
            calibrate::write_new(out, &text, &[urdf.as_path()])?;
        }
        Ok(text)
    })
    .map_err(py_err)
}

/// A calibrated robot in a control loop (`hapcal_runtime::Robot`): loaded from the URDF and
/// sidecar `hapcal calibrate --out robot.urdf` writes; poses of its tips, rigid or deflected
/// under its own weight, and compensated joint commands.
#[pyclass(module = "hapcal", name = "RuntimeRobot", frozen)]
struct PyRuntimeRobot {
    robot: hapcal_runtime::Robot,
}

/// A pose as a 4 × 4 homogeneous matrix (rows; translation in m).
fn matrix_of(p: &hapcal_runtime::Pose) -> Vec<Vec<f64>> {
    let mut rows: Vec<Vec<f64>> = (0..3)
        .map(|i| {
            let mut row = p.rotation[i].to_vec();
            row.push(p.translation_m[i]);
            row
        })
        .collect();
    rows.push(vec![0.0, 0.0, 0.0, 1.0]);
    rows
}

fn runtime_err(e: impl std::fmt::Display) -> PyErr {
    HapcalError::new_err(e.to_string())
}

#[pymethods]
impl PyRuntimeRobot {
    /// Loads `urdf` (and its sidecar `<stem>.calibration.toml` beside it) with the links
    /// `tips` as tips.
    #[new]
    fn new(urdf: PathBuf, tips: Vec<String>) -> PyResult<Self> {
        let tips: Vec<&str> = tips.iter().map(String::as_str).collect();
        let robot = hapcal_runtime::Robot::load_urdf(&urdf, &tips).map_err(runtime_err)?;
        Ok(Self { robot })
    }

    /// Joint names, in the order of `q`.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.robot.joint_names().to_vec()
    }

    /// Tip link names, in the order of the tip indices.
    #[getter]
    fn tip_names(&self) -> Vec<String> {
        self.robot.tip_names().to_vec()
    }

    /// An identified frame of the calibration by name (4 × 4, m): `instrument` (the robot's
    /// root link frame in the instrument frame) or `marker1`, `marker2`, … (a marker's frame
    /// in its tip link's frame); `None` if the calibration identified none of that name.
    fn frame(&self, name: &str) -> Option<Vec<Vec<f64>>> {
        self.robot.frame(name).as_ref().map(matrix_of)
    }

    /// Pose of each tip (4 × 4, m) at joint angles `q` (rad, m for a prismatic joint): of the
    /// robot deflected under its own weight, or of the rigid robot with `deflected=False`.
    #[pyo3(signature = (q, deflected = true))]
    fn tip_poses(&self, q: Vec<f64>, deflected: bool) -> PyResult<Vec<Vec<Vec<f64>>>> {
        let mut ws = self.robot.workspace();
        let mut out = vec![hapcal_runtime::Pose::IDENTITY; self.robot.tip_names().len()];
        if deflected {
            self.robot.deflected_tip_poses(&q, &mut ws, &mut out)
        } else {
            self.robot
                .tip_poses(&q, &mut ws, &mut out)
                .map(|()| Default::default())
        }
        .map_err(runtime_err)?;
        Ok(out.iter().map(matrix_of).collect())
    }

    /// The joint command at which tip `tip` (an index into `tip_names`) of the deflected robot
    /// reaches `target`: `(x, y, z)` m, or `(x, y, z, qw, qx, qy, qz)` with a unit quaternion;
    /// from `start` (the nominal inverse kinematics' solution). Returns a dict with `q`,
    /// `reached`, `position_error_m`, `orientation_error_rad`, `iterations`.
    #[pyo3(signature = (target, start, tip = 0, tolerance_m = 1e-6, tolerance_rad = 1e-6, max_iterations = 50))]
    #[allow(clippy::too_many_arguments, reason = "Python keyword arguments")]
    fn compensate<'py>(
        &self,
        py: Python<'py>,
        target: Vec<f64>,
        start: Vec<f64>,
        tip: usize,
        tolerance_m: f64,
        tolerance_rad: f64,
        max_iterations: usize,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let target = match target.as_slice() {
            [x, y, z] => hapcal_runtime::Target::Position([*x, *y, *z]),
            [x, y, z, w, qx, qy, qz] => {
                let q =
                    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(*w, *qx, *qy, *qz));
                let r = q.to_rotation_matrix();
                let mut rotation = [[0.0; 3]; 3];
                for (i, row) in rotation.iter_mut().enumerate() {
                    for (j, v) in row.iter_mut().enumerate() {
                        *v = r[(i, j)];
                    }
                }
                hapcal_runtime::Target::Pose(hapcal_runtime::Pose {
                    rotation,
                    translation_m: [*x, *y, *z],
                })
            }
            other => {
                return Err(HapcalError::new_err(format!(
                    "target: expected 3 values (x, y, z) or 7 (x, y, z, qw, qx, qy, qz), found {}",
                    other.len()
                )));
            }
        };
        let cfg = hapcal_runtime::CompensationConfig {
            tolerance_m,
            tolerance_rad,
            max_iterations,
            damping_m: 1e-3,
            orientation_scale_m: 0.1,
        };
        let mut ws = self.robot.workspace();
        let mut q = vec![0.0; self.robot.n_joints()];
        let c =
            hapcal_runtime::compensate(&self.robot, tip, &target, &start, &cfg, &mut ws, &mut q)
                .map_err(runtime_err)?;
        let d = pyo3::types::PyDict::new(py);
        d.set_item("q", q)?;
        d.set_item("reached", c.reached)?;
        d.set_item("position_error_m", c.position_error_m)?;
        d.set_item("orientation_error_rad", c.orientation_error_rad)?;
        d.set_item("iterations", c.iterations)?;
        Ok(d)
    }
}

/// A calibrated haptic device in a control loop (`hapcal_runtime::Model`, the object the C ABI's
/// handle holds): loaded from the device file `hapcal calibrate` writes (D-H rows and the
/// `[calibration]` table), evaluated for joint readings θ.
#[pyclass(module = "hapcal", name = "RuntimeModel", frozen)]
struct PyRuntimeModel {
    model: hapcal_runtime::Model,
}

#[pymethods]
impl PyRuntimeModel {
    /// Loads the device file `path` (TOML).
    #[new]
    fn new(path: PathBuf) -> PyResult<Self> {
        let model = hapcal_runtime::Model::load(&path).map_err(runtime_err)?;
        Ok(Self { model })
    }

    /// Number of joints n.
    #[getter]
    fn n_joints(&self) -> usize {
        self.model.n_joints()
    }

    /// Everything one reading gives, as `hapcal_runtime::Model::evaluate`: for joint readings
    /// `theta` (n values, rad) and a wrench `wrench` in the tip frame (fx, fy, fz in N, then
    /// mx, my, mz in N·m), a dict with `q_rad` (the calibrated joint angles), `dq_dtheta`,
    /// `pose` (4 × 4, m), `body_jacobian` (6 rows × n columns: linear, then angular) and
    /// `motor_torques_nm`.
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        theta: Vec<f64>,
        wrench: Vec<f64>,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let wrench: [f64; 6] = wrench.as_slice().try_into().map_err(|_| {
            HapcalError::new_err(format!(
                "wrench: expected 6 values (fx, fy, fz, mx, my, mz), found {}",
                wrench.len()
            ))
        })?;
        let mut e = hapcal_runtime::Evaluation::default();
        self.model
            .evaluate(&theta, &wrench, &mut e)
            .map_err(runtime_err)?;
        let n = e.n_joints;
        let d = pyo3::types::PyDict::new(py);
        d.set_item("q_rad", e.q_rad[..n].to_vec())?;
        d.set_item("dq_dtheta", e.dq_dtheta[..n].to_vec())?;
        d.set_item("pose", matrix_of(&e.pose))?;
        let jac: Vec<Vec<f64>> = (0..6)
            .map(|r| (0..n).map(|c| e.body_jacobian[c][r]).collect())
            .collect();
        d.set_item("body_jacobian", jac)?;
        d.set_item("motor_torques_nm", e.motor_torques_nm[..n].to_vec())?;
        Ok(d)
    }
}

/// One kind of error figure of `_predict`: (count, mean, RMS, max), `None` without samples.
fn figures(f: &hapcal_runtime::ErrorFigures) -> Option<(usize, f64, f64, f64)> {
    (f.count > 0).then(|| (f.count, f.mean(), f.rms(), f.max()))
}

/// What `_predict` returns: per row its line, per row and tip the pose (x, y, z, qw, qx, qy,
/// qz; m) and σ (m, rad; NaN without), per row the region flag (joint index or −1, and how
/// far past its range), the errors against the measured columns (position, orientation,
/// distance figures), the uncertainty's basis and note, the number of values, the reader's
/// warnings.
type Predicted = (
    Vec<u64>,
    Vec<Vec<[f64; 7]>>,
    Vec<Vec<(f64, f64)>>,
    Vec<(i64, f64)>,
    Option<[Option<(usize, f64, f64, f64)>; 3]>,
    (String, Option<String>, usize),
    Vec<String>,
);

/// The calibrated model's predictions at the joint readings of a measurement file, as
/// `hapcal predict` makes them (`hapcal_runtime::Predictor`): the tip links in the root frame
/// or, with `instrument_frame`, the markers in the instrument frame, with their 1σ and the
/// region flag, and the errors against the file's measured columns (no refit). See
/// `hapcal.predict`.
#[pyfunction]
#[pyo3(signature = (urdf, tips, data, length_unit, angle_unit, instrument_frame))]
fn _predict(
    py: Python<'_>,
    urdf: PathBuf,
    tips: Vec<String>,
    data: PathBuf,
    length_unit: &str,
    angle_unit: &str,
    instrument_frame: bool,
) -> PyResult<Predicted> {
    let units = units(length_unit, angle_unit).map_err(py_err)?;
    py.detach(move || -> Result<Predicted> {
        use hapcal_runtime::{PredictionFrame, Predictor};
        if tips.is_empty() {
            bail!("tips: give the tip link (e.g. \"ball_link\"), one per tip of a tree");
        }
        let tip_refs: Vec<&str> = tips.iter().map(String::as_str).collect();
        let robot = hapcal_runtime::Robot::load_urdf(&urdf, &tip_refs)
            .with_context(|| format!("loading the calibrated robot {}", urdf.display()))?;
        if instrument_frame && robot.frame("instrument").is_none() {
            bail!(
                "instrument_frame: {} has no identified instrument frame (frames.instrument of \
                 its calibration sidecar)",
                urdf.display()
            );
        }
        if data.is_dir() {
            bail!(
                "{}: a folder; predict reads a measurement file (CSV with the joints as q1..qn \
                 or by name)",
                data.display()
            );
        }
        let table = hapcal_calibrate::predict::with_joint_schema(&robot, |schema| {
            hapcal_io::read_measurement_file(&data, schema, &units)
        })
        .with_context(|| format!("reading joint readings {}", data.display()))?;
        if table.rows.is_empty() {
            bail!(
                "{}: no data row: expected one joint configuration per row",
                data.display()
            );
        }
        let frame = if instrument_frame {
            PredictionFrame::Instrument
        } else {
            PredictionFrame::Root
        };
        let predictor = Predictor::new(&robot, frame).map_err(|e| anyhow!("{e}"))?;
        let mut ws = predictor.workspace();
        let mut out = vec![hapcal_runtime::TipPrediction::default(); tips.len()];
        let measured = table.n_markers > 0 || table.has_distance;
        let mut errors = hapcal_runtime::MeasuredErrors::default();
        let (mut lines, mut poses, mut sigmas, mut region) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for row in &table.rows {
            let at = || format!("{}:{}", data.display(), row.line);
            predictor
                .predict(&row.q, &mut ws, &mut out)
                .map_err(|e| anyhow!("{}: {e}", at()))?;
            let outside = (robot.outside_region(&row.q)).map_err(|e| anyhow!("{}: {e}", at()))?;
            if measured {
                let markers: Vec<hapcal_runtime::MarkerObservation> = (row.markers.iter())
                    .map(|m| hapcal_runtime::MarkerObservation {
                        marker: m.marker,
                        position_m: m.position_m,
                        rotation_wxyz: m.rotation,
                    })
                    .collect();
                predictor
                    .add_errors(&row.q, &markers, row.distance_m, &mut ws, &mut errors)
                    .map_err(|e| anyhow!("{}: {e}", at()))?;
            }
            lines.push(row.line);
            poses.push(
                (out.iter())
                    .map(|t| {
                        let [w, x, y, z] =
                            hapcal_calibrate::predict::quaternion_of(&t.pose.rotation);
                        let p = t.pose.translation_m;
                        [p[0], p[1], p[2], w, x, y, z]
                    })
                    .collect(),
            );
            sigmas.push(
                (out.iter())
                    .map(|t| {
                        (
                            t.sigma_m.unwrap_or(f64::NAN),
                            t.sigma_rad.unwrap_or(f64::NAN),
                        )
                    })
                    .collect(),
            );
            region.push(outside.map_or((-1, f64::NAN), |(j, past)| (j as i64, past)));
        }
        let basis = predictor.basis().name();
        let note = predictor.uncertainty_note();
        let errors = measured.then(|| {
            [
                figures(&errors.position),
                figures(&errors.orientation),
                figures(&errors.distance),
            ]
        });
        Ok((
            lines,
            poses,
            sigmas,
            region,
            errors,
            (basis.to_owned(), note, predictor.n_values()),
            table.warnings,
        ))
    })
    .map_err(py_err)
}

/// hapcal's compiled core; use the `hapcal` package.
#[pymodule]
fn _hapcal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("HapcalError", m.py().get_type::<HapcalError>())?;
    m.add_class::<PyDevice>()?;
    m.add_class::<PyMeasurements>()?;
    m.add_class::<PyCalibration>()?;
    m.add_class::<PyRuntimeRobot>()?;
    m.add_class::<PyRuntimeModel>()?;
    m.add_function(wrap_pyfunction!(_calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(_simulate, m)?)?;
    m.add_function(wrap_pyfunction!(_plan_poses, m)?)?;
    m.add_function(wrap_pyfunction!(_diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(_check, m)?)?;
    m.add_function(wrap_pyfunction!(_import_urdf, m)?)?;
    m.add_function(wrap_pyfunction!(_predict, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The models `calibrate` takes, from the one definition of the model choice.
    m.add("MODELS", model_names())?;
    Ok(())
}
