//! Evaluation calls allocate nothing: a counting global allocator for this test binary
//! counts the allocations of the current thread around the calls.

use hapcal_runtime::{Evaluation, Model};

use crate::counting::allocations;
use crate::fixture;

#[test]
fn evaluation_calls_do_not_allocate() {
    let model = Model::load(&fixture("reference-device/calibrated.toml")).expect("fixture");
    let theta = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4];
    let wrench = [1.5, -2.0, 0.5, 0.05, -0.02, 0.1];
    let (mut q, mut dq, mut tau) = ([0.0; 7], [0.0; 7], [0.0; 7]);
    let mut jac = [[0.0; 6]; 7];
    let mut out = Evaluation::default();
    let before = allocations();
    for _ in 0..100 {
        model.joint_angles(&theta, &mut q, &mut dq).expect("valid");
        model.end_pose(&theta).expect("valid");
        model.end_pose_at_joints(&q).expect("valid");
        model.body_jacobian(&theta, &mut jac).expect("valid");
        model.spatial_jacobian(&theta, &mut jac).expect("valid");
        model
            .motor_torques(&theta, &wrench, &mut tau)
            .expect("valid");
        model.evaluate(&theta, &wrench, &mut out).expect("valid");
        // The error path allocates nothing either.
        assert!(model.end_pose(&theta[..6]).is_err());
    }
    assert_eq!(allocations() - before, 0);
    // Negative control: the counter sees an allocation.
    let v = std::hint::black_box(vec![1.0; 3]);
    assert_eq!(allocations() - before, 1, "{v:?}");
}

#[test]
fn robot_evaluation_and_compensation_do_not_allocate() {
    use hapcal_runtime::{CompensationConfig, Pose, Robot, Target, compensate};

    let text =
        std::fs::read_to_string(crate::robot::test_data("torso_two_arms.urdf")).expect("fixture");
    let values = [crate::robot::compliance(
        "l_joint2+r_joint2",
        8e-4,
        "rad/(N·m)",
    )];
    let path = crate::robot::write_calibrated(
        &crate::robot::scratch("no-alloc"),
        &text,
        &values,
        &["l_gripper", "r_tool"],
    );
    let robot = Robot::load_urdf(&path, &["l_gripper", "r_tool"]).expect("valid");
    let mut ws = robot.workspace();
    let q = [0.1, 0.3, -0.4, 0.6, 0.2, 0.5, -0.7, 0.3];
    let (mut theta, mut tau) = ([0.0; 8], [0.0; 8]);
    let mut jac = [[0.0; 6]; 8];
    let mut poses = [Pose::IDENTITY; 2];
    let cfg = CompensationConfig {
        tolerance_m: 1e-6,
        tolerance_rad: 1e-6,
        max_iterations: 20,
        damping_m: 1e-3,
        orientation_scale_m: 0.1,
    };
    let target = robot.tip_pose(1, &[0.12, 0.25, -0.3, 0.5, 0.3, 0.45, -0.6, 0.35], &mut ws);
    let target = Target::Pose(target.expect("valid"));
    let mut command = [0.0; 8];
    let before = allocations();
    for _ in 0..10 {
        robot.tip_poses(&q, &mut ws, &mut poses).expect("valid");
        robot.tip_pose(0, &q, &mut ws).expect("valid");
        robot
            .spatial_jacobian(1, &q, &mut ws, &mut jac)
            .expect("valid");
        robot
            .body_jacobian(0, &q, &mut ws, &mut jac)
            .expect("valid");
        robot.gravity_torques(&q, &mut ws, &mut tau).expect("valid");
        robot.deflect(&q, &mut ws, &mut theta).expect("valid");
        robot
            .deflected_tip_poses(&q, &mut ws, &mut poses)
            .expect("valid");
        let c = compensate(&robot, 1, &target, &q, &cfg, &mut ws, &mut command).expect("valid");
        assert!(c.reached, "{c:?}");
        assert!(robot.tip_pose(2, &q, &mut ws).is_err());
    }
    assert_eq!(allocations() - before, 0);
}
