//! A simulated tracker recording of the KUKA LBR iiwa 14 (MUKCa's URDF) trained on one part of
//! joint 1's range and used on another: every URDF placement parameter deviates (0.5 mm,
//! 1 mrad), and joint 1 carries an error of its own angle the calibration does not model (a
//! harmonic or a gear-ratio error). Shared by the coverage test and its sweep.
#![allow(clippy::unwrap_used, clippy::expect_used, dead_code, unreachable_pub)]

use std::path::PathBuf;

use hapcal_calibrate::measured::{Robot, robot_from_urdf};
use hapcal_io::{MarkerSample, MeasuredRow, MeasurementTable};
use hapcal_kinematics::{FrameSpec, Isometry3, Tree, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

/// Marker noise per axis, m (a laser tracker).
pub const NOISE_M: f64 = 5e-5;

/// The iiwa 14 with its ball on the last link.
pub fn robot() -> Robot {
    let urdf =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/mukca/urdf/iiwa14.urdf");
    robot_from_urdf(&urdf, &["ball_link".to_owned()]).unwrap()
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
    let base = FrameSpec {
        name: "instrument".into(),
        nominal: Isometry3::new(Vector3::new(2.5, -0.4, -0.8), Vector3::new(0.0, 0.0, 1.2)),
    };
    let marker = FrameSpec {
        name: "marker1".into(),
        nominal: Isometry3::translation(0.02, 0.01, 0.06),
    };
    let framed = (robot.tree.with_joint_offsets())
        .with_frames(&base, &[(0, marker)])
        .unwrap();
    let lin = Normal::new(0.0, 5e-4 * scale).unwrap();
    let ang = Normal::new(0.0, 1e-3 * scale).unwrap();
    let names: Vec<String> = framed.params().iter().map(|p| p.name.clone()).collect();
    let x = (names.iter().enumerate())
        .map(|(i, name)| {
            if i < 6 || name.starts_with("marker") {
                0.0
            } else if name.ends_with(".x") || name.ends_with(".y") || name.ends_with(".z") {
                lin.sample(&mut rng)
            } else {
                ang.sample(&mut rng)
            }
        })
        .collect();
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
            let mut q: Vec<f64> = (robot.limits.iter())
                .map(|(lo, hi)| rng.random_range(0.8 * lo..0.8 * hi))
                .collect();
            let j = truth.joint;
            q[j] = rng.random_range(q1.0..q1.1);
            let mut moved = q.clone();
            moved[j] += truth.effect.error_rad(q[j]);
            let p = truth.framed.tips()[0].end_point(&truth.x, &moved);
            MeasuredRow {
                line: i as u64 + 2,
                q,
                t_s: None,
                markers: vec![MarkerSample {
                    marker: 0,
                    position_m: std::array::from_fn(|k| p[k] + noise.sample(&mut rng)),
                    rotation: None,
                }],
                distance_m: None,
            }
        })
        .collect();
    MeasurementTable {
        name: name.to_owned(),
        path: PathBuf::from(format!("{name}.csv")),
        rows,
        n_markers: 1,
        has_orientation: false,
        has_distance: false,
        ignored_columns: Vec::new(),
        warnings: Vec::new(),
    }
}
