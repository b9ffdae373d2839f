//! serde glue between the domain types and the file's spelling, for writing a [`Device`]
//! with serde (the file is read by `hapcal_contract::device::DeviceFile`).
//!
//! [`Device`]: super::Device

use hapcal_contract::device::{Convention, PlacementEntry};
use hapcal_kinematics::{DhConvention, Placement};
use serde::Serializer;

/// The convention's name in the file: `dh` or `mdh`.
pub(super) fn convention_name(c: DhConvention) -> &'static str {
    match c {
        DhConvention::Standard => Convention::Standard.name(),
        DhConvention::Modified => Convention::Modified.name(),
    }
}

/// `convention = "dh" | "mdh"`.
pub(super) fn serialize_convention<S: Serializer>(
    c: &DhConvention,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_str(convention_name(*c))
}

/// [`Placement`]s as `[[placement]]` rows.
pub(super) fn serialize_placements<S: Serializer>(
    placements: &[Placement],
    s: S,
) -> Result<S::Ok, S::Error> {
    s.collect_seq(placements.iter().map(|p| PlacementEntry {
        name: p.name.clone(),
        xyz_m: p.xyz_m,
        rpy_rad: p.rpy_rad,
        axis: p.axis,
        prismatic: p.prismatic,
    }))
}
