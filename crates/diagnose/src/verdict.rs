//! What a diagnosis names, typed end to end in the one vocabulary ([`Effect`]); rendered and
//! serialised as the report writes it (`none`, `setup`, `cable_angle+thermal_drift`).

use hapcal_contract::Effect;
use serde::Serialize;

/// The verdict of a diagnosis (the haptic device's, `crate::diagnose`, or a robot's,
/// `crate::arm`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// No effect of the library is named: the gap is at the floor, or what explains it lies
    /// outside the library.
    None,
    /// The setup check found the data set up wrong and the user went on anyway: no physical
    /// effect is named (the command line sets it; the notes carry the finding).
    Setup,
    /// The library effects named, in the order they were named; never empty.
    Effects(Vec<Effect>),
}

impl Verdict {
    /// The verdict naming `effects` (in order), or [`Verdict::None`] for none.
    pub fn of(effects: &[Effect]) -> Verdict {
        if effects.is_empty() {
            Verdict::None
        } else {
            Verdict::Effects(effects.to_vec())
        }
    }

    /// Turns this into [`Verdict::Setup`] for data the setup check found set up wrong and the
    /// user went on with: no physical effect is named on them. `finding` (the check's finding,
    /// in words) joins `notes`, after a note naming the effects the fits would have named, if
    /// any.
    pub fn on_accepted_setup(&mut self, notes: &mut Vec<String>, finding: String) {
        if !self.effects().is_empty() {
            notes.push(format!(
                "the fits named {self}, but no physical effect is named on data the setup \
                 check found set up wrong"
            ));
        }
        *self = Verdict::Setup;
        notes.push(finding);
    }

    /// The effects named (empty for `none` and `setup`).
    pub fn effects(&self) -> &[Effect] {
        match self {
            Verdict::Effects(e) => e,
            Verdict::None | Verdict::Setup => &[],
        }
    }
}

impl std::fmt::Display for Verdict {
    /// `none`, `setup`, or the effects joined by `+`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Verdict::None => f.pad("none"),
            Verdict::Setup => f.pad("setup"),
            Verdict::Effects(e) => {
                let names: Vec<&str> = e.iter().map(|e| e.name()).collect();
                f.pad(&names.join("+"))
            }
        }
    }
}

impl Serialize for Verdict {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl PartialEq<str> for Verdict {
    /// Whether the report would write this verdict as `other`.
    fn eq(&self, other: &str) -> bool {
        match self {
            Verdict::None => other == "none",
            Verdict::Setup => other == "setup",
            Verdict::Effects(e) => other.split('+').eq(e.iter().map(|e| e.name())),
        }
    }
}

impl PartialEq<&str> for Verdict {
    fn eq(&self, other: &&str) -> bool {
        *self == **other
    }
}

/// Why the rounds named no further effect after `named` of at most `max_effects`: the cap, or
/// no candidate of the library passing (the haptic and the arm diagnosis word it alike).
pub(crate) fn stop_reason(named: usize, max_effects: usize) -> String {
    if named >= max_effects {
        format!("the search stops at {max_effects} effects (max_effects)")
    } else {
        "no further candidate of the library passes".to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_verdict_reads_as_the_report_writes_it() {
        assert_eq!(Verdict::of(&[]).to_string(), "none");
        assert_eq!(Verdict::Setup.to_string(), "setup");
        let two = Verdict::of(&[Effect::CableAngle, Effect::ThermalDrift]);
        assert_eq!(two.to_string(), "cable_angle+thermal_drift");
        assert_eq!(two, "cable_angle+thermal_drift");
        assert_eq!(two.effects(), [Effect::CableAngle, Effect::ThermalDrift]);
        assert_ne!(two, "cable_angle");
        assert_ne!(Verdict::None, "setup");
    }
}
