//! The one vocabulary of effects: every effect that a calibration model frees or a diagnosis
//! can name, defined once with one name and one meaning (docs/design.md §6.1).
//!
//! `hapcal calibrate`'s models ([`ModelName`]) are sets of these effects
//! ([`ModelName::effects`]); `hapcal diagnose` names them; the simulator's effect library
//! injects them; the studies score verdicts made of them; the Python package reads the same
//! names. A name is written here and nowhere else: `cargo xtask tidy` fails on a crate's source
//! that spells one of these names as a string of its own.
//!
//! Names are `snake_case` (`gravity_compliance`), as the diagnosis's JSON and the simulator's
//! truth files write them; models keep their `kebab-case` `--model` names.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::ModelName;

/// An effect: a deviation of the real device from its nominal kinematics that a calibration
/// can fit or a diagnosis can name. Each variant's doc comment is its one meaning; [`Effect::name`]
/// is its one name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// A constant offset of each joint's reading, rad (m for a prismatic joint).
    JointOffsets,
    /// Every kinematic parameter the data determine: lengths (m), twists and offsets (rad)
    /// of every joint's frame, Denavit–Hartenberg or URDF origin deviations.
    Geometric,
    /// A haptic device's capstan drives: each capstan's ratio and drum eccentricity (the
    /// paper's eq. 1), from the external encoders.
    Capstans,
    /// A haptic device's parallelogram: the polynomial from the motor angle to joint 4's
    /// angle, from the external encoder.
    Parallelogram,
    /// Joint compliance about each joint's axis under the gravity torques of known masses:
    /// `Δq_j = k_j·τ_j(q)`, `τ_j` in N·m from the URDF's `<inertial>` masses, a robot's
    /// published link masses or a haptic device's handle mass; `k_j` in rad/(N·m) (Zhou,
    /// Kang & Ryu 2014; Nubiola & Bonev 2013).
    GravityCompliance,
    /// Joint compliance with the published link masses and one `k` per actuator size,
    /// rad/(N·m).
    ActuatorCompliance,
    /// Joint compliance without masses: `Δq_j = k_j·τ̂_j(q)`, `τ̂_j` the moment about joint
    /// `j`'s axis of a unit weight at the origin of every joint below it and at each tip, m;
    /// `k_j` in rad/m.
    LumpedCompliance,
    /// Each revolute joint's frame bends about the axes normal to the joint axis under the
    /// gravity moment about them, alike in every direction: tilt `c_j·m⊥_j(q)`, `c_j` in
    /// rad/(N·m) (rad/m without masses).
    TransversalCompliance,
    /// As transversal compliance, with one `c` about each of the two axes of the link's frame
    /// normal to the joint axis (a link that bends more easily one way than the other).
    TransversalAxes,
    /// Once-per-revolution angle error of each revolute joint, `a_j sin q_j + b_j cos q_j`,
    /// rad: encoder or gear eccentricity (Renders et al. 1991; Heidenhain, "Angle encoder
    /// accuracy").
    FirstHarmonic,
    /// Twice-per-revolution angle error, `a_j sin 2q_j + b_j cos 2q_j`, rad: an elliptic gear
    /// or encoder disc.
    SecondHarmonic,
    /// The second harmonic of a capstan's motor-drum eccentricity, in the drum's angle (the
    /// next term of the paper's eq. 1 Fourier series).
    CapstanHarmonic,
    /// Backlash: `Δq_j = b_j·s_j`, `s_j` the sign of the joint's last motion; `|b_j|` the
    /// half-play, rad.
    Backlash,
    /// Gear-ratio (scale) error of a joint: `Δq_j = s_j·q_j`.
    GearRatio,
    /// Thermal drift: the measurement drifts linearly in time (a measured point by `v·t`, m;
    /// a cable length by a scale `k·t`).
    ThermalDrift,
    /// Link deflection under gravity: the tip sags by `c·(ρ/ρ_max)³` along gravity, `ρ` its
    /// horizontal reach (a cantilever under an end load), m.
    LinkDeflection,
    /// Scale error of the instrument: `Δp = s·p` (positions) or `Δd = s·d` (distances).
    InstrumentScale,
    /// Cable-encoder error growing with the cable's angle from the rig's z axis, m/rad.
    CableAngle,
    /// Zero offset of the cable encoder, m.
    CableOffset,
    /// Time offset between the joint and cable samples, s.
    Latency,
    /// A local bump in one joint's angle (a dent in a drum): outside every library, for blind
    /// tests.
    JointBump,
    /// Once-per-revolution error of the cable-encoder drum: outside every library, for blind
    /// tests.
    CableDrumRunout,
}

/// The measurement that tells two effects apart, in the words of a report.
pub type SeparatingMeasurement = &'static str;

impl Effect {
    /// Every effect, in report order.
    pub const ALL: [Effect; 22] = [
        Effect::JointOffsets,
        Effect::Geometric,
        Effect::Capstans,
        Effect::Parallelogram,
        Effect::GravityCompliance,
        Effect::ActuatorCompliance,
        Effect::LumpedCompliance,
        Effect::TransversalCompliance,
        Effect::TransversalAxes,
        Effect::FirstHarmonic,
        Effect::SecondHarmonic,
        Effect::CapstanHarmonic,
        Effect::Backlash,
        Effect::GearRatio,
        Effect::ThermalDrift,
        Effect::LinkDeflection,
        Effect::InstrumentScale,
        Effect::CableAngle,
        Effect::CableOffset,
        Effect::Latency,
        Effect::JointBump,
        Effect::CableDrumRunout,
    ];

    /// The one name (`gravity_compliance`, …): the diagnosis's JSON, the simulator's truth
    /// files, the studies and the Python package.
    pub const fn name(self) -> &'static str {
        match self {
            Effect::JointOffsets => "joint_offsets",
            Effect::Geometric => "geometric",
            Effect::Capstans => "capstan",
            Effect::Parallelogram => "parallelogram",
            Effect::GravityCompliance => "gravity_compliance",
            Effect::ActuatorCompliance => "actuator_compliance",
            Effect::LumpedCompliance => "lumped_compliance",
            Effect::TransversalCompliance => "transversal_compliance",
            Effect::TransversalAxes => "transversal_axes",
            Effect::FirstHarmonic => "first_harmonic",
            Effect::SecondHarmonic => "second_harmonic",
            Effect::CapstanHarmonic => "capstan_harmonic",
            Effect::Backlash => "backlash",
            Effect::GearRatio => "gear_ratio",
            Effect::ThermalDrift => "thermal_drift",
            Effect::LinkDeflection => "link_deflection",
            Effect::InstrumentScale => "instrument_scale",
            Effect::CableAngle => "cable_angle",
            Effect::CableOffset => "cable_offset",
            Effect::Latency => "latency",
            Effect::JointBump => "joint_bump",
            Effect::CableDrumRunout => "cable_drum_runout",
        }
    }

    /// The effect named `name`; `None` for any other string.
    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The effect in a report's words (`joint compliance under gravity`).
    pub fn words(self) -> &'static str {
        match self {
            Effect::JointOffsets => "joint offsets",
            Effect::Geometric => "kinematic deviations",
            Effect::Capstans => "capstan ratio and drum eccentricity",
            Effect::Parallelogram => "parallelogram transmission error",
            Effect::GravityCompliance => "joint compliance under the links' weight",
            Effect::ActuatorCompliance => "joint compliance per actuator size",
            Effect::LumpedCompliance => "joint compliance under lumped unit weights",
            Effect::TransversalCompliance => "links bending sideways under gravity",
            Effect::TransversalAxes => "links bending sideways, per axis",
            Effect::FirstHarmonic => "once-per-revolution joint angle error",
            Effect::SecondHarmonic => "twice-per-revolution joint angle error",
            Effect::CapstanHarmonic => "second harmonic of a capstan drum",
            Effect::Backlash => "backlash",
            Effect::GearRatio => "gear-ratio error",
            Effect::ThermalDrift => "thermal drift",
            Effect::LinkDeflection => "link deflection under gravity",
            Effect::InstrumentScale => "instrument scale error",
            Effect::CableAngle => "cable-angle error of the cable encoder",
            Effect::CableOffset => "cable-encoder zero offset",
            Effect::Latency => "latency between joint and cable samples",
            Effect::JointBump => "a local bump in one joint's angle",
            Effect::CableDrumRunout => "cable-encoder drum run-out",
        }
    }

    /// Whether this is a joint compliance about the joint axes (one effect under three torque
    /// models).
    pub fn is_joint_compliance(self) -> bool {
        matches!(
            self,
            Effect::GravityCompliance | Effect::ActuatorCompliance | Effect::LumpedCompliance
        )
    }

    /// Whether this is a transversal compliance (isotropic or per axis).
    pub fn is_transversal(self) -> bool {
        matches!(
            self,
            Effect::TransversalCompliance | Effect::TransversalAxes
        )
    }

    /// The smallest calibration model that fits this effect on measurement files, or why
    /// there is none: the rung of `--model auto`'s ladder (or an alternative of a level) that
    /// describes what a diagnosis names.
    pub fn model(self) -> Result<ModelName, &'static str> {
        match self {
            Effect::JointOffsets => Ok(ModelName::JointOffsets),
            Effect::Geometric => Ok(ModelName::Geometric),
            Effect::Capstans | Effect::Parallelogram => Ok(ModelName::Transmissions),
            Effect::GravityCompliance | Effect::LumpedCompliance => Ok(ModelName::Compliance),
            Effect::ActuatorCompliance => Ok(ModelName::ActuatorCompliance),
            Effect::TransversalCompliance => Ok(ModelName::TransversalCompliance),
            Effect::TransversalAxes => Ok(ModelName::TransversalAxes),
            Effect::FirstHarmonic => Ok(ModelName::Harmonic),
            Effect::SecondHarmonic => Ok(ModelName::Harmonic2),
            Effect::CapstanHarmonic => Err(
                "the transmission model has the capstan's first harmonic only (the paper's eq. 1)",
            ),
            Effect::Backlash => Err(
                "no calibration model has backlash: it depends on the direction each joint was \
                 last moved in, which a pose to be commanded does not carry",
            ),
            Effect::GearRatio => Err(
                "no calibration model has a gear-ratio error: over a joint's range it is \
                 indistinguishable from the joint offset and the first harmonic on most data",
            ),
            Effect::ThermalDrift => Err(
                "no calibration model has thermal drift: it depends on the time of the \
                 measurement, not on the pose",
            ),
            Effect::LinkDeflection => Err(
                "no calibration model has a cantilever sag; transversal compliance is the \
                 model of links bending under gravity",
            ),
            Effect::InstrumentScale => Err(
                "the instrument's scale is the instrument's error, not the robot's: calibrate \
                 the instrument (a scale bar)",
            ),
            Effect::CableAngle | Effect::CableOffset | Effect::Latency => Err(
                "an error of the cable-encoder rig, not of the device: fix or calibrate the rig",
            ),
            Effect::JointBump | Effect::CableDrumRunout => {
                Err("outside every library (simulated for blind tests only)")
            }
        }
    }

    /// The same effect under its other model, which the data may not tell apart: the other
    /// torque model of a joint compliance, the other order of a joint harmonic, the other form
    /// of a transversal compliance; `None` for an effect with one model.
    pub fn alternative(self) -> Option<Effect> {
        match self {
            Effect::GravityCompliance => Some(Effect::LumpedCompliance),
            Effect::LumpedCompliance => Some(Effect::GravityCompliance),
            Effect::FirstHarmonic => Some(Effect::SecondHarmonic),
            Effect::SecondHarmonic => Some(Effect::FirstHarmonic),
            Effect::TransversalCompliance => Some(Effect::TransversalAxes),
            Effect::TransversalAxes => Some(Effect::TransversalCompliance),
            _ => None,
        }
    }

    /// The measurement that separates this effect from `other` when the data confuse them.
    pub fn separating_measurement(self, other: Effect) -> SeparatingMeasurement {
        use Effect::*;
        let pair = |a, b| (self == a && other == b) || (self == b && other == a);
        let either = |e| self == e || other == e;
        if pair(GravityCompliance, LumpedCompliance) {
            "the same poses with and without a known payload"
        } else if either(LinkDeflection)
            && (self.is_joint_compliance() || other.is_joint_compliance())
        {
            "poses of equal joint torque at different reach (elbow up and down)"
        } else if (self.is_transversal() || other.is_transversal())
            && (self.is_joint_compliance() || other.is_joint_compliance() || either(LinkDeflection))
        {
            "poses that load each joint about its axis and across it in different proportions \
             (the same tip position with the arm rotated about the base)"
        } else if either(Backlash) {
            "each pose approached from both sides of every joint"
        } else if either(ThermalDrift) {
            "one reference pose repeated at the start, middle and end of the recording"
        } else if either(InstrumentScale) {
            "a calibrated length (scale bar) measured by the instrument"
        } else if either(GearRatio) && (either(FirstHarmonic) || either(SecondHarmonic)) {
            "poses covering each joint's full range"
        } else {
            "poses spread over every joint's range and the workspace"
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

impl ModelName {
    /// The effects this model frees on top of the nominal kinematics and the instrument and
    /// marker frames, with the torque model its compliance takes: `masses` when the robot's
    /// link masses are known (URDF `<inertial>` elements, or a haptic device's handle mass),
    /// lumped unit weights otherwise.
    pub fn effects(self, masses: bool) -> Vec<Effect> {
        let compliance = if masses {
            Effect::GravityCompliance
        } else {
            Effect::LumpedCompliance
        };
        match self {
            ModelName::FramesOnly => vec![],
            ModelName::JointOffsets => vec![Effect::JointOffsets],
            ModelName::Geometric => vec![Effect::Geometric],
            ModelName::Compliance => vec![Effect::Geometric, compliance],
            ModelName::MassCompliance => vec![Effect::Geometric, Effect::GravityCompliance],
            ModelName::ActuatorCompliance => vec![Effect::Geometric, Effect::ActuatorCompliance],
            ModelName::TransversalCompliance => {
                vec![Effect::Geometric, compliance, Effect::TransversalCompliance]
            }
            ModelName::TransversalAxes => {
                vec![Effect::Geometric, compliance, Effect::TransversalAxes]
            }
            ModelName::Harmonic => vec![Effect::Geometric, Effect::FirstHarmonic],
            ModelName::Harmonic2 => vec![
                Effect::Geometric,
                Effect::FirstHarmonic,
                Effect::SecondHarmonic,
            ],
            ModelName::MassComplianceHarmonic => vec![
                Effect::Geometric,
                Effect::GravityCompliance,
                Effect::FirstHarmonic,
            ],
            ModelName::ComplianceHarmonic => {
                vec![Effect::Geometric, compliance, Effect::FirstHarmonic]
            }
            ModelName::Transmissions => {
                vec![Effect::Capstans, Effect::Parallelogram, Effect::Geometric]
            }
        }
    }
}

/// The calibration model that describes a diagnosis's verdict ([`ModelName::for_effects`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ModelFor {
    /// The smallest model that frees every named effect that has a model: `Ok(None)` when
    /// none has one (the kinematic rungs describe the data), `Err` with the effects when no
    /// single model frees them together.
    pub model: Result<Option<ModelName>, Vec<Effect>>,
    /// The named effects no calibration model has, each with the reason
    /// ([`Effect::model`]).
    pub beyond: Vec<(Effect, &'static str)>,
}

impl ModelName {
    /// The smallest model (fewest effects; a data-dependent compliance before the published
    /// masses) that frees every effect of `effects` which has a model, with either torque
    /// model of its compliance; the other effects with the reason no model has them. How a
    /// diagnosis's verdict is compared with the rung `--model auto` takes.
    pub fn for_effects(effects: &[Effect]) -> ModelFor {
        let mut beyond = Vec::new();
        let mut fitted = Vec::new();
        for &e in effects {
            match e.model() {
                Ok(_) => fitted.push(e),
                Err(reason) => beyond.push((e, reason)),
            }
        }
        if fitted.is_empty() {
            return ModelFor {
                model: Ok(None),
                beyond,
            };
        }
        let published = |m: ModelName| {
            matches!(
                m,
                ModelName::MassCompliance
                    | ModelName::ActuatorCompliance
                    | ModelName::MassComplianceHarmonic
            )
        };
        let frees = |m: ModelName| {
            [true, false]
                .into_iter()
                .any(|masses| fitted.iter().all(|e| m.effects(masses).contains(e)))
        };
        let model = (ModelName::ALL.into_iter())
            .filter(|&m| frees(m))
            .min_by_key(|&m| (m.effects(true).len(), published(m)));
        ModelFor {
            model: model.map(Some).ok_or(fitted),
            beyond,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_is_one_effect_and_no_model() {
        let mut names: Vec<&str> = Effect::ALL.iter().map(|e| e.name()).collect();
        names.sort_unstable();
        let before = names.len();
        names.dedup();
        assert_eq!(names.len(), before, "two effects share a name");
        for e in Effect::ALL {
            assert_eq!(Effect::from_name(e.name()), Some(e));
            // A model spelled as an effect is the model whose topmost effect it is
            // (`geometric`, `transversal-compliance`); `harmonic2` is a model, the first two
            // orders, and the second order alone is the effect `second_harmonic`.
            for m in ModelName::ALL {
                if m.name().replace('-', "_") == e.name() {
                    assert_eq!(m.effects(true).last(), Some(&e), "{m} and {e}");
                    assert_eq!(m.effects(false).last(), Some(&e), "{m} and {e}");
                }
            }
        }
    }

    #[test]
    fn each_models_effects_lead_back_to_a_model_no_larger() {
        for m in ModelName::ALL {
            for e in m.effects(true).into_iter().chain(m.effects(false)) {
                let back = e.model().expect("a model's effect has a model");
                assert!(
                    back.effects(true).len() <= m.effects(true).len(),
                    "{e} of {m} leads to {back}"
                );
            }
        }
    }

    #[test]
    fn a_verdict_leads_to_the_smallest_model_that_frees_it() {
        use Effect::*;
        let of = |e: &[Effect]| ModelName::for_effects(e);
        assert_eq!(of(&[]).model, Ok(None));
        for (effects, model) in [
            (&[GravityCompliance][..], ModelName::Compliance),
            (&[LumpedCompliance], ModelName::Compliance),
            (
                &[GravityCompliance, FirstHarmonic],
                ModelName::ComplianceHarmonic,
            ),
            (
                &[GravityCompliance, TransversalCompliance],
                ModelName::TransversalCompliance,
            ),
            (&[FirstHarmonic, SecondHarmonic], ModelName::Harmonic2),
        ] {
            assert_eq!(of(effects).model, Ok(Some(model)), "{effects:?}");
        }
        // No one model has transversal compliance and harmonics together.
        assert_eq!(
            of(&[TransversalCompliance, FirstHarmonic]).model,
            Err(vec![TransversalCompliance, FirstHarmonic])
        );
        // Effects without a model are set apart with their reason.
        let f = of(&[Backlash, FirstHarmonic, GearRatio]);
        assert_eq!(f.model, Ok(Some(ModelName::Harmonic)));
        let apart: Vec<Effect> = f.beyond.iter().map(|b| b.0).collect();
        assert_eq!(apart, [Backlash, GearRatio]);
    }

    #[test]
    fn alternatives_are_symmetric() {
        for e in Effect::ALL {
            if let Some(a) = e.alternative() {
                assert_eq!(a.alternative(), Some(e));
            }
        }
    }
}
