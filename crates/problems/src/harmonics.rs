//! Joint-angle harmonic errors: encoder eccentricity and transmission ripple, linear in parameters.

use hapcal_contract::ValueName;

/// Harmonic angle errors of the joints (encoder eccentricity, once- and twice-per-revolution
/// transmission error).
///
/// An encoder disc mounted off the joint's axis of rotation reads
/// `q = θ + e·sin(θ + φ)` (Δθ periodic in θ with period 2π); a second harmonic comes from an
/// elliptical disc or a harmonic drive's flexspline (Tuttle & Seering 1996, "A nonlinear model
/// of a harmonic drive gear transmission", IEEE T-RA 12(3); Heidenhain, "Angle encoders",
/// 2017, §"Eccentricity"). For each joint `j` in [`Self::joints`] and order `h` in
/// [`Self::orders`] the true angle is
///
/// `θ_j = q_j + a_{jh}·sin(h·q_j) + b_{jh}·cos(h·q_j)`   (rad; `q_j` the reading, rad)
///
/// with `a_{jh}`, `b_{jh}` (rad) identified. The basis is evaluated at the readings, so the
/// problem stays linear in these parameters. A constant offset would duplicate the joint's
/// zero (a kinematic parameter), so none is added.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JointHarmonics {
    /// Joints with harmonic terms (0-based, chain order, increasing).
    pub joints: Vec<usize>,
    /// Harmonic orders `h ≥ 1` (e.g. `[1]` or `[1, 2]`).
    pub orders: Vec<u32>,
}

impl JointHarmonics {
    /// First-order (once per revolution) terms on every joint of an `n_joints` chain.
    pub fn first_order(n_joints: usize) -> Self {
        Self {
            joints: (0..n_joints).collect(),
            orders: vec![1],
        }
    }

    /// Number of parameters: 2 per (joint, order) pair.
    pub fn n_params(&self) -> usize {
        2 * self.joints.len() * self.orders.len()
    }

    /// The parameters in layout order: (joint, order, `true` for the sine term), sine before
    /// cosine, orders inside joints.
    pub fn terms(&self) -> Vec<(usize, u32, bool)> {
        self.joints
            .iter()
            .flat_map(|&j| {
                self.orders
                    .iter()
                    .flat_map(move |&h| [(j, h, true), (j, h, false)])
            })
            .collect()
    }

    /// Stable parameter names in layout order: `harmonic.<joint>.sin<h>` / `.cos<h>`.
    pub fn names(&self, joint_names: &[String]) -> Vec<String> {
        self.terms()
            .into_iter()
            .map(|(j, h, sin)| {
                let joint = joint_names.get(j).map_or("?", |s| s.as_str()).to_owned();
                ValueName::Harmonic {
                    joint,
                    order: h,
                    sine: sin,
                }
                .to_string()
            })
            .collect()
    }

    /// Basis values (length [`Self::n_params`], dimensionless) at readings `q` (rad): `sin(h·q_j)`
    /// or `cos(h·q_j)` per parameter.
    ///
    /// # Panics
    /// If a joint of [`Self::joints`] is not an index of `q`.
    #[track_caller]
    pub fn basis(&self, q: &[f64]) -> Vec<f64> {
        self.terms()
            .into_iter()
            .map(|(j, h, sin)| {
                let a = f64::from(h) * q[j];
                if sin { a.sin() } else { a.cos() }
            })
            .collect()
    }

    /// Angle corrections (length `q.len()`, rad) for coefficients `coef` (layout order, rad).
    ///
    /// # Panics
    /// If `coef.len() != self.n_params()` or a joint is not an index of `q`.
    #[track_caller]
    pub fn corrections(&self, q: &[f64], coef: &[f64]) -> Vec<f64> {
        assert_eq!(coef.len(), self.n_params(), "harmonic coefficient count");
        let mut out = vec![0.0; q.len()];
        for ((j, _, _), (b, c)) in self.terms().into_iter().zip(self.basis(q).iter().zip(coef)) {
            out[j] += b * c;
        }
        out
    }
}
