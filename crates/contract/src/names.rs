//! The names of recorded values, typed.

use crate::TorqueSource;

/// A D-H deviation's field (`da3`, `dalpha3`, `dd3`, `dtheta3`, `dbeta3`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DhField {
    /// Link length `a`, m.
    A,
    /// Twist `α`, rad.
    Alpha,
    /// Offset `d`, m.
    D,
    /// Joint angle `θ`, rad.
    Theta,
    /// Hayati's `β`, rad.
    Beta,
}

/// The field a name spells `text` in `table` (spelling, field), if any.
fn field<F: Copy>(table: &[(&str, F)], text: &str) -> Option<F> {
    (table.iter()).find_map(|&(s, f)| (s == text).then_some(f))
}

/// How names spell `field` in `table` (spelling, field); every field of a table is in it.
fn spelling<F: PartialEq>(table: &[(&'static str, F)], field: F) -> &'static str {
    (table.iter())
        .find_map(|(s, f)| (*f == field).then_some(*s))
        .unwrap_or_default()
}

impl DhField {
    /// The fields by the prefix a name spells them with (`da3`, `dalpha3`, …), the longest
    /// prefixes first (`dalpha3` also starts with `da`).
    const PREFIXES: [(&'static str, DhField); 5] = [
        ("dalpha", DhField::Alpha),
        ("dtheta", DhField::Theta),
        ("dbeta", DhField::Beta),
        ("da", DhField::A),
        ("dd", DhField::D),
    ];

    /// The prefix of the field's names: `da`, `dalpha`, `dd`, `dtheta` or `dbeta`.
    pub fn prefix(self) -> &'static str {
        spelling(&Self::PREFIXES, self)
    }
}

/// A deviation of a placement element (`{element}.x` … `.rz`, `.offset`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ElementField {
    /// Translation along x, m.
    X,
    /// Translation along y, m.
    Y,
    /// Translation along z, m.
    Z,
    /// Rotation about x, rad.
    Rx,
    /// Rotation about y, rad.
    Ry,
    /// Rotation about z, rad.
    Rz,
    /// A joint's zero offset about (rad) or along (m) its axis.
    Offset,
}

impl ElementField {
    /// The fields by the suffix a name spells them with (`{element}.x`, …).
    const SUFFIXES: [(&'static str, ElementField); 7] = [
        ("x", ElementField::X),
        ("y", ElementField::Y),
        ("z", ElementField::Z),
        ("rx", ElementField::Rx),
        ("ry", ElementField::Ry),
        ("rz", ElementField::Rz),
        ("offset", ElementField::Offset),
    ];

    /// The field by its suffix (`x`, `y`, `z`, `rx`, `ry`, `rz`, `offset`).
    pub fn parse(suffix: &str) -> Option<ElementField> {
        field(&Self::SUFFIXES, suffix)
    }

    /// The suffix of the field's names: `x`, `y`, `z`, `rx`, `ry`, `rz` or `offset`.
    pub fn suffix(self) -> &'static str {
        spelling(&Self::SUFFIXES, self)
    }
}

/// A capstan parameter of paper eq. 1 (`capstan{j}.c`, …).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CapstanField {
    /// `c`, rad.
    C,
    /// `re`, the ratio error, 1.
    Re,
    /// `r_o`, m.
    ROut,
    /// `beta_o`, rad.
    BetaOut,
    /// `r_i`, m.
    RIn,
    /// `beta_i`, rad.
    BetaIn,
}

impl CapstanField {
    /// The fields in the order of paper eq. 1's parameter vector, by their file names.
    pub const ALL: [(&'static str, CapstanField); 6] = [
        ("c", CapstanField::C),
        ("re", CapstanField::Re),
        ("r_o", CapstanField::ROut),
        ("beta_o", CapstanField::BetaOut),
        ("r_i", CapstanField::RIn),
        ("beta_i", CapstanField::BetaIn),
    ];

    /// The field by its file name (`c`, `re`, `r_o`, `beta_o`, `r_i`, `beta_i`).
    pub fn parse(name: &str) -> Option<CapstanField> {
        field(&Self::ALL, name)
    }

    /// Its file name: `c`, `re`, `r_o`, `beta_o`, `r_i` or `beta_i`.
    pub fn name(self) -> &'static str {
        spelling(&Self::ALL, self)
    }

    /// Its unit: `rad`, `1` or `m`.
    pub fn unit(self) -> &'static str {
        match self {
            CapstanField::C | CapstanField::BetaOut | CapstanField::BetaIn => "rad",
            CapstanField::Re => "1",
            CapstanField::ROut | CapstanField::RIn => "m",
        }
    }
}

/// What a recorded value is, from its name.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum ValueName {
    /// A D-H deviation of joint row `row` (as the name numbers it).
    Dh {
        /// The field.
        field: DhField,
        /// The number in the name.
        row: usize,
    },
    /// A deviation of a URDF placement element (a joint, a tip, a frame, an anchor).
    Element {
        /// The element's name.
        element: String,
        /// The field.
        field: ElementField,
    },
    /// A gravity compliance about a joint's axis, shared by the joints named
    /// (`compliance.a+b`).
    Compliance {
        /// The joints.
        joints: Vec<String>,
    },
    /// A transversal compliance of a revolute joint: isotropic (`transversal.{joint}`) or
    /// about one axis of its link frame (`.u`, `.v`).
    Transversal {
        /// The joint.
        joint: String,
        /// `None`, `Some('u')` or `Some('v')`.
        axis: Option<char>,
    },
    /// A joint harmonic `harmonic.{joint}.sin{h}` / `.cos{h}`, rad.
    Harmonic {
        /// The joint.
        joint: String,
        /// Order h ≥ 1.
        order: u32,
        /// Sine (true) or cosine term.
        sine: bool,
    },
    /// A haptic device's joint compliance under the handle's weight
    /// (`joint_compliance.j{k}`), rad/(N·m).
    HandleCompliance {
        /// Joint number k (1-based).
        joint: usize,
    },
    /// A capstan parameter (`capstan{j}.{field}`).
    Capstan {
        /// Joint number (1-based).
        joint: usize,
        /// The field.
        field: CapstanField,
    },
    /// A Chebyshev coefficient of a joint's polynomial drive (`joint{j}.cheb{k}`), rad.
    Chebyshev {
        /// Joint number (1-based).
        joint: usize,
        /// Coefficient index.
        index: usize,
    },
}

const GRAMMAR: &str = "expected a D-H deviation (da3, dalpha3, dd3, dtheta3, dbeta3), an element \
                       deviation (<element>.x, .y, .z, .rx, .ry, .rz, .offset), \
                       compliance.<joint>, transversal.<joint>[.u|.v], \
                       harmonic.<joint>.sin<h>|cos<h>, joint_compliance.j<k>, \
                       capstan<j>.<c|re|r_o|beta_o|r_i|beta_i> or joint<j>.cheb<k>";

fn number(s: &str) -> Option<usize> {
    (!s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
        .then(|| s.parse().ok())
        .flatten()
}

impl ValueName {
    /// Parses a recorded value's name.
    ///
    /// # Errors
    /// A name that is none of the forms, with the forms expected.
    pub fn parse(name: &str) -> Result<ValueName, String> {
        let unknown = || Err(format!("unknown value name; {GRAMMAR}"));
        if let Some(rest) = name.strip_prefix("compliance.") {
            let joints: Vec<String> = rest.split('+').map(str::to_owned).collect();
            if joints.iter().any(String::is_empty) {
                return unknown();
            }
            return Ok(ValueName::Compliance { joints });
        }
        if let Some(rest) = name.strip_prefix("transversal.") {
            let (joint, axis) = match rest.rsplit_once('.') {
                Some((j, "u")) => (j, Some('u')),
                Some((j, "v")) => (j, Some('v')),
                _ => (rest, None),
            };
            if joint.is_empty() {
                return unknown();
            }
            return Ok(ValueName::Transversal {
                joint: joint.to_owned(),
                axis,
            });
        }
        if let Some(rest) = name.strip_prefix("harmonic.") {
            let Some((joint, term)) = rest.rsplit_once('.') else {
                return unknown();
            };
            let (sine, order) = if let Some(h) = term.strip_prefix("sin") {
                (true, h)
            } else if let Some(h) = term.strip_prefix("cos") {
                (false, h)
            } else {
                return unknown();
            };
            return match number(order).and_then(|h| u32::try_from(h).ok()) {
                Some(order) if order >= 1 && !joint.is_empty() => Ok(ValueName::Harmonic {
                    joint: joint.to_owned(),
                    order,
                    sine,
                }),
                _ => unknown(),
            };
        }
        if let Some(k) = name.strip_prefix("joint_compliance.j") {
            return match number(k) {
                Some(joint) if joint >= 1 => Ok(ValueName::HandleCompliance { joint }),
                _ => unknown(),
            };
        }
        if let Some((element, field)) = name.split_once('.') {
            if let Some(j) = element.strip_prefix("capstan").and_then(number) {
                return match CapstanField::parse(field) {
                    Some(field) if j >= 1 => Ok(ValueName::Capstan { joint: j, field }),
                    _ => Err(format!(
                        "unknown capstan parameter {field:?}: expected c, re, r_o, beta_o, r_i \
                         or beta_i"
                    )),
                };
            }
            if let Some(j) = element.strip_prefix("joint").and_then(number)
                && let Some(k) = field.strip_prefix("cheb")
            {
                return match number(k) {
                    Some(index) if j >= 1 => Ok(ValueName::Chebyshev { joint: j, index }),
                    _ => unknown(),
                };
            }
        }
        if let Some((element, field)) = name.rsplit_once('.') {
            let Some(field) = ElementField::parse(field) else {
                return unknown();
            };
            if element.is_empty() {
                return unknown();
            }
            return Ok(ValueName::Element {
                element: element.to_owned(),
                field,
            });
        }
        for (prefix, field) in DhField::PREFIXES {
            if let Some(row) = name.strip_prefix(prefix).and_then(number) {
                return Ok(ValueName::Dh { field, row });
            }
        }
        unknown()
    }

    /// Whether the value is a compliance (axial or transversal, of a robot or a handle).
    pub fn is_compliance(&self) -> bool {
        matches!(
            self,
            ValueName::Compliance { .. }
                | ValueName::Transversal { .. }
                | ValueName::HandleCompliance { .. }
        )
    }

    /// `None` if `unit` is one the value may be in ([`Self::units`] under `torque`), else the
    /// units expected, as a message gives them: `"m"`, or `"rad/(N·m)" or "rad/m"`.
    pub fn unexpected_unit(&self, unit: &str, torque: Option<TorqueSource>) -> Option<String> {
        let allowed = self.units(torque);
        if allowed.is_empty() || allowed.contains(&unit) {
            return None;
        }
        let expected: Vec<String> = allowed.iter().map(|u| format!("{u:?}")).collect();
        Some(expected.join(" or "))
    }

    /// The units the value may be in, given the record's torque source (`None`: none
    /// recorded, an earlier hapcal's record, whose compliances may be in either unit).
    pub fn units(&self, torque: Option<TorqueSource>) -> &'static [&'static str] {
        match self {
            ValueName::Dh { field, .. } => match field {
                DhField::A | DhField::D => &["m"],
                _ => &["rad"],
            },
            ValueName::Element { field, .. } => match field {
                ElementField::X | ElementField::Y | ElementField::Z => &["m"],
                ElementField::Rx | ElementField::Ry | ElementField::Rz => &["rad"],
                // A prismatic joint's offset is a length.
                ElementField::Offset => &["rad", "m"],
            },
            ValueName::Compliance { .. } | ValueName::Transversal { .. } => match torque {
                Some(TorqueSource::LumpedUnitWeights) => &["rad/m"],
                Some(_) => &["rad/(N·m)"],
                None => &["rad/(N·m)", "rad/m"],
            },
            ValueName::HandleCompliance { .. } => &["rad/(N·m)"],
            ValueName::Harmonic { .. } | ValueName::Chebyshev { .. } => &["rad"],
            ValueName::Capstan { field, .. } => match field.unit() {
                "rad" => &["rad"],
                "m" => &["m"],
                _ => &["1"],
            },
        }
    }
}

/// The name as records, reports and layouts write it: the inverse of [`ValueName::parse`]
/// (`dtheta3`, `joint_a2.rx`, `compliance.a+b`, `transversal.j.u`, `harmonic.j.sin2`,
/// `joint_compliance.j3`, `capstan2.beta_o`, `joint4.cheb10`).
impl std::fmt::Display for ValueName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ValueName::Dh { field, row } => write!(f, "{}{row}", field.prefix()),
            ValueName::Element { element, field } => write!(f, "{element}.{}", field.suffix()),
            ValueName::Compliance { joints } => write!(f, "compliance.{}", joints.join("+")),
            ValueName::Transversal { joint, axis } => match axis {
                Some(axis) => write!(f, "transversal.{joint}.{axis}"),
                None => write!(f, "transversal.{joint}"),
            },
            ValueName::Harmonic { joint, order, sine } => {
                let term = if *sine { "sin" } else { "cos" };
                write!(f, "harmonic.{joint}.{term}{order}")
            }
            ValueName::HandleCompliance { joint } => write!(f, "joint_compliance.j{joint}"),
            ValueName::Capstan { joint, field } => write!(f, "capstan{joint}.{}", field.name()),
            ValueName::Chebyshev { joint, index } => write!(f, "joint{joint}.cheb{index}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_written_form_parses_to_its_kind() {
        let cases = [
            ("dalpha3", "Dh"),
            ("da0", "Dh"),
            ("dtheta7", "Dh"),
            ("joint_a2.rx", "Element"),
            ("ball_joint.offset", "Element"),
            ("compliance.joint_a2", "Compliance"),
            ("compliance.a+b", "Compliance"),
            ("transversal.left_1", "Transversal"),
            ("transversal.left_1.u", "Transversal"),
            ("harmonic.joint_a3.cos2", "Harmonic"),
            ("joint_compliance.j3", "HandleCompliance"),
            ("capstan2.beta_o", "Capstan"),
            ("joint4.cheb10", "Chebyshev"),
        ];
        for (name, kind) in cases {
            let parsed = ValueName::parse(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(
                format!("{parsed:?}").starts_with(kind),
                "{name}: {parsed:?}"
            );
        }
        let h = ValueName::parse("harmonic.j.sin2").expect("parses");
        assert_eq!(
            h,
            ValueName::Harmonic {
                joint: "j".into(),
                order: 2,
                sine: true
            }
        );
    }

    #[test]
    fn every_name_is_written_as_it_parses() {
        for name in [
            "dalpha3",
            "da0",
            "dd12",
            "dtheta7",
            "dbeta2",
            "joint_a2.rx",
            "l_1.x",
            "torso.2.rz",
            "ball_joint.offset",
            "compliance.joint_a2",
            "compliance.a+b+c",
            "transversal.left_1",
            "transversal.left_1.u",
            "transversal.left_1.v",
            "harmonic.joint_a3.cos2",
            "harmonic.j.sin11",
            "joint_compliance.j3",
            "capstan2.c",
            "capstan2.re",
            "capstan2.r_o",
            "capstan2.beta_o",
            "capstan2.r_i",
            "capstan2.beta_i",
            "joint4.cheb10",
        ] {
            let parsed = ValueName::parse(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(parsed.to_string(), name);
            assert_eq!(ValueName::parse(&parsed.to_string()), Ok(parsed));
        }
    }

    #[test]
    fn unknown_names_are_refused_with_the_forms_expected() {
        for name in [
            "dgamma3",
            "capstan2.ratio",
            "harmonic.j.tan1",
            "harmonic.j.sin0",
            "joint_compliance.jx",
            "compliance.",
            "compliance.a+",
            "nothing",
            "joint_a2.w",
        ] {
            let err = ValueName::parse(name).expect_err(name);
            assert!(err.contains("expected"), "{name}: {err}");
        }
    }

    #[test]
    fn a_compliance_unit_follows_the_torque_source() {
        let c = ValueName::parse("compliance.j").expect("parses");
        assert_eq!(c.units(Some(TorqueSource::LumpedUnitWeights)), ["rad/m"]);
        assert_eq!(c.units(Some(TorqueSource::PublishedMasses)), ["rad/(N·m)"]);
        assert_eq!(c.units(None).len(), 2);
    }
}
