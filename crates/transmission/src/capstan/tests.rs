use std::f64::consts::PI;

use proptest::prelude::*;

use super::*;

const D: f64 = 0.06;

/// Eq. 1 written out again, independently of the implementation (plain f64, no helpers).
fn eq1_by_hand(r: f64, d: f64, p: &CapstanParams, t: f64) -> f64 {
    let o = (p.r_o_m * (t + p.beta_o_rad).sin() / (d - p.r_o_m * (t + p.beta_o_rad).cos())).atan()
        - (p.r_o_m * p.beta_o_rad.sin() / (d - p.r_o_m * p.beta_o_rad.cos())).atan();
    let i = (p.r_i_m * (r * t + p.beta_i_rad).sin() / (d - p.r_i_m * (r * t + p.beta_i_rad).cos()))
        .atan()
        - (p.r_i_m * p.beta_i_rad.sin() / (d - p.r_i_m * p.beta_i_rad.cos())).atan();
    p.c_rad + (-p.re / (p.re + r)) * t + o + i
}

fn table2_joint1() -> CapstanParams {
    CapstanParams {
        c_rad: 0.0,
        re: -0.025,
        r_o_m: 0.2e-3,
        beta_o_rad: (-105.0f64).to_radians(),
        r_i_m: 0.005e-3,
        beta_i_rad: (-15.0f64).to_radians(),
    }
}

#[test]
fn zero_reading_gives_exactly_the_offset() {
    let cap = Capstan::try_new(10.0, D).unwrap();
    let p = CapstanParams {
        c_rad: 1.25e-3,
        ..table2_joint1()
    };
    assert_eq!(cap.error_rad(&p, JointRad(0.0)), 1.25e-3);
    assert_eq!(cap.output_rad(&p, JointRad(0.0)), 1.25e-3);
}

#[test]
fn ideal_drive_has_no_error() {
    let cap = Capstan::try_new(12.0, D).unwrap();
    for t in [-1.5, -0.3, 0.0, 0.7, 1.8] {
        assert_eq!(cap.error_rad(&CapstanParams::default(), JointRad(t)), 0.0);
    }
}

#[test]
fn ratio_error_alone_is_linear() {
    // R = 10, Re = 0.1: Δθ = −0.1/10.1·θ; at θ = 1.01 that is −0.01 (to rounding).
    let cap = Capstan::try_new(10.0, D).unwrap();
    let p = CapstanParams {
        re: 0.1,
        ..Default::default()
    };
    assert!((cap.error_rad(&p, JointRad(1.01)) + 0.01).abs() < 1e-15);
}

#[test]
fn output_eccentricity_at_a_quarter_turn() {
    // r_o = D/2, β_o = 0, θ = π/2: atan((D/2)/D) − atan(0) = atan(1/2).
    let cap = Capstan::try_new(10.0, D).unwrap();
    let p = CapstanParams {
        r_o_m: D / 2.0,
        ..Default::default()
    };
    let expected = 0.5f64.atan();
    assert!((cap.error_rad(&p, JointRad(PI / 2.0)) - expected).abs() < 1e-15);
}

#[test]
fn table2_values_match_the_formula_written_by_hand() {
    let cap = Capstan::try_new(10.0, D).unwrap();
    let p = table2_joint1();
    for t in [-1.0, -0.4, 0.25, 0.9, 3.0] {
        let got = cap.error_rad(&p, JointRad(t));
        let want = eq1_by_hand(10.0, D, &p, t);
        assert!((got - want).abs() < 1e-15, "θ = {t}: {got} vs {want}");
        assert_eq!(cap.output_rad(&p, JointRad(t)), t + got);
    }
    // Order of magnitude: Re = −0.025 on R = 10 gives ≈ 2.5 mrad per rad, r_o/D ≈ 3.3 mrad.
    let e = cap.error_rad(&p, JointRad(1.0));
    assert!(e.abs() > 1e-3 && e.abs() < 1e-2, "{e}");
}

#[test]
fn accessors_return_the_ratio_and_drum_distance() {
    let cap = Capstan::try_new(12.0, D).unwrap();
    assert_eq!(cap.ratio(), 12.0);
    assert_eq!(cap.drum_distance_m(), D);
}

#[test]
fn invalid_capstans_are_rejected_with_a_message() {
    let err = Capstan::try_new(0.0, D).unwrap_err();
    assert_eq!(
        err,
        Error::NonPositive {
            name: "ratio",
            value: 0.0
        }
    );
    assert_eq!(err.to_string(), "ratio must be positive, found 0");
    let err = Capstan::try_new(10.0, f64::NAN).unwrap_err();
    assert_eq!(err.to_string(), "drum_distance_m = NaN is not finite");
    assert!(Capstan::try_new(10.0, -0.06).is_err());
}

#[test]
fn check_params_rejects_eccentricity_at_the_drum_distance() {
    let cap = Capstan::try_new(10.0, D).unwrap();
    assert_eq!(cap.check_params(&table2_joint1()), Ok(()));
    let p = CapstanParams {
        r_i_m: -D,
        ..Default::default()
    };
    let err = cap.check_params(&p).unwrap_err();
    assert_eq!(
        err.to_string(),
        "r_i_m = -0.06 m is not below the drum distance 0.06 m"
    );
    let p = CapstanParams {
        re: -10.0,
        ..Default::default()
    };
    assert_eq!(
        cap.check_params(&p).unwrap_err().to_string(),
        "ratio + re must be positive, found 0"
    );
    let p = CapstanParams {
        beta_o_rad: f64::INFINITY,
        ..Default::default()
    };
    assert_eq!(
        cap.check_params(&p).unwrap_err().to_string(),
        "beta_o_rad = inf is not finite"
    );
}

/// Parameters in the paper's ranges (Table 2): r_o ≤ 0.3 mm, r_i ≤ 0.01 mm, any β, |Re| ≤ 0.03.
fn params() -> impl Strategy<Value = CapstanParams> {
    (
        -0.01..0.01f64,
        -0.03..0.03f64,
        0.0..0.3e-3f64,
        -PI..PI,
        0.0..0.01e-3f64,
        -PI..PI,
    )
        .prop_map(|(c, re, ro, bo, ri, bi)| CapstanParams {
            c_rad: c,
            re,
            r_o_m: ro,
            beta_o_rad: bo,
            r_i_m: ri,
            beta_i_rad: bi,
        })
}

fn with(p: &CapstanParams, j: usize, v: f64) -> CapstanParams {
    let mut q = *p;
    match j {
        0 => q.c_rad = v,
        1 => q.re = v,
        2 => q.r_o_m = v,
        3 => q.beta_o_rad = v,
        4 => q.r_i_m = v,
        _ => q.beta_i_rad = v,
    }
    q
}

fn get(p: &CapstanParams, j: usize) -> f64 {
    [p.c_rad, p.re, p.r_o_m, p.beta_o_rad, p.r_i_m, p.beta_i_rad][j]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn error_grad_matches_central_differences(
        p in params(), ratio in 8.0..14.0f64, t in -1.8..1.8f64,
    ) {
        let cap = Capstan::try_new(ratio, D).unwrap();
        let grad = cap.error_grad(&p, JointRad(t));
        // Steps relative to each parameter's scale: rad, 1, m, rad, m, rad.
        let steps = [1e-6, 1e-6, 1e-9, 1e-6, 1e-10, 1e-6];
        for (j, h) in steps.iter().enumerate() {
            let x = get(&p, j);
            let up = cap.error_rad(&with(&p, j, x + h), JointRad(t));
            let down = cap.error_rad(&with(&p, j, x - h), JointRad(t));
            let fd = (up - down) / (2.0 * h);
            // Absolute floor: rounding of Δθ (≈ 1e-18) divided by the step.
            let floor = 1e-17 / h;
            prop_assert!(
                (grad[j] - fd).abs() <= floor + 1e-6 * fd.abs(),
                "parameter {j}: {} vs {fd}", grad[j]
            );
        }
    }

    #[test]
    fn error_dtheta_matches_central_differences(
        p in params(), ratio in 8.0..14.0f64, t in -1.8..1.8f64,
    ) {
        let cap = Capstan::try_new(ratio, D).unwrap();
        let h = 1e-6;
        let fd = (cap.error_rad(&p, JointRad(t + h)) - cap.error_rad(&p, JointRad(t - h))) / (2.0 * h);
        let an = cap.error_dtheta(&p, JointRad(t));
        prop_assert!((an - fd).abs() <= 1e-11 + 1e-6 * fd.abs(), "{an} vs {fd}");
    }

    #[test]
    fn eq1_matches_the_formula_written_by_hand(
        p in params(), ratio in 8.0..14.0f64, t in -1.8..1.8f64,
    ) {
        let cap = Capstan::try_new(ratio, D).unwrap();
        let got = cap.error_rad(&p, JointRad(t));
        let want = eq1_by_hand(ratio, D, &p, t);
        prop_assert!((got - want).abs() <= 1e-16, "{got} vs {want}");
    }
}

/// The linear basis is eq. 1's first-order expansion about a perfect drive: with eccentricities
/// of `ε·D` and a ratio error of `ε·R`, its combination with the Cartesian coefficients differs
/// from eq. 1 by O(ε²), so shrinking ε tenfold shrinks the gap a hundredfold.
#[test]
fn linear_basis_is_the_first_order_expansion_of_eq1() {
    let (r, d) = (13.5, 0.03);
    let capstan = Capstan::try_new(r, d).unwrap();
    let gap = |eps: f64| {
        let p = CapstanParams {
            c_rad: 1e-3,
            re: eps * r,
            r_o_m: eps * d,
            beta_o_rad: 0.7,
            r_i_m: 0.5 * eps * d,
            beta_i_rad: -1.9,
        };
        let coef = [
            p.c_rad,
            -p.re / r,
            p.r_o_m / d * p.beta_o_rad.cos(),
            p.r_o_m / d * p.beta_o_rad.sin(),
            p.r_i_m / d * p.beta_i_rad.cos(),
            p.r_i_m / d * p.beta_i_rad.sin(),
        ];
        (0..50)
            .map(|k| -1.5 + 3.0 * f64::from(k) / 49.0)
            .map(|t| {
                let basis = capstan.linear_basis(JointRad(t));
                let linear: f64 = basis.iter().zip(coef).map(|(b, c)| b * c).sum();
                (capstan.error_rad(&p, JointRad(t)) - linear).abs()
            })
            .fold(0.0, f64::max)
    };
    let (coarse, fine) = (gap(1e-3), gap(1e-4));
    assert!(coarse > 0.0 && coarse < 1e-5, "gap at ε = 1e-3: {coarse}");
    assert!(
        fine < coarse / 50.0,
        "gap {coarse} → {fine}: not second order"
    );
}
