//! The HTML report's renderer: escaping, every figure of a measurement-file calibration, no
//! figure for a set that is empty, and `--report` on the command line (refused over an input,
//! no file written unasked).

use hapcal::html::{calibration_figures, calibration_page, escape};
use hapcal_calibrate::model::ModelName;
use hapcal_calibrate::report::{
    CalibrationReport, Figures, ParamReport, PoseFigures, RungReport, SampleErrors, SampleRow,
    SetReport, SetRole,
};

/// A report as a measurement-file calibration writes it: two rungs, a training and a test set
/// of one marker each (rows at joint readings `q1 = i / n`), one parameter; `name` is the
/// device's name.
fn report(name: &str, n_train: usize, n_test: usize) -> CalibrationReport {
    let set = |role: SetRole, n: usize, offset: usize| {
        let rows: Vec<SampleRow> = (0..n)
            .map(|i| SampleRow {
                line: (offset + i + 2) as u64,
                q: vec![(offset + i) as f64 / 40.0, 0.3].into(),
                markers: vec![0],
                distance: false,
            })
            .collect();
        let before: Vec<f64> = (0..n).map(|i| 1e-3 * (1.0 + (i % 5) as f64)).collect();
        let after: Vec<f64> = before.iter().map(|e| e / 4.0).collect();
        let pose = |e: &[f64]| PoseFigures {
            position_rms_m: (e.iter().map(|v| v * v).sum::<f64>() / e.len().max(1) as f64).sqrt(),
            ..Default::default()
        };
        let figures = |p: PoseFigures| Figures {
            mean_absolute_error_m: None,
            distance_error_m: None,
            distance_rms_m: None,
            pose: Some(p),
        };
        SetReport {
            name: format!("{role} set"),
            role,
            n_rows: n,
            before: figures(pose(&before)),
            after: figures(pose(&after)),
            errors: Some(SampleErrors {
                position_before_m: before,
                position_after_m: after,
                rows,
                joints: vec![
                    ("joint_a1".to_owned(), "rad"),
                    ("joint_a2".to_owned(), "rad"),
                ],
                ..Default::default()
            }),
        }
    };
    let rung = |rung, rms: f64, d: f64| RungReport {
        rung,
        heldout_rms_m: rms,
        score_difference_to_frames: (d, 0.5),
        range_rms_m: None,
        range_difference_to_frames: 0.0,
        range_predicted_to_frames: (0.0, 0.0),
        nested: None,
        n_kept: 3,
    };
    CalibrationReport {
        device: name.to_owned(),
        model: ModelName::Geometric,
        folds: 5,
        cross_validation: Vec::new(),
        cross_validated_rows: None,
        ladder: vec![
            rung(ModelName::FramesOnly, 2e-3, 0.0),
            rung(ModelName::Geometric, 5e-4, -8.0),
        ],
        frames: Vec::new(),
        sigma_m: 5e-4,
        sigma_source: "residuals",
        parameters: vec![ParamReport {
            name: "joint_a2.offset".to_owned(),
            value: 1e-3,
            std: 1e-4,
            unit: "rad",
        }],
        pruned: Vec::new(),
        correlated: Vec::new(),
        observability: None,
        warnings: vec!["a warning with <markup> & \"quotes\"".to_owned()],
        termination: hapcal_identify::Termination::FtolReached,
        backend: "dense".to_owned(),
        n_evaluations: 10,
        n_jacobians: 5,
        rounds: 1,
        placements: vec![
            set(SetRole::Train, n_train, 0),
            set(SetRole::Test, n_test, n_train),
        ],
        elapsed_s: 0.0,
        downweighted: Vec::new(),
        range_folds: Vec::new(),
        coverage: None,
        equilibrium_step_m: None,
        equilibrium_refits: 0,
        implausible: Vec::new(),
        refitted_lengths: Vec::new(),
        origins: Vec::new(),
    }
}

#[test]
fn escapes_every_markup_character() {
    assert_eq!(
        escape(r#"<a href="x">'&'</a>"#),
        "&lt;a href=&quot;x&quot;&gt;&#39;&amp;&#39;&lt;/a&gt;"
    );
    let page = calibration_page(&report("<robot>.urdf", 30, 10), "hapcal calibrate", &[]);
    assert!(
        !page.contains("<robot>"),
        "a user string reached the page unescaped"
    );
    assert!(page.contains("&lt;robot&gt;.urdf"));
    assert!(page.contains("a warning with &lt;markup&gt; &amp; &quot;quotes&quot;"));
    assert!(!page.contains("<script"), "the report holds no script");
    assert!(
        !page.contains("http://") || !page.contains("<link"),
        "nothing is fetched"
    );
}

#[test]
fn a_measurement_calibration_has_every_figure() {
    let r = report("robot.urdf", 30, 10);
    let ids: Vec<String> = calibration_figures(&r).into_iter().map(|f| f.id).collect();
    for id in [
        "fig-ladder",
        "fig-ladder-rms",
        "fig-sets",
        "fig-residual-rows",
        "fig-histograms",
        "fig-markers",
        "fig-residual-joint",
        "fig-ranges",
        "fig-parameters",
    ] {
        assert!(ids.iter().any(|i| i == id), "{id} missing from {ids:?}");
    }
    // Every figure draws text as SVG <text> (no font file) and has a non-zero size.
    for f in calibration_figures(&r) {
        assert!(f.svg.contains("<text"), "{} has no text", f.id);
        assert!(!f.svg.contains("figure not drawn"), "{} not drawn", f.id);
        assert!(!f.svg.contains("width=\"0\""), "{} of zero width", f.id);
    }
    // The histogram counts every sample of its set once: 30 training, 10 test samples.
    let hist = calibration_figures(&r)
        .into_iter()
        .find(|f| f.id == "fig-histograms")
        .unwrap();
    let counts: Vec<u64> = hist.values[0]["counts"][0]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_u64().unwrap())
        .collect();
    assert_eq!(counts.iter().sum::<u64>(), 30);
    assert_eq!(hist.values.as_array().unwrap().len(), 2);
}

#[test]
fn an_empty_set_draws_no_figure() {
    let r = report("robot.urdf", 30, 0);
    let figures = calibration_figures(&r);
    let hist = figures.iter().find(|f| f.id == "fig-histograms").unwrap();
    assert_eq!(
        hist.values.as_array().unwrap().len(),
        1,
        "a panel for the empty test set"
    );
    let rows = figures
        .iter()
        .find(|f| f.id == "fig-residual-rows")
        .unwrap();
    assert!(
        rows.values
            .as_array()
            .unwrap()
            .iter()
            .all(|s| s["label"] != "calibrated, test"),
        "a series for the empty test set"
    );
    let none = report("robot.urdf", 0, 0);
    let ids: Vec<String> = calibration_figures(&none)
        .into_iter()
        .map(|f| f.id)
        .collect();
    for id in [
        "fig-residual-rows",
        "fig-histograms",
        "fig-residual-joint",
        "fig-ranges",
    ] {
        assert!(!ids.iter().any(|i| i == id), "{id} drawn without a sample");
    }
}

#[test]
fn report_is_refused_over_an_input() {
    let root = crate::root();
    let data = root.join("fixtures/industrial-calibration/measurements.yaml");
    let out = crate::hapcal(&[
        "calibrate",
        "--device",
        root.join("fixtures/industrial-calibration/two_axis_positioner.toml")
            .to_str()
            .unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--report",
        data.to_str().unwrap(),
    ]);
    crate::assert_exit(&out, 2, &[".html"]);
}
