//! Denavit–Hartenberg tables (standard, modified, with Hayati's beta).

use hapcal_contract::{DhField, ValueName};
use nalgebra::{Unit, Vector3};

use crate::{Chain, Error, Factor, Motion, ParamInfo, ParamUnit};

/// Which Denavit–Hartenberg convention a [`DhRow`] follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DhConvention {
    /// Standard (distal) D-H, Denavit & Hartenberg 1955, paper eq. 3:
    /// `A_i = Rz(theta_i + q) · Tz(d_i) · Tx(a_i) · Rx(alpha_i) [· Ry(beta_i)]`.
    Standard,
    /// Modified (proximal) D-H, Craig 1989, *Introduction to Robotics*, §3.4:
    /// `A_i = Rx(alpha_i) [· Ry(beta_i)] · Tx(a_i) · Rz(theta_i + q) · Tz(d_i)`.
    Modified,
}

/// One row of a D-H table: the transform from frame `i − 1` to frame `i`.
///
/// Nominal values; the chain adds deviations `da{i}`, `dalpha{i}`, `dd{i}`, `dtheta{i}`
/// (and `dbeta{i}` when `beta_rad` is `Some`) from `x`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DhRow {
    /// Standard or modified convention.
    pub convention: DhConvention,
    /// Link length `a` along x, m.
    pub a_m: f64,
    /// Link twist `alpha` about x, rad.
    pub alpha_rad: f64,
    /// Link offset `d` along z, m.
    pub d_m: f64,
    /// Joint angle offset `theta` about z, rad (the joint angle `q` is added to it).
    pub theta_rad: f64,
    /// Hayati 1983 `beta` about y, rad, for near-parallel consecutive axes; `None` = no
    /// beta factor and no `dbeta` parameter.
    pub beta_rad: Option<f64>,
    /// Index into `q` of the row's revolute joint; `None` = fixed row (e.g. rig → base).
    pub joint: Option<usize>,
}

impl DhRow {
    /// A standard-convention row with link length `a_m` (m), twist `alpha_rad` (rad) and
    /// offset `d_m` (m), no joint angle offset and no Hayati `beta`; `joint` as in
    /// [`DhRow::joint`].
    pub const fn standard(a_m: f64, alpha_rad: f64, d_m: f64, joint: Option<usize>) -> DhRow {
        DhRow {
            convention: DhConvention::Standard,
            a_m,
            alpha_rad,
            d_m,
            theta_rad: 0.0,
            beta_rad: None,
            joint,
        }
    }
}

fn screw(
    motion: Motion,
    axis: Unit<Vector3<f64>>,
    nominal: f64,
    param: usize,
    joint: Option<usize>,
) -> Factor {
    Factor::Screw {
        motion,
        axis,
        nominal,
        param: Some(param),
        joint,
    }
}

impl Chain {
    /// A chain from a D-H table, row 0 first (row 0 may be a fixed rig → base row).
    ///
    /// Row `i` becomes the factors of its convention (see [`DhConvention`]) and the
    /// parameters `da{i}`, `dalpha{i}`, `dd{i}`, `dtheta{i}` [, `dbeta{i}`], in that order,
    /// row by row: the paper's reference device (docs/design.md §2) has 8 rows, 32 parameters
    /// and 7 joints. Element `i` is `row{i}`; joint `j` is named `q{j+1}`. The tip is the
    /// origin of the last row's frame.
    ///
    /// # Errors
    ///
    /// [`Error::EmptyChain`] if `rows` is empty; [`Error::NotFinite`] for a NaN or
    /// infinite value; [`Error::JointIndices`] unless the rows' joints are exactly
    /// `0..n_joints`, each used once.
    pub fn from_dh(rows: &[DhRow]) -> Result<Chain, Error> {
        if rows.is_empty() {
            return Err(Error::EmptyChain);
        }
        for (i, row) in rows.iter().enumerate() {
            let fields = [
                ("a_m", row.a_m),
                ("alpha_rad", row.alpha_rad),
                ("d_m", row.d_m),
                ("theta_rad", row.theta_rad),
                ("beta_rad", row.beta_rad.unwrap_or(0.0)),
            ];
            if let Some((field, value)) = fields.into_iter().find(|(_, v)| !v.is_finite()) {
                return Err(Error::NotFinite {
                    element: format!("row{i}"),
                    field: field.to_owned(),
                    value,
                });
            }
        }
        let found: Vec<usize> = rows.iter().filter_map(|r| r.joint).collect();
        let mut sorted = found.clone();
        sorted.sort_unstable();
        if sorted.iter().enumerate().any(|(i, &j)| i != j) {
            return Err(Error::JointIndices { found });
        }

        let (x_axis, y_axis, z_axis) = (Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis());
        let (rot, trans) = (Motion::Rotation, Motion::Translation);
        let mut factors = Vec::with_capacity(5 * rows.len());
        let mut params = Vec::with_capacity(5 * rows.len());
        for (i, row) in rows.iter().enumerate() {
            let base = params.len();
            let mut param = |field: DhField, unit: ParamUnit| {
                params.push(ParamInfo {
                    name: ValueName::Dh { field, row: i }.to_string(),
                    unit,
                    element: i,
                });
            };
            param(DhField::A, ParamUnit::Meter);
            param(DhField::Alpha, ParamUnit::Radian);
            param(DhField::D, ParamUnit::Meter);
            param(DhField::Theta, ParamUnit::Radian);
            if row.beta_rad.is_some() {
                param(DhField::Beta, ParamUnit::Radian);
            }
            let (p_a, p_alpha, p_d, p_theta, p_beta) =
                (base, base + 1, base + 2, base + 3, base + 4);
            let beta = row.beta_rad.map(|b| screw(rot, y_axis, b, p_beta, None));
            let theta = screw(rot, z_axis, row.theta_rad, p_theta, row.joint);
            let d = screw(trans, z_axis, row.d_m, p_d, None);
            let a = screw(trans, x_axis, row.a_m, p_a, None);
            let alpha = screw(rot, x_axis, row.alpha_rad, p_alpha, None);
            match row.convention {
                DhConvention::Standard => {
                    factors.extend([theta, d, a, alpha]);
                    factors.extend(beta);
                }
                DhConvention::Modified => {
                    factors.push(alpha);
                    factors.extend(beta);
                    factors.extend([a, theta, d]);
                }
            }
        }
        let joint_names = (1..=found.len()).map(|j| format!("q{j}")).collect();
        let element_names = (0..rows.len()).map(|i| format!("row{i}")).collect();
        Chain::from_factors(factors, params, joint_names, element_names)
    }
}
