//! The same per-cycle evaluation as `hapcal-runtime`'s `reference_device/evaluate`, called
//! through the C ABI (`hapcal_evaluate`, by a function pointer the optimiser cannot see
//! through): pointer checks, the panic guard and the copies out.
//!
//! Robots: the C ABI's 7-joint test robot (`tests/data/iiwa14_calibrated.urdf`, link masses,
//! joint compliances of 1e-4 to 3e-4 rad/(N·m) in its sidecar), tip `ball_link`: one control
//! cycle (rigid tip pose + spatial Jacobian + deflected tip pose), pose + spatial Jacobian in
//! one call (rigid, and deflected with the Jacobian at the deflected angles) and one
//! compensation of a 6-D target, through the C ABI (function pointers) and through
//! `hapcal_runtime::Robot` directly.

use std::ffi::CString;
use std::hint::black_box;
use std::ptr;

use criterion::{Criterion, criterion_group, criterion_main};
use hapcal_runtime::{CompensationConfig, Pose, Robot, Target, compensate};
use hapcal_runtime_c::{
    HAPCAL_TARGET_POSE, HapcalCompensation, HapcalCompensationConfig, HapcalStatus, HapcalTarget,
    hapcal_evaluate, hapcal_model_free, hapcal_robot_compensate,
    hapcal_robot_deflected_spatial_jacobian, hapcal_robot_deflected_tip_poses, hapcal_robot_free,
    hapcal_robot_load, hapcal_robot_spatial_jacobian, hapcal_robot_tip_pose,
};

const THETA: [f64; 7] = [0.1, 0.5, -0.2, 1.0, 0.3, 0.6, -0.4];
const WRENCH: [f64; 6] = [1.5, -2.0, 0.5, 0.05, -0.02, 0.1];

#[path = "../tests/it/reference_model.rs"]
mod reference_model;
use reference_model::{load_reference_model, zero_pose};

fn bench(c: &mut Criterion) {
    let model = load_reference_model();
    let evaluate = black_box::<unsafe extern "C" fn(_, _, _, _, _, _, _) -> _>(hapcal_evaluate);
    let mut pose = zero_pose();
    let (mut jac, mut tau) = ([0.0; 42], [0.0; 7]);
    let mut group = c.benchmark_group("c_abi");
    group.bench_function("hapcal_evaluate", |b| {
        b.iter(|| {
            let theta = black_box(&THETA);
            // SAFETY: a live model and arrays of the stated sizes.
            unsafe {
                evaluate(
                    model,
                    theta.as_ptr(),
                    7,
                    WRENCH.as_ptr(),
                    &mut pose,
                    jac.as_mut_ptr(),
                    tau.as_mut_ptr(),
                )
            }
        })
    });
    group.finish();
    // SAFETY: a live model, freed once.
    unsafe { hapcal_model_free(model) };
}

const Q: [f64; 7] = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];

fn bench_robot(c: &mut Criterion) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/iiwa14_calibrated.urdf"
    );
    let robot = Robot::load_urdf(std::path::Path::new(path), &["ball_link"]).expect("test robot");
    let mut ws = robot.workspace();
    let c_path = CString::new(path).expect("no NUL");
    let tip = CString::new("ball_link").expect("no NUL");
    let mut handle = ptr::null_mut();
    // SAFETY: valid strings, array and out pointer.
    let status = unsafe { hapcal_robot_load(c_path.as_ptr(), &tip.as_ptr(), 1, &mut handle) };
    assert_eq!(status, HapcalStatus::Ok);
    // Function pointers the optimiser cannot see through, their signatures the functions'.
    let tip_pose = black_box::<unsafe extern "C" fn(_, _, _, _, _) -> _>(hapcal_robot_tip_pose);
    let spatial =
        black_box::<unsafe extern "C" fn(_, _, _, _, _, _) -> _>(hapcal_robot_spatial_jacobian);
    let deflected =
        black_box::<unsafe extern "C" fn(_, _, _, _, _, _) -> _>(hapcal_robot_deflected_tip_poses);
    let comp =
        black_box::<unsafe extern "C" fn(_, _, _, _, _, _, _, _) -> _>(hapcal_robot_compensate);
    let deflected_jacobian = black_box::<unsafe extern "C" fn(_, _, _, _, _, _, _) -> _>(
        hapcal_robot_deflected_spatial_jacobian,
    );
    // The target: where the rigid arm puts its tip at Q (Q is the nominal solution); the
    // compensation corrects the sag.
    let rigid = robot
        .with_compliances(&[0.0; 7])
        .expect("valid")
        .tip_pose(0, &Q, &mut ws)
        .expect("valid");
    let cfg = CompensationConfig::default();
    let c_cfg = HapcalCompensationConfig {
        tolerance_m: cfg.tolerance_m,
        tolerance_rad: cfg.tolerance_rad,
        max_iterations: cfg.max_iterations,
        damping_m: cfg.damping_m,
        orientation_scale_m: cfg.orientation_scale_m,
    };
    let c_target = HapcalTarget {
        kind: HAPCAL_TARGET_POSE,
        pose: rigid.into(),
    };

    let (mut pose, mut c_tips, mut c_jac) = (zero_pose(), [zero_pose()], [0.0; 42]);
    let (mut tips, mut jac) = ([Pose::IDENTITY], [[0.0; 6]; 7]);
    c_abi_and_rust(
        c,
        "robot_cycle",
        || {
            let q = black_box(&Q);
            // SAFETY: a live handle and arrays of the stated sizes.
            unsafe {
                let s1 = tip_pose(handle, 0, q.as_ptr(), 7, &mut pose);
                let s2 = spatial(
                    handle,
                    0,
                    q.as_ptr(),
                    7,
                    c_jac.as_mut_ptr(),
                    ptr::null_mut(),
                );
                let s3 = deflected(
                    handle,
                    q.as_ptr(),
                    7,
                    c_tips.as_mut_ptr(),
                    1,
                    ptr::null_mut(),
                );
                (s1, s2, s3, c_tips[0].translation_m[0])
            }
        },
        || {
            let q = black_box(&Q);
            let pose = robot.tip_pose(0, q, &mut ws).map(|p| p.translation_m[0]);
            let j = robot.spatial_jacobian(0, q, &mut ws, &mut jac).is_ok();
            let d = robot.deflected_tip_poses(q, &mut ws, &mut tips).is_ok();
            (pose, j, d, tips[0].translation_m[0])
        },
    );

    // Pose + Jacobian in one call: of the rigid robot, and of the deflected robot (one
    // deflection, the Jacobian at the deflected angles), what a controller calls per cycle.
    c_abi_and_rust(
        c,
        "robot_pose_jacobian",
        || {
            let q = black_box(&Q);
            // SAFETY: a live handle and arrays of the stated sizes.
            let s = unsafe { spatial(handle, 0, q.as_ptr(), 7, c_jac.as_mut_ptr(), &mut pose) };
            (s, pose.translation_m[0], c_jac[0])
        },
        || {
            let q = black_box(&Q);
            let pose = robot.spatial_jacobian(0, q, &mut ws, &mut jac);
            (pose.map(|p| p.translation_m[0]), jac[0][0])
        },
    );
    c_abi_and_rust(
        c,
        "robot_deflected_pose_jacobian",
        || {
            let q = black_box(&Q);
            let (jac, pose) = (c_jac.as_mut_ptr(), &mut pose);
            // SAFETY: a live handle and arrays of the stated sizes.
            let s =
                unsafe { deflected_jacobian(handle, 0, q.as_ptr(), 7, jac, pose, ptr::null_mut()) };
            (s, pose.translation_m[0], c_jac[0])
        },
        || {
            let q = black_box(&Q);
            let out = robot.deflected_spatial_jacobian(0, q, &mut ws, &mut jac);
            (out.map(|(p, _)| p.translation_m[0]), jac[0][0])
        },
    );

    let (mut c_q, mut result, mut q) = ([0.0; 7], HapcalCompensation::default(), [0.0; 7]);
    let target = Target::Pose(rigid);
    c_abi_and_rust(
        c,
        "robot_compensate_pose",
        || {
            let (target, out) = (black_box(&c_target), c_q.as_mut_ptr());
            // SAFETY: a live handle and arrays of the stated sizes.
            let s = unsafe { comp(handle, 0, target, Q.as_ptr(), 7, &c_cfg, out, &mut result) };
            assert!(s == HapcalStatus::Ok && result.reached);
            c_q[0]
        },
        || {
            let c = compensate(&robot, 0, black_box(&target), &Q, &cfg, &mut ws, &mut q);
            assert!(c.is_ok_and(|c| c.reached));
            q[0]
        },
    );
    // SAFETY: a live handle, freed once.
    unsafe { hapcal_robot_free(handle) };
}

/// Benchmark group `name`: the same work through the C ABI (`c_abi`) and through
/// `hapcal_runtime` directly (`rust`), each routine called once per iteration.
fn c_abi_and_rust<A, B>(
    c: &mut Criterion,
    name: &str,
    mut c_abi: impl FnMut() -> A,
    mut rust: impl FnMut() -> B,
) {
    let mut group = c.benchmark_group(name);
    group.bench_function("c_abi", |b| b.iter(&mut c_abi));
    group.bench_function("rust", |b| b.iter(&mut rust));
    group.finish();
}

criterion_group!(benches, bench, bench_robot);
criterion_main!(benches);
