//! Calibrated URDF robots (trees, masses, compliance) against the calibration library
//! (`hapcal_problems::CalibratedModel`, `hapcal_kinematics::Chain`), to 1e-12.

use std::path::{Path, PathBuf};

use hapcal_contract::{
    Calibration, Frame, ModelName, PointMass, Region, SCHEMA_VERSION, Torque, TorqueSource,
};
use hapcal_io::CalibratedValue;
use hapcal_kinematics::{Isometry3, Tree, Vector3};
use hapcal_problems::{CalibratedModel, GravityCompliance, LinkMass};
use hapcal_runtime::{GravityModel, Pose, Robot};

use crate::iiwa_masses::calibrated_iiwa_text;
use crate::readings;

const TOL: f64 = 1e-12;

/// The tree fixture of this crate.
pub(crate) fn test_data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("test_data")
        .join(rel)
}

/// A fresh folder under the system's temporary directory.
pub(crate) fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hapcal-runtime-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    dir
}

/// Largest difference between a runtime pose and a library pose (rotation entries and
/// translation, m).
pub(crate) fn pose_gap(ours: &Pose, theirs: &Isometry3<f64>) -> f64 {
    let r = theirs.rotation.to_rotation_matrix();
    let mut gap: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            gap = gap.max((ours.rotation[i][j] - r[(i, j)]).abs());
        }
        gap = gap.max((ours.translation_m[i] - theirs.translation.vector[i]).abs());
    }
    gap
}

/// A compliance value as `hapcal calibrate` writes it into the sidecar.
pub(crate) fn compliance(joints: &str, value: f64, unit: &str) -> CalibratedValue {
    CalibratedValue {
        name: format!("compliance.{joints}"),
        value,
        std: value * 0.01,
        unit: unit.to_owned(),
    }
}

/// Writes `urdf_text` as `<dir>/robot.urdf` and beside it the record of `values` (a
/// `compliance` model with an instrument frame; loads from the URDF's link masses for `tips`,
/// else lumped unit weights; gravity along −z at the equilibrium) through the contract's one
/// writer, as `hapcal calibrate --out robot.urdf` does; returns the URDF's path.
pub(crate) fn write_calibrated(
    dir: &Path,
    urdf_text: &str,
    values: &[CalibratedValue],
    tips: &[&str],
) -> PathBuf {
    let urdf = dir.join("robot.urdf");
    std::fs::write(&urdf, urdf_text).expect("write urdf");
    let tips: Vec<String> = tips.iter().map(|t| (*t).to_owned()).collect();
    let tree = hapcal_io::import_urdf_tips(&urdf, &tips).expect("valid urdf");
    let masses: Vec<PointMass> = (tree.inertials.iter())
        .map(|l| PointMass {
            joint: tree.joints[l.joint].name.clone(),
            mass_kg: l.mass_kg,
            com_m: l.com_m,
        })
        .collect();
    let source = if masses.is_empty() {
        TorqueSource::LumpedUnitWeights
    } else {
        TorqueSource::UrdfMasses
    };
    let record = Calibration {
        schema_version: Some(SCHEMA_VERSION),
        model: Some(ModelName::Compliance),
        torque: Some(Torque {
            source,
            gravity_direction: [0.0, 0.0, -1.0],
            gravity_m_s2: hapcal_runtime::STANDARD_GRAVITY,
            equilibrium: true,
            tips: Vec::new(),
            masses,
            handle_mass_kg: None,
        }),
        region: Some(Region {
            rows: 100,
            joints: Vec::new(),
        }),
        frames: [(
            "instrument".to_owned(),
            Frame {
                xyz_m: [1.2, -0.3, 0.05],
                rpy_rad: [0.01, -0.02, 1.5],
            },
        )]
        .into(),
        values: values.to_vec(),
        ..Calibration::default()
    };
    std::fs::write(
        urdf.with_extension("calibration.toml"),
        record.to_sidecar_toml(),
    )
    .expect("write sidecar");
    urdf
}

/// The calibration library's model of the calibrated URDF `path` with tips `tips`: its
/// placements as the nominal tree (the origins are the calibrated ones), the URDF's masses
/// (lumped weights without), compliances `k` per joint name, loads at the equilibrium.
pub(crate) fn library_model(path: &Path, tips: &[&str], k: &[(&str, f64)]) -> CalibratedModel {
    let tips: Vec<String> = tips.iter().map(|t| (*t).to_owned()).collect();
    let urdf = hapcal_io::import_urdf_tips(path, &tips).expect("valid urdf");
    let tree = Tree::from_placement_paths(&urdf.paths).expect("valid tree");
    let masses: Vec<LinkMass> = (urdf.inertials.iter())
        .map(|l| LinkMass {
            joint: l.joint,
            mass_kg: l.mass_kg,
            com_m: Vector3::from(l.com_m),
        })
        .collect();
    let gravity = if masses.is_empty() {
        GravityCompliance::default()
    } else {
        GravityCompliance::from_link_masses(masses, -Vector3::z())
    };
    let compliances: Vec<f64> = (tree.joint_names().iter())
        .map(|name| (k.iter()).find(|(j, _)| j == name).map_or(0.0, |(_, v)| *v))
        .collect();
    CalibratedModel {
        chain: tree.tips()[0].clone(),
        tips: tree.tips().to_vec(),
        torque_tips: tree.tips().to_vec(),
        x_kin: vec![0.0; tree.n_params()],
        compliance: Some((gravity, compliances)),
        harmonics: None,
        transversal: Vec::new(),
        equilibrium: true,
    }
}

/// Joint angles over the robot's limits (continuous joints over one turn).
pub(crate) fn joint_samples(robot: &Robot, n: usize) -> Vec<Vec<f64>> {
    let limits: Vec<(f64, f64)> = (robot.limits().iter())
        .map(|&(lo, hi)| {
            if lo.is_finite() && hi.is_finite() {
                (lo, hi)
            } else {
                (-std::f64::consts::PI, std::f64::consts::PI)
            }
        })
        .collect();
    readings(&limits, n)
}

/// Deflected tip poses, rigid spatial and body Jacobians against the library's model of the
/// same file ([`library_model`] of `path`, `tips`, `k`); returns the largest gap and the
/// largest deflection of a tip (m), so that callers can check that the compliance mattered.
fn compare(robot: &Robot, path: &Path, tips: &[&str], k: &[(&str, f64)]) -> (f64, f64) {
    let model = library_model(path, tips, k);
    assert_eq!(model.chain.joint_names(), robot.joint_names());
    let n = robot.n_joints();
    let n_tips = robot.tip_names().len();
    let tips: Vec<usize> = (0..n_tips).collect();
    let mut ws = robot.workspace();
    let (mut deflected, mut rigid) = (vec![Pose::IDENTITY; n_tips], vec![Pose::IDENTITY; n_tips]);
    let (mut worst, mut moved): (f64, f64) = (0.0, 0.0);
    for q in joint_samples(robot, 100) {
        let deflection = robot
            .deflected_tip_poses(&q, &mut ws, &mut deflected)
            .expect("valid");
        assert!(deflection.converged, "{deflection:?}");
        assert!(deflection.iterations >= 2, "{deflection:?}");
        robot.tip_poses(&q, &mut ws, &mut rigid).expect("valid");
        let library = model.end_poses_of(&tips, &q);
        let x0 = vec![0.0; model.x_kin.len()];
        for t in 0..n_tips {
            worst = worst.max(pose_gap(&deflected[t], &library[t]));
            let rigid_lib = model.tips[t].end_pose(&x0, &q);
            worst = worst.max(pose_gap(&rigid[t], &rigid_lib));
            let d = (0..3)
                .map(|i| (deflected[t].translation_m[i] - rigid[t].translation_m[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            moved = moved.max(d);
            let jac_lib = model.tips[t].geometric_jacobian(&x0, &q);
            let (mut spatial, mut body) = (vec![[0.0; 6]; n], vec![[0.0; 6]; n]);
            let pose = robot
                .spatial_jacobian(t, &q, &mut ws, &mut spatial)
                .expect("valid");
            robot
                .body_jacobian(t, &q, &mut ws, &mut body)
                .expect("valid");
            let rt = rigid_lib.rotation.to_rotation_matrix().transpose();
            for k in 0..n {
                let lin = rt * Vector3::new(jac_lib[(0, k)], jac_lib[(1, k)], jac_lib[(2, k)]);
                let ang = rt * Vector3::new(jac_lib[(3, k)], jac_lib[(4, k)], jac_lib[(5, k)]);
                for r in 0..6 {
                    worst = worst.max((spatial[k][r] - jac_lib[(r, k)]).abs());
                    let b = if r < 3 { lin[r] } else { ang[r - 3] };
                    worst = worst.max((body[k][r] - b).abs());
                }
            }
            assert_eq!(pose, rigid[t]);
        }
    }
    (worst, moved)
}

fn tree_compliances() -> Vec<CalibratedValue> {
    let unit = "rad/(N·m)";
    vec![
        compliance("torso_joint", 3e-4, unit),
        compliance("l_joint1", 5e-4, unit),
        compliance("l_joint2+r_joint2", 8e-4, unit),
        compliance("l_joint3", 1.2e-3, unit),
        compliance("r_joint1", 4e-4, unit),
        compliance("r_joint3", 1e-3, unit),
    ]
}

const TREE_K: [(&str, f64); 7] = [
    ("torso_joint", 3e-4),
    ("l_joint1", 5e-4),
    ("l_joint2", 8e-4),
    ("r_joint2", 8e-4),
    ("l_joint3", 1.2e-3),
    ("r_joint1", 4e-4),
    ("r_joint3", 1e-3),
];

/// The tips of the tree fixture's calibrations.
const TREE_TIPS: [&str; 2] = ["l_gripper", "r_tool"];

/// The tree fixture with the compliance `values` at [`TREE_TIPS`], written into the scratch
/// folder `name`; returns the written URDF.
fn calibrated_tree(name: &str, values: &[CalibratedValue]) -> PathBuf {
    let text = std::fs::read_to_string(test_data("torso_two_arms.urdf")).expect("fixture");
    write_calibrated(&scratch(name), &text, values, &TREE_TIPS)
}

#[test]
fn tree_with_masses_and_compliance_matches_the_calibrated_model() {
    let path = calibrated_tree("tree", &tree_compliances());
    let tips = TREE_TIPS;
    let robot = Robot::load_urdf(&path, &tips).expect("valid");
    assert_eq!(robot.gravity_model(), GravityModel::Masses);
    // lift, torso, three per arm; the head joint is on no path.
    assert_eq!(
        robot.joint_names(),
        [
            "lift_joint",
            "torso_joint",
            "l_joint1",
            "l_joint2",
            "l_joint3",
            "r_joint1",
            "r_joint2",
            "r_joint3"
        ]
    );
    assert_eq!(robot.compliances()[3], 8e-4);
    assert_eq!(robot.compliances()[6], 8e-4);
    assert!(robot.frame("instrument").is_some());
    let (worst, moved) = compare(&robot, &path, &tips, &TREE_K);
    assert!(worst <= TOL, "largest gap {worst:e}");
    // The deflection is large enough for the comparison to see it (millimetres).
    assert!(moved > 1e-3, "largest deflection {moved:e} m");
}

/// Negative control: a compliance 1 % off moves the comparison far past its tolerance.
#[test]
fn tree_comparison_detects_a_changed_compliance() {
    let mut values = tree_compliances();
    values[3].value *= 1.01;
    let path = calibrated_tree("tree-changed", &values);
    let tips = TREE_TIPS;
    let robot = Robot::load_urdf(&path, &tips).expect("valid");
    let (worst, _) = compare(&robot, &path, &tips, &TREE_K);
    assert!(
        worst > 1e-7,
        "largest gap {worst:e}: the change went unseen"
    );
}

#[test]
fn seven_joint_arm_with_lumped_weights_matches_the_calibrated_model() {
    let dir = scratch("iiwa-lumped");
    let names = [
        "joint_a1", "joint_a2", "joint_a3", "joint_a4", "joint_a5", "joint_a6", "joint_a7",
    ];
    let k: Vec<(&str, f64)> = (names.iter().enumerate())
        .map(|(i, n)| (*n, 4e-4 + 1e-4 * i as f64))
        .collect();
    let values: Vec<CalibratedValue> = (k.iter())
        .map(|(n, v)| compliance(n, *v, "rad/m"))
        .collect();
    let path = write_calibrated(&dir, &calibrated_iiwa_text(), &values, &["ball_link"]);
    let robot = Robot::load_urdf(&path, &["ball_link"]).expect("valid");
    assert_eq!(robot.gravity_model(), GravityModel::Lumped);
    assert_eq!(robot.joint_names(), names);
    let (worst, moved) = compare(&robot, &path, &["ball_link"], &k);
    assert!(worst <= TOL, "largest gap {worst:e}");
    assert!(moved > 1e-4, "largest deflection {moved:e} m");
}

#[test]
fn loading_errors_name_the_file_and_what_is_wrong() {
    let text = std::fs::read_to_string(test_data("torso_two_arms.urdf")).expect("fixture");
    let dir = scratch("errors");
    let path = write_calibrated(&dir, &text, &tree_compliances(), &TREE_TIPS);
    let message = |tips: &[&str]| {
        Robot::load_urdf(&path, tips)
            .expect_err("invalid")
            .to_string()
    };
    let origin = path.display().to_string();
    let m = message(&["no_such_link"]);
    assert!(
        m.starts_with(&origin) && m.contains("\"no_such_link\"") && m.contains("r_tool"),
        "{m}"
    );
    let m = message(&["r_tool", "r_tool"]);
    assert!(m.contains("given twice"), "{m}");
    // A compliance of a joint that is not on the tips' paths.
    let m = message(&["r_tool"]);
    assert!(
        m.contains("\"l_joint1\"") && m.contains("no moving joint"),
        "{m}"
    );
    // A compliance in the lumped unit beside link masses (the record's source).
    let wrong = [compliance("torso_joint", 1e-4, "rad/m")];
    let path = write_calibrated(&dir, &text, &wrong, &TREE_TIPS);
    let m = Robot::load_urdf(&path, &["r_tool"])
        .expect_err("invalid")
        .to_string();
    assert!(m.contains("is in \"rad/m\", expected \"rad/(N·m)\""), "{m}");
    // A value the runtime does not evaluate.
    let transversal = [CalibratedValue {
        name: "transversal.torso_joint".to_owned(),
        value: 1e-4,
        std: 0.0,
        unit: "rad/(N·m)".to_owned(),
    }];
    let path = write_calibrated(&dir, &text, &transversal, &TREE_TIPS);
    let m = Robot::load_urdf(&path, &["r_tool"])
        .expect_err("invalid")
        .to_string();
    assert!(m.contains("transversal.torso_joint"), "{m}");
    // A malformed sidecar: file, line and column.
    let sidecar = path.with_extension("calibration.toml");
    let refused = |text: &str| {
        std::fs::write(&sidecar, text).expect("write");
        Robot::load_urdf(&path, &["r_tool"])
            .expect_err("invalid")
            .to_string()
    };
    let m = refused("[values]\n\"compliance.torso_joint\" = 3\n");
    let sidecar = sidecar.display().to_string();
    assert!(m.starts_with(&format!("{sidecar}:2:")), "{m}");
    // An earlier hapcal's sidecar (frames and values, no schema_version) is refused.
    let m = refused(
        "[values]\n\"compliance.torso_joint\" = { value = 1e-4, std = 0.0, unit = \"rad/(N·m)\" }\n",
    );
    assert!(
        m.starts_with(&format!("{sidecar}:1:1: missing key schema_version")),
        "{m}"
    );
}
