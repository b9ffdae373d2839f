//! Poses planned after a calibration (`hapcal plan-poses --data … --workspace …`) on simulated
//! tracker data of the KUKA LBR iiwa 14 (MUKCa's URDF): trained on one half of the elbow's
//! range, used on the other, with a gear-ratio error of the elbow that the geometric model
//! does not have. The planned poses go where the calibration will be used, and measuring
//! them brings the error there down more than as many poses from the covered half.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use hapcal_calibrate::measured::{MeasuredConfig, Robot, calibrate_measured};
use hapcal_calibrate::model::ModelName;
use hapcal_calibrate::plan::{AfterConfig, after_summary, plan_after};
use hapcal_identify::Criterion;
use hapcal_io::MeasurementTable;
use hapcal_kinematics::Tree;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::Normal;

/// Tracker noise per axis, m.
const NOISE_M: f64 = 5e-5;
/// The joint with the gear-ratio error and the split range (the elbow, a4).
const JOINT: usize = 3;
/// Gear-ratio error of that joint: the true angle is `(1 + RATIO_ERROR)·q`.
const RATIO_ERROR: f64 = 2e-3;

#[path = "sim/tracker.rs"]
mod tracker;

use tracker::iiwa as robot;

/// The simulated robot: the URDF with joint offsets of ±0.5 mrad, behind a tracker frame,
/// with a marker 5 cm off the ball, and its parameter vector.
fn truth(robot: &Robot) -> (Tree, Vec<f64>) {
    tracker::offsets_truth(robot, 5e-4)
}

/// Which half of the elbow's range a configuration takes.
#[derive(Clone, Copy)]
enum Half {
    /// `[0, 0.9·upper]`: the training rows.
    Upper,
    /// `[0.9·lower, 0]`: where the calibration is used.
    Lower,
}

/// `n` configurations within 90 % of the limits, the elbow on `half`.
fn configurations(robot: &Robot, n: usize, half: Half, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
    (0..n)
        .map(|_| {
            (robot.limits.iter().enumerate())
                .map(|(j, &(lo, hi))| match (j == JOINT, half) {
                    (true, Half::Upper) => rng.random_range(0.0..0.9 * hi),
                    (true, Half::Lower) => rng.random_range(0.9 * lo..0.0),
                    _ => rng.random_range(0.9 * lo..0.9 * hi),
                })
                .collect()
        })
        .collect()
}

/// The tracker's reading of the marker at each configuration: the truth with the elbow's
/// gear-ratio error, plus noise.
fn measure(robot: &Robot, qs: &[Vec<f64>], rng: &mut ChaCha8Rng) -> MeasurementTable {
    let (framed, x) = truth(robot);
    let noise = Normal::new(0.0, NOISE_M).unwrap();
    let rows = (qs.iter().enumerate())
        .map(|(i, q)| {
            let mut q_true = q.clone();
            q_true[JOINT] *= 1.0 + RATIO_ERROR;
            let p = framed.tips()[0].end_point(&x, &q_true);
            let marker = tracker::sample(0, &p, &noise, rng);
            tracker::row(i as u64 + 2, q.clone(), vec![marker])
        })
        .collect();
    MeasurementTable::positions("tracker", "tracker.csv", 1, rows)
}

/// The geometric calibration of `train`, and its 3-D RMS error on `test`, m.
fn heldout_rms(robot: &Robot, train: &[MeasurementTable], test: &MeasurementTable) -> f64 {
    let cfg = MeasuredConfig {
        rung: Some(ModelName::Geometric),
        marker_tips: vec![0],
        ..MeasuredConfig::default()
    };
    let out = calibrate_measured(robot, train, std::slice::from_ref(test), &cfg).unwrap();
    out.sets.last().unwrap().4.position_rms_m
}

#[test]
fn poses_planned_for_the_uncovered_half_bring_its_error_down() {
    let robot = robot();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let train = measure(
        &robot,
        &configurations(&robot, 40, Half::Upper, &mut rng),
        &mut rng,
    );
    let workspace = configurations(&robot, 100, Half::Lower, &mut rng);
    let test = measure(
        &robot,
        &configurations(&robot, 60, Half::Lower, &mut rng),
        &mut rng,
    );
    let count = 10;
    let cfg = AfterConfig {
        count,
        n_candidates: 300,
        seed: 3,
        criterion: Criterion::IOptimal,
        model: ModelName::Geometric.into(),
        sigma_m: None,
        sigma_rad: None,
        refine: false,
    };
    let plan = plan_after(&robot, std::slice::from_ref(&train), &workspace, &cfg).unwrap();
    let summary = after_summary(&plan);
    // Mostly in the uncovered half: the candidates are spread over the whole joint box, half
    // of them on each side, so a planner blind to the workspace would put about 5 there.
    let uncovered = plan.readings.iter().filter(|q| q[JOINT] < 0.0).count();
    assert!(uncovered >= 8, "{uncovered} of {count} poses\n{summary}");
    // Its own prediction: the planned poses beat as many random ones of the joint box.
    assert!(
        plan.rms_after_m < plan.rms_before_m && plan.rms_after_m < plan.rms_random_m,
        "{summary}"
    );
    // Measured with the same truth and noise, then calibrated again: the planned poses bring
    // the error where the calibration is used down; as many poses from the covered half do
    // not. On seeds 1 to 5 and 11 the planned poses took it from 1.7–2.1 mm to 0.75–0.84 mm
    // and the covered ones left it within 5 % of where it was: the margins below are 1.5
    // times wider than the worst of those.
    let planned = measure(&robot, &plan.readings, &mut rng);
    let covered = measure(
        &robot,
        &configurations(&robot, count, Half::Upper, &mut rng),
        &mut rng,
    );
    let before = heldout_rms(&robot, std::slice::from_ref(&train), &test);
    let with_planned = heldout_rms(&robot, &[train.clone(), planned], &test);
    let with_covered = heldout_rms(&robot, &[train, covered], &test);
    eprintln!(
        "{summary}{uncovered} of {count} in the uncovered half; held-out RMS {:.3} mm, {:.3} mm \
         with the planned poses, {:.3} mm with as many of the covered half",
        before * 1e3,
        with_planned * 1e3,
        with_covered * 1e3
    );
    // The elbow's ratio error over the half it was not trained on is far above the noise.
    assert!(before > 10.0 * NOISE_M, "before: {before} m");
    assert!(
        with_planned < 0.7 * before && with_planned < 0.7 * with_covered,
        "held-out RMS {before} m; with the planned poses {with_planned} m, with poses of the \
         covered half {with_covered} m\n{summary}"
    );
}
