use std::f64::consts::{FRAC_PI_2, PI};

use proptest::prelude::*;

use super::*;

/// docs/design.md §2 parallelogram with the paper's Table 2 deviations read as mm.
fn paper_bar() -> FourBar {
    FourBar::try_new(0.05 - 0.0005, 0.21 - 0.0007, 0.05, 0.21).unwrap()
}

#[test]
fn rectangle_is_transmitted_exactly() {
    let bar = FourBar::try_new(0.05, 0.21, 0.05, 0.21).unwrap();
    assert!((bar.output_rad(FRAC_PI_2).unwrap() - FRAC_PI_2).abs() < 1e-15);
    assert!(bar.error_rad(1.0).unwrap().abs() < 1e-15);
    assert!((bar.d_output_d_input(1.0).unwrap() - 1.0).abs() < 1e-12);
}

#[test]
fn closure_by_hand_for_a_non_parallelogram() {
    // Written out independently: intersect the circles |Q − P| = l2 and |Q − B| = l3 and take
    // the intersection on the clockwise side of B→P.
    let bar = FourBar::try_new(0.04, 0.2, 0.06, 0.19).unwrap();
    for phi in [0.5, 1.2, 2.0, 2.6] {
        let p = (0.04 * f64::cos(phi), 0.04 * f64::sin(phi));
        let b = (0.19, 0.0);
        let (dx, dy) = (p.0 - b.0, p.1 - b.1);
        let s2 = dx * dx + dy * dy;
        let lambda = ((0.06 * 0.06 + s2 - 0.2 * 0.2) / (2.0 * 0.06 * s2.sqrt())).acos();
        let want = dy.atan2(dx) - lambda;
        let got = bar.output_rad(phi).unwrap();
        assert!((got - want).abs() < 1e-12, "φ = {phi}: {got} vs {want}");
        // The loop really closes: |Q − P| = l2.
        let q = (b.0 + 0.06 * got.cos(), b.1 + 0.06 * got.sin());
        let l2 = ((q.0 - p.0).powi(2) + (q.1 - p.1).powi(2)).sqrt();
        assert!((l2 - 0.2).abs() < 1e-15);
        // Open branch: A and Q on opposite sides of the diagonal B→P.
        let side_a = dx * (0.0 - b.1) - dy * (0.0 - b.0);
        let side_q = dx * (q.1 - b.1) - dy * (q.0 - b.0);
        assert!(side_a * side_q < 0.0);
    }
}

#[test]
fn the_paper_four_bar_cannot_close_near_pi() {
    // l1 + l4 = 0.2595 m > l2 + l3 = 0.2593 m: at φ = π the diagonal is too long.
    let bar = paper_bar();
    let err = bar.output_rad(PI).unwrap_err();
    assert_eq!(err, Error::NoClosure { phi: PI });
    assert_eq!(
        err.to_string(),
        format!("the four-bar loop cannot close at crank angle {PI} rad")
    );
    assert!(bar.d_output_d_input(PI).is_err());
    assert!(bar.d_output_d_lengths(PI).is_err());
    assert!(bar.output_rad(2.5).is_ok());
}

#[test]
fn invalid_lengths_are_rejected() {
    assert_eq!(
        FourBar::try_new(0.05, 0.0, 0.05, 0.21)
            .unwrap_err()
            .to_string(),
        "l2_m must be positive, found 0"
    );
    assert!(FourBar::try_new(0.05, 0.21, f64::NAN, 0.21).is_err());
    assert!(paper_bar().output_rad(f64::NAN).is_err());
}

#[test]
fn joint4_with_ideal_parts_has_no_error() {
    let t = Joint4Transmission {
        capstan: Capstan::try_new(12.0, 0.06).unwrap(),
        params: CapstanParams::default(),
        four_bar: FourBar::try_new(0.05, 0.21, 0.05, 0.21).unwrap(),
        phi0_rad: Joint4Transmission::phi0_mid_range_rad(0.3, 1.8),
    };
    for th in [0.3, 0.8, 1.05, 1.8] {
        assert!(t.error_rad(JointRad(th)).unwrap().abs() < 1e-12);
    }
    assert!((t.phi0_rad - (FRAC_PI_2 - 1.05)).abs() < 1e-15);
}

#[test]
fn joint4_composes_capstan_then_four_bar() {
    let capstan = Capstan::try_new(12.0, 0.06).unwrap();
    let params = CapstanParams {
        c_rad: 1e-3,
        re: 0.02,
        r_o_m: 0.1e-3,
        beta_o_rad: -0.7,
        r_i_m: 0.002e-3,
        beta_i_rad: -2.1,
    };
    let four_bar = paper_bar();
    let t = Joint4Transmission {
        capstan,
        params,
        four_bar,
        phi0_rad: 0.52,
    };
    let th = 1.1;
    let phi = 0.52 + th + capstan.error_rad(&params, JointRad(th));
    let want = four_bar.output_rad(phi).unwrap() - 0.52 - th;
    assert_eq!(t.error_rad(JointRad(th)).unwrap(), want);
    assert_eq!(t.output_rad(JointRad(th)).unwrap(), want + th);
}

/// Four-bars near the parallelogram of docs/design.md §2 (±3 mm on every link).
fn near_parallelogram() -> impl Strategy<Value = FourBar> {
    (
        0.02..0.1f64,
        0.1..0.3f64,
        prop::array::uniform4(-3e-3..3e-3f64),
    )
        .prop_map(|(l1, l2, d)| {
            FourBar::try_new(l1 + d[0], l2 + d[1], l1 + d[2], l2 + d[3]).unwrap()
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn ideal_parallelogram_transmits_exactly(
        phi in 0.2..2.9f64, l1 in 0.02..0.1f64, l2 in 0.1..0.3f64,
    ) {
        let bar = FourBar::try_new(l1, l2, l1, l2).unwrap();
        let psi = bar.output_rad(phi).unwrap();
        prop_assert!((psi - phi).abs() < 1e-12, "{psi} vs {phi}");
        prop_assert!((bar.d_output_d_input(phi).unwrap() - 1.0).abs() < 1e-9);
    }

    #[test]
    fn d_output_d_input_matches_central_differences(bar in near_parallelogram(), phi in 0.4..2.7f64) {
        let h = 1e-6;
        let (Ok(up), Ok(down), Ok(an)) =
            (bar.output_rad(phi + h), bar.output_rad(phi - h), bar.d_output_d_input(phi))
        else {
            return Err(TestCaseError::reject("no closure"));
        };
        let fd = (up - down) / (2.0 * h);
        prop_assert!((an - fd).abs() <= 1e-9 + 1e-6 * fd.abs(), "{an} vs {fd}");
    }

    #[test]
    fn d_output_d_lengths_matches_central_differences(bar in near_parallelogram(), phi in 0.4..2.7f64) {
        let Ok(an) = bar.d_output_d_lengths(phi) else {
            return Err(TestCaseError::reject("no closure"));
        };
        let h = 1e-8;
        for j in 0..4 {
            let shifted = |dl: f64| {
                let mut l = [bar.l1_m, bar.l2_m, bar.l3_m, bar.l4_m];
                l[j] += dl;
                FourBar::try_new(l[0], l[1], l[2], l[3]).unwrap().output_rad(phi)
            };
            let (Ok(up), Ok(down)) = (shifted(h), shifted(-h)) else {
                return Err(TestCaseError::reject("no closure"));
            };
            let fd = (up - down) / (2.0 * h);
            prop_assert!((an[j] - fd).abs() <= 1e-7 + 1e-6 * fd.abs(), "l{}: {} vs {fd}", j + 1, an[j]);
        }
    }
}
