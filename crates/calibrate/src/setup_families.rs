//! The hypotheses every setup check draws from: a few general families of mistake, generated
//! once for every kind of data (measurement files, socket folders, a haptic device's logs).
//!
//! A kind of data says what it holds (its `Layout`: joint columns as the files name them,
//! length columns, the units it was read with, the arms of a tree) and how to correct it
//! (`SetupData`); `general_hypotheses` turns that into hypotheses of
//!
//! - **units** ([`Family::Units`]): every angle unit (rad, deg, grad, rev) for the whole file
//!   and for each joint column, every length unit (m, mm, cm, in, ft) for the whole file and for
//!   each length column group (one marker's positions, the distances);
//! - **scales and couplings** (also [`Family::Units`]): each revolute joint column read times a
//!   factor of the usual suspects (`scale_suspects`: a motor-side reading through a gear of
//!   50 to 160, encoder counts of 2¹⁰ to 2²⁴ per revolution, and their inverses; factors equal
//!   to an angle unit's are left to the units), times a free factor near 1 (a gear ratio a few
//!   per cent off), or plus a free multiple of another joint column (`q_j + c·q_k`, a coupled
//!   wrist; every pair up to 8 joints, the adjacent ones past it). The free
//!   factor and coefficient are estimated by a 1-D search of the check's screening residual
//!   (`fitted_hypotheses`): a grid, then a golden-section search about its best point;
//! - **signs** ([`Family::Sign`]): each joint column negated (an encoder counting the other
//!   way);
//! - **zeros** ([`Family::Zero`]): each revolute joint's zero off by ±90° or 180°;
//! - **permutations** ([`Family::Permutation`]): any two joint columns of one kind swapped,
//!   every joint column reversed, one arm's columns given as another's;
//! - **row alignment** ([`Family::RowAlignment`]): joint readings 1 to 4 rows out of step, for
//!   the whole file or from the row on where the per-row residuals jump, and rows whose joints
//!   and measurements do not belong together, found from the per-row residuals
//!   (`row_hypotheses`).
//!
//! The families a kind adds itself (frames and conventions of pose data, tips and sockets)
//! are its own; [`DataKind::families`] lists, for each kind, every family it must generate and
//! why the others cannot apply, and a test fails when a kind misses one.
//!
//! The per-column families multiply the hypotheses by the joint count: they are
//! `Tier::Suspicious`, generated only when the data as given leave more than right data of a
//! real robot do ([`Residual::is_clean`]), so that the check of right data costs what it did.
//! A free factor or coefficient lowers the residual of right data by what the one parameter
//! absorbs of the noise and of the manufacturing deviations, which on a real robot's socket
//! scatter can be a factor of 3: the free hypotheses are tried only on suspicious data, and one
//! is kept only when it leaves what right data leave ([`Residual::is_clean`]) and divides the
//! residual by [`crate::setup_findings::OVERWHELMING_FACTOR`] or more.

use crate::setup_findings::{Corrected, MistakeClass, OVERWHELMING_FACTOR, Residual, ResidualFn};

/// A general family of setup mistakes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Family {
    /// A unit or scale: angle columns in deg, grad or rev, lengths in mm, cm, in or ft, for the
    /// whole file or one column; a joint column read times a gear ratio, in encoder counts or
    /// plus a multiple of another joint's.
    Units,
    /// One joint column's sign reversed.
    Sign,
    /// One joint's zero off by a multiple of 90°.
    Zero,
    /// Joint columns in another order: a pair swapped, all reversed, arms exchanged.
    Permutation,
    /// Joint rows out of step with the measurement rows, or rows that do not belong together.
    RowAlignment,
    /// Frames and conventions of pose data: quaternion order and conjugate, Euler orders,
    /// mirrored axes, inverted poses.
    Conventions,
    /// Tip links and sockets: the tip link, tips swapped, the socket distance, rows filed under
    /// the wrong socket.
    TipsAndSockets,
    /// Another device or robot: calibrated deviations beyond manufacturing tolerance (judged
    /// after the fit).
    AnotherDevice,
}

impl Family {
    /// Every family.
    pub const ALL: [Family; 8] = [
        Family::Units,
        Family::Sign,
        Family::Zero,
        Family::Permutation,
        Family::RowAlignment,
        Family::Conventions,
        Family::TipsAndSockets,
        Family::AnotherDevice,
    ];

    /// The family's name in reports and tests.
    pub fn name(self) -> &'static str {
        match self {
            Family::Units => "units",
            Family::Sign => "sign",
            Family::Zero => "zero",
            Family::Permutation => "permutation",
            Family::RowAlignment => "row alignment",
            Family::Conventions => "frames and conventions",
            Family::TipsAndSockets => "tips and sockets",
            Family::AnotherDevice => "another device",
        }
    }
}

impl MistakeClass {
    /// The family a class of mistake belongs to; `None` for findings from the data alone (a
    /// frozen joint) and for the residual nothing explains.
    pub fn family(self) -> Option<Family> {
        use MistakeClass as C;
        Some(match self {
            C::LengthUnit
            | C::AngleUnit
            | C::OrientationUnit
            | C::ColumnUnit
            | C::ColumnScale
            | C::ColumnCoupling => Family::Units,
            C::ColumnSign => Family::Sign,
            C::ColumnZero => Family::Zero,
            C::JointOrder => Family::Permutation,
            C::RowShift | C::RowMismatch | C::Latency => Family::RowAlignment,
            C::QuaternionOrder | C::QuaternionInverse | C::EulerOrder | C::MirroredAxis => {
                Family::Conventions
            }
            C::TipLink | C::SwappedTips | C::SocketDistance | C::WrongSocket => {
                Family::TipsAndSockets
            }
            C::AnotherDevice => Family::AnotherDevice,
            // Found on the data alone, or on the calibrated estimate after the fit: no
            // hypothesis of the check before it corrects the data.
            C::FrozenJoint | C::NoHypothesis | C::Mounting | C::ImplausibleEstimate => {
                return None;
            }
        })
    }
}

/// A kind of data the setup check corrects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataKind {
    /// Measurement files (marker positions, poses, distances) of a URDF or a D-H device.
    MeasurementFiles,
    /// Socket folders (a tip held in sockets a known distance apart).
    SocketFolders,
    /// A haptic device's logs (joint readings, cable distance, external encoders).
    HapticLogs,
}

impl DataKind {
    /// Every kind.
    pub const ALL: [DataKind; 3] = [
        DataKind::MeasurementFiles,
        DataKind::SocketFolders,
        DataKind::HapticLogs,
    ];

    /// The families the kind's check generates before the fit, and, for each family it does
    /// not, why none of its mistakes can occur in (or be told from) such data.
    pub fn families(self) -> (&'static [Family], &'static [(Family, &'static str)]) {
        const AFTER_FIT: &str = "judged after the fit, on the calibrated deviations";
        match self {
            DataKind::MeasurementFiles => (
                &[
                    Family::Units,
                    Family::Sign,
                    Family::Zero,
                    Family::Permutation,
                    Family::RowAlignment,
                    Family::Conventions,
                    Family::TipsAndSockets,
                ],
                &[(Family::AnotherDevice, AFTER_FIT)],
            ),
            DataKind::SocketFolders => (
                &[
                    Family::Units,
                    Family::Sign,
                    Family::Zero,
                    Family::Permutation,
                    Family::TipsAndSockets,
                ],
                &[
                    (
                        Family::RowAlignment,
                        "a socket file's rows pair no joint reading with a measurement; rows \
                         filed under the wrong socket are found from the data (tips and sockets)",
                    ),
                    (
                        Family::Conventions,
                        "socket files hold joint readings only: no instrument frame, no \
                         orientation",
                    ),
                    (Family::AnotherDevice, AFTER_FIT),
                ],
            ),
            DataKind::HapticLogs => (
                &[
                    Family::Units,
                    Family::Sign,
                    Family::Zero,
                    Family::Permutation,
                    Family::RowAlignment,
                ],
                &[
                    (
                        Family::Conventions,
                        "a cable distance has no frame, orientation or axis convention",
                    ),
                    (
                        Family::TipsAndSockets,
                        "the cable is fixed to the device's handle: no tip to choose, no socket",
                    ),
                    (Family::AnotherDevice, AFTER_FIT),
                ],
            ),
        }
    }
}

/// An angle unit a column may be in: name (as `--column-unit` takes it), words, rad per unit.
pub(crate) const ANGLE_UNITS: [(&str, &str, f64); 4] = [
    ("rad", "radians", 1.0),
    ("deg", "degrees", std::f64::consts::PI / 180.0),
    ("grad", "gradians", std::f64::consts::PI / 200.0),
    ("rev", "revolutions", std::f64::consts::TAU),
];

/// A length unit a column may be in: name (as `--length-unit` and `--column-unit` take it),
/// words, m per unit.
pub(crate) const LENGTH_UNITS: [(&str, &str, f64); 5] = [
    ("m", "metres", 1.0),
    ("mm", "millimetres", 1e-3),
    ("cm", "centimetres", 1e-2),
    ("in", "inches", 0.0254),
    ("ft", "feet", 0.3048),
];

/// Joint zeros tried: +90°, −90°, 180°.
const ZERO_OFFSETS: [f64; 3] = [
    std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
    std::f64::consts::PI,
];

/// Gear ratios a joint may be read through on its motor side.
const GEAR_RATIOS: [f64; 6] = [50.0, 80.0, 100.0, 101.0, 120.0, 160.0];

/// Encoder resolutions a joint may be read in, as powers of two counts per revolution.
const ENCODER_BITS: std::ops::RangeInclusive<i32> = 10..=24;

/// Relative distance from an angle unit's factor within which a suspected scale is left to
/// the units (the unit names the mistake better).
const UNIT_CLASH: f64 = 0.02;

/// The range of a free scale (true angle per reading) searched: a gear ratio up to a fifth
/// off.
const FREE_SCALE: (f64, f64) = (0.8, 1.25);

/// The range of a free coupling coefficient searched.
const FREE_COUPLING: (f64, f64) = (-1.5, 1.5);

/// Points of the coarse grid of a 1-D search, and golden-section steps about its best point
/// (each shrinks the bracket by 0.618: 18 steps take two grid steps to 1.7e-4 of them).
const GRID_POINTS: usize = 13;
const GOLDEN_STEPS: usize = 18;

/// Row shifts tried always (±1, ±2 rows) and when the data are suspicious (±3, ±4).
const SHIFTS_ALWAYS: [isize; 4] = [-2, -1, 1, 2];
const SHIFTS_SUSPICIOUS: [isize; 4] = [-4, -3, 3, 4];

/// Joint counts up to which every pair of joint columns is tried always; past it, the
/// adjacent pairs always and the others when the data are suspicious.
const ALL_PAIRS_UP_TO: usize = 8;

/// Per-row residual, as a multiple of the median row's, above which a row does not belong
/// with its measurement: the per-row residuals of right data (a 3-D noise vector and smooth
/// model deviations) stay within about 4 medians.
const MISMATCH_FACTOR: f64 = 8.0;

/// Share of rows the row-mismatch hypothesis may set aside: more is not a few rows that do
/// not belong, but a shift or data of another robot.
const MISMATCH_MAX_SHARE: f64 = 0.45;

/// A joint column, as the files name it.
#[derive(Clone, Debug)]
pub(crate) struct JointColumn {
    /// The column's name in the files (`q3`, `elbow_joint`): what the flags take.
    pub(crate) label: String,
    /// In words: `elbow_joint (q3)`.
    pub(crate) words: String,
    /// A revolute joint (angle unit, zero offsets), or prismatic (length unit).
    pub(crate) revolute: bool,
}

/// A group of length columns read in one unit: one marker's positions, the distances.
#[derive(Clone, Debug)]
pub(crate) struct LengthGroup {
    /// The columns as `--column-unit` takes them: `x2,y2,z2`, `distance_m`.
    pub(crate) label: String,
    /// In words: `marker 2's positions`.
    pub(crate) words: String,
}

/// What a kind of data holds, as the generator needs it.
#[derive(Clone, Debug, Default)]
pub(crate) struct Layout {
    /// Joint columns, in the order of the joint readings.
    pub(crate) joints: Vec<JointColumn>,
    /// Length column groups; empty without measured lengths.
    pub(crate) lengths: Vec<LengthGroup>,
    /// The angle unit the files were read with (a name of [`ANGLE_UNITS`]).
    pub(crate) angle_unit: &'static str,
    /// The length unit the files were read with (a name of [`LENGTH_UNITS`]).
    pub(crate) length_unit: &'static str,
    /// The whole file's units as a flag (`--angle-unit`, `--length-unit`) or `None` where the
    /// data have no such flag (then the fix names the conversion).
    pub(crate) file_flags: bool,
    /// The joints of each arm of a tree that no other arm moves, in chain order; empty for a
    /// chain.
    pub(crate) arms: Vec<(String, Vec<usize>)>,
    /// Joint rows: whether the rows pair joint readings with measurements (row alignment
    /// applies).
    pub(crate) paired_rows: bool,
}

/// How a kind of data is corrected; each method returns the data as the correction reads them.
pub(crate) trait SetupData: Sized + Send + Sync {
    /// Every row's joint readings (rad, m) edited by `f`.
    fn with_joints(&self, f: &(dyn Fn(&mut [f64]) + Sync)) -> Self;
    /// Every length of `group` (every length with `None`) times `factor`.
    fn with_lengths(&self, group: Option<usize>, factor: f64) -> Self;
    /// Each row's joint readings taken from the row `shift` further down its file (rows
    /// without a partner dropped), from row `from` of file `file` on (`None`: every row of
    /// every file); `None` when too few rows are left.
    fn with_shift(&self, shift: isize, from: Option<(usize, u64)>) -> Option<Self>;
}

/// When a hypothesis is generated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tier {
    /// Always: a handful per data set.
    Always,
    /// Only when the data as given leave more than right data do: the per-column families.
    Suspicious,
}

/// The hypotheses of the general families of `tier` for `data` laid out as `layout`.
pub(crate) fn general_hypotheses<D: SetupData>(
    data: &D,
    layout: &Layout,
    tier: Tier,
) -> Vec<Corrected<D>> {
    let mut out = Vec::new();
    match tier {
        Tier::Always => file_units(data, layout, &mut out),
        Tier::Suspicious => {
            column_units(data, layout, &mut out);
            column_scales(data, layout, &mut out);
            signs_and_zeros(data, layout, &mut out);
        }
    }
    permutations(data, layout, tier, &mut out);
    whole_file_shifts(data, layout, tier, &mut out);
    out
}

/// The units of the whole file: every angle in each unit other than the one read, every
/// length likewise.
fn file_units<D: SetupData>(data: &D, layout: &Layout, out: &mut Vec<Corrected<D>>) {
    let joints = &layout.joints;
    let any_revolute = joints.iter().any(|c| c.revolute);
    if any_revolute {
        for (unit, words, factor, ratio) in others(&ANGLE_UNITS, layout.angle_unit) {
            let fix = if layout.file_flags {
                format!("--angle-unit {unit}")
            } else {
                format!(
                    "convert the joint readings to radians (multiply by {})",
                    factor_text(factor)
                )
            };
            out.push(Corrected::new(
                MistakeClass::AngleUnit,
                format!(
                    "the joint readings are in {words}, read as {}",
                    unit_words(&ANGLE_UNITS, layout.angle_unit)
                ),
                fix,
                data.with_joints(&|q: &mut [f64]| {
                    for (v, c) in q.iter_mut().zip(joints) {
                        if c.revolute {
                            *v *= ratio;
                        }
                    }
                }),
            ));
        }
    }
    if !layout.lengths.is_empty() {
        for (unit, words, factor, ratio) in others(&LENGTH_UNITS, layout.length_unit) {
            out.push(Corrected::new(
                MistakeClass::LengthUnit,
                format!(
                    "the positions and distances are in {words}, read as {}",
                    unit_words(&LENGTH_UNITS, layout.length_unit)
                ),
                if layout.file_flags {
                    format!("--length-unit {unit}")
                } else {
                    format!(
                        "convert the lengths to metres (multiply by {})",
                        factor_text(factor)
                    )
                },
                data.with_lengths(None, ratio),
            ));
        }
    }
}

/// The unit of each revolute joint's column, and of each group of lengths where a file holds
/// several.
fn column_units<D: SetupData>(data: &D, layout: &Layout, out: &mut Vec<Corrected<D>>) {
    let joints = &layout.joints;
    for (j, c) in joints.iter().enumerate().filter(|(_, c)| c.revolute) {
        for (unit, words, _, ratio) in others(&ANGLE_UNITS, layout.angle_unit) {
            out.push(Corrected::new(
                MistakeClass::ColumnUnit,
                format!(
                    "the readings of {} are in {words}, read as {}",
                    c.words,
                    unit_words(&ANGLE_UNITS, layout.angle_unit)
                ),
                format!("--column-unit {}={unit}", c.label),
                data.with_joints(&|q: &mut [f64]| {
                    if let Some(v) = q.get_mut(j) {
                        *v *= ratio;
                    }
                }),
            ));
        }
    }
    if layout.lengths.len() > 1 {
        for (g, group) in layout.lengths.iter().enumerate() {
            for (unit, words, _, ratio) in others(&LENGTH_UNITS, layout.length_unit) {
                out.push(Corrected::new(
                    MistakeClass::LengthUnit,
                    format!(
                        "{} are in {words}, read as {} as the other lengths",
                        group.words,
                        unit_words(&LENGTH_UNITS, layout.length_unit)
                    ),
                    format!("--column-unit {}={unit}", group.label),
                    data.with_lengths(Some(g), ratio),
                ));
            }
        }
    }
}

/// The factors (reading per true angle) a joint column is suspected to be read with, each
/// with its words: a motor-side reading through each of [`GEAR_RATIOS`], encoder counts of
/// 2ⁿ per revolution for n in [`ENCODER_BITS`], and their inverses; none within [`UNIT_CLASH`]
/// of an angle unit's factor relative to `read` (a column in degrees is a unit's mistake).
pub(crate) fn scale_suspects(read: &'static str) -> Vec<(f64, String)> {
    let mut out = Vec::new();
    for r in GEAR_RATIOS {
        out.push((r, format!("a motor-side reading through a {r}:1 gear?")));
        out.push((1.0 / r, format!("the angle divided by a {r}:1 gear?")));
    }
    for n in ENCODER_BITS {
        let k = 2f64.powi(n) / std::f64::consts::TAU;
        out.push((k, format!("encoder counts, 2^{n} per revolution?")));
        out.push((1.0 / k, format!("the angle divided by 2^{n}/2π?")));
    }
    let clashes = |k: f64| {
        others(&ANGLE_UNITS, read).any(|(.., ratio)| {
            [ratio, 1.0 / ratio]
                .iter()
                .any(|u| (k / u - 1.0).abs() < UNIT_CLASH)
        })
    };
    out.retain(|(k, _)| !clashes(*k));
    out
}

/// A factor as a flag takes it: ten significant digits, in the shortest form that reads back
/// (`0.01`, `0.00004793689962`).
fn flag_number(v: f64, digits: usize) -> String {
    let rounded: f64 = format!("{v:.*e}", digits.saturating_sub(1))
        .parse()
        .unwrap_or(v);
    format!("{rounded}")
}

/// A factor (reading per true angle) in words: `100`, `20861`, `1/100`, `1.050`.
fn factor_words(k: f64) -> String {
    let whole = |v: f64| {
        if (v - v.round()).abs() < 1e-9 * v || v >= 100.0 {
            format!("{v:.0}")
        } else {
            format!("{v:.3}")
        }
    };
    if k >= 1.0 {
        format!("{} ×", whole(k))
    } else {
        format!("1/{} of", whole(1.0 / k))
    }
}

/// The mistake and the fix of `c` read as `k` times its joint's angle (`why` in words).
fn scale_words(c: &JointColumn, k: f64, why: &str, digits: usize) -> (String, String) {
    (
        format!(
            "{} reads {} the joint angle ({why})",
            c.label,
            factor_words(k)
        ),
        format!(
            "--column-scale {}={}",
            c.label,
            flag_number(1.0 / k, digits)
        ),
    )
}

/// Each revolute joint column read times each factor of [`scale_suspects`].
fn column_scales<D: SetupData>(data: &D, layout: &Layout, out: &mut Vec<Corrected<D>>) {
    let suspects = scale_suspects(layout.angle_unit);
    for (j, c) in layout.joints.iter().enumerate().filter(|(_, c)| c.revolute) {
        for (k, why) in &suspects {
            let (what, fix) = scale_words(c, *k, why, 10);
            let s = 1.0 / k;
            out.push(Corrected::new(
                MistakeClass::ColumnScale,
                what,
                fix,
                data.with_joints(&|q: &mut [f64]| {
                    if let Some(v) = q.get_mut(j) {
                        *v *= s;
                    }
                }),
            ));
        }
    }
}

/// What a free hypothesis edits: joint `j` times a factor, or plus a coefficient times joint
/// `k`.
#[derive(Clone, Copy)]
enum Free {
    Scale(usize),
    Coupling(usize, usize),
}

impl Free {
    /// Applies the edit with parameter `p` to one row's joint readings.
    fn apply(self, p: f64, q: &mut [f64]) {
        match self {
            Free::Scale(j) => {
                if let Some(v) = q.get_mut(j) {
                    *v *= p;
                }
            }
            Free::Coupling(j, k) => {
                if let Some(&other) = q.get(k)
                    && let Some(v) = q.get_mut(j)
                {
                    *v += p * other;
                }
            }
        }
    }
}

/// The hypotheses with a free parameter, Suspicious tier: each revolute joint column times a
/// factor in [`FREE_SCALE`] (a gear ratio a few per cent off), and each joint column plus a
/// coefficient in [`FREE_COUPLING`] times another revolute joint's (every ordered pair up to
/// [`ALL_PAIRS_UP_TO`] joints, the adjacent ones past it), each parameter estimated by a 1-D
/// search of `screen` on the data `given` (residual `as_given`): [`GRID_POINTS`] points, then
/// [`GOLDEN_STEPS`] golden-section steps about the best. Only a parameter that leaves what right
/// data leave ([`Residual::is_clean`]), dividing the residual by [`OVERWHELMING_FACTOR`] or
/// more, gives a hypothesis: one free parameter absorbs part of any robot's manufacturing
/// deviations.
pub(crate) fn fitted_hypotheses<D: SetupData>(
    given: &D,
    layout: &Layout,
    as_given: &Residual,
    screen: ResidualFn<'_, D>,
) -> Vec<Corrected<D>> {
    use rayon::prelude::*;
    let joints = &layout.joints;
    let n = joints.len();
    let revolute = |j: usize| joints.get(j).is_some_and(|c| c.revolute);
    let mut free: Vec<Free> = (0..n).filter(|&j| revolute(j)).map(Free::Scale).collect();
    for j in (0..n).filter(|&j| revolute(j)) {
        for k in (0..n).filter(|&k| k != j && revolute(k)) {
            if n <= ALL_PAIRS_UP_TO || j.abs_diff(k) == 1 {
                free.push(Free::Coupling(j, k));
            }
        }
    }
    // The screening residual relative to the data as given's, squared per channel: one number
    // for positions and orientations alike.
    let cost = |r: Option<Residual>| {
        let Some(r) = r else { return f64::INFINITY };
        let rel = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) if a.is_finite() => (a / b.max(1e-12)).powi(2),
            (None, None) => 0.0,
            _ => f64::INFINITY,
        };
        rel(r.length_rms_m, as_given.length_rms_m)
            + rel(r.orientation_rms_rad, as_given.orientation_rms_rad)
    };
    let edited = |f: Free, p: f64| given.with_joints(&|q: &mut [f64]| f.apply(p, q));
    let estimates: Vec<(Free, f64, f64)> = (free.par_iter())
        .map(|&f| {
            let (lo, hi, none) = match f {
                Free::Scale(_) => (FREE_SCALE.0.ln(), FREE_SCALE.1.ln(), 0.0),
                Free::Coupling(..) => (FREE_COUPLING.0, FREE_COUPLING.1, 0.0),
            };
            let param = |x: f64| match f {
                Free::Scale(_) => x.exp(),
                Free::Coupling(..) => x,
            };
            let (x, c) = minimise(&|x| cost(screen(&edited(f, param(x)))), lo, hi);
            let c0 = cost(screen(&edited(f, param(none))));
            (f, param(x), c / c0.max(f64::MIN_POSITIVE))
        })
        .collect();
    let mut out = Vec::new();
    for (f, p, ratio) in estimates {
        // No better than the data as given (within the search's own rounding).
        if ratio.is_nan() || ratio >= 0.999 {
            continue;
        }
        // A free parameter absorbs part of a real robot's manufacturing deviations (a few
        // per cent of a gear ratio lowers a MUKCa Panda's socket scatter from 10.8 to 3.1 mm):
        // it explains the data only when it leaves what right data leave, by
        // OVERWHELMING_FACTOR.
        let data = edited(f, p);
        let explains = screen(&data).is_some_and(|r| {
            r.is_clean() && crate::setup_findings::gain(as_given, &r) >= OVERWHELMING_FACTOR
        });
        if !explains {
            continue;
        }
        let (class, what, fix) = match f {
            Free::Scale(j) => {
                let k = 1.0 / p;
                let why = format!("a gear ratio {:.1} % off?", 100.0 * (k - 1.0).abs());
                let (what, fix) = scale_words(&joints[j], k, &why, 5);
                (MistakeClass::ColumnScale, what, fix)
            }
            Free::Coupling(j, k) => {
                let (a, b) = (&joints[j].label, &joints[k].label);
                let c = -p;
                let sign = if c < 0.0 { '−' } else { '+' };
                (
                    MistakeClass::ColumnCoupling,
                    format!(
                        "{a} reads {a} {sign} {:.2}·{b} (a joint coupled to another?)",
                        c.abs()
                    ),
                    format!("--column-coupling {a}={}*{b}", flag_number(p, 3)),
                )
            }
        };
        out.push(Corrected::new(class, what, fix, data));
    }
    out
}

/// The minimum of `f` on `[lo, hi]`: the best of [`GRID_POINTS`] evenly spaced points, then
/// [`GOLDEN_STEPS`] golden-section steps between its neighbours; `(x, f(x))`.
fn minimise(f: &dyn Fn(f64) -> f64, lo: f64, hi: f64) -> (f64, f64) {
    let step = (hi - lo) / (GRID_POINTS - 1) as f64;
    let grid: Vec<(f64, f64)> = (0..GRID_POINTS)
        .map(|i| {
            let x = lo + step * i as f64;
            (x, f(x))
        })
        .collect();
    let Some(&(x0, f0)) = grid.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
        return (lo, f64::INFINITY);
    };
    let (mut a, mut b) = ((x0 - step).max(lo), (x0 + step).min(hi));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..GOLDEN_STEPS {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - g * (b - a);
            fc = f(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    [(x0, f0), (c, fc), (d, fd)]
        .into_iter()
        .min_by(|p, q| p.1.total_cmp(&q.1))
        .unwrap_or((x0, f0))
}

/// Each joint's sign, and each revolute joint's zero off by [`ZERO_OFFSETS`].
fn signs_and_zeros<D: SetupData>(data: &D, layout: &Layout, out: &mut Vec<Corrected<D>>) {
    let joints = &layout.joints;
    for (j, c) in joints.iter().enumerate() {
        out.push(Corrected::new(
            MistakeClass::ColumnSign,
            format!(
                "the readings of {} have the wrong sign (its encoder counts the other way)",
                c.words
            ),
            format!("--column-sign {}", c.label),
            data.with_joints(&|q: &mut [f64]| {
                if let Some(v) = q.get_mut(j) {
                    *v = -*v;
                }
            }),
        ));
        if !c.revolute {
            continue;
        }
        for offset in ZERO_OFFSETS {
            out.push(Corrected::new(
                MistakeClass::ColumnZero,
                format!(
                    "the zero of {} is {:+.0}° off (its reading plus {:.0}° is the joint's \
                     angle)",
                    c.words,
                    offset.to_degrees(),
                    offset.to_degrees()
                ),
                format!("--column-offset {}={offset:.6}", c.label),
                data.with_joints(&|q: &mut [f64]| {
                    if let Some(v) = q.get_mut(j) {
                        *v += offset;
                    }
                }),
            ));
        }
    }
}

/// Permutations of the joint columns: pairs of one kind (all of them up to
/// [`ALL_PAIRS_UP_TO`] joints, else the adjacent ones always and the rest when suspicious),
/// the reversal, arms exchanged.
fn permutations<D: SetupData>(data: &D, layout: &Layout, tier: Tier, out: &mut Vec<Corrected<D>>) {
    let suspicious = tier == Tier::Suspicious;
    let joints = &layout.joints;
    let n = joints.len();
    for a in 0..n {
        for b in a + 1..n {
            let adjacent = b == a + 1;
            let always = n <= ALL_PAIRS_UP_TO || adjacent;
            if always == suspicious || joints[a].revolute != joints[b].revolute {
                continue;
            }
            out.push(Corrected::new(
                MistakeClass::JointOrder,
                format!(
                    "the readings of {} and {} are swapped",
                    joints[a].words, joints[b].words
                ),
                format!(
                    "swap the columns {} and {}",
                    joints[a].label, joints[b].label
                ),
                data.with_joints(&|q: &mut [f64]| {
                    if a < q.len() && b < q.len() {
                        q.swap(a, b);
                    }
                }),
            ));
        }
    }
    let revolute: Vec<usize> = (0..n).filter(|&j| joints[j].revolute).collect();
    if !suspicious && layout.arms.len() <= 1 && revolute.len() >= 3 {
        let (first, last) = (revolute[0], revolute[revolute.len() - 1]);
        let order = revolute.clone();
        out.push(Corrected::new(
            MistakeClass::JointOrder,
            format!(
                "the joint columns are reversed ({} … {} read as {} … {})",
                joints[last].words, joints[first].words, joints[first].words, joints[last].words
            ),
            "reverse the order of the joint columns (the first joint of the chain is the one at \
             the base)"
                .to_owned(),
            data.with_joints(&|q: &mut [f64]| {
                let src: Vec<f64> = q.to_vec();
                for (slot, from) in order.iter().zip(order.iter().rev()) {
                    if let (Some(d), Some(s)) = (q.get_mut(*slot), src.get(*from)) {
                        *d = *s;
                    }
                }
            }),
        ));
    }
    if !suspicious {
        for (x, (arm_a, ja)) in layout.arms.iter().enumerate() {
            for (arm_b, jb) in layout.arms.iter().skip(x + 1) {
                if ja.len() != jb.len()
                    || ja.is_empty()
                    || (ja.iter().zip(jb)).any(|(a, b)| joints[*a].revolute != joints[*b].revolute)
                {
                    continue;
                }
                let (ja, jb) = (ja.clone(), jb.clone());
                let labels = |js: &[usize]| {
                    js.iter()
                        .map(|&j| joints[j].label.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                out.push(Corrected::new(
                    MistakeClass::JointOrder,
                    format!("the readings of the {arm_a} arm and of the {arm_b} arm are exchanged"),
                    format!(
                        "exchange the columns {} with {}, in order",
                        labels(&ja),
                        labels(&jb)
                    ),
                    data.with_joints(&|q: &mut [f64]| {
                        for (a, b) in ja.iter().zip(&jb) {
                            if *a < q.len() && *b < q.len() {
                                q.swap(*a, *b);
                            }
                        }
                    }),
                ));
            }
        }
    }
}

/// Rows out of step by a whole number of rows, for the whole file.
fn whole_file_shifts<D: SetupData>(
    data: &D,
    layout: &Layout,
    tier: Tier,
    out: &mut Vec<Corrected<D>>,
) {
    if layout.paired_rows {
        let shifts: &[isize] = if tier == Tier::Suspicious {
            &SHIFTS_SUSPICIOUS
        } else {
            &SHIFTS_ALWAYS
        };
        for &shift in shifts {
            if let Some(d) = data.with_shift(shift, None) {
                let (what, fix) = shift_words(shift, None);
                out.push(Corrected::new(MistakeClass::RowShift, what, fix, d));
            }
        }
    }
}

/// The hypotheses estimated from the per-row residuals of the data as given: joint readings
/// out of step from the row on where the residuals jump (per file), and the rows that do not
/// belong with their measurements set aside. `per_row` holds, for each row checked, its file
/// (index), its line and its residual (m, or any one scale for every row); `without` gives
/// the data without the rows of the lines listed per file.
pub(crate) fn row_hypotheses<D: SetupData>(
    data: &D,
    layout: &Layout,
    per_row: &[(usize, u64, f64)],
    file_names: &[String],
    without: impl Fn(&[(usize, u64)]) -> Option<D>,
) -> Vec<Corrected<D>> {
    let mut out = Vec::new();
    if !layout.paired_rows || per_row.len() < 12 {
        return out;
    }
    // Rows that do not belong: far above the median row.
    let mut sorted: Vec<f64> = per_row.iter().map(|r| r.2).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let flagged: Vec<(usize, u64)> = (per_row.iter())
        .filter(|r| r.2 > MISMATCH_FACTOR * median)
        .map(|r| (r.0, r.1))
        .collect();
    let share = flagged.len() as f64 / per_row.len() as f64;
    if !flagged.is_empty()
        && share <= MISMATCH_MAX_SHARE
        && let Some(d) = without(&flagged)
    {
        let lines: Vec<String> = (flagged.iter().take(6))
            .map(|(f, l)| format!("{}:{l}", file_names.get(*f).map_or("?", String::as_str)))
            .collect();
        let more = if flagged.len() > 6 { ", …" } else { "" };
        out.push(Corrected::new(
            MistakeClass::RowMismatch,
            format!(
                "{} of the {} rows checked ({:.0} %) do not belong with their measurements: their \
                 residual is more than {MISMATCH_FACTOR:.0} times the median row's ({}{more})",
                flagged.len(),
                per_row.len(),
                100.0 * share,
                lines.join(", ")
            ),
            "check the export of these rows: the joint readings and the measurements of a row \
             must be taken at the same instant (rows copied, re-sorted or merged from another \
             recording)"
                .to_owned(),
            d,
        ));
    }
    // A shift from a row on: per file, the split that best separates low residuals before
    // from high ones after.
    for f in 0..file_names.len() {
        let rows: Vec<(u64, f64)> = (per_row.iter())
            .filter(|r| r.0 == f)
            .map(|r| (r.1, r.2))
            .collect();
        if rows.len() < 12 {
            continue;
        }
        let prefix: Vec<f64> = (rows.iter())
            .scan(0.0, |sum, r| {
                *sum += r.1;
                Some(*sum)
            })
            .collect();
        let total = prefix[rows.len() - 1];
        let mut best: Option<(usize, f64)> = None;
        for k in 4..rows.len() - 3 {
            let before = prefix[k - 1];
            let mean_before = before / k as f64;
            let mean_after = (total - before) / (rows.len() - k) as f64;
            let contrast = mean_after / mean_before.max(f64::MIN_POSITIVE);
            if best.is_none_or(|(_, c)| contrast > c) {
                best = Some((k, contrast));
            }
        }
        let Some((k, contrast)) = best else { continue };
        if contrast < MISMATCH_FACTOR / 2.0 {
            continue;
        }
        // The change lies between the last good row checked and the first bad one: try both.
        let lines = [rows[k - 1].0 + 1, rows[k].0];
        for shift in [-2, -1, 1, 2] {
            for &line in lines.iter().take(if lines[0] == lines[1] { 1 } else { 2 }) {
                if let Some(d) = data.with_shift(shift, Some((f, line))) {
                    let file = file_names.get(f).map_or("?", String::as_str);
                    let (what, fix) = shift_words(shift, Some((file, line)));
                    out.push(Corrected::new(MistakeClass::RowShift, what, fix, d));
                }
            }
        }
    }
    out
}

/// The mistake and fix of joint readings `shift` rows out of step (from `from`'s file and line
/// on).
fn shift_words(shift: isize, from: Option<(&str, u64)>) -> (String, String) {
    let k = shift.unsigned_abs();
    let rows = if k == 1 { "row" } else { "rows" };
    let (place, moved) = match from {
        Some((file, line)) => (
            format!(" from {file}:{line} on"),
            format!(" from {file}:{line} on"),
        ),
        None => (String::new(), String::new()),
    };
    if shift > 0 {
        (
            format!("the joint readings are {k} {rows} behind the measurements{place}"),
            format!(
                "move the joint columns up by {k} {rows}{moved}: the readings on line L + {k} \
                 belong to the measurement on line L"
            ),
        )
    } else {
        (
            format!("the joint readings are {k} {rows} ahead of the measurements{place}"),
            format!(
                "move the joint columns down by {k} {rows}{moved}: the readings on line L belong \
                 to the measurement on line L + {k}"
            ),
        )
    }
}

/// The units of `units` other than the one named `read`, each with its name, words, SI factor
/// and the ratio that turns a value read in `read` into one in it.
fn others(
    units: &'static [(&'static str, &'static str, f64)],
    read: &'static str,
) -> impl Iterator<Item = (&'static str, &'static str, f64, f64)> {
    let read_factor = unit_factor(units, read);
    (units.iter())
        .filter(move |u| u.0 != read)
        .map(move |&(name, words, factor)| (name, words, factor, factor / read_factor))
}

/// The SI factor of the unit named `name` in `units` (1 when unknown).
fn unit_factor(units: &[(&str, &str, f64)], name: &str) -> f64 {
    (units.iter()).find(|u| u.0 == name).map_or(1.0, |u| u.2)
}

/// The words of the unit named `name` in `units`.
fn unit_words(units: &[(&'static str, &'static str, f64)], name: &str) -> &'static str {
    (units.iter()).find(|u| u.0 == name).map_or("?", |u| u.1)
}

/// A conversion factor as the fixes write it: `π/180`, `π/200`, `2π`, `0.0254`.
fn factor_text(factor: f64) -> String {
    let pi = std::f64::consts::PI;
    for (f, text) in [
        (pi / 180.0, "π/180"),
        (pi / 200.0, "π/200"),
        (2.0 * pi, "2π"),
    ] {
        if (factor - f).abs() < 1e-12 {
            return text.to_owned();
        }
    }
    format!("{factor}")
}

impl Residual {
    /// Whether right data of a real robot can leave this residual: the frames-only residual of
    /// the bundled recordings is a few millimetres and below 0.6° (docs/results/reliability.md),
    /// a fifth of [`Residual::is_plausible`]'s bound in length and 0.02 rad in orientation.
    /// Above it, the check tries the per-column families (`Tier::Suspicious`).
    pub fn is_clean(&self) -> bool {
        self.length_rms_m
            .is_none_or(|e| e <= crate::noise::PLAUSIBLE_FRAMES_ONLY_RMS_M / 5.0)
            && self.orientation_rms_rad.is_none_or(|e| e <= 0.02)
    }
}

/// Fails the test when the classes of `hypotheses` do not cover exactly the families `kind`
/// generates before the fit.
#[cfg(test)]
pub(crate) fn assert_families<T>(kind: DataKind, hypotheses: &[Corrected<T>]) {
    let (generated, _) = kind.families();
    let mut got: Vec<Family> = hypotheses.iter().filter_map(|h| h.class.family()).collect();
    got.dedup();
    for f in generated {
        assert!(
            got.contains(f),
            "the check of {kind:?} generates no hypothesis of the family {}",
            f.name()
        );
    }
    for f in &got {
        assert!(
            generated.contains(f),
            "the check of {kind:?} generates the family {}, which its kind does not list",
            f.name()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_generates_or_excuses_every_family_once() {
        for kind in DataKind::ALL {
            let (generated, excused) = kind.families();
            for f in Family::ALL {
                let n = generated.iter().filter(|g| **g == f).count()
                    + excused.iter().filter(|(g, _)| *g == f).count();
                assert_eq!(n, 1, "{kind:?}: family {} listed {n} times", f.name());
            }
        }
    }

    #[test]
    fn every_class_of_a_hypothesis_has_a_family() {
        for c in MistakeClass::ALL {
            let data_alone = matches!(
                c,
                MistakeClass::FrozenJoint
                    | MistakeClass::NoHypothesis
                    | MistakeClass::Mounting
                    | MistakeClass::ImplausibleEstimate
            );
            assert_eq!(c.family().is_none(), data_alone, "{c}");
        }
    }

    #[test]
    fn unit_factors_turn_a_column_into_radians_and_metres() {
        // 180 degrees, 200 gradians and half a revolution are π rad.
        for (unit, value) in [("deg", 180.0), ("grad", 200.0), ("rev", 0.5)] {
            let rad = value * unit_factor(&ANGLE_UNITS, unit);
            assert!((rad - std::f64::consts::PI).abs() < 1e-15, "{unit}");
        }
        // One foot is 12 inches, 30.48 cm, 304.8 mm.
        let ft = unit_factor(&LENGTH_UNITS, "ft");
        assert!((ft - 12.0 * unit_factor(&LENGTH_UNITS, "in")).abs() < 1e-15);
        assert!((ft - 30.48 * unit_factor(&LENGTH_UNITS, "cm")).abs() < 1e-15);
        assert!((ft - 304.8 * unit_factor(&LENGTH_UNITS, "mm")).abs() < 1e-15);
    }
}
