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

mod judge;
mod report;
mod table;
mod write;
pub use judge::*;
pub use report::*;
pub use table::*;
pub use write::*;

/// The units a column or every length may be written in by mistake: the readers' own
/// (`--angle-unit`, `--length-unit`, `--column-unit` take their symbols).
pub use hapcal_io::{AngleUnit, LengthUnit};

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
            Mistake::ColumnUnit { col, unit } => format!("col{col}-{}", unit.symbol()),
            Mistake::AllDegrees => "deg".to_owned(),
            Mistake::Lengths(u) => u.symbol().to_owned(),
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
