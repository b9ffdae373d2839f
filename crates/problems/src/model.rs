//! A calibrated model: the chain with identified deviations and compliance.

use crate::{GravityCompliance, JointHarmonics, TransversalTerm};
use hapcal_kinematics::{Chain, Isometry3, Point3};

/// A chain plus identified parameter deviations, ready to predict end points.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibratedModel {
    /// The nominal chain (the first tip's).
    pub chain: Chain,
    /// The chain of every tip of a tree ([`crate::CalibrationProblem::on_tree`]); empty for
    /// one chain.
    pub tips: Vec<Chain>,
    /// The tips whose base frame gravity is expressed in, for the compliance loads (the robot
    /// without an instrument frame, every branch of its tree); empty: `[chain]`.
    pub torque_tips: Vec<Chain>,
    /// Kinematic deviations (length `chain.n_params()`, m or rad; zeros = nominal).
    pub x_kin: Vec<f64>,
    /// Compliance model and its `k_j` (length `n_joints`, rad/m), if modelled.
    pub compliance: Option<(GravityCompliance, Vec<f64>)>,
    /// Joint harmonic model and its coefficients (length [`JointHarmonics::n_params`], rad),
    /// if modelled.
    pub harmonics: Option<(JointHarmonics, Vec<f64>)>,
    /// Transversal compliance of each joint that has it, with its identified value (loads
    /// from [`Self::compliance`]'s model); empty without.
    pub transversal: Vec<TransversalTerm>,
    /// Whether the gravity loads are those of the deflected robot, the torque equilibrium
    /// `θ = q + k∘τ(θ)` solved by fixed-point iteration ([`Self::load_angles`]), rather than
    /// those of the undeflected robot at the readings.
    pub equilibrium: bool,
}

/// Most fixed-point iterations of the torque equilibrium ([`CalibratedModel::load_angles`]);
/// each multiplies the error by about `k·∂τ/∂q` (10⁻³ for a stiff arm, 10⁻² for an elastic
/// one), so a handful reach 10⁻¹² rad.
pub const EQUILIBRIUM_ITERATIONS: usize = 20;

impl CalibratedModel {
    /// The nominal model of `chain` (no deviation, no compliance).
    pub fn nominal(chain: Chain) -> Self {
        let x_kin = vec![0.0; chain.n_params()];
        Self {
            chain,
            tips: Vec::new(),
            torque_tips: Vec::new(),
            x_kin,
            compliance: None,
            harmonics: None,
            transversal: Vec::new(),
            equilibrium: false,
        }
    }

    /// Joint angles the chain actually takes for readings `q` (rad): `q + k∘τ̂(θ)` plus the
    /// harmonic corrections ([`JointHarmonics::corrections`]), `θ` where the loads are
    /// evaluated ([`Self::load_angles`]).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn effective_angles(&self, q: &[f64]) -> Vec<f64> {
        self.effective(q).1
    }

    fn torque_tips(&self) -> &[Chain] {
        if self.torque_tips.is_empty() {
            std::slice::from_ref(&self.chain)
        } else {
            &self.torque_tips
        }
    }

    /// Where the gravity loads are evaluated for readings `q` (rad, m for a prismatic joint):
    /// `q` itself, or with [`Self::equilibrium`] the fixed point of `θ = q + k∘τ(θ)`, iterated
    /// from `q` until no joint moves by more than 10⁻¹² rad or [`EQUILIBRIUM_ITERATIONS`];
    /// with the iterations taken (0 without equilibrium or compliance).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn load_angles(&self, q: &[f64]) -> (Vec<f64>, usize) {
        let Some((model, k)) = self.compliance.as_ref().filter(|_| self.equilibrium) else {
            return (q.to_vec(), 0);
        };
        let mut theta = q.to_vec();
        for iteration in 1..=EQUILIBRIUM_ITERATIONS {
            let loads = model.joint_loads(self.torque_tips(), &theta);
            let mut change: f64 = 0.0;
            for ((t, q), (k, l)) in theta.iter_mut().zip(q).zip(k.iter().zip(&loads)) {
                let next = q + k * l.torque;
                change = change.max((next - *t).abs());
                *t = next;
            }
            if change <= 1e-12 {
                return (theta, iteration);
            }
        }
        (theta, EQUILIBRIUM_ITERATIONS)
    }

    /// The kinematic deviations (with the transversal tilts) and the joint angles (with the
    /// axial deflection and the harmonics) for readings `q`, from one evaluation of the
    /// gravity loads.
    fn effective(&self, q: &[f64]) -> (std::borrow::Cow<'_, [f64]>, Vec<f64>) {
        let Some((model, k)) = &self.compliance else {
            let mut angles = q.to_vec();
            self.add_harmonics(q, &mut angles);
            return (std::borrow::Cow::Borrowed(&self.x_kin), angles);
        };
        let (at, _) = self.load_angles(q);
        self.deflect(q, k, &model.joint_loads(self.torque_tips(), &at))
    }

    /// The deviations and joint angles for readings `q` under the gravity `loads`, with the
    /// axial compliances `k`.
    fn deflect(
        &self,
        q: &[f64],
        k: &[f64],
        loads: &[crate::JointLoad],
    ) -> (std::borrow::Cow<'_, [f64]>, Vec<f64>) {
        let mut angles: Vec<f64> = (q.iter().zip(k).zip(loads))
            .map(|((q, k), l)| q + k * l.torque)
            .collect();
        self.add_harmonics(q, &mut angles);
        if self.transversal.is_empty() {
            return (std::borrow::Cow::Borrowed(&self.x_kin), angles);
        }
        let mut x = self.x_kin.clone();
        for t in &self.transversal {
            let v = t.tilt(&loads[t.joint]);
            for (&i, v) in t.rotation_params.iter().zip(v.iter()) {
                x[i] += t.compliance * v;
            }
        }
        (std::borrow::Cow::Owned(x), angles)
    }

    fn add_harmonics(&self, q: &[f64], angles: &mut [f64]) {
        if let Some((h, coef)) = &self.harmonics {
            for (o, c) in angles.iter_mut().zip(h.corrections(q, coef)) {
                *o += c;
            }
        }
    }

    /// Kinematic deviations for readings `q`: [`Self::x_kin`] with the transversal tilts
    /// added to their joints' rotation deviations ([`TransversalTerm`]).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn effective_deviations(&self, q: &[f64]) -> std::borrow::Cow<'_, [f64]> {
        self.effective(q).0
    }

    /// How far one more fixed-point step of the torque equilibrium would move the tips, m:
    /// the model deflects the joints under the gravity loads at [`Self::load_angles`] (the
    /// undeflected robot `q` without [`Self::equilibrium`]), `q + k∘τ(θ)`; the loads of that
    /// deflected robot give the next iterate of `θ = q + k∘τ(θ)`. The largest tip displacement between the two (every tip,
    /// axial and transversal compliance), 0 without compliance. Small against the noise, the
    /// equilibrium needs no iteration.
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn equilibrium_step_m(&self, q: &[f64]) -> f64 {
        let Some((model, k)) = &self.compliance else {
            return 0.0;
        };
        let (at, _) = self.load_angles(q);
        let first = model.joint_loads(self.torque_tips(), &at);
        let deflected: Vec<f64> = (q.iter().zip(k).zip(&first))
            .map(|((q, k), l)| q + k * l.torque)
            .collect();
        let second = model.joint_loads(self.torque_tips(), &deflected);
        let (x1, q1) = self.deflect(q, k, &first);
        let (x2, q2) = self.deflect(q, k, &second);
        let tips: Vec<&Chain> = if self.tips.is_empty() {
            vec![&self.chain]
        } else {
            self.tips.iter().collect()
        };
        (tips.iter())
            .map(|c| (c.end_point(&x1, &q1) - c.end_point(&x2, &q2)).norm())
            .fold(0.0, f64::max)
    }

    /// End point (m, base frame) for joint readings `q` (rad).
    ///
    /// # Panics
    /// If `q.len()` differs from the chain's joint count.
    #[track_caller]
    pub fn end_point(&self, q: &[f64]) -> Point3<f64> {
        let (x, angles) = self.effective(q);
        self.chain.end_point(&x, &angles)
    }

    /// Poses of the frames of `tips` (as [`Self::end_pose_of`]) for one reading `q`, with one
    /// evaluation of the gravity loads for them all.
    ///
    /// # Panics
    /// If a tip is not a tip of the model or `q.len()` differs from the joint count.
    #[track_caller]
    pub fn end_poses_of(&self, tips: &[usize], q: &[f64]) -> Vec<Isometry3<f64>> {
        let (x, angles) = self.effective(q);
        (tips.iter())
            .map(|&tip| {
                let chain = if self.tips.is_empty() && tip == 0 {
                    &self.chain
                } else {
                    &self.tips[tip]
                };
                chain.end_pose(&x, &angles)
            })
            .collect()
    }

    /// Pose of tip `tip`'s frame (m; in the instrument frame for a tree with frames) for
    /// joint readings `q` (rad or m); tip 0 is [`Self::chain`].
    ///
    /// # Panics
    /// If `tip` is not a tip of the model or `q.len()` differs from the joint count.
    #[track_caller]
    pub fn end_pose_of(&self, tip: usize, q: &[f64]) -> Isometry3<f64> {
        let chain = if self.tips.is_empty() && tip == 0 {
            &self.chain
        } else {
            &self.tips[tip]
        };
        let (x, angles) = self.effective(q);
        chain.end_pose(&x, &angles)
    }
}
