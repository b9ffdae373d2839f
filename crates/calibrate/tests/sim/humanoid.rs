//! A simulated two-arm humanoid upper body: a pitching torso under a head and two seven-joint
//! arms, a CAD mass on every link, joint and transversal compliance on the torso and both
//! arms, a tracker marker on each hand. The truth is evaluated with the measurement model of
//! `hapcal-problems` at known parameters. Shared by the humanoid test, the measured-data
//! benchmark and the example that writes the recording (`sim_humanoid`).
#![allow(clippy::unwrap_used, clippy::expect_used, dead_code, unreachable_pub)]

use std::fmt::Write as _;

use faer::Col;
use hapcal_calibrate::measured::{Robot, robot_from_urdf};
use hapcal_identify::Problem;
use hapcal_io::{MarkerSample, MeasuredRow, MeasurementTable};
use hapcal_kinematics::{FrameSpec, Isometry3, Vector3};
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, ModelTerms, Observations, Row, RowKind, Weights,
};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

/// Marker noise per axis, m (motion capture).
pub const NOISE_M: f64 = 2e-4;

/// One joint of the URDF: name, parent, child, origin xyz, origin rpy, axis (fixed if `None`).
type JointRow<'a> = (
    &'a str,
    &'a str,
    &'a str,
    [f64; 3],
    [f64; 3],
    Option<[f64; 3]>,
);

/// One arm joint: number, origin xyz (left arm), axis.
type ArmJoint = (&'static str, [f64; 3], [f64; 3]);

/// An arm joint named for its side: joint, link, origin, axis, side sign.
type SideJoint = (&'static str, &'static str, [f64; 3], [f64; 3], f64);

/// The humanoid's URDF: torso yaw (vertical, no gravity torque) and two pitches, a head
/// (fixed, 4 kg), two arms of seven revolute joints, a hand on each: 17 joints.
pub fn humanoid_urdf() -> String {
    humanoid_urdf_with_torso(false)
}

/// The humanoid's URDF, with `long_torso` a torso of five joints (yaw, pitch, pitch, roll,
/// pitch, as an upper body with a waist and a chest joint): 19 joints on the two hands.
pub fn humanoid_urdf_with_torso(long_torso: bool) -> String {
    humanoid_urdf_of(long_torso, false)
}

/// The humanoid of [`humanoid_urdf_with_torso`] described as many real humanoids' URDFs are:
/// every moving joint turns about its own z axis, the frame turned onto the joint by the
/// fixed `rpy` of its origin (rotations of ±π/2, so the written numbers carry rounding), the
/// fixed hand and head joints turning back. The same robot: every link's centre of mass and
/// every tip frame at the same place as in [`humanoid_urdf_with_torso`].
pub fn humanoid_urdf_z_axes(long_torso: bool) -> String {
    humanoid_urdf_of(long_torso, true)
}

/// Re-expresses `joints` and the links' centres of mass `links` in frames whose moving joints
/// turn about z: a joint about `a` gets the frame `R_a` (z onto `a`) after its original frame;
/// a fixed joint keeps its original frame. Origins `T = (xyz, I)` in the parent's original
/// frame become `R_p⁻¹·(xyz, R_c)`, centres of mass `R_c⁻¹·com`.
fn z_axis_frames(joints: &mut [JointRow<'_>], links: &mut [(String, f64, [f64; 3])]) {
    use hapcal_kinematics::UnitQuaternion;
    use std::f64::consts::FRAC_PI_2;
    // Ry(π/2) turns z onto x, Rx(−π/2) turns z onto y.
    let turn_of = |axis: Option<[f64; 3]>| match axis {
        Some([x, _, _]) if x != 0.0 => {
            UnitQuaternion::from_euler_angles(0.0, x.signum() * FRAC_PI_2, 0.0)
        }
        Some([_, y, _]) if y != 0.0 => {
            UnitQuaternion::from_euler_angles(-y.signum() * FRAC_PI_2, 0.0, 0.0)
        }
        _ => UnitQuaternion::identity(),
    };
    let turns: Vec<(String, UnitQuaternion<f64>)> = (joints.iter())
        .map(|(_, _, child, _, _, axis)| ((*child).to_owned(), turn_of(*axis)))
        .collect();
    let turn = |link: &str| {
        (turns.iter())
            .find(|(l, _)| l == link)
            .map_or_else(UnitQuaternion::identity, |(_, r)| *r)
    };
    for (_, parent, child, xyz, rpy, axis) in joints.iter_mut() {
        let (rp, rc) = (turn(parent), turn(child));
        let t = rp.inverse() * Vector3::from(*xyz);
        *xyz = [t.x, t.y, t.z];
        let (roll, pitch, yaw) = (rp.inverse() * rc).euler_angles();
        *rpy = [roll, pitch, yaw];
        if axis.is_some() {
            *axis = Some([0.0, 0.0, 1.0]);
        }
    }
    for (name, _, com) in links.iter_mut() {
        let c = turn(name).inverse() * Vector3::from(*com);
        *com = [c.x, c.y, c.z];
    }
}

fn humanoid_urdf_of(long_torso: bool, z_axes: bool) -> String {
    let chest_parent = if long_torso {
        "torso_4_link"
    } else {
        "torso_2_link"
    };
    let mut joints: Vec<JointRow<'_>> = vec![
        (
            "torso_1",
            "base",
            "torso_1_link",
            [0.0, 0.0, 0.3],
            [0.0; 3],
            Some([0.0, 0.0, 1.0]),
        ),
        (
            "torso_2",
            "torso_1_link",
            "torso_2_link",
            [0.0, 0.0, 0.1],
            [0.0; 3],
            Some([0.0, 1.0, 0.0]),
        ),
    ];
    if long_torso {
        joints.extend([
            (
                "torso_3",
                "torso_2_link",
                "torso_3_link",
                [0.0, 0.0, 0.2],
                [0.0; 3],
                Some([0.0, 1.0, 0.0]),
            ),
            (
                "torso_4",
                "torso_3_link",
                "torso_4_link",
                [0.0, 0.0, 0.05],
                [0.0; 3],
                Some([1.0, 0.0, 0.0]),
            ),
        ]);
    }
    let last = if long_torso { "torso_5" } else { "torso_3" };
    let rise = if long_torso { 0.1 } else { 0.35 };
    joints.extend([
        (
            last,
            chest_parent,
            "chest",
            [0.0, 0.0, rise],
            [0.0; 3],
            Some([0.0, 1.0, 0.0]),
        ),
        ("neck", "chest", "head", [0.0, 0.0, 0.3], [0.0; 3], None),
    ]);
    let arm: [ArmJoint; 7] = [
        ("1", [0.0, 0.22, 0.15], [0.0, 1.0, 0.0]),
        ("2", [0.0, 0.08, 0.0], [1.0, 0.0, 0.0]),
        ("3", [0.0, 0.0, -0.12], [0.0, 0.0, 1.0]),
        ("4", [0.0, 0.0, -0.18], [0.0, 1.0, 0.0]),
        ("5", [0.0, 0.0, -0.12], [0.0, 0.0, 1.0]),
        ("6", [0.0, 0.0, -0.16], [0.0, 1.0, 0.0]),
        ("7", [0.0, 0.0, -0.05], [1.0, 0.0, 0.0]),
    ];
    let mut names = Vec::new();
    for side in ["l", "r"] {
        let s = if side == "l" { 1.0 } else { -1.0 };
        for (k, xyz, axis) in arm {
            names.push((
                format!("{side}_{k}"),
                format!("{side}_link{k}"),
                xyz,
                axis,
                s,
            ));
        }
    }
    let leaked: Vec<SideJoint> = names
        .into_iter()
        .map(|(j, l, xyz, axis, s)| {
            let j: &'static str = Box::leak(j.into_boxed_str());
            let l: &'static str = Box::leak(l.into_boxed_str());
            (j, l, xyz, axis, s)
        })
        .collect();
    for side in 0..2 {
        let mut parent = "chest";
        for &(j, l, xyz, axis, s) in &leaked[7 * side..7 * side + 7] {
            joints.push((
                j,
                parent,
                l,
                [xyz[0], s * xyz[1], xyz[2]],
                [0.0; 3],
                Some(axis),
            ));
            parent = l;
        }
        let hand = if side == 0 { "l_hand" } else { "r_hand" };
        let name = if side == 0 {
            "l_hand_joint"
        } else {
            "r_hand_joint"
        };
        joints.push((name, parent, hand, [0.0, 0.0, -0.1], [0.0; 3], None));
    }
    let mut links: Vec<(String, f64, [f64; 3])> = vec![("base".into(), 0.0, [0.0; 3])];
    for (_, _, child, _, _, _) in &joints {
        let (mass, com) = match *child {
            "torso_1_link" => (6.0, [0.0, 0.0, 0.05]),
            "torso_2_link" => (8.0, [0.02, 0.0, 0.15]),
            "torso_3_link" => (3.0, [0.01, 0.0, 0.1]),
            "torso_4_link" => (2.0, [0.0, 0.0, 0.03]),
            "chest" => (15.0, [0.03, 0.0, 0.15]),
            "head" => (4.0, [0.02, 0.0, 0.1]),
            "l_hand" | "r_hand" => (0.8, [0.0, 0.0, -0.05]),
            c if c.ends_with("link1") || c.ends_with("link2") => (2.5, [0.0, 0.0, -0.03]),
            c if c.ends_with("link3") || c.ends_with("link4") => (2.0, [0.01, 0.0, -0.09]),
            _ => (1.2, [0.0, 0.01, -0.06]),
        };
        links.push(((*child).to_owned(), mass, com));
    }
    if z_axes {
        z_axis_frames(&mut joints, &mut links);
    }
    let mut s = String::from("<?xml version=\"1.0\"?>\n<robot name=\"humanoid\">\n");
    for (name, mass, c) in &links {
        if *mass > 0.0 {
            writeln!(
                s,
                "  <link name=\"{name}\"><inertial><mass value=\"{mass}\"/><origin xyz=\"{} {} {}\"/>\
                 <inertia ixx=\"0.01\" ixy=\"0\" ixz=\"0\" iyy=\"0.01\" iyz=\"0\" izz=\"0.01\"/></inertial></link>",
                c[0], c[1], c[2]
            )
            .unwrap();
        } else {
            writeln!(s, "  <link name=\"{name}\"/>").unwrap();
        }
    }
    for (name, parent, child, xyz, rpy, axis) in &joints {
        let kind = if axis.is_some() { "revolute" } else { "fixed" };
        write!(
            s,
            "  <joint name=\"{name}\" type=\"{kind}\"><parent link=\"{parent}\"/><child link=\"{child}\"/>\
             <origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
            xyz[0], xyz[1], xyz[2], rpy[0], rpy[1], rpy[2]
        )
        .unwrap();
        if let Some(a) = axis {
            let limit = if name.starts_with("torso") { 0.5 } else { 2.0 };
            write!(
                s,
                "<axis xyz=\"{} {} {}\"/><limit lower=\"-{limit}\" upper=\"{limit}\" effort=\"100\" velocity=\"1\"/>",
                a[0], a[1], a[2]
            )
            .unwrap();
        }
        s.push_str("</joint>\n");
    }
    s.push_str("</robot>\n");
    s
}

/// The humanoid with tips `tips`, from its URDF written to a temporary file.
pub fn humanoid(tips: &[&str]) -> Robot {
    humanoid_of(&humanoid_urdf(), tips)
}

/// The humanoid of [`humanoid_urdf_with_torso`] (19 joints) with tips `tips`.
pub fn long_torso_humanoid(tips: &[&str]) -> Robot {
    humanoid_of(&humanoid_urdf_with_torso(true), tips)
}

/// The humanoid of [`humanoid_urdf_z_axes`] with tips `tips`.
pub fn z_axes_humanoid(long_torso: bool, tips: &[&str]) -> Robot {
    humanoid_of(&humanoid_urdf_z_axes(long_torso), tips)
}

fn humanoid_of(urdf: &str, tips: &[&str]) -> Robot {
    let dir = std::env::temp_dir().join(format!("hapcal-humanoid-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // One file per caller and robot: tests run in parallel.
    let robot = match (
        urdf.contains("torso_5"),
        urdf.contains("<axis xyz=\"0 1 0\""),
    ) {
        (true, true) => "humanoid19",
        (false, true) => "humanoid",
        (true, false) => "humanoid19-z",
        (false, false) => "humanoid-z",
    };
    let path = dir.join(format!("{robot}-{}.urdf", tips.join("-")));
    let tmp = path.with_extension(format!("{:?}.tmp", std::thread::current().id()));
    std::fs::write(&tmp, urdf).unwrap();
    std::fs::rename(&tmp, &path).unwrap();
    let tips: Vec<String> = tips.iter().map(|t| (*t).to_owned()).collect();
    robot_from_urdf(&path, &tips).unwrap()
}

/// The simulated robot: the tree with both hands framed, and the truth in its problem layout.
pub struct Truth {
    /// The problem whose model the truth is.
    pub problem: CalibrationProblem,
    /// The true parameters, in its layout.
    pub x: Col<f64>,
}

/// Truth compliance of a joint, rad/(N·m): torso stiffer than the arms' small drives.
pub fn compliance_of(joint: &str) -> f64 {
    if joint.starts_with("torso") {
        4e-5
    } else {
        1.5e-4
    }
}

/// Transversal compliance of a joint, rad/(N·m).
pub fn transversal_of(joint: &str) -> f64 {
    if joint.starts_with("torso") {
        3e-5
    } else {
        6e-5
    }
}

/// The per-axis transversal compliances of a joint, rad/(N·m): about `u` and `v` of
/// [`hapcal_problems::Transversal::PerAxis`], one four times the other.
pub fn transversal_axes_of(joint: &str) -> [f64; 2] {
    let c = transversal_of(joint);
    [1.6 * c, 0.4 * c]
}

/// The truth: geometric deviations (0.3 mm, 0.3 mrad) drawn from `seed`, the compliances of
/// [`compliance_of`] and [`transversal_of`].
pub fn truth(robot: &Robot, seed: u64) -> Truth {
    truth_with(robot, seed, hapcal_problems::Transversal::Isotropic)
}

/// Marker noise per axis of the recording that behaves like real motion capture, m.
pub const REAL_LIKE_NOISE_M: f64 = 2e-3;

/// Relative standard deviation of a link's true mass from the URDF's (a CAD model's mass
/// leaves out cables, fasteners and covers).
pub const CAD_MASS_ERROR: f64 = 0.1;

/// Rows of the recording that behaves like real motion capture.
pub const REAL_LIKE_ROWS: usize = 350;

/// The link masses the robot really has: the URDF's (CAD) masses each scaled by
/// `1 + CAD_MASS_ERROR·z`, `z` standard normal drawn from `seed`, in the URDF's order.
pub fn true_masses(robot: &Robot, seed: u64) -> Vec<hapcal_problems::LinkMass> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let z = Normal::new(0.0, CAD_MASS_ERROR).unwrap();
    (robot.masses.iter())
        .map(|m| hapcal_problems::LinkMass {
            mass_kg: m.mass_kg * (1.0 + z.sample(&mut rng)),
            ..m.clone()
        })
        .collect()
}

/// Seed of the bundled recording that behaves like real motion capture
/// (fixtures/sim-humanoid/real-like.csv).
pub const REAL_LIKE_SEED: u64 = 21;

/// The truth of the simulated two-arm humanoid that behaves like the real data: per-axis
/// transversal compliance ([`transversal_axes_of`]), geometric deviations drawn from `seed`,
/// and the gravity loads of the link masses of [`true_masses`] (seed `seed + 100`) where the
/// URDF gives the CAD ones. Returns the truth and its masses.
pub fn real_like_truth(robot: &Robot, seed: u64) -> (Truth, Vec<hapcal_problems::LinkMass>) {
    let masses = true_masses(robot, seed + 100);
    let truth = truth_of(
        robot,
        seed,
        hapcal_problems::Transversal::PerAxis,
        masses.clone(),
    );
    (truth, masses)
}

/// The recording of [`real_like_truth`]: [`REAL_LIKE_ROWS`] rows of both hands' markers with
/// [`REAL_LIKE_NOISE_M`] noise (seed `seed + 1`). Returns the truth, its masses and the table.
pub fn real_like(
    robot: &Robot,
    seed: u64,
) -> (Truth, Vec<hapcal_problems::LinkMass>, MeasurementTable) {
    let (truth, masses) = real_like_truth(robot, seed);
    let table = table_with_noise(
        robot,
        &truth,
        &[0, 1],
        REAL_LIKE_ROWS,
        seed + 1,
        REAL_LIKE_NOISE_M,
    );
    (truth, masses, table)
}

/// As [`truth`], with the transversal compliance `transversal` ([`transversal_axes_of`] for
/// per-axis).
pub fn truth_with(robot: &Robot, seed: u64, transversal: hapcal_problems::Transversal) -> Truth {
    truth_of(robot, seed, transversal, robot.masses.clone())
}

/// As [`truth_with`], the gravity loads from the link masses `masses`.
pub fn truth_of(
    robot: &Robot,
    seed: u64,
    transversal: hapcal_problems::Transversal,
    masses: Vec<hapcal_problems::LinkMass>,
) -> Truth {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let base = FrameSpec {
        name: "instrument".into(),
        nominal: Isometry3::new(Vector3::new(2.5, 0.4, -0.9), Vector3::new(0.05, -0.02, 2.8)),
    };
    let marker = |name: &str| FrameSpec {
        name: name.into(),
        nominal: Isometry3::translation(0.04, 0.0, -0.08),
    };
    let tree = robot.tree.with_joint_offsets();
    let framed = tree
        .with_frames(&base, &[(0, marker("marker1")), (1, marker("marker2"))])
        .unwrap();
    let dummy = Observations {
        rows: vec![Row {
            q: vec![0.0; robot.joint_names.len()].into(),
            kind: RowKind::Marker {
                tip: 0,
                position_m: [0.0; 3],
            },
        }],
        ..Observations::default()
    };
    let problem = CalibrationProblem::on_tree(
        framed,
        dummy,
        Weights::default(),
        ModelTerms {
            compliance: Some(GravityCompliance::from_link_masses(masses, -Vector3::z())),
            transversal,
            harmonics: None,
            torque_tips: Some(robot.tree.tips().to_vec()),
            load_angles: None,
        },
    )
    .unwrap();
    let layout = problem.layout();
    let geometry = Normal::new(0.0, 3e-4).unwrap();
    let x = Col::from_fn(layout.len(), |i| {
        let name = layout.name(i);
        if name.starts_with("instrument.") || name.starts_with("marker") {
            0.0
        } else if let Some(j) = name.strip_prefix("compliance.") {
            compliance_of(j)
        } else if let Some(j) = name.strip_prefix("transversal.") {
            match (j.strip_suffix(".u"), j.strip_suffix(".v")) {
                (Some(j), _) => transversal_axes_of(j)[0],
                (_, Some(j)) => transversal_axes_of(j)[1],
                _ => transversal_of(j),
            }
        } else {
            // Geometric deviations: 0.3 mm and 0.3 mrad.
            geometry.sample(&mut rng)
        }
    });
    Truth { problem, x }
}

/// `n` rows of the markers in `markers` (0: left hand, 1: right hand) measured in the
/// tracker frame, with noise [`NOISE_M`].
pub fn table(
    robot: &Robot,
    truth: &Truth,
    markers: &[usize],
    n: usize,
    seed: u64,
) -> MeasurementTable {
    table_with_noise(robot, truth, markers, n, seed, NOISE_M)
}

/// As [`table`], with Gaussian noise `noise_m` per axis (m) on the markers.
pub fn table_with_noise(
    robot: &Robot,
    truth: &Truth,
    markers: &[usize],
    n: usize,
    seed: u64,
    noise_m: f64,
) -> MeasurementTable {
    let rows = rows_with_noise(robot, truth, markers, seed, noise_m)
        .take(n)
        .collect();
    MeasurementTable::positions(format!("seed{seed}"), "mocap.csv", markers.len(), rows)
}

/// The rows of [`table_with_noise`] one at a time, without end (take as many as wanted): row
/// `i` at line `i + 2`, the same rows for the same `seed` whatever the number taken, so a long
/// file is written as it is drawn, never held whole.
pub fn rows_with_noise<'a>(
    robot: &'a Robot,
    truth: &Truth,
    markers: &'a [usize],
    seed: u64,
    noise_m: f64,
) -> impl Iterator<Item = MeasuredRow> + 'a {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    // The robot deflects until the gravity loads of its deflected links balance: the torque
    // equilibrium, not one step from the undeflected robot.
    let model = hapcal_problems::CalibratedModel {
        equilibrium: true,
        ..truth.problem.model(truth.x.as_ref())
    };
    let noise = Normal::new(0.0, noise_m).unwrap();
    (0u64..).map(move |i| {
        let q: Vec<f64> = (robot.limits.iter())
            .map(|(lo, hi)| rng.random_range(0.8 * lo..0.8 * hi))
            .collect();
        let samples = (markers.iter().enumerate())
            .map(|(k, &tip)| {
                let p = model.end_pose_of(tip, &q).translation.vector;
                MarkerSample {
                    marker: k,
                    position_m: std::array::from_fn(|a| p[a] + noise.sample(&mut rng)),
                    rotation: None,
                }
            })
            .collect();
        MeasuredRow {
            line: i + 2,
            q: q.into(),
            t_s: None,
            markers: samples,
            distance_m: None,
        }
    })
}
