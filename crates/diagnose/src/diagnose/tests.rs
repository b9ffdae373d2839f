use std::path::Path;

use hapcal_calibrate::haptic::{
    HapticDevice, identify_jointly, identify_kinematics, identify_transmissions,
};
use hapcal_sim::{MotionConfig, NoiseModel, SimConfig, simulate_motion};

use super::baseline::fit_transmissions;
use super::cv::Base;
use crate::model::{Setup, Trans, log_data};
use crate::solve::{lstsq, refine};
use crate::stats::chi2_sf;

/// The `transmissions` baseline and `hapcal calibrate`'s joint identification
/// (`hapcal_calibrate::haptic::identify_jointly`) fit the same model to the same clean log:
/// every kinematic deviation both identify, outside the gauge-coupled ones of row 0 and joint
/// 1, agrees within half a standard error.
#[test]
fn the_transmissions_baseline_is_the_calibrations_joint_fit() {
    let truth_file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/reference-device/truth.toml");
    let truth = hapcal_sim::read_truth(&truth_file).expect("fixture truth");
    let device = truth.read_device(&truth_file).expect("fixture device");
    let cable = device.cable_encoder.expect("cable encoder");
    let cfg = SimConfig::new(5, 400).with_noise(NoiseModel::paper(&cable));
    let rows =
        simulate_motion(&device, &truth, &cfg, &MotionConfig::default(), &[]).expect("simulates");

    // The diagnosis's baseline, as `diagnose` fits it.
    let chain = device.chain().expect("chain");
    let data = log_data(&rows).expect("log");
    let mut setup = Setup::new(&device, chain, data.clone()).expect("model");
    let trans_joints: Vec<usize> = device.capstans.iter().map(|c| c.joint - 1).collect();
    setup.set_ext_joints(trans_joints).expect("ext rows");
    let trans = fit_transmissions(&device, &data, setup.sigma_e_rad()).expect("step 1");
    let (state, lin) = refine(&setup, setup.initial_state(trans), 8).expect("fit");
    let base = Base::new(lin, state.n_params(), 5, data.n_rows());
    let quantised = 1.0 - chi2_sf(base.rss, base.dof()) >= 1e-3;
    let (state, lin) = if quantised {
        (state, base.lin)
    } else {
        setup.set_quantisation(false);
        refine(&setup, state, 2).expect("refit")
    };
    let cols = {
        let b = Base::new(lin, state.n_params(), 5, data.n_rows());
        let a = b.lin.j.select_columns(&b.cols);
        let (_, cov) = lstsq(&a, &b.lin.r);
        let s2 = (b.rss / b.dof()).max(1.0);
        (b.cols.iter().enumerate())
            .map(|(k, &c)| (b.lin.names[c].clone(), (cov[(k, k)] * s2).sqrt()))
            .collect::<Vec<_>>()
    };
    let n_trans: usize = state.transmissions.iter().map(Trans::n_params).sum();

    // The calibration's joint identification.
    let haptic = HapticDevice::new(device.clone()).expect("haptic device");
    let t = identify_transmissions(&haptic, &rows).expect("transmissions");
    let (_, kin) = identify_kinematics(&haptic, &rows, Some(&t)).expect("kinematics");
    let (problem, joint) = identify_jointly(&haptic, &rows, &t, &kin).expect("joint fit");
    let nt = problem.n_trans();
    assert_eq!(nt, n_trans);

    // Row 0 (rig → base) and joint 1's offsets are gauge-coupled for distances (dd0 with dd1,
    // dtheta1 with dalpha0 and dtheta0 through the rig → base row), and the two fits keep
    // different members: the baseline's pivoted columns keep dd0 and dalpha0 and hold dtheta1
    // where it starts, the calibration's rank analysis (priors, later member kept on ties)
    // keeps dd1 and dtheta1. The other deviations are compared.
    let gauge_coupled = ["dalpha0", "dd0", "dtheta0", "dd1", "dtheta1"];
    let mut compared = 0;
    for (k, name) in haptic.chain.params().iter().map(|p| &p.name).enumerate() {
        if gauge_coupled.contains(&name.as_str()) {
            continue;
        }
        let Some(std_c) = joint.covariance.std_of(name) else {
            continue;
        };
        let Some((_, std_d)) = cols.iter().find(|(n, _)| n == name) else {
            continue;
        };
        // The same model on the same rows, weighted differently (the baseline: each row's σ
        // from the specification, with the reading quantisation; the calibration: σ_e and σ_m
        // rescaled to each group's residual RMS): the estimates differ by a small part of
        // their standard error, the standard errors hardly.
        let (x_d, x_c) = (state.x_kin[k], joint.fit.x[nt + k]);
        let std = std_c.max(*std_d);
        assert!(
            (x_d - x_c).abs() <= 0.5 * std,
            "{name}: baseline {x_d:.4e} ± {std_d:.1e}, calibration {x_c:.4e} ± {std_c:.1e}"
        );
        assert!(
            (0.8..1.25).contains(&(std_d / std_c)),
            "{name}: standard errors {std_d:.2e} (baseline) and {std_c:.2e} (calibration)"
        );
        compared += 1;
    }
    assert!(
        compared >= 24,
        "only {compared} deviations identified by both"
    );
}
