//! The hostile sweep of setup mistakes: recordings (the bundled real and simulated ones, and
//! positions files of the arm blind test's simulated iiwa 14 and Panda) with one ordinary
//! setup mistake each, written as a user would hand them to `hapcal calibrate`, and what the
//! setup check should answer. Written without the check's code: a case is judged only by the
//! command's exit code and its standard error ([`judge`]).
//!
//! **Mistakes** ([`FAMILIES`], the table of expectations): one joint column in degrees,
//! gradians or revolutions; every angle in degrees; lengths in mm, cm, inches or feet; one
//! marker of several in mm; one encoder's sign reversed; one joint's zero off by ±90° or
//! 180°; joint columns swapped or reversed, the arms' columns exchanged; rows out of step
//! (whole file, or from a row on) or partly decoupled; quaternions in the wrong order or
//! conjugated; Euler angles in the wrong order; a mirrored or exchanged instrument axis; the
//! tips exchanged or one joint off; another robot's data; the socket distance wrong or rows
//! filed under the wrong socket; a haptic log with a real latency (a note, not a stop).
//! **Correct data** ([`Family::is_correct`]): the recordings as they are, their rows
//! re-ordered or sub-sampled, simulated arms with library effects, simulated haptic logs with
//! effects: any setup finding on them is a false alarm.
//!
//! **Split.** Each case belongs to one half ([`Half`]) by a hash of its identity (family,
//! recording, parameters), so the two halves do not change when cases are added.
//!
//! **Visibility.** A mistake may leave no trace in the data (the zero of a positioner's joint
//! absorbed by the fitted frames). Each mistake is screened without the check's code: the
//! least model's fit ([`screening_model`], [`screening_args`]) of the mistaken data and of its
//! [`correct_twin`] (the same rows and simulation seed, no mistake); the mistake is invisible
//! when the ratio of their training residuals ([`residual_ratio`]) is below
//! [`INVISIBLE_RATIO`] ([`Visibility`]).
//!
//! Sources of the recordings: fixtures/figaroh (UR10, TIAGo; Apache-2.0), fixtures/sim-humanoid,
//! fixtures/industrial-calibration (Apache-2.0), fixtures/mukca (MIT, TU Delft),
//! fixtures/reference-device.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use hapcal_calibrate::measured::robot_from_urdf;
use hapcal_contract::{Effect, ModelName};
use nalgebra::{Rotation3, UnitQuaternion};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::arm_blind::{self, ArmCase, ArmCaseKind, ArmData, ArmRobot, Injected};

/// Rows of a simulated arm's positions file (the blind test's walk, fewer rows for speed).
pub const SIM_ROWS: usize = 120;

/// Distance between the two MUKCa sockets, m (fixtures/mukca/README.md).
pub const SOCKET_DISTANCE_M: f64 = 0.05;

/// How many times one mistake on one recording is drawn (parts 0, 1, 2, 3).
pub const MAX_PARTS: u32 = 4;

/// Default number of cases per mistake family (a few hundred cases in all).
pub const DEFAULT_CASES_PER_FAMILY: usize = 16;

/// A recording a case starts from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Recording {
    /// figaroh's UR10: camera poses of a checkerboard, Euler angles (fixtures/figaroh/ur10).
    Ur10,
    /// The same rows with the orientation written as a quaternion (`qw1,qx1,qy1,qz1`).
    Ur10Quaternion,
    /// figaroh's TIAGo: four motion-capture markers on the hand, a prismatic torso.
    Tiago,
    /// The simulated two-arm humanoid, a marker on each hand (fixtures/sim-humanoid).
    Humanoid,
    /// industrial_calibration's two-axis positioner, 6-D poses with quaternions.
    Positioner,
    /// The positioner's poses written with figaroh's Euler angles (`phix,phiy,phiz`).
    PositionerEuler,
    /// A MUKCa socket folder: the iiwa 14's `front` placement.
    SocketsIiwa,
    /// A MUKCa socket folder: the Panda unit 2's `front_center` placement.
    SocketsPanda,
    /// The reference haptic device's log (fixtures/reference-device/log.csv).
    Haptic,
    /// A haptic log simulated by `hapcal simulate` along a time-ordered motion at 20 Hz.
    HapticMotion,
    /// Positions of the arm blind test's simulated iiwa 14 (tip `ball_link`).
    SimIiwa,
    /// Positions of the arm blind test's simulated Panda (tip `ball_link`).
    SimPanda,
}

impl Recording {
    /// Every recording.
    pub const ALL: [Recording; 12] = [
        Recording::Ur10,
        Recording::Ur10Quaternion,
        Recording::Tiago,
        Recording::Humanoid,
        Recording::Positioner,
        Recording::PositionerEuler,
        Recording::SocketsIiwa,
        Recording::SocketsPanda,
        Recording::Haptic,
        Recording::HapticMotion,
        Recording::SimIiwa,
        Recording::SimPanda,
    ];

    /// Short name, used in case identities.
    pub fn name(self) -> &'static str {
        match self {
            Recording::Ur10 => "ur10",
            Recording::Ur10Quaternion => "ur10-quat",
            Recording::Tiago => "tiago",
            Recording::Humanoid => "humanoid",
            Recording::Positioner => "positioner",
            Recording::PositionerEuler => "positioner-euler",
            Recording::SocketsIiwa => "sockets-iiwa14",
            Recording::SocketsPanda => "sockets-panda2",
            Recording::Haptic => "haptic",
            Recording::HapticMotion => "haptic-20hz",
            Recording::SimIiwa => "sim-iiwa14",
            Recording::SimPanda => "sim-panda",
        }
    }

    /// The device file, relative to the project root.
    fn device(self) -> &'static str {
        match self {
            Recording::Ur10 | Recording::Ur10Quaternion => "fixtures/figaroh/ur10/ur10_robot.urdf",
            Recording::Tiago => "fixtures/figaroh/tiago/tiago.urdf",
            Recording::Humanoid => "fixtures/sim-humanoid/humanoid.urdf",
            Recording::Positioner | Recording::PositionerEuler => {
                "fixtures/industrial-calibration/two_axis_positioner.toml"
            }
            Recording::SocketsIiwa | Recording::SimIiwa => "fixtures/mukca/urdf/iiwa14.urdf",
            Recording::SocketsPanda | Recording::SimPanda => "fixtures/mukca/urdf/panda.urdf",
            Recording::Haptic | Recording::HapticMotion => "fixtures/reference-device/device.toml",
        }
    }

    /// The tip links (`--tip`, in order); empty for a device file without a URDF.
    fn tips(self) -> &'static [&'static str] {
        match self {
            Recording::Ur10 | Recording::Ur10Quaternion => &["wrist_3_link"],
            Recording::Tiago => &["arm_7_link"],
            Recording::Humanoid => &["l_hand", "r_hand"],
            Recording::SocketsIiwa
            | Recording::SocketsPanda
            | Recording::SimIiwa
            | Recording::SimPanda => &["ball_link"],
            _ => &[],
        }
    }

    /// The tip one moving joint up from the first tip, if any.
    fn tip_up(self) -> Option<&'static str> {
        match self {
            Recording::Ur10 | Recording::Ur10Quaternion => Some("wrist_2_link"),
            Recording::Tiago => Some("arm_6_link"),
            Recording::Humanoid => Some("l_link6"),
            Recording::SimIiwa | Recording::SocketsIiwa => Some("link_6"),
            Recording::SimPanda | Recording::SocketsPanda => Some("panda_link6"),
            _ => None,
        }
    }

    /// The first tip and the links fixed to the same moving link (any of them names the
    /// tip the markers sit on).
    fn tip_aliases(self) -> &'static [&'static str] {
        match self {
            Recording::Ur10 | Recording::Ur10Quaternion => {
                &["wrist_3_link", "flange", "tool0", "ee_link"]
            }
            Recording::Tiago => &["arm_7_link", "arm_tool_link"],
            Recording::Humanoid => &["l_hand", "l_link7"],
            Recording::SocketsIiwa | Recording::SimIiwa => &["ball_link", "link_7", "tool0"],
            Recording::SocketsPanda | Recording::SimPanda => &[
                "ball_link",
                "panda_link7",
                "panda_link8",
                "panda_hand",
                "panda_hand_tcp",
            ],
            _ => &[],
        }
    }

    /// The revolute joint columns (prismatic ones left out), in chain order.
    fn revolute(self, table: &Table) -> Vec<String> {
        let skip = |h: &str| {
            h == "torso_lift_joint"
                || h == "t_s"
                || h == "distance_m"
                || h.starts_with("ext")
                || is_position(h)
                || is_orientation(h)
        };
        table.header.iter().filter(|h| !skip(h)).cloned().collect()
    }

    /// Whether the recording is a haptic device's log.
    fn is_haptic(self) -> bool {
        matches!(self, Recording::Haptic | Recording::HapticMotion)
    }

    /// Whether the recording is a simulated arm.
    fn sim_arm(self) -> Option<ArmRobot> {
        match self {
            Recording::SimIiwa => Some(ArmRobot::Iiwa14),
            Recording::SimPanda => Some(ArmRobot::Panda),
            _ => None,
        }
    }
}

/// A position column: `x`, `y`, `z`, optionally numbered (`x2`).
fn is_position(h: &str) -> bool {
    let mut c = h.chars();
    matches!(c.next(), Some('x' | 'y' | 'z')) && c.all(|c| c.is_ascii_digit())
}

/// An orientation column: `phix1`, `qw`, `qx2`, ….
fn is_orientation(h: &str) -> bool {
    let rest = |p: &str| {
        h.strip_prefix(p)
            .is_some_and(|r| r.chars().all(|c| c.is_ascii_digit()))
    };
    ["phix", "phiy", "phiz", "qw", "qx", "qy", "qz"]
        .iter()
        .any(|p| rest(p))
}

/// A mistake family or a kind of correct data: one row of [`FAMILIES`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Family {
    /// One joint column in degrees, gradians or revolutions, read as rad.
    ColumnUnit,
    /// Every angle in degrees.
    AngleUnit,
    /// Positions (and distances) in mm, cm, inches or feet.
    LengthUnit,
    /// One marker of several in mm.
    MarkerUnit,
    /// One joint's encoder sign reversed.
    ColumnSign,
    /// One joint's zero off by +90°, −90° or 180°.
    ColumnZero,
    /// Two joint columns swapped, all reversed, or the arms' columns exchanged.
    JointOrder,
    /// Joint rows out of step with the measurements by k rows, or from a row on.
    RowShift,
    /// 10–30 % of the rows with joints and measurements decoupled.
    RowMismatch,
    /// Quaternions written x, y, z, w under `qw,qx,qy,qz`.
    QuaternionOrder,
    /// Quaternions conjugated (the inverse rotation).
    QuaternionInverse,
    /// Euler angles of R = Rx·Ry·Rz written where R = Rz·Ry·Rx is read.
    EulerOrder,
    /// One instrument axis mirrored, or two exchanged.
    MirroredAxis,
    /// The humanoid's tips given in the other order.
    SwappedTips,
    /// The tip link one moving joint up or down.
    TipLink,
    /// Another robot's data, or data of a robot with longer links.
    AnotherDevice,
    /// `--socket-distance-m` a tenth, ten times, or in mm.
    SocketDistance,
    /// A tenth of one socket's rows filed under the other.
    WrongSocket,
    /// A haptic log with a real latency of 45 ms at 20 Hz: a note or warning, not a stop.
    Latency,
    /// Correct: a recording as it is.
    AsIs,
    /// Correct: rows re-ordered or sub-sampled.
    Resampled,
    /// Correct: a simulated arm with library effects (the arm blind test's draws).
    SimEffects,
    /// Correct: a simulated haptic log with an effect or a small latency.
    HapticEffects,
    /// One set of frames before a row and another after it: the tracker moved, a marker or
    /// tool re-mounted, a capstan re-tensioned (a joint's zero jumps).
    ChangePoint,
    /// One joint column scaled: encoder counts, a motor-side reading, a gear-ratio error.
    ColumnScale,
    /// One joint column's reading depends on another joint's (q_j + c·q_k).
    ColumnCoupling,
    /// The last rows' positions in millimetres, the rest in metres.
    PartUnit,
    /// One joint reading of one row off by a glitch (0.2 rad).
    GlitchRow,
    /// Another variant of the robot: the same joint names, other link lengths.
    WrongVariant,
    /// The robot mounted upside down (its description turned by π about x).
    Mounting,
}

/// What the check should answer to a family.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Expect {
    /// Stop (exit 2) naming this setup class, with this flag in the fix (if any).
    Stop(&'static str, Option<&'static str>),
    /// Run (exit 0 or 1) with a finding of this class (a note or a warning), never a stop.
    Note(&'static str),
    /// Correct data: no setup finding at all.
    Clean,
    /// Run (exit 0 or 1) naming the row (file:line) the fit left out or bounded: one gross
    /// error must not stop a calibration nor move it.
    Listed,
}

/// One row of the table of expectations.
#[derive(Clone, Copy, Debug)]
pub struct FamilySpec {
    /// The family.
    pub family: Family,
    /// Its name in case identities and the report.
    pub name: &'static str,
    /// What the check should answer.
    pub expect: Expect,
    /// The recordings it applies to.
    pub recordings: &'static [Recording],
}

/// The class name of a latency finding (spelled by the effect vocabulary, whose word it is).
pub const LATENCY_CLASS: &str = Effect::Latency.name();

use Recording as R;

/// Arms with joint columns (every recording but the haptic logs' special families).
const JOINTED: &[Recording] = &[
    R::Ur10,
    R::Tiago,
    R::Humanoid,
    R::Positioner,
    R::SocketsIiwa,
    R::SocketsPanda,
    R::SimIiwa,
    R::SimPanda,
    R::Haptic,
];

/// The arms with markers (the camera, motion-capture and simulated recordings) and the haptic
/// log.
const MARKERS_AND_HAPTIC: &[Recording] = &[
    R::Ur10,
    R::Tiago,
    R::Humanoid,
    R::Positioner,
    R::SimIiwa,
    R::SimPanda,
    R::Haptic,
];

/// The arms with markers (the camera, motion-capture and simulated recordings).
const MARKERS: &[Recording] = &[
    R::Ur10,
    R::Tiago,
    R::Humanoid,
    R::Positioner,
    R::SimIiwa,
    R::SimPanda,
];

/// The recordings with orientation quaternions.
const QUATERNIONS: &[Recording] = &[R::Positioner, R::Ur10Quaternion];

/// The socket recordings.
const SOCKETS: &[Recording] = &[R::SocketsIiwa, R::SocketsPanda];

/// A row of [`FAMILIES`].
const fn spec(
    family: Family,
    name: &'static str,
    expect: Expect,
    recordings: &'static [Recording],
) -> FamilySpec {
    FamilySpec {
        family,
        name,
        expect,
        recordings,
    }
}

/// A row of [`FAMILIES`] whose family must stop naming its own class, with `flag` in the fix.
const fn stop(
    family: Family,
    name: &'static str,
    flag: Option<&'static str>,
    recordings: &'static [Recording],
) -> FamilySpec {
    spec(family, name, Expect::Stop(name, flag), recordings)
}

/// The table of expectations: each family, what the check should say, and where it applies.
pub const FAMILIES: &[FamilySpec] = &[
    stop(
        Family::ColumnUnit,
        "column-unit",
        Some("--column-unit"),
        JOINTED,
    ),
    stop(
        Family::AngleUnit,
        "angle-unit",
        Some("--angle-unit"),
        &[
            R::Ur10,
            R::Tiago,
            R::Humanoid,
            R::Positioner,
            R::SocketsIiwa,
            R::SocketsPanda,
            R::SimIiwa,
            R::SimPanda,
        ],
    ),
    stop(
        Family::LengthUnit,
        "length-unit",
        Some("--length-unit"),
        MARKERS_AND_HAPTIC,
    ),
    spec(
        Family::MarkerUnit,
        "marker-unit",
        Expect::Stop("length-unit", Some("--column-unit")),
        &[R::Tiago, R::Humanoid],
    ),
    stop(
        Family::ColumnSign,
        "column-sign",
        Some("--column-sign"),
        JOINTED,
    ),
    stop(
        Family::ColumnZero,
        "column-zero",
        Some("--column-offset"),
        JOINTED,
    ),
    stop(
        Family::JointOrder,
        "joint-order",
        None,
        &[
            R::Ur10,
            R::Tiago,
            R::Humanoid,
            R::Positioner,
            R::SocketsIiwa,
            R::SimIiwa,
            R::SimPanda,
        ],
    ),
    stop(Family::RowShift, "row-shift", None, MARKERS_AND_HAPTIC),
    stop(
        Family::RowMismatch,
        "row-mismatch",
        None,
        MARKERS_AND_HAPTIC,
    ),
    stop(
        Family::QuaternionOrder,
        "quaternion-order",
        None,
        QUATERNIONS,
    ),
    stop(
        Family::QuaternionInverse,
        "quaternion-inverse",
        None,
        QUATERNIONS,
    ),
    stop(
        Family::EulerOrder,
        "euler-order",
        None,
        &[R::Ur10, R::PositionerEuler],
    ),
    stop(Family::MirroredAxis, "mirrored-axis", None, MARKERS),
    stop(Family::SwappedTips, "swapped-tips", None, &[R::Humanoid]),
    stop(
        Family::TipLink,
        "tip-link",
        Some("--tip"),
        &[
            R::Ur10,
            R::Tiago,
            R::Humanoid,
            R::SocketsIiwa,
            R::SimIiwa,
            R::SimPanda,
        ],
    ),
    stop(
        Family::AnotherDevice,
        "another-device",
        None,
        &[R::Ur10, R::SimIiwa, R::SimPanda, R::HapticMotion],
    ),
    stop(
        Family::SocketDistance,
        "socket-distance",
        Some("--socket-distance-m"),
        SOCKETS,
    ),
    stop(Family::WrongSocket, "wrong-socket", None, SOCKETS),
    spec(
        Family::Latency,
        LATENCY_CLASS,
        Expect::Note(LATENCY_CLASS),
        &[R::HapticMotion],
    ),
    spec(
        Family::AsIs,
        "correct-as-is",
        Expect::Clean,
        &[
            R::Ur10,
            R::Ur10Quaternion,
            R::Tiago,
            R::Humanoid,
            R::Positioner,
            R::PositionerEuler,
            R::SocketsIiwa,
            R::SocketsPanda,
            R::Haptic,
            R::HapticMotion,
        ],
    ),
    spec(
        Family::Resampled,
        "correct-resampled",
        Expect::Clean,
        &[
            R::Ur10,
            R::Tiago,
            R::Humanoid,
            R::Positioner,
            R::SocketsIiwa,
            R::SocketsPanda,
            R::Haptic,
        ],
    ),
    spec(
        Family::SimEffects,
        "correct-sim-effects",
        Expect::Clean,
        &[R::SimIiwa, R::SimPanda],
    ),
    spec(
        Family::HapticEffects,
        "correct-haptic-effects",
        Expect::Clean,
        &[R::HapticMotion],
    ),
    stop(
        Family::ChangePoint,
        "change-point",
        None,
        &[
            R::Tiago,
            R::Humanoid,
            R::Ur10Quaternion,
            R::Positioner,
            R::SimIiwa,
            R::SimPanda,
            R::Haptic,
            R::HapticMotion,
        ],
    ),
    stop(
        Family::ColumnScale,
        "column-scale",
        Some("--column-scale"),
        JOINTED,
    ),
    stop(
        Family::ColumnCoupling,
        "column-coupling",
        Some("--column-coupling"),
        &[
            R::Ur10,
            R::Tiago,
            R::Humanoid,
            R::SocketsIiwa,
            R::SimIiwa,
            R::SimPanda,
            R::Haptic,
        ],
    ),
    spec(
        Family::PartUnit,
        "part-unit",
        Expect::Stop("length-unit", None),
        MARKERS,
    ),
    spec(
        Family::GlitchRow,
        "glitch-row",
        Expect::Listed,
        &[
            R::Ur10,
            R::Tiago,
            R::Humanoid,
            R::SocketsIiwa,
            R::SocketsPanda,
            R::SimIiwa,
            R::SimPanda,
            R::Haptic,
        ],
    ),
    spec(
        Family::WrongVariant,
        "wrong-variant",
        Expect::Stop("another-device", None),
        &[R::Ur10, R::SocketsIiwa, R::SimIiwa],
    ),
    stop(
        Family::Mounting,
        "mounting",
        Some("--gravity"),
        &[R::Humanoid],
    ),
];

impl Family {
    /// Its row of [`FAMILIES`].
    ///
    /// # Panics
    /// Never: every family has a row (a test checks it).
    pub fn spec(self) -> &'static FamilySpec {
        FAMILIES
            .iter()
            .find(|s| s.family == self)
            .unwrap_or_else(|| unreachable!("every family has a row"))
    }

    /// Whether the family is one of those added with the change-point, per-joint scale and
    /// coupling hypotheses (reported apart from the earlier families).
    pub fn is_new(self) -> bool {
        matches!(
            self,
            Family::ChangePoint
                | Family::ColumnScale
                | Family::ColumnCoupling
                | Family::PartUnit
                | Family::GlitchRow
                | Family::WrongVariant
                | Family::Mounting
        )
    }

    /// Whether the family is correct data (any finding is a false alarm).
    pub fn is_correct(self) -> bool {
        self.spec().expect == Expect::Clean
    }
}

/// The two halves of the sweep.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Half {
    /// The half a change of the check may be tuned on.
    Tuning,
    /// The half kept back to measure the change.
    HeldBack,
}

impl Half {
    /// `tuning` or `held-back`.
    pub fn name(self) -> &'static str {
        match self {
            Half::Tuning => "tuning",
            Half::HeldBack => "held-back",
        }
    }

    /// The half of a case identity: FNV-1a 64 of the identity, its lowest bit.
    pub fn of(id: &str) -> Half {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in id.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        // Fold the high bits in: FNV's lowest bit alone is the parity of the bytes' sum.
        if (h ^ (h >> 29) ^ (h >> 41)) & 1 == 0 {
            Half::Tuning
        } else {
            Half::HeldBack
        }
    }
}

/// A unit an angle column may be written in, read as rad.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AngleUnit {
    /// Degrees.
    Deg,
    /// Gradians.
    Grad,
    /// Revolutions.
    Rev,
}

impl AngleUnit {
    /// The flag's word.
    pub fn name(self) -> &'static str {
        match self {
            AngleUnit::Deg => "deg",
            AngleUnit::Grad => "grad",
            AngleUnit::Rev => "rev",
        }
    }

    /// The number written for 1 rad.
    pub fn per_rad(self) -> f64 {
        match self {
            AngleUnit::Deg => 180.0 / PI,
            AngleUnit::Grad => 200.0 / PI,
            AngleUnit::Rev => 0.5 / PI,
        }
    }
}

/// A unit a length may be written in, read as m.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LengthUnit {
    /// Millimetres.
    Mm,
    /// Centimetres.
    Cm,
    /// Inches.
    In,
    /// Feet.
    Ft,
}

impl LengthUnit {
    /// The flag's word.
    pub fn name(self) -> &'static str {
        match self {
            LengthUnit::Mm => "mm",
            LengthUnit::Cm => "cm",
            LengthUnit::In => "in",
            LengthUnit::Ft => "ft",
        }
    }

    /// The number written for 1 m.
    pub fn per_m(self) -> f64 {
        match self {
            LengthUnit::Mm => 1e3,
            LengthUnit::Cm => 1e2,
            LengthUnit::In => 1.0 / 0.0254,
            LengthUnit::Ft => 1.0 / 0.3048,
        }
    }
}

/// The mistake of a case, with its parameters (columns are found in the recording's table
/// when the case is written: `col` is an index into its revolute joint columns).
#[derive(Clone, Debug, PartialEq)]
pub enum Mistake {
    /// One revolute joint column written in `unit`.
    ColumnUnit {
        /// Index into the revolute joint columns.
        col: usize,
        /// The unit written.
        unit: AngleUnit,
    },
    /// Every angle (joints, Euler angles) in degrees.
    AllDegrees,
    /// Every length in `unit`.
    Lengths(LengthUnit),
    /// Marker `marker` (1-based) in mm.
    MarkerMm(usize),
    /// One revolute joint column negated.
    Sign(usize),
    /// One revolute joint column plus `offset_rad`.
    Zero(usize, f64),
    /// Two revolute joint columns' data exchanged.
    Swap(usize, usize),
    /// The revolute joint columns' data in reverse order.
    Reverse,
    /// The humanoid's left-arm columns given as the right arm's and back.
    Arms,
    /// Measurements of row `i + k` paired with the joints of row `i` (k rows dropped).
    Shift(usize),
    /// From `percent` % of the rows on, the measurements one row late.
    ShiftFrom(usize),
    /// `percent` % of the rows' joint readings shuffled among themselves (seeded).
    Decouple(u32),
    /// Quaternions written x, y, z, w.
    Xyzw,
    /// Quaternions conjugated.
    Conjugate,
    /// Euler angles of R = Rx(a)·Ry(b)·Rz(c).
    EulerXyz,
    /// Instrument axis `0..3` negated.
    Mirror(usize),
    /// Instrument axes exchanged.
    SwapAxes(usize, usize),
    /// `--tip r_hand --tip l_hand`.
    TipsSwapped,
    /// The tip given one moving joint up from the one measured.
    TipUp,
    /// The data measured one moving joint up from the tip given.
    TipDown,
    /// TIAGo's readings and first marker on the UR10 / the iiwa 14's positions on the Panda.
    OtherRobot,
    /// The data simulated with every link longer by `mm` millimetres.
    LongerLinks(u32),
    /// `--socket-distance-m` times `factor`.
    SocketDistance(f64),
    /// `percent` % of socket 0's rows filed under socket 1.
    WrongSocket(u32),
    /// Cable distance sampled `ms` milliseconds after the joints.
    LatencyMs(u32),
    /// Nothing.
    None,
    /// Rows re-ordered (seeded permutation).
    Shuffled,
    /// Every `n`-th row kept.
    EveryNth(usize),
    /// The arm blind test's draw `i` (its effects).
    Draw(u64),
    /// `hapcal simulate --effect` with this effect and parameter.
    HapticEffect(Effect, &'static str),
    /// From `from_pct` % of the rows on, the instrument turned by `deg`° about a seeded axis
    /// and moved by `mm` mm in a seeded direction (positions and orientations alike).
    TrackerMoved {
        /// Where the change happens, % of the rows.
        from_pct: u32,
        /// Rotation, degrees.
        deg: u32,
        /// Translation, mm.
        mm: u32,
    },
    /// From `from_pct` % of the rows on, the measured pose's origin `mm` mm away along a seeded
    /// direction of its own frame (a marker or tool re-mounted).
    MarkerMoved {
        /// Where the change happens, % of the rows.
        from_pct: u32,
        /// Offset, mm.
        mm: u32,
    },
    /// From `from_pct` % of the rows on, revolute column `col` plus `mrad` (a capstan
    /// re-tensioned, an encoder re-homed).
    ZeroFrom {
        /// Index into the revolute joint columns.
        col: usize,
        /// Where the change happens, % of the rows.
        from_pct: u32,
        /// The jump, mrad.
        mrad: i32,
    },
    /// Revolute column `col` times `factor`.
    Scale {
        /// Index into the revolute joint columns.
        col: usize,
        /// The factor.
        factor: ScaleFactor,
    },
    /// Revolute column `col` (1 or more) plus `centi`/100 times column `col - 1`.
    Coupling {
        /// Index into the revolute joint columns.
        col: usize,
        /// The coefficient, hundredths.
        centi: i32,
    },
    /// From `from_pct` % of the rows on, every position in mm.
    PartMm(u32),
    /// Revolute column `col` of the row `at_pct` % into the file plus 0.2 rad.
    Glitch {
        /// Index into the revolute joint columns.
        col: usize,
        /// Where the row is, % of the rows.
        at_pct: u32,
    },
    /// The description of another variant with the same joint names (fixtures/wrong-robot).
    Variant,
    /// The description turned by π about x at its root.
    Ceiling,
}

/// A factor a joint column may be scaled by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ScaleFactor {
    /// Encoder counts of a 17-bit encoder: 2¹⁷/2π per rad.
    Counts17,
    /// The motor side of a 100:1 gear.
    MotorSide100,
    /// A gear ratio 5 % off.
    GearError5,
}

impl ScaleFactor {
    /// The number written for 1 rad.
    pub fn per_rad(self) -> f64 {
        match self {
            ScaleFactor::Counts17 => f64::from(1u32 << 17) / (2.0 * PI),
            ScaleFactor::MotorSide100 => 100.0,
            ScaleFactor::GearError5 => 1.05,
        }
    }

    /// Its part of a case identity.
    fn name(self) -> &'static str {
        match self {
            ScaleFactor::Counts17 => "counts17",
            ScaleFactor::MotorSide100 => "motor100",
            ScaleFactor::GearError5 => "gear1.05",
        }
    }
}

impl Mistake {
    /// Its part of the case identity.
    fn label(&self) -> String {
        match self {
            Mistake::ColumnUnit { col, unit } => format!("col{col}-{}", unit.name()),
            Mistake::AllDegrees => "deg".to_owned(),
            Mistake::Lengths(u) => u.name().to_owned(),
            Mistake::MarkerMm(m) => format!("marker{m}-mm"),
            Mistake::Sign(c) => format!("col{c}"),
            Mistake::Zero(c, o) => format!("col{c}{:+.0}deg", o.to_degrees()),
            Mistake::Swap(a, b) => format!("col{a}-col{b}"),
            Mistake::Reverse => "reversed".to_owned(),
            Mistake::Arms => "arms".to_owned(),
            Mistake::Shift(k) => format!("k{k}"),
            Mistake::ShiftFrom(p) => format!("from-{p}pct"),
            Mistake::Decouple(p) => format!("{p}pct"),
            Mistake::Xyzw => "xyzw".to_owned(),
            Mistake::Conjugate => "conjugate".to_owned(),
            Mistake::EulerXyz => "xyz".to_owned(),
            Mistake::Mirror(a) => format!("mirror-{}", axis(*a)),
            Mistake::SwapAxes(a, b) => format!("swap-{}{}", axis(*a), axis(*b)),
            Mistake::TipsSwapped => "tips".to_owned(),
            Mistake::TipUp => "up".to_owned(),
            Mistake::TipDown => "down".to_owned(),
            Mistake::OtherRobot => "other-robot".to_owned(),
            Mistake::LongerLinks(mm) => format!("longer-{mm}mm"),
            Mistake::SocketDistance(f) => format!("x{f}"),
            Mistake::WrongSocket(p) => format!("{p}pct"),
            Mistake::LatencyMs(ms) => format!("{ms}ms"),
            Mistake::None => "as-is".to_owned(),
            Mistake::Shuffled => "shuffled".to_owned(),
            Mistake::EveryNth(n) => format!("every-{n}"),
            Mistake::Draw(i) => format!("draw{i}"),
            Mistake::HapticEffect(e, p) => format!("{}-{p}", e.name()),
            Mistake::TrackerMoved { from_pct, deg, mm } => {
                format!("tracker-{deg}deg-{mm}mm-from-{from_pct}pct")
            }
            Mistake::MarkerMoved { from_pct, mm } => format!("marker-{mm}mm-from-{from_pct}pct"),
            Mistake::ZeroFrom {
                col,
                from_pct,
                mrad,
            } => format!("col{col}{mrad:+}mrad-from-{from_pct}pct"),
            Mistake::Scale { col, factor } => format!("col{col}-{}", factor.name()),
            Mistake::Coupling { col, centi } => format!("col{col}{centi:+}pct-col{}", col - 1),
            Mistake::PartMm(p) => format!("mm-from-{p}pct"),
            Mistake::Glitch { col, at_pct } => format!("col{col}-row-{at_pct}pct"),
            Mistake::Variant => "variant".to_owned(),
            Mistake::Ceiling => "ceiling".to_owned(),
        }
    }
}

/// `x`, `y` or `z`.
fn axis(a: usize) -> char {
    ['x', 'y', 'z'][a % 3]
}

/// One case of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Case {
    /// Identity: `family/recording/parameters`, unique.
    pub id: String,
    /// Family.
    pub family: Family,
    /// Recording it starts from.
    pub recording: Recording,
    /// The mistake and its parameters.
    pub mistake: Mistake,
    /// Seed of anything random in writing it (shuffles, simulations).
    pub seed: u64,
    /// 0, or the repeat of a mistake with few parameters: a recorded file then loses a
    /// seeded fifth of its rows first (a simulated one differs by its seed).
    pub part: u32,
    /// Its half.
    pub half: Half,
}

/// Number of revolute joint columns of a recording (for drawing column indices).
fn n_revolute(r: Recording) -> usize {
    match r {
        R::Ur10 | R::Ur10Quaternion => 6,
        R::Tiago | R::SocketsIiwa | R::SocketsPanda | R::SimIiwa | R::SimPanda | R::Haptic => 7,
        R::HapticMotion => 7,
        R::Humanoid => 17,
        R::Positioner | R::PositionerEuler => 2,
    }
}

/// Draws the parameters of the `k`-th case of `family` on `rec`.
fn draw(family: Family, rec: Recording, k: usize, rng: &mut ChaCha8Rng) -> Mistake {
    let n = n_revolute(rec);
    let col = |rng: &mut ChaCha8Rng| rng.random_range(0..n);
    match family {
        Family::ColumnUnit => Mistake::ColumnUnit {
            col: col(rng),
            unit: [AngleUnit::Deg, AngleUnit::Grad, AngleUnit::Rev][k % 3],
        },
        Family::AngleUnit => Mistake::AllDegrees,
        Family::LengthUnit => {
            if rec == R::Haptic {
                Mistake::Lengths(LengthUnit::Mm)
            } else {
                Mistake::Lengths(
                    [
                        LengthUnit::Mm,
                        LengthUnit::Cm,
                        LengthUnit::In,
                        LengthUnit::Ft,
                    ][k % 4],
                )
            }
        }
        Family::MarkerUnit => Mistake::MarkerMm(if rec == R::Tiago {
            1 + k % 3
        } else {
            1 + k % 2
        }),
        Family::ColumnSign => Mistake::Sign(col(rng)),
        Family::ColumnZero => Mistake::Zero(col(rng), [PI / 2.0, -PI / 2.0, PI][k % 3]),
        Family::JointOrder => match (rec, k % 4) {
            (R::Humanoid, 3) => Mistake::Arms,
            (_, 2) if n > 2 => Mistake::Reverse,
            (_, 1) if n > 3 => {
                let a = rng.random_range(0..n - 2);
                Mistake::Swap(a, rng.random_range(a + 2..n))
            }
            _ => {
                let a = rng.random_range(0..n - 1);
                Mistake::Swap(a, a + 1)
            }
        },
        Family::RowShift => {
            if k % 5 == 4 {
                Mistake::ShiftFrom(50)
            } else {
                Mistake::Shift(1 + k % 4)
            }
        }
        Family::RowMismatch => Mistake::Decouple(10 + 10 * (k % 3) as u32),
        Family::QuaternionOrder => Mistake::Xyzw,
        Family::QuaternionInverse => Mistake::Conjugate,
        Family::EulerOrder => Mistake::EulerXyz,
        Family::MirroredAxis => {
            if k.is_multiple_of(2) {
                Mistake::Mirror(rng.random_range(0..3))
            } else {
                let a = rng.random_range(0..3);
                Mistake::SwapAxes(a, (a + 1 + rng.random_range(0..2)) % 3)
            }
        }
        Family::SwappedTips => Mistake::TipsSwapped,
        Family::TipLink => {
            if rec.sim_arm().is_some() && k % 2 == 1 {
                Mistake::TipDown
            } else {
                Mistake::TipUp
            }
        }
        Family::AnotherDevice => match rec {
            R::Ur10 => Mistake::OtherRobot,
            R::SimIiwa if k % 2 == 1 => Mistake::OtherRobot,
            _ => Mistake::LongerLinks(rng.random_range(40..=100)),
        },
        Family::SocketDistance => Mistake::SocketDistance([0.1, 10.0, 1000.0][k % 3]),
        Family::WrongSocket => Mistake::WrongSocket(10),
        Family::Latency => Mistake::LatencyMs(45),
        Family::AsIs => Mistake::None,
        Family::Resampled => match k % 3 {
            0 => Mistake::Shuffled,
            1 => Mistake::EveryNth(2),
            _ => Mistake::EveryNth(3),
        },
        Family::SimEffects => Mistake::Draw(rng.random_range(0..64)),
        Family::HapticEffects => {
            let effects: [(Effect, &'static str); 5] = [
                (Effect::Backlash, "j2=1e-3"),
                (Effect::CableAngle, "k=2e-4"),
                (Effect::GravityCompliance, "j2=2e-3"),
                (Effect::ThermalDrift, "k=2e-5"),
                (Effect::Latency, "tau=0.005"),
            ];
            let (e, p) = effects[k % effects.len()];
            Mistake::HapticEffect(e, p)
        }
        Family::ChangePoint => {
            let from_pct = 40 + 10 * (k % 3) as u32;
            match rec {
                R::Haptic | R::HapticMotion => Mistake::ZeroFrom {
                    col: col(rng),
                    from_pct,
                    mrad: [20, -30][k % 2],
                },
                R::Ur10Quaternion | R::Positioner if k % 2 == 1 => Mistake::MarkerMoved {
                    from_pct,
                    mm: 15 + 5 * (k % 2) as u32,
                },
                _ => Mistake::TrackerMoved {
                    from_pct,
                    deg: 2 + (k % 3) as u32,
                    mm: 20 + 10 * (k % 2) as u32,
                },
            }
        }
        Family::ColumnScale => Mistake::Scale {
            col: col(rng),
            factor: [
                ScaleFactor::MotorSide100,
                ScaleFactor::Counts17,
                ScaleFactor::GearError5,
            ][k % 3],
        },
        Family::ColumnCoupling => Mistake::Coupling {
            col: rng.random_range(1..n),
            centi: [50, -10, 30][k % 3],
        },
        Family::PartUnit => Mistake::PartMm([80, 85, 90][k % 3]),
        Family::GlitchRow => Mistake::Glitch {
            col: col(rng),
            at_pct: rng.random_range(10..90),
        },
        Family::WrongVariant => Mistake::Variant,
        Family::Mounting => Mistake::Ceiling,
    }
}

/// The cases of the sweep: `per_family` cases of every mistake family (recordings in turn,
/// parameters drawn from a seed per family and index), and of every kind of correct data;
/// a mistake drawn again is kept as a new part (a fifth of the rows dropped, or another
/// simulation seed) up to [`MAX_PARTS`] times.
pub fn cases(per_family: usize) -> Vec<Case> {
    let mut out: Vec<Case> = Vec::new();
    let mut seen: BTreeMap<String, u32> = BTreeMap::new();
    for (f_idx, spec) in FAMILIES.iter().enumerate() {
        // Families with few distinct cases stop when the draws repeat.
        let mut k = 0;
        let mut made = 0;
        while made < per_family && k < 4 * per_family {
            let rec = spec.recordings[k % spec.recordings.len()];
            let seed = 0x5E7_0000 + 1000 * f_idx as u64 + k as u64;
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mistake = draw(spec.family, rec, k / spec.recordings.len(), &mut rng);
            let base = format!("{}/{}/{}", spec.name, rec.name(), mistake.label());
            k += 1;
            let part = seen.entry(base.clone()).or_insert(0u32);
            if *part >= MAX_PARTS {
                continue;
            }
            let id = if *part == 0 {
                base
            } else {
                format!("{base}/part{part}")
            };
            let this_part = *part;
            *part += 1;
            made += 1;
            out.push(Case {
                half: Half::of(&id),
                id,
                family: spec.family,
                recording: rec,
                mistake,
                seed,
                part: this_part,
            });
        }
    }
    out
}

/// A table of numbers with a header (a CSV measurement file); NaN is an empty cell.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows, one value per column.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Reads a CSV file with a header row (`headerless`: none, columns named so).
    ///
    /// # Errors
    /// An unreadable file or a cell that is not a number.
    pub fn read_csv(path: &Path, headerless: Option<Vec<String>>) -> Result<Table> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let header = match headerless {
            Some(h) => h,
            None => (lines.next().unwrap_or_default().split(','))
                .map(|s| s.trim().to_owned())
                .collect(),
        };
        let mut rows = Vec::new();
        for (i, line) in lines.enumerate() {
            let row = (line.split(','))
                .map(|c| {
                    let c = c.trim();
                    if c.is_empty() {
                        Ok(f64::NAN)
                    } else {
                        c.parse::<f64>().with_context(|| {
                            format!("{}: row {}: not a number: {c}", path.display(), i + 1)
                        })
                    }
                })
                .collect::<Result<Vec<f64>>>()?;
            rows.push(row);
        }
        Ok(Table { header, rows })
    }

    /// The CSV text (with the header row unless `headerless`); shortest round-trip numbers.
    pub fn to_csv(&self, headerless: bool) -> String {
        let mut s = String::new();
        if !headerless {
            s.push_str(&self.header.join(","));
            s.push('\n');
        }
        for row in &self.rows {
            let cells: Vec<String> = (row.iter())
                .map(|v| {
                    if v.is_nan() {
                        String::new()
                    } else {
                        format!("{v}")
                    }
                })
                .collect();
            s.push_str(&cells.join(","));
            s.push('\n');
        }
        s
    }

    /// Index of column `name`.
    pub fn col(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// Applies `f` to every cell of column `name` (empty cells stay empty).
    fn map_col(&mut self, name: &str, f: impl Fn(f64) -> f64) {
        if let Some(c) = self.col(name) {
            for row in &mut self.rows {
                row[c] = f(row[c]);
            }
        }
    }

    /// Exchanges the data of two columns.
    fn swap_cols(&mut self, a: &str, b: &str) {
        if let (Some(a), Some(b)) = (self.col(a), self.col(b)) {
            for row in &mut self.rows {
                row.swap(a, b);
            }
        }
    }
}

/// The two-axis positioner's `measurements.yaml` as a table `q1,q2,x,y,z,qw,qx,qy,qz` in
/// file order (its device file's joints are read by position).
///
/// # Errors
/// An unreadable file or an observation without its numbers.
pub fn read_positioner_yaml(path: &Path) -> Result<Table> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let header: Vec<String> = ["q1", "q2", "x", "y", "z", "qw", "qx", "qy", "qz"]
        .map(str::to_owned)
        .to_vec();
    let mut rows = Vec::new();
    let mut cur: BTreeMap<String, f64> = BTreeMap::new();
    let mut joints: Vec<f64> = Vec::new();
    let mut flush = |cur: &mut BTreeMap<String, f64>, joints: &mut Vec<f64>| -> Result<()> {
        if cur.is_empty() && joints.is_empty() {
            return Ok(());
        }
        let mut row = joints.clone();
        for k in ["x", "y", "z", "qw", "qx", "qy", "qz"] {
            row.push(
                *cur.get(k)
                    .with_context(|| format!("an observation without {k}"))?,
            );
        }
        if row.len() != 9 {
            bail!("an observation with {} joints, expected 2", joints.len());
        }
        rows.push(row);
        cur.clear();
        joints.clear();
        Ok(())
    };
    for line in text.lines() {
        if !line.starts_with(' ') && line.trim_end().ends_with(':') {
            flush(&mut cur, &mut joints)?;
            continue;
        }
        let t = line.trim();
        if let Some(v) = t.strip_prefix("- ") {
            joints.push(v.trim().parse()?);
        } else if let Some((k, v)) = t.split_once(':')
            && let Ok(v) = v.trim().parse::<f64>()
        {
            cur.insert(k.trim().to_owned(), v);
        }
    }
    flush(&mut cur, &mut joints)?;
    Ok(Table { header, rows })
}

/// Replaces the quaternion columns `qw{s},qx{s},qy{s},qz{s}` by figaroh's Euler angles
/// `phix{s},phiy{s},phiz{s}` (R = Rz·Ry·Rx).
fn quaternion_to_euler(t: &mut Table, s: &str) {
    let names = ["qw", "qx", "qy", "qz"].map(|n| format!("{n}{s}"));
    let Some(idx) = names.iter().map(|n| t.col(n)).collect::<Option<Vec<_>>>() else {
        return;
    };
    for row in &mut t.rows {
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            row[idx[0]],
            row[idx[1]],
            row[idx[2]],
            row[idx[3]],
        ));
        let (r, p, y) = q.euler_angles();
        row[idx[0]] = r;
        row[idx[1]] = p;
        row[idx[2]] = y;
        row.remove(idx[3]);
    }
    t.header[idx[0]] = format!("phix{s}");
    t.header[idx[1]] = format!("phiy{s}");
    t.header[idx[2]] = format!("phiz{s}");
    t.header.remove(idx[3]);
}

/// Replaces figaroh's Euler columns `phix{s},phiy{s},phiz{s}` by the quaternion
/// `qw{s},qx{s},qy{s},qz{s}` of the same rotation.
fn euler_to_quaternion(t: &mut Table, s: &str) {
    let names = ["phix", "phiy", "phiz"].map(|n| format!("{n}{s}"));
    let Some(idx) = names.iter().map(|n| t.col(n)).collect::<Option<Vec<_>>>() else {
        return;
    };
    for row in &mut t.rows {
        let q = UnitQuaternion::from_euler_angles(row[idx[0]], row[idx[1]], row[idx[2]]);
        row[idx[0]] = q.w;
        row[idx[1]] = q.i;
        row[idx[2]] = q.j;
        row.insert(idx[2] + 1, q.k);
    }
    t.header[idx[0]] = format!("qw{s}");
    t.header[idx[1]] = format!("qx{s}");
    t.header[idx[2]] = format!("qy{s}");
    t.header.insert(idx[2] + 1, format!("qz{s}"));
}

/// The Euler angles (a, b, c) of R = Rx(a)·Ry(b)·Rz(c) for figaroh's (roll, pitch, yaw) of
/// R = Rz(yaw)·Ry(pitch)·Rx(roll).
pub fn euler_xyz_of(roll: f64, pitch: f64, yaw: f64) -> [f64; 3] {
    // Rᵀ = Rz(−c)·Ry(−b)·Rx(−a): figaroh's order with the angles negated.
    let rt = Rotation3::from_euler_angles(roll, pitch, yaw).transpose();
    let (r, p, y) = rt.euler_angles();
    [-r, -p, -y]
}

/// What a written case runs: the arguments of `hapcal calibrate` (without `--out`) and what
/// the fix must name.
#[derive(Clone, Debug, PartialEq)]
pub struct Invocation {
    /// Arguments after `hapcal calibrate`, paths absolute.
    pub args: Vec<String>,
    /// Words the fix must hold: each inner list is one requirement, met by any of its words
    /// (a column's name or its `q<k>` position, the factor's word, the flag).
    pub fix_words: Vec<Vec<String>>,
    /// Words that locate the mistake (`data.csv:61`, a column's name): a stop that names no
    /// cause but one of these locates it.
    pub locate_words: Vec<String>,
}

/// The loaded sources: the arm blind test's setups (loaded once).
pub struct Sources {
    root: PathBuf,
    arms: Vec<arm_blind::ArmSetup>,
}

impl Sources {
    /// Loads the simulated arms' fixtures under `root` (the project root).
    ///
    /// # Errors
    /// Unreadable fixtures.
    pub fn load(root: &Path) -> Result<Sources> {
        let arms = (ArmRobot::ALL.iter())
            .map(|&r| arm_blind::load_setup(r))
            .collect::<Result<Vec<_>>>()?;
        Ok(Sources {
            root: root.to_owned(),
            arms,
        })
    }

    fn arm(&self, robot: ArmRobot) -> &arm_blind::ArmSetup {
        &self.arms[robot as usize]
    }

    /// The absolute path of `path`, relative to the project root.
    fn abs(&self, path: &str) -> String {
        self.root.join(path).display().to_string()
    }
}

/// A simulated arm's positions table (`t_s`, joints by name, `x,y,z`) for `case` with the
/// given setup.
fn arm_table(case: &ArmCase, setup: &arm_blind::ArmSetup) -> Result<Table> {
    let m = arm_blind::simulate_positions_table(case, setup, SIM_ROWS)
        .context("a positions case has a table")?;
    let mut header = vec!["t_s".to_owned()];
    header.extend(setup.robot.joint_names.iter().cloned());
    header.extend(["x", "y", "z"].map(str::to_owned));
    let rows = (m.rows.iter())
        .enumerate()
        .map(|(i, r)| {
            let mut v = vec![r.t_s.unwrap_or(i as f64)];
            v.extend(&r.q);
            v.extend(r.markers.first().map_or([f64::NAN; 3], |s| s.position_m));
            v
        })
        .collect();
    Ok(Table { header, rows })
}

/// The URDF text with every joint origin of length over 5 cm longer by `extra_m` along itself.
pub fn lengthen_urdf(text: &str, extra_m: f64) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("<origin") {
        out.push_str(&rest[..i]);
        rest = &rest[i..];
        let end = rest.find('>').map_or(rest.len(), |e| e + 1);
        let tag = &rest[..end];
        out.push_str(&lengthen_origin(tag, extra_m));
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// One `<origin … xyz="…" …>` tag lengthened (see [`lengthen_urdf`]).
fn lengthen_origin(tag: &str, extra_m: f64) -> String {
    let Some(s) = tag.find("xyz=\"") else {
        return tag.to_owned();
    };
    let a = s + 5;
    let Some(len) = tag[a..].find('"') else {
        return tag.to_owned();
    };
    let v: Vec<f64> = (tag[a..a + len].split_whitespace())
        .filter_map(|x| x.parse().ok())
        .collect();
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if v.len() != 3 || norm < 0.05 {
        return tag.to_owned();
    }
    let k = (norm + extra_m) / norm;
    format!(
        "{}{} {} {}{}",
        &tag[..a],
        v[0] * k,
        v[1] * k,
        v[2] * k,
        &tag[a + len..]
    )
}

/// The device TOML with every D-H length (`a_m`, `d_m`) over 5 cm in magnitude longer by
/// `extra_m`.
pub fn lengthen_device_toml(text: &str, extra_m: f64) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let t = line.trim_start();
        let is_len = t.starts_with("a_m") || t.starts_with("d_m");
        let value = (t.split_once('=')).and_then(|(_, v)| {
            v.split('#')
                .next()
                .and_then(|v| v.trim().parse::<f64>().ok())
        });
        match value {
            Some(v) if is_len && v.abs() > 0.05 => {
                let key = t.split('=').next().unwrap_or_default().trim();
                let _ = writeln!(out, "{key} = {}", v + extra_m * v.signum());
            }
            _ => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    out
}

/// Where a case's data come from before the mistake: a table, or socket files.
enum Base {
    /// One measurement table.
    Table(Table),
    /// MUKCa socket files `hole_0`, `hole_1` (no header), joint names as columns.
    Sockets(Table, Table),
}

impl Base {
    /// The tables to write, in file order (a socket case: `hole_0`, then `hole_1`).
    fn tables_mut(&mut self) -> Vec<&mut Table> {
        match self {
            Base::Table(t) => vec![t],
            Base::Sockets(a, b) => vec![a, b],
        }
    }

    /// The first table (the socket case's `hole_0`).
    fn first(&self) -> &Table {
        match self {
            Base::Table(t) | Base::Sockets(t, _) => t,
        }
    }

    /// The file a line number names: the first socket file, or the measurement file.
    fn data_name(&self) -> &'static str {
        match self {
            Base::Table(_) => "data.csv",
            Base::Sockets(..) => "hole_0.csv",
        }
    }
}

/// The joint columns of a case's data, to name a column the way a fix does.
struct JointColumns {
    /// The revolute joint columns, in the order the mistakes index them.
    revolute: Vec<String>,
    /// Every joint column, in chain order (a prismatic joint included).
    joints: Vec<String>,
}

impl JointColumns {
    /// The name of revolute column `c` (empty past the last).
    fn name_of(&self, c: usize) -> String {
        self.revolute.get(c).cloned().unwrap_or_default()
    }

    /// The words that name revolute column `c`: its joint name and `q<k>`, its place among all
    /// joints.
    fn words(&self, c: usize) -> Vec<String> {
        let name = self.name_of(c);
        let k = self.joints.iter().position(|j| *j == name).unwrap_or(c);
        vec![name, format!("q{}", k + 1)]
    }
}

/// The invocation of a case while its mistake is made: the device and tips it names, extra
/// arguments, and what the fix must name and what locates the mistake.
struct InvocationDraft {
    /// The device file (absolute path).
    device: String,
    /// The tips, in `--tip` order.
    tips: Vec<String>,
    /// Arguments after the data.
    extra: Vec<String>,
    /// See [`Invocation::fix_words`].
    fix_words: Vec<Vec<String>>,
    /// See [`Invocation::locate_words`].
    locate_words: Vec<String>,
}

/// One table of a case as a mistake is made in it.
struct TableSite<'a> {
    /// The case.
    case: &'a Case,
    /// Its joint columns (of the first table).
    columns: &'a JointColumns,
    /// The file a line number names ([`Base::data_name`]).
    data_name: &'static str,
    /// Index of this table among the case's tables (0: the first, which alone adds the words
    /// of a mistake made in every table).
    t_idx: usize,
    /// Number of tables (2 for socket files).
    n_tables: usize,
}

/// Writes `case` into `dir` (a fresh folder) and returns what to run. `simulate` runs
/// `hapcal simulate` with the given arguments (haptic logs along a motion: the sweep passes
/// the release binary; a test may pass a function that refuses).
///
/// # Errors
/// Unreadable fixtures, an unwritable folder, a failed simulation.
pub fn write_case(
    case: &Case,
    sources: &Sources,
    dir: &Path,
    simulate: &dyn Fn(&[String]) -> Result<()>,
) -> Result<Invocation> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let rec = case.recording;
    let mut draft = InvocationDraft {
        device: sources.abs(rec.device()),
        tips: rec.tips().iter().map(|s| (*s).to_owned()).collect(),
        extra: Vec::new(),
        fix_words: Vec::new(),
        locate_words: Vec::new(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(case.seed ^ 0xC0FF_EE00);
    let mut base = load_base(case, sources, dir, simulate)?;
    thin_recorded(case, &mut base, &mut rng);
    let columns = JointColumns {
        revolute: rec.revolute(base.first()),
        joints: joint_side(base.first()),
    };
    if let Expect::Stop(_, Some(flag)) = case.family.spec().expect {
        draft.fix_words.push(vec![flag.to_owned()]);
    }
    let data_name = base.data_name();
    let tables = base.tables_mut();
    let n_tables = tables.len();
    for (t_idx, t) in tables.into_iter().enumerate() {
        let site = TableSite {
            case,
            columns: &columns,
            data_name,
            t_idx,
            n_tables,
        };
        make_mistake(&site, sources, dir, t, &mut draft, &mut rng)?;
    }
    move_to_wrong_socket(&case.mistake, &mut base, &mut rng);
    write_data(rec, &base, dir, draft)
}

/// A repeat of a mistake on a recorded file (`case.part > 0`) first drops a seeded fifth of
/// the rows of each table (a simulated one differs by its seed instead).
fn thin_recorded(case: &Case, base: &mut Base, rng: &mut ChaCha8Rng) {
    let rec = case.recording;
    let simulated = rec.sim_arm().is_some() || rec == R::HapticMotion;
    if case.part == 0 || simulated {
        return;
    }
    for t in base.tables_mut() {
        let n = t.rows.len();
        let mut keep: Vec<usize> = (0..n).collect();
        keep.shuffle(rng);
        keep.truncate(n - n / 5);
        keep.sort_unstable();
        t.rows = keep.iter().map(|&i| t.rows[i].clone()).collect();
    }
}

/// Makes the case's mistake in table `t` (or in the invocation), adding what the fix must name
/// and what locates it to `draft`.
///
/// # Errors
/// A recording without the tip or root joint the mistake needs, an unreadable or unwritable
/// device file.
fn make_mistake(
    site: &TableSite<'_>,
    sources: &Sources,
    dir: &Path,
    t: &mut Table,
    draft: &mut InvocationDraft,
    rng: &mut ChaCha8Rng,
) -> Result<()> {
    match &site.case.mistake {
        Mistake::ColumnUnit { .. }
        | Mistake::AllDegrees
        | Mistake::Lengths(_)
        | Mistake::MarkerMm(_)
        | Mistake::Sign(_)
        | Mistake::Zero(..)
        | Mistake::Swap(..)
        | Mistake::Reverse
        | Mistake::Arms
        | Mistake::Scale { .. }
        | Mistake::Coupling { .. } => column_mistake(site, t, draft),
        Mistake::Shift(_)
        | Mistake::ShiftFrom(_)
        | Mistake::Decouple(_)
        | Mistake::Shuffled
        | Mistake::EveryNth(_) => row_mistake(&site.case.mistake, t, rng),
        Mistake::Xyzw
        | Mistake::Conjugate
        | Mistake::EulerXyz
        | Mistake::Mirror(_)
        | Mistake::SwapAxes(..) => frame_mistake(&site.case.mistake, t),
        Mistake::TrackerMoved { .. }
        | Mistake::MarkerMoved { .. }
        | Mistake::ZeroFrom { .. }
        | Mistake::PartMm(_)
        | Mistake::Glitch { .. } => partial_mistake(site, t, draft, rng),
        Mistake::TipsSwapped
        | Mistake::TipUp
        | Mistake::TipDown
        | Mistake::OtherRobot
        | Mistake::SocketDistance(_)
        | Mistake::Variant
        | Mistake::Ceiling => setup_mistake(site, sources, dir, t, draft)?,
        Mistake::WrongSocket(_)
        | Mistake::LongerLinks(_)
        | Mistake::LatencyMs(_)
        | Mistake::None
        | Mistake::Draw(_)
        | Mistake::HapticEffect(..) => {}
    }
    Ok(())
}

/// A mistake in whole columns: a unit, a sign, a zero, a scale or a coupling of a joint
/// column, swapped or reversed joint columns, the arms swapped, lengths or a marker in another
/// unit.
fn column_mistake(site: &TableSite<'_>, t: &mut Table, draft: &mut InvocationDraft) {
    let (columns, first) = (site.columns, site.t_idx == 0);
    let revolute = &columns.revolute;
    let fix_words = &mut draft.fix_words;
    match &site.case.mistake {
        Mistake::ColumnUnit { col, unit } => {
            let f = unit.per_rad();
            t.map_col(&columns.name_of(*col), |v| v * f);
            if first {
                fix_words.push(columns.words(*col));
                fix_words.push(vec![unit.name().to_owned()]);
            }
        }
        Mistake::AllDegrees => {
            let names: Vec<String> = (t.header.iter())
                .filter(|h| revolute.contains(h) || h.starts_with("phi"))
                .cloned()
                .collect();
            for n in names {
                t.map_col(&n, f64::to_degrees);
            }
            if first {
                fix_words.push(vec!["deg".to_owned()]);
            }
        }
        Mistake::Lengths(u) => {
            let f = u.per_m();
            let names: Vec<String> = (t.header.iter())
                .filter(|h| is_position(h) || *h == "distance_m")
                .cloned()
                .collect();
            for n in names {
                t.map_col(&n, |v| v * f);
            }
            fix_words.push(vec![u.name().to_owned()]);
        }
        Mistake::MarkerMm(m) => {
            for a in ["x", "y", "z"] {
                t.map_col(&format!("{a}{m}"), |v| v * 1e3);
            }
            fix_words.push(vec![format!("x{m}")]);
            fix_words.push(vec!["mm".to_owned()]);
        }
        Mistake::Sign(c) => {
            t.map_col(&columns.name_of(*c), |v| -v);
            if first {
                fix_words.push(columns.words(*c));
            }
        }
        Mistake::Zero(c, o) => {
            t.map_col(&columns.name_of(*c), |v| v + o);
            if first {
                fix_words.push(columns.words(*c));
            }
        }
        Mistake::Swap(a, b) => {
            t.swap_cols(&columns.name_of(*a), &columns.name_of(*b));
            if first {
                let mut w = columns.words(*a);
                w.extend(columns.words(*b));
                fix_words.push(w);
            }
        }
        Mistake::Reverse => {
            let n = revolute.len();
            for i in 0..n / 2 {
                t.swap_cols(&columns.name_of(i), &columns.name_of(n - 1 - i));
            }
        }
        Mistake::Arms => {
            for j in 1..=7 {
                t.swap_cols(&format!("l_{j}"), &format!("r_{j}"));
            }
        }
        Mistake::Scale { col, factor } => {
            let f = factor.per_rad();
            t.map_col(&columns.name_of(*col), |v| v * f);
            if first {
                fix_words.push(columns.words(*col));
                draft.locate_words.extend(columns.words(*col));
            }
        }
        Mistake::Coupling { col, centi } => {
            let c = f64::from(*centi) / 100.0;
            if let (Some(a), Some(b)) = (
                t.col(&columns.name_of(*col)),
                t.col(&columns.name_of(col - 1)),
            ) {
                for row in &mut t.rows {
                    row[a] += c * row[b];
                }
            }
            if first {
                fix_words.push(columns.words(*col));
                draft.locate_words.extend(columns.words(*col));
            }
        }
        _ => {}
    }
}

/// A mistake in the rows: joint readings shifted against the measurements (from the start or
/// from a row on), decoupled, shuffled, or every n-th row kept.
fn row_mistake(mistake: &Mistake, t: &mut Table, rng: &mut ChaCha8Rng) {
    match mistake {
        Mistake::Shift(k) => shift_rows(t, &joint_side(t), 0, *k),
        Mistake::ShiftFrom(p) => {
            let from = t.rows.len() * p / 100;
            shift_rows(t, &joint_side(t), from, 1);
        }
        Mistake::Decouple(p) => decouple(t, &joint_side(t), *p, rng),
        Mistake::Shuffled => t.rows.shuffle(rng),
        Mistake::EveryNth(n) => {
            let rows = std::mem::take(&mut t.rows);
            t.rows = rows.into_iter().step_by(*n).collect();
        }
        _ => {}
    }
}

/// A mistake in the frames of the measurements: quaternions in x, y, z, w order or
/// conjugated, Euler angles of another convention, a position axis mirrored or two swapped.
fn frame_mistake(mistake: &Mistake, t: &mut Table) {
    match mistake {
        Mistake::Xyzw => {
            let s = quaternion_suffix(t);
            // The file's qw,qx,qy,qz hold x, y, z, w.
            let idx: Vec<usize> = (["qw", "qx", "qy", "qz"].iter())
                .filter_map(|n| t.col(&format!("{n}{s}")))
                .collect();
            if idx.len() == 4 {
                for row in &mut t.rows {
                    let (w, x, y, z) = (row[idx[0]], row[idx[1]], row[idx[2]], row[idx[3]]);
                    row[idx[0]] = x;
                    row[idx[1]] = y;
                    row[idx[2]] = z;
                    row[idx[3]] = w;
                }
            }
        }
        Mistake::Conjugate => {
            let s = quaternion_suffix(t);
            for n in ["qx", "qy", "qz"] {
                t.map_col(&format!("{n}{s}"), |v| -v);
            }
        }
        Mistake::EulerXyz => {
            let s = if t.col("phix1").is_some() { "1" } else { "" };
            let idx: Vec<usize> = (["phix", "phiy", "phiz"].iter())
                .filter_map(|n| t.col(&format!("{n}{s}")))
                .collect();
            if idx.len() == 3 {
                for row in &mut t.rows {
                    let e = euler_xyz_of(row[idx[0]], row[idx[1]], row[idx[2]]);
                    for (i, v) in idx.iter().zip(e) {
                        row[*i] = v;
                    }
                }
            }
        }
        Mistake::Mirror(a) => {
            let names: Vec<String> = (t.header.iter())
                .filter(|h| is_position(h) && h.starts_with(axis(*a)))
                .cloned()
                .collect();
            for n in names {
                t.map_col(&n, |v| -v);
            }
        }
        Mistake::SwapAxes(a, b) => {
            let names: Vec<String> = (t.header.iter())
                .filter(|h| is_position(h) && h.starts_with(axis(*a)))
                .cloned()
                .collect();
            for n in names {
                let other = format!("{}{}", axis(*b), &n[1..]);
                t.swap_cols(&n, &other);
            }
        }
        _ => {}
    }
}

/// A mistake from a row on: the tracker or the marker moved, a joint's zero moved, positions
/// in mm, or one glitched reading; each names the line where it starts.
fn partial_mistake(
    site: &TableSite<'_>,
    t: &mut Table,
    draft: &mut InvocationDraft,
    rng: &mut ChaCha8Rng,
) {
    let (columns, data_name) = (site.columns, site.data_name);
    let (fix_words, locate_words) = (&mut draft.fix_words, &mut draft.locate_words);
    match &site.case.mistake {
        Mistake::TrackerMoved { from_pct, deg, mm } => {
            let from = t.rows.len() * *from_pct as usize / 100;
            let axis = nalgebra::Unit::new_normalize(random_direction(rng));
            let turn = UnitQuaternion::from_axis_angle(&axis, f64::from(*deg).to_radians());
            let shift = random_direction(rng) * (f64::from(*mm) / 1e3);
            move_poses(t, from, |p, q| (turn * p + shift, turn * q));
            locate_words.extend(lines_near(data_name, from + 2));
            fix_words.push(lines_near(data_name, from + 2));
        }
        Mistake::MarkerMoved { from_pct, mm } => {
            let from = t.rows.len() * *from_pct as usize / 100;
            let offset = random_direction(rng) * (f64::from(*mm) / 1e3);
            move_poses(t, from, |p, q| (p + q * offset, q));
            locate_words.extend(lines_near(data_name, from + 2));
            fix_words.push(lines_near(data_name, from + 2));
        }
        Mistake::ZeroFrom {
            col,
            from_pct,
            mrad,
        } => {
            let from = t.rows.len() * *from_pct as usize / 100;
            if let Some(c) = t.col(&columns.name_of(*col)) {
                for row in &mut t.rows[from..] {
                    row[c] += f64::from(*mrad) / 1e3;
                }
            }
            locate_words.extend(lines_near(data_name, from + 2));
            locate_words.extend(columns.words(*col));
            fix_words.push(lines_near(data_name, from + 2));
        }
        Mistake::PartMm(p) => {
            let from = t.rows.len() * *p as usize / 100;
            let cols: Vec<usize> = (t.header.iter().enumerate())
                .filter(|(_, h)| is_position(h))
                .map(|(i, _)| i)
                .collect();
            for row in &mut t.rows[from..] {
                for &c in &cols {
                    row[c] *= 1e3;
                }
            }
            let line = from + 2;
            locate_words.push(format!("{data_name}:{line}"));
            fix_words.push(vec![format!("{data_name}:{line}"), format!("{line}")]);
        }
        Mistake::Glitch { col, at_pct } if site.t_idx == 0 => {
            let row = t.rows.len() * *at_pct as usize / 100;
            if let Some(c) = t.col(&columns.name_of(*col)) {
                t.rows[row][c] += 0.2;
            }
            // Socket files have no header: row 0 is line 1.
            let line = if site.n_tables == 2 { row + 1 } else { row + 2 };
            locate_words.push(format!("{data_name}:{line}"));
        }
        _ => {}
    }
}

/// A mistake in the setup rather than the data: the tips swapped or one joint off, another
/// robot's joint names or device, a wrong socket distance, a variant's or a ceiling-mounted
/// device file (written into `dir`).
///
/// # Errors
/// A recording without a tip one joint up, an unreadable device file or one whose root joint
/// is not upright, an unwritable `dir`.
fn setup_mistake(
    site: &TableSite<'_>,
    sources: &Sources,
    dir: &Path,
    t: &mut Table,
    draft: &mut InvocationDraft,
) -> Result<()> {
    let rec = site.case.recording;
    let first = site.t_idx == 0;
    match &site.case.mistake {
        Mistake::TipsSwapped => draft.tips.reverse(),
        Mistake::TipUp if first => {
            let up = rec.tip_up().context("a tip one joint up")?;
            draft.tips[0] = up.to_owned();
            (draft.fix_words).push(rec.tip_aliases().iter().map(|s| (*s).to_owned()).collect());
        }
        Mistake::TipDown if first => {
            (draft.fix_words).push(vec![rec.tip_up().unwrap_or_default().to_owned()]);
        }
        Mistake::OtherRobot if rec == R::SimIiwa => {
            draft.device = sources.abs(R::SimPanda.device());
            let panda = &sources.arm(ArmRobot::Panda).robot.joint_names;
            for (h, p) in t
                .header
                .iter_mut()
                .filter(|h| h.starts_with("joint_a"))
                .zip(panda)
            {
                h.clone_from(p);
            }
        }
        Mistake::SocketDistance(f) if first => {
            draft.extra.push("--socket-distance-m".to_owned());
            draft.extra.push(format!("{}", SOCKET_DISTANCE_M * f));
        }
        Mistake::Variant if first => {
            draft.device = sources.abs(match rec {
                R::Ur10 => "fixtures/wrong-robot/ur5e_lengths.urdf",
                _ => "fixtures/wrong-robot/iiwa7_lengths.urdf",
            });
        }
        Mistake::Ceiling if first => {
            draft.device = write_ceiling_device(sources, rec, dir)?;
        }
        _ => {}
    }
    Ok(())
}

/// Writes `rec`'s device file turned upside down at its root joint into `dir`
/// (`humanoid_ceiling.urdf`) and returns its path.
///
/// # Errors
/// An unreadable device file, a root joint origin that is not upright, an unwritable `dir`.
fn write_ceiling_device(sources: &Sources, rec: Recording, dir: &Path) -> Result<String> {
    let text = std::fs::read_to_string(sources.root.join(rec.device()))?;
    let upright = r#"<origin xyz="0 0 0.3" rpy="0 0 0"/>"#;
    let turned = text.replacen(
        upright,
        r#"<origin xyz="0 0 0.3" rpy="3.141592653589793 0 0"/>"#,
        1,
    );
    if turned == text {
        bail!("the humanoid's root joint origin is not {upright}");
    }
    let path = dir.join("humanoid_ceiling.urdf");
    write(&path, &turned)?;
    Ok(path.display().to_string())
}

/// The wrong-socket mistake: a seeded `p` % (at least one) of `hole_0`'s rows moved to the end
/// of `hole_1`.
fn move_to_wrong_socket(mistake: &Mistake, base: &mut Base, rng: &mut ChaCha8Rng) {
    if let (Mistake::WrongSocket(p), Base::Sockets(a, b)) = (mistake, base) {
        let n_move = (a.rows.len() * *p as usize).div_ceil(100).max(1);
        let mut idx: Vec<usize> = (0..a.rows.len()).collect();
        idx.shuffle(rng);
        let mut moved: Vec<usize> = idx.into_iter().take(n_move).collect();
        moved.sort_unstable();
        for i in moved.into_iter().rev() {
            let row = a.rows.remove(i);
            b.rows.push(row);
        }
    }
}

/// Writes the case's data into `dir` (`data.csv`, or `placement/hole_0.csv` and `hole_1.csv`)
/// and returns the invocation that reads them.
///
/// # Errors
/// An unwritable `dir`.
fn write_data(
    rec: Recording,
    base: &Base,
    dir: &Path,
    draft: InvocationDraft,
) -> Result<Invocation> {
    let mut args = vec!["--device".to_owned(), draft.device];
    for tip in &draft.tips {
        args.push("--tip".to_owned());
        args.push(tip.clone());
    }
    match base {
        Base::Table(t) => {
            let path = dir.join("data.csv");
            write(&path, &t.to_csv(false))?;
            args.push("--data".to_owned());
            args.push(path.display().to_string());
            if !rec.is_haptic() {
                args.push("--test-last".to_owned());
                args.push("0.3".to_owned());
            }
        }
        Base::Sockets(a, b) => {
            let folder = dir.join("placement");
            std::fs::create_dir_all(&folder)?;
            write(&folder.join("hole_0.csv"), &a.to_csv(true))?;
            write(&folder.join("hole_1.csv"), &b.to_csv(true))?;
            args.push("--data".to_owned());
            args.push(folder.display().to_string());
        }
    }
    args.extend(draft.extra);
    Ok(Invocation {
        args,
        fix_words: draft.fix_words,
        locate_words: draft.locate_words,
    })
}

/// A unit vector drawn from `rng` (uniform on the sphere).
fn random_direction(rng: &mut ChaCha8Rng) -> nalgebra::Vector3<f64> {
    loop {
        let v = nalgebra::Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

/// `file:line` for the lines within two of `line`: where a change found from the residuals
/// may be named (the last row before it or the first after it).
fn lines_near(file: &str, line: usize) -> Vec<String> {
    (line.saturating_sub(2)..=line + 2)
        .map(|l| format!("{file}:{l}"))
        .collect()
}

/// Applies `f` to the measured poses of every row from `from` on: each position group
/// (`x,y,z`, `x2,y2,z2`, …) with the orientation of the same number (identity without one);
/// the orientation written back where the file has one.
fn move_poses(
    t: &mut Table,
    from: usize,
    f: impl Fn(
        nalgebra::Vector3<f64>,
        UnitQuaternion<f64>,
    ) -> (nalgebra::Vector3<f64>, UnitQuaternion<f64>),
) {
    let suffixes: Vec<String> = (t.header.iter())
        .filter_map(|h| h.strip_prefix('x'))
        .filter(|r| r.chars().all(|c| c.is_ascii_digit()))
        .map(str::to_owned)
        .collect();
    for s in suffixes {
        let p: Vec<usize> = (["x", "y", "z"].iter())
            .filter_map(|a| t.col(&format!("{a}{s}")))
            .collect();
        let q: Vec<usize> = (["qw", "qx", "qy", "qz"].iter())
            .filter_map(|a| t.col(&format!("{a}{s}")))
            .collect();
        if p.len() != 3 {
            continue;
        }
        let from = from.min(t.rows.len());
        for row in &mut t.rows[from..] {
            let pos = nalgebra::Vector3::new(row[p[0]], row[p[1]], row[p[2]]);
            if pos.iter().any(|v| v.is_nan()) {
                continue;
            }
            let rot = if q.len() == 4 {
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    row[q[0]], row[q[1]], row[q[2]], row[q[3]],
                ))
            } else {
                UnitQuaternion::identity()
            };
            let (pos, rot) = f(pos, rot);
            for (c, v) in p.iter().zip(pos.iter()) {
                row[*c] = *v;
            }
            if q.len() == 4 {
                let r = rot.quaternion();
                for (c, v) in q.iter().zip([r.w, r.i, r.j, r.k]) {
                    row[*c] = v;
                }
            }
        }
    }
}

/// The columns read on the robot's side: joints (prismatic too) and a haptic device's
/// external encoders; the rest (positions, orientations, distances, time) are the
/// instrument's.
fn joint_side(t: &Table) -> Vec<String> {
    (t.header.iter())
        .filter(|h| !(is_position(h) || is_orientation(h) || *h == "distance_m" || *h == "t_s"))
        .cloned()
        .collect()
}

/// Writes `text` to `path`.
fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// The numbering of the quaternion columns (`1` for `qw1`, empty for `qw`).
fn quaternion_suffix(t: &Table) -> &'static str {
    if t.col("qw1").is_some() { "1" } else { "" }
}

/// Pairs the joint readings of row `i` with the other columns of row `i + k`, from row
/// `from` on (rows before `from` unchanged; `k` rows dropped at the end).
fn shift_rows(t: &mut Table, joints: &[String], from: usize, k: usize) {
    let idx: Vec<usize> = joints.iter().filter_map(|j| t.col(j)).collect();
    let n = t.rows.len();
    if n <= from + k {
        return;
    }
    let orig = t.rows.clone();
    for (row, later) in t.rows[from..n - k].iter_mut().zip(&orig[from + k..]) {
        for (c, (v, w)) in row.iter_mut().zip(later).enumerate() {
            if !idx.contains(&c) {
                *v = *w;
            }
        }
    }
    t.rows.truncate(n - k);
}

/// Shuffles the joint readings of `percent` % of the rows among themselves (a derangement
/// by rotation of the chosen rows, so every chosen row is decoupled).
fn decouple(t: &mut Table, joints: &[String], percent: u32, rng: &mut ChaCha8Rng) {
    let idx: Vec<usize> = joints.iter().filter_map(|j| t.col(j)).collect();
    let n = t.rows.len();
    let n_pick = (n * percent as usize).div_ceil(100).max(2).min(n);
    let mut rows: Vec<usize> = (0..n).collect();
    rows.shuffle(rng);
    let picked: Vec<usize> = rows.into_iter().take(n_pick).collect();
    let orig = t.rows.clone();
    for (k, &r) in picked.iter().enumerate() {
        let src = picked[(k + 1) % picked.len()];
        for &c in &idx {
            t.rows[r][c] = orig[src][c];
        }
    }
}

/// The data of a case before its mistake.
fn load_base(
    case: &Case,
    sources: &Sources,
    dir: &Path,
    simulate: &dyn Fn(&[String]) -> Result<()>,
) -> Result<Base> {
    let root = &sources.root;
    let csv = |p: &str| Table::read_csv(&root.join(p), None);
    Ok(match case.recording {
        R::Ur10 if case.mistake == Mistake::OtherRobot => {
            // TIAGo's first marker and its first six arm joints under the UR10's names.
            let tiago = csv("fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv")?;
            let ur10 = csv("fixtures/figaroh/ur10/calibration.csv")?;
            let mut header: Vec<String> = vec!["x1".into(), "y1".into(), "z1".into()];
            let names = R::Ur10.revolute(&ur10);
            header.extend(names.iter().cloned());
            let src: Vec<usize> = (["x1", "y1", "z1"].iter().map(|s| (*s).to_owned()))
                .chain((1..=6).map(|j| format!("arm_{j}_joint")))
                .filter_map(|n| tiago.col(&n))
                .collect();
            let rows = (tiago.rows.iter())
                .map(|r| src.iter().map(|&c| r[c]).collect())
                .collect();
            Base::Table(Table { header, rows })
        }
        R::Ur10 => Base::Table(csv("fixtures/figaroh/ur10/calibration.csv")?),
        R::Ur10Quaternion => {
            let mut t = csv("fixtures/figaroh/ur10/calibration.csv")?;
            euler_to_quaternion(&mut t, "1");
            Base::Table(t)
        }
        R::Tiago => Base::Table(csv(
            "fixtures/figaroh/tiago/qualysis_base_hand_calibration.csv",
        )?),
        R::Humanoid => Base::Table(csv("fixtures/sim-humanoid/mocap.csv")?),
        R::Positioner | R::PositionerEuler => {
            let mut t = read_positioner_yaml(
                &root.join("fixtures/industrial-calibration/measurements.yaml"),
            )?;
            if case.recording == R::PositionerEuler {
                quaternion_to_euler(&mut t, "");
            }
            Base::Table(t)
        }
        R::SocketsIiwa | R::SocketsPanda => {
            let (robot, folder) = if case.recording == R::SocketsIiwa {
                (ArmRobot::Iiwa14, "fixtures/mukca/data/kuka_14/front")
            } else {
                (ArmRobot::Panda, "fixtures/mukca/data/panda_2/front_center")
            };
            let names = sources.arm(robot).robot.joint_names.clone();
            let read = |f: &str| Table::read_csv(&root.join(folder).join(f), Some(names.clone()));
            Base::Sockets(read("hole_0.csv")?, read("hole_1.csv")?)
        }
        R::Haptic => Base::Table(csv("fixtures/reference-device/log.csv")?),
        R::HapticMotion => {
            let out = dir.join("simulated.csv");
            let mut args: Vec<String> = vec![
                "--seed".into(),
                format!("{}", case.seed % 1000 + 1),
                "--poses".into(),
                "300".into(),
                "--motion".into(),
                "--period-s".into(),
                "0.05".into(),
                "--out".into(),
                out.display().to_string(),
            ];
            match &case.mistake {
                Mistake::LatencyMs(ms) => {
                    args.push("--effect".into());
                    args.push(format!(
                        "{}:tau={}",
                        Effect::Latency.name(),
                        f64::from(*ms) / 1e3
                    ));
                }
                Mistake::HapticEffect(e, p) => {
                    args.push("--effect".into());
                    args.push(format!("{}:{p}", e.name()));
                }
                Mistake::LongerLinks(mm) => {
                    let text = std::fs::read_to_string(root.join(R::Haptic.device()))?;
                    let dev = dir.join("longer-device.toml");
                    write(&dev, &lengthen_device_toml(&text, f64::from(*mm) / 1e3))?;
                    args.push("--device".into());
                    args.push(dev.display().to_string());
                }
                _ => {}
            }
            simulate(&args)?;
            Base::Table(Table::read_csv(&out, None)?)
        }
        R::SimIiwa | R::SimPanda => {
            let robot = case.recording.sim_arm().context("a simulated arm")?;
            let setup = sources.arm(robot);
            let arm_case = match &case.mistake {
                Mistake::Draw(i) => {
                    // The blind test's draw i on this robot, as positions data.
                    let mut c = arm_blind::draw_case(*i, setup.robot.joint_names.len());
                    c.robot = robot;
                    c.data = ArmData::Positions;
                    c.seed = *i;
                    c
                }
                _ => ArmCase {
                    seed: case.seed,
                    robot,
                    data: ArmData::Positions,
                    kind: ArmCaseKind::None,
                    injected: Injected::None,
                },
            };
            let mut setup = setup.clone();
            let urdf = root.join(case.recording.device());
            match &case.mistake {
                Mistake::LongerLinks(mm) => {
                    let text = std::fs::read_to_string(&urdf)?;
                    let longer = dir.join("longer.urdf");
                    write(&longer, &lengthen_urdf(&text, f64::from(*mm) / 1e3))?;
                    setup.robot = robot_from_urdf(&longer, &["ball_link".to_owned()])?;
                }
                Mistake::TipDown => {
                    let up = case.recording.tip_up().context("a tip one joint up")?;
                    setup.robot = robot_from_urdf(&urdf, &[up.to_owned()])?;
                }
                _ => {}
            }
            Base::Table(arm_table(&arm_case, &setup)?)
        }
    })
}

/// How the check answered a case.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Outcome {
    /// Stopped (or, for a note family, ran) naming the expected class, the fix naming the cause
    /// (for a listed family: ran naming the row); or stopped naming another cause and, as one
    /// the data fit as well, the expected fix.
    NamedRight,
    /// Stopped naming the expected class, but the fix does not name the cause (the column,
    /// the factor's unit or the flag).
    ClassOnly,
    /// Stopped without naming a cause (`no-hypothesis`, an implausible estimate, the reader's
    /// own error) but naming where the mistake is: the rows or the column.
    Located,
    /// Stopped naming another cause whose fix is an edit, not a flag.
    WrongCause,
    /// Stopped with a fix that harms: another cause's flag, or the expected cause's flag that,
    /// applied, still stops.
    HarmfulFix,
    /// Stopped otherwise: no cause, no place.
    Generic,
    /// Ran with a setup warning (a mistake family).
    Warned,
    /// Ran with no setup finding (a mistake family).
    Silent,
    /// Correct data with a setup finding, or a stop on a note family.
    FalseAlarm,
    /// Correct data with no setup finding.
    Clean,
}

impl Outcome {
    /// Words of the report.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::NamedRight => "named right",
            Outcome::ClassOnly => "class only",
            Outcome::Located => "located",
            Outcome::WrongCause => "wrong cause",
            Outcome::HarmfulFix => "harmful fix",
            Outcome::Generic => "generic",
            Outcome::Warned => "warned",
            Outcome::Silent => "silent",
            Outcome::FalseAlarm => "false alarm",
            Outcome::Clean => "clean",
        }
    }

    /// Whether the answer names the cause (the class right).
    pub fn is_named(self) -> bool {
        matches!(self, Outcome::NamedRight | Outcome::ClassOnly)
    }
}

/// The setup findings of a command's standard error: (class, the line from the class on).
pub fn findings(stderr: &str) -> Vec<(String, String)> {
    findings_with_severity(stderr)
        .into_iter()
        .map(|(_, c, t)| (c, t))
        .collect()
}

/// The setup findings with whether each is a warning (the line says `warning` before the
/// finding, or the finding was accepted) rather than the error that stopped the command.
fn findings_with_severity(stderr: &str) -> Vec<(bool, String, String)> {
    let mut out = Vec::new();
    for line in stderr.lines() {
        let Some(i) = line.find("setup check") else {
            continue;
        };
        let rest = &line[i..];
        let (Some(a), Some(b)) = (rest.find('['), rest.find(']')) else {
            continue;
        };
        if a < b {
            let warning = line[..i].contains("warning") || rest[..a].contains("accepted");
            out.push((warning, rest[a + 1..b].to_owned(), rest.to_owned()));
        }
    }
    out
}

/// Classes that name no cause: the residual nothing explains, an implausible estimate.
const NO_CAUSE: [&str; 2] = ["no-hypothesis", "implausible-estimate"];

/// Whether `word` occurs in `text` with no letter, digit or `_` on either side.
fn has_word(text: &str, word: &str) -> bool {
    if word.is_empty() {
        return false;
    }
    let bytes = text.as_bytes();
    let inner = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut from = 0;
    while let Some(i) = text[from..].find(word) {
        let s = from + i;
        let e = s + word.len();
        let before = s == 0 || !inner(bytes[s - 1]) || word.starts_with('-');
        let after = e >= bytes.len() || !inner(bytes[e]);
        if before && after {
            return true;
        }
        from = s + 1;
    }
    false
}

/// The flags of a fix (`--column-sign q3`, `use --tip l_link6`, `--gravity +z`): each
/// `--flag` with its value, from the fix's start (after a leading `use`); empty when the fix
/// is an edit in words.
pub fn fix_flags(fix: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let fix = fix.trim_start().strip_prefix("use ").unwrap_or(fix);
    let mut words = fix.split_whitespace().peekable();
    while let Some(w) = words.next() {
        let w = w.trim_end_matches([',', ';', ')']);
        if !w.starts_with("--") || w.len() < 3 {
            break;
        }
        match words.peek() {
            Some(v) if !v.starts_with("--") => {
                let v = v.trim_end_matches([',', ';', ')']).to_owned();
                words.next();
                out.push((w.to_owned(), v));
            }
            _ => out.push((w.to_owned(), String::new())),
        }
    }
    out
}

/// The fix of the finding that stopped a command: the text after the last `fix: ` of its
/// first error line, up to the option that accepts the data.
pub fn stop_fix(stderr: &str) -> Option<String> {
    let (_, _, text) = (findings_with_severity(stderr).into_iter()).find(|(w, _, _)| !w)?;
    // The finding's own fix is its last: an alternative that fits as well is named before it
    // with its fix in parentheses.
    let fix = text.rsplit_once("; fix: ")?.1;
    let fix = fix.split("; --accept-setup").next().unwrap_or(fix);
    Some(fix.trim().to_owned())
}

/// A case's arguments with a fix's flags applied: a flag that takes one value (`--tip`,
/// `--length-unit`, `--gravity`, `--socket-distance-m`, …) replaces the one given (every
/// `--tip` by the fix's tips), a column edit (`--column-…`) is added.
pub fn with_fix(args: &[String], flags: &[(String, String)]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let replaced = |f: &str| !f.starts_with("--column-") && flags.iter().any(|(g, _)| g == f);
    let mut i = 0;
    while i < args.len() {
        if replaced(&args[i]) {
            i += 2;
            continue;
        }
        out.push(args[i].clone());
        i += 1;
    }
    for (f, v) in flags {
        out.push(f.clone());
        if !v.is_empty() {
            out.push(v.clone());
        }
    }
    out
}

/// Whether a printed fix, applied, let the command run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FixApplied {
    /// No flag to apply (no stop, or a fix in words).
    NotApplicable,
    /// Applied, the command ran (exit 0 or 1).
    Ran,
    /// Applied, the command stopped again.
    StoppedAgain,
}

/// Judges a case by the command's exit code (`None`: killed or no code), its output
/// (standard error, then standard output) and, for a stop with a flag in its fix, what
/// applying the fix did (`applied`). `fix_words`: what the fix must name; `locate_words`:
/// words that place the mistake (a line, a column).
pub fn judge(
    family: Family,
    words: (&[Vec<String>], &[String]),
    code: Option<i32>,
    output: &str,
    applied: FixApplied,
) -> Outcome {
    let (fix_words, locate_words) = words;
    let found = findings_with_severity(output);
    let stopped = code != Some(0) && code != Some(1);
    let located = || (locate_words.iter()).any(|w| has_word(output, w));
    match family.spec().expect {
        Expect::Clean => {
            if found.is_empty() {
                Outcome::Clean
            } else {
                Outcome::FalseAlarm
            }
        }
        Expect::Listed => match (stopped, located()) {
            (false, true) => Outcome::NamedRight,
            (false, false) if found.is_empty() => Outcome::Silent,
            (false, false) => Outcome::Warned,
            (true, true) => Outcome::Located,
            (true, false) => Outcome::Generic,
        },
        Expect::Note(class) => {
            if stopped {
                if found.is_empty() {
                    Outcome::Generic
                } else {
                    Outcome::FalseAlarm
                }
            } else if found.iter().any(|(_, c, _)| c == class) {
                Outcome::NamedRight
            } else if found.is_empty() {
                Outcome::Silent
            } else {
                Outcome::Warned
            }
        }
        Expect::Stop(class, _) => {
            if !stopped {
                return if found.is_empty() {
                    Outcome::Silent
                } else {
                    Outcome::Warned
                };
            }
            let named =
                |text: &str| (fix_words.iter()).all(|any| any.iter().any(|w| has_word(text, w)));
            let errors: Vec<&(bool, String, String)> = found.iter().filter(|f| !f.0).collect();
            let right = (errors.iter()).find(|(_, c, _)| c == class);
            let wrong = (errors.iter()).find(|(_, c, _)| c != class && !NO_CAUSE.contains(&&**c));
            if let Some((_, _, text)) = right {
                if applied == FixApplied::StoppedAgain {
                    Outcome::HarmfulFix
                } else if named(text) {
                    Outcome::NamedRight
                } else {
                    Outcome::ClassOnly
                }
            } else if let Some((_, _, text)) = wrong {
                let fix = text.rsplit_once("; fix: ").map_or("", |f| f.1);
                if !fix_words.is_empty() && named(text) {
                    // The data fit the cause named and the expected one as well, and the
                    // finding names both (the expected fix as the alternative's).
                    Outcome::NamedRight
                } else if fix_flags(fix).is_empty() {
                    Outcome::WrongCause
                } else {
                    Outcome::HarmfulFix
                }
            } else if located() {
                Outcome::Located
            } else {
                Outcome::Generic
            }
        }
    }
}

/// One run case: the case, what it ran, its outcome and the first setup line (or the last
/// line of the standard error).
#[derive(Clone, Debug)]
pub struct CaseResult {
    /// The case.
    pub case: Case,
    /// Its outcome.
    pub outcome: Outcome,
    /// Exit code (`None`: none).
    pub code: Option<i32>,
    /// What the check said: the first setup line, else the first error line, else empty.
    pub said: String,
    /// Seconds the command took.
    pub seconds: f64,
    /// Whether the mistake leaves a trace a fit of the least model can see ([`Visibility`]).
    pub visibility: Visibility,
}

/// A mistake is *invisible in the data* when the screening fit's training residual on the
/// mistaken data is below this many times the one on the same data without the mistake: the
/// data carry no trace of it that a fit of the nominal model (frames only) could see.
pub const INVISIBLE_RATIO: f64 = 1.05;

/// The model of the screening fit (`hapcal calibrate --model`): the least one the data's kind
/// takes. Measurement files (markers, poses, positions): frames-only, the nominal kinematics
/// with the instrument's and markers' frames fitted. Socket folders and haptic logs take no
/// frames-only fit: geometric, which also fits joint offsets and link lengths (a zero off or
/// a longer link can be absorbed there).
pub fn screening_model(rec: Recording) -> ModelName {
    match rec {
        R::SocketsIiwa | R::SocketsPanda | R::Haptic | R::HapticMotion => ModelName::Geometric,
        _ => ModelName::FramesOnly,
    }
}

/// The arguments that turn a case's `hapcal calibrate` arguments into its screening fit:
/// the setup check accepted, the [`screening_model`], the report as JSON on standard output.
pub fn screening_args(rec: Recording) -> Vec<String> {
    vec![
        "--accept-setup".to_owned(),
        "--model".to_owned(),
        screening_model(rec).name().to_owned(),
        "--json".to_owned(),
    ]
}

/// The training residual of a calibration, read from `hapcal calibrate --json`: the figures
/// the data's kind has after the fit, each over the training sets (test sets left out).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Residual {
    /// RMS of the 3-D marker position error, m (marker and pose data).
    pub position_rms_m: Option<f64>,
    /// RMS orientation error, rad (pose data).
    pub orientation_rms_rad: Option<f64>,
    /// RMS distance error, m (distance rows, haptic logs).
    pub distance_rms_m: Option<f64>,
    /// Mean absolute error of the tips about their sockets ("consistency"), m (socket data).
    pub consistency_m: Option<f64>,
    /// Socket distance error ("distortion"), m (socket data with two sockets).
    pub socket_distance_error_m: Option<f64>,
}

impl Residual {
    /// Reads the training residual from the JSON report of `hapcal calibrate --json`
    /// (`placements[]` with `role`, `n_rows` and `after`). Over several training sets each
    /// figure is the row-weighted root mean square of the sets' figures.
    ///
    /// # Errors
    /// Text that is not JSON, or a report without a training set or without a figure.
    pub fn from_report_json(text: &str) -> Result<Residual> {
        let doc: serde_json::Value =
            serde_json::from_str(text).context("the calibration report is not JSON")?;
        let sets = (doc.get("placements"))
            .and_then(serde_json::Value::as_array)
            .context("the calibration report has no data sets")?;
        // Per figure: Σ n·v², Σ n.
        let mut acc = [(0.0f64, 0.0f64); 5];
        let mut n_train = 0;
        for set in sets {
            if set.get("role").and_then(serde_json::Value::as_str) != Some("train") {
                continue;
            }
            n_train += 1;
            let n = (set.get("n_rows").and_then(serde_json::Value::as_f64)).unwrap_or(1.0);
            let after = set.get("after");
            let at = |path: &[&str]| -> Option<f64> {
                let mut v = after?;
                for k in path {
                    v = v.get(*k)?;
                }
                v.as_f64()
            };
            let figures = [
                at(&["pose", "position_rms_m"]),
                at(&["pose", "orientation_rms_rad"]),
                at(&["pose", "distance_rms_m"]).or_else(|| at(&["distance_rms_m"])),
                at(&["mean_absolute_error_m"]),
                at(&["distance_error_m"]),
            ];
            for (a, f) in acc.iter_mut().zip(figures) {
                if let Some(v) = f {
                    a.0 += n * v * v;
                    a.1 += n;
                }
            }
        }
        if n_train == 0 {
            bail!("the calibration report has no training set");
        }
        let [p, o, d, c, s] = acc.map(|(sum, n)| (n > 0.0).then(|| (sum / n).sqrt()));
        let r = Residual {
            position_rms_m: p,
            orientation_rms_rad: o,
            distance_rms_m: d,
            consistency_m: c,
            socket_distance_error_m: s,
        };
        if r.figures().iter().all(Option::is_none) {
            bail!("the calibration report has no residual figure");
        }
        Ok(r)
    }

    /// The figures in a fixed order (position, orientation, distance, consistency, socket
    /// distance).
    fn figures(&self) -> [Option<f64>; 5] {
        [
            self.position_rms_m,
            self.orientation_rms_rad,
            self.distance_rms_m,
            self.consistency_m,
            self.socket_distance_error_m,
        ]
    }
}

/// How much larger the mistaken data's residual is than the correct data's: the largest
/// ratio over the figures both have (a mistake in the orientations alone shows in the
/// orientation RMS only). A figure zero on the correct data counts 1 if it is zero on the
/// mistaken data too, else infinity. `None`: no figure in common.
pub fn residual_ratio(mistaken: &Residual, correct: &Residual) -> Option<f64> {
    (mistaken.figures().into_iter())
        .zip(correct.figures())
        .filter_map(|(m, c)| Some((m?, c?)))
        .map(|(m, c)| {
            let (m, c) = (m.abs(), c.abs());
            if c > 0.0 {
                m / c
            } else if m > 0.0 {
                f64::INFINITY
            } else {
                1.0
            }
        })
        .reduce(f64::max)
}

/// Whether a mistake leaves a trace the screening fit can see.
#[derive(Clone, Debug, PartialEq)]
pub enum Visibility {
    /// Correct data: not screened.
    NotScreened,
    /// The mistaken data's residual over the correct data's ([`residual_ratio`]).
    Ratio(f64),
    /// The screening fit of the mistaken data failed (the reader or the fit refused them:
    /// the data show the mistake); the message's first line.
    MistakenFailed(String),
    /// The screening fit of the correct data failed, or the two have no figure in common:
    /// not decided, counted visible.
    Undecided(String),
}

impl Visibility {
    /// Screens a mistake from its two screening fits: the mistaken data's and the correct
    /// data's (`Err`: the fit's error message).
    pub fn screen(
        mistaken: &std::result::Result<Residual, String>,
        correct: &std::result::Result<Residual, String>,
    ) -> Visibility {
        match (mistaken, correct) {
            (_, Err(e)) => Visibility::Undecided(format!("correct data: {e}")),
            (Err(e), Ok(_)) => Visibility::MistakenFailed(e.clone()),
            (Ok(m), Ok(c)) => residual_ratio(m, c).map_or_else(
                || Visibility::Undecided("no residual figure in common".to_owned()),
                Visibility::Ratio,
            ),
        }
    }

    /// Whether the mistake is invisible in the data: a ratio below [`INVISIBLE_RATIO`].
    pub fn is_invisible(&self) -> bool {
        matches!(self, Visibility::Ratio(r) if *r < INVISIBLE_RATIO)
    }

    /// The ratio, or a word for the report (`fit failed`, `undecided`, `—` unscreened).
    pub fn cell(&self) -> String {
        match self {
            Visibility::NotScreened => "—".to_owned(),
            Visibility::Ratio(r) if *r >= 1e4 => format!("{r:.1e}"),
            Visibility::Ratio(r) if *r >= 10.0 => format!("{r:.0}"),
            Visibility::Ratio(r) => format!("{r:.3}"),
            Visibility::MistakenFailed(_) => "fit failed".to_owned(),
            Visibility::Undecided(_) => "undecided".to_owned(),
        }
    }
}

/// The case's data without its mistake: the same recording, rows (a part drops the same
/// fifth) and simulation seed, read as the recording is (its tips, socket distance).
pub fn correct_twin(case: &Case) -> Case {
    Case {
        id: twin_key(case),
        family: Family::AsIs,
        recording: case.recording,
        mistake: Mistake::None,
        seed: case.seed,
        part: case.part,
        half: case.half,
    }
}

/// The identity of a case's [`correct_twin`]: cases with the same key have the same correct
/// data (a recording's part 0 is the recording; a part or a simulation has its own seed).
pub fn twin_key(case: &Case) -> String {
    let rec = case.recording;
    let simulated = rec.sim_arm().is_some() || rec == R::HapticMotion;
    if simulated {
        format!("{}/seed{}", rec.name(), case.seed)
    } else if case.part > 0 {
        format!("{}/part{}/seed{}", rec.name(), case.part, case.seed)
    } else {
        rec.name().to_owned()
    }
}

/// What the check said, for the report: the first setup finding's line, else the first
/// line with `error`, else the last line.
pub fn what_was_said(stderr: &str) -> String {
    if let Some((_, line)) = findings(stderr).into_iter().next() {
        return line;
    }
    (stderr.lines().find(|l| l.contains("error")))
        .or_else(|| stderr.lines().last())
        .unwrap_or_default()
        .trim()
        .to_owned()
}

/// Counts per outcome.
fn counts<'a>(results: impl Iterator<Item = &'a CaseResult>) -> BTreeMap<Outcome, usize> {
    let mut m = BTreeMap::new();
    for r in results {
        *m.entry(r.outcome).or_insert(0) += 1;
    }
    m
}

/// Whether a case is a visible mistake: a mistake family (not correct data) whose screening
/// did not find it invisible ([`Visibility::is_invisible`]).
pub fn is_visible_mistake(r: &CaseResult) -> bool {
    !r.case.family.is_correct() && !r.visibility.is_invisible()
}

/// The figures the lead quotes for one selection of cases: over visible mistakes, how many
/// the check named, located, named wrongly, gave a harmful fix for, and was silent on; over
/// the cases where a finding or a stop is a false alarm (correct data, and visible mistakes
/// of a note family), how many.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VisibleSummary {
    /// Visible mistakes (stop, note and listed families).
    pub n_visible: usize,
    /// Of them, named (the class right, [`Outcome::is_named`]).
    pub named: usize,
    /// Of them, located without a cause.
    pub located: usize,
    /// Of them, another cause named with a fix in words.
    pub wrong_cause: usize,
    /// Of them, a harmful fix.
    pub harmful: usize,
    /// Of them, silent.
    pub silent: usize,
    /// False alarms.
    pub false_alarms: usize,
    /// Cases a false alarm is possible on: correct data and visible note-family mistakes.
    pub n_alarm_cases: usize,
}

impl VisibleSummary {
    /// Counts `results`.
    pub fn of<'a>(results: impl IntoIterator<Item = &'a CaseResult>) -> VisibleSummary {
        let mut s = VisibleSummary {
            n_visible: 0,
            named: 0,
            located: 0,
            wrong_cause: 0,
            harmful: 0,
            silent: 0,
            false_alarms: 0,
            n_alarm_cases: 0,
        };
        for r in results {
            let visible = is_visible_mistake(r);
            let note = matches!(r.case.family.spec().expect, Expect::Note(_));
            if visible {
                s.n_visible += 1;
                s.named += usize::from(r.outcome.is_named());
                s.located += usize::from(r.outcome == Outcome::Located);
                s.wrong_cause += usize::from(r.outcome == Outcome::WrongCause);
                s.harmful += usize::from(r.outcome == Outcome::HarmfulFix);
                s.silent += usize::from(r.outcome == Outcome::Silent);
            }
            if r.case.family.is_correct() || (visible && note) {
                s.n_alarm_cases += 1;
                s.false_alarms += usize::from(r.outcome == Outcome::FalseAlarm);
            }
        }
        s
    }

    /// One line: `visible mistakes N, named X (x %), located …, named or located (z %), wrong
    /// cause W, harmful fixes H, silent S (s %), false alarms F of G`.
    pub fn line(&self) -> String {
        let pct = |k: usize| {
            if self.n_visible == 0 {
                "—".to_owned()
            } else {
                format!("{:.0} %", 100.0 * k as f64 / self.n_visible as f64)
            }
        };
        format!(
            "visible mistakes {}, named {} ({}), located {} ({}), named or located {}, wrong \
             cause {}, harmful fixes {}, silent {} ({}), false alarms {} of {}",
            self.n_visible,
            self.named,
            pct(self.named),
            self.located,
            pct(self.located),
            pct(self.named + self.located),
            self.wrong_cause,
            self.harmful,
            self.silent,
            pct(self.silent),
            self.false_alarms,
            self.n_alarm_cases
        )
    }
}

/// The outcomes in the order of the report's columns.
const OUTCOME_COLUMNS: [Outcome; 10] = [
    Outcome::NamedRight,
    Outcome::ClassOnly,
    Outcome::Located,
    Outcome::WrongCause,
    Outcome::HarmfulFix,
    Outcome::Generic,
    Outcome::Warned,
    Outcome::Silent,
    Outcome::FalseAlarm,
    Outcome::Clean,
];

/// One table of counts per family (and a total row) over `sel`.
fn family_table(s: &mut String, sel: &[&CaseResult]) {
    let _ = writeln!(
        s,
        "| family | expected | cases | named right | class only | located | wrong cause | harmful fix | generic | warned | silent | false alarm | clean |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut total: BTreeMap<Outcome, usize> = BTreeMap::new();
    for spec in FAMILIES {
        let fam: Vec<&CaseResult> = (sel.iter().copied())
            .filter(|r| r.case.family == spec.family)
            .collect();
        if fam.is_empty() {
            continue;
        }
        let c = counts(fam.iter().copied());
        for (k, v) in &c {
            *total.entry(*k).or_insert(0) += v;
        }
        let expected = match spec.expect {
            Expect::Stop(class, _) => format!("stop [{class}]"),
            Expect::Note(class) => format!("note [{class}]"),
            Expect::Clean => "nothing".to_owned(),
            Expect::Listed => "the row listed".to_owned(),
        };
        let cells: Vec<String> = (OUTCOME_COLUMNS.iter())
            .map(|o| c.get(o).copied().unwrap_or(0).to_string())
            .collect();
        let _ = writeln!(
            s,
            "| {} | {expected} | {} | {} |",
            spec.name,
            fam.len(),
            cells.join(" | ")
        );
    }
    let cells: Vec<String> = (OUTCOME_COLUMNS.iter())
        .map(|o| total.get(o).copied().unwrap_or(0).to_string())
        .collect();
    let _ = writeln!(s, "| **all** | | {} | {} |\n", sel.len(), cells.join(" | "));
}

/// What the check said, for a table cell: 150 characters, no `|` or backquote.
fn said_cell(r: &CaseResult) -> String {
    let said: String = r.said.chars().take(150).collect();
    said.replace('|', "\\|").replace('`', "'")
}

/// The report page (markdown): how visibility is decided and the figures over visible
/// mistakes per half; per family and half the counts over all cases, then over visible
/// mistakes; the invisible mistakes; every case not named right (or a false alarm) with what
/// the check said; every mistake's ratio.
pub fn report_markdown(results: &[CaseResult], command: &str, machine: &str) -> String {
    let mut s = String::new();
    write_report_intro(&mut s, command, machine);
    write_visible_summaries(&mut s, results);
    write_family_tables(&mut s, results);
    write_invisible_mistakes(&mut s, results);
    write_not_named_right(&mut s, results);
    write_every_ratio(&mut s, results);
    s
}

/// The report's title, what the outcomes mean, how visibility is screened, and the command
/// and machine of the run.
fn write_report_intro(s: &mut String, command: &str, machine: &str) {
    let frames = ModelName::FramesOnly.name();
    let geometric = ModelName::Geometric.name();
    let _ = writeln!(s, "# Setup check: the hostile sweep\n");
    let _ = writeln!(
        s,
        "Ordinary setup mistakes the check was not built on, written into the bundled \
         recordings and simulated ones (crates/studies/src/setup_hostile.rs has the table of \
         expectations), run through `hapcal calibrate` as a user runs it and judged only by \
         its exit code and what it prints. A mistake is *named right* when the command stops \
         (exit 2) with `setup check [<expected class>]` and the fix names the cause (the \
         column, the factor's unit, the flag, the line); *class only* when the class is right \
         but the fix does not name the cause; *located* when it stops without naming a cause \
         (`no-hypothesis`, an implausible estimate, the reader's error) but names the rows \
         (within two lines) or the column of the mistake; *wrong cause* when it stops naming \
         another cause whose fix is an edit in words; *harmful fix* when it stops naming \
         another cause with a flag to apply, or names the right cause with a flag that, \
         applied to the same command, stops it again (every flag a stop prints is applied and \
         the command rerun); *generic* when it stops otherwise; *warned* when it runs with a \
         setup warning; *silent* when it runs with none. On correct data any setup finding is \
         a *false alarm*. The glitch-row family (one joint reading 0.2 rad off) expects the \
         calibration to run and list the row (file:line) it bounded or left out; it is named \
         right when it does, located when it stops naming the row. The latency family expects \
         a note or warning \
         of class `{LATENCY_CLASS}`, and a stop on it is a false alarm.\n"
    );
    let _ = writeln!(
        s,
        "**Visibility.** A mistake may leave no trace in the data (the zero of a positioner's \
         joint absorbed by the fitted frames, the sign of a last joint whose axis passes \
         through the marker). Each mistake is screened without the check's code: \
         `hapcal calibrate <the case's arguments> --accept-setup --model {frames} --json` \
         (`--model {geometric}` for socket folders and haptic logs, the least model they \
         take; it also fits joint offsets and link lengths) is run on the mistaken data and \
         on the same data without the mistake (the same rows, the same simulation seed, the \
         recording's tips and socket distance). The ratio is the mistaken data's training \
         residual over the correct data's, the largest over the figures both reports have \
         (position RMS, orientation RMS, distance RMS, socket consistency, socket distance \
         error). A mistake is *invisible in the data* when the ratio is below \
         {INVISIBLE_RATIO}; a mistake whose screening fit fails (the reader refuses a reading \
         past a joint limit, the fit fails) is visible. The tables over all cases stay on \
         the page; the tables over visible mistakes follow them, with the correct data \
         unchanged.\n"
    );
    let _ = writeln!(s, "Command: `{command}`  ");
    let _ = writeln!(s, "Machine: {machine}\n");
}

/// Per half, and within it for the earlier and the newer families: the one-line summary over
/// visible mistakes ([`VisibleSummary::line`]).
fn write_visible_summaries(s: &mut String, results: &[CaseResult]) {
    let _ = writeln!(s, "## Over visible mistakes\n");
    for half in [Half::Tuning, Half::HeldBack] {
        let sum = VisibleSummary::of(results.iter().filter(|r| r.case.half == half));
        let _ = writeln!(s, "- {} half: {}", half.name(), sum.line());
        for (name, sel) in [
            ("families of earlier sweeps", false),
            (
                "families added with the change-point, scale and coupling hypotheses",
                true,
            ),
        ] {
            let sum = VisibleSummary::of(
                (results.iter()).filter(|r| r.case.half == half && r.case.family.is_new() == sel),
            );
            let _ = writeln!(s, "  - {name}: {}", sum.line());
        }
    }
    let _ = writeln!(
        s,
        "\nFalse alarms are counted over the correct data and the visible mistakes of the \
         latency family (a stop on them is a false alarm).\n"
    );
}

/// The family tables over all cases and per half, then per half over the visible mistakes
/// and the correct data.
fn write_family_tables(s: &mut String, results: &[CaseResult]) {
    let halves = [
        ("All cases", None),
        ("Tuning half", Some(Half::Tuning)),
        ("Held-back half", Some(Half::HeldBack)),
    ];
    for (title, filter) in halves {
        let sel: Vec<&CaseResult> = (results.iter())
            .filter(|r| filter.is_none_or(|h| r.case.half == h))
            .collect();
        let _ = writeln!(s, "## {title} ({} cases)\n", sel.len());
        family_table(s, &sel);
    }
    for (title, half) in [
        ("Tuning half", Half::Tuning),
        ("Held-back half", Half::HeldBack),
    ] {
        let sel: Vec<&CaseResult> = (results.iter())
            .filter(|r| {
                r.case.half == half && (r.case.family.is_correct() || is_visible_mistake(r))
            })
            .collect();
        let n_visible = sel.iter().filter(|r| !r.case.family.is_correct()).count();
        let _ = writeln!(
            s,
            "## {title}, visible mistakes only ({n_visible} mistakes, {} correct)\n",
            sel.len() - n_visible
        );
        family_table(s, &sel);
    }
}

/// The table of the mistakes invisible in the data, with their ratio and outcome.
fn write_invisible_mistakes(s: &mut String, results: &[CaseResult]) {
    let invisible: Vec<&CaseResult> = (results.iter())
        .filter(|r| !r.case.family.is_correct() && r.visibility.is_invisible())
        .collect();
    let _ = writeln!(s, "## Invisible mistakes ({})\n", invisible.len());
    let _ = writeln!(
        s,
        "Mistakes whose data fit as well as the correct data (ratio below {INVISIBLE_RATIO}): \
         case, half, screening model, ratio, outcome, and what the check said.\n"
    );
    let _ = writeln!(s, "| case | half | model | ratio | outcome | said |");
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for r in &invisible {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            r.case.id,
            r.case.half.name(),
            screening_model(r.case.recording).name(),
            r.visibility.cell(),
            r.outcome.name(),
            said_cell(r)
        );
    }
    let _ = writeln!(s);
}

/// The table of the mistakes not named right and of the false alarms.
fn write_not_named_right(s: &mut String, results: &[CaseResult]) {
    let _ = writeln!(s, "## Cases not named right\n");
    let _ = writeln!(
        s,
        "Mistakes not named right and false alarms: case, half, expected, outcome, exit code, \
         visibility ratio, and what the check said (first setup line, else the error; 150 \
         characters).\n"
    );
    let _ = writeln!(
        s,
        "| case | half | expected | outcome | exit | ratio | said |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for r in results {
        if matches!(r.outcome, Outcome::NamedRight | Outcome::Clean) {
            continue;
        }
        let expected = match r.case.family.spec().expect {
            Expect::Stop(class, _) | Expect::Note(class) => class.to_owned(),
            Expect::Clean => "nothing".to_owned(),
            Expect::Listed => "the row listed".to_owned(),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {expected} | {} | {} | {} | {} |",
            r.case.id,
            r.case.half.name(),
            r.outcome.name(),
            r.code.map_or("none".to_owned(), |c| c.to_string()),
            r.visibility.cell(),
            said_cell(r)
        );
    }
    let _ = writeln!(s);
}

/// The table of every mistake's screening: its ratio, or why there is none.
fn write_every_ratio(s: &mut String, results: &[CaseResult]) {
    let _ = writeln!(s, "## Every mistake's ratio\n");
    let _ = writeln!(
        s,
        "The screening of every mistake: case, half, screening model, ratio (or why there is \
         none: the mistaken data's fit failed, or the correct data's), outcome.\n"
    );
    let _ = writeln!(s, "| case | half | model | ratio | outcome |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    for r in results.iter().filter(|r| !r.case.family.is_correct()) {
        let why = match &r.visibility {
            Visibility::MistakenFailed(e) | Visibility::Undecided(e) => {
                let e: String = e.chars().take(140).collect();
                format!(" ({})", e.replace('|', "\\|").replace('`', "'"))
            }
            _ => String::new(),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}{why} | {} |",
            r.case.id,
            r.case.half.name(),
            screening_model(r.case.recording).name(),
            r.visibility.cell(),
            r.outcome.name(),
        );
    }
}
