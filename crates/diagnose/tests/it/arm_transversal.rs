//! Transversal compliance in the serial-arm diagnosis, on the simulated two-arm humanoid of
//! `hapcal-calibrate` (`tests/sim/humanoid.rs`): its columns are the first derivatives of the
//! calibration's own transversal model, the diagnosis names it beside the joint compliance
//! when the data hold both, alone when the links bend sideways without any compliance about
//! the joint axes, and names nothing on the same robot without compliance.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "../../../calibrate/tests/sim/humanoid.rs"]
mod sim;

use hapcal_calibrate::model::ModelName;
use std::path::PathBuf;

use faer::Col;
use hapcal_calibrate::baseline::baseline_from_tables;
use hapcal_calibrate::calibrate::Plan;
use hapcal_calibrate::measured::Robot;
use hapcal_calibrate::model::terms;
use hapcal_contract::Effect;
use hapcal_diagnose::Verdict;
use hapcal_diagnose::arm::{ArmConfig, ArmDiagnosis, diagnose_arm, transversal_columns};
use hapcal_identify::Problem;
use hapcal_io::MeasurementTable;
use hapcal_kinematics::{FrameSpec, Isometry3, Vector3};
use hapcal_problems::{
    CalibrationProblem, GravityCompliance, ModelTerms, Observations, Row, RowKind, Weights,
};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// The generator's seeds of `fixtures/sim-humanoid` (truth 11, rows 12).
const TRUTH_SEED: u64 = 11;
const ROWS_SEED: u64 = 12;

/// Rows of the diagnosed recordings: the fixture has 550; at 300, 400 and 550 the two
/// verdicts are the same, and 300 keeps the compliant case near 10 s in a debug build.
const ROWS: usize = 300;

/// Marker rows of `table` as calibration observations (marker `k` on tip `k`).
fn observations(table: &MeasurementTable) -> Observations {
    let rows = (table.rows.iter())
        .flat_map(|row| {
            row.markers.iter().map(|m| Row {
                q: row.q.clone(),
                kind: RowKind::Marker {
                    tip: m.marker,
                    position_m: m.position_m,
                },
            })
        })
        .collect();
    Observations {
        rows,
        ..Observations::default()
    }
}

#[test]
fn transversal_columns_are_the_first_derivatives_of_the_calibrations_model() {
    let robot = sim::humanoid(&["l_hand", "r_hand"]);
    let truth = sim::truth(&robot, TRUTH_SEED);
    let obs = observations(&sim::table(&robot, &truth, &[0, 1], 24, ROWS_SEED));
    // The tree the calibration builds on marker files: joint offsets, an instrument frame and
    // a marker frame per hand (any nominal frames will do).
    let framed = (robot.tree.with_joint_offsets())
        .with_frames(
            &FrameSpec {
                name: "instrument".into(),
                nominal: Isometry3::new(Vector3::new(2.0, 0.3, -0.8), Vector3::new(0.1, 0.0, 2.5)),
            },
            &[
                (
                    0,
                    FrameSpec {
                        name: "marker1".into(),
                        nominal: Isometry3::translation(0.04, 0.0, -0.08),
                    },
                ),
                (
                    1,
                    FrameSpec {
                        name: "marker2".into(),
                        nominal: Isometry3::translation(0.03, 0.01, -0.07),
                    },
                ),
            ],
        )
        .unwrap();
    let weights = Weights {
        sigma_position_m: sim::NOISE_M,
        ..Weights::default()
    };
    let geometric =
        CalibrationProblem::on_tree(framed.clone(), obs.clone(), weights, ModelTerms::default())
            .unwrap();
    // A geometric estimate away from the nominal robot: 1 mm and 1 mrad deviations.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let spread = Normal::new(0.0, 1e-3).unwrap();
    let n_kin = framed.n_params();
    let x_kin = Col::from_fn(n_kin, |_| spread.sample(&mut rng));
    let names = &robot.joint_names;
    for masses in [robot.masses.clone(), Vec::new()] {
        let loads = if masses.is_empty() {
            GravityCompliance::default()
        } else {
            GravityCompliance::from_link_masses(masses.clone(), -Vector3::z())
        };
        for (model, effect) in [
            (
                ModelName::TransversalCompliance,
                Effect::TransversalCompliance,
            ),
            (ModelName::TransversalAxes, Effect::TransversalAxes),
        ] {
            let columns = transversal_columns(&geometric, &x_kin, &robot.tree, &loads, effect)
                .expect("columns");
            // The calibration's own problem for `--model transversal-compliance` (or
            // `transversal-axes`) on marker files: the model's terms with the gravity loads on
            // every tip of the robot's tree.
            let library = CalibrationProblem::on_tree(
                framed.clone(),
                obs.clone(),
                weights,
                ModelTerms {
                    torque_tips: Some(robot.tree.tips().to_vec()),
                    ..terms(model, names, &masses).unwrap()
                },
            )
            .unwrap();
            let layout = library.layout();
            let first = n_kin + library.n_compliance();
            assert_eq!(library.n_transversal(), columns.len(), "{effect}");
            // 17 revolute joints: one term each, or two per axis.
            let per_joint = if effect == Effect::TransversalAxes {
                2
            } else {
                1
            };
            assert_eq!(columns.len(), 17 * per_joint);
            let residuals = |t: usize, h: f64| {
                let mut x = Col::<f64>::zeros(layout.len());
                for i in 0..n_kin {
                    x[i] = x_kin[i];
                }
                x[first + t] = h;
                let mut r = Col::<f64>::zeros(library.n_residuals());
                library.residuals(x.as_ref(), r.as_mut()).unwrap();
                r
            };
            let norm = |c: &[f64]| c.iter().map(|v| v * v).sum::<f64>().sqrt();
            let largest = columns.iter().map(|(_, c)| norm(c)).fold(0.0, f64::max);
            assert!(largest > 0.0, "{effect}: every column zero");
            for (t, (name, column)) in columns.iter().enumerate() {
                // One parameter, one name: `transversal.l_4.u` is `transversal_axes.l_4.u`.
                let joint = layout.name(first + t).strip_prefix("transversal.").unwrap();
                assert_eq!(name, &format!("{effect}.{joint}"));
                // Central differences at a step that tilts a joint by at most ~1e-5 rad
                // (moments up to ~100 N·m): truncation ~(1e-5)² relative, rounding ~1e-16/1e-7
                // of the residuals' size; both far below the tolerance. A column may be zero
                // (the wrist's axis along the hand's lever bends under no moment): its
                // differences must then be zero beside the largest column.
                let h = 1e-7;
                let (plus, minus) = (residuals(t, h), residuals(t, -h));
                let err = (column.iter().enumerate())
                    .map(|(i, c)| (c - (plus[i] - minus[i]) / (2.0 * h)).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let n = norm(column);
                assert!(
                    err <= 1e-6 * n + 1e-9 * largest,
                    "{name} ({} loads): column {n:.3e}, off by {err:.3e}",
                    if masses.is_empty() { "unit" } else { "mass" }
                );
            }
        }
    }
}

/// The diagnosis of the humanoid simulated from `truth` (the recording of
/// `fixtures/sim-humanoid`, shortened to [`ROWS`] rows: the last 30 % held out, no stated σ).
fn diagnose_humanoid(robot: &Robot, truth: &sim::Truth) -> ArmDiagnosis {
    let table = sim::table(robot, truth, &[0, 1], ROWS, ROWS_SEED);
    let plan = Plan {
        workspace: None,
        device: PathBuf::from("humanoid.urdf"),
        tip: "l_hand".into(),
        tips: vec!["r_hand".into()],
        test_last: Some(0.3),
        ..Plan::bundled_default()
    };
    let baseline = baseline_from_tables(robot, vec![table], Vec::new(), &plan, false).unwrap();
    diagnose_arm(&baseline, &ArmConfig::default()).unwrap()
}

/// `truth` with every parameter whose name starts with one of `prefixes` set to zero.
fn zero_params(truth: &mut sim::Truth, prefixes: &[&str]) {
    let layout = truth.problem.layout();
    for i in 0..layout.len() {
        if prefixes.iter().any(|p| layout.name(i).starts_with(p)) {
            truth.x[i] = 0.0;
        }
    }
}

/// What a report reads: the verdict, each step's held-out RMS and the candidates' reasons.
fn summary(d: &ArmDiagnosis) -> String {
    let steps: Vec<String> = (d.steps.iter())
        .map(|s| {
            format!(
                "{}: {:.3} -> {:.3} mm, alike {:?}",
                s.effect,
                s.heldout_rms_before_m * 1e3,
                s.heldout_rms_after_m * 1e3,
                s.alike
            )
        })
        .collect();
    let candidates: Vec<String> = (d.candidates.iter())
        .map(|c| format!("round {} {}: {}", c.round, c.effect, c.reason))
        .collect();
    format!(
        "verdict {}; steps {steps:#?}; test RMS {:?} -> {:?} m; candidates {candidates:#?}; notes {:#?}",
        d.verdict, d.test_rms_m, d.test_rms_final_m, d.notes
    )
}

#[test]
fn humanoid_with_joint_and_transversal_compliance_names_both() {
    let robot = sim::humanoid(&["l_hand", "r_hand"]);
    let truth = sim::truth(&robot, TRUTH_SEED);
    let d = diagnose_humanoid(&robot, &truth);
    // The joint compliance first (it carries most of the signal), then the tilts beside it.
    let Verdict::Effects(named) = &d.verdict else {
        panic!("{}", summary(&d));
    };
    assert_eq!(named.len(), 2, "{}", summary(&d));
    assert_eq!(named[0], Effect::GravityCompliance, "{}", summary(&d));
    assert!(named[1].is_transversal(), "{}", summary(&d));
    // Together they bring the held-out error to the noise (`√6·σ` per configuration: two
    // markers, three axes) within 10 %: the RMS's sampling error over a few hundred
    // configurations (≈ 3 %) and the estimation error of ~180 parameters from ~1,300
    // residuals (≈ 6 % of the RMS).
    let clean = 6f64.sqrt() * sim::NOISE_M;
    for rms in d.test_rms_final_m.iter().chain([&d.heldout_rms_final_m]) {
        assert!(*rms < 1.1 * clean, "{rms} m: {}", summary(&d));
    }
}

#[test]
fn humanoid_with_transversal_compliance_alone_names_it_alone() {
    let robot = sim::humanoid(&["l_hand", "r_hand"]);
    let mut truth = sim::truth(&robot, TRUTH_SEED);
    // The same deviations, frames, rows and transversal compliances, stiff about the joint
    // axes.
    zero_params(&mut truth, &["compliance."]);
    let d = diagnose_humanoid(&robot, &truth);
    // The tilts are a candidate of the first round, on the link masses' gravity loads, and
    // named there: no joint compliance is named on the way.
    assert_eq!(
        d.verdict,
        Verdict::of(&[Effect::TransversalCompliance]),
        "{}",
        summary(&d)
    );
    let steps: Vec<Effect> = d.steps.iter().map(|s| s.effect).collect();
    assert_eq!(steps, [Effect::TransversalCompliance], "{}", summary(&d));
    // It brings the held-out error to the noise within 10 %, as the pair above does.
    let clean = 6f64.sqrt() * sim::NOISE_M;
    assert!(d.heldout_rms_final_m < 1.1 * clean, "{}", summary(&d));
}

#[test]
fn humanoid_without_compliance_names_none() {
    let robot = sim::humanoid(&["l_hand", "r_hand"]);
    let mut truth = sim::truth(&robot, TRUTH_SEED);
    // The same geometric deviations, frames and rows, without the joint and transversal
    // compliances.
    zero_params(&mut truth, &["compliance.", "transversal."]);
    let d = diagnose_humanoid(&robot, &truth);
    assert_eq!(d.verdict, "none", "{}", summary(&d));
}
