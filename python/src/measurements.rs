//! Measurements handed over as NumPy arrays: their columns checked, turned into the library's measurement table.

use super::*;

/// Measurements given as arrays, in SI units but for the joints (converted when the device,
/// and so which joints are prismatic, is known).
#[derive(Clone, Debug)]
pub(super) struct Arrays {
    pub(super) name: String,
    /// Joint readings per row, in the columns' order and `units`.
    pub(super) q: Vec<Vec<f64>>,
    /// Column names of `q` (device joint names or `q1..qn`), or chain order.
    pub(super) joint_names: Option<Vec<String>>,
    pub(super) markers: Vec<Vec<MarkerSample>>,
    pub(super) n_markers: usize,
    pub(super) has_orientation: bool,
    pub(super) distances: Option<Vec<Option<f64>>>,
    pub(super) t_s: Option<Vec<f64>>,
    pub(super) units: Units,
    pub(super) ignored_columns: Vec<String>,
    /// Columns of `q` named in `joint_names` that are no joint of the device are ignored (and
    /// reported) rather than an error: a data frame's columns, as a CSV header's.
    pub(super) ignore_unknown_joints: bool,
}

#[derive(Clone, Debug)]
pub(super) enum Source {
    /// A measurement file (CSV, YAML), a MUKCa placement or run folder, or a hapcal log.
    Path {
        path: PathBuf,
        units: Units,
    },
    Arrays(Box<Arrays>),
}

/// Measurements: a file or folder read at calibration time, or arrays.
#[pyclass(module = "hapcal._hapcal", name = "_Measurements", frozen)]
pub(super) struct PyMeasurements {
    pub(super) source: Source,
}

pub(super) fn check_len(what: &str, got: usize, want: usize) -> Result<()> {
    if got != want {
        bail!("{what}: expected {want} values, found {got}");
    }
    Ok(())
}

/// The marker columns of one array input, flattened row-major: `positions` `(n, k, 3)` in
/// the input's length unit, with `quaternions` `(n, k, 4)` (w, x, y, z) or `rpy` `(n, k, 3)`
/// in its angle unit; `length` and `angle` convert to m and rad.
pub(super) struct FlatMarkers<'a> {
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
pub(super) fn joint_columns(a: &Arrays, robot: &Robot) -> Result<(Vec<usize>, Vec<String>)> {
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
pub(super) fn table(a: &Arrays, robot: &Robot) -> Result<MeasurementTable> {
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
            q: q.into(),
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
