//! The runtime's calibrated robot and haptic model for a control loop, and prediction of a calibration on new data.

use super::*;

/// A calibrated robot in a control loop (`hapcal_runtime::Robot`): loaded from the URDF and
/// sidecar `hapcal calibrate --out robot.urdf` writes; poses of its tips, rigid or deflected
/// under its own weight, and compensated joint commands.
#[pyclass(module = "hapcal", name = "RuntimeRobot", frozen)]
pub(super) struct PyRuntimeRobot {
    robot: hapcal_runtime::Robot,
}

/// A pose as a 4 × 4 homogeneous matrix (rows; translation in m).
pub(super) fn matrix_of(p: &hapcal_runtime::Pose) -> Vec<Vec<f64>> {
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

pub(super) fn runtime_err(e: impl std::fmt::Display) -> PyErr {
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
pub(super) struct PyRuntimeModel {
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
pub(super) fn figures(f: &hapcal_runtime::ErrorFigures) -> Option<(usize, f64, f64, f64)> {
    (f.count > 0).then(|| (f.count, f.mean(), f.rms(), f.max()))
}

/// What `_predict` returns: per row its line, per row and tip the pose (x, y, z, qw, qx, qy,
/// qz; m) and σ (m, rad; NaN without), per row the region flag (joint index or −1, and how
/// far past its range), the errors against the measured columns (position, orientation,
/// distance figures), the uncertainty's basis and note, the number of values, the reader's
/// warnings.
pub(super) type Predicted = (
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
pub(super) fn _predict(
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
