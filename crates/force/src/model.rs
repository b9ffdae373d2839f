//! The full static model of a device: kinematic chain plus one drive per joint, evaluated
//! by the runtime (the models a controller runs) or by the calibration library (the truth).

use hapcal_contract::drives::{JointDrive, haptic_drives};
use hapcal_io::Device;
use hapcal_kinematics::{Chain, Isometry3, Matrix6xX};
use hapcal_runtime::{Evaluation, MAX_JOINTS};
use hapcal_sim::{PARALLELOGRAM_JOINT, Truth};
use hapcal_transmission::{Capstan, CapstanParams, Chebyshev, Joint4Transmission, JointRad};
use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector6};

use crate::Error;

/// How one joint is driven: the map from its reading θ (motor angle / R, rad) to its joint
/// angle q (rad), and the nominal ratio R between motor and reading.
///
/// The motor angle is `φ_m = R·θ` by definition of the reading. A lossless transmission
/// obeys virtual work, `τ_m·dφ_m = τ_j·dq`, so (paper eq. 1 differentiated):
///
/// ```text
/// τ_j = τ_m · R / (dq/dθ)        τ_m = τ_j · (dq/dθ) / R        (N·m, N·m)
/// ```
///
/// For a pure ratio error `q = θ·R/(R + Re)` this is `τ_j = (R + Re)·τ_m`: the true ratio.
#[derive(Clone, Debug, PartialEq)]
pub enum Drive {
    /// Direct drive: `q = θ`, `R = 1`.
    Direct,
    /// Capstan drive, `q = θ + Δθ_caps(θ)` (paper eq. 1); all-zero parameters give `q = θ`.
    Capstan {
        /// Ratio and drum distance.
        capstan: Capstan,
        /// Transmission-error parameters.
        params: CapstanParams,
    },
    /// Capstan feeding a four-bar (paper eqs. 1 and 2), as the truth device's joint 4.
    Parallelogram(Joint4Transmission),
    /// A calibrated joint: `q = θ + p(θ)` with `p` the identified polynomial (the paper's
    /// tenth-order joint-4 error), behind a drive of nominal ratio `ratio`.
    Polynomial {
        /// Nominal ratio R (motor angle per unit reading).
        ratio: f64,
        /// The error polynomial, rad.
        poly: Chebyshev,
    },
}

impl Drive {
    /// Nominal ratio R between the motor angle and the reading (1 for a direct drive).
    pub fn ratio(&self) -> f64 {
        match self {
            Drive::Direct => 1.0,
            Drive::Capstan { capstan, .. } => capstan.ratio(),
            Drive::Parallelogram(j4) => j4.capstan.ratio(),
            Drive::Polynomial { ratio, .. } => *ratio,
        }
    }

    /// Joint angle q (rad) for reading `theta` (rad).
    ///
    /// # Errors
    /// [`hapcal_transmission::Error::NoClosure`] where a four-bar cannot close.
    pub fn angle_rad(&self, theta: f64) -> Result<f64, hapcal_transmission::Error> {
        Ok(match self {
            Drive::Direct => theta,
            Drive::Capstan { capstan, params } => capstan.output_rad(params, JointRad(theta)),
            Drive::Parallelogram(j4) => j4.output_rad(JointRad(theta))?,
            Drive::Polynomial { poly, .. } => theta + poly.eval(theta),
        })
    }

    /// `dq/dθ` (rad/rad) at reading `theta`, analytic: `1 + ∂Δθ_caps/∂θ` for a capstan,
    /// `dψ/dφ · (1 + ∂Δθ_caps/∂θ)` for a parallelogram, `1 + p'(θ)` for a polynomial.
    ///
    /// # Errors
    /// As [`Drive::angle_rad`], and at a four-bar dead centre.
    pub fn angle_derivative(&self, theta: f64) -> Result<f64, hapcal_transmission::Error> {
        Ok(match self {
            Drive::Direct => 1.0,
            Drive::Capstan { capstan, params } => {
                1.0 + capstan.error_dtheta(params, JointRad(theta))
            }
            Drive::Parallelogram(j4) => {
                let phi = j4.phi0_rad + j4.capstan.output_rad(&j4.params, JointRad(theta));
                j4.four_bar.d_output_d_input(phi)?
                    * (1.0 + j4.capstan.error_dtheta(&j4.params, JointRad(theta)))
            }
            Drive::Polynomial { poly, .. } => 1.0 + poly.derivative(theta),
        })
    }
}

/// A device as the force computation sees it: a kinematic chain and one drive per joint.
/// Used both for the model under test (what the controller believes) and for the truth (what
/// the simulated device is).
///
/// Two evaluations stand behind it:
///
/// - **the runtime** ([`hapcal_runtime::Model`], allocation-free, the code a controller
///   runs): [`ForceModel::nominal`] and [`ForceModel::calibrated`] load the device file into
///   it exactly as [`hapcal_runtime::Model::from_toml`] reads it, so the force study
///   measures what a controller would render;
/// - **the calibration library** (`hapcal-kinematics` chain with deviations `x`, [`Drive`]s
///   of `hapcal-transmission`): [`ForceModel::truth`], the simulated "real device" with its
///   four-bar, which is no controller code; [`ForceModel::try_new`]; and
///   [`ForceModel::nominal_library`], [`ForceModel::calibrated_library`], the independent
///   implementation the runtime models are tested against (to 1e-12).
///
/// Wrenches and Jacobians are in the **end-effector (body) frame at the end point**: a
/// wrench `w = (f, m)` holds the force f (N) and moment m (N·m) about the end point,
/// expressed in the tip frame of the chain — the frame of a force sensor at the handle.
/// That makes every result independent of the base frame (row 0 and its unidentifiable
/// `alpha0`, `theta0` do not matter).
#[derive(Clone, Debug)]
pub struct ForceModel {
    eval: Eval,
}

/// How a [`ForceModel`] is evaluated.
#[derive(Clone, Debug)]
enum Eval {
    /// The runtime a controller runs (boxed: its storage is fixed-size and large).
    Runtime(Box<hapcal_runtime::Model>),
    /// The calibration library: chain, deviations (length `chain.n_params()`), drives.
    Library {
        chain: Chain,
        x: Vec<f64>,
        drives: Vec<Drive>,
    },
}

/// The runtime model of `device`'s file text, as [`hapcal_runtime::Model::from_toml`] reads
/// it (the text is the device written back, [`hapcal_io::write_device`]).
fn runtime_model(device: &Device) -> Result<ForceModel, Error> {
    let text = hapcal_io::write_device(device);
    let model = hapcal_runtime::Model::from_toml(&text, "device file")
        .map_err(|source| Error::Runtime { source })?;
    Ok(ForceModel {
        eval: Eval::Runtime(Box::new(model)),
    })
}

/// A runtime pose as an isometry (the rotation re-orthonormalised through a quaternion,
/// which changes entries by rounding only).
fn isometry(pose: &hapcal_runtime::Pose) -> Isometry3<f64> {
    let r = Matrix3::from_fn(|i, j| pose.rotation[i][j]);
    let [x, y, z] = pose.translation_m;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}

/// The capstan of 1-based joint `joint`, if the device has one.
fn device_capstan(device: &Device, joint: usize) -> Result<Option<Capstan>, Error> {
    device
        .capstans
        .iter()
        .find(|c| c.joint == joint)
        .map(|c| {
            Capstan::try_new(c.ratio, c.drum_distance_m)
                .map_err(|source| Error::Transmission { joint, source })
        })
        .transpose()
}

impl ForceModel {
    /// A model from its parts: `chain`, deviations `x` (length `chain.n_params()`, m or rad)
    /// and one drive per joint.
    ///
    /// # Errors
    /// [`Error::Length`] if `x` or `drives` has the wrong length.
    pub fn try_new(chain: Chain, x: Vec<f64>, drives: Vec<Drive>) -> Result<ForceModel, Error> {
        if x.len() != chain.n_params() {
            return Err(Error::Length {
                what: "deviations x",
                expected: chain.n_params(),
                found: x.len(),
            });
        }
        if drives.len() != chain.n_joints() {
            return Err(Error::Length {
                what: "drives",
                expected: chain.n_joints(),
                found: drives.len(),
            });
        }
        Ok(ForceModel {
            eval: Eval::Library { chain, x, drives },
        })
    }

    /// The nominal model of `device`, evaluated by the runtime: its D-H rows as written and
    /// ideal drives (`q = θ`) with the nominal capstan ratios, i.e. the device file without
    /// its `[calibration]` loaded by [`hapcal_runtime::Model::from_toml`]. This is the
    /// uncalibrated controller; for a calibrated device file (rows already corrected) use
    /// [`ForceModel::calibrated`]. The same model in the calibration library is
    /// [`ForceModel::nominal_library`].
    ///
    /// # Errors
    /// [`Error::Runtime`] for a device the runtime refuses: a `[[placement]]` (URDF) chain,
    /// more than [`hapcal_runtime::MAX_JOINTS`] joints, an invalid capstan.
    pub fn nominal(device: &Device) -> Result<ForceModel, Error> {
        let mut nominal = device.clone();
        nominal.calibration = None;
        runtime_model(&nominal)
    }

    /// The calibrated model stored in a calibrated device file, evaluated by the runtime as a
    /// controller loads it ([`hapcal_runtime::Model::from_toml`]): the same model as
    /// [`ForceModel::calibrated_library`] (which lists the `[calibration.values]` entries it
    /// reads), computed by other code. A device without `[calibration]` gives the nominal
    /// model.
    ///
    /// # Errors
    /// [`Error::Runtime`] naming the entry for an unknown capstan field, a joint without a
    /// capstan, a wrong unit, a gap in the Chebyshev indices or invalid capstan parameters;
    /// and those of [`ForceModel::nominal`].
    pub fn calibrated(device: &Device) -> Result<ForceModel, Error> {
        runtime_model(device)
    }

    /// [`ForceModel::nominal`] evaluated by the calibration library (hapcal-kinematics,
    /// hapcal-transmission) instead of the runtime: D-H rows as written (x = 0), ideal
    /// capstan drives, direct drives elsewhere.
    ///
    /// # Errors
    /// [`Error::Device`] if the chain cannot be built, [`Error::Transmission`] for an invalid
    /// capstan.
    pub fn nominal_library(device: &Device) -> Result<ForceModel, Error> {
        let (chain, x, drives) = ForceModel::nominal_parts(device)?;
        ForceModel::try_new(chain, x, drives)
    }

    /// Chain, zero deviations and ideal drives of [`ForceModel::nominal_library`].
    fn nominal_parts(device: &Device) -> Result<(Chain, Vec<f64>, Vec<Drive>), Error> {
        let chain = device.chain().map_err(|source| Error::Device { source })?;
        let mut drives = Vec::with_capacity(chain.n_joints());
        for joint in 1..=chain.n_joints() {
            drives.push(match device_capstan(device, joint)? {
                Some(capstan) => Drive::Capstan {
                    capstan,
                    params: CapstanParams::default(),
                },
                None => Drive::Direct,
            });
        }
        let x = vec![0.0; chain.n_params()];
        Ok((chain, x, drives))
    }

    /// [`ForceModel::calibrated`] evaluated by the calibration library instead of the
    /// runtime, the independent implementation the runtime is tested against: the D-H rows
    /// as written (the identified kinematic deviations are already applied, see
    /// [`Device::with_calibration`]) and the drives of `[calibration.values]` as the runtime
    /// reads them ([`haptic_drives`]): `capstan{j}.*` on each capstan (missing ones 0; paper
    /// eq. 1), `joint{j}.cheb*` as the joint's error polynomial on its range (the paper's
    /// tenth-order joint-4 model) in place of its capstan, keeping the nominal ratio. A
    /// device without `[calibration]` gives the nominal model.
    ///
    /// # Errors
    /// [`Error::Calibration`] naming the entry (`[[capstan]]` for the file's capstans) for a
    /// record [`haptic_drives`] refuses or invalid capstan parameters or coefficients; and the
    /// errors of [`ForceModel::nominal_library`].
    pub fn calibrated_library(device: &Device) -> Result<ForceModel, Error> {
        let (chain, x, _) = ForceModel::nominal_parts(device)?;
        let bad = |name: String, message: String| Error::Calibration { name, message };
        let read = haptic_drives(
            &device.capstans,
            chain.n_joints(),
            device.dh.len(),
            device.calibration.as_ref(),
        )
        .map_err(|f| {
            bad(
                f.value.clone().unwrap_or_else(|| "[[capstan]]".into()),
                f.message,
            )
        })?;
        let limits = device.joint_limits();
        let drives = (read.drives.into_iter().enumerate())
            .map(|(j, drive)| match drive {
                JointDrive::Direct => Ok(Drive::Direct),
                JointDrive::Capstan {
                    ratio,
                    drum_distance_m,
                    params,
                } => {
                    let capstan = Capstan::try_new(ratio, drum_distance_m).map_err(|source| {
                        Error::Transmission {
                            joint: j + 1,
                            source,
                        }
                    })?;
                    capstan
                        .check_params(&params)
                        .map_err(|e| bad(format!("capstan{}.*", j + 1), e.to_string()))?;
                    Ok(Drive::Capstan { capstan, params })
                }
                JointDrive::Polynomial { ratio, coeffs } => {
                    let (lo, hi) = limits.get(j).copied().unwrap_or((-1.0, 1.0));
                    let poly = Chebyshev::try_new(lo, hi, coeffs)
                        .map_err(|e| bad(format!("joint{}.cheb*", j + 1), e.to_string()))?;
                    Ok(Drive::Polynomial { ratio, poly })
                }
            })
            .collect::<Result<_, Error>>()?;
        ForceModel::try_new(chain, x, drives)
    }

    /// The truth device, evaluated by the calibration library (it is the simulated real
    /// device, not controller code): the chain with the truth's deviations, every capstan with its true
    /// eq.-1 parameters, and joint [`PARALLELOGRAM_JOINT`] through its capstan and the true
    /// four-bar (lengths `L + ΔL`, crank offset `phi0_rad`; paper eqs. 1–2). Its
    /// [`ForceModel::joint_angles`] equal [`hapcal_sim::true_joint_angles`].
    ///
    /// # Errors
    /// [`Error::Truth`] for a deviation that is not a chain parameter or a capstan the truth
    /// lacks; [`Error::Transmission`] for invalid values; and those of
    /// [`ForceModel::nominal_library`].
    pub fn truth(device: &Device, truth: &Truth) -> Result<ForceModel, Error> {
        let (chain, _, mut drives) = ForceModel::nominal_parts(device)?;
        let x = hapcal_sim::truth_deviations(&chain, truth)
            .map_err(|source| Error::Truth { source })?;
        for (j, drive) in drives.iter_mut().enumerate() {
            let joint = j + 1;
            let Drive::Capstan { capstan, params } = drive else {
                continue;
            };
            let t = (truth.capstans.iter())
                .find(|t| t.joint == joint)
                .ok_or(Error::Truth {
                    source: hapcal_sim::Error::MissingCapstan { joint },
                })?;
            *params = t.params();
            let transmission = |source| Error::Transmission { joint, source };
            capstan.check_params(params).map_err(transmission)?;
            if device.parallelogram.is_some() && joint == PARALLELOGRAM_JOINT {
                let joint4 = (truth.joint4(device, *capstan, *params))
                    .map_err(|source| Error::Truth { source })?;
                *drive = Drive::Parallelogram(joint4);
            }
        }
        ForceModel::try_new(chain, x, drives)
    }

    /// Number of joints.
    pub fn n_joints(&self) -> usize {
        match &self.eval {
            Eval::Runtime(model) => model.n_joints(),
            Eval::Library { drives, .. } => drives.len(),
        }
    }

    /// The calibration library's drives, one per joint; `None` for a model the runtime
    /// evaluates ([`ForceModel::runtime`] has its drives).
    pub fn library_drives(&self) -> Option<&[Drive]> {
        match &self.eval {
            Eval::Runtime(_) => None,
            Eval::Library { drives, .. } => Some(drives),
        }
    }

    /// The runtime model behind [`ForceModel::nominal`] and [`ForceModel::calibrated`], the
    /// one a controller loads; `None` for a model the calibration library evaluates.
    pub fn runtime(&self) -> Option<&hapcal_runtime::Model> {
        match &self.eval {
            Eval::Runtime(model) => Some(model),
            Eval::Library { .. } => None,
        }
    }

    /// Nominal ratio R of each joint's drive (motor angle per unit reading; 1 for a direct
    /// drive), one per joint.
    pub fn ratios(&self) -> Vec<f64> {
        match &self.eval {
            Eval::Runtime(model) => model.drives().iter().map(|d| d.ratio()).collect(),
            Eval::Library { drives, .. } => drives.iter().map(Drive::ratio).collect(),
        }
    }

    fn check_readings(&self, theta: &[f64]) -> Result<(), Error> {
        if theta.len() != self.n_joints() {
            return Err(Error::Length {
                what: "joint readings",
                expected: self.n_joints(),
                found: theta.len(),
            });
        }
        Ok(())
    }

    /// Joint angles q and `dq/dθ` from the runtime (n entries each).
    fn runtime_angles(
        model: &hapcal_runtime::Model,
        theta: &[f64],
    ) -> Result<(Vec<f64>, Vec<f64>), Error> {
        let n = model.n_joints();
        let (mut q, mut dq) = (vec![0.0; n], vec![0.0; n]);
        (model.joint_angles(theta, &mut q, &mut dq))
            .map_err(|source| Error::Evaluate { source })?;
        Ok((q, dq))
    }

    /// Joint angles q (rad, one per joint) for readings `theta` (rad): each drive's map.
    ///
    /// # Errors
    /// [`Error::Length`] for a wrong number of readings; [`Error::Transmission`] where a
    /// four-bar cannot close; [`Error::Evaluate`] for a reading the runtime refuses (NaN or
    /// infinite).
    pub fn joint_angles(&self, theta: &[f64]) -> Result<Vec<f64>, Error> {
        self.drive_maps(theta, false)
    }

    /// `dq/dθ` of each drive at readings `theta` (rad/rad, one per joint).
    ///
    /// # Errors
    /// As [`ForceModel::joint_angles`].
    pub fn angle_derivatives(&self, theta: &[f64]) -> Result<Vec<f64>, Error> {
        self.drive_maps(theta, true)
    }

    /// Each drive's map at readings `theta`: the joint angles (rad) or, with `derivative`,
    /// `dq/dθ` (rad/rad); errors as [`ForceModel::joint_angles`].
    fn drive_maps(&self, theta: &[f64], derivative: bool) -> Result<Vec<f64>, Error> {
        self.check_readings(theta)?;
        match &self.eval {
            Eval::Runtime(model) => {
                let (q, dq) = ForceModel::runtime_angles(model, theta)?;
                Ok(if derivative { dq } else { q })
            }
            Eval::Library { drives, .. } => (drives.iter().zip(theta).enumerate())
                .map(|(j, (d, &t))| {
                    let map = if derivative {
                        d.angle_derivative(t)
                    } else {
                        d.angle_rad(t)
                    };
                    map.map_err(|source| Error::Transmission {
                        joint: j + 1,
                        source,
                    })
                })
                .collect(),
        }
    }

    /// Pose of the end-effector (tip) frame in the chain's base frame for readings `theta`
    /// (translation in m).
    ///
    /// # Errors
    /// As [`ForceModel::joint_angles`].
    pub fn end_pose(&self, theta: &[f64]) -> Result<Isometry3<f64>, Error> {
        self.check_readings(theta)?;
        match &self.eval {
            Eval::Runtime(model) => {
                let pose = (model.end_pose(theta)).map_err(|source| Error::Evaluate { source })?;
                Ok(isometry(&pose))
            }
            Eval::Library { chain, x, .. } => {
                let q = self.joint_angles(theta)?;
                Ok(chain.end_pose(x, &q))
            }
        }
    }

    /// Body Jacobian with respect to the joint angles at readings `theta`: 6 × `n_joints`,
    /// `J_b = diag(Rᵀ, Rᵀ)·J_geo(q)` with R the tip orientation and `J_geo` the geometric
    /// Jacobian at the end point (Siciliano et al. 2009, §3.1). Rows 0–2: end-point velocity
    /// in the tip frame, m/rad; rows 3–5: angular velocity in the tip frame, rad/rad.
    ///
    /// # Errors
    /// As [`ForceModel::joint_angles`].
    pub fn body_jacobian(&self, theta: &[f64]) -> Result<Matrix6xX<f64>, Error> {
        self.check_readings(theta)?;
        match &self.eval {
            Eval::Runtime(model) => {
                let n = model.n_joints();
                let mut jac = [[0.0; 6]; MAX_JOINTS];
                (model.body_jacobian(theta, &mut jac[..n]))
                    .map_err(|source| Error::Evaluate { source })?;
                Ok(Matrix6xX::from_fn(n, |r, k| jac[k][r]))
            }
            Eval::Library { chain, x, .. } => {
                let q = self.joint_angles(theta)?;
                let pose = chain.end_pose(x, &q);
                let rt: Matrix3<f64> = pose.rotation.to_rotation_matrix().matrix().transpose();
                let mut jac = chain.geometric_jacobian(x, &q);
                for col in 0..jac.ncols() {
                    let lin = rt * jac.fixed_view::<3, 1>(0, col);
                    let ang = rt * jac.fixed_view::<3, 1>(3, col);
                    jac.fixed_view_mut::<3, 1>(0, col).copy_from(&lin);
                    jac.fixed_view_mut::<3, 1>(3, col).copy_from(&ang);
                }
                Ok(jac)
            }
        }
    }

    /// Motor torques (N·m, one per joint) that this model commands for the body-frame wrench
    /// `wrench` (N, N·m) at readings `theta`: `τ_j = J_bᵀ w` (paper Fig. 11's Jacobian
    /// block), then `τ_m = τ_j·(dq/dθ)/R` per drive ([`Drive`]). A runtime model computes
    /// them with [`hapcal_runtime::Model::evaluate`], as a controller does.
    ///
    /// # Errors
    /// As [`ForceModel::joint_angles`].
    pub fn motor_torques(&self, theta: &[f64], wrench: &Vector6<f64>) -> Result<Vec<f64>, Error> {
        self.check_readings(theta)?;
        if let Eval::Runtime(model) = &self.eval {
            let w = [
                wrench[0], wrench[1], wrench[2], wrench[3], wrench[4], wrench[5],
            ];
            let mut out = Evaluation::default();
            (model.evaluate(theta, &w, &mut out)).map_err(|source| Error::Evaluate { source })?;
            return Ok(out.motor_torques_nm[..model.n_joints()].to_vec());
        }
        let tau_j = self.body_jacobian(theta)?.transpose() * wrench;
        let dq = self.angle_derivatives(theta)?;
        Ok((self.ratios().iter().zip(&dq).zip(tau_j.iter()))
            .map(|((r, &g), &t)| t * g / r)
            .collect())
    }

    /// Joint torques (N·m) that motor torques `tau_m` (N·m) produce at readings `theta`:
    /// `τ_j = τ_m·R/(dq/dθ)` per drive ([`Drive`]).
    ///
    /// # Errors
    /// [`Error::Length`] if `tau_m` has the wrong length; as [`ForceModel::joint_angles`].
    pub fn joint_torques(&self, theta: &[f64], tau_m: &[f64]) -> Result<Vec<f64>, Error> {
        if tau_m.len() != self.n_joints() {
            return Err(Error::Length {
                what: "motor torques",
                expected: self.n_joints(),
                found: tau_m.len(),
            });
        }
        let dq = self.angle_derivatives(theta)?;
        Ok((self.ratios().iter().zip(&dq).zip(tau_m))
            .map(|((r, &g), &t)| t * r / g)
            .collect())
    }
}
