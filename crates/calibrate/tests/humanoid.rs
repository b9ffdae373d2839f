//! The marker workflow on a simulated two-arm humanoid upper body (`sim/humanoid.rs`): the
//! ladder names the compliance rungs the simulation holds, the held-out error reaches the
//! noise floor, and the compliances are recovered within their covariance.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "sim/humanoid.rs"]
mod sim;
#[path = "sim/tracker.rs"]
mod tracker;

use hapcal_calibrate::measured::{MeasuredConfig, MeasuredOutcome, calibrate_measured};
use hapcal_calibrate::model::ModelName;
use sim::{NOISE_M, compliance_of, humanoid, table, transversal_of, truth, truth_with};

fn config(rung: Option<ModelName>, marker_tips: Vec<usize>) -> MeasuredConfig {
    MeasuredConfig {
        rung,
        marker_tips,
        ..MeasuredConfig::default()
    }
}

/// The compliance parameters (axial and transversal) the fit kept, each as (name, estimate,
/// σ, truth).
fn compliances(out: &MeasuredOutcome) -> Vec<(String, f64, f64, f64)> {
    let id = &out.fitted.identified;
    (id.identifiability.kept.iter())
        .map(|&i| id.layout.name(i).to_owned())
        .filter_map(|name| {
            let truth = if let Some(j) = name.strip_prefix("compliance.") {
                compliance_of(j)
            } else {
                transversal_of(name.strip_prefix("transversal.")?)
            };
            Some((name.clone(), id.value(&name)?, id.std(&name)?, truth))
        })
        .collect()
}

#[test]
fn both_hands_recover_every_compliance_and_reach_the_noise_floor() {
    let robot = humanoid(&["l_hand", "r_hand"]);
    assert_eq!(robot.joint_names.len(), 17);
    let seed = 11;
    let truth = truth(&robot, seed);
    let train = table(&robot, &truth, &[0, 1], 400, seed + 1);
    let test = table(&robot, &truth, &[0, 1], 150, seed + 2);
    let out = calibrate_measured(&robot, &[train], &[test], &config(None, vec![0, 1])).unwrap();
    assert_eq!(
        out.rung,
        ModelName::TransversalCompliance,
        "ladder {:?}",
        out.ladder
    );
    // Held out, the error of a marker is the noise: √3·σ in 3-D, plus the estimation error
    // of ~150 parameters from 2,400 residuals (√(150/2400) ≈ 25 % of σ per axis).
    let floor = 3f64.sqrt() * NOISE_M;
    tracker::assert_test_rms(&out, floor, 1.15, (10.0, f64::INFINITY));
    let found = compliances(&out);
    // A compliance the fit put below zero within the noise is held at zero (compliance ≥ 0):
    // its free estimate fell below zero, which a truth beyond 3 σ of zero does once in 700.
    let held: Vec<(String, f64, f64)> = (out.fitted.identified.identifiability.pruned.iter())
        .filter(|p| p.reason == hapcal_identify::PruneReason::AtBound)
        .map(|p| {
            let truth = match p.name.strip_prefix("compliance.") {
                Some(j) => compliance_of(j),
                None => transversal_of(p.name.strip_prefix("transversal.").unwrap()),
            };
            (p.name.clone(), p.std_if_kept, truth)
        })
        .collect();
    for (name, std, truth) in &held {
        assert!(
            *truth < 3.0 * std,
            "{name} held at zero: σ {std:e}, truth {truth:e}"
        );
    }
    // Every joint but the vertical torso yaw carries a gravity torque: 16 axial and 17
    // transversal compliances, estimated or held at zero.
    assert!(
        found.len() + held.len() >= 30,
        "kept {found:?}, held {held:?}"
    );
    // The estimates' error against their covariance: with a right covariance the squared
    // Mahalanobis distance d² = eᵀ·C⁻¹·e is χ² with k degrees of freedom, k the kept
    // compliances (mean k, sd √(2k)). The compliances of the torso's two pitch joints and their
    // transversal ones are strongly correlated, so a test per parameter ("each within 2σ",
    // which also fails by chance four times in five over 33 parameters, 0.95³³ ≈ 0.18)
    // would not measure whether the covariance is right.
    let cov = &out.fitted.identified.covariance;
    let index: Vec<usize> = (found.iter())
        .map(|(name, ..)| cov.names.iter().position(|n| n == name).unwrap())
        .collect();
    let k = index.len();
    let c = nalgebra::DMatrix::from_fn(k, k, |a, b| cov.matrix[(index[a], index[b])]);
    let e = nalgebra::DVector::from_fn(k, |a, _| found[a].1 - found[a].3);
    let d2 = e.dot(&c.cholesky().expect("positive definite").solve(&e));
    // The 0.1 % quantile of χ² with k degrees of freedom (Wilson–Hilferty, z = 3.090: 63.9
    // for k = 33).
    let kf = k as f64;
    let h = 2.0 / (9.0 * kf);
    let quantile = kf * (1.0 - h + 3.090 * h.sqrt()).powi(3);
    assert!(
        d2 < quantile,
        "squared Mahalanobis distance {d2:.1} over {k} compliances"
    );
    for (name, value, sigma, truth) in &found {
        assert!(
            (value - truth).abs() < 4.0 * sigma,
            "{name}: {value:e} ± {sigma:e}, truth {truth:e}"
        );
    }
}

#[test]
fn one_hand_still_recovers_the_torso_compliance() {
    // Both arms in the tree (their joints are read, their masses load the torso), the
    // markers on the left hand only.
    let robot = humanoid(&["l_hand", "r_hand"]);
    let truth = truth(&robot, 21);
    let train = table(&robot, &truth, &[0], 400, 22);
    let out = calibrate_measured(
        &robot,
        &[train],
        &[],
        &config(Some(ModelName::TransversalCompliance), vec![0]),
    )
    .unwrap();
    let found = compliances(&out);
    for joint in ["torso_2", "torso_3"] {
        let name = format!("compliance.{joint}");
        let (_, value, sigma, truth) = (found.iter())
            .find(|c| c.0 == name)
            .unwrap_or_else(|| panic!("{name} not kept: {found:?}"));
        // Two estimates: 3σ each is a false alarm of 0.5 %; and the torso's compliance is
        // determined, not merely consistent (σ under a quarter of its value).
        assert!(
            (value - truth).abs() < 3.0 * sigma && *sigma < 0.25 * truth,
            "{name}: {value:e} ± {sigma:e}, truth {truth:e}"
        );
    }
}

#[test]
fn the_simulated_humanoid_passes_the_setup_check_silently() {
    let robot = humanoid(&["l_hand", "r_hand"]);
    let urdf = std::env::temp_dir()
        .join(format!("hapcal-humanoid-{}", std::process::id()))
        .join("humanoid-l_hand-r_hand.urdf");
    let tips = ["l_hand".to_owned(), "r_hand".to_owned()];
    for seed in [11, 21] {
        let truth = truth(&robot, seed);
        let train = table(&robot, &truth, &[0, 1], 200, seed + 1);
        tracker::assert_no_setup_finding(&robot, &train, &urdf, &tips);
    }
}

/// A humanoid whose links bend four times more easily about one axis than about the other:
/// the ladder climbs to the per-axis model (`transversal-axes`), which reaches the noise floor
/// held out, where the isotropic one (one compliance per joint for both axes) cannot.
#[test]
fn per_axis_transversal_compliance_fits_links_that_bend_one_way() {
    let robot = humanoid(&["l_hand", "r_hand"]);
    let truth = truth_with(&robot, 31, hapcal_problems::Transversal::PerAxis);
    let train = table(&robot, &truth, &[0, 1], 400, 32);
    let test = table(&robot, &truth, &[0, 1], 150, 33);
    let out = calibrate_measured(
        &robot,
        std::slice::from_ref(&train),
        std::slice::from_ref(&test),
        &config(None, vec![0, 1]),
    )
    .unwrap();
    assert_eq!(
        out.rung,
        ModelName::TransversalAxes,
        "ladder {:?}",
        out.ladder
    );
    let floor = 3f64.sqrt() * NOISE_M;
    let axes = out.sets[1].4.position_rms_m;
    // As in the test above: the noise plus the estimation error of ~170 parameters.
    assert!(
        axes < 1.15 * floor,
        "per axis: test RMS {axes} m, floor {floor} m"
    );
    let cross_validated = |rung| {
        (out.ladder.iter())
            .find(|r| r.rung == rung)
            .map(|r| r.heldout_rms_m)
            .unwrap()
    };
    let (isotropic, per_axis) = (
        cross_validated(ModelName::TransversalCompliance),
        cross_validated(ModelName::TransversalAxes),
    );
    assert!(
        isotropic > 1.3 * per_axis,
        "isotropic {isotropic} m against per axis {per_axis} m cross-validated: the anisotropy \
         was not seen"
    );
}

/// The bundled humanoid's URDF (fixtures/sim-humanoid) mounted upside down: its root joint's
/// origin turned by π about x, written to a scratch folder.
fn ceiling_urdf() -> std::path::PathBuf {
    let root = hapcal_calibrate::project_root();
    let text = std::fs::read_to_string(root.join("fixtures/sim-humanoid/humanoid.urdf")).unwrap();
    let upright = r#"<origin xyz="0 0 0.3" rpy="0 0 0"/>"#;
    let turned = text.replacen(
        upright,
        r#"<origin xyz="0 0 0.3" rpy="3.141592653589793 0 0"/>"#,
        1,
    );
    assert_ne!(turned, text, "the root joint's origin moved in the fixture");
    let dir = std::env::temp_dir().join(format!("hapcal-ceiling-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("humanoid_ceiling.urdf");
    std::fs::write(&path, turned).unwrap();
    path
}

/// `hapcal calibrate --device <device> --tip l_hand --tip r_hand --data
/// fixtures/sim-humanoid/mocap.csv --model compliance --gravity <gravity>`, and what the
/// check after the fit finds.
fn calibrate_fixture(
    device: &std::path::Path,
    gravity: [f64; 3],
) -> (
    hapcal_calibrate::report::CalibrationReport,
    Option<hapcal_calibrate::setup::Finding>,
) {
    use hapcal_calibrate::inputs::Plan;
    let root = hapcal_calibrate::project_root();
    let plan = Plan {
        device: device.to_path_buf(),
        tip: "l_hand".to_owned(),
        tips: vec!["r_hand".to_owned()],
        data: vec![root.join("fixtures/sim-humanoid/mocap.csv")],
        test: Vec::new(),
        model: ModelName::Compliance.into(),
        gravity,
        ..Plan::bundled_default()
    };
    let outcome = hapcal_calibrate::calibrate::run(&plan).unwrap();
    let finding = hapcal_calibrate::setup::after_fit(&outcome.report, &[]);
    (outcome.report, finding)
}

#[test]
fn a_ceiling_mount_is_named_and_its_fix_gives_the_upright_compliances() {
    use hapcal_calibrate::report::ImplausibleKind;
    use hapcal_calibrate::setup::{MistakeClass, Severity};
    let ceiling = ceiling_urdf();
    // Gravity along −z of a root turned upside down loads every joint the other way: the
    // compliances come out negative, a finding that names the mounting and its flag.
    let (report, finding) = calibrate_fixture(&ceiling, [0.0, 0.0, -1.0]);
    let f = finding.expect("negative compliances pass the check after the fit");
    assert_eq!(f.class, MistakeClass::Mounting, "{}", f.text());
    assert_eq!(f.severity, Severity::Error);
    assert_eq!(f.fix, "--gravity +z", "{}", f.text());
    assert!(f.message.contains("upside down"), "{}", f.message);
    assert_eq!(report.implausible[0].kind, ImplausibleKind::Mounting);
    // The fix applied: nothing implausible, and every compliance is the upright robot's
    // within its standard deviation (the same data, the same loads in another frame).
    let (fixed, finding) = calibrate_fixture(&ceiling, [0.0, 0.0, 1.0]);
    assert!(fixed.implausible.is_empty(), "{:?}", fixed.implausible);
    assert!(finding.is_none(), "{:?}", finding.map(|f| f.text()));
    let upright = hapcal_calibrate::project_root().join("fixtures/sim-humanoid/humanoid.urdf");
    let (reference, _) = calibrate_fixture(&upright, [0.0, 0.0, -1.0]);
    let compliances = |r: &hapcal_calibrate::report::CalibrationReport| -> Vec<(String, f64, f64)> {
        (r.parameters.iter())
            .filter(|p| p.name.starts_with("compliance."))
            .map(|p| (p.name.clone(), p.value, p.std))
            .collect()
    };
    let (a, b) = (compliances(&fixed), compliances(&reference));
    assert_eq!(a.len(), b.len());
    assert!(a.len() >= 14, "{a:?}");
    for ((name, value, std), (name_b, value_b, _)) in a.iter().zip(&b) {
        assert_eq!(name, name_b);
        assert!(
            (value - value_b).abs() < *std,
            "{name}: {value} vs {value_b} ± {std}"
        );
    }
}

#[test]
fn an_unconverged_fit_is_left_out_of_the_ladder_and_a_finding_when_given() {
    use hapcal_calibrate::report::{ImplausibleKind, UNCONVERGED_RUNG_NOTE};
    let robot = humanoid(&["l_hand", "r_hand"]);
    let truth = truth(&robot, 31);
    let train = table(&robot, &truth, &[0, 1], 200, 32);
    // Two residual evaluations: no fit above frames only (fitted before the ladder, at the
    // solver's default) can converge from the frames-only estimate.
    let limited = |rung| MeasuredConfig {
        max_evaluations: Some(2),
        ..config(rung, vec![0, 1])
    };
    let out =
        calibrate_measured(&robot, std::slice::from_ref(&train), &[], &limited(None)).unwrap();
    assert_eq!(out.rung, ModelName::FramesOnly, "ladder {:?}", out.ladder);
    assert!(out.fitted.identified.fit.termination.is_success());
    assert_eq!(out.ladder.len(), 1, "ladder {:?}", out.ladder);
    let notes: Vec<&String> = (out.warnings.iter())
        .filter(|w| w.starts_with(UNCONVERGED_RUNG_NOTE))
        .collect();
    assert!(
        notes
            .iter()
            .any(|w| w.contains("transversal-compliance model")),
        "{notes:?}"
    );
    assert!(
        notes
            .iter()
            .all(|w| w.ends_with("the ladder keeps frames-only")),
        "{notes:?}"
    );
    assert!(out.implausible.is_empty(), "{:?}", out.implausible);
    // The model given: its unconverged fit is a finding, never a result.
    let given = calibrate_measured(
        &robot,
        std::slice::from_ref(&train),
        &[],
        &limited(Some(ModelName::Geometric)),
    )
    .unwrap();
    assert_eq!(given.implausible[0].kind, ImplausibleKind::Unconverged);
    assert!(given.implausible[0].fix.contains("--model"));
    // Without the limit the same rows climb past frames only: the limit alone kept it there.
    let free = calibrate_measured(
        &robot,
        std::slice::from_ref(&train),
        &[],
        &config(None, vec![0, 1]),
    )
    .unwrap();
    assert_ne!(free.rung, ModelName::FramesOnly);
    assert!(free.implausible.is_empty(), "{:?}", free.implausible);
}

/// On a tree whose Huber pass bounds nothing, the ladder's runs start beside the fit of its
/// head (isotropic transversal compliance) and the pass; their held-out figures are those of
/// the ladder that waits for both (`ladder_heldout`, which starts nothing early), bit for bit.
#[test]
fn the_ladder_started_beside_its_head_scores_as_the_ladder_that_waits() {
    let robot = humanoid(&["l_hand", "r_hand"]);
    let seed = 41;
    let truth = truth(&robot, seed);
    let train = [table(&robot, &truth, &[0, 1], 160, seed + 1)];
    let test = [table(&robot, &truth, &[0, 1], 40, seed + 2)];
    let cfg = config(None, vec![0, 1]);
    let whole = calibrate_measured(&robot, &train, &test, &cfg).unwrap();
    assert!(whole.downweighted.is_empty(), "{:?}", whole.downweighted);
    let rungs: Vec<ModelName> = whole.ladder.iter().map(|r| r.rung).collect();
    for nested in [ModelName::TransversalCompliance, ModelName::TransversalAxes] {
        assert!(rungs.contains(&nested), "{rungs:?}");
    }
    let waited =
        hapcal_calibrate::measured::ladder_heldout(&robot, &train, &test, &cfg, &rungs).unwrap();
    let figures =
        |reports: &[hapcal_calibrate::measured::RungReport]| -> Vec<(ModelName, [u64; 3])> {
            (reports.iter())
                .map(|r| {
                    let (d, s) = r.score_difference_to_frames;
                    (
                        r.rung,
                        [r.heldout_rms_m.to_bits(), d.to_bits(), s.to_bits()],
                    )
                })
                .collect()
        };
    assert_eq!(figures(&waited), figures(&whole.ladder));
}
