use std::path::Path;

use hapcal_io::{
    CalibratedValue, CalibrationMeta, Error, import_urdf, import_urdf_tips, load_tips,
    parse_device, write_calibrated_urdf, write_device,
};

use crate::{assert_contains, data, message, mukca};

fn value(name: &str, value: f64) -> CalibratedValue {
    let unit = if name.ends_with(".x") || name.ends_with(".y") || name.ends_with(".z") {
        "m"
    } else {
        "rad"
    };
    CalibratedValue {
        name: name.into(),
        value,
        std: 1e-6,
        unit: unit.into(),
    }
}

/// A temporary folder of this test process, removed on drop.
struct TempDir(std::path::PathBuf);

impl TempDir {
    fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("hapcal-io-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temporary folder");
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn iiwa_imports_seven_revolute_joints_and_two_fixed_ones() {
    let path = mukca("urdf/iiwa14.urdf");
    let device = import_urdf(&path, "ball_link").unwrap();
    let names: Vec<&str> = device.placements.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "joint_a1",
            "joint_a2",
            "joint_a3",
            "joint_a4",
            "joint_a5",
            "joint_a6",
            "joint_a7",
            "joint_a7-tool0",
            "ball_joint"
        ]
    );
    let moving: Vec<bool> = device.placements.iter().map(|p| p.axis.is_some()).collect();
    assert_eq!(
        moving,
        [true, true, true, true, true, true, true, false, false]
    );
    assert_eq!(device.placements[1].xyz_m, [-0.00043624, 0.0, 0.36]);
    assert_eq!(device.placements[3].axis, Some([0.0, -1.0, 0.0]));
    assert_eq!(device.placements[8].xyz_m, [0.0, 0.0, 0.04]);
    assert_eq!(device.n_joints(), 7);
    assert_eq!(device.joints[0].name, "joint_a1");
    assert_eq!(device.joint_limits()[1], (-2.0942, 2.0942));
    assert_eq!(device.joint_limits()[6], (-3.0541, 3.0541));
    let urdf = device.urdf.as_ref().unwrap();
    assert_eq!(
        (urdf.path.as_path(), urdf.tip.as_str()),
        (path.as_path(), "ball_link")
    );

    let chain = device.chain().unwrap();
    assert_eq!(chain.n_joints(), 7);
    assert_eq!(chain.n_params(), 8 * 6); // 7 joints + the tip element
    assert!(chain.param_index("ball_joint.z").is_some());

    // The imported device is a self-contained device file.
    let again = parse_device(&write_device(&device), Path::new("iiwa.toml")).unwrap();
    assert_eq!(again, device);
}

#[test]
fn missing_tip_lists_the_links() {
    let err = import_urdf(&mukca("urdf/iiwa14.urdf"), "ball").unwrap_err();
    match &err {
        Error::TipNotFound { tip, available, .. } => {
            assert_eq!(tip, "ball");
            assert_eq!(available.len(), 11);
            assert!(available.iter().any(|l| l == "ball_link"));
        }
        other => panic!("unexpected {other:?}"),
    }
    assert_contains(
        &err.to_string(),
        &["iiwa14.urdf: no link named \"ball\"; the links are: base_link, link_1, "],
    );
}

#[test]
fn tiny_urdf_imports_continuous_and_missing_origins() {
    let device = import_urdf(&data("tiny.urdf"), "tool").unwrap();
    let p = &device.placements;
    assert_eq!(p.len(), 3);
    assert_eq!((p[0].xyz_m, p[0].rpy_rad), ([0.0; 3], [0.0; 3]));
    assert_eq!(p[1].axis, Some([0.0, 1.0, 0.0]));
    assert_eq!(p[2].rpy_rad, [0.0, 0.0, 0.5]);
    let pi = std::f64::consts::PI;
    assert_eq!(device.joint_limits(), [(-1.5, 1.5), (-pi, pi)]);
}

#[test]
fn prismatic_joints_and_trees_of_several_tips_import() {
    let device = import_urdf(&data("tiny.urdf"), "slider").unwrap();
    let p = &device.placements;
    assert_eq!(p.len(), 3);
    assert!(p[2].prismatic && !p[1].prismatic);
    assert_eq!(p[2].axis, Some([1.0, 0.0, 0.0]));
    let pi = std::f64::consts::PI;
    assert_eq!(device.joint_limits(), [(-1.5, 1.5), (-pi, pi), (0.0, 0.1)]);

    let tree = import_urdf_tips(
        &data("tiny.urdf"),
        &["tool".to_owned(), "slider".to_owned()],
    )
    .unwrap();
    let names: Vec<&str> = tree.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["shoulder", "elbow", "slide"]);
    assert_eq!(tree.prismatic, [false, false, true]);
    let path_names =
        |k: usize| -> Vec<String> { tree.paths[k].iter().map(|p| p.name.clone()).collect() };
    assert_eq!(path_names(0), ["shoulder", "elbow", "tool_joint"]);
    assert_eq!(path_names(1), ["shoulder", "elbow", "slide"]);
    // A continuous joint of a tree may have turned many times.
    assert_eq!(
        (tree.joints[1].lower_rad, tree.joints[1].upper_rad),
        (-1e3, 1e3)
    );
}

#[test]
fn link_masses_are_carried_to_the_nearest_moving_joint() {
    // The tool hangs from the arm by a fixed joint (0.2 m along x, then 90° about z): its
    // centre of mass, 0.01 m along the tool's x, is (0.2, 0.01, 0) in the joint's frame.
    let tree = import_urdf_tips(&data("inertial.urdf"), &["tool".to_owned()]).unwrap();
    assert_eq!(
        tree.inertials.len(),
        2,
        "the base link is not carried by a joint"
    );
    let arm = &tree.inertials[0];
    assert_eq!((arm.link.as_str(), arm.joint, arm.mass_kg), ("arm", 0, 2.0));
    assert_eq!(arm.com_m, [0.0, 0.0, 0.05]);
    let tool = &tree.inertials[1];
    assert_eq!(
        (tool.link.as_str(), tool.joint, tool.mass_kg),
        ("tool", 0, 1.0)
    );
    let expected = [0.2, 0.01, 0.0];
    for (got, want) in tool.com_m.iter().zip(expected) {
        assert!(
            (got - want).abs() < 1e-15,
            "{:?} against {expected:?}",
            tool.com_m
        );
    }
}

#[test]
fn masses_off_the_measured_paths_load_the_joint_above_them() {
    // Only arm_a is measured: arm_b (another branch, its joint held at zero) and the tool below
    // a tip still weigh on the joints above them.
    let tree = import_urdf_tips(&data("branches.urdf"), &["arm_a".to_owned()]).unwrap();
    let names: Vec<&str> = tree.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["j1", "a1"]);
    let of = |link: &str| {
        (tree.inertials.iter())
            .find(|l| l.link == link)
            .unwrap_or_else(|| panic!("no inertial for {link}: {:?}", tree.inertials))
    };
    assert_eq!((of("torso").joint, of("torso").mass_kg), (0, 4.0));
    assert_eq!((of("arm_a").joint, of("arm_a").com_m), (1, [0.1, 0.0, 0.0]));
    let b = of("arm_b");
    assert_eq!((b.joint, b.mass_kg), (0, 3.0));
    // b1's origin (0, −0.2, 0.3), rotated 90° about z: the 0.1 m along arm_b's x is along
    // the torso's y.
    for (got, want) in b.com_m.iter().zip([0.0, -0.1, 0.3]) {
        assert!((got - want).abs() < 1e-15, "{:?}", b.com_m);
    }
    // b1 moves but no measurement reads it: it is the one joint held at zero.
    assert_eq!(tree.held_joints, ["b1"]);
    let tool_below_tip = import_urdf_tips(&data("inertial.urdf"), &["arm".to_owned()]).unwrap();
    assert!(tool_below_tip.inertials.iter().any(|l| l.link == "tool"));
    // The tool hangs by a fixed joint: nothing is held.
    assert!(tool_below_tip.held_joints.is_empty());
    let both = import_urdf_tips(
        &data("branches.urdf"),
        &["arm_a".to_owned(), "arm_b".to_owned()],
    )
    .unwrap();
    assert!(both.held_joints.is_empty(), "{:?}", both.held_joints);
}

/// The joints off the measured paths that the data read become paths of further tips: the
/// deepest link reached through read joints alone (the simulated humanoid, its left hand
/// measured).
#[test]
fn read_joints_off_the_paths_get_a_load_tip() {
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/sim-humanoid/humanoid.urdf");
    let tips = ["l_hand".to_owned()];
    let right: Vec<String> = (1..=7).map(|k| format!("r_{k}")).collect();
    assert_eq!(load_tips(&urdf, &tips, &right).unwrap(), ["r_hand"]);
    // Without r_7's reading, the deepest link reached through read joints is r_7's parent.
    assert_eq!(load_tips(&urdf, &tips, &right[..6]).unwrap(), ["r_link6"]);
    // No right-arm reading: nothing to add (the arm stays held at zero).
    assert!(load_tips(&urdf, &tips, &[]).unwrap().is_empty());
}

#[test]
fn unsupported_and_malformed_urdfs_are_errors() {
    let msg = message(import_urdf(&data("tiny.urdf"), "base"));
    assert_contains(&msg, &["no moving joint between the root link \"base\""]);
    let msg = message(import_urdf_tips(
        &data("tiny.urdf"),
        &["tool".to_owned(), "tool".to_owned()],
    ));
    assert_contains(&msg, &["tip link \"tool\" is given twice"]);
    let msg = message(import_urdf(&data("broken.urdf"), "a"));
    assert_contains(&msg, &["broken.urdf:3:3: "]);
    let msg = message(import_urdf(&data("no_such.urdf"), "a"));
    assert_contains(&msg, &["cannot read ", "no_such.urdf: "]);
    // The joint type as the file spells it.
    let msg = message(import_urdf(&data("floating.urdf"), "tool"));
    assert_contains(
        &msg,
        &["floating.urdf: joint \"free_flyer\" is floating; only revolute"],
    );
}

#[test]
fn calibrated_urdf_reads_back_with_exactly_the_new_origins() {
    let source = mukca("urdf/iiwa14.urdf");
    let device = import_urdf(&source, "ball_link").unwrap();
    let values = [
        value("joint_a2.x", 1.25e-4),
        value("joint_a2.rz", -3e-3),
        value("joint_a4.ry", 0.1 + 0.2),
        value("joint_a6.z", -2e-4),
        value("ball_joint.x", 1e-3),
        value("ball_joint.rx", 2e-3),
    ];
    let calibrated = device
        .with_calibration(&values, CalibrationMeta::default())
        .unwrap();
    let changed: Vec<&str> = (calibrated.placements.iter().zip(&device.placements))
        .filter(|(c, d)| c != d)
        .map(|(c, _)| c.name.as_str())
        .collect();
    assert_eq!(changed, ["joint_a2", "joint_a4", "joint_a6", "ball_joint"]);

    let text = write_calibrated_urdf(&source, &calibrated.placements).unwrap();
    let robot = urdf_rs::read_from_string(&text).unwrap();
    for p in &calibrated.placements {
        let joint = robot.joints.iter().find(|j| j.name == p.name).unwrap();
        assert_eq!(joint.origin.xyz.0, p.xyz_m, "{}", p.name);
        assert_eq!(joint.origin.rpy.0, p.rpy_rad, "{}", p.name);
    }

    // Only the origin lines of the changed joints differ; comments and the rest stay.
    let original = std::fs::read_to_string(&source).unwrap();
    let differing: Vec<(&str, &str)> = (original.lines().zip(text.lines()))
        .filter(|(a, b)| a != b)
        .collect();
    assert_eq!(original.lines().count(), text.lines().count());
    assert_eq!(differing.len(), 4, "{differing:#?}");
    assert!(
        differing
            .iter()
            .all(|(a, b)| a.contains("<origin") && b.contains("<origin"))
    );
    assert_contains(&text, &["<!--origin rpy=\"0 0 0\" xyz=\"0 0 0.1034\"/-->"]);

    // Importing the written URDF gives the calibrated placements.
    let dir = TempDir::new("urdf");
    let written = dir.0.join("iiwa14_calibrated.urdf");
    std::fs::write(&written, &text).unwrap();
    let reimported = import_urdf(&written, "ball_link").unwrap();
    assert_eq!(reimported.placements, calibrated.placements);
}

#[test]
fn calibrated_chain_at_zero_equals_nominal_chain_at_the_deviations() {
    let device = import_urdf(&mukca("urdf/iiwa14.urdf"), "ball_link").unwrap();
    let nominal = device.chain().unwrap();
    let values: Vec<CalibratedValue> = (nominal.params().iter().enumerate())
        .map(|(k, p)| value(&p.name, 1e-3 * ((k as f64 * 0.7).sin())))
        .collect();
    let mut x = vec![0.0; nominal.n_params()];
    for v in &values {
        x[nominal.param_index(&v.name).unwrap()] = v.value;
    }
    let calibrated = device
        .with_calibration(&values, CalibrationMeta::default())
        .unwrap()
        .chain()
        .unwrap();
    let zero = vec![0.0; calibrated.n_params()];
    for q in [[0.0; 7], [0.3, -0.5, 1.0, 1.2, -2.0, 0.7, 2.5]] {
        let want = nominal.end_pose(&x, &q);
        let got = calibrated.end_pose(&zero, &q);
        let dp = (want.translation.vector - got.translation.vector).norm();
        let dr = want.rotation.angle_to(&got.rotation);
        assert!(dp < 1e-12 && dr < 1e-12, "q {q:?}: {dp} m, {dr} rad");
    }
}

#[test]
fn write_back_inserts_a_missing_origin_and_keeps_formatting() {
    let source = data("tiny.urdf");
    let device = import_urdf(&source, "tool").unwrap();
    let values = [value("shoulder.z", 0.05), value("tool_joint.y", -0.01)];
    let calibrated = device
        .with_calibration(&values, CalibrationMeta::default())
        .unwrap();
    let text = write_calibrated_urdf(&source, &calibrated.placements).unwrap();
    assert_contains(
        &text,
        &[
            "<joint name=\"shoulder\" type=\"revolute\">\n    <origin xyz=\"0.0 0.0 0.05\" rpy=\"0.0 0.0 0.0\"/>\n    <!-- no <origin>",
            "<origin xyz=\"0.3 0 0\" rpy=\"0 0 0\"></origin>",
            "<!--origin rpy=\"0 0 0\" xyz=\"0 0 0\"/-->",
        ],
    );
    // tool_joint: xyz = (0.2, 0, 0) + Rz(0.5)·(0, −0.01, 0), rpy unchanged, spacing kept.
    let [x, y, _] = calibrated.placements[2].xyz_m;
    assert!((x - (0.2 + 0.01 * 0.5f64.sin())).abs() < 1e-15);
    assert!((y + 0.01 * 0.5f64.cos()).abs() < 1e-15);
    assert_contains(
        &text,
        &[&format!(
            "<origin rpy=\"0 0 0.5\"   xyz=\"{x:?} {y:?} 0.0\" />"
        )],
    );
    let reimported = import_urdf_from_text(&text, "tool");
    assert_eq!(reimported.placements, calibrated.placements);
}

fn import_urdf_from_text(text: &str, tip: &str) -> hapcal_io::Device {
    let dir = TempDir::new(&format!("tiny-{tip}"));
    let path = dir.0.join("tiny.urdf");
    std::fs::write(&path, text).expect("temporary file");
    import_urdf(&path, tip).expect("the written URDF imports")
}

#[test]
fn write_back_of_an_unknown_joint_is_an_error() {
    let mut device = import_urdf(&data("tiny.urdf"), "tool").unwrap();
    device.placements[0].name = "wrist".into();
    let msg = message(write_calibrated_urdf(
        &data("tiny.urdf"),
        &device.placements,
    ));
    assert_contains(&msg, &["tiny.urdf: no joint named \"wrist\" to write back"]);
}

#[test]
fn links_and_joints_that_are_not_one_tree_name_the_element_and_its_line() {
    let text = std::fs::read_to_string(mukca("urdf/iiwa14.urdf")).expect("fixture");
    let dir = std::env::temp_dir().join(format!("hapcal-io-urdf-tree-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let mm: String = {
        // Every origin length ×1000: the iiwa in millimetres.
        let mut out = String::new();
        let mut rest = text.as_str();
        while let Some(i) = rest.find("xyz=\"") {
            out.push_str(&rest[..i + 5]);
            rest = &rest[i + 5..];
            let end = rest.find('"').expect("closing quote");
            let scaled: Vec<String> = (rest[..end].split_whitespace())
                .map(|v| format!("{}", v.parse::<f64>().expect("number") * 1000.0))
                .collect();
            out.push_str(&scaled.join(" "));
            rest = &rest[end..];
        }
        out + rest
    };
    let cases = [
        (
            "no_parent.urdf",
            text.replacen("<parent link=\"link_2\"/>", "<parent link=\"nowhere\"/>", 1),
            "ball_link",
            "no_parent.urdf:89:3: joint \"joint_a3\": parent link \"nowhere\" is not defined by any <link>",
        ),
        (
            "two_parents.urdf",
            text.replacen("<child link=\"link_3\"/>", "<child link=\"link_2\"/>", 1),
            "ball_link",
            "two_parents.urdf:89:3: link \"link_2\" has two parent joints, \"joint_a2\" and \"joint_a3\"",
        ),
        (
            "two_roots.urdf",
            text.replacen(
                "<link name=\"ball_link\">",
                "<link name=\"lost\"/>\n  <link name=\"ball_link\">",
                1,
            ),
            "ball_link",
            "two_roots.urdf:138:3: 2 links have no parent joint (base_link, lost): a URDF is one tree with one root",
        ),
        (
            "mm.urdf",
            mm,
            "ball_link",
            "mm.urdf:96:3: the chain to \"ball_link\" is 1346.0 m long (joint \"joint_a4\" alone 420.0 m), more than 50 m",
        ),
    ];
    for (name, body, tip, expected) in cases {
        let path = dir.join(name);
        std::fs::write(&path, body).expect("write");
        assert_contains(&message(hapcal_io::import_urdf(&path, tip)), &[expected]);
    }
    // The fixture itself is one tree of 1.3 m.
    assert!(hapcal_io::import_urdf(&mukca("urdf/iiwa14.urdf"), "ball_link").is_ok());
    std::fs::remove_dir_all(&dir).expect("clean up");
}
