//! A simulated tracker recording of the KUKA LBR iiwa 14 (MUKCa's URDF) trained on one part of
//! joint 1's range and used on another: every URDF placement parameter deviates (0.5 mm,
//! 1 mrad), and joint 1 carries an error of its own angle the calibration does not model (a
//! harmonic or a gear-ratio error). Shared by the coverage test and its sweep.
#![allow(clippy::unwrap_used, clippy::expect_used, dead_code, unreachable_pub)]

use hapcal_calibrate::measured::Robot;
use hapcal_io::MeasurementTable;
use hapcal_kinematics::Tree;
use rand::{Rng, SeedableRng};
use rand_distr::Normal;

/// Marker noise per axis, m (a laser tracker).
pub const NOISE_M: f64 = 5e-5;

#[path = "tracker.rs"]
pub mod tracker;

/// The iiwa 14 with its ball on the last link.
pub fn robot() -> Robot {
    tracker::iiwa()
}

/// An error of joint 1's own angle that no rung models: the true angle is the reading plus
/// [`Effect::error_rad`].
#[derive(Clone, Copy, Debug)]
pub enum Effect {
    /// `a·sin(k·q + φ)`: amplitude a (rad), order k, phase φ (rad).
    Harmonic {
        amplitude_rad: f64,
        order: f64,
        phase_rad: f64,
    },
    /// `ε·q`: a gear-ratio error ε (dimensionless).
    Ratio { epsilon: f64 },
}

impl Effect {
    /// The error of a reading `q` (rad), rad.
    pub fn error_rad(&self, q: f64) -> f64 {
        match *self {
            Effect::Harmonic {
                amplitude_rad,
                order,
                phase_rad,
            } => amplitude_rad * (order * q + phase_rad).sin(),
            Effect::Ratio { epsilon } => epsilon * q,
        }
    }
}

/// The simulated robot: the framed tree, its true parameters and joint 1's effect.
pub struct Truth {
    /// The joint the effect acts on (index, chain order).
    pub joint: usize,
    pub framed: Tree,
    pub x: Vec<f64>,
    pub effect: Effect,
}

/// A truth drawn from `seed`: placement deviations of 0.5 mm and 1 mrad (σ) on every URDF
/// parameter, joint offsets of 1 mrad, the instrument 2.5 m away.
pub fn truth(robot: &Robot, seed: u64, effect: Effect) -> Truth {
    truth_scaled(robot, seed, effect, 1.0)
}

/// [`truth`] with the placement deviations scaled by `scale`.
pub fn truth_scaled(robot: &Robot, seed: u64, effect: Effect, scale: f64) -> Truth {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let base = tracker::instrument([2.5, -0.4, -0.8], [0.0, 0.0, 1.2]);
    let marker = tracker::marker("marker1", 0.02, 0.01, 0.06);
    let framed = (robot.tree.with_joint_offsets())
        .with_frames(&base, &[(0, marker)])
        .unwrap();
    let x = tracker::placement_deviations(&framed, scale, &mut rng);
    Truth {
        joint: 0,
        framed,
        x,
        effect,
    }
}

/// `n` rows of one tracker marker, joint 1 uniform in `q1` (rad), the other joints uniform in
/// 80 % of their limits, lines from `first_line`; named `name`.
pub fn rows(
    robot: &Robot,
    truth: &Truth,
    n: usize,
    q1: (f64, f64),
    seed: u64,
    name: &str,
) -> MeasurementTable {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, NOISE_M).unwrap();
    let rows = (0..n)
        .map(|i| {
            let mut q = tracker::within_limits(robot, &mut rng);
            let j = truth.joint;
            q[j] = rng.random_range(q1.0..q1.1);
            let mut moved = q.clone();
            moved[j] += truth.effect.error_rad(q[j]);
            let p = truth.framed.tips()[0].end_point(&truth.x, &moved);
            let marker = tracker::sample(0, &p, &noise, &mut rng);
            tracker::row(i as u64 + 2, q, vec![marker])
        })
        .collect();
    MeasurementTable::positions(name, format!("{name}.csv"), 1, rows)
}
