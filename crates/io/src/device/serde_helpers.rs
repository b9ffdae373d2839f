//! serde glue between the file's spelling and the domain types.

use std::fmt;

use hapcal_kinematics::DhConvention;
use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::JointRef;

pub(super) fn standard() -> DhConvention {
    DhConvention::Standard
}

/// `convention = "dh" | "mdh"`.
pub(super) mod convention {
    use super::*;

    pub(in crate::device) fn serialize<S: Serializer>(
        c: &DhConvention,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.serialize_str(name(*c))
    }

    pub(in crate::device) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<DhConvention, D::Error> {
        let text = String::deserialize(d)?;
        match text.as_str() {
            "dh" => Ok(DhConvention::Standard),
            "mdh" => Ok(DhConvention::Modified),
            other => Err(de::Error::custom(format!(
                "unknown convention {other:?}, expected \"dh\" (standard) or \"mdh\" (modified)"
            ))),
        }
    }

    pub(in crate::device) fn name(c: DhConvention) -> &'static str {
        match c {
            DhConvention::Standard => "dh",
            DhConvention::Modified => "mdh",
        }
    }
}

/// `[[placement]]` rows ↔ [`hapcal_kinematics::Placement`].
pub(super) mod placements {
    use hapcal_kinematics::Placement;

    use super::*;

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Row {
        name: String,
        xyz_m: [f64; 3],
        rpy_rad: [f64; 3],
        #[serde(default, skip_serializing_if = "Option::is_none")]
        axis: Option<[f64; 3]>,
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        prismatic: bool,
    }

    pub(in crate::device) fn serialize<S: Serializer>(
        placements: &[Placement],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(placements.iter().map(|p| Row {
            name: p.name.clone(),
            xyz_m: p.xyz_m,
            rpy_rad: p.rpy_rad,
            axis: p.axis,
            prismatic: p.prismatic,
        }))
    }

    pub(in crate::device) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Vec<Placement>, D::Error> {
        let rows = Vec::<Row>::deserialize(d)?;
        Ok(rows
            .into_iter()
            .map(|r| Placement {
                name: r.name,
                xyz_m: r.xyz_m,
                rpy_rad: r.rpy_rad,
                axis: r.axis,
                prismatic: r.prismatic,
            })
            .collect())
    }
}

impl Serialize for JointRef {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            JointRef::Joint(j) => s.serialize_u64(*j as u64),
            JointRef::Fixed => s.serialize_str("fixed"),
        }
    }
}

impl<'de> Deserialize<'de> for JointRef {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct JointVisitor;
        impl Visitor<'_> for JointVisitor {
            type Value = JointRef;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a joint number 1, 2, … or \"fixed\"")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<JointRef, E> {
                match usize::try_from(v) {
                    Ok(j) if j >= 1 => Ok(JointRef::Joint(j)),
                    _ => Err(E::custom(format!(
                        "joint number {v} is invalid, expected 1, 2, … or \"fixed\""
                    ))),
                }
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<JointRef, E> {
                match usize::try_from(v) {
                    Ok(j) if j >= 1 => Ok(JointRef::Joint(j)),
                    _ => Err(E::custom(format!(
                        "joint number {v} is invalid, expected 1, 2, … or \"fixed\""
                    ))),
                }
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<JointRef, E> {
                if v == "fixed" {
                    Ok(JointRef::Fixed)
                } else {
                    Err(E::custom(format!(
                        "joint {v:?} is invalid, expected a joint number 1, 2, … or \"fixed\""
                    )))
                }
            }
        }
        d.deserialize_any(JointVisitor)
    }
}
