//! A fleet of devices of one design, measured on one rig: each device has its own kinematic
//! deviations, the rig's cable encoder has a zero offset and a cable-angle error shared by all.

use faer::{Col, ColMut, ColRef, MatMut};
use hapcal_identify::{EvalError, ParamLayout, ParamSpec, Problem, Role, SparseJacobian, Unit};
use hapcal_kinematics::{Chain, FkWorkspace, ParamUnit, Point3, Vector3};

use crate::Error;

/// Distance measurements of one device of a fleet.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FleetDevice {
    /// Joint angles, rad, row-major (`n_poses × n_joints`).
    pub q_rad: Vec<f64>,
    /// Measured cable distances, m (length `n_poses`).
    pub distance_m: Vec<f64>,
}

/// Angle of the cable from the rig's z axis, rad: `φ(P) = atan2(√(Px² + Py²), Pz)`, and its
/// gradient with respect to `P` (rad/m). The `cable_angle` effect of docs/design.md §6 is an error
/// `k·φ` of the measured distance.
pub fn cable_angle(p: &Point3<f64>) -> (f64, Vector3<f64>) {
    let rho2 = p.x * p.x + p.y * p.y;
    let rho = rho2.sqrt();
    let r2 = rho2 + p.z * p.z;
    let phi = rho.atan2(p.z);
    if rho == 0.0 || r2 == 0.0 {
        return (phi, Vector3::zeros());
    }
    let grad = Vector3::new(p.x * p.z / (rho * r2), p.y * p.z / (rho * r2), -rho / r2);
    (phi, grad)
}

/// The fleet calibration problem (docs/design.md §4, sparse back end):
/// `x = [device 0's deviations | device 1's | … | rig.cable_offset | rig.cable_angle]`.
///
/// Residual of pose `i` of device `d`: `(|P_d(q_i)| + c + k·φ(P_d) − δ_i)/σ_m` (paper eq. 5 plus
/// the rig's cable-encoder zero offset `c`, m, and cable-angle coefficient `k`, m/rad; `φ` from
/// [`cable_angle`]). Each device owns the chain parameters `device_params` (e.g. the 28
/// identifiable deviations of the reference device), the others stay 0. The cable encoder's
/// scale is not a parameter: every link length absorbs it exactly.
///
/// Its Jacobian is block-angular (each row touches its device's block and the 2 shared
/// columns), so it provides [`Problem::sparse_jacobian`]; [`hapcal_identify::identify`]
/// chooses the sparse back end for it.
#[derive(Debug)]
pub struct FleetProblem {
    chain: Chain,
    device_params: Vec<usize>,
    devices: Vec<FleetDevice>,
    /// First residual of each device, and `m` at the end.
    row_start: Vec<usize>,
    sigma_m: f64,
    layout: ParamLayout,
}

impl FleetProblem {
    /// Builds the problem. `device_params` are indices into `chain.params()` (each device's
    /// unknowns), `sigma_distance_m` the cable noise (m).
    ///
    /// # Errors
    /// [`Error::BadSigma`] for a non-positive or non-finite sigma; [`Error::JointCount`] when a
    /// device's `q_rad` is not `n_poses × n_joints`; [`Error::NotFinite`] for a NaN or ∞ reading
    /// (`row` counts poses across the fleet); [`Error::NoSuchParam`] for an index past the
    /// chain's parameters.
    pub fn new(
        chain: Chain,
        device_params: Vec<usize>,
        devices: Vec<FleetDevice>,
        sigma_distance_m: f64,
    ) -> Result<Self, Error> {
        if !(sigma_distance_m.is_finite() && sigma_distance_m > 0.0) {
            return Err(Error::BadSigma {
                name: "sigma_distance_m",
                value: sigma_distance_m,
            });
        }
        if let Some(&index) = device_params.iter().find(|&&i| i >= chain.n_params()) {
            return Err(Error::NoSuchParam {
                index,
                n_params: chain.n_params(),
            });
        }
        let nj = chain.n_joints();
        let mut row_start = vec![0];
        for (d, dev) in devices.iter().enumerate() {
            let n = dev.distance_m.len();
            let start = *row_start.last().unwrap_or(&0);
            Error::check_joint_count(start, n * nj, dev.q_rad.len())?;
            let bad = dev
                .q_rad
                .iter()
                .position(|v| !v.is_finite())
                .map(|k| k / nj)
                .or_else(|| dev.distance_m.iter().position(|v| !v.is_finite()));
            if let Some(pose) = bad {
                return Err(Error::NotFinite { row: start + pose });
            }
            let _ = d;
            row_start.push(start + n);
        }
        let mut specs = Vec::with_capacity(devices.len() * device_params.len() + 2);
        for d in 0..devices.len() {
            for &j in &device_params {
                let p = &chain.params()[j];
                specs.push(ParamSpec {
                    name: format!("device{d}.{}", p.name),
                    unit: match p.unit {
                        ParamUnit::Meter => Unit::Meter,
                        ParamUnit::Radian => Unit::Radian,
                    },
                    role: Role::Model,
                });
            }
        }
        for name in ["rig.cable_offset", "rig.cable_angle"] {
            specs.push(ParamSpec {
                name: name.to_owned(),
                unit: Unit::Meter,
                role: Role::Model,
            });
        }
        Ok(Self {
            chain,
            device_params,
            devices,
            row_start,
            sigma_m: sigma_distance_m,
            layout: ParamLayout::new(specs),
        })
    }

    /// Number of devices.
    pub fn n_devices(&self) -> usize {
        self.devices.len()
    }

    /// Layout indices of the shared rig parameters `[rig.cable_offset, rig.cable_angle]`.
    pub fn shared(&self) -> [usize; 2] {
        let n = self.layout.len();
        [n - 2, n - 1]
    }

    /// Layout index of device `d`'s first parameter (its block is `device_params.len()` long).
    pub fn device_offset(&self, d: usize) -> usize {
        d * self.device_params.len()
    }

    /// Evaluates device `d`: residuals into `r` (its rows), and for each row the gradient of
    /// the residual with respect to its device's parameters (`grad`, row-major
    /// `n_poses × n_dev`) and the two shared parameters (`shared`, `n_poses × 2`).
    fn eval_device(
        &self,
        d: usize,
        x: ColRef<'_, f64>,
        r: &mut [f64],
        mut grads: Option<(&mut [f64], &mut [f64])>,
    ) {
        let np = self.device_params.len();
        let nj = self.chain.n_joints();
        let off = self.device_offset(d);
        let [ci, ki] = self.shared();
        let (c, k) = (x[ci], x[ki]);
        let mut x_kin = vec![0.0; self.chain.n_params()];
        for (a, &j) in self.device_params.iter().enumerate() {
            x_kin[j] = x[off + a];
        }
        let frozen = self.chain.freeze(&x_kin);
        let mut ws = FkWorkspace::new(&self.chain);
        let mut buf = vec![0.0; 3 * self.chain.n_params()];
        let dev = &self.devices[d];
        let s = self.sigma_m;
        for (i, &delta) in dev.distance_m.iter().enumerate() {
            let q = &dev.q_rad[i * nj..(i + 1) * nj];
            let p = if grads.is_some() {
                frozen.point_and_jacobian(q, &mut buf, &mut ws)
            } else {
                frozen.end_point(q)
            };
            let (norm, u) = crate::problem::length_and_direction(&p.coords);
            let (phi, dphi) = cable_angle(&p);
            r[i] = (norm + c + k * phi - delta) / s;
            if let Some((g, sh)) = grads.as_mut() {
                let w = (u + dphi * k) / s;
                for (a, &j) in self.device_params.iter().enumerate() {
                    g[i * np + a] = crate::problem::along(&w, &buf, j);
                }
                sh[2 * i] = 1.0 / s;
                sh[2 * i + 1] = phi / s;
            }
        }
    }
}

impl Problem for FleetProblem {
    fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    fn n_residuals(&self) -> usize {
        *self.row_start.last().unwrap_or(&0)
    }

    fn residuals(&self, x: ColRef<'_, f64>, mut out: ColMut<'_, f64>) -> Result<(), EvalError> {
        self.check_shape(x.nrows(), out.nrows())?;
        let mut r = Vec::new();
        for d in 0..self.devices.len() {
            let (a, b) = (self.row_start[d], self.row_start[d + 1]);
            r.resize(b - a, 0.0);
            self.eval_device(d, x, &mut r, None);
            for (i, v) in r.iter().enumerate() {
                out[a + i] = *v;
            }
        }
        Ok(())
    }

    fn jacobian(&self, x: ColRef<'_, f64>, mut jac: MatMut<'_, f64>) -> Result<(), EvalError> {
        self.check_shape(x.nrows(), jac.nrows())?;
        jac.fill(0.0);
        let np = self.device_params.len();
        let [ci, ki] = self.shared();
        for d in 0..self.devices.len() {
            let (a, b) = (self.row_start[d], self.row_start[d + 1]);
            let (mut r, mut g, mut sh) = (
                vec![0.0; b - a],
                vec![0.0; (b - a) * np],
                vec![0.0; 2 * (b - a)],
            );
            self.eval_device(d, x, &mut r, Some((&mut g, &mut sh)));
            let off = self.device_offset(d);
            for i in 0..b - a {
                for t in 0..np {
                    jac[(a + i, off + t)] = g[i * np + t];
                }
                jac[(a + i, ci)] = sh[2 * i];
                jac[(a + i, ki)] = sh[2 * i + 1];
            }
        }
        Ok(())
    }

    fn sparse_jacobian(&self) -> Option<&dyn SparseJacobian> {
        Some(self)
    }
}

impl SparseJacobian for FleetProblem {
    fn pattern(&self) -> (Vec<usize>, Vec<usize>) {
        let np = self.device_params.len();
        let m = self.n_residuals();
        let mut col_ptr = vec![0];
        let mut row_idx = Vec::with_capacity(m * (np + 2));
        for d in 0..self.devices.len() {
            for _ in 0..np {
                row_idx.extend(self.row_start[d]..self.row_start[d + 1]);
                col_ptr.push(row_idx.len());
            }
        }
        for _ in 0..2 {
            row_idx.extend(0..m);
            col_ptr.push(row_idx.len());
        }
        (col_ptr, row_idx)
    }

    fn residuals_and_values(
        &self,
        x: ColRef<'_, f64>,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), EvalError> {
        let np = self.device_params.len();
        let m = self.n_residuals();
        if x.nrows() != self.layout.len() || r.len() != m || values.len() != m * (np + 2) {
            return Err(EvalError {
                reason: "shape mismatch in the sparse fleet jacobian".to_owned(),
            });
        }
        // Device d's block holds np columns of its rows, column-major; the shared columns
        // follow, each with all m rows.
        let shared_start = m * np;
        let (device_vals, shared_vals) = values.split_at_mut(shared_start);
        let (offset_vals, angle_vals) = shared_vals.split_at_mut(m);
        let mut g = Vec::new();
        let mut sh = Vec::new();
        for d in 0..self.devices.len() {
            let (a, b) = (self.row_start[d], self.row_start[d + 1]);
            let len = b - a;
            g.resize(len * np, 0.0);
            sh.resize(2 * len, 0.0);
            self.eval_device(d, x, &mut r[a..b], Some((&mut g, &mut sh)));
            let block = &mut device_vals[a * np..b * np];
            for t in 0..np {
                for i in 0..len {
                    block[t * len + i] = g[i * np + t];
                }
            }
            for i in 0..len {
                offset_vals[a + i] = sh[2 * i];
                angle_vals[a + i] = sh[2 * i + 1];
            }
        }
        Ok(())
    }

    fn covariance_of(&self) -> Vec<usize> {
        self.shared().to_vec()
    }
}

impl FleetProblem {
    /// `x` of `nx` entries and an output of `nr` rows: the layout's length and the number of
    /// residuals, else the shape mismatch.
    fn check_shape(&self, nx: usize, nr: usize) -> Result<(), EvalError> {
        let (n, m) = (self.layout.len(), self.n_residuals());
        if nx != n || nr != m {
            return Err(EvalError {
                reason: format!(
                    "shape mismatch: x has {nx} entries (expected {n}), output {nr} rows (expected {m})"
                ),
            });
        }
        Ok(())
    }
}

/// Start vector of a fleet: all deviations 0, the rig parameters 0.
pub fn fleet_initial_guess(p: &FleetProblem) -> Col<f64> {
    Col::zeros(p.layout().len())
}
