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

/// Share of its round's held-out gap above the floor, and of its in-sample excess `RSS − dof`,
/// one of which the last accepted effect must close unless what it leaves is consistent with
/// the floor (docs/diagnosis.md §3 (d)): an effect estimated poorly on training folds closes
/// less of the held-out gap than of the in-sample excess.
const SUFFICIENT_SHARE: (f64, f64) = (0.8, 0.9);

/// What an accepted effect closes of the gap its round faced: shares (0–1) of the held-out gap
/// and of the in-sample excess, and whether a significant gap remains after it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RoundShare {
    pub(crate) heldout: f64,
    pub(crate) in_sample: f64,
    pub(crate) significant: bool,
}

/// How many of the accepted effects (`shares`, in the order accepted) are named: from the
/// last back, one closing less than [`SUFFICIENT_SHARE`] and leaving a significant gap explains
/// a part of something else and is not named (`not_enough` is told its index).
pub(crate) fn sufficient(shares: &[RoundShare], mut not_enough: impl FnMut(usize)) -> usize {
    let mut named = shares.len();
    while let Some(s) = named.checked_sub(1).map(|k| shares[k]) {
        let (heldout, in_sample) = SUFFICIENT_SHARE;
        if s.heldout >= heldout || s.in_sample >= in_sample || !s.significant {
            break;
        }
        named -= 1;
        not_enough(named);
    }
    named
}

/// The note on a significant residual after the `named` effects of `verdict` (at most
/// `max_effects`): their cross-validated mean squared error against the floor's, m².
pub(crate) fn residual_note(
    verdict: &Verdict,
    (final_mse, floor_mse): (f64, f64),
    (named, max_effects): (usize, usize),
    length: Length,
) -> String {
    let why = if named >= max_effects {
        format!("the search stops at {max_effects} effects (max_effects)")
    } else {
        "no further candidate of the library passes".to_owned()
    };
    let (rms, floor, unit) = (
        length.of(final_mse.sqrt()),
        length.of(floor_mse.sqrt()),
        length.0,
    );
    format!(
        "after {verdict} the cross-validated RMS is {rms} {unit}, {:.1}× the floor's {floor} \
         {unit}, a significant residual: another effect is at work that the verdict does not \
         name ({why})",
        (final_mse / floor_mse).sqrt(),
    )
}

/// The unit a report writes lengths in: name, metres per unit, decimals.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Length(pub(crate) &'static str, f64, usize);

/// µm to 0.1: a haptic device's cable distance.
pub(crate) const MICROMETRES: Length = Length("µm", 1e6, 1);

/// mm to 0.001: a robot's positions.
pub(crate) const MILLIMETRES: Length = Length("mm", 1e3, 3);

impl Length {
    /// `m` (m) in this unit, without the unit.
    pub(crate) fn of(self, m: f64) -> String {
        format!("{:.*}", self.2, m * self.1)
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
