//! Error paths: wrong inputs give errors that name what is wrong, never a panic.

use hapcal_runtime::{CapstanParams, Drive, Error, LoadError, MAX_JOINTS, Model};

use crate::fixture;

fn reference() -> (Model, String) {
    let path = fixture("reference-device/calibrated.toml");
    let text = std::fs::read_to_string(&path).expect("fixture");
    (Model::from_toml(&text, "ref").expect("fixture"), text)
}

#[test]
fn wrong_lengths_and_non_finite_readings_are_errors() {
    let (model, _) = reference();
    let err = model.end_pose(&[0.0; 6]).expect_err("6 of 7");
    assert_eq!(
        err,
        Error::Length {
            what: "joint readings",
            expected: 7,
            found: 6
        }
    );
    assert_eq!(
        err.to_string(),
        "joint readings: expected 7 values, found 6"
    );
    let mut theta = [0.1; 7];
    theta[3] = f64::NAN;
    let err = model.end_pose(&theta).expect_err("NaN");
    assert!(
        matches!(
            err,
            Error::NotFinite {
                what: "joint readings",
                index: 3,
                ..
            }
        ),
        "{err:?}"
    );
    let mut tau = [0.0; 8];
    let err = (model.motor_torques(&[0.1; 7], &[0.0; 6], &mut tau)).expect_err("8 torques");
    assert_eq!(err.to_string(), "motor torques: expected 7 values, found 8");
    let mut jac = [[0.0; 6]; 6];
    assert!(model.body_jacobian(&[0.1; 7], &mut jac).is_err());
}

#[test]
fn invalid_files_name_the_place_and_the_problem() {
    let (_, text) = reference();
    let err =
        Model::from_toml("name = \"x\"\n[[dh]]\na_m = \"one\"\n", "dev.toml").expect_err("type");
    assert!(matches!(err, LoadError::Parse { line: 3, .. }), "{err:?}");
    assert!(err.to_string().starts_with("dev.toml:3:"), "{err}");

    let err = Model::from_toml(&text.replace("[handle]", "[handel]"), "dev.toml")
        .expect_err("unknown table");
    assert!(err.to_string().contains("handel"), "{err}");

    // One entry's line changed, the rest of the file as written.
    let edit_line = |start: &str, edit: &dyn Fn(&str) -> String| -> String {
        (text.lines())
            .map(|l| {
                if l.starts_with(start) {
                    edit(l)
                } else {
                    l.to_owned()
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let unit = edit_line("\"capstan1.re\"", &|l| {
        l.replace("unit = \"1\"", "unit = \"rad\"")
    });
    assert_ne!(unit, text);
    let err = Model::from_toml(&unit, "dev.toml").expect_err("unit");
    let line = 1
        + (unit.lines())
            .position(|l| l.starts_with("\"capstan1.re\""))
            .expect("the entry");
    assert_eq!(
        err.to_string(),
        format!("dev.toml:{line}:1: \"capstan1.re\" is in \"rad\", expected \"1\"")
    );

    let gap = text.replace("\"joint4.cheb3\"", "\"joint4.cheb13\"");
    let err = Model::from_toml(&gap, "dev.toml").expect_err("gap");
    assert!(err.to_string().contains("joint4.cheb3 is missing"), "{err}");

    let eccentric = edit_line("\"capstan3.r_o\"", &|_| {
        "\"capstan3.r_o\" = { value = 0.07, std = 1e-5, unit = \"m\" }".to_owned()
    });
    assert_ne!(eccentric, text);
    let err = Model::from_toml(&eccentric, "dev.toml").expect_err("r_o ≥ D");
    assert!(
        err.to_string()
            .contains("capstan3: r_o_m = 0.07 is invalid"),
        "{err}"
    );

    let numbering = text.replacen("joint = 2\n", "joint = 3\n", 1);
    let err = Model::from_toml(&numbering, "dev.toml").expect_err("numbering");
    assert!(
        err.to_string()
            .contains("[[dh]] row 2: joint = 3, expected 2"),
        "{err}"
    );

    let err = Model::load(&fixture("no-such-device.toml")).expect_err("missing");
    assert!(matches!(err, LoadError::Io { .. }), "{err:?}");
}

/// Numbers the command line's readers refuse at their place: a length of 1e308 m, a NaN
/// parallelogram length, a polynomial coefficient of 1e300 rad.
#[test]
fn absurd_and_non_finite_numbers_are_refused_at_their_line() {
    let (_, text) = reference();
    let line_of = |needle: &str, t: &str| {
        1 + t[..t.find(needle).expect("in the file")]
            .matches('\n')
            .count()
    };
    let cases = [
        (
            text.replacen("d_m = 0.0\n", "d_m = 1e308\n", 1),
            "d_m = 1e308",
            "dh[0].d_m",
        ),
        (
            text.replacen("l1_m = 0.05", "l1_m = nan", 1),
            "l1_m = nan",
            "parallelogram.l1_m",
        ),
        (
            text.replacen("value = 0.01620786094299803", "value = 1e300", 1),
            "value = 1e300",
            "joint4.cheb0",
        ),
    ];
    for (bad, needle, name) in cases {
        let err = Model::from_toml(&bad, "dev.toml").expect_err(name);
        let LoadError::Parse {
            line, ref message, ..
        } = err
        else {
            panic!("{err:?}");
        };
        assert_eq!(line, line_of(needle, &bad), "{message}");
        assert!(message.contains(name), "{message}");
    }
}

#[test]
fn placement_chains_are_refused_with_a_reason() {
    let text = "[[placement]]\nname = \"j1\"\nxyz_m = [0, 0, 0]\nrpy_rad = [0, 0, 0]\naxis = [0, 0, 1]\n\
                [[joint]]\nname = \"j1\"\nlower_rad = -1.0\nupper_rad = 1.0\n";
    let err = Model::from_toml(text, "urdf.toml").expect_err("placements");
    assert!(
        err.to_string().contains("not supported by the runtime"),
        "{err}"
    );
}

#[test]
fn drive_constructors_check_their_domain() {
    let p = CapstanParams {
        r_i_m: 0.06,
        ..CapstanParams::default()
    };
    assert_eq!(
        Drive::capstan(10.0, 0.06, p),
        Err(Error::Invalid {
            what: "r_i_m",
            value: 0.06,
            expected: "|r| < drum_distance_m"
        })
    );
    let p = CapstanParams {
        re: -10.0,
        ..CapstanParams::default()
    };
    assert!(matches!(
        Drive::capstan(10.0, 0.06, p),
        Err(Error::Invalid {
            what: "ratio + re",
            ..
        })
    ));
    assert!(Drive::polynomial(1.0, 1.0, 1.0, &[0.0]).is_err());
    assert!(Drive::polynomial(1.0, 0.0, 1.0, &[]).is_err());
    assert!(matches!(
        Drive::polynomial(1.0, 0.0, 1.0, &[0.0; 17]),
        Err(Error::TooMany {
            what: "coefficients",
            ..
        })
    ));
    assert!(matches!(
        Model::from_dh(hapcal_runtime::DhConvention::Standard, &[], &[]),
        Err(Error::Invalid { what: "joints", .. })
    ));
    let row = hapcal_runtime::DhRow {
        a_m: 0.0,
        alpha_rad: 0.0,
        d_m: 0.0,
        theta_rad: 0.0,
        beta_rad: None,
        joint: true,
    };
    let rows = [row; MAX_JOINTS + 1];
    assert!(matches!(
        Model::from_dh(hapcal_runtime::DhConvention::Standard, &rows, &[]),
        Err(Error::TooMany { what: "joints", .. })
    ));
}
