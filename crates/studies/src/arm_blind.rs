//! The blind test of the serial-arm diagnosis ([`hapcal_diagnose::arm`]) on simulated URDF
//! robots: draw a case (robot, data kind, a random geometric truth, and no effect, one effect
//! of [`ARM_LIBRARY`], two of them together, or one effect outside it), simulate the data
//! without telling the diagnosis which, fit the geometric baseline
//! ([`hapcal_calibrate::baseline`]) and score the verdict.
//!
//! **Truth.** The nominal URDF chain (fixtures/mukca/urdf, tip `ball_link`) with every joint
//! origin deviation of [`hapcal_kinematics::Chain::params`] drawn from N(0, 0.5 mm) (lengths)
//! or N(0, 1 mrad) (angles), plus the injected effect with the sign convention of the
//! diagnosis: the kinematics sees `q_effective = q_read + Δq`, so the simulated reading is
//! `q_read = q_effective − Δq(q_effective)` (the basis is evaluated at the effective angles;
//! the difference from the readings is second order, ~1e-6 of the effect), except backlash's
//! sign, which is that of the readings' own last motion, as the diagnosis computes it (the
//! motor drives, the output trails by the play).
//!
//! **Positions data.** [`N_POSITIONS`] configurations of a random walk within the joint
//! limits (time-ordered, `t_s` = row index in s, so that backlash and drift have a meaning);
//! the tip measured by an instrument at a random rigid transform (uniform rotation, 1–2 m
//! away) with N(0, [`SIGMA_POSITION_M`]) noise per axis; the last 30 % of the rows are held
//! out (`Plan::test_last`).
//!
//! **Sockets data.** Two sockets 0.05 m apart near the recorded MUKCa sockets of a placement
//! (fixtures/mukca/data, MIT licence, TU Delft); each recorded configuration is moved onto the
//! truth's socket point by Newton steps of the minimum-norm inverse kinematics (numerical
//! Jacobian). Seating noise is noise on the reached point: the configuration is solved for the
//! socket point plus N(0, [`SIGMA_SEATING_M`]) per axis, so the residual of the true model is
//! exactly that noise. A second placement of the same unit is the held-out set.
//!
//! The diagnosis is told the noise σ (`Plan::sigma_m`) and runs with [`ArmConfig::default`].

use hapcal_calibrate::model::ModelName;
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::PathBuf;

use anyhow::{Context, Result};
use hapcal_calibrate::baseline::{GeometricBaseline, baseline_from_sets, baseline_from_tables};
use hapcal_calibrate::calibrate::{DataSet, Plan, load_device};
use hapcal_calibrate::measured::{Robot, robot_from_urdf};
use hapcal_calibrate::setup::{SetupInput, SetupReport, Severity, check_setup};
use hapcal_contract::Effect;
use hapcal_diagnose::Verdict;
use hapcal_diagnose::arm::{ARM_LIBRARY, ArmConfig, ArmDiagnosis, REPEAT_TOLERANCE, diagnose_arm};
use hapcal_io::{
    MarkerSample, MeasuredRow, MeasurementTable, SocketPlacement, SocketSamples, Units,
};
use hapcal_kinematics::{Chain, ParamUnit};
use hapcal_problems::GravityCompliance;
use nalgebra::{DMatrix, DVector, Matrix3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, StandardNormal};
use serde::Serialize;

mod report;
mod simulate;
pub use report::*;
pub(crate) use simulate::apply_point_effects;
use simulate::*;

/// Rows of a positions case (the last 30 % held out).
pub const N_POSITIONS: usize = 200;

/// Held-out fraction of a positions case (the last rows in time order).
pub const TEST_FRACTION: f64 = 0.3;

/// Instrument noise of the positions data, m per axis.
pub const SIGMA_POSITION_M: f64 = 5e-5;

/// Seating noise of the sockets data (on the reached point), m per axis.
pub const SIGMA_SEATING_M: f64 = 2e-5;

/// Distance between the two sockets of a placement, m (MUKCa).
pub const SOCKET_DISTANCE_M: f64 = 0.05;

/// σ of the truth's length deviations of every URDF joint origin, m.
pub const SIGMA_GEOMETRY_M: f64 = 5e-4;

/// σ of the truth's angle deviations of every URDF joint origin, rad.
pub const SIGMA_GEOMETRY_RAD: f64 = 1e-3;

/// The simulated robots.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ArmRobot {
    /// KUKA LBR iiwa 14 (fixtures/mukca/urdf/iiwa14.urdf; sockets of MUKCa `kuka_14`).
    Iiwa14,
    /// Franka Emika Panda (fixtures/mukca/urdf/panda.urdf; sockets of MUKCa `panda_2`).
    Panda,
}

impl ArmRobot {
    /// Both robots, in report order.
    pub const ALL: [ArmRobot; 2] = [ArmRobot::Iiwa14, ArmRobot::Panda];

    /// Stable name (`iiwa14`, `panda`).
    pub fn name(self) -> &'static str {
        match self {
            ArmRobot::Iiwa14 => "iiwa14",
            ArmRobot::Panda => "panda",
        }
    }

    fn urdf(self) -> PathBuf {
        crate::project_root().join(format!("fixtures/mukca/urdf/{}.urdf", self.name()))
    }

    /// The MUKCa unit and placements whose recorded configurations seed the socket data.
    fn placements(self) -> (&'static str, &'static [&'static str]) {
        match self {
            ArmRobot::Iiwa14 => ("kuka_14", &["front", "left_back", "raised_left"]),
            ArmRobot::Panda => (
                "panda_2",
                &[
                    "front_center",
                    "back_left",
                    "mid_right",
                    "high",
                    "front_left",
                ],
            ),
        }
    }
}

/// What the simulated data measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ArmData {
    /// Tip positions in an external instrument's frame (marker data).
    Positions,
    /// A ball in two sockets at unknown points (MUKCa-style).
    Sockets,
}

impl ArmData {
    /// Stable name (`positions`, `sockets`).
    pub fn name(self) -> &'static str {
        match self {
            ArmData::Positions => "positions",
            ArmData::Sockets => "sockets",
        }
    }

    /// The library effects drawn for these data. Instrument scale is never drawn: a uniform
    /// scale of the instrument is a uniform scale of every URDF joint origin, which the
    /// geometric baseline fits exactly (the diagnosis reports it "absorbed by the geometric
    /// parameters"), so it leaves no gap to diagnose. Link deflection (a function of the tip's
    /// reach) cannot vary at a socket, where the tip does not move: left out for sockets.
    pub fn library(self) -> Vec<Effect> {
        (ARM_LIBRARY.into_iter())
            .filter(|e| *e != Effect::InstrumentScale)
            .filter(|e| self == ArmData::Positions || *e != Effect::LinkDeflection)
            .collect()
    }
}

/// What a case holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ArmCaseKind {
    /// Geometry and noise only: the answer must be `none`.
    None,
    /// One library effect: the answer must name it.
    One,
    /// One effect outside the library: the answer must be `none`.
    Outside,
    /// Two library effects together: the answer must name both (in either order).
    Two,
}

impl ArmCaseKind {
    /// The class as the reports name it: `none`, `one`, `outside`, `two`.
    pub fn name(self) -> &'static str {
        match self {
            ArmCaseKind::None => "none",
            ArmCaseKind::One => "one",
            ArmCaseKind::Outside => "outside",
            ArmCaseKind::Two => "two",
        }
    }
}

/// An injected effect with its true parameters. Joint vectors have one entry per joint
/// (chain order).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Injected {
    /// Nothing.
    None,
    /// `Δq_j = k_j·τ_j(q)`, τ the published link masses' gravity torque (N·m), k rad/(N·m).
    GravityCompliance {
        /// Compliance per joint, rad/(N·m).
        k: Vec<f64>,
    },
    /// `Δq_j = k_j·τ̂_j(q)`, τ̂ the torque of a unit weight at the tip (m), k rad/m.
    LumpedCompliance {
        /// Compliance per joint, rad/m.
        k: Vec<f64>,
    },
    /// `Δq_j = a_j sin(h·q_j) + b_j cos(h·q_j)`, rad; `h` = 1, 2 (library) or 3 (outside).
    Harmonic {
        /// Order.
        h: u8,
        /// Sine amplitudes, rad.
        a: Vec<f64>,
        /// Cosine amplitudes, rad.
        b: Vec<f64>,
    },
    /// `Δq_j = −b_j·s_j`, `s_j` the sign of joint `j`'s last motion in its readings
    /// ([`hapcal_diagnose::arm::approach_signs`], the diagnosis's own definition): the output
    /// trails the motor by the half-play `b_j > 0`, so the diagnosis's parameter is `−b_j`.
    Backlash {
        /// Half-play per joint, rad.
        b: Vec<f64>,
    },
    /// `Δq_j = s_j·q_j`.
    GearRatio {
        /// Scale error per joint, 1.
        s: Vec<f64>,
    },
    /// `Δp = v·(t − t̄)/T` in the measurement frame (`T` the recording's span), m.
    ThermalDrift {
        /// Displacement over the recording, m.
        v: [f64; 3],
    },
    /// The tip sags by `c·(ρ/ρ_max)³` along gravity (base −z), ρ its horizontal reach, m.
    LinkDeflection {
        /// Sag at the largest reach, m.
        c: f64,
    },
    /// `Δp = s·p`, p the position in the instrument frame.
    InstrumentScale {
        /// Scale error, 1.
        s: f64,
    },
    /// Outside: `Δq_j = c·q_k` (a coupling between two joints).
    Coupling {
        /// Driven joint (0-based).
        j: usize,
        /// Driving joint (0-based).
        k: usize,
        /// Coupling, 1.
        c: f64,
    },
    /// Outside: `Δp_axis = d·u²`, `u = (p_axis − p̄_axis)/max|p_axis − p̄_axis|` over the
    /// rows, along one axis of the instrument frame (a quadratic distortion; centred so that
    /// it is not mostly a scale).
    QuadraticInstrument {
        /// Instrument axis (0–2).
        axis: usize,
        /// Displacement at the extreme, m.
        d: f64,
    },
    /// Outside: `Δp = v·(4((t − t̄)/T)² − 1/3)`, a drift quadratic in time, m.
    QuadraticDrift {
        /// Displacement at the ends, m.
        v: [f64; 3],
    },
    /// A transversal compliance of every revolute joint (the joint's placement tilts by
    /// `c_j·m⊥_j`, `m⊥` the gravity moment normal to its axis; the calibration's
    /// `transversal.<joint>`), under the loads of the joint compliance beside it, or of the
    /// link masses alone; used by the tree blind test ([`crate::tree_blind`]).
    TransversalCompliance {
        /// Compliance per joint (0 for a prismatic joint), rad/(N·m) (rad/m under lumped
        /// unit weights).
        c: Vec<f64>,
    },
    /// Two library effects at once (their joint-angle errors and displacements add).
    Pair(Box<Injected>, Box<Injected>),
}

/// Two effects of `pool` drawn with `rng`, never two joint compliances, injected in the order
/// of `pool` with the parameters `library_effect` draws for each.
pub(crate) fn draw_pair(
    rng: &mut ChaCha8Rng,
    pool: &[Effect],
    library_effect: impl Fn(&mut ChaCha8Rng, Effect) -> Injected,
) -> Injected {
    let a = pool[rng.random_range(0..pool.len())];
    let others: Vec<Effect> = (pool.iter().copied())
        .filter(|&b| b != a && !(a.is_joint_compliance() && b.is_joint_compliance()))
        .collect();
    let b = others[rng.random_range(0..others.len())];
    let position = |e: Effect| pool.iter().position(|&x| x == e);
    let (a, b) = if position(a) < position(b) {
        (a, b)
    } else {
        (b, a)
    };
    Injected::Pair(
        Box::new(library_effect(rng, a)),
        Box::new(library_effect(rng, b)),
    )
}

impl Injected {
    /// The right verdict of a case of `kind` that injects this: the injected library effects
    /// for [`ArmCaseKind::One`] and [`ArmCaseKind::Two`], else none.
    pub fn expected(&self, kind: ArmCaseKind) -> Verdict {
        match kind {
            ArmCaseKind::One | ArmCaseKind::Two => {
                let named: Vec<Effect> = (self.parts().iter()).filter_map(|p| p.effect()).collect();
                Verdict::of(&named)
            }
            _ => Verdict::None,
        }
    }

    /// The library effect this injects (one vocabulary with the diagnosis); `None` for no
    /// effect, an effect outside the library or a pair.
    pub fn effect(&self) -> Option<Effect> {
        match self {
            Injected::GravityCompliance { .. } => Some(Effect::GravityCompliance),
            Injected::LumpedCompliance { .. } => Some(Effect::LumpedCompliance),
            Injected::Harmonic { h: 1, .. } => Some(Effect::FirstHarmonic),
            Injected::Harmonic { h: 2, .. } => Some(Effect::SecondHarmonic),
            Injected::Backlash { .. } => Some(Effect::Backlash),
            Injected::GearRatio { .. } => Some(Effect::GearRatio),
            Injected::ThermalDrift { .. } => Some(Effect::ThermalDrift),
            Injected::LinkDeflection { .. } => Some(Effect::LinkDeflection),
            Injected::InstrumentScale { .. } => Some(Effect::InstrumentScale),
            Injected::TransversalCompliance { .. } => Some(Effect::TransversalCompliance),
            _ => None,
        }
    }

    /// Short label: a library effect's name (`gravity_compliance`), or `harmonic3`,
    /// `coupling`, …, `none`.
    pub fn label(&self) -> String {
        if let Some(e) = self.effect() {
            return e.name().into();
        }
        match self {
            Injected::None => "none".into(),
            Injected::Harmonic { h, .. } => format!("harmonic{h}"),
            Injected::Coupling { .. } => "coupling".into(),
            Injected::QuadraticInstrument { .. } => "quadratic_instrument".into(),
            Injected::QuadraticDrift { .. } => "quadratic_drift".into(),
            Injected::Pair(a, b) => format!("{}+{}", a.label(), b.label()),
            _ => unreachable!("a library effect is labelled by its name"),
        }
    }

    /// The injected effects one by one (both of a [`Injected::Pair`]).
    pub fn parts(&self) -> Vec<&Injected> {
        match self {
            Injected::Pair(a, b) => (a.parts().into_iter()).chain(b.parts()).collect(),
            other => vec![other],
        }
    }
}

/// One blind case.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArmCase {
    /// Seed of the draw and the simulation.
    pub seed: u64,
    /// Robot.
    pub robot: ArmRobot,
    /// Data kind.
    pub data: ArmData,
    /// Kind.
    pub kind: ArmCaseKind,
    /// The injected effect.
    pub injected: Injected,
}

impl ArmCase {
    /// The right verdict: the injected effect for [`ArmCaseKind::One`], both for
    /// [`ArmCaseKind::Two`], else none.
    pub fn expected(&self) -> Verdict {
        self.injected.expected(self.kind)
    }

    /// Whether `verdict` is right: the expected effects, in any order.
    pub fn is_right(&self, verdict: &Verdict) -> bool {
        self.is_right_with(verdict, &[])
    }

    /// Whether `verdict` is right when a named compliance whose torque model the diagnosis
    /// left open (`open`: the named compliance and the other torque model it predicts alike,
    /// [`hapcal_diagnose::arm::ArmStep::alike`]) also stands for that other model.
    pub fn is_right_with(&self, verdict: &Verdict, open: &[(Effect, Effect)]) -> bool {
        names_right(self.expected().effects(), verdict, open)
    }
}

/// Harmonic `h` of `n` joints, each at an amplitude (rad) drawn from `amp` and a random phase.
pub(crate) fn harmonic_draw(
    rng: &mut ChaCha8Rng,
    h: u8,
    n: usize,
    amp: std::ops::RangeInclusive<f64>,
) -> Injected {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..n {
        let amp = rng.random_range(amp.clone());
        let phase = rng.random_range(0.0..2.0 * PI);
        a.push(amp * phase.cos());
        b.push(amp * phase.sin());
    }
    Injected::Harmonic { h, a, b }
}

/// Whether `verdict` names exactly the effects `expected` (in any order), a named compliance
/// whose torque model the diagnosis left open (`open`: the named effect and the other model
/// it predicts alike) standing for either model.
pub(crate) fn names_right(
    expected: &[Effect],
    verdict: &Verdict,
    open: &[(Effect, Effect)],
) -> bool {
    let sorted = |v: &[Effect]| {
        let mut n = v.to_vec();
        n.sort();
        n
    };
    let expected = sorted(expected);
    let named = verdict.effects();
    sorted(named) == expected
        || open.iter().any(|&(named_model, alike)| {
            let swapped: Vec<Effect> = (named.iter())
                .map(|&e| if e == named_model { alike } else { e })
                .collect();
            expected.contains(&alike) && sorted(&swapped) == expected
        })
}

/// The kind of case `i`, stratified: of every 8, one clean, one outside, five single library
/// effects and one pair of library effects.
pub fn kind_of(i: u64) -> ArmCaseKind {
    match i % 8 {
        0 => ArmCaseKind::None,
        1 => ArmCaseKind::Outside,
        7 => ArmCaseKind::Two,
        _ => ArmCaseKind::One,
    }
}

/// Magnitude drawn uniformly in `[lo, hi]` with a random sign.
pub(crate) fn signed(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    let m = rng.random_range(lo..=hi);
    if rng.random_bool(0.5) { m } else { -m }
}

/// A vector of norm uniform in `[lo, hi]` in a uniformly random direction.
pub(crate) fn vector(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> [f64; 3] {
    let v =
        Vector3::from_fn(|_, _| StandardNormal.sample(rng)).normalize() * rng.random_range(lo..=hi);
    [v.x, v.y, v.z]
}

/// Draws case `i` (its seed): kind by [`kind_of`], robot and data kind stratified by
/// `i / 8` and `i / 16`, the library effect cycling through [`ArmData::library`] (a pair: two
/// distinct effects of it drawn at random, not both compliances, which are one physical
/// effect under two torque models), magnitudes
/// (sign random unless physical) uniform in: gravity compliance 1e-5–5e-5 rad/(N·m), lumped
/// compliance 2e-4–1e-3 rad/m, harmonics, backlash 0.2–1 mrad, gear ratio 1e-4–1e-3, drift
/// and deflection 0.2–1 mm, instrument scale 2e-4–1e-3; outside: coupling 3e-4–1e-3,
/// third harmonic 0.2–1 mrad, quadratic instrument and quadratic drift 0.2–1 mm.
pub fn draw_case(i: u64, n_joints: usize) -> ArmCase {
    let mut rng = ChaCha8Rng::seed_from_u64(0xA4B1_0000 + i);
    let kind = kind_of(i);
    let robot = ArmRobot::ALL[((i / 8) % 2) as usize];
    let data = if (i / 16).is_multiple_of(2) {
        ArmData::Positions
    } else {
        ArmData::Sockets
    };
    let per_joint = |rng: &mut ChaCha8Rng, lo: f64, hi: f64, sign: bool| -> Vec<f64> {
        (0..n_joints)
            .map(|_| {
                if sign {
                    signed(rng, lo, hi)
                } else {
                    rng.random_range(lo..=hi)
                }
            })
            .collect()
    };
    let harmonic = |rng: &mut ChaCha8Rng, h: u8| harmonic_draw(rng, h, n_joints, 2e-4..=1e-3);
    let library_effect = |rng: &mut ChaCha8Rng, effect: Effect| -> Injected {
        match effect {
            Effect::GravityCompliance => Injected::GravityCompliance {
                k: per_joint(rng, 1e-5, 5e-5, false),
            },
            Effect::LumpedCompliance => Injected::LumpedCompliance {
                k: per_joint(rng, 2e-4, 1e-3, false),
            },
            Effect::FirstHarmonic => harmonic(rng, 1),
            Effect::SecondHarmonic => harmonic(rng, 2),
            Effect::Backlash => Injected::Backlash {
                b: per_joint(rng, 2e-4, 1e-3, false),
            },
            Effect::GearRatio => Injected::GearRatio {
                s: per_joint(rng, 1e-4, 1e-3, true),
            },
            Effect::ThermalDrift => Injected::ThermalDrift {
                v: vector(rng, 2e-4, 1e-3),
            },
            Effect::LinkDeflection => Injected::LinkDeflection {
                c: rng.random_range(2e-4..=1e-3),
            },
            Effect::InstrumentScale => Injected::InstrumentScale {
                s: signed(rng, 2e-4, 1e-3),
            },
            other => unreachable!("{other} is not in the arm library"),
        }
    };
    let lib = data.library();
    let injected = match kind {
        ArmCaseKind::None => Injected::None,
        ArmCaseKind::One => {
            let slot = (i / 8) * 5 + (i % 8 - 2);
            library_effect(&mut rng, lib[(slot % lib.len() as u64) as usize])
        }
        ArmCaseKind::Two => draw_pair(&mut rng, &lib, library_effect),
        ArmCaseKind::Outside => {
            let n_kinds = if data == ArmData::Positions { 4 } else { 3 };
            match (i / 8) % n_kinds {
                0 => {
                    let j = rng.random_range(0..n_joints);
                    let k = (j + rng.random_range(1..n_joints)) % n_joints;
                    Injected::Coupling {
                        j,
                        k,
                        c: signed(&mut rng, 3e-4, 1e-3),
                    }
                }
                1 => harmonic(&mut rng, 3),
                2 => Injected::QuadraticDrift {
                    v: vector(&mut rng, 2e-4, 1e-3),
                },
                _ => Injected::QuadraticInstrument {
                    axis: rng.random_range(0..3),
                    d: signed(&mut rng, 2e-4, 1e-3),
                },
            }
        }
    };
    ArmCase {
        seed: i,
        robot,
        data,
        kind,
        injected,
    }
}

/// A loaded robot: what the calibration reads of its URDF, and the recorded socket
/// placements of its MUKCa unit.
#[derive(Clone, Debug)]
pub struct ArmSetup {
    /// Which.
    pub which: ArmRobot,
    /// The robot of [`robot_from_urdf`] (tip `ball_link`).
    pub robot: Robot,
    /// The calibration chain of the URDF device ([`load_device`]), for socket data.
    pub chain: Chain,
    /// Gravity-torque model: the URDF's link masses, else the published ones.
    pub gravity: Option<GravityCompliance>,
    /// Recorded MUKCa placements (rad), in [`ArmRobot`]'s placement order.
    pub placements: Vec<SocketPlacement>,
}

/// Loads `which` from fixtures/mukca.
///
/// # Errors
/// Unreadable URDF or socket files.
pub fn load_setup(which: ArmRobot) -> Result<ArmSetup> {
    let urdf = which.urdf();
    let robot = robot_from_urdf(&urdf, &["ball_link".to_owned()])?;
    let chain = load_device(&urdf, "ball_link")?
        .chain()
        .with_context(|| format!("building the chain of {}", urdf.display()))?;
    let gravity = if robot.masses.is_empty() {
        GravityCompliance::published(&robot.joint_names)
    } else {
        Some(GravityCompliance::from_link_masses(
            robot.masses.clone(),
            -Vector3::z(),
        ))
    };
    let (unit, names) = which.placements();
    let root = crate::project_root().join("fixtures/mukca/data").join(unit);
    let paths: Vec<PathBuf> = names.iter().map(|n| root.join(n)).collect();
    let placements = hapcal_io::read_mukca_paths(&paths, robot.joint_names.len())
        .with_context(|| format!("reading the placements of {}", root.display()))?;
    Ok(ArmSetup {
        which,
        robot,
        chain,
        gravity,
        placements,
    })
}

/// The result of one case of a blind test of the arm diagnosis: `C` the case (an
/// [`ArmCase`], a [`crate::tree_blind::TreeCase`]), `S` what the study records beside the
/// diagnosis's figures ([`ArmRecord`], [`crate::tree_blind::TreeRecord`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BlindOutcome<C, S> {
    /// The case.
    pub case: C,
    /// The diagnosis's verdict, or the error that stopped the pipeline (serialised as the
    /// report writes it: `gravity_compliance+backlash`, `none`, `error: …`).
    #[serde(serialize_with = "verdict_or_error")]
    pub verdict: Result<Verdict, String>,
    /// Whether it names the injected effects (a compliance whose torque model the diagnosis
    /// left open stands for either model; [`ArmCase::is_right_with`]).
    pub right: bool,
    /// Whether it equals the case's expected verdict as written (an open torque model counted
    /// as the one the verdict names).
    pub right_as_written: bool,
    /// Each named compliance whose torque model the diagnosis left open, with the other
    /// model.
    pub torque_model_open: Vec<(Effect, Effect)>,
    /// Share of the gap above the floor the named effects closed, %.
    pub gap_closed_pct: f64,
    /// Held-out (cross-validated) 3-D position RMS of the geometric baseline, m.
    pub heldout_rms_m: f64,
    /// Its floor, m.
    pub floor_rms_m: f64,
    /// What the study records beside (serialised as fields of the outcome).
    #[serde(flatten)]
    pub study: S,
    /// Wall time of the case, s.
    pub seconds: f64,
}

impl<C, S> BlindOutcome<C, S> {
    /// The outcome of `case`, whose right verdict names the effects `expected`, from its
    /// diagnosis `d`, begun at `start`; `study` what the study records beside.
    pub(crate) fn of(
        case: C,
        expected: &[Effect],
        d: ArmDiagnosis,
        study: S,
        start: std::time::Instant,
    ) -> Self {
        let open = open_torque_models(&d);
        BlindOutcome {
            case,
            right: names_right(expected, &d.verdict, &open),
            right_as_written: names_right(expected, &d.verdict, &[]),
            torque_model_open: open,
            verdict: Ok(d.verdict),
            gap_closed_pct: d.gap_closed_pct,
            heldout_rms_m: d.heldout_rms_m,
            floor_rms_m: d.floor_rms_m.unwrap_or(f64::NAN),
            study,
            seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// The outcome of `case` whose pipeline stopped with `error` (an `error: …` verdict, no
    /// figures); `study` what the study records beside.
    pub(crate) fn failed(case: C, error: &anyhow::Error, study: S) -> Self {
        BlindOutcome {
            case,
            verdict: Err(format!("{error:#}")),
            right: false,
            right_as_written: false,
            torque_model_open: Vec::new(),
            gap_closed_pct: f64::NAN,
            heldout_rms_m: f64::NAN,
            floor_rms_m: f64::NAN,
            study,
            seconds: 0.0,
        }
    }
}

/// What the arm study records of a case beside the diagnosis's figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ArmRecord {
    /// Whether the gap above the floor was significant.
    pub gap_significant: bool,
    /// Per library effect, the round-1 candidate's held-out RMS after, m, and its reason.
    pub round1: Vec<(Effect, f64, String)>,
}

/// The result of one case of the arm study.
pub type ArmOutcome = BlindOutcome<ArmCase, ArmRecord>;

/// Simulates, calibrates and diagnoses `case` (`n_rows` positions configurations) with
/// [`ArmConfig::default`].
///
/// # Errors
/// A failed load, calibration or diagnosis.
pub fn run_case(case: &ArmCase, setup: &ArmSetup, n_rows: usize) -> Result<ArmOutcome> {
    run_case_with(case, setup, n_rows, &ArmConfig::default())
}

/// [`run_case`] with other diagnosis settings (sensitivity runs; the blind test's figures use
/// the defaults).
///
/// # Errors
/// A failed load, calibration or diagnosis.
pub fn run_case_with(
    case: &ArmCase,
    setup: &ArmSetup,
    n_rows: usize,
    cfg: &ArmConfig,
) -> Result<ArmOutcome> {
    let start = std::time::Instant::now();
    let baseline = simulate_baseline(case, setup, n_rows)?;
    let d = diagnose_arm(&baseline, cfg)?;
    let record = ArmRecord {
        gap_significant: d.gap_significant,
        round1: (d.candidates.iter())
            .filter(|c| c.round == 1)
            .map(|c| (c.effect, c.heldout_rms_after_m, c.reason.clone()))
            .collect(),
    };
    let expected = case.expected();
    Ok(ArmOutcome::of(
        case.clone(),
        expected.effects(),
        d,
        record,
        start,
    ))
}

/// Each named compliance of `d`'s verdict whose torque model the diagnosis left open, with
/// the other model ([`hapcal_diagnose::arm::ArmStep::alike`]).
pub(crate) fn open_torque_models(d: &ArmDiagnosis) -> Vec<(Effect, Effect)> {
    (d.steps.iter())
        .filter(|s| d.verdict.effects().contains(&s.effect))
        .flat_map(|s| s.alike.iter().map(|&a| (s.effect, a)))
        .collect()
}

/// Simulates `case` (`n_rows` positions configurations) and fits its geometric baseline, the
/// input of the diagnosis, with the noise σ stated.
///
/// # Errors
/// A failed calibration.
pub fn simulate_baseline(
    case: &ArmCase,
    setup: &ArmSetup,
    n_rows: usize,
) -> Result<GeometricBaseline> {
    let mut rng = simulation_rng(case);
    let mut plan = Plan::bundled_default();
    plan.device = case.robot.urdf();
    plan.data = Vec::new();
    plan.test = Vec::new();
    plan.model = ModelName::Geometric.into();
    plan.socket_distance_m = SOCKET_DISTANCE_M;
    Ok(match case.data {
        ArmData::Positions => {
            let table = simulate_positions(case, setup, n_rows, &mut rng);
            plan.sigma_m = Some(SIGMA_POSITION_M);
            plan.test_last = Some(TEST_FRACTION);
            baseline_from_tables(&setup.robot, vec![table], Vec::new(), &plan, false)?
        }
        ArmData::Sockets => {
            let (train, test) = simulate_sockets(case, setup, &mut rng);
            plan.sigma_m = Some(SIGMA_SEATING_M);
            baseline_from_sets(
                &setup.robot,
                &setup.chain,
                &[DataSet::Sockets(train)],
                &[DataSet::Sockets(test)],
                &plan,
                false,
            )?
        }
    })
}

/// The random stream of `case`'s simulation (geometry, configurations, instrument, noise).
fn simulation_rng(case: &ArmCase) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(0x51B0_0000 + case.seed)
}

/// The measurement table [`simulate_baseline`] calibrates for a positions case (`n_rows`
/// rows, all of them: the held-out last [`TEST_FRACTION`] is in the same file); `None` for a
/// sockets case (MUKCa socket folders are not measurement files).
pub fn simulate_positions_table(
    case: &ArmCase,
    setup: &ArmSetup,
    n_rows: usize,
) -> Option<MeasurementTable> {
    (case.data == ArmData::Positions)
        .then(|| simulate_positions(case, setup, n_rows, &mut simulation_rng(case)))
}

/// The setup check ([`hapcal_calibrate::setup::check_setup`]) of a positions case's table
/// ([`simulate_positions_table`]) on the robot's URDF, tip `ball_link`, SI units, as `hapcal
/// check` runs it on the written file; `None` for a sockets case.
///
/// # Errors
/// A failed frames-only fit of the data as given.
pub fn setup_check_case(
    case: &ArmCase,
    setup: &ArmSetup,
    n_rows: usize,
) -> Result<Option<SetupReport>> {
    let Some(table) = simulate_positions_table(case, setup, n_rows) else {
        return Ok(None);
    };
    let urdf = case.robot.urdf();
    check_setup(&SetupInput {
        robot: &setup.robot,
        tables: std::slice::from_ref(&table),
        urdf: Some(&urdf),
        tips: &["ball_link".to_owned()],
        units: Units::default(),
    })
    .map(Some)
}

/// The setup check over simulated positions cases ([`setup_sweep`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SetupSweep {
    /// Per case: the case, the largest gain of any hypothesis (`None`: no hypothesis read),
    /// its class, and the findings as `severity [class]: text` lines (`error: …` when the
    /// check failed).
    pub cases: Vec<(ArmCase, Option<f64>, String, Vec<String>)>,
}

impl SetupSweep {
    /// Cases with a finding of severity error (or a check that failed).
    pub fn n_errors(&self) -> usize {
        (self.cases.iter())
            .filter(|c| c.3.iter().any(|f| f.starts_with("error")))
            .count()
    }

    /// Cases with warnings only.
    pub fn n_warnings(&self) -> usize {
        (self.cases.iter())
            .filter(|c| !c.3.is_empty() && !c.3.iter().any(|f| f.starts_with("error")))
            .count()
    }

    /// The largest gain of any hypothesis over every case, with its case's label and class.
    pub fn largest_gain(&self) -> Option<(f64, String, String)> {
        (self.cases.iter())
            .filter_map(|(case, g, class, _)| {
                Some((
                    (*g)?,
                    format!(
                        "{} {} seed {}",
                        case.robot.name(),
                        case.injected.label(),
                        case.seed
                    ),
                    class.clone(),
                ))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
    }

    /// Plain text: one line per case with a finding, then the counts and the largest gain.
    pub fn text(&self) -> String {
        let mut out = String::new();
        for (case, _, _, findings) in &self.cases {
            for f in findings {
                out.push_str(&format!(
                    "{} {} seed {}: {f}\n",
                    case.robot.name(),
                    case.injected.label(),
                    case.seed
                ));
            }
        }
        out.push_str(&format!(
            "{} positions cases: {} with an error, {} with warnings only, {} silent\n",
            self.cases.len(),
            self.n_errors(),
            self.n_warnings(),
            self.cases.len() - self.n_errors() - self.n_warnings()
        ));
        if let Some((g, label, class)) = self.largest_gain() {
            out.push_str(&format!(
                "largest gain of any hypothesis: {g:.3} ({class}, {label})\n"
            ));
        }
        out
    }
}

/// The positions cases of the setup sweep: those of `0..n_cases` ([`draw_case`]) and, since
/// the draw gives positions data only the coupling and the third harmonic of the outside
/// effects, a quadratic instrument and a quadratic drift of 1 mm per robot (seeds from
/// `n_cases` on).
pub fn setup_sweep_cases(n_cases: u64, setups: &[ArmSetup]) -> Vec<ArmCase> {
    let n_joints = |robot: ArmRobot| {
        (setups.iter())
            .find(|s| s.which == robot)
            .map_or(7, |s| s.robot.joint_names.len())
    };
    let drawn = (0..n_cases)
        .map(|i| draw_case(i, n_joints(ArmRobot::ALL[((i / 8) % 2) as usize])))
        .filter(|c| c.data == ArmData::Positions);
    let outside = (ArmRobot::ALL.iter().enumerate()).flat_map(|(r, &robot)| {
        [
            Injected::QuadraticInstrument { axis: r, d: 1e-3 },
            Injected::QuadraticDrift {
                v: [6e-4, -6e-4, 5e-4],
            },
        ]
        .into_iter()
        .enumerate()
        .map(move |(k, injected)| ArmCase {
            seed: n_cases + 2 * r as u64 + k as u64,
            robot,
            data: ArmData::Positions,
            kind: ArmCaseKind::Outside,
            injected,
        })
    });
    drawn.chain(outside).collect()
}

/// Runs the setup check ([`setup_check_case`]) on every case of [`setup_sweep_cases`] with
/// `n_rows` rows, in parallel (rayon).
///
/// # Errors
/// A robot that cannot be loaded (a failed check is a finding line `error: …`).
pub fn setup_sweep(n_cases: u64, n_rows: usize) -> Result<SetupSweep> {
    use rayon::prelude::*;
    let setups = (ArmRobot::ALL.iter())
        .map(|&r| load_setup(r))
        .collect::<Result<Vec<_>>>()?;
    let cases = setup_sweep_cases(n_cases, &setups);
    let cases = cases
        .into_par_iter()
        .map(|case| {
            let setup = &setups[case.robot as usize];
            match setup_check_case(&case, setup, n_rows) {
                Ok(Some(report)) => {
                    let (gain, class) = report
                        .closest
                        .as_ref()
                        .map_or((None, String::new()), |c| (c.gain, c.class.to_string()));
                    let findings = (report.findings.iter())
                        .map(|f| {
                            let severity = match f.severity {
                                Severity::Error => "error",
                                Severity::Warning => "warning",
                            };
                            format!("{severity} [{}]: {}", f.class, f.text())
                        })
                        .collect();
                    (case, gain, class, findings)
                }
                Ok(None) => (case, None, String::new(), Vec::new()),
                Err(e) => (case, None, String::new(), vec![format!("error: {e:#}")]),
            }
        })
        .collect();
    Ok(SetupSweep { cases })
}

/// Runs cases `0..n_cases` in parallel (rayon) with diagnosis settings `cfg`; `progress` is
/// called after each case with the number done.
///
/// # Errors
/// A robot that cannot be loaded (a failed case is an outcome with an `error: …` verdict).
pub fn run(
    n_cases: u64,
    n_rows: usize,
    cfg: &ArmConfig,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<ArmOutcome>> {
    let setups = (ArmRobot::ALL.iter())
        .map(|&r| load_setup(r))
        .collect::<Result<Vec<_>>>()?;
    Ok(crate::par_map_counted(0..n_cases, progress, |i| {
        let robot = ArmRobot::ALL[((i / 8) % 2) as usize];
        let setup = &setups[robot as usize];
        let case = draw_case(i, setup.robot.joint_names.len());
        run_case_with(&case, setup, n_rows, cfg)
            .unwrap_or_else(|e| ArmOutcome::failed(case, &e, ArmRecord::default()))
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_are_stratified_and_applicable() {
        for i in 0..64 {
            let c = draw_case(i, 7);
            assert_eq!(c.kind, kind_of(i));
            if matches!(c.kind, ArmCaseKind::One | ArmCaseKind::Two) {
                let parts = c.injected.parts();
                assert_eq!(parts.len(), if c.kind == ArmCaseKind::Two { 2 } else { 1 });
                for p in parts {
                    let e = Effect::from_name(&p.label()).expect("a library effect");
                    assert!(c.data.library().contains(&e), "{c:?}");
                }
                assert!(c.is_right(&c.expected()));
            } else {
                assert!(Effect::from_name(&c.injected.label()).is_none());
            }
        }
    }
}
