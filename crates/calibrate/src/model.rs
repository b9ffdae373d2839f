//! The calibration model, typed once for every kind of data. The models are named once, by
//! [`ModelName`] (`hapcal-contract`, the name every file and report writes); this module says
//! what calibration makes of them: which parameter families a model frees
//! ([`ModelRules::families`]), which kinds of data can determine it ([`DataKind`],
//! [`ModelRules::refusal`]), the model terms a problem is built with ([`terms`]), what
//! `--model` asks for ([`ModelChoice`]: `auto` or a model), the ladder `--model auto` climbs on
//! each kind of data ([`ladder`]) and the one rule that climbs it ([`climb`], argued in
//! docs/engine.md, "The rule that picks a rung").
//!
//! `calibrate` (every workflow), `diagnose`, `plan-poses`, the Rust API and the Python package
//! name models with these types alone.

use anyhow::{Context, Result, bail};
use hapcal_problems::{GravityCompliance, JointHarmonics, LinkMass, ModelTerms, Transversal};
use serde::Serialize;

pub use hapcal_contract::ModelName;

/// What `--model` asks for: the ladder ([`ModelChoice::Auto`]) or one model
/// ([`ModelName`], defined once in `hapcal-contract`, the name every file and report writes).
/// Rendered, and serialised, as the user types it: `auto`, or the model's name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ModelChoice {
    /// Chosen on the training data only (see [`help`] for the ladders).
    Auto,
    /// The model named.
    Model(ModelName),
}

/// `auto`, then every model in ladder order: the values `--model` takes.
const CHOICES: [ModelChoice; 14] = {
    let mut all = [ModelChoice::Auto; 14];
    let mut i = 0;
    while i < ModelName::ALL.len() {
        all[i + 1] = ModelChoice::Model(ModelName::ALL[i]);
        i += 1;
    }
    all
};

impl From<ModelName> for ModelChoice {
    fn from(model: ModelName) -> ModelChoice {
        ModelChoice::Model(model)
    }
}

impl PartialEq<ModelName> for ModelChoice {
    /// Whether this choice names `model` (`auto` names none).
    fn eq(&self, model: &ModelName) -> bool {
        *self == ModelChoice::Model(*model)
    }
}

impl clap::ValueEnum for ModelChoice {
    fn value_variants<'a>() -> &'a [Self] {
        &CHOICES
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()).help(help(*self)))
    }
}

/// The `hapcal calibrate --help` text of a `--model` value: plain words (no links).
pub fn help(choice: ModelChoice) -> &'static str {
    let ModelChoice::Model(model) = choice else {
        return "Chosen on the training data only: the ladder of the data's kind is climbed by \
                repeated blocked cross-validation, a model must beat the one chosen below it by \
                2 standard errors of the held-out difference (and, where the calibration will be \
                used beyond the training range of a joint, do no worse on folds that hold out \
                that end of the range). Measurement files: frames-only, joint-offsets, \
                geometric, compliance, transversal-compliance or transversal-axes, then harmonic \
                or harmonic2. Socket recordings and distance logs: geometric, then compliance. \
                For a robot with published link masses, mass-compliance and actuator-compliance are \
                alternatives to compliance (the lowest held-out error of those that pass). A \
                haptic device's logs: geometric, then transmissions (when the logs have \
                external-encoder columns), then compliance (when the device file has a handle \
                mass).";
    };
    match model {
        ModelName::FramesOnly => {
            "The nominal kinematics; only the instrument's and the markers' frames are fitted \
             (measurement files)."
        }
        ModelName::JointOffsets => "The frames plus one offset per joint (measurement files).",
        ModelName::Geometric => {
            "Every kinematic parameter the data determine (the others are pruned and reported). \
             On a haptic device's logs: the kinematic deviations alone, without the \
             transmissions."
        }
        ModelName::Compliance => {
            "Geometric plus one gravity compliance per joint, about its axis: the torques of \
             the URDF's inertial masses on the whole tree when measurement files come with \
             them, lumped link weights otherwise. On a haptic device's logs: the transmissions \
             (when the logs have external-encoder columns), the kinematic deviations and the \
             compliance of each joint under the handle's weight (the handle mass of the device \
             file), in rad/(N·m), fitted together."
        }
        ModelName::MassCompliance => {
            "Geometric plus one gravity compliance per joint with the torques of the robot's \
             published link masses (Franka Panda, KUKA LBR iiwa 14; refused for other robots)."
        }
        ModelName::ActuatorCompliance => {
            "As mass-compliance, with one compliance per actuator size."
        }
        ModelName::TransversalCompliance => {
            "Compliance plus a transversal compliance per revolute joint: the joint frame \
             bends about the axes normal to its axis under the gravity moment about them, alike \
             in every direction (URDF robots)."
        }
        ModelName::TransversalAxes => {
            "Compliance plus two transversal compliances per revolute joint, one about each of \
             the two axes of the link's frame normal to the joint axis: a link that bends more \
             easily one way than the other (URDF robots). A rung of auto on measurement files, \
             the alternative of transversal-compliance."
        }
        ModelName::Harmonic => {
            "Geometric plus once-per-revolution harmonic angle errors on every joint (encoder \
             eccentricity). A rung of auto on measurement files (the last level, with \
             harmonic2), not on socket recordings: on one MUKCa placement the harmonic models \
             fit the training data better and the other placements worse \
             (docs/results/mukca.md)."
        }
        ModelName::Harmonic2 => {
            "Geometric plus first- and second-order harmonic angle errors on every joint (the \
             alternative of harmonic on auto's last level on measurement files)."
        }
        ModelName::MassComplianceHarmonic => "Mass-compliance plus harmonic.",
        ModelName::ComplianceHarmonic => "Compliance plus harmonic.",
        ModelName::Transmissions => {
            "A haptic device's logs only: the transmissions (each capstan's eq. 1 and the \
             parallelogram's polynomial, from the external-encoder columns, which every \
             training log must have) and then the kinematic deviations (from the cable \
             distances): the paper's two steps."
        }
    }
}

/// The kind of the training data, typed when they are loaded: it decides which models the
/// data can determine and which ladder `--model auto` climbs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DataKind {
    /// MUKCa socket recordings: the tip in a fixed socket, whose position is identified.
    Sockets,
    /// Distance logs of a device with a cable encoder of its own (anchor known).
    Distances,
    /// Measurement files: marker positions, poses or distances from an anchor, in an
    /// instrument's frame that is identified with the kinematics.
    Measurements,
    /// The logs of a haptic device with transmissions (joint readings, external encoders,
    /// cable distance).
    HapticLogs,
}

impl DataKind {
    /// The data, in the words of a message.
    pub fn words(self) -> &'static str {
        match self {
            DataKind::Sockets => "socket recordings",
            DataKind::Distances => "distance logs of a device with its own cable encoder",
            DataKind::Measurements => {
                "measurement files (marker positions, poses, anchor distances)"
            }
            DataKind::HapticLogs => "a haptic device's logs",
        }
    }
}

/// Where a compliance model's gravity torques come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ComplianceSource {
    /// The URDF's inertial masses when the robot has them, a unit weight per link otherwise.
    Robot,
    /// The robot's published link masses (by joint names).
    Published,
    /// The published link masses with one compliance per actuator size.
    PublishedByActuator,
}

/// The parameter families a model frees besides the instrument and marker frames (which every
/// model on measurement files fits).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Families {
    /// One offset per joint (and no other kinematic parameter unless `geometric`).
    pub joint_offsets: bool,
    /// Every kinematic deviation the data determine.
    pub geometric: bool,
    /// Gravity compliance about each joint axis, with its torque source.
    pub compliance: Option<ComplianceSource>,
    /// Transversal compliance of each revolute joint: none, one, or one per axis normal to
    /// the joint axis.
    #[serde(serialize_with = "transversal_name")]
    pub transversal: Transversal,
    /// Highest order of the joint angle harmonics (0: none).
    pub harmonic_order: usize,
    /// The haptic device's transmissions (capstans, parallelogram).
    pub transmissions: bool,
}

/// `none`, `isotropic` or `per_axis`.
fn transversal_name<S: serde::Serializer>(t: &Transversal, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(match t {
        Transversal::None => "none",
        Transversal::Isotropic => "isotropic",
        Transversal::PerAxis => "per_axis",
    })
}

/// A rung of a kinematic ladder as a report names it: the nominal model (nothing fitted but
/// the nuisance parameters, the socket points) or a model.
/// Rendered, and serialised, as the user reads it: `nominal`, or the model's `--model` value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rung {
    /// The nominal kinematics.
    Nominal,
    /// A model of the ladder.
    Model(ModelName),
}

impl std::fmt::Display for Rung {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Rung::Nominal => f.pad("nominal"),
            Rung::Model(m) => f.pad(m.name()),
        }
    }
}

impl Serialize for Rung {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl Serialize for ModelChoice {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl std::fmt::Display for ModelChoice {
    /// The `--model` value, as the user types it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

impl ModelChoice {
    /// The `--model` value (`auto`, `mass-compliance`), as the user types it.
    pub fn name(self) -> &'static str {
        match self {
            ModelChoice::Auto => "auto",
            ModelChoice::Model(m) => m.name(),
        }
    }

    /// `auto`, then every model in ladder order (`--help` order).
    pub fn all() -> &'static [ModelChoice] {
        &CHOICES
    }

    /// The choice whose `--model` value is `name` (`-` or `_` between words), if any.
    pub fn from_name(name: &str) -> Option<ModelChoice> {
        if name.trim().eq_ignore_ascii_case("auto") {
            return Some(ModelChoice::Auto);
        }
        ModelName::from_name(name).map(ModelChoice::Model)
    }

    /// The model named, `None` for `auto`.
    pub fn model(self) -> Option<ModelName> {
        match self {
            ModelChoice::Auto => None,
            ModelChoice::Model(m) => Some(m),
        }
    }

    /// Why data of `kind` cannot determine this choice, in the user's words; `None` when they
    /// can (`auto` always can).
    pub fn refusal(self, kind: DataKind) -> Option<&'static str> {
        self.model().and_then(|m| m.refusal(kind))
    }

    /// `Ok` when data of `kind` can determine this choice.
    ///
    /// # Errors
    /// The model, named as the user typed it, the reason, and the values those data take.
    pub fn check_fits(self, kind: DataKind) -> Result<()> {
        let Some(reason) = self.refusal(kind) else {
            return Ok(());
        };
        let names: Vec<&str> = (Self::all().iter())
            .filter(|m| m.refusal(kind).is_none())
            .map(|m| m.name())
            .collect();
        bail!(
            "--model {self} does not apply to {}: {reason}; they take {}",
            kind.words(),
            names.join(", ")
        )
    }
}

/// What calibration makes of a model ([`ModelName`], defined in `hapcal-contract`): the
/// parameter families it frees and the kinds of data that determine it.
pub trait ModelRules {
    /// The parameter families this model frees.
    fn families(self) -> Families;

    /// Why data of `kind` cannot determine this model, in the user's words; `None` when they
    /// can (whether a particular robot carries it, such as published masses or revolute
    /// joints with rotation deviations, is decided when the problem is built).
    fn refusal(self, kind: DataKind) -> Option<&'static str>;

    /// Whether this model contains `simpler`, an alternative of its own ladder level: every
    /// estimate of `simpler` is one of this model's (per-axis transversal compliance with its
    /// two compliances equal is the isotropic one; harmonic2 with its second-order terms zero
    /// is harmonic). [`climb`] takes such a model only where it beats `simpler` too.
    /// Compliance from the URDF's masses (or lumped weights) and mass-compliance are not
    /// nested: their torques differ, so neither holds the other. Actuator-compliance is
    /// mass-compliance with the compliances of one actuator size equal, but it is not named
    /// here: on the MUKCa units that pair decides with one standard error between the two
    /// (docs/results/mukca.md), and the socket ladder's figures are held as measured.
    fn contains(self, simpler: ModelName) -> bool;
}

impl ModelRules for ModelName {
    fn families(self) -> Families {
        use ModelName as M;
        let compliance = match self {
            M::Compliance
            | M::TransversalCompliance
            | M::TransversalAxes
            | M::ComplianceHarmonic => Some(ComplianceSource::Robot),
            M::MassCompliance | M::MassComplianceHarmonic => Some(ComplianceSource::Published),
            M::ActuatorCompliance => Some(ComplianceSource::PublishedByActuator),
            _ => None,
        };
        Families {
            joint_offsets: self == M::JointOffsets,
            geometric: !matches!(self, M::FramesOnly | M::JointOffsets),
            compliance,
            transversal: match self {
                M::TransversalCompliance => Transversal::Isotropic,
                M::TransversalAxes => Transversal::PerAxis,
                _ => Transversal::None,
            },
            harmonic_order: match self {
                M::Harmonic | M::MassComplianceHarmonic | M::ComplianceHarmonic => 1,
                M::Harmonic2 => 2,
                _ => 0,
            },
            transmissions: self == M::Transmissions,
        }
    }

    fn refusal(self, kind: DataKind) -> Option<&'static str> {
        use ModelName as M;
        match (self, kind) {
            (M::Transmissions, DataKind::HapticLogs) => None,
            (M::Transmissions, _) => Some(
                "the transmissions are identified from a haptic device's external-encoder columns",
            ),
            (M::Geometric | M::Compliance, DataKind::HapticLogs) => None,
            (_, DataKind::HapticLogs) => Some(
                "a haptic device's logs determine its transmissions, its kinematic deviations \
                 and the gravity compliance of its handle (one per joint); they carry no link \
                 masses, transversal bending or harmonic terms",
            ),
            (M::FramesOnly | M::JointOffsets, DataKind::Sockets | DataKind::Distances) => Some(
                "socket recordings and distance logs have no instrument or marker frame: their \
                 smallest model is geometric",
            ),
            _ => None,
        }
    }

    fn contains(self, simpler: ModelName) -> bool {
        use ModelName as M;
        matches!(
            (self, simpler),
            (M::TransversalAxes, M::TransversalCompliance) | (M::Harmonic2, M::Harmonic)
        )
    }
}

/// The model terms (compliance, transversal compliance, joint harmonics) of `model` for a
/// robot with joints `joint_names` and, from a URDF, link masses `masses` (empty: lumped unit
/// weights for [`ComplianceSource::Robot`]). `torque_tips` and `load_angles` are left `None`
/// (the caller sets them for a tree or an equilibrium).
///
/// # Errors
/// A published-mass model on a robot whose joint names have no published masses.
pub fn terms(model: ModelName, joint_names: &[String], masses: &[LinkMass]) -> Result<ModelTerms> {
    let families = model.families();
    let compliance = match families.compliance {
        None => None,
        Some(ComplianceSource::Robot) if masses.is_empty() => Some(GravityCompliance::default()),
        Some(ComplianceSource::Robot) => Some(GravityCompliance::from_link_masses(
            masses.to_vec(),
            -nalgebra::Vector3::z(),
        )),
        Some(ComplianceSource::Published) => {
            Some(GravityCompliance::published(joint_names).with_context(|| {
                format!("--model {model}: no published link masses for this robot's joint names")
            })?)
        }
        Some(ComplianceSource::PublishedByActuator) => Some(
            GravityCompliance::published_by_actuator(joint_names).with_context(|| {
                format!("--model {model}: no published link masses for this robot's joint names")
            })?,
        ),
    };
    let n = joint_names.len();
    let harmonics = match families.harmonic_order {
        0 => None,
        1 => Some(JointHarmonics::first_order(n)),
        order => Some(JointHarmonics {
            joints: (0..n).collect(),
            orders: (1..=order as u32).collect(),
        }),
    };
    Ok(ModelTerms {
        compliance,
        transversal: families.transversal,
        harmonics,
        torque_tips: None,
        load_angles: None,
    })
}

/// The ladder `--model auto` climbs on data of `kind`: levels, simplest first, each a list of
/// alternatives (`published_masses`: the robot's joint names have published link masses, so
/// the compliance level also offers mass-compliance and actuator-compliance). Whether a robot
/// carries a rung (transversal compliance needs revolute joints with rotation deviations) is
/// the caller's filter.
///
/// - measurement files: frames-only → joint-offsets → geometric → compliance →
///   {transversal-compliance, transversal-axes} → {harmonic, harmonic2} (the diagnosis names
///   joint harmonics on these data: docs/engine.md);
/// - socket recordings and distance logs (no frame to fit: geometric is the bottom): geometric
///   → compliance (or its published-mass alternatives);
/// - a haptic device's logs: geometric → transmissions (when the logs have external-encoder
///   columns) → compliance (when the device file has a handle mass).
pub fn ladder(kind: DataKind, published_masses: bool) -> Vec<Vec<ModelName>> {
    use ModelName as M;
    let compliance = if published_masses {
        vec![M::Compliance, M::MassCompliance, M::ActuatorCompliance]
    } else {
        vec![M::Compliance]
    };
    match kind {
        DataKind::Measurements => vec![
            vec![M::FramesOnly],
            vec![M::JointOffsets],
            vec![M::Geometric],
            compliance,
            // Isotropic or per-axis transversal compliance: a link may bend more easily one
            // way than the other; the per-axis rung is taken only where it beats the rung
            // chosen below by the margin, with the lower held-out error of the two.
            vec![M::TransversalCompliance, M::TransversalAxes],
            // The diagnosis names joint harmonics on these data, so their models are rungs;
            // the joint-range folds stop them where they would extrapolate (docs/engine.md).
            vec![M::Harmonic, M::Harmonic2],
        ],
        // Transversal compliance is a model of these data (`--model transversal-compliance`)
        // but not a rung: a device file carries no link masses, so its moments come from
        // unit weights, and on one MUKCa placement it climbed by chance (panda_1 at 9 folds,
        // test error doubled: docs/results/mukca.md).
        DataKind::Sockets | DataKind::Distances => vec![vec![M::Geometric], compliance],
        // The bottom is geometric, as on every kind without frames; the transmissions need
        // the logs' external-encoder columns, the compliance the device's handle mass
        // (`haptic::haptic_rungs`).
        DataKind::HapticLogs => vec![
            vec![M::Geometric],
            vec![M::Transmissions],
            vec![M::Compliance],
        ],
    }
}

/// Whether a robot whose tips are `tips` carries transversal compliance: a revolute joint
/// with rotation deviations (`{joint}.rx`: URDF placements; a D-H row has none).
pub fn carries_transversal(tips: &[hapcal_kinematics::Chain]) -> bool {
    let Some(chain) = tips.first() else {
        return false;
    };
    let motions = hapcal_kinematics::joint_motions(tips);
    (chain.joint_names().iter().zip(&motions)).any(|(name, motion)| {
        *motion == Some(hapcal_kinematics::Motion::Rotation)
            && chain.param_index(&format!("{name}.rx")).is_some()
    })
}

/// Whether a robot with joints `joint_names` and tips `tips` carries `model`: transversal
/// compliance needs a revolute joint with rotation deviations ([`carries_transversal`]), the
/// published-mass models joint names with published masses; every other model fits any robot.
pub fn carries(
    model: ModelName,
    joint_names: &[String],
    tips: &[hapcal_kinematics::Chain],
) -> bool {
    let families = model.families();
    if families.transversal != Transversal::None {
        carries_transversal(tips)
    } else if families
        .compliance
        .is_some_and(|c| c != ComplianceSource::Robot)
    {
        GravityCompliance::published(joint_names).is_some()
    } else {
        true
    }
}

/// The rungs of `kind`'s ladder ([`ladder`]) that a robot with joints `joint_names` and tips
/// `tips` carries ([`carries`]), simplest first, and each one's level: what [`climb`] takes.
pub fn ladder_for(
    kind: DataKind,
    joint_names: &[String],
    tips: &[hapcal_kinematics::Chain],
) -> (Vec<ModelName>, Vec<usize>) {
    let published = GravityCompliance::published(joint_names).is_some();
    let mut rungs = Vec::new();
    let mut levels = Vec::new();
    for (l, level) in ladder(kind, published).into_iter().enumerate() {
        for m in level.into_iter().filter(|&m| carries(m, joint_names, tips)) {
            rungs.push(m);
            levels.push(l);
        }
    }
    (rungs, levels)
}

/// Standard errors by which a rung's held-out score must beat the rung chosen so far.
///
/// The ladder makes up to four sequential one-sided comparisons, each of which can climb by
/// chance. At one standard error a useless rung wins a comparison with probability ≈ 0.16
/// (normal tail), ≈ 0.5 over four; at two, ≈ 0.023 and ≈ 0.09. A calibration that is worse
/// than doing nothing costs more than one that leaves a small gain unclaimed, so the ladder
/// uses two, on every kind of data.
pub const LADDER_SIGNIFICANCE_Z: f64 = 2.0;

/// The one rule that picks a rung (docs/engine.md). `level[i]` is candidate `i`'s level on
/// the ladder (candidates in ladder order, candidate 0 the bottom rung, level 0);
/// `beats(i, j)` whether candidate `i` beats candidate `j` (its held-out score lower by
/// [`LADDER_SIGNIFICANCE_Z`] blocked standard errors, and no worse where the calibration
/// extrapolates); `rms(i)` its held-out RMS; `nested(i, j)`, where candidate `i` contains
/// candidate `j` ([`ModelRules::contains`]), whether it beats `j` by the same margin on the
/// blocked folds (`None` where it does not contain it). Level by level, among the
/// alternatives that beat the rung chosen so far, and beat every alternative of their level
/// they contain (parsimony: a richer model must earn its extra parameters against the simpler
/// one), the one with the lowest held-out RMS is chosen; a level where none does is passed
/// over (the next is compared with the same rung). Returns the chosen candidate's index.
///
/// Parsimony is judged on the blocked folds alone, as the choice of the lowest held-out RMS
/// among a level's alternatives is: the joint-range folds judge a rung against the one chosen
/// below it, the safe model where the calibration extrapolates, not one alternative against
/// another of the same level.
///
/// # Panics
/// If `level` is empty.
pub fn climb(
    level: &[usize],
    beats: &dyn Fn(usize, usize) -> bool,
    rms: &dyn Fn(usize) -> f64,
    nested: &dyn Fn(usize, usize) -> Option<bool>,
) -> usize {
    assert!(!level.is_empty(), "a ladder has at least one rung");
    let mut chosen = 0;
    let top = level.iter().copied().max().unwrap_or(0);
    let parsimonious = |i: usize| {
        (0..level.len())
            .filter(|&j| j != i && level[j] == level[i])
            .all(|j| nested(i, j).unwrap_or(true))
    };
    for l in (level[0] + 1)..=top {
        let passing =
            (0..level.len()).filter(|&i| level[i] == l && beats(i, chosen) && parsimonious(i));
        if let Some(best) = passing.min_by(|&a, &b| rms(a).total_cmp(&rms(b))) {
            chosen = best;
        }
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::{DataKind, ModelChoice, ModelName, climb, ladder};

    #[test]
    fn a_model_is_named_by_its_command_line_value() {
        for &model in ModelChoice::all() {
            let value = clap::ValueEnum::to_possible_value(&model).map(|v| v.get_name().to_owned());
            assert_eq!(Some(model.to_string()), value, "{model:?}");
        }
        assert_eq!(
            ModelChoice::from(ModelName::ComplianceHarmonic).to_string(),
            "compliance-harmonic"
        );
        // `auto` first, then every model once, in ladder order.
        let models: Vec<ModelName> = ModelChoice::all()
            .iter()
            .filter_map(|c| c.model())
            .collect();
        assert_eq!(ModelChoice::all()[0], ModelChoice::Auto);
        assert_eq!(models, ModelName::ALL);
        for &choice in ModelChoice::all() {
            assert_eq!(ModelChoice::from_name(choice.name()), Some(choice));
        }
    }

    #[test]
    fn each_kind_of_data_refuses_the_models_it_cannot_determine_by_their_values() {
        use DataKind as K;
        use ModelName as M;
        let cases = [
            (
                M::MassCompliance,
                K::HapticLogs,
                "auto, geometric, compliance, transmissions",
            ),
            (
                M::FramesOnly,
                K::Sockets,
                "their smallest model is geometric",
            ),
            (M::JointOffsets, K::Distances, "auto, geometric, compliance"),
            (
                M::Transmissions,
                K::Measurements,
                "external-encoder columns",
            ),
        ];
        for (model, kind, listed) in cases {
            let model = ModelChoice::Model(model);
            let Err(err) = model.check_fits(kind).map_err(|e| e.to_string()) else {
                panic!("{model} is refused on {kind:?}");
            };
            assert!(
                err.starts_with(&format!(
                    "--model {model} does not apply to {}",
                    kind.words()
                )) && err.contains(listed)
                    && !err.contains("ModelChoice"),
                "{err}"
            );
        }
        // Every non-transmission model on every robot data kind; the haptic logs' own four.
        for kind in [K::Sockets, K::Distances, K::Measurements] {
            for &m in ModelChoice::all() {
                let frames = m == M::FramesOnly || m == M::JointOffsets;
                let expected = m != M::Transmissions && (kind == K::Measurements || !frames);
                assert_eq!(m.check_fits(kind).is_ok(), expected, "{m} on {kind:?}");
            }
        }
        for &m in ModelChoice::all() {
            let expected = m == ModelChoice::Auto
                || m == M::Transmissions
                || m == M::Geometric
                || m == M::Compliance;
            assert_eq!(m.check_fits(K::HapticLogs).is_ok(), expected, "{m}");
        }
    }

    #[test]
    fn every_rung_of_every_ladder_is_a_model_its_data_determine() {
        for kind in [
            DataKind::Sockets,
            DataKind::Distances,
            DataKind::Measurements,
            DataKind::HapticLogs,
        ] {
            for published in [false, true] {
                let rungs = ladder(kind, published);
                assert!(!rungs.is_empty());
                for m in rungs.iter().flatten() {
                    let choice = ModelChoice::Model(*m);
                    assert!(choice.check_fits(kind).is_ok(), "{m} on {kind:?}");
                }
                // Simplest first: the rungs' order is the models' order (the transmissions,
                // last of the models, sit below the compliance on the haptic ladder: the
                // haptic compliance model holds them).
                let flat: Vec<ModelName> = rungs.iter().flatten().copied().collect();
                if kind == DataKind::HapticLogs {
                    assert_eq!(
                        flat,
                        [
                            ModelName::Geometric,
                            ModelName::Transmissions,
                            ModelName::Compliance
                        ]
                    );
                } else {
                    assert!(flat.windows(2).all(|w| w[0] < w[1]), "{flat:?}");
                }
            }
        }
        // Measurement files: isotropic and per-axis transversal compliance are one level's
        // alternatives.
        let transversal = [ModelName::TransversalCompliance, ModelName::TransversalAxes];
        assert!(
            ladder(DataKind::Measurements, false).contains(&transversal.to_vec()),
            "{:?}",
            ladder(DataKind::Measurements, false)
        );
    }

    #[test]
    fn the_rule_climbs_level_by_level_and_takes_the_best_passing_alternative() {
        // Levels: 0 | 1 | 2, 2, 2 | 3.
        let level = [0, 1, 2, 2, 2, 3];
        let rms = [10.0, 9.0, 5.0, 4.0, 4.5, 3.0];
        // Level 1 fails, level 2: candidates 2 and 4 beat the bottom, 3 does not (lower RMS
        // but inside the margin); level 3 does not beat candidate 4.
        let beats = |i: usize, j: usize| matches!((i, j), (2, 0) | (4, 0) | (5, 2));
        let none = |_: usize, _: usize| None;
        assert_eq!(climb(&level, &beats, &|i| rms[i], &none), 4);
        // A rung is compared with the one chosen so far, not with the bottom.
        let beats = |i: usize, j: usize| matches!((i, j), (1, 0) | (2, 0) | (5, 1));
        assert_eq!(climb(&level, &beats, &|i| rms[i], &none), 5);
        // Nothing beats the bottom: it stays.
        assert_eq!(climb(&level, &|_, _| false, &|i| rms[i], &none), 0);
    }

    #[test]
    fn a_richer_alternative_is_taken_only_where_it_beats_the_one_it_contains() {
        use super::ModelRules;
        use ModelName as M;
        // Geometric | isotropic, per-axis transversal compliance: both beat geometric, the
        // per-axis one with the lower held-out RMS but not by the margin over the isotropic
        // one it contains (the real humanoid's −5.85 ± 0.11 per row, both).
        let rungs = [M::Geometric, M::TransversalCompliance, M::TransversalAxes];
        let level = [0, 1, 1];
        let rms = [5.0, 3.96, 3.95];
        let beats = |i: usize, j: usize| matches!((i, j), (1, 0) | (2, 0) | (2, 1));
        let nested = |i: usize, j: usize| rungs[i].contains(rungs[j]).then(|| beats(i, j));
        // Where it does beat the isotropic one by the margin, the per-axis rung is taken.
        assert_eq!(climb(&level, &beats, &|i| rms[i], &nested), 2);
        let beats = |i: usize, j: usize| matches!((i, j), (1, 0) | (2, 0));
        let nested = |i: usize, j: usize| rungs[i].contains(rungs[j]).then(|| beats(i, j));
        assert_eq!(climb(&level, &beats, &|i| rms[i], &nested), 1);
        // The nested comparison is its own: a rung the range folds would not let past the
        // isotropic one is still taken where the blocked folds say it earns its parameters.
        let beats = |i: usize, j: usize| matches!((i, j), (1, 0) | (2, 0));
        let nested = |i: usize, j: usize| rungs[i].contains(rungs[j]).then_some(true);
        assert_eq!(climb(&level, &beats, &|i| rms[i], &nested), 2);
        // The harmonics nest the same way; the compliance sources do not.
        assert!(M::Harmonic2.contains(M::Harmonic) && !M::Harmonic.contains(M::Harmonic2));
        assert!(!M::MassCompliance.contains(M::Compliance));
        assert!(!M::TransversalCompliance.contains(M::TransversalAxes));
    }
}
