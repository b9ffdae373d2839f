use faer::{Col, Mat};
use hapcal_identify::Problem;
use hapcal_kinematics::{Chain, DhRow};
use hapcal_transmission::JointRad;

use super::*;
use crate::{PolynomialProblem, Row, RowKind};

const SIGMA_EXT: f64 = 1e-4;
const SIGMA_D: f64 = 1e-5;

/// A spatial three-joint chain (standard D-H) with a fixed rig → base row.
fn chain() -> Chain {
    let row = DhRow::standard;
    Chain::from_dh(&[
        row(0.1, 0.0, 0.2, None),
        row(0.0, std::f64::consts::FRAC_PI_2, 0.05, Some(0)),
        row(0.25, 0.0, 0.0, Some(1)),
        row(0.2, 0.3, 0.02, Some(2)),
    ])
    .unwrap()
}

fn capstan_params(c: f64) -> CapstanParams {
    CapstanParams {
        c_rad: c,
        re: -0.02,
        r_o_m: 0.2e-3,
        beta_o_rad: -1.8,
        r_i_m: 0.01e-3,
        beta_i_rad: 0.7,
    }
}

fn transmissions() -> JointTransmissions {
    JointTransmissions {
        capstans: vec![
            (1, Capstan::try_new(10.0, 0.06).unwrap()),
            (2, Capstan::try_new(12.0, 0.06).unwrap()),
        ],
        poly_joint: 3,
        poly_degree: 3,
        poly_lo_rad: -1.0,
        poly_hi_rad: 1.2,
    }
}

fn poly() -> Chebyshev {
    Chebyshev::try_new(-1.0, 1.2, vec![1e-3, -2e-3, 5e-4, 3e-4]).unwrap()
}

/// Readings, ext angles of the truth transmissions and distances 1 mm off the nominal chain.
fn data() -> JointData {
    let t = transmissions();
    let chain = chain();
    let x0 = vec![0.0; chain.n_params()];
    let q: Vec<Vec<f64>> = (0..12)
        .map(|i| {
            let s = i as f64;
            vec![(0.7 * s).sin(), 0.4 * (1.3 * s).cos(), 0.1 + 0.08 * s]
        })
        .collect();
    let mut ext = vec![Vec::new(); 3];
    for row in &q {
        for (c, (joint, capstan)) in t.capstans.iter().enumerate() {
            let p = capstan_params(1e-3 * c as f64);
            ext[c].push(capstan.output_rad(&p, JointRad(row[joint - 1])));
        }
        ext[2].push(row[2] + poly().eval(row[2]));
    }
    let distance_m = q
        .iter()
        .map(|row| chain.end_point(&x0, row).coords.norm() + 1e-3)
        .collect();
    JointData { q, ext, distance_m }
}

fn problem() -> JointProblem {
    JointProblem::new(chain(), transmissions(), data(), SIGMA_EXT, SIGMA_D).unwrap()
}

/// The truth transmissions and a small kinematic deviation.
fn x_test(p: &JointProblem) -> Col<f64> {
    let caps = [capstan_params(0.0), capstan_params(1e-3)];
    let n_kin = chain().n_params();
    let x_kin = Col::from_fn(n_kin, |i| 1e-3 * ((i as f64) * 0.37).sin());
    p.start(&caps, &poly().coeffs, x_kin.as_ref())
}

#[test]
fn layout_residual_counts_and_offsets() {
    let p = problem();
    let n_kin = chain().n_params();
    assert_eq!(p.n_trans(), 2 * 6 + 4);
    assert_eq!(p.layout().len(), 16 + n_kin);
    assert_eq!(p.n_residuals(), 4 * 12);
    assert_eq!(p.distance_offset(), 3 * 12);
    let names: Vec<&str> = (0..p.layout().len()).map(|i| p.layout().name(i)).collect();
    assert_eq!(names[0], "capstan1.c");
    assert_eq!(names[11], "capstan2.beta_i");
    assert_eq!(names[12], "joint3.cheb0");
    assert_eq!(names[15], "joint3.cheb3");
    assert_eq!(names[16], chain().params()[0].name);
    let x = x_test(&p);
    let (caps, poly_x) = p.transmissions(x.as_ref()).unwrap();
    assert_eq!(caps, [capstan_params(0.0), capstan_params(1e-3)]);
    assert_eq!(poly_x, poly());
}

#[test]
fn residual_blocks_are_the_step_1_and_distance_residuals() {
    let p = problem();
    let x = x_test(&p);
    let mut r = Col::zeros(p.n_residuals());
    p.residuals(x.as_ref(), r.as_mut()).unwrap();
    let d = data();
    let t = transmissions();
    // Each capstan's block is its CapstanProblem's residuals (here scaled by the same σ).
    for (c, (joint, capstan)) in t.capstans.iter().enumerate() {
        let theta: Vec<f64> = d.q.iter().map(|q| q[joint - 1]).collect();
        let step1 =
            CapstanProblem::new(*capstan, *joint, theta, d.ext[c].clone(), SIGMA_EXT).unwrap();
        let mut r1 = Col::zeros(12);
        step1.residuals(x.subrows(6 * c, 6), r1.as_mut()).unwrap();
        for k in 0..12 {
            assert_eq!(r[c * 12 + k], r1[k], "capstan {joint}, row {k}");
        }
    }
    // The polynomial's block is PolynomialProblem's (Clenshaw against the basis sum: rounding).
    let theta: Vec<f64> = d.q.iter().map(|q| q[2]).collect();
    let step1 =
        PolynomialProblem::new(3, 3, -1.0, 1.2, theta, d.ext[2].clone(), SIGMA_EXT).unwrap();
    let mut r1 = Col::zeros(12);
    step1.residuals(x.subrows(12, 4), r1.as_mut()).unwrap();
    for k in 0..12 {
        assert!((r[24 + k] - r1[k]).abs() < 1e-9, "row {k}");
    }
    // The distance block is CalibrationProblem's on the corrected readings.
    let (caps, poly_x) = p.transmissions(x.as_ref()).unwrap();
    let rows =
        d.q.iter()
            .zip(&d.distance_m)
            .map(|(q, &distance_m)| {
                let mut q = q.clone();
                for (c, (joint, capstan)) in t.capstans.iter().enumerate() {
                    q[joint - 1] = capstan.output_rad(&caps[c], JointRad(q[joint - 1]));
                }
                q[2] += poly_x.eval(q[2]);
                Row {
                    q: q.into(),
                    kind: RowKind::Distance { distance_m },
                }
            })
            .collect();
    let kin = crate::CalibrationProblem::new(
        chain(),
        crate::Observations {
            rows,
            ..crate::Observations::default()
        },
        crate::Weights {
            sigma_distance_m: SIGMA_D,
            ..crate::Weights::default()
        },
        None,
    )
    .unwrap();
    let mut r2 = Col::zeros(12);
    kin.residuals(x.subrows(16, chain().n_params()), r2.as_mut())
        .unwrap();
    for k in 0..12 {
        assert!(
            (r[36 + k] - r2[k]).abs() < 1e-8,
            "row {k}: {} vs {}",
            r[36 + k],
            r2[k]
        );
    }
}

#[test]
fn jacobian_matches_central_differences() {
    let p = problem();
    let x = x_test(&p);
    let (m, n) = (p.n_residuals(), p.layout().len());
    let mut jac = Mat::zeros(m, n);
    p.jacobian(x.as_ref(), jac.as_mut()).unwrap();
    let (mut up, mut down) = (Col::<f64>::zeros(m), Col::<f64>::zeros(m));
    for col in 0..n {
        // Eq. 1 varies on the scale of the drum distance (0.06 m), the chain on its links'.
        let h = 1e-7;
        let (mut xp, mut xm) = (x.clone(), x.clone());
        xp[col] += h;
        xm[col] -= h;
        p.residuals(xp.as_ref(), up.as_mut()).unwrap();
        p.residuals(xm.as_ref(), down.as_mut()).unwrap();
        for row in 0..m {
            let fd = (up[row] - down[row]) / (2.0 * h);
            let a = jac[(row, col)];
            assert!(
                (a - fd).abs() <= 1e-3 * (1.0 + fd.abs()),
                "{}: row {row}: analytic {a} vs central difference {fd}",
                p.layout().name(col)
            );
        }
    }
}

#[test]
fn construction_validates_the_data() {
    let new = |t: JointTransmissions, d: JointData, s: f64| {
        JointProblem::new(chain(), t, d, s, SIGMA_D).unwrap_err()
    };
    assert_eq!(
        new(transmissions(), data(), 0.0),
        Error::BadSigma {
            name: "sigma_ext_rad",
            value: 0.0
        }
    );
    let mut t = transmissions();
    t.poly_joint = 4;
    assert_eq!(
        new(t, data(), SIGMA_EXT),
        Error::NoSuchJoint {
            joint: 4,
            n_joints: 3
        }
    );
    let mut t = transmissions();
    t.poly_hi_rad = -2.0;
    assert_eq!(
        new(t, data(), SIGMA_EXT),
        Error::Transmission(TransmissionError::Domain { lo: -1.0, hi: -2.0 })
    );
    let mut d = data();
    d.ext.pop();
    assert_eq!(
        new(transmissions(), d, SIGMA_EXT).to_string(),
        "ext has 2 entries, expected 3"
    );
    let mut d = data();
    d.ext[1].pop();
    assert_eq!(
        new(transmissions(), d, SIGMA_EXT).to_string(),
        "ext column has 11 entries, expected 12"
    );
    let mut d = data();
    d.q[5].push(0.0);
    assert_eq!(
        new(transmissions(), d, SIGMA_EXT),
        Error::JointCount {
            row: 5,
            expected: 3,
            found: 4
        }
    );
    let mut d = data();
    d.ext[2][7] = f64::NAN;
    assert_eq!(
        new(transmissions(), d, SIGMA_EXT),
        Error::NotFinite { row: 7 }
    );
}
