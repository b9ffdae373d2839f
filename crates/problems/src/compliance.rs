//! Joint compliance under gravity: a lumped, linear-in-parameters model.

use hapcal_kinematics::{Chain, Factor, Isometry3, Motion, Point3, UnitQuaternion, Vector3};

use crate::Error;

/// Gravity of the haptic device's handle model, m/s² (docs/design.md §2.5: the handle's
/// weight drives the `joint_compliance` effect of §6). The simulator's value since the first
/// reference-device studies, kept so that their logs and compliances (rad/(N·m) against this
/// torque) do not move; the link masses of robot arms use standard gravity, 9.80665 m/s²,
/// 0.03 % less.
pub const GRAVITY_M_S2: f64 = 9.81;

/// Gravity torques of a haptic device's handle about each joint, N·m (length `n_joints`):
/// `τ = J_vᵀ·F` with `F = −m·g·ẑ_0`, `ẑ_0` the axis of joint 1 (vertical, docs/design.md §2)
/// and `J_v` the linear part of the geometric Jacobian at deviations `x` (m, rad) and joint
/// angles `q` (rad) (Siciliano et al. 2009, §3.8.1); `mass_kg` the handle's point mass at the
/// end point (docs/design.md §2.5), `g` = [`GRAVITY_M_S2`].
///
/// Unlike [`GravityCompliance`] (link masses or lumped unit weights on the nominal chain, with
/// gravity along a fixed direction of the base frame and `g₀` = 9.80665 m/s²), this follows the
/// deviations: gravity is along the (deviated) axis of joint 1, the lever arms those of the
/// chain at `x`.
///
/// # Errors
/// [`Error::LengthMismatch`] for `x` not of `chain.n_params()` entries; [`Error::JointCount`]
/// for `q` not of `chain.n_joints()`.
pub fn handle_gravity_torques_nm(
    chain: &Chain,
    x: &[f64],
    q: &[f64],
    mass_kg: f64,
) -> Result<Vec<f64>, Error> {
    if x.len() != chain.n_params() {
        return Err(Error::LengthMismatch {
            name: "x",
            expected: chain.n_params(),
            found: x.len(),
        });
    }
    Error::check_joint_count(0, chain.n_joints(), q.len())?;
    let jac = chain.geometric_jacobian(x, q);
    let up: Vector3<f64> = if jac.ncols() > 0 {
        Vector3::new(jac[(3, 0)], jac[(4, 0)], jac[(5, 0)])
    } else {
        Vector3::z()
    };
    let force = -mass_kg * GRAVITY_M_S2 * up;
    Ok((0..jac.ncols())
        .map(|j| jac[(0, j)] * force[0] + jac[(1, j)] * force[1] + jac[(2, j)] * force[2])
        .collect())
}

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
///
/// With published link masses ([`GravityCompliance::masses`] not empty) the torque is the
/// physical one instead: `τ_j(q) = w_j · Σ_{i ≥ j} (c_i − o_j) × (m_i·g₀·ĝ)` (N·m), `c_i` the
/// centre of mass of link `i` (the child link of joint `i`), and `k_j` is in rad/(N·m).
#[derive(Clone, Debug, PartialEq)]
pub struct GravityCompliance {
    /// Unit vector of gravity in the chain's base frame (default `−z`).
    pub gravity_dir: Vector3<f64>,
    /// Point masses of the links; empty for the lumped unit weights.
    pub masses: Vec<LinkMass>,
    /// Compliance parameter of each joint (`groups[j]`, 0-based, dense, length `n_joints`);
    /// empty for one parameter per joint. Joints with the same actuator share one stiffness.
    pub groups: Vec<usize>,
}

/// A point mass rigidly attached to the child link of a joint.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkMass {
    /// Index of the joint whose child link carries the mass (0-based, chain order).
    pub joint: usize,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in that link's frame (the frame just after the joint's rotation), m.
    pub com_m: Vector3<f64>,
}

/// A link's mass (kg) and centre of mass (m, in its link frame).
type Inertial = (f64, [f64; 3]);

/// Standard gravity, m/s² (CGPM 1901).
const G0: f64 = 9.806_65;

/// Franka Emika Panda link masses (kg) and centres of mass (m, link frames `panda_link1..7`):
/// Gaz, Cognetti, Oliva, Robuffo Giordano & De Luca, "Dynamic identification of the Franka
/// Emika Panda robot with retrieval of feasible parameters using penalty-based optimization",
/// IEEE RA-L 4(4), 2019, as `franka_description` (frankaemika/franka_ros) ships them in its
/// `<inertial>` elements.
const PANDA_GAZ_2019: [Inertial; 7] = [
    (4.970_684, [3.875e-3, 2.081e-3, -4.762e-2]),
    (0.646_926, [-3.141e-3, -2.872e-2, 3.495e-3]),
    (3.228_604, [2.7518e-2, 3.9252e-2, -6.6502e-2]),
    (3.587_895, [-5.317e-2, 1.04419e-1, 2.7454e-2]),
    (1.225_946, [-1.1953e-2, 4.1065e-2, -3.8437e-2]),
    (1.666_555, [6.0149e-2, -1.4117e-2, -1.0517e-2]),
    (0.735_522, [1.0517e-2, -4.252e-3, 6.1597e-2]),
];

/// Franka Hand: 0.73 kg at (−0.01, 0, 0.03) m in `panda_hand` (`franka_description`,
/// hand.urdf inertial), expressed in `panda_link7`: the hand frame is 0.107 m along z and
/// rotated −π/4 about z.
const PANDA_HAND: Inertial = (
    0.73,
    [
        -0.01 * std::f64::consts::FRAC_1_SQRT_2,
        0.01 * std::f64::consts::FRAC_1_SQRT_2,
        0.137,
    ],
);

/// KUKA LBR iiwa 14 R820 link masses (kg) and centres of mass (m): Drake's `iiwa14` model
/// (RobotLocomotion/drake, `manipulation/models/iiwa_description`; the same values are in
/// MuJoCo Menagerie's `kuka_iiwa_14`), masses 5.76, 6.35, 3.5, 3.5, 3.5, 1.8, 1.2 kg. Drake's
/// link frames differ from the ROS-Industrial `joint_a1..a7` frames of MUKCa's URDF (all of
/// which are aligned with the base at zero angles): each centre of mass is re-expressed through
/// its world position at zero angles, relative to the joint origin at 0, 0.36, 0.36, 0.78, 0.78,
/// 1.18, 1.18 m (x offsets of ±0.44 mm as in the URDF). No tool mass is known; none is added.
const IIWA14_DRAKE: [Inertial; 7] = [
    (5.76, [0.0, -0.03, 0.2775]),
    (6.35, [0.000_136, 0.042, 0.059]),
    (3.5, [0.000_436, 0.03, 0.3345]),
    (3.5, [0.0, -0.034, 0.067]),
    (3.5, [-0.000_1, -0.021, 0.2605]),
    (1.8, [0.0, 0.000_4, 0.000_6]),
    (1.2, [0.0, 0.0, 0.101]),
];

impl Default for GravityCompliance {
    /// Gravity along −z of the base frame: a robot mounted upright (ROS REP 103 convention);
    /// lumped unit weights.
    fn default() -> Self {
        Self {
            gravity_dir: -Vector3::z(),
            masses: Vec::new(),
            groups: Vec::new(),
        }
    }
}

impl GravityCompliance {
    /// Published link masses for a chain whose joints are named like a known robot (gravity
    /// along −z): the Franka Emika Panda (`panda_joint1..7`: Gaz et al. 2019 plus the Franka
    /// Hand) and the KUKA LBR iiwa 14 (`joint_a1..a7`: Drake's model). `None` for any other.
    pub fn published(joint_names: &[String]) -> Option<Self> {
        let named = |f: &dyn Fn(usize) -> String| {
            joint_names.len() == 7 && joint_names.iter().enumerate().all(|(i, n)| *n == f(i + 1))
        };
        let (links, extra): (&[Inertial], Option<Inertial>) =
            if named(&|i| format!("panda_joint{i}")) {
                (&PANDA_GAZ_2019, Some(PANDA_HAND))
            } else if named(&|i| format!("joint_a{i}")) {
                (&IIWA14_DRAKE, None)
            } else {
                return None;
            };
        let masses = links
            .iter()
            .enumerate()
            .map(|(joint, (m, c))| (joint, m, c))
            .chain(extra.iter().map(|(m, c)| (6, m, c)))
            .map(|(joint, m, c)| LinkMass {
                joint,
                mass_kg: *m,
                com_m: Vector3::from(*c),
            })
            .collect();
        Some(Self {
            gravity_dir: -Vector3::z(),
            masses,
            groups: Vec::new(),
        })
    }

    /// Link masses from a robot description (a URDF's `<inertial>` tags), one compliance per
    /// joint, gravity along `gravity_dir` (normalised; `−z` if it has no length) in the
    /// chain's base frame. Torques in N·m, `k_j` in rad/(N·m).
    pub fn from_link_masses(masses: Vec<LinkMass>, gravity_dir: Vector3<f64>) -> Self {
        let norm = gravity_dir.norm();
        Self {
            gravity_dir: if norm > 0.0 && norm.is_finite() {
                gravity_dir / norm
            } else {
                -Vector3::z()
            },
            masses,
            groups: Vec::new(),
        }
    }

    /// [`Self::published`] with one compliance per actuator size instead of per joint (fewer
    /// parameters, the same torque shapes): the Panda's joints 1–4 and 5–7 (rated 87 and
    /// 12 N·m, Franka Emika datasheet), the iiwa 14's A1–A2, A3–A4, A5 and A6–A7 (rated 320,
    /// 176, 110 and 40 N·m, KUKA LBR iiwa specification). `None` for any other robot.
    pub fn published_by_actuator(joint_names: &[String]) -> Option<Self> {
        let mut model = Self::published(joint_names)?;
        model.groups = if joint_names[0].starts_with("panda") {
            vec![0, 0, 0, 0, 1, 1, 1]
        } else {
            vec![0, 0, 1, 1, 2, 3, 3]
        };
        Some(model)
    }

    /// Compliance parameter of joint `j`.
    pub fn group(&self, j: usize) -> usize {
        self.groups.get(j).copied().unwrap_or(j)
    }

    /// Number of compliance parameters for a chain of `n_joints` joints.
    pub fn n_params(&self, n_joints: usize) -> usize {
        if self.groups.is_empty() {
            n_joints
        } else {
            self.groups.iter().max().map_or(0, |g| g + 1)
        }
    }

    /// Gravity torques (length `n_joints`) at angles `q` (rad) on the nominal chain: lumped `τ̂`
    /// (m) without [`Self::masses`], physical `τ` (N·m) with them. The chain is one path of
    /// the robot; [`Self::joint_loads`] gives the torques of a tree.
    ///
    /// # Panics
    /// If `q.len() != chain.n_joints()`, or a [`LinkMass::joint`] is not a joint of `chain`.
    #[track_caller]
    pub fn lumped_torques(&self, chain: &Chain, q: &[f64]) -> Vec<f64> {
        (self.joint_loads(std::slice::from_ref(chain), q).iter())
            .map(|l| l.torque)
            .collect()
    }

    /// The gravity load of every joint of a tree (`tips`: one chain per tip, all with the same
    /// joints and parameters, as [`hapcal_kinematics::Tree::tips`]) at readings `q` (rad, m
    /// for a prismatic joint), evaluated on the nominal tree (zero deviations) in the frame of
    /// the tips' base, where [`Self::gravity_dir`] is given. Length `n_joints`.
    ///
    /// The moment about joint `j`'s origin `o_j` sums the weights hanging below it on every
    /// branch: a weight counts for `j` when `j` lies on the path from the root to the joint
    /// whose link carries it, on some tip,
    ///
    /// `M_j = Σ_{i ⪰ j} (c_i − o_j) × (m_i·g₀·ĝ)`  (N·m; `i ⪰ j`: `j` on `i`'s root path),
    ///
    /// with [`Self::masses`]; without them, unit weights at the origin of every joint below
    /// `j` and at the end of every tip below `j`: `M_j = Σ (o_i − o_j) × ĝ` (m). The torque
    /// about the axis is `τ_j = w_j·M_j`; the transversal moment, `M_j − (w_j·M_j)·w_j`, is
    /// expressed in the joint's frame before its motion (the frame of its placement's
    /// rotation deviations), for transversal compliance. A prismatic joint carries the
    /// links below it but no moment (zeros); so does a joint on no tip's path.
    ///
    /// Source: the gravity torque of a serial chain (Siciliano et al., *Robotics: Modelling,
    /// Planning and Control*, 2009, §7.2), summed over the subtree of a branched chain
    /// (Featherstone, *Rigid Body Dynamics Algorithms*, 2008, §4.1: the loads of a joint are
    /// those of its subtree).
    ///
    /// # Panics
    /// If `tips` is empty, `q.len()` differs from the tips' joint count, or a
    /// [`LinkMass::joint`] is not a joint of the tips.
    #[track_caller]
    pub fn joint_loads(&self, tips: &[Chain], q: &[f64]) -> Vec<JointLoad> {
        let n = tips[0].n_joints();
        let mut origin = vec![Vector3::zeros(); n];
        let mut axis = vec![Vector3::zeros(); n];
        let mut before = vec![UnitQuaternion::identity(); n];
        let mut link = vec![Isometry3::identity(); n];
        // below[j * n + i]: joint j lies on the root path of joint i (i = j included).
        let mut below = vec![false; n * n];
        // Tips whose path passes through each joint.
        let mut tips_below = vec![Vec::new(); n];
        let mut ends = Vec::with_capacity(tips.len());
        for (t, chain) in tips.iter().enumerate() {
            let x0 = vec![0.0; chain.n_params()];
            let poses = chain.frame_poses(&x0, q);
            let mut path = Vec::new();
            let mut previous = Isometry3::identity();
            for (factor, pose) in chain.factors().iter().zip(&poses) {
                if let Factor::Screw {
                    motion,
                    axis: a,
                    joint: Some(j),
                    ..
                } = factor
                {
                    link[*j] = *pose;
                    origin[*j] = pose.translation.vector;
                    before[*j] = previous.rotation;
                    if *motion == Motion::Rotation {
                        axis[*j] = pose.rotation * a.into_inner();
                    }
                    path.push(*j);
                    for &k in &path {
                        below[k * n + *j] = true;
                    }
                    tips_below[*j].push(t);
                }
                previous = *pose;
            }
            ends.push(previous.translation.vector);
        }
        let g = self.gravity_dir;
        let moment = |j: usize| -> Vector3<f64> {
            if self.masses.is_empty() {
                let joints = (0..n)
                    .filter(|&i| i != j && below[j * n + i])
                    .map(|i| origin[i]);
                let tips = tips_below[j].iter().map(|&t| ends[t]);
                joints.chain(tips).map(|o| (o - origin[j]).cross(&g)).sum()
            } else {
                (self.masses.iter())
                    .filter(|m| below[j * n + m.joint])
                    .map(|m| {
                        let c = link[m.joint] * Point3::from(m.com_m);
                        (c.coords - origin[j]).cross(&(g * (m.mass_kg * G0)))
                    })
                    .sum()
            }
        };
        (0..n)
            .map(|j| {
                if axis[j] == Vector3::zeros() {
                    return JointLoad::default();
                }
                let m = moment(j);
                let torque = axis[j].dot(&m);
                JointLoad {
                    torque,
                    transversal: before[j].inverse() * (m - torque * axis[j]),
                    turn: before[j].inverse() * link[j].rotation,
                }
            })
            .collect()
    }
}

/// The gravity load of one joint at one configuration ([`GravityCompliance::joint_loads`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointLoad {
    /// Moment about the joint axis, N·m (m for the lumped unit weights).
    pub torque: f64,
    /// Moment normal to the joint axis, in the joint's frame before its motion, N·m (m for
    /// the lumped unit weights).
    pub transversal: Vector3<f64>,
    /// The joint's own rotation at the configuration: its frame after the motion in its frame
    /// before it (identity for a prismatic joint or a joint on no tip's path).
    pub turn: UnitQuaternion<f64>,
}
