//! The candidates' terms: each effect of the haptic device's library as parametric terms of
//! the log's model (joint-angle errors, distance terms, the model's own effect terms), or why
//! it cannot be tested on this log.

use hapcal_contract::Effect;
use hapcal_io::{Capstan, Device};
use hapcal_transmission::Chebyshev;

use crate::model::{Data, POLY_DEGREE, Term, TermKind};

/// The candidate terms of an effect, or why it cannot be tested on this log.
pub(super) fn candidate_terms(
    effect: Effect,
    device: &Device,
    data: &Data,
    n_joints: usize,
) -> Result<Vec<Term>, String> {
    let terms = match effect {
        // Eyelet wrap `k·(γ − sin γ)`. (Adding powers of cos γ for other laws made the
        // mostly absorbed columns nearly collinear and the refit unstable.)
        Effect::CableAngle => vec![Term {
            name: format!("{effect}.k"),
            unit: "m",
            kind: TermKind::CableAngle { power: 0 },
        }],
        Effect::GravityCompliance => (0..n_joints).map(Term::handle_compliance).collect(),
        Effect::Backlash => backlash(data, n_joints)?,
        Effect::FirstHarmonic => first_harmonic(device, data, n_joints),
        Effect::CapstanHarmonic => capstan_harmonic(device, data, n_joints),
        Effect::ThermalDrift => thermal_drift(data)?,
        Effect::Latency => {
            need_t(data)?;
            vec![Term {
                name: format!("{effect}.tau"),
                unit: "s",
                kind: TermKind::Latency,
            }]
        }
        Effect::CableOffset => vec![Term {
            name: format!("{effect}.c"),
            unit: "m",
            kind: TermKind::Distance {
                h: vec![1.0; data.n_rows()],
            },
        }],
        Effect::Capstans => capstans(device, data, n_joints),
        Effect::Parallelogram => parallelogram(device, data)?,
        other => {
            return Err(format!(
                "not a candidate of the haptic device's library: {other}"
            ));
        }
    };
    if terms.is_empty() {
        return Err("not testable: the device has no joint it applies to".to_owned());
    }
    Ok(terms)
}

/// A time-dependent effect needs the log's `t_s` column.
fn need_t(data: &Data) -> Result<(), String> {
    if data.t_s().is_some() {
        Ok(())
    } else {
        Err("not testable: the log has no t_s column".to_owned())
    }
}

/// A joint-angle error `Δq_joint = c·g(row)`.
fn joint_term(name: String, joint: usize, g: Vec<f64>) -> Term {
    Term {
        name,
        unit: "rad",
        kind: TermKind::Joint { joint, g },
    }
}

/// `f` of joint `j`'s reading, per row.
fn col(data: &Data, j: usize, f: &dyn Fn(f64) -> f64) -> Vec<f64> {
    data.q()
        .iter()
        .map(|q| f(q.get(j).copied().unwrap_or(0.0)))
        .collect()
}

/// The capstan of joint `j` (0-based).
fn capstan_of(device: &Device, j: usize) -> Option<&Capstan> {
    device.capstans.iter().find(|c| c.joint == j + 1)
}

/// The joints of the first `n_joints` (0-based, in order) with a capstan drive, and its drive.
fn capstan_joints(device: &Device, n_joints: usize) -> impl Iterator<Item = (usize, &Capstan)> {
    (0..n_joints).filter_map(|j| capstan_of(device, j).map(|c| (j, c)))
}

/// Half the dead band against each joint's direction of motion.
fn backlash(data: &Data, n_joints: usize) -> Result<Vec<Term>, String> {
    need_t(data)?;
    let effect = Effect::Backlash;
    let terms = (0..n_joints)
        .map(|j| {
            let dir = data.direction(j).unwrap_or_default();
            joint_term(
                format!("{effect}.j{}", j + 1),
                j,
                dir.iter().map(|d| -d).collect(),
            )
        })
        .collect();
    Ok(terms)
}

/// Sine and cosine of the reading of each joint without a capstan.
fn first_harmonic(device: &Device, data: &Data, n_joints: usize) -> Vec<Term> {
    let effect = Effect::FirstHarmonic;
    let mut terms = Vec::new();
    for j in (0..n_joints).filter(|&j| capstan_of(device, j).is_none()) {
        terms.push(joint_term(
            format!("{effect}.j{}_sin", j + 1),
            j,
            col(data, j, &f64::sin),
        ));
        terms.push(joint_term(
            format!("{effect}.j{}_cos", j + 1),
            j,
            col(data, j, &f64::cos),
        ));
    }
    terms
}

/// Second harmonic of each capstan's motor drum, 2·R·θ. (The output drum's, 2·θ, is so
/// smooth over a joint range that it fits any slow joint error: not tested.)
fn capstan_harmonic(device: &Device, data: &Data, n_joints: usize) -> Vec<Term> {
    let effect = Effect::CapstanHarmonic;
    let mut terms = Vec::new();
    for (j, c) in capstan_joints(device, n_joints) {
        let r = c.ratio;
        terms.push(joint_term(
            format!("{effect}.j{}_sin", j + 1),
            j,
            col(data, j, &|q| (2.0 * r * q).sin()),
        ));
        terms.push(joint_term(
            format!("{effect}.j{}_cos", j + 1),
            j,
            col(data, j, &|q| (2.0 * r * q).cos()),
        ));
    }
    terms
}

/// A scale drift and an offset drift of the distance over time.
fn thermal_drift(data: &Data) -> Result<Vec<Term>, String> {
    need_t(data)?;
    let effect = Effect::ThermalDrift;
    Ok(vec![
        Term {
            name: format!("{effect}.k"),
            unit: "1/s",
            kind: TermKind::ThermalDrift { scale: true },
        },
        Term {
            name: format!("{effect}.rate"),
            unit: "m/s",
            kind: TermKind::ThermalDrift { scale: false },
        },
    ])
}

/// Paper eq. 1 to first order in r/D, per capstan joint outside the parallelogram: offset
/// (= dtheta), ratio error, output- and input-drum eccentricity harmonics.
fn capstans(device: &Device, data: &Data, n_joints: usize) -> Vec<Term> {
    let effect = Effect::Capstans;
    let mut terms = Vec::new();
    for (j, c) in capstan_joints(device, n_joints) {
        if device.parallelogram.is_some() && j + 1 == hapcal_sim::PARALLELOGRAM_JOINT {
            continue;
        }
        let r = c.ratio;
        let n = j + 1;
        let columns: [(&str, &dyn Fn(f64) -> f64); 5] = [
            ("ratio", &|q| q),
            ("out_sin", &f64::sin),
            ("out_cos", &f64::cos),
            ("in_sin", &|q| (r * q).sin()),
            ("in_cos", &|q| (r * q).cos()),
        ];
        for (key, f) in columns {
            terms.push(joint_term(
                format!("{effect}.j{n}_{key}"),
                j,
                col(data, j, f),
            ));
        }
    }
    terms
}

/// The parallelogram joint's error as Chebyshev polynomials 1 to [`POLY_DEGREE`] over its
/// range.
fn parallelogram(device: &Device, data: &Data) -> Result<Vec<Term>, String> {
    let effect = Effect::Parallelogram;
    let j = hapcal_sim::PARALLELOGRAM_JOINT - 1;
    let (lo, hi) = device.joint_limits().get(j).copied().unwrap_or((-1.0, 1.0));
    let probe =
        Chebyshev::try_new(lo, hi, vec![0.0; POLY_DEGREE + 1]).map_err(|e| e.to_string())?;
    let basis: Vec<Vec<f64>> = data
        .q()
        .iter()
        .map(|q| probe.basis(q.get(j).copied().unwrap_or(0.0)))
        .collect();
    let terms = (1..=POLY_DEGREE)
        .map(|k| {
            joint_term(
                format!("{effect}.cheb{k}"),
                j,
                basis
                    .iter()
                    .map(|b| b.get(k).copied().unwrap_or(0.0))
                    .collect(),
            )
        })
        .collect();
    Ok(terms)
}
