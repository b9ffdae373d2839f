//! The virtual-wall experiment of paper Fig. 12 and its extension to random poses and all six
//! wrench directions.

use hapcal_io::Device;
use nalgebra::{Matrix6, Vector6};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::control::{
    Direction, Readings, WrenchError, closed_loop, condition_number, wrench_error, wrench_map,
};
use crate::{Error, ForceModel};

/// Settings shared by the wall experiment and the random-pose sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallConfig {
    /// Wall stiffness K (virtual environment Z_e), N/m. Paper: 100 N/m.
    pub stiffness_n_per_m: f64,
    /// Wall travel along the tip z axis, m. Paper: 0.02 m (so the final desired force is 2 N).
    pub travel_m: f64,
    /// Number of travel steps (samples are at `k·travel/n_steps`, `k = 0..=n_steps`).
    pub n_steps: usize,
    /// Force-feedback gain G (dimensionless, ≥ 0; 0 = open loop).
    pub gain: f64,
    /// The joint locked at home (1-based). Paper: the redundant joint 3.
    pub locked_joint: usize,
    /// Round the controller's readings to the encoder resolution
    /// ([`hapcal_sim::quantise_readings`]) while the device sits at the exact readings.
    pub quantise: bool,
}

impl WallConfig {
    /// The paper's experiment (Fig. 12): K = 100 N/m, 20 mm of travel in 1 mm steps, joint 3
    /// locked, quantised readings, open loop (`gain = 0`; the paper gives no G).
    pub fn paper() -> WallConfig {
        WallConfig {
            stiffness_n_per_m: 100.0,
            travel_m: 0.02,
            n_steps: 20,
            gain: 0.0,
            locked_joint: 3,
            quantise: true,
        }
    }

    /// This configuration with force-feedback gain `gain`.
    #[must_use]
    pub fn with_gain(mut self, gain: f64) -> WallConfig {
        self.gain = gain;
        self
    }

    fn check(&self) -> Result<(), Error> {
        for (name, value) in [
            ("stiffness_n_per_m", self.stiffness_n_per_m),
            ("travel_m", self.travel_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::InvalidConfig {
                    name,
                    value,
                    expected: "a finite number > 0",
                });
            }
        }
        if self.n_steps == 0 {
            return Err(Error::InvalidConfig {
                name: "n_steps",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }
}

/// The home readings of `device`: the mid-range of each joint (docs/design.md §2), rad.
pub fn home_readings(device: &Device) -> Vec<f64> {
    (device.joint_limits().iter())
        .map(|(lo, hi)| 0.5 * (lo + hi))
        .collect()
}

fn readings(device: &Device, theta: &[f64], quantise: bool) -> Readings {
    Readings {
        controller: if quantise {
            hapcal_sim::quantise_readings(device, theta)
        } else {
            theta.to_vec()
        },
        device: theta.to_vec(),
    }
}

/// One sample of the wall experiment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallSample {
    /// Wall travel s, m.
    pub travel_m: f64,
    /// Desired force along the model's tip z, `K·s`, N.
    pub desired_n: f64,
    /// Rendered wrench in the handle's (true tip) frame, as the force sensor reads it:
    /// `(Fx, Fy, Fz)` in N, `(Mx, My, Mz)` in N·m.
    pub wrench: Vector6<f64>,
}

/// The virtual-wall experiment of paper Fig. 12 at readings `theta` (rad): the handle fixed,
/// the wall (stiffness K) moved `travel_m` along the tip z axis, so the desired wrench is
/// `w_d(s) = (0, 0, K·s, 0, 0, 0)` in the model's tip frame; the rendered wrench is
/// `C·w_d(s)` ([`closed_loop`] of [`wrench_map`]), `model` in the controller and `truth` as
/// the device. Ideally `Fx = Fy = 0` and `Fz = K·s`.
///
/// `device` gives the encoder resolution for quantisation. Returns `n_steps + 1` samples.
///
/// # Errors
/// [`Error::InvalidConfig`] for a bad configuration, and those of [`wrench_map`] and
/// [`closed_loop`].
pub fn virtual_wall(
    device: &Device,
    model: &ForceModel,
    truth: &ForceModel,
    theta: &[f64],
    cfg: &WallConfig,
) -> Result<Vec<WallSample>, Error> {
    cfg.check()?;
    let r = readings(device, theta, cfg.quantise);
    let c = closed_loop(
        &wrench_map(model, truth, &r, Some(cfg.locked_joint))?,
        cfg.gain,
    )?;
    Ok((0..=cfg.n_steps)
        .map(|k| {
            let travel_m = cfg.travel_m * k as f64 / cfg.n_steps as f64;
            let desired_n = cfg.stiffness_n_per_m * travel_m;
            let wd = Vector6::new(0.0, 0.0, desired_n, 0.0, 0.0, 0.0);
            WallSample {
                travel_m,
                desired_n,
                wrench: c * wd,
            }
        })
        .collect())
}

/// Settings of the random-pose sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepConfig {
    /// Number of accepted poses.
    pub n_poses: usize,
    /// Seed of `ChaCha8Rng`.
    pub seed: u64,
    /// Poses whose truth Jacobian has a condition number above this
    /// ([`condition_number`] with `length_m`) are redrawn: near a singularity the fixed
    /// handle cannot be pushed in every direction and every model fails.
    pub max_condition: f64,
    /// Length that scales the linear rows for the condition number, m.
    pub length_m: f64,
}

impl SweepConfig {
    /// The sweep of the reference device's force report: 200 poses, seed 4, condition
    /// number ≤ 100 with a 0.21 m length scale (the reference device's upper arm and forearm,
    /// docs/design.md §2).
    pub fn reference_device() -> SweepConfig {
        SweepConfig {
            n_poses: 200,
            seed: 4,
            max_condition: 100.0,
            length_m: 0.21,
        }
    }
}

impl SweepConfig {
    fn check(&self) -> Result<(), Error> {
        if self.n_poses == 0 {
            return Err(Error::InvalidConfig {
                name: "n_poses",
                value: 0.0,
                expected: "at least 1",
            });
        }
        if !(self.max_condition.is_finite() && self.max_condition >= 1.0) {
            return Err(Error::InvalidConfig {
                name: "max_condition",
                value: self.max_condition,
                expected: "a finite number ≥ 1",
            });
        }
        if !(self.length_m.is_finite() && self.length_m > 0.0) {
            return Err(Error::InvalidConfig {
                name: "length_m",
                value: self.length_m,
                expected: "a finite length > 0 m",
            });
        }
        Ok(())
    }
}

/// Random poses for the sweep: readings drawn uniformly within the joint limits
/// ([`hapcal_sim::sample_readings`]), the locked joint set to its home reading, redrawn while
/// the truth's condition number exceeds `sweep.max_condition`.
///
/// Returns the accepted readings and the number of draws.
///
/// # Errors
/// [`Error::InvalidConfig`] for `n_poses = 0`, `max_condition < 1` or a non-positive
/// `length_m`; [`Error::TooFewPoses`] if fewer than `n_poses` of `100·n_poses` draws are
/// accepted; those of [`condition_number`].
pub fn sample_poses(
    device: &Device,
    truth: &ForceModel,
    locked_joint: usize,
    sweep: &SweepConfig,
) -> Result<(Vec<Vec<f64>>, usize), Error> {
    sweep.check()?;
    let home = home_readings(device);
    let mut rng = ChaCha8Rng::seed_from_u64(sweep.seed);
    let max_draws = 100 * sweep.n_poses.max(1);
    let mut poses = Vec::with_capacity(sweep.n_poses);
    let mut drawn = 0;
    while poses.len() < sweep.n_poses {
        if drawn >= max_draws {
            return Err(Error::TooFewPoses {
                accepted: poses.len(),
                drawn,
                max_condition: sweep.max_condition,
            });
        }
        drawn += 1;
        let Some(mut theta) = hapcal_sim::sample_readings(device, &mut rng, 1).pop() else {
            break;
        };
        if let (Some(slot), Some(h)) = (
            theta.get_mut(locked_joint.wrapping_sub(1)),
            home.get(locked_joint.wrapping_sub(1)),
        ) {
            *slot = *h;
        }
        let cond = condition_number(truth, &theta, Some(locked_joint), sweep.length_m)?;
        if cond <= sweep.max_condition {
            poses.push(theta);
        }
    }
    Ok((poses, drawn))
}

/// Per-pose errors of the six wrench directions for one model and one gain.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepErrors {
    /// `errors[d][p]`: direction `Direction::ALL[d]` at pose p.
    pub errors: [Vec<WrenchError>; 6],
}

/// The wall experiment's static map at every pose of `poses`, for each of the six body-frame
/// directions: the desired wrench is the unit wrench `e_d` (any magnitude gives the same
/// errors, the map is linear), the rendered one `C·e_d` ([`closed_loop`] with `cfg.gain`).
///
/// # Errors
/// Those of [`wrench_map`] and [`closed_loop`].
pub fn sweep(
    device: &Device,
    model: &ForceModel,
    truth: &ForceModel,
    poses: &[Vec<f64>],
    cfg: &WallConfig,
) -> Result<SweepErrors, Error> {
    let mut errors: [Vec<WrenchError>; 6] = Default::default();
    for theta in poses {
        let r = readings(device, theta, cfg.quantise);
        let c: Matrix6<f64> = closed_loop(
            &wrench_map(model, truth, &r, Some(cfg.locked_joint))?,
            cfg.gain,
        )?;
        for (d, out) in Direction::ALL.iter().zip(errors.iter_mut()) {
            let mut wd = Vector6::zeros();
            wd[d.index()] = 1.0;
            out.push(wrench_error(&wd, &(c * wd), *d));
        }
    }
    Ok(SweepErrors { errors })
}

/// The `p`-quantile (0 ≤ p ≤ 1) of `values` by linear interpolation between order
/// statistics; NaN for an empty slice.
pub fn quantile(values: &[f64], p: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let pos = p.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    v[lo] + (v[hi] - v[lo]) * (pos - lo as f64)
}
