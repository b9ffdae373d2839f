//! The iiwa 14's joint names and Drake's link masses written into its URDF: shared by the
//! accuracy study's tests, the compensation benchmark (`benches/compensate.rs`) and the
//! command line's compensation test (`crates/cli/tests/it/compensate.rs`).

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
