//! A D-H robot's table of rows and the joint origins it places: what the runtime keeps of a
//! device file's `[[dh]]` rows to move them by a record's D-H deviations.

use hapcal_contract::{Calibration, DhField, ValueName};

use crate::model::dh_split;
use crate::{DhConvention, DhRow, Pose};

/// A D-H robot's table: the convention and the `[[dh]]` rows at the nominal geometry (the
/// record's D-H deviations removed), in file order.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct DhTable {
    /// The rows' convention.
    pub(crate) convention: DhConvention,
    /// The rows at the nominal geometry, in file order.
    pub(crate) nominal: Vec<DhRow>,
}

/// One D-H row split at its joint's motion `Rz(q)` ([`dh_split`], with the standard
/// library's sines and cosines): the factors before it and after it. Standard:
/// `Rz(θ) | Rz(q) | Tz(d)·Tx(a)·Rx(α)·Ry(β)`; modified:
/// `Rx(α)·Ry(β)·Tx(a)·Rz(θ) | Rz(q) | Tz(d)`.
fn dh_parts(convention: DhConvention, row: &DhRow) -> (Pose, Pose) {
    let (pre, post) = dh_split(convention, row, f64::sin_cos);
    let (s, c) = row.theta_rad.sin_cos();
    match convention {
        DhConvention::Standard => (Pose::rot_z(s, c), post),
        DhConvention::Modified => (pre.compose(&Pose::rot_z(s, c)), post),
    }
}

/// The joint origins of the chain `rows` (each joint's frame at zero motion in the frame of
/// the joint before it after that joint's motion, the first in the base frame: the frame
/// just after the joint's `Rz(θ + q)`, where the calibration library places a joint) and the
/// tip's offset in the last joint's frame (the rest of the chain, fixed rows included).
pub(crate) fn dh_frames(convention: DhConvention, rows: &[DhRow]) -> (Vec<Pose>, Pose) {
    let mut origins = Vec::new();
    let mut pending = Pose::IDENTITY;
    for row in rows {
        let (before, after) = dh_parts(convention, row);
        if row.joint {
            origins.push(pending.compose(&before));
            pending = after;
        } else {
            pending = pending.compose(&before).compose(&after);
        }
    }
    (origins, pending)
}

/// Adds `sign ×` the D-H deviation `field` (m or rad) to `row`; a `β` deviation on a row
/// without β gives it one (as the device file's writer does).
pub(crate) fn add_dh(row: &mut DhRow, field: DhField, value: f64) {
    match field {
        DhField::A => row.a_m += value,
        DhField::Alpha => row.alpha_rad += value,
        DhField::D => row.d_m += value,
        DhField::Theta => row.theta_rad += value,
        DhField::Beta => row.beta_rad = Some(row.beta_rad.unwrap_or(0.0) + value),
    }
}

impl DhTable {
    /// The rows with the D-H deviations of `record` added (those of rows it names).
    pub(crate) fn calibrated_rows(&self, record: Option<&Calibration>) -> Vec<DhRow> {
        let mut rows = self.nominal.clone();
        for v in record.iter().flat_map(|r| &r.values) {
            if let Ok(ValueName::Dh { field, row }) = ValueName::parse(&v.name)
                && let Some(r) = rows.get_mut(row)
            {
                add_dh(r, field, v.value);
            }
        }
        rows
    }
}
