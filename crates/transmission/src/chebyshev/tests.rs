use proptest::prelude::*;

use super::*;

#[test]
fn low_degrees_by_hand() {
    // On [0, 2]: u = θ − 1. p = 1·T0 + 2·T1 + 3·T2 = 1 + 2u + 3(2u² − 1) = 6u² + 2u − 2.
    let p = Chebyshev::try_new(0.0, 2.0, vec![1.0, 2.0, 3.0]).unwrap();
    assert_eq!(p.degree(), 2);
    for theta in [0.0, 0.5, 1.3, 2.0] {
        let u: f64 = theta - 1.0;
        assert!((p.eval(theta) - (6.0 * u * u + 2.0 * u - 2.0)).abs() < 1e-14);
        assert!((p.derivative(theta) - (12.0 * u + 2.0)).abs() < 1e-14);
    }
    // In θ: 6(θ−1)² + 2(θ−1) − 2 = 6θ² − 10θ + 2.
    let k = p.to_monomial();
    assert_eq!(k.len(), 3);
    for (got, want) in k.iter().zip([2.0, -10.0, 6.0]) {
        assert!((got - want).abs() < 1e-13, "{k:?}");
    }
    assert_eq!(p.basis(1.5), vec![1.0, 0.5, -0.5]);
}

#[test]
fn constant_polynomial() {
    let p = Chebyshev::try_new(-1.0, 1.0, vec![0.25]).unwrap();
    assert_eq!(p.degree(), 0);
    assert_eq!(p.eval(0.3), 0.25);
    assert_eq!(p.derivative(0.3), 0.0);
    assert_eq!(p.to_monomial(), vec![0.25]);
}

#[test]
fn invalid_polynomials_are_rejected() {
    let err = Chebyshev::try_new(1.0, 1.0, vec![0.0]).unwrap_err();
    assert_eq!(err, Error::Domain { lo: 1.0, hi: 1.0 });
    assert_eq!(
        err.to_string(),
        "the domain [1, 1] rad is not a finite interval with lo < hi"
    );
    assert_eq!(
        Chebyshev::try_new(0.0, 1.0, vec![])
            .unwrap_err()
            .to_string(),
        "coeffs is empty"
    );
    assert_eq!(
        Chebyshev::try_new(0.0, 1.0, vec![0.0, f64::NAN])
            .unwrap_err()
            .to_string(),
        "coeffs[1] = NaN is not finite"
    );
    assert!(Chebyshev::from_monomial(0.0, f64::INFINITY, &[1.0]).is_err());
}

/// Monomial coefficients of `p` with every term of the Clenshaw recurrence taken in absolute
/// value (`|c_k|`, `|a|`, `|b|`, and `+ b_{k+2}` for `− b_{k+2}`): an entrywise upper bound of
/// the magnitudes that [`Chebyshev::to_monomial`] adds up, hence a scale for its rounding.
fn absolute_monomial(p: &Chebyshev) -> Vec<f64> {
    let n = p.degree();
    let w = p.hi - p.lo;
    let (a, b) = ((2.0 / w).abs(), ((p.lo + p.hi) / w).abs());
    let mut b1 = vec![0.0; n + 2];
    let mut b2 = vec![0.0; n + 2];
    for &c in p.coeffs.iter().skip(1).rev() {
        let mut b0 = vec![0.0; n + 2];
        for i in 0..=n {
            b0[i] += 2.0 * b * b1[i] + b2[i];
            b0[i + 1] += 2.0 * a * b1[i];
        }
        b0[0] += c.abs();
        b2 = b1;
        b1 = b0;
    }
    let mut out = vec![0.0; n + 1];
    for i in 0..=n {
        out[i] += b * b1[i] + b2[i];
        if i < n {
            out[i + 1] += a * b1[i];
        }
    }
    out[0] += p.coeffs.first().map_or(0.0, |c| c.abs());
    out
}

/// A joint range of docs/design.md §2 (rad).
fn joint_range() -> impl Strategy<Value = (f64, f64)> {
    prop::sample::select(vec![
        (-1.0, 1.0),
        (-0.3, 1.2),
        (-0.8, 0.8),
        (0.3, 1.8),
        (-2.0, 2.0),
        (-1.2, 1.2),
        (-2.5, 2.5),
    ])
}

/// A polynomial of degree 0..=10 with coefficients of transmission-error size (≤ 0.1 rad).
fn polynomial() -> impl Strategy<Value = Chebyshev> {
    (joint_range(), prop::collection::vec(-0.1..0.1f64, 1..=11))
        .prop_map(|((lo, hi), c)| Chebyshev::try_new(lo, hi, c).unwrap())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn derivative_matches_central_differences(p in polynomial(), s in 0.0..1.0f64) {
        let theta = p.lo + s * (p.hi - p.lo);
        let h = 1e-6;
        let fd = (p.eval(theta + h) - p.eval(theta - h)) / (2.0 * h);
        let an = p.derivative(theta);
        prop_assert!((an - fd).abs() <= 1e-8 + 1e-6 * fd.abs(), "{an} vs {fd}");
    }

    #[test]
    fn basis_is_the_jacobian_of_eval(p in polynomial(), s in 0.0..1.0f64) {
        let theta = p.lo + s * (p.hi - p.lo);
        let basis = p.basis(theta);
        prop_assert_eq!(basis.len(), p.degree() + 1);
        // eval is linear in the coefficients: a central difference is exact up to rounding.
        let h = 1e-6;
        for (k, &b) in basis.iter().enumerate() {
            let mut up = p.clone();
            up.coeffs[k] += h;
            let mut down = p.clone();
            down.coeffs[k] -= h;
            let fd = (up.eval(theta) - down.eval(theta)) / (2.0 * h);
            prop_assert!((b - fd).abs() <= 1e-9 + 1e-6 * fd.abs(), "T{k}: {b} vs {fd}");
        }
        let sum: f64 = basis.iter().zip(&p.coeffs).map(|(t, c)| t * c).sum();
        prop_assert!((sum - p.eval(theta)).abs() < 1e-14);
    }

    #[test]
    fn to_monomial_reproduces_eval(p in polynomial(), s in -0.1..1.1f64) {
        let theta = p.lo + s * (p.hi - p.lo);
        let k = p.to_monomial();
        prop_assert_eq!(k.len(), p.degree() + 1);
        let horner = k.iter().rev().fold(0.0, |acc, &ki| acc * theta + ki);
        // Rounding in the conversion and in Horner's rule is bounded by a few ulps per
        // operation of the same sums taken in absolute value (Higham, "Accuracy and Stability
        // of Numerical Algorithms", 2nd ed., §5.1): the scale is the polynomial with every
        // recurrence term added in absolute value, evaluated at |θ|.
        let scale = absolute_monomial(&p).iter().rev().fold(0.0, |acc, &ki| acc * theta.abs() + ki);
        let tol = 8.0 * (2.0 * k.len() as f64 + 2.0) * f64::EPSILON * scale;
        prop_assert!(
            (horner - p.eval(theta)).abs() <= tol,
            "{horner} vs {} (tolerance {tol})", p.eval(theta)
        );
    }

    #[test]
    fn monomial_round_trip(p in polynomial()) {
        let back = Chebyshev::from_monomial(p.lo, p.hi, &p.to_monomial()).unwrap();
        prop_assert_eq!(back.coeffs.len(), p.coeffs.len());
        for (b, c) in back.coeffs.iter().zip(&p.coeffs) {
            prop_assert!((b - c).abs() < 1e-9, "{:?} vs {:?}", back.coeffs, p.coeffs);
        }
    }
}
