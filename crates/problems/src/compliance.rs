//! Joint compliance under gravity: a lumped, linear-in-parameters model.

use hapcal_kinematics::{Chain, Factor, Motion, Vector3};

/// Joint deflection proportional to a lumped gravity torque (non-geometric calibration,
/// Judd & Knasinski 1990, "A technique to calibrate industrial robots with experimental
/// verification"; Zhou, Na & Kang 2014 for the linear compliance model).
///
/// Masses are not known from a bare URDF, so the gravity torque about joint j is *lumped*: a unit
/// weight (1 m·(unit force)) at the origin of every downstream joint and at the end point,
///
/// `τ̂_j(q) = w_j · Σ_{i>j} (o_i − o_j) × ĝ`   (m; w_j joint j's world axis, ĝ the unit gravity),
///
/// evaluated on the nominal chain at the measured angles. The true joint angle is
/// `q_j + k_j·τ̂_j(q)`, and `k_j` (rad per m of lumped lever arm) is identified; its physical
/// meaning is compliance × weight, absorbed into one number per joint. A joint whose axis is
/// parallel to gravity has `τ̂ ≡ 0`, and identification prunes its `k` as a zero column.
#[derive(Clone, Debug, PartialEq)]
pub struct GravityCompliance {
    /// Unit vector of gravity in the chain's base frame (default `−z`).
    pub gravity_dir: Vector3<f64>,
}

impl Default for GravityCompliance {
    /// Gravity along −z of the base frame: a robot mounted upright (ROS REP 103 convention).
    fn default() -> Self {
        Self {
            gravity_dir: -Vector3::z(),
        }
    }
}

impl GravityCompliance {
    /// Lumped gravity torques `τ̂` (length `n_joints`, m) at angles `q` (rad) on the nominal chain.
    ///
    /// # Panics
    /// If `q.len() != chain.n_joints()`.
    #[track_caller]
    pub fn lumped_torques(&self, chain: &Chain, q: &[f64]) -> Vec<f64> {
        let x0 = vec![0.0; chain.n_params()];
        let poses = chain.frame_poses(&x0, q);
        let n = chain.n_joints();
        let mut origin = vec![Vector3::zeros(); n];
        let mut axis = vec![Vector3::zeros(); n];
        for (factor, pose) in chain.factors().iter().zip(&poses) {
            if let Factor::Screw {
                motion: Motion::Rotation,
                axis: a,
                joint: Some(j),
                ..
            } = factor
            {
                origin[*j] = pose.translation.vector;
                axis[*j] = pose.rotation * a.into_inner();
            }
        }
        let tip = chain.end_point(&x0, q).coords;
        let g = self.gravity_dir;
        (0..n)
            .map(|j| {
                let lever: Vector3<f64> = origin[j + 1..]
                    .iter()
                    .chain(std::iter::once(&tip))
                    .map(|o| (o - origin[j]).cross(&g))
                    .sum();
                axis[j].dot(&lever)
            })
            .collect()
    }
}
