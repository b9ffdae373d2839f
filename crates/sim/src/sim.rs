//! Pose sampling, encoder quantisation, the truth transmissions and the simulated log.

use std::f64::consts::TAU;

use hapcal_io::{CableEncoder, Device, LogRow, N_EXT};
use hapcal_kinematics::Chain;
use hapcal_transmission::{Capstan, CapstanParams, Joint4Transmission, JointRad};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::{Error, Truth};

/// The joint (1-based) that the device's `[parallelogram]` drives, fed by that joint's
/// capstan (docs/design.md §2: joint 4, capstan 4).
pub const PARALLELOGRAM_JOINT: usize = 4;

/// Standard deviations of the simulated measurement noise (paper, simulation section;
/// docs/design.md §3). Both are zero-mean Gaussian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseModel {
    /// External encoders (`ext1..ext4`), rad.
    pub sigma_e_rad: f64,
    /// Cable-encoder distance (`distance_m`), m.
    pub sigma_m_m: f64,
}

impl NoiseModel {
    /// Noise with the given standard deviations: `sigma_e_rad` (rad) on the external
    /// encoders, `sigma_m_m` (m) on the distance. Checked by [`simulate`].
    pub fn new(sigma_e_rad: f64, sigma_m_m: f64) -> NoiseModel {
        NoiseModel {
            sigma_e_rad,
            sigma_m_m,
        }
    }

    /// No noise at all.
    pub fn none() -> NoiseModel {
        NoiseModel::new(0.0, 0.0)
    }

    /// The paper's noise: `σ_e = 2π/counts/3` (a third of the encoder's quantisation step)
    /// and, for the distance, its formula `σ_m = 2π·R_d·σ_e` ("multiplied by the cable
    /// encoder drum circumference"), ≈ 9.87 µm for `R_d = 0.015` m and 20000 counts/rev.
    ///
    /// The external encoders are taken to have the cable encoder's `counts_per_rev`
    /// (docs/design.md §2: 20000 on every encoder; the device file lists no external encoders).
    pub fn paper(cable: &CableEncoder) -> NoiseModel {
        // The model's own noise (one definition of the paper's formulas).
        let paper = hapcal_problems::DistanceLogNoise::paper(
            cable.counts_per_rev,
            cable.drum_radius_m,
            Vec::new(),
        );
        NoiseModel::new(paper.sigma_e_rad, paper.sigma_m_m)
    }

    /// As [`NoiseModel::paper`], but with the arc length `σ_m = R_d·σ_e` (≈ 1.57 µm for the
    /// reference device): an angle error σ_e of the drum pays out `R_d·σ_e` of cable. The
    /// paper's extra 2π (circumference instead of radius) looks like a slip; this model
    /// lets the consequences be compared.
    pub fn arc_length(cable: &CableEncoder) -> NoiseModel {
        let sigma_e_rad = encoder_sigma_rad(cable.counts_per_rev);
        NoiseModel::new(sigma_e_rad, cable.drum_radius_m * sigma_e_rad)
    }

    /// The noise model named `name` for `cable`: `paper` ([`NoiseModel::paper`]) or
    /// `arc-length` ([`NoiseModel::arc_length`]); `None` for any other name.
    pub fn named(name: &str, cable: &CableEncoder) -> Option<NoiseModel> {
        match name {
            "paper" => Some(NoiseModel::paper(cable)),
            "arc-length" => Some(NoiseModel::arc_length(cable)),
            _ => None,
        }
    }

    fn check(&self) -> Result<(), Error> {
        for (name, value) in [
            ("sigma_e_rad", self.sigma_e_rad),
            ("sigma_m_m", self.sigma_m_m),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::InvalidNoise { name, value });
            }
        }
        Ok(())
    }
}

/// One third of the quantisation step of an encoder with `counts` counts/rev, rad.
fn encoder_sigma_rad(counts: u32) -> f64 {
    TAU / f64::from(counts) / 3.0
}

/// The reference device's cable encoder (docs/design.md §2: 20000 counts/rev on a 0.015 m
/// drum): the encoder a device file without a `[cable_encoder]` is simulated and diagnosed
/// with.
pub const REFERENCE_CABLE_ENCODER: CableEncoder = CableEncoder {
    drum_radius_m: 0.015,
    counts_per_rev: 20_000,
};

/// What [`simulate`] produces: seed, number of poses, noise, quantisation.
///
/// Build it with [`SimConfig::new`] and adjust fields or use the `with_…` methods; more
/// knobs (unmodelled effects) will be added without breaking callers.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct SimConfig {
    /// Seed of the random generator (`ChaCha8Rng::seed_from_u64`); equal seeds give equal logs.
    pub seed: u64,
    /// Number of poses (log rows).
    pub n_poses: usize,
    /// Measurement noise.
    pub noise: NoiseModel,
    /// Quantise the joint readings to their encoders' resolution at the joint side
    /// ([`joint_resolutions_rad`]).
    pub quantise_joints: bool,
}

impl SimConfig {
    /// `n_poses` poses from `seed`, with the paper's noise for the reference device
    /// ([`NoiseModel::paper`] of a 20000-count cable encoder with a 0.015 m drum, i.e.
    /// `σ_e = 2π/20000/3` rad and `σ_m ≈ 9.87 µm`) and quantised joint readings. For another
    /// device, set `noise` from its cable encoder.
    pub fn new(seed: u64, n_poses: usize) -> SimConfig {
        SimConfig {
            seed,
            n_poses,
            noise: NoiseModel::paper(&REFERENCE_CABLE_ENCODER),
            quantise_joints: true,
        }
    }

    /// This configuration with noise `noise`.
    #[must_use]
    pub fn with_noise(mut self, noise: NoiseModel) -> SimConfig {
        self.noise = noise;
        self
    }

    /// This configuration with joint quantisation on or off.
    #[must_use]
    pub fn with_quantise_joints(mut self, quantise_joints: bool) -> SimConfig {
        self.quantise_joints = quantise_joints;
        self
    }
}

/// How one joint turns its reading into its true angle.
enum JointModel {
    Direct,
    Capstan(Capstan, CapstanParams),
    Joint4(Joint4Transmission),
}

/// The truth device's transmissions, one model per joint.
struct Transmissions {
    joints: Vec<JointModel>,
}

impl Transmissions {
    fn new(device: &Device, truth: &Truth) -> Result<Transmissions, Error> {
        let n_joints = device.n_joints();
        for t in &truth.capstans {
            if !device.capstans.iter().any(|c| c.joint == t.joint) {
                return Err(Error::UnexpectedCapstan { joint: t.joint });
            }
        }
        let mut joints: Vec<JointModel> = (0..n_joints).map(|_| JointModel::Direct).collect();
        for c in &device.capstans {
            let joint = c.joint;
            let t = (truth.capstans.iter())
                .find(|t| t.joint == joint)
                .ok_or(Error::MissingCapstan { joint })?;
            let transmission = |source| Error::Transmission { joint, source };
            let capstan = Capstan::try_new(c.ratio, c.drum_distance_m).map_err(transmission)?;
            let params = t.params();
            capstan.check_params(&params).map_err(transmission)?;
            let model = match device.parallelogram {
                Some(_) if joint == PARALLELOGRAM_JOINT => {
                    JointModel::Joint4(truth.joint4(device, capstan, params)?)
                }
                _ => JointModel::Capstan(capstan, params),
            };
            // A capstan on a joint the chain does not have (impossible for a device from
            // `read_device`) drives nothing.
            if let Some(slot) = joints.get_mut(joint.wrapping_sub(1)) {
                *slot = model;
            }
        }
        if device.parallelogram.is_some()
            && !matches!(
                joints.get(PARALLELOGRAM_JOINT - 1),
                Some(JointModel::Joint4(_))
            )
        {
            return Err(Error::Parallelogram {
                joint: PARALLELOGRAM_JOINT,
                message: "the device has no capstan on this joint to drive it".to_owned(),
            });
        }
        Ok(Transmissions { joints })
    }

    /// Whether joint `joint_idx` (0-based) has a transmission (and so an external encoder).
    fn has_transmission(&self, joint_idx: usize) -> bool {
        matches!(
            self.joints.get(joint_idx),
            Some(JointModel::Capstan(..) | JointModel::Joint4(_))
        )
    }

    fn true_angles(&self, theta: &[f64]) -> Result<Vec<f64>, Error> {
        if theta.len() != self.joints.len() {
            return Err(Error::JointCount {
                expected: self.joints.len(),
                found: theta.len(),
            });
        }
        (self.joints.iter().zip(theta).enumerate())
            .map(|(j, (model, &t))| match model {
                JointModel::Direct => Ok(t),
                JointModel::Capstan(capstan, params) => Ok(capstan.output_rad(params, JointRad(t))),
                JointModel::Joint4(j4) => {
                    (j4.output_rad(JointRad(t))).map_err(|source| Error::Transmission {
                        joint: j + 1,
                        source,
                    })
                }
            })
            .collect()
    }
}

/// True joint angles, rad, for joint readings `theta` (rad, one per joint) of the truth device.
///
/// Joints with a capstan: [`Capstan::output_rad`] with the truth's parameters (paper eq. 1).
/// The parallelogram joint ([`PARALLELOGRAM_JOINT`]): [`Joint4Transmission::output_rad`],
/// its capstan feeding the four-bar of lengths `L + ΔL` (paper eqs. 1 and 2). Other joints
/// (direct drive): the reading itself. Returns one angle per joint.
///
/// # Errors
///
/// [`Error::JointCount`] if `theta` has another length than the device has joints;
/// [`Error::MissingCapstan`], [`Error::UnexpectedCapstan`], [`Error::Parallelogram`] if the
/// truth's transmissions do not match the device's; [`Error::Transmission`] if the
/// transmission model rejects the truth values or the four-bar cannot close.
pub fn true_joint_angles(device: &Device, truth: &Truth, theta: &[f64]) -> Result<Vec<f64>, Error> {
    Transmissions::new(device, truth)?.true_angles(theta)
}

/// The truth's kinematic deviation vector `x` for `chain` (length [`Chain::n_params`], in
/// the order of [`Chain::params`], m or rad): [`Truth::deviations`] by name, 0 elsewhere.
///
/// # Errors
///
/// [`Error::UnknownParameter`] if a name is not a parameter of `chain`.
pub fn truth_deviations(chain: &Chain, truth: &Truth) -> Result<Vec<f64>, Error> {
    let mut x = vec![0.0; chain.n_params()];
    for (name, value) in &truth.deviations {
        let slot = (chain.param_index(name))
            .and_then(|i| x.get_mut(i))
            .ok_or_else(|| Error::UnknownParameter {
                name: name.clone(),
                available: (chain.params().iter())
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
        *slot = *value;
    }
    Ok(x)
}

/// `n` joint-reading vectors (rad, one entry per joint), each entry uniform in its joint's
/// limits `[lower, upper)` ([`Device::joint_limits`]); not quantised (see
/// [`quantise_readings`]).
///
/// Draws exactly one `f64` per joint per pose from `rng`, pose by pose, joint by joint.
pub fn sample_readings<R: Rng + ?Sized>(device: &Device, rng: &mut R, n: usize) -> Vec<Vec<f64>> {
    let limits = device.joint_limits();
    (0..n)
        .map(|_| {
            (limits.iter())
                .map(|&(lower, upper)| {
                    let u: f64 = rng.random();
                    (lower + (upper - lower) * u).max(lower).min(upper)
                })
                .collect()
        })
        .collect()
}

/// The noise of a distance log of `device` from its encoder specification
/// ([`hapcal_problems::DistanceLogNoise::paper`]): its cable encoder's counts and drum radius
/// (the [`crate::REFERENCE_CABLE_ENCODER`] when the file has no `[cable_encoder]`) and its
/// joints' reading resolutions ([`joint_resolutions_rad`], 0 where unknown). The noise model
/// of `diagnose` and of `hapcal calibrate --model compliance` on a haptic device's logs.
pub fn distance_log_noise(device: &Device) -> hapcal_problems::DistanceLogNoise {
    let cable = (device.cable_encoder).unwrap_or(crate::REFERENCE_CABLE_ENCODER);
    hapcal_problems::DistanceLogNoise::paper(
        cable.counts_per_rev,
        cable.drum_radius_m,
        (joint_resolutions_rad(device).into_iter())
            .map(|r| r.unwrap_or(0.0))
            .collect(),
    )
}

/// Resolution of each joint's reading at the joint side, rad (one entry per
/// `[[joint]]`): `2π/(counts·R)` for a joint with a capstan of ratio `R`, `2π/counts` for a
/// direct-drive joint (encoder on the motor, docs/design.md §2); `None` where the device file
/// gives no `counts_per_rev`.
pub fn joint_resolutions_rad(device: &Device) -> Vec<Option<f64>> {
    (device.joints.iter().enumerate())
        .map(|(j, spec)| {
            let counts = f64::from(spec.counts_per_rev?);
            let ratio = (device.capstans.iter())
                .find(|c| c.joint == j + 1)
                .map_or(1.0, |c| c.ratio);
            Some(TAU / (counts * ratio))
        })
        .collect()
}

/// Joint readings `theta` (rad) rounded to the nearest multiple of their resolution
/// ([`joint_resolutions_rad`]), staying within the joint limits: a multiple just outside a
/// limit is replaced by its neighbour inside. Joints without a resolution, and entries past
/// the device's joints, are returned unchanged.
pub fn quantise_readings(device: &Device, theta: &[f64]) -> Vec<f64> {
    let resolutions = joint_resolutions_rad(device);
    let limits = device.joint_limits();
    (theta.iter().enumerate())
        .map(|(j, &t)| {
            let (Some(Some(res)), Some(&(lower, upper))) = (resolutions.get(j), limits.get(j))
            else {
                return t;
            };
            let k = (t / res).round();
            let mut v = k * res;
            if v < lower {
                v = (k + 1.0) * res;
            } else if v > upper {
                v = (k - 1.0) * res;
            }
            if (lower..=upper).contains(&v) { v } else { t }
        })
        .collect()
}

/// Simulates a measurement log of the truth device (paper, simulation section; docs/design.md §3).
///
/// `device` is the nominal device ([`Truth::read_device`]). With a
/// `ChaCha8Rng::seed_from_u64(cfg.seed)`, it first draws the readings of all
/// `cfg.n_poses` poses ([`sample_readings`]), then per pose, in order, one standard normal
/// for the distance and one for each of `ext1..ext4`. Per pose:
///
/// - `q`: the readings, quantised if `cfg.quantise_joints` ([`quantise_readings`]); always
///   within the joint limits, so the log passes [`hapcal_io::read_log`];
/// - true joint angles from the readings ([`true_joint_angles`]);
/// - `distance_m = |P| + N(0, σ_m)`, `P` the end point of the chain with the truth's
///   deviations ([`truth_deviations`], paper eqs. 3–5);
/// - `ext[k] = true angle of joint k+1 + N(0, σ_e)` for joints 1–4 that have a transmission
///   (an external encoder on its output shaft), `None` for the others;
/// - `t_s = None`, `line` = the row's line in a file written by [`hapcal_io::write_log`]
///   (pose 0 on line 2).
///
/// Equal configurations give equal logs.
///
/// # Errors
///
/// [`Error::InvalidNoise`] for a negative or non-finite σ; [`Error::Device`] if the device's
/// chain cannot be built; [`Error::UnknownParameter`] for a deviation that is not a chain
/// parameter; and the errors of [`true_joint_angles`].
pub fn simulate(device: &Device, truth: &Truth, cfg: &SimConfig) -> Result<Vec<LogRow>, Error> {
    cfg.noise.check()?;
    let chain = device.chain().map_err(|source| Error::Device { source })?;
    let x = truth_deviations(&chain, truth)?;
    let transmissions = Transmissions::new(device, truth)?;

    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let readings = sample_readings(device, &mut rng, cfg.n_poses);
    let mut rows = Vec::with_capacity(readings.len());
    for (pose_idx, theta) in readings.into_iter().enumerate() {
        let q = if cfg.quantise_joints {
            quantise_readings(device, &theta)
        } else {
            theta
        };
        let q_true = transmissions.true_angles(&q)?;
        let p = chain.end_point(&x, &q_true);
        let z_m: f64 = rng.sample(StandardNormal);
        let distance_m = p.coords.norm() + cfg.noise.sigma_m_m * z_m;
        let ext = (0..N_EXT)
            .map(|k| {
                let z_e: f64 = rng.sample(StandardNormal);
                let angle = q_true
                    .get(k)
                    .filter(|_| transmissions.has_transmission(k))?;
                Some(angle + cfg.noise.sigma_e_rad * z_e)
            })
            .collect();
        rows.push(LogRow {
            q,
            distance_m,
            ext,
            t_s: None,
            line: pose_idx as u64 + 2,
        });
    }
    Ok(rows)
}

/// Distance data of the truth's *kinematics* alone, for benchmarks and scale tests: joint
/// angles uniform within the joint limits (not quantised, no transmission errors, i.e. the
/// readings are already corrected as after step 1 of the paper's procedure) and cable
/// distances `|P(x_truth; q)| + N(0, σ_m)` (paper eq. 5).
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceSamples {
    /// Number of joints (row length of `q_rad`).
    pub n_joints: usize,
    /// Joint angles, rad, row-major: pose `k` is `q_rad[k·n_joints..(k+1)·n_joints]`.
    pub q_rad: Vec<f64>,
    /// Measured distances, m, one per pose.
    pub distance_m: Vec<f64>,
}

impl DistanceSamples {
    /// Number of poses.
    pub fn n_poses(&self) -> usize {
        self.distance_m.len()
    }

    /// Joint angles of pose `pose_idx`, rad.
    ///
    /// # Panics
    /// If `pose_idx >= n_poses()`.
    #[track_caller]
    pub fn q(&self, pose_idx: usize) -> &[f64] {
        &self.q_rad[pose_idx * self.n_joints..(pose_idx + 1) * self.n_joints]
    }
}

/// `n_poses` poses of [`DistanceSamples`] from `seed` (`ChaCha8Rng`): per pose, one uniform
/// draw per joint then one standard normal for the distance noise of `sigma_m_m` (m).
///
/// # Errors
/// [`Error::InvalidNoise`] for a negative or non-finite `sigma_m_m`; [`Error::Device`] if the
/// device's chain cannot be built; [`Error::UnknownParameter`] for a deviation that is not a
/// chain parameter.
pub fn distance_samples(
    device: &Device,
    truth: &Truth,
    seed: u64,
    n_poses: usize,
    sigma_m_m: f64,
) -> Result<DistanceSamples, Error> {
    NoiseModel::new(0.0, sigma_m_m).check()?;
    let chain = device.chain().map_err(|source| Error::Device { source })?;
    let x = truth_deviations(&chain, truth)?;
    let frozen = chain.freeze(&x);
    let limits = device.joint_limits();
    let n_joints = limits.len();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut q_rad = Vec::with_capacity(n_poses * n_joints);
    let mut distance_m = Vec::with_capacity(n_poses);
    for _ in 0..n_poses {
        let start = q_rad.len();
        for &(lower, upper) in &limits {
            let u: f64 = rng.random();
            q_rad.push((lower + (upper - lower) * u).max(lower).min(upper));
        }
        let p = frozen.end_point(&q_rad[start..]);
        let z: f64 = rng.sample(StandardNormal);
        distance_m.push(p.coords.norm() + sigma_m_m * z);
    }
    Ok(DistanceSamples {
        n_joints,
        q_rad,
        distance_m,
    })
}
