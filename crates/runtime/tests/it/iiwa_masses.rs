//! The iiwa 14's joint names, Drake's link masses written into its URDF, and a calibrated
//! copy of its URDF: shared by the accuracy study's tests, the compensation benchmark
//! (`benches/compensate.rs`) and the command line's compensation test
//! (`crates/cli/tests/it/compensate.rs`).

use hapcal_problems::GravityCompliance;

/// The iiwa 14's joints, base to wrist.
pub(crate) const JOINTS: [&str; 7] = [
    "joint_a1", "joint_a2", "joint_a3", "joint_a4", "joint_a5", "joint_a6", "joint_a7",
];

/// `urdf_text` with Drake's iiwa 14 link masses (`GravityCompliance::published`) as
/// `<inertial>`s of `link_1` … `link_7`.
pub(crate) fn with_iiwa_masses(urdf_text: &str) -> String {
    let names: Vec<String> = JOINTS.iter().map(|j| (*j).to_owned()).collect();
    let model = GravityCompliance::published(&names).expect("iiwa joint names");
    let mut text = urdf_text.to_owned();
    for m in &model.masses {
        let link = format!("<link name=\"link_{}\">", m.joint + 1);
        let c = m.com_m;
        let inertial = format!(
            "{link}\n    <inertial><origin xyz=\"{:?} {:?} {:?}\" rpy=\"0 0 0\"/><mass value=\"{:?}\"/><inertia ixx=\"0.01\" ixy=\"0\" ixz=\"0\" iyy=\"0.01\" iyz=\"0\" izz=\"0.01\"/></inertial>",
            c.x, c.y, c.z, m.mass_kg
        );
        assert!(text.contains(&link), "{link}");
        text = text.replacen(&link, &inertial, 1);
    }
    text
}

/// The iiwa 14 with calibrated joint origins written by `hapcal_io::write_calibrated_urdf`
/// (the writer of `hapcal calibrate --out robot.urdf`): each moving joint's origin off by
/// 0.2–0.8 mm and 0.3–1.2 mrad, deterministic.
pub(crate) fn calibrated_iiwa_text() -> String {
    let source = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/mukca/urdf/iiwa14.urdf");
    let device = hapcal_io::import_urdf(&source, "ball_link").expect("fixture");
    let mut placements = device.placements.clone();
    for (k, p) in placements.iter_mut().enumerate() {
        if p.axis.is_none() {
            continue;
        }
        let s = |i: usize| if (k + i).is_multiple_of(2) { 1.0 } else { -1.0 };
        let kf = k as f64;
        for i in 0..3 {
            p.xyz_m[i] += s(i) * (2e-4 + 2e-4 * ((kf + i as f64) % 4.0));
            p.rpy_rad[i] += s(i + 1) * (3e-4 + 3e-4 * ((kf + 2.0 * i as f64) % 4.0));
        }
    }
    hapcal_io::write_calibrated_urdf(&source, &placements).expect("fixture")
}
