//! What every setup check shares: the classes of mistake, the residuals the checks compare,
//! the findings and the report ([`SetupReport`]), the factors a hypothesis is judged by
//! ([`OVERWHELMING_FACTOR`], [`SUGGESTIVE_FACTOR`]) and the rule that judges the hypotheses of
//! a check (`judge`), with the geometry more than one check needs. The checks themselves are
//! the measurement files' (`setup`), a haptic device's logs' (`setup_haptic`) and the socket
//! folders' (`setup_sockets`).

use rayon::prelude::*;
use serde::Serialize;

use crate::noise::PLAUSIBLE_FRAMES_ONLY_RMS_M;

/// Factor by which a hypothesis must divide the frames-only residual (position RMS, or
/// orientation RMS of pose data) to be an error, when the corrected residual is plausible.
///
/// Right data leave the instrument's noise and the robot's manufacturing deviations; a
/// hypothesis with nothing to fit can lower that only by the chance fluctuation of a RMS over
/// the rows (a few per cent for tens of rows; on the bundled recordings the largest gain of
/// any hypothesis is below 1.1, docs/results/reliability.md). A mistake turns millimetres
/// into metres or decimetres: factors of tens to thousands. Five lies far from both.
pub const OVERWHELMING_FACTOR: f64 = 5.0;

/// Factor by which a hypothesis must divide the frames-only residual to be a warning: twice
/// the residual of right data is out of reach of chance, but a small mistake (a short link, a
/// few rows of a slow motion) may explain only part of a residual.
pub const SUGGESTIVE_FACTOR: f64 = 2.0;

/// Frames-only RMS orientation error (rad) beyond which the nominal model cannot be the
/// robot's: joint zero offsets and link twists of a real robot are milliradians, a few of them
/// in series stay below 0.02 rad, a camera's orientation noise is a few milliradians; a
/// quaternion read in the wrong order or an angle in degrees read in radians gives tenths of a
/// radian to radians.
pub const PLAUSIBLE_FRAMES_ONLY_RAD: f64 = 0.05;

/// Largest spread (max − min) of a joint's readings, rad or m, that counts as a column that
/// never changes: exported encoder readings of a moving joint differ in their last digits.
pub const FROZEN_SPREAD: f64 = 1e-9;

/// Rows a frames-only fit of the check takes at most (evenly spaced over each file): a factor
/// of [`OVERWHELMING_FACTOR`] shows on far fewer, and the check stays a small part of a
/// calibration on long recordings.
pub const MAX_CHECK_ROWS: usize = 200;

/// Most rows of the measurement files the setup check keeps to judge: a longer recording is
/// read whole (every row checked, file:line kept) but judged on a sample spread over it, every
/// `s`-th row of each file ([`crate::fit::ladder_sample`] with this cap). Each hypothesis holds
/// a corrected copy of the rows kept (about 16 kB a row in all on the simulated humanoid), so the
/// cap bounds the check's memory: a 5,000-row sample of a 1,000,000-row file takes about 80 MB.
/// 25 times the rows the residuals are judged on ([`MAX_CHECK_ROWS`]), and more than every
/// bundled recording holds (at most 550 rows), which the check reads whole.
pub const CHECK_SAMPLE_ROWS: usize = 5_000;

/// Half-width (rad or m) of the joint ranges with which the checks read files again after a
/// reading past a joint's limit (the measurement-file check's `past_limits`, the haptic
/// check's logs): wide enough for any reading in degrees or millimetres.
pub(crate) const OPEN_LIMIT: f64 = 1e6;

/// A class of setup mistake; its name (`length-unit`, `joint-order`, …) appears in the
/// reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(into = "String")]
pub enum MistakeClass {
    /// Positions and distances in another length unit (mm read as m, or m as mm).
    LengthUnit,
    /// Angles (revolute joints and `phix, phiy, phiz`) in another unit.
    AngleUnit,
    /// Only the orientation angles `phix, phiy, phiz` in degrees, the joints in radians.
    OrientationUnit,
    /// Quaternion columns holding `x, y, z, w` under the names `qw, qx, qy, qz`.
    QuaternionOrder,
    /// The inverse (conjugate) rotation: the instrument in the marker's frame.
    QuaternionInverse,
    /// Roll and yaw swapped (`phix` and `phiz`).
    EulerOrder,
    /// One position axis negated or two swapped (a left-handed instrument frame; the data
    /// cannot tell which).
    MirroredAxis,
    /// Two joint columns swapped, or all of them in reverse order.
    JointOrder,
    /// Joint rows out of step with the measurement rows.
    RowShift,
    /// A joint whose reading never changes while the description lets it move.
    FrozenJoint,
    /// The tip link one or two moving joints up or down the chain from the markers' link.
    TipLink,
    /// Tips given in the wrong order (marker sets of two branches swapped).
    SwappedTips,
    /// The residual is far above what a real robot produces and no hypothesis explains it.
    NoHypothesis,
    /// One joint column in another angle unit than the file's (degrees, gradians,
    /// revolutions).
    ColumnUnit,
    /// One joint column's sign reversed (an encoder counting the other way).
    ColumnSign,
    /// One joint's zero off by a multiple of 90°.
    ColumnZero,
    /// One joint column read times a factor: on the motor side of its gear, in encoder
    /// counts, or through a gear ratio a few per cent off (`--column-scale`).
    ColumnScale,
    /// One joint column read plus a multiple of another joint's: a coupled joint
    /// (`--column-coupling`).
    ColumnCoupling,
    /// Rows whose joint readings and measurements do not belong together.
    RowMismatch,
    /// Joint readings that lag the measurements by a fraction of a row: a latency, which
    /// `diagnose` models, not a mistake.
    Latency,
    /// The known distance between two sockets given wrong (`--socket-distance-m`).
    SocketDistance,
    /// Rows filed under the wrong socket of a placement.
    WrongSocket,
    /// Calibrated deviations beyond any manufacturing tolerance: the data of another device or
    /// robot.
    AnotherDevice,
    /// Compliances negative beyond their uncertainty under the gravity given, non-negative
    /// under another axis of the root frame: the robot is mounted on a ceiling or a wall
    /// (`--gravity`).
    Mounting,
    /// An estimate no real robot can have (negative compliances, a marker frame metres from its
    /// link, an unconverged fit): found after the fit, never a result.
    ImplausibleEstimate,
    /// One set of instrument and marker frames before a row of a file and another from it on:
    /// the instrument moved or a marker was mounted again during the recording.
    ChangePoint,
}

/// Every class with its name in reports, in report order.
const CLASS_NAMES: [(MistakeClass, &str); 26] = [
    (MistakeClass::LengthUnit, "length-unit"),
    (MistakeClass::AngleUnit, "angle-unit"),
    (MistakeClass::OrientationUnit, "orientation-unit"),
    (MistakeClass::QuaternionOrder, "quaternion-order"),
    (MistakeClass::QuaternionInverse, "quaternion-inverse"),
    (MistakeClass::EulerOrder, "euler-order"),
    (MistakeClass::MirroredAxis, "mirrored-axis"),
    (MistakeClass::JointOrder, "joint-order"),
    (MistakeClass::RowShift, "row-shift"),
    (MistakeClass::FrozenJoint, "frozen-joint"),
    (MistakeClass::TipLink, "tip-link"),
    (MistakeClass::SwappedTips, "swapped-tips"),
    (MistakeClass::NoHypothesis, "no-hypothesis"),
    (MistakeClass::ColumnUnit, "column-unit"),
    (MistakeClass::ColumnSign, "column-sign"),
    (MistakeClass::ColumnZero, "column-zero"),
    (MistakeClass::ColumnScale, "column-scale"),
    (MistakeClass::ColumnCoupling, "column-coupling"),
    (MistakeClass::RowMismatch, "row-mismatch"),
    (
        MistakeClass::Latency,
        hapcal_contract::Effect::Latency.name(),
    ),
    (MistakeClass::SocketDistance, "socket-distance"),
    (MistakeClass::WrongSocket, "wrong-socket"),
    (MistakeClass::AnotherDevice, "another-device"),
    (MistakeClass::Mounting, "mounting"),
    (MistakeClass::ImplausibleEstimate, "implausible-estimate"),
    (MistakeClass::ChangePoint, "change-point"),
];

impl MistakeClass {
    /// Every class, in report order.
    pub const ALL: [MistakeClass; 26] = {
        let mut all = [MistakeClass::LengthUnit; 26];
        let mut i = 0;
        while i < all.len() {
            all[i] = CLASS_NAMES[i].0;
            i += 1;
        }
        all
    };

    /// The class's name in reports.
    pub fn name(self) -> &'static str {
        (CLASS_NAMES.iter())
            .find(|(c, _)| *c == self)
            .map_or("", |(_, name)| name)
    }
}

impl std::fmt::Display for MistakeClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl From<MistakeClass> for String {
    fn from(c: MistakeClass) -> String {
        c.name().to_owned()
    }
}

impl std::str::FromStr for MistakeClass {
    type Err = String;
    /// A name of [`MistakeClass::name`].
    fn from_str(s: &str) -> Result<Self, String> {
        (MistakeClass::ALL.into_iter())
            .find(|c| c.name() == s)
            .ok_or_else(|| format!("expected a setup mistake class, found {s:?}"))
    }
}

/// How strongly a finding speaks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// Overwhelming evidence: the caller stops (exit 2) unless the data are accepted.
    Error,
    /// Worth a look; the calibration goes on.
    Warning,
}

impl Severity {
    /// [`Severity::Error`] when `error`, else [`Severity::Warning`].
    pub(crate) fn of(error: bool) -> Severity {
        if error {
            Severity::Error
        } else {
            Severity::Warning
        }
    }
}

/// Which fit a [`Residual`] is the residual of.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidualOf {
    /// The nominal kinematics with the instrument and marker frames fitted (measurement
    /// files).
    #[default]
    FramesOnly,
    /// The nominal device's cable distance, its zero fitted (a haptic device's logs).
    CableDistance,
    /// The scatter of the nominal tip positions about each socket's mean, with the error of
    /// the distance between a placement's two sockets (socket recordings).
    SocketScatter,
}

impl ResidualOf {
    /// In the reports' words: `frames-only RMS`, `nominal cable-distance RMS`.
    pub fn words(self) -> &'static str {
        match self {
            ResidualOf::FramesOnly => "frames-only RMS",
            ResidualOf::CableDistance => "nominal cable-distance RMS",
            ResidualOf::SocketScatter => "nominal socket-scatter RMS",
        }
    }
}

/// Frames-only residual of a data set (or its counterpart for other data, [`ResidualOf`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Residual {
    /// The fit this is the residual of.
    pub of: ResidualOf,
    /// RMS over every marker sample's 3-D position error and every distance error, m;
    /// `None` without either.
    pub length_rms_m: Option<f64>,
    /// RMS orientation error (angle of the relative rotation) of pose data, rad.
    pub orientation_rms_rad: Option<f64>,
    /// RMS distance of the measured positions from each marker's centroid, and of the
    /// distances from their mean, m: the scale the length residual is judged at (a
    /// hypothesis that shrinks the data shrinks its residual without explaining anything).
    pub spread_m: Option<f64>,
}

impl Residual {
    /// Whether a real robot's manufacturing deviations can leave this residual
    /// ([`PLAUSIBLE_FRAMES_ONLY_RMS_M`], [`PLAUSIBLE_FRAMES_ONLY_RAD`]).
    pub fn is_plausible(&self) -> bool {
        self.length_rms_m
            .is_none_or(|e| e <= PLAUSIBLE_FRAMES_ONLY_RMS_M)
            && self
                .orientation_rms_rad
                .is_none_or(|e| e <= PLAUSIBLE_FRAMES_ONLY_RAD)
    }

    /// In words: `163942.1 mm` or `1.92 mm, 0.31°`.
    pub fn text(&self) -> String {
        let mut parts = Vec::new();
        if let Some(e) = self.length_rms_m {
            parts.push(format!("{} mm", mm(e)));
        }
        if let Some(e) = self.orientation_rms_rad {
            parts.push(format!("{:.2}°", e.to_degrees()));
        }
        if parts.is_empty() {
            "no residual".to_owned()
        } else {
            parts.join(", ")
        }
    }
}

/// Millimetres of `m`, with three significant digits for small values.
pub(crate) fn mm(m: f64) -> String {
    let v = m * 1e3;
    if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// One thing the check found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    /// The class of mistake.
    pub class: MistakeClass,
    /// Error (the caller stops unless accepted) or warning.
    pub severity: Severity,
    /// What was found, in plain words.
    pub message: String,
    /// The flag or the edit of the files that applies.
    pub fix: String,
    /// Frames-only residual of the data as given.
    pub before: Residual,
    /// Frames-only residual of the data as the fix reads them (`None` for a finding from the
    /// data alone).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub after: Option<Residual>,
}

impl Finding {
    /// A finding of `class` from the data alone: no residual before (the default) or after;
    /// [`Finding::with_residuals`] adds those a fit gave.
    pub(crate) fn new(
        class: MistakeClass,
        severity: Severity,
        message: String,
        fix: impl Into<String>,
    ) -> Finding {
        Finding {
            class,
            severity,
            message,
            fix: fix.into(),
            before: Residual::default(),
            after: None,
        }
    }

    /// The finding with the residual of the data as given, `before`, and as the fix reads
    /// them, `after`.
    pub(crate) fn with_residuals(self, before: Residual, after: Option<Residual>) -> Finding {
        Finding {
            before,
            after,
            ..self
        }
    }

    /// One line: the message, the residual before → after, the fix.
    pub fn text(&self) -> String {
        let unread = self.before == Residual::default();
        let residual = match &self.after {
            Some(after) if unread => {
                format!(" ({} {} with the fix)", after.of.words(), after.text())
            }
            Some(after) => format!(
                " ({} {} → {})",
                after.of.words(),
                self.before.text(),
                after.text()
            ),
            None => String::new(),
        };
        format!("{}{residual}; fix: {}", self.message, self.fix)
    }
}

/// The hypothesis of a mistake that lowered the frames-only residual most.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClosestHypothesis {
    /// Its class.
    pub class: MistakeClass,
    /// The flag or edit it stands for.
    pub fix: String,
    /// The frames-only residual of the data as it corrects them.
    pub after: Residual,
    /// How many times it divides the residual as given (position residual relative to the
    /// data's spread, or orientation residual; below 1: every hypothesis raises it); `None`
    /// when the data do not read as given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain: Option<f64>,
}

/// Everything the setup check found.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SetupReport {
    /// Training rows checked.
    pub n_rows: usize,
    /// Frames-only residual of the data as given.
    pub as_given: Residual,
    /// Hypotheses of a mistake fitted.
    pub n_hypotheses: usize,
    /// The hypothesis that lowered the residual most (reported whether or not it is a
    /// finding).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub closest: Option<ClosestHypothesis>,
    /// Findings, errors first.
    pub findings: Vec<Finding>,
}

impl SetupReport {
    /// The report of data that do not read as given, with the one `finding` that makes them
    /// read, its residual `after` (no residual before): the tip one or two links up.
    pub(crate) fn of_unread(n_rows: usize, finding: Finding, after: Residual) -> SetupReport {
        let finding = finding.with_residuals(Residual::default(), Some(after));
        SetupReport {
            n_rows,
            as_given: Residual::default(),
            n_hypotheses: 1,
            closest: Some(ClosestHypothesis {
                class: finding.class,
                fix: finding.fix.clone(),
                after,
                gain: None,
            }),
            findings: vec![finding],
        }
    }

    /// Adds, first, the error "`message`: nothing explains the residual as given" when
    /// `as_given` is more than a real robot leaves and no finding is an error yet.
    pub(crate) fn add_implausible(
        findings: &mut Vec<Finding>,
        as_given: Residual,
        message: String,
        fix: &str,
    ) {
        if as_given.is_plausible() || findings.iter().any(|f| f.severity == Severity::Error) {
            return;
        }
        let finding = Finding::new(MistakeClass::NoHypothesis, Severity::Error, message, fix);
        findings.insert(0, finding.with_residuals(as_given, None));
    }

    /// The first finding of severity error, if any.
    pub fn overwhelming(&self) -> Option<&Finding> {
        self.findings.iter().find(|f| f.severity == Severity::Error)
    }

    /// The report as plain text, one finding per line.
    pub fn render(&self) -> String {
        let mut out = if self.as_given == Residual::default() {
            format!(
                "setup check: {} rows; the files do not read with the tips given\n",
                self.n_rows
            )
        } else {
            format!(
                "setup check: {} rows, {} {} as given, {} hypotheses of a mistake fitted\n",
                self.n_rows,
                self.as_given.of.words(),
                self.as_given.text(),
                self.n_hypotheses
            )
        };
        if let Some(c) = &self.closest
            && let Some(g) = c.gain
        {
            out.push_str(&format!(
                "  closest hypothesis [{}]: {} ({} {}, gain {g:.2}×)\n",
                c.class,
                c.fix,
                c.after.of.words(),
                c.after.text()
            ));
        }
        if self.findings.is_empty() {
            out.push_str("  nothing found: the data fit this robot as they are\n");
        }
        for f in &self.findings {
            out.push_str(&format!(
                "  {} [{}]: {}\n",
                f.severity_word(),
                f.class,
                f.text()
            ));
        }
        out
    }
}

impl Finding {
    fn severity_word(&self) -> &'static str {
        match self.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        }
    }
}

/// The joints among the first `n_joints` whose readings in `rows` (rad or m) spread by at most
/// [`FROZEN_SPREAD`] while `limits` let them move (a joint without limits moves): `(joint,
/// its lowest reading)`.
pub(crate) fn frozen_columns(
    rows: &[&[f64]],
    limits: &[(f64, f64)],
    n_joints: usize,
) -> Vec<(usize, f64)> {
    (0..n_joints)
        .filter_map(|j| {
            let values = rows.iter().filter_map(|q| q.get(j).copied());
            let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            });
            let moves = limits
                .get(j)
                .is_none_or(|(min, max)| max - min > FROZEN_SPREAD);
            (hi - lo <= FROZEN_SPREAD && moves).then_some((j, lo))
        })
        .collect()
}

/// The nearest rotation to `m` (its polar factor, by SVD; Horn 1987).
pub(crate) fn nearest_rotation(m: &nalgebra::Matrix3<f64>) -> nalgebra::Matrix3<f64> {
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return nalgebra::Matrix3::identity();
    };
    let mut d = nalgebra::Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    u * d * v_t
}

/// [`nearest_rotation`] by ascent from `start`, a rotation near the answer: nalgebra's
/// `Rotation3::from_matrix_eps`, which turns `R` about `ω = Σ_c R_c × M_c / |Σ_c R_c · M_c|`
/// (columns `c`) until `Rᵀ·M` is symmetric (Müller, Bender, Chentanez & Macklin, "A Robust
/// Method to Extract the Rotational Part of Deformations", MIG 2016). `tr(Rᵀ·M)` has one
/// maximum on the rotations, so the ascent reaches the SVD's answer; from a start close to
/// it, in a few steps of a few dozen flops, where a 3 × 3 SVD costs microseconds.
pub(crate) fn nearest_rotation_from(
    m: &nalgebra::Matrix3<f64>,
    start: &nalgebra::Matrix3<f64>,
) -> nalgebra::Matrix3<f64> {
    let guess = nalgebra::Rotation3::from_matrix_unchecked(*start);
    nalgebra::Rotation3::from_matrix_eps(m, 1e-14, 20, guess).into_inner()
}

/// How many times smaller `after` is than `before`: the larger of the position and the
/// orientation ratio, unless the other one grows by more than half (then the smaller ratio:
/// a hypothesis that trades one for the other explains nothing). Lengths are taken relative
/// to the data's spread ([`Residual::spread_m`]): a rescaled data set is judged at its own
/// scale.
pub(crate) fn gain(before: &Residual, after: &Residual) -> f64 {
    ratio_of(before, after, true)
}

/// [`gain`] with the lengths as they are (m), not relative to the spread: how the residual
/// itself falls, which decides whether a hypothesis brings an implausible residual to a
/// plausible one.
pub(crate) fn absolute_gain(before: &Residual, after: &Residual) -> f64 {
    ratio_of(before, after, false)
}

fn ratio_of(before: &Residual, after: &Residual, relative_to_spread: bool) -> f64 {
    let ratio = |b: Option<f64>, a: Option<f64>, floor: f64| match (b, a) {
        (Some(b), Some(a)) if a.is_finite() && b.is_finite() => Some(b.max(floor) / a.max(floor)),
        (Some(_), _) | (_, Some(_)) => Some(0.0),
        _ => None,
    };
    let length = |r: &Residual| match (r.length_rms_m, r.spread_m) {
        (Some(e), Some(s)) if relative_to_spread => Some(e / s),
        (e, _) => e,
    };
    let r = [
        ratio(length(before), length(after), 1e-9),
        ratio(before.orientation_rms_rad, after.orientation_rms_rad, 1e-5),
    ];
    let r: Vec<f64> = r.into_iter().flatten().collect();
    let lo = r.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = r.iter().copied().fold(0.0, f64::max);
    if r.is_empty() {
        0.0
    } else if lo < 1.0 / 1.5 {
        lo
    } else {
        hi
    }
}

/// A hypothesis of a mistake with the data as it corrects them.
pub(crate) struct Corrected<T> {
    pub(crate) class: MistakeClass,
    /// What the mistake is, in words.
    pub(crate) what: String,
    /// The flag or the edit that applies.
    pub(crate) fix: String,
    pub(crate) data: T,
    /// Columns the files name that the hypothesis uses and the data as given leave out (a tip
    /// below the one given): evidence of its own, so that a gain of [`SUGGESTIVE_FACTOR`] with
    /// a plausible residual is an error.
    pub(crate) evidence: Vec<String>,
}

impl<T> Corrected<T> {
    pub(crate) fn new(
        class: MistakeClass,
        what: impl Into<String>,
        fix: impl Into<String>,
        data: T,
    ) -> Self {
        Corrected {
            class,
            what: what.into(),
            fix: fix.into(),
            data,
            evidence: Vec::new(),
        }
    }
}

/// The residual of data as a hypothesis corrects them; `None` when they do not fit.
pub(crate) type ResidualFn<'a, T> = &'a (dyn Fn(&T) -> Option<Residual> + Sync);

/// How a check scores data: a quick residual for every hypothesis, and optionally a finer
/// one for the data as given and the best few when something looks wrong.
pub(crate) struct Scoring<'a, T> {
    /// The quick residual.
    pub(crate) screen: ResidualFn<'a, T>,
    /// The finer residual (the calibration's own frames-only fit), if the check has one.
    pub(crate) refine: Option<ResidualFn<'a, T>>,
}

/// Hypotheses refitted with [`Scoring::refine`] when something looks wrong: this many by
/// rank, and this many by gain.
const REFINED: usize = 3;

/// Two hypotheses whose residuals lie within this factor of each other explain the data
/// equally: the finding names both.
const EQUAL_FACTOR: f64 = 1.25;

/// The hypotheses of a check, judged.
pub(crate) struct Judged {
    /// The residual of the data as given (refined when the others were).
    pub(crate) as_given: Residual,
    /// The hypothesis closest to the data.
    pub(crate) closest: Option<ClosestHypothesis>,
    /// Its finding, if it is one.
    pub(crate) finding: Option<Finding>,
    /// Its index when its finding is an error.
    pub(crate) error_at: Option<usize>,
    /// Hypotheses scored.
    pub(crate) n_scored: usize,
}

/// One hypothesis scored.
#[derive(Clone, Copy)]
struct Score {
    at: usize,
    after: Residual,
    gain: f64,
    absolute: f64,
    explains: bool,
}

impl Score {
    fn of(at: usize, as_given: &Residual, after: Residual) -> Score {
        let absolute = absolute_gain(as_given, &after);
        Score {
            at,
            after,
            gain: gain(as_given, &after),
            absolute,
            // Not a collapse of the data onto the model: relative to their spread, the
            // corrected data fit no worse (positions in mm read as m fit as well relative to
            // their spread; a shrunken data set relative to it does not).
            explains: !as_given.is_plausible()
                && after.is_plausible()
                && absolute >= SUGGESTIVE_FACTOR
                && gain(as_given, &after) >= 1.0 / 1.5,
        }
    }

    /// The order of the hypotheses, best first: those that bring an implausible residual to
    /// a plausible one (by how far the residual itself falls), then the others by gain.
    fn rank(&self) -> (bool, f64) {
        (
            self.explains,
            if self.explains {
                self.absolute
            } else {
                self.gain
            },
        )
    }
}

fn by_rank(a: &Score, b: &Score) -> std::cmp::Ordering {
    let (ea, va) = a.rank();
    let (eb, vb) = b.rank();
    eb.cmp(&ea).then(vb.total_cmp(&va))
}

/// Judges `hypotheses` of the data `given` (residual `as_given` by [`Scoring::screen`]):
///
/// - a hypothesis that brings a residual more than a real robot leaves
///   ([`Residual::is_plausible`]) to one it can leave, falling by [`SUGGESTIVE_FACTOR`] or
///   more, explains the data whatever its gain relative to their spread: an error;
/// - otherwise one that divides the residual by [`OVERWHELMING_FACTOR`] (by
///   [`SUGGESTIVE_FACTOR`] with columns of its own as evidence) and leaves a plausible residual
///   is an error, one that divides it by [`SUGGESTIVE_FACTOR`] and leaves a plausible
///   residual a warning; one that leaves more than a real robot leaves is no finding (its fix
///   would fail again: no cause is named that does not explain the data);
/// - a second hypothesis with another fix whose residual lies within [`EQUAL_FACTOR`] of the
///   best one's is named with it.
pub(crate) fn judge<T: Sync>(
    as_given: Residual,
    given: &T,
    hypotheses: &[Corrected<T>],
    scoring: &Scoring<'_, T>,
) -> Judged {
    let mut as_given = as_given;
    let mut scores: Vec<Score> = (hypotheses.par_iter().enumerate())
        .filter_map(|(i, h)| Some(Score::of(i, &as_given, (scoring.screen)(&h.data)?)))
        .collect();
    scores.sort_by(by_rank);
    let n_scored = scores.len();
    let suspicious = !as_given.is_plausible()
        || (scores.first()).is_some_and(|s| s.explains || s.gain >= SUGGESTIVE_FACTOR);
    if suspicious && let Some(refine) = scoring.refine {
        if let Some(full) = refine(given) {
            as_given = full;
        }
        // The best few by rank and the best few by gain: the screen may rank a hypothesis
        // that explains the data only by its cruder fit above one the full fit prefers.
        let mut by_gain = scores.clone();
        by_gain.sort_by(|a, b| b.gain.total_cmp(&a.gain));
        scores.truncate(REFINED);
        for s in by_gain.into_iter().take(REFINED) {
            if scores.iter().all(|k| k.at != s.at) {
                scores.push(s);
            }
        }
        scores = (scores.par_iter())
            .filter_map(|s| {
                Some(Score::of(
                    s.at,
                    &as_given,
                    refine(&hypotheses.get(s.at)?.data)?,
                ))
            })
            .collect();
        scores.sort_by(by_rank);
    }
    let no_finding = |closest| Judged {
        as_given,
        closest,
        finding: None,
        error_at: None,
        n_scored,
    };
    let Some(best) = scores.first().copied() else {
        return no_finding(None);
    };
    let h = &hypotheses[best.at];
    let closest = Some(ClosestHypothesis {
        class: h.class,
        fix: h.fix.clone(),
        after: best.after,
        gain: Some(best.gain),
    });
    let g = best.gain;
    let named = !h.evidence.is_empty();
    let plausible = best.after.is_plausible();
    let error = best.explains
        || (plausible && (g >= OVERWHELMING_FACTOR || (named && g >= SUGGESTIVE_FACTOR)));
    // No harmful fix: a correction that leaves more than a real robot leaves is not the
    // cause, or not the only one, and its fix would fail again; the check then names no cause
    // (the residual nothing explains is located by the caller).
    if !error && (g < SUGGESTIVE_FACTOR || !plausible) {
        return no_finding(closest);
    }
    let scale = if h.class == MistakeClass::LengthUnit {
        " relative to the spread of the positions"
    } else {
        ""
    };
    let mut message = if error && named {
        let digits = if g < 10.0 { 1 } else { 0 };
        format!(
            "{} ({g:.digits$}× smaller residual when corrected, and the files have a column for \
             {}, which the chain to the tip given leaves out)",
            h.what,
            h.evidence.join(", ")
        )
    } else if error && best.explains && g < OVERWHELMING_FACTOR {
        format!(
            "{} (corrected, the residual falls {:.0}× to what a real robot leaves)",
            h.what, best.absolute
        )
    } else if error {
        format!(
            "{} ({g:.0}× smaller residual{scale} when corrected)",
            h.what
        )
    } else {
        format!(
            "perhaps {} ({g:.1}× smaller residual{scale} when corrected)",
            h.what
        )
    };
    let close = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) => a <= b * EQUAL_FACTOR,
        _ => true,
    };
    if let Some(other) = scores.iter().skip(1).find(|s| {
        let o = &hypotheses[s.at];
        o.fix != h.fix
            && s.explains == best.explains
            && close(s.after.length_rms_m, best.after.length_rms_m)
            && close(s.after.orientation_rms_rad, best.after.orientation_rms_rad)
    }) {
        let o = &hypotheses[other.at];
        message.push_str(&format!(
            "; the data fit as well if {} ({} {}; fix: {})",
            o.what,
            other.after.of.words(),
            other.after.text(),
            o.fix
        ));
    }
    Judged {
        as_given,
        closest,
        finding: Some(
            Finding::new(h.class, Severity::of(error), message, h.fix.clone())
                .with_residuals(as_given, Some(best.after)),
        ),
        error_at: error.then_some(best.at),
        n_scored,
    }
}

/// The links one and two moving joints above and below `tip` in the URDF, each with how
/// many moving joints it lies above (negative) or below (positive) the tip.
pub(crate) fn tip_candidates(
    urdf: &urdf_rs::Robot,
    tip: &str,
) -> Vec<(String, isize, Vec<String>)> {
    let moving = |j: &urdf_rs::Joint| !matches!(j.joint_type, urdf_rs::JointType::Fixed);
    let mut out = Vec::new();
    // Up: the parent link of the first and second moving joints above the tip.
    let mut link = tip.to_owned();
    let mut crossed = 0;
    for _ in 0..urdf.joints.len() {
        let Some(joint) = urdf.joints.iter().find(|j| j.child.link == link) else {
            break;
        };
        link.clone_from(&joint.parent.link);
        if moving(joint) {
            crossed += 1;
            out.push((link.clone(), -crossed, Vec::new()));
            if crossed == 2 {
                break;
            }
        }
    }
    // Down: the child link of the first and second moving joints below the tip, on every
    // branch (at most a few).
    let mut frontier: Vec<(String, isize, Vec<String>)> = vec![(tip.to_owned(), 0, Vec::new())];
    for _ in 0..urdf.joints.len() {
        let Some((link, depth, joints)) = frontier.pop() else {
            break;
        };
        for joint in urdf.joints.iter().filter(|j| j.parent.link == link) {
            let mut joints = joints.clone();
            let d = if moving(joint) {
                joints.push(joint.name.clone());
                depth + 1
            } else {
                depth
            };
            if d > depth {
                out.push((joint.child.link.clone(), d, joints.clone()));
            }
            if d < 2 && out.len() < 8 {
                frontier.push((joint.child.link.clone(), d, joints));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_class_survives_the_round_trip_of_its_name() {
        for c in MistakeClass::ALL {
            assert_eq!(c.name().parse::<MistakeClass>(), Ok(c));
        }
        assert!("mm".parse::<MistakeClass>().is_err());
    }

    #[test]
    fn gain_takes_the_better_channel_unless_the_other_grows() {
        let r = |l: f64, o: f64| Residual {
            of: ResidualOf::FramesOnly,
            length_rms_m: Some(l),
            orientation_rms_rad: Some(o),
            spread_m: Some(0.5),
        };
        // Orientation 10× better, position unchanged: 10.
        assert!((gain(&r(1e-3, 0.5), &r(1e-3, 0.05)) - 10.0).abs() < 1e-9);
        // Orientation 10× better, position 3× worse: no evidence (1/3).
        assert!(gain(&r(1e-3, 0.5), &r(3e-3, 0.05)) < 1.0);
    }
}
